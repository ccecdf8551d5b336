//! Time: integer nanoseconds at the data boundary, `f64` seconds inside.

use std::fmt;

/// A sensor timestamp in integer nanoseconds (EuRoC, event cameras), exact over any duration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Timestamp(i64);

impl Timestamp {
    /// From integer nanoseconds.
    pub const fn from_nanos(nanos: i64) -> Self {
        Self(nanos)
    }
    /// From seconds, rounded to the nearest nanosecond.
    pub fn from_secs_f64(secs: f64) -> Self {
        Self((secs * 1e9).round() as i64)
    }
    /// Integer nanoseconds.
    pub const fn as_nanos(self) -> i64 {
        self.0
    }
    /// Seconds as `f64` (sub-microsecond resolution for absolute Unix times; subtract an origin
    /// with [`Timestamp::secs_since`] before evaluating a pose field).
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }
    /// Seconds elapsed since `origin`, exact to the nanosecond before the conversion to `f64`.
    pub fn secs_since(self, origin: Timestamp) -> f64 {
        (self.0 - origin.0) as f64 * 1e-9
    }
}

/// The closed interval of times, in seconds since the sequence's time origin, at which a
/// [`PoseField`](crate::PoseField) may be evaluated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeRange {
    /// First valid time, seconds.
    pub start_secs: f64,
    /// Last valid time, seconds; `end_secs > start_secs`.
    pub end_secs: f64,
}

impl TimeRange {
    /// A range `[start_secs, end_secs]`; an error unless both are finite and
    /// `start_secs < end_secs`.
    pub fn new(start_secs: f64, end_secs: f64) -> Result<Self, crate::PoseFieldError> {
        if start_secs.is_finite() && end_secs.is_finite() && start_secs < end_secs {
            Ok(Self {
                start_secs,
                end_secs,
            })
        } else {
            Err(crate::PoseFieldError::Invalid(format!(
                "time range [{start_secs} s, {end_secs} s]: expected finite ends, start < end"
            )))
        }
    }
    /// `end_secs − start_secs`.
    pub fn duration_secs(&self) -> f64 {
        self.end_secs - self.start_secs
    }
    /// Whether `t_secs` lies in the closed interval.
    pub fn contains(&self, t_secs: f64) -> bool {
        t_secs >= self.start_secs && t_secs <= self.end_secs
    }
    /// Maps `[start, end]` affinely onto `[-1, 1]` (PoseNet's input normalisation); the
    /// derivative of the map is [`TimeRange::normalized_rate`].
    pub fn normalize(&self, t_secs: f64) -> f64 {
        2.0 * (t_secs - self.start_secs) / self.duration_secs() - 1.0
    }
    /// `d t_n / d t = 2 / (end − start)`, the chain-rule factor of [`TimeRange::normalize`].
    pub fn normalized_rate(&self) -> f64 {
        2.0 / self.duration_secs()
    }
}

impl fmt::Display for TimeRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{} s, {} s]", self.start_secs, self.end_secs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalisation_maps_ends_to_unit_interval() {
        let r = TimeRange::new(2.0, 6.0).unwrap();
        assert_eq!(r.normalize(2.0), -1.0);
        assert_eq!(r.normalize(6.0), 1.0);
        assert_eq!(r.normalized_rate(), 0.5);
        let err = TimeRange::new(1.0, 1.0).unwrap_err().to_string();
        assert!(
            err.contains("time range [1 s, 1 s]: expected finite ends, start < end"),
            "{err}"
        );
        assert!(TimeRange::new(0.0, f64::NAN).is_err());
    }

    #[test]
    fn timestamps_are_exact_nanoseconds() {
        let a = Timestamp::from_nanos(1_403_715_273_262_142_976);
        let b = Timestamp::from_nanos(1_403_715_273_267_142_912);
        assert_eq!(b.secs_since(a), 0.004_999_936);
        assert_eq!(Timestamp::from_secs_f64(1.5).as_nanos(), 1_500_000_000);
    }
}
