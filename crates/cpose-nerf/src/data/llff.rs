//! LLFF forward-facing scenes (`poses_bounds.npy` + `images_N/`), as released by the LLFF and
//! NeRF authors and used by BARF (`data/llff.py`).
//!
//! # Layout
//!
//! `<scene>/poses_bounds.npy` is an `N × 17` little-endian float64 array (NPY v1–v3, C order).
//! Row `i` is a `3 × 5` matrix `M` stored row-major, then `near`, `far`:
//!
//! * `M[:, 0..3] = R_llff`: camera-to-world rotation whose columns are the camera axes in world
//!   coordinates, in LLFF's order **[down, right, backwards]**;
//! * `M[:, 3] = c`: the camera centre in world coordinates;
//! * `M[:, 4] = (H, W, f)`: height, width and focal length of the **original** photos;
//! * `near, far`: depth bounds of the scene seen by that camera (COLMAP point depths).
//!
//! `<scene>/images_N/` (or `images/` for `N = 1`) holds the photos downscaled by `N`, sorted by
//! file name in the same order as the rows.
//!
//! # Axis conversion
//!
//! OpenCV axes are (right, down, forward) = (LLFF column 1, LLFF column 0, −LLFF column 2), so
//!
//! `R_cv = R_llff · P`, `P = [[0, 1, 0], [1, 0, 0], [0, 0, −1]]` (`det P = +1`),
//!
//! i.e. `R_cv = [r₁ | r₀ | −r₂]` for `R_llff = [r₀ | r₁ | r₂]`. (NeRF's loader first builds the
//! OpenGL frame `[r₁ | −r₀ | r₂]` = (right, up, back); right-multiplying that by `diag(1, −1, −1)`
//! gives the same `R_cv`.) The centre is unchanged: `world_from_camera = [R_cv | c]`.
//!
//! # Intrinsics
//!
//! With the loaded image size `w × h`, `fx = fy = f · w / W` and the principal point is the image
//! centre `(w/2, h/2)`.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};

use super::npy::{Dtype, NpyArray, NpyError, NpyHeader, shape_str};
use super::{Dataset, isometry_from_rt, load_same_size};
use crate::DataError;
use crate::camera::PinholeCamera;
use crate::image::Image;

/// `P` with `R_cv = R_llff · P` (see the module docs): LLFF (down, right, back) columns to
/// OpenCV (right, down, forward).
pub fn cv_from_llff_axes() -> Matrix3<f64> {
    Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
}

/// Loads the LLFF scene in `scene_dir` at downscale `factor` (images from `images_{factor}/`,
/// or `images/` when `factor == 1`). Images are sorted by file name (`.png`, `.jpg`, `.jpeg`,
/// any case); `bounds` holds each row's `[near, far]`.
///
/// Errors name the file or folder: a missing folder or `poses_bounds.npy`, an NPY file that is
/// not `<f8`, C order, shape `(N, 17)`, a pose whose rotation is not orthonormal, a number of
/// images different from `N`, images of different sizes, or an unreadable image.
pub fn load_llff(scene_dir: impl AsRef<Path>, factor: u32) -> Result<Dataset, DataError> {
    let scene_dir = scene_dir.as_ref();
    let npy_path = scene_dir.join("poses_bounds.npy");
    let (rows, values) = read_npy_f64_matrix(&npy_path, 17)?;

    let folder = if factor == 1 {
        scene_dir.join("images")
    } else {
        scene_dir.join(format!("images_{factor}"))
    };
    if !folder.is_dir() {
        return Err(DataError::Format {
            expected: format!(
                "a folder of {rows} images (downscale factor {factor}), one per row of {}",
                npy_path.display()
            ),
            found: format!("no such folder ({})", image_folders(scene_dir)),
            path: folder,
        });
    }
    let paths = list_images(&folder)?;
    if paths.len() != rows {
        return Err(DataError::Format {
            path: folder,
            expected: format!("{rows} images, one per row of {}", npy_path.display()),
            found: format!("{} images", paths.len()),
        });
    }
    let (images, (width, height)) = load_same_size(&paths, &folder, |p| Image::load(p))?;

    let permutation = cv_from_llff_axes();
    let mut world_from_camera = Vec::with_capacity(rows);
    let mut bounds = Vec::with_capacity(rows);
    let mut hwf0 = None;
    for (i, row) in values.chunks_exact(17).enumerate() {
        let m = |r: usize, c: usize| row[5 * r + c];
        let r_llff = Matrix3::from_fn(m);
        let centre = Vector3::new(m(0, 3), m(1, 3), m(2, 3));
        let what = format!("row {i}");
        // Checked first as stored, so that an error shows the file's numbers (`P` is a
        // rotation: `R_llff` is one iff `R_llff · P` is).
        isometry_from_rt(r_llff, centre, &npy_path, &what)?;
        world_from_camera.push(isometry_from_rt(
            r_llff * permutation,
            centre,
            &npy_path,
            &what,
        )?);
        let (near, far) = (row[15], row[16]);
        if !(near.is_finite() && far.is_finite() && 0.0 < near && near < far) {
            return Err(DataError::Format {
                path: npy_path,
                expected: format!("{what}: bounds 0 < near < far"),
                found: format!("near = {near}, far = {far}"),
            });
        }
        bounds.push([near, far]);
        hwf0.get_or_insert([m(0, 4), m(1, 4), m(2, 4)]);
    }
    // `rows ≥ 1` since it equals the (non-empty) number of images.
    let [_, w0, f0] = hwf0.unwrap_or([f64::NAN; 3]);
    if !(w0.is_finite() && w0 > 0.0 && f0.is_finite() && f0 > 0.0) {
        return Err(DataError::Format {
            path: npy_path,
            expected: "row 0: positive original width W and focal f".to_owned(),
            found: format!("W = {w0}, f = {f0}"),
        });
    }
    let focal = f0 * width as f64 / w0;
    let names = paths
        .iter()
        .map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect::<Option<Vec<_>>>()
        .unwrap_or_default();
    Ok(Dataset {
        images,
        world_from_camera,
        camera: PinholeCamera::centred(width, height, focal),
        bounds: Some(bounds),
        names,
    })
}

