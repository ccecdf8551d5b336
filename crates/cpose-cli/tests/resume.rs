//! `cpose run --resume` for every task on the study skeleton: a run killed with SIGKILL in the
//! middle of a unit and resumed ends with the metrics and files of an uninterrupted run with the
//! same seed; finished units are not run again; folders that cannot be resumed say why.

// The helpers below are test code too: a failed file operation should just fail the test.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::util::{TempDir, temp_dir, unit_file};

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
            map.retain(|k, _| {
                !matches!(
                    k.as_str(),
                    "wall_s" | "cpu_s" | "fps" | "tracking_fps" | "mapping_fps"
                )
            });
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
    let ready = |dir: &Path| {
        count(dir, "result.json") >= finished && (!mid_unit || count(dir, "checkpoint.bin") > 0)
    };
    kill_when(config, settings, ready, finished, mid_unit)
}

/// [`kill_and_resume`] with the moment of the kill chosen by `ready`.
fn kill_when(
    config: &str,
    settings: &[&str],
    ready: impl Fn(&Path) -> bool,
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
    let cut = interrupt(config, settings, ready, finished, mid_unit);
    assert_eq!(metrics(&cut), metrics(&whole));
    (whole, cut)
}

/// Runs `config`, kills it with SIGKILL once `ready` holds and resumes it: at least `finished`
/// units are kept by the resume and, with `mid_unit`, one continues from its checkpoint.
fn interrupt(
    config: &str,
    settings: &[&str],
    ready: impl Fn(&Path) -> bool,
    finished: usize,
    mid_unit: bool,
) -> TempDir {
    let cut = temp_dir("resume-cut");
    let mut child = Command::new(env!("CARGO_BIN_EXE_cpose"))
        .current_dir(workspace_root())
        .args(run_args(config, settings, &cut))
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("the cpose binary starts");
    let started = Instant::now();
    while !ready(&cut) {
        assert!(
            child.try_wait().expect("the run can be polled").is_none(),
            "the run finished before it could be killed"
        );
        assert!(
            started.elapsed().as_secs() < 600,
            "not ready to be killed in 10 minutes"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().expect("the run can be killed"); // SIGKILL
    child.wait().expect("the killed run is reaped");
    let done_before = count(&cut, "result.json");
    assert!(done_before >= finished);
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
    if mid_unit {
        assert!(log.contains("resumed after step"), "{log}");
    }
    assert_eq!(
        count(&cut, "checkpoint.bin"),
        0,
        "finished units keep no checkpoint"
    );
    cut
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

/// Kills at seeded random moments — while the run starts, inside a step, while a checkpoint or
/// an output is written, after the last output — and every resume killed again the same way,
/// until one completes: the results equal the uninterrupted run's each time.
#[test]
fn trajectory_resumes_after_kills_at_random_moments() {
    let config = "configs/trajectory_fit.toml";
    let settings = [
        "fit.iterations=150",
        "fields.posenet.width=32",
        "run.threads=1",
        "run.checkpoint_secs=0",
    ];
    let whole = temp_dir("random-whole");
    let started = Instant::now();
    let out = cpose(&run_args(config, &settings, &whole));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let wall = started.elapsed().as_secs_f64();
    // xorshift64: the same moments on every run of the test.
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let finished = |dir: &Path| {
        std::fs::read_to_string(dir.join("study.json"))
            .is_ok_and(|m| m.contains("\"finished\": true"))
    };
    for trial in 0..3 {
        let cut = temp_dir("random-cut");
        let mut args = run_args(config, &settings, &cut);
        let mut kills = 0;
        loop {
            let mut child = Command::new(env!("CARGO_BIN_EXE_cpose"))
                .current_dir(workspace_root())
                .args(&args)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .expect("the cpose binary starts");
            std::thread::sleep(Duration::from_secs_f64(uniform() * wall));
            if let Some(status) = child.try_wait().expect("the run can be polled") {
                assert!(status.success(), "trial {trial}: {status}");
                break;
            }
            child.kill().expect("the run can be killed"); // SIGKILL
            child.wait().expect("the killed run is reaped");
            kills += 1;
            if finished(&cut) {
                break; // killed after its last write
            }
            // A run killed before its folder holds its config starts again; later, it resumes.
            if cut.join("config.toml").is_file() {
                args = vec![
                    "run".into(),
                    "--resume".into(),
                    cut.display().to_string(),
                    "-q".into(),
                ];
            }
            if kills == 5 {
                let out = cpose(&args);
                assert!(
                    out.status.success(),
                    "{}",
                    String::from_utf8_lossy(&out.stderr)
                );
                break;
            }
        }
        assert_eq!(
            metrics(&cut),
            metrics(&whole),
            "trial {trial}, {kills} kills"
        );
        same_trajectories(&whole, &cut);
    }
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

/// NeRF units checkpoint their whole training state (field, poses, optimisers, generator): the
/// killed unit continues from its last step.
#[test]
fn nerf_resumes_after_kill_9_with_the_uninterrupted_results() {
    let settings = [
        "train.iterations=60",
        "train.rays_per_step=64",
        "render.samples=16",
        "eval.refine_iterations=2",
        "eval.refine_rays=64",
        "data.test_views=2",
        "eval.saved_views=1",
        "data.width=24",
        "data.height=24",
        "orbit.frames=12",
        "run.threads=1",
        "run.checkpoint_secs=0",
    ];
    let (whole, cut) = kill_and_resume("configs/nerf_synthetic.toml", &settings, 1, true);
    same_trajectories(&whole, &cut);
}

/// `slam` checkpoints its map, estimates and pose model: the killed method continues after its
/// last frame. The per-frame tracking log keeps the rows from before the kill, none twice, and
/// its errors are those of the trajectory.
#[test]
fn slam_resumes_after_kill_9_with_the_uninterrupted_trajectory() {
    let data = temp_dir("resume-room");
    let path = format!("data.path={}", data.display());
    let settings = [
        "synthetic.frames=24",
        "synthetic.width=48",
        "tracking.edge=2",
        "tracking.pixels=64",
        "mapping.pixels=128",
        "mapping.first_iterations=40",
        "slam.methods=[\"baseline\", \"prev\"]",
        "run.threads=1",
        "run.checkpoint_secs=0",
        &path,
    ];
    let (whole, cut) = kill_and_resume("configs/synthetic_room.toml", &settings, 1, true);
    same_trajectories(&whole, &cut);
    let rows = |dir: &Path| -> Vec<Vec<f64>> {
        let text = std::fs::read_to_string(unit_file(dir, "tracking", "prev", "csv")).unwrap();
        let mut lines = text.lines();
        assert!(
            lines
                .next()
                .unwrap()
                .starts_with("frame,time_s,start_error_cm,error_cm,")
        );
        lines
            .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
            .collect()
    };
    let (whole_rows, cut_rows) = (rows(&whole), rows(&cut));
    let frames: Vec<f64> = whole_rows.iter().map(|r| r[0]).collect();
    assert_eq!(frames, (1..24).map(f64::from).collect::<Vec<_>>());
    assert_eq!(whole_rows, cut_rows);
    let a = cpose_core::eval::read_tum(unit_file(&whole, "traj", "prev", "txt")).unwrap();
    let gt = cpose_core::eval::read_tum(whole.join("traj_gt.txt")).unwrap();
    for r in &whole_rows {
        let (i, start_cm, cm, moved_cm) = (r[0] as usize, r[2], r[3], r[6]);
        let truth = 100.0 * (a.poses()[i].translation.vector - gt.poses()[i].translation.vector);
        assert!(
            (cm - truth.norm()).abs() < 2e-3,
            "frame {i}: {cm} against {truth}"
        );
        // The start is where tracking began: the two errors differ by at most the move.
        assert!((cm - start_cm).abs() <= moved_cm + 2e-3, "frame {i}: {r:?}");
    }
    // Frame 0 is at its true pose, so frame 1's start is off from the truth by as much as its
    // motion from frame 0 is off from the true motion.
    let first = &whole_rows[0];
    assert!((first[11] - first[2]).abs() < 2e-3, "{first:?}");
    assert!((first[12] - first[4]).abs() < 2e-4, "{first:?}");
}

/// `slam_imu` runs its methods through the same units as `slam`.
#[test]
fn slam_imu_resumes_after_kill_9_with_the_uninterrupted_results() {
    let data = temp_dir("resume-imu");
    let path = format!("data.path={}", data.display());
    let settings = [
        "synthetic.width=48",
        "synthetic.frames=21",
        "tracking.edge=2",
        "tracking.pixels=64",
        "tracking.iterations=5",
        "mapping.pixels=128",
        "mapping.first_iterations=20",
        "mapping.iterations=5",
        "imu.predict_steps=3",
        "mesh.voxel=0",
        "slam.methods=[\"baseline\", \"tight\"]",
        "run.threads=1",
        "run.checkpoint_secs=0",
        &path,
    ];
    let (whole, cut) = kill_and_resume("configs/synthetic_imu.toml", &settings, 1, true);
    same_trajectories(&whole, &cut);
}

/// `synth_room` is one unit: killed while it writes the room, it writes it again.
#[test]
fn synth_room_resumes_after_kill_9_with_the_same_room() {
    let (a, b) = (temp_dir("resume-synth-a"), temp_dir("resume-synth-b"));
    let (path_a, path_b) = (
        format!("output.path={}", a.display()),
        format!("output.path={}", b.display()),
    );
    let small = ["synthetic.frames=60", "synthetic.width=48", "run.threads=1"];
    let whole = temp_dir("resume-synth-whole");
    let mut settings: Vec<&str> = small.to_vec();
    settings.push(&path_a);
    let out = cpose(&run_args("configs/synth_room.toml", &settings, &whole));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The interrupted run writes into its own folder (through a staging folder beside it),
    // killed once a few frames are there.
    let mut settings: Vec<&str> = small.to_vec();
    settings.push(&path_b);
    let staging = format!(".{}.generating-", b.file_name().unwrap().to_string_lossy());
    let beside = {
        let (parent, staging) = (b.parent().unwrap().to_path_buf(), staging.clone());
        move || -> Vec<PathBuf> {
            std::fs::read_dir(&parent)
                .unwrap()
                .flatten()
                .filter(|e| e.file_name().to_string_lossy().starts_with(&staging))
                .map(|e| e.path())
                .collect()
        }
    };
    let frames = |dir: &Path| std::fs::read_dir(dir.join("results")).map_or(0, |e| e.count());
    let staged = beside.clone();
    let cut = interrupt(
        "configs/synth_room.toml",
        &settings,
        move |_| staged().iter().any(|d| frames(d) >= 4),
        0,
        false,
    );
    // The resumed run generated the room again and removed the killed one's staging folder.
    assert_eq!(beside(), Vec::<PathBuf>::new());
    assert_eq!(metrics(&cut)["room"]["synthetic"]["frames"], 60);
    for name in [
        "traj.txt",
        "results/frame000059.jpg",
        "results/depth000059.png",
    ] {
        assert_eq!(
            std::fs::read(a.join(name)).ok(),
            std::fs::read(b.join(name)).ok(),
            "{name}"
        );
    }
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
