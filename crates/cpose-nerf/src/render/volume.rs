//! Stratified depth sampling and BARF's volume compositing with an analytic `O(N)` backward.
//!
//! # Compositing (one ray, `N` samples)
//!
//! Densities `σ_j ≥ 0` (already activated), colours `c_j ∈ R³`, depths `d_j` (increasing) and
//! the ray norm `‖d‖`:
//!
//! * `δ_j = (d_{j+1} − d_j)·‖d‖`, last `δ_{N−1} = 10¹⁰·‖d‖`; `τ_j = σ_j δ_j`;
//! * `α_j = 1 − e^{−τ_j}`, `T_j = exp(−Σ_{k<j} τ_k)` (so `T_{j+1} = T_j e^{−τ_j}`),
//!   `w_j = T_j α_j = T_j − T_{j+1}`;
//! * `C = Σ w_j c_j + (1 − A)·bg` (the last term only with a background colour),
//!   `D = Σ w_j d_j`, `A = Σ w_j`.
//!
//! # Backward
//!
//! `∂w_k/∂τ_j` is `0` for `k < j`, `T_{j+1}` for `k = j` and `−w_k` for `k > j`. With
//! `e_k = ∂L/∂w_k = g_C·(c_k − bg) + g_D d_k + g_A` (`bg = 0` without background):
//!
//! * `∂L/∂σ_j = δ_j (T_{j+1} e_j − Σ_{k>j} w_k e_k)`, the suffix sum being `E − Σ_{k≤j} w_k e_k`
//!   with `E = Σ_k w_k e_k` (a first pass computes `E`, a second the gradients);
//! * `∂L/∂c_j = w_j g_C`.
//!
//! Depths are constants (no gradient). Buffers are flat, `rays × samples` (colours
//! `rays × samples × 3`); nothing allocates.

use cpose_core::Real;
use rand::RngExt;

/// The `δ` of the last sample, in units of `‖d‖` (BARF: `1e10`).
pub const LAST_DELTA: f64 = 1e10;

/// The length of a ray's last sample interval.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LastInterval {
    /// BARF's `10¹⁰·‖d‖`: the last sample closes the ray (its weights sum to 1 unless its
    /// `σ` is 0).
    #[default]
    Closed,
    /// The spacing before it, as NICE-SLAM's rendering, whose weights need not sum to 1: a ray
    /// through empty space stays transparent, so depth supervision has to build the surface
    /// (a closed ray meets a measured depth with no density at all, on its last sample).
    Open,
}

/// The `ε` of BARF's inverse-depth parametrisation, `depth = 1/(s + ε)`.
pub const INVERSE_DEPTH_EPS: f64 = 1e-8;

/// How stratified samples are spread between `near` and `far` (depths along `z = 1` rays).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampling {
    /// Uniform in depth: `d_j = near + (j + u_j)/N·(far − near)` (BARF Blender: `[2, 6]`).
    Metric {
        /// First depth.
        near: f64,
        /// Last depth.
        far: f64,
    },
    /// Uniform in disparity: `s_j = 1/near + (j + u_j)/N·(1/far − 1/near)`,
    /// `d_j = 1/(s_j + 10⁻⁸)`; `far` may be `f64::INFINITY` (`1/far = 0`). BARF's LLFF
    /// (`param: inverse`, range `[1, 0]` in `s`) is `near = 1`, `far = ∞`.
    InverseDepth {
        /// First depth (> 0).
        near: f64,
        /// Last depth (> near, may be infinite).
        far: f64,
    },
}

impl Sampling {
    /// The depth at the normalised position `x ∈ [0, 1]` (`x = (j + u_j)/N`).
    #[inline]
    pub fn depth_at(&self, x: f64) -> f64 {
        match *self {
            Sampling::Metric { near, far } => near + x * (far - near),
            Sampling::InverseDepth { near, far } => {
                let (s_near, s_far) = (1.0 / near, 1.0 / far);
                1.0 / (s_near + x * (s_far - s_near) + INVERSE_DEPTH_EPS)
            }
        }
    }

