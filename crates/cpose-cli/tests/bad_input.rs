//! The bad-input corpus: every reader and every task's config fed truncated files, NaN and
//! infinite values, wrong shapes and column counts, unsorted and repeated timestamps, missing
//! files, lying headers, decompression bombs, hostile paths, typos, out-of-range numbers and
//! wrong types. Each case pins the exit code (2: bad arguments or config, 1: the task failed while
//! running), and that stderr holds one message, printed once, naming the file or the config key
//! and what was expected; where cpose repairs its input, that the repair is reported.
//!
//! Cases are tables, one `#[test]` per reader family; a failing family lists every failing case.
//! Every input is built here (byte-level helpers for PNG, NPY and ZIP); every case fails at
//! config or data load, before any training.

// Test code: a failed file operation should just fail the test.
#![allow(clippy::unwrap_used)]

use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::temp_dir;

/// Longest a case may take: every case fails at load, in well under a second on an idle machine.
const FAST: Duration = Duration::from_secs(20);
/// A case still running after this is killed (and fails).
const KILL_AFTER: Duration = Duration::from_secs(60);

/// One file (or folder) of a case, applied in order inside the case's folder.
#[derive(Clone, Copy)]
enum F {
    /// Text; `{dir}` becomes the case's folder.
    T(&'static str),
    /// Bytes from a builder.
    B(fn() -> Vec<u8>),
    /// A whole valid scene written by a builder into this folder.
    S(fn(&Path)),
    /// An empty folder.
    D,
    /// Removes the file or folder.
    Rm,
    /// Keeps the first half of the file.
    Half,
    /// Keeps the first `n` bytes of the file.
    Cut(usize),
}
use F::{B, Cut, D, Half, Rm, S, T};

/// A bad input and the exact outcome.
struct Case<'a> {
    name: &'a str,
    files: &'a [(&'a str, F)],
    /// `cpose` arguments; `{root}` is the workspace, `{dir}` the case's folder (the working
    /// folder). `run` gets `-q`, and `--out run` unless the case names `--out` or an `out_dir`.
    args: &'a [&'a str],
    code: i32,
    /// Substrings of stderr: the file or key first, then what was expected. The last one must
    /// appear exactly once (the cause is not repeated).
    expect: &'a [&'a str],
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Runs `cpose` in `dir`, killing it after [`KILL_AFTER`]: (exit code, stderr, seconds).
fn cpose_in(dir: &Path, args: &[String]) -> (Option<i32>, String, Duration) {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_cpose"))
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the cpose binary runs");
    let mut pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = pipe.read_to_string(&mut text);
        text
    });
    let code = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status.code();
        }
        if started.elapsed() > KILL_AFTER {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    (code, reader.join().unwrap(), started.elapsed())
}

fn apply(dir: &Path, rel: &str, file: F) {
    let path = dir.join(rel);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    match file {
        T(text) => {
            std::fs::write(&path, text.replace("{dir}", &dir.display().to_string())).unwrap()
        }
        B(bytes) => std::fs::write(&path, bytes()).unwrap(),
        S(scene) => {
            std::fs::create_dir_all(&path).unwrap();
            scene(&path);
        }
        D => std::fs::create_dir_all(&path).unwrap(),
        Rm if path.is_dir() => std::fs::remove_dir_all(&path).unwrap(),
        Rm => std::fs::remove_file(&path).unwrap(),
        Half | Cut(_) => {
            let bytes = std::fs::read(&path).unwrap();
            let keep = if let Cut(n) = file {
                n
            } else {
                bytes.len() / 2
            };
            std::fs::write(&path, &bytes[..keep.min(bytes.len())]).unwrap();
        }
    }
}

/// Runs one case; `Err` says what differs from the pinned outcome.
fn check(family: &str, case: &Case) -> Result<(), String> {
    let dir = temp_dir(&format!("bad-{family}"));
    for &(rel, file) in case.files {
        apply(&dir, rel, file);
    }
    let (root, here) = (
        workspace_root().display().to_string(),
        dir.display().to_string(),
    );
    let mut args: Vec<String> = case
        .args
        .iter()
        .map(|a| a.replace("{root}", &root).replace("{dir}", &here))
        .collect();
    if args[0] == "run" {
        args.push("-q".into());
        if !args
            .iter()
            .any(|a| a == "--out" || a == "--resume" || a.contains("out_dir"))
        {
            args.extend(["--out".into(), "run".into()]);
        }
    }
    let (code, err, took) = cpose_in(&dir, &args);
    let mut problems = Vec::new();
    if code != Some(case.code) {
        problems.push(format!("exit code {code:?}, expected {}", case.code));
    }
    for e in case.expect {
        if !err.contains(e) {
            problems.push(format!("no {e:?}"));
        }
    }
    if let Some(last) = case.expect.last()
        && err.matches(last).count() > 1
    {
        problems.push(format!("{last:?} printed more than once"));
    }
    if err.matches("(os error").count() > 1 {
        problems.push("the I/O cause printed more than once".into());
    }
    if err.contains("panicked") {
        problems.push("panicked".into());
    }
    if case.code != 0 {
        let messages = err
            .lines()
            .filter(|l| l.starts_with("cpose:") || l.starts_with("error:"))
            .count();
        // A TOML error draws the line and a caret; clap adds a hint; anything else is one line.
        let drawn = err.contains("TOML parse error") || err.starts_with("error:");
        if messages != 1 || (!drawn && err.trim_end().lines().count() != 1) {
            problems.push("not one message".into());
        }
    }
    if took > FAST {
        problems.push(format!("took {:.1} s", took.as_secs_f64()));
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{}: {}\n    cpose {}\n    stderr: {}",
            case.name,
            problems.join("; "),
            case.args.join(" "),
            err.trim_end().replace('\n', "\n            ")
        ))
    }
}

/// Runs every case of a family and fails with the list of all failing ones.
fn check_all(family: &str, cases: &[Case]) {
    let mut names: Vec<&str> = cases.iter().map(|c| c.name).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), cases.len(), "case names must be unique");
    let failures: Vec<String> = cases
        .iter()
        .filter_map(|c| check(family, c).err())
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} {family} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

// ---------------------------------------------------------------------------------------------
// Byte-level builders: PNG, NPY, ZIP.

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A zlib stream of STORED deflate blocks.
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    out.extend(deflate_stored(data));
    let (mut a, mut b) = (1u32, 0u32);
    for &x in data {
        a = (a + u32::from(x)) % 65521;
        b = (b + a) % 65521;
    }
    out.extend(((b << 16) | a).to_be_bytes());
    out
}

/// Raw deflate data of STORED blocks (valid DEFLATE that any inflater reads).
fn deflate_stored(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let chunks: Vec<&[u8]> = if data.is_empty() {
        vec![&[]]
    } else {
        data.chunks(65535).collect()
    };
    for (i, chunk) in chunks.iter().enumerate() {
        out.push(u8::from(i + 1 == chunks.len()));
        let len = chunk.len() as u16;
        out.extend(len.to_le_bytes());
        out.extend((!len).to_le_bytes());
        out.extend(*chunk);
    }
    out
}

fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend((data.len() as u32).to_be_bytes());
    let mut body = kind.to_vec();
    body.extend(data);
    out.extend(&body);
    out.extend(crc32(&body).to_be_bytes());
}

/// A PNG whose header says `width × height` (bit depth, colour type) over `rows` (each with
/// its filter byte), which may describe another size: a lying header.
fn png_raw(width: u32, height: u32, depth: u8, colour: u8, rows: &[u8]) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = width.to_be_bytes().to_vec();
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([depth, colour, 0, 0, 0]);
    png_chunk(&mut out, b"IHDR", &ihdr);
    png_chunk(&mut out, b"IDAT", &zlib_stored(rows));
    png_chunk(&mut out, b"IEND", &[]);
    out
}

/// A valid `width × height` PNG with `channels` samples of `bytes` bytes per pixel.
fn png(width: u32, height: u32, colour: u8, channels: usize, bytes: usize) -> Vec<u8> {
    let mut rows = Vec::new();
    for y in 0..height as usize {
        rows.push(0);
        for x in 0..width as usize * channels * bytes {
            rows.push(if bytes == 2 && x % 2 == 0 {
                0x07 // 16-bit depth: about 1800 units
            } else {
                (17 * x + 29 * y) as u8
            });
        }
    }
    png_raw(width, height, 8 * bytes as u8, colour, &rows)
}

fn rgb(width: u32, height: u32) -> Vec<u8> {
    png(width, height, 2, 3, 1)
}

fn rgba(width: u32, height: u32) -> Vec<u8> {
    png(width, height, 6, 4, 1)
}

/// A 16-bit single-channel depth PNG.
fn depth16(width: u32, height: u32) -> Vec<u8> {
    png(width, height, 0, 1, 2)
}

fn rgb_12x10() -> Vec<u8> {
    rgb(12, 10)
}
fn rgb_11x10() -> Vec<u8> {
    rgb(11, 10)
}
fn rgb_16x12() -> Vec<u8> {
    rgb(16, 12)
}
fn rgb_20x12() -> Vec<u8> {
    rgb(20, 12)
}
fn rgba_8x8() -> Vec<u8> {
    rgba(8, 8)
}
fn depth_16x12() -> Vec<u8> {
    depth16(16, 12)
}
fn gray8_16x12() -> Vec<u8> {
    png(16, 12, 0, 1, 1)
}
/// The header of a 100000 × 100000 RGB image over a few bytes of data.
fn png_lying_header() -> Vec<u8> {
    png_raw(100_000, 100_000, 8, 2, &[0, 1, 2, 3])
}
/// A 16-bit depth header of 160000 × 120000 (the 16 × 12 camera's aspect) over a few bytes.
fn depth_lying_header() -> Vec<u8> {
    png_raw(160_000, 120_000, 16, 0, &[0, 1, 2])
}
/// A valid PNG with one flipped byte in its image data (its CRC no longer matches).
fn png_bad_crc() -> Vec<u8> {
    let mut bytes = rgb(12, 10);
    let at = bytes.len() - 30;
    bytes[at] ^= 0xFF;
    bytes
}
/// JPEG markers up to a scan that never ends: a truncated JPEG.
fn jpeg_truncated() -> Vec<u8> {
    let mut bytes = vec![0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x10];
    bytes.extend(b"JFIF\0\x01\x01\0\0\x01\0\x01\0\0");
    bytes.extend([0xFF, 0xDA, 0x00, 0x08, 0x01, 0x01, 0x00, 0x00, 0x3F, 0x00]);
    bytes.extend([0x12, 0x34, 0x56, 0x78]);
    bytes
}
fn not_an_image() -> Vec<u8> {
    b"this is not an image\n".to_vec()
}

/// An NPY v1 file: `dict` entries, then `data`.
fn npy_raw(descr: &str, fortran: &str, shape: &str, data: &[u8]) -> Vec<u8> {
    let mut dict =
        format!("{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape}, }}");
    let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
    dict.push_str(&" ".repeat(pad));
    dict.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((dict.len() as u16).to_le_bytes());
    out.extend(dict.as_bytes());
    out.extend(data);
    out
}

fn f64_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// LLFF rows: identity LLFF rotations, centres 0.1·i apart, original 40×30 with f = 50,
/// bounds [1, 10]; `edit` changes them.
fn llff_rows(n: usize, edit: impl Fn(&mut Vec<f64>)) -> Vec<f64> {
    let mut rows: Vec<f64> = (0..n)
        .flat_map(|i| {
            let c = 0.1 * i as f64;
            [
                1.0, 0.0, 0.0, c, 30.0, 0.0, 1.0, 0.0, 0.0, 40.0, 0.0, 0.0, 1.0, 0.0, 50.0, 1.0,
                10.0,
            ]
        })
        .collect();
    edit(&mut rows);
    rows
}

fn poses_bounds(rows: &[f64]) -> Vec<u8> {
    npy_raw(
        "<f8",
        "False",
        &format!("({}, 17)", rows.len() / 17),
        &f64_bytes(rows),
    )
}

/// One ZIP entry as its headers describe it.
struct Entry {
    name: &'static str,
    method: u16,
    flags: u16,
    crc: u32,
    data: Vec<u8>,
    /// The uncompressed size the headers declare (in a ZIP64 extra field above 4 GiB).
    size: u64,
}

fn stored(name: &'static str, data: Vec<u8>) -> Entry {
    Entry {
        name,
        method: 0,
        flags: 0,
        crc: crc32(&data),
        size: data.len() as u64,
        data,
    }
}

/// A ZIP archive of `entries`, headers as given.
fn zip(entries: &[Entry]) -> Vec<u8> {
    let (mut out, mut central) = (Vec::new(), Vec::new());
    for e in entries {
        let zip64 = e.size >= u64::from(u32::MAX);
        let size32 = if zip64 { u32::MAX } else { e.size as u32 };
        let extra: Vec<u8> = if zip64 {
            [
                &1u16.to_le_bytes()[..],
                &8u16.to_le_bytes(),
                &e.size.to_le_bytes(),
            ]
            .concat()
        } else {
            Vec::new()
        };
        let offset = out.len() as u32;
        let mut common = Vec::new();
        for v in [20u16, e.flags, e.method, 0, 33] {
            common.extend(v.to_le_bytes());
        }
        for v in [e.crc, e.data.len() as u32, size32] {
            common.extend(v.to_le_bytes());
        }
        common.extend((e.name.len() as u16).to_le_bytes());
        out.extend(0x0403_4b50u32.to_le_bytes());
        out.extend(&common);
        out.extend(0u16.to_le_bytes());
        out.extend(e.name.as_bytes());
        out.extend(&e.data);
        central.extend(0x0201_4b50u32.to_le_bytes());
        central.extend(20u16.to_le_bytes());
        central.extend(&common);
        central.extend((extra.len() as u16).to_le_bytes());
        central.extend([0u8; 10]);
        central.extend(offset.to_le_bytes());
        central.extend(e.name.as_bytes());
        central.extend(&extra);
    }
    let cd_offset = out.len() as u32;
    let cd_size = central.len() as u32;
    out.extend(&central);
    out.extend(0x0605_4b50u32.to_le_bytes());
    out.extend([0u8; 4]);
    out.extend((entries.len() as u16).to_le_bytes());
    out.extend((entries.len() as u16).to_le_bytes());
    out.extend(cd_size.to_le_bytes());
    out.extend(cd_offset.to_le_bytes());
    out.extend(0u16.to_le_bytes());
    out
}

