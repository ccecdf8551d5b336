//! NumPy `.npz` archives (a ZIP of `.npy` files, [`crate::zip`]) and event streams stored in
//! them as EventNeRF does: four 1-D arrays `x`, `y`, `t`, `p` of equal length.
//!
//! Reading accepts every numeric dtype numpy writes for these columns
//! ([`Dtype`](cpose_nerf::data::npy::Dtype)): integer or integral float pixels, integer or float
//! times in a [`TimeUnit`], polarities coded `{−1, 1}`, `{0, 1}` or as booleans. The checks of
//! [`crate::format`] apply (out-of-sensor events are dropped and counted, out-of-order times are
//! errors). Writing produces `x, y` as `<u2`, `p` as `|i1` (±1, summed as-is by EventNeRF) and
//! `t` as `<f8` seconds or `<i8` integers of a finer unit, in an archive of STORED entries that
//! `np.load` reads.

use std::collections::BTreeMap;
use std::path::Path;

use cpose_nerf::data::npy::{NpyArray, NpyValue, shape_str};

use crate::error::EventsError;
use crate::format::{LoadReport, ReadOptions, StreamBuilder, TimeUnit};
use crate::stream::EventStream;
use crate::zip::{read_zip, write_zip};

/// The arrays of an `.npz` file by name (the entry name without `.npy`), in name order.
pub fn read_npz(path: &Path) -> Result<BTreeMap<String, NpyArray>, EventsError> {
    let bytes = std::fs::read(path).map_err(|error| EventsError::Read {
        path: path.to_path_buf(),
        error,
    })?;
    let entries =
        read_zip(&bytes).map_err(|e| EventsError::format(path, None, e.expected, e.found))?;
    let mut arrays = BTreeMap::new();
    for (name, data) in entries {
        let key = name.strip_suffix(".npy").unwrap_or(&name).to_owned();
        let array = NpyArray::parse(&data).map_err(|e| {
            EventsError::format(path, Some(format!("entry {name:?}")), e.expected, e.found)
        })?;
        arrays.insert(key, array);
    }
    Ok(arrays)
}

/// Writes `arrays` as an `.npz` file (entries `<name>.npy`, STORED), atomically
/// ([`cpose_core::fs::write_atomic`]).
pub fn write_npz(path: &Path, arrays: &[(&str, &NpyArray)]) -> Result<(), EventsError> {
    let files: Vec<(String, Vec<u8>)> = arrays
        .iter()
        .map(|(name, a)| (format!("{name}.npy"), a.to_bytes()))
        .collect();
    let entries: Vec<(&str, &[u8])> = files
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice()))
        .collect();
    let bytes =
        write_zip(&entries).map_err(|e| EventsError::format(path, None, e.expected, e.found))?;
    cpose_core::fs::write_atomic(path, bytes).map_err(|error| EventsError::Write {
        path: path.to_path_buf(),
        error,
    })
}

/// The arrays EventNeRF reads, in its order.
const EVENT_ARRAYS: [&str; 4] = ["x", "y", "t", "p"];

