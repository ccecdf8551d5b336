//! The task and pose-field registries: plug-ins registered as data with `inventory`.
//!
//! A crate registers a task or a pose field with `inventory::submit!` next to its code; the
//! `cpose` binary (and every integration test) names the crate with `use cpose_x as _;` so that
//! the registration is linked. Lists are sorted by name, since `inventory` gives no order.
//!
//! ```no_run
//! use anyhow::Context;
//! use cpose_core::registry::{FieldContext, Task, TaskInput, build_pose_field};
//! use cpose_core::{Config, PoseField, RunConfig, TimeRange};
//!
//! #[derive(serde::Deserialize)]
//! #[serde(deny_unknown_fields)]
//! struct Params {
//!     /// Seconds covered by the field.
//!     duration_secs: f64,
//!     /// Decoded by the pose-field registry.
//!     #[allow(dead_code)]
//!     model: serde::de::IgnoredAny,
//! }
//!
//! /// Decodes every key without running: a typo names line, column and the valid keys, and
//! /// `[model]` picks a pose field by `kind`.
//! fn build(config: &Config, run: &RunConfig) -> anyhow::Result<Box<dyn PoseField>> {
//!     let params: Params = config.parse_params()?;
//!     let time_range = TimeRange::new(0.0, params.duration_secs).context("duration_secs > 0")?;
//!     let ctx = FieldContext { time_range, frame_times_secs: Vec::new(), seed: run.seed };
//!     Ok(build_pose_field(&config.section("model"), &ctx)?)
//! }
//!
//! fn run(input: &TaskInput) -> anyhow::Result<()> {
//!     let field = build(input.config, input.run)?;
//!     input.run_dir.write_json("metrics.json", &field.num_params())?;
//!     Ok(())
//! }
//!
//! inventory::submit! {
//!     Task {
//!         name: "count_params",
//!         about: "build a pose field and count its parameters",
//!         default_config: || "task = \"count_params\"\nduration_secs = 2.0\n[model]\nkind = \"posenet\"\n".into(),
//!         check: |config, run| build(config, run).map(drop),
//!         run,
//!     }
//! }
//! ```

use std::collections::BTreeSet;

use thiserror::Error;

use crate::config::{Config, ConfigError, RunConfig, Section};
use crate::progress::Progress;
use crate::run_dir::RunDir;
use crate::{PoseField, TimeRange};

/// What a task receives: the config, its run folder and the decoded `[run]` table.
#[derive(Debug)]
pub struct TaskInput<'a> {
    /// The resolved config; decode the task's tables with [`Config::parse`],
    /// [`Config::parse_params`] or [`Config::section`].
    pub config: &'a Config,
    /// Where to write outputs and the log.
    pub run_dir: &'a RunDir,
    /// The `[run]` table: seed, threads, iteration scale.
    pub run: &'a RunConfig,
    /// Whether progress bars may draw (they also need stderr to be a terminal).
    pub show_progress: bool,
    /// `cpose run --resume`: continue the study in the run folder ([`crate::study`]): finished
    /// units are kept, unfinished ones continue from their checkpoints.
    pub resume: bool,
}

impl TaskInput<'_> {
    /// A progress bar over `len` steps (hidden unless enabled and stderr is a terminal).
    pub fn progress(
        &self,
        len: u64,
        message: impl Into<std::borrow::Cow<'static, str>>,
    ) -> Progress {
        Progress::new(len, message, self.show_progress)
    }
}

/// A task: a named entry point that `cpose run` calls with a config.
#[derive(Debug)]
pub struct Task {
    /// Name used as `task = "…"` in configs, e.g. `"trajectory"`.
    pub name: &'static str,
    /// One line for `cpose list`.
    pub about: &'static str,
    /// A complete config of the task with every key at its default, commented, that runs as it
    /// is: what `cpose config show` prints, followed by the shared `[run]` table
    /// ([`crate::config::RUN_TABLE_DEFAULTS`]).
    pub default_config: fn() -> String,
    /// Decodes and checks the whole config (every table, every value's range) without reading
    /// data or writing anything: `cpose config check`, and `cpose run` before it creates the run
    /// folder. Problems only the data can show (a missing file) are left to `run`.
    pub check: fn(&Config, &RunConfig) -> anyhow::Result<()>,
    /// Runs the task; the run folder already holds `config.toml`.
    pub run: fn(&TaskInput) -> anyhow::Result<()>,
}

inventory::collect!(Task);

/// What a pose-field builder may need besides its own section.
#[derive(Clone, Debug)]
pub struct FieldContext {
    /// Times the field must cover, seconds since the sequence origin.
    pub time_range: TimeRange,
    /// Times of the frames, seconds (for per-frame fields such as discrete poses).
    pub frame_times_secs: Vec<f64>,
    /// Seed for the field's initialisation.
    pub seed: u64,
}

