//! EventNeRF's dataset folders (the NeRF++ layout of `data_loader_split.py`), read into and
//! written from one [`EventNerfScene`].
//!
//! # Layout
//!
//! ```text
//! <scene>/<split>/pose/*.txt        one 4×4 camera-to-world matrix per view (OpenCV axes)
//! <scene>/<split>/intrinsics/*.txt  per view: 4×4 with K top-left, or 5×4 with [k1 k2 · ·] last
//! <scene>/<split>/events/*.npz      exactly one file with arrays x, y, t, p
//! <scene>/<split>/times.txt         (cpose) one time per view, seconds; optional
//! <scene>/validation/pose, intrinsics, rgb/*.png, times.txt   held-out views (optional)
//! ```
//!
//! Views are the files sorted by name. Numbers are whitespace-separated. Poses are OpenCV
//! camera-to-world (`world_from_camera`, x right, y down, z forward) as in EventNeRF, so no axes
//! are converted; the pixel-centre convention (`K⁻¹ [x + ½, y + ½, 1]`) is EventNeRF's and
//! [`PinholeCamera`]'s.
//!
//! # Time
//!
//! EventNeRF places view `i` of `K` at `i/(K − 1) · max(t)`, uniform over the sequence, with
//! the events' time origin at view 0. Without `times.txt` the reader does the same (with
//! `max(t)` the last event's time); `times.txt` — which EventNeRF ignores — states the view
//! times exactly, and the writer always writes it.
//!
//! # Sensor size
//!
//! The layout does not store it (EventNeRF hard-codes 346 × 260). The reader takes it from
//! [`EventNerfOptions::sensor`], else from the held-out images, else 346 × 260.

use std::path::{Path, PathBuf};

use cpose_core::Timestamp;
use cpose_nerf::camera::PinholeCamera;
use cpose_nerf::data::isometry_from_rt;
use cpose_nerf::image::Image;
use nalgebra::{Isometry3, Matrix3, Vector3};

use crate::error::EventsError;
use crate::format::{LoadReport, ReadOptions, TimeUnit, secs_string};
use crate::npz::{read_events_npz, write_events_npz};
use crate::stream::EventStream;
use crate::text::parse_secs_to_nanos;

/// EventNeRF's sensor, the DAVIS346: width.
pub const DAVIS346_WIDTH: u16 = 346;
/// EventNeRF's sensor, the DAVIS346: height.
pub const DAVIS346_HEIGHT: u16 = 260;

/// The relative difference below which two views' intrinsics count as equal (files store
/// rounded decimals).
const INTRINSICS_TOLERANCE: f64 = 1e-9;

/// How far the last row of a pose file may be from `0 0 0 1`.
const POSE_LAST_ROW_TOLERANCE: f64 = 1e-6;

/// A held-out view with its ground-truth image (the `validation` split).
#[derive(Clone, Debug, PartialEq)]
pub struct HeldOutView {
    /// File stem, e.g. `r_00003`.
    pub name: String,
    /// Its time since view 0, when `times.txt` gives it.
    pub time: Option<Timestamp>,
    /// `world_from_camera`, OpenCV axes.
    pub world_from_camera: Isometry3<f64>,
    /// The ground-truth RGB image.
    pub image: Image,
}

/// Everything EventNeRF training needs: the events, the views (poses and times) that delimit
/// the event windows, one camera, and held-out views to evaluate on.
#[derive(Clone, Debug, PartialEq)]
pub struct EventNerfScene {
    /// The events, time origin at view 0.
    pub events: EventStream,
    /// File stems of the views, e.g. `r_00000` (sorted).
    pub view_names: Vec<String>,
    /// `world_from_camera` of each view, OpenCV axes.
    pub world_from_camera: Vec<Isometry3<f64>>,
    /// Time of each view since view 0 (non-decreasing).
    pub view_times: Vec<Timestamp>,
    /// The pinhole camera, sized as the event sensor.
    pub camera: PinholeCamera,
    /// Radial distortion `[k1, k2]` (EventNeRF undistorts `x / (1 + k1 r² + k2 r⁴)`); zero for
    /// synthetic data.
    pub distortion: [f64; 2],
    /// Held-out views with images (may be empty).
    pub held_out: Vec<HeldOutView>,
}

