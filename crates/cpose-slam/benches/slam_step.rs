//! One tracking iteration and one mapping iteration of the `slam` task at its defaults (the
//! default map of 16 samples per ray), on frames of the synthetic room seen through 7-Scenes'
//! camera at 320×240, the size of `configs/7scenes_redkitchen.toml`: tracking renders 400 pixels,
//! takes the pose gradient and steps the free pose; mapping renders 1024 pixels and steps the
//! map's Adam. The map is first trained on frame 0 as the task does (300 steps), so the field is
//! not empty.
//!
//! `cargo bench -p cpose-slam --bench slam_step -- --warm-up-time 1 --measurement-time 5 --sample-size 20`

use std::hint::black_box;
use std::path::Path;

use cpose_nerf::camera::PoseGradient;
use cpose_nerf::field3d::SceneBounds;
use cpose_slam::data::{RgbdFrame, SEVEN_SCENES_INTRINSICS};
use cpose_slam::map::{MapConfig, NeuralMap};
use cpose_slam::slam::{MappingConfig, Slam, TrackingConfig, sample_pixels};
use cpose_slam::synth::{RoomConfig, RoomMotion, render_frame, room_scene};
use cpose_slam::track::{FreePose, PoseModel};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn bench(c: &mut Criterion) {
    let config = RoomConfig::default();
    let camera = SEVEN_SCENES_INTRINSICS
        .camera_for(320, 240, Path::new("bench"))
        .expect("7-Scenes' aspect ratio");
    let poses = RoomMotion::from_config(&config)
        .expect("default walk")
        .camera_poses();
    let scene = room_scene();
    let frame = |i: usize| {
        let (color, depth) = render_frame(&scene, &camera, &poses[i], 2, true, 0, i, 1.0);
        RgbdFrame {
            index: i,
            time: i as f64 / config.frame_rate,
            color,
            depth,
        }
    };
    let bounds = SceneBounds {
        centre: [0.0, 0.0, 1.4],
        radius: 3.3,
        unbounded: false,
    };
    let map = NeuralMap::new(&MapConfig::default(), bounds).expect("default map");
    let tracking = TrackingConfig::default();
    let mapping = MappingConfig::default();
    let mut slam = Slam::new(map, camera, &tracking, &mapping, 0).expect("valid settings");
    let mut model = FreePose::new(tracking.lr, 1.0);
    slam.process(frame(0), poses[0], &mut model)
        .expect("frame 0 maps");
    let frame1 = frame(1);
    model.begin(1, frame1.time, &poses[..1]).expect("start");
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut pixels = Vec::new();
    let mut grads = vec![PoseGradient::new()];

    let mut group = c.benchmark_group("slam_step");
    group.throughput(Throughput::Elements(tracking.pixels as u64));
    group.bench_function("tracking_iteration", |b| {
        b.iter(|| {
            let pose = model.pose();
            sample_pixels(
                &frame1,
                &camera,
                &pose,
                0,
                tracking.pixels,
                tracking.edge,
                &mut rng,
                &mut pixels,
            );
            grads[0] = PoseGradient::new();
            let loss = slam.map.tracking_loss(&pixels, &mut rng, &mut grads);
            let (gq, gt) = grads[0].quaternion_translation(&pose.rotation);
            model.step(&gq, &gt).expect("step");
            black_box(loss)
        })
    });
    group.throughput(Throughput::Elements(mapping.pixels as u64));
    let frame0 = frame(0);
    group.bench_function("mapping_iteration", |b| {
        b.iter(|| {
            sample_pixels(
                &frame0,
                &camera,
                &poses[0],
                0,
                mapping.pixels,
                0,
                &mut rng,
                &mut pixels,
            );
            black_box(slam.map.mapping_step(&pixels, &mut rng))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
