//! Task `synth_room`: writes the synthetic room ([`crate::synth`]) as a Replica-layout dataset,
//! a stand-in for Replica that `task = "slam"` then reads like the real thing.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use cpose_core::registry::{Task, TaskInput};
use serde::Deserialize;

use crate::data::read_replica;
use crate::synth::{RoomConfig, generate_room};

inventory::submit! {
    Task {
        name: "synth_room",
        about: "write the synthetic RGB-D room (colour, noisy depth, true poses) in Replica's layout",
        run,
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Experiment {
    #[serde(default)]
    synthetic: RoomConfig,
    output: Output,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Output {
    /// Folder of the dataset (created; existing frames are overwritten).
    path: PathBuf,
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let exp: Experiment = input.config.parse_params()?;
    let started = Instant::now();
    let progress = input.progress(exp.synthetic.frames as u64, "rendering");
    let n = generate_room(&exp.synthetic, &exp.output.path, |i, n| {
        progress.set_length(n as u64);
        progress.set_position(i as u64);
    })
    .with_context(|| {
        format!(
            "writing the synthetic room to {}",
            exp.output.path.display()
        )
    })?;
    progress.finish();
    // Read it back as any Replica scene would be, and keep a preview of frame 0.
    let seq = read_replica(&exp.output.path, None, 1.0, exp.synthetic.frame_rate)?;
    let frame = seq.load(0)?;
    frame
        .color
        .save_png(input.run_dir.file("frame0_color.png"))?;
    frame
        .depth
        .to_image(0.0, 6.0)
        .save_png(input.run_dir.file("frame0_depth.png"))?;
    input.run_dir.write_json(
        "metrics.json",
        &serde_json::json!({
            "frames": n,
            "width": seq.camera.width,
            "height": seq.camera.height,
            "path": exp.output.path,
            "wall_s": started.elapsed().as_secs_f64(),
        }),
    )?;
    input.run_dir.log(format_args!(
        "wrote {n} frames of {}×{} to {} in {:.1} s",
        seq.camera.width,
        seq.camera.height,
        exp.output.path.display(),
        started.elapsed().as_secs_f64()
    ));
    Ok(())
}
