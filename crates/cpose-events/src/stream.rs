//! [`EventStream`]: events `(t, x, y, p)` of one sensor in columns, sorted by time, and
//! [`EventWindow`], a borrowed view of the events in a time window.
//!
//! # Representation
//!
//! * **Time is `i64` nanoseconds** ([`Timestamp`]) since the stream's origin (for EventNeRF data
//!   and the simulator: the time of view 0). Integers make the order, the binary searches of
//!   [`EventStream::window`] and round trips through files exact: a window boundary taken from
//!   a stored time selects exactly the events at or after it, with no rounding in between. They
//!   also cover absolute Unix times at full resolution (an `f64` of seconds since 1970 resolves
//!   only about 0.24 µs, coarser than the 1 µs of a DAVIS). Pose fields are queried with `f64`
//!   seconds ([`Timestamp::secs_since`]), where sub-nanosecond rounding no longer matters.
//! * **Pixels are `u16`** column `x` and row `y` (OpenCV image axes, pixel `(x, y)` covers
//!   `[x, x + 1) × [y, y + 1)`), inside the sensor's `width × height`.
//! * **Polarity is `i8`, `+1` (brighter) or `−1` (darker)**, so that EventNeRF's accumulation
//!   `E[y, x] += p` is a plain sum. Files coded `{0, 1}` are converted when read.

use cpose_core::Timestamp;

use crate::EventsError;

/// One event.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Event {
    /// Time since the stream's origin.
    pub t: Timestamp,
    /// Pixel column.
    pub x: u16,
    /// Pixel row.
    pub y: u16,
    /// `+1` (log intensity rose by a threshold) or `−1` (fell).
    pub p: i8,
}

/// The events of one `width × height` sensor, in columns, sorted by time (ties keep their
/// order). See the [module docs](self) for the representation.
///
/// Invariants: the four columns have one length; `t` is non-decreasing; `x < width`,
/// `y < height`; `p ∈ {−1, +1}`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EventStream {
    width: u16,
    height: u16,
    t_ns: Vec<i64>,
    x: Vec<u16>,
    y: Vec<u16>,
    p: Vec<i8>,
}

impl EventStream {
    /// An empty stream of a `width × height` sensor (both ≥ 1).
    pub fn new(width: u16, height: u16) -> Result<Self, EventsError> {
        if width == 0 || height == 0 {
            return Err(EventsError::EmptySensor { width, height });
        }
        Ok(Self {
            width,
            height,
            ..Self::default()
        })
    }

    /// A stream from columns, checking every invariant (the first violation is the error).
    pub fn from_columns(
        width: u16,
        height: u16,
        t_ns: Vec<i64>,
        x: Vec<u16>,
        y: Vec<u16>,
        p: Vec<i8>,
    ) -> Result<Self, EventsError> {
        let n = t_ns.len();
        if x.len() != n || y.len() != n || p.len() != n {
            return Err(EventsError::ColumnLengths {
                t: n,
                x: x.len(),
                y: y.len(),
                p: p.len(),
            });
        }
        let stream = Self {
            t_ns,
            x,
            y,
            p,
            ..Self::new(width, height)?
        };
        for i in 0..n {
            stream.check(i)?;
        }
        Ok(stream)
    }

    /// Checks event `i` against the sensor, the polarity rule and its predecessor.
    fn check(&self, i: usize) -> Result<(), EventsError> {
        let (x, y, p) = (self.x[i], self.y[i], self.p[i]);
        if x >= self.width || y >= self.height {
            return Err(EventsError::OutsideSensor {
                index: i,
                x,
                y,
                width: self.width,
                height: self.height,
            });
        }
        if p != 1 && p != -1 {
            return Err(EventsError::Polarity { index: i, p });
        }
        if i > 0 && self.t_ns[i] < self.t_ns[i - 1] {
            return Err(EventsError::Unsorted {
                index: i,
                t_ns: self.t_ns[i],
                prev_ns: self.t_ns[i - 1],
            });
        }
        Ok(())
    }

    /// Appends `event`, which must be inside the sensor, of polarity ±1 and not earlier than the
    /// last event; on error the stream is unchanged.
    pub fn push(&mut self, event: Event) -> Result<(), EventsError> {
        self.t_ns.push(event.t.as_nanos());
        self.x.push(event.x);
        self.y.push(event.y);
        self.p.push(event.p);
        let result = self.check(self.len() - 1);
        if result.is_err() {
            self.t_ns.pop();
            self.x.pop();
            self.y.pop();
            self.p.pop();
        }
        result
    }

    /// Sensor width in pixels.
    pub fn width(&self) -> u16 {
        self.width
    }

