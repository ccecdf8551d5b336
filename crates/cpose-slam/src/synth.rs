//! A synthetic RGB-D stand-in for Replica: a procedural textured room ray-cast to colour and
//! metric depth along any camera trajectory, with a Kinect-like depth-noise model, written in
//! NICE-SLAM's Replica layout ([`crate::data::write_replica`]) so that it is read exactly as a
//! real Replica scene.
//!
//! * **Room** ([`room_scene`]): 6 × 5 × 2.8 m (x ∈ [−3, 3], y ∈ [−2.5, 2.5], z ∈ [0, 2.8], z up),
//!   four walls, floor and ceiling each with its own texture, and furniture: a table with things
//!   on it, a cabinet, a lamp pillar, boxes, a ball, a rug and a picture on the wall.
//! * **Camera**: Replica's (90° horizontal field of view) at a chosen width, `300 × 170` by
//!   default (a quarter of Replica's 1200 × 680).
//! * **Motion** ([`RoomMotion`]): a built-in hand-held walk (per axis a sum of four sines at
//!   0.03–0.25 Hz, up to ±0.8 m and ±35°; about 0.3 m/s, like TUM's fr1 sequences), or any recorded trajectory such as TUM's `groundtruth.txt`,
//!   replayed relative to its first pose from the room's start pose.
//! * **Depth noise** (Nguyen, Izadi and Lovell 2012, the Kinect's axial model):
//!   `z̃ = z + N(0, σ(z)²)`, `σ(z) = 0.0012 + 0.0019 (z − 0.4)²` m; no reading (0) where the
//!   surface is seen at more than 80° from its normal, nearer than 0.1 m or farther than 10 m.

use std::path::Path;

use cpose_core::eval::{Trajectory, read_tum};
use cpose_core::pose_field::sinusoid::SinusoidMotion;
use cpose_core::{Order, PoseBatch, PoseField, TimeRange};
use cpose_nerf::camera::PinholeCamera;
use cpose_nerf::image::Image;
use cpose_nerf::scene::{Object, Shape, SyntheticScene, Texture};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::data::{DepthImage, Intrinsics, REPLICA_INTRINSICS, RgbdError, write_replica};

/// Half the room's inner extent along x and y, metres (walls at `±3`, `±2.5`).
const ROOM_HALF: [f64; 2] = [3.0, 2.5];

/// The ceiling's height, metres.
const ROOM_HEIGHT: f64 = 2.8;

/// Largest angle between the viewing ray and the surface normal with a depth reading, degrees.
const DROPOUT_INCIDENCE_DEG: f64 = 80.0;

/// Depth readings outside `[MIN_RANGE, MAX_RANGE]` metres are missing.
const MIN_RANGE: f64 = 0.1;
const MAX_RANGE: f64 = 10.0;

/// What to generate. Every field has a default; `[synthetic]` in a config.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RoomConfig {
    /// Image width in pixels; the height and intrinsics follow Replica's camera (`f = W/2`).
    pub width: usize,
    /// Number of frames (a recorded trajectory may end sooner).
    pub frames: usize,
    /// Frames per second.
    pub frame_rate: f64,
    /// A TUM-format trajectory file to replay (relative to its first pose); none: the built-in
    /// hand-held walk.
    pub trajectory: Option<std::path::PathBuf>,
    /// Seconds of the recorded trajectory to skip before the first frame.
    pub trajectory_offset_s: f64,
    /// Kinect-like depth noise and dropout; `false` writes exact depth.
    pub depth_noise: bool,
    /// Sub-pixel rays per side for the colour (anti-aliasing).
    pub supersample: usize,
    /// Seed of the hand-held walk and of the depth noise.
    pub seed: u64,
    /// Size of the room and everything in it relative to the built-in 6 × 5 × 2.8 m (textures
    /// scale with it); `1.5` gives a 9 × 7.5 × 4.2 m hall, about EuRoC's flying room.
    pub scale: f64,
}

