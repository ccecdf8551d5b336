//! Whole views: every pixel of a camera rendered through a [`RadianceField`] in chunks of rays,
//! and the depth map as a picture.

use nalgebra::Isometry3;

use super::{CameraRay, RenderSettings, Renderer};
use crate::camera::PinholeCamera;
use crate::field3d::RadianceField;
use crate::image::Image;
use cpose_core::Real;

/// A whole view rendered at midpoint depths: the image and the depth map (`Σ w_j s_j`, camera
/// z-depth where the opacity is 1), row-major.
pub struct RenderedView {
    /// Colours.
    pub image: Image,
    /// Expected depth per pixel.
    pub depth: Vec<f32>,
    /// Opacity per pixel.
    pub opacity: Vec<f32>,
}

/// Renders every pixel of `camera` at `world_from_camera`, `chunk` rays at a time.
pub fn render_view<S: Real>(
    renderer: &mut Renderer<S>,
    field: &mut dyn RadianceField<S>,
    settings: &RenderSettings,
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    chunk: usize,
) -> RenderedView {
    render_view_with(
        renderer,
        field,
        settings,
        (camera.width, camera.height),
        |x, y| camera.ray_direction_cam(x, y),
        world_from_camera,
        chunk,
    )
}

/// [`render_view`] with each pixel's camera-frame direction from `direction(x, y)` (e.g. a
/// lens with distortion).
pub fn render_view_with<S: Real>(
    renderer: &mut Renderer<S>,
    field: &mut dyn RadianceField<S>,
    settings: &RenderSettings,
    (w, h): (usize, usize),
    direction: impl Fn(usize, usize) -> [f64; 3],
    world_from_camera: &Isometry3<f64>,
    chunk: usize,
) -> RenderedView {
    let mut rgb = vec![0.0f32; 3 * w * h];
    let mut depth = vec![0.0f32; w * h];
    let mut opacity = vec![0.0f32; w * h];
    let mut rays = Vec::with_capacity(chunk);
    let pixels = w * h;
    let mut start = 0;
    while start < pixels {
        let end = (start + chunk).min(pixels);
        rays.clear();
        rays.extend(
            (start..end).map(|p| CameraRay::new(0, world_from_camera, direction(p % w, p / w))),
        );
        let out = renderer.forward(field, settings, &rays, None::<&mut rand_chacha::ChaCha8Rng>);
        for (i, o) in out.iter().enumerate() {
            for c in 0..3 {
                rgb[3 * (start + i) + c] = o.rgb[c].to_f64() as f32;
            }
            depth[start + i] = o.depth.to_f64() as f32;
            opacity[start + i] = o.opacity.to_f64() as f32;
        }
        start = end;
    }
    RenderedView {
        image: Image::from_fn(w, h, |x, y| {
            let i = 3 * (y * w + x);
            [rgb[i], rgb[i + 1], rgb[i + 2]]
        }),
        depth,
        opacity,
    }
}

/// A depth map as a grey image: near white, far black, transparent pixels (opacity below ½)
/// black; `[near, far]` spans the grey ramp.
pub fn depth_image(
    width: usize,
    height: usize,
    depth: &[f32],
    opacity: &[f32],
    near: f64,
    far: f64,
) -> Image {
    Image::from_fn(width, height, |x, y| {
        let i = y * width + x;
        if opacity[i] < 0.5 {
            return [0.0; 3];
        }
        let v = (1.0 - (depth[i] as f64 / opacity[i] as f64 - near) / (far - near)).clamp(0.0, 1.0)
            as f32;
        [v, v, v]
    })
}
