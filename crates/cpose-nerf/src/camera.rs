//! Pinhole cameras, world rays and the pose gradient of a camera's rays.
//!
//! Conventions (BARF, OpenCV axes x right, y down, z forward): pixel `(x, y)` (column, row) has
//! its centre at `(x + 0.5, y + 0.5)`; its camera-frame direction is `d_cam = K⁻¹ [x + 0.5,
//! y + 0.5, 1]ᵀ`, with `z = 1` and **not** normalised, so that volume-rendering distances are
//! `Δdepth · ‖d‖`. With `world_from_camera = (R, t)` the world ray is `o = t`, `d = R d_cam`.
//!
//! # Pose gradient
//!
//! Given `g_o = ∂L/∂o` and `g_d = ∂L/∂d` for the rays of one camera, [`PoseGradient`] sums
//! `G_o = Σ g_o` and `M = Σ g_d d_camᵀ` (3 × 3), from which both gradients follow:
//!
//! * **Left perturbation** `T' = Exp(δ) T`, `δ = (ω, v)`, at `δ = 0`: `Exp(δ) ≈ I + [ω]×` and
//!   translation `v` to first order, so `o' = o + ω × o + v`, `d' = d + ω × d`, i.e.
//!   `∂o/∂ω = −[o]×`, `∂o/∂v = I`, `∂d/∂ω = −[d]×`, `∂d/∂v = 0`. Transposing (`[a]×ᵀ = −[a]×`):
//!   `∂L/∂ω = Σ (o × g_o + d × g_d) = t × G_o + Σ d × g_d`, `∂L/∂v = G_o`.
//!   `Σ d × g_d = axial(N)` with `N = Σ g_d dᵀ = M Rᵀ` and
//!   `axial(N) = (N₂₁ − N₁₂, N₀₂ − N₂₀, N₁₀ − N₀₁)`.
//! * **Quaternion and translation** of `world_from_camera`, `q = (w, u)` (w first): `d(q) = q ⊗
//!   (0, d_cam) ⊗ q* = (w² − u·u) v + 2 (u·v) u + 2 w u × v` with `v = d_cam` (the homogeneous
//!   form; equals `R(q) v` for unit `q`, degree 2 otherwise). Its raw partials give, with
//!   `s = axial(M) = Σ v × g_d`:
//!   `∂L/∂w = 2 (w tr M + u·s)`, `∂L/∂u = 2 (M u + Mᵀ u − tr(M) u + w s)`, `∂L/∂t = G_o`.
//!   The radial part (along `q`) is `2 Σ g_d·d`; a unit-norm pose field discards it.

use nalgebra::{Isometry3, Matrix3, Quaternion, UnitQuaternion, Vector3, Vector6};

/// A pinhole camera (no distortion) in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinholeCamera {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Focal length along x, in pixels.
    pub fx: f64,
    /// Focal length along y, in pixels.
    pub fy: f64,
    /// Principal point x, in pixels (continuous coordinates, pixel `x` spans `[x, x + 1)`).
    pub cx: f64,
    /// Principal point y, in pixels.
    pub cy: f64,
}

impl PinholeCamera {
    /// Square pixels of focal length `focal` and the principal point at the image centre
    /// `(W/2, H/2)` (the LLFF and Blender readers' convention).
    pub fn centred(width: usize, height: usize, focal: f64) -> Self {
        Self {
            width,
            height,
            fx: focal,
            fy: focal,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
        }
    }

    /// Square pixels, principal point at the image centre, horizontal field of view `fov_x`
    /// (radians): `f = ½ W / tan(½ fov_x)` (Blender's `camera_angle_x`).
    pub fn from_fov_x(width: usize, height: usize, fov_x: f64) -> Self {
        Self::centred(width, height, 0.5 * width as f64 / (0.5 * fov_x).tan())
    }

