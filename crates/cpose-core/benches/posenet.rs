//! PoseNet training-step cost (forward + backward) and faer's matrix-product rate.
//!
//! `cargo bench -p cpose-core --bench posenet -- --warm-up-time 1 --measurement-time 3`;
//! threads from `CPOSE_THREADS` (default 2).

use std::hint::black_box;

use cpose_core::nn::Activation;
use cpose_core::{Order, PoseBatch, PoseField, PoseNet, PoseNetConfig, TimeRange};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};

fn init_pool() {
    let threads = std::env::var("CPOSE_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2);
    // Fails only if a pool exists already (criterion runs all groups in one process).
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global();
}

/// One step: forward at `order`, gradient of `½‖y − y*‖²` on every output up to `order`
/// (targets zero), backward into a zeroed gradient.
fn step(
    net: &mut PoseNet<f32>,
    times: &[f64],
    order: Order,
    out: &mut PoseBatch,
    cot: &mut PoseBatch,
    grad: &mut [f32],
) {
    net.forward(times, order, out).expect("in range");
    cot.clone_from(out);
    grad.fill(0.0);
    net.backward(times, cot, grad).expect("shapes match");
}

fn posenet(c: &mut Criterion) {
    init_pool();
    let range = TimeRange::new(0.0, 100.0).expect("valid");
    let mut group = c.benchmark_group("posenet");
    group.sample_size(10);
    for b in [64usize, 1024, 4096, 16384] {
        let times: Vec<f64> = (0..b).map(|i| 100.0 * i as f64 / b as f64).collect();
        group.throughput(Throughput::Elements(b as u64));
        for (id, activation, order) in [
            ("plain", Activation::Relu, Order::Pose),
            ("derivatives", Activation::Softplus, Order::Acceleration),
        ] {
            let config = PoseNetConfig {
                activation,
                ..PoseNetConfig::default()
            };
            let mut net = config.init::<f32>(range).expect("default config");
            let (mut out, mut cot) = (PoseBatch::default(), PoseBatch::default());
            let mut grad = vec![0.0f32; net.num_params()];
            group.bench_function(BenchmarkId::new(id, b), |bench| {
                bench.iter(|| {
                    step(
                        &mut net,
                        black_box(&times),
                        order,
                        &mut out,
                        &mut cot,
                        &mut grad,
                    );
                    black_box(&grad);
                })
            });
        }
    }
    group.finish();
}

fn faer_matmul(c: &mut Criterion) {
    init_pool();
    let (m, k, n) = (4096usize, 256usize, 256usize);
    let a = Mat::<f32>::from_fn(m, k, |i, j| ((i * 7 + j * 3) % 13) as f32 * 0.01);
    let w = Mat::<f32>::from_fn(k, n, |i, j| ((i * 5 + j) % 11) as f32 * 0.01);
    let mut out = Mat::<f32>::zeros(m, n);
    let mut group = c.benchmark_group("faer_matmul");
    group.throughput(Throughput::Elements((2 * m * n * k) as u64)); // elements/s = FLOP/s
    group.bench_function("seq_4096x256x256", |bench| {
        bench.iter(|| {
            matmul(
                out.as_mut(),
                Accum::Replace,
                black_box(a.as_ref()),
                w.as_ref(),
                1.0,
                Par::Seq,
            );
            black_box(&out);
        })
    });
    group.bench_function("split2_4096x256x256", |bench| {
        bench.iter(|| {
            let (o1, o2) = out.as_mut().split_at_row_mut(m / 2);
            let (a1, a2) = black_box(a.as_ref()).split_at_row(m / 2);
            rayon::join(
                || matmul(o1, Accum::Replace, a1, w.as_ref(), 1.0, Par::Seq),
                || matmul(o2, Accum::Replace, a2, w.as_ref(), 1.0, Par::Seq),
            );
            black_box(&out);
        })
    });
    group.finish();
}

criterion_group!(benches, posenet, faer_matmul);
criterion_main!(benches);
