//! The conformance suite every [`PoseField`] implementation passes, and [`TempDir`] for tests
//! that write files (enable the `testing` feature to use them from another crate's tests).
//!
//! [`check_pose_field`] asserts, on a field with `f64` parameters:
//! 1. queries outside [`PoseField::time_range`] are errors; `evaluate` and `forward` agree and
//!    fill every output up to the requested order;
//! 2. `q` is a unit quaternion and `q̇` is tangent to the unit sphere (`q·q̇ = 0`);
//! 3. `q̇, q̈, ṗ, p̈` match central differences of the evaluated outputs in time;
//! 4. continuity: over a dense sweep of the range, no step of `q` or `p` is larger than the
//!    local derivative allows (this catches sign flips of `q` and jumps at segment ends);
//! 5. parameter gradients of linear losses on the pose, on the first and on the second
//!    derivatives (separately and together) match central differences in the parameters, and
//!    `backward` accumulates rather than overwrites.
//!
//! Central differences use `h = 1e-4 · duration` in time (truncation `O(h²)`) and
//! `h = 1e-6 · max(1, |θ|)` in the parameters; tolerances are relative to the magnitude of the
//! compared quantities over the batch, see [`Tolerances`].

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::pose_field::{params_from_slice, params_to_vec};
use crate::{Order, PoseBatch, PoseField, PoseFieldError};

/// Tolerances of [`check_pose_field_with`].
#[derive(Clone, Copy, Debug)]
pub struct Tolerances {
    /// Relative tolerance of time derivatives against central differences, relative to the
    /// largest magnitude of that derivative over the batch.
    pub time_derivative: f64,
    /// Relative tolerance of parameter gradients against central differences, relative to the
    /// largest magnitude of the gradient entries checked.
    pub param_gradient: f64,
    /// At most this many parameters are checked by finite differences (chosen at random).
    pub max_params_checked: usize,
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            time_derivative: 1e-5,
            param_gradient: 1e-5,
            max_params_checked: 48,
        }
    }
}

/// Runs the whole suite with default [`Tolerances`]. `times_secs` must lie inside the range and
/// away from points where the field is not twice differentiable (e.g. the frame times of
/// piecewise-linear interpolation). Panics with a description of the first failure.
pub fn check_pose_field(field: &mut dyn PoseField<f64>, times_secs: &[f64]) {
    check_pose_field_with(field, times_secs, &Tolerances::default());
}

/// [`check_pose_field`] with explicit tolerances.
pub fn check_pose_field_with(field: &mut dyn PoseField<f64>, times_secs: &[f64], tol: &Tolerances) {
    assert!(!times_secs.is_empty(), "the suite needs at least one time");
    check_range_and_shapes(field, times_secs);
    check_unit_and_tangent(field, times_secs);
    check_time_derivatives(field, times_secs, tol);
    check_continuity(field);
    check_param_gradients(field, times_secs, tol);
}

fn eval(field: &dyn PoseField<f64>, times: &[f64], order: Order) -> PoseBatch {
    let mut out = PoseBatch::default();
    field
        .evaluate(times, order, &mut out)
        .unwrap_or_else(|e| panic!("evaluate failed: {e}"));
    out
}

fn check_range_and_shapes(field: &mut dyn PoseField<f64>, times: &[f64]) {
    let range = field.time_range();
    for &t in times {
        assert!(
            range.contains(t),
            "test time {t} is outside the field's range {range}"
        );
    }
    let mut out = PoseBatch::default();
    for bad in [
        range.start_secs - 1e-3 * range.duration_secs(),
        range.end_secs + 1.0,
    ] {
        let err = field.evaluate(&[range.start_secs, bad], Order::Pose, &mut out);
        assert!(
            matches!(err, Err(PoseFieldError::OutOfRange { .. })),
            "a query at {bad} s outside {range} must be an OutOfRange error, got {err:?}"
        );
    }
    // Both ends are valid.
    eval(
        field,
        &[range.start_secs, range.end_secs],
        Order::Acceleration,
    );
    for order in [Order::Pose, Order::Velocity, Order::Acceleration] {
        let e = eval(field, times, order);
        e.check_shape(times.len(), order)
            .unwrap_or_else(|err| panic!("evaluate at {order:?}: {err}"));
        assert_eq!(e.order, order);
        let mut f = PoseBatch::default();
        field
            .forward(times, order, &mut f)
            .unwrap_or_else(|err| panic!("forward failed: {err}"));
        assert_eq!(e, f, "evaluate and forward disagree at {order:?}");
        if order == Order::Acceleration {
            let lower = eval(field, times, Order::Pose);
            assert_eq!(
                lower.rotation, e.rotation,
                "the pose must not depend on the requested order"
            );
            assert_eq!(
                lower.translation, e.translation,
                "the pose must not depend on the requested order"
            );
        }
    }
}