impl Default for RoomConfig {
    fn default() -> Self {
        Self {
            width: 300,
            frames: 500,
            frame_rate: 30.0,
            trajectory: None,
            trajectory_offset_s: 0.0,
            depth_noise: true,
            supersample: 2,
            seed: 0,
            scale: 1.0,
        }
    }
}

impl RoomConfig {
    /// Replica's intrinsics scaled to `width` (height `round(680 W / 1200)`).
    pub fn intrinsics(&self) -> Intrinsics {
        let s = self.width as f64 / REPLICA_INTRINSICS.width as f64;
        let height = (REPLICA_INTRINSICS.height as f64 * s).round() as usize;
        Intrinsics {
            width: self.width,
            height,
            fx: REPLICA_INTRINSICS.fx * s,
            fy: REPLICA_INTRINSICS.fy * s,
            // Continuous centre (c + ½) scales; back to integer-pixel coordinates.
            cx: (REPLICA_INTRINSICS.cx + 0.5) * s - 0.5,
            cy: (REPLICA_INTRINSICS.cy + 0.5) * height as f64 / REPLICA_INTRINSICS.height as f64
                - 0.5,
        }
    }

    /// The `[synthetic]` table at the defaults, commented, for tasks' default configs.
    pub const DEFAULT_TABLE: &str = include_str!("../defaults/room.toml");

    /// [`RoomConfig::validate`] as a task's check: the error names the config file and
    /// `[synthetic]`.
    pub fn check(&self, config: &cpose_core::Config) -> anyhow::Result<()> {
        self.validate()
            .map_err(|m| anyhow::anyhow!("{}: [synthetic]: {m}", config.path().display()))
    }

    /// Checks the values; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        if !(16..=4096).contains(&self.width) {
            return Err(format!("width = {} must lie in 16..=4096", self.width));
        }
        if self.frames < 2 {
            return Err(format!("frames = {} must be at least 2", self.frames));
        }
        if !(self.frame_rate.is_finite() && self.frame_rate > 0.0) {
            return Err(format!("frame_rate = {} must be positive", self.frame_rate));
        }
        if !(1..=8).contains(&self.supersample) {
            return Err(format!(
                "supersample = {} must lie in 1..=8",
                self.supersample
            ));
        }
        if !(self.scale.is_finite() && (0.1..=10.0).contains(&self.scale)) {
            return Err(format!("scale = {} must lie in [0.1, 10]", self.scale));
        }
        if !(self.trajectory_offset_s.is_finite() && self.trajectory_offset_s >= 0.0) {
            return Err(format!(
                "trajectory_offset_s = {} must be ≥ 0",
                self.trajectory_offset_s
            ));
        }
        Ok(())
    }
}

/// Where the room's camera starts: `world_from_rig` of a z-up rig at (−1.2, −0.3, 1.4) m,
/// facing +x (towards the table and the far wall) and pitched 15° down.
pub fn room_start() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(-1.2, -0.3, 1.4),
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 15f64.to_radians()),
    )
}

