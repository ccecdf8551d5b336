//! One EventNeRF training step of task `events` at its default size (`configs/events_interp.toml`):
//! a 173 × 130 sensor, 1024 ray pairs in 8 windows, 48 samples per ray, the hash-grid field,
//! PoseNet evaluated at the 16 window ends and the 7 anchors of `K = 6` known views.
//! Throughput in events (mean events summed per step, measured over the first 50 steps)
//! and in ray pairs.
//!
//! `cargo bench -p cpose-events --bench event_step -- --warm-up-time 2 --measurement-time 10 --sample-size 20`

use std::collections::BTreeMap;

use cpose_core::nn::ExponentialDecay;
use cpose_core::{PoseNetConfig, TimeRange};
use cpose_events::loss::EventLoss;
use cpose_events::simulate::{SyntheticEventsConfig, simulate_eventnerf_scene};
use cpose_events::train::{EventSchedule, EventTrainer, InitialPath, KeyedPoses};
use cpose_nerf::field3d::{RadianceFieldConfig, SceneBounds};
use cpose_nerf::poses::{FramePoses, PoseSchedules};
use cpose_nerf::render::{Clip, LastInterval, RenderSettings, Sampling};
use cpose_nerf::scene::SyntheticScene;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let scene = SyntheticScene::object_centric();
    let config = SyntheticEventsConfig::default();
    let (data, _) = simulate_eventnerf_scene(&scene, &config).expect("simulated");
    let tt = &config.turntable;
    let k = 6;
    let times: Vec<f64> = (0..=k)
        .map(|i| i as f64 * tt.duration_secs / k as f64)
        .collect();
    let poses: Vec<_> = times.iter().map(|&t| tt.world_from_camera(t)).collect();
    let anchors = times.iter().copied().zip(poses.iter().copied()).collect();
    let initial = InitialPath::Keyed(KeyedPoses::new(times, poses).expect("increasing"));
    let bounds = SceneBounds {
        centre: [0.0; 3],
        radius: scene.bounding_radius(),
        unbounded: false,
    };
    let mut field = RadianceFieldConfig::default()
        .init::<f32>(bounds)
        .expect("default field");
    let range = TimeRange::new(0.0, tt.duration_secs).expect("positive");
    let posenet = PoseNetConfig::default()
        .init::<f32>(range)
        .expect("posenet");
    let decay = ExponentialDecay {
        lr0: 1e-4,
        lr_end: 1e-5,
        max_iter: 1_000_000,
    };
    let mut poses = FramePoses::new(
        Vec::new(),
        Vec::new(),
        Some(Box::new(posenet)),
        PoseSchedules {
            rotation: decay,
            translation: decay,
            pose: decay,
            hold: 0,
            warmup: 0,
            rotation_warmup: 0,
        },
    );
    let settings = RenderSettings {
        samples: 48,
        sampling: Sampling::Metric {
            near: 1.0,
            far: 9.0,
        },
        background: Some([1.0; 3]),
        clip: Some(Clip {
            centre: [0.0; 3],
            radius: bounds.radius,
        }),
        last_interval: LastInterval::Closed,
    };
    let schedule = EventSchedule {
        iterations: 1_000_000,
        rays_per_step: 1024,
        windows_per_step: 8,
        window_secs: [0.02, 0.5],
        time_span: Some([0.0, tt.duration_secs]),
        neg_ratio: 0.1,
        loss: EventLoss {
            threshold: 0.25,
            eps: 0.1,
        },
        field_lr: BTreeMap::from([
            ("grid".to_owned(), [1e-2, 1e-3]),
            ("mlp".to_owned(), [1e-3, 1e-4]),
        ]),
        anchor_weight: 1.0,
        anchor_windows: 0.0,
        seed: 0,
    };
    let mut trainer = EventTrainer::new(
        field.as_mut(),
        &mut poses,
        &initial,
        anchors,
        &data.events,
        data.camera,
        settings,
        schedule,
    )
    .expect("valid setup");
    let warm = 50;
    let events: usize = (0..warm)
        .map(|it| trainer.step(it).expect("step").events)
        .sum();
    let mut it = warm;
    let mut group = c.benchmark_group("event_step");
    group.sample_size(10);
    group.throughput(Throughput::Elements((events / warm as usize) as u64));
    group.bench_function("events", |b| {
        b.iter(|| {
            it += 1;
            trainer.step(it).expect("step")
        })
    });
    group.throughput(Throughput::Elements(1024));
    group.bench_function("ray_pairs", |b| {
        b.iter(|| {
            it += 1;
            trainer.step(it).expect("step")
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