fn check_unit_and_tangent(field: &dyn PoseField<f64>, times: &[f64]) {
    let e = eval(field, times, Order::Velocity);
    for i in 0..times.len() {
        let q = e.rotation[i];
        assert!(
            (q.norm() - 1.0).abs() < 1e-9,
            "|q| = {} at t = {}",
            q.norm(),
            times[i]
        );
        let dot = q.coords.dot(&e.rotation_rate[i].coords);
        let scale = 1e-9 * (1.0 + e.rotation_rate[i].norm());
        assert!(
            dot.abs() < scale,
            "q·q̇ = {dot} at t = {} (q̇ must be tangent to the unit sphere)",
            times[i]
        );
    }
}

fn quat_diff(a: &Quaternion<f64>, b: &Quaternion<f64>, h: f64) -> Quaternion<f64> {
    (a - b) / (2.0 * h)
}

fn check_time_derivatives(field: &dyn PoseField<f64>, times: &[f64], tol: &Tolerances) {
    let range = field.time_range();
    let h = 1e-4 * range.duration_secs();
    // Shift times near the ends so that t ± h stays inside; the margin is 2h, not h, because
    // `(start + h) − h` can round to just below `start` (e.g. start = 0.5).
    let centre: Vec<f64> = times
        .iter()
        .map(|&t| t.clamp(range.start_secs + 2.0 * h, range.end_secs - 2.0 * h))
        .collect();
    let plus: Vec<f64> = centre.iter().map(|t| t + h).collect();
    let minus: Vec<f64> = centre.iter().map(|t| t - h).collect();
    let (c, p, m) = (
        eval(field, &centre, Order::Acceleration),
        eval(field, &plus, Order::Acceleration),
        eval(field, &minus, Order::Acceleration),
    );
    let n = times.len();
    let fd_q1: Vec<_> = (0..n)
        .map(|i| quat_diff(&p.rotation[i], &m.rotation[i], h))
        .collect();
    let fd_q2: Vec<_> = (0..n)
        .map(|i| quat_diff(&p.rotation_rate[i], &m.rotation_rate[i], h))
        .collect();
    let fd_p1: Vec<_> = (0..n)
        .map(|i| (p.translation[i] - m.translation[i]) / (2.0 * h))
        .collect();
    let fd_p2: Vec<_> = (0..n)
        .map(|i| (p.lin_vel_world[i] - m.lin_vel_world[i]) / (2.0 * h))
        .collect();
    let tol = tol.time_derivative;
    compare(
        "q̇ = dq/dt",
        &centre,
        &quat_rows(&c.rotation_rate),
        &quat_rows(&fd_q1),
        tol,
    );
    compare(
        "q̈ = d²q/dt²",
        &centre,
        &quat_rows(&c.rotation_acc),
        &quat_rows(&fd_q2),
        tol,
    );
    compare(
        "ṗ = dp/dt",
        &centre,
        &vec_rows(&c.lin_vel_world),
        &vec_rows(&fd_p1),
        tol,
    );
    compare(
        "p̈ = d²p/dt²",
        &centre,
        &vec_rows(&c.lin_acc_world),
        &vec_rows(&fd_p2),
        tol,
    );
}

/// Asserts `|a_i − b_i| ≤ rtol · max_j(|a_j|, |b_j|) + 1e-9` elementwise.
fn compare(what: &str, times: &[f64], analytic: &[Vec<f64>], numeric: &[Vec<f64>], rtol: f64) {
    let amax = |v: &Vec<f64>| v.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
    let scale = analytic.iter().chain(numeric).map(amax).fold(0.0, f64::max);
    for i in 0..analytic.len() {
        let err = analytic[i]
            .iter()
            .zip(&numeric[i])
            .fold(0.0, |m: f64, (a, b)| m.max((a - b).abs()));
        assert!(
            err <= rtol * scale + 1e-9,
            "{what} at t = {}: analytic {:?} vs reference {:?} (error {err:.3e}, scale {scale:.3e})",
            times[i],
            analytic[i],
            numeric[i]
        );
    }
}

/// Quaternions as `[w, x, y, z]` rows.
fn quat_rows(v: &[Quaternion<f64>]) -> Vec<Vec<f64>> {
    v.iter().map(|q| vec![q.w, q.i, q.j, q.k]).collect()
}