/// Where and how to read an EventNeRF scene.
#[derive(Clone, Debug, PartialEq)]
pub struct EventNerfOptions {
    /// The split with the events, `train` (or e.g. `angle2`).
    pub split: String,
    /// The split with held-out views and images; read when the folder exists.
    pub held_out_split: Option<String>,
    /// Sensor `(width, height)`; `None`: the held-out images' size, else 346 × 260.
    pub sensor: Option<(u16, u16)>,
    /// Unit of the events' `t` array.
    pub time_unit: TimeUnit,
}

impl Default for EventNerfOptions {
    fn default() -> Self {
        Self {
            split: "train".to_owned(),
            held_out_split: Some("validation".to_owned()),
            sensor: None,
            time_unit: TimeUnit::Seconds,
        }
    }
}

/// The poses, intrinsics and optional times of one split.
struct Views {
    names: Vec<String>,
    world_from_camera: Vec<Isometry3<f64>>,
    /// `(fx, fy, cx, cy)` and `[k1, k2]`, equal for every view.
    intrinsics: ([f64; 4], [f64; 2]),
    times: Option<Vec<Timestamp>>,
}

fn read_err(path: &Path) -> impl Fn(std::io::Error) -> EventsError + '_ {
    move |error| EventsError::Read {
        path: path.to_path_buf(),
        error,
    }
}

fn write_err(path: &Path) -> impl Fn(std::io::Error) -> EventsError + '_ {
    move |error| EventsError::Write {
        path: path.to_path_buf(),
        error,
    }
}

/// The files of `folder` with extension `ext` (any case), sorted by name; an error if the folder
/// is missing.
fn list_files(folder: &Path, ext: &str) -> Result<Vec<PathBuf>, EventsError> {
    let mut paths = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(read_err(folder))? {
        let path = entry.map_err(read_err(folder))?.path();
        let matches = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case(ext));
        if matches && path.is_file() {
            paths.push(path);
        }
    }
    paths.sort();
    Ok(paths)
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The whitespace-separated numbers of a text file.
fn read_numbers(path: &Path) -> Result<Vec<f64>, EventsError> {
    let text = std::fs::read_to_string(path).map_err(read_err(path))?;
    text.split_whitespace()
        .map(|tok| {
            tok.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    EventsError::format(path, None, "finite numbers", format!("{tok:?}"))
                })
        })
        .collect()
}

/// A 4×4 camera-to-world matrix file as `world_from_camera`.
fn read_pose(path: &Path) -> Result<Isometry3<f64>, EventsError> {
    let m = read_numbers(path)?;
    if m.len() != 16 {
        return Err(EventsError::format(
            path,
            None,
            "16 numbers (a 4×4 camera-to-world matrix)",
            format!("{} numbers", m.len()),
        ));
    }
    let last = [m[12], m[13], m[14], m[15]];
    let ideal = [0.0, 0.0, 0.0, 1.0];
    if last
        .iter()
        .zip(ideal)
        .any(|(a, b)| (a - b).abs() > POSE_LAST_ROW_TOLERANCE)
    {
        return Err(EventsError::format(
            path,
            None,
            "last row 0 0 0 1",
            format!("{last:?}"),
        ));
    }
    let rotation = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    let translation = Vector3::new(m[3], m[7], m[11]);
    Ok(isometry_from_rt(
        rotation,
        translation,
        path,
        "the camera-to-world matrix",
    )?)
}

