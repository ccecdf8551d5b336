//! A synthetic textured 3-D scene, ray-cast exactly, for NeRF from noisy poses (the paper's
//! §4.1.2 and its supplement): the scene ([`SyntheticScene`], shapes and textures in
//! [`primitives`]), the monocular orbit ([`MonocularOrbit`]), pose perturbations
//! ([`PoseNoise`]) and a rendered sequence ([`render_sequence`]).
//!
//! # Conventions
//!
//! * World `z` is up; cameras use OpenCV axes and BARF's pixel-centre rays ([`crate::camera`]):
//!   pixel `(x, y)` looks along `d_cam = K⁻¹ [x + ½, y + ½, 1]ᵀ` (`z = 1`, not normalised).
//! * Ray parameters `t` are in units of the (unnormalised) direction, so for a camera ray `t` is
//!   the camera `z`-depth of the hit.
//! * Colours are linear RGB in `[0, 1]`. A surface's colour is its texture's albedo times a
//!   fixed Lambertian shading, `albedo · (AMBIENT + (1 − AMBIENT) · max(0, n·l))`
//!   ([`AMBIENT`], [`LIGHT_DIRECTION`]), with `n` the normal facing the side the ray came from.
//!   Nothing depends on the viewing direction (NeRF here has no view dependence); a two-sided
//!   surface (a disk) may be shaded differently on its two sides.
//! * There are no shadows or reflections.
//!
//! This is not a general renderer: no acceleration structure (scenes have ~10 objects), no
//! materials beyond albedo and one light.

use nalgebra::{Isometry3, Unit, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::camera::PinholeCamera;
use crate::data::Dataset;
use crate::image::Image;

pub mod noise;
pub mod orbit;
pub mod primitives;

pub use noise::{AnchorDraws, PoseNoise};
pub use orbit::{MonocularOrbit, look_at};
pub use primitives::{Shape, Texture};

/// Errors of the scene's configuration; each names the TOML key at fault.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A parameter is out of its range.
    #[error("{key}: expected {expected}, got {found}")]
    Invalid {
        /// The key, e.g. `orbit.frames`.
        key: &'static str,
        /// What the key must satisfy.
        expected: &'static str,
        /// The value found.
        found: String,
    },
}

/// Smallest ray parameter accepted as a hit (in units of `|d|`), so that a ray starting on a
/// surface does not hit it again at `t ≈ 0`.
pub const T_MIN: f64 = 1e-9;

/// Fraction of the albedo a surface facing away from the light keeps.
pub const AMBIENT: f64 = 0.35;

/// Unit direction towards the light (world frame; from above, slightly to the side), unnormalised
/// components `(0.4, −0.3, 0.85)`.
pub const LIGHT_DIRECTION: [f64; 3] = [0.405_616_1, -0.304_212_1, 0.861_934_2];

/// Horizontal field of view of [`experiment_camera`], degrees.
pub const EXPERIMENT_FOV_X_DEG: f64 = 40.0;

/// Enlargement of [`SyntheticScene::object_centric`] from its design coordinates.
const OBJECT_CENTRIC_SCALE: f64 = 1.25;

/// Image side of [`experiment_camera`], pixels.
pub const EXPERIMENT_IMAGE_SIZE: usize = 100;

/// The camera of the synthetic experiment: 100 × 100 pixels, horizontal field of view 40°
/// (focal length `50 / tan 20° ≈ 137.4` px), principal point at the centre. From the orbit's
/// 4 units the view spans `±1.46` units at the origin, so [`SyntheticScene::object_centric`]
/// spans about two thirds of the width and covers 20–25 % of the pixels in every view of
/// [`MonocularOrbit::default`].
pub fn experiment_camera() -> PinholeCamera {
    PinholeCamera::from_fov_x(
        EXPERIMENT_IMAGE_SIZE,
        EXPERIMENT_IMAGE_SIZE,
        EXPERIMENT_FOV_X_DEG.to_radians(),
    )
}

/// A shape with its texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// Geometry.
    pub shape: Shape,
    /// Albedo.
    pub texture: Texture,
}

/// Objects and a background colour.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticScene {
    /// The objects; overlapping objects are fine (the nearest surface wins).
    pub objects: Vec<Object>,
    /// Colour of rays that hit nothing (linear RGB).
    pub background: [f64; 3],
}

