//! What the event readers share: options ([`ReadOptions`], [`TimeUnit`]), the report of
//! dropped events ([`LoadReport`]) and the checks that turn raw file columns into an
//! [`EventStream`].
//!
//! # Rules for every reader
//!
//! * An event outside the sensor (`x ∉ [0, width)` or `y ∉ [0, height)`, including negative
//!   values) is **dropped and counted** in [`LoadReport::dropped_out_of_bounds`]: real recordings
//!   occasionally hold a few such events, and one bad pixel should not void a file.
//! * Times must be **non-decreasing** in file order; the first event earlier than its predecessor
//!   is an error naming the line or index (a shuffled file is a broken file, and sorting it
//!   silently would hide that).
//! * Polarities are coded either `{−1, +1}` or `{0, 1}` (booleans count as `{0, 1}`): if any
//!   event has `−1` the file is signed and a `0` is an error; otherwise `0` means `−1`. Any other
//!   value is an error.

use std::fmt;
use std::path::Path;

use crate::error::EventsError;
use crate::stream::EventStream;

/// The unit of the time values in a file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TimeUnit {
    /// Seconds (EventNeRF's `t` and the text format; floats).
    #[default]
    Seconds,
    /// Milliseconds.
    Milliseconds,
    /// Microseconds (many DAVIS and Prophesee tools).
    Microseconds,
    /// Nanoseconds (ESIM).
    Nanoseconds,
}

impl TimeUnit {
    /// Nanoseconds per unit.
    pub fn nanos_per_unit(self) -> i64 {
        match self {
            TimeUnit::Seconds => 1_000_000_000,
            TimeUnit::Milliseconds => 1_000_000,
            TimeUnit::Microseconds => 1_000,
            TimeUnit::Nanoseconds => 1,
        }
    }

    /// An integer time in this unit as nanoseconds; `None` if it overflows `i64`.
    pub fn int_to_nanos(self, v: i128) -> Option<i64> {
        v.checked_mul(i128::from(self.nanos_per_unit()))
            .and_then(|n| i64::try_from(n).ok())
    }

    /// A float time in this unit as nanoseconds, rounded to the nearest; `None` if not finite or
    /// out of the `i64` range.
    pub fn float_to_nanos(self, v: f64) -> Option<i64> {
        let n = (v * self.nanos_per_unit() as f64).round();
        // 2⁶³ is exactly representable; every float below it converts exactly.
        (n.is_finite() && n >= -(2f64.powi(63)) && n < 2f64.powi(63)).then_some(n as i64)
    }
}

impl fmt::Display for TimeUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            TimeUnit::Seconds => "s",
            TimeUnit::Milliseconds => "ms",
            TimeUnit::Microseconds => "µs",
            TimeUnit::Nanoseconds => "ns",
        })
    }
}

/// `ns` nanoseconds as seconds with nine decimals, exactly (`-0.000000005`, `12.500000000`).
pub fn secs_string(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let abs = ns.unsigned_abs();
    format!("{sign}{}.{:09}", abs / 1_000_000_000, abs % 1_000_000_000)
}

/// How a file codes polarity.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PolarityCoding {
    /// `+1` brighter, `−1` darker (EventNeRF).
    #[default]
    Signed,
    /// `1` brighter, `0` darker (the text files of the public event-camera datasets).
    ZeroOne,
}

/// The sensor and the time unit of an event file, which the formats do not store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReadOptions {
    /// Sensor width in pixels.
    pub width: u16,
    /// Sensor height in pixels.
    pub height: u16,
    /// Unit of the time values (for the text format always seconds).
    pub time_unit: TimeUnit,
}

impl ReadOptions {
    /// A `width × height` sensor with times in seconds.
    pub fn new(width: u16, height: u16) -> Self {
        Self {
            width,
            height,
            time_unit: TimeUnit::Seconds,
        }
    }

    /// The DAVIS346 of EventNeRF's data, `346 × 260` (hard-coded in EventNeRF's loader), seconds.
    pub fn davis346() -> Self {
        Self::new(346, 260)
    }

    /// The same options with times in `unit`.
    pub fn with_time_unit(self, unit: TimeUnit) -> Self {
        Self {
            time_unit: unit,
            ..self
        }
    }
}

/// What a reader did besides returning the events: how many it read and dropped.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadReport {
    /// Events in the file.
    pub events_read: usize,
    /// Events dropped because their pixel lies outside the sensor.
    pub dropped_out_of_bounds: usize,
    /// The first dropped event, e.g. `line 7: (400, 12)`.
    pub first_out_of_bounds: Option<String>,
    /// The polarity coding found.
    pub polarity: PolarityCoding,
}

