//! Cubic B-spline pose fields: the paper's per-dimension baseline ([`PerDimSplinePoses`]) and a
//! cumulative cubic B-spline on SO(3)×R³ ([`LieSplinePoses`]), both behind [`SplinePoses`] for
//! the registry ([`SplineConfig`]).
//!
//! Both evaluate exact time derivatives (no finite differences) and exact parameter gradients.
//! One evaluation depends on 4 control points (24 values): their translations enter linearly
//! (gradients from the basis weights), their rotation vectors through forward-mode automatic
//! differentiation with `num-dual`, narrowed by the chain rule to the few intermediate values the
//! rotation at one time depends on (`r, ṙ, r̈` for the per-dimension spline; `q_0, φ_1..3` for the
//! cumulative one, whose Jacobian with respect to the controls is computed once per segment).

use nalgebra::{DMatrix, Isometry3, Quaternion, UnitQuaternion, Vector3};
use num_dual::{Dual2, DualSVec64};
use serde::{Deserialize, Serialize};

use super::lie_dual::{self, Jet, Quat, Scalar, V3};
use super::{Order, ParamKind, PoseBatch, PoseField, PoseFieldError, check_times};
use crate::{Real, TimeRange};

/// Parameters per control point: rotation vector (radians) then translation.
const PER_CONTROL: usize = 6;
/// Control points one evaluation depends on (cubic: degree + 1).
const SUPPORT: usize = 4;
/// Local parameters of one evaluation.
const LOCAL: usize = PER_CONTROL * SUPPORT;
/// Spline degree (cubic).
const DEGREE: usize = 3;
/// Fewest control points of a cubic spline (one segment).
const MIN_CONTROL_POINTS: usize = DEGREE + 1;
/// Most control points (checked before they are allocated): a knot every millisecond for 15
/// minutes.
const MAX_CONTROL_POINTS: usize = 1_000_000;

/// Number of segments `m = ⌈duration / spacing⌉ ≥ 1` for a requested knot spacing, and so
/// `m + 3` control points; the actual spacing `duration / m` is at most the requested one.
fn num_control_points_for_spacing(
    range: &TimeRange,
    knot_spacing_secs: f64,
) -> Result<usize, PoseFieldError> {
    if !(knot_spacing_secs.is_finite() && knot_spacing_secs > 0.0) {
        return Err(PoseFieldError::Invalid(format!(
            "knot spacing must be positive and finite, got {knot_spacing_secs} s"
        )));
    }
    // Tolerate rounding so that an exact divisor gives exactly that many segments.
    let segments = (range.duration_secs() / knot_spacing_secs * (1.0 - 1e-12)).ceil();
    if segments + DEGREE as f64 > MAX_CONTROL_POINTS as f64 {
        return Err(PoseFieldError::Invalid(format!(
            "knot spacing {knot_spacing_secs} s over {} s gives {segments:.3e} segments; at most \
             {MAX_CONTROL_POINTS} control points",
            range.duration_secs()
        )));
    }
    Ok((segments.max(1.0) as usize) + DEGREE)
}

fn check_num_control_points(num_control_points: usize) -> Result<(), PoseFieldError> {
    if !(MIN_CONTROL_POINTS..=MAX_CONTROL_POINTS).contains(&num_control_points) {
        return Err(PoseFieldError::Invalid(format!(
            "a cubic B-spline has {MIN_CONTROL_POINTS}..={MAX_CONTROL_POINTS} control points, got \
             {num_control_points}"
        )));
    }
    Ok(())
}

fn check_grad_len(got: usize, expected: usize) -> Result<(), PoseFieldError> {
    if got != expected {
        return Err(PoseFieldError::Shape {
            what: "parameter gradient",
            expected,
            got,
        });
    }
    Ok(())
}

/// Below this rotation angle (radians, compared against `|r|`) the axis of a rotation vector is
/// taken as undefined when unwrapping, and the previous vector's axis is used instead.
const AXIS_MIN_ANGLE: f64 = 1e-9;

/// Rotation vectors of `rotations`, made continuous: each is the equivalent rotation vector
/// `n (θ + 2πk)` (angle-axis `(θ, n)`, any integer `k`) closest to its predecessor, so that
/// fitting or interpolating them per dimension does not jump at ±π.
pub(crate) fn unwrap_rotation_vectors(rotations: &[UnitQuaternion<f64>]) -> Vec<Vector3<f64>> {
    use std::f64::consts::TAU;
    let mut out: Vec<Vector3<f64>> = Vec::with_capacity(rotations.len());
    for q in rotations {
        let r = q.scaled_axis();
        let Some(prev) = out.last().copied() else {
            out.push(r);
            continue;
        };
        let theta = r.norm();
        let axis = if theta > AXIS_MIN_ANGLE {
            r / theta
        } else if prev.norm() > AXIS_MIN_ANGLE {
            prev.normalize()
        } else {
            Vector3::x()
        };
        let k0 = ((prev.dot(&axis) - theta) / TAU).round();
        let best = (-1..=1)
            .map(|dk| axis * (theta + TAU * (k0 + dk as f64)))
            .min_by(|a, b| (a - prev).norm().total_cmp(&(b - prev).norm()))
            .unwrap_or(r);
        out.push(best);
    }
    out
}

/// Writes control point `k` (rotation vector, translation) into `ctrl`.
fn set_control<S: Real>(ctrl: &mut [S], k: usize, r: &Vector3<f64>, p: &Vector3<f64>) {
    for a in 0..3 {
        ctrl[PER_CONTROL * k + a] = S::from_f64(r[a]);
        ctrl[PER_CONTROL * k + 3 + a] = S::from_f64(p[a]);
    }
}

/// Rotation-vector values of the 4 local control points.
const ROT_LOCAL: usize = 3 * SUPPORT;

/// Local control point `k`'s rotation vector (`offset = 0`) or translation (`offset = 3`).
fn local_vec(theta: &[f64; LOCAL], k: usize, offset: usize) -> V3<f64> {
    std::array::from_fn(|a| theta[PER_CONTROL * k + offset + a])
}

/// The 24 parameters of control points `first..first + 4` in `f64`.
fn local_params<S: Real>(ctrl: &[S], first: usize) -> [f64; LOCAL] {
    std::array::from_fn(|k| ctrl[PER_CONTROL * first + k].to_f64())
}

// ---------------------------------------------------------------------------------------------
// The paper's baseline: a cubic B-spline per pose dimension.
// ---------------------------------------------------------------------------------------------

/// Values, first and second time derivatives (`[order][o]`) of the 4 cubic basis functions
/// `N_{j−3+o}` that are non-zero in knot span `j`.
type BasisJet = [[f64; SUPPORT]; 3];

