//! Forward and forward + backward throughput of the 3-D radiance fields, in points per second:
//! the hash grid at its default config on 65,536 points (a step of 1024 rays × 64 samples), and
//! the NeRF MLP at a reduced (4 × 128) and BARF's default (8 × 256) size on 8192 points. All
//! levels and bands are on (progress 1), the scene is bounded and points are uniform in the
//! cube, from a seeded generator. The forward pass alone is the baseline in each group.
//!
//! `cargo bench -p cpose-nerf --bench field3d -- --warm-up-time 1 --measurement-time 3 --sample-size 10`

use std::hint::black_box;

use cpose_nerf::field3d::{HashGridConfig, NerfMlpConfig, RadianceField, SceneBounds};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `n` points uniform in `[−1, 1]³` (interleaved) and fixed cotangents.
fn inputs(n: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let points = (0..3 * n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let grad_sigma = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let grad_rgb = (0..3 * n).map(|_| rng.random_range(-1.0..1.0)).collect();
    (points, grad_sigma, grad_rgb)
}

fn run(c: &mut Criterion, group: &str, name: &str, mut field: Box<dyn RadianceField>, n: usize) {
    field.set_progress(1.0);
    let (points, grad_sigma, grad_rgb) = inputs(n);
    let (mut sigma, mut rgb) = (vec![0.0f32; n], vec![0.0f32; 3 * n]);
    let mut grad = vec![0.0f32; field.num_params()];
    let mut grad_points = vec![0.0f32; 3 * n];
    let mut g = c.benchmark_group(group);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function(BenchmarkId::new("forward", name), |b| {
        b.iter(|| {
            field.forward(black_box(&points), &mut sigma, &mut rgb);
            black_box((&sigma, &rgb));
        })
    });
    g.bench_function(BenchmarkId::new("forward_backward", name), |b| {
        b.iter(|| {
            field.forward(black_box(&points), &mut sigma, &mut rgb);
            field.backward(
                black_box(&grad_sigma),
                black_box(&grad_rgb),
                &mut grad,
                &mut grad_points,
            );
            black_box((&grad, &grad_points));
        })
    });
    g.finish();
}

fn hash_grid(c: &mut Criterion) {
    let field = HashGridConfig::default()
        .init::<f32>(SceneBounds::UNIT)
        .expect("default config");
    run(c, "hash_grid", "default_65536", Box::new(field), 65_536);
}

fn nerf_mlp(c: &mut Criterion) {
    let reduced = NerfMlpConfig {
        depth: 4,
        width: 128,
        skip_layer: Some(2),
        ..NerfMlpConfig::default()
    };
    for (name, config) in [
        ("4x128_8192", reduced),
        ("8x256_8192", NerfMlpConfig::default()),
    ] {
        let field = config.init::<f32>(SceneBounds::UNIT).expect("valid config");
        run(c, "nerf_mlp", name, Box::new(field), 8192);
    }
}

criterion_group!(benches, hash_grid, nerf_mlp);
criterion_main!(benches);
