//! [`Composed`]: the pointwise product of two pose fields, `T(t) = T_a(t) ∘ T_b(t)`, for
//! `T_init ∘ T_refine` (a fixed initial trajectory refined by a PoseNet) and the intrinsic
//! motion frame `T_o ∘ T_I` (paper §3.3).

use nalgebra::{Quaternion, Vector3};

use super::{Order, ParamKind, PoseBatch, PoseField, PoseFieldError};
use crate::geometry::QuatJet;
use crate::{Real, TimeRange};

/// `world_from_body(t) = T_a(t) · T_b(t)`: with `T_a = (q_a, p_a)` and `T_b = (q_b, p_b)`,
///
/// ```text
/// q = q_a ⊗ q_b,        p = p_a + R(q_a) p_b,   R(q_a) v = vec(q_a ⊗ (0, v) ⊗ q_a*),
/// ```
///
/// so `a` maps the frame of `b`'s target into the world (`world_from_mid = T_a`,
/// `mid_from_body = T_b`). The time derivatives are exact, by the product rule on the quaternion
/// products (Leibniz, [`QuatJet::mul`]):
/// `q̇ = q̇_a⊗q_b + q_a⊗q̇_b`, `q̈ = q̈_a⊗q_b + 2 q̇_a⊗q̇_b + q_a⊗q̈_b`, and the same for the
/// triple product `q_a ⊗ (0, p_b) ⊗ q_a*` (exact because `q_a(t)` is unit for every `t`, so
/// `q_a* = q_a⁻¹` along the trajectory). The reverse pass maps the cotangents of `(q, p)` and
/// their derivatives onto those of `a`'s and `b`'s outputs ([`QuatJet::mul_backward`]) and calls
/// `a.backward` and `b.backward` on their slices of the flat gradient.
///
/// The time range is the intersection of both; [`PoseField::params`] visits `a`'s slices, then
/// `b`'s. [`PoseField::forward`] caches both sub-batches in the struct (no allocation in the
/// steady state).
pub struct Composed<S: Real = f32> {
    a: Box<dyn PoseField<S>>,
    b: Box<dyn PoseField<S>>,
    range: TimeRange,
    /// Outputs of `a` and `b` at the last `forward`.
    batch_a: PoseBatch,
    batch_b: PoseBatch,
    /// Cotangent buffers of `a`'s and `b`'s outputs.
    grad_a: PoseBatch,
    grad_b: PoseBatch,
    /// Order of the last `forward`, `None` before the first.
    forward_order: Option<Order>,
}

impl<S: Real> std::fmt::Debug for Composed<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Composed")
            .field("range", &self.range)
            .field("num_params_a", &self.a.num_params())
            .field("num_params_b", &self.b.num_params())
            .finish_non_exhaustive()
    }
}

impl<S: Real> Composed<S> {
    /// `T_a ∘ T_b` on the intersection of both time ranges; an error if they do not overlap.
    pub fn new(a: Box<dyn PoseField<S>>, b: Box<dyn PoseField<S>>) -> Result<Self, PoseFieldError> {
        let (ra, rb) = (a.time_range(), b.time_range());
        let range = TimeRange::new(
            ra.start_secs.max(rb.start_secs),
            ra.end_secs.min(rb.end_secs),
        )
        .map_err(|_| {
            PoseFieldError::Invalid(format!(
                "composed pose field: time ranges {ra} and {rb} do not overlap"
            ))
        })?;
        Ok(Self {
            a,
            b,
            range,
            batch_a: PoseBatch::default(),
            batch_b: PoseBatch::default(),
            grad_a: PoseBatch::default(),
            grad_b: PoseBatch::default(),
            forward_order: None,
        })
    }

    /// The outer field `T_a` (e.g. the fixed initial trajectory).
    pub fn outer(&self) -> &dyn PoseField<S> {
        self.a.as_ref()
    }

    /// The inner field `T_b` (e.g. the refining PoseNet).
    pub fn inner(&self) -> &dyn PoseField<S> {
        self.b.as_ref()
    }

    /// The two fields, outer first.
    pub fn into_parts(self) -> (Box<dyn PoseField<S>>, Box<dyn PoseField<S>>) {
        (self.a, self.b)
    }
}

const ZERO_Q: Quaternion<f64> = Quaternion::new(0.0, 0.0, 0.0, 0.0);

