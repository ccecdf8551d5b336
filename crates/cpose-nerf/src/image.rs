//! RGB images for the planar (2-D alignment) study: loading and saving, resizing, BARF's
//! normalised coordinates, bilinear sampling, a procedural test texture, simple drawing and PSNR.
//!
//! # Coordinates
//!
//! Three coordinate systems appear here; each function says which one it takes.
//!
//! * **Pixel index** `(x, y)`: column `x` and row `y`, x right and y down. Pixel `(x, y)` covers
//!   the square `[x, x+1) × [y, y+1)` of the continuous plane, so its **centre** is at continuous
//!   `(x + 0.5, y + 0.5)`. Fractional indices interpolate between pixel centres (used by
//!   [`NormalizedFrame`] and [`Image::sample_bilinear`]).
//! * **Continuous pixel coordinates**: the plane above; the image spans `[0, W] × [0, H]` and pixel
//!   centres sit at `index + 0.5`. The drawing functions ([`Image::draw_line`] …) take these.
//!   [`NormalizedFrame::to_continuous`] converts normalised coordinates to them.
//! * **Normalised coordinates** (BARF, `model/planar.py`): the long side spans `[−1, 1]`, the
//!   short side `[−S/L, S/L]`, the origin is the image centre; see [`NormalizedFrame`].

use std::path::Path;

use ::image::ImageEncoder as _;

use crate::DataError;

