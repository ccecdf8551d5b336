//! COLMAP sparse models (`sparse/0/` of a COLMAP reconstruction): the cameras, the registered
//! images with their poses and 2-D keypoints, and the triangulated 3-D points with their tracks,
//! read by [`read_colmap_model`] and written by [`write_colmap_model`].
//!
//! # Files
//!
//! A model is three files in one folder, each binary (`.bin`, little-endian) or text (`.txt`):
//! `cameras`, `images` and `points3D`. The reader picks the format per file and prefers `.bin`
//! when both exist. `cameras` is required; `images` and `points3D` may be missing, and then the
//! model's [`ColmapModel::images`] / [`ColmapModel::points`] is `None` (a present but empty file
//! is `Some(vec![])`).
//!
//! Binary layout (every count is a `u64` followed by that many records):
//!
//! * `cameras.bin`: per camera `u32 id, i32 model_id, u64 width, u64 height, f64 × n_params`;
//! * `images.bin`: per image `u32 id, f64 qw qx qy qz, f64 tx ty tz, u32 camera_id`, the name as
//!   UTF-8 bytes ending in a NUL, `u64 n_points2D`, then per keypoint `f64 x, f64 y,
//!   i64 point3D_id` (`−1`: not triangulated);
//! * `points3D.bin`: per point `u64 id, f64 x y z, u8 r g b, f64 error, u64 track_length`, then
//!   per track element `u32 image_id, u32 point2D_idx`.
//!
//! COLMAP writes the 32-bit ids as `uint32`; its Python script reads them as `int32`. The bytes
//! agree for every id below 2³¹; this module reads and writes `u32`.
//!
//! Text: lines starting with `#` are comments and blank lines are skipped; fields are separated
//! by whitespace; CRLF line ends and trailing whitespace are accepted.
//!
//! * `cameras.txt`: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS...` (the model by name);
//! * `images.txt`: two lines per image, `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` (the name
//!   is the rest of the line) and then the keypoints as `X Y POINT3D_ID` triples; that second
//!   line is always the one right after the first and may be empty;
//! * `points3D.txt`: `POINT3D_ID X Y Z R G B ERROR (IMAGE_ID POINT2D_IDX)...`.
//!
//! # Conventions
//!
//! * On disk a pose is **camera-from-world**, `x_cam = R(q) x_world + t`, with the quaternion in
//!   the order **(w, x, y, z)** (Hamilton, real part first). In memory it is
//!   [`ColmapImage::world_from_camera`], the inverse, as everywhere in cpose (CONVENTIONS.md):
//!   its translation is the camera centre in world coordinates.
//! * COLMAP's camera axes are OpenCV's: **x right, y down, z forward** (the viewing direction is
//!   `+z`), which are cpose's, so no axis change is made. A point is in front of a camera when
//!   `world_from_camera⁻¹ · p` has `z > 0`.
//! * The world frame is the reconstruction's own (arbitrary up direction and scale).
//! * Pixel coordinates of keypoints and principal points are COLMAP's: the centre of the top-left
//!   pixel is `(0.5, 0.5)`, as in cpose.
//!
//! # Supported camera models
//!
//! `SIMPLE_PINHOLE (f, cx, cy)`, `PINHOLE (fx, fy, cx, cy)`, `SIMPLE_RADIAL (f, cx, cy, k)` and
//! `RADIAL (f, cx, cy, k1, k2)` ([`CameraModel`]). Any other model (`OPENCV`, `OPENCV_FISHEYE`,
//! `FULL_OPENCV`, `FOV`, `SIMPLE_RADIAL_FISHEYE`, `RADIAL_FISHEYE`, `THIN_PRISM_FISHEYE`, …) is
//! an error naming the file, the camera and the model.
//!
//! # Checks
//!
//! Every error is a [`DataError`] naming the file (and, for text, the line) and what was
//! expected; malformed or hostile input never panics and never makes the reader allocate more
//! than the file's size: each binary count is checked against the bytes left before anything is
//! reserved. Rejected: truncated files and trailing bytes, non-finite numbers, a quaternion whose
//! norm is not within [`QUATERNION_NORM_TOLERANCE`] of 1 (others are normalised), duplicate
//! camera, image or point ids, an image whose camera is not in `cameras`, a name that is not
//! UTF-8, a width or height outside `1..=65535`, a wrong number of parameters, and a focal
//! length that is not positive. Keypoint ↔ track cross-references are not checked (a model may
//! carry images without keypoints, as COLMAP's own exports sometimes do).
//!
//! # Round trips
//!
//! [`write_colmap_model`] writes `f64`s bit-exactly in binary and with the shortest decimal that
//! parses back to the same `f64` in text, so a model written in binary and in text reads back
//! identically from both, and every value except the poses round-trips exactly (binary → text →
//! binary rewrites `cameras.bin` and `points3D.bin` byte for byte). A pose is inverted on the
//! way to and from disk (camera-from-world there, world-from-camera here): its rotation
//! round-trips exactly (a quaternion that is unit to rounding is not renormalised), its
//! translation to the rounding of one rotation, ≈ 1e-16 relative.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::DataError;

/// The largest accepted `|‖q‖ − 1|` of a pose quaternion read from a file (or about to be
/// written); quaternions within it are normalised.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// The largest accepted image width or height.
pub const MAX_IMAGE_SIDE: usize = 65535;

/// A supported COLMAP camera model (COLMAP's model ids 0 to 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CameraModel {
    /// `SIMPLE_PINHOLE`, id 0: `f, cx, cy`.
    SimplePinhole,
    /// `PINHOLE`, id 1: `fx, fy, cx, cy`.
    Pinhole,
    /// `SIMPLE_RADIAL`, id 2: `f, cx, cy, k`.
    SimpleRadial,
    /// `RADIAL`, id 3: `f, cx, cy, k1, k2`.
    Radial,
}

/// COLMAP's other camera models, by id, which this module does not support.
const UNSUPPORTED_MODELS: [(i32, &str); 7] = [
    (4, "OPENCV"),
    (5, "OPENCV_FISHEYE"),
    (6, "FULL_OPENCV"),
    (7, "FOV"),
    (8, "SIMPLE_RADIAL_FISHEYE"),
    (9, "RADIAL_FISHEYE"),
    (10, "THIN_PRISM_FISHEYE"),
];

impl CameraModel {
    /// All supported models, in id order.
    pub const ALL: [CameraModel; 4] = [
        CameraModel::SimplePinhole,
        CameraModel::Pinhole,
        CameraModel::SimpleRadial,
        CameraModel::Radial,
    ];

    /// COLMAP's model id (`model_id` in `cameras.bin`).
    pub fn id(self) -> i32 {
        match self {
            CameraModel::SimplePinhole => 0,
            CameraModel::Pinhole => 1,
            CameraModel::SimpleRadial => 2,
            CameraModel::Radial => 3,
        }
    }

    /// COLMAP's model name (the `MODEL` column of `cameras.txt`).
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::SimplePinhole => "SIMPLE_PINHOLE",
            CameraModel::Pinhole => "PINHOLE",
            CameraModel::SimpleRadial => "SIMPLE_RADIAL",
            CameraModel::Radial => "RADIAL",
        }
    }

    /// The names of the parameters, in COLMAP's order.
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            CameraModel::SimplePinhole => &["f", "cx", "cy"],
            CameraModel::Pinhole => &["fx", "fy", "cx", "cy"],
            CameraModel::SimpleRadial => &["f", "cx", "cy", "k"],
            CameraModel::Radial => &["f", "cx", "cy", "k1", "k2"],
        }
    }

    /// The number of parameters.
    pub fn num_params(self) -> usize {
        self.param_names().len()
    }

    /// The indices of the focal lengths among the parameters (they must be positive).
    fn focal_indices(self) -> &'static [usize] {
        match self {
            CameraModel::Pinhole => &[0, 1],
            _ => &[0],
        }
    }

    /// The model of COLMAP id `id`, if supported.
    pub fn from_id(id: i32) -> Option<CameraModel> {
        Self::ALL.into_iter().find(|m| m.id() == id)
    }

    /// The model named `name` (exactly, as COLMAP spells it), if supported.
    pub fn from_name(name: &str) -> Option<CameraModel> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// `"SIMPLE_PINHOLE (f, cx, cy), PINHOLE (fx, fy, cx, cy), …"`, for error messages.
fn supported_models() -> String {
    CameraModel::ALL
        .iter()
        .map(|m| format!("{} ({})", m.name(), m.param_names().join(", ")))
        .collect::<Vec<_>>()
        .join(", ")
}

/// One camera of `cameras.{bin,txt}`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapCamera {
    /// COLMAP's camera id.
    pub id: u32,
    /// The camera model.
    pub model: CameraModel,
    /// Image width in pixels, `1..=65535`.
    pub width: usize,
    /// Image height in pixels, `1..=65535`.
    pub height: usize,
    /// The model's parameters in COLMAP's order ([`CameraModel::param_names`]).
    pub params: Vec<f64>,
}

/// One registered image of `images.{bin,txt}`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    /// COLMAP's image id.
    pub id: u32,
    /// The id of its camera in [`ColmapModel::cameras`].
    pub camera_id: u32,
    /// The image file name, relative to the image folder of the reconstruction.
    pub name: String,
    /// The pose, OpenCV camera axes (the file stores the inverse, camera-from-world).
    pub world_from_camera: Isometry3<f64>,
    /// The keypoints: pixel position `[x, y]` and the id of the 3-D point it observes, if any.
    pub points2d: Vec<([f64; 2], Option<u64>)>,
}

/// One 3-D point of `points3D.{bin,txt}`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapPoint {
    /// COLMAP's point id.
    pub id: u64,
    /// Position in world coordinates.
    pub xyz: [f64; 3],
    /// Colour.
    pub rgb: [u8; 3],
    /// Mean reprojection error in pixels (COLMAP writes −1 when unknown).
    pub error: f64,
    /// The observations: `(image_id, point2d_idx)`, the index into that image's
    /// [`ColmapImage::points2d`].
    pub track: Vec<(u32, u32)>,
}

