//! Lens distortion of the readers' camera models (COLMAP's `SIMPLE_RADIAL` / `RADIAL`,
//! nerfstudio's `OPENCV`), removed on load by resampling each image to the pinhole camera of the
//! same `fx, fy, cx, cy`, as COLMAP's `image_undistorter` does.
//!
//! The model is OpenCV's (Brown–Conrady) in normalised coordinates `(x, y) = ((u − cx)/fx,
//! (v − cy)/fy)`, `r² = x² + y²`:
//!
//! `x_d = x (1 + k₁r² + k₂r⁴ + k₃r⁶) + 2p₁xy + p₂(r² + 2x²)`,
//! `y_d = y (1 + k₁r² + k₂r⁴ + k₃r⁶) + p₁(r² + 2y²) + 2p₂xy`.

use crate::camera::PinholeCamera;
use crate::image::Image;

/// Radial (`k₁, k₂, k₃`) and tangential (`p₁, p₂`) coefficients; all zero is no distortion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Distortion {
    /// `k₁, k₂, k₃`.
    pub radial: [f64; 3],
    /// `p₁, p₂`.
    pub tangential: [f64; 2],
}

impl Distortion {
    /// Whether every coefficient is zero.
    pub fn is_none(&self) -> bool {
        self.radial == [0.0; 3] && self.tangential == [0.0; 2]
    }

    /// Where the undistorted pixel `[u, v]` (continuous coordinates) of `camera` lies in the
    /// distorted image.
    pub fn distorted_pixel(&self, camera: &PinholeCamera, [u, v]: [f64; 2]) -> [f64; 2] {
        let (x, y) = ((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy);
        let r2 = x * x + y * y;
        let [k1, k2, k3] = self.radial;
        let [p1, p2] = self.tangential;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        [camera.fx * xd + camera.cx, camera.fy * yd + camera.cy]
    }

    /// `image`, taken through this lens with `camera`'s `fx, fy, cx, cy`, resampled (bilinear,
    /// edge pixels repeated outside) to the pinhole `camera`.
    pub fn undistort(&self, image: &Image, camera: &PinholeCamera) -> Image {
        let frame = image.frame();
        Image::from_fn(image.width(), image.height(), |x, y| {
            let [u, v] = self.distorted_pixel(camera, [x as f64 + 0.5, y as f64 + 0.5]);
            // Continuous coordinates to pixel indices (centres at integers).
            image.sample_bilinear(frame.to_normalized([u - 0.5, v - 0.5]))
        })
    }

    /// The largest shift undistortion makes, in pixels, over the image's corners and edge
    /// midpoints.
    pub fn max_shift_px(&self, camera: &PinholeCamera) -> f64 {
        let (w, h) = (camera.width as f64, camera.height as f64);
        [0.0, 0.5, 1.0]
            .iter()
            .flat_map(|&a| [0.0, 0.5, 1.0].map(|b| [a * w, b * h]))
            .map(|p| {
                let d = self.distorted_pixel(camera, p);
                (d[0] - p[0]).hypot(d[1] - p[1])
            })
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undistortion_samples_the_distorted_image_where_the_model_says() {
        let camera = PinholeCamera {
            width: 40,
            height: 30,
            fx: 50.0,
            fy: 48.0,
            cx: 20.0,
            cy: 15.0,
        };
        let lens = Distortion {
            radial: [-0.2, 0.05, 0.01],
            tangential: [0.003, -0.002],
        };
        // A distorted image of a linear ramp in x: bilinear sampling reproduces it exactly.
        let distorted = Image::from_fn(40, 30, |x, _| [x as f32 / 40.0; 3]);
        let straight = lens.undistort(&distorted, &camera);
        for (x, y) in [(5, 5), (20, 15), (33, 27)] {
            let [u, _] = lens.distorted_pixel(&camera, [x as f64 + 0.5, y as f64 + 0.5]);
            let expected = ((u - 0.5).clamp(0.0, 39.0) / 40.0) as f32;
            assert!((straight.pixel(x, y)[0] - expected).abs() < 1e-5);
        }
        // The formula at one point, by hand: x = 0.4, y = −0.25.
        let [u, v] = lens.distorted_pixel(&camera, [40.0, 3.0]);
        let (x, y, r2) = (0.4, -0.25, 0.4f64 * 0.4 + 0.0625);
        let radial = 1.0 - 0.2 * r2 + 0.05 * r2 * r2 + 0.01 * r2 * r2 * r2;
        let xd = x * radial + 2.0 * 0.003 * x * y - 0.002 * (r2 + 2.0 * x * x);
        let yd = y * radial + 0.003 * (r2 + 2.0 * y * y) + 2.0 * -0.002 * x * y;
        assert!((u - (50.0 * xd + 20.0)).abs() < 1e-12 && (v - (48.0 * yd + 15.0)).abs() < 1e-12);
        // No distortion moves nothing; the centre never moves under radial distortion.
        let none = Distortion::default();
        assert!(none.is_none() && none.max_shift_px(&camera) == 0.0);
        let radial = Distortion {
            radial: [-0.2, 0.0, 0.0],
            ..Distortion::default()
        };
        assert_eq!(radial.distorted_pixel(&camera, [20.0, 15.0]), [20.0, 15.0]);
        let corner = radial.distorted_pixel(&camera, [0.0, 0.0]);
        assert!((radial.max_shift_px(&camera) - corner[0].hypot(corner[1])).abs() < 1e-9);
    }
}