/// Reads the events of an `.npz` with 1-D arrays `x`, `y`, `t`, `p` of equal length (other
/// arrays are ignored), times in `options.time_unit`, on a sensor of `options`' size.
///
/// Errors name the file and the array: a missing array (listing those present), an array that is
/// not 1-D, lengths that differ, a non-integral pixel, a non-finite or overflowing time, a
/// polarity other than −1, 0, 1 (or mixed codings), a time earlier than its predecessor. Events
/// outside the sensor are dropped and counted in the report.
pub fn read_events_npz(
    path: &Path,
    options: &ReadOptions,
) -> Result<(EventStream, LoadReport), EventsError> {
    let arrays = read_npz(path)?;
    let mut columns = Vec::with_capacity(4);
    for name in EVENT_ARRAYS {
        let array = arrays.get(name).ok_or_else(|| {
            EventsError::format(
                path,
                None,
                format!(
                    "arrays {} (EventNeRF's event layout)",
                    EVENT_ARRAYS.join(", ")
                ),
                format!(
                    "no array {name:?}; the file has {}",
                    if arrays.is_empty() {
                        "no arrays".to_owned()
                    } else {
                        arrays.keys().cloned().collect::<Vec<_>>().join(", ")
                    }
                ),
            )
        })?;
        if array.shape().len() != 1 {
            return Err(EventsError::format(
                path,
                Some(format!("array '{name}'")),
                "a 1-D array",
                format!("shape {}", shape_str(array.shape())),
            ));
        }
        columns.push(array);
    }
    let [x, y, t, p] = [columns[0], columns[1], columns[2], columns[3]];
    let n = x.len();
    if [y, t, p].iter().any(|a| a.len() != n) {
        return Err(EventsError::format(
            path,
            None,
            "arrays x, y, t, p of equal length",
            format!(
                "lengths x {}, y {}, t {}, p {}",
                x.len(),
                y.len(),
                t.len(),
                p.len()
            ),
        ));
    }
    let bad = |name: &str, i: usize, expected: &str, found: String| {
        EventsError::format(
            path,
            Some(format!("array '{name}' at index {i}")),
            expected,
            found,
        )
    };
    let pixel = |a: &NpyArray, name: &str, i: usize| match a.value(i) {
        NpyValue::Int(v) => Ok(v),
        // Integral floats only; ±∞ and NaN fail `fract() == 0`, huge values land outside the
        // sensor after the saturating cast.
        NpyValue::Float(v) if v.fract() == 0.0 => Ok(v as i128),
        NpyValue::Float(v) => Err(bad(name, i, "an integer pixel coordinate", v.to_string())),
    };
    let unit = options.time_unit;
    let mut builder = StreamBuilder::new(path, "event", options, n);
    for i in 0..n {
        let t_ns = match t.value(i) {
            NpyValue::Int(v) => unit.int_to_nanos(v),
            NpyValue::Float(v) => unit.float_to_nanos(v),
        }
        .ok_or_else(|| {
            let v = match t.value(i) {
                NpyValue::Int(v) => v.to_string(),
                NpyValue::Float(v) => v.to_string(),
            };
            bad(
                "t",
                i,
                &format!("a finite time in {unit} within ±292 years"),
                v,
            )
        })?;
        let polarity = match p.value(i) {
            NpyValue::Int(v @ -1..=1) => v as i8,
            NpyValue::Float(v) if v == -1.0 || v == 0.0 || v == 1.0 => v as i8,
            NpyValue::Int(v) => return Err(bad("p", i, "polarity −1, 0 or 1", v.to_string())),
            NpyValue::Float(v) => return Err(bad("p", i, "polarity −1, 0 or 1", v.to_string())),
        };
        builder.add(i, t_ns, pixel(x, "x", i)?, pixel(y, "y", i)?, polarity)?;
    }
    builder.finish()
}

