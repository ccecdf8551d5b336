//! Private quaternion / SO(3) / SE(3) helpers generic over a dual-number scalar, shared by the
//! discrete and spline pose fields.
//!
//! Every function is written once for `D: DualNum<Primitive = f64> + Copy`: with `D = f64` it is
//! the plain forward path; with `D = DualSVec64<N>` it yields the exact Jacobian with respect to
//! `N` local parameters (forward-mode automatic differentiation); with `D = Dual2<…>` it carries
//! exact first and second time derivatives. The singular points of `sqrt` and `atan2` at zero
//! rotation are avoided by Taylor branches in `θ²` (no square root), so derivatives stay finite
//! and exact at the all-zero initial parameters.
//!
//! Conventions: Hamilton quaternions `w + xi + yj + zk`; a rotation vector `r = θ n` (radians)
//! maps to the unit quaternion `exp(r/2) = (cos(θ/2), sin(θ/2) n)`.

use nalgebra::{Const, Quaternion, U1, Vector3};
use num_dual::{Dual2, DualNum, DualSVec64};

use super::{Order, PoseBatch};

/// The scalar of the generic evaluation: `f64`, a forward-mode dual number, or nested duals.
pub(crate) trait Scalar: DualNum<Primitive = f64> + Copy {}
impl<D: DualNum<Primitive = f64> + Copy> Scalar for D {}

/// Taylor branches are taken when `θ²` (half-angle of a quaternion exponential, or angle of the
/// se(3) `V` matrix, radians²) is below this. Compared against `θ²`, not `θ`: the series below
/// are truncated after the `θ⁶` term, so the dropped `θ⁸/8!` term is below `3e-21` relative,
/// while the closed forms at `θ = 0.01` lose at most ~`1e-11` to cancellation.
const SMALL_ANGLE_SQ: f64 = 1e-4;

/// Taylor branch of the quaternion logarithm when `|vec(q)|² / w² < SMALL_TAN_SQ` (the squared
/// tangent of the half angle); the series of `atan(x)/x` is truncated after `x⁶` (error `< x⁸/9`).
const SMALL_TAN_SQ: f64 = 1e-4;

/// A 3-vector of generic scalars.
pub(crate) type V3<D> = [D; 3];

/// A quaternion `w + xi + yj + zk` of generic scalars (Hamilton product).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Quat<D> {
    pub w: D,
    pub x: D,
    pub y: D,
    pub z: D,
}

impl<D: Scalar> Quat<D> {
    /// The pure quaternion `(0, v)`.
    pub fn pure(v: V3<D>) -> Self {
        Self {
            w: D::zero(),
            x: v[0],
            y: v[1],
            z: v[2],
        }
    }

    /// `(w, v)`.
    pub fn from_parts(w: D, v: V3<D>) -> Self {
        Self {
            w,
            x: v[0],
            y: v[1],
            z: v[2],
        }
    }

    /// The identity `(1, 0, 0, 0)`.
    pub fn identity() -> Self {
        Self {
            w: D::one(),
            x: D::zero(),
            y: D::zero(),
            z: D::zero(),
        }
    }

    /// A constant quaternion.
    pub fn constant(q: &Quaternion<f64>) -> Self {
        Self {
            w: D::from(q.w),
            x: D::from(q.i),
            y: D::from(q.j),
            z: D::from(q.k),
        }
    }

    /// The vector part.
    pub fn imag(&self) -> V3<D> {
        [self.x, self.y, self.z]
    }

