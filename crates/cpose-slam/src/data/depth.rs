//! Metric depth images and their 16-bit PNG encoding.

use std::io::Cursor;
use std::path::Path;

use ::image::ImageEncoder as _;
use cpose_nerf::image::Image;

use super::RgbdError;

/// A depth image: metric camera `z` per pixel, row-major; `0` where there is no reading.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl DepthImage {
    /// A depth image from row-major values; `None` unless `data.len() = width · height`.
    /// Non-finite and negative values become `0` (missing).
    pub fn new(width: usize, height: usize, mut data: Vec<f32>) -> Option<Self> {
        if data.len() != width * height {
            return None;
        }
        for v in &mut data {
            if !(v.is_finite() && *v > 0.0) {
                *v = 0.0;
            }
        }
        Some(Self {
            width,
            height,
            data,
        })
    }

    /// Width, pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The values, row-major, metres (`0` = missing).
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The depth at pixel `(x, y)`.
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Reads a 16-bit single-channel PNG whose values are `depth · scale`.
    pub fn load_png(path: &Path, scale: f64) -> Result<Self, RgbdError> {
        Self::load_png_masked(path, scale, None)
    }

    /// [`DepthImage::load_png`] with the stored value `invalid` read as missing (`0`): 7-Scenes
    /// marks pixels without a reading with 65535.
    pub fn load_png_masked(
        path: &Path,
        scale: f64,
        invalid: Option<u16>,
    ) -> Result<Self, RgbdError> {
        let bytes = std::fs::read(path).map_err(|e| RgbdError::io(path, e))?;
        let decoded =
            ::image::ImageReader::with_format(Cursor::new(bytes), ::image::ImageFormat::Png)
                .decode()
                .map_err(|e| {
                    RgbdError::format(path, "a 16-bit single-channel depth PNG", e.to_string())
                })?;
        // 8-bit depth would hold 256 levels; no RGB-D dataset stores it, so it is refused rather
        // than guessed at.
        let color = decoded.color();
        if color != ::image::ColorType::L16 {
            let channels = color.channel_count();
            return Err(RgbdError::format(
                path,
                "a 16-bit single-channel depth PNG",
                format!(
                    "{channels} channel(s) of {} bits",
                    color.bits_per_pixel() / u16::from(channels)
                ),
            ));
        }
        let luma = decoded.into_luma16();
        let (w, h) = (luma.width() as usize, luma.height() as usize);
        let inv = (1.0 / scale) as f32;
        let data = luma
            .into_raw()
            .into_iter()
            .map(|v| {
                if Some(v) == invalid {
                    0.0
                } else {
                    v as f32 * inv
                }
            })
            .collect();
        Ok(Self {
            width: w,
            height: h,
            data,
        })
    }

    /// Writes a 16-bit single-channel PNG of `round(depth · scale)` (saturating at 65535),
    /// atomically. Replica's scale 6553.5 covers 0–10 m in steps of 0.15 mm.
    pub fn save_png(&self, path: &Path, scale: f64) -> Result<(), RgbdError> {
        let bytes: Vec<u8> = self
            .data
            .iter()
            .flat_map(|&d| {
                let v = (d as f64 * scale).round().clamp(0.0, 65535.0) as u16;
                v.to_ne_bytes() // the encoder takes native-endian samples
            })
            .collect();
        let mut png = Vec::new();
        ::image::codecs::png::PngEncoder::new(&mut png)
            .write_image(
                &bytes,
                self.width as u32,
                self.height as u32,
                ::image::ExtendedColorType::L16,
            )
            .map_err(|e| RgbdError::format(path, "an encodable depth image", e.to_string()))?;
        cpose_core::fs::write_atomic(path, &png).map_err(|e| RgbdError::io(path, e))
    }

    /// Resized to `w × h` by taking, for each output pixel, the stored pixel under its centre
    /// (no averaging across depth edges).
    pub fn resized_nearest(&self, w: usize, h: usize) -> Self {
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            let sy =
                (((y as f64 + 0.5) * self.height as f64 / h as f64) as usize).min(self.height - 1);
            for x in 0..w {
                let sx = (((x as f64 + 0.5) * self.width as f64 / w as f64) as usize)
                    .min(self.width - 1);
                data.push(self.data[sy * self.width + sx]);
            }
        }
        Self {
            width: w,
            height: h,
            data,
        }
    }

    /// A grey preview: `near` white to `far` black, missing readings dark red.
    pub fn to_image(&self, near: f32, far: f32) -> Image {
        Image::from_fn(self.width, self.height, |x, y| {
            let d = self.at(x, y);
            if d <= 0.0 {
                return [0.5, 0.0, 0.0];
            }
            let v = (1.0 - (d - near) / (far - near)).clamp(0.0, 1.0);
            [v, v, v]
        })
    }

    /// Without `e` pixels on every side.
    pub fn cropped(&self, e: usize) -> Self {
        if e == 0 {
            return self.clone();
        }
        let (w, h) = (self.width - 2 * e, self.height - 2 * e);
        let mut data = Vec::with_capacity(w * h);
        for y in e..e + h {
            data.extend_from_slice(&self.data[y * self.width + e..y * self.width + e + w]);
        }
        Self {
            width: w,
            height: h,
            data,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_dir;
    use super::*;

    #[test]
    fn png_round_trip_keeps_depth_to_the_quantum_and_missing_as_zero() {
        let dir = test_dir("depth-round-trip");
        let path = dir.join("d.png");
        let values = vec![0.0, 1.0, 2.345_678, 9.99, f32::NAN, -1.0];
        let depth = DepthImage::new(3, 2, values).unwrap();
        depth.save_png(&path, 6553.5).unwrap();
        let back = DepthImage::load_png(&path, 6553.5).unwrap();
        assert_eq!((back.width(), back.height()), (3, 2));
        for (a, b) in depth.data().iter().zip(back.data()) {
            assert!((a - b).abs() <= 0.5 / 6553.5 + 1e-6, "{a} vs {b}");
        }
        assert_eq!(&back.data()[4..], &[0.0, 0.0]);
    }

    #[test]
    fn an_rgb_png_is_not_a_depth_image() {
        let dir = test_dir("depth-rgb");
        let path = dir.join("rgb.png");
        cpose_nerf::image::Image::new(2, 2, vec![0.5; 12])
            .unwrap()
            .save_png(&path)
            .unwrap();
        let err = DepthImage::load_png(&path, 1000.0).unwrap_err().to_string();
        assert!(
            err.contains("rgb.png") && err.contains("3 channel(s) of 8 bits"),
            "{err}"
        );
        // 8-bit grey is refused too, not read as 257 times its value.
        let grey = dir.join("grey8.png");
        ::image::GrayImage::from_raw(2, 2, vec![10, 20, 30, 40])
            .unwrap()
            .save(&grey)
            .unwrap();
        let err = DepthImage::load_png(&grey, 1000.0).unwrap_err().to_string();
        assert!(
            err.contains("grey8.png")
                && err.contains("16-bit")
                && err.contains("1 channel(s) of 8 bits"),
            "{err}"
        );
        let err = DepthImage::load_png(&dir.join("none.png"), 1000.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("none.png"), "{err}");
    }

    #[test]
    fn nearest_resize_and_crop_pick_stored_pixels() {
        let depth = DepthImage::new(4, 4, (0..16).map(|v| v as f32 + 1.0).collect()).unwrap();
        let half = depth.resized_nearest(2, 2);
        // Output pixel (x, y) reads stored pixel (2x + 1, 2y + 1).
        assert_eq!(half.data(), &[6.0, 8.0, 14.0, 16.0]);
        let inner = depth.cropped(1);
        assert_eq!(inner.data(), &[6.0, 7.0, 10.0, 11.0]);
    }
}
