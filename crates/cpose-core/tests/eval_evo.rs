//! Agreement of `cpose_core::eval` with evo on real data (TUM RGB-D fr1_xyz: mocap ground truth
//! and an RGBD-SLAM estimate with different timestamps), plus invariants on the same files.
//!
//! Needs the shared data folder (`CPOSE_DATA_DIR`, else `../shared/data` beside the workspace);
//! the evo tests also need `evo_ape`/`evo_rpe` on PATH (`pip install evo==1.38.1`). Without the
//! data the tests print one line and pass; without evo they print one line and pass, unless the
//! environment variable `CI` is set, where a missing evo is a failure.

// A test crate: its helpers panic on failure and print the numbers and skip notices.
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

use cpose_core::eval::{
    Alignment, DEFAULT_MAX_DIFF_SECS, ReflectionFix, RpeDelta, Trajectory, TrajectoryFormat,
    align_poses, ape_rotation_angle, associate, barf_pose_errors, error_stats, read_trajectory,
    read_tum, rpe, rpe_report, write_trajectory, write_tum,
};

/// The fr1_xyz files `(ground truth, estimate)`, or `None` (after saying so) when the shared data
/// folder is missing.
fn tum_files(test: &str) -> Option<(PathBuf, PathBuf)> {
    let Some(dir) = cpose_core::fs::shared_data_dir() else {
        println!("{test}: skipped, shared data folder not found (set CPOSE_DATA_DIR)");
        return None;
    };
    let dir = dir.join("tum/fr1_xyz");
    Some((
        dir.join("groundtruth.txt"),
        dir.join("rgbdslam_estimate.txt"),
    ))
}

/// A unique path in the system temp folder.
fn temp_path(name: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    std::env::temp_dir().join(format!("cpose-eval-evo-{}-{n}-{name}", std::process::id()))
}

/// Runs an evo command (`evo_ape` or `evo_rpe`) with `args` and `--save_results` to a temporary
/// zip, and returns its `stats.json` statistics at full precision (evo prints only 6 decimals).
/// `None` (after saying so) when the command is not installed and `CI` is unset.
fn run_evo(test: &str, program: &str, args: &[&str]) -> Option<serde_json::Value> {
    let zip = temp_path("results.zip");
    let output = Command::new(program)
        .args(args)
        .arg("--no_warnings")
        .arg("--save_results")
        .arg(&zip)
        .output();
    let output = match output {
        Ok(output) => output,
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => {
            assert!(
                std::env::var_os("CI").is_none(),
                "{program} not found on PATH; CI must install evo (pip install evo==1.38.1)"
            );
            println!("{test}: skipped, {program} not on PATH (pip install evo==1.38.1)");
            return None;
        }
        Err(err) => panic!("cannot run {program}: {err}"),
    };
    assert!(
        output.status.success(),
        "{program} {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let bytes = std::fs::read(&zip).unwrap();
    std::fs::remove_file(&zip).unwrap();
    let stats = stored_zip_entry(&bytes, "stats.json")
        .unwrap_or_else(|| panic!("no stored stats.json in the results zip of {program}"));
    Some(serde_json::from_slice(stats).unwrap())
}

/// The bytes of entry `name` of a zip archive written without compression (Python's
/// `zipfile.ZipFile.writestr` default, `ZIP_STORED`, which evo's `save_res_file` uses). Walks the
/// local file headers: signature `PK\x03\x04`, method at byte 8, compressed size at 18, name
/// length at 26, extra length at 28, then the name, the extra field and the data.
fn stored_zip_entry<'a>(zip: &'a [u8], name: &str) -> Option<&'a [u8]> {
    let u16_at = |i: usize| u16::from_le_bytes([zip[i], zip[i + 1]]) as usize;
    let u32_at =
        |i: usize| u32::from_le_bytes([zip[i], zip[i + 1], zip[i + 2], zip[i + 3]]) as usize;
    let mut pos = 0;
    while pos + 30 <= zip.len() && zip[pos..pos + 4] == *b"PK\x03\x04" {
        let method = u16_at(pos + 8);
        let size = u32_at(pos + 18);
        let name_len = u16_at(pos + 26);
        let extra_len = u16_at(pos + 28);
        let entry_name = &zip[pos + 30..pos + 30 + name_len];
        let data = pos + 30 + name_len + extra_len;
        if entry_name == name.as_bytes() {
            assert_eq!(method, 0, "{name} is compressed; expected a stored entry");
            return Some(&zip[data..data + size]);
        }
        pos = data + size;
    }
    None
}