/// `rig_from_camera`: the OpenCV camera (z forward, x right, y down) looking along the rig's x
/// axis with the rig's z up.
pub fn rig_from_camera() -> UnitQuaternion<f64> {
    // Columns: the camera's x, y, z axes in rig coordinates.
    let m = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// The camera motion of a generated sequence, and its frame times.
pub struct RoomMotion {
    kind: MotionKind,
    frames: usize,
    frame_rate: f64,
}

enum MotionKind {
    /// The built-in hand-held walk: `world_from_camera(t) = start ∘ M(t) ∘ rig_from_camera`.
    Handheld(SinusoidMotion<f64>),
    /// A recorded camera trajectory `P(t)` replayed as `start ∘ rig_from_camera ∘ P(t₀)⁻¹ P(t)`
    /// (slerp and linear interpolation between its samples).
    Recorded {
        /// The recording.
        trajectory: Trajectory,
        /// Its time of the first frame.
        t0: f64,
    },
}

impl RoomMotion {
    /// The motion `config` asks for.
    pub fn from_config(config: &RoomConfig) -> Result<Self, RgbdError> {
        config.validate().map_err(|message| RgbdError::Layout {
            path: "[synthetic]".into(),
            message,
        })?;
        let duration = (config.frames - 1) as f64 / config.frame_rate;
        let kind = match &config.trajectory {
            None => {
                let range = TimeRange::new(0.0, duration.max(1e-3)).expect("a positive duration");
                let motion = SinusoidMotion::random(
                    range,
                    config.seed,
                    4,
                    0.8,
                    35f64.to_radians(),
                    0.03,
                    0.25,
                )
                .expect("the walk's constants are valid");
                MotionKind::Handheld(motion)
            }
            Some(path) => {
                let trajectory = read_tum(path).map_err(|e| RgbdError::Format {
                    path: path.clone(),
                    expected: "a TUM trajectory (t tx ty tz qx qy qz qw per line)".into(),
                    found: e.to_string(),
                })?;
                let t0 = trajectory.timestamps_secs()[0] + config.trajectory_offset_s;
                MotionKind::Recorded { trajectory, t0 }
            }
        };
        Ok(Self {
            kind,
            frames: config.frames,
            frame_rate: config.frame_rate,
        })
    }

    /// `world_from_camera` at the frame times `i / frame_rate`, `i < frames`, stopping early
    /// where a recording ends.
    pub fn camera_poses(&self) -> Vec<Isometry3<f64>> {
        let (frames, rate) = (self.frames, self.frame_rate);
        let start = room_start();
        let rig_cam = Isometry3::from_parts(Translation3::identity(), rig_from_camera());
        match &self.kind {
            MotionKind::Handheld(motion) => {
                let times: Vec<f64> = (0..frames).map(|i| i as f64 / rate).collect();
                let mut out = PoseBatch::default();
                // The walk was built for exactly these times (`from_config`).
                motion
                    .evaluate(&times, Order::Pose, &mut out)
                    .expect("frame times within the walk's range");
                (0..frames)
                    .map(|i| start * out.world_from_body(i) * rig_cam)
                    .collect()
            }
            MotionKind::Recorded { trajectory, t0 } => {
                let Some(first) = interpolate(trajectory, *t0) else {
                    return Vec::new();
                };
                let first_inv = first.inverse();
                (0..frames)
                    .map_while(|i| interpolate(trajectory, t0 + i as f64 / rate))
                    .map(|p| start * rig_cam * first_inv * p)
                    .collect()
            }
        }
    }
}

/// The pose of `trajectory` at `t` (slerp and linear interpolation), `None` outside its span.
fn interpolate(trajectory: &Trajectory, t: f64) -> Option<Isometry3<f64>> {
    let times = trajectory.timestamps_secs();
    let poses = trajectory.poses();
    if times.is_empty() || t < times[0] || t > times[times.len() - 1] {
        return None;
    }
    let k = times
        .partition_point(|&x| x <= t)
        .clamp(1, times.len().max(2) - 1);
    if times.len() == 1 {
        return Some(poses[0]);
    }
    let (a, b) = (&poses[k - 1], &poses[k]);
    let u = ((t - times[k - 1]) / (times[k] - times[k - 1])).clamp(0.0, 1.0);
    Some(Isometry3::from_parts(
        Translation3::from(a.translation.vector.lerp(&b.translation.vector, u)),
        a.rotation.slerp(&b.rotation, u),
    ))
}

/// Renders frame `index` at `world_from_camera` in `scene` enlarged `scale` times: colour with
/// `supersample²` rays per pixel, the depth of the pixel-centre ray with the noise model when
/// `noise` (seeded by `seed` and `index`, so a frame is the same whenever it is rendered).
pub fn render_frame(
    scene: &SyntheticScene,
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    supersample: usize,
    noise: bool,
    seed: u64,
    index: usize,
    scale: f64,
) -> (Image, DepthImage) {
    // The enlarged scene seen from `p` is the scene seen from `p / scale`, distances × scale.
    let mut unit_pose = *world_from_camera;
    unit_pose.translation.vector /= scale;
    let view = scene.render(camera, &unit_pose, supersample);
    let origin = unit_pose.translation.vector;
    let rotation = world_from_camera.rotation.to_rotation_matrix();
    let cos_max = DROPOUT_INCIDENCE_DEG.to_radians().cos();
    let (w, h) = (camera.width, camera.height);
    let depth: Vec<f32> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut rng = ChaCha8Rng::seed_from_u64(
                seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ ((index as u64) << 20) ^ y as u64,
            );
            let rotation = &rotation;
            (0..w)
                .map(move |x| {
                    let d = rotation * Vector3::from(camera.ray_direction_cam(x, y));
                    let Some(hit) = scene.trace(&origin, &d) else {
                        return 0.0;
                    };
                    let z = hit.t * scale; // camera z-depth (d_cam.z = 1)
                    if !noise {
                        return z as f32;
                    }
                    let cos = -hit.normal.dot(&d) / d.norm();
                    if cos < cos_max || !(MIN_RANGE..=MAX_RANGE).contains(&z) {
                        return 0.0;
                    }
                    let sigma = 0.0012 + 0.0019 * (z - 0.4).powi(2);
                    (z + sigma * gaussian(&mut rng)) as f32
                })
                .collect::<Vec<f32>>()
        })
        .collect();
    let depth = DepthImage::new(w, h, depth).expect("w·h values");
    (view.image, depth)
}