/// Signature of a pose-field builder: its section of the config and the context of the run.
pub type BuildPoseField =
    fn(&Section<'_>, &FieldContext) -> Result<Box<dyn PoseField>, ConfigError>;

/// A pose field that configs choose by name: `[model]` with `kind = "<name>"`.
#[derive(Debug)]
pub struct PoseFieldSpec {
    /// The `kind` that selects it, e.g. `"posenet"`.
    pub name: &'static str,
    /// One line for `cpose list`.
    pub about: &'static str,
    /// Builds the field from its section (decode it with [`Section::decode_params`], which skips
    /// `kind`) and validates the parameters.
    pub build: BuildPoseField,
}

inventory::collect!(PoseFieldSpec);

/// Errors of registry look-ups.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum RegistryError {
    /// No entry with that name.
    #[error("unknown {what} {name:?}; known {what}s: {}", list(known))]
    Unknown {
        /// `"task"` or `"pose field"`.
        what: &'static str,
        /// The name asked for.
        name: String,
        /// The registered names, sorted.
        known: Vec<&'static str>,
    },
    /// Two registrations share a name.
    #[error("{what} {name:?} is registered twice")]
    Duplicate {
        /// `"task"` or `"pose field"`.
        what: &'static str,
        /// The name.
        name: &'static str,
    },
}

fn list(names: &[&str]) -> String {
    if names.is_empty() {
        "(none)".to_owned()
    } else {
        names.join(", ")
    }
}

/// All registered tasks, sorted by name.
pub fn tasks() -> Vec<&'static Task> {
    let mut all: Vec<_> = inventory::iter::<Task>.into_iter().collect();
    all.sort_by_key(|t| t.name);
    all
}

/// All registered pose fields, sorted by name.
pub fn pose_fields() -> Vec<&'static PoseFieldSpec> {
    let mut all: Vec<_> = inventory::iter::<PoseFieldSpec>.into_iter().collect();
    all.sort_by_key(|f| f.name);
    all
}

/// The task called `name`.
pub fn find_task(name: &str) -> Result<&'static Task, RegistryError> {
    let all = tasks();
    let found = all.iter().find(|t| t.name == name).copied();
    found.ok_or_else(|| RegistryError::Unknown {
        what: "task",
        name: name.to_owned(),
        known: all.iter().map(|t| t.name).collect(),
    })
}

/// The pose field called `name`.
pub fn find_pose_field(name: &str) -> Result<&'static PoseFieldSpec, RegistryError> {
    let all = pose_fields();
    let found = all.iter().find(|f| f.name == name).copied();
    found.ok_or_else(|| RegistryError::Unknown {
        what: "pose field",
        name: name.to_owned(),
        known: all.iter().map(|f| f.name).collect(),
    })
}

/// The task named by the config's `task` key; an unknown name is reported at its line.
pub fn task_for(config: &Config) -> Result<&'static Task, ConfigError> {
    let name = config.task_name()?;
    find_task(&name).map_err(|e| ConfigError::At {
        path: config.path().to_owned(),
        location: config.task_location(),
        message: e.to_string(),
    })
}

/// Builds the pose field that `section` selects with its `kind` key; an unknown kind is
/// reported at its line and column with the known kinds.
pub fn build_pose_field(
    section: &Section<'_>,
    ctx: &FieldContext,
) -> Result<Box<dyn PoseField>, ConfigError> {
    let (kind, offset) = section.kind()?;
    let spec = find_pose_field(&kind)
        .map_err(|e| section.config().error_at(Some(offset), e.to_string()))?;
    (spec.build)(section, ctx)
}

/// Checks that no two tasks and no two pose fields share a name (call at start-up and in a
/// test of every binary).
pub fn check_unique() -> Result<(), RegistryError> {
    first_duplicate("task", tasks().into_iter().map(|t| t.name))?;
    first_duplicate("pose field", pose_fields().into_iter().map(|f| f.name))
}

