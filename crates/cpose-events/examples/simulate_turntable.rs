//! Simulates a synthetic EventNeRF dataset — one turntable revolution around `cpose-nerf`'s
//! object-centric scene, seen by a 173 × 130 colour event camera — and writes it for a look:
//! `cargo run --release -p cpose-events --example simulate_turntable -- [OUT_DIR] [TILT_DEG]`.
//!
//! `OUT_DIR` (default: `cpose-events-turntable` in the system temp folder) receives the dataset
//! (`train/`, `validation/`, see `cpose_events::eventnerf`) and `event_frames/`, the events of
//! eight windows of 1/36 revolution drawn as images (red: positive, blue: negative). `TILT_DEG`
//! tilts the turntable axis (the paper's calibration experiment uses 0.24, 1.5 and 2.85).
//! Reports the simulation time and the number of events.

use std::path::PathBuf;
use std::time::Instant;

use cpose_core::Timestamp;
use cpose_events::{SyntheticEventsConfig, Turntable, write_synthetic_eventnerf};
use cpose_nerf::image::Image;
use cpose_nerf::scene::SyntheticScene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = args.next().map_or_else(
        || std::env::temp_dir().join("cpose-events-turntable"),
        PathBuf::from,
    );
    let tilt_deg: f64 = args.next().map_or(Ok(0.0), |s| s.parse())?;
    let _ = std::fs::remove_dir_all(out.join("train"));
    let _ = std::fs::remove_dir_all(out.join("validation"));
    let config = SyntheticEventsConfig {
        turntable: Turntable {
            axis_tilt_rad: tilt_deg.to_radians(),
            ..Default::default()
        },
        ..Default::default()
    };
    let start = Instant::now();
    let (scene, dropped) =
        write_synthetic_eventnerf(&out, &SyntheticScene::object_centric(), &config)?;
    let secs = start.elapsed().as_secs_f64();
    let events = &scene.events;
    eprintln!(
        "{} events ({} dropped by the refractory period) from {} renders of {}×{} in {secs:.1} s; written to {}",
        events.len(),
        dropped,
        config.render_steps + 1,
        config.camera.width,
        config.camera.height,
        out.display()
    );

    let frames = out.join("event_frames");
    std::fs::create_dir_all(&frames)?;
    let (w, h) = (events.width(), events.height());
    let period = config.turntable.duration_secs;
    for k in 0..8 {
        let t0 = period * k as f64 / 8.0;
        let window = events.window(
            Timestamp::from_secs_f64(t0),
            Timestamp::from_secs_f64(t0 + period / 36.0),
        )?;
        let sum = window.accumulate(w, h);
        let image = Image::from_fn(usize::from(w), usize::from(h), |x, y| {
            let e = sum[y * usize::from(w) + x] / 4.0;
            [
                1.0 - (-e).max(0.0),
                1.0 - e.abs().min(1.0),
                1.0 - e.max(0.0),
            ]
        });
        image.save_png(frames.join(format!("window_{k}.png")))?;
    }
    Ok(())
}