/// Generates the sequence `config` describes and writes it to `root` in the Replica layout.
/// Returns the number of frames written.
pub fn generate_room(
    config: &RoomConfig,
    root: &Path,
    on_frame: impl FnMut(usize, usize),
) -> Result<usize, RgbdError> {
    let motion = RoomMotion::from_config(config)?;
    let poses = motion.camera_poses();
    if poses.len() < 2 {
        return Err(RgbdError::Layout {
            path: config.trajectory.clone().unwrap_or_default(),
            message: "the trajectory covers fewer than two frames".into(),
        });
    }
    render_room(config, &poses, root, on_frame)
}

/// Renders the room from the cameras `world_from_camera` (with `config`'s camera, noise and
/// anti-aliasing; its motion settings are not used) and writes them to `root` in the Replica
/// layout. Returns the number of frames written.
pub fn render_room(
    config: &RoomConfig,
    poses: &[Isometry3<f64>],
    root: &Path,
    mut on_frame: impl FnMut(usize, usize),
) -> Result<usize, RgbdError> {
    let intrinsics = config.intrinsics();
    let camera = intrinsics.camera_for(intrinsics.width, intrinsics.height, root)?;
    let scene = room_scene();
    let n = poses.len();
    write_replica(root, &intrinsics, poses, |i| {
        on_frame(i, n);
        render_frame(
            &scene,
            &camera,
            &poses[i],
            config.supersample,
            config.depth_noise,
            config.seed,
            i,
            config.scale,
        )
    })?;
    Ok(n)
}