    /// The same camera at a resolution scaled by `factor`: `fx, fy, cx, cy` times `factor`,
    /// `width, height` times `factor` rounded to the nearest integer.
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            width: (self.width as f64 * factor).round() as usize,
            height: (self.height as f64 * factor).round() as usize,
            fx: self.fx * factor,
            fy: self.fy * factor,
            cx: self.cx * factor,
            cy: self.cy * factor,
        }
    }

    /// `K⁻¹ [u, v, 1]ᵀ = ((u − cx)/fx, (v − cy)/fy, 1)` for continuous image coordinates.
    #[inline]
    pub fn direction_at(&self, u: f64, v: f64) -> [f64; 3] {
        [(u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0]
    }

    /// Camera-frame direction through the centre of pixel `(px, py)` (column, row):
    /// `K⁻¹ [px + 0.5, py + 0.5, 1]ᵀ`, `z = 1`, not normalised.
    #[inline]
    pub fn ray_direction_cam(&self, px: usize, py: usize) -> [f64; 3] {
        self.direction_at(px as f64 + 0.5, py as f64 + 0.5)
    }

    /// Projects a camera-frame point to continuous image coordinates `(u, v)` (`None` if
    /// `z ≤ 0`). Inverse of [`Self::direction_at`] along the ray.
    pub fn project(&self, p_cam: &Vector3<f64>) -> Option<[f64; 2]> {
        (p_cam.z > 0.0).then(|| {
            [
                self.fx * p_cam.x / p_cam.z + self.cx,
                self.fy * p_cam.y / p_cam.z + self.cy,
            ]
        })
    }

    /// World ray through the centre of pixel `(px, py)` of a camera at `world_from_camera`.
    #[inline]
    pub fn world_ray(&self, world_from_camera: &Isometry3<f64>, px: usize, py: usize) -> Ray {
        Ray::from_camera(world_from_camera, self.ray_direction_cam(px, py))
    }
}

/// A ray `x(s) = origin + s · direction`; `direction` keeps the length of `R d_cam`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// `o = t`, the camera centre in the world.
    pub origin: Vector3<f64>,
    /// `d = R d_cam` (not normalised).
    pub direction: Vector3<f64>,
}

impl Ray {
    /// `o = t`, `d = R d_cam` for `world_from_camera = (R, t)`.
    #[inline]
    pub fn from_camera(world_from_camera: &Isometry3<f64>, d_cam: [f64; 3]) -> Self {
        Self {
            origin: world_from_camera.translation.vector,
            direction: world_from_camera.rotation * Vector3::from(d_cam),
        }
    }

    /// The point at parameter `s` (camera depth `s` when `d_cam.z = 1`).
    #[inline]
    pub fn at(&self, s: f64) -> Vector3<f64> {
        self.origin + self.direction * s
    }
}

/// `(N₂₁ − N₁₂, N₀₂ − N₂₀, N₁₀ − N₀₁)`: for `N = Σ b aᵀ` this is `Σ a × b`.
#[inline]
fn axial(n: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        n[(2, 1)] - n[(1, 2)],
        n[(0, 2)] - n[(2, 0)],
        n[(1, 0)] - n[(0, 1)],
    )
}

/// Accumulates the ray cotangents of one camera into its pose gradient (see the module docs);
/// `O(1)` memory, no allocation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseGradient {
    /// `G_o = Σ ∂L/∂o`.
    pub sum_grad_origin: Vector3<f64>,
    /// `M = Σ (∂L/∂d) d_camᵀ`.
    pub moment: Matrix3<f64>,
}

impl Default for PoseGradient {
    fn default() -> Self {
        Self::new()
    }
}

impl PoseGradient {
    /// Zero gradient.
    pub fn new() -> Self {
        Self {
            sum_grad_origin: Vector3::zeros(),
            moment: Matrix3::zeros(),
        }
    }

    /// Adds one ray: its camera-frame direction and the cotangents of its world origin and
    /// direction.
    #[inline]
    pub fn add_ray(&mut self, d_cam: [f64; 3], grad_origin: [f64; 3], grad_direction: [f64; 3]) {
        self.sum_grad_origin += Vector3::from(grad_origin);
        self.moment += Vector3::from(grad_direction) * Vector3::from(d_cam).transpose();
    }

    /// `∂L/∂δ = (∂L/∂ω, ∂L/∂v)` for the left perturbation `Exp(δ) · world_from_camera` at
    /// `δ = 0`: `(t × G_o + axial(M Rᵀ), G_o)`.
    pub fn left_se3(&self, world_from_camera: &Isometry3<f64>) -> Vector6<f64> {
        let r = world_from_camera.rotation.to_rotation_matrix();
        let t = world_from_camera.translation.vector;
        let omega = t.cross(&self.sum_grad_origin) + axial(&(self.moment * r.matrix().transpose()));
        let mut out = Vector6::zeros();
        out.fixed_rows_mut::<3>(0).copy_from(&omega);
        out.fixed_rows_mut::<3>(3).copy_from(&self.sum_grad_origin);
        out
    }