/// The nearest surface along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter: the hit is at `origin + t · direction` (the camera depth for `d_cam.z = 1`).
    pub t: f64,
    /// Shaded colour (linear RGB).
    pub rgb: [f64; 3],
    /// Unit normal facing the ray's origin (`n · direction < 0`).
    pub normal: Vector3<f64>,
    /// Index of the object hit in [`SyntheticScene::objects`].
    pub object: usize,
}

/// One rendered view.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedView {
    /// Colour, averaged over the `s × s` sub-pixel rays.
    pub image: Image,
    /// Camera `z`-depth of the surface hit by each pixel's centre ray (row-major,
    /// `width · height` values); `f32::INFINITY` where the centre ray hits nothing.
    pub depth: Vec<f32>,
    /// Fraction of each pixel's sub-pixel rays that hit a surface, in `[0, 1]` (row-major).
    pub coverage: Vec<f32>,
}

/// A rendered orbit: the images with ground-truth poses, their times and depth maps.
#[derive(Clone, Debug)]
pub struct SyntheticSequence {
    /// Images, ground-truth `world_from_camera`, the camera, no bounds, names `frame_000.png`, ….
    pub dataset: Dataset,
    /// Frame times, seconds since frame 0 ([`MonocularOrbit::frame_times`]).
    pub times: Vec<f64>,
    /// Depth map per frame ([`RenderedView::depth`]).
    pub depths: Vec<Vec<f32>>,
}

/// Renders every frame of `orbit` (in parallel) with `supersample × supersample` rays per pixel.
/// `orbit` should be [validated](MonocularOrbit::validate).
pub fn render_sequence(
    scene: &SyntheticScene,
    camera: &PinholeCamera,
    orbit: &MonocularOrbit,
    supersample: usize,
) -> SyntheticSequence {
    let times = orbit.frame_times();
    let poses: Vec<Isometry3<f64>> = times.iter().map(|&t| orbit.world_from_camera(t)).collect();
    let views: Vec<RenderedView> = poses
        .par_iter()
        .map(|pose| scene.render(camera, pose, supersample))
        .collect();
    let names = (0..times.len())
        .map(|i| format!("frame_{i:03}.png"))
        .collect();
    let (images, depths) = views.into_iter().map(|v| (v.image, v.depth)).unzip();
    SyntheticSequence {
        dataset: Dataset {
            images,
            world_from_camera: poses,
            camera: *camera,
            bounds: None,
            names,
        },
        times,
        depths,
    }
}

impl SyntheticScene {
    /// The nearest surface hit by `origin + t · direction` with `t > T_MIN`.
    pub fn trace(&self, origin: &Vector3<f64>, direction: &Vector3<f64>) -> Option<Hit> {
        let mut best: Option<(f64, Vector3<f64>, usize)> = None;
        for (k, object) in self.objects.iter().enumerate() {
            let t_max = best.map_or(f64::INFINITY, |b| b.0);
            if let Some((t, n)) = object.shape.intersect(origin, direction, T_MIN, t_max) {
                best = Some((t, n, k));
            }
        }
        let (t, n, k) = best?;
        // Face the side the ray came from.
        let normal = if n.dot(direction) > 0.0 { -n } else { n };
        let albedo = self.objects[k].texture.albedo(&(origin + direction * t));
        let light = Vector3::from(LIGHT_DIRECTION);
        let shade = AMBIENT + (1.0 - AMBIENT) * normal.dot(&light).max(0.0);
        Some(Hit {
            t,
            rgb: albedo.map(|c| c * shade),
            normal,
            object: k,
        })
    }