fn stat(stats: &serde_json::Value, key: &str) -> f64 {
    stats[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no `{key}` in evo stats {stats}"))
}

/// Relative difference `|ours − evo| / |evo|`.
fn rel_diff(ours: f64, evo: f64) -> f64 {
    (ours - evo).abs() / evo.abs().max(1e-300)
}

fn assert_rel(ours: f64, evo: f64, what: &str) {
    let rel = rel_diff(ours, evo);
    assert!(
        rel < 1e-6,
        "{what}: ours {ours:.12}, evo {evo:.12}, relative difference {rel:e}"
    );
}

fn load(gt: &Path, est: &Path) -> (Trajectory, Trajectory) {
    (read_tum(gt).unwrap(), read_tum(est).unwrap())
}

#[test]
fn eval_ate_matches_evo_ape_on_tum_fr1_xyz() {
    let test = "eval_ate_matches_evo_ape_on_tum_fr1_xyz";
    let Some((gt_path, est_path)) = tum_files(test) else {
        return;
    };
    let (gt, est) = load(&gt_path, &est_path);
    let (gt_s, est_s) = (gt_path.to_str().unwrap(), est_path.to_str().unwrap());
    for (align, flags) in [
        (Alignment::None, &[][..]),
        (Alignment::Se3, &["-a"][..]),
        (Alignment::Sim3, &["-as"][..]),
    ] {
        let mut args = vec!["tum", gt_s, est_s];
        args.extend_from_slice(flags);
        let Some(stats) = run_evo(test, "evo_ape", &args) else {
            return;
        };
        let ours = cpose_core::eval::ate(&gt, &est, align, DEFAULT_MAX_DIFF_SECS).unwrap();
        println!(
            "APE translation, {align}: evo rmse {:.15} m, ours {:.15} m, relative difference {:.1e} ({} pairs)",
            stat(&stats, "rmse"),
            ours.rmse_m,
            rel_diff(ours.rmse_m, stat(&stats, "rmse")),
            ours.num_matched
        );
        assert_rel(ours.rmse_m, stat(&stats, "rmse"), &format!("{align} rmse"));
        assert_rel(ours.mean_m, stat(&stats, "mean"), &format!("{align} mean"));
        assert_rel(
            ours.median_m,
            stat(&stats, "median"),
            &format!("{align} median"),
        );
        assert_rel(ours.std_m, stat(&stats, "std"), &format!("{align} std"));
        assert_rel(ours.min_m, stat(&stats, "min"), &format!("{align} min"));
        assert_rel(ours.max_m, stat(&stats, "max"), &format!("{align} max"));
        assert_rel(ours.sse_m2, stat(&stats, "sse"), &format!("{align} sse"));
    }
}

#[test]
fn eval_rotation_ape_and_rpe_match_evo_on_tum_fr1_xyz() {
    let test = "eval_rotation_ape_and_rpe_match_evo_on_tum_fr1_xyz";
    let Some((gt_path, est_path)) = tum_files(test) else {
        return;
    };
    let (gt, est) = load(&gt_path, &est_path);
    let (gt_s, est_s) = (gt_path.to_str().unwrap(), est_path.to_str().unwrap());
    let (reference, estimate) = associate(&gt, &est, DEFAULT_MAX_DIFF_SECS)
        .unwrap()
        .poses(&gt, &est);

    // Rotation-angle APE after SE(3) alignment: checks that orientations are aligned as evo does.
    let Some(stats) = run_evo(
        test,
        "evo_ape",
        &["tum", gt_s, est_s, "-a", "-r", "angle_deg"],
    ) else {
        return;
    };
    let (_, aligned) = align_poses(&reference, &estimate, Alignment::Se3).unwrap();
    let deg: Vec<f64> = ape_rotation_angle(&reference, &aligned)
        .unwrap()
        .iter()
        .map(|a| a.to_degrees())
        .collect();
    let ours = error_stats(&deg).unwrap();
    println!(
        "APE angle, se3: evo rmse {:.15} deg, ours {:.15} deg, relative difference {:.1e}",
        stat(&stats, "rmse"),
        ours.rmse,
        rel_diff(ours.rmse, stat(&stats, "rmse"))
    );
    assert_rel(ours.rmse, stat(&stats, "rmse"), "APE angle rmse");
    assert_rel(ours.max, stat(&stats, "max"), "APE angle max");

    // RPE, delta 1 frame, translation and rotation angle.
    let rel = rpe(&reference, &estimate, 1).unwrap();
    let Some(stats) = run_evo(test, "evo_rpe", &["tum", gt_s, est_s]) else {
        return;
    };
    let ours = error_stats(&rel.translation).unwrap();
    println!(
        "RPE translation: evo rmse {:.15} m, ours {:.15} m, relative difference {:.1e}",
        stat(&stats, "rmse"),
        ours.rmse,
        rel_diff(ours.rmse, stat(&stats, "rmse"))
    );
    assert_rel(ours.rmse, stat(&stats, "rmse"), "RPE translation rmse");
    assert_rel(
        ours.median,
        stat(&stats, "median"),
        "RPE translation median",
    );
    let Some(stats) = run_evo(test, "evo_rpe", &["tum", gt_s, est_s, "-r", "angle_deg"]) else {
        return;
    };
    let deg: Vec<f64> = rel
        .rotation_angle_rad
        .iter()
        .map(|a| a.to_degrees())
        .collect();
    let ours = error_stats(&deg).unwrap();
    let report = cpose_core::eval::rpe_report(
        &gt,
        &est,
        DEFAULT_MAX_DIFF_SECS,
        RpeDelta::Frames(1),
        Alignment::None,
    )
    .unwrap();
    assert_eq!(report.rot_rmse_deg, ours.rmse);
    assert_eq!(report.num_pairs, rel.pairs.len());
    println!(
        "RPE angle: evo rmse {:.15} deg, ours {:.15} deg, relative difference {:.1e}",
        stat(&stats, "rmse"),
        ours.rmse,
        rel_diff(ours.rmse, stat(&stats, "rmse"))
    );
    assert_rel(ours.rmse, stat(&stats, "rmse"), "RPE angle rmse");
    assert_rel(ours.mean, stat(&stats, "mean"), "RPE angle mean");
}

#[test]
fn rpe_in_frames_and_metres_with_alignment_matches_evo_rpe_on_tum_fr1_xyz() {
    let test = "rpe_in_frames_and_metres_with_alignment_matches_evo_rpe_on_tum_fr1_xyz";
    let Some((gt_path, est_path)) = tum_files(test) else {
        return;
    };
    let (gt, est) = load(&gt_path, &est_path);
    let (gt_s, est_s) = (gt_path.to_str().unwrap(), est_path.to_str().unwrap());
    for (delta, unit, value, align, flag) in [
        (RpeDelta::Frames(5), "f", "5", Alignment::None, None),
        (
            RpeDelta::Metres(0.1),
            "m",
            "0.1",
            Alignment::Se3,
            Some("-a"),
        ),
        (
            RpeDelta::Metres(0.25),
            "m",
            "0.25",
            Alignment::Sim3,
            Some("-as"),
        ),
    ] {
        let ours = rpe_report(&gt, &est, DEFAULT_MAX_DIFF_SECS, delta, align).unwrap();
        for (relation, rmse, mean) in [
            ("trans_part", ours.trans_rmse_m, ours.trans_mean_m),
            ("angle_deg", ours.rot_rmse_deg, ours.rot_mean_deg),
        ] {
            let mut args = vec![
                "tum",
                gt_s,
                est_s,
                "--delta",
                value,
                "--delta_unit",
                unit,
                "-r",
                relation,
            ];
            args.extend(flag);
            let Some(stats) = run_evo(test, "evo_rpe", &args) else {
                return;
            };
            println!(
                "RPE {relation}, delta {value} {unit}, {align}: evo rmse {:.15}, ours {rmse:.15} ({} pairs)",
                stat(&stats, "rmse"),
                ours.num_pairs
            );
            assert_rel(rmse, stat(&stats, "rmse"), "RPE rmse");
            assert_rel(mean, stat(&stats, "mean"), "RPE mean");
        }
    }
}

#[test]
fn euroc_and_kitti_files_give_evo_ape_s_numbers() {
    let test = "euroc_and_kitti_files_give_evo_ape_s_numbers";
    let Some((gt_path, est_path)) = tum_files(test) else {
        return;
    };
    let (gt, est) = load(&gt_path, &est_path);
    // EuRoC csv: evo's `evo_ape euroc` takes the ground truth as EuRoC csv and the estimate as
    // TUM. The real V1_02 ground truth (17 columns, ns timestamps, w-first quaternions), against
    // a perturbed copy of every 10th pose; and the same ground truth as cpose writes it.
    let data = cpose_core::fs::shared_data_dir().unwrap();
    let euroc_gt = data.join("euroc/V1_02_excerpt/mav0/state_groundtruth_estimate0/data.csv");
    let (real, _) = read_trajectory(&euroc_gt, None, None).unwrap();
    let (times, poses): (Vec<f64>, Vec<_>) = real
        .iter()
        .step_by(10)
        .enumerate()
        .map(|(i, (t, p))| {
            let k = i as f64;
            let shift = nalgebra::Vector3::new(0.01 * k.sin(), 0.02 * (0.3 * k).cos(), 0.005);
            let turn = nalgebra::UnitQuaternion::from_scaled_axis(shift * 0.5);
            let pose = nalgebra::Isometry3::from_parts(
                (p.translation.vector + shift).into(),
                p.rotation * turn,
            );
            (t + 0.001, pose)
        })
        .unzip();
    let est_tum = temp_path("est.txt");
    let estimate = Trajectory::new(times, poses).unwrap();
    write_tum(&est_tum, &estimate).unwrap();
    let written_gt = temp_path("gt.csv");
    write_trajectory(&written_gt, &real, TrajectoryFormat::Euroc, None).unwrap();
    for gt_csv in [euroc_gt.as_path(), written_gt.as_path()] {
        let (gt_back, _) = read_trajectory(gt_csv, None, None).unwrap();
        let ours =
            cpose_core::eval::ate(&gt_back, &estimate, Alignment::Se3, DEFAULT_MAX_DIFF_SECS)
                .unwrap();
        let args = [
            "euroc",
            gt_csv.to_str().unwrap(),
            est_tum.to_str().unwrap(),
            "-a",
        ];
        let Some(stats) = run_evo(test, "evo_ape", &args) else {
            return;
        };
        println!(
            "EuRoC csv {}: evo ATE {:.15} m, ours {:.15} m ({} pairs)",
            gt_csv.display(),
            stat(&stats, "rmse"),
            ours.rmse_m,
            ours.num_matched
        );
        assert_rel(ours.rmse_m, stat(&stats, "rmse"), "EuRoC ATE rmse");
    }
    for p in [&est_tum, &written_gt] {
        std::fs::remove_file(p).unwrap();
    }

    // KITTI has no timestamps, so evo pairs by index: the associated poses are written as two
    // KITTI files of equal length, read back by cpose with a times file.
    let association = associate(&gt, &est, DEFAULT_MAX_DIFF_SECS).unwrap();
    let (reference, estimate) = association.poses(&gt, &est);
    let times: Vec<f64> = association
        .pairs
        .iter()
        .map(|&(i, _)| gt.timestamps_secs()[i])
        .collect();
    let (ref_txt, est_txt, times_txt) = (
        temp_path("ref.txt"),
        temp_path("est.txt"),
        temp_path("times.txt"),
    );
    let reference = Trajectory::new(times.clone(), reference).unwrap();
    let estimate = Trajectory::new(times, estimate).unwrap();
    write_trajectory(
        &ref_txt,
        &reference,
        TrajectoryFormat::Kitti,
        Some(&times_txt),
    )
    .unwrap();
    write_trajectory(&est_txt, &estimate, TrajectoryFormat::Kitti, None).unwrap();
    let (ref_back, _) = read_trajectory(&ref_txt, None, Some(&times_txt)).unwrap();
    let (est_back, _) = read_trajectory(&est_txt, None, Some(&times_txt)).unwrap();
    let ours = cpose_core::eval::ate(&ref_back, &est_back, Alignment::Se3, 1e-9).unwrap();
    let evo = run_evo(
        test,
        "evo_ape",
        &[
            "kitti",
            ref_txt.to_str().unwrap(),
            est_txt.to_str().unwrap(),
            "-a",
        ],
    );
    for p in [&ref_txt, &est_txt, &times_txt] {
        std::fs::remove_file(p).unwrap();
    }
    let Some(stats) = evo else { return };
    println!(
        "KITTI ATE: evo {:.15} m, ours {:.15} m",
        stat(&stats, "rmse"),
        ours.rmse_m
    );
    assert_rel(ours.rmse_m, stat(&stats, "rmse"), "KITTI ATE rmse");
}

#[test]
fn a_repeated_ground_truth_timestamp_gives_evo_ape_s_number() {
    let test = "a_repeated_ground_truth_timestamp_gives_evo_ape_s_number";
    let Some((gt_path, est_path)) = tum_files(test) else {
        return;
    };
    let (gt, est) = load(&gt_path, &est_path);
    // Repeat the ground-truth line matched to the 100th estimate, 5 cm off, right after it (as
    // TUM RGB-D's fr2/desk ground truth repeats one timestamp).
    let association = associate(&gt, &est, DEFAULT_MAX_DIFF_SECS).unwrap();
    let (index, _) = association.pairs[100];
    let text = std::fs::read_to_string(&gt_path).unwrap();
    let stamp = gt.timestamps_secs()[index];
    let mut out = String::new();
    for line in text.lines() {
        out.push_str(line);
        out.push('\n');
        let values: Vec<f64> = line
            .split_whitespace()
            .map(|v| v.parse().unwrap_or(f64::NAN))
            .collect();
        if values.len() == 8 && values[0] == stamp {
            let mut moved = values.clone();
            moved[1] += 0.05;
            let fields: Vec<String> = moved.iter().map(|v| v.to_string()).collect();
            out.push_str(&format!("{}\n", fields.join(" ")));
        }
    }
    let repeated = temp_path("gt_repeated.txt");
    std::fs::write(&repeated, out).unwrap();
    let (gt_read, duplicates) = read_trajectory(&repeated, None, None).unwrap();
    assert_eq!(duplicates.lines.len(), 1);
    assert_eq!(gt_read.len(), gt.len());
    let ours =
        cpose_core::eval::ate(&gt_read, &est, Alignment::Se3, DEFAULT_MAX_DIFF_SECS).unwrap();
    let unchanged =
        cpose_core::eval::ate(&gt, &est, Alignment::Se3, DEFAULT_MAX_DIFF_SECS).unwrap();
    assert_ne!(ours.rmse_m, unchanged.rmse_m, "the repeat is used");
    let args = [
        "tum",
        repeated.to_str().unwrap(),
        est_path.to_str().unwrap(),
        "-a",
    ];
    let evo = run_evo(test, "evo_ape", &args);
    std::fs::remove_file(&repeated).unwrap();
    let Some(stats) = evo else { return };
    println!(
        "repeated timestamp: evo ATE {:.15} m, ours {:.15} m",
        stat(&stats, "rmse"),
        ours.rmse_m
    );
    assert_rel(
        ours.rmse_m,
        stat(&stats, "rmse"),
        "ATE rmse with a repeated timestamp",
    );
}

#[test]
fn eval_invariants_on_tum_fr1_xyz() {
    let Some((gt_path, est_path)) = tum_files("eval_invariants_on_tum_fr1_xyz") else {
        return;
    };
    let (gt, est) = load(&gt_path, &est_path);
    assert_eq!(gt.len(), 3000);
    assert_eq!(est.len(), 788);

    let none = cpose_core::eval::ate(&gt, &est, Alignment::None, DEFAULT_MAX_DIFF_SECS).unwrap();
    let se3 = cpose_core::eval::ate(&gt, &est, Alignment::Se3, DEFAULT_MAX_DIFF_SECS).unwrap();
    let sim3 = cpose_core::eval::ate(&gt, &est, Alignment::Sim3, DEFAULT_MAX_DIFF_SECS).unwrap();
    // Umeyama minimises the SSE over a growing set of transforms.
    assert!(se3.sse_m2 <= none.sse_m2 && sim3.sse_m2 <= se3.sse_m2 * (1.0 + 1e-12));
    assert!(
        se3.rmse_m < 0.05,
        "an RGBD-SLAM estimate of fr1_xyz is good to a few cm"
    );
    assert_eq!(se3.transform.scale, 1.0);
    assert!((sim3.transform.scale - 1.0).abs() < 0.1);
    // Every estimated pose lies within 10 ms of a 100 Hz ground-truth pose.
    assert!(none.num_matched <= est.len() && none.num_matched > est.len() * 9 / 10);
    // Association is symmetric in the pairs it finds.
    let forward = associate(&gt, &est, DEFAULT_MAX_DIFF_SECS).unwrap();
    let backward = associate(&est, &gt, DEFAULT_MAX_DIFF_SECS).unwrap();
    let flipped: Vec<_> = backward.pairs.iter().map(|&(a, b)| (b, a)).collect();
    assert_eq!(forward.pairs, flipped);
    // BARF errors on the associated poses are finite and small for a good estimate.
    let (reference, estimate) = forward.poses(&gt, &est);
    let barf = barf_pose_errors(&reference, &estimate, ReflectionFix::BarfThirdRow).unwrap();
    assert!(
        barf.rot_err_deg.is_finite() && barf.rot_err_deg < 10.0,
        "{}",
        barf.rot_err_deg
    );
    assert!(
        barf.trans_err.is_finite() && barf.trans_err < 0.2,
        "{}",
        barf.trans_err
    );
    // Writing and reading back the real file loses nothing.
    let copy = temp_path("groundtruth.txt");
    write_tum(&copy, &gt).unwrap();
    let back = read_tum(&copy).unwrap();
    std::fs::remove_file(&copy).unwrap();
    assert_eq!(back.timestamps_secs(), gt.timestamps_secs());
    for (a, b) in back.poses().iter().zip(gt.poses()) {
        assert_eq!(a.translation, b.translation);
        assert!(a.rotation.angle_to(&b.rotation) < 1e-15);
    }
}