/// The paper's B-spline baseline (§4.1 "BaRF with B-spline": 5 knots, degree 3, re-fit every 100
/// steps): an independent cubic B-spline **per pose dimension**, on 3 translation channels and
/// the 3 coordinates of a rotation vector `r(t) ∈ so(3)`:
///
/// `p(t) = Σ_k N_k(t) p_k`, `r(t) = Σ_k N_k(t) r_k`, `q(t) = exp(r(t)/2)` (unit quaternion of the
/// rotation vector, so `q` is continuous whenever `r` is).
///
/// Knots: **clamped (open-uniform)**, degree 3, `K` control points, knot vector
/// `[a, a, a, a, a + Δ, …, b − Δ, b, b, b, b]` with `Δ = (b − a)/(K − 3)` over the time range
/// `[a, b]`, so the spline spans exactly the range, interpolates the first and last control
/// points at `a` and `b`, and is C² inside. Basis functions by the Cox–de Boor recursion and
/// their derivatives by `N'_{i,p} = p (N_{i,p−1}/(t_{i+p} − t_i) − N_{i+1,p−1}/(t_{i+p+1} − t_{i+1}))`
/// (Piegl & Tiller, *The NURBS Book*, eq. 2.7 and 2.9).
///
/// Parameters: `6K` values of kind [`ParamKind::Pose`], control point by control point
/// `(r_k, p_k)` (rotation vector first), zero at construction (identity). `q̇, q̈` follow from
/// `ṙ, r̈` by the exact chain rule through `exp` (second-order dual numbers).
/// [`PerDimSplinePoses::fit`] re-fits the control values to sampled poses by least squares.
#[derive(Clone, Debug)]
pub struct PerDimSplinePoses<S: Real = f32> {
    range: TimeRange,
    knots: Vec<f64>,
    ctrl: Vec<S>,
}

impl<S: Real> PerDimSplinePoses<S> {
    /// Identity poses with `num_control_points` (4 to a million) control points over `range`
    /// (the paper's planar experiment uses 5).
    pub fn new(range: TimeRange, num_control_points: usize) -> Result<Self, PoseFieldError> {
        check_num_control_points(num_control_points)?;
        let segments = num_control_points - DEGREE;
        let (a, b) = (range.start_secs, range.end_secs);
        let mut knots = vec![a; DEGREE + 1];
        for m in 1..segments {
            knots.push(a + (b - a) * m as f64 / segments as f64);
        }
        knots.extend([b; DEGREE + 1]);
        Ok(Self {
            range,
            knots,
            ctrl: vec![S::ZERO; PER_CONTROL * num_control_points],
        })
    }

    /// Identity poses with `⌈duration / knot_spacing_secs⌉ + 3` control points (the interior
    /// knot spacing is then at most `knot_spacing_secs`).
    pub fn with_knot_spacing(
        range: TimeRange,
        knot_spacing_secs: f64,
    ) -> Result<Self, PoseFieldError> {
        Self::new(
            range,
            num_control_points_for_spacing(&range, knot_spacing_secs)?,
        )
    }

    /// A spline with `num_control_points` fitted to poses sampled at `times_secs`
    /// (see [`PerDimSplinePoses::fit`]).
    pub fn from_samples(
        range: TimeRange,
        num_control_points: usize,
        times_secs: &[f64],
        world_from_body: &[Isometry3<f64>],
    ) -> Result<Self, PoseFieldError> {
        let mut s = Self::new(range, num_control_points)?;
        s.fit(times_secs, world_from_body)?;
        Ok(s)
    }

    /// Number of control points `K`.
    pub fn num_control_points(&self) -> usize {
        self.ctrl.len() / PER_CONTROL
    }

    /// The clamped knot vector (`K + 4` knots, seconds).
    pub fn knots_secs(&self) -> &[f64] {
        &self.knots
    }

    /// Least-squares fit of all control values to samples (the paper's "re-fit every 100
    /// steps"): minimises `Σ_m |y(t_m) − Σ_k N_k(t_m) c_k|²` independently per channel, where
    /// `y` is `(r, p)` with the sample rotations converted to rotation vectors and unwrapped to be
    /// continuous in sample order (sort the samples by time). Solves the `K × K` normal
    /// equations `AᵀA c = Aᵀ y` by Cholesky in `f64`; an error if they are singular (e.g. a knot
    /// span without samples or fewer samples than control points).
    pub fn fit(
        &mut self,
        times_secs: &[f64],
        world_from_body: &[Isometry3<f64>],
    ) -> Result<(), PoseFieldError> {
        if world_from_body.len() != times_secs.len() {
            return Err(PoseFieldError::Shape {
                what: "poses",
                expected: times_secs.len(),
                got: world_from_body.len(),
            });
        }
        check_times(&self.range, times_secs)?;
        let k = self.num_control_points();
        let rotations: Vec<_> = world_from_body.iter().map(|p| p.rotation).collect();
        let rotvecs = unwrap_rotation_vectors(&rotations);
        let m = times_secs.len();
        let mut a = DMatrix::<f64>::zeros(m, k);
        let mut y = DMatrix::<f64>::zeros(m, PER_CONTROL);
        for (row, &t) in times_secs.iter().enumerate() {
            let (first, basis) = self.basis(t);
            for o in 0..SUPPORT {
                a[(row, first + o)] = basis[0][o];
            }
            for c in 0..3 {
                y[(row, c)] = rotvecs[row][c];
                y[(row, 3 + c)] = world_from_body[row].translation.vector[c];
            }
        }
        let c = solve_normal_equations(&a, &y)?;
        for kk in 0..k {
            let r = Vector3::new(c[(kk, 0)], c[(kk, 1)], c[(kk, 2)]);
            let p = Vector3::new(c[(kk, 3)], c[(kk, 4)], c[(kk, 5)]);
            set_control(&mut self.ctrl, kk, &r, &p);
        }
        Ok(())
    }

    /// The knot span `j ∈ [3, K−1]` with `t_j ≤ t < t_{j+1}` (the last span at `t = b`), as the
    /// index `j − 3` of the first non-zero basis function, and the [`BasisJet`] there.
    fn basis(&self, t: f64) -> (usize, BasisJet) {
        let kn = &self.knots;
        let k = self.num_control_points();
        let j = kn
            .partition_point(|&x| x <= t)
            .saturating_sub(1)
            .clamp(DEGREE, k - 1);
        // n[d][o] = N_{j−3+o, d}(t) for o in 0..5 (o = 4 is always zero).
        let mut n = [[0.0; SUPPORT + 1]; DEGREE + 1];
        n[0][DEGREE] = 1.0;
        let ratio = |num: f64, den: f64| if den > 0.0 { num / den } else { 0.0 };
        for d in 1..=DEGREE {
            for o in 0..SUPPORT {
                let i = j - DEGREE + o;
                n[d][o] = ratio(t - kn[i], kn[i + d] - kn[i]) * n[d - 1][o]
                    + ratio(kn[i + d + 1] - t, kn[i + d + 1] - kn[i + 1]) * n[d - 1][o + 1];
            }
        }
        // First derivatives of degree 2 and 3, second derivative of degree 3.
        let deriv = |lower: &[f64; SUPPORT + 1], d: usize| -> [f64; SUPPORT + 1] {
            let mut out = [0.0; SUPPORT + 1];
            for o in 0..SUPPORT {
                let i = j - DEGREE + o;
                out[o] = d as f64
                    * (ratio(lower[o], kn[i + d] - kn[i])
                        - ratio(lower[o + 1], kn[i + d + 1] - kn[i + 1]));
            }
            out
        };
        let d1_deg2 = deriv(&n[1], 2);
        let d1 = deriv(&n[2], 3);
        let d2 = deriv(&d1_deg2, 3);
        let first = |v: &[f64; SUPPORT + 1]| -> [f64; SUPPORT] { std::array::from_fn(|o| v[o]) };
        (j - DEGREE, [first(&n[3]), first(&d1), first(&d2)])
    }
}

/// Least-squares coefficients `c = argmin |A c − Y|²` by Cholesky on the normal equations.
fn solve_normal_equations(
    a: &DMatrix<f64>,
    y: &DMatrix<f64>,
) -> Result<DMatrix<f64>, PoseFieldError> {
    let (m, k) = a.shape();
    let chol = (a.transpose() * a).cholesky().ok_or_else(|| {
        PoseFieldError::Invalid(format!(
            "least-squares spline fit is singular: {m} samples for {k} control points \
             (every knot span needs samples)"
        ))
    })?;
    Ok(chol.solve(&(a.transpose() * y)))
}