    /// Renders the view of `camera` at `world_from_camera`. Each pixel averages the colours of
    /// `s × s` rays through the sub-pixel points `(x + (i + ½)/s, y + (j + ½)/s)`, `s =
    /// supersample` (box-filter anti-aliasing); the depth comes from the pixel-centre ray
    /// `(x + ½, y + ½)`. Rows are rendered in parallel.
    ///
    /// # Panics
    /// If `supersample` is 0 or the camera has no pixels.
    pub fn render(
        &self,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
        supersample: usize,
    ) -> RenderedView {
        assert!(supersample >= 1, "supersample must be ≥ 1");
        let (w, h) = (camera.width, camera.height);
        assert!(w >= 1 && h >= 1, "camera has no pixels: {w}×{h}");
        let s = supersample;
        let origin = world_from_camera.translation.vector;
        let rotation = world_from_camera.rotation.to_rotation_matrix();
        let ray = |u: f64, v: f64| rotation * Vector3::from(camera.direction_at(u, v));
        let rows: Vec<(Vec<f32>, Vec<f32>, Vec<f32>)> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut rgb = Vec::with_capacity(3 * w);
                let mut depth = Vec::with_capacity(w);
                let mut coverage = Vec::with_capacity(w);
                for x in 0..w {
                    let mut sum = [0.0; 3];
                    let mut hits = 0usize;
                    let mut centre_depth = f64::INFINITY;
                    for j in 0..s {
                        for i in 0..s {
                            let (du, dv) =
                                ((i as f64 + 0.5) / s as f64, (j as f64 + 0.5) / s as f64);
                            let hit = self.trace(&origin, &ray(x as f64 + du, y as f64 + dv));
                            let c = match hit {
                                Some(hit) => {
                                    hits += 1;
                                    if 2 * i + 1 == s && 2 * j + 1 == s {
                                        centre_depth = hit.t; // odd s: the centre sample
                                    }
                                    hit.rgb
                                }
                                None => self.background,
                            };
                            for k in 0..3 {
                                sum[k] += c[k];
                            }
                        }
                    }
                    if s.is_multiple_of(2) {
                        let centre = self.trace(&origin, &ray(x as f64 + 0.5, y as f64 + 0.5));
                        centre_depth = centre.map_or(f64::INFINITY, |hit| hit.t);
                    }
                    let n = (s * s) as f64;
                    rgb.extend(sum.map(|c| (c / n) as f32));
                    depth.push(centre_depth as f32);
                    coverage.push((hits as f64 / n) as f32);
                }
                (rgb, depth, coverage)
            })
            .collect();
        let mut rgb = Vec::with_capacity(3 * w * h);
        let mut depth = Vec::with_capacity(w * h);
        let mut coverage = Vec::with_capacity(w * h);
        for (r, d, c) in rows {
            rgb.extend(r);
            depth.extend(d);
            coverage.extend(c);
        }
        RenderedView {
            image: Image::new(w, h, rgb).expect("w·h RGB values of a camera with pixels"),
            depth,
            coverage,
        }
    }

    /// Radius of the smallest ball about the world origin containing every object (exact per
    /// shape, see [`Shape::farthest_distance`]); `∞` if the scene has a plane.
    pub fn bounding_radius(&self) -> f64 {
        self.objects
            .iter()
            .map(|o| o.shape.farthest_distance(&Vector3::zeros()))
            .fold(0.0, f64::max)
    }

    /// The default object-centric scene, a small stand-in for Blender's "lego": nine textured
    /// objects (boxes, spheres, cylinders, a disk; some stacked or intersecting) on a checkered
    /// slab, all within a ball of radius ≈ 1.31 about the origin
    /// ([`SyntheticScene::bounding_radius`]), on a white background. Asymmetric, and textured
    /// on every side seen from the [`MonocularOrbit`] (heights above the slab).
    pub fn object_centric() -> Self {
        let z_rot =
            |deg: f64| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), deg.to_radians());
        let dir = |x: f64, y: f64, z: f64| Unit::new_normalize(Vector3::new(x, y, z));
        // Designed at unit scale, enlarged by `k` about the origin (texture scales unchanged).
        let k = OBJECT_CENTRIC_SCALE;
        let v = |x: f64, y: f64, z: f64| Vector3::new(x, y, z) * k;
        let objects = vec![
            // The base slab, top at z = −0.39.
            Object {
                shape: Shape::Box {
                    centre: v(0.0, 0.0, -0.45),
                    half_extents: v(0.72, 0.56, 0.06),
                    rotation: z_rot(20.0),
                },
                texture: Texture::Checker {
                    a: [0.85, 0.8, 0.65],
                    b: [0.25, 0.3, 0.45],
                    scale: 0.18,
                },
            },
            // A tower standing on the slab.
            Object {
                shape: Shape::Box {
                    centre: v(-0.3, 0.15, -0.05),
                    half_extents: v(0.22, 0.3, 0.34),
                    rotation: z_rot(-25.0),
                },
                texture: Texture::Marble {
                    a: [0.8, 0.15, 0.1],
                    b: [0.95, 0.8, 0.3],
                    period: 0.3,
                    direction: dir(0.3, 0.5, 0.8),
                    turbulence: 0.8,
                    seed: 1,
                },
            },
            // A striped ball sunk a little into the tower's top.
            Object {
                shape: Shape::Sphere {
                    centre: v(-0.3, 0.15, 0.45),
                    radius: 0.2 * k,
                },
                texture: Texture::Stripes {
                    a: [0.15, 0.3, 0.8],
                    b: [0.9, 0.9, 0.85],
                    period: 0.16,
                    direction: dir(0.2, 0.3, 1.0),
                },
            },
            // A green column.
            Object {
                shape: Shape::Cylinder {
                    centre: v(0.4, -0.25, -0.1),
                    axis: Vector3::z_axis(),
                    half_height: 0.29 * k,
                    radius: 0.16 * k,
                },
                texture: Texture::Noise {
                    a: [0.1, 0.35, 0.1],
                    b: [0.6, 0.85, 0.4],
                    scale: 0.12,
                    seed: 2,
                },
            },
            // A tilted plate on top of the column.
            Object {
                shape: Shape::Disk {
                    centre: v(0.4, -0.25, 0.21),
                    normal: dir(0.3, -0.2, 1.0),
                    radius: 0.26 * k,
                },
                texture: Texture::Checker {
                    a: [0.85, 0.2, 0.6],
                    b: [0.95, 0.85, 0.2],
                    scale: 0.11,
                },
            },
            // A small ball resting on the slab.
            Object {
                shape: Shape::Sphere {
                    centre: v(0.35, 0.3, -0.24),
                    radius: 0.15 * k,
                },
                texture: Texture::Checker {
                    a: [0.95, 0.5, 0.1],
                    b: [0.35, 0.1, 0.45],
                    scale: 0.1,
                },
            },
            // A log lying on the slab.
            Object {
                shape: Shape::Cylinder {
                    centre: v(0.0, -0.42, -0.29),
                    axis: dir(1.0, 0.4, 0.0),
                    half_height: 0.3 * k,
                    radius: 0.1 * k,
                },
                texture: Texture::Stripes {
                    a: [0.45, 0.25, 0.1],
                    b: [0.9, 0.75, 0.55],
                    period: 0.12,
                    direction: dir(1.0, 0.4, 0.0),
                },
            },
            // A tilted cube sunk into the slab.
            Object {
                shape: Shape::Box {
                    centre: v(0.05, 0.42, -0.27),
                    half_extents: v(0.13, 0.13, 0.13),
                    rotation: UnitQuaternion::from_euler_angles(0.5, 0.6, 0.3),
                },
                texture: Texture::Noise {
                    a: [0.1, 0.5, 0.6],
                    b: [0.8, 0.95, 0.95],
                    scale: 0.1,
                    seed: 3,
                },
            },
            // A low wide drum at the front corner.
            Object {
                shape: Shape::Cylinder {
                    centre: v(-0.45, -0.35, -0.33),
                    axis: Vector3::z_axis(),
                    half_height: 0.06 * k,
                    radius: 0.2 * k,
                },
                texture: Texture::Marble {
                    a: [0.2, 0.2, 0.25],
                    b: [0.75, 0.75, 0.8],
                    period: 0.15,
                    direction: dir(1.0, 0.0, 0.2),
                    turbulence: 1.2,
                    seed: 4,
                },
            },
        ];
        Self {
            objects,
            background: [1.0; 3],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::primitives::surface_distance;

    /// Luminance of pixel `(x, y)`.
    fn lum(img: &Image, x: usize, y: usize) -> f32 {
        let p = img.pixel(x, y);
        0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]
    }

    /// (object coverage fraction, mean |∇ lum| over neighbour pairs inside the object,
    /// fraction of fully covered 10×10 blocks with luminance std > 0.02).
    fn view_stats(view: &RenderedView) -> (f64, f64, f64) {
        let img = &view.image;
        let (w, h) = (img.width(), img.height());
        let inside = |x: usize, y: usize| view.coverage[y * w + x] == 1.0;
        let covered = view.coverage.iter().map(|&c| f64::from(c)).sum::<f64>() / (w * h) as f64;
        let (mut grad, mut pairs) = (0.0, 0usize);
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                if inside(x, y) && inside(x + 1, y) && inside(x, y + 1) {
                    grad += f64::from((lum(img, x + 1, y) - lum(img, x, y)).abs());
                    grad += f64::from((lum(img, x, y + 1) - lum(img, x, y)).abs());
                    pairs += 2;
                }
            }
        }
        let (mut blocks, mut textured) = (0usize, 0usize);
        for by in (0..h - 9).step_by(10) {
            for bx in (0..w - 9).step_by(10) {
                let vals: Vec<f64> = (0..100)
                    .filter(|i| inside(bx + i % 10, by + i / 10))
                    .map(|i| f64::from(lum(img, bx + i % 10, by + i / 10)))
                    .collect();
                if vals.len() == 100 {
                    blocks += 1;
                    let mean = vals.iter().sum::<f64>() / 100.0;
                    let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 100.0;
                    if var.sqrt() > 0.02 {
                        textured += 1;
                    }
                }
            }
        }
        (
            covered,
            grad / pairs.max(1) as f64,
            textured as f64 / blocks.max(1) as f64,
        )
    }

    #[test]
    fn every_orbit_view_is_framed_and_textured() {
        let scene = SyntheticScene::object_centric();
        let r = scene.bounding_radius();
        assert!(r > 1.0 && r < 1.4, "{r}");
        let cam = experiment_camera();
        let orbit = MonocularOrbit::default();
        for t in orbit.frame_times() {
            let view = scene.render(&cam, &orbit.world_from_camera(t), 1);
            let (covered, grad, textured_blocks) = view_stats(&view);
            // Observed: coverage 0.20–0.25, gradient ≥ 0.054, every block textured.
            assert!((0.15..=0.7).contains(&covered), "t {t}: coverage {covered}");
            assert!(grad > 0.03, "t {t}: mean |∇ lum| inside the object {grad}");
            assert!(
                textured_blocks >= 0.9,
                "t {t}: textured blocks {textured_blocks}"
            );
        }
    }

    #[test]
    fn depth_map_points_lie_on_the_surfaces() {
        let scene = SyntheticScene::object_centric();
        let cam = experiment_camera();
        let pose = MonocularOrbit::default().world_from_camera(13.5); // a held-out time
        let view = scene.render(&cam, &pose, 1);
        let (w, h) = (cam.width, cam.height);
        let mut hits = 0;
        for y in 0..h {
            for x in 0..w {
                let depth = view.depth[y * w + x];
                if depth.is_finite() {
                    hits += 1;
                    assert_eq!(view.coverage[y * w + x], 1.0);
                    let p = cam.world_ray(&pose, x, y).at(f64::from(depth));
                    let d = scene
                        .objects
                        .iter()
                        .map(|o| surface_distance(&o.shape, &p))
                        .fold(f64::INFINITY, f64::min);
                    // f32 depth: relative rounding 6e-8 of a depth ≈ 4.
                    assert!(d < 1e-5, "pixel ({x}, {y}): {d} off the surface");
                    // Nothing is in front: the ray to just before the hit is clear.
                    let ray = cam.world_ray(&pose, x, y);
                    let t = f64::from(depth);
                    let nearer = scene
                        .objects
                        .iter()
                        .filter_map(|o| {
                            o.shape
                                .intersect(&ray.origin, &ray.direction, T_MIN, t - 1e-4)
                        })
                        .count();
                    assert_eq!(nearer, 0, "pixel ({x}, {y})");
                } else {
                    assert_eq!(view.coverage[y * w + x], 0.0);
                    assert_eq!(view.image.pixel(x, y), [1.0; 3]);
                }
            }
        }
        assert!(hits > w * h / 10);
        // The depth comes from the pixel-centre ray whatever the supersampling.
        for s in [2, 3] {
            let view_s = scene.render(&cam, &pose, s);
            assert_eq!(view_s.depth, view.depth, "s = {s}");
            assert!(view_s.coverage.iter().any(|&c| c > 0.0 && c < 1.0));
            assert!(view_s.image.data().iter().all(|v| (0.0..=1.0).contains(v)));
            // Supersampling changes edges and fine texture only.
            let diff = view_s
                .image
                .data()
                .iter()
                .zip(view.image.data())
                .map(|(a, b)| f64::from((a - b).abs()))
                .sum::<f64>()
                / view.image.data().len() as f64;
            assert!(diff > 1e-4 && diff < 0.05, "s = {s}: mean change {diff}");
        }
    }

    #[test]
    fn trace_takes_the_nearest_surface_and_shades_it() {
        let albedo = [0.8, 0.6, 0.4];
        let sphere = |x: f64| Object {
            shape: Shape::Sphere {
                centre: Vector3::new(x, 0.0, 0.0),
                radius: 1.0,
            },
            texture: Texture::Solid(albedo),
        };
        // The farther sphere first in the list: order does not matter.
        let scene = SyntheticScene {
            objects: vec![sphere(1.5), sphere(0.0)],
            background: [0.0; 3],
        };
        let o = Vector3::new(0.0, 0.0, 5.0);
        let hit = scene.trace(&o, &-Vector3::z()).unwrap();
        assert_eq!(hit.object, 1);
        assert!((hit.t - 4.0).abs() < 1e-12);
        assert!((hit.normal - Vector3::z()).norm() < 1e-12);
        let shade = AMBIENT + (1.0 - AMBIENT) * LIGHT_DIRECTION[2];
        for k in 0..3 {
            assert!((hit.rgb[k] - albedo[k] * shade).abs() < 1e-12);
        }
        // From below: the light is behind the surface, only the ambient part remains.
        let hit = scene.trace(&-o, &Vector3::z()).unwrap();
        assert!((hit.rgb[0] - albedo[0] * AMBIENT).abs() < 1e-12);
        assert!(scene.trace(&o, &Vector3::z()).is_none());
    }

    #[test]
    fn a_room_renders_from_inside() {
        let checker = Texture::Checker {
            a: [0.9, 0.9, 0.9],
            b: [0.2, 0.3, 0.4],
            scale: 0.5,
        };
        let scene = SyntheticScene {
            objects: vec![Object {
                shape: Shape::Box {
                    centre: Vector3::zeros(),
                    half_extents: Vector3::new(3.0, 2.5, 1.5),
                    rotation: UnitQuaternion::identity(),
                },
                texture: checker,
            }],
            background: [1.0, 0.0, 0.0],
        };
        let cam = PinholeCamera::from_fov_x(20, 20, 90f64.to_radians());
        let pose = look_at(&Vector3::zeros(), &Vector3::x(), &Vector3::z());
        let view = scene.render(&cam, &pose, 2);
        assert!(view.coverage.iter().all(|&c| c == 1.0));
        assert!(view.depth.iter().all(|d| d.is_finite()));
        // Central pixels see the wall x = 3 at depth 3; the normal faces the camera.
        assert!((view.depth[10 * 20 + 10] - 3.0).abs() < 1e-6);
        let hit = scene.trace(&Vector3::zeros(), &Vector3::x()).unwrap();
        assert!((hit.normal + Vector3::x()).norm() < 1e-12);
    }

    #[test]
    fn render_sequence_fills_the_dataset() {
        let scene = SyntheticScene::object_centric();
        let cam = experiment_camera().scaled(0.2);
        let orbit = MonocularOrbit {
            frames: 4,
            ..Default::default()
        };
        let seq = render_sequence(&scene, &cam, &orbit, 2);
        assert_eq!(seq.times, [0.0, 1.0, 2.0, 3.0]);
        assert_eq!(seq.dataset.len(), 4);
        assert_eq!(seq.dataset.world_from_camera, orbit.poses());
        assert_eq!(seq.dataset.names[3], "frame_003.png");
        assert_eq!(seq.dataset.camera, cam);
        assert!(seq.dataset.bounds.is_none());
        assert_eq!(seq.depths.len(), 4);
        for (img, depth) in seq.dataset.images.iter().zip(&seq.depths) {
            assert_eq!((img.width(), img.height()), (20, 20));
            assert_eq!(depth.len(), 400);
        }
        let single = scene.render(&cam, &orbit.world_from_camera(2.0), 2);
        assert_eq!(seq.dataset.images[2], single.image);
        // The default camera: 100 × 100, 40° horizontal field of view, centred.
        let cam = experiment_camera();
        assert_eq!(
            (cam.width, cam.height, cam.cx, cam.cy),
            (100, 100, 50.0, 50.0)
        );
        assert!((2.0 * (50.0 / cam.fx).atan() - 40f64.to_radians()).abs() < 1e-12);
    }

    #[test]
    fn light_direction_is_unit() {
        let l = Vector3::from(LIGHT_DIRECTION);
        assert!((l.norm() - 1.0).abs() < 1e-6);
        assert!((l - Vector3::new(0.4, -0.3, 0.85).normalize()).norm() < 1e-6);
    }
}
