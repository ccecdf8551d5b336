//! Rendering batches of camera rays through a [`RadianceField`], and the reverse pass from pixel
//! colours to the field's parameters and to every camera's pose.
//!
//! A ray of camera `(R, t)` through camera-frame direction `d_cam` samples the points
//! `x_j = o + s_j d` with `o = t`, `d = R d_cam` and depths `s_j` ([`Sampling`]); the field
//! gives `σ_j, c_j` and [`composite_batch`] the pixel. Backwards, the field returns `∂L/∂x_j`,
//! and `∂L/∂o = Σ_j ∂L/∂x_j`, `∂L/∂d = Σ_j s_j ∂L/∂x_j`, which [`PoseGradient`] turns into the
//! camera's pose gradient. (The ray norm `‖d‖ = ‖d_cam‖` in the compositing distances does not
//! depend on the pose, so it carries no pose gradient.)

use nalgebra::{Isometry3, Vector3};
use rand::RngExt;
use rayon::prelude::*;

use super::volume::{
    Composited, LastInterval, Sampling, composite_batch, composite_batch_backward, delta,
};
use crate::camera::PoseGradient;
use crate::field3d::RadianceField;
use cpose_core::Real;

/// Rays per parallel work item.
const CHUNK: usize = 64;

/// How rays are sampled and composited.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Samples per ray.
    pub samples: usize,
    /// Depth range and spacing of the samples.
    pub sampling: Sampling,
    /// Colour behind the scene (`None`: black, BARF's `setbg_opaque: false`).
    pub background: Option<[f32; 3]>,
    /// The scene is empty outside this sphere: metric samples are spread over the ray's chord
    /// through it instead of all of `[near, far]`, and points outside have `σ = 0` ([`Clip`]).
    pub clip: Option<Clip>,
    /// The last sample's interval: BARF's closed ray, or open (NICE-SLAM).
    pub last_interval: LastInterval,
}

impl RenderSettings {
    /// The clip sphere and `[near, far]` when they apply (metric sampling only).
    fn metric_clip(&self) -> Option<(Clip, f64, f64)> {
        match self.sampling {
            Sampling::Metric { near, far } => self.clip.map(|c| (c, near, far)),
            Sampling::InverseDepth { .. } => None,
        }
    }
}

/// A sphere outside which the scene is empty (a bounded scene's bounding sphere).
///
/// With metric sampling, the `N` samples of the ray `o + s d` cover `[a, b']`, where
/// `[a, b] = [near, far] ∩ {s : ‖o + s d − c‖ ≤ r}` and `b' = (N b − a)/(N − 1)`: the first
/// `N − 1` strata tile the chord and the last lies beyond it, where `σ = 0` closes the ray in
/// place of BARF's 10¹⁰-long last interval. Rays that miss the sphere see only the background.
/// The interval ends move with the camera but are constants for the gradient (stop-gradient,
/// as every stratified sampler treats its depths); the `σ = 0` outside is exact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip {
    /// Centre `c`.
    pub centre: [f64; 3],
    /// Radius `r`.
    pub radius: f64,
}

impl Clip {
    /// `[a, b']` of the ray `o + s d` with `samples ≥ 2` strata over `[near, far]` (type docs),
    /// or `None` when the ray misses the sphere inside `[near, far]`.
    pub fn interval(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        near: f64,
        far: f64,
        samples: usize,
    ) -> Option<(f64, f64)> {
        let (o, d, c) = (
            Vector3::from(o),
            Vector3::from(d),
            Vector3::from(self.centre),
        );
        // ‖o − c + s d‖² = r²: A s² + 2 B s + C = 0.
        let oc = o - c;
        let (a2, b, c2) = (
            d.norm_squared(),
            d.dot(&oc),
            oc.norm_squared() - self.radius.powi(2),
        );
        let disc = b * b - a2 * c2;
        if disc <= 0.0 || a2 == 0.0 {
            return None;
        }
        let root = disc.sqrt();
        let (enter, exit) = ((-b - root) / a2, (-b + root) / a2);
        let (a, b) = (enter.max(near), exit.min(far));
        if a >= b {
            return None;
        }
        let k = samples.max(2) as f64;
        Some((a, (k * b - a) / (k - 1.0)))
    }