/// Replaces sampled values by their least-squares fit with the baseline's clamped cubic B-spline
/// ([`PerDimSplinePoses`]'s knots, `num_control_points` over `range`), independently per channel:
/// the projection behind the paper's "re-fit every 100 steps" for parameters that are not SE(3)
/// poses (e.g. the 2-D warps of the planar study). `values` is sample-major, `channels` per sample.
pub fn smooth_with_cubic_spline(
    range: TimeRange,
    num_control_points: usize,
    times_secs: &[f64],
    values: &mut [f64],
    channels: usize,
) -> Result<(), PoseFieldError> {
    let m = times_secs.len();
    if values.len() != m * channels {
        return Err(PoseFieldError::Shape {
            what: "spline samples",
            expected: m * channels,
            got: values.len(),
        });
    }
    check_times(&range, times_secs)?;
    let spline = PerDimSplinePoses::<f64>::new(range, num_control_points)?;
    let mut a = DMatrix::<f64>::zeros(m, num_control_points);
    let bases: Vec<_> = times_secs.iter().map(|&t| spline.basis(t)).collect();
    for (row, (first, basis)) in bases.iter().enumerate() {
        for o in 0..SUPPORT {
            a[(row, first + o)] = basis[0][o];
        }
    }
    let y = DMatrix::from_fn(m, channels, |r, c| values[r * channels + c]);
    let coeffs = solve_normal_equations(&a, &y)?;
    let fitted = a * coeffs;
    for r in 0..m {
        for c in 0..channels {
            values[r * channels + c] = fitted[(r, c)];
        }
    }
    Ok(())
}

/// The pose jet of the per-dimension spline from the 4 local control points `θ` and the basis.
fn per_dim_jet<D: Scalar>(theta: &[D; LOCAL], basis: &BasisJet) -> Jet<D> {
    let channel = |c: usize, order: usize| -> D {
        (0..SUPPORT).fold(D::zero(), |acc, o| {
            acc + theta[PER_CONTROL * o + c] * basis[order][o]
        })
    };
    let r: V3<Dual2<D>> =
        std::array::from_fn(|c| lie_dual::jet2(channel(c, 0), channel(c, 1), channel(c, 2)));
    Jet {
        q: rotation_from_rotvec_jet(&r),
        p: std::array::from_fn(|order| std::array::from_fn(|c| channel(3 + c, order))),
    }
}

/// `q, q̇, q̈` of `q = exp(r/2)` from `r, ṙ, r̈` (exact chain rule through [`Dual2`] numbers).
fn rotation_from_rotvec_jet<D: Scalar>(r: &V3<Dual2<D>>) -> [Quat<D>; 3] {
    Jet::quat_from_dual2(&lie_dual::exp_rotvec(r))
}

/// Width of the rotation Jacobian of the per-dimension spline: `(r, ṙ, r̈)` at `t`.
const ROT_JET: usize = 9;

impl<S: Real> PoseField<S> for PerDimSplinePoses<S> {
    fn time_range(&self) -> TimeRange {
        self.range
    }

