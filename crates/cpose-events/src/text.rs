//! The plain text event format of the public event-camera datasets (e.g. the RPG "Event Camera
//! Dataset" `events.txt`): one event per line, `t x y p`, separated by spaces or tabs, `t` in
//! seconds, `p` coded `{0, 1}` or `{−1, 1}`. Empty lines and lines starting with `#` are skipped.
//!
//! Times written as plain decimals (`1403715273.262142976`) are converted to nanoseconds
//! exactly, digit by digit, rounding at the tenth decimal; exponent forms (`1e-3`) go through
//! `f64`. The checks of [`crate::format`] apply.

use std::io::{BufRead, BufWriter, Write};
use std::path::Path;

use crate::error::EventsError;
use crate::format::{LoadReport, PolarityCoding, ReadOptions, StreamBuilder, secs_string};
use crate::stream::EventStream;

/// Seconds as written (`[-]digits[.digits]`, or any float syntax) to nanoseconds; `None` if not
/// a number or out of the `i64` range.
pub fn parse_secs_to_nanos(s: &str) -> Option<i64> {
    let (negative, body) = match s.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, s.strip_prefix('+').unwrap_or(s)),
    };
    let (int, frac) = body.split_once('.').unwrap_or((body, ""));
    let digits = |d: &str| d.bytes().all(|b| b.is_ascii_digit());
    if (int.is_empty() && frac.is_empty()) || !digits(int) || !digits(frac) {
        // Exponents, "inf", "nan", garbage: f64 decides, then the finite range check.
        let v: f64 = s.parse().ok()?;
        let n = (v * 1e9).round();
        return (n.is_finite() && n.abs() < 2f64.powi(63)).then_some(n as i64);
    }
    let secs: i64 = if int.is_empty() { 0 } else { int.parse().ok()? };
    let mut nanos: i64 = 0;
    for k in 0..9 {
        nanos = nanos * 10 + frac.as_bytes().get(k).map_or(0, |b| i64::from(b - b'0'));
    }
    // Round half up on the tenth decimal.
    if frac.as_bytes().get(9).is_some_and(|&b| b >= b'5') {
        nanos += 1;
    }
    let total = secs.checked_mul(1_000_000_000)?.checked_add(nanos)?;
    Some(if negative { -total } else { total })
}

/// Reads a text event file on a sensor of `options`' size (the time unit is ignored: the format
/// is in seconds).
///
/// Errors name the file and the line (1-based): a line without exactly four fields, a field that
/// is not a number, a polarity other than −1, 0, 1 (or mixed codings), a time earlier than the
/// previous event's. Events outside the sensor are dropped and counted in the report.
pub fn read_events_text(
    path: &Path,
    options: &ReadOptions,
) -> Result<(EventStream, LoadReport), EventsError> {
    let read_err = |error| EventsError::Read {
        path: path.to_path_buf(),
        error,
    };
    let file = std::fs::File::open(path).map_err(read_err)?;
    let mut reader = std::io::BufReader::new(file);
    let mut builder = StreamBuilder::new(path, "line", options, 0);
    let mut line = String::new();
    let mut number = 0;
    loop {
        line.clear();
        if reader.read_line(&mut line).map_err(read_err)? == 0 {
            break;
        }
        number += 1;
        let text = line.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let bad = |expected: &str, found: String| {
            EventsError::format(path, Some(format!("line {number}")), expected, found)
        };
        let fields: Vec<&str> = text.split_whitespace().collect();
        let &[t, x, y, p] = fields.as_slice() else {
            return Err(bad(
                "4 fields `t x y p` (t in seconds)",
                format!("{} fields {text:?}", fields.len()),
            ));
        };
        let t_ns =
            parse_secs_to_nanos(t).ok_or_else(|| bad("a time in seconds", format!("{t:?}")))?;
        let pixel = |v: &str, name: &str| {
            v.parse::<i128>()
                .map_err(|_| bad(&format!("an integer pixel {name}"), format!("{v:?}")))
        };
        let polarity = match p {
            "1" | "+1" => 1,
            "0" => 0,
            "-1" => -1,
            _ => return Err(bad("polarity 0, 1 or −1, 1", format!("{p:?}"))),
        };
        builder.add(number, t_ns, pixel(x, "x")?, pixel(y, "y")?, polarity)?;
    }
    builder.finish()
}

