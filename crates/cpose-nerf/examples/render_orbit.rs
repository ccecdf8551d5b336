//! Renders the synthetic NeRF experiment's orbit (paper §4.1.2) to PNG files for a look:
//! `cargo run --release -p cpose-nerf --example render_orbit -- [OUT_DIR] [EVERY]`.
//!
//! Writes every `EVERY`-th frame (default 10) of [`MonocularOrbit::default`] seen by
//! [`experiment_camera`] with 2×2 supersampling, plus one 400 × 400 view, into `OUT_DIR`
//! (default: `cpose-scene` in the system temp folder), and reports the rendering time per frame.

use std::path::PathBuf;
use std::time::Instant;

use cpose_nerf::scene::{MonocularOrbit, SyntheticScene, experiment_camera};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .map_or_else(|| std::env::temp_dir().join("cpose-scene"), PathBuf::from);
    let every: usize = args.next().map_or(Ok(10), |s| s.parse())?;
    std::fs::create_dir_all(&out)?;
    let scene = SyntheticScene::object_centric();
    let camera = experiment_camera();
    let orbit = MonocularOrbit::default();
    orbit.validate()?;
    let mut rendering_secs = 0.0;
    let mut frames = 0;
    for t in orbit.frame_times().into_iter().step_by(every.max(1)) {
        let start = Instant::now();
        let view = scene.render(&camera, &orbit.world_from_camera(t), 2);
        rendering_secs += start.elapsed().as_secs_f64();
        view.image
            .save_png(out.join(format!("frame_{:03}.png", t as usize)))?;
        frames += 1;
    }
    let per_frame = rendering_secs * 1e3 / f64::from(frames);
    let large = scene.render(&camera.scaled(4.0), &orbit.world_from_camera(12.0), 2);
    large.image.save_png(out.join("large_012.png"))?;
    eprintln!(
        "{frames} frames ({}×{}, 2×2 supersampling) in {per_frame:.1} ms each; written to {}",
        camera.width,
        camera.height,
        out.display()
    );
    Ok(())
}