/// The `images*` folders of `scene_dir`, sorted, for an error message: `"the scene has images,
/// images_4"` or `"the scene has no images* folder"`.
fn image_folders(scene_dir: &Path) -> String {
    let mut names: Vec<String> = std::fs::read_dir(scene_dir)
        .into_iter()
        .flatten()
        .filter_map(|e| {
            let e = e.ok()?;
            let name = e.file_name().into_string().ok()?;
            (name.starts_with("images") && e.path().is_dir()).then_some(name)
        })
        .collect();
    names.sort();
    if names.is_empty() {
        "the scene has no images* folder".to_owned()
    } else {
        format!("the scene has {}", names.join(", "))
    }
}

/// The image files (`.png`, `.jpg`, `.jpeg`, any case) of `folder`, sorted by file name.
pub(super) fn list_images(folder: &Path) -> Result<Vec<PathBuf>, DataError> {
    let io_err = |error| DataError::Io {
        path: folder.to_path_buf(),
        error,
    };
    let mut paths = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(io_err)? {
        let path = entry.map_err(io_err)?.path();
        let is_image = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"));
        if is_image && path.is_file() {
            paths.push(path);
        }
    }
    // Same folder, so ordering the paths orders the file names.
    paths.sort();
    Ok(paths)
}

/// Reads a 2-D little-endian float64 NPY array with `cols` columns ([`NpyArray::parse`]:
/// format versions 1.0 to 3.0) whose header has `'descr': '<f8'`, `'fortran_order': False` and
/// `'shape': (N, cols)`, `N ≥ 1`. Returns `N` and the row-major values. Anything else is a
/// [`DataError::Format`] naming the file and what was expected.
pub fn read_npy_f64_matrix(path: &Path, cols: usize) -> Result<(usize, Vec<f64>), DataError> {
    let bytes = std::fs::read(path).map_err(|error| DataError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let bad = |expected: &str, found: String| DataError::Format {
        path: path.to_path_buf(),
        expected: expected.to_owned(),
        found,
    };
    let npy_err = |e: NpyError| bad(&e.expected, e.found);
    // The header first, so that a wrong type or shape is reported rather than the data length.
    let header = NpyHeader::parse(&bytes).map_err(npy_err)?;
    if header.dtype != Dtype::F64 {
        return Err(bad(
            "'descr': '<f8' (little-endian float64)",
            format!("'descr': '{}'", header.dtype),
        ));
    }
    let rows = match header.shape[..] {
        [rows, c] if c == cols && rows >= 1 => rows,
        _ => {
            return Err(bad(
                &format!("'shape': (N, {cols}) with N ≥ 1"),
                format!("'shape': {}", shape_str(&header.shape)),
            ));
        }
    };
    let array = NpyArray::parse(&bytes).map_err(npy_err)?;
    Ok((rows, array.to_f64_vec()))
}

/// Writes `values` (row-major, `values.len() / cols` rows) as a 2-D little-endian float64 NPY
/// file (format 1.0, C order) that [`read_npy_f64_matrix`] reads back: with `cols = 17`, an LLFF
/// `poses_bounds.npy`.
///
/// # Panics
/// If `cols` is 0 or does not divide `values.len()`.
pub fn write_npy_f64_matrix(path: &Path, cols: usize, values: &[f64]) -> std::io::Result<()> {
    assert!(
        cols >= 1 && values.len().is_multiple_of(cols),
        "{} values do not fill rows of {cols}",
        values.len()
    );
    let array = NpyArray::from_f64(values)
        .reshaped(vec![values.len() / cols, cols])
        .expect("cols divides the number of values");
    std::fs::write(path, array.to_bytes())
}

/// An NPY 1.0 file with the header dict `dict` (any text, for tests of bad headers), then
/// `values` little-endian.
#[cfg(test)]
fn npy_bytes(dict: &str, values: &[f64]) -> Vec<u8> {
    let mut bytes = super::npy::npy_header_bytes(dict);
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn temp_dir(name: &str) -> cpose_core::testing::TempDir {
        cpose_core::testing::TempDir::new(&format!("llff-{name}"))
    }

    /// An NPY v1 file with the given header dict and values.
    fn write_npy(path: &Path, dict: &str, values: &[f64]) {
        std::fs::write(path, npy_bytes(dict, values)).unwrap();
    }

    /// One LLFF row: identity-ish LLFF rotation columns (down, right, back) = world (x, y, z).
    fn row(centre: [f64; 3]) -> Vec<f64> {
        let mut r = vec![0.0; 17];
        let m = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let hwf = [30.0, 40.0, 50.0];
        for (i, m_row) in m.iter().enumerate() {
            r[5 * i..5 * i + 3].copy_from_slice(m_row);
            r[5 * i + 3] = centre[i];
            r[5 * i + 4] = hwf[i];
        }
        r[15] = 1.0;
        r[16] = 10.0;
        r
    }

    #[test]
    fn npy_header_is_parsed_and_bad_headers_are_rejected() {
        let dir = temp_dir("npy");
        let path = dir.join("poses_bounds.npy");
        let values: Vec<f64> = [row([1.0, 2.0, 3.0]), row([4.0, 5.0, 6.0])].concat();
        write_npy(
            &path,
            "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 17), }",
            &values,
        );
        let (rows, read) = read_npy_f64_matrix(&path, 17).unwrap();
        assert_eq!((rows, read), (2, values.clone()));
        for (dict, needle) in [
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 17), }",
                "<f8",
            ),
            (
                "{'descr': '<f8', 'fortran_order': True, 'shape': (2, 17), }",
                "fortran_order",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (17, 2), }",
                "(N, 17)",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (34,), }",
                "(N, 17)",
            ),
        ] {
            write_npy(&path, dict, &values);
            let err = read_npy_f64_matrix(&path, 17).unwrap_err().to_string();
            assert!(
                err.contains(needle) && err.contains("poses_bounds.npy"),
                "{err}"
            );
        }
        write_npy(
            &path,
            "{'descr': '<f8', 'fortran_order': False, 'shape': (3, 17), }",
            &values,
        );
        let err = read_npy_f64_matrix(&path, 17).unwrap_err().to_string();
        assert!(err.contains("data bytes"), "{err}");
        std::fs::write(&path, b"not numpy at all").unwrap();
        assert!(read_npy_f64_matrix(&path, 17).is_err());
    }

    #[test]
    fn synthetic_scene_loads_with_permuted_axes_and_scaled_focal() {
        let dir = temp_dir("scene");
        let values: Vec<f64> = [row([1.0, 2.0, 3.0]), row([4.0, 5.0, 6.0])].concat();
        let dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 17), }";
        write_npy(&dir.join("poses_bounds.npy"), dict, &values);
        // Missing image folder.
        let err = load_llff(&dir, 4).unwrap_err().to_string();
        assert!(err.contains("images_4"), "{err}");
        let folder = dir.join("images_4");
        std::fs::create_dir_all(&folder).unwrap();
        let grey = |v: f32| Image::from_fn(10, 8, move |_, _| [v; 3]);
        grey(0.2).save_png(folder.join("b.png")).unwrap();
        // N mismatch: one image for two rows.
        let err = load_llff(&dir, 4).unwrap_err().to_string();
        assert!(
            err.contains("2 images") && err.contains("got 1 images"),
            "{err}"
        );
        grey(0.8).save_png(folder.join("a.png")).unwrap();
        let data = load_llff(&dir, 4).unwrap();
        assert_eq!(data.names, ["a.png", "b.png"]);
        assert!((data.images[0].pixel(0, 0)[0] - 0.8).abs() < 1e-2);
        // f = 50 at W = 40 → 12.5 at width 10; principal point at the centre.
        let cam = data.camera;
        assert_eq!((cam.width, cam.height), (10, 8));
        assert_eq!((cam.fx, cam.fy, cam.cx, cam.cy), (12.5, 12.5, 5.0, 4.0));
        assert_eq!(
            data.bounds.as_deref(),
            Some(&[[1.0, 10.0], [1.0, 10.0]][..])
        );
        // LLFF columns (down, right, back) = world (x, y, z), so OpenCV (right, down, forward)
        // = world (y, x, −z).
        let pose = data.world_from_camera[1];
        let r = pose.rotation.to_rotation_matrix();
        let expect = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
        assert!((r.matrix() - expect).amax() < 1e-12);
        assert_eq!(pose.translation.vector, Vector3::new(4.0, 5.0, 6.0));
        // Different sizes.
        Image::from_fn(9, 8, |_, _| [0.0; 3])
            .save_png(folder.join("b.png"))
            .unwrap();
        let err = load_llff(&dir, 4).unwrap_err().to_string();
        assert!(err.contains("b.png") && err.contains("10×8"), "{err}");
        // Missing npy.
        let err = load_llff(dir.join("nowhere"), 4).unwrap_err().to_string();
        assert!(err.contains("poses_bounds.npy"), "{err}");
    }

    /// A fresh valid scene: `n` rows and `n` textured `10×8` PNGs `image000.png, …` in
    /// `images_8/`.
    fn valid_scene(name: &str, n: usize) -> cpose_core::testing::TempDir {
        let dir = temp_dir(name);
        let folder = dir.join("images_8");
        std::fs::create_dir_all(&folder).unwrap();
        let values: Vec<f64> = (0..n).flat_map(|i| row([i as f64, 0.0, 0.0])).collect();
        write_npy_f64_matrix(&dir.join("poses_bounds.npy"), 17, &values).unwrap();
        for i in 0..n {
            crate::image::procedural_texture(10, 8, i as u64)
                .save_png(folder.join(format!("image{i:03}.png")))
                .unwrap();
        }
        assert_eq!(load_llff(&dir, 8).unwrap().len(), n);
        dir
    }

    /// The message of `load_llff`'s error, asserting that it is one line and names `file`.
    fn one_line_error(dir: &Path, factor: u32, file: &str) -> String {
        let message = load_llff(dir, factor).unwrap_err().to_string();
        assert_eq!(message.lines().count(), 1, "{message}");
        assert!(message.contains(file), "{file}: {message}");
        message
    }

    /// Issue "bad input: missing images, a poses_bounds.npy of the wrong shape, mismatched image
    /// sizes — one clear message": each bad scene is an error (not a panic) whose message is one
    /// line naming the file or folder at fault and what was expected.
    #[test]
    fn bad_scenes_are_rejected_with_one_line_naming_the_file() {
        let dir = valid_scene("bad", 3);
        let folder = dir.join("images_8");
        let npy = dir.join("poses_bounds.npy");
        let image1 = folder.join("image001.png");
        let good_png = std::fs::read(&image1).unwrap();

        // A missing image: 2 images for 3 rows.
        std::fs::remove_file(&image1).unwrap();
        let m = one_line_error(&dir, 8, "images_8");
        assert!(
            m.contains("expected 3 images, one per row of")
                && m.contains("poses_bounds.npy")
                && m.contains("got 2 images"),
            "{m}"
        );
        std::fs::write(&image1, &good_png).unwrap();

        // No folder for the factor: the message lists the folders there are.
        let m = one_line_error(&dir, 4, "images_4");
        assert!(
            m.contains("expected a folder of 3 images (downscale factor 4)")
                && m.contains("got no such folder (the scene has images_8)"),
            "{m}"
        );
        let m = one_line_error(&dir, 1, "images:");
        assert!(m.contains("no such folder"), "{m}");

        // poses_bounds.npy of the wrong shape: N × 15, and 1-D.
        let values: Vec<f64> = (0..3).flat_map(|i| row([i as f64, 0.0, 0.0])).collect();
        write_npy_f64_matrix(&npy, 15, &values[..45]).unwrap();
        let m = one_line_error(&dir, 8, "poses_bounds.npy");
        assert!(
            m.contains("expected 'shape': (N, 17) with N ≥ 1, got 'shape': (3, 15)"),
            "{m}"
        );
        write_npy(
            &npy,
            "{'descr': '<f8', 'fortran_order': False, 'shape': (51,), }",
            &values,
        );
        let m = one_line_error(&dir, 8, "poses_bounds.npy");
        assert!(m.contains("got 'shape': (51,)"), "{m}");
        // A row that is not a pose (nalgebra prints matrices on several lines; we do not).
        let mut bad_rotation = values.clone();
        bad_rotation[17] = 2.0;
        write_npy_f64_matrix(&npy, 17, &bad_rotation).unwrap();
        let m = one_line_error(&dir, 8, "poses_bounds.npy");
        assert!(m.contains("row 1: a rotation"), "{m}");
        write_npy_f64_matrix(&npy, 17, &values).unwrap();

        // Images of different sizes: named with the first image and both sizes.
        crate::image::procedural_texture(9, 8, 1)
            .save_png(&image1)
            .unwrap();
        let m = one_line_error(&dir, 8, "image001.png");
        assert!(
            m.contains("expected the size of the first image")
                && m.contains("image000.png, 10×8, got 9×8"),
            "{m}"
        );

        // A truncated PNG, and a file that is not an image at all.
        std::fs::write(&image1, &good_png[..good_png.len() / 2]).unwrap();
        let m = one_line_error(&dir, 8, "image001.png");
        assert!(m.contains("expected valid PNG data"), "{m}");
        std::fs::write(&image1, b"not an image").unwrap();
        let m = one_line_error(&dir, 8, "image001.png");
        assert!(m.contains("expected PNG or JPEG data"), "{m}");

        std::fs::write(&image1, &good_png).unwrap();
        assert_eq!(load_llff(&dir, 8).unwrap().len(), 3);
    }

    /// The COLMAP sparse points of fern (`sparse/0/points3D.bin`): per point `u64 id, 3 × f64
    /// xyz, 3 × u8 rgb, f64 error, u64 track length, track × (i32, i32)`.
    fn colmap_points(path: &Path) -> Vec<Vector3<f64>> {
        let b = std::fs::read(path).unwrap();
        let u64_at = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap());
        let f64_at = |o: usize| f64::from_le_bytes(b[o..o + 8].try_into().unwrap());
        let n = u64_at(0) as usize;
        let mut o = 8;
        let mut points = Vec::with_capacity(n);
        for _ in 0..n {
            points.push(Vector3::new(f64_at(o + 8), f64_at(o + 16), f64_at(o + 24)));
            o += 8 + 24 + 3 + 8;
            let track = u64_at(o) as usize;
            o += 8 + 8 * track;
        }
        assert_eq!(o, b.len());
        points
    }

    #[test]
    fn fern_cameras_look_at_the_colmap_points_with_opencv_axes() {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return;
        };
        let scene = data_dir.join("llff/fern");
        let data = load_llff(&scene, 8).unwrap();
        assert_eq!(data.len(), 20);
        assert_eq!((data.camera.width, data.camera.height), (504, 378));
        // Original 4032 wide, focal ≈ 3260.5 → ×504/4032.
        assert!(
            (data.camera.fx - 3260.526 / 8.0).abs() < 0.01,
            "{:?}",
            data.camera
        );
        assert_eq!(data.names[0], "image000.png");
        let points = colmap_points(&scene.join("sparse/0/points3D.bin"));
        let bounds = data.bounds.as_ref().unwrap();
        for (i, pose) in data.world_from_camera.iter().enumerate() {
            let r = pose.rotation.to_rotation_matrix();
            assert!((r.matrix().determinant() - 1.0).abs() < 1e-9);
            let [near, far] = bounds[i];
            let cam_points: Vec<_> = points
                .iter()
                .map(|p| pose.inverse_transform_point(&Point3::from(*p)))
                .collect();
            // The scene lies in front (+z) within LLFF's bounds …
            let in_depth = cam_points
                .iter()
                .filter(|p| p.z > 0.9 * near && p.z < 1.1 * far)
                .count();
            assert!(in_depth as f64 > 0.99 * points.len() as f64, "camera {i}");
            // … and projects into the image (x right, y down; swapping x and y drops this to
            // about 0.83 on this scene).
            let c = data.camera;
            let inside = cam_points
                .iter()
                .filter(|p| {
                    let (u, v) = (c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy);
                    p.z > 0.0
                        && (0.0..c.width as f64).contains(&u)
                        && (0.0..c.height as f64).contains(&v)
                })
                .count();
            assert!(
                inside as f64 > 0.95 * points.len() as f64,
                "camera {i}: {inside}"
            );
        }
    }
}
