//! 2-D warps of normalised image coordinates (see [`crate::image::NormalizedFrame`]) for the
//! planar alignment study (docs/methods.md §2.1; BARF `warp.py`), with analytic Jacobians with
//! respect to the warp parameters.
//!
//! * [`WarpKind::Se2`], `p = [θ, tx, ty]`: `x' = R(θ)·x + t`, `R(θ) = [[cos θ, −sin θ],
//!   [sin θ, cos θ]]`. Positive θ turns +x towards +y, counter-clockwise in the (x, y) plane as
//!   written; on screen, where y points down, that looks clockwise. This is the SO(2)×R²
//!   parameterisation: BARF's `se2` warp instead uses the group exponential, translation `V(θ)·t`.
//! * [`WarpKind::Homography`], `p = [h1, …, h8]`: BARF's sl(3) exponential,
//!   `A = [[h5, h3, h1], [h4, −h5−h6, h2], [h7, h8, h6]]` (trace 0, so `det H = 1`), `H = expm(A)`,
//!   `x' = (H·[x, y, 1])_{1:2} / ((H·[x, y, 1])_3 + 1e-8)`.
//!
//! [`Warp`] precomputes `H` and `∂H/∂p_k` once per parameter vector, so the per-pixel work in
//! [`Warp::apply_jacobian`] is two 3×3 matrix–vector products per parameter.

use nalgebra::{Matrix3, SMatrix, Vector3};
use serde::{Deserialize, Serialize};

use crate::image::NormalizedFrame;

/// The largest parameter count of any [`WarpKind`] (the homography's 8); the size of the
/// Jacobian array returned by [`Warp::apply_jacobian`].
pub const MAX_WARP_DIM: usize = 8;

/// BARF's guard added to the homogeneous coordinate before dividing:
/// `x' = v_{1:2} / (v_3 + 1e-8)`. Kept for fidelity; it makes the identity homography scale
/// points by `1/(1 + 1e-8)`.
pub const HOMOGRAPHY_DEPTH_EPS: f64 = 1e-8;

/// Scaling-and-squaring threshold: `A` is halved until `‖A/2^s‖₁ ≤ EXPM_THETA`.
const EXPM_THETA: f64 = 0.5;

/// Degree of the Taylor polynomial used after scaling. With `‖X‖₁ ≤ 0.5` the truncation error is
/// below `0.5^19/19!·e^0.5 ≈ 5e-23`, far under f64 rounding.
const EXPM_TAYLOR_DEGREE: usize = 18;

/// The family of a 2-D warp. Spelled `"se2"` and `"homography"` in configuration files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WarpKind {
    /// Rotation and translation, `p = [θ, tx, ty]` (θ in radians, t in normalised units).
    Se2,
    /// BARF's 8-parameter sl(3) homography, `p = [h1, …, h8]`.
    Homography,
}

impl WarpKind {
    /// Number of parameters: 3 for [`WarpKind::Se2`], 8 for [`WarpKind::Homography`].
    pub fn dim(self) -> usize {
        match self {
            WarpKind::Se2 => 3,
            WarpKind::Homography => 8,
        }
    }
}

/// The sl(3) generator of BARF's homography:
/// `A(h) = [[h5, h3, h1], [h4, −h5−h6, h2], [h7, h8, h6]]` for `h = [h1, …, h8]` (0-based
/// `h[0] = h1`). `A` is linear in `h`: `A = Σ_k h_k·E_k` with `E_k` = [`sl3_basis`]`(k)`.
///
/// # Panics
/// If `h.len() != 8`.
pub fn sl3_generator(h: &[f64]) -> Matrix3<f64> {
    assert_eq!(h.len(), 8, "sl(3) generator needs 8 parameters");
    #[rustfmt::skip]
    let a = Matrix3::new(
        h[4], h[2], h[0],
        h[3], -h[4] - h[5], h[1],
        h[6], h[7], h[5],
    );
    a
}