/// An intrinsics file: `(fx, fy, cx, cy)` and `[k1, k2]`.
fn read_intrinsics(path: &Path) -> Result<([f64; 4], [f64; 2]), EventsError> {
    let m = read_numbers(path)?;
    if m.len() != 16 && m.len() != 20 {
        return Err(EventsError::format(
            path,
            None,
            "16 or 20 numbers (a 4×4 matrix with K top-left, or 5×4 with distortion last)",
            format!("{} numbers", m.len()),
        ));
    }
    let (fx, skew, cx, fy, cy) = (m[0], m[1], m[2], m[5], m[6]);
    let third = [m[8], m[9], m[10]];
    if skew != 0.0 || m[4] != 0.0 || third != [0.0, 0.0, 1.0] || !(fx > 0.0 && fy > 0.0) {
        return Err(EventsError::format(
            path,
            None,
            "K = [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0 in the top-left 3×3",
            format!(
                "rows [{} {} {}; {} {} {}; {} {} {}]",
                m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]
            ),
        ));
    }
    let distortion = if m.len() == 20 {
        [m[16], m[17]]
    } else {
        [0.0; 2]
    };
    Ok(([fx, fy, cx, cy], distortion))
}

/// `times.txt` of a split with `n` views, if present.
fn read_times(path: &Path, n: usize) -> Result<Option<Vec<Timestamp>>, EventsError> {
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(read_err(path))?;
    let mut times = Vec::with_capacity(n);
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let place = || Some(format!("line {}", k + 1));
        let ns = parse_secs_to_nanos(line).ok_or_else(|| {
            EventsError::format(path, place(), "a time in seconds", format!("{line:?}"))
        })?;
        if times
            .last()
            .is_some_and(|&prev: &Timestamp| ns < prev.as_nanos())
        {
            return Err(EventsError::format(
                path,
                place(),
                "non-decreasing view times",
                format!("{line} s"),
            ));
        }
        times.push(Timestamp::from_nanos(ns));
    }
    if times.len() != n {
        return Err(EventsError::format(
            path,
            None,
            format!("{n} view times, one per pose file"),
            format!("{} times", times.len()),
        ));
    }
    Ok(Some(times))
}

/// The views of a split folder: poses, intrinsics (equal for all), times.
fn read_views(split_dir: &Path) -> Result<Views, EventsError> {
    let pose_dir = split_dir.join("pose");
    let intr_dir = split_dir.join("intrinsics");
    let pose_files = list_files(&pose_dir, "txt")?;
    let intr_files = list_files(&intr_dir, "txt")?;
    if pose_files.is_empty() || pose_files.len() != intr_files.len() {
        return Err(EventsError::format(
            &intr_dir,
            None,
            format!(
                "one intrinsics file per pose file ({} in {}), at least one",
                pose_files.len(),
                pose_dir.display()
            ),
            format!("{} files", intr_files.len()),
        ));
    }
    let world_from_camera = pose_files
        .iter()
        .map(|p| read_pose(p))
        .collect::<Result<Vec<_>, _>>()?;
    let first = read_intrinsics(&intr_files[0])?;
    for path in &intr_files[1..] {
        let other = read_intrinsics(path)?;
        let a = first.0.iter().chain(&first.1);
        let b = other.0.iter().chain(&other.1);
        let differ = a
            .zip(b)
            .any(|(a, b)| (a - b).abs() > INTRINSICS_TOLERANCE * a.abs().max(b.abs()).max(1.0));
        if differ {
            return Err(EventsError::format(
                path,
                None,
                format!("the intrinsics of {}", intr_files[0].display()),
                "different values (one camera per split is supported)",
            ));
        }
    }
    let names: Vec<String> = pose_files.iter().map(|p| stem(p)).collect();
    let times = read_times(&split_dir.join("times.txt"), names.len())?;
    Ok(Views {
        names,
        world_from_camera,
        intrinsics: first,
        times,
    })
}