/// An RGB image, `f32` values nominally in `[0, 1]`, stored interleaved and row-major:
/// the red value of pixel `(x, y)` is `data[3·(y·width + x)]`.
///
/// Invariant: `1 ≤ width, height ≤ u32::MAX` and `data.len() == 3·width·height`.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl Image {
    /// An image from interleaved row-major RGB data (see [`Image`]).
    ///
    /// Errors with [`DataError::ImageShape`] unless `1 ≤ width, height ≤ u32::MAX` and
    /// `data.len() == 3·width·height`.
    pub fn new(width: usize, height: usize, data: Vec<f32>) -> Result<Image, DataError> {
        let fits = |n: usize| n >= 1 && u32::try_from(n).is_ok();
        let expected = width.checked_mul(height).and_then(|n| n.checked_mul(3));
        if fits(width) && fits(height) && expected == Some(data.len()) {
            Ok(Image {
                width,
                height,
                data,
            })
        } else {
            Err(DataError::ImageShape {
                width,
                height,
                len: data.len(),
            })
        }
    }

    /// The image whose pixel `(x, y)` is `f(x, y)`.
    ///
    /// # Panics
    /// If `width` or `height` is 0 or exceeds `u32::MAX` (a caller bug).
    pub fn from_fn(
        width: usize,
        height: usize,
        mut f: impl FnMut(usize, usize) -> [f32; 3],
    ) -> Image {
        assert!(
            width >= 1 && height >= 1 && u32::try_from(width.max(height)).is_ok(),
            "image size {width}×{height} out of range"
        );
        let mut data = Vec::with_capacity(3 * width * height);
        for y in 0..height {
            for x in 0..width {
                data.extend_from_slice(&f(x, y));
            }
        }
        Image {
            width,
            height,
            data,
        }
    }

    /// Width W in pixels (columns).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height H in pixels (rows).
    pub fn height(&self) -> usize {
        self.height
    }

    /// The interleaved row-major RGB values (length `3·W·H`).
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// `self | other` side by side (the shorter padded with black below).
    pub fn beside(&self, other: &Image) -> Image {
        let (a, b) = (self, other);
        let h = a.height().max(b.height());
        Image::from_fn(a.width() + b.width(), h, |x, y| {
            let (img, x) = if x < a.width() {
                (a, x)
            } else {
                (b, x - a.width())
            };
            if y < img.height() {
                img.pixel(x, y)
            } else {
                [0.0; 3]
            }
        })
    }

    /// The normalised coordinate frame of an image of this size.
    pub fn frame(&self) -> NormalizedFrame {
        NormalizedFrame::new(self.width, self.height)
    }

    /// The RGB value of pixel index `(x, y)`.
    ///
    /// # Panics
    /// If `x ≥ W` or `y ≥ H`.
    pub fn pixel(&self, x: usize, y: usize) -> [f32; 3] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside {}×{}",
            self.width,
            self.height
        );
        let i = 3 * (y * self.width + x);
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Loads a PNG or JPEG file (the format is detected from the bytes, not the extension).
    /// Grey, grey+alpha, RGBA and 16-bit images are converted to RGB in `[0, 1]` (alpha dropped,
    /// 8-bit values divided by 255, 16-bit by 65535).
    ///
    /// Errors name the file: [`DataError::ImageRead`] (missing or unreadable),
    /// [`DataError::ImageUnsupported`] (neither PNG nor JPEG), [`DataError::ImageDecode`] (corrupt).
    pub fn load(path: impl AsRef<Path>) -> Result<Image, DataError> {
        let rgb = decode(path.as_ref())?.into_rgb32f();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        Image::new(width, height, rgb.into_raw())
    }

    /// Loads a PNG or JPEG file like [`Image::load`] and composites it over the opaque colour
    /// `background`: `rgb = α·rgb_file + (1 − α)·background` per pixel, with α in `[0, 1]`
    /// (images without alpha have α = 1 and load unchanged). This is how NeRF-synthetic RGBA
    /// renders are turned into RGB (BARF: white background, `bgcolor: 1`).
    pub fn load_rgba_over(
        path: impl AsRef<Path>,
        background: [f32; 3],
    ) -> Result<Image, DataError> {
        let rgba = decode(path.as_ref())?.into_rgba32f();
        let (width, height) = (rgba.width() as usize, rgba.height() as usize);
        let data = rgba
            .into_raw()
            .chunks_exact(4)
            .flat_map(|p| {
                let a = p[3].clamp(0.0, 1.0);
                [0, 1, 2].map(|c| a * p[c] + (1.0 - a) * background[c])
            })
            .collect();
        Image::new(width, height, data)
    }

    /// Saves as an 8-bit RGB PNG, atomically ([`cpose_core::fs::write_atomic`]): the file is
    /// encoded in memory, written to `<path>.tmp` and renamed. Each value is stored as
    /// `round(255·clamp(v, 0, 1))` (NaN becomes 0).
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), DataError> {
        let path = path.as_ref();
        let bytes: Vec<u8> = self
            .data
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let mut png = Vec::new();
        let (w, h) = self.size_u32();
        ::image::codecs::png::PngEncoder::new(&mut png)
            .write_image(&bytes, w, h, ::image::ExtendedColorType::Rgb8)
            .map_err(|error| DataError::ImageEncode {
                path: path.to_path_buf(),
                error,
            })?;
        cpose_core::fs::write_atomic(path, &png).map_err(|error| DataError::ImageWrite {
            path: path.to_path_buf(),
            error,
        })
    }

    /// The image resized by `scale` to `max(1, round(W·scale)) × max(1, round(H·scale))` with a
    /// triangle (tent) filter whose support widens by the reduction factor when shrinking, so
    /// downsampling averages (anti-aliases) instead of skipping pixels (the `image` crate's
    /// `resize` with `FilterType::Triangle`).
    ///
    /// # Panics
    /// If `scale` is not finite and positive.
    pub fn resized(&self, scale: f64) -> Image {
        assert!(
            scale.is_finite() && scale > 0.0,
            "resize scale must be finite and positive, got {scale}"
        );
        let new_size = |n: usize| ((n as f64 * scale).round() as u32).max(1);
        let (w, h) = self.size_u32();
        let (nw, nh) = (new_size(self.width), new_size(self.height));
        let src: ::image::Rgb32FImage = ::image::ImageBuffer::from_raw(w, h, self.data.clone())
            .expect("the Image invariant guarantees 3·W·H values");
        let out = ::image::imageops::resize(&src, nw, nh, ::image::imageops::FilterType::Triangle);
        Image {
            width: nw as usize,
            height: nh as usize,
            data: out.into_raw(),
        }
    }

    /// Bilinear sample at normalised coordinates `p_norm` (see [`NormalizedFrame`]), equal to
    /// PyTorch `grid_sample(image, p_norm · (L/W, L/H), mode="bilinear", align_corners=False,
    /// padding_mode="border")`. BARF uses the same call with the default `padding_mode="zeros"`,
    /// so the two agree inside the image and differ only outside it:
    ///
    /// `(x, y) = frame.to_pixel(p_norm)` (pixel index, centres at integers), clamped to
    /// `[0, W−1] × [0, H−1]` (clamp to edge: outside the image the nearest edge value is
    /// repeated; BARF's default `padding_mode="zeros"` would fade to black instead), then
    /// `v = (1−fx)(1−fy)·I[y0][x0] + fx(1−fy)·I[y0][x0+1] + (1−fx)fy·I[y0+1][x0] + fx·fy·I[y0+1][x0+1]`
    /// with `x0 = ⌊x⌋`, `fx = x − x0` (same for y). NaN coordinates give NaN values.
    pub fn sample_bilinear(&self, p_norm: [f64; 2]) -> [f32; 3] {
        let [x, y] = self.frame().to_pixel(p_norm);
        let x = x.clamp(0.0, (self.width - 1) as f64);
        let y = y.clamp(0.0, (self.height - 1) as f64);
        // `as usize` saturates (NaN → 0), so the indices below stay in range.
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let (p00, p10, p01, p11) = (
            self.pixel(x0, y0),
            self.pixel(x1, y0),
            self.pixel(x0, y1),
            self.pixel(x1, y1),
        );
        std::array::from_fn(|c| {
            let top = (1.0 - fx) * f64::from(p00[c]) + fx * f64::from(p10[c]);
            let bottom = (1.0 - fx) * f64::from(p01[c]) + fx * f64::from(p11[c]);
            ((1.0 - fy) * top + fy * bottom) as f32
        })
    }

    /// Draws the segment from `a` to `b` (continuous pixel coordinates, centres at `index + 0.5`)
    /// with the given thickness in pixels, anti-aliased: a pixel whose centre is at distance `d`
    /// from the segment gets coverage `clamp(thickness/2 + 0.5 − d, 0, 1)` and becomes
    /// `(1 − coverage)·old + coverage·rgb`. Parts outside the image are clipped; non-finite
    /// points or thickness draw nothing (and so, through overflow, may segments with coordinates
    /// beyond about 1e150 pixels).
    pub fn draw_line(&mut self, a: [f64; 2], b: [f64; 2], rgb: [f32; 3], thickness_px: f64) {
        self.draw_segments(&[a, b], false, rgb, thickness_px);
    }

    /// Draws the closed polygon through `points` (continuous pixel coordinates), last point joined
    /// to the first, like [`Image::draw_line`]; where edges meet, the larger coverage is used
    /// (no double blending at vertices).
    pub fn draw_polygon(&mut self, points: &[[f64; 2]], rgb: [f32; 3], thickness_px: f64) {
        self.draw_segments(points, true, rgb, thickness_px);
    }

    /// Draws a filled square of side `size_px` centred at `centre` (continuous pixel coordinates),
    /// anti-aliased: coverage `clamp(s/2 + 0.5 − |dx|, 0, 1)·clamp(s/2 + 0.5 − |dy|, 0, 1)` for a
    /// pixel centre at offset `(dx, dy)`. Clipped like [`Image::draw_line`].
    pub fn draw_marker(&mut self, centre: [f64; 2], rgb: [f32; 3], size_px: f64) {
        let half = size_px / 2.0;
        if !(half.is_finite() && half > 0.0) {
            return;
        }
        let [cx, cy] = centre;
        let bbox = [
            cx - half - 1.0,
            cy - half - 1.0,
            cx + half + 1.0,
            cy + half + 1.0,
        ];
        self.paint(bbox, rgb, |px, py| {
            (half + 0.5 - (px - cx).abs()).clamp(0.0, 1.0)
                * (half + 0.5 - (py - cy).abs()).clamp(0.0, 1.0)
        });
    }

    /// Segments through `points` (closed: also last → first), blended once with the maximum
    /// coverage over segments.
    fn draw_segments(
        &mut self,
        points: &[[f64; 2]],
        closed: bool,
        rgb: [f32; 3],
        thickness_px: f64,
    ) {
        let radius = thickness_px / 2.0;
        let finite = points.iter().flatten().all(|v| v.is_finite());
        if points.is_empty() || !finite || !(radius.is_finite() && radius > 0.0) {
            return;
        }
        let mut segments: Vec<([f64; 2], [f64; 2])> =
            points.windows(2).map(|w| (w[0], w[1])).collect();
        if closed && points.len() > 2 {
            segments.push((points[points.len() - 1], points[0]));
        }
        if segments.is_empty() {
            segments.push((points[0], points[0]));
        }
        let margin = radius + 1.0;
        let mut bbox = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for p in points {
            bbox = [
                bbox[0].min(p[0] - margin),
                bbox[1].min(p[1] - margin),
                bbox[2].max(p[0] + margin),
                bbox[3].max(p[1] + margin),
            ];
        }
        self.paint(bbox, rgb, |px, py| {
            segments
                .iter()
                .map(|&(a, b)| (radius + 0.5 - distance_to_segment([px, py], a, b)).clamp(0.0, 1.0))
                .fold(0.0, f64::max)
        });
    }

    /// Blends `rgb` into every pixel whose centre lies in `bbox = [x0, y0, x1, y1]` (continuous
    /// pixel coordinates, clipped to the image) with weight `coverage(centre_x, centre_y)`.
    /// A non-finite box paints nothing.
    fn paint(&mut self, bbox: [f64; 4], rgb: [f32; 3], coverage: impl Fn(f64, f64) -> f64) {
        if bbox.iter().any(|v| !v.is_finite()) {
            return;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        // Clamp in f64 before converting so huge coordinates cannot overflow.
        let (x0, x1) = (
            bbox[0].clamp(0.0, w).floor() as usize,
            bbox[2].clamp(0.0, w).ceil() as usize,
        );
        let (y0, y1) = (
            bbox[1].clamp(0.0, h).floor() as usize,
            bbox[3].clamp(0.0, h).ceil() as usize,
        );
        for y in y0..y1 {
            for x in x0..x1 {
                let c = coverage(x as f64 + 0.5, y as f64 + 0.5);
                if c.is_nan() || c <= 0.0 {
                    continue;
                }
                let c = c.min(1.0) as f32;
                let i = 3 * (y * self.width + x);
                for k in 0..3 {
                    self.data[i + k] = (1.0 - c) * self.data[i + k] + c * rgb[k];
                }
            }
        }
    }

    /// `(W, H)` as `u32` (guaranteed by the invariant).
    fn size_u32(&self) -> (u32, u32) {
        let w = u32::try_from(self.width).expect("the Image invariant keeps W ≤ u32::MAX");
        let h = u32::try_from(self.height).expect("the Image invariant keeps H ≤ u32::MAX");
        (w, h)
    }
}

