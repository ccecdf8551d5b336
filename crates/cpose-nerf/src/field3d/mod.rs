//! 3-D radiance fields for NeRF (BARF §4.2; docs/methods.md §2.2).
//!
//! A field maps a world point `x ∈ R³` to a density `σ ≥ 0` (per world unit of length, the unit
//! of the renderer's `δ`, see [`crate::render::volume`]) and a colour `rgb ∈ (0, 1)³`, and
//! differentiates both with respect to its parameters *and* to the point, which is what the
//! camera poses need.
//!
//! - [`HashGridField`] (the fast default): instant-NGP's multiresolution hash encoding
//!   (Müller et al. 2022) and a tiny MLP.
//! - [`NerfMlpField`] (fidelity): BARF's NeRF MLP on the positional encoding, with
//!   coarse-to-fine weighted bands.
//!
//! Both are built from a config (`init` validates it; [`RadianceFieldConfig`] chooses one in
//! TOML) and used through the object-safe [`RadianceField`] trait.
//!
//! # Where the scene is
//!
//! [`SceneBounds`] places the scene: a point is normalised as `y = (x − c)/r` (centre `c`,
//! radius `r`). A bounded scene uses `p = y`; the grid spans `[−1, 1]³` and points outside read
//! the grid at the nearest border point (clamped per axis, zero derivative along a clamped
//! axis), while the MLP encodes `p` as it is. An unbounded scene (forward-facing LLFF captures sampled to infinite depth) uses
//! mip-NeRF 360's contraction (Barron et al. 2022, eq. 10), [`contract`]:
//!
//! `p = contract(y) = y` if `‖y‖ ≤ 1`, else `(2 − 1/‖y‖) · y/‖y‖`,
//!
//! which maps `R³` into the ball of radius 2 (the grid spans `[−2, 2]³`). With `ρ = ‖y‖`,
//! `u = y/ρ`, its Jacobian outside the unit ball is symmetric,
//!
//! `∂p/∂y = (2ρ − 1)/ρ² · (I − u uᵀ) + 1/ρ² · u uᵀ`
//!
//! (tangential scale `(2 − 1/ρ)/ρ`, radial `d(2 − 1/ρ)/dρ = 1/ρ²`), equal to `I` on the unit
//! sphere, so the map is C¹. The reverse pass is `∂L/∂x = (∂p/∂y)ᵀ ∂L/∂p / r`
//! ([`contract_backward`]). Both fields apply the same map; the network never sees raw world
//! coordinates.
//!
//! # No view dependence
//!
//! The colour depends on the point only, not on the viewing direction. This halves the head's
//! input, keeps the pose gradient flowing through the sample points alone, and is exact for
//! the Lambertian synthetic scenes we generate; specular highlights are baked into the colour.
//! BARF's view-dependent head (`L_view = 4`) is therefore left out; a direction argument can be
//! added to the trait when a task needs it.
//!
//! # Threading and buffers
//!
//! A field is `Send`, not `Sync`: `forward` keeps what `backward` needs. Batches of at least
//! [`PARALLEL_MIN_POINTS`] points are split into [`cpose_core::nn::batch_parts`] contiguous
//! parts processed on rayon's pool, each with its own buffers; partial parameter gradients are
//! added in part order, so results are deterministic for a given thread count. Within a part
//! the networks run on chunks of 1024 rows, whose activations stay in cache from one layer to
//! the next. Buffers grow with the batch and are kept, so a training loop does not allocate in
//! its steady state.
//!
//! Not for: sampling or compositing along rays ([`crate::render::volume`]), cameras ([`crate::camera`]).

mod grid;
mod mlp;
mod optimizer;

use std::ops::Range;

use cpose_core::Real;
use cpose_core::nn::{Accum, Activation};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::field_common::{Invalid, grow, invalid};

pub use grid::{GRID_DENSITY_BIAS, HashGridConfig, HashGridField, Interpolation};
pub use mlp::{NerfMlpConfig, NerfMlpField};
pub use optimizer::FieldOptimizer;