/// Reads the scene in `scene_dir` (see the [module docs](self)): the views and events of
/// `options.split`, and the held-out views of `options.held_out_split` if that folder exists.
/// Returns the scene and the events' [`LoadReport`].
///
/// Errors name the file: missing folders, not exactly one `.npz`, a pose that is not a rigid
/// 4×4 matrix, intrinsics that are not a pinhole `K` or differ between views, a `times.txt`
/// that does not give one non-decreasing time per view, held-out images missing or of another
/// size, no event on the sensor, and every event-file error of [`read_events_npz`]. Without
/// `times.txt`, at least two views are needed to place the views in time.
pub fn read_eventnerf(
    scene_dir: &Path,
    options: &EventNerfOptions,
) -> Result<(EventNerfScene, LoadReport), EventsError> {
    let split_dir = scene_dir.join(&options.split);
    let views = read_views(&split_dir)?;
    let ([fx, fy, cx, cy], distortion) = views.intrinsics;

    let mut held_out = Vec::new();
    let mut image_size = None;
    if let Some(name) = &options.held_out_split {
        let dir = scene_dir.join(name);
        if dir.is_dir() {
            let hv = read_views(&dir)?;
            let rgb_dir = dir.join("rgb");
            let images = list_files(&rgb_dir, "png")?;
            if images.len() != hv.names.len() {
                return Err(EventsError::format(
                    &rgb_dir,
                    None,
                    format!("{} PNG images, one per pose file", hv.names.len()),
                    format!("{} images", images.len()),
                ));
            }
            for (k, path) in images.iter().enumerate() {
                let image = Image::load(path)?;
                let size = (image.width(), image.height());
                match image_size {
                    None => image_size = Some((size, path.clone())),
                    Some((first, ref first_path)) if first != size => {
                        return Err(EventsError::format(
                            path,
                            None,
                            format!(
                                "the size of {}, {}×{}",
                                first_path.display(),
                                first.0,
                                first.1
                            ),
                            format!("{}×{}", size.0, size.1),
                        ));
                    }
                    Some(_) => {}
                }
                held_out.push(HeldOutView {
                    name: hv.names[k].clone(),
                    time: hv.times.as_ref().map(|t| t[k]),
                    world_from_camera: hv.world_from_camera[k],
                    image,
                });
            }
        }
    }

    let (width, height) = match (options.sensor, &image_size) {
        (Some(size), _) => size,
        (None, Some(((w, h), path))) => (
            u16::try_from(*w).map_err(|_| {
                EventsError::format(
                    path,
                    None,
                    "an image narrower than 65536 pixels",
                    w.to_string(),
                )
            })?,
            u16::try_from(*h).map_err(|_| {
                EventsError::format(
                    path,
                    None,
                    "an image lower than 65536 pixels",
                    h.to_string(),
                )
            })?,
        ),
        (None, None) => (DAVIS346_WIDTH, DAVIS346_HEIGHT),
    };
    if let Some(((w, h), path)) = &image_size
        && (*w, *h) != (usize::from(width), usize::from(height))
    {
        return Err(EventsError::format(
            path,
            None,
            format!("held-out images of the sensor's size {width}×{height}"),
            format!("{w}×{h}"),
        ));
    }

    let events_dir = split_dir.join("events");
    let npz_files = list_files(&events_dir, "npz")?;
    let [npz] = npz_files.as_slice() else {
        return Err(EventsError::format(
            &events_dir,
            None,
            "exactly one .npz file",
            format!("{} files", npz_files.len()),
        ));
    };
    let read_options = ReadOptions::new(width, height).with_time_unit(options.time_unit);
    let (events, report) = read_events_npz(npz, &read_options)?;
    if events.is_empty() {
        return Err(EventsError::format(
            npz,
            None,
            format!("events on the {width}×{height} sensor"),
            format!("none ({report})"),
        ));
    }

    let k = views.names.len();
    let view_times = match views.times {
        Some(times) => times,
        None => {
            let last = events.time_span().map(|(_, last)| last.as_nanos());
            let (Some(last), true) = (last, k >= 2) else {
                return Err(EventsError::format(
                    &split_dir,
                    None,
                    "at least 2 views and 1 event to place the views in time (or a times.txt)",
                    format!("{k} views and {} events", events.len()),
                ));
            };
            // EventNeRF: view i at i/(K − 1) · max(t), rounded to the nanosecond (halves up);
            // between 0 and `last`, so the cast back to i64 is exact.
            let den = (k - 1) as i128;
            (0..k)
                .map(|i| {
                    let num = i as i128 * i128::from(last);
                    Timestamp::from_nanos((2 * num + den).div_euclid(2 * den) as i64)
                })
                .collect()
        }
    };
    let camera = PinholeCamera {
        width: usize::from(width),
        height: usize::from(height),
        fx,
        fy,
        cx,
        cy,
    };
    Ok((
        EventNerfScene {
            events,
            view_names: views.names,
            world_from_camera: views.world_from_camera,
            view_times,
            camera,
            distortion,
            held_out,
        },
        report,
    ))
}