impl fmt::Display for LoadReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} events read, {} dropped outside the sensor",
            self.events_read, self.dropped_out_of_bounds
        )?;
        if let Some(first) = &self.first_out_of_bounds {
            write!(f, " (first: {first})")?;
        }
        Ok(())
    }
}

/// Builds an [`EventStream`] from a file's events one at a time, applying the rules of the
/// [module docs](self).
pub(crate) struct StreamBuilder<'p> {
    path: &'p Path,
    /// How events are numbered in errors: `line` (1-based) or `event` (0-based index).
    place_kind: &'static str,
    width: u16,
    height: u16,
    t_ns: Vec<i64>,
    x: Vec<u16>,
    y: Vec<u16>,
    /// Raw polarities, −1, 0 or 1, normalised in [`StreamBuilder::finish`].
    p: Vec<i8>,
    /// The latest time so far and the number of its first event.
    last_t: Option<(i64, usize)>,
    first_zero: Option<usize>,
    first_minus: Option<usize>,
    report: LoadReport,
}

impl<'p> StreamBuilder<'p> {
    /// A builder for `path`, numbering events as `place_kind` (`"line"` or `"event"`).
    pub(crate) fn new(
        path: &'p Path,
        place_kind: &'static str,
        options: &ReadOptions,
        capacity: usize,
    ) -> Self {
        Self {
            path,
            place_kind,
            width: options.width,
            height: options.height,
            t_ns: Vec::with_capacity(capacity),
            x: Vec::with_capacity(capacity),
            y: Vec::with_capacity(capacity),
            p: Vec::with_capacity(capacity),
            last_t: None,
            first_zero: None,
            first_minus: None,
            report: LoadReport::default(),
        }
    }

    /// `line 12` or `event 5`.
    fn place(&self, n: usize) -> String {
        format!("{} {n}", self.place_kind)
    }

    /// Adds event number `n` (its line or index, for errors). `p` must be −1, 0 or 1 (the
    /// caller reports other values).
    pub(crate) fn add(
        &mut self,
        n: usize,
        t_ns: i64,
        x: i128,
        y: i128,
        p: i8,
    ) -> Result<(), EventsError> {
        self.report.events_read += 1;
        match self.last_t {
            Some((prev, prev_n)) if t_ns < prev => {
                return Err(EventsError::format(
                    self.path,
                    Some(self.place(n)),
                    format!(
                        "times in non-decreasing order (after {prev} ns at {})",
                        self.place(prev_n)
                    ),
                    format!("{t_ns} ns"),
                ));
            }
            Some((prev, _)) if t_ns == prev => {}
            _ => self.last_t = Some((t_ns, n)),
        }
        match p {
            0 if self.first_zero.is_none() => self.first_zero = Some(n),
            -1 if self.first_minus.is_none() => self.first_minus = Some(n),
            _ => {}
        }
        let inside = |v: i128, n: u16| (0..i128::from(n)).contains(&v);
        if !(inside(x, self.width) && inside(y, self.height)) {
            self.report.dropped_out_of_bounds += 1;
            if self.report.first_out_of_bounds.is_none() {
                self.report.first_out_of_bounds = Some(format!("{}: ({x}, {y})", self.place(n)));
            }
            return Ok(());
        }
        self.t_ns.push(t_ns);
        // In range of u16 since inside the sensor.
        self.x.push(x as u16);
        self.y.push(y as u16);
        self.p.push(p);
        Ok(())
    }

    /// The stream and the report; errors on mixed polarity codings.
    pub(crate) fn finish(mut self) -> Result<(EventStream, LoadReport), EventsError> {
        match (self.first_minus, self.first_zero) {
            (Some(minus), Some(zero)) => {
                return Err(EventsError::format(
                    self.path,
                    Some(self.place(zero)),
                    format!(
                        "polarity −1 or +1 (the file is signed: −1 at {})",
                        self.place(minus)
                    ),
                    "0",
                ));
            }
            // Only +1 (or nothing): both codings agree.
            (_, None) => self.report.polarity = PolarityCoding::Signed,
            (None, Some(_)) => {
                self.report.polarity = PolarityCoding::ZeroOne;
                for p in &mut self.p {
                    if *p == 0 {
                        *p = -1;
                    }
                }
            }
        }
        let stream =
            EventStream::from_columns(self.width, self.height, self.t_ns, self.x, self.y, self.p)?;
        Ok((stream, self.report))
    }
}