    fn num_params(&self) -> usize {
        self.ctrl.len()
    }

    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S])) {
        visit(ParamKind::Pose, &self.ctrl);
    }

    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S])) {
        visit(ParamKind::Pose, &mut self.ctrl);
    }

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        out.reset(times_secs.len(), order);
        for (n, &t) in times_secs.iter().enumerate() {
            let (first, basis) = self.basis(t);
            let jet = per_dim_jet(&local_params(&self.ctrl, first), &basis);
            lie_dual::write_jet(out, n, &jet);
        }
        Ok(())
    }

    /// Stateless: recomputes each evaluation. The translation is linear in the control values
    /// (`∂p^{(d)}/∂p_k = N_k^{(d)}`); the rotation is differentiated by forward-mode AD with
    /// respect to the 9 values `(r, ṙ, r̈)` at `t` (`DualSVec64<9>`) and chained through
    /// `∂r^{(d)}/∂r_k = N_k^{(d)}`.
    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        grad.check_shape(times_secs.len(), grad.order)?;
        check_grad_len(param_grad.len(), self.ctrl.len())?;
        for (n, &t) in times_secs.iter().enumerate() {
            let (first, basis) = self.basis(t);
            let theta = local_params(&self.ctrl, first);
            let rjet: [f64; ROT_JET] = std::array::from_fn(|k| {
                let (order, c) = (k / 3, k % 3);
                (0..SUPPORT).fold(0.0, |acc, o| {
                    acc + theta[PER_CONTROL * o + c] * basis[order][o]
                })
            });
            let x: [DualSVec64<ROT_JET>; ROT_JET] = lie_dual::seed(&rjet);
            let r: V3<Dual2<DualSVec64<ROT_JET>>> =
                std::array::from_fn(|c| lie_dual::jet2(x[c], x[3 + c], x[6 + c]));
            let g_rot = lie_dual::pullback_rotation(&rotation_from_rotvec_jet(&r), grad, n);
            let g_p = lie_dual::translation_cotangent(grad, n);
            for o in 0..SUPPORT {
                let base = PER_CONTROL * (first + o);
                for c in 0..3 {
                    let (mut gr, mut gp) = (0.0, 0.0);
                    for order in 0..3 {
                        gr += basis[order][o] * g_rot[3 * order + c];
                        gp += basis[order][o] * g_p[order][c];
                    }
                    param_grad[base + c] += S::from_f64(gr);
                    param_grad[base + 3 + c] += S::from_f64(gp);
                }
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Cumulative cubic B-spline on SO(3)×R³.
// ---------------------------------------------------------------------------------------------

/// A uniform cumulative cubic B-spline on SO(3)×R³ (Kim et al. 1995 cumulative basis; Lovegrove
/// et al. 2013; derivatives as in Sommer et al. 2020, "Efficient Derivative Computation for
/// Cumulative B-Splines on Lie Groups"). In segment `s` with `u = (t − a)/Δt − s ∈ [0, 1]`:
///
/// `q(u) = q_s ⊗ Π_{j=1..3} exp(λ̃_j(u) φ_j / 2)`, `φ_j = log(q_{s+j−1}* ⊗ q_{s+j})`,
///
/// `p(u) = p_s + Σ_j λ̃_j(u) (p_{s+j} − p_{s+j−1})`,
///
/// `λ̃_1 = (5 + 3u − 3u² + u³)/6`, `λ̃_2 = (1 + 3u + 3u² − 2u³)/6`, `λ̃_3 = u³/6`.
///
/// Time derivatives by the product rule over the exp factors: for a fixed axis,
/// `d/dt exp(λφ/2) = exp(λφ/2) ⊗ (0, λ̇φ/2)` and
/// `d²/dt² exp(λφ/2) = exp(λφ/2) ⊗ (−λ̇²|φ|²/4, λ̈φ/2)`, with `λ̇ = (dλ/du)/Δt`.
///
/// **Layout**: `N ≥ 4` control poses ("knots" in basalt's and Sommer et al.'s usage) on a
/// uniform grid of spacing `Δt`; control pose `k` belongs to time `a + (k − 1)Δt`, so the grid
/// extends one spacing before `a` and one after `b`, and the `N − 3`
/// segments cover exactly `[a, b] = [a, a + (N − 3)Δt]`. At `t = b` the last segment is used
/// with `u = 1`. With control poses sampled from a trajectory at their times, constant poses and
/// constant velocities (and constant-rate rotations) are reproduced exactly.
///
/// Parameters: `6N` values of kind [`ParamKind::Pose`], control pose by control pose
/// `(r_k, p_k)`: the **absolute** rotation vector `r_k` of the control rotation `q_k =
/// exp(r_k/2)` (radians), then its translation; zero (identity) at construction. For
/// shortest-path interpolation consecutive `q_k` should lie in the same hemisphere, which
/// [`LieSplinePoses::from_trajectory`] ensures by unwrapping the rotation vectors; the field is
/// continuous (no sign flips, C² inside the range) whatever the parameters, because the log used
/// for `φ_j` inverts `exp` exactly (half angle in `[0, π]`).
#[derive(Clone, Debug)]
pub struct LieSplinePoses<S: Real = f32> {
    range: TimeRange,
    dt_secs: f64,
    ctrl: Vec<S>,
    /// Scratch of [`PoseField::backward`]: per-segment Jacobians, rebuilt on every call.
    segment_cache: Vec<Option<SegmentJacobian>>,
}

impl<S: Real> LieSplinePoses<S> {
    /// Identity control poses, `num_control_points ≥ 4` of them, covering `range` with
    /// `num_control_points − 3` uniform segments.
    pub fn with_num_knots(
        range: TimeRange,
        num_control_points: usize,
    ) -> Result<Self, PoseFieldError> {
        check_num_control_points(num_control_points)?;
        Ok(Self {
            range,
            dt_secs: range.duration_secs() / (num_control_points - DEGREE) as f64,
            ctrl: vec![S::ZERO; PER_CONTROL * num_control_points],
            segment_cache: Vec::new(),
        })
    }

    /// Identity control poses with `⌈duration / knot_spacing_secs⌉` segments (the spacing is
    /// rounded down so that an integer number of segments covers `range` exactly).
    pub fn with_knot_spacing(
        range: TimeRange,
        knot_spacing_secs: f64,
    ) -> Result<Self, PoseFieldError> {
        Self::with_num_knots(
            range,
            num_control_points_for_spacing(&range, knot_spacing_secs)?,
        )
    }

    /// Control poses initialised from `world_from_body` sampled at the control times
    /// [`LieSplinePoses::control_times_secs`] (which reach `Δt` before and after the range
    /// ends: the closure must accept them, e.g. by extrapolating or clamping), rotation vectors
    /// unwrapped to be continuous.
    pub fn from_trajectory(
        range: TimeRange,
        num_control_points: usize,
        world_from_body: impl Fn(f64) -> Isometry3<f64>,
    ) -> Result<Self, PoseFieldError> {
        let mut s = Self::with_num_knots(range, num_control_points)?;
        let poses: Vec<_> = s
            .control_times_secs()
            .into_iter()
            .map(world_from_body)
            .collect();
        let rotations: Vec<_> = poses.iter().map(|p| p.rotation).collect();
        let rotvecs = unwrap_rotation_vectors(&rotations);
        for (k, pose) in poses.iter().enumerate() {
            set_control(&mut s.ctrl, k, &rotvecs[k], &pose.translation.vector);
        }
        Ok(s)
    }

    /// Number of control poses `N`.
    pub fn num_control_points(&self) -> usize {
        self.ctrl.len() / PER_CONTROL
    }

    /// Spacing of the control poses `Δt`, seconds.
    pub fn knot_spacing_secs(&self) -> f64 {
        self.dt_secs
    }

    /// The time of control pose `k`, `a + (k − 1)Δt`, for every `k`.
    pub fn control_times_secs(&self) -> Vec<f64> {
        (0..self.num_control_points())
            .map(|k| self.range.start_secs + (k as f64 - 1.0) * self.dt_secs)
            .collect()
    }

    /// Segment `s ∈ [0, N − 4]` and `u ∈ [0, 1]` of time `t`.
    fn segment(&self, t: f64) -> (usize, f64) {
        let x = (t - self.range.start_secs) / self.dt_secs;
        let last = self.num_control_points() - SUPPORT;
        let s = (x.floor().max(0.0) as usize).min(last);
        (s, (x - s as f64).clamp(0.0, 1.0))
    }
}

/// Cumulative basis `λ̃_j(u)`, j = 1..3, and its first and second time derivatives
/// (`[order][j − 1]`), with `du/dt = 1/Δt`.
fn cumulative_basis(u: f64, inv_dt: f64) -> [[f64; 3]; 3] {
    let (u2, u3) = (u * u, u * u * u);
    let d1 = inv_dt;
    let d2 = inv_dt * inv_dt;
    [
        [
            (5.0 + 3.0 * u - 3.0 * u2 + u3) / 6.0,
            (1.0 + 3.0 * u + 3.0 * u2 - 2.0 * u3) / 6.0,
            u3 / 6.0,
        ],
        [
            d1 * (3.0 - 6.0 * u + 3.0 * u2) / 6.0,
            d1 * (3.0 + 6.0 * u - 6.0 * u2) / 6.0,
            d1 * 0.5 * u2,
        ],
        [d2 * (u - 1.0), d2 * (1.0 - 2.0 * u), d2 * u],
    ]
}

/// The per-segment quantities of the cumulative spline's rotation: `q_0 = exp(r_0/2)` and
/// `φ_j = log(q_{j−1}* ⊗ q_j)`, j = 1..3, from the rotation vectors of the 4 local controls.
fn lie_segment<D: Scalar>(r: &[V3<D>; SUPPORT]) -> (Quat<D>, [V3<D>; 3]) {
    let q: [Quat<D>; SUPPORT] = std::array::from_fn(|k| lie_dual::exp_rotvec(&r[k]));
    let phi = std::array::from_fn(|j| lie_dual::log_rotvec(&q[j].conj().mul(&q[j + 1])));
    (q[0], phi)
}

/// `R, Ṙ, R̈` of the relative rotation `R(u) = Π_{j=1..3} exp(λ̃_j(u) φ_j / 2)`, so that
/// `q^{(d)} = q_0 ⊗ R^{(d)}` (product rule over the exp factors, see [`LieSplinePoses`]).
fn lie_relative<D: Scalar>(phi: &[V3<D>; 3], lambda: &[[f64; 3]; 3]) -> [Quat<D>; 3] {
    let zero = Quat::pure([D::zero(); 3]);
    // (A, Ȧ, Ä) starts at the identity and is multiplied by each factor (E, Ė, Ë):
    // (AE)' = ȦE + AĖ, (AE)'' = ÄE + 2ȦĖ + AË.
    let mut acc = [Quat::identity(), zero, zero];
    for j in 0..3 {
        let (l, ld, ldd) = (lambda[0][j], lambda[1][j], lambda[2][j]);
        // E = exp(λφ/2), Ė = E ⊗ (0, λ̇φ/2), Ë = E ⊗ (−λ̇²|φ/2|², λ̈φ/2) (E commutes with φ).
        let e = lie_dual::exp_rotvec(&lie_dual::scale3(&phi[j], D::from(l)));
        let half_phi = lie_dual::scale3(&phi[j], D::from(0.5));
        let e1 = e.mul(&Quat::pure(lie_dual::scale3(&half_phi, D::from(ld))));
        let e2 = e.mul(&Quat::from_parts(
            -lie_dual::dot(&half_phi, &half_phi) * (ld * ld),
            lie_dual::scale3(&half_phi, D::from(ldd)),
        ));
        let [a0, a1, a2] = acc;
        acc = [
            a0.mul(&e),
            a1.mul(&e).add(&a0.mul(&e1)),
            a2.mul(&e)
                .add(&a1.mul(&e1).scale(D::from(2.0)))
                .add(&a0.mul(&e2)),
        ];
    }
    acc
}

/// Inputs of the per-time rotation: `q_0` (4 components `w, x, y, z`) then `φ_1, φ_2, φ_3`.
const SEG_OUT: usize = 4 + 9;

/// `∂(q_0, φ_1..3)/∂(r_0..r_3)`, `SEG_OUT × 12`, row-major, with the values `(q_0, φ)`.
#[derive(Clone, Copy, Debug)]
struct SegmentJacobian {
    q0: Quaternion<f64>,
    phi: [V3<f64>; 3],
    d_in_d_r: [[f64; ROT_LOCAL]; SEG_OUT],
}

impl SegmentJacobian {
    fn new(theta: &[f64; LOCAL]) -> Self {
        let rot: [f64; ROT_LOCAL] = std::array::from_fn(|k| local_vec(theta, k / 3, 0)[k % 3]);
        let x: [DualSVec64<ROT_LOCAL>; ROT_LOCAL] = lie_dual::seed(&rot);
        let r = std::array::from_fn(|k| [x[3 * k], x[3 * k + 1], x[3 * k + 2]]);
        let (q0, phi) = lie_segment(&r);
        let outs = [
            q0.w, q0.x, q0.y, q0.z, phi[0][0], phi[0][1], phi[0][2], phi[1][0], phi[1][1],
            phi[1][2], phi[2][0], phi[2][1], phi[2][2],
        ];
        let d_in_d_r = std::array::from_fn(|o| {
            let e = outs[o]
                .eps
                .unwrap_generic(nalgebra::Const::<ROT_LOCAL>, nalgebra::U1);
            std::array::from_fn(|k| e[k])
        });
        Self {
            q0: Quaternion::new(q0.w.re, q0.x.re, q0.y.re, q0.z.re),
            phi: std::array::from_fn(|j| std::array::from_fn(|a| phi[j][a].re)),
            d_in_d_r,
        }
    }

    /// `∂L/∂r` (12) from the rotation cotangents `c_d` of `q^{(d)} = q_0 ⊗ R^{(d)}` at one time:
    /// `∂L/∂q_0 = Σ_d c_d ⊗ R^{(d)}*`, `∂L/∂R^{(d)} = q_0* ⊗ c_d`, the latter pulled back to `φ`
    /// by forward-mode AD (`DualSVec64<9>`), then both through `∂(q_0, φ)/∂r`.
    fn pullback(&self, lambda: &[[f64; 3]; 3], c: &[Quaternion<f64>; 3]) -> [f64; ROT_LOCAL] {
        let x: [DualSVec64<9>; 9] =
            lie_dual::seed(&std::array::from_fn(|k| self.phi[k / 3][k % 3]));
        let phi = std::array::from_fn(|j| [x[3 * j], x[3 * j + 1], x[3 * j + 2]]);
        let rel = lie_relative(&phi, lambda);
        let rel_re: [Quaternion<f64>; 3] = std::array::from_fn(|d| {
            Quaternion::new(rel[d].w.re, rel[d].x.re, rel[d].y.re, rel[d].z.re)
        });
        let c_rel: [Quaternion<f64>; 3] = std::array::from_fn(|d| self.q0.conjugate() * c[d]);
        let g_phi = lie_dual::pullback_quats(&rel, &c_rel);
        let g_q0 = (0..3).fold(Quaternion::new(0.0, 0.0, 0.0, 0.0), |acc, d| {
            acc + c[d] * rel_re[d].conjugate()
        });
        let g_in: [f64; SEG_OUT] = std::array::from_fn(|o| match o {
            0 => g_q0.w,
            1 => g_q0.i,
            2 => g_q0.j,
            3 => g_q0.k,
            _ => g_phi[o - 4],
        });
        std::array::from_fn(|k| (0..SEG_OUT).map(|o| self.d_in_d_r[o][k] * g_in[o]).sum())
    }
}

/// Weights `w[d][k]` of the local control translations in `p^{(d)}`:
/// `p = p_0 + Σ_j λ̃_j (p_j − p_{j−1}) = Σ_k (λ̃_k − λ̃_{k+1}) p_k` with `λ̃_0 = 1`, `λ̃_4 = 0`
/// (and `λ̃_0` contributes nothing to the derivatives).
fn translation_weights(lambda: &[[f64; 3]; 3]) -> [[f64; SUPPORT]; 3] {
    std::array::from_fn(|d| {
        let l = |k: usize| match k {
            0 if d == 0 => 1.0,
            1..=3 => lambda[d][k - 1],
            _ => 0.0,
        };
        std::array::from_fn(|k| l(k) - l(k + 1))
    })
}

impl<S: Real> PoseField<S> for LieSplinePoses<S> {
    fn time_range(&self) -> TimeRange {
        self.range
    }

    fn num_params(&self) -> usize {
        self.ctrl.len()
    }

    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S])) {
        visit(ParamKind::Pose, &self.ctrl);
    }

    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S])) {
        visit(ParamKind::Pose, &mut self.ctrl);
    }

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        out.reset(times_secs.len(), order);
        let inv_dt = 1.0 / self.dt_secs;
        for (n, &t) in times_secs.iter().enumerate() {
            let (s, u) = self.segment(t);
            let lambda = cumulative_basis(u, inv_dt);
            let theta = local_params(&self.ctrl, s);
            let r = std::array::from_fn(|k| local_vec(&theta, k, 0));
            let w = translation_weights(&lambda);
            let p = std::array::from_fn(|d| {
                std::array::from_fn(|a| {
                    (0..SUPPORT).fold(0.0, |acc, k| acc + w[d][k] * local_vec(&theta, k, 3)[a])
                })
            });
            let (q0, phi) = lie_segment(&r);
            let rel = lie_relative(&phi, &lambda);
            let jet = Jet {
                q: std::array::from_fn(|d| q0.mul(&rel[d])),
                p,
            };
            lie_dual::write_jet(out, n, &jet);
        }
        Ok(())
    }

    /// Recomputes each evaluation (no state from `forward`). The rotation is differentiated in
    /// two stages: per segment (cached for the call) `∂(q_0, φ)/∂r` by forward-mode AD over the
    /// 12 local rotation-vector values, per time `∂q/∂(q_0, φ)` (see `SegmentJacobian`); the
    /// translation is linear in the control translations (`translation_weights`).
    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        grad.check_shape(times_secs.len(), grad.order)?;
        check_grad_len(param_grad.len(), self.ctrl.len())?;
        let inv_dt = 1.0 / self.dt_secs;
        let mut cache = std::mem::take(&mut self.segment_cache);
        cache.clear();
        cache.resize(self.num_control_points() - DEGREE, None);
        for (n, &t) in times_secs.iter().enumerate() {
            let (s, u) = self.segment(t);
            let lambda = cumulative_basis(u, inv_dt);
            let seg =
                cache[s].get_or_insert_with(|| SegmentJacobian::new(&local_params(&self.ctrl, s)));
            let g_rot = seg.pullback(&lambda, &lie_dual::rotation_cotangent(grad, n));
            let g_p = lie_dual::translation_cotangent(grad, n);
            let w = translation_weights(&lambda);
            for k in 0..SUPPORT {
                let base = PER_CONTROL * (s + k);
                for a in 0..3 {
                    param_grad[base + a] += S::from_f64(g_rot[3 * k + a]);
                    let gp = (0..3).fold(0.0, |acc, d| acc + w[d][k] * g_p[d][a]);
                    param_grad[base + 3 + a] += S::from_f64(gp);
                }
            }
        }
        self.segment_cache = cache;
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// One type for the registry.
// ---------------------------------------------------------------------------------------------

