//! One training step of the `nerf` task (`Trainer::step`: pixel draw and rays, forward,
//! backward, Adam on the field and on the poses), in rays per second, at the task's synthetic
//! defaults: 100 frames of 100×100 of the built-in scene along the monocular orbit, initial
//! poses with the default time-correlated noise, PoseNet's correction, `rays_per_step = 1024`
//! × 48 samples on the chord through the scene's bounding sphere (`configs/nerf_synthetic.toml`).
//! The trainer draws the same `⌊1024 / 100⌋ = 10` pixels in every frame, so a step renders 1000
//! rays, the throughput's unit.
//! Fields: the hash grid at its default config (the baseline) and the NeRF MLP at a reduced
//! 4 × 128 (BARF's 8 × 256 takes seconds per step). Every step runs at iteration 3000 of 6000
//! (progress ½: all grid levels and all MLP bands on), so each measured step does the same work.
//!
//! `cargo bench -p cpose-nerf --bench nerf_step -- --warm-up-time 1 --measurement-time 5 --sample-size 10`

use std::collections::BTreeMap;
use std::hint::black_box;

use cpose_core::nn::ExponentialDecay;
use cpose_core::{PoseNetConfig, TimeRange};
use cpose_nerf::camera::PinholeCamera;
use cpose_nerf::field3d::{HashGridConfig, NerfMlpConfig, RadianceFieldConfig, SceneBounds};
use cpose_nerf::image::Image;
use cpose_nerf::nerf::train::{Schedule, Trainer};
use cpose_nerf::poses::{FramePoses, PoseSchedules};
use cpose_nerf::render::{Clip, LastInterval, RenderSettings, Sampling};
use cpose_nerf::scene::{MonocularOrbit, PoseNoise, SyntheticScene};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

const ITERATIONS: u64 = 6000;
const RAYS: usize = 1024;

/// The training views as the task renders them (`[data]` and `[orbit]` defaults).
struct Views {
    camera: PinholeCamera,
    images: Vec<Image>,
    times: Vec<f64>,
    initial: Vec<nalgebra::Isometry3<f64>>,
    bounds: SceneBounds,
}

fn views() -> Views {
    let orbit = MonocularOrbit::default();
    let camera = PinholeCamera::from_fov_x(100, 100, 40f64.to_radians());
    let scene = SyntheticScene::object_centric();
    let times = orbit.frame_times();
    let truth: Vec<_> = times.iter().map(|&t| orbit.world_from_camera(t)).collect();
    let images = truth
        .iter()
        .map(|pose| scene.render(&camera, pose, 2).image)
        .collect();
    // Seeded by the noise config.
    let initial = PoseNoise::default().apply(&truth, orbit.diameter());
    Views {
        camera,
        images,
        times,
        initial,
        bounds: SceneBounds {
            centre: [0.0; 3],
            radius: scene.bounding_radius(),
            unbounded: false,
        },
    }
}

fn decay([lr0, lr_end]: [f64; 2]) -> ExponentialDecay {
    ExponentialDecay {
        lr0,
        lr_end,
        max_iter: ITERATIONS,
    }
}

fn nerf_step(c: &mut Criterion) {
    let views = views();
    let mlp = NerfMlpConfig {
        depth: 4,
        width: 128,
        skip_layer: Some(2),
        ..NerfMlpConfig::default()
    };
    let mut group = c.benchmark_group("nerf_step");
    // Rays actually rendered per step: the same pixels in every frame.
    let rays = RAYS / views.images.len() * views.images.len();
    group.throughput(Throughput::Elements(rays as u64));
    for (name, config) in [
        ("grid", RadianceFieldConfig::Grid(HashGridConfig::default())),
        ("mlp_4x128", RadianceFieldConfig::Mlp(mlp)),
    ] {
        let mut field = config.init::<f32>(views.bounds).expect("valid config");
        let range = TimeRange::new(views.times[0], views.times[views.times.len() - 1])
            .expect("distinct frame times");
        let posenet = PoseNetConfig::default()
            .init::<f32>(range)
            .expect("default config");
        // The task's default learning rates ([train] in the nerf module).
        let mut poses = FramePoses::new(
            views.initial.clone(),
            views.times.clone(),
            Some(Box::new(posenet)),
            PoseSchedules {
                rotation: decay([2e-4, 1e-6]),
                translation: decay([1e-3, 1e-5]),
                pose: decay([1e-3, 1e-5]),
                hold: 0,
                warmup: 600,
                rotation_warmup: 600,
            },
        );
        let settings = RenderSettings {
            last_interval: LastInterval::Closed,
            samples: 48,
            sampling: Sampling::Metric {
                near: 2.0,
                far: 6.0,
            },
            background: Some([1.0; 3]),
            // As the task: samples on the chord through the scene's bounding sphere.
            clip: Some(Clip {
                centre: views.bounds.centre,
                radius: views.bounds.radius,
            }),
        };
        let schedule = Schedule {
            iterations: ITERATIONS,
            rays_per_step: RAYS,
            field_lr: BTreeMap::from([
                ("grid".to_owned(), [1e-2, 1e-3]),
                ("mlp".to_owned(), [1e-3, 1e-4]),
            ]),
            seed: 0,
            field_restart_every: 0,
            field_restart_until: 0,
        };
        let mut trainer = Trainer::new(
            field.as_mut(),
            &mut poses,
            &views.images,
            views.camera,
            settings,
            schedule,
        )
        .expect("one image per frame");
        group.bench_function(BenchmarkId::new("step", name), |b| {
            b.iter(|| {
                let loss = trainer
                    .step(black_box(ITERATIONS / 2))
                    .expect("a finite loss");
                black_box(loss)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, nerf_step);
criterion_main!(benches);