/// Writes `stream` as text: a `#` comment naming the columns and the sensor, then one line
/// `t x y p` per event with `t` in seconds to nine decimals (exact) and `p` in `coding`.
pub fn write_events_text(
    path: &Path,
    stream: &EventStream,
    coding: PolarityCoding,
) -> Result<(), EventsError> {
    let mut out = BufWriter::new(Vec::with_capacity(stream.len() * 24));
    let io = |r: std::io::Result<()>| {
        r.map_err(|error| EventsError::Write {
            path: path.to_path_buf(),
            error,
        })
    };
    let (w, h) = (stream.width(), stream.height());
    let p_text = match coding {
        PolarityCoding::Signed => "1 brighter, -1 darker",
        PolarityCoding::ZeroOne => "1 brighter, 0 darker",
    };
    io(writeln!(
        out,
        "# t x y p (t in seconds; p {p_text}); sensor {w}x{h}"
    ))?;
    for e in stream.all().iter() {
        let p = match (coding, e.p) {
            (PolarityCoding::ZeroOne, -1) => 0,
            (_, p) => p,
        };
        io(writeln!(
            out,
            "{} {} {} {p}",
            secs_string(e.t.as_nanos()),
            e.x,
            e.y
        ))?;
    }
    let bytes = out.into_inner().map_err(|e| EventsError::Write {
        path: path.to_path_buf(),
        error: e.into_error(),
    })?;
    io(cpose_core::fs::write_atomic(path, bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> cpose_core::testing::TempDir {
        cpose_core::testing::TempDir::new(&format!("text-{name}"))
    }

    #[test]
    fn seconds_parse_exactly() {
        assert_eq!(
            parse_secs_to_nanos("1403715273.262142976"),
            Some(1_403_715_273_262_142_976)
        );
        assert_eq!(parse_secs_to_nanos("0.000000001"), Some(1));
        assert_eq!(parse_secs_to_nanos("0.0000000015"), Some(2));
        assert_eq!(parse_secs_to_nanos("0.00000000149"), Some(1));
        assert_eq!(parse_secs_to_nanos("12"), Some(12_000_000_000));
        assert_eq!(parse_secs_to_nanos(".5"), Some(500_000_000));
        assert_eq!(parse_secs_to_nanos("3."), Some(3_000_000_000));
        assert_eq!(parse_secs_to_nanos("-1.5"), Some(-1_500_000_000));
        assert_eq!(parse_secs_to_nanos("1e-3"), Some(1_000_000));
        assert_eq!(parse_secs_to_nanos("1.5E2"), Some(150_000_000_000));
        for bad in [
            "",
            ".",
            "abc",
            "1.2.3",
            "nan",
            "inf",
            "1e300",
            "99999999999999999999",
        ] {
            assert_eq!(parse_secs_to_nanos(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn text_round_trips_in_both_codings() {
        let dir = temp_dir("roundtrip");
        let path = dir.join("events.txt");
        let s = EventStream::from_columns(
            5,
            3,
            vec![-5, 0, 7, 1_000_000_000, 1_403_715_273_262_142_976],
            vec![0, 4, 1, 2, 3],
            vec![0, 2, 1, 0, 2],
            vec![1, -1, -1, 1, -1],
        )
        .unwrap();
        for coding in [PolarityCoding::ZeroOne, PolarityCoding::Signed] {
            write_events_text(&path, &s, coding).unwrap();
            let (back, report) = read_events_text(&path, &ReadOptions::new(5, 3)).unwrap();
            assert_eq!(back, s);
            assert_eq!(report.polarity, coding);
            assert_eq!(report.events_read, 5);
        }
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("# t x y p"), "{text}");
        assert!(text.contains("\n-0.000000005 0 0 1\n"), "{text}");
        assert!(text.ends_with("\n1403715273.262142976 3 2 -1\n"), "{text}");
    }

    #[test]
    fn public_dataset_layout_reads_with_comments_and_blank_lines() {
        let dir = temp_dir("public");
        let path = dir.join("events.txt");
        std::fs::write(
            &path,
            "# a comment\n0.000000000 33 39 1\n\n0.000011001 158 145 1\r\n\t0.000050000\t88 19 0\n# end\n",
        )
        .unwrap();
        let (s, report) = read_events_text(&path, &ReadOptions::new(240, 180)).unwrap();
        assert_eq!(s.t_ns(), [0, 11_001, 50_000]);
        assert_eq!(s.x(), [33, 158, 88]);
        assert_eq!(s.p(), [1, 1, -1]);
        assert_eq!(report.polarity, PolarityCoding::ZeroOne);
    }

    #[test]
    fn bad_lines_are_errors_naming_file_and_line() {
        let dir = temp_dir("bad");
        let path = dir.join("events.txt");
        let opts = ReadOptions::new(10, 10);
        let error_of = |content: &str| {
            std::fs::write(&path, content).unwrap();
            let m = read_events_text(&path, &opts).unwrap_err().to_string();
            assert_eq!(m.lines().count(), 1, "{m}");
            assert!(m.contains("events.txt: line "), "{m}");
            m
        };
        let m = error_of("# header\n0.1 1 2 1\n0.2 1 2\n");
        assert!(
            m.contains(
                "line 3: expected 4 fields `t x y p` (t in seconds), got 3 fields \"0.2 1 2\""
            ),
            "{m}"
        );
        let m = error_of("0.1 1 2 1 7\n");
        assert!(m.contains("line 1: expected 4 fields"), "{m}");
        let m = error_of("zero 1 2 1\n");
        assert!(
            m.contains("line 1: expected a time in seconds, got \"zero\""),
            "{m}"
        );
        let m = error_of("0.1 1.5 2 1\n");
        assert!(
            m.contains("expected an integer pixel x, got \"1.5\""),
            "{m}"
        );
        let m = error_of("0.1 1 2 2\n");
        assert!(
            m.contains("expected polarity 0, 1 or −1, 1, got \"2\""),
            "{m}"
        );
        let m = error_of("0.2 1 2 1\n0.1 1 2 1\n");
        assert!(m.contains("line 2: expected times in non-decreasing order (after 200000000 ns at line 1), got 100000000 ns"), "{m}");
        let m = error_of("0.1 1 2 -1\n0.2 1 2 0\n");
        assert!(
            m.contains(
                "line 2: expected polarity −1 or +1 (the file is signed: −1 at line 1), got 0"
            ),
            "{m}"
        );
        // Out of bounds: dropped and counted, not an error.
        std::fs::write(&path, "0.1 10 2 1\n0.2 1 -2 1\n0.3 9 9 1\n").unwrap();
        let (s, report) = read_events_text(&path, &opts).unwrap();
        assert_eq!(s.len(), 1);
        assert_eq!(report.dropped_out_of_bounds, 2);
        assert_eq!(
            report.first_out_of_bounds.as_deref(),
            Some("line 1: (10, 2)")
        );
        // A missing file.
        let m = read_events_text(&dir.join("none.txt"), &opts)
            .unwrap_err()
            .to_string();
        assert!(
            m.starts_with("cannot read") && m.contains("none.txt"),
            "{m}"
        );
    }
}
