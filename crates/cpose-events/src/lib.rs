//! cpose-events: event streams (`x, y, t, p`), readers and writers, an event simulator and the
//! EventNeRF loss; task `events`.
//!
//! * [`EventStream`] holds one sensor's events in columns sorted by time and slices time windows
//!   without copying ([`EventStream::window`]).
//! * Files: EventNeRF's `.npz` ([`npz`], over a small ZIP reader and writer in [`zip`]), the
//!   text format `t x y p` of the public event-camera datasets ([`text`]), and EventNeRF's
//!   dataset folder with poses, intrinsics and events ([`eventnerf`]). Readers drop events
//!   outside the sensor and say how many ([`LoadReport`]); every other defect is an error naming
//!   the file and the line or array.
//! * An ESIM-style simulator of a colour event camera ([`simulate`]) over `cpose-nerf`'s
//!   synthetic scene along any pose field, e.g. a [`Turntable`] revolution with an optionally
//!   tilted axis, and the synthetic EventNeRF datasets built with it
//!   ([`write_synthetic_eventnerf`]).
//!
//! Not for: decoding camera vendors' binary formats (AEDAT, EVT, HDF5); convert those to `.npz`
//! or text first.

pub use cpose_nerf;

pub mod colour;
mod error;
pub mod eventnerf;
pub mod format;
pub mod loss;
pub mod npz;
pub mod simulate;
pub mod stream;
mod task;
pub mod text;
pub mod train;
pub mod turntable;
pub mod zip;

pub use error::EventsError;
pub use eventnerf::{
    EventNerfOptions, EventNerfScene, HeldOutView, read_eventnerf, write_eventnerf,
};
pub use format::{LoadReport, PolarityCoding, ReadOptions, TimeUnit};
pub use npz::{read_events_npz, read_npz, write_events_npz, write_npz};
pub use simulate::{
    EventSimulator, SimulatedEvents, SimulatorConfig, SyntheticEventsConfig, bayer_channel,
    simulate_eventnerf_scene, simulate_scene_events, write_synthetic_eventnerf,
};
pub use stream::{Event, EventStream, EventWindow};
pub use text::{read_events_text, write_events_text};
pub use turntable::Turntable;