/// A COLMAP sparse model. Records keep the files' order.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapModel {
    /// The cameras (always present).
    pub cameras: Vec<ColmapCamera>,
    /// The images; `None` when the folder has neither `images.bin` nor `images.txt`.
    pub images: Option<Vec<ColmapImage>>,
    /// The 3-D points; `None` when the folder has neither `points3D.bin` nor `points3D.txt`.
    pub points: Option<Vec<ColmapPoint>>,
}

impl ColmapModel {
    /// The camera with id `id`.
    pub fn camera(&self, id: u32) -> Option<&ColmapCamera> {
        self.cameras.iter().find(|c| c.id == id)
    }
}

/// The file format [`write_colmap_model`] writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColmapFormat {
    /// `cameras.bin`, `images.bin`, `points3D.bin`.
    Binary,
    /// `cameras.txt`, `images.txt`, `points3D.txt`.
    Text,
}

impl ColmapFormat {
    /// The files' extension, `"bin"` or `"txt"`.
    pub fn extension(self) -> &'static str {
        match self {
            ColmapFormat::Binary => "bin",
            ColmapFormat::Text => "txt",
        }
    }
}

/// The three files' stems.
const CAMERAS: &str = "cameras";
pub(super) const IMAGES: &str = "images";
const POINTS: &str = "points3D";

/// Which file of part `stem` the folder has: `.bin` if it exists, else `.txt`, else none.
pub(super) fn find_part(dir: &Path, stem: &str) -> Option<(PathBuf, ColmapFormat)> {
    [ColmapFormat::Binary, ColmapFormat::Text]
        .into_iter()
        .map(|f| (dir.join(format!("{stem}.{}", f.extension())), f))
        .find(|(p, _)| p.is_file())
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, DataError> {
    std::fs::read(path).map_err(|error| DataError::Io {
        path: path.to_path_buf(),
        error,
    })
}

fn read_text(path: &Path) -> Result<String, DataError> {
    String::from_utf8(read_bytes(path)?).map_err(|e| {
        DataError::format(
            path,
            "UTF-8 text",
            format!(
                "a byte that is not UTF-8 at offset {}",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

/// Reads the COLMAP sparse model in `dir` (see the module docs for the files, formats and
/// checks). `cameras` is required; a missing `images` or `points3D` file gives `None`.
pub fn read_colmap_model(dir: &Path) -> Result<ColmapModel, DataError> {
    if !dir.is_dir() {
        return Err(DataError::format(
            dir,
            "a folder holding a COLMAP sparse model",
            "no such folder",
        ));
    }
    let Some((path, format)) = find_part(dir, CAMERAS) else {
        return Err(DataError::format(
            dir,
            "a COLMAP sparse model with cameras.bin or cameras.txt",
            "neither file",
        ));
    };
    let cameras = match format {
        ColmapFormat::Binary => read_cameras_bin(&path, &read_bytes(&path)?)?,
        ColmapFormat::Text => read_cameras_txt(&path, &read_text(&path)?)?,
    };
    let camera_ids: HashSet<u32> = cameras.iter().map(|c| c.id).collect();
    let images = match find_part(dir, IMAGES) {
        None => None,
        Some((path, ColmapFormat::Binary)) => {
            Some(read_images_bin(&path, &read_bytes(&path)?, &camera_ids)?)
        }
        Some((path, ColmapFormat::Text)) => {
            Some(read_images_txt(&path, &read_text(&path)?, &camera_ids)?)
        }
    };
    let points = match find_part(dir, POINTS) {
        None => None,
        Some((path, ColmapFormat::Binary)) => Some(read_points_bin(&path, &read_bytes(&path)?)?),
        Some((path, ColmapFormat::Text)) => Some(read_points_txt(&path, &read_text(&path)?)?),
    };
    Ok(ColmapModel {
        cameras,
        images,
        points,
    })
}

// ---------------------------------------------------------------------------------------------
// Checks shared by the readers and the writer. `at` says where: "line 4: camera 1" or
// "camera 1 (record 0)".

fn check_camera(cam: &ColmapCamera, path: &Path, at: &str) -> Result<(), DataError> {
    for (side, value) in [("width", cam.width), ("height", cam.height)] {
        if !(1..=MAX_IMAGE_SIDE).contains(&value) {
            return Err(DataError::format(
                path,
                format!("{at}: an image {side} in 1..={MAX_IMAGE_SIDE}"),
                value.to_string(),
            ));
        }
    }
    let model = cam.model;
    if cam.params.len() != model.num_params() {
        return Err(DataError::format(
            path,
            format!(
                "{at}: {} parameters for {} ({})",
                model.num_params(),
                model.name(),
                model.param_names().join(", ")
            ),
            format!("{} parameters", cam.params.len()),
        ));
    }
    for (name, value) in model.param_names().iter().zip(&cam.params) {
        if !value.is_finite() {
            return Err(DataError::format(
                path,
                format!("{at}: a finite parameter {name}"),
                value.to_string(),
            ));
        }
    }
    for &i in model.focal_indices() {
        if cam.params[i] <= 0.0 {
            return Err(DataError::format(
                path,
                format!("{at}: a positive focal length {}", model.param_names()[i]),
                format!("{:?}", cam.params[i]),
            ));
        }
    }
    Ok(())
}

/// The error for a model id or name that is not supported.
/// Checks the camera `(id, model, width, height, params)` read from either format and appends
/// it, refusing a duplicate id. Out-of-range sizes saturate and are then rejected by
/// [`check_camera`].
fn accept_camera(
    cameras: &mut Vec<ColmapCamera>,
    ids: &mut HashSet<u32>,
    (id, model, width, height, params): (u32, CameraModel, u64, u64, Vec<f64>),
    path: &Path,
    at: &str,
) -> Result<(), DataError> {
    let camera = ColmapCamera {
        id,
        model,
        width: usize::try_from(width).unwrap_or(usize::MAX),
        height: usize::try_from(height).unwrap_or(usize::MAX),
        params,
    };
    check_camera(&camera, path, at)?;
    if !ids.insert(id) {
        return Err(duplicate(path, at, "camera", id));
    }
    cameras.push(camera);
    Ok(())
}

fn unsupported_model(path: &Path, at: &str, found: String) -> DataError {
    DataError::format(
        path,
        format!("{at}: a supported camera model: {}", supported_models()),
        found,
    )
}

/// The name of COLMAP model `id` and that it is unsupported, or "an unknown model id".
fn describe_model_id(id: i32) -> String {
    match UNSUPPORTED_MODELS.iter().find(|(i, _)| *i == id) {
        Some((_, name)) => format!("{name} (model id {id}), which is not supported"),
        None => format!("unknown model id {id}"),
    }
}

/// `world_from_camera` from the file's camera-from-world `q = (w, x, y, z)` and `t`.
fn pose_from_disk(
    q: [f64; 4],
    t: [f64; 3],
    path: &Path,
    at: &str,
) -> Result<Isometry3<f64>, DataError> {
    if !q.iter().chain(&t).all(|v| v.is_finite()) {
        return Err(DataError::format(
            path,
            format!("{at}: a finite pose (QW QX QY QZ TX TY TZ)"),
            format!("q = {q:?}, t = {t:?}"),
        ));
    }
    let quaternion = Quaternion::new(q[0], q[1], q[2], q[3]);
    let norm = quaternion.norm();
    // `norm` is not NaN (finite entries), but may overflow to infinity: rejected here.
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(DataError::format(
            path,
            format!(
                "{at}: a unit quaternion (QW QX QY QZ; norm within {QUATERNION_NORM_TOLERANCE} of 1)"
            ),
            format!("norm {norm} (q = {q:?})"),
        ));
    }
    // A quaternion that is unit to rounding is kept bit for bit, so that rotations round-trip
    // exactly; others are normalised.
    let rotation = if (norm - 1.0).abs() <= 4.0 * f64::EPSILON {
        UnitQuaternion::new_unchecked(quaternion)
    } else {
        UnitQuaternion::new_normalize(quaternion)
    };
    let camera_from_world = Isometry3::from_parts(Translation3::from(Vector3::from(t)), rotation);
    Ok(camera_from_world.inverse())
}

/// The file's camera-from-world `(q = (w, x, y, z), t)` of `world_from_camera`.
fn pose_to_disk(world_from_camera: &Isometry3<f64>) -> ([f64; 4], [f64; 3]) {
    let camera_from_world = world_from_camera.inverse();
    let q = camera_from_world.rotation.quaternion();
    let t = camera_from_world.translation.vector;
    ([q.w, q.i, q.j, q.k], [t.x, t.y, t.z])
}

fn check_keypoint(xy: [f64; 2], path: &Path, at: &str) -> Result<(), DataError> {
    if xy.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(DataError::format(
            path,
            format!("{at}: finite keypoint coordinates"),
            format!("{xy:?}"),
        ))
    }
}

fn check_point_values(point: &ColmapPoint, path: &Path, at: &str) -> Result<(), DataError> {
    if point.xyz.iter().all(|v| v.is_finite()) && point.error.is_finite() {
        Ok(())
    } else {
        Err(DataError::format(
            path,
            format!("{at}: finite X Y Z and ERROR"),
            format!("xyz = {:?}, error = {}", point.xyz, point.error),
        ))
    }
}

fn duplicate(path: &Path, at: &str, what: &str, id: impl std::fmt::Display) -> DataError {
    DataError::format(
        path,
        format!("{at}: a {what} id not used before"),
        format!("a second {what} {id}"),
    )
}

fn unknown_camera(path: &Path, at: &str, camera_id: u32) -> DataError {
    DataError::format(
        path,
        format!("{at}: a CAMERA_ID of the model's cameras"),
        format!("camera {camera_id}, which is not in cameras"),
    )
}

// ---------------------------------------------------------------------------------------------
// Binary reading.

/// A cursor over a binary file's bytes; every read checks the bytes left.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn new(path: &'a Path, bytes: &'a [u8]) -> Self {
        Reader {
            bytes,
            pos: 0,
            path,
        }
    }

    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn take<const N: usize>(&mut self, what: &dyn Fn() -> String) -> Result<[u8; N], DataError> {
        let end = self.pos.checked_add(N).filter(|&e| e <= self.bytes.len());
        match end.and_then(|e| self.bytes[self.pos..e].try_into().ok()) {
            Some(array) => {
                self.pos += N;
                Ok(array)
            }
            None => Err(DataError::format(
                self.path,
                format!("{} ({N} bytes at offset {})", what(), self.pos),
                format!(
                    "the end of the file after {} more bytes (truncated?)",
                    self.remaining()
                ),
            )),
        }
    }

    fn u8(&mut self, what: &dyn Fn() -> String) -> Result<u8, DataError> {
        Ok(self.take::<1>(what)?[0])
    }

    fn u32(&mut self, what: &dyn Fn() -> String) -> Result<u32, DataError> {
        self.take(what).map(u32::from_le_bytes)
    }

    fn i32(&mut self, what: &dyn Fn() -> String) -> Result<i32, DataError> {
        self.take(what).map(i32::from_le_bytes)
    }

    fn u64(&mut self, what: &dyn Fn() -> String) -> Result<u64, DataError> {
        self.take(what).map(u64::from_le_bytes)
    }

    fn i64(&mut self, what: &dyn Fn() -> String) -> Result<i64, DataError> {
        self.take(what).map(i64::from_le_bytes)
    }

    fn f64(&mut self, what: &dyn Fn() -> String) -> Result<f64, DataError> {
        self.take(what).map(f64::from_le_bytes)
    }

    fn f64s<const N: usize>(&mut self, what: &dyn Fn() -> String) -> Result<[f64; N], DataError> {
        let mut values = [0.0; N];
        for v in &mut values {
            *v = self.f64(what)?;
        }
        Ok(values)
    }

    /// A `u64` count of records of at least `min_bytes` each, checked against the bytes left
    /// before the caller allocates anything.
    fn count(&mut self, what: &dyn Fn() -> String, min_bytes: usize) -> Result<usize, DataError> {
        let at = self.pos;
        let n = self.u64(&|| format!("the number of {}", what()))?;
        let left = self.remaining();
        let fits = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(min_bytes))
            .is_some_and(|need| need <= left);
        if !fits {
            return Err(DataError::format(
                self.path,
                format!(
                    "the number of {} at offset {at}: at most {} ({left} bytes left, at least \
                     {min_bytes} bytes each)",
                    what(),
                    left / min_bytes
                ),
                n.to_string(),
            ));
        }
        // `n · min_bytes ≤ left` fits in `usize`.
        Ok(n as usize)
    }

    /// Bytes up to a NUL, which is consumed.
    fn nul_terminated(&mut self, what: &dyn Fn() -> String) -> Result<&'a [u8], DataError> {
        let rest = &self.bytes[self.pos..];
        match rest.iter().position(|&b| b == 0) {
            Some(len) => {
                self.pos += len + 1;
                Ok(&rest[..len])
            }
            None => Err(DataError::format(
                self.path,
                format!("{} ending in a NUL byte (from offset {})", what(), self.pos),
                "the end of the file (truncated?)",
            )),
        }
    }

    fn finish(&self, records: usize, what: &str) -> Result<(), DataError> {
        if self.remaining() == 0 {
            Ok(())
        } else {
            Err(DataError::format(
                self.path,
                format!("the end of the file after {records} {what}"),
                format!("{} more bytes", self.remaining()),
            ))
        }
    }
}