/// `E_k = ∂A/∂h_k`, the k-th (0-based) basis matrix of [`sl3_generator`]: h1 → (0,2), h2 → (1,2),
/// h3 → (0,1), h4 → (1,0), h5 → (0,0) − (1,1), h6 → (2,2) − (1,1), h7 → (2,0), h8 → (2,1)
/// (entries (row, column) set to ±1).
///
/// # Panics
/// If `k ≥ 8`.
pub fn sl3_basis(k: usize) -> Matrix3<f64> {
    let mut e = [0.0; 8];
    e[k] = 1.0;
    sl3_generator(&e)
}

/// The matrix exponential `e^A = Σ_k A^k/k!` of a 3×3 matrix, by scaling and squaring:
/// `e^A = (T_m(A/2^s))^(2^s)` with `s` the smallest integer such that `‖A/2^s‖₁ ≤ 0.5` and
/// `T_m` the degree-18 Taylor polynomial. Accurate to a few ulps times `2^s·‖e^A‖` (about
/// `1e-15` relative for the small generators of the planar study). Non-finite input gives NaN.
pub fn expm(a: &Matrix3<f64>) -> Matrix3<f64> {
    expm_with_frechet(a, &[]).0
}

/// The exponential and its Fréchet derivative in direction `E`:
/// `(e^A, L(A, E))` with `L(A, E) = d/dε e^{A + εE} |_{ε=0}
/// = ∫₀¹ e^{(1−u)A} E e^{uA} du`, the top-right block of `expm([[A, E], [0, A]])`.
///
/// Computed by differentiating the scaling-and-squaring algorithm of [`expm`] exactly:
/// the Taylor terms `T_k = T_{k−1}·X/k` get derivatives `D_k = (D_{k−1}·X + T_{k−1}·F)/k`
/// (`X = A/2^s`, `F = E/2^s`), and each squaring `e^{2Y} = e^Y·e^Y` gives
/// `L(2Y, 2F) = e^Y·L(Y, F) + L(Y, F)·e^Y`.
pub fn expm_frechet(a: &Matrix3<f64>, e: &Matrix3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let (exp, mut d) = expm_with_frechet(a, std::slice::from_ref(e));
    (exp, d.pop().expect("one direction in, one derivative out"))
}

/// `e^A` and `L(A, E_j)` for every direction `E_j` (see [`expm_frechet`]), for any square size.
fn expm_with_frechet<const N: usize>(
    a: &SMatrix<f64, N, N>,
    directions: &[SMatrix<f64, N, N>],
) -> (SMatrix<f64, N, N>, Vec<SMatrix<f64, N, N>>) {
    let norm = one_norm(a);
    if !norm.is_finite() {
        let nan = SMatrix::<f64, N, N>::from_element(f64::NAN);
        return (nan, vec![nan; directions.len()]);
    }
    // Smallest s ≥ 0 with ‖A‖₁/2^s ≤ θ (at most ~1030 for finite f64 input).
    let mut squarings = 0;
    let mut scale = 1.0;
    while norm * scale > EXPM_THETA {
        squarings += 1;
        scale *= 0.5;
    }
    let x = a * scale;
    let f: Vec<_> = directions.iter().map(|e| e * scale).collect();

    // e^X ≈ Σ_{k=0}^{m} T_k, T_0 = I, T_k = T_{k−1}·X/k; D_k = dT_k in direction F.
    let mut term = SMatrix::<f64, N, N>::identity();
    let mut exp = term;
    let mut d_term = vec![SMatrix::<f64, N, N>::zeros(); f.len()];
    let mut d_exp = d_term.clone();
    for k in 1..=EXPM_TAYLOR_DEGREE {
        let inv_k = 1.0 / k as f64;
        for j in 0..f.len() {
            // D_k = (D_{k−1}·X + T_{k−1}·F)/k, using T_{k−1} before it is updated.
            d_term[j] = (d_term[j] * x + term * f[j]) * inv_k;
            d_exp[j] += d_term[j];
        }
        term = term * x * inv_k;
        exp += term;
    }
    for _ in 0..squarings {
        for d in &mut d_exp {
            // L(2Y, 2F) = e^Y·L(Y, F) + L(Y, F)·e^Y
            *d = exp * *d + *d * exp;
        }
        exp = exp * exp;
    }
    (exp, d_exp)
}

