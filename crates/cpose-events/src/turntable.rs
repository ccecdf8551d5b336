//! [`Turntable`]: the camera path of EventNeRF's recordings — an object turning on a turntable
//! in front of a fixed camera, seen in the object's frame as the camera circling the turntable
//! axis once per revolution, always looking at the object.
//!
//! The paper's calibration experiment (§4.2, supplement "Continuous Pose for Asynchronous
//! Events") trains with poses about the nominal vertical axis while the data was recorded about
//! an axis tilted by 0.24°, 1.5° or 2.85°; [`Turntable::axis_tilt_rad`] generates such data.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use cpose_core::pose_field::check_times;
use cpose_core::{Order, ParamKind, PoseBatch, PoseField, PoseFieldError, Real, TimeRange};
use cpose_nerf::scene::look_at;

use crate::error::EventsError;

/// A camera circling a tilted turntable axis through the world origin (world `z` up, OpenCV
/// camera axes).
///
/// At `t = 0` the camera is at `c₀ = (radius, 0, height)` looking at the origin with world `z`
/// up ([`look_at`]): `world_from_camera(0) = (q₀, c₀)`. The axis is the unit vector
/// `a = (sin α cos β, sin α sin β, cos α)` with `α` = [`Self::axis_tilt_rad`] and `β` =
/// [`Self::tilt_azimuth_rad`], and the camera turns about it at `ω = 2π / duration`:
///
/// `world_from_camera(t) = Rot(a, ω t) · world_from_camera(0)`, i.e.
/// `q(t) = q_a(ω t) ⊗ q₀` with `q_a(φ) = (cos φ/2, sin φ/2 · a)` and `p(t) = R_a(ω t) c₀`.
///
/// Exact derivatives: `q̇ = ½ ω (0, a) ⊗ q`, `q̈ = −¼ ω² q`, `ṗ = ω a × p`,
/// `p̈ = ω² a × (a × p)`. The field has no parameters. With `α = 0` the camera stays at height
/// `height` and `world_from_camera(t)` is `look_at` from `(radius cos ωt, radius sin ωt, height)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Turntable {
    /// Horizontal distance of the camera from the world `z` axis at `t = 0` (> 0).
    pub radius: f64,
    /// Camera height above the object's centre (world `z`) at `t = 0`.
    pub height: f64,
    /// Duration of one revolution, seconds (> 0); the field is valid on `[0, duration]`.
    pub duration_secs: f64,
    /// Angle between the turntable axis and world `z`, radians (0: the nominal axis).
    pub axis_tilt_rad: f64,
    /// Direction the axis tilts towards, radians from world `x` towards `y`.
    pub tilt_azimuth_rad: f64,
}

impl Default for Turntable {
    /// Radius 4.5 and height 1.5 (about 18° above the equator), 10 s per revolution, no tilt.
    fn default() -> Self {
        Self {
            radius: 4.5,
            height: 1.5,
            duration_secs: 10.0,
            axis_tilt_rad: 0.0,
            tilt_azimuth_rad: 0.0,
        }
    }
}

impl Turntable {
    /// The longest revolution, seconds (11.6 days): far beyond any event recording, and well
    /// inside the nanosecond timestamps' range.
    pub const MAX_DURATION_SECS: f64 = 1e6;

    /// Checks the ranges of the field docs; the error names the parameter.
    pub fn validate(&self) -> Result<(), EventsError> {
        let invalid = |key, expected, found: f64| {
            Err(EventsError::Invalid {
                key,
                expected,
                found: found.to_string(),
            })
        };
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return invalid("turntable.radius", "a finite value > 0", self.radius);
        }
        if !self.height.is_finite() {
            return invalid("turntable.height", "a finite value", self.height);
        }
        if !(self.duration_secs > 0.0 && self.duration_secs <= Self::MAX_DURATION_SECS) {
            return invalid(
                "turntable.duration_secs",
                "a value in (0, 1e6] seconds",
                self.duration_secs,
            );
        }
        if !(self.axis_tilt_rad.is_finite() && self.tilt_azimuth_rad.is_finite()) {
            return invalid(
                "turntable.axis_tilt_rad",
                "finite tilt and azimuth",
                self.axis_tilt_rad,
            );
        }
        Ok(())
    }

    /// The unit turntable axis `a`.
    pub fn axis(&self) -> Vector3<f64> {
        let (sa, ca) = self.axis_tilt_rad.sin_cos();
        let (sb, cb) = self.tilt_azimuth_rad.sin_cos();
        Vector3::new(sa * cb, sa * sb, ca)
    }

    /// Angular speed `ω = 2π / duration`, rad/s.
    pub fn angular_speed(&self) -> f64 {
        std::f64::consts::TAU / self.duration_secs
    }

    /// `world_from_camera(0)`.
    pub fn start_pose(&self) -> Isometry3<f64> {
        look_at(
            &Vector3::new(self.radius, 0.0, self.height),
            &Vector3::zeros(),
            &Vector3::z(),
        )
    }

    /// `world_from_camera(t_secs)` for any real `t_secs` (seconds since the start; periodic).
    pub fn world_from_camera(&self, t_secs: f64) -> Isometry3<f64> {
        let turn = UnitQuaternion::from_scaled_axis(self.axis() * (self.angular_speed() * t_secs));
        Isometry3::from_parts(Translation3::identity(), turn) * self.start_pose()
    }

    /// The field's time range `[0, duration]`.
    fn range(&self) -> TimeRange {
        // A validated turntable has duration > 0; otherwise a degenerate 1-second range.
        TimeRange::new(0.0, self.duration_secs).unwrap_or(TimeRange {
            start_secs: 0.0,
            end_secs: 1.0,
        })
    }
}