/// The smallest record of each binary file (for the count checks).
const MIN_CAMERA_BYTES: usize = 4 + 4 + 8 + 8 + 3 * 8;
const MIN_IMAGE_BYTES: usize = 4 + 7 * 8 + 4 + 1 + 8;
const KEYPOINT_BYTES: usize = 8 + 8 + 8;
const MIN_POINT_BYTES: usize = 8 + 3 * 8 + 3 + 8 + 8;
const TRACK_ELEMENT_BYTES: usize = 4 + 4;

fn read_cameras_bin(path: &Path, bytes: &[u8]) -> Result<Vec<ColmapCamera>, DataError> {
    let mut r = Reader::new(path, bytes);
    let n = r.count(&|| "cameras".to_owned(), MIN_CAMERA_BYTES)?;
    let mut cameras = Vec::with_capacity(n);
    let mut ids = HashSet::with_capacity(n);
    for k in 0..n {
        let id = r.u32(&|| format!("camera record {k}: CAMERA_ID"))?;
        let at = format!("camera {id} (record {k})");
        let model_id = r.i32(&|| format!("{at}: MODEL_ID"))?;
        let model = CameraModel::from_id(model_id)
            .ok_or_else(|| unsupported_model(path, &at, describe_model_id(model_id)))?;
        let width = r.u64(&|| format!("{at}: WIDTH"))?;
        let height = r.u64(&|| format!("{at}: HEIGHT"))?;
        let mut params = Vec::with_capacity(model.num_params());
        for name in model.param_names() {
            params.push(r.f64(&|| format!("{at}: parameter {name}"))?);
        }
        let camera = (id, model, width, height, params);
        accept_camera(&mut cameras, &mut ids, camera, path, &at)?;
    }
    r.finish(n, "cameras")?;
    Ok(cameras)
}

fn read_images_bin(
    path: &Path,
    bytes: &[u8],
    camera_ids: &HashSet<u32>,
) -> Result<Vec<ColmapImage>, DataError> {
    let mut r = Reader::new(path, bytes);
    let n = r.count(&|| "images".to_owned(), MIN_IMAGE_BYTES)?;
    let mut images = Vec::with_capacity(n);
    let mut ids = HashSet::with_capacity(n);
    for k in 0..n {
        let id = r.u32(&|| format!("image record {k}: IMAGE_ID"))?;
        let at = format!("image {id} (record {k})");
        let q = r.f64s::<4>(&|| format!("{at}: QW QX QY QZ"))?;
        let t = r.f64s::<3>(&|| format!("{at}: TX TY TZ"))?;
        let world_from_camera = pose_from_disk(q, t, path, &at)?;
        let camera_id = r.u32(&|| format!("{at}: CAMERA_ID"))?;
        if !camera_ids.contains(&camera_id) {
            return Err(unknown_camera(path, &at, camera_id));
        }
        let name_bytes = r.nul_terminated(&|| format!("{at}: NAME"))?;
        let name = std::str::from_utf8(name_bytes)
            .map_err(|e| {
                DataError::format(
                    path,
                    format!("{at}: a UTF-8 image name"),
                    format!(
                        "a byte that is not UTF-8 at offset {} of {:?}",
                        e.valid_up_to(),
                        String::from_utf8_lossy(name_bytes)
                    ),
                )
            })?
            .to_owned();
        let n_points = r.count(&|| format!("keypoints of {at}"), KEYPOINT_BYTES)?;
        let mut points2d = Vec::with_capacity(n_points);
        for j in 0..n_points {
            let what = || format!("{at}: keypoint {j}");
            let xy = r.f64s::<2>(&what)?;
            let point_id = r.i64(&what)?;
            check_keypoint(xy, path, &what())?;
            points2d.push((xy, point3d_id(point_id, path, &what())?));
        }
        if !ids.insert(id) {
            return Err(duplicate(path, &at, "image", id));
        }
        images.push(ColmapImage {
            id,
            camera_id,
            name,
            world_from_camera,
            points2d,
        });
    }
    r.finish(n, "images")?;
    Ok(images)
}

/// A keypoint's `POINT3D_ID`: `−1` is none, other negatives are errors.
fn point3d_id(id: i64, path: &Path, at: &str) -> Result<Option<u64>, DataError> {
    match id {
        -1 => Ok(None),
        id if id >= 0 => Ok(Some(id as u64)),
        id => Err(DataError::format(
            path,
            format!("{at}: a POINT3D_ID ≥ 0, or −1 for none"),
            id.to_string(),
        )),
    }
}

fn read_points_bin(path: &Path, bytes: &[u8]) -> Result<Vec<ColmapPoint>, DataError> {
    let mut r = Reader::new(path, bytes);
    let n = r.count(&|| "3-D points".to_owned(), MIN_POINT_BYTES)?;
    let mut points = Vec::with_capacity(n);
    let mut ids = HashSet::with_capacity(n);
    for k in 0..n {
        let id = r.u64(&|| format!("point record {k}: POINT3D_ID"))?;
        // Built only when needed: fern has 10⁴ points.
        let at = || format!("point {id} (record {k})");
        let xyz = r.f64s::<3>(&|| format!("{}: X Y Z", at()))?;
        let mut rgb = [0; 3];
        for c in &mut rgb {
            *c = r.u8(&|| format!("{}: R G B", at()))?;
        }
        let error = r.f64(&|| format!("{}: ERROR", at()))?;
        let len = r.count(
            &|| format!("track elements of {}", at()),
            TRACK_ELEMENT_BYTES,
        )?;
        let mut track = Vec::with_capacity(len);
        for _ in 0..len {
            let image_id = r.u32(&|| format!("{}: track IMAGE_ID", at()))?;
            let idx = r.u32(&|| format!("{}: track POINT2D_IDX", at()))?;
            track.push((image_id, idx));
        }
        let point = ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track,
        };
        check_point_values(&point, path, &at())?;
        if !ids.insert(id) {
            return Err(duplicate(path, &at(), "point", id));
        }
        points.push(point);
    }
    r.finish(n, "points")?;
    Ok(points)
}

// ---------------------------------------------------------------------------------------------
// Text reading.

/// The lines of `text` with their 1-based numbers, line ends (LF or CRLF) and trailing
/// whitespace removed.
fn text_lines(text: &str) -> Vec<(usize, &str)> {
    text.split('\n')
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end()))
        .collect()
}