/// Vectors as rows.
fn vec_rows(v: &[Vector3<f64>]) -> Vec<Vec<f64>> {
    v.iter().map(|x| x.as_slice().to_vec()).collect()
}

fn check_continuity(field: &dyn PoseField<f64>) {
    let range = field.time_range();
    let n = 2001;
    let dt = range.duration_secs() / (n - 1) as f64;
    let times: Vec<f64> = (0..n)
        .map(|k| (range.start_secs + k as f64 * dt).min(range.end_secs))
        .collect();
    let e = eval(field, &times, Order::Velocity);
    for k in 0..n - 1 {
        // By the mean value theorem a step is bounded by dt times the rate somewhere between the
        // samples; allow the rate to vary by 50% within one step.
        let dq = (e.rotation[k + 1] - e.rotation[k]).norm();
        let rate_q = e.rotation_rate[k].norm().max(e.rotation_rate[k + 1].norm());
        assert!(
            dq <= 1.5 * dt * rate_q + 1e-9,
            "rotation jumps between t = {} and {}: |Δq| = {dq:.3e}, but |q̇|·dt = {:.3e}",
            times[k],
            times[k + 1],
            dt * rate_q
        );
        let dp = (e.translation[k + 1] - e.translation[k]).norm();
        let rate_p = e.lin_vel_world[k].norm().max(e.lin_vel_world[k + 1].norm());
        assert!(
            dp <= 1.5 * dt * rate_p + 1e-9,
            "translation jumps between t = {} and {}: |Δp| = {dp:.3e}, but |ṗ|·dt = {:.3e}",
            times[k],
            times[k + 1],
            dt * rate_p
        );
    }
}

/// Random cotangents on the outputs selected by `orders` (0: pose, 1: first, 2: second derivatives).
fn random_cotangent(n: usize, orders: &[usize], rng: &mut ChaCha8Rng) -> PoseBatch {
    let mut g = PoseBatch::zeros(n, Order::Acceleration);
    let q = |rng: &mut ChaCha8Rng| {
        Quaternion::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
    };
    let v = |rng: &mut ChaCha8Rng| {
        Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
    };
    for i in 0..n {
        if orders.contains(&0) {
            g.rotation[i] = q(rng);
            g.translation[i] = v(rng);
        }
        if orders.contains(&1) {
            g.rotation_rate[i] = q(rng);
            g.lin_vel_world[i] = v(rng);
        }
        if orders.contains(&2) {
            g.rotation_acc[i] = q(rng);
            g.lin_acc_world[i] = v(rng);
        }
    }
    g
}

/// `L = Σ_i ⟨g_i, out_i⟩` over all outputs.
fn linear_loss(g: &PoseBatch, out: &PoseBatch) -> f64 {
    let dq = |a: &[Quaternion<f64>], b: &[Quaternion<f64>]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| x.coords.dot(&y.coords))
            .sum::<f64>()
    };
    let dv = |a: &[Vector3<f64>], b: &[Vector3<f64>]| {
        a.iter().zip(b).map(|(x, y)| x.dot(y)).sum::<f64>()
    };
    dq(&g.rotation, &out.rotation)
        + dv(&g.translation, &out.translation)
        + dq(&g.rotation_rate, &out.rotation_rate)
        + dv(&g.lin_vel_world, &out.lin_vel_world)
        + dq(&g.rotation_acc, &out.rotation_acc)
        + dv(&g.lin_acc_world, &out.lin_acc_world)
}