    /// `∂L/∂δ = (∂L/∂ω, ∂L/∂v)` for the right perturbation `world_from_camera · Exp(δ)` at
    /// `δ = 0` (a correction in the camera frame, BARF's `compose([Exp(δ), P])` on
    /// world-to-camera poses): `o' = t + R v`, `d' = R (d_cam + ω × d_cam)`, so
    /// `∂L/∂v = Rᵀ G_o` and `∂L/∂ω = Σ d_cam × Rᵀ g_d = axial(Rᵀ M)`.
    pub fn right_se3(&self, world_from_camera: &Isometry3<f64>) -> Vector6<f64> {
        let rt = world_from_camera
            .rotation
            .to_rotation_matrix()
            .into_inner()
            .transpose();
        let omega = axial(&(rt * self.moment));
        let v = rt * self.sum_grad_origin;
        Vector6::new(omega.x, omega.y, omega.z, v.x, v.y, v.z)
    }

    /// The gradient with respect to `world_from_body` of a camera mounted at `body_from_camera`
    /// (`world_from_camera = world_from_body ∘ body_from_camera`): the rays leave from
    /// `t_b + R_b t_c` along `R_b R_c d_cam`, so the origin offset `t_c` enters the moment as a
    /// rotated vector with cotangent `G_o`: `M_b = M R_cᵀ + G_o t_cᵀ`.
    pub fn to_body(&self, body_from_camera: &Isometry3<f64>) -> PoseGradient {
        let rc = body_from_camera.rotation.to_rotation_matrix();
        let tc = body_from_camera.translation.vector;
        PoseGradient {
            sum_grad_origin: self.sum_grad_origin,
            moment: self.moment * rc.matrix().transpose() + self.sum_grad_origin * tc.transpose(),
        }
    }

    /// `(∂L/∂q, ∂L/∂t)`: raw partials with respect to the components of `q` (w first) of
    /// `q ⊗ (0, d_cam) ⊗ q*`, and with respect to the translation — a `PoseBatch` cotangent.
    pub fn quaternion_translation(
        &self,
        q: &UnitQuaternion<f64>,
    ) -> (Quaternion<f64>, Vector3<f64>) {
        let m = &self.moment;
        let w = q.w;
        let u = q.imag();
        let s = axial(m);
        let tr = m.trace();
        let gw = 2.0 * (w * tr + u.dot(&s));
        let gu = 2.0 * (m * u + m.transpose() * u - u * tr + s * w);
        (Quaternion::new(gw, gu.x, gu.y, gu.z), self.sum_grad_origin)
    }
}

