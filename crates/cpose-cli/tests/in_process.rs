use std::process::ExitCode;

use cpose_core::pose_field::check_times;
use cpose_core::registry::{self, FieldContext, PoseFieldSpec, Task, TaskInput, build_pose_field};
use cpose_core::{
    ConfigError, Order, ParamKind, PoseBatch, PoseField, PoseFieldError, Section, TimeRange,
};
use nalgebra::{Quaternion, Vector3};
use serde::Deserialize;
use serde::de::IgnoredAny;

use crate::util::{temp_dir, write};

/// The parameters of the test task: everything but `task` and `[run]`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    /// Iterations before `[run] iterations_scale`.
    steps: usize,
    /// Fail after the loop (a run failure, not a config error).
    #[serde(default)]
    fail: bool,
    /// The pose field, decoded by the registry.
    #[allow(dead_code)]
    model: IgnoredAny,
}

fn fit(input: &TaskInput) -> anyhow::Result<()> {
    let params: Params = input.config.parse_params()?;
    let time_range = TimeRange::new(0.0, 2.0)?;
    let ctx = FieldContext {
        time_range,
        frame_times_secs: vec![0.0, 1.0, 2.0],
        seed: input.run.seed,
    };
    let field = build_pose_field(&input.config.section("model"), &ctx)?;
    let iterations = input.run.iterations(params.steps);
    let bar = input.progress(iterations as u64, "fit");
    for _ in 0..iterations {
        bar.inc(1);
    }
    bar.finish();
    if params.fail {
        anyhow::bail!("diverged after {iterations} iterations");
    }
    let mut out = PoseBatch::default();
    field.evaluate(&[1.0], Order::Pose, &mut out)?;
    let metrics = serde_json::json!({
        "posenet": { "iterations": iterations, "seed": input.run.seed, "trans_err_m": out.translation[0].x },
    });
    input.run_dir.write_json("metrics.json", &metrics)?;
    input.run_dir.log("fitted");
    Ok(())
}

inventory::submit! {
    Task {
        name: "zz_cli_fit",
        about: "fits nothing (test task)",
        default_config: || "task = \"zz_cli_fit\"\n[model]\nkind = \"posenet\"\n".into(),
        check: |config, _| config.parse_params::<Params>().map(drop).map_err(Into::into),
        run: fit,
    }
}

/// A constant translation along x, identity rotation.
struct Constant {
    range: TimeRange,
    x: [f32; 1],
}

