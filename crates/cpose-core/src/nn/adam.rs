//! Adam (Kingma & Ba) exactly as PyTorch's `torch.optim.Adam` (no weight decay, no amsgrad), and
//! the exponential learning-rate decay of the paper's code (docs/methods.md §1.2).

use rayon::prelude::*;

use crate::{ParamKind, PoseField, Real};

/// Parameters per task when a large group's update is split over threads.
const PARALLEL_CHUNK: usize = 1 << 15;

/// Adam state over one flat parameter vector; parameter groups are ranges of it with their own
/// learning rates.
///
/// Step `t` (1-based): `m ← β1 m + (1 − β1) g`, `v ← β2 v + (1 − β2) g²`,
/// `p ← p − lr · m̂ / (sqrt(v̂) + ε)` with `m̂ = m/(1 − β1^t)`, `v̂ = v/(1 − β2^t)`.
#[derive(Clone, Debug)]
pub struct Adam<S: Real> {
    /// First-moment decay β1 (0.9).
    pub beta1: f64,
    /// Second-moment decay β2 (0.999).
    pub beta2: f64,
    /// ε added to `sqrt(v̂)` (1e-8).
    pub eps: f64,
    m: Vec<S>,
    v: Vec<S>,
    t: u64,
}

impl<S: Real> Adam<S> {
    /// Zero state for `n` parameters with PyTorch's defaults.
    pub fn new(n: usize) -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            m: vec![S::ZERO; n],
            v: vec![S::ZERO; n],
            t: 0,
        }
    }

    /// Back to the zero state (a new optimiser over the same parameters, without allocating).
    pub fn reset(&mut self) {
        self.m.fill(S::ZERO);
        self.v.fill(S::ZERO);
        self.t = 0;
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.t
    }

    /// The state `(m, v, t)`, for checkpoints.
    pub fn state(&self) -> (&[S], &[S], u64) {
        (&self.m, &self.v, self.t)
    }

    /// Restores a [`Adam::state`] of the same length; `false` (and no change) otherwise.
    pub fn set_state(&mut self, m: &[S], v: &[S], t: u64) -> bool {
        if m.len() != self.m.len() || v.len() != self.v.len() {
            return false;
        }
        self.m.copy_from_slice(m);
        self.v.copy_from_slice(v);
        self.t = t;
        true
    }

    /// Starts step `t + 1`; follow with [`Adam::update`] on every parameter group.
    pub fn begin_step(&mut self) {
        self.t += 1;
    }

    /// Updates the group `params` stored at `offset` of the flat state, with its gradient and
    /// learning rate (one fused loop; PyTorch's form `p −= (lr/bc1) m / (sqrt(v)/sqrt(bc2) + ε)`).
    pub fn update(&mut self, offset: usize, params: &mut [S], grads: &[S], lr: f64) {
        let n = params.len();
        assert!(
            grads.len() == n && offset + n <= self.m.len(),
            "Adam group out of range"
        );
        let t = self.t.max(1) as i32;
        let bc1 = 1.0 - self.beta1.powi(t);
        let bc2 = 1.0 - self.beta2.powi(t);
        let step = S::from_f64(lr / bc1);
        let inv_sqrt_bc2 = S::from_f64(1.0 / bc2.sqrt());
        let (b1, b2, eps) = (
            S::from_f64(self.beta1),
            S::from_f64(self.beta2),
            S::from_f64(self.eps),
        );
        let (c1, c2) = (S::ONE - b1, S::ONE - b2);
        let m = &mut self.m[offset..offset + n];
        let v = &mut self.v[offset..offset + n];
        let update = |params: &mut [S], grads: &[S], m: &mut [S], v: &mut [S]| {
            for (((p, &g), m), v) in params.iter_mut().zip(grads).zip(m).zip(v) {
                *m = b1 * *m + c1 * g;
                *v = b2 * *v + c2 * g * g;
                *p -= step * *m / (v.sqrt() * inv_sqrt_bc2 + eps);
            }
        };
        // Element by element, so a large group is split over the threads with the same result.
        if n < PARALLEL_CHUNK * 2 {
            update(params, grads, m, v);
        } else {
            params
                .par_chunks_mut(PARALLEL_CHUNK)
                .zip(grads.par_chunks(PARALLEL_CHUNK))
                .zip(m.par_chunks_mut(PARALLEL_CHUNK))
                .zip(v.par_chunks_mut(PARALLEL_CHUNK))
                .for_each(|(((p, g), m), v)| update(p, g, m, v));
        }
    }

    /// One step on a single group.
    pub fn step(&mut self, params: &mut [S], grads: &[S], lr: f64) {
        self.begin_step();
        self.update(0, params, grads, lr);
    }

    /// One step on all parameter slices of `field` (visit order of [`PoseField::params_mut`],
    /// `grad` in the same flat layout), with the learning rate `lr(kind)` per slice.
    pub fn step_pose_field(
        &mut self,
        field: &mut dyn PoseField<S>,
        grad: &[S],
        lr: impl Fn(ParamKind) -> f64,
    ) {
        assert!(grad.len() == field.num_params(), "gradient length");
        self.begin_step();
        let mut offset = 0;
        field.params_mut(&mut |kind, p| {
            let n = p.len();
            self.update(offset, p, &grad[offset..offset + n], lr(kind));
            offset += n;
        });
    }
}