    /// Deterministic samples (`u_j = ½`, for evaluation), every ray of `out` (`rays × samples`)
    /// the same.
    pub fn midpoint_depths<S: Real>(&self, samples: usize, out: &mut [S]) {
        check_len(out.len(), samples);
        for ray in out.chunks_exact_mut(samples) {
            for (j, d) in ray.iter_mut().enumerate() {
                *d = S::from_f64(self.depth_at((j as f64 + 0.5) / samples as f64));
            }
        }
    }

    /// Stratified samples with `u_j ~ U[0, 1)` drawn independently per ray and sample.
    pub fn jittered_depths<S: Real, R: RngExt + ?Sized>(
        &self,
        rng: &mut R,
        samples: usize,
        out: &mut [S],
    ) {
        check_len(out.len(), samples);
        for ray in out.chunks_exact_mut(samples) {
            for (j, d) in ray.iter_mut().enumerate() {
                let u: f64 = rng.random();
                *d = S::from_f64(self.depth_at((j as f64 + u) / samples as f64));
            }
        }
    }
}

fn check_len(len: usize, samples: usize) {
    assert!(
        samples > 0 && len.is_multiple_of(samples),
        "buffer of length {len} is not rays × {samples} samples"
    );
}

/// Composited outputs of one ray (or their cotangents `∂L/∂C, ∂L/∂D, ∂L/∂A`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Composited<S> {
    /// `C`, RGB.
    pub rgb: [S; 3],
    /// `D = Σ w d`.
    pub depth: S,
    /// `A = Σ w`.
    pub opacity: S,
}

/// `δ_j` of sample `j` (the last as `last` says).
#[inline]
pub(crate) fn delta<S: Real>(depths: &[S], j: usize, ray_norm: S, last: LastInterval) -> S {
    let n = depths.len();
    if j + 1 < n {
        (depths[j + 1] - depths[j]) * ray_norm
    } else {
        match last {
            LastInterval::Closed => S::from_f64(LAST_DELTA) * ray_norm,
            LastInterval::Open if n >= 2 => (depths[n - 1] - depths[n - 2]) * ray_norm,
            LastInterval::Open => S::ZERO,
        }
    }
}

/// Composites one ray (module docs): `sigma`, `depths` of length `N`, `rgb` of `3N`
/// (interleaved `r, g, b`).
pub fn composite_ray<S: Real>(
    sigma: &[S],
    rgb: &[S],
    depths: &[S],
    ray_norm: S,
    background: Option<[S; 3]>,
    last: LastInterval,
) -> Composited<S> {
    let n = sigma.len();
    debug_assert!(depths.len() == n && rgb.len() == 3 * n);
    let mut out = Composited::default();
    let mut trans = S::ONE;
    for j in 0..n {
        let e = Real::exp(-sigma[j] * delta(depths, j, ray_norm, last));
        let w = trans * (S::ONE - e);
        trans *= e;
        for c in 0..3 {
            out.rgb[c] += w * rgb[3 * j + c];
        }
        out.depth += w * depths[j];
        out.opacity += w;
    }
    if let Some(bg) = background {
        for c in 0..3 {
            out.rgb[c] += (S::ONE - out.opacity) * bg[c];
        }
    }
    out
}