/// Euclidean distance from `p` to the segment `[a, b]`: `|p − (a + t·(b − a))|` with
/// `t = clamp(⟨p − a, b − a⟩ / |b − a|², 0, 1)` (`t = 0` for a degenerate segment).
fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (ap[0] - t * ab[0]).hypot(ap[1] - t * ab[1])
}

/// BARF's normalised image coordinates for a `width × height` image (`model/planar.py`): with
/// `L = max(W, H)`, pixel index `(x, y)` (centre at continuous `(x + 0.5, y + 0.5)`) maps to
///
/// `x_n = ((x + 0.5)/W·2 − 1)·(W/L) = (2x + 1 − W)/L`,
/// `y_n = ((y + 0.5)/H·2 − 1)·(H/L) = (2y + 1 − H)/L`,
///
/// so the long side's outer pixel edges are at `±1`, the short side's at `±S/L`, one pixel is
/// `2/L` wide, and the scale is the same on both axes. For 480×360: `x_n ∈ [−1, 1]`,
/// `y_n ∈ [−0.75, 0.75]` (pixel edges).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NormalizedFrame {
    /// Image width W in pixels.
    pub width: usize,
    /// Image height H in pixels.
    pub height: usize,
}

impl NormalizedFrame {
    /// The frame of a `width × height` image.
    pub fn new(width: usize, height: usize) -> NormalizedFrame {
        NormalizedFrame { width, height }
    }

    /// `L = max(W, H)` as `f64`: the long side, which spans 2 normalised units.
    fn long_side(&self) -> f64 {
        self.width.max(self.height) as f64
    }