/// A 3-D radiance field: world point → density `σ ≥ 0` and colour `rgb ∈ (0, 1)³`.
pub trait RadianceField<S: Real = f32>: Send {
    /// Number of trainable parameters.
    fn num_params(&self) -> usize;
    /// All trainable parameters, one flat vector (layout documented by each field).
    fn params(&self) -> &[S];
    /// Mutable access to the parameters (for the optimiser).
    fn params_mut(&mut self) -> &mut [S];
    /// Named parameter groups for per-group learning rates, covering `0..num_params` exactly
    /// and in order, e.g. `[("grid", 0..g), ("mlp", g..n)]` or `[("mlp", 0..n)]`.
    fn param_groups(&self) -> Vec<(&'static str, Range<usize>)>;
    /// Coarse-to-fine: `progress` = fraction of training done (0–1).
    fn set_progress(&mut self, progress: f64);
    /// The parameters a restart of the field keeps (`nerf::train::Schedule::field_restart_every`):
    /// its coarsest part, which coarse-to-fine never turns off. The hash grid keeps its first
    /// level; by default nothing is kept.
    fn kept_on_restart(&self) -> Range<usize> {
        0..0
    }
    /// Densities and colours at `points` (`n × 3` interleaved x, y, z, world coordinates) into
    /// `sigma` (`n`) and `rgb` (`n × 3` interleaved). Keeps what `backward` needs; allocates only
    /// when n grows.
    fn forward(&mut self, points: &[S], sigma: &mut [S], rgb: &mut [S]);
    /// Reverse pass of the last `forward`: ADDS ∂L/∂θ into `grad` (len `num_params`) and WRITES
    /// ∂L/∂points into `grad_points` (`n × 3`), given ∂L/∂σ (`n`) and ∂L/∂rgb (`n × 3`).
    fn backward(&mut self, grad_sigma: &[S], grad_rgb: &[S], grad: &mut [S], grad_points: &mut [S]);
    /// [`RadianceField::backward`] with the parameters held fixed: WRITES only ∂L/∂points (a
    /// camera tracked against a trained field). The default runs the full pass into a scratch
    /// gradient; a field overrides it to skip the parameter gradient's work.
    fn backward_points(&mut self, grad_sigma: &[S], grad_rgb: &[S], grad_points: &mut [S]) {
        let mut scratch = vec![S::ZERO; self.num_params()];
        self.backward(grad_sigma, grad_rgb, &mut scratch, grad_points);
    }
}

/// Invalid construction parameters of a 3-D field or its scene bounds.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Field3dError {
    /// A configuration value is out of its valid range.
    #[error("invalid {key}: expected {expected}, got {got}")]
    Invalid {
        /// The config key (as spelled in TOML).
        key: &'static str,
        /// What the key accepts.
        expected: String,
        /// The value given.
        got: String,
    },
}

impl From<Invalid> for Field3dError {
    fn from(e: Invalid) -> Self {
        Field3dError::Invalid {
            key: e.key,
            expected: e.expected,
            got: e.got,
        }
    }
}

/// Where the scene lies in world coordinates and whether it extends to infinity (see the
/// module docs for the map to field coordinates).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneBounds {
    /// Centre `c` of the region of interest, world coordinates.
    pub centre: [f64; 3],
    /// Radius `r > 0` in world units: the ball `‖x − c‖ ≤ r` maps onto the unit ball.
    pub radius: f64,
    /// `true`: points beyond the radius are contracted into the ball of radius 2 (forward-facing
    /// scenes sampled to infinite depth); `false`: the grid covers the cube `[−1, 1]³` of
    /// normalised coordinates and points outside read its clamped border values.
    pub unbounded: bool,
}

impl SceneBounds {
    /// The unit cube around the origin: centre 0, radius 1, bounded.
    pub const UNIT: SceneBounds = SceneBounds {
        centre: [0.0; 3],
        radius: 1.0,
        unbounded: false,
    };

    /// Checks `radius > 0` (finite) and a finite centre.
    pub fn validate(&self) -> Result<(), Field3dError> {
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return invalid("radius", "a finite value > 0", self.radius);
        }
        if !self.centre.iter().all(|c| c.is_finite()) {
            return invalid(
                "centre",
                "finite coordinates",
                format_args!("{:?}", self.centre),
            );
        }
        Ok(())
    }

    /// The bounds as seen through wrong camera poses. A camera posed at `initial_i` instead of
    /// `truth_i` sees the scene moved by the rigid map `T_i = initial_i ∘ truth_i⁻¹`, which
    /// takes the ball `B(c, r)` to `B(T_i(c), r)`; all of them lie in `B(c, r + max_i ‖T_i(c) −
    /// c‖)`, the bounds returned. A field that starts from the initial poses must be able to
    /// hold the scene wherever they put it. Unbounded (contracted) bounds are returned as they
    /// are.
    pub fn widened_for(
        &self,
        truth: &[nalgebra::Isometry3<f64>],
        initial: &[nalgebra::Isometry3<f64>],
    ) -> SceneBounds {
        if self.unbounded {
            return *self;
        }
        let c = nalgebra::Point3::from(self.centre);
        let shift = truth
            .iter()
            .zip(initial)
            .map(|(t, i)| ((i * t.inverse()) * c - c).norm())
            .fold(0.0, f64::max);
        SceneBounds {
            radius: self.radius + shift,
            ..*self
        }
    }

    /// Half the side of the cube of field coordinates the grids span: 1 (bounded) or 2
    /// (contracted).
    pub fn extent(&self) -> f64 {
        if self.unbounded { 2.0 } else { 1.0 }
    }

    /// The field coordinates of a world point: `y = (x − c)/r`, then [`contract`]`(y)` when
    /// unbounded.
    pub fn field_point(&self, x: [f64; 3]) -> [f64; 3] {
        let map = PointMap::<f64>::new(self);
        map.field_point(map.normalise(x))
    }
}

/// mip-NeRF 360's contraction (eq. 10): `y` if `‖y‖ ≤ 1`, else `(2 − 1/‖y‖) · y/‖y‖`, which lies
/// in the open ball of radius 2. For finite `y` with `‖y‖²` representable in `S`.
#[inline(always)]
pub fn contract<S: Real>(y: [S; 3]) -> [S; 3] {
    let rho2 = y[0] * y[0] + y[1] * y[1] + y[2] * y[2];
    if rho2 <= S::ONE {
        return y;
    }
    // (2 − 1/ρ)/ρ = (2ρ − 1)/ρ².
    let rho = rho2.sqrt();
    let s = (rho + rho - S::ONE) / rho2;
    [s * y[0], s * y[1], s * y[2]]
}