/// `‖A‖₁ = max_j Σ_i |a_ij|` (maximum column sum). NaN if any entry is NaN.
fn one_norm<const N: usize>(a: &SMatrix<f64, N, N>) -> f64 {
    let mut norm: f64 = 0.0;
    for j in 0..N {
        let col: f64 = (0..N).map(|i| a[(i, j)].abs()).sum();
        if col.is_nan() {
            return f64::NAN;
        }
        norm = norm.max(col);
    }
    norm
}

/// The 3×3 matrix of a warp, acting on homogeneous normalised coordinates `[x, y, 1]`:
///
/// * SE(2): `[[cos θ, −sin θ, tx], [sin θ, cos θ, ty], [0, 0, 1]]`;
/// * homography: `expm(A(h))` with `A` from [`sl3_generator`].
///
/// # Panics
/// If `p.len() != kind.dim()`.
pub fn matrix(kind: WarpKind, p: &[f64]) -> Matrix3<f64> {
    assert_eq!(
        p.len(),
        kind.dim(),
        "{kind:?} warp needs {} parameters",
        kind.dim()
    );
    match kind {
        WarpKind::Se2 => {
            let (s, c) = p[0].sin_cos();
            #[rustfmt::skip]
            let m = Matrix3::new(
                c, -s, p[1],
                s, c, p[2],
                0.0, 0.0, 1.0,
            );
            m
        }
        WarpKind::Homography => expm(&sl3_generator(p)),
    }
}

/// A warp with its matrix `H` and the derivatives `∂H/∂p_k` precomputed, for cheap per-pixel
/// evaluation of `x'(x; p)` and `∂x'/∂p`.
#[derive(Clone, Debug, PartialEq)]
pub struct Warp {
    kind: WarpKind,
    h: Matrix3<f64>,
    /// `∂H/∂p_k` for `k < kind.dim()`; the rest zero (a fixed array: building a rigid warp
    /// does not allocate).
    d_h_d_p: [Matrix3<f64>; MAX_WARP_DIM],
}

impl Warp {
    /// Precomputes `H = matrix(kind, p)` and `∂H/∂p_k` for `k < kind.dim()`:
    ///
    /// * SE(2): `∂H/∂θ = [[−sin θ, −cos θ, 0], [cos θ, −sin θ, 0], [0, 0, 0]]`,
    ///   `∂H/∂tx = e₁e₃ᵀ`, `∂H/∂ty = e₂e₃ᵀ`;
    /// * homography: `∂H/∂h_k = L(A, E_k)`, the Fréchet derivative of `expm` at `A(h)` in the
    ///   direction [`sl3_basis`]`(k)` ([`expm_frechet`]).
    ///
    /// # Panics
    /// If `p.len() != kind.dim()`.
    pub fn new(kind: WarpKind, p: &[f64]) -> Warp {
        assert_eq!(
            p.len(),
            kind.dim(),
            "{kind:?} warp needs {} parameters",
            kind.dim()
        );
        match kind {
            WarpKind::Se2 => {
                let (s, c) = p[0].sin_cos();
                #[rustfmt::skip]
                let d_theta = Matrix3::new(
                    -s, -c, 0.0,
                    c, -s, 0.0,
                    0.0, 0.0, 0.0,
                );
                let mut d_tx = Matrix3::zeros();
                d_tx[(0, 2)] = 1.0;
                let mut d_ty = Matrix3::zeros();
                d_ty[(1, 2)] = 1.0;
                let mut d_h_d_p = [Matrix3::zeros(); MAX_WARP_DIM];
                d_h_d_p[..3].copy_from_slice(&[d_theta, d_tx, d_ty]);
                Warp {
                    kind,
                    h: matrix(kind, p),
                    d_h_d_p,
                }
            }
            WarpKind::Homography => {
                let basis: Vec<Matrix3<f64>> = (0..8).map(sl3_basis).collect();
                let (h, d) = expm_with_frechet(&sl3_generator(p), &basis);
                let mut d_h_d_p = [Matrix3::zeros(); MAX_WARP_DIM];
                d_h_d_p.copy_from_slice(&d);
                Warp { kind, h, d_h_d_p }
            }
        }
    }