/// Backward of [`composite_ray`]: writes (overwrites) `grad_sigma` (`N`) and `grad_rgb` (`3N`)
/// from the output cotangents `grad`, in two `O(N)` passes (module docs).
pub fn composite_ray_backward<S: Real>(
    sigma: &[S],
    rgb: &[S],
    depths: &[S],
    ray_norm: S,
    background: Option<[S; 3]>,
    last: LastInterval,
    grad: &Composited<S>,
    grad_sigma: &mut [S],
    grad_rgb: &mut [S],
) {
    let n = sigma.len();
    debug_assert!(depths.len() == n && rgb.len() == 3 * n);
    debug_assert!(grad_sigma.len() == n && grad_rgb.len() == 3 * n);
    let g = grad.rgb;
    // e_k = g_C·c_k + g_D d_k + (g_A − g_C·bg).
    let offset =
        grad.opacity - background.map_or(S::ZERO, |bg| g[0] * bg[0] + g[1] * bg[1] + g[2] * bg[2]);
    let e_of = |j: usize| {
        g[0] * rgb[3 * j]
            + g[1] * rgb[3 * j + 1]
            + g[2] * rgb[3 * j + 2]
            + grad.depth * depths[j]
            + offset
    };
    // Pass 1: E = Σ w_k e_k.
    let mut total = S::ZERO;
    let mut trans = S::ONE;
    for j in 0..n {
        let e = Real::exp(-sigma[j] * delta(depths, j, ray_norm, last));
        total += trans * (S::ONE - e) * e_of(j);
        trans *= e;
    }
    // Pass 2: gradients with the suffix Σ_{k>j} w_k e_k = E − Σ_{k≤j} w_k e_k.
    let mut prefix = S::ZERO;
    let mut trans = S::ONE;
    for j in 0..n {
        let dj = delta(depths, j, ray_norm, last);
        let ex = Real::exp(-sigma[j] * dj);
        let w = trans * (S::ONE - ex);
        let next = trans * ex;
        let ej = e_of(j);
        prefix += w * ej;
        grad_sigma[j] = dj * (next * ej - (total - prefix));
        for c in 0..3 {
            grad_rgb[3 * j + c] = w * g[c];
        }
        trans = next;
    }
}

/// [`composite_ray`] over `rays = out.len()` rays of `samples` samples each: `sigma`, `depths`
/// are `rays × samples`, `rgb` is `rays × samples × 3`, `ray_norms` is `rays`.
pub fn composite_batch<S: Real>(
    samples: usize,
    sigma: &[S],
    rgb: &[S],
    depths: &[S],
    ray_norms: &[S],
    background: Option<[S; 3]>,
    last: LastInterval,
    out: &mut [Composited<S>],
) {
    check_batch(samples, sigma, rgb, depths, ray_norms, out.len());
    for (r, o) in out.iter_mut().enumerate() {
        let (s, e) = (r * samples, (r + 1) * samples);
        *o = composite_ray(
            &sigma[s..e],
            &rgb[3 * s..3 * e],
            &depths[s..e],
            ray_norms[r],
            background,
            last,
        );
    }
}

/// [`composite_ray_backward`] over a batch laid out as in [`composite_batch`]; `grad` holds the
/// cotangents of the outputs, `grad_sigma` and `grad_rgb` are overwritten.
pub fn composite_batch_backward<S: Real>(
    samples: usize,
    sigma: &[S],
    rgb: &[S],
    depths: &[S],
    ray_norms: &[S],
    background: Option<[S; 3]>,
    last: LastInterval,
    grad: &[Composited<S>],
    grad_sigma: &mut [S],
    grad_rgb: &mut [S],
) {
    check_batch(samples, sigma, rgb, depths, ray_norms, grad.len());
    assert!(grad_sigma.len() == sigma.len() && grad_rgb.len() == rgb.len());
    for (r, g) in grad.iter().enumerate() {
        let (s, e) = (r * samples, (r + 1) * samples);
        composite_ray_backward(
            &sigma[s..e],
            &rgb[3 * s..3 * e],
            &depths[s..e],
            ray_norms[r],
            background,
            last,
            g,
            &mut grad_sigma[s..e],
            &mut grad_rgb[3 * s..3 * e],
        );
    }
}