fn u16s(v: &[u16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// EventNeRF's event arrays as `.npy` entries: `x`, `y`, `t` (seconds), `p`, four events.
fn event_entries(t: &[f64], p: &[i8], x: &[u16]) -> Vec<Entry> {
    let n = |len: usize| format!("({len},)");
    vec![
        stored("x.npy", npy_raw("<u2", "False", &n(x.len()), &u16s(x))),
        stored(
            "y.npy",
            npy_raw("<u2", "False", "(4,)", &u16s(&[5, 6, 7, 8])),
        ),
        stored("t.npy", npy_raw("<f8", "False", &n(t.len()), &f64_bytes(t))),
        stored(
            "p.npy",
            npy_raw(
                "|i1",
                "False",
                &n(p.len()),
                &p.iter().map(|&v| v as u8).collect::<Vec<_>>(),
            ),
        ),
    ]
}

const T4: [f64; 4] = [0.1, 0.2, 0.3, 0.4];
const P4: [i8; 4] = [1, -1, 1, -1];
const X4: [u16; 4] = [10, 20, 30, 40];

fn events_npz() -> Vec<u8> {
    zip(&event_entries(&T4, &P4, &X4))
}

// ---------------------------------------------------------------------------------------------
// Valid scenes, each broken by a case afterwards.

fn write(dir: &Path, rel: &str, bytes: impl AsRef<[u8]>) {
    let path = dir.join(rel);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// LLFF: 4 rows and 4 images of 12 × 10 in `images_8/`.
fn llff(dir: &Path) {
    write(dir, "poses_bounds.npy", poses_bounds(&llff_rows(4, |_| {})));
    for i in 0..4 {
        write(dir, &format!("images_8/image{i:03}.png"), rgb_12x10());
    }
}

fn blender_frame(i: usize, scale: f64) -> String {
    format!(
        "{{\"file_path\": \"./train/r_{i}\", \"transform_matrix\": [[{scale}, 0, 0, {i}], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}}"
    )
}

/// Blender: `transforms_train.json` with 4 frames and their RGBA images of 8 × 8.
fn blender(dir: &Path) {
    let frames: Vec<String> = (0..4).map(|i| blender_frame(i, 1.0)).collect();
    write(
        dir,
        "transforms_train.json",
        format!(
            "{{\"camera_angle_x\": 0.69, \"frames\": [{}]}}",
            frames.join(", ")
        ),
    );
    for i in 0..4 {
        write(dir, &format!("train/r_{i}.png"), rgba_8x8());
    }
}

/// A COLMAP text model: one pinhole camera of 12 × 10, three images, one point seen by all.
const COLMAP_CAMERAS: &str = "1 PINHOLE 12 10 10 10 6 5\n";
const COLMAP_IMAGES: &str =
    "1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0.1 0 0 1 b.png\n\n3 1 0 0 0 0.2 0 0 1 c.png\n\n";
const COLMAP_POINTS: &str = "1 0 0 5 128 128 128 0.5 1 0 2 0 3 0\n";
const NERFSTUDIO_FISHEYE: &str = r#"{"camera_model": "OPENCV_FISHEYE", "fl_x": 10, "fl_y": 10, "cx": 6, "cy": 5, "w": 12, "h": 10, "frames": [{"file_path": "a.png", "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]}"#;

const IDENTITY_ROW: &str = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n";
const IDENTITY_4X4: &str = "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";
const CAM_PARAMS: &str = r#"{"camera": {"w": 16, "h": 12, "fx": 10.0, "fy": 10.0, "cx": 7.5, "cy": 5.5, "scale": 1000.0}}"#;

/// Replica (NICE-SLAM's layout): 4 frames of 16 × 12, `traj.txt`, `cam_params.json`.
fn replica(dir: &Path) {
    for i in 0..4 {
        write(dir, &format!("results/frame{i:06}.png"), rgb_16x12());
        write(dir, &format!("results/depth{i:06}.png"), depth_16x12());
    }
    write(dir, "traj.txt", IDENTITY_ROW.repeat(4));
    write(dir, "cam_params.json", CAM_PARAMS);
}

/// ScanNet: `color/`, `depth/`, `pose/`, 4 frames of 16 × 12, and `intrinsic/`.
fn scannet(dir: &Path) {
    for i in 0..4 {
        write(dir, &format!("color/{i}.png"), rgb_16x12());
        write(dir, &format!("depth/{i}.png"), depth_16x12());
        write(dir, &format!("pose/{i}.txt"), IDENTITY_4X4);
    }
    write(
        dir,
        "intrinsic/intrinsic_depth.txt",
        "10 0 7.5 0\n0 10 5.5 0\n0 0 1 0\n0 0 0 1\n",
    );
}

/// 7-Scenes: 4 frames of 16 × 12 and `camera-intrinsics.txt`.
fn seven_scenes(dir: &Path) {
    for i in 0..4 {
        write(dir, &format!("frame-{i:06}.color.png"), rgb_16x12());
        write(dir, &format!("frame-{i:06}.depth.png"), depth_16x12());
        write(dir, &format!("frame-{i:06}.pose.txt"), IDENTITY_4X4);
    }
    write(dir, "camera-intrinsics.txt", "10 0 7.5\n0 10 5.5\n0 0 1\n");
}

/// TUM RGB-D: 4 frames 0.1 s apart, 16 × 12 (a quarter of 640 × 480 would be 160 × 120; the
/// aspect ratio is what matters), with ground truth.
fn tum_rgbd(dir: &Path) {
    let (mut rgb_txt, mut depth_txt, mut gt) = (String::new(), String::new(), String::new());
    for i in 0..4 {
        let t = 0.1 * i as f64;
        write(dir, &format!("rgb/{i}.png"), rgb(16, 12));
        write(dir, &format!("depth/{i}.png"), depth16(16, 12));
        rgb_txt.push_str(&format!("{t:.3} rgb/{i}.png\n"));
        depth_txt.push_str(&format!("{t:.3} depth/{i}.png\n"));
        gt.push_str(&format!("{t:.3} {i} 0 0 0 0 0 1\n"));
    }
    write(dir, "rgb.txt", rgb_txt);
    write(dir, "depth.txt", depth_txt);
    write(dir, "groundtruth.txt", gt);
}

const SENSOR_YAML: &str = "%YAML:1.0\nsensor_type: imu\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, 0.0, 0.0,\n         0.0, 1.0, 0.0, 0.0,\n         0.0, 0.0, 1.0, 0.0,\n         0.0, 0.0, 0.0, 1.0]\nrate_hz: 200\ngyroscope_noise_density: 1.6968e-04\ngyroscope_random_walk: 1.9393e-05\naccelerometer_noise_density: 2.0000e-3\naccelerometer_random_walk: 3.0000e-3\n";

/// The first timestamp (ns) of the EuRoC folders of [`euroc`].
const EUROC_T0: i64 = 1_403_715_523_912_140_000;

/// EuRoC (ASL): `mav0/` with 100 ground-truth states and 200 IMU readings over 1 s, and both
/// `sensor.yaml`.
fn euroc(dir: &Path) {
    let t0 = EUROC_T0;
    let mut gt = String::from(
        "#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z,v_x,v_y,v_z,bw_x,bw_y,bw_z,ba_x,ba_y,ba_z\n",
    );
    for i in 0..100 {
        let s = i as f64 * 0.01;
        gt.push_str(&format!(
            "{},{},{},1,1,0,0,0,0.1,0.05,0,0,0,0,0,0,0\n",
            t0 + i * 10_000_000,
            0.1 * s,
            0.05 * s * s
        ));
    }
    let mut imu = String::from("#timestamp,w_x,w_y,w_z,a_x,a_y,a_z\n");
    for i in 0..200 {
        imu.push_str(&format!("{},0,0,0,0,0,9.81\n", t0 + i * 5_000_000));
    }
    write(dir, "mav0/state_groundtruth_estimate0/data.csv", gt);
    write(dir, "mav0/imu0/data.csv", imu);
    write(dir, "mav0/imu0/sensor.yaml", SENSOR_YAML);
    write(
        dir,
        "mav0/cam0/sensor.yaml",
        SENSOR_YAML.replace("sensor_type: imu", "sensor_type: camera"),
    );
}

/// [`euroc`] with the IMU readings `(k, w_x)` at `k` × 5 ms, the other axes at rest.
fn euroc_imu(dir: &Path, readings: impl Iterator<Item = (i64, f64)>) {
    euroc(dir);
    let mut imu = String::from("#timestamp,w_x,w_y,w_z,a_x,a_y,a_z\n");
    for (i, w) in readings {
        imu.push_str(&format!("{},{w},0,0,0,0,9.81\n", EUROC_T0 + i * 5_000_000));
    }
    write(dir, "mav0/imu0/data.csv", imu);
}

/// [`euroc`] with a turning IMU from the first reading: no stationary start.
fn euroc_moving(dir: &Path) {
    euroc_imu(
        dir,
        (0..200).map(|i| (i, if i % 2 == 0 { 0.5 } else { -0.5 })),
    );
}

/// [`euroc`] with no IMU readings from 0.1 s to 0.2 s, between the frames.
fn euroc_gap(dir: &Path) {
    euroc_imu(
        dir,
        (0..200).filter(|i| !(20..40).contains(i)).map(|i| (i, 0.0)),
    );
}

const INTRINSICS: &str = "100 0 173 0\n0 100 130 0\n0 0 1 0\n0 0 0 1\n";

/// EventNeRF: 3 views in `train/` (pose, intrinsics), four events in `train/events/`.
fn eventnerf(dir: &Path) {
    for i in 0..3 {
        write(
            dir,
            &format!("train/pose/r_{i:05}.txt"),
            format!("1 0 0 {i}\n0 1 0 0\n0 0 1 -4\n0 0 0 1\n"),
        );
        write(dir, &format!("train/intrinsics/r_{i:05}.txt"), INTRINSICS);
    }
    write(dir, "train/events/events.npz", events_npz());
}

/// `eventnerf` with a `validation/` split of 2 views with images of the sensor's 346 × 260.
fn eventnerf_validation(dir: &Path) {
    eventnerf(dir);
    for i in 0..2 {
        write(
            dir,
            &format!("validation/pose/r_{i:05}.txt"),
            format!("1 0 0 {i}\n0 1 0 0\n0 0 1 -4\n0 0 0 1\n"),
        );
        write(
            dir,
            &format!("validation/intrinsics/r_{i:05}.txt"),
            INTRINSICS,
        );
        write(dir, &format!("validation/rgb/r_{i:05}.png"), rgb(346, 260));
    }
}

// ---------------------------------------------------------------------------------------------
// Trajectory files: `cpose eval` and `cpose convert` on TUM, EuRoC csv and KITTI.

const GT: (&str, F) = (
    "gt.txt",
    T("1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n3.0 1 1 0 0 0 0 1\n4.0 2 1 0.5 0 0 0 1\n"),
);
const KITTI_POSES: &str = "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 1 0 0 1 0\n1 0 0 2 0 1 0 1 0 0 1 0.5\n";
const ATE: &[&str] = &["eval", "ate", "gt.txt", "est.txt"];
const ATE_CSV: &[&str] = &["eval", "ate", "gt.txt", "est.csv"];
const ATE_KITTI: &[&str] = &[
    "eval",
    "ate",
    "gt.txt",
    "est.kitti",
    "--est-times",
    "times.txt",
];

#[test]
fn trajectory_files() {
    let cases = [
        Case {
            name: "tum: a missing file, its cause printed once",
            files: &[GT],
            args: ATE,
            code: 2,
            expect: &[
                "cannot read trajectory file est.txt",
                "No such file or directory",
            ],
        },
        Case {
            name: "tum: a line with 7 columns",
            files: &[GT, ("est.txt", T("1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 1\n"))],
            args: ATE,
            code: 2,
            expect: &[
                "est.txt",
                "line 2: expected 8 columns `timestamp tx ty tz qx qy qz qw`, got 7",
            ],
        },
        Case {
            name: "tum: truncated in the middle of a line",
            files: &[
                GT,
                ("est.txt", T("1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n")),
                ("est.txt", Cut(26)),
            ],
            args: ATE,
            code: 2,
            expect: &["est.txt", "line 2: expected 8 columns", "got 3"],
        },
        Case {
            name: "tum: nan",
            files: &[
                GT,
                ("est.txt", T("1.0 0 0 0 0 0 0 1\n2.0 nan 0 0 0 0 0 1\n")),
            ],
            args: ATE,
            code: 2,
            expect: &[
                "est.txt",
                "line 2: expected a finite number for `tx`, got `nan`",
            ],
        },
        Case {
            name: "tum: infinite timestamp",
            files: &[GT, ("est.txt", T("inf 0 0 0 0 0 0 1\n"))],
            args: ATE,
            code: 2,
            expect: &[
                "est.txt",
                "line 1: expected a finite number for `timestamp`, got `inf`",
            ],
        },
        Case {
            name: "tum: a number beyond f64",
            files: &[GT, ("est.txt", T("1.0 0 0 1e400 0 0 0 1\n"))],
            args: ATE,
            code: 2,
            expect: &[
                "est.txt",
                "line 1: expected a finite number for `tz`, got `1e400`",
            ],
        },
        Case {
            name: "tum: a word for a number",
            files: &[GT, ("est.txt", T("1.0 0 0 zero 0 0 0 1\n"))],
            args: ATE,
            code: 2,
            expect: &["est.txt", "line 1: expected a number for `tz`, got `zero`"],
        },
        Case {
            name: "tum: unsorted timestamps",
            files: &[GT, ("est.txt", T("2 0 0 0 0 0 0 1\n\n1 0 0 0 0 0 0 1\n"))],
            args: ATE,
            code: 2,
            expect: &[
                "est.txt",
                "line 3: expected increasing timestamps, got 1 after 2",
            ],
        },
        Case {
            name: "tum: zero quaternion",
            files: &[GT, ("est.txt", T("1 0 0 0 0 0 0 0\n"))],
            args: ATE,
            code: 2,
            expect: &[
                "est.txt",
                "line 1: expected a non-zero quaternion `qx qy qz qw`, got norm 0e0",
            ],
        },
        Case {
            name: "tum: empty file",
            files: &[GT, ("est.txt", T(""))],
            args: ATE,
            code: 2,
            expect: &["est.txt", "expected at least one pose line, got none"],
        },
        Case {
            name: "tum: only comments",
            files: &[
                GT,
                ("est.txt", T("# timestamp tx ty tz qx qy qz qw\n\n   \n")),
            ],
            args: ATE,
            code: 2,
            expect: &["est.txt", "expected at least one pose line, got none"],
        },
        Case {
            name: "tum: the reference is broken",
            files: &[
                ("gt.txt", T("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 -inf\n")),
                ("est.txt", GT.1),
            ],
            args: ATE,
            code: 2,
            expect: &[
                "gt.txt",
                "line 2: expected a finite number for `qw`, got `-inf`",
            ],
        },
        Case {
            name: "tum: repeated timestamp kept once and reported",
            files: &[
                GT,
                (
                    "est.txt",
                    T(
                        "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n2.0 1 0.1 0 0 0 0 1\n3.0 1 1 0 0 0 0 1\n4.0 2 1 0.5 0 0 0 1\n",
                    ),
                ),
            ],
            args: ATE,
            code: 0,
            expect: &[
                "est.txt: 1 repeated timestamp(s) (first on line 3); kept the later pose of each",
            ],
        },
        Case {
            name: "convert: repeated timestamps reported while converting",
            files: &[(
                "in.txt",
                T(
                    "1 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n2 0 1 0 0 0 0 1\n3 0 0 0 0 0 0 1\n",
                ),
            )],
            args: &["convert", "in.txt", "out.csv"],
            code: 0,
            expect: &[
                "wrote 3 poses to out.csv as euroc",
                "in.txt: 2 repeated timestamp(s) (first on line 2); kept the later pose of each",
            ],
        },
        Case {
            name: "detect: 3 values on the first line",
            files: &[GT, ("est.txt", T("1 2 3\n"))],
            args: ATE,
            code: 2,
            expect: &[
                "est.txt",
                "cannot tell the trajectory format: expected 8 values (TUM), 12 (KITTI) or a csv of at least 8 (EuRoC) on the first data line, got 3; name the format with --format",
            ],
        },
        Case {
            name: "detect: unknown --format",
            files: &[GT, ("est.txt", GT.1)],
            args: &["eval", "ate", "gt.txt", "est.txt", "--format", "vicon"],
            code: 2,
            expect: &[
                "--format",
                "unknown trajectory format `vicon` (expected tum, euroc or kitti)",
            ],
        },
        Case {
            name: "euroc: 7 columns",
            files: &[GT, ("est.csv", T("#timestamp,x\n1000000000,0,0,0,1,0,0\n"))],
            args: ATE_CSV,
            code: 2,
            expect: &[
                "est.csv",
                "line 2: expected at least 8 comma-separated columns `timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z` (EuRoC csv), got 7",
            ],
        },
        Case {
            name: "euroc: inf",
            files: &[
                GT,
                (
                    "est.csv",
                    T("1000000000,0,0,0,1,0,0,0\n2000000000,inf,0,0,1,0,0,0\n"),
                ),
            ],
            args: ATE_CSV,
            code: 2,
            expect: &[
                "est.csv",
                "line 2: expected a finite number for `p_x`, got `inf`",
            ],
        },
        Case {
            name: "euroc: nan quaternion",
            files: &[GT, ("est.csv", T("1000000000,0,0,0,NaN,0,0,0\n"))],
            args: ATE_CSV,
            code: 2,
            expect: &[
                "est.csv",
                "line 1: expected a finite number for `q_w`, got `NaN`",
            ],
        },
        Case {
            name: "euroc: unsorted",
            files: &[
                GT,
                (
                    "est.csv",
                    T("2000000000,0,0,0,1,0,0,0\n1000000000,1,0,0,1,0,0,0\n"),
                ),
            ],
            args: ATE_CSV,
            code: 2,
            expect: &[
                "est.csv",
                "line 2: expected increasing timestamps, got 1 after 2",
            ],
        },
        Case {
            name: "euroc: a word for the timestamp",
            files: &[GT, ("est.csv", T("abc,0,0,0,1,0,0,0\n"))],
            args: ATE_CSV,
            code: 2,
            expect: &[
                "est.csv",
                "line 1: expected a number for `timestamp`, got `abc`",
            ],
        },
        Case {
            name: "euroc: zero quaternion",
            files: &[GT, ("est.csv", T("1000000000,0,0,0,0,0,0,0\n"))],
            args: ATE_CSV,
            code: 2,
            expect: &["est.csv", "line 1: expected a non-zero quaternion"],
        },
        Case {
            name: "euroc: repeated timestamp kept once and reported",
            files: &[
                GT,
                (
                    "est.csv",
                    T(
                        "1000000000,0,0,0,1,0,0,0\n2000000000,1,0,0,1,0,0,0\n2000000000,1,0.1,0,1,0,0,0\n3000000000,1,1,0,1,0,0,0\n4000000000,2,1,0.5,1,0,0,0\n",
                    ),
                ),
            ],
            args: ATE_CSV,
            code: 0,
            expect: &[
                "est.csv: 1 repeated timestamp(s) (first on line 3); kept the later pose of each",
            ],
        },
        Case {
            name: "euroc: a TUM file read as EuRoC",
            files: &[GT],
            args: &["convert", "gt.txt", "out.txt", "--from", "euroc"],
            code: 2,
            expect: &[
                "gt.txt",
                "line 1: expected at least 8 comma-separated columns",
                "got 1",
            ],
        },
        Case {
            name: "kitti: no times file",
            files: &[GT, ("est.kitti", T(KITTI_POSES))],
            args: &["eval", "ate", "gt.txt", "est.kitti"],
            code: 2,
            expect: &[
                "est.kitti",
                "a KITTI trajectory has no timestamps: expected its times file",
            ],
        },
        Case {
            name: "kitti: fewer times than poses",
            files: &[
                GT,
                ("est.kitti", T(KITTI_POSES)),
                ("times.txt", T("1\n2\n3\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &["expected one time per pose: est.kitti has 4 poses, times.txt 3 times"],
        },
        Case {
            name: "kitti: a scaled rotation",
            files: &[
                GT,
                ("est.kitti", T("1.01 0 0 0 0 1 0 0 0 0 1 0\n")),
                ("times.txt", T("1\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &[
                "est.kitti",
                "line 1: expected a rotation matrix in `r11 … r33`, got one 2.01e-2 away from orthonormal",
            ],
        },
        Case {
            name: "kitti: a reflection",
            files: &[
                GT,
                ("est.kitti", T("-1 0 0 0 0 1 0 0 0 0 1 0\n")),
                ("times.txt", T("1\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &[
                "est.kitti",
                "line 1: expected a rotation matrix in `r11 … r33`, got one 2.00e0 away from orthonormal",
            ],
        },
        Case {
            name: "kitti: 11 values",
            files: &[
                GT,
                (
                    "est.kitti",
                    T("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n"),
                ),
                ("times.txt", T("1\n2\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &[
                "est.kitti",
                "line 2: expected 12 space-separated values `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz` (KITTI), got 11",
            ],
        },
        Case {
            name: "kitti: nan in the rotation",
            files: &[
                GT,
                (
                    "est.kitti",
                    T("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 nan 0 0 0 0 1 0\n"),
                ),
                ("times.txt", T("1\n2\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &[
                "est.kitti",
                "line 2: expected a finite number for `r22`, got `nan`",
            ],
        },
        Case {
            name: "kitti: unsorted times",
            files: &[
                GT,
                ("est.kitti", T(KITTI_POSES)),
                ("times.txt", T("1\n3\n2\n4\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &[
                "est.kitti",
                "line 3: expected increasing timestamps, got 2 after 3",
            ],
        },
        Case {
            name: "kitti: nan time",
            files: &[
                GT,
                ("est.kitti", T(KITTI_POSES)),
                ("times.txt", T("1\nnan\n3\n4\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &[
                "times.txt",
                "line 2: expected a finite number for `timestamp`, got `nan`",
            ],
        },
        Case {
            name: "kitti: two values on a times line",
            files: &[
                GT,
                ("est.kitti", T(KITTI_POSES)),
                ("times.txt", T("1 2\n2\n3\n4\n")),
            ],
            args: ATE_KITTI,
            code: 2,
            expect: &[
                "times.txt",
                "line 1: expected one timestamp in seconds per line, got 2",
            ],
        },
        Case {
            name: "kitti: repeated time kept once and reported",
            files: &[
                GT,
                (
                    "est.kitti",
                    T(
                        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0.1 0 0 1 0\n1 0 0 1 0 1 0 1 0 0 1 0\n1 0 0 2 0 1 0 1 0 0 1 0.5\n",
                    ),
                ),
                ("times.txt", T("1\n2\n2\n3\n4\n")),
            ],
            args: ATE_KITTI,
            code: 0,
            expect: &[
                "est.kitti: 1 repeated timestamp(s) (first on line 3); kept the later pose of each",
            ],
        },
        Case {
            name: "kitti: no poses",
            files: &[("in.kitti", T("# nothing\n")), ("times.txt", T(""))],
            args: &[
                "convert",
                "in.kitti",
                "out.txt",
                "--from",
                "kitti",
                "--times",
                "times.txt",
            ],
            code: 2,
            expect: &["in.kitti", "expected at least one pose line, got none"],
        },
        Case {
            name: "convert: kitti input without times",
            files: &[("in.kitti", T(KITTI_POSES))],
            args: &["convert", "in.kitti", "out.txt"],
            code: 2,
            expect: &["in.kitti", "expected its times file"],
        },
        Case {
            name: "convert: never over an existing file",
            files: &[GT, ("out.txt", T("keep me\n"))],
            args: &["convert", "gt.txt", "out.txt"],
            code: 2,
            expect: &["out.txt exists; give --force to replace it"],
        },
        Case {
            name: "eval: no timestamps in common",
            files: &[GT, ("est.txt", T("10.0 0 0 0 0 0 0 1\n11 0 0 0 0 0 0 1\n"))],
            args: ATE,
            code: 1,
            expect: &[
                "comparing est.txt with gt.txt",
                "expected matching timestamps within 0.01 s (offset 0 s), got none between trajectories of 4 and 2 poses",
            ],
        },
        Case {
            name: "eval: one pose cannot be aligned",
            files: &[GT, ("est.txt", T("1.0 0 0 0 0 0 0 1\n"))],
            args: ATE,
            code: 1,
            expect: &[
                "comparing est.txt with gt.txt",
                "Umeyama alignment: the point covariance has rank < 2",
            ],
        },
        Case {
            name: "rpe: delta beyond the trajectory",
            files: &[GT, ("est.txt", GT.1)],
            args: &["eval", "rpe", "gt.txt", "est.txt", "--delta", "100"],
            code: 1,
            expect: &[
                "comparing est.txt with gt.txt",
                "RPE delta 100 frames leaves no pair among 4 poses",
            ],
        },
        Case {
            name: "eval: --plot names a file",
            files: &[GT, ("est.txt", GT.1)],
            args: &["eval", "ate", "gt.txt", "est.txt", "--plot", "gt.txt"],
            code: 2,
            expect: &["creating the plot folder gt.txt: File exists"],
        },
        Case {
            name: "eval: --max-diff NaN",
            files: &[GT, ("est.txt", GT.1)],
            args: &["eval", "ate", "gt.txt", "est.txt", "--max-diff", "nan"],
            code: 2,
            expect: &["--max-diff NaN: expected a finite, non-negative time in seconds"],
        },
        Case {
            name: "rpe: a negative distance",
            files: &[GT, ("est.txt", GT.1)],
            args: &[
                "eval",
                "rpe",
                "gt.txt",
                "est.txt",
                "--delta-unit",
                "m",
                "--delta=-1",
            ],
            code: 2,
            expect: &["--delta -1 with --delta-unit m: expected a finite distance above 0 metres"],
        },
        Case {
            name: "rpe: half a frame",
            files: &[GT, ("est.txt", GT.1)],
            args: &["eval", "rpe", "gt.txt", "est.txt", "--delta", "0.5"],
            code: 2,
            expect: &[
                "--delta 0.5 with --delta-unit f: expected a whole number of frames of at least 1",
            ],
        },
        Case {
            name: "rpe: a unit that is none",
            files: &[GT, ("est.txt", GT.1)],
            args: &["eval", "rpe", "gt.txt", "est.txt", "--delta-unit", "s"],
            code: 2,
            expect: &["--delta-unit", "invalid value 's'"],
        },
    ];
    check_all("trajectories", &cases);
}

// ---------------------------------------------------------------------------------------------
// Configs: the shared `[run]` table, the command line around it, and every task's own tables.

const PLANAR: &str = "{root}/configs/planar.toml";
const FIT: &str = "{root}/configs/trajectory_fit.toml";
const NERF: &str = "{root}/configs/nerf_synthetic.toml";
const EVENTS: &str = "{root}/configs/events_interp.toml";
const ROOM: &str = "{root}/configs/synthetic_room.toml";
const IMU: &str = "{root}/configs/synthetic_imu.toml";
const SYNTH: &str = "{root}/configs/synth_room.toml";

#[test]
fn run_table_and_command_line() {
    let x = |text: &'static str| ("x.toml", T(text));
    let run_x: &[&str] = &["run", "x.toml"];
    let cases = [
        Case {
            name: "config: missing file",
            files: &[],
            args: &["run", "nope.toml"],
            code: 2,
            expect: &["cannot read config nope.toml: No such file or directory"],
        },
        Case {
            name: "config: a folder",
            files: &[("adir", D)],
            args: &["run", "adir"],
            code: 2,
            expect: &["cannot read config adir: Is a directory"],
        },
        Case {
            name: "config: truncated table header",
            files: &[x("task = \"planar\"\n[run\nseed = 1\n")],
            args: run_x,
            code: 2,
            expect: &["x.toml: TOML parse error at line 2"],
        },
        Case {
            name: "config: no task",
            files: &[x("[run]\nseed = 1\n")],
            args: run_x,
            code: 2,
            expect: &["x.toml", "missing field `task`"],
        },
        Case {
            name: "config: unknown task",
            files: &[x("# a comment\ntask = \"slam.trak\"\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml:2:8: unknown task \"slam.trak\"; known tasks: events, nerf, planar, slam, slam_imu, synth_room, trajectory",
            ],
        },
        Case {
            name: "config: task is a number",
            files: &[x("task = 3\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml: TOML parse error at line 1, column 8",
                "invalid type: integer `3`, expected a string",
            ],
        },
        Case {
            name: "run: typo",
            files: &[x("task = \"planar\"\n[run]\nthreds = 4\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml: TOML parse error at line 3, column 1",
                "3 | threds = 4",
                "unknown field `threds`, expected one of `seed`, `threads`, `out_dir`, `iterations_scale`, `report_every`, `checkpoint_secs`",
            ],
        },
        Case {
            name: "run: threads = 0",
            files: &[x("task = \"planar\"\n[run]\nthreads = 0\n")],
            args: run_x,
            code: 2,
            expect: &["x.toml:3:11: [run.threads]: threads = 0 must lie in 1..=1024"],
        },
        Case {
            name: "run: threads = 100000",
            files: &[x("task = \"planar\"\n[run]\nthreads = 100000\n")],
            args: run_x,
            code: 2,
            expect: &["x.toml:3:11: [run.threads]: threads = 100000 must lie in 1..=1024"],
        },
        Case {
            name: "run: iterations_scale = -1",
            files: &[x("task = \"planar\"\n[run]\niterations_scale = -1.0\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml:3:20: [run.iterations_scale]: iterations_scale = -1 must be a number in (0, 100]",
            ],
        },
        Case {
            name: "run: iterations_scale = nan",
            files: &[x("task = \"planar\"\n[run]\niterations_scale = nan\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml:3:20: [run.iterations_scale]: iterations_scale = NaN must be a number in (0, 100]",
            ],
        },
        Case {
            name: "run: iterations_scale = 1e9",
            files: &[x("task = \"planar\"\n[run]\niterations_scale = 1e9\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml:3:20: [run.iterations_scale]: iterations_scale = 1000000000 must be a number in (0, 100]",
            ],
        },
        Case {
            name: "run: negative seed",
            files: &[x("task = \"planar\"\n[run]\nseed = -1\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml: TOML parse error at line 3, column 8",
                "invalid value: integer `-1`, expected u64",
            ],
        },
        Case {
            name: "run: seed is a string",
            files: &[x("task = \"planar\"\n[run]\nseed = \"x\"\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml: TOML parse error at line 3, column 8",
                "invalid type: string \"x\", expected u64",
            ],
        },
        Case {
            name: "run: report_every = 0",
            files: &[x("task = \"planar\"\n[run]\nreport_every = 0\n")],
            args: run_x,
            code: 2,
            expect: &["x.toml:3:16: [run.report_every]: report_every must be at least 1"],
        },
        Case {
            name: "run: checkpoint_secs = inf",
            files: &[x("task = \"planar\"\n[run]\ncheckpoint_secs = inf\n")],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml:3:19: [run.checkpoint_secs]: checkpoint_secs = inf must be a finite number ≥ 0",
            ],
        },
        Case {
            name: "run: out_dir leaves the working folder",
            files: &[x("task = \"planar\"\n")],
            args: &["run", "x.toml", "--set", "run.out_dir=\"../x\""],
            code: 2,
            expect: &[
                "[run] out_dir must stay below the working folder (no absolute path, no `..`), got ../x; pass --out to write elsewhere",
            ],
        },
        Case {
            name: "run: absolute out_dir",
            files: &[x("task = \"planar\"\n")],
            args: &["run", "x.toml", "--set", "run.out_dir=\"{dir}/abs\""],
            code: 2,
            expect: &[
                "[run] out_dir must stay below the working folder (no absolute path",
                "/abs; pass --out to write elsewhere",
            ],
        },
        Case {
            name: "override: no value",
            files: &[],
            args: &["run", PLANAR, "--set", "run.seed"],
            code: 2,
            expect: &["invalid override \"run.seed\": expected key.path=value"],
        },
        Case {
            name: "override: typo",
            files: &[],
            args: &["run", PLANAR, "--set", "run.sede=3"],
            code: 2,
            expect: &[
                "planar.toml: TOML parse error",
                "sede = 3",
                "unknown field `sede`",
            ],
        },
        Case {
            name: "override: a table replaced by a number",
            files: &[],
            args: &["run", PLANAR, "--set", "run=3"],
            code: 2,
            expect: &["invalid override \"run=3\": \"run\" is a table; set its keys one by one"],
        },
        Case {
            name: "out: --force never clears a folder without a run",
            files: &[("mine/notes.txt", T("mine\n"))],
            args: &["run", FIT, "--out", "mine", "--force"],
            code: 2,
            expect: &[
                "not a run folder (no provenance.json or config.toml), so --force does not clear it; choose another --out: mine",
            ],
        },
        Case {
            name: "out: a non-empty folder without --force",
            files: &[("mine/notes.txt", T("mine\n"))],
            args: &["run", FIT, "--out", "mine"],
            code: 2,
            expect: &[
                "run folder is not empty (pass --force to replace the earlier run in it): mine",
            ],
        },
        Case {
            name: "resume: a folder without a run",
            files: &[("mine/notes.txt", T("mine\n"))],
            args: &["run", "--resume", "mine"],
            code: 2,
            expect: &["--resume mine: not a run folder (no config.toml in it)"],
        },
        Case {
            name: "variables: unset environment variable",
            files: &[x(
                "task = \"trajectory\"\n[data]\nsource = \"tum\"\npath = \"${CPOSE_SURELY_UNSET_VARIABLE}/gt.txt\"\n",
            )],
            args: run_x,
            code: 2,
            expect: &[
                "x.toml",
                "data.path: ",
                "no environment variable CPOSE_SURELY_UNSET_VARIABLE",
            ],
        },
        Case {
            name: "variables: unclosed",
            files: &[x(
                "task = \"trajectory\"\n[data]\nsource = \"tum\"\npath = \"${DATA/gt.txt\"\n",
            )],
            args: run_x,
            code: 2,
            expect: &["x.toml", "data.path: expected ${NAME}"],
        },
        Case {
            name: "table: truncated metrics.json",
            files: &[("tb/metrics.json", T("{\"a\": {\"m\": {\"x\": 1"))],
            args: &["table", "tb"],
            code: 2,
            expect: &["tb/metrics.json is not valid JSON: EOF while parsing"],
        },
        Case {
            name: "table: a folder without metrics.json",
            files: &[("tb", D)],
            args: &["table", "tb"],
            code: 2,
            expect: &[
                "cannot read tb/metrics.json (a run folder holds one when its run finished): No such file or directory",
            ],
        },
        Case {
            name: "table: a file for a run folder",
            files: &[("tb", T("{}"))],
            args: &["table", "tb"],
            code: 2,
            expect: &[
                "cannot read tb/metrics.json (a run folder holds one when its run finished): Not a directory",
            ],
        },
        Case {
            name: "table: metrics.json holds an array",
            files: &[("tb/metrics.json", T("[1, 2]"))],
            args: &["table", "tb"],
            code: 2,
            expect: &["tb/metrics.json holds no metrics: expected a JSON object with numbers"],
        },
        Case {
            name: "table: an unknown metric",
            files: &[("tb/metrics.json", T("{\"a\": {\"m\": {\"x\": 1.5}}}"))],
            args: &["table", "tb", "--metrics", "nope"],
            code: 2,
            expect: &["no run has the metric \"nope\" (metrics: x)"],
        },
    ];
    check_all("run", &cases);
}

#[test]
fn task_configs() {
    let cases = [
        // planar
        Case {
            name: "planar: typo in [image]",
            files: &[],
            args: &["run", PLANAR, "--set", "image.scal=0.5"],
            code: 2,
            expect: &[
                "planar.toml: TOML parse error",
                "scal = 0.5",
                "unknown field `scal`, expected one of `path`, `procedural_size`, `scale`, `crop_px`",
            ],
        },
        Case {
            name: "planar: scale = -1",
            files: &[],
            args: &["run", PLANAR, "--set", "image.scale=-1"],
            code: 2,
            expect: &["planar.toml", "[image] scale must be in (0, 1], got -1"],
        },
        Case {
            name: "planar: scale = nan",
            files: &[],
            args: &["run", PLANAR, "--set", "image.scale=nan"],
            code: 2,
            expect: &["planar.toml", "[image] scale must be in (0, 1], got NaN"],
        },
        Case {
            name: "planar: crop_px = 1000000",
            files: &[],
            args: &["run", PLANAR, "--set", "image.crop_px=1000000"],
            code: 1,
            expect: &[
                "planar.toml",
                "[image] crop_px = 1000000 does not fit the 480×360 image at scale 0.5",
            ],
        },
        Case {
            name: "planar: procedural_size = [0, 0]",
            files: &[],
            args: &["run", PLANAR, "--set", "image.procedural_size=[0,0]"],
            code: 2,
            expect: &[
                "planar.toml",
                "[image] procedural_size 0×0: each side must lie in 8..=8192",
            ],
        },
        Case {
            name: "planar: unknown warp",
            files: &[],
            args: &["run", PLANAR, "--set", "motion.warp=\"affine\""],
            code: 2,
            expect: &[
                "planar.toml: TOML parse error",
                "unknown variant `affine`, expected `se2` or `homography`",
            ],
        },
        Case {
            name: "planar: one control point",
            files: &[],
            args: &["run", PLANAR, "--set", "motion.control_points=1"],
            code: 2,
            expect: &[
                "planar.toml",
                "[motion] control_points must be at least 4 (a cubic spline), got 1",
            ],
        },
        Case {
            name: "planar: rotation_deg = nan",
            files: &[],
            args: &["run", PLANAR, "--set", "motion.rotation_deg=nan"],
            code: 2,
            expect: &[
                "planar.toml",
                "[motion] rotation_deg must be finite and ≥ 0, got NaN",
            ],
        },
        Case {
            name: "planar: translation = inf",
            files: &[],
            args: &["run", PLANAR, "--set", "motion.translation=inf"],
            code: 2,
            expect: &[
                "planar.toml",
                "[motion] translation must be finite and ≥ 0, got inf",
            ],
        },
        Case {
            name: "planar: unknown method",
            files: &[],
            args: &["run", PLANAR, "--set", "train.methods=[\"nope\"]"],
            code: 2,
            expect: &[
                "planar.toml: TOML parse error",
                "unknown variant `nope`, expected one of `posenet`, `barf`, `spline`",
            ],
        },
        Case {
            name: "planar: iterations = 1e12",
            files: &[],
            args: &["run", PLANAR, "--set", "train.iterations=1e12"],
            code: 2,
            expect: &[
                "planar.toml: TOML parse error",
                "invalid type: floating point `1000000000000.0`, expected usize",
            ],
        },
        Case {
            name: "planar: lr_rotation = nan",
            files: &[],
            args: &["run", PLANAR, "--set", "train.lr_rotation=nan"],
            code: 2,
            expect: &[
                "planar.toml",
                "[train] lr_rotation must be finite and ≥ 0, got NaN",
            ],
        },
        Case {
            name: "planar: spline_reset_every = 0",
            files: &[],
            args: &["run", PLANAR, "--set", "train.spline_reset_every=0"],
            code: 2,
            expect: &[
                "planar.toml",
                "[train] spline reset: reset_every must be ≥ 1",
            ],
        },
        Case {
            name: "planar: unknown field kind",
            files: &[],
            args: &["run", PLANAR, "--set", "field.kind=\"nope\""],
            code: 2,
            expect: &[
                "planar.toml:",
                "unknown neural image kind \"nope\"; known kinds: grid, mlp",
            ],
        },
        Case {
            name: "planar: typo in [field]",
            files: &[],
            args: &["run", PLANAR, "--set", "field.widht=3"],
            code: 2,
            expect: &[
                "planar.toml: TOML parse error",
                "widht = 3",
                "unknown field `widht`, expected one of `levels`",
            ],
        },
        // trajectory
        Case {
            name: "trajectory: duration_secs = 1e12",
            files: &[],
            args: &["run", FIT, "--set", "data.duration_secs=1e12"],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "[data] duration_secs × the larger of pose_rate_hz and imu_rate_hz is 2.000e14 samples; at most 10000000 are generated",
            ],
        },
        Case {
            name: "trajectory: pose_rate_hz = nan",
            files: &[],
            args: &["run", FIT, "--set", "data.pose_rate_hz=nan"],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "pose_rate_hz = NaN and imu_rate_hz = 200 must be positive finite numbers",
            ],
        },
        Case {
            name: "trajectory: known_every = 0",
            files: &[],
            args: &["run", FIT, "--set", "data.known_every=0"],
            code: 1,
            expect: &[
                "trajectory_fit.toml",
                "[data] known_every must be at least 1",
            ],
        },
        Case {
            name: "trajectory: known_every = 100000",
            files: &[],
            args: &["run", FIT, "--set", "data.known_every=100000"],
            code: 1,
            expect: &[
                "trajectory_fit.toml",
                "the cropped trajectory has 1 poses and 1 known ones; at least 4 known poses are needed",
            ],
        },
        Case {
            name: "trajectory: unknown source",
            files: &[],
            args: &["run", FIT, "--set", "data.source=\"vicon\""],
            code: 2,
            expect: &[
                "trajectory_fit.toml: TOML parse error",
                "unknown variant `vicon`, expected one of `synthetic`, `tum`, `euroc`",
            ],
        },
        Case {
            name: "trajectory: typo in [data]",
            files: &[],
            args: &["run", FIT, "--set", "data.sorce=1"],
            code: 2,
            expect: &[
                "trajectory_fit.toml: TOML parse error",
                "unknown field `sorce`, expected one of `source`, `path`",
            ],
        },
        Case {
            name: "trajectory: tum source without a path",
            files: &[],
            args: &["run", FIT, "--set", "data.source=\"tum\""],
            code: 1,
            expect: &["trajectory_fit.toml", "[data] source = Tum needs a `path`"],
        },
        Case {
            name: "trajectory: tolerance_deg = nan",
            files: &[],
            args: &["run", FIT, "--set", "fit.tolerance_deg=nan"],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "[fit] tolerance_deg = NaN must be a number ≥ 0",
            ],
        },
        Case {
            name: "trajectory: lr_translation = inf",
            files: &[],
            args: &["run", FIT, "--set", "fit.lr_translation=inf"],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "[fit] lr_translation = inf must be a positive number",
            ],
        },
        Case {
            name: "trajectory: unknown imu mode",
            files: &[],
            args: &["run", FIT, "--set", "fit.imu=[\"magic\"]"],
            code: 2,
            expect: &[
                "trajectory_fit.toml: TOML parse error",
                "unknown variant `magic`, expected one of `none`, `loose`, `tight`, `accel`, `combined`",
            ],
        },
        Case {
            name: "trajectory: fit.fields names no table",
            files: &[],
            args: &["run", FIT, "--set", "fit.fields=[\"nope\"]"],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "[fit] fields names \"nope\", which has no [fields.nope] table (tables: lie_spline, posenet, spline)",
            ],
        },
        Case {
            name: "trajectory: lr_factor = 2",
            files: &[],
            args: &["run", FIT, "--set", "fit.lr_factor=2"],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "[fit] lr_factor = 2 must lie in (0, 1)",
            ],
        },
        Case {
            name: "trajectory: loose window of -1 s",
            files: &[],
            args: &[
                "run",
                FIT,
                "--set",
                "fit.imu=[\"loose\"]",
                "--set",
                "fit.loose_window_secs=-1",
            ],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "[fit] loose_window_secs = -1 must be a positive number",
            ],
        },
        Case {
            name: "trajectory: unknown pose field",
            files: &[],
            args: &["run", FIT, "--set", "fields.posenet.kind=\"nope\""],
            code: 2,
            expect: &[
                "trajectory_fit.toml:",
                "unknown pose field \"nope\"; known pose fields: composed, discrete, lie_spline, posenet, spline",
            ],
        },
        Case {
            name: "trajectory: typo in a pose field",
            files: &[],
            args: &["run", FIT, "--set", "fields.posenet.widht=3"],
            code: 2,
            expect: &[
                "trajectory_fit.toml: TOML parse error",
                "widht = 3",
                "unknown field `widht`, expected one of `bands`, `depth`, `width`",
            ],
        },
        Case {
            name: "trajectory: knot spacing 0",
            files: &[],
            args: &[
                "run",
                FIT,
                "--set",
                "fit.fields=[\"spline\"]",
                "--set",
                "fields.spline.knot_spacing_secs=0",
            ],
            code: 2,
            expect: &[
                "trajectory_fit.toml:",
                "[fields.spline]: invalid pose field: knot spacing must be positive and finite, got 0 s",
            ],
        },
        Case {
            name: "trajectory: a field named like the reference",
            files: &[],
            args: &["run", FIT, "--set", "fields.interp.kind=\"spline\""],
            code: 2,
            expect: &[
                "trajectory_fit.toml",
                "[fields.interp] is the name of the interpolation reference; call the field otherwise",
            ],
        },
        Case {
            name: "trajectory: no [fields] at all",
            files: &[(
                "x.toml",
                T("task = \"trajectory\"\n[data]\nsource = \"synthetic\"\n"),
            )],
            args: &["run", "x.toml"],
            code: 2,
            expect: &["x.toml", "missing field `fields`"],
        },
        Case {
            name: "trajectory: tum file with nan",
            files: &[("gt.txt", T("1 0 0 0 0 0 0 1\n2 0 0 nan 0 0 0 1\n"))],
            args: &[
                "run",
                FIT,
                "--set",
                "data.source=\"tum\"",
                "--set",
                "data.path=\"gt.txt\"",
            ],
            code: 1,
            expect: &[
                "gt.txt",
                "line 2: expected a finite number for `tz`, got `nan`",
            ],
        },
        Case {
            name: "trajectory: tum file without IMU for imu = tight",
            files: &[(
                "gt.txt",
                T("1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n3 1 1 0 0 0 0 1\n4 2 1 0 0 0 0 1\n"),
            )],
            args: &[
                "run",
                FIT,
                "--set",
                "data.source=\"tum\"",
                "--set",
                "data.path=\"gt.txt\"",
                "--set",
                "data.known_every=1",
            ],
            code: 1,
            expect: &[
                "trajectory_fit.toml",
                "[fit] imu = [None, Tight] needs IMU data, but source Tum has none; use imu = [\"none\"]",
            ],
        },
        // nerf
        Case {
            name: "nerf: width = 1000000",
            files: &[],
            args: &["run", NERF, "--set", "data.width=1000000"],
            code: 1,
            expect: &[
                "[data]: 110 views of width × height = 1000000 × 100 are 1.100e10 pixels; at most 100000000 are rendered",
            ],
        },
        Case {
            name: "nerf: rays_per_step = 0",
            files: &[],
            args: &["run", NERF, "--set", "train.rays_per_step=0"],
            code: 2,
            expect: &["[train] rays_per_step = 0: expected at least 1"],
        },
        Case {
            name: "nerf: a NaN rate of a method that does not run",
            files: &[],
            args: &["run", NERF, "--set", "train.lr_pose=[nan, 1e-5]"],
            code: 2,
            expect: &["[train] lr_pose = [NaN, 0.00001]: expected a start rate above 0"],
        },
        Case {
            name: "nerf: an infinite field rate",
            files: &[],
            args: &["run", NERF, "--set", "train.lr_field.grid=[1e-2, inf]"],
            code: 2,
            expect: &["[train] lr_field.grid = [0.01, inf]: expected a start rate above 0"],
        },
        Case {
            name: "events: a negative PoseNet rate",
            files: &[],
            args: &[
                "run",
                EVENTS,
                "--set",
                "train.posenet_lr_rotation=[-1, 1e-5]",
            ],
            code: 2,
            expect: &["[train] posenet_lr_rotation = [-1, 0.00001]: expected a start rate above 0"],
        },
        Case {
            name: "nerf: fov_x_deg = 180",
            files: &[],
            args: &["run", NERF, "--set", "data.fov_x_deg=180"],
            code: 1,
            expect: &["[data]: need width, height ≥ 1 and 0 < fov_x_deg < 180"],
        },
        Case {
            name: "nerf: unknown source",
            files: &[],
            args: &["run", NERF, "--set", "data.source=\"kitti\""],
            code: 2,
            expect: &[
                "nerf_synthetic.toml: TOML parse error",
                "unknown variant `kitti`, expected one of `synthetic`, `llff`, `blender`, `colmap`, `nerfstudio`",
            ],
        },
        Case {
            name: "nerf: typo in [data]",
            files: &[],
            args: &["run", NERF, "--set", "data.widht=3"],
            code: 2,
            expect: &[
                "nerf_synthetic.toml: TOML parse error",
                "unknown field `widht`, expected one of `source`, `path`",
            ],
        },
        Case {
            name: "nerf: llff without a path",
            files: &[],
            args: &["run", NERF, "--set", "data.source=\"llff\""],
            code: 1,
            expect: &["[data] path: the LLFF scene folder is required for source = \"llff\""],
        },
        Case {
            name: "nerf: llff folder that does not exist",
            files: &[],
            args: &[
                "run",
                NERF,
                "--set",
                "data.source=\"llff\"",
                "--set",
                "data.path=\"nowhere\"",
            ],
            code: 1,
            expect: &[
                "no LLFF scene at nowhere",
                "nerf_llff_data",
                "Set data.path to it",
            ],
        },
        Case {
            name: "nerf: colmap image without its photo",
            files: &[
                ("sparse/0/cameras.txt", T(COLMAP_CAMERAS)),
                ("sparse/0/images.txt", T(COLMAP_IMAGES)),
                ("sparse/0/points3D.txt", T(COLMAP_POINTS)),
                ("images/a.png", B(rgb_12x10)),
                ("images/b.png", B(rgb_12x10)),
            ],
            args: &[
                "run",
                NERF,
                "--set",
                "data.source=\"colmap\"",
                "--set",
                "data.path=\".\"",
            ],
            code: 1,
            expect: &[
                "images/c.png",
                "the photo of a registered image",
                "no such file",
            ],
        },
        Case {
            name: "nerf: colmap image name twice",
            files: &[
                ("sparse/0/cameras.txt", T(COLMAP_CAMERAS)),
                (
                    "sparse/0/images.txt",
                    T("1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0.1 0 0 1 a.png\n\n"),
                ),
                ("sparse/0/points3D.txt", T(COLMAP_POINTS)),
                ("images/a.png", B(rgb_12x10)),
            ],
            args: &[
                "run",
                NERF,
                "--set",
                "data.source=\"colmap\"",
                "--set",
                "data.path=\".\"",
            ],
            code: 1,
            expect: &[
                "sparse/0/images.txt",
                "each image name once",
                "a.png for images 1 and 2",
            ],
        },
        Case {
            name: "nerf: colmap without images.txt",
            files: &[
                ("sparse/0/cameras.txt", T(COLMAP_CAMERAS)),
                ("sparse/0/points3D.txt", T(COLMAP_POINTS)),
            ],
            args: &[
                "run",
                NERF,
                "--set",
                "data.source=\"colmap\"",
                "--set",
                "data.path=\".\"",
            ],
            code: 1,
            expect: &["sparse/0", "an images.bin or images.txt"],
        },
        Case {
            name: "nerf: colmap without a model",
            files: &[("images/a.png", B(rgb_12x10))],
            args: &[
                "run",
                NERF,
                "--set",
                "data.source=\"colmap\"",
                "--set",
                "data.path=\".\"",
            ],
            code: 1,
            expect: &["a COLMAP reconstruction: sparse/0/ or sparse/"],
        },
        Case {
            name: "nerf: nerfstudio fisheye",
            files: &[("transforms.json", T(NERFSTUDIO_FISHEYE))],
            args: &[
                "run",
                NERF,
                "--set",
                "data.source=\"nerfstudio\"",
                "--set",
                "data.path=\".\"",
            ],
            code: 1,
            expect: &[
                "transforms.json",
                "camera_model PINHOLE, SIMPLE_PINHOLE or OPENCV",
            ],
        },
        Case {
            name: "nerf: nerfstudio without frames",
            files: &[("transforms.json", T("{\"fl_x\": 10, \"frames\": []}"))],
            args: &[
                "run",
                NERF,
                "--set",
                "data.source=\"nerfstudio\"",
                "--set",
                "data.path=\".\"",
            ],
            code: 1,
            expect: &["transforms.json", "a non-empty list `frames`"],
        },
        Case {
            name: "nerf: no frames",
            files: &[],
            args: &["run", NERF, "--set", "orbit.frames=0"],
            code: 2,
            expect: &["orbit.frames: expected 2 to 100000, got 0"],
        },
        Case {
            name: "nerf: unknown noise",
            files: &[],
            args: &[
                "run",
                NERF,
                "--set",
                "data.width=12",
                "--set",
                "data.height=12",
                "--set",
                "noise.kind=\"gaussian\"",
            ],
            code: 2,
            expect: &[
                "nerf_synthetic.toml: TOML parse error",
                "unknown variant `gaussian`, expected one of `time_correlated`, `iid`, `identity`, `none`",
            ],
        },
        Case {
            name: "nerf: max_rotation_deg = nan",
            files: &[],
            args: &[
                "run",
                NERF,
                "--set",
                "data.width=12",
                "--set",
                "data.height=12",
                "--set",
                "noise.max_rotation_deg=nan",
            ],
            code: 2,
            expect: &["noise.max_rotation_deg: expected a value in [0, 180], got NaN"],
        },
        Case {
            name: "nerf: no samples",
            files: &[],
            args: &[
                "run",
                NERF,
                "--set",
                "data.width=12",
                "--set",
                "data.height=12",
                "--set",
                "render.samples=0",
            ],
            code: 1,
            expect: &["[render] samples: expected at least 1"],
        },
        Case {
            name: "nerf: unknown sampling",
            files: &[],
            args: &[
                "run",
                NERF,
                "--set",
                "data.width=12",
                "--set",
                "data.height=12",
                "--set",
                "render.sampling=\"log\"",
            ],
            code: 1,
            expect: &[
                "[render] sampling: expected \"metric\" (finite far) or \"inverse\", got \"log\"",
            ],
        },
        Case {
            name: "nerf: iterations = 1.5",
            files: &[],
            args: &["run", NERF, "--set", "train.iterations=1.5"],
            code: 2,
            expect: &[
                "nerf_synthetic.toml: TOML parse error",
                "invalid type: floating point `1.5`, expected usize",
            ],
        },
        Case {
            name: "nerf: pose_warmup = 2",
            files: &[],
            args: &[
                "run",
                NERF,
                "--set",
                "data.width=12",
                "--set",
                "data.height=12",
                "--set",
                "train.pose_warmup=2",
            ],
            code: 2,
            expect: &["[train] pose_warmup = 2 must lie in [0, 1] (a fraction of the steps)"],
        },
        Case {
            name: "nerf: PoseNet translation_scale = -1",
            files: &[],
            args: &[
                "run",
                NERF,
                "--set",
                "data.width=12",
                "--set",
                "data.height=12",
                "--set",
                "posenet.translation_scale=-1",
            ],
            code: 1,
            expect: &["invalid pose field: translation_scale = -1 must be positive"],
        },
        Case {
            name: "nerf: typo in [eval]",
            files: &[],
            args: &["run", NERF, "--set", "eval.foo=1"],
            code: 2,
            expect: &[
                "nerf_synthetic.toml: TOML parse error",
                "unknown field `foo`, expected one of `refine_iterations`, `refine_rays`, `saved_views`",
            ],
        },
        // events
        Case {
            name: "events: width = 1000000",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.width=1000000"],
            code: 2,
            expect: &["[simulation]: camera.width: expected 1 to 65535 pixels, got 1000000"],
        },
        Case {
            name: "events: duration_secs = -1",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.duration_secs=-1"],
            code: 2,
            expect: &[
                "[simulation]: turntable.duration_secs: expected a value in (0, 1e6] seconds, got -1",
            ],
        },
        Case {
            name: "events: duration_secs = 1e12",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.duration_secs=1e12"],
            code: 2,
            expect: &[
                "[simulation]: turntable.duration_secs: expected a value in (0, 1e6] seconds, got 1000000000000",
            ],
        },
        Case {
            name: "events: radius = nan",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.radius=nan"],
            code: 2,
            expect: &["[simulation]: turntable.radius: expected a finite value > 0, got NaN"],
        },
        Case {
            name: "events: render_steps = 0",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.render_steps=0"],
            code: 2,
            expect: &["[simulation]: render_steps: expected at least 1, got 0"],
        },
        Case {
            name: "events: threshold_sigma = -1",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.threshold_sigma=-1"],
            code: 2,
            expect: &[
                "[simulation]: simulator.threshold_sigma: expected a finite value ≥ 0, got -1",
            ],
        },
        Case {
            name: "events: threshold = 0",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.threshold=0"],
            code: 2,
            expect: &["[simulation]: simulator.threshold: expected a finite value > 0, got 0"],
        },
        Case {
            name: "events: typo in [simulation]",
            files: &[],
            args: &["run", EVENTS, "--set", "simulation.widht=3"],
            code: 2,
            expect: &[
                "events_interp.toml: TOML parse error",
                "unknown field `widht`, expected one of `width`, `height`",
            ],
        },
        Case {
            name: "events: unknown experiment",
            files: &[],
            args: &["run", EVENTS, "--set", "experiment.kind=\"calib\""],
            code: 2,
            expect: &[
                "events_interp.toml: TOML parse error",
                "unknown variant `calib`, expected `interpolation` or `calibration`",
            ],
        },
        Case {
            name: "events: one known pose",
            files: &[],
            args: &[
                "run",
                EVENTS,
                "--set",
                "simulation.width=16",
                "--set",
                "simulation.height=12",
                "--set",
                "simulation.render_steps=8",
                "--set",
                "experiment.known_poses=[1]",
            ],
            code: 1,
            expect: &["[experiment] known_poses: need at least 2 known views, got 1"],
        },
        Case {
            name: "events: window lengths reversed",
            files: &[],
            args: &[
                "run",
                EVENTS,
                "--set",
                "simulation.width=16",
                "--set",
                "simulation.height=12",
                "--set",
                "simulation.render_steps=8",
                "--set",
                "train.methods=[\"posenet\"]",
                "--set",
                "train.window=[0.5, 0.1]",
            ],
            code: 1,
            expect: &["[train]: window lengths [5, 1] s: need 0 < min ≤ max < the"],
        },
        Case {
            name: "events: no methods",
            files: &[],
            args: &["run", EVENTS, "--set", "train.methods=[]"],
            code: 2,
            expect: &["[train] methods: no methods to run"],
        },
        Case {
            name: "events: PoseNet with 1000 bands",
            files: &[],
            args: &[
                "run",
                EVENTS,
                "--set",
                "simulation.width=16",
                "--set",
                "simulation.height=12",
                "--set",
                "simulation.render_steps=8",
                "--set",
                "train.methods=[\"posenet\"]",
                "--set",
                "posenet.bands=1000",
            ],
            code: 1,
            expect: &["unit K20_posenet: invalid pose field: bands = 1000 must be in 1..=24"],
        },
        Case {
            name: "events: PoseNet with -1 bands",
            files: &[],
            args: &[
                "run",
                EVENTS,
                "--set",
                "simulation.width=16",
                "--set",
                "simulation.height=12",
                "--set",
                "simulation.render_steps=8",
                "--set",
                "train.methods=[\"posenet\"]",
                "--set",
                "posenet.bands=-1",
            ],
            code: 2,
            expect: &[
                "events_interp.toml: TOML parse error",
                "bands = -1",
                "invalid value: integer `-1`, expected usize",
            ],
        },
        // slam
        Case {
            name: "slam: width = 1000000",
            files: &[],
            args: &[
                "run",
                ROOM,
                "--set",
                "data.path=\"room\"",
                "--set",
                "synthetic.width=1000000",
            ],
            code: 2,
            expect: &["[synthetic]: width = 1000000 must lie in 16..=4096"],
        },
        Case {
            name: "slam: tracking.lr = nan",
            files: &[],
            args: &[
                "run",
                ROOM,
                "--set",
                "data.path=\"room\"",
                "--set",
                "tracking.lr=nan",
            ],
            code: 2,
            expect: &["[tracking] lr = NaN must be a positive number"],
        },
        Case {
            name: "slam: one frame",
            files: &[],
            args: &[
                "run",
                ROOM,
                "--set",
                "data.path=\"room\"",
                "--set",
                "synthetic.frames=1",
            ],
            code: 2,
            expect: &["[synthetic]: frames = 1 must be at least 2"],
        },
        Case {
            name: "slam: frame_rate = nan",
            files: &[],
            args: &[
                "run",
                ROOM,
                "--set",
                "data.path=\"room\"",
                "--set",
                "synthetic.frame_rate=nan",
            ],
            code: 2,
            expect: &["[synthetic]: frame_rate = NaN must be positive"],
        },
        Case {
            name: "slam: unknown source",
            files: &[],
            args: &["run", ROOM, "--set", "data.source=\"kinect\""],
            code: 2,
            expect: &[
                "synthetic_room.toml: TOML parse error",
                "unknown variant `kinect`, expected one of `synthetic`, `replica`, `scannet`, `tum`, `7scenes`",
            ],
        },
        Case {
            name: "slam: no methods",
            files: &[],
            args: &["run", ROOM, "--set", "slam.methods=[]"],
            code: 2,
            expect: &[
                "slam.methods is empty: name at least one of baseline, prev, world, random, intrinsic",
            ],
        },
        Case {
            name: "slam: typo in [slam]",
            files: &[],
            args: &["run", ROOM, "--set", "slam.method=1"],
            code: 2,
            expect: &[
                "synthetic_room.toml: TOML parse error",
                "unknown field `method`, expected `methods`",
            ],
        },
        Case {
            name: "slam: an empty bounding box",
            files: &[],
            args: &[
                "run",
                ROOM,
                "--set",
                "mesh.voxel=0",
                "--set",
                "bounds.box=[[1, 0], [0, 1], [0, 1]]",
            ],
            code: 2,
            expect: &[
                "bounds.box = [[1.0, 0.0], [0.0, 1.0], [0.0, 1.0]]: every axis needs [min, max] with min < max",
            ],
        },
        Case {
            name: "slam: a mesh voxel whose grid would overflow",
            files: &[],
            args: &["run", ROOM, "--set", "mesh.voxel=1e-9"],
            code: 2,
            expect: &["[mesh]", "nodes (at most 134217728): choose a larger voxel"],
        },
        Case {
            name: "slam: a mesh voxel of NaN",
            files: &[],
            args: &["run", ROOM, "--set", "mesh.voxel=nan"],
            code: 2,
            expect: &[
                "[mesh]",
                "mesh voxel size must be a positive number, got NaN",
            ],
        },
        Case {
            name: "slam: a radius without a centre",
            files: &[],
            args: &["run", ROOM, "--set", "bounds.radius=-1"],
            code: 2,
            expect: &[
                "[bounds]: give either box = [[x0, x1], [y0, y1], [z0, z1]] or centre and radius",
            ],
        },
        Case {
            name: "slam: negative tracking iterations",
            files: &[],
            args: &["run", ROOM, "--set", "tracking.iterations=-1"],
            code: 2,
            expect: &[
                "synthetic_room.toml: TOML parse error",
                "invalid value: integer `-1`, expected usize",
            ],
        },
        Case {
            name: "slam: data.path is a file",
            files: &[("room.txt", T("not a folder\n"))],
            args: &[
                "run",
                ROOM,
                "--set",
                "data.path=\"room.txt\"",
                "--set",
                "synthetic.width=48",
                "--set",
                "synthetic.frames=4",
            ],
            code: 1,
            expect: &["room.txt: expected a folder for the synthetic data, found a file"],
        },
        Case {
            name: "slam: data.path holds someone's files",
            files: &[("mine/notes.txt", T("mine\n"))],
            args: &["run", ROOM, "--set", "data.path=\"mine\""],
            code: 1,
            expect: &[
                "mine is not empty and was not written by the synthetic generator (no synthetic.json)",
            ],
        },
        Case {
            name: "slam: no [data] table",
            files: &[(
                "x.toml",
                T("task = \"slam\"\n[slam]\nmethods = [\"baseline\"]\n"),
            )],
            args: &["run", "x.toml"],
            code: 2,
            expect: &["x.toml", "missing field `data`"],
        },
        // slam_imu
        Case {
            name: "slam_imu: imu_sim.rate_hz = 0",
            files: &[],
            args: &[
                "run",
                IMU,
                "--set",
                "data.path=\"room\"",
                "--set",
                "synthetic.width=48",
                "--set",
                "synthetic.frames=8",
                "--set",
                "imu_sim.rate_hz=0",
            ],
            code: 2,
            expect: &["[imu_sim] rate_hz = 0: expected a rate in (0, 10000] Hz"],
        },
        Case {
            name: "slam_imu: imu_sim.rate_hz = 1e12",
            files: &[],
            args: &["run", IMU, "--set", "imu_sim.rate_hz=1e12"],
            code: 2,
            expect: &["[imu_sim] rate_hz = 1000000000000: expected a rate in (0, 10000] Hz"],
        },
        Case {
            name: "slam_imu: noise = 3",
            files: &[],
            args: &["run", IMU, "--set", "imu_sim.noise=3"],
            code: 2,
            expect: &[
                "synthetic_imu.toml: TOML parse error",
                "invalid type: integer `3`, expected a boolean",
            ],
        },
        Case {
            name: "slam_imu: typo in [imu_sim]",
            files: &[],
            args: &["run", IMU, "--set", "imu_sim.nois=true"],
            code: 2,
            expect: &[
                "synthetic_imu.toml: TOML parse error",
                "unknown field `nois`, expected `rate_hz` or `noise`",
            ],
        },
        Case {
            name: "slam_imu: imu.translation_scale = -1",
            files: &[],
            args: &["run", IMU, "--set", "imu.translation_scale=-1"],
            code: 2,
            expect: &["imu.translation_scale = -1 must be positive"],
        },
        Case {
            name: "slam_imu: unknown method",
            files: &[],
            args: &["run", IMU, "--set", "slam.methods=[\"tigth\"]"],
            code: 2,
            expect: &[
                "unknown method \"tigth\"; known methods: baseline, prev, prev_loose, prev_tight, prev_accel, prev_combined, none, loose, tight, accel, combined",
            ],
        },
        Case {
            name: "trajectory: pose_weight = -1",
            files: &[],
            args: &["run", FIT, "--set", "fit.pose_weight=-1"],
            code: 2,
            expect: &["[fit] pose_weight = -1 must be a number ≥ 0"],
        },
        Case {
            name: "trajectory: gyro_weight = nan",
            files: &[],
            args: &["run", FIT, "--set", "fit.gyro_weight=nan"],
            code: 2,
            expect: &["[fit] gyro_weight = NaN must be a number ≥ 0"],
        },
        Case {
            name: "trajectory: imu_batch = 0",
            files: &[],
            args: &["run", FIT, "--set", "fit.imu_batch=0"],
            code: 2,
            expect: &["[fit] imu_batch = 0 must be at least 1"],
        },
        Case {
            name: "events: scene_radius = -1",
            files: &[],
            args: &["run", EVENTS, "--set", "render.scene_radius=-1"],
            code: 2,
            expect: &["[render] scene_radius = -1: expected a finite radius > 0"],
        },
        Case {
            name: "planar: 100000 patches",
            files: &[],
            args: &["run", PLANAR, "--set", "motion.patches=100000"],
            code: 2,
            expect: &["[motion] patches must lie in 2..=1000, got 100000"],
        },
        Case {
            name: "nerf: a billion frames",
            files: &[],
            args: &["run", NERF, "--set", "orbit.frames=1000000000"],
            code: 2,
            expect: &["orbit.frames: expected 2 to 100000, got 1000000000"],
        },
        Case {
            name: "config check: a bad value",
            files: &[],
            args: &["config", "check", NERF, "--set", "train.rays_per_step=0"],
            code: 2,
            expect: &["[train] rays_per_step = 0: expected at least 1"],
        },
        Case {
            name: "config show: unknown task",
            files: &[],
            args: &["config", "show", "slma"],
            code: 2,
            expect: &["unknown task \"slma\"; known tasks: "],
        },
        Case {
            name: "slam_imu: unknown bias",
            files: &[],
            args: &[
                "run",
                IMU,
                "--set",
                "euroc.path=\"seq\"",
                "--set",
                "euroc.bias=\"magic\"",
            ],
            code: 2,
            expect: &[
                "synthetic_imu.toml: TOML parse error",
                "unknown variant `magic`, expected one of `estimate`, `ground_truth`, `raw`",
            ],
        },
        Case {
            name: "slam_imu: [euroc] without a path",
            files: &[],
            args: &["run", IMU, "--set", "euroc.max_gap_secs=1"],
            code: 2,
            expect: &[
                "synthetic_imu.toml: TOML parse error",
                "missing field `path`",
            ],
        },
        Case {
            name: "slam_imu: keyframe_every = 0",
            files: &[],
            args: &[
                "run",
                IMU,
                "--set",
                "data.path=\"room\"",
                "--set",
                "synthetic.width=48",
                "--set",
                "synthetic.frames=8",
                "--set",
                "mapping.keyframe_every=0",
            ],
            code: 1,
            expect: &["mapping.window must be ≥ 2 and mapping.keyframe_every ≥ 1"],
        },
        // synth_room
        Case {
            name: "synth_room: width = 1000000",
            files: &[],
            args: &[
                "run",
                SYNTH,
                "--set",
                "output.path=\"room\"",
                "--set",
                "synthetic.width=1000000",
            ],
            code: 2,
            expect: &["synth_room.toml: [synthetic]: width = 1000000 must lie in 16..=4096"],
        },
        Case {
            name: "synth_room: depth_noise = \"yes\"",
            files: &[],
            args: &["run", SYNTH, "--set", "synthetic.depth_noise=\"yes\""],
            code: 2,
            expect: &[
                "synth_room.toml: TOML parse error",
                "invalid type: string \"yes\", expected a boolean",
            ],
        },
        Case {
            name: "synth_room: typo in [output]",
            files: &[],
            args: &["run", SYNTH, "--set", "output.pth=1"],
            code: 2,
            expect: &[
                "synth_room.toml: TOML parse error",
                "unknown field `pth`, expected `path`",
            ],
        },
        Case {
            name: "synth_room: output.path is a file",
            files: &[("room.txt", T("not a folder\n"))],
            args: &[
                "run",
                SYNTH,
                "--set",
                "output.path=\"room.txt\"",
                "--set",
                "synthetic.width=48",
                "--set",
                "synthetic.frames=4",
            ],
            code: 1,
            expect: &[
                "writing the synthetic room to room.txt: room.txt: expected a folder for the synthetic data, found a file",
            ],
        },
        Case {
            name: "synth_room: missing trajectory",
            files: &[],
            args: &[
                "run",
                SYNTH,
                "--set",
                "output.path=\"room\"",
                "--set",
                "synthetic.trajectory=\"nope.txt\"",
            ],
            code: 1,
            expect: &["nope.txt: expected a TUM trajectory (t tx ty tz qx qy qz qw per line)"],
        },
        Case {
            name: "synth_room: scale = -1",
            files: &[],
            args: &[
                "run",
                SYNTH,
                "--set",
                "output.path=\"room\"",
                "--set",
                "synthetic.scale=-1",
            ],
            code: 2,
            expect: &["[synthetic]: scale = -1 must lie in [0.1, 10]"],
        },
        Case {
            name: "synth_room: trajectory_offset_s = nan",
            files: &[],
            args: &[
                "run",
                SYNTH,
                "--set",
                "output.path=\"room\"",
                "--set",
                "synthetic.trajectory_offset_s=nan",
            ],
            code: 2,
            expect: &["[synthetic]: trajectory_offset_s = NaN must be ≥ 0"],
        },
    ];
    check_all("configs", &cases);
}

// ---------------------------------------------------------------------------------------------
// Images (PNG, JPEG), LLFF (`poses_bounds.npy`, `images_N/`) and Blender (`transforms_*.json`).

const LLFF_X: (&str, F) = (
    "x.toml",
    T(
        "task = \"nerf\"\n[run]\nthreads = 1\n[data]\nsource = \"llff\"\npath = \"scene\"\n[train]\nmethods = [\"fixed\"]\n",
    ),
);
const BLENDER_X: (&str, F) = (
    "x.toml",
    T(
        "task = \"nerf\"\n[run]\nthreads = 1\n[data]\nsource = \"blender\"\npath = \"scene\"\n[train]\nmethods = [\"fixed\"]\n",
    ),
);
const RUN_X: &[&str] = &["run", "x.toml"];

fn npy_f4() -> Vec<u8> {
    let rows = llff_rows(4, |_| {});
    let data: Vec<u8> = rows
        .iter()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    npy_raw("<f4", "False", "(4, 17)", &data)
}
fn npy_big_endian() -> Vec<u8> {
    npy_raw(">f8", "False", "(4, 17)", &f64_bytes(&llff_rows(4, |_| {})))
}
fn npy_fortran() -> Vec<u8> {
    npy_raw("<f8", "True", "(4, 17)", &f64_bytes(&llff_rows(4, |_| {})))
}
fn npy_15_columns() -> Vec<u8> {
    npy_raw("<f8", "False", "(4, 15)", &f64_bytes(&[0.5; 60]))
}
/// A header that promises a billion rows over the bytes of four.
fn npy_lying_rows() -> Vec<u8> {
    npy_raw(
        "<f8",
        "False",
        "(1000000000, 17)",
        &f64_bytes(&llff_rows(4, |_| {})),
    )
}
/// A shape whose byte count overflows.
fn npy_overflowing_shape() -> Vec<u8> {
    npy_raw("<f8", "False", "(18446744073709551615, 17)", &[])
}
fn npy_version_9() -> Vec<u8> {
    let mut bytes = poses_bounds(&llff_rows(4, |_| {}));
    bytes[6] = 9;
    bytes
}
fn npy_nan_centre() -> Vec<u8> {
    poses_bounds(&llff_rows(4, |r| r[17 + 3] = f64::NAN))
}
fn npy_scaled_rotation() -> Vec<u8> {
    poses_bounds(&llff_rows(4, |r| r[2 * 17] = 2.0))
}
fn npy_far_before_near() -> Vec<u8> {
    poses_bounds(&llff_rows(4, |r| {
        r[15] = 10.0;
        r[16] = 1.0;
    }))
}
fn npy_zero_width() -> Vec<u8> {
    poses_bounds(&llff_rows(4, |r| r[9] = 0.0))
}
fn npy_two_rows() -> Vec<u8> {
    poses_bounds(&llff_rows(2, |_| {}))
}

#[test]
fn images_llff_and_blender() {
    let cases = [
        // Any image: the planar study's photograph.
        Case {
            name: "image: missing",
            files: &[],
            args: &["run", PLANAR, "--set", "image.path=\"nope.png\""],
            code: 1,
            expect: &[
                "cannot read image nope.png (expected a readable PNG or JPEG file): No such file or directory",
            ],
        },
        Case {
            name: "image: a folder",
            files: &[("img.png", D)],
            args: &["run", PLANAR, "--set", "image.path=\"img.png\""],
            code: 1,
            expect: &[
                "cannot read image img.png (expected a readable PNG or JPEG file): Is a directory",
            ],
        },
        Case {
            name: "image: empty file",
            files: &[("img.png", T(""))],
            args: &["run", PLANAR, "--set", "image.path=\"img.png\""],
            code: 1,
            expect: &["image img.png: expected PNG or JPEG data, got unrecognised data"],
        },
        Case {
            name: "image: text",
            files: &[("img.png", B(not_an_image))],
            args: &["run", PLANAR, "--set", "image.path=\"img.png\""],
            code: 1,
            expect: &["image img.png: expected PNG or JPEG data, got unrecognised data"],
        },
        Case {
            name: "image: truncated PNG",
            files: &[("img.png", B(rgb_12x10)), ("img.png", Half)],
            args: &["run", PLANAR, "--set", "image.path=\"img.png\""],
            code: 1,
            expect: &["image img.png: expected valid PNG data, got a decoding error"],
        },
        Case {
            name: "image: PNG header of 100000 × 100000",
            files: &[("img.png", B(png_lying_header))],
            args: &["run", PLANAR, "--set", "image.path=\"img.png\""],
            code: 1,
            expect: &["image img.png: expected valid PNG data, got a decoding error"],
        },
        Case {
            name: "image: PNG with a corrupt chunk",
            files: &[("img.png", B(png_bad_crc))],
            args: &["run", PLANAR, "--set", "image.path=\"img.png\""],
            code: 1,
            expect: &["image img.png: expected valid PNG data, got a decoding error"],
        },
        Case {
            name: "image: truncated JPEG",
            files: &[("img.jpg", B(jpeg_truncated))],
            args: &["run", PLANAR, "--set", "image.path=\"img.jpg\""],
            code: 1,
            expect: &[
                "image img.jpg: expected complete JPEG data, got a file that ends inside its image data",
            ],
        },
        Case {
            name: "image: smaller than the crop",
            files: &[("img.png", B(rgb_12x10))],
            args: &["run", PLANAR, "--set", "image.path=\"img.png\""],
            code: 1,
            expect: &[
                "planar.toml",
                "[image] crop_px = 180 does not fit the 12×10 image at scale 0.5",
            ],
        },
        // LLFF
        Case {
            name: "llff: no poses_bounds.npy",
            files: &[LLFF_X, ("scene", S(llff)), ("scene/poses_bounds.npy", Rm)],
            args: RUN_X,
            code: 1,
            expect: &["cannot read scene/poses_bounds.npy: No such file or directory"],
        },
        Case {
            name: "llff: not NPY",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(not_an_image)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected an NPY file (magic \\x93NUMPY), got 21 bytes without that magic",
            ],
        },
        Case {
            name: "llff: header cut short",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", Cut(40)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected a complete text NPY header, got a truncated header",
            ],
        },
        Case {
            name: "llff: data cut short",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", Cut(300)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected 544 data bytes for <f8 values of shape (4, 17), got 172 bytes",
            ],
        },
        Case {
            name: "llff: a billion rows promised",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_lying_rows)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected 136000000000 data bytes for <f8 values of shape (1000000000, 17), got 544 bytes",
            ],
        },
        Case {
            name: "llff: a shape beyond memory",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_overflowing_shape)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/poses_bounds.npy: expected more than usize::MAX data bytes"],
        },
        Case {
            name: "llff: 15 columns",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_15_columns)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected 'shape': (N, 17) with N ≥ 1, got 'shape': (4, 15)",
            ],
        },
        Case {
            name: "llff: float32",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_f4)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected 'descr': '<f8' (little-endian float64), got 'descr': '<f4'",
            ],
        },
        Case {
            name: "llff: big endian",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_big_endian)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected 'descr' a little-endian bool, integer or float type",
            ],
        },
        Case {
            name: "llff: Fortran order",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_fortran)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/poses_bounds.npy: expected 'fortran_order': False"],
        },
        Case {
            name: "llff: NPY version 9",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_version_9)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected NPY format version 1, 2 or 3, got version 9.0",
            ],
        },
        Case {
            name: "llff: nan centre",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_nan_centre)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected row 1: a rotation (|RᵀR − I| and |det R − 1| below 0.0001) and a finite translation",
            ],
        },
        Case {
            name: "llff: scaled rotation",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_scaled_rotation)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected row 2: a rotation",
                "det R = 2.000000",
            ],
        },
        Case {
            name: "llff: far before near",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_far_before_near)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected row 0: bounds 0 < near < far, got near = 10, far = 1",
            ],
        },
        Case {
            name: "llff: zero original width",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_zero_width)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/poses_bounds.npy: expected row 0: positive original width W and focal f, got W = 0, f = 50",
            ],
        },
        Case {
            name: "llff: an image missing",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/images_8/image003.png", Rm),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/images_8: expected 4 images, one per row of scene/poses_bounds.npy, got 3 images",
            ],
        },
        Case {
            name: "llff: truncated PNG",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/images_8/image001.png", Half),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "image scene/images_8/image001.png: expected valid PNG data, got a decoding error",
            ],
        },
        Case {
            name: "llff: PNG header of 100000 × 100000",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/images_8/image002.png", B(png_lying_header)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "image scene/images_8/image002.png: expected valid PNG data, got a decoding error",
            ],
        },
        Case {
            name: "llff: a text file named .png",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/images_8/image000.png", B(not_an_image)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "image scene/images_8/image000.png: expected PNG or JPEG data, got unrecognised data",
            ],
        },
        Case {
            name: "llff: truncated JPEG among PNGs",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/images_8/image003.png", Rm),
                ("scene/images_8/image003.jpg", B(jpeg_truncated)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["image scene/images_8/image003.jpg: expected complete JPEG data"],
        },
        Case {
            name: "llff: images of two sizes",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/images_8/image002.png", B(rgb_11x10)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "image scene/images_8/image002.png: expected the size of the first image scene/images_8/image000.png, 12×10, got 11×10",
            ],
        },
        Case {
            name: "llff: no folder for the factor",
            files: &[LLFF_X, ("scene", S(llff))],
            args: &["run", "x.toml", "--set", "data.factor=4"],
            code: 1,
            expect: &[
                "scene/images_4: expected a folder of 4 images (downscale factor 4), one per row of scene/poses_bounds.npy, got no such folder (the scene has images_8)",
            ],
        },
        Case {
            name: "llff: factor = 0",
            files: &[LLFF_X, ("scene", S(llff))],
            args: &["run", "x.toml", "--set", "data.factor=0"],
            code: 1,
            expect: &["[data] factor = 0: expected at least 1"],
        },
        Case {
            name: "llff: factor = -1",
            files: &[LLFF_X, ("scene", S(llff))],
            args: &["run", "x.toml", "--set", "data.factor=-1"],
            code: 2,
            expect: &[
                "x.toml: TOML parse error",
                "factor = -1",
                "invalid value: integer `-1`, expected u32",
            ],
        },
        Case {
            name: "llff: subsample = 0",
            files: &[LLFF_X, ("scene", S(llff))],
            args: &["run", "x.toml", "--set", "data.subsample=0"],
            code: 1,
            expect: &["[data] subsample = 0: expected at least 1"],
        },
        Case {
            name: "llff: Blender options",
            files: &[LLFF_X, ("scene", S(llff))],
            args: &["run", "x.toml", "--set", "data.sequence=true"],
            code: 1,
            expect: &["[data] split, sequence and eval_split are for Blender scenes"],
        },
        Case {
            name: "llff: two images",
            files: &[
                LLFF_X,
                ("scene", S(llff)),
                ("scene/poses_bounds.npy", B(npy_two_rows)),
                ("scene/images_8/image002.png", Rm),
                ("scene/images_8/image003.png", Rm),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene: need at least 3 images, found 2"],
        },
        Case {
            name: "llff: the path is a file",
            files: &[LLFF_X, ("scene", T("not a folder\n"))],
            args: RUN_X,
            code: 1,
            expect: &["cannot read scene/poses_bounds.npy: Not a directory"],
        },
        // Blender
        Case {
            name: "blender: a factor beyond the images' side",
            files: &[BLENDER_X, ("scene", S(blender))],
            args: &["run", "x.toml", "--set", "data.factor=1000000"],
            code: 1,
            expect: &["[data] factor = 1000000: expected at most 8, the side of the 8×8 images"],
        },
        Case {
            name: "blender: truncated JSON",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                ("scene/transforms_train.json", Half),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/transforms_train.json: expected valid JSON, got a parse error"],
        },
        Case {
            name: "blender: a number beyond f64",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T("{\"camera_angle_x\": 1e400, \"frames\": []}"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/transforms_train.json: expected valid JSON, got a parse error",
                "number out of range",
            ],
        },
        Case {
            name: "blender: no camera_angle_x",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                ("scene/transforms_train.json", T("{\"frames\": []}")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/transforms_train.json: expected a number camera_angle_x in (0, π), got None",
            ],
        },
        Case {
            name: "blender: camera_angle_x = 4",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T("{\"camera_angle_x\": 4, \"frames\": []}"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/transforms_train.json: expected a number camera_angle_x in (0, π), got Some(Number(4))",
            ],
        },
        Case {
            name: "blender: no frames",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T("{\"camera_angle_x\": 0.69}"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/transforms_train.json: expected a list `frames`, got none"],
        },
        Case {
            name: "blender: a 3 × 4 matrix",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T(
                        "{\"camera_angle_x\": 0.69, \"frames\": [{\"file_path\": \"./train/r_0\", \"transform_matrix\": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4]]}]}",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/transforms_train.json: expected frame 0: a 4×4 numeric transform_matrix with last row 0 0 0 1",
            ],
        },
        Case {
            name: "blender: a scaled rotation",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T(
                        "{\"camera_angle_x\": 0.69, \"frames\": [{\"file_path\": \"./train/r_0\", \"transform_matrix\": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]}",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/transforms_train.json: expected frame 0 (./train/r_0): a rotation"],
        },
        Case {
            name: "blender: file_path is a number",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T("{\"camera_angle_x\": 0.69, \"frames\": [{\"file_path\": 7}]}"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/transforms_train.json: expected frame 0: a string file_path"],
        },
        Case {
            name: "blender: truncated RGBA image",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                ("scene/train/r_2.png", Cut(60)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["image scene/./train/r_2.png: expected valid PNG data, got a decoding error"],
        },
        Case {
            name: "blender: a sequence out of order",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T(
                        "{\"camera_angle_x\": 0.69, \"frames\": [{\"file_path\": \"./train/r_0\", \"transform_matrix\": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}, {\"file_path\": \"./train/r_2\", \"transform_matrix\": [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}, {\"file_path\": \"./train/r_1\", \"transform_matrix\": [[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}, {\"file_path\": \"./train/r_3\", \"transform_matrix\": [[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]}",
                    ),
                ),
            ],
            args: &[
                "run",
                "x.toml",
                "--set",
                "data.sequence=true",
                "--set",
                "data.subsample=2",
            ],
            code: 1,
            expect: &[
                "scene/transforms_train.json: expected frames of a time sequence, in rising order of their numbers, got frame 2: r_1.png comes after frame 1: r_2.png",
            ],
        },
        Case {
            name: "blender: a sequence with a repeated frame",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                (
                    "scene/transforms_train.json",
                    T(
                        "{\"camera_angle_x\": 0.69, \"frames\": [{\"file_path\": \"./train/r_0\", \"transform_matrix\": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}, {\"file_path\": \"./train/r_1\", \"transform_matrix\": [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}, {\"file_path\": \"./train/r_1\", \"transform_matrix\": [[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}, {\"file_path\": \"./train/r_3\", \"transform_matrix\": [[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]}",
                    ),
                ),
            ],
            args: &[
                "run",
                "x.toml",
                "--set",
                "data.sequence=true",
                "--set",
                "data.subsample=2",
            ],
            code: 1,
            expect: &["got frame 2: r_1.png repeats frame 1: r_1.png"],
        },
        Case {
            name: "blender: a sequence image missing",
            files: &[
                BLENDER_X,
                ("scene", S(blender)),
                ("scene/train/r_3.png", Rm),
            ],
            args: &[
                "run",
                "x.toml",
                "--set",
                "data.sequence=true",
                "--set",
                "data.subsample=2",
            ],
            code: 1,
            expect: &[
                "cannot read image scene/./train/r_3.png (expected a readable PNG or JPEG file): No such file or directory",
            ],
        },
        Case {
            name: "blender: no such split",
            files: &[BLENDER_X, ("scene", S(blender))],
            args: &["run", "x.toml", "--set", "data.split=\"val\""],
            code: 1,
            expect: &["cannot read scene/transforms_val.json: No such file or directory"],
        },
        Case {
            name: "blender: max_frames = 0",
            files: &[BLENDER_X, ("scene", S(blender))],
            args: &["run", "x.toml", "--set", "data.max_frames=0"],
            code: 1,
            expect: &["scene/transforms_train.json: expected at least one image, got none"],
        },
    ];
    check_all("images", &cases);
}