/// `(q, q̇, q̈)` at entry `i`, zeros for derivatives the batch does not hold.
fn rotation_jet(batch: &PoseBatch, i: usize) -> QuatJet {
    QuatJet::new(
        batch.rotation[i],
        batch.rotation_rate.get(i).copied().unwrap_or(ZERO_Q),
        batch.rotation_acc.get(i).copied().unwrap_or(ZERO_Q),
    )
}

/// `((0, p), (0, ṗ), (0, p̈))` at entry `i`, zeros for derivatives the batch does not hold.
fn translation_jet(batch: &PoseBatch, i: usize) -> QuatJet {
    let z = Vector3::zeros();
    QuatJet::from_vectors(
        &batch.translation[i],
        batch.lin_vel_world.get(i).unwrap_or(&z),
        batch.lin_acc_world.get(i).unwrap_or(&z),
    )
}

/// Writes the jets `q` and `p` (as pure quaternions) into entry `i` of `out` up to its order.
fn store(out: &mut PoseBatch, i: usize, q: &QuatJet, p: &QuatJet) {
    out.rotation[i] = q.value;
    out.translation[i] = p.value.imag();
    if out.order >= Order::Velocity {
        out.rotation_rate[i] = q.rate;
        out.lin_vel_world[i] = p.rate.imag();
    }
    if out.order >= Order::Acceleration {
        out.rotation_acc[i] = q.acc;
        out.lin_acc_world[i] = p.acc.imag();
    }
}

/// `out = a ∘ b` entry by entry, up to `order`.
fn compose(a: &PoseBatch, b: &PoseBatch, order: Order, out: &mut PoseBatch) {
    let n = a.len();
    out.reset(n, order);
    for i in 0..n {
        let qa = rotation_jet(a, i);
        let qb = rotation_jet(b, i);
        // q = q_a ⊗ q_b
        let q = qa.mul(&qb);
        // p = p_a + vec(q_a ⊗ (0, p_b) ⊗ q_a*)
        let rotated = qa.mul(&translation_jet(b, i)).mul(&qa.conjugate());
        let p = translation_jet(a, i).add(&rotated);
        store(out, i, &q, &p);
    }
}

impl<S: Real> PoseField<S> for Composed<S> {
    fn time_range(&self) -> TimeRange {
        self.range
    }

