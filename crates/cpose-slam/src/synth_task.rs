//! Task `synth_room`: writes the synthetic room ([`crate::synth`]) as a Replica-layout dataset,
//! a stand-in for Replica that `task = "slam"` then reads like the real thing.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use cpose_core::Config;
use cpose_core::registry::{Task, TaskInput};
use cpose_core::study::{Metrics, Study, UnitKey};
use serde::Deserialize;

use crate::data::read_replica;
use crate::synth::RoomConfig;
use crate::task::ensure_synthetic;

inventory::submit! {
    Task {
        name: "synth_room",
        about: "write the synthetic RGB-D room (colour, noisy depth, true poses) in Replica's layout",
        default_config: || [include_str!("../defaults/synth_room.toml"), RoomConfig::DEFAULT_TABLE].join("\n"),
        check: |config, _| Experiment::new(config).map(drop),
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
    /// Folder of the dataset: created, or one this generator wrote (kept if it holds the same
    /// room, else rewritten); any other non-empty folder is refused.
    path: PathBuf,
}

impl Experiment {
    /// The config, decoded and checked.
    fn new(config: &Config) -> anyhow::Result<Self> {
        let exp: Self = config.parse_params()?;
        exp.synthetic.check(config)?;
        Ok(exp)
    }
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let exp = Experiment::new(input.config)?;
    // One unit: the room, written (again, on a resume that finds it unfinished) as a whole.
    let unit = UnitKey::new("room", "synthetic", input.run.seed);
    Study::new(input, vec![unit])
        .columns(&["frames", "width", "height"])
        .run(|unit| {
            let started = Instant::now();
            // As `slam` generates it: a folder of the same room is kept, one that the generator
            // did not write is refused (it may hold a real dataset).
            ensure_synthetic(&exp.synthetic, &exp.output.path, input).with_context(|| {
                format!(
                    "writing the synthetic room to {}",
                    exp.output.path.display()
                )
            })?;
            // Read it back as any Replica scene would be, and keep a preview of frame 0.
            let seq = read_replica(&exp.output.path, None, 1.0, exp.synthetic.frame_rate)?;
            let frame = seq.load(0)?;
            frame.color.save_png(unit.file("frame0_color", "png"))?;
            frame
                .depth
                .to_image(0.0, 6.0)
                .save_png(unit.file("frame0_depth", "png"))?;
            let n = seq.len();
            unit.log(format_args!(
                "{n} frames of {}×{} in {} ({:.1} s)",
                seq.camera.width,
                seq.camera.height,
                exp.output.path.display(),
                started.elapsed().as_secs_f64()
            ));
            Ok(Metrics::new()
                .with("frames", n)
                .with("width", seq.camera.width)
                .with("height", seq.camera.height)
                .with("path", &exp.output.path))
        })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cpose config show synth_room` states the defaults: its values are those of a config
    /// with only the output folder.
    #[test]
    fn the_default_config_holds_the_defaults() {
        let required = "task = \"synth_room\"\n[output]\npath = \"data/synthetic_room\"\n";
        cpose_core::testing::check_default_config("synth_room", required, |config, _| {
            Experiment::new(config)
        });
    }
}