fn is_skipped(line: &str) -> bool {
    let line = line.trim_start();
    line.is_empty() || line.starts_with('#')
}

/// The whitespace-separated fields of one text line, each parsed with its column name.
struct Fields<'a> {
    rest: &'a str,
    path: &'a Path,
    line: usize,
}

impl<'a> Fields<'a> {
    fn new(path: &'a Path, line: usize, text: &'a str) -> Self {
        Fields {
            rest: text.trim_start(),
            path,
            line,
        }
    }

    fn next_token(&mut self) -> Option<&'a str> {
        if self.rest.is_empty() {
            return None;
        }
        let end = self
            .rest
            .find(char::is_whitespace)
            .unwrap_or(self.rest.len());
        let token = &self.rest[..end];
        self.rest = self.rest[end..].trim_start();
        Some(token)
    }

    fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    fn token(&mut self, what: &str) -> Result<&'a str, DataError> {
        self.next_token().ok_or_else(|| {
            DataError::format(
                self.path,
                format!("line {}: {what}", self.line),
                "the end of the line",
            )
        })
    }

    fn parse<T: std::str::FromStr>(&mut self, what: &str, kind: &str) -> Result<T, DataError> {
        let token = self.token(what)?;
        token.parse().map_err(|_| {
            DataError::format(
                self.path,
                format!("line {}: {what} ({kind})", self.line),
                format!("{token:?}"),
            )
        })
    }

    fn f64(&mut self, what: &str) -> Result<f64, DataError> {
        let value: f64 = self.parse(what, "a finite number")?;
        if value.is_finite() {
            Ok(value)
        } else {
            Err(DataError::format(
                self.path,
                format!("line {}: {what} (a finite number)", self.line),
                value.to_string(),
            ))
        }
    }

    /// The rest of the line (trailing whitespace already removed).
    fn rest(&mut self) -> &'a str {
        std::mem::take(&mut self.rest)
    }

    fn end(&self, what: &str) -> Result<(), DataError> {
        if self.rest.is_empty() {
            Ok(())
        } else {
            Err(DataError::format(
                self.path,
                format!("line {}: the end of the line after {what}", self.line),
                format!("{:?}", self.rest),
            ))
        }
    }
}

fn read_cameras_txt(path: &Path, text: &str) -> Result<Vec<ColmapCamera>, DataError> {
    let mut cameras = Vec::new();
    let mut ids = HashSet::new();
    for (line, content) in text_lines(text) {
        if is_skipped(content) {
            continue;
        }
        let mut f = Fields::new(path, line, content);
        let id: u32 = f.parse("CAMERA_ID", "an integer in 0..=4294967295")?;
        let at = format!("line {line}: camera {id}");
        let name = f.token("MODEL")?;
        let model = CameraModel::from_name(name).ok_or_else(|| {
            let found = match UNSUPPORTED_MODELS.iter().find(|(_, n)| *n == name) {
                Some(_) => format!("{name}, which is not supported"),
                None => format!("unknown model {name:?}"),
            };
            unsupported_model(path, &at, found)
        })?;
        let width: u64 = f.parse("WIDTH", "an integer in 1..=65535")?;
        let height: u64 = f.parse("HEIGHT", "an integer in 1..=65535")?;
        let mut params = Vec::with_capacity(model.num_params());
        for p in model.param_names() {
            params.push(f.f64(&format!("{} parameter {p}", model.name()))?);
        }
        f.end(&format!("the {} parameters", model.name()))?;
        let camera = (id, model, width, height, params);
        accept_camera(&mut cameras, &mut ids, camera, path, &at)?;
    }
    Ok(cameras)
}

fn read_images_txt(
    path: &Path,
    text: &str,
    camera_ids: &HashSet<u32>,
) -> Result<Vec<ColmapImage>, DataError> {
    let lines = text_lines(text);
    let mut images = Vec::new();
    let mut ids = HashSet::new();
    let mut rows = lines.iter();
    while let Some(&(line, content)) = rows.next() {
        if is_skipped(content) {
            continue;
        }
        let mut f = Fields::new(path, line, content);
        let id: u32 = f.parse("IMAGE_ID", "an integer in 0..=4294967295")?;
        let at = format!("line {line}: image {id}");
        let mut q = [0.0; 4];
        for (v, name) in q.iter_mut().zip(["QW", "QX", "QY", "QZ"]) {
            *v = f.f64(name)?;
        }
        let mut t = [0.0; 3];
        for (v, name) in t.iter_mut().zip(["TX", "TY", "TZ"]) {
            *v = f.f64(name)?;
        }
        let camera_id: u32 = f.parse("CAMERA_ID", "an integer in 0..=4294967295")?;
        let name = f.rest();
        if name.is_empty() {
            return Err(DataError::format(
                path,
                format!("line {line}: NAME after CAMERA_ID"),
                "the end of the line",
            ));
        }
        let world_from_camera = pose_from_disk(q, t, path, &at)?;
        if !camera_ids.contains(&camera_id) {
            return Err(unknown_camera(path, &at, camera_id));
        }
        if !ids.insert(id) {
            return Err(duplicate(path, &at, "image", id));
        }
        // The keypoints are on the next line, even when it is empty; a file may end without it.
        let mut points2d = Vec::new();
        if let Some(&(kp_line, kp_content)) = rows.next() {
            let mut f = Fields::new(path, kp_line, kp_content);
            while !f.is_empty() {
                let j = points2d.len();
                let xy = [
                    f.f64(&format!("keypoint {j} of image {id}: X"))?,
                    f.f64(&format!("keypoint {j} of image {id}: Y"))?,
                ];
                let what = format!("keypoint {j} of image {id}: POINT3D_ID");
                let point_id: i64 = f.parse(&what, "an integer, −1 for none")?;
                points2d.push((
                    xy,
                    point3d_id(point_id, path, &format!("line {kp_line}: {what}"))?,
                ));
            }
        }
        images.push(ColmapImage {
            id,
            camera_id,
            name: name.to_owned(),
            world_from_camera,
            points2d,
        });
    }
    Ok(images)
}

fn read_points_txt(path: &Path, text: &str) -> Result<Vec<ColmapPoint>, DataError> {
    let mut points = Vec::new();
    let mut ids = HashSet::new();
    for (line, content) in text_lines(text) {
        if is_skipped(content) {
            continue;
        }
        let mut f = Fields::new(path, line, content);
        let id: u64 = f.parse("POINT3D_ID", "an integer in 0..=18446744073709551615")?;
        let at = format!("line {line}: point {id}");
        let xyz = [f.f64("X")?, f.f64("Y")?, f.f64("Z")?];
        let mut rgb = [0; 3];
        for (c, name) in rgb.iter_mut().zip(["R", "G", "B"]) {
            *c = f.parse(name, "an integer in 0..=255")?;
        }
        let error = f.f64("ERROR")?;
        let mut track = Vec::new();
        while !f.is_empty() {
            let j = track.len();
            let image_id: u32 = f.parse(
                &format!("track element {j}: IMAGE_ID"),
                "an integer in 0..=4294967295",
            )?;
            let idx: u32 = f.parse(
                &format!("track element {j}: POINT2D_IDX"),
                "an integer in 0..=4294967295",
            )?;
            track.push((image_id, idx));
        }
        let point = ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track,
        };
        check_point_values(&point, path, &at)?;
        if !ids.insert(id) {
            return Err(duplicate(path, &at, "point", id));
        }
        points.push(point);
    }
    Ok(points)
}

// ---------------------------------------------------------------------------------------------
// Writing.