impl<S: Real> PoseField<S> for Turntable {
    fn time_range(&self) -> TimeRange {
        self.range()
    }

    fn num_params(&self) -> usize {
        0
    }

    fn params(&self, _visit: &mut dyn FnMut(ParamKind, &[S])) {}

    fn params_mut(&mut self, _visit: &mut dyn FnMut(ParamKind, &mut [S])) {}

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range(), times_secs)?;
        out.reset(times_secs.len(), order);
        let a = self.axis();
        let w = self.angular_speed();
        let a_quat = Quaternion::from_imag(a);
        for (i, &t) in times_secs.iter().enumerate() {
            let pose = self.world_from_camera(t);
            let q = *pose.rotation.quaternion();
            let p = pose.translation.vector;
            out.rotation[i] = q;
            out.translation[i] = p;
            if order >= Order::Velocity {
                out.rotation_rate[i] = a_quat * q * (0.5 * w);
                out.lin_vel_world[i] = a.cross(&p) * w;
            }
            if order >= Order::Acceleration {
                out.rotation_acc[i] = q * (-0.25 * w * w);
                out.lin_acc_world[i] = a.cross(&a.cross(&p)) * (w * w);
            }
        }
        Ok(())
    }

    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range(), times_secs)?;
        grad.check_shape(times_secs.len(), grad.order)?;
        if !param_grad.is_empty() {
            return Err(PoseFieldError::Shape {
                what: "parameter gradient",
                expected: 0,
                got: param_grad.len(),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::testing::check_pose_field;
    use nalgebra::{Matrix3, Point3};

    #[test]
    fn poses_at_start_and_quarter_turn_are_pinned() {
        let tt = Turntable {
            radius: 4.0,
            height: 1.0,
            duration_secs: 8.0,
            ..Default::default()
        };
        tt.validate().unwrap();
        // t = 0: at (4, 0, 1) looking at the origin; camera x (right) = world +y, camera z
        // (forward) = −(4, 0, 1)/√17, camera y (down) = z × x.
        let p0 = tt.world_from_camera(0.0);
        assert!((p0.translation.vector - Vector3::new(4.0, 0.0, 1.0)).norm() < 1e-12);
        let s = 17f64.sqrt();
        let fwd = Vector3::new(-4.0, 0.0, -1.0) / s;
        let right = Vector3::new(0.0, 1.0, 0.0);
        let r0 = Matrix3::from_columns(&[right, fwd.cross(&right), fwd]);
        assert!((p0.rotation.to_rotation_matrix().matrix() - r0).amax() < 1e-12);
        // t = T/4: a quarter turn counter-clockwise seen from above, at (0, 4, 1); right = −x.
        let p1 = tt.world_from_camera(2.0);
        assert!((p1.translation.vector - Vector3::new(0.0, 4.0, 1.0)).norm() < 1e-12);
        let r1 = p1.rotation.to_rotation_matrix();
        assert!((r1 * Vector3::x() - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((r1 * Vector3::z() - Vector3::new(0.0, -4.0, -1.0) / s).norm() < 1e-12);
        // Always looking at the origin, and periodic.
        for t in [0.3, 2.0, 5.5, 8.0] {
            let pose = tt.world_from_camera(t);
            let o = pose.inverse_transform_point(&Point3::origin());
            assert!(
                o.x.abs() < 1e-12 && o.y.abs() < 1e-12 && o.z > 0.0,
                "{t}: {o}"
            );
        }
        assert!((tt.world_from_camera(8.0).to_homogeneous() - p0.to_homogeneous()).amax() < 1e-12);
    }

    #[test]
    fn tilted_axis_moves_the_camera_off_the_nominal_circle() {
        let tilt = 1.5f64.to_radians();
        let tt = Turntable {
            axis_tilt_rad: tilt,
            ..Default::default()
        };
        let nominal = Turntable::default();
        // The same start view; half a turn later the camera is off by the rotation of the
        // start position about two axes 1.5° apart: the angle between the two poses is 2·1.5°.
        let half = 0.5 * tt.duration_secs;
        assert_eq!(tt.world_from_camera(0.0), nominal.world_from_camera(0.0));
        let a = tt.world_from_camera(half);
        let b = nominal.world_from_camera(half);
        let angle = a.rotation.angle_to(&b.rotation);
        assert!((angle - 2.0 * tilt).abs() < 1e-9, "{}", angle.to_degrees());
        // The camera stays on a circle about the tilted axis.
        let axis = tt.axis();
        let c0 = tt.world_from_camera(0.0).translation.vector;
        for t in [1.0, 3.0, 7.0] {
            let c = tt.world_from_camera(t).translation.vector;
            assert!((c.dot(&axis) - c0.dot(&axis)).abs() < 1e-12);
            assert!((c.norm() - c0.norm()).abs() < 1e-12);
        }
    }

    #[test]
    fn turntable_passes_the_pose_field_conformance_suite() {
        for tilt_deg in [0.0, 2.85] {
            let mut tt = Turntable {
                axis_tilt_rad: f64::to_radians(tilt_deg),
                tilt_azimuth_rad: 0.7,
                ..Default::default()
            };
            let times: Vec<f64> = (1..10).map(|i| i as f64 * 0.97).collect();
            check_pose_field(&mut tt, &times);
            let field: &dyn PoseField<f64> = &tt;
            let mut out = PoseBatch::default();
            assert!(field.evaluate(&[10.5], Order::Pose, &mut out).is_err());
        }
        let bad = Turntable {
            duration_secs: 0.0,
            ..Default::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .starts_with("turntable.duration_secs")
        );
    }
}