    fn contains<S: Real>(&self, p: &[S]) -> bool {
        let d2: f64 = (0..3)
            .map(|c| (p[c].to_f64() - self.centre[c]).powi(2))
            .sum();
        d2 <= self.radius * self.radius
    }
}

/// One ray of a batch: which camera, its camera-frame direction and its world origin and
/// direction (from that camera's current pose).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRay {
    /// Index of the camera (frame) the ray belongs to.
    pub camera: usize,
    /// `K⁻¹ [u, v, 1]ᵀ`.
    pub d_cam: [f64; 3],
    /// World origin `o = t`.
    pub origin: [f64; 3],
    /// World direction `d = R d_cam`.
    pub direction: [f64; 3],
}

impl CameraRay {
    /// The ray of camera `camera` at `world_from_camera` through `d_cam`.
    pub fn new(camera: usize, world_from_camera: &Isometry3<f64>, d_cam: [f64; 3]) -> Self {
        let d = world_from_camera.rotation * Vector3::from(d_cam);
        Self {
            camera,
            d_cam,
            origin: world_from_camera.translation.vector.into(),
            direction: d.into(),
        }
    }
}

/// Buffers of a forward/backward pair over a batch of rays (grow, never shrink).
#[derive(Debug, Default)]
pub struct Renderer<S: Real = f32> {
    depths: Vec<S>,
    points: Vec<S>,
    sigma: Vec<S>,
    rgb: Vec<S>,
    norms: Vec<S>,
    out: Vec<Composited<S>>,
    grad_sigma: Vec<S>,
    grad_rgb: Vec<S>,
    grad_points: Vec<S>,
}

fn grow<T: Copy + Default>(v: &mut Vec<T>, n: usize) -> &mut [T] {
    if v.len() < n {
        v.resize(n, T::default());
    }
    &mut v[..n]
}

impl<S: Real> Renderer<S> {
    /// Renders `rays`: jittered depths when `rng` is given (training), midpoints otherwise.
    /// Returns the composited colour, depth and opacity of every ray.
    pub fn forward<R: RngExt + ?Sized>(
        &mut self,
        field: &mut dyn RadianceField<S>,
        settings: &RenderSettings,
        rays: &[CameraRay],
        rng: Option<&mut R>,
    ) -> &[Composited<S>] {
        let (n, k) = (rays.len(), settings.samples);
        let depths = grow(&mut self.depths, n * k);
        match rng {
            Some(rng) => settings.sampling.jittered_depths(rng, k, depths),
            None => settings.sampling.midpoint_depths(k, depths),
        }
        self.place_samples(settings, rays);
        self.shade(field, settings, n)
    }

    /// Renders `rays` with the caller's stratum offsets `u ∈ [0, 1)` (`rays × samples`, as
    /// [`Sampling::jittered_depths`] draws them): e.g. the same offsets for two rays whose
    /// renders are compared (EventNeRF's two window ends).
    pub fn forward_with_offsets(
        &mut self,
        field: &mut dyn RadianceField<S>,
        settings: &RenderSettings,
        rays: &[CameraRay],
        offsets: &[f64],
    ) -> &[Composited<S>] {
        let (n, k) = (rays.len(), settings.samples);
        assert_eq!(offsets.len(), n * k, "rays × samples offsets");
        let depths = grow(&mut self.depths, n * k);
        for (d, (i, u)) in depths.iter_mut().zip(offsets.iter().enumerate()) {
            *d = S::from_f64(settings.sampling.depth_at(((i % k) as f64 + u) / k as f64));
        }
        self.place_samples(settings, rays);
        self.shade(field, settings, n)
    }