/// Reverse of [`contract`]: `∂L/∂y = (∂p/∂y)ᵀ ∂L/∂p` with, outside the unit ball (`ρ = ‖y‖`),
/// `∂p/∂y = s I − k y yᵀ`, `s = (2ρ − 1)/ρ²`, `k = 2(ρ − 1)/ρ⁴` (symmetric; the identity
/// inside).
#[inline(always)]
pub fn contract_backward<S: Real>(y: [S; 3], grad_p: [S; 3]) -> [S; 3] {
    let rho2 = y[0] * y[0] + y[1] * y[1] + y[2] * y[2];
    if rho2 <= S::ONE {
        return grad_p;
    }
    let rho = rho2.sqrt();
    let s = (rho + rho - S::ONE) / rho2;
    let k = (rho - S::ONE) * S::from_f64(2.0) / (rho2 * rho2);
    let yg = y[0] * grad_p[0] + y[1] * grad_p[1] + y[2] * grad_p[2];
    let ky = k * yg;
    [
        s * grad_p[0] - ky * y[0],
        s * grad_p[1] - ky * y[1],
        s * grad_p[2] - ky * y[2],
    ]
}

/// Which field to build, as a TOML table tagged by `kind`:
///
/// ```toml
/// [params.field]
/// kind = "grid"          # or "mlp"
/// log2_table_size = 19   # keys of HashGridConfig (or NerfMlpConfig); unknown keys are errors
/// ```
///
/// Serde's internal tagging buffers the table before the variant's struct reads it; the
/// variant structs keep `deny_unknown_fields`, so typos are still rejected (with the key and
/// the list of valid keys; the line of the table, not of the key).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RadianceFieldConfig {
    /// [`HashGridField`] (`kind = "grid"`).
    Grid(HashGridConfig),
    /// [`NerfMlpField`] (`kind = "mlp"`).
    Mlp(NerfMlpConfig),
}

impl Default for RadianceFieldConfig {
    fn default() -> Self {
        RadianceFieldConfig::Grid(HashGridConfig::default())
    }
}

impl RadianceFieldConfig {
    /// The `[field]` table at the defaults, commented, for tasks' default configs.
    pub const DEFAULT_TABLE: &str = include_str!("../../defaults/radiance_field.toml");

    /// The field of a config table (default: the hash grid when the table is absent), its
    /// seed offset by the run's `seed`.
    pub fn from_section(
        section: &cpose_core::Section<'_>,
        seed: u64,
    ) -> Result<Self, cpose_core::ConfigError> {
        let mut config = if section.exists()? {
            section.decode::<RadianceFieldConfig>()?
        } else {
            RadianceFieldConfig::default()
        };
        match &mut config {
            RadianceFieldConfig::Grid(c) => c.seed = c.seed.wrapping_add(seed),
            RadianceFieldConfig::Mlp(c) => c.seed = c.seed.wrapping_add(seed),
        }
        Ok(config)
    }

    /// The field at progress 0 (validates the config and `scene`).
    pub fn init<S: Real>(
        &self,
        scene: SceneBounds,
    ) -> Result<Box<dyn RadianceField<S>>, Field3dError> {
        Ok(match self {
            RadianceFieldConfig::Grid(c) => Box::new(c.init::<S>(scene)?),
            RadianceFieldConfig::Mlp(c) => Box::new(c.init::<S>(scene)?),
        })
    }
}

/// Batches of at least this many points are split across rayon's threads (a training step has
/// ~65k). Smaller batches (a few rays, tests) stay on the calling thread: there the split's
/// fixed costs — the hand-off, and per extra part a sum of the MLP gradient (0.6 M values for
/// BARF's MLP) — are a noticeable fraction of a pass, and on a busy machine a split of a small
/// batch loses outright (docs/methods.md §5.1).
pub const PARALLEL_MIN_POINTS: usize = 4096;

/// Rows per MLP call within a part, so that a chunk's activations (1 MiB for a 256-wide
/// layer) stay in cache between layers. Measured (best of 4): a step of the default grid field
/// at 65,536 points takes 11% less time than with one call per part on one thread, 14% less on
/// two (1024 and 2048 rows equal, 4096 3% slower); the 8 × 256 NeRF MLP at 8192 points 6%.
const MLP_CHUNK: usize = 1024;

/// The chunks of `b` points, `MLP_CHUNK` each but the last. Per-point buffers that feed the
/// MLP are *chunk-blocked*: chunk `r` occupies `[r.start·cols, r.end·cols)`, itself a
/// `[r.len() × cols]` column-major block.
fn chunks(b: usize) -> impl Iterator<Item = Range<usize>> {
    (0..b.div_ceil(MLP_CHUNK)).map(move |k| k * MLP_CHUNK..((k + 1) * MLP_CHUNK).min(b))
}