fn check_batch<S>(
    samples: usize,
    sigma: &[S],
    rgb: &[S],
    depths: &[S],
    ray_norms: &[S],
    rays: usize,
) {
    assert!(
        samples > 0
            && sigma.len() == rays * samples
            && depths.len() == rays * samples
            && rgb.len() == 3 * rays * samples
            && ray_norms.len() == rays,
        "batch buffers do not match {rays} rays × {samples} samples"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// BARF's compositing, where nothing else is under test.
    const LAST: LastInterval = LastInterval::Closed;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    const N: usize = 12;

    /// A ray with mixed densities (the last one opaque enough that its `T_{N}` underflows).
    fn ray(seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>, f64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let sigma: Vec<f64> = (0..N)
            .map(|j| {
                if j == N - 1 {
                    2.0
                } else {
                    3.0 * rng.random::<f64>()
                }
            })
            .collect();
        let rgb: Vec<f64> = (0..3 * N).map(|_| rng.random()).collect();
        let mut depths = vec![0.0; N];
        Sampling::Metric {
            near: 2.0,
            far: 6.0,
        }
        .jittered_depths(&mut rng, N, &mut depths);
        (sigma, rgb, depths, 1.3)
    }

    fn loss(c: &Composited<f64>, g: &Composited<f64>) -> f64 {
        (0..3).map(|k| c.rgb[k] * g.rgb[k]).sum::<f64>() + c.depth * g.depth + c.opacity * g.opacity
    }

    #[test]
    fn backward_matches_central_differences_with_and_without_background() {
        let g = Composited {
            rgb: [0.7, -1.1, 0.4],
            depth: 0.3,
            opacity: -0.8,
        };
        for (seed, bg, last) in [
            (1, None, LAST),
            (2, Some([1.0, 0.5, 0.2]), LAST),
            (3, Some([0.9, 0.9, 0.9]), LAST),
            (1, None, LastInterval::Open),
            (2, Some([1.0, 0.5, 0.2]), LastInterval::Open),
        ] {
            let (sigma, rgb, depths, norm) = ray(seed);
            let mut gs = vec![0.0; N];
            let mut gc = vec![0.0; 3 * N];
            composite_ray_backward(&sigma, &rgb, &depths, norm, bg, last, &g, &mut gs, &mut gc);
            let h = 1e-6;
            for j in 0..N {
                let (mut p, mut m) = (sigma.clone(), sigma.clone());
                p[j] += h;
                m[j] -= h;
                let fd = (loss(&composite_ray(&p, &rgb, &depths, norm, bg, last), &g)
                    - loss(&composite_ray(&m, &rgb, &depths, norm, bg, last), &g))
                    / (2.0 * h);
                assert!(
                    (fd - gs[j]).abs() < 1e-7,
                    "σ_{j} (bg {bg:?}): fd {fd} vs {}",
                    gs[j]
                );
            }
            for i in 0..3 * N {
                let (mut p, mut m) = (rgb.clone(), rgb.clone());
                p[i] += h;
                m[i] -= h;
                let fd = (loss(&composite_ray(&sigma, &p, &depths, norm, bg, last), &g)
                    - loss(&composite_ray(&sigma, &m, &depths, norm, bg, last), &g))
                    / (2.0 * h);
                assert!((fd - gc[i]).abs() < 1e-7, "c_{i}: fd {fd} vs {}", gc[i]);
            }
        }
    }

    #[test]
    fn backward_matches_central_differences_when_the_last_sample_is_transparent() {
        // σ_{N−1} small: T_N = T_{N−1} e^{−σ·10¹⁰‖d‖} is not negligible, the last gradient is huge.
        let (mut sigma, rgb, depths, norm) = ray(4);
        for s in sigma.iter_mut() {
            *s *= 0.01;
        }
        sigma[N - 1] = 1e-12;
        let g = Composited {
            rgb: [0.2, 0.5, -0.3],
            depth: -0.1,
            opacity: 0.6,
        };
        let bg = Some([0.3, 0.6, 0.9]);
        let mut gs = vec![0.0; N];
        let mut gc = vec![0.0; 3 * N];
        composite_ray_backward(&sigma, &rgb, &depths, norm, bg, LAST, &g, &mut gs, &mut gc);
        for j in 0..N {
            let h = if j == N - 1 { 1e-14 } else { 1e-7 };
            let (mut p, mut m) = (sigma.clone(), sigma.clone());
            p[j] += h;
            m[j] -= h;
            let fd = (loss(&composite_ray(&p, &rgb, &depths, norm, bg, LAST), &g)
                - loss(&composite_ray(&m, &rgb, &depths, norm, bg, LAST), &g))
                / (2.0 * h);
            assert!(
                (fd - gs[j]).abs() < 1e-5 * (1.0 + fd.abs()),
                "σ_{j}: fd {fd} vs {}",
                gs[j]
            );
        }
    }

    #[test]
    fn an_open_ray_through_empty_space_stays_transparent() {
        let depths: Vec<f64> = (0..N).map(|j| 2.0 + j as f64 * 0.25).collect();
        let rgb = vec![0.5; 3 * N];
        let mut sigma = vec![1e-3; N];
        let open = composite_ray(&sigma, &rgb, &depths, 1.0, None, LastInterval::Open);
        let closed = composite_ray(&sigma, &rgb, &depths, 1.0, None, LAST);
        assert!(open.opacity < 0.01 && closed.opacity > 0.999);
        // A closed ray "measures" the last sample's depth with no density at all.
        assert!((closed.depth - depths[N - 1]).abs() < 0.01);
        // An opaque wall at sample 3 looks the same either way.
        sigma[3] = 1e3;
        let open = composite_ray(&sigma, &rgb, &depths, 1.0, None, LastInterval::Open);
        let closed = composite_ray(&sigma, &rgb, &depths, 1.0, None, LAST);
        assert!((open.depth - closed.depth).abs() < 1e-9 && (open.depth - depths[3]).abs() < 0.01);
    }

    #[test]
    fn compositing_limits() {
        let depths: Vec<f64> = (0..N).map(|j| 2.0 + j as f64 * 0.25).collect();
        let rgb: Vec<f64> = (0..3 * N).map(|i| (i % 7) as f64 / 7.0).collect();
        // Empty space: nothing but the background.
        let empty = composite_ray(&[0.0; N], &rgb, &depths, 1.0, Some([0.1, 0.2, 0.3]), LAST);
        assert_eq!(empty.opacity, 0.0);
        assert_eq!(empty.rgb, [0.1, 0.2, 0.3]);
        // An opaque sample k hides everything behind it.
        let k = 5;
        let mut sigma = [0.0; N];
        sigma[k] = 1e6;
        let c = composite_ray(&sigma, &rgb, &depths, 1.0, Some([1.0, 1.0, 1.0]), LAST);
        assert!((c.opacity - 1.0).abs() < 1e-12 && (c.depth - depths[k]).abs() < 1e-12);
        for ch in 0..3 {
            assert!((c.rgb[ch] - rgb[3 * k + ch]).abs() < 1e-12);
        }
        // Without background C = Σ w c; weights sum to at most 1; the last sample closes the ray.
        let (sigma, rgb, depths, norm) = ray(5);
        let c = composite_ray(&sigma, &rgb, &depths, norm, None, LAST);
        assert!((c.opacity - 1.0).abs() < 1e-12);
        assert!(c.depth >= depths[0] && c.depth <= depths[N - 1]);
    }

    #[test]
    fn f32_agrees_with_f64() {
        let g = Composited {
            rgb: [0.7, -1.1, 0.4],
            depth: 0.3,
            opacity: -0.8,
        };
        let g32 = Composited {
            rgb: g.rgb.map(|x| x as f32),
            depth: 0.3,
            opacity: -0.8,
        };
        let bg = Some([1.0, 0.5, 0.2]);
        let bg32 = Some([1.0f32, 0.5, 0.2]);
        let (sigma, rgb, depths, norm) = ray(6);
        let to32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let c = composite_ray(&sigma, &rgb, &depths, norm, bg, LAST);
        let c32 = composite_ray(
            &to32(&sigma),
            &to32(&rgb),
            &to32(&depths),
            norm as f32,
            bg32,
            LAST,
        );
        for k in 0..3 {
            assert!((c.rgb[k] - c32.rgb[k] as f64).abs() < 1e-5);
        }
        assert!((c.depth - c32.depth as f64).abs() < 1e-4);
        assert!((c.opacity - c32.opacity as f64).abs() < 1e-5);
        let (mut gs, mut gc) = (vec![0.0; N], vec![0.0; 3 * N]);
        let (mut gs32, mut gc32) = (vec![0.0f32; N], vec![0.0f32; 3 * N]);
        composite_ray_backward(&sigma, &rgb, &depths, norm, bg, LAST, &g, &mut gs, &mut gc);
        let (s32, r32, d32) = (to32(&sigma), to32(&rgb), to32(&depths));
        composite_ray_backward(
            &s32,
            &r32,
            &d32,
            norm as f32,
            bg32,
            LAST,
            &g32,
            &mut gs32,
            &mut gc32,
        );
        for j in 0..N {
            assert!(
                (gs[j] - gs32[j] as f64).abs() < 1e-4 * (1.0 + gs[j].abs()),
                "σ_{j}"
            );
        }
        for i in 0..3 * N {
            assert!((gc[i] - gc32[i] as f64).abs() < 1e-5, "c_{i}");
        }
    }

    #[test]
    fn batch_matches_single_rays() {
        let rays = 3;
        let (mut sigma, mut rgb, mut depths, mut norms) = (vec![], vec![], vec![], vec![]);
        for r in 0..rays {
            let (s, c, d, n) = ray(10 + r as u64);
            sigma.extend(s);
            rgb.extend(c);
            depths.extend(d);
            norms.push(n + r as f64 * 0.1);
        }
        let bg = Some([0.2, 0.4, 0.6]);
        let mut out = vec![Composited::default(); rays];
        composite_batch(N, &sigma, &rgb, &depths, &norms, bg, LAST, &mut out);
        let grads: Vec<Composited<f64>> = (0..rays)
            .map(|r| Composited {
                rgb: [r as f64, 0.5, -0.2],
                depth: 0.1,
                opacity: 0.3 * r as f64,
            })
            .collect();
        let (mut gs, mut gc) = (vec![0.0; rays * N], vec![0.0; 3 * rays * N]);
        composite_batch_backward(
            N, &sigma, &rgb, &depths, &norms, bg, LAST, &grads, &mut gs, &mut gc,
        );
        for r in 0..rays {
            let (s, e) = (r * N, (r + 1) * N);
            let single = composite_ray(
                &sigma[s..e],
                &rgb[3 * s..3 * e],
                &depths[s..e],
                norms[r],
                bg,
                LAST,
            );
            assert_eq!(out[r], single);
            let (mut gs1, mut gc1) = (vec![0.0; N], vec![0.0; 3 * N]);
            composite_ray_backward(
                &sigma[s..e],
                &rgb[3 * s..3 * e],
                &depths[s..e],
                norms[r],
                bg,
                LAST,
                &grads[r],
                &mut gs1,
                &mut gc1,
            );
            assert_eq!(&gs[s..e], &gs1[..]);
            assert_eq!(&gc[3 * s..3 * e], &gc1[..]);
        }
    }

    #[test]
    fn stratified_depths() {
        let n = 4;
        let metric = Sampling::Metric {
            near: 2.0,
            far: 6.0,
        };
        let mut d = vec![0.0f64; 2 * n];
        metric.midpoint_depths(n, &mut d);
        assert_eq!(d, [2.5, 3.5, 4.5, 5.5, 2.5, 3.5, 4.5, 5.5]);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut d = vec![0.0f64; 50 * n];
        metric.jittered_depths(&mut rng, n, &mut d);
        for ray in d.chunks(n) {
            for (j, &x) in ray.iter().enumerate() {
                assert!(x >= 2.0 + j as f64 && x < 3.0 + j as f64);
            }
        }
        assert_ne!(d[0], d[n]); // independent per ray
        // BARF LLFF: s from 1 to 0 in disparity, depth = 1/(s + 1e-8).
        let llff = Sampling::InverseDepth {
            near: 1.0,
            far: f64::INFINITY,
        };
        let mut d = vec![0.0f64; n];
        llff.midpoint_depths(n, &mut d);
        for j in 0..n {
            let s = 1.0 - (j as f64 + 0.5) / n as f64;
            assert_eq!(d[j], 1.0 / (s + 1e-8));
        }
        assert!(d.windows(2).all(|w| w[0] < w[1]));
        assert!((llff.depth_at(0.0) - 1.0).abs() < 1e-7 && llff.depth_at(1.0) == 1e8);
        let inv = Sampling::InverseDepth {
            near: 2.0,
            far: 8.0,
        };
        assert!((inv.depth_at(1.0) - 8.0).abs() < 1e-6 && (inv.depth_at(0.5) - 3.2).abs() < 1e-6);
    }
}