    /// Maps the depths of `[near, far]` onto each ray's chord through the clip sphere (if any)
    /// and places the sample points.
    fn place_samples(&mut self, settings: &RenderSettings, rays: &[CameraRay]) {
        let (n, k) = (rays.len(), settings.samples);
        let depths = &mut self.depths[..n * k];
        let points = grow(&mut self.points, 3 * n * k);
        let norms = grow(&mut self.norms, n);
        let clip = settings.metric_clip();
        points
            .par_chunks_mut(3 * k * CHUNK)
            .zip(depths.par_chunks_mut(k * CHUNK))
            .zip(norms.par_chunks_mut(CHUNK))
            .zip(rays.par_chunks(CHUNK))
            .for_each(|(((pts, ds), ns), rs)| {
                for (r, ray) in rs.iter().enumerate() {
                    let (o, d) = (ray.origin, ray.direction);
                    ns[r] = S::from_f64(Vector3::from(d).norm());
                    if let Some((clip, near, far)) = clip {
                        // Map [near, far] onto the chord [a, b'] (a miss keeps [near, far],
                        // all outside the sphere, so empty).
                        let (a, b) = clip.interval(o, d, near, far, k).unwrap_or((near, far));
                        for s in &mut ds[r * k..(r + 1) * k] {
                            *s = S::from_f64(a + (s.to_f64() - near) / (far - near) * (b - a));
                        }
                    }
                    for j in 0..k {
                        let s = ds[r * k + j].to_f64();
                        for c in 0..3 {
                            pts[3 * (r * k + j) + c] = S::from_f64(o[c] + s * d[c]);
                        }
                    }
                }
            });
    }

    /// Renders `rays` at the caller's sample depths `depths` (`rays × settings.samples`, each
    /// ray's increasing, in units of its direction, e.g. spread around a measured depth), as
    /// [`Renderer::forward`] does after sampling. `settings.sampling` is not used and
    /// `settings.clip` must be `None`. [`Renderer::backward`] reverses it.
    pub fn forward_at_depths(
        &mut self,
        field: &mut dyn RadianceField<S>,
        settings: &RenderSettings,
        rays: &[CameraRay],
        depths: &[S],
    ) -> &[Composited<S>] {
        let (n, k) = (rays.len(), settings.samples);
        assert_eq!(depths.len(), n * k, "rays × samples depths");
        assert!(
            settings.clip.is_none(),
            "caller-chosen depths are not clipped"
        );
        grow(&mut self.depths, n * k).copy_from_slice(depths);
        let points = grow(&mut self.points, 3 * n * k);
        let norms = grow(&mut self.norms, n);
        for (r, ray) in rays.iter().enumerate() {
            let (o, d) = (ray.origin, ray.direction);
            norms[r] = S::from_f64(Vector3::from(d).norm());
            for j in 0..k {
                let s = depths[r * k + j].to_f64();
                for c in 0..3 {
                    points[3 * (r * k + j) + c] = S::from_f64(o[c] + s * d[c]);
                }
            }
        }
        self.shade(field, settings, n)
    }

    /// The depth variance `Var = Σ_j w_j (s_j − D)²` of each ray of the last forward pass with
    /// `settings` (`D` its composited depth) into `out` (NICE-SLAM's tracking weight; a constant
    /// for the gradient, as there).
    pub fn depth_variances(&self, settings: &RenderSettings, out: &mut [S]) {
        let k = settings.samples;
        for (r, v) in out.iter_mut().enumerate() {
            let (sigma, depths) = (
                &self.sigma[r * k..(r + 1) * k],
                &self.depths[r * k..(r + 1) * k],
            );
            let depth = self.out[r].depth;
            let mut trans = S::ONE;
            let mut acc = S::ZERO;
            for j in 0..k {
                let e =
                    Real::exp(-sigma[j] * delta(depths, j, self.norms[r], settings.last_interval));
                let w = trans * (S::ONE - e);
                trans *= e;
                let dev = depths[j] - depth;
                acc += w * dev * dev;
            }
            *v = acc;
        }
    }

