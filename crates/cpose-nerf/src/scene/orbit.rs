//! The monocular orbit of the paper's synthetic NeRF experiment (§4.1.2): "The simulated camera
//! orbits the model in the xy-plane, moving up and down at a constant speed in the
//! z-direction", always looking at the origin.
//!
//! Time is in seconds since frame 0, one frame per second: frame `i` is at `t = i`, and the
//! orbit can be evaluated at any real `t` (held-out views at `t = i + ½`).

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::SceneError;

/// Below this `|forward × up|` (both unit) [`look_at`] has no defined roll.
const LOOK_AT_MIN_SIN: f64 = 1e-9;

/// `world_from_camera` of a camera at `eye` looking at `target`, OpenCV axes: `z` forward (from
/// `eye` to `target`), `x = z × up` right, `y = z × x` down (`y` is `−up` projected orthogonally
/// to `z`). The target projects to the principal point and `up` points to image `−y`.
///
/// # Panics
/// If `eye == target` or `target − eye` is parallel to `up` (no defined roll: a caller bug).
pub fn look_at(eye: &Vector3<f64>, target: &Vector3<f64>, up: &Vector3<f64>) -> Isometry3<f64> {
    let forward = target - eye;
    let z = forward.normalize();
    let x = z.cross(&up.normalize());
    assert!(
        forward.norm() > 0.0 && x.norm() > LOOK_AT_MIN_SIN,
        "look_at: view direction {forward} is zero or parallel to up {up}"
    );
    let x = x.normalize();
    let y = z.cross(&x);
    let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Isometry3::from_parts(
        Translation3::from(*eye),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// A camera circling the origin at a fixed horizontal `radius`, azimuth linear in time, height a
/// triangle wave at constant vertical speed between `z_min` and `z_max`, looking at the origin
/// with world `z` up. A `[orbit]` TOML table; every key has a default.
///
/// At `t` seconds (frame index): azimuth `φ(t) = 2π · revolutions · t / frames` (so frame
/// `frames` would repeat frame 0 when `revolutions = 1`), height `z(t) = z_min + (z_max − z_min) ·
/// tri(z_cycles · t / frames)` with `tri(u) = 1 − |1 − 2 frac(u)|` (0 at `u = 0`, 1 at `u = ½`),
/// centre `(radius cos φ, radius sin φ, z)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MonocularOrbit {
    /// Frames in the sequence, at `t = 0, 1, …, frames − 1` (2 to [`Self::MAX_FRAMES`]).
    pub frames: usize,
    /// Horizontal distance of the camera centre from the world z axis (> 0, scene units).
    pub radius: f64,
    /// Lowest camera height (world z).
    pub z_min: f64,
    /// Highest camera height (≥ `z_min`).
    pub z_max: f64,
    /// Up-and-down periods over `frames` seconds (≥ 0; 0 keeps the camera at `z_min`).
    pub z_cycles: f64,
    /// Turns about the z axis over `frames` seconds (finite; negative turns clockwise).
    pub revolutions: f64,
}

impl Default for MonocularOrbit {
    fn default() -> Self {
        Self {
            frames: 100,
            radius: 4.0,
            z_min: 0.5,
            z_max: 2.5,
            z_cycles: 2.0,
            revolutions: 1.0,
        }
    }
}

impl MonocularOrbit {
    /// The most frames an orbit has (a thousand times the paper's).
    pub const MAX_FRAMES: usize = 100_000;

    /// Checks the ranges given in the field docs; the error names the `orbit.*` key.
    pub fn validate(&self) -> Result<(), SceneError> {
        let invalid = |key: &'static str, expected: &'static str, found: String| {
            Err(SceneError::Invalid {
                key,
                expected,
                found,
            })
        };
        if !(2..=Self::MAX_FRAMES).contains(&self.frames) {
            return invalid("orbit.frames", "2 to 100000", self.frames.to_string());
        }
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return invalid(
                "orbit.radius",
                "a finite value > 0",
                self.radius.to_string(),
            );
        }
        if !(self.z_min.is_finite() && self.z_max.is_finite()) {
            return invalid(
                "orbit.z_min",
                "finite z_min and z_max",
                format!("{} and {}", self.z_min, self.z_max),
            );
        }
        if self.z_min > self.z_max {
            return invalid(
                "orbit.z_max",
                "z_max ≥ z_min",
                format!("z_max = {} < z_min = {}", self.z_max, self.z_min),
            );
        }
        if !(self.z_cycles >= 0.0 && self.z_cycles.is_finite()) {
            return invalid(
                "orbit.z_cycles",
                "a finite value ≥ 0",
                self.z_cycles.to_string(),
            );
        }
        if !self.revolutions.is_finite() {
            return invalid(
                "orbit.revolutions",
                "a finite value",
                self.revolutions.to_string(),
            );
        }
        Ok(())
    }

    /// Frame times `0, 1, …, frames − 1` (seconds since frame 0).
    pub fn frame_times(&self) -> Vec<f64> {
        (0..self.frames).map(|i| i as f64).collect()
    }

    /// `2 · radius`, the scale of translation noise.
    pub fn diameter(&self) -> f64 {
        2.0 * self.radius
    }

    /// The camera centre at `t_secs` seconds since frame 0 (see [`MonocularOrbit`]).
    pub fn centre(&self, t_secs: f64) -> Vector3<f64> {
        let n = self.frames as f64;
        let phi = std::f64::consts::TAU * self.revolutions * t_secs / n;
        let u = self.z_cycles * t_secs / n;
        let tri = 1.0 - (1.0 - 2.0 * (u - u.floor())).abs();
        Vector3::new(
            self.radius * phi.cos(),
            self.radius * phi.sin(),
            self.z_min + (self.z_max - self.z_min) * tri,
        )
    }

    /// `world_from_camera` at `t_secs` seconds since frame 0: [`look_at`] from
    /// [`MonocularOrbit::centre`] to the origin with world `z` up.
    pub fn world_from_camera(&self, t_secs: f64) -> Isometry3<f64> {
        look_at(&self.centre(t_secs), &Vector3::zeros(), &Vector3::z())
    }

    /// Ground-truth poses of all frames, `world_from_camera(i)` for `i` in [`Self::frame_times`].
    pub fn poses(&self) -> Vec<Isometry3<f64>> {
        self.frame_times()
            .into_iter()
            .map(|t| self.world_from_camera(t))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::PinholeCamera;
    use nalgebra::Point3;

    fn camera() -> PinholeCamera {
        PinholeCamera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 52.0,
            cx: 31.0,
            cy: 25.0,
        }
    }

    /// `(u, v)` of a world point seen from `world_from_camera`.
    fn project(pose: &Isometry3<f64>, p: Vector3<f64>) -> [f64; 2] {
        let p_cam = pose.inverse_transform_point(&Point3::from(p)).coords;
        camera()
            .project(&p_cam)
            .expect("point in front of the camera")
    }

    #[test]
    fn look_at_centres_the_target_and_keeps_up_up() {
        let cam = camera();
        for (eye, target) in [
            (Vector3::new(4.0, 0.0, 1.0), Vector3::zeros()),
            (Vector3::new(-1.0, 3.0, -2.0), Vector3::new(0.5, 0.2, 0.1)),
            (Vector3::new(0.1, -2.0, 5.0), Vector3::new(0.0, 0.0, 0.3)),
        ] {
            let pose = look_at(&eye, &target, &Vector3::z());
            assert!((pose.translation.vector - eye).norm() < 1e-12);
            let r = pose.rotation.to_rotation_matrix();
            assert!((r.matrix().determinant() - 1.0).abs() < 1e-12);
            let [u, v] = project(&pose, target);
            assert!((u - cam.cx).abs() < 1e-9 && (v - cam.cy).abs() < 1e-9);
            // A point above the target is higher in the image (smaller row), not sideways.
            let [u_up, v_up] = project(&pose, target + 0.1 * Vector3::z());
            assert!(
                v_up < cam.cy - 0.1 && (u_up - cam.cx).abs() < 1e-9,
                "{u_up} {v_up}"
            );
            // Camera y (down) has a negative world z component; camera x is horizontal.
            assert!(r[(2, 1)] < 0.0 && r[(2, 0)].abs() < 1e-12);
        }
        // Looking along +x with z up: right is −y, down is −z.
        let r = look_at(&Vector3::zeros(), &Vector3::x(), &Vector3::z())
            .rotation
            .to_rotation_matrix();
        let expected = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
        assert!((r.matrix() - expected).norm() < 1e-12);
    }

    #[test]
    fn orbit_radius_speed_and_gaze() {
        let orbit = MonocularOrbit::default();
        orbit.validate().unwrap();
        assert_eq!(
            orbit.frame_times(),
            (0..100).map(f64::from).collect::<Vec<_>>()
        );
        assert_eq!(orbit.diameter(), 8.0);
        assert_eq!(orbit.poses().len(), 100);
        let cam = camera();
        // Period of the height: frames / z_cycles = 50 s; speed 2 (z_max − z_min) / 50.
        let speed = 2.0 * (orbit.z_max - orbit.z_min) / 50.0;
        let h = 0.01;
        let mut t = 0.0;
        while t < 100.0 {
            let c = orbit.centre(t);
            assert!((c.xy().norm() - 4.0).abs() < 1e-12);
            assert!(c.z >= orbit.z_min - 1e-12 && c.z <= orbit.z_max + 1e-12);
            // Constant vertical speed away from the turning points (t = 0, 25, 50, 75).
            if (t / 25.0 - (t / 25.0).round()).abs() * 25.0 > 2.0 * h {
                let vz = (orbit.centre(t + h).z - orbit.centre(t - h).z) / (2.0 * h);
                assert!((vz.abs() - speed).abs() < 1e-9, "t {t}: vz {vz}");
            }
            // The origin projects to the principal point.
            let [u, v] = project(&orbit.world_from_camera(t), Vector3::zeros());
            assert!((u - cam.cx).abs() < 1e-9 && (v - cam.cy).abs() < 1e-9);
            t += 0.37;
        }
        // Low at the start, high a quarter in; azimuth linear: a quarter turn at t = 25.
        assert!((orbit.centre(0.0) - Vector3::new(4.0, 0.0, 0.5)).norm() < 1e-12);
        assert!((orbit.centre(25.0) - Vector3::new(0.0, 4.0, 2.5)).norm() < 1e-12);
        assert!((orbit.centre(100.0) - orbit.centre(0.0)).norm() < 1e-12);
        // Between frames: the azimuth half-way.
        let mid = orbit.centre(10.5);
        let phi = mid.y.atan2(mid.x);
        assert!((phi - std::f64::consts::TAU * 10.5 / 100.0).abs() < 1e-12);
    }

    #[test]
    fn orbit_parses_with_defaults_and_validation_names_the_key() {
        let orbit: MonocularOrbit = toml::from_str("frames = 40\nz_cycles = 1.5").unwrap();
        assert_eq!(orbit.frames, 40);
        assert_eq!(orbit.z_cycles, 1.5);
        assert_eq!(orbit.radius, 4.0);
        let err = toml::from_str::<MonocularOrbit>("radiu = 3.0").unwrap_err();
        assert!(err.to_string().contains("radius"), "{err}");
        for (bad, key) in [
            (
                MonocularOrbit {
                    frames: 1,
                    ..Default::default()
                },
                "orbit.frames",
            ),
            (
                MonocularOrbit {
                    radius: 0.0,
                    ..Default::default()
                },
                "orbit.radius",
            ),
            (
                MonocularOrbit {
                    z_min: 3.0,
                    ..Default::default()
                },
                "orbit.z_max",
            ),
            (
                MonocularOrbit {
                    z_cycles: -1.0,
                    ..Default::default()
                },
                "orbit.z_cycles",
            ),
            (
                MonocularOrbit {
                    revolutions: f64::NAN,
                    ..Default::default()
                },
                "orbit.revolutions",
            ),
        ] {
            let err = bad.validate().unwrap_err();
            assert!(err.to_string().starts_with(key), "{err}");
        }
    }
}