/// Colours from chunk-blocked `[len × 3]` blocks into `n × 3` interleaved.
fn copy_colours<S: Real>(blocked: &[S], rgb: &mut [S]) {
    for r in chunks(blocked.len() / 3) {
        let (len, block) = (r.len(), &blocked[3 * r.start..3 * r.end]);
        for (k, i) in r.enumerate() {
            for c in 0..3 {
                rgb[3 * i + c] = block[c * len + k];
            }
        }
    }
}

/// Number of parts a batch of `n` points is split into (1 below [`PARALLEL_MIN_POINTS`]).
fn parts_for(n: usize) -> usize {
    if n >= PARALLEL_MIN_POINTS {
        cpose_core::nn::batch_parts(n)
    } else {
        1
    }
}

/// Batch size of the forward buffers, asserting their lengths agree (a caller bug otherwise).
fn batch_len<S>(points: &[S], sigma: &[S], rgb: &[S]) -> usize {
    let n = sigma.len();
    assert!(
        points.len() == 3 * n && rgb.len() == 3 * n,
        "points and rgb must be n × 3 for n = sigma.len() = {n}, got {} and {}",
        points.len(),
        rgb.len()
    );
    n
}

/// Asserts the backward buffers' lengths for a batch of `n` and `num_params` parameters.
fn check_backward<S>(
    n: usize,
    num_params: usize,
    grad_sigma: &[S],
    grad_rgb: &[S],
    grad: &[S],
    grad_points: &[S],
) {
    assert!(
        grad_sigma.len() == n
            && grad_rgb.len() == 3 * n
            && grad_points.len() == 3 * n
            && grad.len() == num_params,
        "backward needs n, n × 3, n × 3 and num_params = {num_params} entries for n = {n}, got \
         {}, {}, {} and {}",
        grad_sigma.len(),
        grad_rgb.len(),
        grad_points.len(),
        grad.len()
    );
}

/// World → field coordinates in `S`: `y = (x − c)/r`, `p = contract(y)` when unbounded.
#[derive(Clone, Copy, Debug)]
struct PointMap<S> {
    centre: [S; 3],
    inv_radius: S,
    unbounded: bool,
}

impl<S: Real> PointMap<S> {
    fn new(scene: &SceneBounds) -> Self {
        Self {
            centre: scene.centre.map(S::from_f64),
            inv_radius: S::from_f64(1.0 / scene.radius),
            unbounded: scene.unbounded,
        }
    }

    /// `y = (x − c)/r`.
    #[inline(always)]
    fn normalise(&self, x: [S; 3]) -> [S; 3] {
        [0, 1, 2].map(|d| (x[d] - self.centre[d]) * self.inv_radius)
    }

    /// `p = contract(y)` (unbounded) or `y`.
    #[inline(always)]
    fn field_point(&self, y: [S; 3]) -> [S; 3] {
        if self.unbounded { contract(y) } else { y }
    }

    /// `∂L/∂x` from `∂L/∂p` at the normalised point `y`.
    #[inline(always)]
    fn backward(&self, y: [S; 3], grad_p: [S; 3]) -> [S; 3] {
        let g = if self.unbounded {
            contract_backward(y, grad_p)
        } else {
            grad_p
        };
        g.map(|g| g * self.inv_radius)
    }
}

/// Density head: `σ = softplus(z + bias)` and its slope `dσ/dz = sigmoid(z + bias)`.
fn density_forward<S: Real>(z: &[S], bias: S, sigma: &mut [S], slope: &mut [S]) {
    for ((&z, s), d) in z.iter().zip(sigma).zip(slope) {
        (*s, *d) = Activation::Softplus.value_and_slope(z + bias);
    }
}

/// Colour head: `rgb = sigmoid(z)` element-wise (any layout).
fn colour_forward<S: Real>(z: &[S], rgb: &mut [S]) {
    for (&z, c) in z.iter().zip(rgb) {
        *c = Activation::Sigmoid.value_and_slope(z).0;
    }
}

/// `∂L/∂z = ∂L/∂rgb · rgb(1 − rgb)` into `grad_z` (`[b × 3]` column-major) from the column-major
/// colours `rgb` and the interleaved `grad_rgb` (`b × 3`).
fn colour_backward<S: Real>(rgb: &[S], grad_rgb: &[S], b: usize, grad_z: &mut [S]) {
    for c in 0..3 {
        for i in 0..b {
            let s = rgb[c * b + i];
            grad_z[c * b + i] = grad_rgb[3 * i + c] * s * (S::ONE - s);
        }
    }
}

/// Runs `f(p, part)` on every part, on rayon's pool when there are several.
fn run_parts<P: Send>(parts: &mut [P], f: impl Fn(usize, &mut P) + Sync) {
    if let [part] = parts {
        f(0, part);
    } else {
        parts
            .par_iter_mut()
            .enumerate()
            .for_each(|(p, part)| f(p, part));
    }
}

