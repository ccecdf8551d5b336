//! Volume rendering, shared by every task that renders a radiance field (`nerf`, and
//! `cpose-events`' and `cpose-slam`'s tasks): depth sampling and BARF's compositing with an
//! analytic backward ([`volume`]), batches of camera rays through a
//! [`RadianceField`](crate::field3d::RadianceField) with the reverse pass to the field and to
//! every camera's pose ([`rays`]), and whole views in chunks of rays ([`view`]).
//!
//! Not for: ray casting of the built-in synthetic scene ([`crate::scene`]), or any task's
//! training loop.

pub mod rays;
pub mod view;
pub mod volume;

pub use rays::{CameraRay, Clip, RenderSettings, Renderer};
pub use view::{RenderedView, depth_image, render_view, render_view_with};
pub use volume::{
    Composited, LastInterval, Sampling, composite_batch, composite_batch_backward, composite_ray,
    composite_ray_backward,
};