    /// The warp family.
    pub fn kind(&self) -> WarpKind {
        self.kind
    }

    /// The 3×3 warp matrix `H` (see [`matrix`]).
    pub fn matrix(&self) -> &Matrix3<f64> {
        &self.h
    }

    /// `∂H/∂p_k` for `k < kind.dim()` (length `kind.dim()`).
    pub fn d_matrix_d_param(&self) -> &[Matrix3<f64>] {
        &self.d_h_d_p[..self.kind.dim()]
    }

    /// The warped point (normalised coordinates in and out), with `v = H·[x, y, 1]`:
    /// SE(2) `x' = v_{1:2}`; homography `x' = v_{1:2} / (v_3 + 1e-8)`.
    pub fn apply(&self, x: [f64; 2]) -> [f64; 2] {
        let v = self.h * Vector3::new(x[0], x[1], 1.0);
        match self.kind {
            WarpKind::Se2 => [v.x, v.y],
            WarpKind::Homography => {
                let w = v.z + HOMOGRAPHY_DEPTH_EPS;
                [v.x / w, v.y / w]
            }
        }
    }

    /// The warped point and its Jacobian with respect to the parameters:
    /// `jac[k] = [∂x'/∂p_k, ∂y'/∂p_k]` for `k < kind.dim()`, zero for the unused entries.
    ///
    /// With `v = H·x̃`, `x̃ = [x, y, 1]` and `∂v/∂p_k = (∂H/∂p_k)·x̃`:
    /// SE(2) `∂x'/∂p_k = (∂v/∂p_k)_{1:2}`; homography (quotient rule, `w = v_3 + 1e-8`)
    /// `∂x'_i/∂p_k = ((∂v_i/∂p_k) − x'_i·(∂v_3/∂p_k)) / w`.
    pub fn apply_jacobian(&self, x: [f64; 2]) -> ([f64; 2], [[f64; 2]; MAX_WARP_DIM]) {
        let xh = Vector3::new(x[0], x[1], 1.0);
        let v = self.h * xh;
        let mut jac = [[0.0; 2]; MAX_WARP_DIM];
        match self.kind {
            WarpKind::Se2 => {
                for (j, d_h) in jac.iter_mut().zip(self.d_matrix_d_param()) {
                    let dv = d_h * xh;
                    *j = [dv.x, dv.y];
                }
                ([v.x, v.y], jac)
            }
            WarpKind::Homography => {
                let w = v.z + HOMOGRAPHY_DEPTH_EPS;
                let out = [v.x / w, v.y / w];
                for (j, d_h) in jac.iter_mut().zip(self.d_matrix_d_param()) {
                    let dv = d_h * xh;
                    *j = [(dv.x - out[0] * dv.z) / w, (dv.y - out[1] * dv.z) / w];
                }
                (out, jac)
            }
        }
    }
}

