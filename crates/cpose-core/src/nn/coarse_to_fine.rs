//! BARF's coarse-to-fine weights (docs/methods.md §2.1, the same in 2-D and 3-D): the one
//! implementation behind the sinusoidal embedding's bands
//! ([`Embedding::set_coarse_to_fine`](super::Embedding::set_coarse_to_fine)) and the grid
//! fields' levels in `cpose-nerf`.

/// BARF's coarse-to-fine weights of `F = weights.len()` bands (or levels) at `progress`: with
/// `α = (progress − start)/(end − start) · F`, band `k` gets
/// `w_k = (1 − cos(π · clamp(α − k, 0, 1)))/2`. `progress`, `start` and `end` are fractions of
/// training (0–1); `end ≤ start` (an empty window, e.g. `[0, 0]`) switches every band fully on.
///
/// # Example
/// ```
/// let mut w = [0.0; 4];
/// cpose_core::nn::coarse_to_fine_weights(0.35, 0.1, 0.5, &mut w); // α = 2.5
/// assert_eq!(w[..2], [1.0, 1.0]);
/// assert!((w[2] - 0.5).abs() < 1e-12 && w[3] == 0.0);
/// ```
pub fn coarse_to_fine_weights(progress: f64, start: f64, end: f64, weights: &mut [f64]) {
    if end <= start {
        weights.fill(1.0);
        return;
    }
    let alpha = (progress - start) / (end - start) * weights.len() as f64;
    for (k, w) in weights.iter_mut().enumerate() {
        let a = (alpha - k as f64).clamp(0.0, 1.0);
        *w = (1.0 - (std::f64::consts::PI * a).cos()) / 2.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Off before `start`, bands opening one by one as `α` passes them (half open at `α = k + ½`),
    /// all on from `end` and for an empty window.
    #[test]
    fn bands_open_one_by_one_over_the_window() {
        let mut w = [0.5; 4];
        coarse_to_fine_weights(0.0, 0.1, 0.5, &mut w);
        assert!(w.iter().all(|&w| w == 0.0));
        coarse_to_fine_weights(0.3, 0.1, 0.5, &mut w); // α = 2
        assert_eq!(w, [1.0, 1.0, 0.0, 0.0]);
        coarse_to_fine_weights(0.35, 0.1, 0.5, &mut w); // α = 2.5
        assert_eq!(w[..2], [1.0, 1.0]);
        assert!((w[2] - 0.5).abs() < 1e-12 && w[3] == 0.0);
        coarse_to_fine_weights(1.0, 0.1, 0.5, &mut w);
        assert!(w.iter().all(|&w| w == 1.0));
        let mut w = [0.5; 4];
        coarse_to_fine_weights(0.0, 0.0, 0.0, &mut w);
        assert!(w.iter().all(|&w| w == 1.0));
    }
}