    fn num_params(&self) -> usize {
        self.a.num_params() + self.b.num_params()
    }

    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S])) {
        self.a.params(visit);
        self.b.params(visit);
    }

    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S])) {
        self.a.params_mut(visit);
        self.b.params_mut(visit);
    }

    fn set_progress(&mut self, progress: f64) {
        self.a.set_progress(progress);
        self.b.set_progress(progress);
    }

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        super::check_times(&self.range, times_secs)?;
        let mut batch_a = PoseBatch::default();
        let mut batch_b = PoseBatch::default();
        self.a.evaluate(times_secs, order, &mut batch_a)?;
        self.b.evaluate(times_secs, order, &mut batch_b)?;
        compose(&batch_a, &batch_b, order, out);
        Ok(())
    }

    fn forward(
        &mut self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        super::check_times(&self.range, times_secs)?;
        self.forward_order = None;
        self.a.forward(times_secs, order, &mut self.batch_a)?;
        self.b.forward(times_secs, order, &mut self.batch_b)?;
        compose(&self.batch_a, &self.batch_b, order, out);
        self.forward_order = Some(order);
        Ok(())
    }

    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        let computed = self.forward_order.ok_or_else(|| {
            PoseFieldError::Invalid("composed pose field: backward before forward".into())
        })?;
        if grad.order > computed {
            return Err(PoseFieldError::Order {
                needed: grad.order,
                computed,
            });
        }
        let n = self.batch_a.len();
        if times_secs.len() != n {
            return Err(PoseFieldError::Shape {
                what: "times (as in the last forward)",
                expected: n,
                got: times_secs.len(),
            });
        }
        grad.check_shape(n, grad.order)?;
        let n_a = self.a.num_params();
        if param_grad.len() != n_a + self.b.num_params() {
            return Err(PoseFieldError::Shape {
                what: "parameter gradient",
                expected: n_a + self.b.num_params(),
                got: param_grad.len(),
            });
        }
        self.grad_a.reset(n, grad.order);
        self.grad_b.reset(n, grad.order);
        for i in 0..n {
            let qa = rotation_jet(&self.batch_a, i);
            let qb = rotation_jet(&self.batch_b, i);
            let pb = translation_jet(&self.batch_b, i);
            let g_q = rotation_jet(grad, i);
            let g_p = translation_jet(grad, i);
            // q = q_a ⊗ q_b
            let (g_qa_rot, g_qb) = qa.mul_backward(&qb, &g_q);
            // p = p_a + vec((q_a ⊗ P_b) ⊗ q_a*): the cotangent of the pure quaternion is (0, ḡ_p).
            let qa_pb = qa.mul(&pb);
            let (g_qa_pb, g_qa_conj) = qa_pb.mul_backward(&qa.conjugate(), &g_p);
            let (g_qa_left, g_pb) = qa.mul_backward(&pb, &g_qa_pb);
            // Conjugation is linear and self-adjoint: ⟨g, a*⟩ = ⟨g*, a⟩.
            let g_qa = g_qa_rot.add(&g_qa_left).add(&g_qa_conj.conjugate());
            // p_a enters additively; only vec(ḡ) of P_b reaches p_b.
            store(&mut self.grad_a, i, &g_qa, &g_p);
            store(&mut self.grad_b, i, &g_qb, &g_pb);
        }
        let (grad_params_a, grad_params_b) = param_grad.split_at_mut(n_a);
        self.a.backward(times_secs, &self.grad_a, grad_params_a)?;
        self.b.backward(times_secs, &self.grad_b, grad_params_b)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose_field::sinusoid::SinusoidMotion;
    use crate::testing::{check_f32_matches_f64, check_pose_field};
    use std::panic::{AssertUnwindSafe, catch_unwind};

    fn range() -> TimeRange {
        TimeRange::new(0.0, 3.0).unwrap()
    }

    fn times() -> Vec<f64> {
        (0..8).map(|i| 0.2 + 2.6 * i as f64 / 7.0).collect()
    }

    /// Two hand-held motions, with larger rotations in `a` so that `R(q_a) p_b` matters.
    fn pair<S: Real>() -> Composed<S> {
        let mut a = SinusoidMotion::<S>::random(range(), 21, 3, 0.5, 1.0, 0.2, 1.5).unwrap();
        a.params_mut(&mut |_, p| {
            // Offsets of roll, pitch, yaw far from zero.
            p[3 * 4] = S::from_f64(0.4);
            p[4 * 4] = S::from_f64(-0.7);
            p[5 * 4] = S::from_f64(2.0);
        });
        let mut b = SinusoidMotion::<S>::random(range(), 22, 3, 0.5, 0.5, 0.2, 1.5).unwrap();
        b.params_mut(&mut |_, p| p[0] = S::from_f64(1.0)); // p_b away from the origin
        Composed::new(Box::new(a), Box::new(b)).unwrap()
    }

    #[test]
    fn composed_passes_the_conformance_suite() {
        let mut field = pair::<f64>();
        check_pose_field(&mut field, &times());
    }

    #[test]
    fn composed_pose_is_the_product_of_isometries() {
        let field = pair::<f64>();
        let ts = times();
        let (mut out, mut a, mut b) = (
            PoseBatch::default(),
            PoseBatch::default(),
            PoseBatch::default(),
        );
        field.evaluate(&ts, Order::Pose, &mut out).unwrap();
        field.outer().evaluate(&ts, Order::Pose, &mut a).unwrap();
        field.inner().evaluate(&ts, Order::Pose, &mut b).unwrap();
        for i in 0..ts.len() {
            let expected = a.world_from_body(i) * b.world_from_body(i);
            let d = (out.world_from_body(i).to_homogeneous() - expected.to_homogeneous())
                .abs()
                .max();
            assert!(d < 1e-14, "entry {i}: {d}");
        }
    }

    #[test]
    fn composed_with_identity_outer_equals_inner() {
        let mut identity = SinusoidMotion::<f64>::handheld(range(), 1);
        identity.params_mut(&mut |_, p| p.fill(0.0));
        let b = SinusoidMotion::<f64>::handheld(range(), 2);
        let field = Composed::new(Box::new(identity), Box::new(b.clone())).unwrap();
        let ts = times();
        let (mut out, mut expected) = (PoseBatch::default(), PoseBatch::default());
        field.evaluate(&ts, Order::Acceleration, &mut out).unwrap();
        b.evaluate(&ts, Order::Acceleration, &mut expected).unwrap();
        assert_eq!(out, expected);
    }

    #[test]
    fn composed_f32_matches_f64() {
        check_f32_matches_f64(&pair::<f32>(), &pair::<f64>(), &times(), 1e-5);
    }

    #[test]
    fn composed_range_is_the_intersection() {
        let a = SinusoidMotion::<f64>::handheld(TimeRange::new(0.0, 2.0).unwrap(), 1);
        let b = SinusoidMotion::<f64>::handheld(TimeRange::new(1.0, 5.0).unwrap(), 2);
        let c = Composed::new(Box::new(a.clone()), Box::new(b.clone())).unwrap();
        assert_eq!(c.time_range(), TimeRange::new(1.0, 2.0).unwrap());
        assert_eq!(c.num_params(), a.num_params() + b.num_params());
        let disjoint = SinusoidMotion::<f64>::handheld(TimeRange::new(3.0, 5.0).unwrap(), 2);
        assert!(Composed::new(Box::new(a), Box::new(disjoint)).is_err());
    }

    #[test]
    fn backward_without_forward_or_above_its_order_is_an_error() {
        let mut field = pair::<f64>();
        let ts = times();
        let mut grad = vec![0.0; field.num_params()];
        let g = PoseBatch::zeros(ts.len(), Order::Acceleration);
        assert!(field.backward(&ts, &g, &mut grad).is_err());
        let mut out = PoseBatch::default();
        field.forward(&ts, Order::Velocity, &mut out).unwrap();
        assert_eq!(
            field.backward(&ts, &g, &mut grad),
            Err(PoseFieldError::Order {
                needed: Order::Acceleration,
                computed: Order::Velocity
            })
        );
    }

    // ----- the conformance suite can fail ----------------------------------------------------

    /// A deliberately wrong field: `q̇` scaled by 1.01, or a backward that ignores the
    /// cotangent of `p̈`.
    struct Broken {
        inner: SinusoidMotion<f64>,
        scale_rotation_rate: bool,
        drop_lin_acc_grad: bool,
    }

    impl PoseField<f64> for Broken {
        fn time_range(&self) -> TimeRange {
            self.inner.time_range()
        }
        fn num_params(&self) -> usize {
            self.inner.num_params()
        }
        fn params(&self, visit: &mut dyn FnMut(ParamKind, &[f64])) {
            self.inner.params(visit)
        }
        fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [f64])) {
            self.inner.params_mut(visit)
        }
        fn evaluate(
            &self,
            times_secs: &[f64],
            order: Order,
            out: &mut PoseBatch,
        ) -> Result<(), PoseFieldError> {
            self.inner.evaluate(times_secs, order, out)?;
            if self.scale_rotation_rate {
                out.rotation_rate.iter_mut().for_each(|q| *q *= 1.01);
            }
            Ok(())
        }
        fn backward(
            &mut self,
            times_secs: &[f64],
            grad: &PoseBatch,
            param_grad: &mut [f64],
        ) -> Result<(), PoseFieldError> {
            let mut g = grad.clone();
            if self.drop_lin_acc_grad {
                g.lin_acc_world
                    .iter_mut()
                    .for_each(|a| *a = Vector3::zeros());
            }
            self.inner.backward(times_secs, &g, param_grad)
        }
    }

    fn suite_fails_on(mut field: Broken) -> bool {
        let ts = times();
        // The panic message is printed by the default hook; the test asserts that it happens.
        catch_unwind(AssertUnwindSafe(|| check_pose_field(&mut field, &ts))).is_err()
    }

    #[test]
    fn conformance_suite_catches_wrong_fields() {
        let inner = || SinusoidMotion::<f64>::handheld(range(), 4);
        // Control: the wrapper without a defect passes.
        assert!(!suite_fails_on(Broken {
            inner: inner(),
            scale_rotation_rate: false,
            drop_lin_acc_grad: false,
        }));
        assert!(suite_fails_on(Broken {
            inner: inner(),
            scale_rotation_rate: true,
            drop_lin_acc_grad: false,
        }));
        assert!(suite_fails_on(Broken {
            inner: inner(),
            scale_rotation_rate: false,
            drop_lin_acc_grad: true,
        }));
    }
}
