//! The IMU losses of `slam_imu` over one second of 200 Hz readings, forward and backward through
//! the tracking PoseNet (`configs/euroc_v102_imu.toml`: 4 × 128, softplus, 5 bands): the tight
//! gyroscope loss (`q̇`, first derivatives) and the combined gyroscope and accelerometer loss
//! (`p̈`, second derivatives). Compare with one tracking iteration's rendering,
//! `cargo bench -p cpose-slam --bench slam_step -- tracking_iteration`.
//!
//! `cargo bench -p cpose-imu --bench imu_loss -- --warm-up-time 1 --measurement-time 5 --sample-size 20`

use std::hint::black_box;

use cpose_core::nn::Activation;
use cpose_core::pose_field::sinusoid::SinusoidMotion;
use cpose_core::{Order, PoseBatch, PoseField, TimeRange, gravity_world};
use cpose_imu::losses::{accel_l1, gyro_tight_l1};
use cpose_imu::sim::simulate_imu;
use cpose_slam::track::PoseNetTrackConfig;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let range = TimeRange::new(0.0, 38.0).expect("a positive span");
    let mut network = PoseNetTrackConfig::default().network;
    network.activation = Activation::Softplus;
    network.translation_scale = 5.0;
    let mut net = network.init::<f32>(range).expect("valid network");
    let times: Vec<f64> = (0..200).map(|k| 10.0 + k as f64 / 200.0).collect();
    let mut motion = SinusoidMotion::<f64>::handheld(range, 0);
    let imu = simulate_imu(&mut motion, &times, &gravity_world(), None, 0)
        .expect("times in range")
        .samples;
    let gyro: Vec<_> = imu.iter().map(|s| s.gyro).collect();
    let accel: Vec<_> = imu.iter().map(|s| s.accel).collect();
    let (mut out, mut cot) = (PoseBatch::default(), PoseBatch::default());
    let mut grad = vec![0.0f32; net.num_params()];

    let mut group = c.benchmark_group("imu_loss");
    group.throughput(Throughput::Elements(times.len() as u64));
    group.bench_function("tight_1s_200hz", |b| {
        b.iter(|| {
            net.forward(&times, Order::Velocity, &mut out)
                .expect("forward");
            cot.reset(times.len(), Order::Velocity);
            let loss = gyro_tight_l1(&out, &gyro, 1.0, &mut cot);
            net.backward(&times, &cot, &mut grad).expect("backward");
            black_box(loss)
        })
    });
    group.bench_function("combined_1s_200hz", |b| {
        b.iter(|| {
            net.forward(&times, Order::Acceleration, &mut out)
                .expect("forward");
            cot.reset(times.len(), Order::Acceleration);
            let g = gravity_world();
            let loss = gyro_tight_l1(&out, &gyro, 1.0, &mut cot)
                + accel_l1(&out, &accel, &g, 1.0, 1.0, &mut cot);
            net.backward(&times, &cot, &mut grad).expect("backward");
            black_box(loss)
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