/// Either spline, as built by [`SplineConfig::init`]; delegates every [`PoseField`] method.
#[derive(Clone, Debug)]
pub enum SplinePoses<S: Real = f32> {
    /// The paper's baseline: a cubic B-spline per dimension of `(r, p)`.
    PerDimension(PerDimSplinePoses<S>),
    /// The cumulative cubic B-spline on SO(3)×R³.
    Lie(LieSplinePoses<S>),
}

impl<S: Real> SplinePoses<S> {
    fn inner(&self) -> &dyn PoseField<S> {
        match self {
            Self::PerDimension(s) => s,
            Self::Lie(s) => s,
        }
    }

    fn inner_mut(&mut self) -> &mut dyn PoseField<S> {
        match self {
            Self::PerDimension(s) => s,
            Self::Lie(s) => s,
        }
    }
}

impl<S: Real> PoseField<S> for SplinePoses<S> {
    fn time_range(&self) -> TimeRange {
        self.inner().time_range()
    }

    fn num_params(&self) -> usize {
        self.inner().num_params()
    }

    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S])) {
        self.inner().params(visit);
    }

    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S])) {
        self.inner_mut().params_mut(visit);
    }

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        self.inner().evaluate(times_secs, order, out)
    }

    fn forward(
        &mut self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        self.inner_mut().forward(times_secs, order, out)
    }

    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        self.inner_mut().backward(times_secs, grad, param_grad)
    }
}

