//! A small neural-network kit with exact input derivatives: activations, an MLP with tangent
//! streams and a hand-written reverse pass (matrix products through faer), input encodings,
//! BARF's coarse-to-fine weights, seeded initialisation, Adam and a stopping rule for fits.
//!
//! Scalars are generic over [`Real`](crate::Real): `f32` for training, `f64` for gradient checks.
//! Buffers live in workspaces that grow with the batch and are reused, so a training loop does
//! not allocate in its steady state.

mod activation;
mod adam;
mod coarse_to_fine;
mod convergence;
mod embedding;
mod mlp;

pub use activation::Activation;
pub use adam::{Adam, ExponentialDecay};
pub use coarse_to_fine::coarse_to_fine_weights;
pub use convergence::{Convergence, StopReason, StopRule};
pub use embedding::{Embedding, Encoding};
pub use faer::Accum;
pub use mlp::{Init, Mlp, MlpSpec, MlpWorkspace};

/// Rows (samples × streams) per part below which splitting a batch across threads does not pay.
///
/// Each part runs single-threaded matrix products (`Par::Seq`) and the parts' weight gradients
/// are summed (docs/methods.md §5.1). On a busy machine (other processes on both
/// cores) a split loses even at large batches, so small batches stay on one thread.
pub const MIN_ROWS_PER_PART: usize = 128;

/// How many parts to split a batch of `rows` stacked rows into: at most
/// `rayon::current_num_threads()`, each with at least [`MIN_ROWS_PER_PART`] rows.
pub fn batch_parts(rows: usize) -> usize {
    (rows / MIN_ROWS_PER_PART).clamp(1, rayon::current_num_threads().max(1))
}

/// The sample range of part `p` of `parts` over `n` samples (contiguous, sizes differ by ≤ 1).
pub fn part_range(n: usize, parts: usize, p: usize) -> std::ops::Range<usize> {
    (p * n / parts)..((p + 1) * n / parts)
}

/// The sign of `x`, `0` at `0`: the subgradient of `|x|` that L1 losses use (`f64::signum`
/// gives 1 at 0).
pub fn l1_subgradient(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}