    /// The field at the points of the last sampling, then compositing.
    fn shade(
        &mut self,
        field: &mut dyn RadianceField<S>,
        settings: &RenderSettings,
        n: usize,
    ) -> &[Composited<S>] {
        let k = settings.samples;
        let clip = settings.metric_clip();
        let (points, depths, norms) = (
            &self.points[..3 * n * k],
            &self.depths[..n * k],
            &self.norms[..n],
        );
        let sigma = grow(&mut self.sigma, n * k);
        let rgb = grow(&mut self.rgb, 3 * n * k);
        field.forward(points, sigma, rgb);
        if let Some((clip, ..)) = clip {
            for (s, p) in sigma.iter_mut().zip(points.chunks_exact(3)) {
                if !clip.contains(p) {
                    *s = S::ZERO;
                }
            }
        }
        let out = grow(&mut self.out, n);
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
            let (a, b) = (c * CHUNK * k, (c * CHUNK + out.len()) * k);
            composite_batch(
                k,
                &sigma[a..b],
                &rgb[3 * a..3 * b],
                &depths[a..b],
                &norms[c * CHUNK..c * CHUNK + out.len()],
                settings
                    .background
                    .map(|b| b.map(|v| S::from_f64(v.into()))),
                settings.last_interval,
                out,
            );
        });
        &self.out[..n]
    }

    /// Reverse pass of the last [`Renderer::forward`] from the cotangents `grad` of its outputs:
    /// adds the field's parameter gradient into `grad_params` when given (`None`: the field is
    /// held fixed, [`RadianceField::backward_points`]) and, when `pose_grads` is given (one per
    /// camera), each ray's contribution to its camera's pose gradient.
    pub fn backward(
        &mut self,
        field: &mut dyn RadianceField<S>,
        settings: &RenderSettings,
        rays: &[CameraRay],
        grad: &[Composited<S>],
        grad_params: Option<&mut [S]>,
        pose_grads: Option<&mut [PoseGradient]>,
    ) {
        let (n, k) = (rays.len(), settings.samples);
        assert_eq!(grad.len(), n, "one cotangent per ray");
        let (depths, sigma, rgb, norms) = (
            &self.depths[..n * k],
            &self.sigma[..n * k],
            &self.rgb[..3 * n * k],
            &self.norms[..n],
        );
        let grad_sigma = grow(&mut self.grad_sigma, n * k);
        let grad_rgb = grow(&mut self.grad_rgb, 3 * n * k);
        grad_sigma
            .par_chunks_mut(CHUNK * k)
            .zip(grad_rgb.par_chunks_mut(3 * CHUNK * k))
            .enumerate()
            .for_each(|(c, (gs, gc))| {
                let rays_here = gs.len() / k;
                let (a, b) = (c * CHUNK * k, c * CHUNK * k + gs.len());
                let r = c * CHUNK..c * CHUNK + rays_here;
                composite_batch_backward(
                    k,
                    &sigma[a..b],
                    &rgb[3 * a..3 * b],
                    &depths[a..b],
                    &norms[r.clone()],
                    settings
                        .background
                        .map(|b| b.map(|v| S::from_f64(v.into()))),
                    settings.last_interval,
                    &grad[r],
                    gs,
                    gc,
                );
            });
        if let Some((clip, ..)) = settings.metric_clip() {
            for (g, p) in grad_sigma.iter_mut().zip(self.points.chunks_exact(3)) {
                if !clip.contains(p) {
                    *g = S::ZERO;
                }
            }
        }
        let grad_points = grow(&mut self.grad_points, 3 * n * k);
        match grad_params {
            Some(grad_params) => field.backward(grad_sigma, grad_rgb, grad_params, grad_points),
            None => field.backward_points(grad_sigma, grad_rgb, grad_points),
        }
        let Some(pose_grads) = pose_grads else {
            return;
        };
        for (r, ray) in rays.iter().enumerate() {
            let (mut g_o, mut g_d) = ([0.0f64; 3], [0.0f64; 3]);
            for j in 0..k {
                let s = depths[r * k + j].to_f64();
                for c in 0..3 {
                    let g = grad_points[3 * (r * k + j) + c].to_f64();
                    g_o[c] += g;
                    g_d[c] += s * g;
                }
            }
            pose_grads[ray.camera].add_ray(ray.d_cam, g_o, g_d);
        }
    }
}

#[cfg(test)]
mod tests {
    use cpose_core::geometry::se3_exp;
    use nalgebra::{Translation3, UnitQuaternion, Vector6};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::camera::PinholeCamera;
    use crate::field3d::{HashGridConfig, SceneBounds};

    fn field() -> crate::field3d::HashGridField<f64> {
        let config = HashGridConfig {
            levels: 3,
            base_resolution: 4,
            finest_resolution: 16,
            width: 16,
            hidden_layers: 1,
            c2f: None,
            ..HashGridConfig::default()
        };
        let mut field = config
            .init::<f64>(SceneBounds {
                centre: [0.0; 3],
                radius: 1.5,
                unbounded: false,
            })
            .expect("valid config");
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let grid = field.grid_range();
        for v in &mut field.params_mut()[grid] {
            *v = rng.random_range(-1.0..1.0);
        }
        field
    }