/// `lr(it) = lr0 · (lr_end/lr0)^(it/max_iter)`: PyTorch's `ExponentialLR` with
/// `γ = (lr_end/lr0)^(1/max_iter)` (the paper's code: `γ = 0.01^(1/max_iter)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExponentialDecay {
    /// Learning rate at iteration 0.
    pub lr0: f64,
    /// Learning rate at `max_iter`.
    pub lr_end: f64,
    /// Iterations over which the rate falls from `lr0` to `lr_end`.
    pub max_iter: u64,
}

impl ExponentialDecay {
    /// Checks a config's `[start, end]` rates: `start` finite and above 0, `end` finite and
    /// at least 0. The message names `key`.
    pub fn check_rates(key: &str, [start, end]: [f64; 2]) -> Result<(), String> {
        if start.is_finite() && start > 0.0 && end.is_finite() && end >= 0.0 {
            Ok(())
        } else {
            Err(format!(
                "{key} = [{start}, {end}]: expected a start rate above 0 and an end rate of at \
                 least 0, both finite"
            ))
        }
    }

    /// [`ExponentialDecay::check_rates`] of every named pair, then of every `lr_field.<group>`
    /// pair of `field_groups`; the message says `[train]`.
    pub fn check_train_rates<'a>(
        named: &[(&str, [f64; 2])],
        field_groups: impl IntoIterator<Item = (&'a String, &'a [f64; 2])>,
    ) -> Result<(), String> {
        let groups = field_groups
            .into_iter()
            .map(|(k, v)| (format!("lr_field.{k}"), *v));
        for (key, value) in named
            .iter()
            .map(|(k, v)| ((*k).to_owned(), *v))
            .chain(groups)
        {
            Self::check_rates(&key, value).map_err(|e| format!("[train] {e}"))?;
        }
        Ok(())
    }

    /// The learning rate at iteration `it`.
    pub fn lr(&self, it: u64) -> f64 {
        self.lr0 * (self.lr_end / self.lr0).powf(it as f64 / self.max_iter.max(1) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two steps by hand (lr = 0.1, p0 = 1, g1 = 0.5, g2 = −1):
    /// t=1: m = 0.05, v = 0.00025, m̂ = 0.5, v̂ = 0.25, p = 1 − 0.1·0.5/(0.5 + 1e-8) = 0.900000002;
    /// t=2: m = 0.045 − 0.1 = −0.055, v = 0.00024975 + 0.001 = 0.00124975,
    ///      m̂ = −0.055/0.19 = −0.28947368, v̂ = 0.00124975/0.001999 = 0.62518759,
    ///      sqrt(v̂) = 0.79068805, p = 0.900000002 + 0.1·0.28947368/0.79068805 = 0.93661035.
    #[test]
    fn two_steps_match_hand_computation() {
        let mut adam = Adam::<f64>::new(1);
        let mut p = [1.0];
        adam.step(&mut p, &[0.5], 0.1);
        assert!((p[0] - 0.900000002).abs() < 1e-12);
        adam.step(&mut p, &[-1.0], 0.1);
        assert!((p[0] - 0.93661035).abs() < 1e-8, "{}", p[0]);
        // After a reset the first step is the first step of a new optimiser again.
        adam.reset();
        let mut q = [1.0];
        adam.step(&mut q, &[0.5], 0.1);
        assert!((q[0] - 0.900000002).abs() < 1e-12 && adam.steps() == 1);
    }

    /// A group large enough to be split over threads (2.5 chunks, the last one short, at an
    /// offset) steps every element as a group of one does.
    #[test]
    fn a_split_group_steps_like_single_elements() {
        let n = PARALLEL_CHUNK * 5 / 2 + 7;
        let grads: Vec<f32> = (0..n)
            .map(|i| ((i * 37 % 101) as f32 - 50.0) * 0.01)
            .collect();
        let mut big = Adam::<f32>::new(n + 3);
        let mut params: Vec<f32> = (0..n).map(|i| (i % 13) as f32 * 0.1).collect();
        let start = params.clone();
        for _ in 0..2 {
            big.begin_step();
            big.update(3, &mut params, &grads, 0.01);
        }
        for i in (0..n)
            .step_by(997)
            .chain([PARALLEL_CHUNK - 1, PARALLEL_CHUNK, n - 1])
        {
            let mut one = Adam::<f32>::new(1);
            let mut p = [start[i]];
            for _ in 0..2 {
                one.step(&mut p, &grads[i..=i], 0.01);
            }
            assert_eq!(p[0], params[i], "element {i}");
        }
        assert_ne!(params, start);
    }

    #[test]
    fn exponential_decay_hits_both_ends() {
        let s = ExponentialDecay {
            lr0: 1e-3,
            lr_end: 1e-5,
            max_iter: 200,
        };
        assert!((s.lr(0) - 1e-3).abs() < 1e-18);
        assert!((s.lr(100) - 1e-4).abs() < 1e-15);
        assert!((s.lr(200) - 1e-5).abs() < 1e-17);
    }
}
