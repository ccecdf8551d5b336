//! EventNeRF's loss on one ray pair (docs/methods.md §3.3).
//!
//! A pixel of Bayer channel `c` whose events in the window `[τ_s, τ_e)` sum to `E` is rendered
//! at both ends, `Ĉ_s` and `Ĉ_e`; its log-intensity change must equal `θ E`:
//!
//! `ℓ = (L(Ĉ_e[c]) − L(Ĉ_s[c]) − θ E)²`, `L(v) = log(v^γ + ε)`, `γ = 2.2`,
//!
//! and the loss of `R` rays is `Σ ℓ / (3R)`: EventNeRF's mean over rays × 3 channels of the
//! Bayer-masked squared difference, where the two masked-out channels contribute zeros.

/// EventNeRF's gamma: rendered colours are linearised as `v^2.2`.
pub const GAMMA: f32 = 2.2;

/// The log-intensity change model of one ray pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EventLoss {
    /// Contrast threshold `θ` (EventNeRF: 0.25 synthetic, 0.1 real).
    pub threshold: f32,
    /// `ε` of `log(v^γ + ε)` (EventNeRF's `tonemap_eps`: 0.1 synthetic).
    pub eps: f32,
}

impl EventLoss {
    /// `L(v) = log(max(v, 0)^γ + ε)`.
    pub fn log_intensity(&self, v: f32) -> f32 {
        (v.max(0.0).powf(GAMMA) + self.eps).ln()
    }

    /// `dL/dv = γ v^(γ−1) / (v^γ + ε)` (0 for `v ≤ 0`).
    fn log_intensity_grad(&self, v: f32) -> f32 {
        if v <= 0.0 {
            return 0.0;
        }
        GAMMA * v.powf(GAMMA - 1.0) / (v.powf(GAMMA) + self.eps)
    }

    /// The residual `L(end) − L(start) − θ E` of channel `channel` of one ray pair.
    pub fn residual(&self, start: f32, end: f32, polarity_sum: f32) -> f32 {
        self.log_intensity(end) - self.log_intensity(start) - self.threshold * polarity_sum
    }

    /// `ℓ · scale` of one ray pair and its gradients `(∂/∂start, ∂/∂end)` in that channel.
    pub fn value_and_grad(
        &self,
        start: f32,
        end: f32,
        polarity_sum: f32,
        scale: f32,
    ) -> (f32, f32, f32) {
        let r = self.residual(start, end, polarity_sum);
        let g = 2.0 * scale * r;
        (
            scale * r * r,
            -g * self.log_intensity_grad(start),
            g * self.log_intensity_grad(end),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loss() -> EventLoss {
        EventLoss {
            threshold: 0.25,
            eps: 0.1,
        }
    }

    /// The residual in `f64`, for central differences.
    fn residual_f64(start: f64, end: f64, e: f64) -> f64 {
        let l = |v: f64| (v.max(0.0).powf(2.2) + 0.1).ln();
        l(end) - l(start) - 0.25 * e
    }

    #[test]
    fn gradient_matches_central_differences() {
        let h = 1e-5;
        for &(s, e, p) in &[(0.3, 0.7, 2.0), (0.9, 0.2, -3.0), (0.05, 0.5, 0.0)] {
            let (_, gs, ge) = loss().value_and_grad(s as f32, e as f32, p as f32, 0.5);
            let f = |s: f64, e: f64| 0.5 * residual_f64(s, e, p).powi(2);
            let fd_s = (f(s + h, e) - f(s - h, e)) / (2.0 * h);
            let fd_e = (f(s, e + h) - f(s, e - h)) / (2.0 * h);
            assert!(
                (gs as f64 - fd_s).abs() < 1e-4 * (1.0 + fd_s.abs()),
                "{gs} vs {fd_s}"
            );
            assert!(
                (ge as f64 - fd_e).abs() < 1e-4 * (1.0 + fd_e.abs()),
                "{ge} vs {fd_e}"
            );
        }
    }

    /// The loss' log intensity is the simulator's, so simulated events are what it expects.
    #[test]
    fn log_intensity_is_the_simulators() {
        for v in [0.0f32, 0.01, 0.3, 0.99, 1.0] {
            let a = f64::from(loss().log_intensity(v));
            let b = crate::simulate::log_intensity(f64::from(v), 0.1);
            assert!((a - b).abs() < 1e-6, "{v}: {a} vs {b}");
        }
    }

    /// A brightness change of exactly `n` thresholds in log intensity costs nothing; one
    /// threshold more costs `θ²`.
    #[test]
    fn events_of_the_true_change_give_zero_loss() {
        let l = loss();
        let start = 0.3f32;
        let target = l.log_intensity(start) + 2.0 * l.threshold;
        // Invert L: v = (exp(target) − ε)^(1/γ).
        let end = ((target.exp() - l.eps).powf(1.0 / GAMMA)).max(0.0);
        let (value, ..) = l.value_and_grad(start, end, 2.0, 1.0);
        assert!(value < 1e-9, "{value}");
        let (value, ..) = l.value_and_grad(start, end, 3.0, 1.0);
        assert!((value - 0.0625).abs() < 1e-5, "{value}");
    }
}
