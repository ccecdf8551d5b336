//! Input encodings: the sinusoidal positional embedding (with BARF's coarse-to-fine weights) and
//! the linear encoding of the paper's ablation.
//!
//! For a `D`-dimensional input `x` the sinusoidal embedding has `D(1 + 2F)` features laid out
//! as `[x_0..x_D, sin(2^0 π x_0)..sin(2^{F−1} π x_0), cos(2^0 π x_0)..cos(2^{F−1} π x_0), …]`:
//! identity first, then per coordinate all sines and all cosines (the authors' PoseNet order for
//! `D = 1`, and BARF's for points). Values and tangents are stored stacked by stream, column-major
//! (`[streams·B × features]`), as the MLP reads them.

use serde::{Deserialize, Serialize};

use super::coarse_to_fine_weights;
use crate::Real;

/// Which encoding a network applies to its input.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// `γ(x) = [x, sin(2^k π x), cos(2^k π x)]` (paper §3.1).
    #[default]
    Sinusoidal,
    /// `γ(x) = x` (the paper's ablation without positional encoding).
    Linear,
}

/// Positional embedding of `dims`-dimensional inputs with `bands` frequency bands
/// `ω_k = 2^k π`, `k = 0..F`, optionally weighted coarse to fine.
#[derive(Clone, Debug, PartialEq)]
pub struct Embedding {
    encoding: Encoding,
    dims: usize,
    bands: usize,
    /// Per-band weight `w_k` (all 1 unless coarse-to-fine is active).
    weights: Vec<f64>,
}

impl Embedding {
    /// An embedding of `dims`-dimensional inputs; `bands` is ignored by [`Encoding::Linear`].
    pub fn new(encoding: Encoding, dims: usize, bands: usize) -> Self {
        let bands = if encoding == Encoding::Linear {
            0
        } else {
            bands
        };
        Self {
            encoding,
            dims,
            bands,
            weights: vec![1.0; bands],
        }
    }

    /// Input dimension `D`.
    pub fn input_dim(&self) -> usize {
        self.dims
    }

    /// Output dimension: `D(1 + 2F)` (sinusoidal) or `D` (linear).
    pub fn output_dim(&self) -> usize {
        self.dims * (1 + 2 * self.bands)
    }

    /// The band weights `w_k`.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// BARF's coarse-to-fine schedule on the bands ([`coarse_to_fine_weights`]): `progress`,
    /// `start`, `end` are fractions of training (0–1); `end ≤ start` switches all bands fully on.
    pub fn set_coarse_to_fine(&mut self, progress: f64, start: f64, end: f64) {
        coarse_to_fine_weights(progress, start, end, &mut self.weights);
    }

    /// Encodes `b` inputs with their tangents. `x` is `[streams·b × D]` column-major: values,
    /// then first and then second derivatives of the inputs (with respect to any scalar
    /// parameter, e.g. time). Writes `[streams·b × output_dim]` column-major into `out`.
    ///
    /// `d/dt sin(ωx) = ω cos(ωx) ẋ`, `d²/dt² sin(ωx) = −ω² sin(ωx) ẋ² + ω cos(ωx) ẍ`, and
    /// `d/dt cos(ωx) = −ω sin(ωx) ẋ`, `d²/dt² cos(ωx) = −ω² cos(ωx) ẋ² − ω sin(ωx) ẍ`.
    pub fn encode<S: Real>(&self, x: &[f64], b: usize, streams: usize, out: &mut [S]) {
        let rows = streams * b;
        let (d_in, f) = (self.dims, self.bands);
        assert!(
            x.len() >= rows * d_in && out.len() >= rows * self.output_dim(),
            "embedding buffers too short"
        );
        for d in 0..d_in {
            let xc = &x[d * rows..(d + 1) * rows];
            for r in 0..rows {
                out[d * rows + r] = S::from_f64(xc[r]);
            }
            for k in 0..f {
                let (w, om) = (self.weights[k], std::f64::consts::PI * (1u64 << k) as f64);
                let sc = (d_in + d * 2 * f + k) * rows;
                let cc = sc + f * rows;
                for i in 0..b {
                    let (s, c) = (om * xc[i]).sin_cos();
                    out[sc + i] = S::from_f64(w * s);
                    out[cc + i] = S::from_f64(w * c);
                    if streams >= 2 {
                        let xd = xc[b + i];
                        out[sc + b + i] = S::from_f64(w * om * c * xd);
                        out[cc + b + i] = S::from_f64(-w * om * s * xd);
                        if streams >= 3 {
                            let (xd2, xdd) = (xd * xd, xc[2 * b + i]);
                            out[sc + 2 * b + i] =
                                S::from_f64(w * (-om * om * s * xd2 + om * c * xdd));
                            out[cc + 2 * b + i] =
                                S::from_f64(w * (-om * om * c * xd2 - om * s * xdd));
                        }
                    }
                }
            }
        }
    }

