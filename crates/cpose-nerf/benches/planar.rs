//! One training step of the planar study per method and neural image, at the committed
//! configs' settings (4096 pixels, 7 patches of 90×90 on a 240×180 working image).
//!
//! `cargo bench -p cpose-nerf --bench planar -- --warm-up-time 1 --measurement-time 3`

use cpose_core::{PoseNetConfig, TimeRange};
use cpose_nerf::field2d::{GridConfig, ImageField, PeMlpConfig};
use cpose_nerf::image::procedural_texture;
use cpose_nerf::planar::model::{FieldModel, FreeModel, PoseModel, PoseRates, SplineReset};
use cpose_nerf::planar::motion::MotionSpec;
use cpose_nerf::planar::train::{Layout, Schedule, Trainer, sample_patches};
use cpose_nerf::warp2d::WarpKind;
use criterion::{Criterion, criterion_group, criterion_main};

fn planar_step(c: &mut Criterion) {
    let original = procedural_texture(480, 360, 0);
    let image = original.resized(0.5);
    let layout = Layout::centre_crop(WarpKind::Se2, [480, 360], 180.0, 90);
    let spec = MotionSpec {
        warp: WarpKind::Se2,
        patches: 7,
        control_points: 10,
        rotation_std_rad: 3f64.to_radians(),
        translation_std: 0.08,
        homography_std: 0.1,
    };
    let motion = spec
        .sample(0, &layout.corners, [1.0, 0.75])
        .expect("a motion fits");
    let patches = sample_patches(&image, &layout, &motion.params);
    let rates = PoseRates {
        translation: 1e-3,
        rotation: 2e-4,
        homography: 1e-3,
    };
    let posenet_rates = PoseRates {
        translation: 1e-4,
        rotation: 2e-5,
        homography: 0.0,
    };
    let schedule = Schedule {
        iterations: 2000,
        pixels_per_step: 4096,
        lr_field: 1e-3,
        pose_hold: 0,
    };
    let range: TimeRange = spec.time_range();
    let times = spec.patch_times();
    let mut group = c.benchmark_group("planar_step");
    group.sample_size(20);
    for field_name in ["grid", "mlp"] {
        for method in ["posenet", "barf", "spline"] {
            let mut field: Box<dyn ImageField> = match field_name {
                "grid" => Box::new(GridConfig::default().init::<f32>().expect("default")),
                _ => Box::new(PeMlpConfig::default().init::<f32>().expect("default")),
            };
            let mut model: Box<dyn PoseModel> = match method {
                "posenet" => Box::new(FieldModel::new(
                    Box::new(
                        PoseNetConfig::default()
                            .init::<f32>(range)
                            .expect("default"),
                    ),
                    times.clone(),
                    posenet_rates,
                )),
                "barf" => Box::new(FreeModel::new(
                    WarpKind::Se2,
                    times.clone(),
                    range,
                    rates,
                    None,
                )),
                _ => Box::new(FreeModel::new(
                    WarpKind::Se2,
                    times.clone(),
                    range,
                    rates,
                    Some(SplineReset {
                        control_points: 5,
                        every: 100,
                    }),
                )),
            };
            let mut trainer = Trainer::new(
                field.as_mut(),
                model.as_mut(),
                &layout,
                &patches,
                schedule,
                0,
            );
            group.bench_function(format!("{field_name}/{method}"), |b| {
                b.iter(|| trainer.step().expect("finite loss"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, planar_step);
criterion_main!(benches);