// ---------------------------------------------------------------------------------------------
// RGB-D folders of task `slam`: Replica, ScanNet, 7-Scenes, TUM RGB-D, and their depth PNGs.

const SLAM_X: (&str, F) = (
    "x.toml",
    T(
        "task = \"slam\"\n[run]\nthreads = 1\n[data]\nsource = \"replica\"\npath = \"scene\"\n[slam]\nmethods = [\"baseline\"]\n[tracking]\nedge = 2\n[mesh]\nvoxel = 0\n",
    ),
);
const SCANNET: &[&str] = &["run", "x.toml", "--set", "data.source=\"scannet\""];
const SEVEN: &[&str] = &["run", "x.toml", "--set", "data.source=\"7scenes\""];
const TUM: &[&str] = &["run", "x.toml", "--set", "data.source=\"tum\""];

#[test]
fn rgbd_folders() {
    let cases = [
        // Replica
        Case {
            name: "replica: no results folder",
            files: &[SLAM_X, ("scene", S(replica)), ("scene/results", Rm)],
            args: RUN_X,
            code: 1,
            expect: &[
                "no Replica scene at scene: NICE-SLAM's Replica (results/frame*.jpg, depth*.png, traj.txt)",
            ],
        },
        Case {
            name: "replica: crop_edge larger than the image",
            files: &[SLAM_X, ("scene", S(replica))],
            args: &["run", "x.toml", "--set", "data.crop_edge=6"],
            code: 1,
            expect: &["scene: crop_edge 6 leaves no pixels of a 16×12 image"],
        },
        Case {
            name: "7scenes: crop_edge larger than the image",
            files: &[SLAM_X, ("scene", S(seven_scenes))],
            args: &[
                "run",
                "x.toml",
                "--set",
                "data.source=\"7scenes\"",
                "--set",
                "data.crop_edge=6",
            ],
            code: 1,
            expect: &["scene: crop_edge 6 leaves no pixels of a 16×12 image"],
        },
        Case {
            name: "replica: the path is a file",
            files: &[SLAM_X, ("scene", T("not a folder\n"))],
            args: RUN_X,
            code: 1,
            expect: &["no Replica scene at scene"],
        },
        Case {
            name: "replica: a frame without depth",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/depth000002.png", Rm),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/results: frame 2 has a colour file (scene/results/frame000002.png) but no depth file",
            ],
        },
        Case {
            name: "replica: no traj.txt",
            files: &[SLAM_X, ("scene", S(replica)), ("scene/traj.txt", Rm)],
            args: RUN_X,
            code: 1,
            expect: &["cannot access scene/traj.txt: No such file or directory"],
        },
        Case {
            name: "replica: fewer poses than frames",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                (
                    "scene/traj.txt",
                    T(
                        "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/traj.txt: 3 poses for frames up to 3: the trajectory must have one line per frame",
            ],
        },
        Case {
            name: "replica: 15 numbers on a pose line",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                (
                    "scene/traj.txt",
                    T(
                        "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/traj.txt:2: expected 16 numbers, got \"1 0 0 0 0 1 0 0 0 0 1 0 0 0 0\"",
            ],
        },
        Case {
            name: "replica: truncated cam_params.json",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/cam_params.json", Half),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/cam_params.json: expected {\"camera\": {\"w\", \"h\", \"fx\", \"fy\", \"cx\", \"cy\", \"scale\"}}, got EOF while parsing",
            ],
        },
        Case {
            name: "replica: typo in cam_params.json",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                (
                    "scene/cam_params.json",
                    T(
                        r#"{"camera": {"w": 16, "h": 12, "fx": 10.0, "fy": 10.0, "cx": 7.5, "cy": 5.5, "scael": 1000.0}}"#,
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/cam_params.json: expected {\"camera\"",
                "unknown field `scael`",
            ],
        },
        Case {
            name: "replica: zero focal length",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                (
                    "scene/cam_params.json",
                    T(
                        r#"{"camera": {"w": 16, "h": 12, "fx": 0.0, "fy": 10.0, "cx": 7.5, "cy": 5.5, "scale": 1000.0}}"#,
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/cam_params.json: expected a camera of at least 1×1 pixels with positive focal lengths and a finite principal point, got 16×12, fx = 0",
            ],
        },
        Case {
            name: "replica: negative depth scale",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                (
                    "scene/cam_params.json",
                    T(
                        r#"{"camera": {"w": 16, "h": 12, "fx": 10.0, "fy": 10.0, "cx": 7.5, "cy": 5.5, "scale": -1.0}}"#,
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/cam_params.json: expected a positive depth scale (PNG units per metre), got scale = -1",
            ],
        },
        Case {
            name: "replica: intrinsics of another aspect ratio",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                (
                    "scene/cam_params.json",
                    T(
                        r#"{"camera": {"w": 32, "h": 12, "fx": 10.0, "fy": 10.0, "cx": 7.5, "cy": 5.5, "scale": 1000.0}}"#,
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/results/depth000000.png: expected an image of the intrinsics' aspect ratio (32×12 or a multiple), got 16×12",
            ],
        },
        Case {
            name: "replica: depth PNG cut inside its header",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/depth000000.png", Cut(20)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/results/depth000000.png: expected a readable depth PNG"],
        },
        Case {
            name: "replica: truncated depth PNG",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/depth000000.png", Half),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/results/depth000000.png: expected a 16-bit single-channel depth PNG"],
        },
        Case {
            name: "replica: 8-bit depth",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/depth000000.png", B(gray8_16x12)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/results/depth000000.png: expected a 16-bit single-channel depth PNG, got 1 channel(s) of 8 bits",
            ],
        },
        Case {
            name: "replica: colour PNG as depth",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/depth000000.png", B(rgb_16x12)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/results/depth000000.png: expected a 16-bit single-channel depth PNG, got 3 channel(s) of 8 bits",
            ],
        },
        Case {
            name: "replica: depth header of 160000 × 120000",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/depth000000.png", B(depth_lying_header)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/results/depth000000.png: expected a 16-bit single-channel depth PNG"],
        },
        Case {
            name: "replica: truncated colour frame",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/frame000000.png", Half),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "image scene/results/frame000000.png: expected valid PNG data, got a decoding error",
            ],
        },
        Case {
            name: "replica: colour frame of another size",
            files: &[
                SLAM_X,
                ("scene", S(replica)),
                ("scene/results/frame000000.png", B(rgb_20x12)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/results/frame000000.png: expected a colour image of 16×12, got 20×12"],
        },
        Case {
            name: "replica: tracking edge wider than the image",
            files: &[SLAM_X, ("scene", S(replica))],
            args: &["run", "x.toml", "--set", "tracking.edge=10"],
            code: 1,
            expect: &["unit scene_baseline: tracking.edge = 10 leaves no pixels of a 16×12 image"],
        },
        Case {
            name: "replica: resolution = 0",
            files: &[SLAM_X, ("scene", S(replica))],
            args: &["run", "x.toml", "--set", "data.resolution=0"],
            code: 1,
            expect: &["scene: resolution factor 0 must lie in (0, 1]"],
        },
        Case {
            name: "replica: frame_rate = -1",
            files: &[SLAM_X, ("scene", S(replica))],
            args: &["run", "x.toml", "--set", "data.frame_rate=-1"],
            code: 1,
            expect: &["scene: frame rate -1 must be positive"],
        },
        Case {
            name: "replica: one frame",
            files: &[SLAM_X, ("scene", S(replica))],
            args: &["run", "x.toml", "--set", "data.frames=1"],
            code: 1,
            expect: &["scene: need at least two frames, found 1"],
        },
        // ScanNet
        Case {
            name: "scannet: no color folder",
            files: &[SLAM_X, ("scene", S(scannet)), ("scene/color", Rm)],
            args: SCANNET,
            code: 1,
            expect: &["scene: expected a ScanNet scene: color/0.jpg, depth/0.png, pose/0.txt"],
        },
        Case {
            name: "scannet: a frame without a pose",
            files: &[SLAM_X, ("scene", S(scannet)), ("scene/pose/2.txt", Rm)],
            args: SCANNET,
            code: 1,
            expect: &["scene: frame 2 has a colour file (scene/color/2.png) but no pose file"],
        },
        Case {
            name: "scannet: a pose of 3 lines",
            files: &[
                SLAM_X,
                ("scene", S(scannet)),
                ("scene/pose/1.txt", T("1 0 0 0\n0 1 0 0\n0 0 1 0\n")),
            ],
            args: SCANNET,
            code: 1,
            expect: &["scene/pose/1.txt: expected a 4×4 matrix on four lines, got 3 lines"],
        },
        Case {
            name: "scannet: a word in a pose",
            files: &[
                SLAM_X,
                ("scene", S(scannet)),
                (
                    "scene/pose/1.txt",
                    T("1 0 0 0\n0 one 0 0\n0 0 1 0\n0 0 0 1\n"),
                ),
            ],
            args: SCANNET,
            code: 1,
            expect: &["scene/pose/1.txt:2: expected 4 numbers, got \"0 one 0 0\""],
        },
        Case {
            name: "scannet: zero focal length",
            files: &[
                SLAM_X,
                ("scene", S(scannet)),
                (
                    "scene/intrinsic/intrinsic_depth.txt",
                    T("0 0 7.5 0\n0 10 5.5 0\n0 0 1 0\n0 0 0 1\n"),
                ),
            ],
            args: SCANNET,
            code: 1,
            expect: &[
                "scene/intrinsic/intrinsic_depth.txt: expected a camera of at least 1×1 pixels with positive focal lengths",
            ],
        },
        Case {
            name: "scannet: crop_edge larger than the image",
            files: &[SLAM_X, ("scene", S(scannet))],
            args: &[
                "run",
                "x.toml",
                "--set",
                "data.source=\"scannet\"",
                "--set",
                "data.crop_edge=100",
            ],
            code: 1,
            expect: &["scene: crop_edge 100 leaves no pixels of a 16×12 image"],
        },
        Case {
            name: "scannet: colour PNG as depth",
            files: &[
                SLAM_X,
                ("scene", S(scannet)),
                ("scene/depth/0.png", B(rgb_16x12)),
            ],
            args: SCANNET,
            code: 1,
            expect: &[
                "scene/depth/0.png: expected a 16-bit single-channel depth PNG, got 3 channel(s) of 8 bits",
            ],
        },
        // 7-Scenes
        Case {
            name: "7scenes: a scene folder instead of a sequence",
            files: &[SLAM_X, ("scene/seq-01", S(seven_scenes))],
            args: SEVEN,
            code: 1,
            expect: &[
                "scene: expected 7-Scenes frames: frame-000000.color.png (or .jpg), frame-000000.depth.png, frame-000000.pose.txt, …; this looks like a scene folder: point at one of seq-01",
            ],
        },
        Case {
            name: "7scenes: no such folder",
            files: &[SLAM_X],
            args: SEVEN,
            code: 1,
            expect: &["no 7-Scenes sequence at scene"],
        },
        Case {
            name: "7scenes: a frame without a pose",
            files: &[
                SLAM_X,
                ("scene", S(seven_scenes)),
                ("scene/frame-000001.pose.txt", Rm),
            ],
            args: SEVEN,
            code: 1,
            expect: &[
                "scene: frame 1 has no pose file (frame-000001.pose…); every frame needs its colour, depth and pose",
            ],
        },
        Case {
            name: "7scenes: two colour files for one frame",
            files: &[
                SLAM_X,
                ("scene", S(seven_scenes)),
                ("scene/frame-000000.color.jpg", B(jpeg_truncated)),
            ],
            args: SEVEN,
            code: 1,
            expect: &["scene: frame 0 has two files of one kind"],
        },
        Case {
            name: "7scenes: a pose of 5 lines",
            files: &[
                SLAM_X,
                ("scene", S(seven_scenes)),
                (
                    "scene/frame-000002.pose.txt",
                    T("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n0 0 0 1\n"),
                ),
            ],
            args: SEVEN,
            code: 1,
            expect: &[
                "scene/frame-000002.pose.txt: expected a 4×4 matrix on four lines, got 5 lines",
            ],
        },
        Case {
            name: "7scenes: intrinsics of 2 lines",
            files: &[
                SLAM_X,
                ("scene", S(seven_scenes)),
                ("scene/camera-intrinsics.txt", T("10 0 7.5\n0 10 5.5\n")),
            ],
            args: SEVEN,
            code: 1,
            expect: &[
                "scene/camera-intrinsics.txt: expected a 3×3 intrinsics matrix on three lines, got 2 lines",
            ],
        },
        Case {
            name: "7scenes: frame_rate = nan",
            files: &[SLAM_X, ("scene", S(seven_scenes))],
            args: &[
                "run",
                "x.toml",
                "--set",
                "data.source=\"7scenes\"",
                "--set",
                "data.frame_rate=nan",
            ],
            code: 1,
            expect: &["scene: frame rate NaN Hz must be positive"],
        },
        // TUM RGB-D
        Case {
            name: "tum rgbd: no rgb.txt",
            files: &[SLAM_X, ("scene", S(tum_rgbd)), ("scene/rgb.txt", Rm)],
            args: TUM,
            code: 1,
            expect: &[
                "scene: expected a TUM RGB-D sequence: rgb.txt, depth.txt, groundtruth.txt, rgb/, depth/",
            ],
        },
        Case {
            name: "tum rgbd: no depth.txt",
            files: &[SLAM_X, ("scene", S(tum_rgbd)), ("scene/depth.txt", Rm)],
            args: TUM,
            code: 1,
            expect: &["cannot access scene/depth.txt: No such file or directory"],
        },
        Case {
            name: "tum rgbd: a line without a path",
            files: &[
                SLAM_X,
                ("scene", S(tum_rgbd)),
                ("scene/rgb.txt", T("# colour\n0.0\n")),
            ],
            args: TUM,
            code: 1,
            expect: &["scene/rgb.txt:2: expected `timestamp path`, got \"0.0\""],
        },
        Case {
            name: "tum rgbd: nan timestamp",
            files: &[
                SLAM_X,
                ("scene", S(tum_rgbd)),
                ("scene/depth.txt", T("nan depth/0.png\n")),
            ],
            args: TUM,
            code: 1,
            expect: &["scene/depth.txt:1: expected `timestamp path`, got \"nan depth/0.png\""],
        },
        Case {
            name: "tum rgbd: zero quaternion in the ground truth",
            files: &[
                SLAM_X,
                ("scene", S(tum_rgbd)),
                (
                    "scene/groundtruth.txt",
                    T("0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 0\n"),
                ),
            ],
            args: TUM,
            code: 1,
            expect: &[
                "scene/groundtruth.txt:2: expected a finite pose with a unit quaternion (qx qy qz qw), got \"0.1 0 0 0 0 0 0 0\"",
            ],
        },
        Case {
            name: "tum rgbd: nan in the ground truth",
            files: &[
                SLAM_X,
                ("scene", S(tum_rgbd)),
                ("scene/groundtruth.txt", T("0.0 0 0 nan 0 0 0 1\n")),
            ],
            args: TUM,
            code: 1,
            expect: &["scene/groundtruth.txt:1: expected a finite pose with a unit quaternion"],
        },
        Case {
            name: "tum rgbd: 7 ground-truth columns",
            files: &[
                SLAM_X,
                ("scene", S(tum_rgbd)),
                ("scene/groundtruth.txt", T("0.0 0 0 0 0 0 1\n")),
            ],
            args: TUM,
            code: 1,
            expect: &["scene/groundtruth.txt:1: expected 8 numbers, got \"0.0 0 0 0 0 0 1\""],
        },
        Case {
            name: "tum rgbd: depth 10 s after colour",
            files: &[
                SLAM_X,
                ("scene", S(tum_rgbd)),
                ("scene/depth.txt", T("10.0 depth/0.png\n10.1 depth/1.png\n")),
            ],
            args: TUM,
            code: 1,
            expect: &[
                "scene: no colour image has a depth image (and a ground-truth pose) within 0.08 s",
            ],
        },
        Case {
            name: "tum rgbd: a depth file missing",
            files: &[SLAM_X, ("scene", S(tum_rgbd)), ("scene/depth/0.png", Rm)],
            args: TUM,
            code: 1,
            expect: &["scene/depth/0.png: expected a readable depth PNG"],
        },
    ];
    check_all("rgbd", &cases);
}

// ---------------------------------------------------------------------------------------------
// EuRoC folders (ASL layout) of tasks `trajectory` and `slam_imu`.

const FIT_EUROC: (&str, F) = (
    "x.toml",
    T(
        "task = \"trajectory\"\n[run]\nthreads = 1\n[data]\nsource = \"euroc\"\npath = \"seq\"\n[fit]\nimu = [\"none\"]\n[fields.spline]\nkind = \"spline\"\n",
    ),
);
const IMU_EUROC: (&str, F) = (
    "x.toml",
    T(
        "task = \"slam_imu\"\n[run]\nthreads = 1\n[data]\nsource = \"synthetic\"\npath = \"room\"\n[synthetic]\nwidth = 48\nframes = 4\n[euroc]\npath = \"seq\"\n[slam]\nmethods = [\"baseline\"]\n",
    ),
);
const GT_CSV: &str = "seq/mav0/state_groundtruth_estimate0/data.csv";
const IMU_CSV: &str = "seq/mav0/imu0/data.csv";
const IMU_YAML: &str = "seq/mav0/imu0/sensor.yaml";

#[test]
fn euroc_folders() {
    let cases = [
        Case {
            name: "ground truth: missing, its cause printed once",
            files: &[FIT_EUROC, ("seq", S(euroc)), (GT_CSV, Rm)],
            args: RUN_X,
            code: 1,
            expect: &[
                "cannot read seq/mav0/state_groundtruth_estimate0/data.csv",
                "No such file or directory",
            ],
        },
        Case {
            name: "ground truth: 16 columns",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T("#h\n1403715523912140000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 2 of seq/mav0/state_groundtruth_estimate0/data.csv: expected 17 comma-separated columns (timestamp, p xyz, q wxyz, v xyz, b_w xyz, b_a xyz), got 16",
            ],
        },
        Case {
            name: "ground truth: cut inside a line",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T(
                        "#h\n1403715523912140000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n1403715523922140000,0,0,1,1,0,0",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 3 of seq/mav0/state_groundtruth_estimate0/data.csv: expected 17 comma-separated columns",
                "got 7",
            ],
        },
        Case {
            name: "ground truth: nan",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T("1403715523912140000,0,nan,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 1 of seq/mav0/state_groundtruth_estimate0/data.csv: expected a finite number, got \"nan\"",
            ],
        },
        Case {
            name: "ground truth: a float timestamp",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (GT_CSV, T("1.4e18,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 1 of seq/mav0/state_groundtruth_estimate0/data.csv: expected an integer timestamp in nanoseconds, got \"1.4e18\"",
            ],
        },
        Case {
            name: "ground truth: a timestamp beyond i64",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T("99999999999999999999,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 1 of seq/mav0/state_groundtruth_estimate0/data.csv: expected an integer timestamp in nanoseconds, got \"99999999999999999999\"",
            ],
        },
        Case {
            name: "ground truth: a repeated timestamp",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T(
                        "#h\n1000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n1000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 3 of seq/mav0/state_groundtruth_estimate0/data.csv: expected increasing timestamps, got a duplicate timestamp 1000 after 1000",
            ],
        },
        Case {
            name: "ground truth: unsorted",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T(
                        "2000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n1000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 2 of seq/mav0/state_groundtruth_estimate0/data.csv: expected increasing timestamps, got an earlier timestamp 1000 after 2000",
            ],
        },
        Case {
            name: "ground truth: zero quaternion",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (GT_CSV, T("1000,0,0,1,0,0,0,0,0,0,0,0,0,0,0,0,0\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 1 of seq/mav0/state_groundtruth_estimate0/data.csv: expected a unit quaternion q_w q_x q_y q_z, got a zero quaternion",
            ],
        },
        Case {
            name: "ground truth: header only",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (GT_CSV, T("#timestamp,p_x\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 1 of seq/mav0/state_groundtruth_estimate0/data.csv: expected at least one data row, the file has none",
            ],
        },
        Case {
            name: "imu: 6 columns",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (IMU_CSV, T("#h\n1403715523912140000,0,0,0,0,0\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 2 of seq/mav0/imu0/data.csv: expected 7 comma-separated columns (timestamp, w xyz, a xyz), got 6",
            ],
        },
        Case {
            name: "imu: inf",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (IMU_CSV, T("1403715523912140000,0,0,0,0,0,inf\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &["line 1 of seq/mav0/imu0/data.csv: expected a finite number, got \"inf\""],
        },
        Case {
            name: "imu: unsorted",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    IMU_CSV,
                    T("2000,0,0,0,0,0,9.81\n3000,0,0,0,0,0,9.81\n1000,0,0,0,0,0,9.81\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 3 of seq/mav0/imu0/data.csv: expected increasing timestamps, got an earlier timestamp 1000 after 3000",
            ],
        },
        Case {
            name: "sensor.yaml: no rate_hz",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    IMU_YAML,
                    T(
                        "%YAML:1.0\nT_BS:\n  data: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\ngyroscope_noise_density: 1.6968e-04\ngyroscope_random_walk: 1.9393e-05\naccelerometer_noise_density: 2.0000e-3\naccelerometer_random_walk: 3.0000e-3\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 1 of seq/mav0/imu0/sensor.yaml: expected a key \"rate_hz\", found none",
            ],
        },
        Case {
            name: "sensor.yaml: a word for a number",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (IMU_YAML, T("%YAML:1.0\ngyroscope_noise_density: high\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 2 of seq/mav0/imu0/sensor.yaml: expected a number for gyroscope_noise_density, got \"high\"",
            ],
        },
        Case {
            name: "sensor.yaml: T_BS of 15 numbers",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    IMU_YAML,
                    T(
                        "%YAML:1.0\nT_BS:\n  cols: 4\n  data: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0]\nrate_hz: 200\ngyroscope_noise_density: 1.6968e-04\ngyroscope_random_walk: 1.9393e-05\naccelerometer_noise_density: 2.0000e-3\naccelerometer_random_walk: 3.0000e-3\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 2 of seq/mav0/imu0/sensor.yaml: expected T_BS data with 16 numbers (a row-major 4×4 matrix)",
            ],
        },
        Case {
            name: "sensor.yaml: T_BS not a rotation",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    IMU_YAML,
                    T(
                        "%YAML:1.0\nT_BS:\n  cols: 4\n  data: [2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\nrate_hz: 200\ngyroscope_noise_density: 1.6968e-04\ngyroscope_random_walk: 1.9393e-05\naccelerometer_noise_density: 2.0000e-3\naccelerometer_random_walk: 3.0000e-3\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &["line 2 of seq/mav0/imu0/sensor.yaml: expected T_BS with a rotation block"],
        },
        Case {
            name: "cam0 sensor.yaml: no T_BS",
            files: &[
                FIT_EUROC,
                ("seq", S(euroc)),
                (
                    "seq/mav0/cam0/sensor.yaml",
                    T("%YAML:1.0\nsensor_type: camera\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &["line 1 of seq/mav0/cam0/sensor.yaml: expected a T_BS entry, found none"],
        },
        Case {
            name: "slam_imu: imu with 6 columns",
            files: &[
                IMU_EUROC,
                ("seq", S(euroc)),
                (IMU_CSV, T("#h\n1403715523912140000,0,0,0,0,0\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 2 of seq/mav0/imu0/data.csv: expected 7 comma-separated columns (timestamp, w xyz, a xyz), got 6",
            ],
        },
        Case {
            name: "slam_imu: ground truth unsorted",
            files: &[
                IMU_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T(
                        "2000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n1000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n",
                    ),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "line 2 of seq/mav0/state_groundtruth_estimate0/data.csv: expected increasing timestamps, got an earlier timestamp 1000 after 2000",
            ],
        },
        Case {
            name: "slam_imu: a trajectory and a flight",
            files: &[
                IMU_EUROC,
                ("seq", S(euroc)),
                ("gt.txt", T("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n")),
            ],
            args: &["run", "x.toml", "--set", "synthetic.trajectory=\"gt.txt\""],
            code: 1,
            expect: &[
                "[synthetic] trajectory cannot be combined with [euroc]: the flight is the motion",
            ],
        },
        Case {
            name: "slam_imu: a flight with one state",
            files: &[
                IMU_EUROC,
                ("seq", S(euroc)),
                (
                    GT_CSV,
                    T("1403715523912140000,0,0,1,1,0,0,0,0,0,0,0,0,0,0,0,0\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &["seq: the ground truth and the IMU need at least two entries each"],
        },
        Case {
            name: "slam_imu: no stationary start for the bias estimate",
            files: &[IMU_EUROC, ("seq", S(euroc_moving))],
            args: RUN_X,
            code: 1,
            expect: &["bias = \"estimate\" needs the recording to start at rest"],
        },
        Case {
            name: "slam_imu: a gap in the IMU readings",
            files: &[IMU_EUROC, ("seq", S(euroc_gap))],
            args: &["run", "x.toml", "--set", "euroc.bias=\"raw\""],
            code: 1,
            expect: &["the IMU readings have a gap of"],
        },
    ];
    check_all("euroc", &cases);
}

// ---------------------------------------------------------------------------------------------
// EventNeRF folders of task `events`: poses, intrinsics, times, and the events in an `.npz`
// (a ZIP of `.npy` arrays).

const EVENTS_X: (&str, F) = (
    "x.toml",
    T(
        "task = \"events\"\n[run]\nthreads = 1\n[data]\nsource = \"eventnerf\"\npath = \"scene\"\n[train]\nmethods = [\"eventnerf\"]\n",
    ),
);
const NPZ: &str = "scene/train/events/events.npz";

fn replaced(mut entries: Vec<Entry>, k: usize, entry: Entry) -> Vec<u8> {
    entries[k] = entry;
    zip(&entries)
}
fn events_entries() -> Vec<Entry> {
    event_entries(&T4, &P4, &X4)
}
/// A DEFLATE entry declaring 4 GB from 10 bytes.
fn npz_forged_deflate() -> Vec<u8> {
    let bomb = Entry {
        name: "x.npy",
        method: 8,
        flags: 0,
        crc: 0,
        data: vec![0; 10],
        size: 4_000_000_000,
    };
    replaced(events_entries(), 0, bomb)
}
/// A STORED entry declaring 9 GiB in its ZIP64 extra field.
fn npz_zip64_bomb() -> Vec<u8> {
    let bomb = Entry {
        size: 9 << 30,
        ..stored("x.npy", vec![0; 10])
    };
    replaced(events_entries(), 0, bomb)
}
fn npz_stored_lying_size() -> Vec<u8> {
    let liar = Entry {
        size: 1000,
        ..stored("x.npy", vec![0; 10])
    };
    replaced(events_entries(), 0, liar)
}
/// Valid DEFLATE data of 100 bytes under a header that says 10.
fn npz_inflates_beyond() -> Vec<u8> {
    let liar = Entry {
        name: "x.npy",
        method: 8,
        flags: 0,
        crc: 0,
        data: deflate_stored(&[0; 100]),
        size: 10,
    };
    replaced(events_entries(), 0, liar)
}
fn npz_bad_crc() -> Vec<u8> {
    let mut entries = events_entries();
    entries[2].crc ^= 1;
    zip(&entries)
}
fn npz_encrypted() -> Vec<u8> {
    let mut entries = events_entries();
    entries[0].flags = 1;
    zip(&entries)
}
fn npz_bzip2() -> Vec<u8> {
    let mut entries = events_entries();
    entries[0].method = 12;
    zip(&entries)
}
fn npz_no_p() -> Vec<u8> {
    let mut entries = events_entries();
    entries.pop();
    zip(&entries)
}
fn npz_short_x() -> Vec<u8> {
    zip(&event_entries(&T4, &P4, &[10, 20, 30]))
}
fn npz_2d_x() -> Vec<u8> {
    let x = stored("x.npy", npy_raw("<u2", "False", "(2, 2)", &u16s(&X4)));
    replaced(events_entries(), 0, x)
}
fn npz_nan_time() -> Vec<u8> {
    zip(&event_entries(&[0.1, f64::NAN, 0.3, 0.4], &P4, &X4))
}
fn npz_unsorted_time() -> Vec<u8> {
    zip(&event_entries(&[0.1, 0.3, 0.2, 0.4], &P4, &X4))
}
fn npz_polarity_2() -> Vec<u8> {
    zip(&event_entries(&T4, &[2, 1, 1, 1], &X4))
}
fn npz_mixed_polarity() -> Vec<u8> {
    zip(&event_entries(&T4, &[1, -1, 0, 1], &X4))
}
fn npz_float_pixel() -> Vec<u8> {
    let x = stored(
        "x.npy",
        npy_raw("<f8", "False", "(4,)", &f64_bytes(&[1.5, 2.0, 3.0, 4.0])),
    );
    replaced(events_entries(), 0, x)
}
fn npz_all_outside() -> Vec<u8> {
    zip(&event_entries(&T4, &P4, &[1000, 2000, 3000, 4000]))
}
/// `x.npy` whose header promises 4 values over 3.
fn npz_truncated_npy() -> Vec<u8> {
    let x = stored("x.npy", npy_raw("<u2", "False", "(4,)", &u16s(&[1, 2, 3])));
    replaced(events_entries(), 0, x)
}

#[test]
fn eventnerf_folders() {
    let cases = [
        // The .npz archive
        Case {
            name: "npz: not a ZIP",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(not_an_image))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected a ZIP archive (an end-of-central-directory record), got 21 bytes without one",
            ],
        },
        Case {
            name: "npz: truncated",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, Half)],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected a ZIP archive (an end-of-central-directory record)",
            ],
        },
        Case {
            name: "npz: decompression bomb (forged DEFLATE size)",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (NPZ, B(npz_forged_deflate)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected entry \"x.npy\": an uncompressed size at most 1032 times its 10 compressed bytes, got 4000000000 bytes declared (a forged header)",
            ],
        },
        Case {
            name: "npz: decompression bomb (9 GiB in ZIP64)",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_zip64_bomb))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected an archive of at most 8589934592 bytes uncompressed, got 9663676416 bytes up to entry \"x.npy\"",
            ],
        },
        Case {
            name: "npz: a STORED entry lying about its size",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (NPZ, B(npz_stored_lying_size)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected entry \"x.npy\": 1000 bytes, got 10 bytes",
            ],
        },
        Case {
            name: "npz: DEFLATE data longer than declared",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (NPZ, B(npz_inflates_beyond)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected entry \"x.npy\": DEFLATE data of 10 bytes, got an inflate error",
            ],
        },
        Case {
            name: "npz: corrupt entry",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_bad_crc))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected entry \"t.npy\": CRC-32",
                "(corrupt data)",
            ],
        },
        Case {
            name: "npz: encrypted entry",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_encrypted))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected entry \"x.npy\" unencrypted, got an encrypted entry",
            ],
        },
        Case {
            name: "npz: bzip2 entry",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_bzip2))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected entry \"x.npy\" STORED (0) or DEFLATE (8), got compression method 12",
            ],
        },
        Case {
            name: "npz: no polarities",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_no_p))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected arrays x, y, t, p (EventNeRF's event layout), got no array \"p\"; the file has t, x, y",
            ],
        },
        Case {
            name: "npz: columns of different lengths",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_short_x))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected arrays x, y, t, p of equal length, got lengths x 3, y 4, t 4, p 4",
            ],
        },
        Case {
            name: "npz: a 2-D column",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_2d_x))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: array 'x': expected a 1-D array, got shape (2, 2)",
            ],
        },
        Case {
            name: "npz: nan time",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_nan_time))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: array 't' at index 1: expected a finite time in s within ±292 years, got NaN",
            ],
        },
        Case {
            name: "npz: unsorted times",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (NPZ, B(npz_unsorted_time)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: event 2: expected times in non-decreasing order (after 300000000 ns at event 1), got 200000000 ns",
            ],
        },
        Case {
            name: "npz: polarity 2",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_polarity_2))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: array 'p' at index 0: expected polarity −1, 0 or 1, got 2",
            ],
        },
        Case {
            name: "npz: polarities 0 and -1 mixed",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (NPZ, B(npz_mixed_polarity)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: event 2: expected polarity −1 or +1 (the file is signed: −1 at event 1), got 0",
            ],
        },
        Case {
            name: "npz: a fractional pixel",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_float_pixel))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: array 'x' at index 0: expected an integer pixel coordinate, got 1.5",
            ],
        },
        Case {
            name: "npz: every event outside the sensor",
            files: &[EVENTS_X, ("scene", S(eventnerf)), (NPZ, B(npz_all_outside))],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: expected events on the 346×260 sensor, got none (4 events read, 4 dropped outside the sensor (first: event 0: (1000, 5))",
            ],
        },
        Case {
            name: "npz: an array shorter than its header",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (NPZ, B(npz_truncated_npy)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/events/events.npz: entry \"x.npy\": expected 8 data bytes for <u2 values of shape (4,), got 6 bytes",
            ],
        },
        Case {
            name: "events: two archives",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/events/more.npz", B(events_npz)),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/train/events: expected exactly one .npz file, got 2 files"],
        },
        Case {
            name: "events: no events folder",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/events", Rm),
            ],
            args: RUN_X,
            code: 1,
            expect: &["cannot read scene/train/events: No such file or directory"],
        },
        // Views
        Case {
            name: "pose: 15 numbers",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (
                    "scene/train/pose/r_00001.txt",
                    T("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/pose/r_00001.txt: expected 16 numbers (a 4×4 camera-to-world matrix), got 15 numbers",
            ],
        },
        Case {
            name: "pose: last row",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (
                    "scene/train/pose/r_00001.txt",
                    T("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/pose/r_00001.txt: expected last row 0 0 0 1, got [0.0, 0.0, 1.0, 1.0]",
            ],
        },
        Case {
            name: "pose: not a rotation",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (
                    "scene/train/pose/r_00002.txt",
                    T("1 0 0 0\n0 1 0 0\n0 0 3 0\n0 0 0 1\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/pose/r_00002.txt: expected the camera-to-world matrix: a rotation",
            ],
        },
        Case {
            name: "pose: nan",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (
                    "scene/train/pose/r_00000.txt",
                    T("1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/train/pose/r_00000.txt: expected finite numbers, got \"nan\""],
        },
        Case {
            name: "intrinsics: skew",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (
                    "scene/train/intrinsics/r_00000.txt",
                    T("100 1 173 0\n0 100 130 0\n0 0 1 0\n0 0 0 1\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/intrinsics/r_00000.txt: expected K = [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0 in the top-left 3×3",
            ],
        },
        Case {
            name: "intrinsics: one file missing",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/intrinsics/r_00002.txt", Rm),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/intrinsics: expected one intrinsics file per pose file (3 in scene/train/pose), at least one, got 2 files",
            ],
        },
        Case {
            name: "intrinsics: two cameras",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                (
                    "scene/train/intrinsics/r_00001.txt",
                    T("120 0 173 0\n0 100 130 0\n0 0 1 0\n0 0 0 1\n"),
                ),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/intrinsics/r_00001.txt: expected the intrinsics of scene/train/intrinsics/r_00000.txt, got different values (one camera per split is supported)",
            ],
        },
        Case {
            name: "times: unsorted",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/times.txt", T("0.0\n0.4\n0.2\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/times.txt: line 3: expected non-decreasing view times, got 0.2 s",
            ],
        },
        Case {
            name: "times: one per view",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/times.txt", T("0.0\n0.4\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train/times.txt: expected 3 view times, one per pose file, got 2 times",
            ],
        },
        Case {
            name: "times: a word",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/times.txt", T("0.0\nlater\n0.4\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &["scene/train/times.txt: line 2: expected a time in seconds, got \"later\""],
        },
        Case {
            name: "times: a repeated view time",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/times.txt", T("0.0\n0.2\n0.2\n")),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene: view poses",
                "key times must increase, found 0.2 then 0.2",
            ],
        },
        Case {
            name: "views: one view and no times",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf)),
                ("scene/train/pose/r_00001.txt", Rm),
                ("scene/train/pose/r_00002.txt", Rm),
                ("scene/train/intrinsics/r_00001.txt", Rm),
                ("scene/train/intrinsics/r_00002.txt", Rm),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/train: expected at least 2 views and 1 event to place the views in time (or a times.txt), got 1 views and 4 events",
            ],
        },
        Case {
            name: "validation: an image missing",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf_validation)),
                ("scene/validation/rgb/r_00001.png", Rm),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/validation/rgb: expected 2 PNG images, one per pose file, got 1 images",
            ],
        },
        Case {
            name: "validation: truncated image",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf_validation)),
                ("scene/validation/rgb/r_00001.png", Half),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "image scene/validation/rgb/r_00001.png: expected valid PNG data, got a decoding error",
            ],
        },
        Case {
            name: "validation: images of two sizes",
            files: &[
                EVENTS_X,
                ("scene", S(eventnerf_validation)),
                ("scene/validation/rgb/r_00001.png", B(rgb_12x10)),
            ],
            args: RUN_X,
            code: 1,
            expect: &[
                "scene/validation/rgb/r_00001.png: expected the size of scene/validation/rgb/r_00000.png, 346×260, got 12×10",
            ],
        },
        Case {
            name: "data: the path is a file",
            files: &[EVENTS_X, ("scene", T("not a folder\n"))],
            args: RUN_X,
            code: 1,
            expect: &[
                "[data] path: no EventNeRF scene folder at scene",
                "Set data.path",
            ],
        },
        Case {
            name: "data: no such split",
            files: &[EVENTS_X, ("scene", S(eventnerf))],
            args: &["run", "x.toml", "--set", "data.split=\"test\""],
            code: 1,
            expect: &["cannot read scene/test/pose: No such file or directory"],
        },
        Case {
            name: "experiment: calibration of a recording",
            files: &[EVENTS_X, ("scene", S(eventnerf))],
            args: &["run", "x.toml", "--set", "experiment.kind=\"calibration\""],
            code: 1,
            expect: &[
                "[experiment] kind = \"calibration\" needs [data] source = \"synthetic\": a recording's own turntable axis is not known",
            ],
        },
    ];
    check_all("eventnerf", &cases);
}
