//! `cpose run --resume` for every task on the study skeleton: a run killed with SIGKILL in the
//! middle of a unit and resumed ends with the metrics and files of an uninterrupted run with the
//! same seed; finished units are not run again; folders that cannot be resumed say why.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::util::{TempDir, temp_dir};

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn cpose(args: &[String]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpose"))
        .current_dir(workspace_root())
        .args(args)
        .output()
        .expect("the cpose binary runs")
}

fn run_args(config: &str, settings: &[&str], out: &Path) -> Vec<String> {
    let mut args = vec![
        "run".to_string(),
        config.to_string(),
        "-q".into(),
        "--out".into(),
        out.display().to_string(),
    ];
    for s in settings {
        args.extend(["--set".into(), (*s).to_string()]);
    }
    args
}

/// Files of a run folder's units that exist.
fn count(dir: &Path, file: &str) -> usize {
    std::fs::read_dir(dir.join("units"))
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .filter(|e| e.path().join(file).is_file())
                .count()
        })
        .unwrap_or(0)
}

/// `metrics.json` without the keys that measure time.
fn metrics(dir: &Path) -> Value {
    fn strip(v: &mut Value) {
        if let Value::Object(map) = v {
            map.retain(|k, _| !matches!(k.as_str(), "wall_s" | "cpu_s" | "fps"));
            map.values_mut().for_each(strip);
        }
    }
    let text = std::fs::read_to_string(dir.join("metrics.json")).expect("metrics.json");
    let mut v = serde_json::from_str(&text).expect("metrics.json is JSON");
    strip(&mut v);
    v
}

/// Runs `config` once uninterrupted and once killed with SIGKILL as soon as `finished` units are
/// done (and, with `mid_unit`, another has a checkpoint), then resumed. Returns both folders.
fn kill_and_resume(
    config: &str,
    settings: &[&str],
    finished: usize,
    mid_unit: bool,
) -> (TempDir, TempDir) {
    let whole = temp_dir("resume-whole");
    let out = cpose(&run_args(config, settings, &whole));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cut = temp_dir("resume-cut");
    let mut child = Command::new(env!("CARGO_BIN_EXE_cpose"))
        .current_dir(workspace_root())
        .args(run_args(config, settings, &cut))
        .spawn()
        .expect("the cpose binary starts");
    let started = Instant::now();
    while count(&cut, "result.json") < finished || (mid_unit && count(&cut, "checkpoint.bin") == 0)
    {
        assert!(
            child.try_wait().expect("the run can be polled").is_none(),
            "the run finished before it could be killed"
        );
        assert!(
            started.elapsed().as_secs() < 600,
            "no checkpoint in 10 minutes"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().expect("the run can be killed"); // SIGKILL
    child.wait().expect("the killed run is reaped");
    let done_before = count(&cut, "result.json");
    let out = cpose(&[
        "run".into(),
        "--resume".into(),
        cut.display().to_string(),
        "-q".into(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let log = std::fs::read_to_string(cut.join("log.txt")).expect("log.txt");
    assert_eq!(
        log.matches("finished before the resume").count(),
        done_before,
        "{log}"
    );
    assert_eq!(log.contains("resumed after step"), mid_unit, "{log}");
    assert_eq!(metrics(&cut), metrics(&whole));
    assert_eq!(
        count(&cut, "checkpoint.bin"),
        0,
        "finished units keep no checkpoint"
    );
    (whole, cut)
}

/// Every `traj_*.txt` of `a` equals the one of `b`, byte for byte.
fn same_trajectories(a: &Path, b: &Path) {
    let mut n = 0;
    for entry in std::fs::read_dir(a).expect("the run folder") {
        let name = entry
            .expect("a folder entry")
            .file_name()
            .to_string_lossy()
            .into_owned();
        if name.starts_with("traj_") && name.ends_with(".txt") {
            let (x, y) = (
                std::fs::read(a.join(&name)).expect("a trajectory"),
                std::fs::read(b.join(&name)),
            );
            assert_eq!(Some(x), y.ok(), "{name}");
            n += 1;
        }
    }
    assert!(n > 0, "no trajectories in {}", a.display());
}

#[test]
fn trajectory_resumes_after_kill_9_with_the_uninterrupted_results() {
    let settings = [
        "fit.iterations=150",
        "fields.posenet.width=32",
        "run.threads=1",
        "run.checkpoint_secs=0",
    ];
    let (whole, cut) = kill_and_resume("configs/trajectory_fit.toml", &settings, 2, true);
    same_trajectories(&whole, &cut);

    // The finished folder cannot be resumed again, and an edited config is refused.
    let resume = vec![
        "run".into(),
        "--resume".into(),
        cut.display().to_string(),
        "-q".into(),
    ];
    let out = cpose(&resume);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("the run finished"), "{err}");
    let manifest = std::fs::read_to_string(cut.join("study.json")).unwrap();
    std::fs::write(
        cut.join("study.json"),
        manifest.replace("\"finished\": true", "\"finished\": false"),
    )
    .unwrap();
    let config = std::fs::read_to_string(cut.join("config.toml")).unwrap();
    std::fs::write(
        cut.join("config.toml"),
        config.replace("known_every = 20", "known_every = 10"),
    )
    .unwrap();
    let out = cpose(&resume);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("config.toml was changed"), "{err}");
}

/// Planar units are short and keep no checkpoint: the killed unit runs again from its start.
#[test]
fn planar_resumes_after_kill_9_with_the_uninterrupted_results() {
    let settings = [
        "motion.trajectories=2",
        "train.iterations=60",
        "train.pixels_per_step=512",
        "image.procedural_size=[160,120]",
        "image.crop_px=80",
        "run.threads=1",
    ];
    let (whole, cut) = kill_and_resume("configs/planar.toml", &settings, 2, false);
    for name in ["overlay_procedural_posenet_s0.png", "curves.csv"] {
        assert!(cut.join(name).is_file(), "{name}");
    }
    let _ = whole;
}

/// Events units checkpoint every step here: the PoseNet unit, killed half-way, continues from
/// its field, pose correction, optimisers and random draws.
#[test]
fn events_resumes_after_kill_9_with_the_uninterrupted_results() {
    let settings = [
        "simulation.width=24",
        "simulation.height=18",
        "simulation.render_steps=40",
        "simulation.held_out_views=1",
        "experiment.known_poses=[6]",
        "train.methods=[\"eventnerf\",\"posenet\"]",
        "train.iterations=40",
        "train.rays_per_step=64",
        "train.windows_per_step=2",
        "render.samples=12",
        "eval.pose_samples=10",
        "run.report_every=10",
        "run.threads=1",
        "run.checkpoint_secs=0",
    ];
    let (whole, cut) = kill_and_resume("configs/events_interp.toml", &settings, 1, true);
    same_trajectories(&whole, &cut);
    assert!(cut.join("view_0_K6_posenet.png").is_file());
    // The live curves agree too, but for their wall-clock column.
    let curves = |d: &Path| -> Vec<String> {
        let text = std::fs::read_to_string(d.join("curves.csv")).unwrap();
        text.lines()
            .map(|l| {
                let mut c: Vec<&str> = l.split(',').collect();
                c.remove(4);
                c.join(",")
            })
            .collect()
    };
    assert_eq!(curves(&cut), curves(&whole));
}
