//! Image quality metrics beyond PSNR ([`crate::image::psnr`]): SSIM.
//!
//! # SSIM
//!
//! [`ssim`] reproduces scikit-image's
//! `structural_similarity(a, b, channel_axis=-1, data_range=1.0, gaussian_weights=True,
//! sigma=1.5, use_sample_covariance=False)` (Wang et al. 2004), computed in `f64`:
//!
//! * Window: the normalised 1-D Gaussian `g(k) ∝ exp(−k²/(2σ²))`, `σ = 1.5`, `k = −r..=r` with
//!   radius `r = ⌊3.5·σ + 0.5⌋ = 5` (skimage's `truncate = 3.5`), applied separably along rows
//!   and columns (window 11 × 11); borders are extended by half-sample symmetric reflection
//!   (SciPy `mode='reflect'`: `… c b a | a b c …`).
//! * Per channel, with `G∗` that filter: `μx = G∗x`, `μy = G∗y`, `σx² = G∗x² − μx²`,
//!   `σy² = G∗y² − μy²`, `σxy = G∗(xy) − μx·μy` (population covariance), and
//!   `S = (2μxμy + C1)(2σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2))`,
//!   `C1 = (0.01·L)²`, `C2 = (0.03·L)²`, `L = 1` (data range).
//! * The SSIM of a channel is the mean of `S` over the pixels at least `r = 5` from every border
//!   (skimage crops `(win − 1)/2` on each side); the result is the mean over the three channels.
//!
//! BARF evaluates with `pohsun_ssim` (11 × 11 Gaussian, σ = 1.5, same constants, zero padding
//! and a mean over all pixels), so its numbers differ slightly near the borders.

use crate::image::Image;

/// The Gaussian standard deviation of the SSIM window, in pixels.
pub const SSIM_SIGMA: f64 = 1.5;
/// The SSIM window radius `⌊3.5·σ + 0.5⌋` (skimage `truncate = 3.5`): the window is 11 × 11.
pub const SSIM_RADIUS: usize = 5;

/// The side of SSIM's window, `2 · SSIM_RADIUS + 1`: the least image side [`ssim`] takes.
pub const SSIM_WINDOW: usize = 2 * SSIM_RADIUS + 1;
/// `C1 = (K1·L)²` with `K1 = 0.01` and data range `L = 1`.
pub const SSIM_C1: f64 = 0.01 * 0.01;
/// `C2 = (K2·L)²` with `K2 = 0.03` and data range `L = 1`.
pub const SSIM_C2: f64 = 0.03 * 0.03;

/// The mean structural similarity of two RGB images with values in `[0, 1]`, as scikit-image's
/// `structural_similarity(…, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
/// data_range=1.0, channel_axis=-1)`; see the module docs for the formula. 1 for identical
/// images.
///
/// # Panics
/// If the images differ in size or either side is shorter than the 11-pixel window (skimage
/// raises an error there too).
pub fn ssim(a: &Image, b: &Image) -> f64 {
    let (w, h) = (a.width(), a.height());
    assert_eq!(
        (w, h),
        (b.width(), b.height()),
        "ssim of images of different sizes"
    );
    let win = SSIM_WINDOW;
    assert!(
        w >= win && h >= win,
        "ssim needs images of at least {win}×{win} pixels, got {w}×{h}"
    );
    let kernel = gaussian_kernel();
    let mut total = 0.0;
    for c in 0..3 {
        let x: Vec<f64> = a.data()[c..]
            .iter()
            .step_by(3)
            .map(|&v| f64::from(v))
            .collect();
        let y: Vec<f64> = b.data()[c..]
            .iter()
            .step_by(3)
            .map(|&v| f64::from(v))
            .collect();
        let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
        let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
        let xy: Vec<f64> = x.iter().zip(&y).map(|(p, q)| p * q).collect();
        let [ux, uy, uxx, uyy, uxy] = [&x, &y, &xx, &yy, &xy].map(|m| filter(m, w, h, &kernel));
        let mut sum = 0.0;
        for row in SSIM_RADIUS..h - SSIM_RADIUS {
            for col in SSIM_RADIUS..w - SSIM_RADIUS {
                let i = row * w + col;
                let (mx, my) = (ux[i], uy[i]);
                let vx = uxx[i] - mx * mx;
                let vy = uyy[i] - my * my;
                let vxy = uxy[i] - mx * my;
                let num = (2.0 * mx * my + SSIM_C1) * (2.0 * vxy + SSIM_C2);
                let den = (mx * mx + my * my + SSIM_C1) * (vx + vy + SSIM_C2);
                sum += num / den;
            }
        }
        total += sum / ((w - 2 * SSIM_RADIUS) * (h - 2 * SSIM_RADIUS)) as f64;
    }
    total / 3.0
}

/// The normalised 1-D Gaussian weights `g(k) ∝ exp(−k²/(2σ²))`, `k = −r..=r`.
fn gaussian_kernel() -> Vec<f64> {
    let r = SSIM_RADIUS as f64;
    let g: Vec<f64> = (0..=2 * SSIM_RADIUS)
        .map(|k| {
            let d = k as f64 - r;
            (-0.5 * d * d / (SSIM_SIGMA * SSIM_SIGMA)).exp()
        })
        .collect();
    let s: f64 = g.iter().sum();
    g.into_iter().map(|v| v / s).collect()
}