    /// The chord through the clip sphere, cut by `[near, far]`, with one stratum beyond it.
    #[test]
    fn clip_interval_is_the_chord_plus_one_stratum() {
        let clip = Clip {
            centre: [0.0, 1.0, 0.0],
            radius: 1.0,
        };
        // Along z through the centre: enters at s = 3, leaves at 5; b' = (8·5 − 3)/7.
        let (a, b) = clip
            .interval([0.0, 1.0, -4.0], [0.0, 0.0, 1.0], 2.0, 6.0, 8)
            .expect("hits");
        assert!((a - 3.0).abs() < 1e-12 && (b - 37.0 / 7.0).abs() < 1e-12);
        // Seven strata of (b − a)/8 end exactly at the exit.
        assert!((a + 7.0 * (b - a) / 8.0 - 5.0).abs() < 1e-12);
        // A non-unit direction measures s in its own units; near cuts the chord.
        let (a, _) = clip
            .interval([0.0, 1.0, -1.5], [0.0, 0.0, 0.5], 2.0, 6.0, 8)
            .expect("hits");
        assert!((a - 2.0).abs() < 1e-12);
        // Misses: beside the sphere, or the sphere beyond far.
        assert_eq!(
            clip.interval([0.0, 2.5, -4.0], [0.0, 0.0, 1.0], 2.0, 6.0, 8),
            None
        );
        assert_eq!(
            clip.interval([0.0, 1.0, -9.0], [0.0, 0.0, 1.0], 2.0, 6.0, 8),
            None
        );
    }

    /// With a clip sphere a ray that misses it is the background exactly, and a ray through
    /// it samples inside the sphere except for its last sample, beyond the exit.
    #[test]
    fn clipped_rays_sample_inside_the_sphere() {
        let mut field = field();
        let settings = RenderSettings {
            last_interval: LastInterval::Closed,
            samples: 16,
            sampling: Sampling::Metric {
                near: 2.0,
                far: 6.0,
            },
            background: Some([1.0, 0.9, 0.8]),
            clip: Some(Clip {
                centre: [0.0; 3],
                radius: 1.0,
            }),
        };
        let pose = Isometry3::translation(0.0, 0.0, -4.0);
        let rays = [
            CameraRay::new(0, &pose, [0.05, -0.1, 1.0]),
            CameraRay::new(0, &pose, [0.5, 0.0, 1.0]),
        ];
        let mut renderer = Renderer::<f64>::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let out = renderer.forward(&mut field, &settings, &rays, Some(&mut rng))[..2].to_vec();
        assert!(out[0].opacity > 0.0);
        let bg = [1.0f32, 0.9, 0.8].map(f64::from);
        assert_eq!(out[1].rgb, bg);
        assert_eq!(out[1].opacity, 0.0);
        let inside: Vec<bool> = renderer.points[..3 * 16]
            .chunks(3)
            .map(|p| p.iter().map(|v| v * v).sum::<f64>() <= 1.0)
            .collect();
        assert!(inside[..15].iter().all(|&i| i) && !inside[15], "{inside:?}");
    }

    /// Offsets drawn from a seed render exactly as `forward` with that seed, and a ray repeated
    /// with its offsets repeated renders the same twice.
    #[test]
    fn caller_offsets_render_as_the_drawn_jitter() {
        let mut field = field();
        let settings = RenderSettings {
            last_interval: LastInterval::Closed,
            samples: 8,
            sampling: Sampling::Metric {
                near: 2.0,
                far: 6.0,
            },
            background: Some([1.0; 3]),
            clip: Some(Clip {
                centre: [0.0; 3],
                radius: 1.5,
            }),
        };
        let pose = Isometry3::translation(0.1, 0.0, -4.0);
        let rays = [
            CameraRay::new(0, &pose, [0.05, -0.1, 1.0]),
            CameraRay::new(0, &pose, [-0.2, 0.1, 1.0]),
        ];
        let mut renderer = Renderer::<f64>::default();
        let drawn = renderer
            .forward(
                &mut field,
                &settings,
                &rays,
                Some(&mut ChaCha8Rng::seed_from_u64(4)),
            )
            .to_vec();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let offsets: Vec<f64> = (0..16).map(|_| rng.random()).collect();
        let given = renderer
            .forward_with_offsets(&mut field, &settings, &rays, &offsets)
            .to_vec();
        assert_eq!(drawn, given);
        let pair = [rays[1], rays[1]];
        let twice = [&offsets[8..], &offsets[8..]].concat();
        let out = renderer.forward_with_offsets(&mut field, &settings, &pair, &twice);
        assert_eq!(out[0], given[1]);
        assert_eq!(out[1], given[1]);
    }

