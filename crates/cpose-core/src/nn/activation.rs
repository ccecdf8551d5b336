//! Element-wise activations with the derivatives the tangent streams need.
//!
//! A hidden layer computes `h = σ(z)` together with the first and second time derivatives
//! `ḣ = σ'(z) ż`, `ḧ = σ'(z) z̈ + σ''(z) ż²`; the reverse pass through these three streams needs
//! `σ'`, `σ''` and `σ'''` (docs/methods.md §5.2).
//! `σ''` and `σ'''` are written as functions of `h = σ(z)` and `s1 = σ'(z)`, so the forward pass
//! stores only `h` and `s1`.

use serde::{Deserialize, Serialize};

use crate::Real;

/// An element-wise activation function.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// `max(z, 0)`; piecewise linear, so `σ'' = σ''' = 0` (no second-derivative signal).
    #[default]
    Relu,
    /// `ln(1 + e^z)` (β = 1), smooth; the authors' choice when derivatives are supervised.
    Softplus,
    /// `tanh(z)`.
    Tanh,
    /// `1 / (1 + e^−z)`.
    Sigmoid,
}

impl Activation {
    /// `(σ(z), σ'(z))`, numerically stable for any finite `z`.
    #[inline(always)]
    pub fn value_and_slope<S: Real>(self, z: S) -> (S, S) {
        match self {
            Activation::Relu => {
                if z > S::ZERO {
                    (z, S::ONE)
                } else {
                    (S::ZERO, S::ZERO)
                }
            }
            Activation::Softplus => {
                // softplus(z) = max(z, 0) + ln(1 + e^−|z|); σ' = sigmoid(z).
                let e = (-z.abs()).exp();
                let inv = S::ONE / (S::ONE + e);
                let sig = if z >= S::ZERO { inv } else { e * inv };
                (z.max(S::ZERO) + (S::ONE + e).ln(), sig)
            }
            Activation::Tanh => {
                let h = z.tanh();
                (h, S::ONE - h * h)
            }
            Activation::Sigmoid => {
                let e = (-z.abs()).exp();
                let inv = S::ONE / (S::ONE + e);
                let h = if z >= S::ZERO { inv } else { e * inv };
                (h, h * (S::ONE - h))
            }
        }
    }

    /// `(σ''(z), σ'''(z))` from `h = σ(z)` and `s1 = σ'(z)`:
    /// - softplus: `σ'' = s1(1 − s1)`, `σ''' = σ''(1 − 2 s1)` (s1 is the logistic sigmoid);
    /// - tanh: `σ'' = −2 h s1`, `σ''' = −2 s1² + 4 h² s1`;
    /// - sigmoid: `σ'' = s1(1 − 2h)`, `σ''' = s1(1 − 6h + 6h²)`;
    /// - relu: both zero.
    #[inline(always)]
    pub fn curvature<S: Real>(self, h: S, s1: S) -> (S, S) {
        let two = S::from_f64(2.0);
        match self {
            Activation::Relu => (S::ZERO, S::ZERO),
            Activation::Softplus => {
                let s2 = s1 * (S::ONE - s1);
                (s2, s2 * (S::ONE - two * s1))
            }
            Activation::Tanh => (
                -two * h * s1,
                -two * s1 * s1 + S::from_f64(4.0) * h * h * s1,
            ),
            Activation::Sigmoid => {
                let six = S::from_f64(6.0);
                (
                    s1 * (S::ONE - two * h),
                    s1 * (S::ONE - six * h + six * h * h),
                )
            }
        }
    }

    /// Whether `σ''` vanishes identically (then the second-derivative stream carries no
    /// curvature term).
    pub fn is_piecewise_linear(self) -> bool {
        self == Activation::Relu
    }

    /// Tangent forward of one scalar: `[z, ż, z̈] ↦ [h, ḣ, ḧ]` for the first `streams` entries.
    #[inline]
    pub fn tangent_forward<S: Real>(self, z: [S; 3], streams: usize) -> [S; 3] {
        let (h, s1) = self.value_and_slope(z[0]);
        let mut out = [h, S::ZERO, S::ZERO];
        if streams >= 2 {
            out[1] = s1 * z[1];
        }
        if streams >= 3 {
            let (s2, _) = self.curvature(h, s1);
            out[2] = s1 * z[2] + s2 * z[1] * z[1];
        }
        out
    }