impl PoseField for Constant {
    fn time_range(&self) -> TimeRange {
        self.range
    }
    fn num_params(&self) -> usize {
        1
    }
    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[f32])) {
        visit(ParamKind::Translation, &self.x);
    }
    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [f32])) {
        visit(ParamKind::Translation, &mut self.x);
    }
    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        out.reset(times_secs.len(), order);
        out.rotation.fill(Quaternion::identity());
        out.translation
            .fill(Vector3::new(f64::from(self.x[0]), 0.0, 0.0));
        Ok(())
    }
    fn backward(&mut self, _: &[f64], _: &PoseBatch, _: &mut [f32]) -> Result<(), PoseFieldError> {
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ConstantConfig {
    /// Translation along x, metres.
    x_m: f32,
}

fn build_constant(
    section: &Section<'_>,
    ctx: &FieldContext,
) -> Result<Box<dyn PoseField>, ConfigError> {
    let c: ConstantConfig = section.decode_params()?;
    Ok(Box::new(Constant {
        range: ctx.time_range,
        x: [c.x_m],
    }))
}

inventory::submit! { PoseFieldSpec { name: "zz_constant", about: "constant pose (test)", build: build_constant } }

const CONFIG: &str = "\
# Test experiment.
task = \"zz_cli_fit\"
steps = 100

[run]
iterations_scale = 0.1 # fast
threads = 1

[model]
kind = \"zz_constant\"
x_m = 0.5
";

fn cpose(args: &[&str]) -> ExitCode {
    cpose_cli::main_with_args(std::iter::once("cpose").chain(args.iter().copied()))
}

fn read(path: std::path::PathBuf) -> String {
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn registrations_of_this_test_are_listed() {
    assert!(registry::tasks().iter().any(|t| t.name == "zz_cli_fit"));
    assert!(
        registry::pose_fields()
            .iter()
            .any(|f| f.name == "zz_constant")
    );
    registry::check_unique().unwrap();
    assert_eq!(cpose(&["list"]), ExitCode::SUCCESS);
}

#[test]
fn run_writes_the_run_folder() {
    let dir = temp_dir("run");
    let config = write(&dir, "x.toml", CONFIG);
    let out = dir.join("runs/first");
    let code = cpose(&[
        "run",
        config.to_str().unwrap(),
        "--set",
        "run.seed=5",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, ExitCode::SUCCESS);
    let saved = read(out.join("config.toml"));
    assert!(saved.starts_with("# Test experiment.\n"), "{saved}");
    assert!(saved.contains("iterations_scale = 0.1 # fast"), "{saved}");
    assert!(saved.contains("seed = 5"), "{saved}");
    let metrics: serde_json::Value = serde_json::from_str(&read(out.join("metrics.json"))).unwrap();
    assert_eq!(metrics["posenet"]["iterations"], 10);
    assert_eq!(metrics["posenet"]["seed"], 5);
    assert_eq!(metrics["posenet"]["trans_err_m"], 0.5);
    let log = read(out.join("log.txt"));
    assert!(
        log.contains("task zz_cli_fit with config")
            && log.contains("fitted")
            && log.contains("done"),
        "{log}"
    );
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty());

    // The folder is not empty now: refused without --force, reused with it.
    assert_eq!(
        cpose(&[
            "run",
            config.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q"
        ]),
        ExitCode::from(2)
    );
    let code = cpose(&[
        "run",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
        "--force",
    ]);
    assert_eq!(code, ExitCode::SUCCESS);

    // `[run] out_dir` may not leave the working folder (only --out may): an absolute one is
    // refused before anything is written (commands.rs runs a relative one).
    let out_dir = dir.join("from-config");
    let set = format!("run.out_dir={}", out_dir.display());
    assert_eq!(
        cpose(&["run", config.to_str().unwrap(), "--set", &set, "-q"]),
        ExitCode::from(2)
    );
    assert!(!out_dir.exists());
}

/// Errors of the task's own `check` stop the run before its folder exists; errors inside the
/// run are logged in it. Config errors exit with 2, run failures with 1.
#[test]
fn errors_inside_the_task_are_config_or_run_failures() {
    let dir = temp_dir("task-errors");
    let cases = [
        // (override, exit code, expected in the log; none: refused before the run folder)
        (
            "model.x_n=1",
            2,
            Some("TOML parse error at line 12, column 1"),
        ),
        (
            "model.kind=zz_constnat",
            2,
            Some(":10:8: unknown pose field \"zz_constnat\"; known pose fields: "),
        ),
        ("stpes=3", 2, None),
        ("fail=true", 1, Some("task zz_cli_fit failed (run folder")),
    ];
    for (i, (set, code, expected)) in cases.into_iter().enumerate() {
        let config = write(&dir, "x.toml", CONFIG);
        let out = dir.join(format!("run{i}"));
        let got = cpose(&[
            "run",
            config.to_str().unwrap(),
            "--set",
            set,
            "--out",
            out.to_str().unwrap(),
            "-q",
        ]);
        assert_eq!(got, ExitCode::from(code), "{set}");
        match expected {
            Some(expected) => {
                let log = read(out.join("log.txt"));
                assert!(log.contains(expected), "{set}: {log}");
            }
            None => assert!(!out.exists(), "{set}: the run folder was created"),
        }
    }
}

#[test]
fn a_resumed_run_keeps_the_provenance_of_every_session() {
    let dir = temp_dir("resume-provenance");
    let config = write(&dir, "x.toml", CONFIG);
    let out = dir.join("run");
    let first = [
        "run",
        config.to_str().unwrap(),
        "--set",
        "fail=true",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ];
    assert_eq!(cpose(&first), ExitCode::from(1));
    // The resumed session reads the saved config, which still fails: set it right.
    let saved = read(out.join("config.toml")).replace("fail = true", "fail = false");
    std::fs::write(out.join("config.toml"), saved).unwrap();
    assert_eq!(
        cpose(&["run", "--resume", out.to_str().unwrap(), "-q"]),
        ExitCode::SUCCESS
    );
    let text = read(out.join("provenance.json"));
    let p: serde_json::Value = serde_json::from_str(&text).unwrap();
    let sessions = p["sessions"].as_array().unwrap();
    assert_eq!(sessions.len(), 2, "{text}");
    let expected: Vec<&str> = std::iter::once("cpose").chain(first).collect();
    assert_eq!(
        sessions[0]["command_line"],
        serde_json::json!(expected),
        "{text}"
    );
    assert!(
        sessions[0]["outcome"]
            .as_str()
            .unwrap()
            .starts_with("failed: task zz_cli_fit failed (run folder"),
        "{text}"
    );
    assert_eq!(sessions[1]["command_line"][2], "--resume");
    assert_eq!(sessions[1]["outcome"], "finished");
    for s in sessions {
        assert!(s["wall_s"].as_f64().is_some_and(|w| w >= 0.0), "{text}");
        assert!(s["finished_utc"].is_string(), "{text}");
        assert_eq!(s["threads"], 1);
    }
    // The top level is the newest session.
    assert_eq!(p["command_line"], sessions[1]["command_line"]);
    assert_eq!(p["outcome"], "finished");
}
