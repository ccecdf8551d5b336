use std::process::{Command, Output};

use crate::util::{temp_dir, write};

fn cpose(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpose"))
        .args(args)
        .output()
        .expect("the cpose binary runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn list_prints_tasks_then_pose_fields() {
    let out = cpose(&["list"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    let tasks = text.find("tasks:\n").unwrap();
    let fields = text.find("pose fields:\n").unwrap();
    assert!(tasks < fields, "{text}");
    // The only check that catches a missing `use cpose_x as _;` in the binary.
    let names: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert_eq!(
        names,
        [
            "events",
            "nerf",
            "planar",
            "slam",
            "slam_imu",
            "synth_room",
            "trajectory",
            "composed",
            "discrete",
            "lie_spline",
            "posenet",
            "spline"
        ],
        "{text}"
    );
}

#[test]
fn no_arguments_is_a_usage_error() {
    let out = cpose(&[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("Usage"), "{}", stderr(&out));
}

#[test]
fn unknown_task_lists_known_tasks() {
    let dir = temp_dir("unknown-task");
    let config = write(&dir, "x.toml", "# a comment\ntask = \"slam.trak\"\n");
    let out = cpose(&[
        "run",
        config.to_str().unwrap(),
        "--out",
        dir.join("run").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.starts_with(&format!(
            "cpose: {}:2:8: unknown task \"slam.trak\"; known tasks: ",
            config.display()
        )),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "printed once: {err}");
    assert!(!dir.join("run").exists(), "no run folder for a bad config");
}

#[test]
fn typo_in_config_reports_line_column_and_valid_keys() {
    let dir = temp_dir("typo");
    let config = write(
        &dir,
        "x.toml",
        "task = \"any\"\n\n[run]\nseed = 1\nthreds = 4\n",
    );
    let out = cpose(&["run", config.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.starts_with(&format!(
            "cpose: {}: TOML parse error at line 5, column 1",
            config.display()
        )),
        "{err}"
    );
    assert!(err.contains("5 | threds = 4"), "{err}");
    assert!(err.contains("unknown field `threds`, expected one of `seed`, `threads`, `out_dir`, `iterations_scale`"), "{err}");
}

#[test]
fn override_with_typo_is_reported_like_a_typo_in_the_file() {
    let dir = temp_dir("override-typo");
    let config = write(&dir, "x.toml", "task = \"any\"\n");
    let out = cpose(&["run", config.to_str().unwrap(), "--set", "run.sede=3"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(err.contains("unknown field `sede`"), "{err}");
    let out = cpose(&["run", config.to_str().unwrap(), "--set", "run.seed"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).starts_with("cpose: invalid override \"run.seed\": expected key.path=value"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn malformed_toml_reports_line() {
    let dir = temp_dir("malformed");
    let config = write(&dir, "x.toml", "task = \"any\"\n[run\nseed = 1\n");
    let out = cpose(&["run", config.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.starts_with(&format!(
            "cpose: {}: TOML parse error at line 2",
            config.display()
        )),
        "{err}"
    );
}

#[test]
fn missing_config_file_names_the_file() {
    let out = cpose(&["run", "/nonexistent/cpose/x.toml"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.starts_with("cpose: cannot read config /nonexistent/cpose/x.toml: "),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn missing_task_key_is_reported() {
    let dir = temp_dir("no-task");
    let config = write(&dir, "x.toml", "[run]\nseed = 1\n");
    let out = cpose(&["run", config.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("missing field `task`"),
        "{}",
        stderr(&out)
    );
}