    /// Reverse of [`Activation::tangent_forward`]: given `z` streams and the cotangents
    /// `[gh, gḣ, gḧ]`, returns `[gz, gż, gz̈]` (docs/methods.md §5.2):
    /// `gz = gh σ' + gḣ σ'' ż + gḧ (σ''' ż² + σ'' z̈)`, `gż = gḣ σ' + 2 gḧ σ'' ż`, `gz̈ = gḧ σ'`.
    #[inline]
    pub fn tangent_backward<S: Real>(self, z: [S; 3], g: [S; 3], streams: usize) -> [S; 3] {
        let (h, s1) = self.value_and_slope(z[0]);
        let (s2, s3) = self.curvature(h, s1);
        tangent_adjoint(s1, s2, s3, [z[1], z[2]], g, streams)
    }
}

/// The adjoint of one scalar through the tangent streams (shared by the MLP kernels and heads).
#[inline(always)]
pub(crate) fn tangent_adjoint<S: Real>(
    s1: S,
    s2: S,
    s3: S,
    zt: [S; 2],
    g: [S; 3],
    streams: usize,
) -> [S; 3] {
    match streams {
        1 => [g[0] * s1, S::ZERO, S::ZERO],
        2 => [g[0] * s1 + g[1] * s2 * zt[0], g[1] * s1, S::ZERO],
        _ => {
            let (zd, zdd) = (zt[0], zt[1]);
            [
                g[0] * s1 + g[1] * s2 * zd + g[2] * (s3 * zd * zd + s2 * zdd),
                g[1] * s1 + S::from_f64(2.0) * g[2] * s2 * zd,
                g[2] * s1,
            ]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [Activation; 4] = [
        Activation::Relu,
        Activation::Softplus,
        Activation::Tanh,
        Activation::Sigmoid,
    ];

    /// σ', σ'', σ''' against central differences of σ, σ', σ'' (h = 1e-5: truncation error
    /// ~h²·σ⁽⁴⁾ ≈ 1e-10, rounding ~1e-16/h ≈ 1e-11; tolerance 1e-8).
    #[test]
    fn derivatives_match_central_differences() {
        let h = 1e-5;
        for act in ALL {
            for &z in &[-30.0, -3.1, -0.7, 0.3, 1.2, 4.5, 30.0] {
                let s = |z: f64| act.value_and_slope(z);
                let c = |z: f64| {
                    let (v, s1) = act.value_and_slope(z);
                    act.curvature(v, s1)
                };
                let (_, s1) = s(z);
                let (s2, s3) = c(z);
                let fd1 = (s(z + h).0 - s(z - h).0) / (2.0 * h);
                let fd2 = (s(z + h).1 - s(z - h).1) / (2.0 * h);
                let fd3 = (c(z + h).0 - c(z - h).0) / (2.0 * h);
                assert!((fd1 - s1).abs() < 1e-8, "{act:?} σ' at {z}: {fd1} vs {s1}");
                assert!((fd2 - s2).abs() < 1e-8, "{act:?} σ'' at {z}: {fd2} vs {s2}");
                assert!(
                    (fd3 - s3).abs() < 1e-8,
                    "{act:?} σ''' at {z}: {fd3} vs {s3}"
                );
            }
        }
    }

    #[test]
    fn softplus_is_stable_and_accurate() {
        let (v, s) = Activation::Softplus.value_and_slope(800.0_f64);
        assert_eq!((v, s), (800.0, 1.0));
        let (v, s) = Activation::Softplus.value_and_slope(-800.0_f64);
        assert_eq!((v, s), (0.0, 0.0));
        let (v, _) = Activation::Softplus.value_and_slope(0.0_f64);
        assert!((v - 2f64.ln()).abs() < 1e-15);
        let (v, s) = Activation::Softplus.value_and_slope(100.0_f32);
        assert!(v.is_finite() && s == 1.0);
    }

    /// The scalar tangent reverse pass against central differences of a linear loss on the
    /// forward streams with respect to z, ż, z̈.
    #[test]
    fn tangent_backward_matches_central_differences() {
        let g = [0.7, -1.3, 0.4];
        let loss = |act: Activation, z: [f64; 3]| {
            let h = act.tangent_forward(z, 3);
            g[0] * h[0] + g[1] * h[1] + g[2] * h[2]
        };
        for act in [Activation::Softplus, Activation::Tanh, Activation::Sigmoid] {
            let z = [0.4, -0.8, 1.7];
            let an = act.tangent_backward(z, g, 3);
            for k in 0..3 {
                let (mut zp, mut zm) = (z, z);
                zp[k] += 1e-6;
                zm[k] -= 1e-6;
                let fd = (loss(act, zp) - loss(act, zm)) / 2e-6;
                assert!(
                    (fd - an[k]).abs() < 1e-8,
                    "{act:?} stream {k}: {fd} vs {}",
                    an[k]
                );
            }
        }
    }
}