/// BARF's corner error in pixels: `mean_c ‖π(W(c; p_est)) − π(W(c; p_true))‖₂` over the corners
/// `c` (normalised coordinates, e.g. of the crop), where `π` = [`NormalizedFrame::to_pixel`]
/// converts normalised coordinates to pixels of `frame`. For one patch; average over patches
/// outside.
///
/// # Panics
/// If `corners_norm` is empty or a parameter vector's length is not `kind.dim()`.
pub fn corner_error_px(
    kind: WarpKind,
    p_est: &[f64],
    p_true: &[f64],
    corners_norm: &[[f64; 2]],
    frame: &NormalizedFrame,
) -> f64 {
    assert!(
        !corners_norm.is_empty(),
        "corner error needs at least one corner"
    );
    let (est, truth) = (Warp::new(kind, p_est), Warp::new(kind, p_true));
    let total: f64 = corners_norm
        .iter()
        .map(|&c| {
            let a = frame.to_pixel(est.apply(c));
            let b = frame.to_pixel(truth.apply(c));
            (a[0] - b[0]).hypot(a[1] - b[1])
        })
        .sum();
    total / corners_norm.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64 stream mapped to `[−1, 1)`: reproducible test parameters.
    struct TestRng(u64);

    impl TestRng {
        fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }

        fn matrix(&mut self, scale: f64) -> Matrix3<f64> {
            Matrix3::from_fn(|_, _| scale * self.uniform())
        }
    }

    fn max_abs_diff(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
        (a - b).abs().max()
    }

    /// `Σ_{k=0}^{n} A^k/k!` without scaling (fine for ‖A‖ ≲ 3 with n = 80).
    fn taylor_series(a: &Matrix3<f64>, n: usize) -> Matrix3<f64> {
        let mut term = Matrix3::identity();
        let mut sum = term;
        for k in 1..=n {
            term = term * a / k as f64;
            sum += term;
        }
        sum
    }

    #[test]
    fn warp_kind_dims_and_spellings() {
        assert_eq!((WarpKind::Se2.dim(), WarpKind::Homography.dim()), (3, 8));
        assert_eq!(serde_json::to_string(&WarpKind::Se2).unwrap(), "\"se2\"");
        assert_eq!(
            serde_json::to_string(&WarpKind::Homography).unwrap(),
            "\"homography\""
        );
        let parsed: WarpKind = serde_json::from_str("\"homography\"").unwrap();
        assert_eq!(parsed, WarpKind::Homography);
        assert!(serde_json::from_str::<WarpKind>("\"SE2\"").is_err());
    }

    #[test]
    fn expm_matches_a_long_taylor_series() {
        let mut rng = TestRng(1);
        for scale in [0.05, 0.3, 1.0, 2.5] {
            for _ in 0..20 {
                let a = rng.matrix(scale);
                let reference = taylor_series(&a, 80);
                let err = max_abs_diff(&expm(&a), &reference) / reference.abs().max();
                assert!(err < 1e-14, "scale {scale}: relative error {err:e}");
            }
        }
    }

    #[test]
    fn expm_matches_closed_forms() {
        // Diagonal: exp(diag(a, b, c)) = diag(e^a, e^b, e^c); norm 6 needs 4 squarings.
        let d = expm(&Matrix3::from_diagonal(&Vector3::new(6.0, -3.0, 0.2)));
        let expected =
            Matrix3::from_diagonal(&Vector3::new(6f64.exp(), (-3f64).exp(), 0.2f64.exp()));
        for i in 0..3 {
            assert!(
                (d[(i, i)] - expected[(i, i)]).abs() <= 1e-14 * expected[(i, i)],
                "{d}"
            );
        }
        assert_eq!(d - Matrix3::from_diagonal(&d.diagonal()), Matrix3::zeros());
        // Nilpotent (N³ = 0): exp(N) = I + N + N²/2.
        #[rustfmt::skip]
        let n = Matrix3::new(
            0.0, 1.5, -2.0,
            0.0, 0.0, 0.7,
            0.0, 0.0, 0.0,
        );
        let expected = Matrix3::identity() + n + n * n / 2.0;
        assert!(max_abs_diff(&expm(&n), &expected) < 1e-14);
        // Rotation generator: exp(θ·[[0, −1], [1, 0]]) = R(θ), with a 3rd axis left alone.
        let theta = 2.9;
        #[rustfmt::skip]
        let g = Matrix3::new(
            0.0, -theta, 0.0,
            theta, 0.0, 0.0,
            0.0, 0.0, 0.0,
        );
        assert!(max_abs_diff(&expm(&g), &matrix(WarpKind::Se2, &[theta, 0.0, 0.0])) < 1e-14);
        assert_eq!(expm(&Matrix3::zeros()), Matrix3::identity());
        assert!(expm(&Matrix3::from_element(f64::NAN))[(0, 0)].is_nan());
        assert!(expm(&Matrix3::from_element(f64::INFINITY))[(0, 0)].is_nan());
    }

    #[test]
    fn expm_frechet_matches_the_block_exponential_and_central_differences() {
        let mut rng = TestRng(2);
        for scale in [0.1, 0.6, 2.0] {
            let (a, e) = (rng.matrix(scale), rng.matrix(1.0));
            let (exp, l) = expm_frechet(&a, &e);
            // expm([[A, E], [0, A]]) = [[e^A, L(A, E)], [0, e^A]].
            let mut block = SMatrix::<f64, 6, 6>::zeros();
            block.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
            block.fixed_view_mut::<3, 3>(3, 3).copy_from(&a);
            block.fixed_view_mut::<3, 3>(0, 3).copy_from(&e);
            let (big, _) = expm_with_frechet(&block, &[]);
            let top_left: Matrix3<f64> = big.fixed_view::<3, 3>(0, 0).into_owned();
            let top_right: Matrix3<f64> = big.fixed_view::<3, 3>(0, 3).into_owned();
            let size = exp.abs().max().max(l.abs().max());
            assert!(max_abs_diff(&exp, &top_left) < 1e-13 * size);
            assert!(max_abs_diff(&l, &top_right) < 1e-13 * size, "scale {scale}");
            // Central difference, step 1e-5: O(h²) ≈ 1e-10 truncation plus ~1e-11 rounding.
            let h = 1e-5;
            let fd = (expm(&(a + e * h)) - expm(&(a - e * h))) / (2.0 * h);
            assert!(max_abs_diff(&l, &fd) < 1e-8 * size, "scale {scale}");
        }
    }

    #[test]
    fn identity_parameters_give_the_identity_warp() {
        for kind in [WarpKind::Se2, WarpKind::Homography] {
            let zero = vec![0.0; kind.dim()];
            assert_eq!(matrix(kind, &zero), Matrix3::identity());
            let warp = Warp::new(kind, &zero);
            for x in [[0.3, -0.7], [-1.0, 0.75], [0.0, 0.0]] {
                let y = warp.apply(x);
                // The homography divides by 1 + 1e-8 (BARF's guard).
                assert!(
                    (y[0] - x[0]).abs() < 2e-8 && (y[1] - x[1]).abs() < 2e-8,
                    "{kind:?}"
                );
            }
        }
    }

    #[test]
    fn homography_has_unit_determinant_and_h1_h2_translate() {
        let mut rng = TestRng(3);
        let p: Vec<f64> = (0..8).map(|_| 0.3 * rng.uniform()).collect();
        assert!((matrix(WarpKind::Homography, &p).determinant() - 1.0).abs() < 1e-14);
        // A = h1·E_13 + h2·E_23 is nilpotent: H = I + A, a pure translation by (h1, h2).
        let warp = Warp::new(
            WarpKind::Homography,
            &[0.1, -0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        let y = warp.apply([0.5, 0.5]);
        assert!((y[0] - 0.6).abs() < 1e-8 && (y[1] - 0.3).abs() < 1e-8);
    }

    #[test]
    fn se2_matrices_compose_by_adding_angles() {
        let m = |p: [f64; 3]| matrix(WarpKind::Se2, &p);
        let (a, b) = ([0.4, 0.1, -0.2], [1.1, -0.3, 0.05]);
        // [R1 t1; 0 1]·[R2 t2; 0 1] = [R1R2, R1 t2 + t1; 0 1], R1R2 = R(θ1 + θ2).
        let t = m(a) * Vector3::new(b[1], b[2], 1.0);
        let expected = m([a[0] + b[0], t.x, t.y]);
        assert!(max_abs_diff(&(m(a) * m(b)), &expected) < 1e-15);
        // θ = π/2 turns +x into +y.
        let y =
            Warp::new(WarpKind::Se2, &[std::f64::consts::FRAC_PI_2, 0.0, 0.0]).apply([1.0, 0.0]);
        assert!(y[0].abs() < 1e-15 && (y[1] - 1.0).abs() < 1e-15);
    }

    /// Analytic Jacobians and `∂H/∂p` against central differences with step 1e-6
    /// (truncation O(h²) ≈ 1e-12, rounding ≈ 1e-16/1e-6 = 1e-10).
    fn check_jacobian(kind: WarpKind, p: &[f64], rng: &mut TestRng) {
        let h = 1e-6;
        let warp = Warp::new(kind, p);
        for k in 0..kind.dim() {
            let (mut plus, mut minus) = (p.to_vec(), p.to_vec());
            plus[k] += h;
            minus[k] -= h;
            let fd = (matrix(kind, &plus) - matrix(kind, &minus)) / (2.0 * h);
            assert!(
                max_abs_diff(&warp.d_matrix_d_param()[k], &fd) < 1e-8,
                "{kind:?} dH/dp_{k}"
            );
        }
        for _ in 0..10 {
            let x = [rng.uniform(), 0.75 * rng.uniform()];
            let (y, jac) = warp.apply_jacobian(x);
            assert_eq!(y, warp.apply(x));
            for k in 0..MAX_WARP_DIM {
                if k >= kind.dim() {
                    assert_eq!(jac[k], [0.0, 0.0]);
                    continue;
                }
                let (mut plus, mut minus) = (p.to_vec(), p.to_vec());
                plus[k] += h;
                minus[k] -= h;
                let (yp, ym) = (
                    Warp::new(kind, &plus).apply(x),
                    Warp::new(kind, &minus).apply(x),
                );
                for i in 0..2 {
                    let fd = (yp[i] - ym[i]) / (2.0 * h);
                    assert!(
                        (jac[k][i] - fd).abs() < 1e-8,
                        "{kind:?} ∂x'_{i}/∂p_{k}: {} vs {fd}",
                        jac[k][i]
                    );
                }
            }
        }
    }

    #[test]
    fn se2_jacobian_matches_central_differences() {
        let mut rng = TestRng(4);
        for _ in 0..10 {
            let p = [
                1.5 * rng.uniform(),
                0.3 * rng.uniform(),
                0.3 * rng.uniform(),
            ];
            check_jacobian(WarpKind::Se2, &p, &mut rng);
        }
    }

    #[test]
    fn homography_jacobian_matches_central_differences() {
        let mut rng = TestRng(5);
        for scale in [0.1, 0.3] {
            for _ in 0..10 {
                let p: Vec<f64> = (0..8).map(|_| scale * rng.uniform()).collect();
                check_jacobian(WarpKind::Homography, &p, &mut rng);
            }
        }
    }

    #[test]
    fn corner_error_is_zero_for_equal_warps_and_in_pixels() {
        let frame = NormalizedFrame::new(480, 360);
        let corners = [
            [-0.375, -0.375],
            [0.375, -0.375],
            [0.375, 0.375],
            [-0.375, 0.375],
        ];
        let p = [0.2, -0.1, 0.05];
        assert_eq!(
            corner_error_px(WarpKind::Se2, &p, &p, &corners, &frame),
            0.0
        );
        // A shift of 0.1 normalised units is 0.1·L/2 = 24 pixels for L = 480.
        let err = corner_error_px(WarpKind::Se2, &[0.0, 0.1, 0.0], &[0.0; 3], &corners, &frame);
        assert!((err - 24.0).abs() < 1e-12, "{err}");
        let mut shifted = [0.0; 8];
        shifted[1] = 0.1; // h2: vertical translation
        let err = corner_error_px(WarpKind::Homography, &shifted, &[0.0; 8], &corners, &frame);
        assert!((err - 24.0).abs() < 1e-5, "{err}");
    }
}