fn check_param_gradients(field: &mut dyn PoseField<f64>, times: &[f64], tol: &Tolerances) {
    let n_params = field.num_params();
    if n_params == 0 {
        return;
    }
    let theta = params_to_vec(field);
    assert_eq!(
        theta.len(),
        n_params,
        "params() must visit num_params() values"
    );
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut checked: Vec<usize> = (0..n_params).collect();
    if n_params > tol.max_params_checked {
        // A seeded partial shuffle picks the parameters to check.
        for k in 0..tol.max_params_checked {
            let j = rng.random_range(k..n_params);
            checked.swap(k, j);
        }
        checked.truncate(tol.max_params_checked);
    }
    for (name, orders, order) in [
        ("pose", &[0][..], Order::Pose),
        ("first derivatives", &[1][..], Order::Velocity),
        ("second derivatives", &[2][..], Order::Acceleration),
        ("all outputs", &[0, 1, 2][..], Order::Acceleration),
    ] {
        let mut g = random_cotangent(times.len(), orders, &mut rng);
        // Truncate the cotangent to the forward order.
        let full = g.clone();
        g.reset(times.len(), order);
        g.rotation.clone_from(&full.rotation);
        g.translation.clone_from(&full.translation);
        if order >= Order::Velocity {
            g.rotation_rate.clone_from(&full.rotation_rate);
            g.lin_vel_world.clone_from(&full.lin_vel_world);
        }
        if order >= Order::Acceleration {
            g.rotation_acc.clone_from(&full.rotation_acc);
            g.lin_acc_world.clone_from(&full.lin_acc_world);
        }
        let mut out = PoseBatch::default();
        field
            .forward(times, order, &mut out)
            .unwrap_or_else(|e| panic!("forward: {e}"));
        // Start from ones to check that backward accumulates.
        let mut grad = vec![1.0; n_params];
        field
            .backward(times, &g, &mut grad)
            .unwrap_or_else(|e| panic!("backward: {e}"));
        let analytic: Vec<f64> = grad.iter().map(|x| x - 1.0).collect();
        let mut numeric = Vec::with_capacity(checked.len());
        let mut perturbed = theta.clone();
        for &k in &checked {
            let h = 1e-6 * theta[k].abs().max(1.0);
            let mut loss_at = |value: f64| {
                perturbed[k] = value;
                params_from_slice(field, &perturbed).expect("same length");
                linear_loss(&g, &eval(field, times, order))
            };
            let fd = (loss_at(theta[k] + h) - loss_at(theta[k] - h)) / (2.0 * h);
            perturbed[k] = theta[k];
            numeric.push(fd);
        }
        params_from_slice(field, &theta).expect("same length");
        let scale = checked
            .iter()
            .map(|&k| analytic[k].abs())
            .chain(numeric.iter().map(|x| x.abs()))
            .fold(0.0, f64::max);
        for (j, &k) in checked.iter().enumerate() {
            let err = (analytic[k] - numeric[j]).abs();
            assert!(
                err <= tol.param_gradient * scale + 1e-9,
                "gradient of a loss on the {name} w.r.t. parameter {k}: backward {} vs central difference {} (error {err:.3e}, scale {scale:.3e})",
                analytic[k],
                numeric[j]
            );
        }
    }
}

/// Asserts that an `f32` field and an `f64` field built from the same configuration and seed
/// produce the same outputs up to `rtol` (relative to each output's magnitude over the batch).
pub fn check_f32_matches_f64(
    f32_field: &dyn PoseField<f32>,
    f64_field: &dyn PoseField<f64>,
    times_secs: &[f64],
    rtol: f64,
) {
    let mut a = PoseBatch::default();
    let mut b = PoseBatch::default();
    f32_field
        .evaluate(times_secs, Order::Acceleration, &mut a)
        .unwrap_or_else(|e| panic!("f32 evaluate: {e}"));
    f64_field
        .evaluate(times_secs, Order::Acceleration, &mut b)
        .unwrap_or_else(|e| panic!("f64 evaluate: {e}"));
    let t = times_secs;
    compare(
        "f32 vs f64 q",
        t,
        &quat_rows(&a.rotation),
        &quat_rows(&b.rotation),
        rtol,
    );
    compare(
        "f32 vs f64 p",
        t,
        &vec_rows(&a.translation),
        &vec_rows(&b.translation),
        rtol,
    );
    compare(
        "f32 vs f64 q̇",
        t,
        &quat_rows(&a.rotation_rate),
        &quat_rows(&b.rotation_rate),
        rtol,
    );
    compare(
        "f32 vs f64 ṗ",
        t,
        &vec_rows(&a.lin_vel_world),
        &vec_rows(&b.lin_vel_world),
        rtol,
    );
    compare(
        "f32 vs f64 q̈",
        t,
        &quat_rows(&a.rotation_acc),
        &quat_rows(&b.rotation_acc),
        rtol,
    );
    compare(
        "f32 vs f64 p̈",
        t,
        &vec_rows(&a.lin_acc_world),
        &vec_rows(&b.lin_acc_world),
        rtol,
    );
}

/// Asserts that `cpose config show TASK` states the task's defaults: the task's decoded
/// config (`settings`, formatted with `{:?}`) of its default config equals that of `required`, a
/// config with only the keys that have no default.
pub fn check_default_config<T: std::fmt::Debug>(
    task: &str,
    required: &str,
    settings: impl Fn(&crate::Config, &crate::RunConfig) -> anyhow::Result<T>,
) {
    let decode = |text: String| {
        let config = crate::Config::from_text("default.toml", text);
        let decoded = settings(&config, &crate::RunConfig::default());
        format!("{:?}", decoded.unwrap_or_else(|e| panic!("{task}: {e:#}")))
    };
    let default = (crate::registry::find_task(task)
        .expect("a registered task")
        .default_config)();
    assert_eq!(decode(default), decode(required.to_owned()), "{task}");
}

