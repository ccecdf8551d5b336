//! EventNeRF's colour correction before image metrics (docs/methods.md §3.4).
//!
//! Events fix log intensity only up to an offset and a contrast per channel, so renders are
//! mapped onto the ground truth before PSNR and SSIM: in `x = log(I^2.2 + 0.1)`, a least-squares
//! line `x_gt ≈ A x + B` per RGB channel over all pixels of all images, then
//! `I' = clip(max(0, exp(A x + B) − 0.1)^(1/2.2), 0, 1)`.

use cpose_nerf::image::Image;

/// `ε` of the metric's log space (EventNeRF's `metric/main.py`).
const EPS: f64 = 0.1;
/// Display gamma.
const GAMMA: f64 = 2.2;

fn to_log(v: f32) -> f64 {
    (f64::from(v).max(0.0).powf(GAMMA) + EPS).ln()
}

/// A per-channel affine map in log intensity, `x ↦ A x + B`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColourCorrection {
    /// `A` per channel.
    pub gain: [f64; 3],
    /// `B` per channel.
    pub offset: [f64; 3],
}

impl ColourCorrection {
    /// The least-squares map from `renders` to `truths` (pairs of equal size); a channel whose
    /// renders are constant gets `A = 0` and `B` = the truth's mean.
    pub fn fit(renders: &[Image], truths: &[Image]) -> Self {
        // Per channel: n, Σx, Σy, Σxx, Σxy.
        let mut s = [[0.0f64; 5]; 3];
        for (r, t) in renders.iter().zip(truths) {
            for (px, py) in r.data().chunks_exact(3).zip(t.data().chunks_exact(3)) {
                for c in 0..3 {
                    let (x, y) = (to_log(px[c]), to_log(py[c]));
                    let a = &mut s[c];
                    a[0] += 1.0;
                    a[1] += x;
                    a[2] += y;
                    a[3] += x * x;
                    a[4] += x * y;
                }
            }
        }
        let mut out = Self {
            gain: [1.0; 3],
            offset: [0.0; 3],
        };
        for c in 0..3 {
            let [n, sx, sy, sxx, sxy] = s[c];
            if n == 0.0 {
                continue;
            }
            let (mx, my) = (sx / n, sy / n);
            let var = sxx / n - mx * mx;
            let cov = sxy / n - mx * my;
            let gain = if var > 1e-12 { cov / var } else { 0.0 };
            out.gain[c] = gain;
            out.offset[c] = my - gain * mx;
        }
        out
    }

    /// `image` mapped by the correction.
    pub fn apply(&self, image: &Image) -> Image {
        Image::from_fn(image.width(), image.height(), |x, y| {
            let p = image.pixel(x, y);
            std::array::from_fn(|c| {
                let v = (self.gain[c] * to_log(p[c]) + self.offset[c]).exp() - EPS;
                (v.max(0.0).powf(1.0 / GAMMA)).clamp(0.0, 1.0) as f32
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use cpose_nerf::image::procedural_texture;

    use super::*;

    /// A render that differs from the truth by an affine map in log space is corrected back to
    /// it, and the fitted map is that one's inverse.
    #[test]
    fn recovers_an_affine_change_of_log_intensity() {
        let truth = procedural_texture(24, 16, 3);
        // Chosen so that the render stays inside [0, 1] (no clipping).
        let (gain, offset) = ([1.3, 1.1, 1.5], [0.2, 0.1, 0.5]);
        let render = Image::from_fn(24, 16, |x, y| {
            let p = truth.pixel(x, y);
            std::array::from_fn(|c| {
                let v = ((to_log(p[c]) - offset[c]) / gain[c]).exp() - EPS;
                v.max(0.0).powf(1.0 / GAMMA) as f32
            })
        });
        let fit =
            ColourCorrection::fit(std::slice::from_ref(&render), std::slice::from_ref(&truth));
        for c in 0..3 {
            assert!((fit.gain[c] - gain[c]).abs() < 1e-3, "{fit:?}");
            assert!((fit.offset[c] - offset[c]).abs() < 1e-3, "{fit:?}");
        }
        let corrected = fit.apply(&render);
        let err = corrected
            .data()
            .iter()
            .zip(truth.data())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(err < 2e-3, "{err}");
    }
}