/// Where a recorded flight fits in the room enlarged `scale` times: the gravity-aligned
/// `room_from_world` (a turn about z by a multiple of 90° and a horizontal shift on a 10 cm
/// grid; heights unchanged) that keeps `positions` inside the walls and farthest from every
/// surface (the smallest distance to a surface along 26 directions, over all positions).
/// Returns it with that clearance, metres; the clearance is negative if no placement keeps
/// every position inside the room.
pub fn fit_in_room(positions: &[Vector3<f64>], scale: f64) -> (Isometry3<f64>, f64) {
    let scene = room_scene();
    let directions: Vec<Vector3<f64>> = (0..27)
        .filter(|&k| k != 13)
        .map(|k| {
            Vector3::new(
                (k % 3) as f64 - 1.0,
                ((k / 3) % 3) as f64 - 1.0,
                (k / 9) as f64 - 1.0,
            )
            .normalize()
        })
        .collect();
    // At most 200 positions, evenly spread over the flight.
    let step = positions.len().div_ceil(200).max(1);
    let probe: Vec<Vector3<f64>> = positions.iter().step_by(step).copied().collect();
    let clearance = |p: &Vector3<f64>| {
        let p = p / scale;
        if p.x.abs() >= ROOM_HALF[0]
            || p.y.abs() >= ROOM_HALF[1]
            || p.z <= 0.0
            || p.z >= ROOM_HEIGHT
        {
            return -1.0;
        }
        scale
            * directions
                .iter()
                .map(|d| scene.trace(&p, d).map_or(f64::INFINITY, |h| h.t))
                .fold(f64::INFINITY, f64::min)
    };
    let mut best = (Isometry3::identity(), f64::NEG_INFINITY);
    for quarter in 0..4 {
        let turn = UnitQuaternion::from_axis_angle(
            &Vector3::z_axis(),
            quarter as f64 * std::f64::consts::FRAC_PI_2,
        );
        let turned: Vec<Vector3<f64>> = probe.iter().map(|p| turn * p).collect();
        let lo = turned
            .iter()
            .fold(Vector3::repeat(f64::INFINITY), |a, p| a.inf(p));
        let hi = turned
            .iter()
            .fold(Vector3::repeat(f64::NEG_INFINITY), |a, p| a.sup(p));
        // Shifts around the one that centres the flight, ±0.8 m.
        let centre = -(lo + hi) / 2.0;
        for i in -8..=8 {
            for j in -8..=8 {
                let shift = Vector3::new(centre.x + 0.1 * i as f64, centre.y + 0.1 * j as f64, 0.0);
                let mut worst = f64::INFINITY;
                for p in &turned {
                    worst = worst.min(clearance(&(p + shift)));
                    if worst <= best.1 {
                        break;
                    }
                }
                if worst > best.1 {
                    best = (
                        Isometry3::from_parts(Translation3::from(shift), turn),
                        worst,
                    );
                }
            }
        }
    }
    best
}