/// A 4×4 matrix as four lines of four numbers (shortest decimals that read back exactly).
fn matrix_text(rows: [[f64; 4]; 4]) -> String {
    rows.iter()
        .map(|r| format!("{} {} {} {}\n", r[0], r[1], r[2], r[3]))
        .collect()
}

fn pose_text(pose: &Isometry3<f64>) -> String {
    let m = pose.to_homogeneous();
    matrix_text(std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])))
}

fn intrinsics_text(camera: &PinholeCamera, distortion: [f64; 2]) -> String {
    let mut text = matrix_text([
        [camera.fx, 0.0, camera.cx, 0.0],
        [0.0, camera.fy, camera.cy, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]);
    if distortion != [0.0; 2] {
        text.push_str(&format!("{} {} 0 0\n", distortion[0], distortion[1]));
    }
    text
}

/// Creates `dir`, which must not exist or be empty (so that no stale views remain).
fn create_empty_dir(dir: &Path) -> Result<(), EventsError> {
    if dir.exists() {
        let mut entries = std::fs::read_dir(dir).map_err(read_err(dir))?;
        if entries.next().is_some() {
            return Err(EventsError::format(
                dir,
                None,
                "a new or empty folder (views of an older scene would mix in)",
                "a folder with files",
            ));
        }
    }
    std::fs::create_dir_all(dir).map_err(write_err(dir))
}

/// Writes the views of one split; `times` one per view.
fn write_views(
    split_dir: &Path,
    names: &[String],
    poses: &[Isometry3<f64>],
    times: Option<&[Timestamp]>,
    camera: &PinholeCamera,
    distortion: [f64; 2],
) -> Result<(), EventsError> {
    create_empty_dir(split_dir)?;
    let (pose_dir, intr_dir) = (split_dir.join("pose"), split_dir.join("intrinsics"));
    for dir in [&pose_dir, &intr_dir] {
        std::fs::create_dir_all(dir).map_err(write_err(dir))?;
    }
    let intrinsics = intrinsics_text(camera, distortion);
    for (name, pose) in names.iter().zip(poses) {
        let path = pose_dir.join(format!("{name}.txt"));
        cpose_core::fs::write_atomic(&path, pose_text(pose)).map_err(write_err(&path))?;
        let path = intr_dir.join(format!("{name}.txt"));
        cpose_core::fs::write_atomic(&path, &intrinsics).map_err(write_err(&path))?;
    }
    if let Some(times) = times {
        let path = split_dir.join("times.txt");
        let text: String = times
            .iter()
            .map(|t| secs_string(t.as_nanos()) + "\n")
            .collect();
        cpose_core::fs::write_atomic(&path, text).map_err(write_err(&path))?;
    }
    Ok(())
}

/// Writes `scene` into `scene_dir` in the layout of the [module docs](self): the views and
/// events in `train/` (events as `events/events.npz`, `t` in seconds), the held-out views with
/// their images in `validation/` (when there are any). Both folders must be new or empty.
///
/// Errors if the scene's vectors disagree in length, a held-out view lacks a time while another
/// has one, or a file cannot be written.
pub fn write_eventnerf(scene_dir: &Path, scene: &EventNerfScene) -> Result<(), EventsError> {
    let n = scene.view_names.len();
    if scene.world_from_camera.len() != n || scene.view_times.len() != n {
        return Err(EventsError::Invalid {
            key: "scene.view_names",
            expected: "one name, pose and time per view",
            found: format!(
                "{n} names, {} poses, {} times",
                scene.world_from_camera.len(),
                scene.view_times.len()
            ),
        });
    }
    let train = scene_dir.join("train");
    write_views(
        &train,
        &scene.view_names,
        &scene.world_from_camera,
        Some(&scene.view_times),
        &scene.camera,
        scene.distortion,
    )?;
    let events_dir = train.join("events");
    std::fs::create_dir_all(&events_dir).map_err(write_err(&events_dir))?;
    write_events_npz(
        &events_dir.join("events.npz"),
        &scene.events,
        TimeUnit::Seconds,
    )?;

    if scene.held_out.is_empty() {
        return Ok(());
    }
    let times: Option<Vec<Timestamp>> = scene.held_out.iter().map(|v| v.time).collect();
    if times.is_none() && scene.held_out.iter().any(|v| v.time.is_some()) {
        return Err(EventsError::Invalid {
            key: "scene.held_out",
            expected: "a time for every held-out view or for none",
            found: "some with and some without".to_owned(),
        });
    }
    let validation = scene_dir.join("validation");
    let names: Vec<String> = scene.held_out.iter().map(|v| v.name.clone()).collect();
    let poses: Vec<Isometry3<f64>> = scene.held_out.iter().map(|v| v.world_from_camera).collect();
    write_views(
        &validation,
        &names,
        &poses,
        times.as_deref(),
        &scene.camera,
        scene.distortion,
    )?;
    let rgb = validation.join("rgb");
    std::fs::create_dir_all(&rgb).map_err(write_err(&rgb))?;
    for view in &scene.held_out {
        view.image
            .save_png(rgb.join(format!("{}.png", view.name)))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn temp_dir(name: &str) -> cpose_core::testing::TempDir {
        cpose_core::testing::TempDir::new(&format!("eventnerf-{name}"))
    }

    fn pose(i: usize) -> Isometry3<f64> {
        let angle = 0.3 * i as f64;
        Isometry3::from_parts(
            Translation3::new(angle.cos() * 4.0, angle.sin() * 4.0, 1.0 / 3.0),
            UnitQuaternion::from_euler_angles(0.1 * i as f64, -0.7, angle),
        )
    }

    /// A small scene: 5 views over 2 s, 4 events, 2 held-out views with 8-bit exact images.
    fn scene() -> EventNerfScene {
        let events = EventStream::from_columns(
            8,
            6,
            vec![0, 400_000_001, 1_000_000_000, 1_999_999_999],
            vec![0, 7, 3, 2],
            vec![0, 5, 1, 4],
            vec![1, -1, 1, 1],
        )
        .unwrap();
        let camera = PinholeCamera {
            width: 8,
            height: 6,
            fx: 7.25,
            fy: 7.5,
            cx: 4.0,
            cy: 3.1,
        };
        let image = |k: usize| Image::from_fn(8, 6, |x, y| [((x + y + k) % 256) as f32 / 255.0; 3]);
        EventNerfScene {
            events,
            view_names: (0..5).map(|i| format!("r_{i:05}")).collect(),
            world_from_camera: (0..5).map(pose).collect(),
            view_times: (0..5)
                .map(|i| Timestamp::from_nanos(i * 500_000_000))
                .collect(),
            camera,
            distortion: [0.0; 2],
            held_out: (0..2)
                .map(|k| HeldOutView {
                    name: format!("r_{k:05}"),
                    time: Some(Timestamp::from_nanos(
                        250_000_000 + 1_000_000_000 * k as i64,
                    )),
                    world_from_camera: pose(10 + k),
                    image: image(k),
                })
                .collect(),
        }
    }

    #[test]
    fn scenes_round_trip_through_the_folder_layout() {
        let dir = temp_dir("roundtrip");
        let original = scene();
        write_eventnerf(&dir, &original).unwrap();
        for sub in [
            "train/pose/r_00004.txt",
            "train/intrinsics/r_00000.txt",
            "train/events/events.npz",
            "train/times.txt",
            "validation/rgb/r_00001.png",
            "validation/pose/r_00001.txt",
        ] {
            assert!(dir.join(sub).is_file(), "{sub}");
        }
        // The sensor size comes from the held-out images.
        let (back, report) = read_eventnerf(&dir, &EventNerfOptions::default()).unwrap();
        assert_eq!(report.events_read, 4);
        assert_eq!(back.events, original.events);
        assert_eq!(back.view_names, original.view_names);
        assert_eq!(back.view_times, original.view_times);
        assert_eq!(back.camera, original.camera);
        assert_eq!(back.distortion, [0.0; 2]);
        for (a, b) in back
            .world_from_camera
            .iter()
            .zip(&original.world_from_camera)
        {
            assert!((a.to_homogeneous() - b.to_homogeneous()).amax() < 1e-15);
        }
        assert_eq!(back.held_out.len(), 2);
        for (a, b) in back.held_out.iter().zip(&original.held_out) {
            assert_eq!((&a.name, a.time), (&b.name, b.time));
            assert!(
                a.image
                    .data()
                    .iter()
                    .zip(b.image.data())
                    .all(|(u, v)| (u - v).abs() < 1e-6)
            );
            assert!(
                (a.world_from_camera.to_homogeneous() - b.world_from_camera.to_homogeneous())
                    .amax()
                    < 1e-15
            );
        }
        // A pose file is the 4×4 camera-to-world matrix, last row 0 0 0 1.
        let text = std::fs::read_to_string(dir.join("train/pose/r_00000.txt")).unwrap();
        assert_eq!(text.lines().count(), 4);
        assert!(text.ends_with("0 0 0 1\n"), "{text}");
        let intr = std::fs::read_to_string(dir.join("train/intrinsics/r_00000.txt")).unwrap();
        assert_eq!(intr, "7.25 0 4 0\n0 7.5 3.1 0\n0 0 1 0\n0 0 0 1\n");
        // Writing again into the same folder is refused.
        let err = write_eventnerf(&dir, &original).unwrap_err().to_string();
        assert!(
            err.contains("train: expected a new or empty folder"),
            "{err}"
        );
    }

    #[test]
    fn without_times_views_are_spread_as_eventnerf_does() {
        let dir = temp_dir("notimes");
        let mut s = scene();
        s.held_out.clear();
        s.distortion = [-0.1, 0.02];
        write_eventnerf(&dir, &s).unwrap();
        std::fs::remove_file(dir.join("train/times.txt")).unwrap();
        // No held-out images and no size given: EventNeRF's DAVIS346.
        let (back, _) = read_eventnerf(&dir, &EventNerfOptions::default()).unwrap();
        assert_eq!((back.camera.width, back.camera.height), (346, 260));
        let options = EventNerfOptions {
            sensor: Some((8, 6)),
            ..Default::default()
        };
        let (back, _) = read_eventnerf(&dir, &options).unwrap();
        // i/(K − 1) · max(t), max(t) = 1.999999999 s.
        let expected: Vec<i64> = vec![0, 500_000_000, 1_000_000_000, 1_499_999_999, 1_999_999_999];
        let got: Vec<i64> = back.view_times.iter().map(|t| t.as_nanos()).collect();
        assert_eq!(got, expected);
        assert_eq!(back.distortion, [-0.1, 0.02]);
        assert!(back.held_out.is_empty());
    }

    #[test]
    fn bad_folders_are_errors_naming_the_file() {
        let dir = temp_dir("bad");
        write_eventnerf(&dir, &scene()).unwrap();
        let opts = EventNerfOptions::default();
        let message = |dir: &Path| {
            let m = read_eventnerf(dir, &opts).unwrap_err().to_string();
            assert_eq!(m.lines().count(), 1, "{m}");
            m
        };
        let train = dir.join("train");
        // A pose that is not rigid, of the wrong size, with a bad last row, with a word.
        let pose_path = train.join("pose/r_00002.txt");
        let good_pose = std::fs::read_to_string(&pose_path).unwrap();
        for (text, needle) in [
            ("2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "a rotation"),
            (
                "1 0 0\n0 1 0\n0 0 1\n",
                "expected 16 numbers (a 4×4 camera-to-world matrix), got 9 numbers",
            ),
            (
                "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n",
                "expected last row 0 0 0 1",
            ),
            (
                "1 0 0 0\n0 one 0 0\n0 0 1 0\n0 0 0 1\n",
                "expected finite numbers, got \"one\"",
            ),
        ] {
            std::fs::write(&pose_path, text).unwrap();
            let m = message(&dir);
            assert!(m.contains("r_00002.txt") && m.contains(needle), "{m}");
        }
        std::fs::write(&pose_path, good_pose).unwrap();
        // Intrinsics that differ between views, and that are not a pinhole K.
        let intr_path = train.join("intrinsics/r_00003.txt");
        let good_intr = std::fs::read_to_string(&intr_path).unwrap();
        std::fs::write(&intr_path, good_intr.replace("7.25", "7.5")).unwrap();
        let m = message(&dir);
        assert!(
            m.contains("r_00003.txt: expected the intrinsics of") && m.contains("r_00000.txt"),
            "{m}"
        );
        std::fs::write(&intr_path, good_intr.replace("7.25 0", "7.25 0.5")).unwrap();
        assert!(message(&dir).contains("expected K = [fx 0 cx; 0 fy cy; 0 0 1]"));
        std::fs::write(&intr_path, &good_intr).unwrap();
        // A missing intrinsics file.
        std::fs::remove_file(&intr_path).unwrap();
        let m = message(&dir);
        assert!(
            m.contains("intrinsics: expected one intrinsics file per pose file (5 in"),
            "{m}"
        );
        std::fs::write(&intr_path, &good_intr).unwrap();
        // times.txt with a missing line, out of order.
        let times = train.join("times.txt");
        let good_times = std::fs::read_to_string(&times).unwrap();
        std::fs::write(&times, "0\n0.5\n1\n").unwrap();
        assert!(
            message(&dir)
                .contains("times.txt: expected 5 view times, one per pose file, got 3 times")
        );
        std::fs::write(&times, "0\n0.5\n0.4\n1\n2\n").unwrap();
        assert!(message(&dir).contains("times.txt: line 3: expected non-decreasing view times"));
        std::fs::write(&times, &good_times).unwrap();
        // Two npz files, none.
        let events = train.join("events");
        std::fs::copy(events.join("events.npz"), events.join("more.npz")).unwrap();
        assert!(message(&dir).contains("events: expected exactly one .npz file, got 2 files"));
        std::fs::remove_file(events.join("more.npz")).unwrap();
        // A held-out image missing, of another size.
        let rgb = dir.join("validation/rgb/r_00001.png");
        let png = std::fs::read(&rgb).unwrap();
        std::fs::remove_file(&rgb).unwrap();
        assert!(message(&dir).contains("expected 2 PNG images, one per pose file, got 1 images"));
        Image::from_fn(4, 6, |_, _| [0.5; 3])
            .save_png(&rgb)
            .unwrap();
        assert!(message(&dir).contains("r_00001.png: expected the size of"));
        std::fs::write(&rgb, png).unwrap();
        // A sensor size that the held-out images contradict.
        let err = read_eventnerf(
            &dir,
            &EventNerfOptions {
                sensor: Some((4, 4)),
                ..opts.clone()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("expected held-out images of the sensor's size 4×4, got 8×6"),
            "{err}"
        );
        // A missing split.
        let m = read_eventnerf(
            &dir,
            &EventNerfOptions {
                split: "angle2".into(),
                ..opts.clone()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(m.starts_with("cannot read") && m.contains("angle2"), "{m}");
        assert!(read_eventnerf(&dir, &opts).is_ok());
    }
}