/// Which spline a [`SplineConfig`] builds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum SplineKind {
    /// `"per_dimension"`: the paper's baseline, [`PerDimSplinePoses`].
    #[default]
    #[serde(rename = "per_dimension")]
    PerDimension,
    /// `"lie"`: the cumulative cubic B-spline on SO(3)×R³, [`LieSplinePoses`].
    #[serde(rename = "lie")]
    Lie,
}

/// Configuration of a spline pose field for the pose-field registry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SplineConfig {
    /// `"per_dimension"` (default; the paper's B-spline baseline) or `"lie"` (cumulative cubic
    /// B-spline on SO(3)×R³).
    pub kind: SplineKind,
    /// Number of control points, at least 4. Default 5 (the paper's planar experiment: "5 knots,
    /// degree 3", read as 5 control points; the paper does not say which). Ignored when
    /// `knot_spacing_secs` is set.
    pub control_points: usize,
    /// Knot spacing in seconds; when set, the spline gets `⌈duration / knot_spacing_secs⌉ + 3`
    /// control points instead of `control_points`. Default unset.
    pub knot_spacing_secs: Option<f64>,
}

impl Default for SplineConfig {
    fn default() -> Self {
        Self {
            kind: SplineKind::PerDimension,
            control_points: 5,
            knot_spacing_secs: None,
        }
    }
}