    /// Pixel index (fractional allowed; centres at integers) → normalised:
    /// `x_n = (2x + 1 − W)/L`, `y_n = (2y + 1 − H)/L`.
    pub fn to_normalized(&self, pixel: [f64; 2]) -> [f64; 2] {
        let l = self.long_side();
        [
            (2.0 * pixel[0] + 1.0 - self.width as f64) / l,
            (2.0 * pixel[1] + 1.0 - self.height as f64) / l,
        ]
    }

    /// Normalised → pixel index (centres at integers), the inverse of
    /// [`NormalizedFrame::to_normalized`]: `x = (x_n·L + W − 1)/2`, `y = (y_n·L + H − 1)/2`
    /// (BARF's corner conversion `X = (x_n·L/W + 1)/2·W − 0.5`).
    pub fn to_pixel(&self, p_norm: [f64; 2]) -> [f64; 2] {
        let l = self.long_side();
        [
            (p_norm[0] * l + self.width as f64 - 1.0) / 2.0,
            (p_norm[1] * l + self.height as f64 - 1.0) / 2.0,
        ]
    }

    /// Normalised → continuous pixel coordinates (centres at `index + 0.5`, the image spans
    /// `[0, W] × [0, H]`), for the drawing functions: `to_pixel(p_norm) + 0.5`.
    pub fn to_continuous(&self, p_norm: [f64; 2]) -> [f64; 2] {
        let [x, y] = self.to_pixel(p_norm);
        [x + 0.5, y + 0.5]
    }
}

/// Peak signal-to-noise ratio for values in `[0, 1]`: `−10·log10(MSE)`,
/// `MSE = mean_i (a_i − b_i)²` (computed in `f64`). Identical inputs give `+∞`.
///
/// # Panics
/// If the slices differ in length or are empty.
pub fn psnr(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "psnr of slices of different lengths");
    assert!(!a.is_empty(), "psnr of empty slices");
    let sse: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum();
    -10.0 * (sse / a.len() as f64).log10()
}

/// A deterministic, natural-looking procedural RGB image for demos and tests of alignment: it
/// has structure at every scale from the whole image down to a few pixels and no large flat
/// region.
///
/// Construction (all randomness from `seed` through a fixed integer hash, so the result does
/// not depend on any RNG crate's version), in coordinates `u = x/L, v = y/L`, `L = max(W, H)`:
/// 1. fBm of 2-D gradient (Perlin-style) noise, `fbm(p) = Σ_k 0.5^k·noise(3·2^k·p)`, octaves
///    until the finest period is about 4 pixels: amplitude ∝ 1/frequency, as in natural images.
/// 2. Domain warping for organic shapes: `t = fbm(p + 0.6·(fbm(p + o₁), fbm(p + o₂)))`.
/// 3. Colour: half a cosine palette `a + b·cos(2π(h + d))` (seeded phases `d`, hue `h` from the
///    noise and the warp field), half a grey level following the noise, so brightness carries
///    the structure and colours stay muted; the warp field also modulates brightness.
/// 4. A few soft-edged discs and rotated bars (edges about 1 pixel wide), shaded by the noise so
///    they stay textured inside.
///
/// # Panics
/// If `width` or `height` is 0.
pub fn procedural_texture(width: usize, height: usize, seed: u64) -> Image {
    let l = width.max(height) as f64;
    // Octaves: base frequency 3 per long side, doubled until the period reaches ~4 px.
    let octaves = ((l / (3.0 * 4.0)).log2().ceil().max(1.0) as u32).min(16);
    let fbm = |u: f64, v: f64, stream: u64| -> f64 {
        let (mut sum, mut amp, mut freq) = (0.0, 1.0, 3.0);
        for k in 0..octaves {
            let key = hash2(seed, stream, u64::from(k));
            // A per-octave offset decorrelates the lattices' origins.
            let (ox, oy) = (unit_f64(key) * 64.0, unit_f64(key ^ 0x5bd1) * 64.0);
            sum += amp * gradient_noise(u * freq + ox, v * freq + oy, key);
            amp *= 0.5;
            freq *= 2.0;
        }
        sum
    };
    let phase: [f64; 3] = std::array::from_fn(|c| unit_f64(hash2(seed, 100, c as u64)));
    let shapes = Shapes::new(seed);
    Image::from_fn(width, height, |x, y| {
        let (u, v) = ((x as f64 + 0.5) / l, (y as f64 + 0.5) / l);
        let (qx, qy) = (fbm(u + 1.7, v + 9.2, 1), fbm(u + 8.3, v + 2.8, 2));
        let t = fbm(u + 0.6 * qx, v + 0.6 * qy, 3);
        // fBm values concentrate around 0 (std ≈ 0.25): stretch to use the whole palette.
        let s = (0.5 + 1.4 * t).clamp(0.0, 1.0);
        let shade = 0.75 + 0.5 * qx.clamp(-0.5, 0.5);
        // Hue from the palette, rgb = a + b·cos(2π(c·h + d)) with a = 0.5, b = 0.45, c = 1, at
        // h = 0.8·s + 0.3·q_y; mixed half and half with the grey level 0.1 + 0.8·s so that
        // brightness follows the noise and colours stay muted, as in photographs.
        let hue = 0.8 * s + 0.3 * qy;
        let mut rgb: [f64; 3] = std::array::from_fn(|c| {
            let palette = 0.5 + 0.45 * (std::f64::consts::TAU * (hue + phase[c])).cos();
            (0.5 * palette + 0.5 * (0.1 + 0.8 * s)) * shade
        });
        shapes.blend(&mut rgb, x as f64 + 0.5, y as f64 + 0.5, l, t);
        rgb.map(|c| c.clamp(0.0, 1.0) as f32)
    })
}

