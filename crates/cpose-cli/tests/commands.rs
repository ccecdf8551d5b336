//! `cpose eval ate` against the library (which agrees with evo, see cpose-core's
//! tests/eval_evo.rs), bad trajectory files, and a smoke run of every committed config.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use cpose_core::eval::{self, Alignment, RpeDelta};

use crate::util::{method_metrics, temp_dir, unit_file, write};

fn cpose_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpose"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("the cpose binary runs")
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tum_dir() -> Option<PathBuf> {
    let dir = cpose_core::fs::shared_data_dir()?.join("tum/fr1_xyz");
    dir.is_dir().then_some(dir)
}

/// The value after `label` on the line that starts with it.
fn value_after(text: &str, label: &str) -> f64 {
    let line = text
        .lines()
        .find(|l| l.starts_with(label))
        .unwrap_or_else(|| panic!("no {label:?} in {text}"));
    line[label.len()..]
        .split_whitespace()
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no number after {label:?} in {line:?}"))
}

#[test]
fn eval_ate_prints_the_library_rmse_for_each_alignment() {
    let Some(dir) = tum_dir() else {
        eprintln!("skipped: shared data folder not found (set CPOSE_DATA_DIR)");
        return;
    };
    let (gt, est) = (
        dir.join("groundtruth.txt"),
        dir.join("rgbdslam_estimate.txt"),
    );
    let gt_traj = eval::read_tum(&gt).unwrap();
    let est_traj = eval::read_tum(&est).unwrap();
    for align in Alignment::ALL {
        let out = cpose_in(
            &workspace_root(),
            &[
                "eval",
                "ate",
                gt.to_str().unwrap(),
                est.to_str().unwrap(),
                "--align",
                align.as_str(),
            ],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let expected = eval::ate(&gt_traj, &est_traj, align, 0.01).unwrap();
        let printed = value_after(&text, "rmse");
        assert!(
            (printed - expected.rmse_m).abs() <= 1e-9 * expected.rmse_m,
            "{align}: {printed} vs {}",
            expected.rmse_m
        );
        assert!(
            text.contains(&format!("matched {} pose pairs", expected.num_matched)),
            "{text}"
        );
    }
    // Default alignment is se3 (evo -a): 0.013470 m on these files.
    let out = cpose_in(
        &workspace_root(),
        &[
            "eval",
            "ate",
            gt.to_str().unwrap(),
            est.to_str().unwrap(),
            "--json",
        ],
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["alignment"], "se3");
    assert!((report["rmse_m"].as_f64().unwrap() - 0.013470088849734).abs() < 1e-12);
}

#[test]
fn eval_ate_rejects_malformed_trajectories_with_file_and_line() {
    let dir = temp_dir("bad-tum");
    let good = write(
        &dir,
        "good.txt",
        "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n3.0 1 1 0 0 0 0 1\n",
    );
    let cases = [
        (
            "columns.txt",
            "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 1\n",
            "line 2",
            "expected 8 columns",
        ),
        (
            "nan.txt",
            "1.0 0 0 0 0 0 0 1\n2.0 nan 0 0 0 0 0 1\n",
            "line 2",
            "finite",
        ),
        (
            "unsorted.txt",
            "2.0 0 0 0 0 0 0 1\n1.0 1 0 0 0 0 0 1\n",
            "line 2",
            "increasing",
        ),
    ];
    for (name, text, line, what) in cases {
        let bad = write(&dir, name, text);
        let out = cpose_in(
            &dir,
            &["eval", "ate", good.to_str().unwrap(), bad.to_str().unwrap()],
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(
            err.contains(line) && err.to_lowercase().contains(what) && err.contains(name),
            "{name}: {err}"
        );
        assert_eq!(err.lines().count(), 1, "{name}: printed once: {err}");
    }
    // A repeated timestamp is read (the later pose kept) and reported once, as evo reads it.
    let repeated = write(
        &dir,
        "repeated.txt",
        "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n2.0 1 0.1 0 0 0 0 1\n3.0 1 1 0 0 0 0 1\n",
    );
    let out = cpose_in(
        &dir,
        &[
            "eval",
            "ate",
            good.to_str().unwrap(),
            repeated.to_str().unwrap(),
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("repeated.txt: 1 repeated timestamp(s) (first on line 3)"),
        "{err}"
    );
    let missing = dir.join("missing.txt");
    let out = cpose_in(
        &dir,
        &[
            "eval",
            "ate",
            good.to_str().unwrap(),
            missing.to_str().unwrap(),
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.txt"));
}

#[test]
fn eval_rpe_prints_the_library_report_in_frames_and_metres() {
    let Some(dir) = tum_dir() else {
        eprintln!("skipped: shared data folder not found (set CPOSE_DATA_DIR)");
        return;
    };
    let (gt, est) = (
        dir.join("groundtruth.txt"),
        dir.join("rgbdslam_estimate.txt"),
    );
    let gt_traj = eval::read_tum(&gt).unwrap();
    let est_traj = eval::read_tum(&est).unwrap();
    for (delta, unit, expected) in [
        ("3", "f", RpeDelta::Frames(3)),
        ("0.2", "m", RpeDelta::Metres(0.2)),
    ] {
        let out = cpose_in(
            &workspace_root(),
            &[
                "eval",
                "rpe",
                gt.to_str().unwrap(),
                est.to_str().unwrap(),
                "--delta",
                delta,
                "--delta-unit",
                unit,
                "--json",
            ],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let ours = eval::rpe_report(&gt_traj, &est_traj, 0.01, expected, Alignment::None).unwrap();
        assert_eq!(report["trans_rmse_m"].as_f64().unwrap(), ours.trans_rmse_m);
        assert_eq!(report["rot_rmse_deg"].as_f64().unwrap(), ours.rot_rmse_deg);
        assert_eq!(
            report["num_pairs"].as_u64().unwrap() as usize,
            ours.num_pairs
        );
    }
    // --plot draws the errors (and for ate the trajectories) into a new folder, never over a plot.
    let plots = temp_dir("eval-plots").join("plots");
    for (command, file) in [("ate", "ate_trajectories.png"), ("rpe", "rpe_error.png")] {
        let args = [
            "eval",
            command,
            gt.to_str().unwrap(),
            est.to_str().unwrap(),
            "--plot",
        ];
        let out = cpose_in(
            &workspace_root(),
            &[&args[..], &[plots.to_str().unwrap()]].concat(),
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            std::fs::read(plots.join(file))
                .unwrap()
                .starts_with(b"\x89PNG")
        );
        let again = cpose_in(
            &workspace_root(),
            &[&args[..], &[plots.to_str().unwrap()]].concat(),
        );
        assert_eq!(again.status.code(), Some(2));
    }
    // Half a frame is no delta.
    let out = cpose_in(
        &workspace_root(),
        &[
            "eval",
            "rpe",
            gt.to_str().unwrap(),
            est.to_str().unwrap(),
            "--delta",
            "0.5",
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("whole number of frames"));
}

#[test]
fn convert_round_trips_every_format_and_never_replaces_a_file_unasked() {
    let dir = temp_dir("convert");
    let tum = write(
        &dir,
        "in.txt",
        "1.5 0 0 0 0 0 0 1\n2.0 1 0.5 0 0 0 0.6 0.8\n3.25 1 1 2 0.5 0.5 0.5 0.5\n",
    );
    let original = eval::read_tum(&tum).unwrap();
    let path = |name: &str| dir.join(name).to_str().unwrap().to_owned();
    let steps: [&[&str]; 3] = [
        &["convert", &path("in.txt"), &path("a.csv")],
        &[
            "convert",
            &path("a.csv"),
            &path("b.kitti"),
            "--to",
            "kitti",
            "--out-times",
            &path("b.times"),
        ],
        &[
            "convert",
            &path("b.kitti"),
            &path("c.txt"),
            "--times",
            &path("b.times"),
        ],
    ];
    for args in steps {
        let out = cpose_in(&dir, args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let euroc = std::fs::read_to_string(dir.join("a.csv")).unwrap();
    assert!(
        euroc.starts_with("#timestamp [ns]")
            && euroc.contains("\n2000000000,1,0.5,0,0.8,0,0,0.6\n"),
        "{euroc}"
    );
    let back = eval::read_tum(dir.join("c.txt")).unwrap();
    assert_eq!(back.timestamps_secs(), original.timestamps_secs());
    for (a, b) in back.poses().iter().zip(original.poses()) {
        assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
        assert!(a.rotation.angle_to(&b.rotation) < 1e-9);
    }
    // An existing output is kept unless --force; a KITTI input without its times is refused.
    let before = std::fs::read(dir.join("c.txt")).unwrap();
    let out = cpose_in(&dir, &["convert", &path("a.csv"), &path("c.txt")]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--force"));
    assert_eq!(std::fs::read(dir.join("c.txt")).unwrap(), before);
    let out = cpose_in(&dir, &["convert", &path("b.kitti"), &path("d.txt")]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("times file") && err.contains("b.kitti") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!dir.join("d.txt").exists());
}

#[test]
fn the_synthetic_room_is_never_generated_into_a_folder_it_did_not_write() {
    let dir = temp_dir("real-dataset");
    let real = dir.join("replica_room");
    std::fs::create_dir_all(&real).unwrap();
    let frame = write(&real, "frame000000.jpg", "the user's own frame");
    // `slam` generating its data, and `synth_room` writing the dataset.
    for (config, key) in [
        ("configs/synthetic_room.toml", "data.path"),
        ("configs/synth_room.toml", "output.path"),
    ] {
        let config = workspace_root().join(config);
        let path = format!("{key}={:?}", real.to_str().unwrap());
        let out_dir = dir.join(format!("run-{key}"));
        let out = cpose_in(
            &dir,
            &[
                "run",
                config.to_str().unwrap(),
                "--set",
                &path,
                "--out",
                out_dir.to_str().unwrap(),
                "-q",
            ],
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.contains("not written by the synthetic generator"),
            "{err}"
        );
        assert_eq!(
            std::fs::read_to_string(&frame).unwrap(),
            "the user's own frame"
        );
        assert_eq!(std::fs::read_dir(&real).unwrap().count(), 1);
    }
}

#[test]
fn config_out_dir_stays_below_the_working_folder_and_force_replaces_only_a_run() {
    let dir = temp_dir("out-dir");
    let config = workspace_root().join("configs/trajectory_fit.toml");
    let quick = [
        "--set",
        "run.iterations_scale=0.002",
        "--set",
        "run.threads=1",
        "-q",
    ];
    let run = |extra: &[&str]| {
        let args = [&["run", config.to_str().unwrap()][..], extra, &quick[..]].concat();
        cpose_in(&dir, &args)
    };
    // A relative [run] out_dir is used when there is no --out.
    let out = run(&["--set", "run.out_dir=\"from-config\""]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("from-config/metrics.json").exists());
    // One that leaves the working folder is refused, naming --out.
    let out = run(&["--set", "run.out_dir=\"../escaped\""]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--out"));
    assert!(!dir.join("../escaped").exists());
    // --force clears the earlier run first (no stale files), but never a folder without a run.
    write(&dir.join("from-config"), "stale.txt", "old");
    let out = run(&["--out", "from-config", "--force"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!dir.join("from-config/stale.txt").exists());
    let mine = dir.join("mine");
    std::fs::create_dir_all(&mine).unwrap();
    write(&mine, "notes.txt", "mine");
    let out = run(&["--out", "mine", "--force"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a run folder"));
    assert_eq!(
        std::fs::read_to_string(mine.join("notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
fn completions_cover_every_command_for_every_shell() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let out = cpose_in(&workspace_root(), &["completions", shell]);
        assert!(out.status.success(), "{shell}");
        let script = String::from_utf8(out.stdout).unwrap();
        for command in ["run", "eval", "rpe", "convert", "table", "list"] {
            assert!(script.contains(command), "{shell}: no {command}");
        }
    }
    let out = cpose_in(&workspace_root(), &["completions", "tcsh"]);
    assert_eq!(out.status.code(), Some(2));
}

/// A run folder records which build, command line and machine made it (`provenance.json`), and
/// `cpose table` prints its counts as integers, on stdout.
#[test]
fn run_records_provenance_and_table_prints_counts_as_integers() {
    let dir = temp_dir("provenance");
    let out_dir = dir.join("run");
    let config = workspace_root().join("configs/trajectory_fit.toml");
    let args = [
        "run",
        config.to_str().unwrap(),
        "--set",
        "run.iterations_scale=0.005",
        "--set",
        "run.threads=1",
        "--out",
        out_dir.to_str().unwrap(),
        "-q",
    ];
    let out = cpose_in(&dir, &args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(out_dir.join("provenance.json")).unwrap();
    let p: serde_json::Value = serde_json::from_str(&text).unwrap();
    let commit = &p["commit"];
    assert!(
        commit.is_null()
            || commit
                .as_str()
                .is_some_and(|c| { c.len() == 40 && c.bytes().all(|b| b.is_ascii_hexdigit()) }),
        "{text}"
    );
    assert!(p["dirty"].is_boolean() || p["dirty"].is_null(), "{text}");
    assert_eq!(p["cpose_version"], env!("CARGO_PKG_VERSION"));
    let command_line: Vec<&str> = p["command_line"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap())
        .collect();
    assert_eq!(command_line[1..], args, "{text}");
    assert!(
        p["machine"]["logical_cpus"]
            .as_u64()
            .is_some_and(|n| n >= 1),
        "{text}"
    );
    assert_eq!(p["machine"]["os"], std::env::consts::OS);
    assert_eq!(p["threads"], 1);
    assert!(p["wall_s"].as_f64().is_some_and(|w| w > 0.0), "{text}");
    assert_eq!(p["outcome"], "finished");
    assert_eq!(p["sessions"].as_array().map(Vec::len), Some(1), "{text}");
    assert_eq!(p["sessions"][0]["wall_s"], p["wall_s"]);
    let log = std::fs::read_to_string(out_dir.join("log.txt")).unwrap();
    let first = log.lines().next().unwrap_or_default();
    assert!(
        first.contains(&format!("] cpose {} (", env!("CARGO_PKG_VERSION")))
            && first.contains(") on ")
            && first.ends_with(", 1 thread"),
        "{log}"
    );

    // `held_out_poses` is a JSON integer: printed as one, in a table on stdout.
    let out = cpose_in(&dir, &["table", out_dir.to_str().unwrap()]);
    assert!(
        out.status.success() && out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8(out.stdout).unwrap();
    let cells = |line: usize| -> Vec<&str> {
        let row = table.lines().nth(line).unwrap_or_default();
        row.split('|').map(str::trim).collect()
    };
    let column = cells(0)
        .iter()
        .position(|h| *h == "held_out_poses")
        .unwrap();
    let row = cells(2);
    assert_eq!(row[column], "950", "{table}");
}

/// Every committed config runs end to end at 0.5% of its iterations, one thread, from a folder
/// outside the repository: configs that read the shared real data find it through
/// `${CPOSE_DATA_DIR}` and are skipped when it is missing.
#[test]
fn every_config_runs_as_a_smoke_test() {
    let configs_dir = workspace_root().join("configs");
    let mut configs: Vec<PathBuf> = std::fs::read_dir(&configs_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    configs.sort();
    // Every task's `cpose config show` too: it must run as it is.
    let defaults = temp_dir("defaults");
    for task in shipped_tasks() {
        let out = cpose_in(&defaults, &["config", "show", task]);
        assert!(out.status.success(), "{task}");
        let text = String::from_utf8(out.stdout).unwrap();
        configs.push(write(&defaults, &format!("default_{task}.toml"), &text));
    }
    assert!(configs.len() >= 2, "{configs:?}");
    let has_data = cpose_core::fs::shared_data_dir().is_some();
    for config in configs {
        let text = std::fs::read_to_string(&config).unwrap();
        let needs_data = text.contains("path = \"${CPOSE_DATA_DIR}");
        if needs_data && !has_data {
            eprintln!("skipped {}: shared data folder not found", config.display());
            continue;
        }
        // The run's folder and any data it generates, removed after the config.
        let scratch = temp_dir("smoke");
        let mut args: Vec<String> =
            vec!["run".into(), config.to_str().unwrap().into(), "-q".into()];
        if text.contains("task = \"nerf\"") {
            // Volume rendering in the test profile: a few small views and rays.
            for set in [
                "train.rays_per_step=64",
                "render.samples=16",
                "eval.refine_iterations=2",
                "eval.refine_rays=64",
                "data.test_views=2",
                "eval.saved_views=1",
            ] {
                args.extend(["--set".into(), set.into()]);
            }
            if !text.contains("source = \"llff\"") {
                for set in ["data.width=24", "data.height=24", "orbit.frames=12"] {
                    args.extend(["--set".into(), set.into()]);
                }
            }
        }
        if text.contains("task = \"slam\"") && text.contains("source = \"synthetic\"") {
            let data_dir = scratch.join("room");
            for set in [
                "synthetic.frames=6".to_string(),
                "synthetic.width=48".to_string(),
                "tracking.edge=2".to_string(),
                "tracking.pixels=32".to_string(),
                "mapping.pixels=64".to_string(),
                "mesh.voxel=0.25".to_string(),
                format!("data.path={}", data_dir.display()),
            ] {
                args.extend(["--set".into(), set]);
            }
        }
        if text.contains("task = \"slam\"") && needs_data {
            // Real frames: the first three, few pixels, a coarse mesh.
            for set in [
                "data.frames=3",
                "tracking.pixels=32",
                "mapping.pixels=64",
                "mesh.voxel=0.25",
            ] {
                args.extend(["--set".into(), set.into()]);
            }
        }
        let users_data = text.contains("source = \"colmap\"")
            || (text.contains("task = \"slam\"") && !text.contains("source = \"synthetic\""));
        if users_data && !needs_data {
            // Real RGB-D datasets and a user's capture are not in the shared data: the run must
            // stop with one clear message naming the folder (and, for Replica, where it comes
            // from).
            let path = text
                .lines()
                .find_map(|l| l.strip_prefix("path = \""))
                .and_then(|l| l.split('"').next())
                .unwrap();
            if workspace_root().join(path).exists() {
                eprintln!("skipped {}: a real dataset is present", config.display());
                continue;
            }
            let out_dir = scratch.join("run");
            args.extend(["--out".into(), out_dir.to_str().unwrap().into()]);
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let out = cpose_in(&workspace_root(), &args);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(!out.status.success(), "{}", config.display());
            assert!(stderr.contains(path), "{}: {stderr}", config.display());
            if text.contains("source = \"replica\"") {
                assert!(
                    stderr.contains("download_replica.sh") && stderr.contains("synth_room.toml"),
                    "{stderr}"
                );
            }
            continue;
        }
        if text.contains("task = \"slam_imu\"") {
            let data_dir = scratch.join("frames");
            for set in [
                "synthetic.frames=12".to_string(),
                "synthetic.width=48".to_string(),
                "tracking.edge=2".to_string(),
                "tracking.pixels=32".to_string(),
                "mapping.pixels=64".to_string(),
                "imu.predict_steps=2".to_string(),
                "mesh.voxel=0".to_string(),
                format!("data.path={}", data_dir.display()),
            ] {
                args.extend(["--set".into(), set]);
            }
        }
        if text.contains("task = \"events\"") {
            // A 24 × 18 sensor over 40 renders, small batches.
            for set in [
                "simulation.width=24",
                "simulation.height=18",
                "simulation.render_steps=40",
                "simulation.held_out_views=1",
                "train.rays_per_step=64",
                "train.windows_per_step=2",
                "render.samples=12",
                "eval.pose_samples=10",
            ] {
                args.extend(["--set".into(), set.into()]);
            }
        }
        if text.contains("task = \"synth_room\"") {
            let data_dir = scratch.join("room");
            for set in [
                "synthetic.frames=3".to_string(),
                "synthetic.width=32".to_string(),
                format!("output.path={}", data_dir.display()),
            ] {
                args.extend(["--set".into(), set]);
            }
        }
        let out_dir = scratch.join("run");
        args.extend([
            "--set".into(),
            "run.iterations_scale=0.005".into(),
            "--set".into(),
            "run.threads=1".into(),
            "--out".into(),
            out_dir.to_str().unwrap().into(),
        ]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = cpose_in(&scratch, &args);
        assert!(
            out.status.success(),
            "{}: {}",
            config.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        for file in ["config.toml", "metrics.json", "log.txt"] {
            assert!(
                out_dir.join(file).is_file(),
                "{}: no {file}",
                config.display()
            );
        }
        let metrics: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out_dir.join("metrics.json")).unwrap())
                .unwrap();
        assert!(
            metrics.as_object().is_some_and(|m| !m.is_empty()),
            "{}: empty metrics",
            config.display()
        );
        if config.ends_with("nerf_synthetic.toml") {
            // The noisy start's errors, BARF's and with the cameras' common turn removed.
            let posenet = &metrics["synthetic"]["posenet"];
            for key in ["init_rot_err_deg", "init_rot_err_relative_deg"] {
                assert!(
                    posenet[key].as_f64().is_some_and(|e| e > 1.0),
                    "{key}: {metrics}"
                );
            }
        }
        if text.contains("task = \"slam\"") {
            let mesh =
                std::fs::read(unit_file(&out_dir, "mesh", "baseline", "ply")).unwrap_or_default();
            assert!(mesh.starts_with(b"ply\n"), "{}: no mesh", config.display());
        }
    }
}

/// The tasks cpose ships (the test's own registrations start with `zz_`).
fn shipped_tasks() -> Vec<&'static str> {
    let tasks: Vec<_> = cpose_core::registry::tasks()
        .into_iter()
        .map(|t| t.name)
        .filter(|name| !name.starts_with("zz_"))
        .collect();
    assert!(tasks.len() >= 7, "{tasks:?}");
    tasks
}

/// The keys serde lists after "expected" in an unknown-field error.
fn expected_keys(message: &str) -> Vec<String> {
    let (_, list) = message
        .split_once(", expected")
        .unwrap_or_else(|| panic!("no list of valid keys in {message}"));
    let list = list.lines().next().unwrap_or_default();
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_owned)
        .collect()
}

/// `cpose config show TASK` prints a config that `cpose config check` accepts, with every key
/// the task reads: a probe key added to each table is refused with the table's valid keys, and
/// each of them is in the table, set or commented (a commented key has no default value). The
/// values are pinned to the defaults by each task's own unit test.
#[test]
fn config_show_prints_every_key_and_config_check_accepts_it() {
    let dir = temp_dir("config-show");
    for task in shipped_tasks() {
        let out = cpose_in(&dir, &["config", "show", task]);
        assert!(out.status.success(), "{task}");
        let text = String::from_utf8(out.stdout).unwrap();
        let file = write(&dir, &format!("{task}.toml"), &text);
        let out = cpose_in(&dir, &["config", "check", file.to_str().unwrap()]);
        assert!(
            out.status.success(),
            "{task}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains(&format!("a valid {task} config")));

        let lines: Vec<&str> = text.lines().collect();
        let header = |line: &str| {
            let line = line.trim_start_matches("# ").trim();
            let name = line.strip_prefix('[')?.split(']').next()?;
            Some(name.to_owned())
        };
        // Each table's lines (the top level is ""), commented ones included.
        let mut tables: Vec<(String, usize, Vec<&str>)> = vec![(String::new(), 0, Vec::new())];
        for (i, line) in lines.iter().enumerate() {
            match header(line) {
                Some(name) => tables.push((name, i, Vec::new())),
                None => tables.last_mut().unwrap().2.push(line),
            }
        }
        let names: Vec<&str> = tables.iter().map(|(n, _, _)| n.as_str()).collect();
        let mut probed = 0;
        for (name, at, body) in &tables {
            if !lines.get(*at).is_some_and(|l| l.starts_with('[')) && !name.is_empty() {
                continue; // a commented table: nothing to probe
            }
            // The probe right after the table's header (or after `task = …` at the top level).
            let after = if name.is_empty() {
                lines.iter().position(|l| l.starts_with("task = ")).unwrap()
            } else {
                *at
            };
            let mut probe: Vec<&str> = lines.clone();
            probe.insert(after + 1, "zz_probe = 0");
            let config = cpose_core::Config::from_text("probe.toml", probe.join("\n"));
            let checked = config
                .run_config()
                .map_err(anyhow::Error::from)
                .and_then(|run| {
                    (cpose_core::registry::find_task(task).unwrap().check)(&config, &run)
                });
            let Err(err) = checked else {
                continue; // a table of free names (a map), or one decoded with the data
            };
            let message = format!("{err:#}");
            assert!(
                message.contains("unknown field `zz_probe`"),
                "{task} [{name}]: {message}"
            );
            for key in expected_keys(&message) {
                let dotted = if name.is_empty() {
                    key.clone()
                } else {
                    format!("{name}.{key}")
                };
                let set = body.iter().any(|l| {
                    let l = l.trim_start_matches("# ");
                    l.starts_with(&format!("{key} ")) || l.starts_with(&format!("{key}="))
                });
                let table = names
                    .iter()
                    .any(|n| *n == dotted || n.starts_with(&format!("{dotted}.")));
                assert!(
                    set || table,
                    "{task}: [{name}] has no {key:?} (set or commented):\n{text}"
                );
            }
            probed += 1;
        }
        assert!(probed >= 2, "{task}: only {probed} tables probed");
    }
    // A task that is not registered: the error lists the tasks.
    let out = cpose_in(&dir, &["config", "show", "nerff"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("known tasks:"));
}

/// `cpose config check` reports a bad value with the file, line and key, exit code 2, and
/// writes nothing; `cpose run` reports the same before it creates the run folder.
#[test]
fn config_check_reports_a_bad_value_before_anything_runs() {
    let dir = temp_dir("config-check");
    let file = write(
        &dir,
        "bad.toml",
        "task = \"nerf\"\n[train]\nrays_per_step = 0\n",
    );
    let out = cpose_in(&dir, &["config", "check", file.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("rays_per_step = 0"), "{err}");
    let out = cpose_in(
        &dir,
        &[
            "config",
            "check",
            file.to_str().unwrap(),
            "--set",
            "train.rays_per_step=64",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run_dir = dir.join("run");
    let out = cpose_in(
        &dir,
        &[
            "run",
            file.to_str().unwrap(),
            "-q",
            "--out",
            run_dir.to_str().unwrap(),
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("rays_per_step = 0"));
    assert!(!run_dir.exists(), "the run folder was created");
    // An error inside the run is in its log and printed once, also with the log echoed.
    let missing = write(
        &dir,
        "missing.toml",
        "task = \"nerf\"\n[data]\nsource = \"llff\"\npath = \"no_such_scene\"\n",
    );
    let out = cpose_in(
        &dir,
        &[
            "run",
            missing.to_str().unwrap(),
            "--out",
            run_dir.to_str().unwrap(),
        ],
    );
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("no_such_scene").count(), 1, "{err}");
    let log = std::fs::read_to_string(run_dir.join("log.txt")).unwrap();
    assert!(
        log.contains("failed: ") && log.contains("no_such_scene"),
        "{log}"
    );
}

/// The planar study's bad input — an unreadable or corrupt image, an image smaller than the
/// patch layout, zero patches, a negative learning rate, a texture too large to allocate — each
/// ends the run with one line naming the problem and a non-zero exit, before any training.
#[test]
fn planar_rejects_bad_input_with_one_clear_line() {
    let dir = temp_dir("planar-bad");
    write(&dir, "corrupt.png", "not a png");
    let tiny = dir.join("tiny.png");
    cpose_nerf_image(&tiny, 64, 48);
    let config = workspace_root().join("configs/planar.toml");
    let cases: [(&str, &[&str], &str); 6] = [
        ("missing image", &["image.path=missing.jpg"], "missing.jpg"),
        ("corrupt image", &["image.path=corrupt.png"], "corrupt.png"),
        ("small image", &["image.path=tiny.png"], "crop_px"),
        ("zero patches", &["motion.patches=0"], "patches"),
        ("negative rate", &["train.lr_field=-1e-3"], "lr_field"),
        (
            "huge texture",
            &["image.procedural_size=[200000,200000]"],
            "procedural_size 200000×200000",
        ),
    ];
    for (name, sets, expected) in cases {
        let mut args = vec!["run", config.to_str().unwrap(), "-q", "--out"];
        let out_dir = dir.join(name.replace(' ', "_"));
        args.push(out_dir.to_str().unwrap());
        for s in sets {
            args.extend(["--set", s]);
        }
        let out = cpose_in(&dir, &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name}: succeeded");
        assert!(err.contains(expected), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        assert!(
            !out_dir.join("metrics.json").exists(),
            "{name}: wrote metrics"
        );
    }
}

/// A user's own capture, six photos of 24×18 by a pinhole camera with points 3–6 m in front, as
/// a COLMAP model and as nerfstudio's `transforms.json`: each trains in the nerf task and each
/// method's poses come back in the capture's format, frame and units — for the true poses exactly
/// the capture's (the normalisation is undone), for BARF moved by training.
#[test]
fn nerf_refines_a_users_capture_and_writes_the_poses_back() {
    use cpose_nerf::data::colmap::{
        CameraModel, ColmapCamera, ColmapFormat, ColmapImage, ColmapModel, ColmapPoint,
        read_colmap_model, write_colmap_model,
    };
    use cpose_nerf::data::nerfstudio::load_nerfstudio;
    use nalgebra::{Isometry3, Vector3};
    let dir = temp_dir("nerf-capture");
    let scene = dir.join("capture");
    std::fs::create_dir_all(scene.join("images")).expect("temp dir is writable");
    std::fs::create_dir_all(scene.join("sparse/0")).expect("temp dir is writable");
    // Six cameras side by side in metres, looking along +z.
    let poses: Vec<Isometry3<f64>> = (0..6)
        .map(|i| {
            Isometry3::new(
                Vector3::new(0.2 * i as f64, 0.05 * i as f64, 0.0),
                Vector3::new(0.0, 0.02 * i as f64, 0.0),
            )
        })
        .collect();
    for i in 0..6 {
        cpose_nerf_image(&scene.join(format!("images/frame_{i:02}.png")), 24, 18);
    }
    let images: Vec<ColmapImage> = (0..6)
        .map(|i| ColmapImage {
            id: 10 + i,
            camera_id: 1,
            name: format!("frame_{i:02}.jpg"),
            world_from_camera: poses[i as usize],
            points2d: vec![],
        })
        .collect();
    let points = (0..40u64)
        .map(|k| ColmapPoint {
            id: k + 1,
            xyz: [
                (k % 5) as f64 * 0.4 - 0.8,
                (k % 3) as f64 * 0.3,
                3.0 + (k % 7) as f64 * 0.5,
            ],
            rgb: [128, 128, 128],
            error: 0.5,
            track: (0..6).map(|i| (10 + i, 0)).collect(),
        })
        .collect();
    let model = ColmapModel {
        cameras: vec![ColmapCamera {
            id: 1,
            model: CameraModel::Pinhole,
            width: 24,
            height: 18,
            params: vec![20.0, 21.0, 12.0, 9.0],
        }],
        images: Some(images.clone()),
        points: Some(points),
    };
    write_colmap_model(&scene.join("sparse/0"), &model, ColmapFormat::Text, false)
        .expect("temp dir is writable");
    let frames: Vec<serde_json::Value> = poses
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            let m = cpose_core::geometry::world_from_cam_gl_from_cv(pose).to_homogeneous();
            let rows: Vec<Vec<f64>> = (0..4).map(|r| (0..4).map(|c| m[(r, c)]).collect()).collect();
            serde_json::json!({"file_path": format!("images/frame_{i:02}.png"), "transform_matrix": rows})
        })
        .collect();
    let transforms = serde_json::json!({
        "camera_model": "PINHOLE", "fl_x": 20.0, "fl_y": 21.0, "cx": 12.0, "cy": 9.0,
        "w": 24, "h": 18, "frames": frames,
    });
    write(&scene, "transforms.json", &transforms.to_string());

    for source in ["colmap", "nerfstudio"] {
        let run = run_config_in(
            &dir,
            "configs/colmap_capture.toml",
            &format!("run-{source}"),
            &[
                &format!("data.source=\"{source}\""),
                "data.path=\"capture\"",
                "data.factor=1",
                "train.methods=[\"true_poses\", \"barf\"]",
                "train.iterations=20",
                "train.rays_per_step=64",
                "render.samples=8",
                "eval.refine_iterations=0",
                "eval.saved_views=0",
                "run.threads=1",
            ],
        );
        let log = std::fs::read_to_string(run.join("log.txt")).expect("log.txt");
        // Five trained on (the last held out), in name order, with their names.
        let exported = |method: &str| -> Vec<(String, Isometry3<f64>)> {
            if source == "colmap" {
                let images = read_colmap_model(&run.join(format!("colmap_capture_{method}")))
                    .expect("a COLMAP model")
                    .images
                    .expect("images");
                images
                    .into_iter()
                    .map(|i| (i.name, i.world_from_camera))
                    .collect()
            } else {
                let (data, _) =
                    load_nerfstudio(run.join(format!("transforms_capture_{method}.json")), 1)
                        .expect("a transforms.json");
                let names = data
                    .names
                    .iter()
                    .map(|n| n.rsplit('/').next().unwrap_or(n).to_owned());
                names.zip(data.world_from_camera).collect()
            }
        };
        if source == "colmap" {
            assert!(
                log.contains("6 registered images of camera PINHOLE"),
                "{log}"
            );
        } else {
            assert!(log.contains("transforms.json: 6 frames"), "{log}");
        }
        let truth = exported("true_poses");
        assert_eq!(truth.len(), 5);
        for (k, (name, pose)) in truth.iter().enumerate() {
            assert!(name.starts_with(&format!("frame_{k:02}.")), "{name}");
            let input = &poses[k];
            assert!((pose.translation.vector - input.translation.vector).norm() < 1e-9);
            assert!(pose.rotation.angle_to(&input.rotation) < 1e-9);
        }
        let moved = exported("barf")
            .iter()
            .zip(&poses)
            .map(|((_, a), b)| (a.translation.vector - b.translation.vector).norm())
            .fold(0.0, f64::max);
        assert!(
            moved > 1e-6 && moved < 0.5,
            "{source}: BARF moved the cameras by {moved}"
        );
    }
}

/// Writes a small valid PNG of `width × height` through the library.
fn cpose_nerf_image(path: &Path, width: usize, height: usize) {
    cpose_nerf::image::procedural_texture(width, height, 0)
        .save_png(path)
        .expect("the test folder is writable");
}

/// Issue "bad input … one clear message": the nerf task on a broken LLFF folder — a truncated
/// image, a missing image, a `poses_bounds.npy` of the wrong shape, images of different sizes,
/// no folder for the downscale factor — ends with a non-zero exit and one line on stderr naming
/// the file and what was expected, before any training.
#[test]
fn nerf_rejects_a_broken_llff_folder_with_one_clear_line() {
    let root = temp_dir("nerf-bad");
    let config = workspace_root().join("configs/llff_fern.toml");
    // A valid scene: 4 rows (identity LLFF rotations, original 40×30, f = 50) and 4 PNGs.
    let scene = |name: &str| {
        let dir = root.join(name);
        std::fs::create_dir_all(dir.join("images_8")).expect("temp dir is writable");
        let rows: Vec<f64> = (0..4)
            .flat_map(|i| {
                let c = 0.1 * i as f64;
                [
                    1.0, 0.0, 0.0, c, 30.0, 0.0, 1.0, 0.0, 0.0, 40.0, 0.0, 0.0, 1.0, 0.0, 50.0,
                    1.0, 10.0,
                ]
            })
            .collect();
        cpose_nerf::data::llff::write_npy_f64_matrix(&dir.join("poses_bounds.npy"), 17, &rows)
            .expect("temp dir is writable");
        for i in 0..4 {
            cpose_nerf_image(&dir.join(format!("images_8/image{i:03}.png")), 12, 10);
        }
        dir
    };
    let truncated = scene("truncated");
    let png = truncated.join("images_8/image001.png");
    let bytes = std::fs::read(&png).unwrap();
    std::fs::write(&png, &bytes[..bytes.len() / 2]).unwrap();
    let missing = scene("missing");
    std::fs::remove_file(missing.join("images_8/image003.png")).unwrap();
    let shape = scene("shape");
    cpose_nerf::data::llff::write_npy_f64_matrix(
        &shape.join("poses_bounds.npy"),
        15,
        &[0.5; 4 * 15],
    )
    .unwrap();
    let sizes = scene("sizes");
    cpose_nerf_image(&sizes.join("images_8/image002.png"), 11, 10);
    let factor = scene("factor");

    let cases: [(&Path, &[&str], &[&str]); 5] = [
        (
            &truncated,
            &[],
            &["images_8/image001.png", "expected valid PNG data"],
        ),
        (
            &missing,
            &[],
            &["images_8", "expected 4 images", "got 3 images"],
        ),
        (
            &shape,
            &[],
            &["poses_bounds.npy", "expected 'shape': (N, 17)", "(4, 15)"],
        ),
        (&sizes, &[], &["images_8/image002.png", "12×10, got 11×10"]),
        (
            &factor,
            &["data.factor=4"],
            &[
                "images_4",
                "expected a folder of 4 images",
                "no such folder",
            ],
        ),
    ];
    for (dir, sets, expected) in cases {
        let out_dir = dir.join("run");
        let data_path = format!("data.path={}", dir.display());
        let mut args = vec![
            "run",
            config.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
            "--force",
            "-q",
            "--set",
            &data_path,
        ];
        for s in sets {
            args.extend(["--set", s]);
        }
        let out = cpose_in(&workspace_root(), &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{}: succeeded", dir.display());
        assert_eq!(err.lines().count(), 1, "one line: {err}");
        for e in expected {
            assert!(err.contains(e), "{e:?} not in {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out_dir.join("metrics.json").exists(), "{err}");
    }
}

/// A TUM RGB-D folder without `groundtruth.txt` runs: the trajectory is written, the ATE is
/// null in `metrics.json` and the log says why.
#[test]
fn slam_without_ground_truth_writes_the_trajectory_and_no_ate() {
    let data = temp_dir("tum-no-gt");
    std::fs::create_dir_all(data.join("rgb")).unwrap();
    std::fs::create_dir_all(data.join("depth")).unwrap();
    let (mut rgb, mut depth) = (String::new(), String::new());
    for i in 0..4 {
        let t = i as f64 * 0.05;
        cpose_nerf::image::Image::from_fn(64, 48, |x, y| [x as f32 / 64.0, y as f32 / 48.0, 0.5])
            .save_png(data.join(format!("rgb/{i}.png")))
            .unwrap();
        let depths = (0..64 * 48).map(|k| 2.0 + 0.01 * (k % 64) as f32).collect();
        cpose_slam::data::DepthImage::new(64, 48, depths)
            .unwrap()
            .save_png(&data.join(format!("depth/{i}.png")), 5000.0)
            .unwrap();
        rgb.push_str(&format!("{t:.3} rgb/{i}.png\n"));
        depth.push_str(&format!("{t:.3} depth/{i}.png\n"));
    }
    write(&data, "rgb.txt", &rgb);
    write(&data, "depth.txt", &depth);
    let out_dir = temp_dir("tum-no-gt-run");
    let config = workspace_root().join("configs/tum_fr1_desk.toml");
    let out = cpose_in(
        &workspace_root(),
        &[
            "run",
            config.to_str().unwrap(),
            "-q",
            "--out",
            out_dir.to_str().unwrap(),
            "--set",
            &format!("data.path={}", data.display()),
            "--set",
            "data.resolution=1.0",
            "--set",
            "slam.methods=[\"baseline\"]",
            "--set",
            "tracking.edge=2",
            "--set",
            "run.iterations_scale=0.05",
            "--set",
            "run.threads=1",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("metrics.json")).unwrap())
            .unwrap();
    assert!(
        method_metrics(&metrics, "baseline")["ate_rmse_cm"].is_null(),
        "{metrics}"
    );
    assert_eq!(
        eval::read_tum(unit_file(&out_dir, "traj", "baseline", "txt"))
            .unwrap()
            .len(),
        4
    );
    let log = std::fs::read_to_string(out_dir.join("log.txt")).unwrap();
    assert!(log.contains("no ground truth"), "{log}");
}

/// `slam_imu` runs end to end on both its data sources at toy sizes: the synthetic room with
/// the simulated IMU (the paper's ScanNet protocol) and the room along the real EuRoC flight
/// with its real IMU. A EuRoC folder without `sensor.yaml` is one clear error.
#[test]
fn slam_imu_runs_on_simulated_and_real_imu() {
    let small = [
        "synthetic.width=48",
        "tracking.edge=2",
        "tracking.pixels=64",
        "tracking.iterations=5",
        "mapping.pixels=128",
        "mapping.first_iterations=20",
        "mapping.iterations=5",
        "imu.predict_steps=3",
        "mesh.voxel=0",
    ];
    let cases = [
        (
            "configs/synthetic_imu.toml",
            "imu-synthetic",
            vec![
                "synthetic.frames=31",
                "slam.methods=[\"baseline\", \"tight\", \"combined\"]",
            ],
            vec!["baseline", "tight", "combined"],
        ),
        (
            "configs/euroc_v102_imu.toml",
            "imu-euroc",
            vec![
                "synthetic.frames=6",
                "slam.methods=[\"loose\", \"accel\", \"prev_tight\", \"prev_combined\"]",
            ],
            vec!["loose", "accel", "prev_tight", "prev_combined"],
        ),
    ];
    for (config, name, sets, keys) in cases {
        let data = temp_dir(&format!("{name}-data"));
        let out_dir = temp_dir(name);
        let data_path = format!("data.path={}", data.display());
        let mut args = vec![
            "run",
            config,
            "--out",
            out_dir.to_str().unwrap(),
            "--force",
            "-q",
        ];
        for s in small.iter().chain(&sets).chain([&data_path.as_str()]) {
            args.extend(["--set", s]);
        }
        let out = cpose_in(&workspace_root(), &args);
        assert!(
            out.status.success(),
            "{config}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let metrics: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out_dir.join("metrics.json")).unwrap())
                .unwrap();
        for key in keys {
            let ate = method_metrics(&metrics, key)["ate_rmse_cm"].as_f64();
            assert!(ate.is_some_and(f64::is_finite), "{config} {key}: {metrics}");
            // The estimate is saved as a field that `cpose query` reads back at the frames
            // (f32 tangents of poses a few metres from the origin).
            assert_query_reproduces(
                &out_dir,
                &unit_file(&out_dir, "field", key, "safetensors"),
                &unit_file(&out_dir, "traj", key, "txt"),
                (1e-5, 1e-5),
            );
        }
        if name == "imu-euroc" {
            let log = std::fs::read_to_string(out_dir.join("log.txt")).unwrap();
            assert!(log.contains("clear of every surface"), "{log}");
            // The same flight under another spelling of its path reuses the rendered hall.
            let again = temp_dir("imu-euroc-again");
            let euroc = format!(
                "euroc.path={}",
                workspace_root()
                    .join("../shared/data/euroc/./V1_02_excerpt")
                    .display()
            );
            // `prev` alone into `again`, with `extra` settings; its log.
            let run_again = |extra: &str| {
                let mut args = vec!["run", config, "--out", again.to_str().unwrap(), "--force"];
                for s in small.iter().chain(&sets).chain([&data_path.as_str()]) {
                    args.extend(["--set", s]);
                }
                args.extend(["-q", "--set", extra, "--set", "slam.methods=[\"prev\"]"]);
                let out = cpose_in(&workspace_root(), &args);
                assert!(
                    out.status.success(),
                    "{}",
                    String::from_utf8_lossy(&out.stderr)
                );
                std::fs::read_to_string(again.join("log.txt")).unwrap()
            };
            let log = run_again(&euroc);
            assert!(log.contains("synthetic data: reusing"), "{log}");
            // A shorter flight replaces the hall: no frame of the longer one is left behind.
            let log = run_again("synthetic.frames=4");
            assert!(log.contains("generated 4 frames"), "{log}");
            let staging = format!(
                ".{}.generating",
                data.file_name().unwrap().to_string_lossy()
            );
            let beside: Vec<_> = std::fs::read_dir(data.parent().unwrap())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with(&staging))
                .collect();
            assert!(beside.is_empty(), "staging left behind: {beside:?}");
        }
    }
    // A EuRoC folder whose sensor.yaml is missing.
    let broken = temp_dir("imu-euroc-broken");
    let source = workspace_root().join("../shared/data/euroc/V1_02_excerpt/mav0");
    for file in ["imu0/data.csv", "state_groundtruth_estimate0/data.csv"] {
        let to = broken.join("mav0").join(file);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(source.join(file), &to).unwrap();
    }
    let out_dir = temp_dir("imu-euroc-broken-run");
    let euroc = format!("euroc.path={}", broken.display());
    let out = cpose_in(
        &workspace_root(),
        &[
            "run",
            "configs/euroc_v102_imu.toml",
            "--out",
            out_dir.to_str().unwrap(),
            "--force",
            "-q",
            "--set",
            &euroc,
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(err.contains("imu0/sensor.yaml"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// Task `events` on an EventNeRF folder written by the simulator: the views are the truth, the
/// known poses a subset; a folder without events is one clear error naming it.
#[test]
fn events_reads_an_eventnerf_folder() {
    use cpose_events::{SyntheticEventsConfig, write_synthetic_eventnerf};
    let root = temp_dir("events-folder");
    let scene_dir = root.join("turntable");
    let config = SyntheticEventsConfig {
        camera: SyntheticEventsConfig::default().camera.scaled(0.15),
        render_steps: 40,
        views: 21,
        held_out_views: 1,
        ..Default::default()
    };
    let scene = cpose_events::cpose_nerf::scene::SyntheticScene::object_centric();
    write_synthetic_eventnerf(&scene_dir, &scene, &config).unwrap();
    let out_dir = root.join("run");
    let path = format!("data.path={}", scene_dir.display());
    let mut args = vec![
        "run",
        "configs/events_interp.toml",
        "--out",
        out_dir.to_str().unwrap(),
        "--force",
        "-q",
    ];
    for set in [
        "data.source=\"eventnerf\"",
        path.as_str(),
        "experiment.known_poses=[4]",
        "train.iterations=20",
        "train.rays_per_step=64",
        "train.windows_per_step=2",
        "render.samples=12",
        "eval.pose_samples=10",
        "run.threads=1",
    ] {
        args.extend(["--set", set]);
    }
    let out = cpose_in(&workspace_root(), &args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("metrics.json")).unwrap())
            .unwrap();
    for method in ["eventnerf", "posenet"] {
        let err = metrics["K4"][method]["trans_err_su"].as_f64();
        assert!(err.is_some_and(f64::is_finite), "{metrics}");
    }
    // The interpolation baseline cuts the chords of the turntable circle.
    assert!(metrics["K4"]["eventnerf"]["trans_err_su"].as_f64().unwrap() > 0.1);

    std::fs::remove_dir_all(scene_dir.join("train/events")).unwrap();
    let out = cpose_in(&workspace_root(), &args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("events"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
}

/// `cpose query FIELD --times …` at the times of `traj` (a run's trajectory file) gives `traj`
/// within `tolerance` (metres or scene units, and radians).
fn assert_query_reproduces(dir: &Path, field: &Path, traj: &Path, tolerance: (f64, f64)) {
    let traj = eval::read_tum(traj).expect("the run's trajectory file");
    let times: Vec<String> = traj
        .timestamps_secs()
        .iter()
        .map(|t| format!("{t}"))
        .collect();
    let out = cpose_in(
        dir,
        &[
            "query",
            field.to_str().expect("a UTF-8 path"),
            "--times",
            &times.join(","),
        ],
    );
    let what = field.display();
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).expect("query prints text");
    let queried = eval::parse_tum(&text, Path::new("query")).expect("query prints TUM");
    assert_eq!(queried.len(), traj.len(), "{what}");
    for (a, b) in queried.poses().iter().zip(traj.poses()) {
        let moved = (a.translation.vector - b.translation.vector).norm();
        assert!(moved < tolerance.0, "{what}: {moved}");
        assert!(a.rotation.angle_to(&b.rotation) < tolerance.1, "{what}");
    }
}

/// Runs `cpose run CONFIG --out OUT -q --set …` in `dir` and asserts that it succeeds; returns the
/// run folder.
fn run_config_in(dir: &Path, config: &str, out: &str, settings: &[&str]) -> PathBuf {
    let config = workspace_root().join(config);
    let mut args = vec!["run", config.to_str().expect("utf-8"), "--out", out, "-q"];
    for setting in settings {
        args.extend(["--set", setting]);
    }
    let run = cpose_in(dir, &args);
    assert!(
        run.status.success(),
        "{}: {}",
        config.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    dir.join(out)
}

/// `events` saves PoseNet's camera path over the whole recording: `cpose query` at the
/// evaluation times gives its trajectory file.
#[test]
fn events_saves_posenets_path_and_query_reproduces_it() {
    let dir = temp_dir("query-events");
    let run = run_config_in(
        &dir,
        "configs/events_interp.toml",
        "run",
        &[
            "simulation.width=24",
            "simulation.height=18",
            "simulation.render_steps=40",
            "simulation.held_out_views=1",
            "experiment.known_poses=[6]",
            "train.iterations=20",
            "train.rays_per_step=64",
            "train.windows_per_step=2",
            "render.samples=12",
            "eval.pose_samples=10",
            "run.threads=1",
        ],
    );
    assert_query_reproduces(
        &dir,
        &run.join("field_K6_posenet.safetensors"),
        &run.join("traj_K6_posenet.txt"),
        (1e-3, 1e-4),
    );
    assert!(!run.join("field_K6_eventnerf.safetensors").exists());
    // The run folder names its one field.
    let by_folder = cpose_in(&dir, &["query", "run", "--times", "0.5"]);
    assert!(
        by_folder.status.success(),
        "{}",
        String::from_utf8_lossy(&by_folder.stderr)
    );
}

/// `nerf` saves the cameras of every method that learns a correction, `C(t) ∘ init(t)` in the
/// frame of its aligned trajectory: `cpose query` at the frame times gives that trajectory.
#[test]
fn nerf_saves_its_cameras_and_query_reproduces_them() {
    let dir = temp_dir("query-nerf");
    let run = run_config_in(
        &dir,
        "configs/nerf_synthetic.toml",
        "run",
        &[
            "train.methods=[\"posenet\", \"barf\", \"spline\"]",
            "train.iterations=40",
            "train.rays_per_step=64",
            "render.samples=12",
            "eval.refine_iterations=0",
            "data.test_views=1",
            "eval.saved_views=0",
            "data.width=16",
            "data.height=16",
            "orbit.frames=10",
            "run.threads=1",
        ],
    );
    // Parameters are f32: the initial poses' tangents keep about 1e-4 of the orbit's radius of
    // 4.5 (measured: at most 2.1e-4 for PoseNet, 1.2e-5 rad in rotation).
    for method in ["posenet", "barf", "spline"] {
        assert_query_reproduces(
            &dir,
            &run.join(format!("field_synthetic_{method}.safetensors")),
            &run.join(format!("traj_synthetic_{method}.txt")),
            (1e-3, 1e-4),
        );
    }
    assert!(!run.join("field_synthetic_true_poses.safetensors").exists());
    // A run folder of several fields asks which.
    let ambiguous = cpose_in(&dir, &["query", "run", "--times", "1"]);
    let stderr = String::from_utf8_lossy(&ambiguous.stderr);
    assert_eq!(ambiguous.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("holds 3 saved pose fields; name one: field_synthetic_barf.safetensors"),
        "{stderr}"
    );
}

#[test]
fn a_fitted_field_is_saved_and_query_reproduces_its_trajectory() {
    let dir = temp_dir("query");
    let config = workspace_root().join("configs/trajectory_fit.toml");
    let out = cpose_in(
        &dir,
        &[
            "run",
            config.to_str().unwrap(),
            "--out",
            "run",
            "-q",
            "--set",
            "run.iterations_scale=0.01",
            "--set",
            "fit.imu=[\"none\"]",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = dir.join("run");
    // The run's trajectories, again from the saved fields at their own times.
    for method in ["posenet", "spline", "lie_spline"] {
        assert_query_reproduces(
            &dir,
            &run.join(format!("field_none_{method}.safetensors")),
            &run.join(format!("traj_none_{method}.txt")),
            (1e-6, 1e-6),
        );
    }
    let field = run.join("field_none_posenet.safetensors");
    let field = field.to_str().unwrap();
    // Velocities at 10 Hz over the whole range: 10 s of motion, 101 rows and a header.
    let out = cpose_in(&dir, &["query", field, "--rate", "10", "--derivatives"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = String::from_utf8(out.stdout).unwrap();
    assert!(
        csv.starts_with("t,tx,ty,tz,qx,qy,qz,qw,wx,wy,wz,vx,vy,vz\n"),
        "{csv}"
    );
    assert_eq!(csv.lines().count(), 102);
    // A time outside the range: one line naming it and the range.
    let out = cpose_in(&dir, &["query", field, "--times", "0,99"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("time 99 s is outside"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    // Not a saved field.
    let bogus = write(&dir, "bogus.safetensors", "not a field");
    let out = cpose_in(&dir, &["query", bogus.to_str().unwrap(), "--times", "0"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bogus.safetensors: expected a pose field saved by cpose"),
        "{err}"
    );
    // The file is safetensors as Python reads it: the same parameters and metadata.
    let script = "import sys, json\n\
        from safetensors import safe_open\n\
        with safe_open(sys.argv[1], framework='numpy') as f:\n\
        \x20   p = f.get_tensor('params')\n\
        \x20   m = f.metadata()\n\
        print(json.dumps({'n': int(p.shape[0]), 'sum': float(p.astype('float64').sum()), 'format': m['format']}))\n";
    let out = Command::new("python3")
        .args(["-c", script, field])
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let python: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let saved = cpose_core::pose_field::saved::SavedPoseField::read(Path::new(field)).unwrap();
    assert_eq!(python["n"], saved.params.len());
    let sum: f64 = saved.params.iter().map(|&p| f64::from(p)).sum();
    assert!((python["sum"].as_f64().unwrap() - sum).abs() < 1e-9 * sum.abs().max(1.0));
    assert_eq!(python["format"], "cpose-pose-field/1");
}