/// `(∂L/∂q, ∂L/∂t)` of the rays `(d_cam, ∂L/∂o, ∂L/∂d)` of one camera with rotation `q` (see
/// [`PoseGradient::quaternion_translation`]).
pub fn pose_cotangent<I>(q: &UnitQuaternion<f64>, rays: I) -> (Quaternion<f64>, Vector3<f64>)
where
    I: IntoIterator<Item = ([f64; 3], [f64; 3], [f64; 3])>,
{
    let mut acc = PoseGradient::new();
    for (d_cam, g_o, g_d) in rays {
        acc.add_ray(d_cam, g_o, g_d);
    }
    acc.quaternion_translation(q)
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::geometry::se3_exp;
    use nalgebra::{Translation3, Vector4};

    fn camera() -> PinholeCamera {
        PinholeCamera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 55.0,
            cx: 31.0,
            cy: 25.0,
        }
    }

    fn pose() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.3, -1.2, 2.0),
            UnitQuaternion::from_euler_angles(0.4, -0.7, 1.1),
        )
    }

    /// Pixels of the test rays.
    fn pixels() -> Vec<(usize, usize)> {
        vec![(0, 0), (10, 40), (63, 5), (31, 24), (50, 47)]
    }

    /// A smooth loss of ray `i` and its gradients:
    /// `a·o + b·d + ½ c |d|² + sin(d·e) + 0.2 o·d`.
    fn loss_and_grads(
        o: &Vector3<f64>,
        d: &Vector3<f64>,
        i: usize,
    ) -> (f64, Vector3<f64>, Vector3<f64>) {
        let k = i as f64;
        let a = Vector3::new(0.3 + k, -0.5, 0.2 * k);
        let b = Vector3::new(-0.4, 0.7 * k, 1.1);
        let e = Vector3::new(0.9, -0.3, 0.5 + k);
        let c = 0.3 + 0.1 * k;
        let l = a.dot(o) + b.dot(d) + 0.5 * c * d.norm_squared() + d.dot(&e).sin() + 0.2 * o.dot(d);
        let g_o = a + 0.2 * d;
        let g_d = b + c * d + e * d.dot(&e).cos() + 0.2 * o;
        (l, g_o, g_d)
    }

    fn total_loss(cam: &PinholeCamera, pose: &Isometry3<f64>) -> f64 {
        pixels()
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| {
                let r = cam.world_ray(pose, x, y);
                loss_and_grads(&r.origin, &r.direction, i).0
            })
            .sum()
    }

    fn accumulate(cam: &PinholeCamera, pose: &Isometry3<f64>) -> PoseGradient {
        let mut acc = PoseGradient::new();
        for (i, &(x, y)) in pixels().iter().enumerate() {
            let r = cam.world_ray(pose, x, y);
            let (_, g_o, g_d) = loss_and_grads(&r.origin, &r.direction, i);
            acc.add_ray(cam.ray_direction_cam(x, y), g_o.into(), g_d.into());
        }
        acc
    }

    #[test]
    fn left_se3_gradient_matches_central_differences() {
        let cam = camera();
        let pose = pose();
        let g = accumulate(&cam, &pose).left_se3(&pose);
        let h = 1e-6;
        for k in 0..6 {
            let mut xi = Vector6::zeros();
            xi[k] = h;
            let lp = total_loss(&cam, &(se3_exp(&xi) * pose));
            let lm = total_loss(&cam, &(se3_exp(&(-xi)) * pose));
            let fd = (lp - lm) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "k={k}: fd {fd} vs {}",
                g[k]
            );
        }
    }

    #[test]
    fn right_se3_gradient_matches_central_differences() {
        let cam = camera();
        let pose = pose();
        let g = accumulate(&cam, &pose).right_se3(&pose);
        let h = 1e-6;
        for k in 0..6 {
            let mut xi = Vector6::zeros();
            xi[k] = h;
            let lp = total_loss(&cam, &(pose * se3_exp(&xi)));
            let lm = total_loss(&cam, &(pose * se3_exp(&(-xi))));
            let fd = (lp - lm) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "k={k}: fd {fd} vs {}",
                g[k]
            );
        }
    }

    #[test]
    fn body_gradient_of_an_offset_camera_matches_central_differences() {
        let cam = camera();
        let body = pose();
        let body_from_camera = Isometry3::from_parts(
            Translation3::new(-0.02, -0.065, 0.3),
            UnitQuaternion::from_euler_angles(-1.5, 0.2, 1.6),
        );
        let g = accumulate(&cam, &(body * body_from_camera))
            .to_body(&body_from_camera)
            .left_se3(&body);
        let h = 1e-6;
        for k in 0..6 {
            let mut xi = Vector6::zeros();
            xi[k] = h;
            let lp = total_loss(&cam, &(se3_exp(&xi) * body * body_from_camera));
            let lm = total_loss(&cam, &(se3_exp(&(-xi)) * body * body_from_camera));
            let fd = (lp - lm) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "k={k}: fd {fd} vs {}",
                g[k]
            );
        }
        // The identity mount changes nothing.
        let direct = accumulate(&cam, &body);
        assert_eq!(direct.to_body(&Isometry3::identity()), direct);
    }

    #[test]
    fn quaternion_gradient_matches_central_differences_of_the_homogeneous_rotation() {
        let cam = camera();
        let pose = pose();
        let q = pose.rotation;
        let (gq, gt) = accumulate(&cam, &pose).quaternion_translation(&q);
        let t = pose.translation.vector;
        // Loss as a function of raw (w, x, y, z) and t, rotating by q ⊗ (0, v) ⊗ q*.
        let raw_loss = |qv: Vector4<f64>, t: Vector3<f64>| -> f64 {
            let qq = Quaternion::new(qv[0], qv[1], qv[2], qv[3]);
            pixels()
                .iter()
                .enumerate()
                .map(|(i, &(x, y))| {
                    let v = Vector3::from(cam.ray_direction_cam(x, y));
                    let d = (qq * Quaternion::from_imag(v) * qq.conjugate()).imag();
                    loss_and_grads(&t, &d, i).0
                })
                .sum()
        };
        let q0 = Vector4::new(q.w, q.i, q.j, q.k);
        let gq = Vector4::new(gq.w, gq.i, gq.j, gq.k);
        let h = 1e-6;
        for k in 0..4 {
            let mut e = Vector4::zeros();
            e[k] = h;
            let fd = (raw_loss(q0 + e, t) - raw_loss(q0 - e, t)) / (2.0 * h);
            assert!(
                (fd - gq[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "q{k}: fd {fd} vs {}",
                gq[k]
            );
        }
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = h;
            let fd = (raw_loss(q0, t + e) - raw_loss(q0, t - e)) / (2.0 * h);
            assert!(
                (fd - gt[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "t{k}: fd {fd} vs {}",
                gt[k]
            );
        }
        // The free function agrees with the accumulator.
        let rays = pixels().into_iter().enumerate().map(|(i, (x, y))| {
            let r = cam.world_ray(&pose, x, y);
            let (_, g_o, g_d) = loss_and_grads(&r.origin, &r.direction, i);
            (cam.ray_direction_cam(x, y), g_o.into(), g_d.into())
        });
        let (gq2, gt2) = pose_cotangent(&q, rays);
        assert!((Vector4::new(gq2.w, gq2.i, gq2.j, gq2.k) - gq).norm() < 1e-12);
        assert!((gt2 - gt).norm() < 1e-12);
    }

    #[test]
    fn opencv_axes_and_pixel_centres() {
        let cam = camera();
        let id = Isometry3::identity();
        // A point on the optical axis projects to the principal point.
        let [u, v] = cam.project(&Vector3::new(0.0, 0.0, 5.0)).unwrap();
        assert_eq!((u, v), (cam.cx, cam.cy));
        // +x world is to the right (larger column), +y world is down (larger row).
        let [ux, _] = cam.project(&Vector3::new(1.0, 0.0, 5.0)).unwrap();
        let [_, vy] = cam.project(&Vector3::new(0.0, 1.0, 5.0)).unwrap();
        assert!(ux > cam.cx && vy > cam.cy);
        assert!(cam.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
        // Pixel (x, y) has its centre at (x + 0.5, y + 0.5); directions have z = 1.
        let d = cam.ray_direction_cam(3, 7);
        assert_eq!(d, [(3.5 - cam.cx) / cam.fx, (7.5 - cam.cy) / cam.fy, 1.0]);
        // A ray from the identity pose hits the point it came from at depth z.
        let r = cam.world_ray(&id, 40, 10);
        let p = r.at(5.0);
        assert!((p.z - 5.0).abs() < 1e-12);
        let [u, v] = cam.project(&p).unwrap();
        assert!((u - 40.5).abs() < 1e-12 && (v - 10.5).abs() < 1e-12);
        // World rays: origin at the camera centre, direction rotated.
        let pose = pose();
        let r = cam.world_ray(&pose, 40, 10);
        assert_eq!(r.origin, pose.translation.vector);
        let back = pose.inverse() * nalgebra::Point3::from(r.at(2.0));
        assert!((back.coords - 2.0 * Vector3::from(cam.ray_direction_cam(40, 10))).norm() < 1e-12);
    }

    #[test]
    fn scaling_and_fov() {
        let cam = PinholeCamera::from_fov_x(800, 800, 0.6911112070083618);
        assert!((cam.fx - 1111.111).abs() < 1e-2);
        let half = cam.scaled(0.5);
        assert_eq!((half.width, half.height), (400, 400));
        assert_eq!((half.fx, half.cx, half.cy), (cam.fx * 0.5, 200.0, 200.0));
        // The pixel centres of the half-resolution grid see the same rays as the continuous
        // points (2x + 1, 2y + 1) of the full grid.
        let a = half.ray_direction_cam(10, 20);
        let b = cam.direction_at(21.0, 41.0);
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-15);
        }
    }
}