/// Writes `model` into `dir` (created if missing) as `cameras`, `images` and `points3D` in
/// `format`, each file atomically ([`cpose_core::fs::write_atomic`]). A part that is `None` in
/// the model gets no file.
///
/// With `replace == false`, any existing model file in `dir` (`.bin` or `.txt`, any part) is an
/// error and nothing is written. With `replace == true`, existing files are replaced, and the
/// other format's files and the files of `None` parts are removed, so that [`read_colmap_model`]
/// reads back exactly this model (it would otherwise prefer a stale `.bin`).
///
/// The model is checked first, with the reader's checks (sizes, parameters, finite numbers, unit
/// quaternions, unique ids, known cameras) and what the format can hold (keypoint point ids
/// below 2⁶³; in binary, names without NUL; in text, non-empty names without whitespace or
/// control characters); a model that fails writes nothing.
pub fn write_colmap_model(
    dir: &Path,
    model: &ColmapModel,
    format: ColmapFormat,
    replace: bool,
) -> Result<(), DataError> {
    let ext = format.extension();
    let path_of = |stem: &str| dir.join(format!("{stem}.{ext}"));
    let cameras_path = path_of(CAMERAS);
    let images_path = path_of(IMAGES);
    let points_path = path_of(POINTS);

    check_model(model, format, &cameras_path, &images_path, &points_path)?;

    let all_files: Vec<PathBuf> = [CAMERAS, IMAGES, POINTS]
        .iter()
        .flat_map(|stem| ["bin", "txt"].map(|e| dir.join(format!("{stem}.{e}"))))
        .collect();
    if !replace && let Some(existing) = all_files.iter().find(|p| p.exists()) {
        return Err(DataError::format(
            existing,
            "no existing COLMAP model file (pass replace = true to overwrite)",
            "an existing file",
        ));
    }

    let mut outputs = vec![(cameras_path, encode_cameras(&model.cameras, format))];
    if let Some(images) = &model.images {
        outputs.push((images_path, encode_images(images, format)));
    }
    if let Some(points) = &model.points {
        outputs.push((points_path, encode_points(points, format)));
    }

    let write_err = |path: &Path| {
        let path = path.to_path_buf();
        move |error| DataError::Write { path, error }
    };
    std::fs::create_dir_all(dir).map_err(write_err(dir))?;
    for (path, bytes) in &outputs {
        cpose_core::fs::write_atomic(path, bytes).map_err(write_err(path))?;
    }
    if replace {
        for stale in all_files
            .iter()
            .filter(|p| !outputs.iter().any(|(o, _)| o == *p))
        {
            match std::fs::remove_file(stale) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(DataError::Write {
                        path: stale.clone(),
                        error: e,
                    });
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// The writer's checks (see [`write_colmap_model`]); errors name the file that would be written.
fn check_model(
    model: &ColmapModel,
    format: ColmapFormat,
    cameras_path: &Path,
    images_path: &Path,
    points_path: &Path,
) -> Result<(), DataError> {
    let mut camera_ids = HashSet::new();
    for cam in &model.cameras {
        let at = format!("camera {}", cam.id);
        check_camera(cam, cameras_path, &at)?;
        if !camera_ids.insert(cam.id) {
            return Err(duplicate(cameras_path, &at, "camera", cam.id));
        }
    }
    let mut image_ids = HashSet::new();
    for image in model.images.iter().flatten() {
        let path = images_path;
        let at = format!("image {}", image.id);
        if !image_ids.insert(image.id) {
            return Err(duplicate(path, &at, "image", image.id));
        }
        if !camera_ids.contains(&image.camera_id) {
            return Err(unknown_camera(path, &at, image.camera_id));
        }
        let (q, t) = pose_to_disk(&image.world_from_camera);
        pose_from_disk(q, t, path, &at)?;
        check_name(&image.name, format, path, &at)?;
        for (j, (xy, point_id)) in image.points2d.iter().enumerate() {
            let at = format!("{at}: keypoint {j}");
            check_keypoint(*xy, path, &at)?;
            if let Some(id) = point_id
                && i64::try_from(*id).is_err()
            {
                return Err(DataError::format(
                    path,
                    format!("{at}: a POINT3D_ID below 2^63 (stored as i64)"),
                    id.to_string(),
                ));
            }
        }
    }
    let mut point_ids = HashSet::new();
    for point in model.points.iter().flatten() {
        let at = format!("point {}", point.id);
        check_point_values(point, points_path, &at)?;
        if !point_ids.insert(point.id) {
            return Err(duplicate(points_path, &at, "point", point.id));
        }
    }
    Ok(())
}

fn check_name(name: &str, format: ColmapFormat, path: &Path, at: &str) -> Result<(), DataError> {
    let ok = match format {
        ColmapFormat::Binary => !name.contains('\0'),
        ColmapFormat::Text => {
            !name.is_empty() && !name.chars().any(|c| c.is_whitespace() || c.is_control())
        }
    };
    if ok {
        return Ok(());
    }
    let expected = match format {
        ColmapFormat::Binary => "a name without NUL bytes",
        ColmapFormat::Text => {
            "a non-empty name without whitespace or control characters (the text format \
             separates fields by spaces; write binary instead)"
        }
    };
    Err(DataError::format(
        path,
        format!("{at}: {expected}"),
        format!("{name:?}"),
    ))
}

/// Text lines joined with `\n`, starting with `header` comment lines.
fn text_file(header: &[String], body: &str) -> Vec<u8> {
    let mut out = String::with_capacity(body.len() + 256);
    for line in header {
        out.push_str("# ");
        out.push_str(line);
        out.push('\n');
    }
    out.push_str(body);
    out.into_bytes()
}

/// `f64` in text: the shortest decimal that parses back to the same value (`{:?}`).
fn push_f64(out: &mut String, v: f64) {
    let _ = write!(out, " {v:?}");
}

fn encode_cameras(cameras: &[ColmapCamera], format: ColmapFormat) -> Vec<u8> {
    match format {
        ColmapFormat::Binary => {
            let mut b = Vec::with_capacity(8 + cameras.len() * 64);
            b.extend_from_slice(&(cameras.len() as u64).to_le_bytes());
            for c in cameras {
                b.extend_from_slice(&c.id.to_le_bytes());
                b.extend_from_slice(&c.model.id().to_le_bytes());
                b.extend_from_slice(&(c.width as u64).to_le_bytes());
                b.extend_from_slice(&(c.height as u64).to_le_bytes());
                for p in &c.params {
                    b.extend_from_slice(&p.to_le_bytes());
                }
            }
            b
        }
        ColmapFormat::Text => {
            let mut body = String::new();
            for c in cameras {
                let _ = write!(body, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
                for &p in &c.params {
                    push_f64(&mut body, p);
                }
                body.push('\n');
            }
            text_file(
                &[
                    "Camera list with one line of data per camera:".to_owned(),
                    "  CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]".to_owned(),
                    format!("Number of cameras: {}", cameras.len()),
                ],
                &body,
            )
        }
    }
}

fn encode_images(images: &[ColmapImage], format: ColmapFormat) -> Vec<u8> {
    let disk_id = |id: &Option<u64>| id.map_or(-1, |id| id as i64);
    match format {
        ColmapFormat::Binary => {
            let mut b = Vec::new();
            b.extend_from_slice(&(images.len() as u64).to_le_bytes());
            for image in images {
                let (q, t) = pose_to_disk(&image.world_from_camera);
                b.extend_from_slice(&image.id.to_le_bytes());
                for v in q.iter().chain(&t) {
                    b.extend_from_slice(&v.to_le_bytes());
                }
                b.extend_from_slice(&image.camera_id.to_le_bytes());
                b.extend_from_slice(image.name.as_bytes());
                b.push(0);
                b.extend_from_slice(&(image.points2d.len() as u64).to_le_bytes());
                for (xy, id) in &image.points2d {
                    b.extend_from_slice(&xy[0].to_le_bytes());
                    b.extend_from_slice(&xy[1].to_le_bytes());
                    b.extend_from_slice(&disk_id(id).to_le_bytes());
                }
            }
            b
        }
        ColmapFormat::Text => {
            let mut body = String::new();
            let mut observations = 0;
            for image in images {
                let (q, t) = pose_to_disk(&image.world_from_camera);
                let _ = write!(body, "{}", image.id);
                for &v in q.iter().chain(&t) {
                    push_f64(&mut body, v);
                }
                let _ = writeln!(body, " {} {}", image.camera_id, image.name);
                let mut first = true;
                for (xy, id) in &image.points2d {
                    if !first {
                        body.push(' ');
                    }
                    first = false;
                    let _ = write!(body, "{:?} {:?} {}", xy[0], xy[1], disk_id(id));
                }
                body.push('\n');
                observations += image.points2d.iter().filter(|p| p.1.is_some()).count();
            }
            let mean = if images.is_empty() {
                0.0
            } else {
                observations as f64 / images.len() as f64
            };
            text_file(
                &[
                    "Image list with two lines of data per image:".to_owned(),
                    "  IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME".to_owned(),
                    "  POINTS2D[] as (X, Y, POINT3D_ID)".to_owned(),
                    format!(
                        "Number of images: {}, mean observations per image: {mean}",
                        images.len()
                    ),
                ],
                &body,
            )
        }
    }
}

fn encode_points(points: &[ColmapPoint], format: ColmapFormat) -> Vec<u8> {
    match format {
        ColmapFormat::Binary => {
            let mut b = Vec::new();
            b.extend_from_slice(&(points.len() as u64).to_le_bytes());
            for p in points {
                b.extend_from_slice(&p.id.to_le_bytes());
                for v in &p.xyz {
                    b.extend_from_slice(&v.to_le_bytes());
                }
                b.extend_from_slice(&p.rgb);
                b.extend_from_slice(&p.error.to_le_bytes());
                b.extend_from_slice(&(p.track.len() as u64).to_le_bytes());
                for (image_id, idx) in &p.track {
                    b.extend_from_slice(&image_id.to_le_bytes());
                    b.extend_from_slice(&idx.to_le_bytes());
                }
            }
            b
        }
        ColmapFormat::Text => {
            let mut body = String::new();
            let mut elements = 0;
            for p in points {
                let _ = write!(body, "{}", p.id);
                for &v in &p.xyz {
                    push_f64(&mut body, v);
                }
                let _ = write!(body, " {} {} {}", p.rgb[0], p.rgb[1], p.rgb[2]);
                push_f64(&mut body, p.error);
                for (image_id, idx) in &p.track {
                    let _ = write!(body, " {image_id} {idx}");
                }
                body.push('\n');
                elements += p.track.len();
            }
            let mean = if points.is_empty() {
                0.0
            } else {
                elements as f64 / points.len() as f64
            };
            text_file(
                &[
                    "3D point list with one line of data per point:".to_owned(),
                    "  POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"
                        .to_owned(),
                    format!(
                        "Number of points: {}, mean track length: {mean}",
                        points.len()
                    ),
                ],
                &body,
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::testing::TempDir;
    use nalgebra::Point3;

    fn temp_dir(name: &str) -> TempDir {
        TempDir::new(&format!("colmap-{name}"))
    }

    fn pose(axis: [f64; 3], angle: f64, t: [f64; 3]) -> Isometry3<f64> {
        Isometry3::new(Vector3::from(t), Vector3::from(axis).normalize() * angle)
    }

    /// Every supported camera model, images with and without keypoints, points with and
    /// without tracks; values with many significant digits.
    fn sample_model() -> ColmapModel {
        let third = 1.0 / 3.0;
        let cameras = vec![
            ColmapCamera {
                id: 1,
                model: CameraModel::SimplePinhole,
                width: 640,
                height: 480,
                params: vec![500.0 + third, 320.5, 240.25],
            },
            ColmapCamera {
                id: 2,
                model: CameraModel::Pinhole,
                width: 1,
                height: 65535,
                params: vec![1e-7, 3.0e8, -0.0, 1e300],
            },
            ColmapCamera {
                id: 3,
                model: CameraModel::SimpleRadial,
                width: 4032,
                height: 3024,
                params: vec![3260.5263, 2016.0, 1512.0, -0.012345678901234567],
            },
            ColmapCamera {
                id: 70,
                model: CameraModel::Radial,
                width: 17,
                height: 9,
                params: vec![std::f64::consts::PI, 8.5, 4.5, 1e-20, -2.5e-5],
            },
        ];
        let images = vec![
            ColmapImage {
                id: 1,
                camera_id: 1,
                name: "a.png".to_owned(),
                world_from_camera: pose([0.3, -1.0, 0.2], 0.7, [1.0, -2.0, third]),
                points2d: vec![
                    ([10.5, 20.25], Some(0)),
                    ([third, 1e-9], None),
                    ([-4.0, 630.125], Some(12)),
                ],
            },
            ColmapImage {
                id: 5,
                camera_id: 70,
                name: "sub/b_01.JPG".to_owned(),
                world_from_camera: pose([0.0, 0.0, 1.0], 3.1, [0.0, 0.0, 0.0]),
                points2d: vec![],
            },
            ColmapImage {
                id: 9,
                camera_id: 3,
                name: "ü.png".to_owned(),
                world_from_camera: pose([1.0, 1.0, 1.0], 2.0, [1e3, 1e-3, -7.0]),
                points2d: vec![([1.0, 2.0], Some(i64::MAX as u64))],
            },
        ];
        let points = vec![
            ColmapPoint {
                id: 0,
                xyz: [1.0, 2.0, third],
                rgb: [0, 128, 255],
                error: 0.5 + third,
                track: vec![(1, 0)],
            },
            ColmapPoint {
                id: 12,
                xyz: [-1e-12, 5e10, 3.0],
                rgb: [1, 2, 3],
                error: -1.0,
                track: vec![(1, 2), (9, 0), (5, 4_000_000_000)],
            },
            ColmapPoint {
                id: u64::MAX,
                xyz: [0.0, -0.0, 1.0],
                rgb: [9, 9, 9],
                error: 0.0,
                track: vec![],
            },
        ];
        ColmapModel {
            cameras,
            images: Some(images),
            points: Some(points),
        }
    }

    /// `a` and `b` are equal, except that poses may differ by `tol` (rotation angle and
    /// translation).
    fn assert_models_match(a: &ColmapModel, b: &ColmapModel, tol: f64) {
        assert_eq!(a.cameras, b.cameras);
        assert!(a.points == b.points, "points differ");
        let (ai, bi) = (a.images.as_ref().unwrap(), b.images.as_ref().unwrap());
        assert_eq!(ai.len(), bi.len());
        for (x, y) in ai.iter().zip(bi) {
            assert_eq!(
                (x.id, x.camera_id, &x.name, &x.points2d),
                (y.id, y.camera_id, &y.name, &y.points2d)
            );
            assert_pose_close(&x.world_from_camera, &y.world_from_camera, tol);
        }
    }

    /// Rotation angle and translation within `tol` (relative for translations beyond 1).
    fn assert_pose_close(a: &Isometry3<f64>, b: &Isometry3<f64>, tol: f64) {
        let (ta, tb) = (a.translation.vector, b.translation.vector);
        let dt = (ta - tb).amax() / ta.amax().max(1.0);
        let angle = a.rotation.angle_to(&b.rotation);
        assert!(
            dt <= tol && angle <= tol,
            "t {ta:?} vs {tb:?}, q {:?} vs {:?}: Δt {dt:e}, angle {angle:e}",
            a.rotation.quaternion(),
            b.rotation.quaternion()
        );
    }

    /// On disk: camera-from-world, quaternion `(w, x, y, z)`. A camera turned +90° about the
    /// world z axis (its x axis along world y) at world `(0, 1, 0)` has `R = Rz(−90°)`, i.e.
    /// `q = (cos 45°, 0, 0, −sin 45°)`, and `t = −R c = (−1, 0, 0)`.
    #[test]
    fn disk_pose_is_camera_from_world_with_w_first() {
        let dir = temp_dir("disk-pose");
        let s = std::f64::consts::FRAC_1_SQRT_2;
        std::fs::write(dir.join("cameras.txt"), "7 PINHOLE 4 3 2 2 2 1.5\n").unwrap();
        std::fs::write(
            dir.join("images.txt"),
            format!("3 {s:?} 0 0 {:?} -1 0 0 7 x.png\n\n", -s),
        )
        .unwrap();
        let model = read_colmap_model(&dir).unwrap();
        let image = &model.images.unwrap()[0];
        let pose = image.world_from_camera;
        assert!((pose.translation.vector - Vector3::new(0.0, 1.0, 0.0)).amax() < 1e-15);
        let camera_x_in_world = pose.rotation * Vector3::x();
        assert!((camera_x_in_world - Vector3::y()).amax() < 1e-15);
        assert_eq!(pose_to_disk(&pose).1.map(|v| v.round()), [-1.0, 0.0, 0.0]);
        assert!(model.points.is_none());
    }

    fn error_of(dir: &Path) -> String {
        let message = read_colmap_model(dir).unwrap_err().to_string();
        assert_eq!(message.lines().count(), 1, "{message}");
        message
    }

    #[test]
    fn colmap_model_round_trips_in_binary_and_text() {
        let model = sample_model();
        let bin = temp_dir("rt-bin");
        write_colmap_model(&bin, &model, ColmapFormat::Binary, false).unwrap();
        for f in ["cameras.bin", "images.bin", "points3D.bin"] {
            assert!(bin.join(f).is_file(), "{f}");
        }
        let from_bin = read_colmap_model(&bin).unwrap();
        assert_models_match(&model, &from_bin, 1e-14);

        let txt = temp_dir("rt-txt");
        write_colmap_model(&txt, &model, ColmapFormat::Text, false).unwrap();
        let from_txt = read_colmap_model(&txt).unwrap();
        // The same numbers on disk in both formats: identical models.
        assert_eq!(from_txt, from_bin);

        // binary → text → binary: the same model (poses to the rounding of their inversion,
        // rotations exactly) and byte-identical cameras.bin and points3D.bin.
        let txt2 = temp_dir("rt-txt2");
        write_colmap_model(&txt2, &from_bin, ColmapFormat::Text, false).unwrap();
        let back_txt = read_colmap_model(&txt2).unwrap();
        assert_models_match(&back_txt, &from_bin, 1e-15);
        let bin2 = temp_dir("rt-bin2");
        write_colmap_model(&bin2, &back_txt, ColmapFormat::Binary, false).unwrap();
        let back_bin = read_colmap_model(&bin2).unwrap();
        assert_models_match(&back_bin, &from_bin, 1e-15);
        for (a, b) in back_bin
            .images
            .iter()
            .flatten()
            .zip(from_bin.images.iter().flatten())
        {
            assert_eq!(a.world_from_camera.rotation, b.world_from_camera.rotation);
        }
        for f in ["cameras.bin", "points3D.bin"] {
            assert_eq!(
                std::fs::read(bin2.join(f)).unwrap(),
                std::fs::read(bin.join(f)).unwrap(),
                "{f}"
            );
        }

        // CRLF, trailing whitespace, indented comments and blank lines in text.
        for f in ["cameras.txt", "images.txt", "points3D.txt"] {
            let text = std::fs::read_to_string(txt.join(f)).unwrap();
            let mut messy = String::from("\r\n   # a comment\r\n\r\n");
            for line in text.lines() {
                messy.push_str(line);
                messy.push_str(" \t\r\n");
            }
            std::fs::write(txt.join(f), messy).unwrap();
        }
        assert_eq!(read_colmap_model(&txt).unwrap(), from_txt);
        // An images.txt whose last image has no keypoint line at all.
        let images_txt = std::fs::read_to_string(txt.join("images.txt")).unwrap();
        let cut = images_txt.trim_end().rfind('\n').unwrap();
        std::fs::write(txt.join("images.txt"), &images_txt[..cut]).unwrap();
        let mut expected = from_txt.clone();
        expected.images.as_mut().unwrap()[2].points2d.clear();
        assert_eq!(read_colmap_model(&txt).unwrap(), expected);
    }

    #[test]
    fn missing_parts_are_none_and_files_are_not_replaced_unless_asked() {
        let mut model = sample_model();
        model.points = None;
        let dir = temp_dir("parts");
        write_colmap_model(&dir, &model, ColmapFormat::Binary, false).unwrap();
        assert!(!dir.join("points3D.bin").exists());
        let read = read_colmap_model(&dir).unwrap();
        assert!(read.points.is_none());
        assert_eq!(read.images.as_ref().unwrap().len(), 3);
        assert_eq!(read.camera(70).unwrap().model, CameraModel::Radial);

        // Present but empty is `Some(vec![])`.
        model.images = Some(vec![]);
        model.points = Some(vec![]);
        let m = write_colmap_model(&dir, &model, ColmapFormat::Text, false)
            .unwrap_err()
            .to_string();
        assert!(
            m.contains("cameras.bin") && m.contains("replace = true"),
            "{m}"
        );
        // Text over binary with `replace`: the stale .bin files go, so the text is read.
        write_colmap_model(&dir, &model, ColmapFormat::Text, true).unwrap();
        assert!(!dir.join("cameras.bin").exists() && !dir.join("images.bin").exists());
        let read = read_colmap_model(&dir).unwrap();
        assert_eq!(read.images, Some(vec![]));
        assert_eq!(read.points, Some(vec![]));
        assert_eq!(read.cameras, model.cameras);
        // A part that becomes `None` loses its file.
        model.images = None;
        write_colmap_model(&dir, &model, ColmapFormat::Binary, true).unwrap();
        assert!(!dir.join("images.txt").exists());
        assert!(read_colmap_model(&dir).unwrap().images.is_none());

        // .bin is preferred when both exist.
        let mut other = model.clone();
        other.cameras.truncate(1);
        encode_cameras(&other.cameras, ColmapFormat::Text);
        std::fs::write(
            dir.join("cameras.txt"),
            encode_cameras(&other.cameras, ColmapFormat::Text),
        )
        .unwrap();
        assert_eq!(read_colmap_model(&dir).unwrap().cameras.len(), 4);

        // No cameras file, no folder.
        let empty = temp_dir("parts-empty");
        let m = error_of(&empty);
        assert!(m.contains("cameras.bin or cameras.txt"), "{m}");
        let m = error_of(&empty.join("nowhere"));
        assert!(m.contains("nowhere") && m.contains("no such folder"), "{m}");
    }

    #[test]
    fn the_writer_refuses_models_it_could_not_read_back() {
        let dir = temp_dir("write-bad");
        type Spoil = Box<dyn Fn(&mut ColmapModel)>;
        let cases: Vec<(Spoil, ColmapFormat, &str)> = vec![
            (
                Box::new(|m| m.images.as_mut().unwrap()[0].camera_id = 4),
                ColmapFormat::Binary,
                "camera 4, which is not in cameras",
            ),
            (
                Box::new(|m| m.images.as_mut().unwrap()[0].name = "a b.png".to_owned()),
                ColmapFormat::Text,
                "without whitespace",
            ),
            (
                Box::new(|m| m.images.as_mut().unwrap()[0].name = "a\0.png".to_owned()),
                ColmapFormat::Binary,
                "without NUL",
            ),
            (
                Box::new(|m| m.cameras[1].params.pop().map(|_| ()).unwrap()),
                ColmapFormat::Binary,
                "4 parameters for PINHOLE",
            ),
            (
                Box::new(|m| m.cameras[2].id = 1),
                ColmapFormat::Text,
                "a second camera 1",
            ),
            (
                Box::new(|m| m.points.as_mut().unwrap()[1].xyz[0] = f64::NAN),
                ColmapFormat::Binary,
                "finite X Y Z",
            ),
            (
                Box::new(|m| m.images.as_mut().unwrap()[2].points2d[0].1 = Some(u64::MAX)),
                ColmapFormat::Binary,
                "below 2^63",
            ),
        ];
        for (spoil, format, needle) in cases {
            let mut model = sample_model();
            spoil(&mut model);
            let m = write_colmap_model(&dir, &model, format, true)
                .unwrap_err()
                .to_string();
            assert!(m.contains(needle), "{needle}: {m}");
            assert_eq!(
                std::fs::read_dir(&*dir).unwrap().count(),
                0,
                "{needle}: {m}"
            );
        }
    }

    /// Patches `bytes[at..]` with `with`.
    fn patch(path: &Path, at: usize, with: &[u8]) {
        let mut bytes = std::fs::read(path).unwrap();
        bytes[at..at + with.len()].copy_from_slice(with);
        std::fs::write(path, bytes).unwrap();
    }

    #[test]
    fn hostile_binary_files_are_clear_errors() {
        let dir = temp_dir("hostile-bin");
        let model = sample_model();
        let write = |format| write_colmap_model(&dir, &model, format, true).unwrap();
        write(ColmapFormat::Binary);
        let cameras = dir.join("cameras.bin");
        let images = dir.join("images.bin");
        let points = dir.join("points3D.bin");

        // A count of 2⁴⁰ cameras in a 64-byte file: an error, not an allocation.
        let mut lying = (1u64 << 40).to_le_bytes().to_vec();
        lying.extend_from_slice(&[0; 56]);
        std::fs::write(&cameras, &lying).unwrap();
        let m = error_of(&dir);
        assert!(
            m.contains("cameras.bin")
                && m.contains("the number of cameras at offset 0: at most 1 (56 bytes left")
                && m.contains("got 1099511627776"),
            "{m}"
        );
        write(ColmapFormat::Binary);
        // A lying keypoint count and track length.
        // images.bin: count 8, id 4, pose 56, camera 4, "a.png\0" 6: n_points2D at 78.
        patch(&images, 78, &u64::MAX.to_le_bytes());
        let m = error_of(&dir);
        assert!(
            m.contains("images.bin") && m.contains("keypoints of image 1"),
            "{m}"
        );
        write(ColmapFormat::Binary);
        patch(&points, 8 + 43, &(1u64 << 61).to_le_bytes());
        let m = error_of(&dir);
        assert!(
            m.contains("points3D.bin") && m.contains("track elements of point 0"),
            "{m}"
        );

        // Every truncation of every file is an error naming the file; so are trailing bytes.
        for path in [&cameras, &images, &points] {
            write(ColmapFormat::Binary);
            let full = std::fs::read(path).unwrap();
            for len in 0..full.len() {
                std::fs::write(path, &full[..len]).unwrap();
                let m = error_of(&dir);
                let name = path.file_name().unwrap().to_str().unwrap();
                assert!(m.contains(name), "{name} cut at {len}: {m}");
            }
            let mut longer = full.clone();
            longer.push(7);
            std::fs::write(path, &longer).unwrap();
            let m = error_of(&dir);
            assert!(
                m.contains("the end of the file after") && m.contains("1 more bytes"),
                "{m}"
            );
        }
        // One image without keypoints (93 bytes) cut inside its keypoint count.
        write(ColmapFormat::Binary);
        let one = &model.images.as_ref().unwrap()[1..2];
        let bytes = encode_images(one, ColmapFormat::Binary);
        assert_eq!(bytes.len(), 93);
        std::fs::write(&images, &bytes[..90]).unwrap();
        let m = error_of(&dir);
        assert!(
            m.contains("images.bin: expected the number of keypoints of image 5 (record 0)")
                && m.contains("truncated"),
            "{m}"
        );

        // Unsupported model: OPENCV (id 4) names itself, the camera and the supported models.
        write(ColmapFormat::Binary);
        patch(&cameras, 12, &4i32.to_le_bytes());
        let m = error_of(&dir);
        assert!(
            m.contains("cameras.bin")
                && m.contains("camera 1 (record 0)")
                && m.contains("OPENCV (model id 4), which is not supported")
                && m.contains("SIMPLE_PINHOLE (f, cx, cy), PINHOLE (fx, fy, cx, cy), SIMPLE_RADIAL (f, cx, cy, k), RADIAL (f, cx, cy, k1, k2)"),
            "{m}"
        );
        patch(&cameras, 12, &11i32.to_le_bytes());
        assert!(error_of(&dir).contains("unknown model id 11"));

        // Sizes, focal lengths, non-finite parameters, duplicate ids.
        for (at, bytes, needle) in [
            (16, 0u64.to_le_bytes(), "an image width in 1..=65535, got 0"),
            (
                24,
                65536u64.to_le_bytes(),
                "an image height in 1..=65535, got 65536",
            ),
            (
                32,
                (-500.0f64).to_le_bytes(),
                "a positive focal length f, got -500.0",
            ),
            (40, f64::NAN.to_le_bytes(), "a finite parameter cx, got NaN"),
        ] {
            write(ColmapFormat::Binary);
            patch(&cameras, at, &bytes);
            let m = error_of(&dir);
            assert!(
                m.contains("cameras.bin") && m.contains(needle),
                "{needle}: {m}"
            );
        }
        write(ColmapFormat::Binary);
        patch(&cameras, 8 + 48, &1u32.to_le_bytes());
        assert!(error_of(&dir).contains("a second camera 1"));

        // Images: unknown camera, non-unit quaternion, non-finite pose, bad UTF-8, bad
        // POINT3D_ID, duplicate id.
        write(ColmapFormat::Binary);
        let mut unknown = model.images.clone().unwrap();
        unknown[1].camera_id = 99;
        std::fs::write(&images, encode_images(&unknown, ColmapFormat::Binary)).unwrap();
        let m = error_of(&dir);
        assert!(
            m.contains("images.bin")
                && m.contains("image 5 (record 1)")
                && m.contains("camera 99, which is not in cameras"),
            "{m}"
        );
        for (at, bytes, needle) in [
            (12, 2.0f64.to_le_bytes().to_vec(), "a unit quaternion"),
            (12, 1.0005f64.to_le_bytes().to_vec(), "a unit quaternion"),
            (44, f64::INFINITY.to_le_bytes().to_vec(), "a finite pose"),
            (72, vec![0xff], "a UTF-8 image name"),
            (
                72 + 6 + 8 + 16,
                (-2i64).to_le_bytes().to_vec(),
                "a POINT3D_ID ≥ 0, or −1",
            ),
            (86, f64::NAN.to_le_bytes().to_vec(), "finite keypoint"),
        ] {
            write(ColmapFormat::Binary);
            patch(&images, at, &bytes);
            let m = error_of(&dir);
            assert!(
                m.contains("images.bin") && m.contains(needle),
                "{needle}: {m}"
            );
        }
        // A quaternion off by less than the tolerance is normalised.
        write(ColmapFormat::Binary);
        let qw = f64::from_le_bytes(std::fs::read(&images).unwrap()[12..20].try_into().unwrap());
        patch(&images, 12, &(qw * (1.0 + 1e-4)).to_le_bytes());
        let read = read_colmap_model(&dir).unwrap();
        let q = read.images.unwrap()[0].world_from_camera.rotation;
        assert!((q.quaternion().norm() - 1.0).abs() < 1e-15);
        let mut dup = model.images.clone().unwrap();
        dup[2].id = 1;
        std::fs::write(&images, encode_images(&dup, ColmapFormat::Binary)).unwrap();
        assert!(error_of(&dir).contains("a second image 1"));

        // Points: non-finite coordinates or error, duplicate id.
        for (at, needle) in [(8 + 16, "finite X Y Z and ERROR"), (8 + 35, "finite X Y Z")] {
            write(ColmapFormat::Binary);
            patch(&points, at, &f64::NAN.to_le_bytes());
            let m = error_of(&dir);
            assert!(m.contains("points3D.bin") && m.contains(needle), "{m}");
        }
        let mut dup = model.points.clone().unwrap();
        dup[2].id = 12;
        std::fs::write(&points, encode_points(&dup, ColmapFormat::Binary)).unwrap();
        assert!(error_of(&dir).contains("a second point 12"));
    }

    /// Random byte corruptions never panic (errors or, rarely, another valid model).
    #[test]
    fn corrupted_binary_files_never_panic() {
        let dir = temp_dir("fuzz");
        let model = sample_model();
        write_colmap_model(&dir, &model, ColmapFormat::Binary, true).unwrap();
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for name in ["cameras.bin", "images.bin", "points3D.bin"] {
            let path = dir.join(name);
            let good = std::fs::read(&path).unwrap();
            for _ in 0..400 {
                let mut bytes = good.clone();
                for _ in 0..1 + next() % 3 {
                    let i = (next() % bytes.len() as u64) as usize;
                    bytes[i] = next() as u8;
                }
                std::fs::write(&path, &bytes).unwrap();
                let _ = read_colmap_model(&dir);
            }
            std::fs::write(&path, &good).unwrap();
        }
    }

    #[test]
    fn hostile_text_files_name_their_line() {
        let dir = temp_dir("hostile-txt");
        let model = sample_model();
        write_colmap_model(&dir, &model, ColmapFormat::Text, true).unwrap();
        let cameras = dir.join("cameras.txt");
        let images = dir.join("images.txt");
        let points = dir.join("points3D.txt");
        let good = |p: &Path| std::fs::read_to_string(p).unwrap();
        let (good_cameras, good_images, good_points) =
            (good(&cameras), good(&images), good(&points));
        // The header has 3 comment lines: camera 1 is on line 4.
        let cases: &[(&Path, &str, &str, &str, &[&str])] = &[
            (
                &cameras,
                "640 480",
                "640 48O",
                "cameras.txt",
                &["line 4: HEIGHT (an integer in 1..=65535), got \"48O\""],
            ),
            (
                &cameras,
                "1 SIMPLE_PINHOLE",
                "1 OPENCV",
                "cameras.txt",
                &[
                    "line 4: camera 1: a supported camera model: SIMPLE_PINHOLE (f, cx, cy)",
                    "got OPENCV, which is not supported",
                ],
            ),
            (
                &cameras,
                "1 SIMPLE_PINHOLE",
                "1 FISHEYE",
                "cameras.txt",
                &["unknown model \"FISHEYE\""],
            ),
            (
                &cameras,
                "320.5 240.25",
                "320.5 240.25 7",
                "cameras.txt",
                &["line 4: the end of the line after the SIMPLE_PINHOLE parameters, got \"7\""],
            ),
            (
                &cameras,
                "320.5 240.25",
                "320.5",
                "cameras.txt",
                &["line 4: SIMPLE_PINHOLE parameter cy, got the end of the line"],
            ),
            (
                &cameras,
                "320.5 240.25",
                "nan 240.25",
                "cameras.txt",
                &["line 4: SIMPLE_PINHOLE parameter cx (a finite number), got NaN"],
            ),
            (
                &cameras,
                "640 480",
                "0 480",
                "cameras.txt",
                &["line 4: camera 1: an image width in 1..=65535, got 0"],
            ),
            (
                &cameras,
                "2 PINHOLE",
                "1 PINHOLE",
                "cameras.txt",
                &["line 5: camera 1: a camera id not used before"],
            ),
            (
                &images,
                " 1 a.png",
                " 99 a.png",
                "images.txt",
                &["line 5: image 1: a CAMERA_ID of the model's cameras, got camera 99"],
            ),
            (
                &images,
                "\n5 ",
                "\n5 2.5e-1x ",
                "images.txt",
                &["line 7: QW (a finite number), got \"2.5e-1x\""],
            ),
            (
                &images,
                " 630.125 12",
                " 630.125",
                "images.txt",
                &["line 6: keypoint 2 of image 1: POINT3D_ID, got the end of the line"],
            ),
            (
                &images,
                "10.5 20.25 0",
                "10.5 20.25 -3",
                "images.txt",
                &["line 6: keypoint 0 of image 1: POINT3D_ID: a POINT3D_ID ≥ 0, or −1"],
            ),
            (
                &points,
                "0 128 255",
                "0 128 256",
                "points3D.txt",
                &["line 4: B (an integer in 0..=255), got \"256\""],
            ),
            (
                &points,
                " 9 0 ",
                " 9 ",
                "points3D.txt",
                &["line 5: track element 2: POINT2D_IDX, got the end of the line"],
            ),
        ];
        for &(path, from, to, file, needles) in cases {
            let text = good(path);
            assert!(text.contains(from), "{from}");
            std::fs::write(path, text.replacen(from, to, 1)).unwrap();
            let m = error_of(&dir);
            assert!(m.contains(file), "{m}");
            for needle in needles {
                assert!(m.contains(needle), "{needle}: {m}");
            }
            std::fs::write(&cameras, &good_cameras).unwrap();
            std::fs::write(&images, &good_images).unwrap();
            std::fs::write(&points, &good_points).unwrap();
        }
        // A quaternion scaled by 2 and a name that is not UTF-8.
        let text = good_images.replacen("\n5 ", "\n5 2", 1);
        std::fs::write(&images, text).unwrap();
        assert!(error_of(&dir).contains("line 7: image 5: a unit quaternion"));
        let mut bytes = good_images.into_bytes();
        let at = bytes.windows(5).position(|w| w == b"a.png").unwrap();
        bytes[at] = 0xfe;
        std::fs::write(&images, bytes).unwrap();
        let m = error_of(&dir);
        assert!(m.contains("images.txt: expected UTF-8 text"), "{m}");
    }

    /// fern's real `cameras.bin` and `points3D.bin`, with an `images.bin` written from the LLFF
    /// poses (fern ships none). The points lie in front of the cameras and project into their
    /// images, which pins the camera axes and the camera-from-world direction on disk.
    #[test]
    fn fern_model_with_images_from_llff_poses() {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return;
        };
        let scene = data_dir.join("llff/fern");
        let sparse = scene.join("sparse/0");
        let dir = temp_dir("fern");
        for f in ["cameras.bin", "points3D.bin"] {
            std::fs::write(dir.join(f), std::fs::read(sparse.join(f)).unwrap()).unwrap();
        }
        let model = read_colmap_model(&dir).unwrap();
        assert!(model.images.is_none());
        assert_eq!(model.cameras.len(), 1);
        let camera = model.cameras[0].clone();
        let points = model.points.clone().unwrap();
        println!(
            "fern: camera {} {} {}×{} params {:?}; {} points",
            camera.id,
            camera.model.name(),
            camera.width,
            camera.height,
            camera.params,
            points.len()
        );
        assert_eq!(camera.model, CameraModel::SimpleRadial);
        assert_eq!((camera.width, camera.height), (4032, 3024));
        assert_eq!(points.len(), 10091);
        assert!(points.iter().all(|p| p.xyz.iter().all(|v| v.is_finite())));

        // LLFF's poses are COLMAP's camera centres and axes (reordered); the LLFF reader gives
        // them as world_from_camera with OpenCV axes.
        let llff = crate::data::llff::load_llff(&scene, 8).unwrap();
        let images: Vec<ColmapImage> = llff
            .world_from_camera
            .iter()
            .zip(&llff.names)
            .enumerate()
            .map(|(i, (pose, name))| ColmapImage {
                id: i as u32 + 1,
                camera_id: camera.id,
                name: name.clone(),
                world_from_camera: *pose,
                points2d: vec![],
            })
            .collect();
        cpose_core::fs::write_atomic(
            dir.join("images.bin"),
            encode_images(&images, ColmapFormat::Binary),
        )
        .unwrap();
        let model = read_colmap_model(&dir).unwrap();
        let read_images = model.images.clone().unwrap();
        assert_eq!(read_images.len(), 20);
        for (a, b) in images.iter().zip(&read_images) {
            assert_eq!((a.id, a.camera_id, &a.name), (b.id, b.camera_id, &b.name));
            assert_pose_close(&a.world_from_camera, &b.world_from_camera, 1e-9);
        }
        // fern's focal (LLFF's f of the original photos) agrees with cameras.bin.
        assert!(
            (camera.params[0] - 3260.5263).abs() < 0.01,
            "{:?}",
            camera.params
        );

        // Points in front of (z > 0) and inside the image of the first camera.
        let first = &read_images[0].world_from_camera;
        let (f, cx, cy) = match camera.model {
            CameraModel::Pinhole => (camera.params[0], camera.params[2], camera.params[3]),
            _ => (camera.params[0], camera.params[1], camera.params[2]),
        };
        let in_cam: Vec<_> = points
            .iter()
            .map(|p| first.inverse_transform_point(&Point3::from(p.xyz)))
            .collect();
        let in_front = in_cam.iter().filter(|p| p.z > 0.0).count();
        let inside = in_cam
            .iter()
            .filter(|p| {
                let (u, v) = (f * p.x / p.z + cx, f * p.y / p.z + cy);
                p.z > 0.0 && (0.0..4032.0).contains(&u) && (0.0..3024.0).contains(&v)
            })
            .count();
        println!(
            "fern: {in_front} of {} points in front of image 1, {inside} inside it",
            points.len()
        );
        assert!(in_front as f64 > 0.9 * points.len() as f64);
        assert!(inside as f64 > 0.9 * points.len() as f64);

        // The whole real model through text and binary: the same model back (poses to
        // rounding), identical from both formats.
        let txt = temp_dir("fern-txt");
        write_colmap_model(&txt, &model, ColmapFormat::Text, false).unwrap();
        let from_txt = read_colmap_model(&txt).unwrap();
        assert_models_match(&model, &from_txt, 1e-14);
        let bin = temp_dir("fern-bin");
        write_colmap_model(&bin, &model, ColmapFormat::Binary, false).unwrap();
        assert!(read_colmap_model(&bin).unwrap() == from_txt);
        for f in ["cameras.bin", "points3D.bin"] {
            assert_eq!(
                std::fs::read(bin.join(f)).unwrap(),
                std::fs::read(sparse.join(f)).unwrap(),
                "{f} is rewritten byte for byte"
            );
        }
    }
}