fn first_duplicate(
    what: &'static str,
    names: impl Iterator<Item = &'static str>,
) -> Result<(), RegistryError> {
    let mut seen = BTreeSet::new();
    for name in names {
        if !seen.insert(name) {
            return Err(RegistryError::Duplicate { what, name });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Order, ParamKind, PoseBatch, PoseFieldError};
    use nalgebra::Quaternion;
    use serde::Deserialize;

    fn noop(_: &TaskInput) -> anyhow::Result<()> {
        Ok(())
    }

    fn no_check(_: &Config, _: &RunConfig) -> anyhow::Result<()> {
        Ok(())
    }

    inventory::submit! { Task { name: "zz_test_b", about: "test task b", default_config: || "task = \"zz_test_b\"\n".into(), check: no_check, run: noop } }
    inventory::submit! { Task { name: "zz_test_a", about: "test task a", default_config: || "task = \"zz_test_a\"\n".into(), check: no_check, run: noop } }

    /// The identity pose over a time range, with a configurable number of dummy parameters.
    struct Identity {
        range: TimeRange,
        params: Vec<f32>,
    }

    impl PoseField for Identity {
        fn time_range(&self) -> TimeRange {
            self.range
        }
        fn num_params(&self) -> usize {
            self.params.len()
        }
        fn params(&self, visit: &mut dyn FnMut(ParamKind, &[f32])) {
            visit(ParamKind::Pose, &self.params);
        }
        fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [f32])) {
            visit(ParamKind::Pose, &mut self.params);
        }
        fn evaluate(
            &self,
            times_secs: &[f64],
            order: Order,
            out: &mut PoseBatch,
        ) -> Result<(), PoseFieldError> {
            crate::pose_field::check_times(&self.range, times_secs)?;
            out.reset(times_secs.len(), order);
            out.rotation.fill(Quaternion::identity());
            Ok(())
        }
        fn backward(
            &mut self,
            _: &[f64],
            _: &PoseBatch,
            _: &mut [f32],
        ) -> Result<(), PoseFieldError> {
            Ok(())
        }
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct IdentityConfig {
        num_params: usize,
    }

    fn build_identity(
        section: &Section<'_>,
        ctx: &FieldContext,
    ) -> Result<Box<dyn PoseField>, ConfigError> {
        let c: IdentityConfig = section.decode_params()?;
        if c.num_params > 100 {
            return Err(section.error(format!(
                "num_params: expected at most 100, got {}",
                c.num_params
            )));
        }
        Ok(Box::new(Identity {
            range: ctx.time_range,
            params: vec![0.0; c.num_params],
        }))
    }

    inventory::submit! { PoseFieldSpec { name: "zz_identity", about: "identity (test)", build: build_identity } }

    fn ctx() -> FieldContext {
        FieldContext {
            time_range: TimeRange::new(0.0, 1.0).unwrap(),
            frame_times_secs: vec![0.0, 1.0],
            seed: 0,
        }
    }

    #[test]
    fn lists_are_sorted_and_unique() {
        let names: Vec<_> = tasks().iter().map(|t| t.name).collect();
        let a = names.iter().position(|n| *n == "zz_test_a").unwrap();
        assert_eq!(names[a + 1], "zz_test_b");
        assert!(names.windows(2).all(|w| w[0] < w[1]), "{names:?}");
        assert!(pose_fields().iter().any(|f| f.name == "zz_identity"));
        check_unique().unwrap();
        let e = first_duplicate("task", ["a", "b", "a"].into_iter()).unwrap_err();
        assert_eq!(e.to_string(), "task \"a\" is registered twice");
    }

    #[test]
    fn unknown_task_lists_known_ones() {
        assert_eq!(find_task("zz_test_a").unwrap().about, "test task a");
        let e = find_task("slam.trak").unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.starts_with("unknown task \"slam.trak\"; known tasks: "),
            "{msg}"
        );
        assert!(msg.contains("zz_test_a, zz_test_b"), "{msg}");
        let config = Config::from_text("configs/x.toml", "# c\ntask = \"nope\"\n");
        let e = task_for(&config).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("configs/x.toml:2:8: unknown task \"nope\"; known tasks:"),
            "{e}"
        );
        assert_eq!(
            task_for(&Config::from_text("x", "task = \"zz_test_b\""))
                .unwrap()
                .name,
            "zz_test_b"
        );
        let e = RegistryError::Unknown {
            what: "task",
            name: "x".into(),
            known: vec![],
        };
        assert_eq!(e.to_string(), "unknown task \"x\"; known tasks: (none)");
    }

    #[test]
    fn pose_fields_build_from_sections() {
        let text = "task = \"t\"\n[model]\nkind = \"zz_identity\"\nnum_params = 3\n";
        let config = Config::from_text("x.toml", text);
        let field = build_pose_field(&config.section("model"), &ctx()).unwrap();
        assert_eq!(field.num_params(), 3);
        let mut out = PoseBatch::default();
        field.evaluate(&[0.5], Order::Pose, &mut out).unwrap();
        assert_eq!(out.rotation[0], Quaternion::identity());
    }

    #[test]
    fn pose_field_errors_are_located() {
        let bad_kind = "task = \"t\"\n[model]\nkind = \"posenett\"\n";
        let config = Config::from_text("configs/x.toml", bad_kind);
        let e = build_pose_field(&config.section("model"), &ctx())
            .err()
            .unwrap();
        let msg = e.to_string();
        assert!(
            msg.starts_with(
                "configs/x.toml:3:8: unknown pose field \"posenett\"; known pose fields: "
            ),
            "{msg}"
        );
        assert!(msg.contains("zz_identity"), "{msg}");

        let typo = "task = \"t\"\n[model]\nkind = \"zz_identity\"\nnum_param = 3\n";
        let config = Config::from_text("configs/x.toml", typo);
        let e = build_pose_field(&config.section("model"), &ctx())
            .err()
            .unwrap();
        assert_eq!(e.location().map(|l| (l.line, l.column)), Some((4, 1)));
        assert!(
            e.to_string()
                .contains("unknown field `num_param`, expected `num_params`"),
            "{e}"
        );

        let invalid = "task = \"t\"\n[model]\nkind = \"zz_identity\"\nnum_params = 300\n";
        let config = Config::from_text("configs/x.toml", invalid);
        let e = build_pose_field(&config.section("model"), &ctx())
            .err()
            .unwrap();
        assert_eq!(
            e.to_string(),
            "configs/x.toml:2:1: [model]: num_params: expected at most 100, got 300"
        );
    }
}