/// The discs and bars of [`procedural_texture`], in continuous pixel coordinates scaled by `L`.
struct Shapes {
    /// `(centre_x, centre_y, radius)` in units of `L`, and colour.
    discs: Vec<([f64; 3], [f64; 3])>,
    /// `(centre_x, centre_y, angle, half_length, half_width)` in units of `L`, and colour.
    bars: Vec<([f64; 5], [f64; 3])>,
}

impl Shapes {
    fn new(seed: u64) -> Shapes {
        let r = |i: u64| unit_f64(hash2(seed, 200, i));
        let colour = |i: u64| -> [f64; 3] { std::array::from_fn(|c| 0.15 + 0.8 * r(i + c as u64)) };
        let discs = (0..5)
            .map(|k| {
                let i = 10 * k;
                (
                    [
                        0.1 + 0.8 * r(i),
                        0.1 + 0.6 * r(i + 1),
                        0.04 + 0.1 * r(i + 2),
                    ],
                    colour(i + 3),
                )
            })
            .collect();
        let bars = (0..3)
            .map(|k| {
                let i = 1000 + 10 * k;
                let geometry = [
                    0.1 + 0.8 * r(i),
                    0.1 + 0.6 * r(i + 1),
                    std::f64::consts::PI * r(i + 2),
                    0.1 + 0.15 * r(i + 3),
                    0.01 + 0.02 * r(i + 4),
                ];
                (geometry, colour(i + 5))
            })
            .collect();
        Shapes { discs, bars }
    }

    /// Alpha-blends the shapes over `rgb` at pixel point `(px, py)`; `t` (the noise value) shades
    /// the shape colour so shapes keep texture.
    fn blend(&self, rgb: &mut [f64; 3], px: f64, py: f64, l: f64, t: f64) {
        let (u, v) = (px / l, py / l);
        let mut over = |signed_distance_px: f64, colour: &[f64; 3]| {
            // Soft edge about one pixel wide: alpha = smoothstep of the signed distance.
            let a = 0.85 * smoothstep((0.5 - signed_distance_px).clamp(0.0, 1.0));
            for c in 0..3 {
                rgb[c] = (1.0 - a) * rgb[c] + a * colour[c] * (0.8 + 0.6 * t);
            }
        };
        for (d, colour) in &self.discs {
            over(((u - d[0]).hypot(v - d[1]) - d[2]) * l, colour);
        }
        for (b, colour) in &self.bars {
            let (s, c) = b[2].sin_cos();
            let (du, dv) = (u - b[0], v - b[1]);
            // Bar frame: along = projection on the axis direction, across = perpendicular.
            let (along, across) = (c * du + s * dv, -s * du + c * dv);
            let outside = (along.abs() - b[3]).max(across.abs() - b[4]);
            over(outside * l, colour);
        }
    }
}

/// `3s² − 2s³` for `s ∈ [0, 1]`.
fn smoothstep(s: f64) -> f64 {
    s * s * (3.0 - 2.0 * s)
}

/// 2-D gradient noise: unit gradients `g` at integer lattice points (angles from the hash of
/// `(key, i, j)`), `n(p) = Σ_corners w(f)·⟨g, p − corner⟩` with the quintic fade
/// `w(s) = 6s⁵ − 15s⁴ + 10s³` (C² across cells). Values lie in about `[−0.7, 0.7]`, 0 at lattice
/// points.
fn gradient_noise(x: f64, y: f64, key: u64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (fx, fy) = (x - xf, y - yf);
    let (ix, iy) = (xf as i64, yf as i64);
    let corner = |di: i64, dj: i64| -> f64 {
        let h = hash2(key, (ix + di) as u64, (iy + dj) as u64);
        let (s, c) = (std::f64::consts::TAU * unit_f64(h)).sin_cos();
        c * (fx - di as f64) + s * (fy - dj as f64)
    };
    let fade = |s: f64| s * s * s * (s * (6.0 * s - 15.0) + 10.0);
    let (wx, wy) = (fade(fx), fade(fy));
    let top = corner(0, 0) + wx * (corner(1, 0) - corner(0, 0));
    let bottom = corner(0, 1) + wx * (corner(1, 1) - corner(0, 1));
    top + wy * (bottom - top)
}

/// SplitMix64's output function (Steele, Lea, Flood 2014): a bijective 64-bit mixer.
fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of three words, chaining [`mix64`].
fn hash2(a: u64, b: u64, c: u64) -> u64 {
    mix64(mix64(mix64(a) ^ b) ^ c)
}