impl SplineConfig {
    /// An identity spline over `range` (validates the number of control points or the knot
    /// spacing). `frame_times_secs` is not used: the knots are uniform over `range`.
    pub fn init<S: Real>(
        &self,
        range: TimeRange,
        _frame_times_secs: &[f64],
    ) -> Result<SplinePoses<S>, PoseFieldError> {
        let k = match self.knot_spacing_secs {
            Some(spacing) => num_control_points_for_spacing(&range, spacing)?,
            None => self.control_points,
        };
        Ok(match self.kind {
            SplineKind::PerDimension => {
                SplinePoses::PerDimension(PerDimSplinePoses::new(range, k)?)
            }
            SplineKind::Lie => SplinePoses::Lie(LieSplinePoses::with_num_knots(range, k)?),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose_field::params_from_slice;
    use crate::testing::{check_f32_matches_f64, check_pose_field};
    use nalgebra::Translation3;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn range() -> TimeRange {
        TimeRange::new(0.5, 3.5).unwrap()
    }

    fn randomize<S: Real>(field: &mut dyn PoseField<S>, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let p: Vec<S> = (0..field.num_params())
            .map(|_| S::from_f64(rng.random_range(-0.8..0.8)))
            .collect();
        params_from_slice(field, &p).unwrap();
    }

    /// Times over the range, including both ends and points near knots but not on interior
    /// knots, where q⃛ jumps and the suite's central difference of q̇ has an O(h) error
    /// (continuity across knots is checked by `both_splines_are_c2_across_knots`).
    fn test_times() -> Vec<f64> {
        vec![
            0.5, 0.61, 0.97, 1.27, 1.48, 1.83, 2.03, 2.41, 2.77, 3.2, 3.49, 3.5,
        ]
    }

    fn eval(field: &dyn PoseField<f64>, times: &[f64]) -> PoseBatch {
        let mut out = PoseBatch::default();
        field
            .evaluate(times, Order::Acceleration, &mut out)
            .unwrap();
        out
    }

    /// The smoothing projection reproduces any cubic exactly, interpolates when there are as
    /// many samples as control points, and otherwise shrinks the residual of off-spline data.
    #[test]
    fn smoothing_projects_onto_the_spline_space() {
        let r = range();
        let times: Vec<f64> = (0..7).map(|i| 0.5 + 3.0 * i as f64 / 6.0).collect();
        let cubic = |t: f64| [1.0 - 0.3 * t + 0.2 * t * t - 0.05 * t * t * t, 2.0 * t];
        let mut v: Vec<f64> = times.iter().flat_map(|&t| cubic(t)).collect();
        let want = v.clone();
        smooth_with_cubic_spline(r, 5, &times, &mut v, 2).unwrap();
        for (a, b) in v.iter().zip(&want) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        let zigzag: Vec<f64> = (0..7)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let mut exact = zigzag.clone();
        smooth_with_cubic_spline(r, 7, &times, &mut exact, 1).unwrap();
        for (a, b) in exact.iter().zip(&zigzag) {
            assert!(
                (a - b).abs() < 1e-9,
                "7 control points interpolate 7 samples"
            );
        }
        let mut smooth = zigzag.clone();
        smooth_with_cubic_spline(r, 5, &times, &mut smooth, 1).unwrap();
        let energy = |x: &[f64]| x.iter().map(|v| v * v).sum::<f64>();
        assert!(energy(&smooth) < 0.8 * energy(&zigzag));
        assert!(smooth_with_cubic_spline(r, 5, &times, &mut smooth, 2).is_err());
        assert!(smooth_with_cubic_spline(r, 8, &times[..3], &mut smooth[..3], 1).is_err());
    }

    /// Asserts `q, q̇, q̈, p, ṗ, p̈` agree just before and just after each of `times`.
    fn assert_c2_at(field: &dyn PoseField<f64>, times: &[f64]) {
        let eps = 1e-9;
        for &t in times {
            let e = eval(field, &[t - eps, t + eps]);
            let close = |a: f64, tol: f64| assert!(a < tol, "jump {a:.3e} at t = {t}");
            close((e.rotation[0] - e.rotation[1]).norm(), 1e-7);
            close((e.translation[0] - e.translation[1]).norm(), 1e-7);
            close((e.rotation_rate[0] - e.rotation_rate[1]).norm(), 1e-6);
            close((e.lin_vel_world[0] - e.lin_vel_world[1]).norm(), 1e-6);
            close((e.rotation_acc[0] - e.rotation_acc[1]).norm(), 1e-5);
            close((e.lin_acc_world[0] - e.lin_acc_world[1]).norm(), 1e-5);
        }
    }

    /// A smooth test trajectory whose rotation passes beyond π about z.
    fn smooth_pose(t: f64) -> Isometry3<f64> {
        let r = Vector3::new(0.3 * t.sin(), 0.2 * (0.7 * t).cos(), 1.5 * t);
        let p = Vector3::new(t.sin(), 0.5 * (2.0 * t).cos(), 0.3 * t);
        Isometry3::from_parts(Translation3::from(p), UnitQuaternion::from_scaled_axis(r))
    }

    #[test]
    fn clamped_basis_is_a_partition_of_unity() {
        let s = PerDimSplinePoses::<f64>::new(range(), 7).unwrap();
        assert_eq!(s.knots_secs().len(), 11);
        assert_eq!(s.knots_secs()[..4], [0.5; 4]);
        assert_eq!(s.knots_secs()[7..], [3.5; 4]);
        for t in [0.5, 0.9, 1.25, 2.0, 3.4999, 3.5] {
            let (first, b) = s.basis(t);
            assert!(first + SUPPORT <= 7);
            assert!((b[0].iter().sum::<f64>() - 1.0).abs() < 1e-14, "t = {t}");
            assert!(b[1].iter().sum::<f64>().abs() < 1e-12);
            assert!(b[2].iter().sum::<f64>().abs() < 1e-10);
        }
        // Clamped: the ends interpolate the first and last control points.
        assert_eq!(s.basis(0.5).1[0], [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(s.basis(3.5).1[0][3], 1.0);
    }

    #[test]
    fn per_dimension_spline_passes_the_conformance_suite() {
        for k in [4, 5, 9] {
            let mut s = PerDimSplinePoses::<f64>::new(range(), k).unwrap();
            check_pose_field(&mut s, &test_times());
            randomize(&mut s, k as u64);
            check_pose_field(&mut s, &test_times());
        }
    }

    #[test]
    fn lie_spline_passes_the_conformance_suite() {
        for n in [4, 6, 9] {
            let mut s = LieSplinePoses::<f64>::with_num_knots(range(), n).unwrap();
            check_pose_field(&mut s, &test_times());
            randomize(&mut s, 10 + n as u64);
            check_pose_field(&mut s, &test_times());
        }
        let mut s = LieSplinePoses::<f64>::from_trajectory(
            TimeRange::new(0.0, 4.0).unwrap(),
            10,
            smooth_pose,
        )
        .unwrap();
        check_pose_field(&mut s, &[0.0, 0.3, 1.7, 2.2, 3.9, 4.0]);
    }

    #[test]
    fn registry_enum_passes_the_conformance_suite() {
        for kind in [SplineKind::PerDimension, SplineKind::Lie] {
            let cfg = SplineConfig {
                kind,
                ..SplineConfig::default()
            };
            let mut s = cfg.init::<f64>(range(), &[]).unwrap();
            randomize(&mut s, 21);
            check_pose_field(&mut s, &test_times());
        }
    }

    #[test]
    fn both_splines_are_c2_across_knots() {
        let mut a = PerDimSplinePoses::<f64>::new(range(), 8).unwrap();
        randomize(&mut a, 3);
        let interior = a.knots_secs()[4..8].to_vec();
        assert_c2_at(&a, &interior);
        let mut b = LieSplinePoses::<f64>::with_num_knots(range(), 8).unwrap();
        randomize(&mut b, 4);
        let knots: Vec<f64> = (1..5)
            .map(|k| 0.5 + k as f64 * b.knot_spacing_secs())
            .collect();
        assert_c2_at(&b, &knots);
    }

    #[test]
    fn constant_pose_and_constant_velocity_are_reproduced_exactly() {
        let rot = UnitQuaternion::from_scaled_axis(Vector3::new(0.4, -1.1, 2.0));
        let (p0, v) = (Vector3::new(1.0, -2.0, 0.5), Vector3::new(0.3, 0.7, -0.2));
        let pose = |t: f64| Isometry3::from_parts(Translation3::from(p0 + v * t), rot);
        let times = test_times();
        let lie = LieSplinePoses::<f64>::from_trajectory(range(), 7, pose).unwrap();
        let samples: Vec<f64> = (0..40).map(|k| 0.5 + 3.0 * k as f64 / 39.0).collect();
        let poses: Vec<_> = samples.iter().map(|&t| pose(t)).collect();
        let per_dim = PerDimSplinePoses::<f64>::from_samples(range(), 6, &samples, &poses).unwrap();
        for field in [&lie as &dyn PoseField<f64>, &per_dim] {
            let e = eval(field, &times);
            for (i, &t) in times.iter().enumerate() {
                let q = UnitQuaternion::new_normalize(e.rotation[i]);
                assert!(q.angle_to(&rot) < 1e-9, "t = {t}");
                assert!((e.translation[i] - (p0 + v * t)).norm() < 1e-9, "t = {t}");
                assert!(e.rotation_rate[i].norm() < 1e-9);
                assert!(e.rotation_acc[i].norm() < 1e-9);
                assert!((e.lin_vel_world[i] - v).norm() < 1e-9);
                assert!(e.lin_acc_world[i].norm() < 1e-9);
            }
        }
    }

    #[test]
    fn lie_spline_constant_rate_rotation_has_constant_body_angular_velocity() {
        let axis = Vector3::new(1.0, 2.0, -2.0).normalize();
        let alpha = 0.9; // radians between consecutive control rotations (> π in total)
        let mut s = LieSplinePoses::<f64>::with_num_knots(range(), 7).unwrap();
        let mut ctrl = vec![0.0; s.num_params()];
        for k in 0..7 {
            for a in 0..3 {
                ctrl[6 * k + a] = axis[a] * alpha * k as f64;
            }
        }
        params_from_slice(&mut s, &ctrl).unwrap();
        let rate = alpha / s.knot_spacing_secs();
        let times = test_times();
        let e = eval(&s, &times);
        for (i, &t) in times.iter().enumerate() {
            assert!((e.ang_vel_body(i) - axis * rate).norm() < 1e-12, "t = {t}");
            assert!(e.ang_acc_body(i).norm() < 1e-12);
            // Control k belongs to time a + (k − 1)Δt, so the angle is α((t − a)/Δt + 1).
            let angle = alpha * ((t - 0.5) / s.knot_spacing_secs() + 1.0);
            // Sign included: exp(angle·axis/2) with angles beyond π (no hemisphere flips).
            let want =
                nalgebra::Quaternion::from_parts((0.5 * angle).cos(), axis * (0.5 * angle).sin());
            assert!((e.rotation[i] - want).norm() < 1e-12, "t = {t}");
        }
    }

    #[test]
    fn least_squares_fit_recovers_a_smooth_trajectory() {
        let r = TimeRange::new(0.0, 4.0).unwrap();
        let samples: Vec<f64> = (0..200).map(|k| 4.0 * k as f64 / 199.0).collect();
        let poses: Vec<_> = samples.iter().map(|&t| smooth_pose(t)).collect();
        let s = PerDimSplinePoses::<f64>::from_samples(r, 16, &samples, &poses).unwrap();
        let check: Vec<f64> = (0..57).map(|k| 4.0 * k as f64 / 56.0).collect();
        let e = eval(&s, &check);
        for (i, &t) in check.iter().enumerate() {
            let want = smooth_pose(t);
            let got = e.world_from_body(i);
            assert!(got.rotation.angle_to(&want.rotation) < 2e-3, "t = {t}");
            assert!(
                (got.translation.vector - want.translation.vector).norm() < 2e-3,
                "t = {t}"
            );
        }
        // Re-fitting in place (the baseline's "every 100 steps") overwrites the controls.
        let mut s2 = PerDimSplinePoses::<f64>::new(r, 16).unwrap();
        s2.fit(&samples, &poses).unwrap();
        assert_eq!(
            crate::pose_field::params_to_vec(&s2),
            crate::pose_field::params_to_vec(&s)
        );
    }

    #[test]
    fn barf_with_bspline_refit_round_trip() {
        // The baseline's reset: per-frame poses → least-squares spline → per-frame poses again.
        let r = TimeRange::new(0.0, 2.0).unwrap();
        let frames: Vec<f64> = (0..21).map(|k| 0.1 * k as f64).collect();
        let noisy: Vec<_> = frames
            .iter()
            .enumerate()
            .map(|(k, &t)| {
                let wiggle = if k % 2 == 0 { 1e-3 } else { -1e-3 };
                Isometry3::from_parts(
                    Translation3::new(t + wiggle, 0.5 * t, 0.0),
                    UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.4 * t + wiggle)),
                )
            })
            .collect();
        let mut discrete = crate::DiscretePoses::<f32>::from_poses(&frames, &noisy).unwrap();
        let mut poses_now = PoseBatch::default();
        discrete
            .evaluate(&frames, Order::Pose, &mut poses_now)
            .unwrap();
        let poses: Vec<_> = (0..frames.len())
            .map(|i| poses_now.world_from_body(i))
            .collect();
        let spline = PerDimSplinePoses::<f64>::from_samples(r, 5, &frames, &poses).unwrap();
        let mut smooth = PoseBatch::default();
        spline.evaluate(&frames, Order::Pose, &mut smooth).unwrap();
        let smooth: Vec<_> = (0..frames.len())
            .map(|i| smooth.world_from_body(i))
            .collect();
        discrete.set_poses(&smooth).unwrap();
        discrete
            .evaluate(&frames, Order::Pose, &mut poses_now)
            .unwrap();
        for (i, &t) in frames.iter().enumerate() {
            let got = poses_now.world_from_body(i);
            // The alternating wiggle is smoothed away (up to f32 storage).
            assert!((got.translation.vector - Vector3::new(t, 0.5 * t, 0.0)).norm() < 8e-4);
            assert!((got.rotation.angle() - 0.4 * t).abs() < 8e-4, "t = {t}");
        }
    }

    #[test]
    fn rotation_vectors_are_unwrapped() {
        let rots: Vec<_> = (0..20)
            .map(|k| UnitQuaternion::from_scaled_axis(Vector3::z() * (0.5 * k as f64)))
            .collect();
        let r = unwrap_rotation_vectors(&rots);
        for k in 0..20 {
            assert!(
                (r[k] - Vector3::z() * (0.5 * k as f64)).norm() < 1e-9,
                "{k}: {}",
                r[k]
            );
        }
    }

    #[test]
    fn f32_matches_f64() {
        let times = test_times();
        let mut a32 = PerDimSplinePoses::<f32>::new(range(), 6).unwrap();
        let mut a64 = PerDimSplinePoses::<f64>::new(range(), 6).unwrap();
        randomize(&mut a32, 5);
        randomize(&mut a64, 5);
        check_f32_matches_f64(&a32, &a64, &times, 1e-4);
        let mut b32 = LieSplinePoses::<f32>::with_num_knots(range(), 6).unwrap();
        let mut b64 = LieSplinePoses::<f64>::with_num_knots(range(), 6).unwrap();
        randomize(&mut b32, 6);
        randomize(&mut b64, 6);
        check_f32_matches_f64(&b32, &b64, &times, 1e-4);
    }

    #[test]
    fn bad_construction_is_an_error() {
        let invalid = |r: Result<(), PoseFieldError>| {
            assert!(matches!(r, Err(PoseFieldError::Invalid(_))), "{r:?}")
        };
        invalid(PerDimSplinePoses::<f64>::new(range(), 3).map(|_| ()));
        invalid(LieSplinePoses::<f64>::with_num_knots(range(), 3).map(|_| ()));
        invalid(LieSplinePoses::<f64>::with_knot_spacing(range(), 0.0).map(|_| ()));
        invalid(PerDimSplinePoses::<f64>::with_knot_spacing(range(), f64::NAN).map(|_| ()));
        // Sizes are refused before anything is allocated.
        invalid(LieSplinePoses::<f64>::with_knot_spacing(range(), 1e-12).map(|_| ()));
        invalid(PerDimSplinePoses::<f64>::new(range(), usize::MAX).map(|_| ()));
        // Fewer samples than control points: singular normal equations.
        let poses = [Isometry3::identity(); 3];
        invalid(
            PerDimSplinePoses::<f64>::from_samples(range(), 5, &[0.5, 1.0, 2.0], &poses)
                .map(|_| ()),
        );
        assert!(matches!(
            PerDimSplinePoses::<f64>::from_samples(range(), 5, &[0.5, 1.0], &poses),
            Err(PoseFieldError::Shape { .. })
        ));
        assert!(matches!(
            PerDimSplinePoses::<f64>::from_samples(range(), 5, &[0.5, 1.0, 9.0], &poses),
            Err(PoseFieldError::OutOfRange { .. })
        ));
    }

    #[test]
    fn backward_checks_buffer_lengths() {
        let mut s = LieSplinePoses::<f64>::with_num_knots(range(), 5).unwrap();
        let mut out = PoseBatch::default();
        s.forward(&[1.0], Order::Velocity, &mut out).unwrap();
        let g = PoseBatch::zeros(1, Order::Velocity);
        let mut short = vec![0.0; 7];
        assert!(matches!(
            s.backward(&[1.0], &g, &mut short),
            Err(PoseFieldError::Shape { .. })
        ));
        let mut grad = vec![0.0; s.num_params()];
        assert!(matches!(
            s.backward(&[1.0, 2.0], &g, &mut grad),
            Err(PoseFieldError::Shape { .. })
        ));
    }

    #[test]
    fn knot_spacing_sets_the_number_of_control_points() {
        // 3 s at 1 s spacing: 3 segments, 6 control points; 0.7 s: ⌈4.29⌉ = 5 segments.
        let a = LieSplinePoses::<f64>::with_knot_spacing(range(), 1.0).unwrap();
        assert_eq!(a.num_control_points(), 6);
        assert_eq!(a.knot_spacing_secs(), 1.0);
        assert_eq!(a.control_times_secs()[0], -0.5);
        let b = PerDimSplinePoses::<f64>::with_knot_spacing(range(), 0.7).unwrap();
        assert_eq!(b.num_control_points(), 8);
    }

    #[test]
    fn config_spellings_defaults_and_typos() {
        let parse = |s: &str| toml::from_str::<SplineConfig>(s);
        assert_eq!(parse("").unwrap(), SplineConfig::default());
        assert_eq!(SplineConfig::default().control_points, 5);
        assert_eq!(
            parse(r#"kind = "per_dimension""#).unwrap().kind,
            SplineKind::PerDimension
        );
        assert_eq!(parse(r#"kind = "lie""#).unwrap().kind, SplineKind::Lie);
        for bad in [r#"kind = "Lie""#, r#"kind = "per-dimension""#, "knots = 5"] {
            assert!(parse(bad).is_err(), "{bad} must be rejected");
        }
        let cfg = parse("kind = \"lie\"\nknot_spacing_secs = 0.5").unwrap();
        match cfg.init::<f32>(range(), &[]).unwrap() {
            SplinePoses::Lie(s) => assert_eq!(s.num_control_points(), 9),
            SplinePoses::PerDimension(_) => panic!("expected the Lie spline"),
        }
        let cfg = parse("control_points = 3").unwrap();
        assert!(matches!(
            cfg.init::<f32>(range(), &[]),
            Err(PoseFieldError::Invalid(_))
        ));
    }
}