    /// `q*`.
    pub fn conj(&self) -> Self {
        Self {
            w: self.w,
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }

    /// Hamilton product `self ⊗ o = (w₁w₂ − v₁·v₂, w₁v₂ + w₂v₁ + v₁×v₂)`.
    pub fn mul(&self, o: &Self) -> Self {
        Self {
            w: self.w * o.w - self.x * o.x - self.y * o.y - self.z * o.z,
            x: self.w * o.x + self.x * o.w + self.y * o.z - self.z * o.y,
            y: self.w * o.y - self.x * o.z + self.y * o.w + self.z * o.x,
            z: self.w * o.z + self.x * o.y - self.y * o.x + self.z * o.w,
        }
    }

    /// Componentwise sum.
    pub fn add(&self, o: &Self) -> Self {
        Self {
            w: self.w + o.w,
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }

    /// Multiplication by a scalar.
    pub fn scale(&self, s: D) -> Self {
        Self {
            w: self.w * s,
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
}

/// `a · b`.
pub(crate) fn dot<D: Scalar>(a: &V3<D>, b: &V3<D>) -> D {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a × b`.
pub(crate) fn cross<D: Scalar>(a: &V3<D>, b: &V3<D>) -> V3<D> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `s · a`.
pub(crate) fn scale3<D: Scalar>(a: &V3<D>, s: D) -> V3<D> {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// The unit quaternion of a rotation vector: `exp(r/2) = (cos θ, sin θ / θ · r/2)` with
/// `θ = |r|/2`. Near zero (`θ² < SMALL_ANGLE_SQ`) `cos θ = 1 − θ²/2 + θ⁴/24 − θ⁶/720` and
/// `sin θ/θ = 1 − θ²/6 + θ⁴/120 − θ⁶/5040`, so no square root is taken.
pub(crate) fn exp_rotvec<D: Scalar>(r: &V3<D>) -> Quat<D> {
    let half = scale3(r, D::from(0.5));
    let t2 = dot(&half, &half);
    let (c, sinc) = if t2.re() < SMALL_ANGLE_SQ {
        let t4 = t2 * t2;
        let t6 = t4 * t2;
        (
            -t2 * 0.5 + t4 * (1.0 / 24.0) - t6 * (1.0 / 720.0) + 1.0,
            -t2 * (1.0 / 6.0) + t4 * (1.0 / 120.0) - t6 * (1.0 / 5040.0) + 1.0,
        )
    } else {
        let t = t2.sqrt();
        let (s, c) = t.sin_cos();
        (c, s / t)
    };
    Quat::from_parts(c, scale3(&half, sinc))
}

/// The rotation vector of a unit quaternion, `r = 2 atan2(|v|, w) / |v| · v`, without choosing
/// the shorter of `±q`: the half angle is in `[0, π]`, so `exp_rotvec(log_rotvec(q)) = q`
/// exactly, sign included (what keeps the cumulative spline continuous across knots). Singular
/// only at `q = −1` (a full turn). Near the identity (`|v|²/w² < SMALL_TAN_SQ`, `w > 0`)
/// `atan2(s, w)/s = (1/w)(1 − x/3 + x²/5 − x³/7)` with `x = s²/w²`.
pub(crate) fn log_rotvec<D: Scalar>(q: &Quat<D>) -> V3<D> {
    let v = q.imag();
    let s2 = dot(&v, &v);
    let w = q.w;
    let wr = w.re();
    let f = if wr > 0.0 && s2.re() < SMALL_TAN_SQ * wr * wr {
        let x = s2 / (w * w);
        let x2 = x * x;
        (-x * (1.0 / 3.0) + x2 * (1.0 / 5.0) - x2 * x * (1.0 / 7.0) + 1.0) / w
    } else {
        let s = s2.sqrt();
        s.atan2(w) / s
    };
    scale3(&v, f * 2.0)
}

/// `V(ω)·v = v + A ω×v + B ω×(ω×v)` with `A = (1 − cos θ)/θ²`, `B = (θ − sin θ)/θ³`, `θ = |ω|`:
/// the translation of the se(3) exponential `Exp(ω, v)` (Barfoot, *State Estimation for
/// Robotics*, eq. 7.86; BARF `camera.py`). Near zero (`θ² < SMALL_ANGLE_SQ`)
/// `A = 1/2 − θ²/24 + θ⁴/720 − θ⁶/40320`, `B = 1/6 − θ²/120 + θ⁴/5040 − θ⁶/362880`.
pub(crate) fn se3_v_times<D: Scalar>(omega: &V3<D>, v: &V3<D>) -> V3<D> {
    let t2 = dot(omega, omega);
    let (a, b) = if t2.re() < SMALL_ANGLE_SQ {
        let t4 = t2 * t2;
        let t6 = t4 * t2;
        (
            -t2 * (1.0 / 24.0) + t4 * (1.0 / 720.0) - t6 * (1.0 / 40320.0) + 0.5,
            -t2 * (1.0 / 120.0) + t4 * (1.0 / 5040.0) - t6 * (1.0 / 362_880.0) + 1.0 / 6.0,
        )
    } else {
        let t = t2.sqrt();
        let (s, c) = t.sin_cos();
        ((-c + 1.0) / t2, (t - s) / (t2 * t))
    };
    let wv = cross(omega, v);
    let wwv = cross(omega, &wv);
    [
        v[0] + a * wv[0] + b * wwv[0],
        v[1] + a * wv[1] + b * wwv[1],
        v[2] + a * wv[2] + b * wwv[2],
    ]
}

/// A scalar with its first and second time derivatives as a [`Dual2`].
pub(crate) fn jet2<D: Scalar>(value: D, d1: D, d2: D) -> Dual2<D> {
    Dual2::new(value, d1, d2)
}

/// The pose and its first two time derivatives: index 0 value, 1 first, 2 second derivative.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Jet<D> {
    /// `q, q̇, q̈`.
    pub q: [Quat<D>; 3],
    /// `p, ṗ, p̈`.
    pub p: [V3<D>; 3],
}

impl<D: Scalar> Jet<D> {
    /// Splits a quaternion of `Dual2` scalars into `q, q̇, q̈`.
    pub fn quat_from_dual2(q: &Quat<Dual2<D>>) -> [Quat<D>; 3] {
        let pick = |f: fn(&Dual2<D>) -> D| Quat {
            w: f(&q.w),
            x: f(&q.x),
            y: f(&q.y),
            z: f(&q.z),
        };
        [pick(|d| d.re), pick(|d| d.v1), pick(|d| d.v2)]
    }

    /// Splits a vector of `Dual2` scalars into `p, ṗ, p̈`.
    pub fn vec_from_dual2(p: &V3<Dual2<D>>) -> [V3<D>; 3] {
        [
            [p[0].re, p[1].re, p[2].re],
            [p[0].v1, p[1].v1, p[2].v1],
            [p[0].v2, p[1].v2, p[2].v2],
        ]
    }
}

/// Writes an `f64` jet into entry `i` of `out` up to `out.order`.
pub(crate) fn write_jet(out: &mut PoseBatch, i: usize, jet: &Jet<f64>) {
    let q = |q: &Quat<f64>| Quaternion::new(q.w, q.x, q.y, q.z);
    let v = |p: &V3<f64>| Vector3::new(p[0], p[1], p[2]);
    out.rotation[i] = q(&jet.q[0]);
    out.translation[i] = v(&jet.p[0]);
    if out.order >= Order::Velocity {
        out.rotation_rate[i] = q(&jet.q[1]);
        out.lin_vel_world[i] = v(&jet.p[1]);
    }
    if out.order >= Order::Acceleration {
        out.rotation_acc[i] = q(&jet.q[2]);
        out.lin_acc_world[i] = v(&jet.p[2]);
    }
}

/// Local parameters `values` as dual numbers seeded with the unit directions `e_k`.
pub(crate) fn seed<const N: usize>(values: &[f64; N]) -> [DualSVec64<N>; N] {
    std::array::from_fn(|k| DualSVec64::<N>::from_re(values[k]).derivative(k))
}

/// `Σ_outputs ⟨cotangent_i, ∂output_i/∂θ_local⟩` for entry `i`, from a jet of dual numbers
/// (empty cotangent vectors are zero).
pub(crate) fn pullback<const N: usize>(
    jet: &Jet<DualSVec64<N>>,
    cot: &PoseBatch,
    i: usize,
) -> [f64; N] {
    let mut g = pullback_rotation(&jet.q, cot, i);
    let cp = translation_cotangent(cot, i);
    for order in 0..3 {
        for a in 0..3 {
            add_scaled_eps(&mut g, &jet.p[order][a], cp[order][a]);
        }
    }
    g
}

/// As [`pullback`] for the rotation outputs `q, q̇, q̈` only.
pub(crate) fn pullback_rotation<const N: usize>(
    q: &[Quat<DualSVec64<N>>; 3],
    cot: &PoseBatch,
    i: usize,
) -> [f64; N] {
    pullback_quats(q, &rotation_cotangent(cot, i))
}

/// `Σ_d ⟨c_d, ∂q^{(d)}/∂θ⟩` for quaternions `q^{(d)}` of dual numbers.
pub(crate) fn pullback_quats<const N: usize>(
    q: &[Quat<DualSVec64<N>>; 3],
    c: &[Quaternion<f64>; 3],
) -> [f64; N] {
    let mut g = [0.0; N];
    for order in 0..3 {
        let (q, c) = (&q[order], &c[order]);
        add_scaled_eps(&mut g, &q.w, c.w);
        add_scaled_eps(&mut g, &q.x, c.i);
        add_scaled_eps(&mut g, &q.y, c.j);
        add_scaled_eps(&mut g, &q.z, c.k);
    }
    g
}

/// The cotangents of `q, q̇, q̈` at entry `i` (zero where absent).
pub(crate) fn rotation_cotangent(cot: &PoseBatch, i: usize) -> [Quaternion<f64>; 3] {
    let zero = Quaternion::new(0.0, 0.0, 0.0, 0.0);
    let get = |v: &Vec<Quaternion<f64>>| v.get(i).copied().unwrap_or(zero);
    [
        get(&cot.rotation),
        get(&cot.rotation_rate),
        get(&cot.rotation_acc),
    ]
}

/// The cotangents of `p, ṗ, p̈` at entry `i` (zero where absent).
pub(crate) fn translation_cotangent(cot: &PoseBatch, i: usize) -> [Vector3<f64>; 3] {
    let get = |v: &Vec<Vector3<f64>>| v.get(i).copied().unwrap_or_else(Vector3::zeros);
    [
        get(&cot.translation),
        get(&cot.lin_vel_world),
        get(&cot.lin_acc_world),
    ]
}

/// `g += c · ∂d/∂θ`.
fn add_scaled_eps<const N: usize>(g: &mut [f64; N], d: &DualSVec64<N>, c: f64) {
    if c != 0.0 {
        let e = d.eps.unwrap_generic(Const::<N>, U1);
        for k in 0..N {
            g[k] += c * e[k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    #[test]
    fn exp_and_log_match_nalgebra_and_invert_each_other() {
        for r in [
            [0.0f64, 0.0, 0.0],
            [1e-4, -2e-4, 3e-5],
            [0.3, -0.2, 0.5],
            [2.0, 1.0, -1.5],
        ] {
            let q = exp_rotvec(&r);
            let reference = UnitQuaternion::from_scaled_axis(Vector3::from(r));
            let diff = (Quaternion::new(q.w, q.x, q.y, q.z) - reference.quaternion()).norm();
            assert!(diff < 1e-15, "{r:?}: {diff}");
            let back = log_rotvec(&q);
            for a in 0..3 {
                assert!((back[a] - r[a]).abs() < 1e-14, "{r:?} vs {back:?}");
            }
        }
        // No hemisphere flip: a rotation of 1.5π about z keeps its sign through log/exp.
        let r = [0.0, 0.0, 1.5 * std::f64::consts::PI];
        let back = log_rotvec(&exp_rotvec(&r));
        assert!((back[2] - r[2]).abs() < 1e-12);
    }

    #[test]
    fn dual_derivatives_are_finite_and_exact_at_zero() {
        // d/dr exp(r/2) at r = 0 is (0, I/2); d/dq log at identity is 2·(vector part).
        let r = seed(&[0.0, 0.0, 0.0]);
        let q = exp_rotvec(&r);
        let ex = q.x.eps.unwrap_generic(Const::<3>, U1);
        assert_eq!(ex[0], 0.5);
        let back = log_rotvec(&q);
        let e = back[1].eps.unwrap_generic(Const::<3>, U1);
        assert!((e[1] - 1.0).abs() < 1e-15 && e[0] == 0.0);
        let v = se3_v_times(&r, &[r[0], r[1], r[2]]);
        assert!(v[0].eps.unwrap_generic(Const::<3>, U1)[0].is_finite());
    }

    #[test]
    fn se3_v_matches_closed_form_on_both_branches() {
        for omega in [[1e-3f64, 2e-3, -1e-3], [0.7, -0.4, 0.2]] {
            let v = [0.3f64, -1.2, 0.8];
            let got = se3_v_times(&omega, &v);
            let w = Vector3::from(omega);
            let t = w.norm();
            let wx = w.cross_matrix();
            let m = nalgebra::Matrix3::identity()
                + wx * ((1.0 - t.cos()) / (t * t))
                + wx * wx * ((t - t.sin()) / (t * t * t));
            let want = m * Vector3::from(v);
            for a in 0..3 {
                assert!((got[a] - want[a]).abs() < 1e-10, "{got:?} vs {want}");
            }
        }
    }
}