/// Index `i` (possibly outside `0..n`) mapped into `0..n` by half-sample symmetric reflection
/// (SciPy `mode='reflect'`), repeated as often as needed.
fn reflect(i: isize, n: usize) -> usize {
    let period = 2 * n as isize;
    let m = i.rem_euclid(period) as usize;
    if m < n { m } else { 2 * n - 1 - m }
}

/// The separable filter of the row-major `w × h` plane `m` with `kernel` along columns (x),
/// then rows (y), borders reflected.
fn filter(m: &[f64], w: usize, h: usize, kernel: &[f64]) -> Vec<f64> {
    let r = (kernel.len() / 2) as isize;
    let mut tmp = vec![0.0; w * h];
    for y in 0..h {
        let row = &m[y * w..(y + 1) * w];
        for x in 0..w {
            tmp[y * w + x] = kernel
                .iter()
                .enumerate()
                .map(|(k, g)| g * row[reflect(x as isize + k as isize - r, w)])
                .sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] = kernel
                .iter()
                .enumerate()
                .map(|(k, g)| g * tmp[reflect(y as isize + k as isize - r, h) * w + x])
                .sum();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth, deterministic test image (sums of sinusoids) with values in `[0, 1]`.
    fn smooth(w: usize, h: usize, phase: f32) -> Image {
        Image::from_fn(w, h, |x, y| {
            let (x, y) = (x as f32, y as f32);
            std::array::from_fn(|c| {
                let c = c as f32;
                0.5 + 0.25 * (0.21 * x + 0.7 * c + phase).sin() * (0.17 * y - 0.3 * c).cos()
                    + 0.2 * (0.05 * (x + 2.0 * y) + phase * c).sin()
            })
        })
    }

    #[test]
    fn reflect_is_half_sample_symmetric() {
        let got: Vec<usize> = (-4..8).map(|i| reflect(i, 4)).collect();
        assert_eq!(got, [3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0]);
        assert_eq!(reflect(-9, 4), 0); // several reflections
    }

    #[test]
    fn ssim_is_one_for_identical_images_and_drops_with_noise() {
        let a = smooth(64, 48, 0.0);
        assert!((ssim(&a, &a) - 1.0).abs() < 1e-12);
        let b = smooth(64, 48, 0.3);
        let s = ssim(&a, &b);
        assert!(s < 0.99 && s > -1.0, "{s}");
        assert!((ssim(&b, &a) - s).abs() < 1e-12); // symmetric
        let kernel = gaussian_kernel();
        assert_eq!(kernel.len(), 11);
        assert!((kernel.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }

    /// Compares with scikit-image on two 8-bit PNGs; skips (one line) when Python or skimage is
    /// missing, unless the environment variable `CI` is set (CI installs scikit-image from
    /// `.ci/requirements.txt`).
    #[test]
    fn ssim_matches_scikit_image() {
        let dir = cpose_core::testing::TempDir::new("ssim");
        let (pa, pb) = (dir.join("a.png"), dir.join("b.png"));
        smooth(64, 48, 0.0).save_png(&pa).unwrap();
        // A shifted phase plus a fine deterministic pattern, so the SSIM is well below 1.
        let shifted = smooth(64, 48, 0.4);
        let noisy = Image::from_fn(64, 48, |x, y| {
            let base = shifted.pixel(x, y);
            let n = (((x * 7 + y * 13) % 11) as f32 - 5.0) * 0.02;
            base.map(|v| (v + n).clamp(0.0, 1.0))
        });
        noisy.save_png(&pb).unwrap();
        // Both sides read the same quantised files.
        let (a, b) = (Image::load(&pa).unwrap(), Image::load(&pb).unwrap());
        let ours = ssim(&a, &b);

        let script = "import sys\n\
            from skimage.io import imread\n\
            from skimage.metrics import structural_similarity as ssim\n\
            a = imread(sys.argv[1]).astype('float64') / 255.0\n\
            b = imread(sys.argv[2]).astype('float64') / 255.0\n\
            print(float(ssim(a, b, channel_axis=-1, data_range=1.0, gaussian_weights=True, \
            sigma=1.5, use_sample_covariance=False)))\n";
        let output = std::process::Command::new("python3")
            .arg("-c")
            .arg(script)
            .arg(&pa)
            .arg(&pb)
            .output();
        let in_ci = std::env::var_os("CI").is_some();
        let output = match output {
            Ok(o) if o.status.success() => o,
            other => {
                let why = match other {
                    Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_owned(),
                    Err(e) => format!("cannot run python3: {e}"),
                };
                assert!(
                    !in_ci,
                    "CI is set but the scikit-image reference failed: {why}"
                );
                println!("skipped: python3 with scikit-image not available ({why})");
                return;
            }
        };
        let theirs: f64 = String::from_utf8_lossy(&output.stdout)
            .trim()
            .parse()
            .unwrap();
        let diff = (ours - theirs).abs();
        println!("ssim ours {ours:.12}, skimage {theirs:.12}, |diff| {diff:.3e}");
        assert!(theirs < 0.95, "test images too similar: {theirs}");
        assert!(diff < 1e-6, "ours {ours}, skimage {theirs}");
    }
}
