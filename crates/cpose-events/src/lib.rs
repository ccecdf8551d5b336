//! cpose-events: event streams (`x, y, t, p`), readers and writers, an event simulator and the
//! EventNeRF loss; task `events`.

pub use cpose_nerf;