    /// Gradient with respect to the input values (value stream only, `b` rows): given
    /// `g = ∂L/∂γ` (`[b × output_dim]`, value rows of a stacked buffer with column stride
    /// `stride`), accumulates `∂L/∂x = g_id + Σ_k w_k ω_k (g_sin cos(ω_k x) − g_cos sin(ω_k x))`
    /// into `grad_x` (`[b × D]`, column-major). `x` holds the value rows (`[b × D]`).
    pub fn backward_input<S: Real>(
        &self,
        x: &[f64],
        b: usize,
        g: &[S],
        stride: usize,
        grad_x: &mut [f64],
    ) {
        let (d_in, f) = (self.dims, self.bands);
        for d in 0..d_in {
            for i in 0..b {
                let xi = x[d * b + i];
                let mut acc = g[d * stride + i].to_f64();
                for k in 0..f {
                    let om = std::f64::consts::PI * (1u64 << k) as f64;
                    let sc = (d_in + d * 2 * f + k) * stride;
                    let cc = sc + f * stride;
                    let (s, c) = (om * xi).sin_cos();
                    acc += self.weights[k] * om * (g[sc + i].to_f64() * c - g[cc + i].to_f64() * s);
                }
                grad_x[d * b + i] += acc;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Layout and values for one scalar input with F = 2.
    #[test]
    fn layout_is_identity_sines_cosines() {
        let e = Embedding::new(Encoding::Sinusoidal, 1, 2);
        let mut out = vec![0.0f64; 5];
        e.encode(&[0.25], 1, 1, &mut out);
        let pi = std::f64::consts::PI;
        let want = [
            0.25,
            (pi * 0.25).sin(),
            (2.0 * pi * 0.25).sin(),
            (pi * 0.25).cos(),
            (2.0 * pi * 0.25).cos(),
        ];
        for (a, b) in out.iter().zip(want) {
            assert!((a - b).abs() < 1e-15);
        }
        assert_eq!(Embedding::new(Encoding::Linear, 3, 5).output_dim(), 3);
    }

    /// Tangents of a 2-D input curve x(t) = (sin 1.3t, t²) against central differences
    /// (first: h = 1e-5, error ~h²·|γ'''| ≲ 1e-7 for ω ≤ 8π; second: h = 1e-4, error
    /// ~h²|γ''''| + 1e-16/h² ≲ 1e-4 relative to |γ''| ~ 1e3).
    #[test]
    fn tangents_match_central_differences() {
        let mut e = Embedding::new(Encoding::Sinusoidal, 2, 4);
        e.set_coarse_to_fine(0.5, 0.1, 0.9);
        let curve = |t: f64| [(1.3 * t).sin(), t * t];
        let enc = |t: f64| {
            let mut o = vec![0.0; e.output_dim()];
            let c = curve(t);
            e.encode(&[c[0], c[1]], 1, 1, &mut o);
            o
        };
        let t = 0.37;
        let x = [
            (1.3 * t).sin(),
            1.3 * (1.3 * t).cos(),
            -1.69 * (1.3 * t).sin(),
            t * t,
            2.0 * t,
            2.0,
        ];
        let mut out = vec![0.0; 3 * e.output_dim()];
        e.encode(&x, 1, 3, &mut out);
        let (h1, h2) = (1e-5, 1e-4);
        let (p1, m1, p2, m2, c) = (enc(t + h1), enc(t - h1), enc(t + h2), enc(t - h2), enc(t));
        for j in 0..e.output_dim() {
            let fd1 = (p1[j] - m1[j]) / (2.0 * h1);
            let fd2 = (p2[j] - 2.0 * c[j] + m2[j]) / (h2 * h2);
            assert!(
                (fd1 - out[3 * j + 1]).abs() < 1e-6 * (1.0 + fd1.abs()),
                "d1 feature {j}"
            );
            assert!(
                (fd2 - out[3 * j + 2]).abs() < 1e-4 * (1.0 + fd2.abs()),
                "d2 feature {j}"
            );
        }
        // Input gradient of a linear functional of the values.
        let g: Vec<f64> = (0..e.output_dim())
            .map(|j| (j as f64 * 0.7).sin())
            .collect();
        let mut gx = [0.0; 2];
        e.backward_input(&[x[0], x[3]], 1, &g, 1, &mut gx);
        for d in 0..2 {
            let f = |dx: f64| {
                let mut v = [x[0], x[3]];
                v[d] += dx;
                let mut o = vec![0.0; e.output_dim()];
                e.encode(&v, 1, 1, &mut o);
                o.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
            };
            let fd = (f(1e-6) - f(-1e-6)) / 2e-6;
            assert!(
                (fd - gx[d]).abs() < 1e-7,
                "input grad {d}: {fd} vs {}",
                gx[d]
            );
        }
    }
}