    /// `Σ_r a_r·C_r + b_r D_r + c_r A_r` of the rays through `pixels` of a camera at `pose`, and
    /// the pose gradient of the right perturbation.
    fn loss(
        field: &mut crate::field3d::HashGridField<f64>,
        pose: &Isometry3<f64>,
        grad: bool,
    ) -> (f64, Vector6<f64>) {
        let camera = PinholeCamera::from_fov_x(40, 30, 0.8);
        let settings = RenderSettings {
            last_interval: LastInterval::Closed,
            samples: 24,
            sampling: Sampling::Metric {
                near: 2.0,
                far: 6.0,
            },
            background: Some([1.0, 0.9, 0.8]),
            clip: None,
        };
        let rays: Vec<CameraRay> = [(3, 4), (20, 15), (35, 27), (11, 22), (28, 6)]
            .iter()
            .map(|&(x, y)| CameraRay::new(0, pose, camera.ray_direction_cam(x, y)))
            .collect();
        let cot: Vec<Composited<f64>> = (0..rays.len())
            .map(|r| Composited {
                rgb: [0.5 - 0.2 * r as f64, 0.3, -0.7 + 0.1 * r as f64],
                depth: 0.05 * r as f64,
                opacity: -0.4,
            })
            .collect();
        let mut renderer = Renderer::<f64>::default();
        let out = renderer.forward(field, &settings, &rays, None::<&mut ChaCha8Rng>);
        let l = out
            .iter()
            .zip(&cot)
            .map(|(o, g)| {
                (0..3).map(|c| o.rgb[c] * g.rgb[c]).sum::<f64>()
                    + o.depth * g.depth
                    + o.opacity * g.opacity
            })
            .sum();
        if !grad {
            return (l, Vector6::zeros());
        }
        let mut sink = vec![0.0; field.num_params()];
        let mut pg = [PoseGradient::new()];
        renderer.backward(
            field,
            &settings,
            &rays,
            &cot,
            Some(&mut sink),
            Some(&mut pg),
        );
        // Holding the field fixed gives the same pose gradient, bit for bit.
        let mut fixed = [PoseGradient::new()];
        renderer.backward(field, &settings, &rays, &cot, None, Some(&mut fixed));
        assert_eq!(fixed[0].right_se3(pose), pg[0].right_se3(pose));
        (l, pg[0].right_se3(pose))
    }

    /// The pose gradient through rays, samples, the field and compositing, against central
    /// differences of `pose · Exp(δ)`.
    #[test]
    fn pose_gradient_through_the_renderer_matches_central_differences() {
        let mut field = field();
        let pose = crate::scene::look_at(
            &Vector3::new(3.5, -1.5, 1.2),
            &Vector3::new(0.1, 0.0, 0.2),
            &Vector3::z(),
        );
        let pose = Isometry3::from_parts(
            Translation3::from(pose.translation.vector),
            pose.rotation * UnitQuaternion::from_euler_angles(0.02, -0.03, 0.01),
        );
        let (_, g) = loss(&mut field, &pose, true);
        assert!(
            g.norm() > 1e-3,
            "a gradient that is all but zero tests nothing: {g}"
        );
        let h = 1e-6;
        for k in 0..6 {
            let mut xi = Vector6::zeros();
            xi[k] = h;
            let (lp, _) = loss(&mut field, &(pose * se3_exp(&xi)), false);
            let (lm, _) = loss(&mut field, &(pose * se3_exp(&(-xi))), false);
            let fd = (lp - lm) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-5 * (1.0 + fd.abs()),
                "δ[{k}]: fd {fd} vs {}",
                g[k]
            );
        }
    }
}