    /// Sensor height in pixels.
    pub fn height(&self) -> u16 {
        self.height
    }

    /// Number of events.
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }

    /// Whether there are no events.
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }

    /// Event `i`, or `None` past the end.
    pub fn get(&self, i: usize) -> Option<Event> {
        self.all().get(i)
    }

    /// Times in nanoseconds since the origin (non-decreasing).
    pub fn t_ns(&self) -> &[i64] {
        &self.t_ns
    }

    /// Pixel columns.
    pub fn x(&self) -> &[u16] {
        &self.x
    }

    /// Pixel rows.
    pub fn y(&self) -> &[u16] {
        &self.y
    }

    /// Polarities (±1).
    pub fn p(&self) -> &[i8] {
        &self.p
    }

    /// The first and last event times, `None` when empty.
    pub fn time_span(&self) -> Option<(Timestamp, Timestamp)> {
        Some((
            Timestamp::from_nanos(*self.t_ns.first()?),
            Timestamp::from_nanos(*self.t_ns.last()?),
        ))
    }

    /// A view of all events.
    pub fn all(&self) -> EventWindow<'_> {
        EventWindow {
            first_index: 0,
            t_ns: &self.t_ns,
            x: &self.x,
            y: &self.y,
            p: &self.p,
        }
    }

    /// The events with `start ≤ t < end`, without copying: two binary searches, `O(log n)`.
    /// `start == end` gives an empty window; `end < start` is an error.
    pub fn window(&self, start: Timestamp, end: Timestamp) -> Result<EventWindow<'_>, EventsError> {
        let (s, e) = (start.as_nanos(), end.as_nanos());
        if e < s {
            return Err(EventsError::ReversedWindow {
                start_ns: s,
                end_ns: e,
            });
        }
        let i0 = self.t_ns.partition_point(|&t| t < s);
        let i1 = i0 + self.t_ns[i0..].partition_point(|&t| t < e);
        Ok(self.all().slice(i0, i1))
    }
}

/// A borrowed, contiguous run of an [`EventStream`]'s events (from [`EventStream::window`] or
/// [`EventStream::all`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EventWindow<'a> {
    first_index: usize,
    t_ns: &'a [i64],
    x: &'a [u16],
    y: &'a [u16],
    p: &'a [i8],
}

impl<'a> EventWindow<'a> {
    /// The sub-run `[i0, i1)` of this run (indices relative to it).
    fn slice(&self, i0: usize, i1: usize) -> Self {
        Self {
            first_index: self.first_index + i0,
            t_ns: &self.t_ns[i0..i1],
            x: &self.x[i0..i1],
            y: &self.y[i0..i1],
            p: &self.p[i0..i1],
        }
    }