/// The parameter-gradient half of a split reverse pass: `f(part, g, accum)` writes or adds the
/// part's gradient into `g`. Part 0 adds into `grad` itself; the others write (`Replace`) their
/// own buffer `buf(part)` in parallel, and those are added into `grad` in part order.
fn backward_parts<S: Real, P: Send>(
    parts: &mut [P],
    grad: &mut [S],
    buf: fn(&mut P) -> &mut Vec<S>,
    f: impl Fn(&mut P, &mut [S], Accum) + Sync,
) {
    let Some((first, rest)) = parts.split_first_mut() else {
        return;
    };
    if rest.is_empty() {
        f(first, grad, Accum::Add);
        return;
    }
    let len = grad.len();
    rayon::join(
        || f(first, grad, Accum::Add),
        || {
            rest.par_iter_mut().for_each(|part| {
                let mut g = std::mem::take(buf(part));
                grow(&mut g, len);
                f(part, &mut g[..len], Accum::Replace);
                *buf(part) = g;
            })
        },
    );
    for part in rest {
        for (a, &g) in grad.iter_mut().zip(buf(part).iter()) {
            *a += g;
        }
    }
}

/// Shared checks for the fields' tests.
#[cfg(test)]
mod test_support {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::RadianceField;

    /// `n` points (interleaved) uniform in `[−half, half]³` around `centre`, skipping any for
    /// which `reject(point)` holds (e.g. too close to a cell plane, where the field has a kink).
    pub fn points(
        n: usize,
        seed: u64,
        centre: [f64; 3],
        half: f64,
        reject: impl Fn([f64; 3]) -> bool,
    ) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut p = Vec::with_capacity(3 * n);
        while p.len() < 3 * n {
            let x = centre.map(|c| c + rng.random_range(-half..half));
            if !reject(x) {
                p.extend(x);
            }
        }
        p
    }

    /// Fixed cotangents for `σ` (`n`) and `rgb` (`3n`), of both signs.
    pub fn cotangents(n: usize) -> (Vec<f64>, Vec<f64>) {
        let gs = (0..n).map(|k| ((k * 5 % 11) as f64 - 5.0) * 0.1).collect();
        let gc = (0..3 * n)
            .map(|k| ((k * 7 % 13) as f64 - 6.0) * 0.1)
            .collect();
        (gs, gc)
    }

    /// `L = Σ a_i σ_i + Σ b_ij rgb_ij` with fixed cotangents `a`, `b`.
    fn loss(field: &mut dyn RadianceField<f64>, points: &[f64], a: &[f64], b: &[f64]) -> f64 {
        let n = a.len();
        let (mut sigma, mut rgb) = (vec![0.0; n], vec![0.0; 3 * n]);
        field.forward(points, &mut sigma, &mut rgb);
        let ls: f64 = sigma.iter().zip(a).map(|(s, a)| s * a).sum();
        let lc: f64 = rgb.iter().zip(b).map(|(c, b)| c * b).sum();
        ls + lc
    }

    /// Parameter gradients (at `indices`) and point gradients of `L = Σ a σ + Σ b ⊙ rgb`
    /// against central differences, `h = 1e-6`: truncation `h²|L'''|/6` and rounding
    /// `ε|L|/h ≈ 1e-10` stay well below `tol` relative to the largest compared magnitude. Also
    /// checks that `backward` adds into `grad` and overwrites `grad_points`.
    pub fn check_gradients(
        field: &mut dyn RadianceField<f64>,
        points: &[f64],
        indices: &[usize],
        tol: f64,
    ) {
        let n = points.len() / 3;
        let (a, b) = cotangents(n);
        let (mut sigma, mut rgb) = (vec![0.0; n], vec![0.0; 3 * n]);
        field.forward(points, &mut sigma, &mut rgb);
        let (pre, junk) = (0.25, 7.0);
        let mut grad = vec![pre; field.num_params()];
        let mut grad_points = vec![junk; 3 * n];
        field.backward(&a, &b, &mut grad, &mut grad_points);
        let h = 1e-6;
        let fd = |field: &mut dyn RadianceField<f64>, k: usize| {
            let p0 = field.params()[k];
            field.params_mut()[k] = p0 + h;
            let lp = loss(field, points, &a, &b);
            field.params_mut()[k] = p0 - h;
            let lm = loss(field, points, &a, &b);
            field.params_mut()[k] = p0;
            (lp - lm) / (2.0 * h)
        };
        let pairs: Vec<(usize, f64, f64)> = indices
            .iter()
            .map(|&k| (k, fd(field, k), grad[k] - pre))
            .collect();
        let scale = pairs.iter().map(|p| p.1.abs()).fold(1e-3, f64::max);
        for (k, fd, an) in pairs {
            assert!(
                (fd - an).abs() <= tol * scale,
                "param {k}: central difference {fd} vs backward {an}"
            );
        }
        let point_fd: Vec<f64> = (0..3 * n)
            .map(|k| {
                let (mut pp, mut pm) = (points.to_vec(), points.to_vec());
                pp[k] += h;
                pm[k] -= h;
                (loss(field, &pp, &a, &b) - loss(field, &pm, &a, &b)) / (2.0 * h)
            })
            .collect();
        let scale = point_fd.iter().map(|g| g.abs()).fold(1e-3, f64::max);
        for (k, (fd, an)) in point_fd.iter().zip(&grad_points).enumerate() {
            assert!(
                (fd - an).abs() <= tol * scale,
                "point coordinate {k}: central difference {fd} vs backward {an}"
            );
        }
    }

    /// [`RadianceField::backward_points`] gives the point gradient of the full
    /// [`RadianceField::backward`] bit for bit, at `points`, and it is not zero.
    pub fn check_points_gradient_alone(field: &mut dyn RadianceField<f64>, points: &[f64]) {
        let n = points.len() / 3;
        let (gs, gc) = cotangents(n);
        let (mut sigma, mut rgb) = (vec![0.0; n], vec![0.0; 3 * n]);
        field.forward(points, &mut sigma, &mut rgb);
        let mut grad = vec![0.0; field.num_params()];
        let mut full = vec![0.0; 3 * n];
        field.backward(&gs, &gc, &mut grad, &mut full);
        let mut alone = vec![f64::NAN; 3 * n];
        field.backward_points(&gs, &gc, &mut alone);
        assert_eq!(alone, full, "{n} points");
        assert!(
            full.iter().any(|&g| g != 0.0),
            "a zero gradient tests nothing"
        );
    }

    /// The `f32` field `b` agrees with the `f64` field `a` (same parameters and progress) on
    /// densities and colours (1e-5 relative to the density scale) and on parameter and point
    /// gradients (1e-4 of the largest), at `points`.
    pub fn assert_f32_matches_f64(
        a: &mut dyn RadianceField<f64>,
        b: &mut dyn RadianceField<f32>,
        points: &[f64],
    ) {
        let n = points.len() / 3;
        let pts32: Vec<f32> = points.iter().map(|&p| p as f32).collect();
        let pts: Vec<f64> = pts32.iter().map(|&p| f64::from(p)).collect();
        let (mut sa, mut ca) = (vec![0.0; n], vec![0.0; 3 * n]);
        let (mut sb, mut cb) = (vec![0.0f32; n], vec![0.0f32; 3 * n]);
        a.forward(&pts, &mut sa, &mut ca);
        b.forward(&pts32, &mut sb, &mut cb);
        let sigma_scale = sa.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for (x, y) in sa.iter().zip(&sb) {
            assert!(
                (x - f64::from(*y)).abs() < 1e-5 * sigma_scale,
                "σ {x} vs {y}"
            );
        }
        for (x, y) in ca.iter().zip(&cb) {
            assert!((x - f64::from(*y)).abs() < 1e-5, "rgb {x} vs {y}");
        }
        let (gs, gc) = cotangents(n);
        let gs32: Vec<f32> = gs.iter().map(|&v| v as f32).collect();
        let gc32: Vec<f32> = gc.iter().map(|&v| v as f32).collect();
        let (mut ga, mut gb) = (vec![0.0; a.num_params()], vec![0.0f32; b.num_params()]);
        let (mut pa, mut pb) = (vec![0.0; 3 * n], vec![0.0f32; 3 * n]);
        a.backward(&gs, &gc, &mut ga, &mut pa);
        b.backward(&gs32, &gc32, &mut gb, &mut pb);
        for (what, x, y) in [("param", ga, gb), ("point", pa, pb)] {
            let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (x, y) in x.iter().zip(&y) {
                assert!(
                    (x - f64::from(*y)).abs() < 1e-4 * scale,
                    "{what} gradient {x} vs {y}"
                );
            }
        }
    }

    /// One call on `points` (one part of several MLP chunks, fewer than `PARALLEL_MIN_POINTS`)
    /// gives the densities, colours, point gradients and summed parameter gradient of calls
    /// on batches of `batch` points.
    pub fn check_batches_agree(field: &mut dyn RadianceField<f64>, points: &[f64], batch: usize) {
        let n = points.len() / 3;
        assert!(n > super::MLP_CHUNK && n < super::PARALLEL_MIN_POINTS);
        let (a, b) = cotangents(n);
        let run =
            |field: &mut dyn RadianceField<f64>, r: std::ops::Range<usize>, grad: &mut [f64]| {
                let m = r.len();
                let (mut sigma, mut rgb) = (vec![0.0; m], vec![0.0; 3 * m]);
                field.forward(&points[3 * r.start..3 * r.end], &mut sigma, &mut rgb);
                let mut gp = vec![0.0; 3 * m];
                field.backward(&a[r.clone()], &b[3 * r.start..3 * r.end], grad, &mut gp);
                [sigma, rgb, gp]
            };
        let mut grad_all = vec![0.0; field.num_params()];
        let all = run(field, 0..n, &mut grad_all);
        let mut grad_sum = vec![0.0; field.num_params()];
        let mut parts = [Vec::new(), Vec::new(), Vec::new()];
        for start in (0..n).step_by(batch) {
            let out = run(field, start..(start + batch).min(n), &mut grad_sum);
            for (p, o) in parts.iter_mut().zip(out) {
                p.extend(o);
            }
        }
        for (what, x, y) in [
            ("sigma", &all[0], &parts[0]),
            ("rgb", &all[1], &parts[1]),
            ("point grad", &all[2], &parts[2]),
            ("param grad", &grad_all, &grad_sum),
        ] {
            let scale = x.iter().fold(1e-12f64, |m, v| m.max(v.abs()));
            for (k, (x, y)) in x.iter().zip(y).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-12 * scale,
                    "{what} {k}: one call {x} vs batches {y}"
                );
            }
        }
    }

    /// Forward and backward of `make()` on one thread (one part) and on two (two parts, as
    /// `points` has at least `PARALLEL_MIN_POINTS`) agree to rounding.
    pub fn check_parallel_matches_single_part(
        make: impl Fn() -> Box<dyn RadianceField<f64>> + Sync,
        points: &[f64],
    ) {
        let n = points.len() / 3;
        assert!(n >= super::PARALLEL_MIN_POINTS && super::parts_for(n) >= 1);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool");
            pool.install(|| {
                assert_eq!(super::parts_for(n), threads);
                let mut field = make();
                let (mut sigma, mut rgb) = (vec![0.0; n], vec![0.0; 3 * n]);
                field.forward(points, &mut sigma, &mut rgb);
                let (a, b) = cotangents(n);
                let mut grad = vec![0.0; field.num_params()];
                let mut gp = vec![0.0; 3 * n];
                field.backward(&a, &b, &mut grad, &mut gp);
                [sigma, rgb, grad, gp]
            })
        };
        let one = run(1);
        let two = run(2);
        for (what, (x, y)) in ["sigma", "rgb", "param grad", "point grad"]
            .iter()
            .zip(one.iter().zip(&two))
        {
            let scale = x.iter().fold(1e-12f64, |m, v| m.max(v.abs()));
            for (k, (x, y)) in x.iter().zip(y).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-12 * scale,
                    "{what} {k}: one part {x} vs two {y}"
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera shifted by `Δ` sees the scene shifted by `Δ`; one turned about the centre sees
    /// it turned in place. The radius grows by the largest shift; contracted bounds stay.
    #[test]
    fn bounds_widen_by_the_largest_scene_shift_of_the_initial_poses() {
        use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
        let bounds = SceneBounds {
            centre: [1.0, 0.0, 0.0],
            radius: 1.5,
            unbounded: false,
        };
        let truth = [
            Isometry3::translation(5.0, 0.0, 0.0),
            Isometry3::translation(1.0, 4.0, 0.0),
        ];
        let about_centre = |t: &Isometry3<f64>| {
            let c = Translation3::new(1.0, 0.0, 0.0);
            c * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.7) * c.inverse() * t
        };
        let initial = [
            about_centre(&truth[0]),
            Translation3::new(0.0, 0.3, 0.4) * truth[1],
        ];
        let widened = bounds.widened_for(&truth, &initial);
        assert!((widened.radius - 2.0).abs() < 1e-12, "{widened:?}");
        assert_eq!(widened.centre, bounds.centre);
        let turned_only = bounds.widened_for(&truth[..1], &initial[..1]);
        assert!((turned_only.radius - 1.5).abs() < 1e-12);
        let unbounded = SceneBounds {
            unbounded: true,
            ..bounds
        };
        assert_eq!(unbounded.widened_for(&truth, &initial), unbounded);
    }

    /// Values: the identity inside the unit ball, radius `2 − 1/ρ` outside along `y`, and
    /// continuity on the unit sphere.
    #[test]
    fn contraction_values() {
        let inside = [0.3, -0.5, 0.2];
        assert_eq!(contract(inside), inside);
        let p = contract([0.0, 4.0, 0.0]);
        assert!((p[1] - 1.75).abs() < 1e-15 && p[0] == 0.0 && p[2] == 0.0);
        let far = contract([3e7f64, -4e7, 0.0]);
        let r = (far[0] * far[0] + far[1] * far[1]).sqrt();
        assert!(r < 2.0 && r > 2.0 - 1e-7, "{far:?}");
        let u = [0.6, 0.0, 0.8];
        let (a, b) = (
            contract(u.map(|v| v * (1.0 - 1e-9))),
            contract(u.map(|v| v * (1.0 + 1e-9))),
        );
        assert!(a.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-8));
    }

    /// `contract_backward` against central differences of `g · contract(y)` (h = 1e-6; the map
    /// is smooth away from the unit sphere: truncation ~h² ≈ 1e-12), and the identity inside.
    #[test]
    fn contraction_backward_matches_central_differences() {
        let g = [0.7, -1.1, 0.4];
        for y in [
            [0.2, 0.3, -0.1],
            [1.5, -0.4, 0.9],
            [-7.0, 3.0, 12.0],
            [0.0, 0.0, -1.3],
        ] {
            let an = contract_backward(y, g);
            for d in 0..3 {
                let f = |h: f64| {
                    let mut v = y;
                    v[d] += h;
                    let p = contract(v);
                    p[0] * g[0] + p[1] * g[1] + p[2] * g[2]
                };
                let fd = (f(1e-6) - f(-1e-6)) / 2e-6;
                assert!(
                    (fd - an[d]).abs() < 1e-8,
                    "y {y:?} axis {d}: {fd} vs {}",
                    an[d]
                );
            }
        }
    }

    /// The world → field map: normalisation by centre and radius, then contraction; and the
    /// point reverse pass scales by `1/r`.
    #[test]
    fn scene_bounds_map_points() {
        let scene = SceneBounds {
            centre: [1.0, 2.0, -1.0],
            radius: 2.0,
            unbounded: false,
        };
        assert_eq!(scene.field_point([2.0, 1.0, 0.0]), [0.5, -0.5, 0.5]);
        assert_eq!(scene.field_point([9.0, 2.0, -1.0]), [4.0, 0.0, 0.0]);
        let unbounded = SceneBounds {
            unbounded: true,
            ..scene
        };
        assert_eq!(unbounded.field_point([9.0, 2.0, -1.0]), [1.75, 0.0, 0.0]);
        assert_eq!((scene.extent(), unbounded.extent()), (1.0, 2.0));
        let map = PointMap::<f64>::new(&unbounded);
        let g = map.backward([4.0, 0.0, 0.0], [1.0, 1.0, 0.0]);
        // Radial slope 1/ρ² = 1/16, tangential (2ρ − 1)/ρ² = 7/16, then 1/r = 1/2.
        assert_eq!(g, [1.0 / 32.0, 7.0 / 32.0, 0.0]);
    }

    #[test]
    fn invalid_scene_bounds_name_the_key() {
        for (bad, key) in [
            (
                SceneBounds {
                    radius: 0.0,
                    ..SceneBounds::UNIT
                },
                "radius",
            ),
            (
                SceneBounds {
                    radius: f64::INFINITY,
                    ..SceneBounds::UNIT
                },
                "radius",
            ),
            (
                SceneBounds {
                    centre: [0.0, f64::NAN, 0.0],
                    ..SceneBounds::UNIT
                },
                "centre",
            ),
        ] {
            let err = bad.validate().expect_err("invalid bounds");
            assert!(
                matches!(&err, Field3dError::Invalid { key: k, .. } if *k == key),
                "{err}"
            );
            for config in [
                RadianceFieldConfig::default(),
                RadianceFieldConfig::Mlp(NerfMlpConfig::default()),
            ] {
                let e = config.init::<f32>(bad).err().expect("invalid bounds");
                assert_eq!(e, err);
            }
        }
    }

    /// The tagged config: both kinds parse with their keys, defaults fill the rest, typos in a
    /// variant's keys and unknown kinds are rejected, and the enum round-trips.
    #[test]
    fn config_enum_parses_from_toml() {
        let grid: RadianceFieldConfig =
            toml::from_str("kind = \"grid\"\nlevels = 4\nc2f = false").expect("valid toml");
        let RadianceFieldConfig::Grid(g) = &grid else {
            panic!("expected a grid config, got {grid:?}");
        };
        assert_eq!((g.levels, g.c2f, g.width), (4, None, 64));
        let mlp: RadianceFieldConfig =
            toml::from_str("kind = \"mlp\"\nskip_layer = false\ndepth = 4").expect("valid toml");
        assert_eq!(
            mlp,
            RadianceFieldConfig::Mlp(NerfMlpConfig {
                skip_layer: None,
                depth: 4,
                ..NerfMlpConfig::default()
            })
        );
        assert_eq!(
            toml::from_str::<RadianceFieldConfig>("kind = \"grid\"").expect("defaults"),
            RadianceFieldConfig::default()
        );
        for text in [
            "kind = \"grid\"\nlevel = 4",
            "kind = \"mlp\"\nlevels = 4",
            "kind = \"hash\"",
            "levels = 4",
        ] {
            let err = toml::from_str::<RadianceFieldConfig>(text).expect_err(text);
            assert!(!err.to_string().is_empty());
        }
        let typo = toml::from_str::<RadianceFieldConfig>("kind = \"grid\"\nlevle = 4")
            .expect_err("unknown key")
            .to_string();
        assert!(typo.contains("levle") && typo.contains("levels"), "{typo}");
        for c in [grid, mlp, RadianceFieldConfig::default()] {
            let text = toml::to_string(&c).expect("serialises");
            assert_eq!(
                toml::from_str::<RadianceFieldConfig>(&text).expect("round trip"),
                c
            );
        }
    }

    /// `init` builds the chosen field behind the trait, with groups covering all parameters.
    #[test]
    fn config_enum_builds_either_field() {
        let small_grid = RadianceFieldConfig::Grid(HashGridConfig {
            levels: 2,
            log2_table_size: 10,
            base_resolution: 2,
            finest_resolution: 4,
            width: 8,
            ..HashGridConfig::default()
        });
        let small_mlp = RadianceFieldConfig::Mlp(NerfMlpConfig {
            bands: 2,
            depth: 2,
            width: 8,
            skip_layer: Some(1),
            rgb_width: 4,
            ..NerfMlpConfig::default()
        });
        for (config, names) in [
            (small_grid, &["grid", "mlp"][..]),
            (small_mlp, &["mlp"][..]),
        ] {
            let mut field = config.init::<f64>(SceneBounds::UNIT).expect("valid");
            let groups = field.param_groups();
            assert_eq!(groups.iter().map(|g| g.0).collect::<Vec<_>>(), names);
            assert_eq!(groups[0].1.start, 0);
            assert_eq!(groups.last().expect("a group").1.end, field.num_params());
            assert!(groups.windows(2).all(|w| w[0].1.end == w[1].1.start));
            field.set_progress(1.0);
            let (mut sigma, mut rgb) = ([0.0; 2], [0.0; 6]);
            field.forward(&[0.1, 0.2, 0.3, -0.5, 0.9, 2.0], &mut sigma, &mut rgb);
            assert!(sigma.iter().all(|&s| s > 0.0) && rgb.iter().all(|&c| c > 0.0 && c < 1.0));
        }
    }
}