/// The top 53 bits of `h` as a uniform value in `[0, 1)`.
fn unit_f64(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Reads and decodes a PNG or JPEG file (format detected from the bytes), with errors naming
/// the file (see [`Image::load`]).
fn decode(path: &Path) -> Result<::image::DynamicImage, DataError> {
    let bytes = std::fs::read(path).map_err(|error| DataError::ImageRead {
        path: path.to_path_buf(),
        error,
    })?;
    let format = match ::image::guess_format(&bytes) {
        Ok(f @ (::image::ImageFormat::Png | ::image::ImageFormat::Jpeg)) => f,
        Ok(other) => {
            return Err(DataError::ImageUnsupported {
                path: path.to_path_buf(),
                found: format!("{other:?} data"),
            });
        }
        Err(_) => {
            return Err(DataError::ImageUnsupported {
                path: path.to_path_buf(),
                found: "unrecognised data".to_owned(),
            });
        }
    };
    let format_name = if format == ::image::ImageFormat::Png {
        "PNG"
    } else {
        if !jpeg_is_complete(&bytes) {
            return Err(DataError::ImageTruncated {
                path: path.to_path_buf(),
            });
        }
        "JPEG"
    };
    let decoded = ::image::load_from_memory_with_format(&bytes, format).map_err(|error| {
        DataError::ImageDecode {
            path: path.to_path_buf(),
            format: format_name,
            error,
        }
    })?;
    Ok(decoded)
}

/// Whether JPEG `bytes` hold an end-of-image marker (`FF D9`) after the start of their last scan
/// (`FF DA`). Scan data never holds `FF D9` (a data byte `FF` is stuffed as `FF 00`), so a file cut
/// inside its image data has none; data appended after the image (a second image, padding)
/// keeps its own marker or does not matter.
fn jpeg_is_complete(bytes: &[u8]) -> bool {
    let marker = |m: u8| move |w: &[u8]| w == [0xFF, m];
    let Some(scan) = bytes.windows(2).rposition(marker(0xDA)) else {
        return false;
    };
    bytes[scan..].windows(2).any(marker(0xD9))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> cpose_core::testing::TempDir {
        cpose_core::testing::TempDir::new(&format!("image-{name}"))
    }

    #[test]
    fn new_checks_shape_and_pixel_reads_interleaved_rows() {
        let img = Image::new(2, 1, vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]).unwrap();
        assert_eq!(img.pixel(1, 0), [0.4, 0.5, 0.6]);
        assert!(matches!(
            Image::new(2, 2, vec![0.0; 6]),
            Err(DataError::ImageShape { .. })
        ));
        assert!(matches!(
            Image::new(0, 0, vec![]),
            Err(DataError::ImageShape { .. })
        ));
        let f = Image::from_fn(3, 2, |x, y| [x as f32, y as f32, 0.0]);
        assert_eq!(f.pixel(2, 1), [2.0, 1.0, 0.0]);
        assert_eq!(f.data()[3 * (3 + 1)], 1.0); // pixel (1, 1), red
    }

    #[test]
    fn normalized_frame_maps_pixel_centre_extremes_and_round_trips() {
        let frame = NormalizedFrame::new(480, 360);
        let lo = frame.to_normalized([0.0, 0.0]);
        let hi = frame.to_normalized([479.0, 359.0]);
        let (ex, ey) = (1.0 - 1.0 / 480.0, 0.75 * (1.0 - 1.0 / 360.0));
        assert!((lo[0] + ex).abs() < 1e-15 && (hi[0] - ex).abs() < 1e-15);
        assert!((lo[1] + ey).abs() < 1e-15 && (hi[1] - ey).abs() < 1e-15);
        // The image centre (between pixels 239/240 and 179/180) is the origin.
        assert_eq!(frame.to_normalized([239.5, 179.5]), [0.0, 0.0]);
        for p in [[0.0, 0.0], [12.25, 300.5], [479.0, 359.0], [-3.0, 400.0]] {
            let q = frame.to_pixel(frame.to_normalized(p));
            assert!((q[0] - p[0]).abs() < 1e-12 && (q[1] - p[1]).abs() < 1e-12);
        }
        // BARF's corner conversion X = (x_n·L/W + 1)/2·W − 0.5.
        let x_n = 0.37;
        let barf = (x_n * 480.0 / 480.0 + 1.0) / 2.0 * 480.0 - 0.5;
        assert!((frame.to_pixel([x_n, 0.0])[0] - barf).abs() < 1e-12);
        assert_eq!(frame.to_continuous([-1.0, -0.75]), [0.0, 0.0]); // outer pixel edge
    }

    #[test]
    fn bilinear_sampling_matches_hand_values() {
        // 2×2: L = 2, x_n = x − 0.5 for pixel index x.
        let img = Image::new(
            2,
            2,
            vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0],
        )
        .unwrap();
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-6);
        // Centre: mean of the four pixels.
        assert!(close(img.sample_bilinear([0.0, 0.0]), [0.5, 0.5, 0.25]));
        // Pixel centres are exact.
        assert!(close(img.sample_bilinear([0.5, -0.5]), [1.0, 0.0, 0.0]));
        // Index (0.25, 1): 0.75·I(0,1) + 0.25·I(1,1).
        assert!(close(img.sample_bilinear([-0.25, 0.5]), [0.25, 1.0, 0.25]));
        // Non-square 3×2 (L = 3): pixel (2, 1) is at ((2·2+1−3)/3, (2·1+1−2)/3) = (2/3, 1/3).
        let img = Image::from_fn(3, 2, |x, y| [x as f32, y as f32, (x * y) as f32]);
        assert!(close(
            img.sample_bilinear([2.0 / 3.0, 1.0 / 3.0]),
            [2.0, 1.0, 2.0]
        ));
        // Half-way between pixels (0, 0) and (1, 0), a quarter down towards row 1.
        let p = img.frame().to_normalized([0.5, 0.25]);
        assert!(close(img.sample_bilinear(p), [0.5, 0.25, 0.125]));
    }

    #[test]
    fn bilinear_sampling_clamps_to_the_edge() {
        let img = Image::from_fn(3, 2, |x, y| [x as f32, y as f32, 0.5]);
        assert_eq!(img.sample_bilinear([-5.0, -5.0]), [0.0, 0.0, 0.5]);
        assert_eq!(img.sample_bilinear([5.0, 5.0]), [2.0, 1.0, 0.5]);
        // Beyond the right edge, half-way between the rows.
        let p = img.frame().to_normalized([7.0, 0.5]);
        assert_eq!(img.sample_bilinear(p), [2.0, 0.5, 0.5]);
        assert!(img.sample_bilinear([f64::NAN, 0.0])[0].is_nan());
    }

    #[test]
    fn png_round_trip_is_exact_for_8_bit_values_and_clamps() {
        let dir = temp_dir("png");
        let path = dir.join("a.png");
        let img = Image::from_fn(5, 3, |x, y| {
            [x as f32 / 255.0, (10 * y) as f32 / 255.0, 200.0 / 255.0]
        });
        img.save_png(&path).unwrap();
        assert!(!dir.join("a.png.tmp").exists());
        let back = Image::load(&path).unwrap();
        assert_eq!((back.width(), back.height()), (5, 3));
        assert!(
            back.data()
                .iter()
                .zip(img.data())
                .all(|(a, b)| (a - b).abs() < 1e-6)
        );
        let out_of_range = Image::new(1, 1, vec![-0.5, 1.7, 0.5]).unwrap();
        out_of_range.save_png(&path).unwrap();
        let back = Image::load(&path).unwrap();
        assert_eq!(back.pixel(0, 0), [0.0, 1.0, 128.0 / 255.0]);
    }

    #[test]
    fn load_converts_grey_rgba_and_jpeg_to_rgb() {
        let dir = temp_dir("formats");
        let grey = ::image::GrayImage::from_raw(2, 1, vec![0, 255]).unwrap();
        grey.save(dir.join("grey.png")).unwrap();
        let img = Image::load(dir.join("grey.png")).unwrap();
        assert_eq!(img.data(), &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        let rgba = ::image::RgbaImage::from_raw(1, 1, vec![255, 0, 51, 7]).unwrap();
        rgba.save(dir.join("rgba.png")).unwrap();
        assert_eq!(
            Image::load(dir.join("rgba.png")).unwrap().data(),
            &[1.0, 0.0, 0.2]
        );
        let flat = ::image::RgbImage::from_pixel(16, 8, ::image::Rgb([200, 100, 50]));
        // Saved under a misleading extension: the format is taken from the bytes.
        flat.save_with_format(dir.join("flat.png"), ::image::ImageFormat::Jpeg)
            .unwrap();
        let img = Image::load(dir.join("flat.png")).unwrap();
        assert_eq!((img.width(), img.height()), (16, 8));
        let p = img.pixel(3, 3);
        assert!(
            (p[0] - 200.0 / 255.0).abs() < 0.02 && (p[2] - 50.0 / 255.0).abs() < 0.02,
            "{p:?}"
        );
        // Cut inside its image data, the same file is refused (the decoder would fill it).
        let bytes = std::fs::read(dir.join("flat.png")).unwrap();
        std::fs::write(dir.join("cut.jpg"), &bytes[..bytes.len() - 40]).unwrap();
        let err = Image::load(dir.join("cut.jpg")).unwrap_err();
        assert!(matches!(err, DataError::ImageTruncated { .. }), "{err}");
        assert!(err.to_string().contains("cut.jpg"), "{err}");
        // Bytes appended after the end of the image do not matter.
        std::fs::write(dir.join("padded.jpg"), [&bytes[..], &[0; 16]].concat()).unwrap();
        assert!(Image::load(dir.join("padded.jpg")).is_ok());
    }

    #[test]
    fn load_rgba_over_composites_on_the_background() {
        let dir = temp_dir("rgba-over");
        let rgba = ::image::RgbaImage::from_raw(2, 1, vec![255, 0, 0, 255, 0, 0, 255, 51]).unwrap();
        rgba.save(dir.join("a.png")).unwrap();
        let img = Image::load_rgba_over(dir.join("a.png"), [1.0, 1.0, 1.0]).unwrap();
        let expect = [1.0, 0.0, 0.0, 0.8, 0.8, 1.0];
        assert!(
            img.data()
                .iter()
                .zip(&expect)
                .all(|(a, b)| (a - b).abs() < 1e-6),
            "{img:?}"
        );
    }

    #[test]
    fn load_errors_name_the_file_and_the_expectation() {
        let dir = temp_dir("errors");
        let missing = dir.join("missing.png");
        let err = Image::load(&missing).unwrap_err();
        assert!(matches!(err, DataError::ImageRead { .. }));
        assert!(err.to_string().contains("missing.png"), "{err}");
        assert!(matches!(
            Image::load(&dir).unwrap_err(),
            DataError::ImageRead { .. }
        ));

        let text = dir.join("notes.png");
        std::fs::write(&text, "this is not an image").unwrap();
        let err = Image::load(&text).unwrap_err();
        assert!(matches!(err, DataError::ImageUnsupported { .. }), "{err}");
        assert!(
            err.to_string().contains("expected PNG or JPEG")
                && err.to_string().contains("notes.png"),
            "{err}"
        );

        let gif = dir.join("x.gif");
        std::fs::write(&gif, b"GIF89a\x01\x00\x01\x00\x00\x00\x00;").unwrap();
        assert!(matches!(
            Image::load(&gif).unwrap_err(),
            DataError::ImageUnsupported { .. }
        ));

        let truncated = dir.join("truncated.png");
        let mut png = Vec::new();
        ::image::codecs::png::PngEncoder::new(&mut png)
            .write_image(&[7u8; 3 * 64], 8, 8, ::image::ExtendedColorType::Rgb8)
            .unwrap();
        std::fs::write(&truncated, &png[..png.len() / 2]).unwrap();
        let err = Image::load(&truncated).unwrap_err();
        assert!(
            matches!(err, DataError::ImageDecode { format: "PNG", .. }),
            "{err}"
        );
    }

    #[test]
    fn resized_rounds_the_size_and_averages_when_shrinking() {
        // A 1-pixel checkerboard averages to grey at half size instead of aliasing.
        let board = Image::from_fn(40, 30, |x, y| [((x + y) % 2) as f32; 3]);
        let half = board.resized(0.5);
        assert_eq!((half.width(), half.height()), (20, 15));
        for &v in half.data() {
            assert!((v - 0.5).abs() < 0.1, "{v}");
        }
        let odd = board.resized(1.0 / 3.0);
        assert_eq!((odd.width(), odd.height()), (13, 10)); // round(13.33), round(10)
        let up = Image::from_fn(2, 2, |_, _| [0.25, 0.5, 0.75]).resized(2.5);
        assert_eq!((up.width(), up.height()), (5, 5));
        assert!(
            up.data()
                .chunks(3)
                .all(|p| (p[0] - 0.25).abs() < 1e-6 && (p[2] - 0.75).abs() < 1e-6)
        );
    }

    #[test]
    fn procedural_texture_is_deterministic_and_textured_everywhere() {
        let a = procedural_texture(240, 180, 7);
        assert_eq!(a, procedural_texture(240, 180, 7));
        assert_ne!(a, procedural_texture(240, 180, 8));
        assert!(a.data().iter().all(|v| (0.0..=1.0).contains(v)));
        // No large flat region: every 20×20 block has luminance spread.
        let lum = |x: usize, y: usize| {
            let p = a.pixel(x, y);
            0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]
        };
        let mut min_std = f32::INFINITY;
        for by in (0..180).step_by(20) {
            for bx in (0..240).step_by(20) {
                let vals: Vec<f32> = (0..400).map(|i| lum(bx + i % 20, by + i / 20)).collect();
                let mean = vals.iter().sum::<f32>() / 400.0;
                let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / 400.0;
                min_std = min_std.min(var.sqrt());
            }
        }
        assert!(min_std > 0.01, "flattest 20×20 block has std {min_std}");
        // Texture at fine scale: mean absolute neighbour difference well above zero.
        let fine: f32 = (0..179)
            .flat_map(|y| (0..239).map(move |x| (x, y)))
            .map(|(x, y)| (lum(x + 1, y) - lum(x, y)).abs())
            .sum::<f32>()
            / (179.0 * 239.0);
        assert!(fine > 0.005, "mean neighbour difference {fine}");
    }

    #[test]
    fn drawing_colours_the_shape_and_clips_safely() {
        let black = || Image::from_fn(10, 8, |_, _| [0.0; 3]);
        let mut img = black();
        // Horizontal line through the centres of row 3, 1 px thick.
        img.draw_line([0.0, 3.5], [10.0, 3.5], [1.0, 0.0, 0.0], 1.0);
        for x in 0..10 {
            assert_eq!(img.pixel(x, 3), [1.0, 0.0, 0.0]);
            assert_eq!(img.pixel(x, 1), [0.0; 3]);
            assert_eq!(img.pixel(x, 5), [0.0; 3]);
        }
        let mut img = black();
        img.draw_polygon(
            &[[1.5, 1.5], [8.5, 1.5], [8.5, 6.5], [1.5, 6.5]],
            [0.0, 1.0, 0.0],
            1.0,
        );
        assert_eq!(img.pixel(1, 4), [0.0, 1.0, 0.0]); // closing edge
        assert_eq!(img.pixel(1, 1), [0.0, 1.0, 0.0]); // vertex
        assert_eq!(img.pixel(4, 4), [0.0; 3]); // inside: not filled
        let mut img = black();
        img.draw_marker([5.0, 4.0], [0.0, 0.0, 1.0], 2.0);
        assert_eq!(img.pixel(4, 3), [0.0, 0.0, 1.0]);
        assert_eq!(img.pixel(5, 4), [0.0, 0.0, 1.0]);
        assert_eq!(img.pixel(7, 4), [0.0; 3]);
        // Outside, huge, non-finite: no panic, nothing drawn outside.
        let mut img = black();
        img.draw_line([-1e300, -5.0], [1e300, -5.0], [1.0; 3], 2.0);
        img.draw_line([f64::NAN, 0.0], [5.0, 5.0], [1.0; 3], 2.0);
        img.draw_line([0.0, 0.0], [5.0, 5.0], [1.0; 3], f64::INFINITY);
        img.draw_polygon(&[], [1.0; 3], 1.0);
        img.draw_marker([-100.0, 1e9], [1.0; 3], 3.0);
        assert_eq!(img, black());
        img.draw_line([-1e12, 3.5], [1e12, 3.5], [1.0; 3], 1.0);
        assert_eq!(img.pixel(0, 3), [1.0; 3]);
    }

    #[test]
    fn psnr_of_known_errors() {
        assert_eq!(psnr(&[0.5, 0.5], &[0.5, 0.5]), f64::INFINITY);
        // MSE = 0.01 → 20 dB.
        assert!((psnr(&[0.1, 0.0], &[0.0, 0.1]) - 20.0).abs() < 1e-5);
        // MSE = 0.5 · 1 → 10·log10(2).
        assert!((psnr(&[1.0, 0.0], &[0.0, 0.0]) - 10.0 * 2f64.log10()).abs() < 1e-12);
    }
}