    /// Number of events.
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }

    /// Whether there are no events.
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }

    /// Index in the stream of the window's first event (where it would be, if empty).
    pub fn first_index(&self) -> usize {
        self.first_index
    }

    /// Event `i` of the window, or `None` past its end.
    pub fn get(&self, i: usize) -> Option<Event> {
        Some(Event {
            t: Timestamp::from_nanos(*self.t_ns.get(i)?),
            x: self.x[i],
            y: self.y[i],
            p: self.p[i],
        })
    }

    /// The events in time order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = Event> + 'a {
        let w = *self;
        (0..w.len()).map(move |i| Event {
            t: Timestamp::from_nanos(w.t_ns[i]),
            x: w.x[i],
            y: w.y[i],
            p: w.p[i],
        })
    }

    /// Times, ns.
    pub fn t_ns(&self) -> &'a [i64] {
        self.t_ns
    }

    /// Pixel columns.
    pub fn x(&self) -> &'a [u16] {
        self.x
    }

    /// Pixel rows.
    pub fn y(&self) -> &'a [u16] {
        self.y
    }

    /// Polarities (±1).
    pub fn p(&self) -> &'a [i8] {
        self.p
    }

    /// EventNeRF's event frame: `E[y·width + x] = Σ p` over the window's events at that pixel
    /// (row-major, `width · height` values; `width, height` are the stream's sensor size).
    pub fn accumulate(&self, width: u16, height: u16) -> Vec<f32> {
        let w = usize::from(width);
        let mut frame = vec![0.0f32; w * usize::from(height)];
        for i in 0..self.len() {
            if let Some(v) = frame.get_mut(usize::from(self.y[i]) * w + usize::from(self.x[i])) {
                *v += f32::from(self.p[i]);
            }
        }
        frame
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ts(ns: i64) -> Timestamp {
        Timestamp::from_nanos(ns)
    }

    /// Times 10, 20, 20, 20, 30, 50 ns at pixels (i, 0).
    fn stream() -> EventStream {
        let t = vec![10, 20, 20, 20, 30, 50];
        let n = t.len();
        EventStream::from_columns(
            8,
            4,
            t,
            (0..n as u16).collect(),
            vec![0; n],
            vec![1, -1, 1, -1, 1, 1],
        )
        .unwrap()
    }

    #[test]
    fn windows_are_half_open_and_borrowed() {
        let s = stream();
        let w = s.window(ts(20), ts(30)).unwrap();
        assert_eq!((w.first_index(), w.len()), (1, 3));
        assert_eq!(w.t_ns(), [20, 20, 20]);
        assert_eq!(w.x(), [1, 2, 3]);
        // The view points into the stream's storage.
        assert!(std::ptr::eq(w.t_ns().as_ptr(), s.t_ns()[1..].as_ptr()));
        // Ties at the start are all included, ties at the end all excluded.
        assert_eq!(s.window(ts(20), ts(50)).unwrap().len(), 4);
        assert_eq!(s.window(ts(21), ts(51)).unwrap().t_ns(), [30, 50]);
        // Whole range, before, after, and between events.
        assert_eq!(s.window(ts(i64::MIN), ts(i64::MAX)).unwrap().len(), 6);
        assert!(s.window(ts(0), ts(10)).unwrap().is_empty());
        let after = s.window(ts(51), ts(100)).unwrap();
        assert!(after.is_empty());
        assert_eq!(after.first_index(), 6);
        let between = s.window(ts(31), ts(49)).unwrap();
        assert_eq!((between.len(), between.first_index()), (0, 5));
        // An empty window [t, t) and a reversed one.
        assert!(s.window(ts(20), ts(20)).unwrap().is_empty());
        assert!(matches!(
            s.window(ts(30), ts(20)).unwrap_err(),
            EventsError::ReversedWindow {
                start_ns: 30,
                end_ns: 20
            }
        ));
        // An empty stream has empty windows.
        let empty = EventStream::new(2, 2).unwrap();
        assert!(empty.window(ts(0), ts(10)).unwrap().is_empty());
        assert_eq!(empty.time_span(), None);
        assert_eq!(s.time_span(), Some((ts(10), ts(50))));
    }

    #[test]
    fn window_events_iterate_and_accumulate() {
        let s = stream();
        let w = s.window(ts(10), ts(31)).unwrap();
        let events: Vec<Event> = w.iter().collect();
        assert_eq!(events.len(), 5);
        assert_eq!(
            events[1],
            Event {
                t: ts(20),
                x: 1,
                y: 0,
                p: -1
            }
        );
        assert_eq!(w.get(4), events.last().copied());
        assert_eq!(w.get(5), None);
        assert_eq!(s.get(5).map(|e| e.t), Some(ts(50)));
        let frame = w.accumulate(8, 4);
        assert_eq!(&frame[..6], [1.0, -1.0, 1.0, -1.0, 1.0, 0.0]);
        assert_eq!(frame.iter().sum::<f32>(), 1.0);
    }

    #[test]
    fn invariants_are_checked() {
        let col = |n: usize| vec![0u16; n];
        assert!(matches!(
            EventStream::from_columns(4, 4, vec![0, 1], col(2), col(1), vec![1, 1]).unwrap_err(),
            EventsError::ColumnLengths {
                t: 2,
                x: 2,
                y: 1,
                p: 2
            }
        ));
        let err = EventStream::from_columns(4, 3, vec![0, 1], vec![0, 1], vec![0, 3], vec![1, 1])
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "event 1: expected a pixel inside the 4×3 sensor, got (1, 3)"
        );
        let err =
            EventStream::from_columns(4, 3, vec![5, 4], col(2), col(2), vec![1, 1]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "event 1: expected times in non-decreasing order, got 4 ns after 5 ns"
        );
        let err = EventStream::from_columns(4, 3, vec![0], col(1), col(1), vec![0]).unwrap_err();
        assert!(matches!(err, EventsError::Polarity { index: 0, p: 0 }));
        assert!(EventStream::new(0, 3).is_err());

        let mut s = EventStream::new(4, 3).unwrap();
        let e = |t: i64, x: u16| Event {
            t: ts(t),
            x,
            y: 0,
            p: 1,
        };
        s.push(e(5, 0)).unwrap();
        s.push(e(5, 1)).unwrap();
        assert!(s.push(e(4, 0)).is_err());
        assert!(s.push(e(6, 4)).is_err());
        assert_eq!(s.len(), 2);
        assert_eq!(s.t_ns(), [5, 5]);
    }
}