/// A standard normal draw (Box–Muller).
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The procedural room (see the module documentation).
pub fn room_scene() -> SyntheticScene {
    let v = Vector3::new;
    let axis_box = |centre: Vector3<f64>, half: Vector3<f64>| Shape::Box {
        centre,
        half_extents: half,
        rotation: UnitQuaternion::identity(),
    };
    let z_box = |centre: Vector3<f64>, half: Vector3<f64>, deg: f64| Shape::Box {
        centre,
        half_extents: half,
        rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), f64::to_radians(deg)),
    };
    let dir = |x: f64, y: f64, z: f64| Unit::new_normalize(v(x, y, z));
    let object = |shape, texture| Object { shape, texture };
    let objects = vec![
        // Floor: wooden boards.
        object(
            axis_box(v(0.0, 0.0, -0.05), v(3.2, 2.7, 0.05)),
            Texture::Marble {
                a: [0.45, 0.3, 0.18],
                b: [0.7, 0.52, 0.32],
                period: 0.25,
                direction: dir(0.0, 1.0, 0.05),
                turbulence: 0.6,
                seed: 11,
            },
        ),
        // Ceiling: plaster.
        object(
            axis_box(v(0.0, 0.0, 2.85), v(3.2, 2.7, 0.05)),
            Texture::Noise {
                a: [0.78, 0.78, 0.74],
                b: [0.95, 0.95, 0.92],
                scale: 0.4,
                seed: 12,
            },
        ),
        // Far wall (x = 3): blotchy green paint.
        object(
            axis_box(v(3.05, 0.0, 1.4), v(0.05, 2.7, 1.5)),
            Texture::Noise {
                a: [0.35, 0.55, 0.4],
                b: [0.75, 0.85, 0.65],
                scale: 0.3,
                seed: 13,
            },
        ),
        // Back wall (x = −3): striped wallpaper.
        object(
            axis_box(v(-3.05, 0.0, 1.4), v(0.05, 2.7, 1.5)),
            Texture::Stripes {
                a: [0.8, 0.7, 0.55],
                b: [0.6, 0.35, 0.3],
                period: 0.3,
                direction: dir(0.0, 1.0, 0.0),
            },
        ),
        // Left wall (y = 2.5): tiles.
        object(
            axis_box(v(0.0, 2.55, 1.4), v(3.2, 0.05, 1.5)),
            Texture::Checker {
                a: [0.85, 0.85, 0.9],
                b: [0.3, 0.45, 0.7],
                scale: 0.35,
            },
        ),
        // Right wall (y = −2.5): marble.
        object(
            axis_box(v(0.0, -2.55, 1.4), v(3.2, 0.05, 1.5)),
            Texture::Marble {
                a: [0.9, 0.88, 0.85],
                b: [0.45, 0.42, 0.5],
                period: 0.5,
                direction: dir(1.0, 0.0, 0.6),
                turbulence: 1.0,
                seed: 14,
            },
        ),
        // Table top and two legs' worth of trestles.
        object(
            z_box(v(1.3, 0.3, 0.74), v(0.6, 0.9, 0.03), 10.0),
            Texture::Marble {
                a: [0.3, 0.18, 0.1],
                b: [0.6, 0.4, 0.22],
                period: 0.12,
                direction: dir(0.2, 1.0, 0.0),
                turbulence: 0.4,
                seed: 15,
            },
        ),
        object(
            z_box(v(1.3, 0.3, 0.36), v(0.08, 0.7, 0.35), 10.0),
            Texture::Solid([0.25, 0.2, 0.18]),
        ),
        // On the table: a ball, a box and a vase.
        object(
            Shape::Sphere {
                centre: v(1.2, -0.2, 0.92),
                radius: 0.15,
            },
            Texture::Checker {
                a: [0.95, 0.55, 0.1],
                b: [0.35, 0.1, 0.45],
                scale: 0.08,
            },
        ),
        object(
            z_box(v(1.45, 0.6, 0.88), v(0.15, 0.2, 0.11), -20.0),
            Texture::Stripes {
                a: [0.15, 0.3, 0.8],
                b: [0.9, 0.9, 0.85],
                period: 0.1,
                direction: dir(0.3, 0.2, 1.0),
            },
        ),
        object(
            Shape::Cylinder {
                centre: v(1.0, 0.75, 0.92),
                axis: Vector3::z_axis(),
                half_height: 0.15,
                radius: 0.07,
            },
            Texture::Noise {
                a: [0.7, 0.1, 0.15],
                b: [0.95, 0.75, 0.3],
                scale: 0.05,
                seed: 16,
            },
        ),
        // A cabinet in the far right corner.
        object(
            axis_box(v(2.6, -1.8, 0.6), v(0.35, 0.6, 0.6)),
            Texture::Noise {
                a: [0.2, 0.25, 0.35],
                b: [0.55, 0.6, 0.75],
                scale: 0.15,
                seed: 17,
            },
        ),
        // A lamp pillar in the far left corner.
        object(
            Shape::Cylinder {
                centre: v(2.3, 1.9, 0.9),
                axis: Vector3::z_axis(),
                half_height: 0.9,
                radius: 0.12,
            },
            Texture::Stripes {
                a: [0.9, 0.8, 0.3],
                b: [0.3, 0.25, 0.2],
                period: 0.2,
                direction: dir(0.0, 0.0, 1.0),
            },
        ),
        object(
            Shape::Sphere {
                centre: v(2.3, 1.9, 1.95),
                radius: 0.25,
            },
            Texture::Solid([0.98, 0.95, 0.8]),
        ),
        // Boxes stacked on the floor to the right.
        object(
            z_box(v(0.9, -1.7, 0.25), v(0.3, 0.25, 0.25), 25.0),
            Texture::Checker {
                a: [0.7, 0.55, 0.3],
                b: [0.45, 0.3, 0.15],
                scale: 0.12,
            },
        ),
        object(
            z_box(v(0.95, -1.65, 0.65), v(0.2, 0.18, 0.15), -10.0),
            Texture::Noise {
                a: [0.1, 0.5, 0.6],
                b: [0.8, 0.95, 0.95],
                scale: 0.08,
                seed: 18,
            },
        ),
        // A big ball on the floor to the left.
        object(
            Shape::Sphere {
                centre: v(0.4, 1.7, 0.35),
                radius: 0.35,
            },
            Texture::Marble {
                a: [0.8, 0.15, 0.1],
                b: [0.95, 0.8, 0.3],
                period: 0.2,
                direction: dir(0.3, 0.5, 0.8),
                turbulence: 0.8,
                seed: 19,
            },
        ),
        // A round rug under the table.
        object(
            Shape::Disk {
                centre: v(1.2, 0.2, 0.005),
                normal: Vector3::z_axis(),
                radius: 1.3,
            },
            Texture::Checker {
                a: [0.6, 0.15, 0.2],
                b: [0.85, 0.75, 0.55],
                scale: 0.2,
            },
        ),
        // A picture on the far wall.
        object(
            axis_box(v(2.98, 0.4, 1.7), v(0.02, 0.6, 0.4)),
            Texture::Marble {
                a: [0.1, 0.2, 0.5],
                b: [0.95, 0.7, 0.2],
                period: 0.15,
                direction: dir(0.0, 1.0, 1.0),
                turbulence: 2.0,
                seed: 20,
            },
        ),
    ];
    SyntheticScene {
        objects,
        background: [0.0, 0.0, 0.0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{read_replica, test_dir};

    #[test]
    fn rig_camera_looks_along_the_rig_x_axis_with_y_down() {
        let q = rig_from_camera();
        assert!((q * Vector3::z() - Vector3::x()).norm() < 1e-12, "forward");
        assert!((q * Vector3::y() + Vector3::z()).norm() < 1e-12, "down");
        assert!((q * Vector3::x() + Vector3::y()).norm() < 1e-12, "right");
    }

    #[test]
    fn replica_scaled_intrinsics_keep_the_field_of_view_and_centre() {
        let k = RoomConfig::default().intrinsics();
        assert_eq!((k.width, k.height, k.fx), (300, 170, 150.0));
        let cam = k.camera_for(300, 170, Path::new("x")).unwrap();
        assert_eq!((cam.cx, cam.cy), (150.0, 85.0));
    }

    #[test]
    fn the_walk_stays_inside_the_room_and_sees_surfaces_everywhere() {
        let config = RoomConfig::default();
        let poses = RoomMotion::from_config(&config).unwrap().camera_poses();
        assert_eq!(poses.len(), 500);
        let scene = room_scene();
        let camera = config
            .intrinsics()
            .camera_for(300, 170, Path::new("x"))
            .unwrap();
        for (i, pose) in poses.iter().enumerate().step_by(25) {
            let c = pose.translation.vector;
            assert!(
                c.x.abs() < 2.5 && c.y.abs() < 2.0 && c.z > 0.6 && c.z < 2.2,
                "{i}: {c}"
            );
            // Every pixel of a closed room has a surface, none nearer than 0.3 m.
            let (_, depth) = render_frame(&scene, &camera.scaled(0.1), pose, 1, false, 0, i, 1.0);
            let min = depth.data().iter().cloned().fold(f32::INFINITY, f32::min);
            assert!(min > 0.3, "frame {i}: nearest surface {min} m");
        }
    }

    #[test]
    fn depth_noise_has_the_stated_spread_and_is_reproducible() {
        let scene = room_scene();
        let camera = RoomConfig::default()
            .intrinsics()
            .camera_for(300, 170, Path::new("x"))
            .unwrap();
        let pose =
            room_start() * Isometry3::from_parts(Translation3::identity(), rig_from_camera());
        let (_, exact) = render_frame(&scene, &camera, &pose, 1, false, 0, 7, 1.0);
        let (_, noisy) = render_frame(&scene, &camera, &pose, 1, true, 0, 7, 1.0);
        let (_, again) = render_frame(&scene, &camera, &pose, 1, true, 0, 7, 1.0);
        assert_eq!(noisy, again);
        let mut z2 = Vec::new();
        let mut dropped = 0;
        for (e, n) in exact.data().iter().zip(noisy.data()) {
            if *n == 0.0 {
                dropped += 1;
                continue;
            }
            let sigma = 0.0012 + 0.0019 * (*e as f64 - 0.4).powi(2);
            z2.push(((n - e) as f64 / sigma).powi(2));
        }
        let chi = z2.iter().sum::<f64>() / z2.len() as f64;
        assert!((chi - 1.0).abs() < 0.05, "normalised variance {chi}");
        assert!(dropped < exact.data().len() / 5, "{dropped} dropped");
    }

    #[test]
    fn a_recorded_trajectory_is_replayed_from_the_start_pose() {
        let dir = test_dir("synth-recorded");
        let path = dir.join("traj.txt");
        // A camera moving 0.5 m/s along its own x axis, yawing about its own y.
        let mut text = String::new();
        for k in 0..=20 {
            let t = 100.0 + k as f64 * 0.1;
            let q = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.1 * k as f64);
            let (qi, qw) = (q.imag(), q.w);
            text.push_str(&format!(
                "{t} {} 0 0 {} {} {} {}\n",
                0.05 * k as f64,
                qi.x,
                qi.y,
                qi.z,
                qw
            ));
        }
        std::fs::write(&path, text).unwrap();
        let config = RoomConfig {
            trajectory: Some(path),
            frames: 100,
            frame_rate: 10.0,
            ..RoomConfig::default()
        };
        let poses = RoomMotion::from_config(&config).unwrap().camera_poses();
        assert_eq!(poses.len(), 21, "stops where the recording ends");
        let start =
            room_start() * Isometry3::from_parts(Translation3::identity(), rig_from_camera());
        assert!((poses[0].translation.vector - start.translation.vector).norm() < 1e-12);
        // The relative motion is the recording's: P₀⁻¹ P₁₀ = (0.5 along x, 1 rad about y).
        let rel = start.inverse() * poses[10];
        assert!((rel.translation.vector - Vector3::new(0.5, 0.0, 0.0)).norm() < 1e-12);
        assert!((rel.rotation.angle() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn generated_rooms_read_back_as_replica() {
        let root = test_dir("synth-generate");
        let config = RoomConfig {
            width: 48,
            frames: 3,
            supersample: 1,
            ..RoomConfig::default()
        };
        let mut seen = Vec::new();
        let n = generate_room(&config, &root, |i, n| seen.push((i, n))).unwrap();
        assert_eq!((n, seen.len()), (3, 3));
        let seq = read_replica(&root, None, 1.0, config.frame_rate).unwrap();
        assert_eq!(
            (seq.len(), seq.camera.width, seq.camera.height),
            (3, 48, 27)
        );
        assert!((seq.camera.fx - 24.0).abs() < 1e-12);
        let frame = seq.load(2).unwrap();
        let valid = frame.depth.data().iter().filter(|&&d| d > 0.0).count();
        assert!(
            valid > frame.depth.data().len() * 3 / 4,
            "{valid} valid depths"
        );
        let err = generate_room(
            &RoomConfig {
                frames: 1,
                ..config
            },
            &root,
            |_, _| {},
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("frames = 1"), "{err}");
    }
}