/// Writes `stream` as an EventNeRF `.npz`: `x`, `y` as `<u2`, `p` as `|i1` (±1) and `t` in
/// `time_unit` — `<f8` for seconds (exact to the nanosecond below about 10⁶ s), `<i8` rounded
/// to the nearest unit otherwise.
pub fn write_events_npz(
    path: &Path,
    stream: &EventStream,
    time_unit: TimeUnit,
) -> Result<(), EventsError> {
    let t = match time_unit {
        TimeUnit::Seconds => {
            let secs: Vec<f64> = stream.t_ns().iter().map(|&n| n as f64 * 1e-9).collect();
            NpyArray::from_f64(&secs)
        }
        unit => {
            let per = unit.nanos_per_unit();
            // Rounded to the nearest unit, halves away from zero.
            let values: Vec<i64> = stream
                .t_ns()
                .iter()
                .map(|&n| (n + n.signum() * per / 2) / per)
                .collect();
            NpyArray::from_i64(&values)
        }
    };
    let x = NpyArray::from_u16(stream.x());
    let y = NpyArray::from_u16(stream.y());
    let p = NpyArray::from_i8(stream.p());
    write_npz(path, &[("x", &x), ("y", &y), ("t", &t), ("p", &p)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::PolarityCoding;
    use crate::zip::tests::{TestEntry, zip_with};
    use cpose_core::Timestamp;
    use cpose_nerf::data::npy::Dtype;

    fn temp_dir(name: &str) -> cpose_core::testing::TempDir {
        cpose_core::testing::TempDir::new(&format!("npz-{name}"))
    }

    fn sample_stream() -> EventStream {
        EventStream::from_columns(
            6,
            4,
            vec![0, 1_000, 1_000, 2_500_000, 1_234_567_891],
            vec![0, 5, 1, 2, 3],
            vec![0, 3, 1, 2, 0],
            vec![1, -1, -1, 1, 1],
        )
        .unwrap()
    }

    /// An array of `dtype` from `f64` values (exact for the test values).
    fn array(dtype: Dtype, values: &[f64]) -> NpyArray {
        let mut data = Vec::new();
        for &v in values {
            match dtype {
                Dtype::Bool | Dtype::U8 => data.push(v as u8),
                Dtype::I8 => data.push(v as i8 as u8),
                Dtype::I16 => data.extend((v as i16).to_le_bytes()),
                Dtype::U16 => data.extend((v as u16).to_le_bytes()),
                Dtype::I32 => data.extend((v as i32).to_le_bytes()),
                Dtype::U32 => data.extend((v as u32).to_le_bytes()),
                Dtype::I64 => data.extend((v as i64).to_le_bytes()),
                Dtype::U64 => data.extend((v as u64).to_le_bytes()),
                Dtype::F32 => data.extend((v as f32).to_le_bytes()),
                Dtype::F64 => data.extend(v.to_le_bytes()),
            }
        }
        NpyArray::from_raw(dtype, vec![values.len()], data).unwrap()
    }

    #[test]
    fn events_round_trip_through_npz_in_every_unit() {
        let dir = temp_dir("roundtrip");
        let path = dir.join("events.npz");
        let s = sample_stream();
        for unit in [TimeUnit::Seconds, TimeUnit::Nanoseconds] {
            write_events_npz(&path, &s, unit).unwrap();
            let opts = ReadOptions::new(6, 4).with_time_unit(unit);
            let (back, report) = read_events_npz(&path, &opts).unwrap();
            assert_eq!(back, s, "{unit}");
            assert_eq!(report.events_read, 5);
            assert_eq!(report.dropped_out_of_bounds, 0);
            assert_eq!(report.polarity, PolarityCoding::Signed);
        }
        // Microseconds round to the nearest microsecond.
        write_events_npz(&path, &s, TimeUnit::Microseconds).unwrap();
        let opts = ReadOptions::new(6, 4).with_time_unit(TimeUnit::Microseconds);
        let (back, _) = read_events_npz(&path, &opts).unwrap();
        assert_eq!(back.t_ns(), [0, 1_000, 1_000, 2_500_000, 1_234_568_000]);
        // The arrays have the documented dtypes.
        write_events_npz(&path, &s, TimeUnit::Seconds).unwrap();
        let arrays = read_npz(&path).unwrap();
        let dtypes: Vec<(&str, Dtype)> = arrays
            .iter()
            .map(|(k, a)| (k.as_str(), a.dtype()))
            .collect();
        assert_eq!(
            dtypes,
            [
                ("p", Dtype::I8),
                ("t", Dtype::F64),
                ("x", Dtype::U16),
                ("y", Dtype::U16)
            ]
        );
        assert_eq!(arrays["t"].to_f64_vec()[4], 1.234567891);
    }

    #[test]
    fn every_numpy_dtype_is_accepted_in_a_deflated_archive() {
        let dir = temp_dir("dtypes");
        let path = dir.join("events.npz");
        let xs = [0.0, 3.0, 5.0];
        let ys = [1.0, 0.0, 3.0];
        let ps01 = [1.0, 0.0, 1.0];
        let ps = [1.0, -1.0, 1.0];
        for (xy_dtype, t_dtype, p_dtype) in [
            (Dtype::U16, Dtype::F64, Dtype::I8),
            (Dtype::I16, Dtype::F32, Dtype::I16),
            (Dtype::I32, Dtype::I64, Dtype::I32),
            (Dtype::I64, Dtype::U64, Dtype::I64),
            (Dtype::U8, Dtype::U32, Dtype::Bool),
            (Dtype::U32, Dtype::I32, Dtype::U8),
            (Dtype::F64, Dtype::F64, Dtype::F64),
            (Dtype::F32, Dtype::I64, Dtype::F32),
        ] {
            let unsigned_p = matches!(p_dtype, Dtype::Bool | Dtype::U8);
            let p_values = if unsigned_p { &ps01 } else { &ps };
            let t_values: &[f64] = if t_dtype.is_float() {
                &[0.5, 0.75, 1.0]
            } else {
                &[500, 750, 1000].map(f64::from)
            };
            let arrays = [
                ("x", array(xy_dtype, &xs)),
                ("y", array(xy_dtype, &ys)),
                ("t", array(t_dtype, t_values)),
                ("p", array(p_dtype, p_values)),
            ];
            let files: Vec<(String, Vec<u8>)> = arrays
                .iter()
                .map(|(n, a)| (format!("{n}.npy"), a.to_bytes()))
                .collect();
            let entries: Vec<TestEntry<'_>> = files
                .iter()
                .map(|(name, data)| TestEntry {
                    name,
                    data,
                    deflate: true,
                    zip64: false,
                })
                .collect();
            std::fs::write(&path, zip_with(&entries, false)).unwrap();
            let unit = if t_dtype.is_float() {
                TimeUnit::Seconds
            } else {
                TimeUnit::Milliseconds
            };
            let opts = ReadOptions::new(6, 4).with_time_unit(unit);
            let (s, report) = read_events_npz(&path, &opts)
                .unwrap_or_else(|e| panic!("{xy_dtype} {t_dtype} {p_dtype}: {e}"));
            assert_eq!(s.x(), [0, 3, 5]);
            assert_eq!(s.y(), [1, 0, 3]);
            assert_eq!(s.t_ns(), [500_000_000, 750_000_000, 1_000_000_000]);
            assert_eq!(s.p(), [1, -1, 1], "{p_dtype}");
            let coding = if unsigned_p {
                PolarityCoding::ZeroOne
            } else {
                PolarityCoding::Signed
            };
            assert_eq!(report.polarity, coding);
        }
        // The unit applies to integer times too: 500 read as seconds.
        assert_eq!(
            read_events_npz(&path, &ReadOptions::new(6, 4))
                .unwrap()
                .0
                .time_span()
                .map(|(a, _)| a),
            Some(Timestamp::from_nanos(500_000_000_000))
        );
    }

    /// Writes arrays `(name, dtype, values)` to `path` as an npz.
    fn write_arrays(path: &Path, arrays: &[(&str, Dtype, &[f64])]) {
        let built: Vec<(&str, NpyArray)> =
            arrays.iter().map(|(n, d, v)| (*n, array(*d, v))).collect();
        let refs: Vec<(&str, &NpyArray)> = built.iter().map(|(n, a)| (*n, a)).collect();
        write_npz(path, &refs).unwrap();
    }

    /// The one-line error message of reading `path` on a 6 × 4 sensor.
    fn error_of(path: &Path) -> String {
        let m = read_events_npz(path, &ReadOptions::new(6, 4))
            .unwrap_err()
            .to_string();
        assert_eq!(m.lines().count(), 1, "{m}");
        assert!(m.contains("events.npz"), "{m}");
        m
    }

    #[test]
    fn bad_npz_files_are_errors_naming_the_file_and_array() {
        let dir = temp_dir("bad");
        let path = dir.join("events.npz");
        let f = Dtype::F64;
        let i = Dtype::I64;
        const THREE: [f64; 3] = [0.0, 1.0, 2.0];
        let three = THREE;
        let good = |t: &'static [f64], p: &'static [f64]| {
            vec![
                ("x", i, &[0.0, 1.0, 2.0][..]),
                ("y", i, &[0.0, 1.0, 2.0][..]),
                ("t", f, t),
                ("p", i, p),
            ]
        };
        write_arrays(&path, &good(&[0.0, 0.5, 1.0], &[1.0, -1.0, 1.0]));
        assert_eq!(
            read_events_npz(&path, &ReadOptions::new(6, 4))
                .unwrap()
                .0
                .len(),
            3
        );

        // A missing array: the message lists the arrays present.
        write_arrays(
            &path,
            &[("x", i, &three), ("y", i, &three), ("t", f, &three)],
        );
        let m = error_of(&path);
        assert!(
            m.contains("expected arrays x, y, t, p")
                && m.contains("got no array \"p\"; the file has t, x, y"),
            "{m}"
        );
        // Mismatched lengths.
        write_arrays(
            &path,
            &[
                ("x", i, &three),
                ("y", i, &three),
                ("t", f, &[0.0, 1.0]),
                ("p", i, &three),
            ],
        );
        let m = error_of(&path);
        assert!(m.ends_with("got lengths x 3, y 3, t 2, p 3"), "{m}");
        // Out of time order: names the index and the previous time.
        write_arrays(&path, &good(&[0.0, 1.0, 0.5], &[1.0, 1.0, 1.0]));
        let m = error_of(&path);
        assert!(
            m.contains("event 2: expected times in non-decreasing order (after 1000000000 ns at event 1), got 500000000 ns"),
            "{m}"
        );
        // A bad polarity, mixed codings, a non-finite time.
        write_arrays(&path, &good(&THREE, &[1.0, 2.0, 1.0]));
        assert!(
            error_of(&path).contains("array 'p' at index 1: expected polarity −1, 0 or 1, got 2")
        );
        write_arrays(&path, &good(&THREE, &[-1.0, 0.0, 1.0]));
        let m = error_of(&path);
        assert!(
            m.contains(
                "event 1: expected polarity −1 or +1 (the file is signed: −1 at event 0), got 0"
            ),
            "{m}"
        );
        write_arrays(&path, &good(&[0.0, f64::NAN, 1.0], &[1.0, 1.0, 1.0]));
        assert!(error_of(&path).contains("array 't' at index 1: expected a finite time in s"));
        // A 2-D array and a fractional pixel.
        let x2 = array(i, &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
            .reshaped(vec![3, 2])
            .unwrap();
        let (y, t, p) = (array(i, &three), array(f, &three), array(i, &[1.0; 3]));
        write_npz(&path, &[("x", &x2), ("y", &y), ("t", &t), ("p", &p)]).unwrap();
        assert!(error_of(&path).contains("array 'x': expected a 1-D array, got shape (3, 2)"));
        write_arrays(
            &path,
            &[
                ("x", f, &[0.0, 1.5, 2.0]),
                ("y", i, &three),
                ("t", f, &three),
                ("p", i, &[1.0; 3]),
            ],
        );
        assert!(
            error_of(&path)
                .contains("array 'x' at index 1: expected an integer pixel coordinate, got 1.5")
        );
        // Not an npz, a corrupt member, a missing file.
        std::fs::write(&path, b"hello").unwrap();
        assert!(error_of(&path).contains("end-of-central-directory"));
        std::fs::write(&path, write_zip(&[("x.npy", b"garbage")]).unwrap()).unwrap();
        assert!(error_of(&path).contains("entry \"x.npy\": expected an NPY file"));
        std::fs::remove_file(&path).unwrap();
        assert!(error_of(&path).starts_with("cannot read"));
    }

    #[test]
    fn events_outside_the_sensor_are_dropped_and_counted() {
        let dir = temp_dir("bounds");
        let path = dir.join("events.npz");
        let i = Dtype::I32;
        write_arrays(
            &path,
            &[
                ("x", i, &[0.0, 6.0, -1.0, 5.0, 2.0]),
                ("y", i, &[0.0, 0.0, 1.0, 3.0, 4.0]),
                ("t", Dtype::F64, &[0.0, 0.1, 0.2, 0.3, 0.4]),
                ("p", i, &[1.0, -1.0, -1.0, 1.0, 1.0]),
            ],
        );
        let (s, report) = read_events_npz(&path, &ReadOptions::new(6, 4)).unwrap();
        assert_eq!(s.x(), [0, 5]);
        assert_eq!(s.t_ns(), [0, 300_000_000]);
        assert_eq!(report.events_read, 5);
        assert_eq!(report.dropped_out_of_bounds, 3);
        assert_eq!(
            report.to_string(),
            "5 events read, 3 dropped outside the sensor (first: event 1: (6, 0))"
        );
    }

    /// Runs `python3 -c script args…`; `None` (skipped) when python3 or one of `modules` is
    /// missing.
    fn python(modules: &str, script: &str, args: &[&Path]) -> Option<String> {
        let probe = std::process::Command::new("python3")
            .args(["-c", &format!("import {modules}")])
            .output()
            .ok()?;
        if !probe.status.success() {
            return None;
        }
        let out = std::process::Command::new("python3")
            .arg("-c")
            .arg(script)
            .args(args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "python failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        Some(String::from_utf8(out.stdout).unwrap())
    }

    /// Python's `zipfile` (the module numpy writes and reads `.npz` with) reads our archives, and
    /// we read its DEFLATE entries written with `force_zip64=True`, as `np.savez_compressed`
    /// writes them.
    #[test]
    fn archives_agree_with_pythons_zipfile() {
        let dir = temp_dir("python-zip");
        let ours = dir.join("ours.npz");
        write_events_npz(&ours, &sample_stream(), TimeUnit::Seconds).unwrap();
        let theirs = dir.join("theirs.npz");
        let script = r#"
import sys, zipfile
with zipfile.ZipFile(sys.argv[1]) as z:
    assert z.testzip() is None
    print(" ".join(f"{i.filename}:{i.file_size}" for i in z.infolist()))
with zipfile.ZipFile(sys.argv[1]) as src, zipfile.ZipFile(sys.argv[2], "w", compression=zipfile.ZIP_DEFLATED) as dst:
    for info in src.infolist():
        with dst.open(info.filename, "w", force_zip64=True) as f:
            f.write(src.read(info.filename))
"#;
        let Some(listing) = python("zipfile", script, &[&ours, &theirs]) else {
            println!("skipped: python3 not found");
            return;
        };
        let arrays = read_npz(&ours).unwrap();
        let expected: Vec<String> = ["x", "y", "t", "p"]
            .iter()
            .map(|k| format!("{k}.npy:{}", arrays[*k].to_bytes().len()))
            .collect();
        assert_eq!(listing.trim(), expected.join(" "));
        let opts = ReadOptions::new(6, 4);
        assert_eq!(
            read_events_npz(&theirs, &opts).unwrap(),
            read_events_npz(&ours, &opts).unwrap()
        );
    }

    /// numpy itself: `np.savez_compressed` files are read, and `np.load` reads ours. Skipped
    /// without numpy.
    #[test]
    fn numpy_savez_compressed_files_are_read_and_ours_load_in_numpy() {
        let dir = temp_dir("numpy");
        let theirs = dir.join("theirs.npz");
        let ours = dir.join("ours.npz");
        write_events_npz(&ours, &sample_stream(), TimeUnit::Seconds).unwrap();
        let script = r#"
import sys, numpy as np
d = np.load(sys.argv[1])
print(d["x"].dtype.str, d["y"].dtype.str, d["t"].dtype.str, d["p"].dtype.str)
print(d["x"].tolist(), d["p"].tolist(), repr(float(d["t"][-1])))
x = np.array([0, 345, 17, 17], dtype=np.uint16)
y = np.array([259, 0, 4, 4], dtype=np.int64)
t = np.array([0.0, 0.25, 1.5, 1.5], dtype=np.float64)
p = np.array([True, False, False, True])
np.savez_compressed(sys.argv[2], x=x, y=y, t=t, p=p, extra=np.eye(3, dtype=np.float32))
"#;
        let Some(out) = python("numpy", script, &[&ours, &theirs]) else {
            println!("skipped: numpy not found");
            return;
        };
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines[0], "<u2 <u2 <f8 |i1");
        assert_eq!(lines[1], "[0, 5, 1, 2, 3] [1, -1, -1, 1, 1] 1.234567891");
        let (s, report) = read_events_npz(&theirs, &ReadOptions::davis346()).unwrap();
        assert_eq!(s.x(), [0, 345, 17, 17]);
        assert_eq!(s.y(), [259, 0, 4, 4]);
        assert_eq!(s.t_ns(), [0, 250_000_000, 1_500_000_000, 1_500_000_000]);
        assert_eq!(s.p(), [1, -1, -1, 1]);
        assert_eq!(report.polarity, PolarityCoding::ZeroOne);
        let arrays = read_npz(&theirs).unwrap();
        assert_eq!(arrays["extra"].shape(), [3, 3]);
        assert_eq!(arrays["extra"].to_f64_vec()[4], 1.0);
    }
}