/// A fresh, empty folder under the system's temp dir for one test, removed with its contents
/// when dropped — also when the test fails and unwinds. Derefs to its [`Path`].
#[derive(Debug)]
pub struct TempDir(PathBuf);

impl TempDir {
    /// Creates `cpose-{name}-{process}-{n}`, unique per process and call, emptied if a crashed
    /// run left it behind. Panics if the temp dir is not writable.
    pub fn new(name: &str) -> Self {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("cpose-{name}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)
            .unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

/// A batch of three samples with arbitrary (non-degenerate) values of every output, to check
/// losses on.
pub fn arbitrary_batch() -> PoseBatch {
    let mut b = PoseBatch::zeros(3, Order::Acceleration);
    for i in 0..3 {
        let x = i as f64;
        b.rotation[i] =
            *UnitQuaternion::from_scaled_axis(Vector3::new(0.3 + x, -0.2, 0.5 * x)).quaternion();
        b.rotation_rate[i] = Quaternion::new(0.1, -0.3 + x, 0.2, 0.05 * x);
        b.translation[i] = Vector3::new(0.4, -x, 1.3);
        b.lin_vel_world[i] = Vector3::new(-0.2, 0.5 * x, 0.3);
        b.lin_acc_world[i] = Vector3::new(0.7 - x, 0.2, -0.4 * x + 0.1);
    }
    b
}

/// One scalar output of a batch.
#[derive(Clone, Copy, Debug)]
enum Slot {
    Rotation(usize, usize),
    RotationRate(usize, usize),
    Translation(usize, usize),
    LinVel(usize, usize),
    LinAcc(usize, usize),
}

fn slot(b: &mut PoseBatch, s: Slot) -> &mut f64 {
    match s {
        Slot::Rotation(i, k) => &mut b.rotation[i].coords[k],
        Slot::RotationRate(i, k) => &mut b.rotation_rate[i].coords[k],
        Slot::Translation(i, k) => &mut b.translation[i][k],
        Slot::LinVel(i, k) => &mut b.lin_vel_world[i][k],
        Slot::LinAcc(i, k) => &mut b.lin_acc_world[i][k],
    }
}

/// Checks a loss on [`arbitrary_batch`] — its value returned, its cotangent accumulated into the
/// second batch — against central differences of its value, one output component at a time
/// (L1 losses are smooth away from zero residuals, which these values avoid).
///
/// # Panics
/// If a cotangent entry differs from its central difference by more than `1e-6`.
pub fn check_batch_loss_gradient(loss: impl Fn(&PoseBatch, &mut PoseBatch) -> f64) {
    let p = arbitrary_batch();
    let mut g = PoseBatch::zeros(3, Order::Acceleration);
    loss(&p, &mut g);
    let value = |b: &PoseBatch| loss(b, &mut PoseBatch::zeros(3, Order::Acceleration));
    let h = 1e-7;
    let slots = (0..3).flat_map(|i| {
        (0..4)
            .flat_map(move |k| [Slot::Rotation(i, k), Slot::RotationRate(i, k)])
            .chain((0..3).flat_map(move |k| {
                [
                    Slot::Translation(i, k),
                    Slot::LinVel(i, k),
                    Slot::LinAcc(i, k),
                ]
            }))
    });
    for s in slots {
        let (mut plus, mut minus) = (p.clone(), p.clone());
        *slot(&mut plus, s) += h;
        *slot(&mut minus, s) -= h;
        let fd = (value(&plus) - value(&minus)) / (2.0 * h);
        let an = *slot(&mut g, s);
        assert!(
            (fd - an).abs() < 1e-6,
            "{s:?}: central difference {fd} vs cotangent {an}"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_temp_dir_is_fresh_and_removed_when_dropped() {
        let (a, b) = (TempDir::new("temp-dir"), TempDir::new("temp-dir"));
        assert_ne!(*a, *b);
        std::fs::create_dir_all(a.join("sub")).unwrap();
        std::fs::write(a.join("sub/file.txt"), "x").unwrap();
        let path = a.to_path_buf();
        drop(a);
        assert!(!path.exists(), "{} is left behind", path.display());
        assert!(b.is_dir());
    }
}
