//! [`HashGridField`]: instant-NGP's multiresolution hash encoding and a tiny MLP.

use std::ops::Range;

use cpose_core::Real;
use cpose_core::nn::{Accum, Activation, Init, Mlp, MlpSpec, MlpWorkspace, coarse_to_fine_weights};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{
    Field3dError, MLP_CHUNK, PointMap, RadianceField, SceneBounds, backward_parts, batch_len,
    check_backward, chunks, colour_backward, colour_forward, copy_colours, density_forward,
    parts_for, run_parts,
};
use crate::field_common::{c2f_serde, c2f_window, check_c2f, grow, invalid};

/// Largest accepted `finest_resolution`: `f32` cell positions `u ≤ 65536` keep a resolution of
/// `2⁻⁷` cells, and vertex coordinates fit the `u32` hash arithmetic.
const MAX_RESOLUTION: usize = 1 << 16;

/// Most features per vertex (the per-point accumulator lives on the stack).
const MAX_FEATURES: usize = 8;

/// Added to the density pre-activation, `σ = softplus(z₀ + GRID_DENSITY_BIAS)`: at initialisation
/// (`z₀ ≈ 0`) `σ ≈ 0.31` per unit length, so a ray through a scene of a few units starts
/// semi-transparent rather than opaque, and softplus keeps a smooth, non-vanishing gradient.
pub const GRID_DENSITY_BIAS: f64 = -1.0;

/// instant-NGP's spatial-hash primes `π₁ = 1, π₂, π₃` (Müller et al. 2022, eq. 4).
const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

/// Construction parameters of a [`HashGridField`] (a TOML table; unknown keys are errors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HashGridConfig {
    /// Number of grid levels `L` (1–32); default 12.
    pub levels: usize,
    /// Features `F` per vertex and level (1–8; network input `L·F`); default 2.
    pub features: usize,
    /// `log₂ T`, the table size per hashed level (10–24); a level whose `(R + 1)³` vertices fit
    /// in `T` entries is stored densely instead. Default 17 (1 MiB per `f32` level at `F = 2`).
    pub log2_table_size: u32,
    /// Cells per side `R₀` of the coarsest level over the cube of field coordinates
    /// (`[−1, 1]³` bounded, `[−2, 2]³` contracted); default 16.
    pub base_resolution: usize,
    /// Cells per side of the finest level (≤ 65536; equal to `base_resolution` when
    /// `levels = 1`); default 256.
    pub finest_resolution: usize,
    /// Units per hidden layer of the MLP; default 64.
    pub width: usize,
    /// Hidden ReLU layers of the MLP (≥ 1); default 2.
    pub hidden_layers: usize,
    /// Coarse-to-fine window `[start, end]` in fractions of training, `0 ≤ start < end ≤ 1`,
    /// over the levels after the coarsest (always on); `false` in TOML (`None`) weights every
    /// level 1. Default `[0.1, 0.5]` (BARF's NeRF window).
    #[serde(with = "c2f_serde")]
    pub c2f: Option<[f64; 2]>,
    /// Grid values start as `U(±init_scale)`; default 1e-4 (instant-NGP).
    pub init_scale: f64,
    /// Weights of the 8 corners from the cell coordinates `t`: trilinear, or trilinear in the
    /// smoothstep `t²(3 − 2t)` (instant-NGP's option), which makes the field's gradient with
    /// respect to position continuous across cell faces, as pose registration wants (Heo et
    /// al. 2023). Default linear.
    pub interpolation: Interpolation,
    /// Seed of the initialisation (ChaCha8: the MLP, then the grid); default 0.
    pub seed: u64,
    /// `k` in `σ = k · softplus(z₀ + GRID_DENSITY_BIAS)`: the density per unit length an MLP
    /// output of order one means. Default 1 (scenes of a few units); metric indoor maps need
    /// surfaces of hundreds per metre.
    pub density_scale: f64,
}

impl Default for HashGridConfig {
    fn default() -> Self {
        Self {
            levels: 12,
            features: 2,
            log2_table_size: 17,
            base_resolution: 16,
            finest_resolution: 256,
            width: 64,
            hidden_layers: 2,
            c2f: Some([0.1, 0.5]),
            init_scale: 1e-4,
            density_scale: 1.0,
            interpolation: Interpolation::Linear,
            seed: 0,
        }
    }
}

/// How a grid level interpolates between the corners of a cell ([`HashGridConfig`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    /// Trilinear in `t`.
    #[default]
    Linear,
    /// Trilinear in `t²(3 − 2t)`.
    Smoothstep,
}

impl HashGridConfig {
    /// A field over `scene` at progress 0: the MLP with PyTorch's default `Linear` init
    /// (`W, b ~ U(±1/sqrt(fan_in))`), grid values `U(±init_scale)`.
    pub fn init<S: Real>(&self, scene: SceneBounds) -> Result<HashGridField<S>, Field3dError> {
        if !(1..=32).contains(&self.levels) {
            return invalid("levels", "1 to 32", self.levels);
        }
        if !(1..=MAX_FEATURES).contains(&self.features) {
            return invalid("features", "1 to 8", self.features);
        }
        if !(10..=24).contains(&self.log2_table_size) {
            return invalid("log2_table_size", "10 to 24", self.log2_table_size);
        }
        if self.base_resolution == 0 {
            return invalid("base_resolution", "at least 1", self.base_resolution);
        }
        if self.finest_resolution > MAX_RESOLUTION {
            return invalid("finest_resolution", "at most 65536", self.finest_resolution);
        }
        if self.finest_resolution < self.base_resolution
            || (self.levels == 1 && self.finest_resolution != self.base_resolution)
        {
            let want = if self.levels == 1 {
                format!(
                    "= base_resolution ({}) when levels = 1",
                    self.base_resolution
                )
            } else {
                format!("≥ base_resolution ({})", self.base_resolution)
            };
            return invalid("finest_resolution", &want, self.finest_resolution);
        }
        if self.width == 0 {
            return invalid("width", "at least 1", self.width);
        }
        if self.hidden_layers == 0 {
            return invalid("hidden_layers", "at least 1", self.hidden_layers);
        }
        if !(self.init_scale.is_finite() && self.init_scale >= 0.0) {
            return invalid("init_scale", "a finite value ≥ 0", self.init_scale);
        }
        if !(self.density_scale.is_finite() && self.density_scale > 0.0) {
            return invalid("density_scale", "a finite value > 0", self.density_scale);
        }
        check_c2f(self.c2f)?;
        scene.validate()?;

        let (base, finest) = (self.base_resolution as f64, self.finest_resolution as f64);
        let growth = if self.levels > 1 {
            (finest / base).powf(1.0 / (self.levels - 1) as f64)
        } else {
            1.0
        };
        let table = 1usize << self.log2_table_size;
        let mut levels = Vec::with_capacity(self.levels);
        let mut offset = 0;
        for l in 0..self.levels {
            let r = ((base * growth.powi(l as i32)).round() as usize).clamp(1, MAX_RESOLUTION);
            let level = Level::new(r, table, offset);
            offset += level.entries * self.features;
            levels.push(level);
        }
        let grid_len = offset;

        let spec = MlpSpec {
            input_dim: self.levels * self.features,
            width: self.width,
            depth: self.hidden_layers + 1,
            output_dim: 4,
            skip_layer: None,
            activation: Activation::Relu,
            hidden_init: Init::TorchDefault,
            output_init: Init::TorchDefault,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mlp = Mlp::new(spec, &mut rng);
        let mut params = Vec::with_capacity(grid_len + mlp.num_params());
        let s = self.init_scale;
        params.extend((0..grid_len).map(|_| {
            if s > 0.0 {
                S::from_f64(rng.random_range(-s..s))
            } else {
                S::ZERO
            }
        }));
        params.extend_from_slice(&mlp.params);

        let mut field = HashGridField {
            config: self.clone(),
            map: PointMap::new(&scene),
            extent: scene.extent(),
            resolutions: levels.iter().map(|l| l.resolution as usize).collect(),
            levels,
            grid_len,
            weights: {
                let mut w = vec![0.0; self.levels];
                level_weights(0.0, self.c2f, &mut w);
                w
            },
            params,
            mlp,
            ws: Workspace::default(),
        };
        field.set_progress(0.0);
        Ok(field)
    }
}

/// instant-NGP's multiresolution hash encoding (Müller et al. 2022, §3) with a tiny MLP: the
/// fast 3-D field.
///
/// Level `l < L` has `R_l` cells per side over the cube `[−E, E]³` of field coordinates
/// (`E` = [`SceneBounds::extent`]), `R_l = round(R_0 · g^l)`, `g = (R_{L−1}/R_0)^{1/(L−1)}`,
/// and `R_l + 1` vertices per side, each with `F` features. Vertex `(i, j, k)` is stored at
/// table entry
///
/// - dense, when `(R_l + 1)³ ≤ T = 2^log2_table_size`: `i + (R_l + 1)(j + (R_l + 1)k)`, a
///   bijection onto `0..(R_l + 1)³`;
/// - hashed otherwise: `(i·π₁ ⊕ j·π₂ ⊕ k·π₃) mod T` in wrapping `u32` arithmetic, with
///   `π = (1, 2654435761, 805459861)`; collisions share (and train) one entry.
///
/// For a field point `p` (see the module docs), per axis `u = (clamp(p, −E, E) + E) · R_l/(2E)`,
/// cell `i₀ = min(⌊u⌋, R_l − 1)`, `t = u − i₀`, and the level's feature is the trilinear
/// interpolation `f_l(p) = Σ_{c ∈ {0,1}³} Π_d (c_d ? t_d : 1 − t_d) · v_{i₀ + c}`. The network
/// input is `[w_0 f_0(p), …, w_{L−1} f_{L−1}(p)]` (`L·F` values; `w_l` are BARF's
/// coarse-to-fine weights with the levels as bands), then `hidden_layers` ReLU layers of
/// `width` units and a linear layer to 4 outputs `z`: `σ = k softplus(z₀ + GRID_DENSITY_BIAS)`
/// ([`GRID_DENSITY_BIAS`]), `rgb = sigmoid(z₁..₃)`.
///
/// Reverse pass to the point: `∂f_l/∂p_d = R_l/(2E) · Σ_c ±Π_{e≠d}(…) v_c` (the sign that of
/// `c_d`), zero along an axis that was clamped; constant in `t_d`, so it jumps across cell
/// planes.
///
/// Parameters: the grid, level by level, entry `e` of level `l` at `offset_l + e·F`, its `F`
/// features contiguous (`offset_l = F · Σ_{k<l} entries_k`, entries `(R_k + 1)³` or `T`); then
/// the MLP's parameters ([`Mlp::params`] layout). The MLP's copy of its weights is refreshed
/// from this vector at every forward pass (a few thousand values), so
/// [`RadianceField::params_mut`] needs no synchronisation. Grids want a larger learning rate than
/// the MLP (instant-NGP: 1e-2); [`RadianceField::param_groups`] returns `("grid", …)` and
/// `("mlp", …)`.
///
/// Work split. The forward pass and the MLP's reverse pass run per part of the batch (see the
/// module docs), the MLP in chunks of a few thousand rows. The grid's reverse pass runs per
/// level instead, each level over all points (rayon steals whole levels), so each thread
/// scatters into its own level's slice of the gradient and no partial grid gradients are
/// summed; each level's point gradient (`n × 3`) is kept apart and the levels are added in
/// order (as fast as one static group of levels per thread, and independent of the schedule).
/// The forward pass keeps each point's Jacobian `∂f_l/∂p` (`3F` values per level, computed
/// while the corners' values are loaded), so the reverse pass to the points reads no table: at
/// 65,536 points a forward pass alone takes ~20% longer, forward and backward ~20% less, and a
/// SLAM tracking step (the points' gradient alone) ~30% less. Corner indices and weights are
/// recomputed for the parameters' scatter: caching them (48 B per point and level) saved only
/// ~3% of a step.
#[derive(Clone, Debug)]
pub struct HashGridField<S: Real = f32> {
    config: HashGridConfig,
    map: PointMap<S>,
    /// Half side `E` of the cube of field coordinates the grids span.
    extent: f64,
    levels: Vec<Level>,
    /// `R_l` of each level.
    resolutions: Vec<usize>,
    /// Number of grid values (all levels).
    grid_len: usize,
    /// Coarse-to-fine weight `w_l` of each level.
    weights: Vec<f64>,
    params: Vec<S>,
    mlp: Mlp<S>,
    ws: Workspace<S>,
}

/// One level's table.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Level {
    /// Cells per side `R`.
    resolution: u32,
    /// First grid value of the level in the parameter vector.
    offset: usize,
    /// Table entries: `(R + 1)³` (dense) or `T` (hashed).
    entries: usize,
    /// Whether vertices are hashed into the table.
    hashed: bool,
}

impl Level {
    fn new(resolution: usize, table: usize, offset: usize) -> Self {
        let vertices = (resolution as u64 + 1).pow(3);
        let hashed = vertices > table as u64;
        Self {
            resolution: resolution as u32,
            offset,
            entries: if hashed { table } else { vertices as usize },
            hashed,
        }
    }

    /// Table entry of vertex `(i, j, k)`.
    #[cfg(test)]
    fn index(&self, i: u32, j: u32, k: u32) -> usize {
        if self.hashed {
            let h =
                i.wrapping_mul(PRIMES[0]) ^ j.wrapping_mul(PRIMES[1]) ^ k.wrapping_mul(PRIMES[2]);
            (h & (self.entries as u32 - 1)) as usize
        } else {
            let s = self.resolution as usize + 1;
            i as usize + s * (j as usize + s * k as usize)
        }
    }

    /// Table entries of the 8 corners of cell `(i, j, k)`, corner `c = x + 2y + 4z` for offsets
    /// `x, y, z ∈ {0, 1}`.
    #[inline(always)]
    fn corners(&self, i: u32, j: u32, k: u32) -> [usize; 8] {
        if self.hashed {
            let mask = self.entries as u32 - 1;
            let hx = [i, i + 1];
            let hy = [j.wrapping_mul(PRIMES[1]), (j + 1).wrapping_mul(PRIMES[1])];
            let hz = [k.wrapping_mul(PRIMES[2]), (k + 1).wrapping_mul(PRIMES[2])];
            std::array::from_fn(|c| ((hx[c & 1] ^ hy[(c >> 1) & 1] ^ hz[c >> 2]) & mask) as usize)
        } else {
            let s1 = self.resolution as usize + 1;
            let s2 = s1 * s1;
            let b = i as usize + s1 * j as usize + s2 * k as usize;
            [
                b,
                b + 1,
                b + s1,
                b + s1 + 1,
                b + s2,
                b + s2 + 1,
                b + s2 + s1,
                b + s2 + s1 + 1,
            ]
        }
    }
}

/// The coarse-to-fine weight of every level at `progress`: the coarsest is always on (as BARF's
/// raw coordinates beside its encoding), so the field depends on position from the first step;
/// the window opens the others.
fn level_weights(progress: f64, c2f: Option<[f64; 2]>, weights: &mut [f64]) {
    weights[0] = 1.0;
    let [start, end] = c2f_window(c2f);
    coarse_to_fine_weights(progress, start, end, &mut weights[1..]);
}

/// Where a point falls on one level.
#[derive(Clone, Copy, Debug)]
struct Cell<S> {
    /// Table entries of the corners (see [`Level::corners`]).
    corners: [usize; 8],
    /// `(t_x, t_y, t_z) ∈ [0, 1]³`.
    t: [S; 3],
    /// Per axis, whether the coordinate was inside `[−E, E]` (else clamped: zero derivative).
    inside: [bool; 3],
    /// `dt/du` per axis: 1 (linear) or `6u(1 − u)` (smoothstep of the cell coordinate `u`).
    dt: [S; 3],
}

impl<S: Real> Cell<S> {
    /// Trilinear weights `Π_d (c_d ? t_d : 1 − t_d)` of the corners.
    #[inline(always)]
    fn weights(&self) -> [S; 8] {
        let [tx, ty, tz] = self.t;
        let (wx, wy, wz) = ([S::ONE - tx, tx], [S::ONE - ty, ty], [S::ONE - tz, tz]);
        let xy = [wx[0] * wy[0], wx[1] * wy[0], wx[0] * wy[1], wx[1] * wy[1]];
        std::array::from_fn(|c| xy[c & 3] * wz[c >> 2])
    }
}

/// Per axis: `u = (clamp(x, −E, E) + E)·scale` (`scale = R/(2E)`), `i₀ = min(⌊u⌋, R − 1)`;
/// returns `(i₀, u − i₀, inside)`.
#[inline(always)]
fn locate<S: Real>(x: S, extent: S, scale: S, res: u32) -> (u32, S, bool) {
    let inside = x >= -extent && x <= extent;
    // `max` first maps NaN to −E, so the index is always valid.
    let u = (x.max(-extent).min(extent) + extent) * scale;
    // u ≥ 0, so truncation is ⌊u⌋ (and `as` saturates).
    let i0 = (u.to_f64() as u32).min(res - 1);
    (i0, u - S::from_f64(f64::from(i0)), inside)
}

/// Buffers of one part of the batch (grow with the batch, never shrink).
#[derive(Clone, Debug, Default)]
struct Part<S: Real> {
    /// First point of the part in the batch.
    start: usize,
    /// Points in the part.
    b: usize,
    /// Normalised points `y`, `b × 3` interleaved.
    y: Vec<S>,
    /// Field points `p` (contracted when unbounded), `b × 3` interleaved.
    p: Vec<S>,
    /// Network input `[w_l f_l]`, chunk-blocked `[len × L·F]` column-major blocks.
    enc: Vec<S>,
    /// Per level, the Jacobians `∂f_l/∂p` of the points, `b × 3 × F` (active levels only).
    jac: Vec<S>,
    /// One MLP workspace per chunk.
    mlp: Vec<MlpWorkspace<S>>,
    /// `σ` and `dσ/dz₀`, `b` each.
    sigma: Vec<S>,
    slope: Vec<S>,
    /// Colours, chunk-blocked `[len × 3]`.
    rgb: Vec<S>,
    /// `∂L/∂z` of one chunk, `[len × 4]`.
    grad_z: Vec<S>,
    /// `∂L/∂(network input)`, laid out as `enc`.
    grad_enc: Vec<S>,
    /// The part's MLP gradient (parts after the first).
    grad: Vec<S>,
}

/// Buffers of one forward/backward pair.
#[derive(Clone, Debug, Default)]
struct Workspace<S: Real> {
    /// Batch size of the last forward pass.
    n: usize,
    /// Parts in use (`parts[..used]`).
    used: usize,
    parts: Vec<Part<S>>,
    /// Per level, `∂L/∂p` from that level, `n × 3` interleaved (active levels only).
    level_grad_p: Vec<Vec<S>>,
}

impl<S: Real> HashGridField<S> {
    /// The configuration it was built from.
    pub fn config(&self) -> &HashGridConfig {
        &self.config
    }

    /// Cells per side `R_l` of each level, coarse to fine.
    pub fn resolutions(&self) -> &[usize] {
        &self.resolutions
    }

    /// Whether level `l` is hashed (else dense).
    pub fn is_hashed(&self, l: usize) -> bool {
        self.levels[l].hashed
    }

    /// Indices of level `l`'s grid values in [`RadianceField::params`].
    pub fn level_range(&self, l: usize) -> Range<usize> {
        let level = &self.levels[l];
        level.offset..level.offset + level.entries * self.config.features
    }

    /// The current coarse-to-fine weight `w_l` of each level (all 1 without coarse-to-fine).
    pub fn level_weights(&self) -> &[f64] {
        &self.weights
    }

    /// Indices of the grid values in [`RadianceField::params`].
    pub fn grid_range(&self) -> Range<usize> {
        0..self.grid_len
    }

    /// Indices of the MLP's parameters in [`RadianceField::params`].
    pub fn mlp_range(&self) -> Range<usize> {
        self.grid_len..self.params.len()
    }

    /// `(E, R/(2E))` of level `l` in `S`.
    fn level_scale(&self, l: usize) -> (S, S) {
        let r = f64::from(self.levels[l].resolution);
        (
            S::from_f64(self.extent),
            S::from_f64(r / (2.0 * self.extent)),
        )
    }

    /// The cell of field point `p` on level `l`.
    #[inline(always)]
    fn cell(&self, level: &Level, extent: S, scale: S, p: &[S]) -> Cell<S> {
        let res = level.resolution;
        let (i, tx, in_x) = locate(p[0], extent, scale, res);
        let (j, ty, in_y) = locate(p[1], extent, scale, res);
        let (k, tz, in_z) = locate(p[2], extent, scale, res);
        let mut cell = Cell {
            corners: level.corners(i, j, k),
            t: [tx, ty, tz],
            inside: [in_x, in_y, in_z],
            dt: [S::ONE; 3],
        };
        if self.config.interpolation == Interpolation::Smoothstep {
            let three = S::from_f64(3.0);
            for (t, dt) in cell.t.iter_mut().zip(&mut cell.dt) {
                let u = *t;
                *dt = S::from_f64(6.0) * u * (S::ONE - u);
                *t = u * u * (three - (u + u));
            }
        }
        cell
    }

    /// `w_l f_l(p)` of level `l` for the field points `p` (`b × 3` interleaved) into the
    /// network input `enc` (chunk-blocked, see [`chunks`]), and the Jacobian `∂f_l/∂p` into
    /// `jac` (`b × 3 × F`, point by point, row `d` the derivative along axis `d`) while the
    /// corners' values are at hand, so the reverse pass to the points reads no table. `F` is
    /// the feature count as a constant (the accumulators then live in registers), or 0 to read
    /// it from the config.
    fn encode_level<const F: usize>(&self, l: usize, p: &[S], enc: &mut [S], jac: &mut [S]) {
        let nf = if F == 0 { self.config.features } else { F };
        let (b, dim) = (p.len() / 3, self.input_dim());
        let level = &self.levels[l];
        let w = S::from_f64(self.weights[l]);
        let (extent, scale) = self.level_scale(l);
        let table = &self.params[level.offset..level.offset + level.entries * nf];
        for r in chunks(b) {
            let len = r.len();
            // Columns `l·F ..` of the chunk's `[len × L·F]` block.
            let cols = &mut enc[r.start * dim + l * nf * len..r.start * dim + (l + 1) * nf * len];
            for (k, i) in r.enumerate() {
                let cell = self.cell(level, extent, scale, &p[3 * i..3 * i + 3]);
                let v: [&[S]; 8] = cell.corners.map(|e| &table[e * nf..(e + 1) * nf]);
                let cw = cell.weights();
                let mut acc = [S::ZERO; MAX_FEATURES];
                for (v, &cw) in v.iter().zip(&cw) {
                    for f in 0..nf {
                        acc[f] += cw * v[f];
                    }
                }
                for f in 0..nf {
                    cols[f * len + k] = w * acc[f];
                }
                // ∂f/∂t_x = Σ_{y,z} w_y w_z (v_{1yz} − v_{0yz}), likewise for y and z; then
                // ∂t/∂p = dt/du · R/(2E) inside, 0 where the coordinate was clamped.
                let [tx, ty, tz] = cell.t;
                let (wx, wy, wz) = ([S::ONE - tx, tx], [S::ONE - ty, ty], [S::ONE - tz, tz]);
                let mut gt = [[S::ZERO; MAX_FEATURES]; 3];
                for a in 0..2 {
                    for c in 0..2 {
                        let (x, y, z) = (wy[a] * wz[c], wx[a] * wz[c], wx[a] * wy[c]);
                        let (x1, x0) = (v[1 + 2 * a + 4 * c], v[2 * a + 4 * c]);
                        let (y1, y0) = (v[a + 2 + 4 * c], v[a + 4 * c]);
                        let (z1, z0) = (v[a + 2 * c + 4], v[a + 2 * c]);
                        for f in 0..nf {
                            gt[0][f] += x * (x1[f] - x0[f]);
                            gt[1][f] += y * (y1[f] - y0[f]);
                            gt[2][f] += z * (z1[f] - z0[f]);
                        }
                    }
                }
                let jac = &mut jac[3 * nf * i..3 * nf * (i + 1)];
                for d in 0..3 {
                    let dp = if cell.inside[d] {
                        cell.dt[d] * scale
                    } else {
                        S::ZERO
                    };
                    for f in 0..nf {
                        jac[d * nf + f] = gt[d][f] * dp;
                    }
                }
            }
        }
    }

    /// Width of the network input, `L·F`.
    fn input_dim(&self) -> usize {
        self.levels.len() * self.config.features
    }

    /// Forward pass of one part: field points, encoding, MLP and heads.
    fn forward_part(&self, part: &mut Part<S>, points: &[S]) {
        let b = points.len() / 3;
        let nf = self.config.features;
        let dim = self.input_dim();
        part.b = b;
        for v in [&mut part.y, &mut part.p, &mut part.rgb] {
            grow(v, 3 * b);
        }
        grow(&mut part.enc, b * dim);
        grow(&mut part.jac, 3 * b * dim);
        grow(&mut part.sigma, b);
        grow(&mut part.slope, b);
        for i in 0..b {
            let x = [points[3 * i], points[3 * i + 1], points[3 * i + 2]];
            let y = self.map.normalise(x);
            part.y[3 * i..3 * i + 3].copy_from_slice(&y);
            part.p[3 * i..3 * i + 3].copy_from_slice(&self.map.field_point(y));
        }
        let (p, enc) = (&part.p[..3 * b], &mut part.enc[..b * dim]);
        for l in 0..self.levels.len() {
            let jac = &mut part.jac[3 * b * nf * l..3 * b * nf * (l + 1)];
            if self.weights[l] == 0.0 {
                for r in chunks(b) {
                    let len = r.len();
                    enc[r.start * dim + l * nf * len..r.start * dim + (l + 1) * nf * len]
                        .fill(S::ZERO);
                }
                continue;
            }
            match nf {
                1 => self.encode_level::<1>(l, p, enc, jac),
                2 => self.encode_level::<2>(l, p, enc, jac),
                4 => self.encode_level::<4>(l, p, enc, jac),
                8 => self.encode_level::<8>(l, p, enc, jac),
                _ => self.encode_level::<0>(l, p, enc, jac),
            }
        }
        let bias = S::from_f64(GRID_DENSITY_BIAS);
        let scale = S::from_f64(self.config.density_scale);
        let chunk_count = b.div_ceil(MLP_CHUNK);
        if part.mlp.len() < chunk_count {
            part.mlp.resize_with(chunk_count, MlpWorkspace::default);
        }
        for (r, ws) in chunks(b).zip(&mut part.mlp) {
            let len = r.len();
            self.mlp
                .forward(&part.enc[r.start * dim..r.end * dim], len, 1, ws);
            let z = ws.output();
            density_forward(
                &z[..len],
                bias,
                &mut part.sigma[r.clone()],
                &mut part.slope[r.clone()],
            );
            if scale != S::ONE {
                for v in part.sigma[r.clone()]
                    .iter_mut()
                    .chain(&mut part.slope[r.clone()])
                {
                    *v *= scale;
                }
            }
            colour_forward(&z[len..4 * len], &mut part.rgb[3 * r.start..3 * r.end]);
        }
    }

    /// Heads and MLP reverse pass of one part: `∂L/∂θ_mlp` into `g` (`accum`; skipped when
    /// `None`) and the network-input gradient into `part.grad_enc`.
    fn backward_mlp_part(
        &self,
        part: &mut Part<S>,
        grad_sigma: &[S],
        grad_rgb: &[S],
        mut g: Option<(&mut [S], Accum)>,
    ) {
        let (b, start) = (part.b, part.start);
        let dim = self.input_dim();
        grow(&mut part.grad_z, 4 * MLP_CHUNK.min(b));
        grow(&mut part.grad_enc, b * dim);
        part.grad_enc[..b * dim].fill(S::ZERO);
        for (k, (r, ws)) in chunks(b).zip(&mut part.mlp).enumerate() {
            let len = r.len();
            let gz = &mut part.grad_z[..4 * len];
            let gs = &grad_sigma[start + r.start..start + r.end];
            for ((g, &gs), &s) in gz.iter_mut().zip(gs).zip(&part.slope[r.clone()]) {
                *g = gs * s;
            }
            colour_backward(
                &part.rgb[3 * r.start..3 * r.end],
                &grad_rgb[3 * (start + r.start)..3 * (start + r.end)],
                len,
                &mut gz[len..],
            );
            let (enc, grad_enc) = (
                &part.enc[r.start * dim..r.end * dim],
                &mut part.grad_enc[r.start * dim..r.end * dim],
            );
            match g.as_mut() {
                // The first chunk writes or adds as asked; the others add.
                Some((g, accum)) => {
                    let accum = if k == 0 { *accum } else { Accum::Add };
                    self.mlp.backward(enc, ws, gz, g, accum, Some(grad_enc));
                }
                None => self.mlp.backward_input(enc, ws, gz, grad_enc),
            }
        }
    }

    /// Grid reverse pass of `levels` over all points of `parts`: scatter-adds `∂L/∂v` into
    /// `grad` when given (the grid gradient from parameter `grad_start` on, up to the end of
    /// the last level) and writes level `l`'s `∂L/∂p` into `grad_p[l − levels.start]`
    /// (`n × 3`). Splits the levels in halves recursively and, when `parallel`, runs the halves
    /// with `rayon::join`, so idle threads steal whole levels: every level writes only its own
    /// slice of the gradient and its own point-gradient buffer, and results do not depend on
    /// the schedule.
    fn backward_levels(
        &self,
        levels: Range<usize>,
        grad: Option<&mut [S]>,
        grad_start: usize,
        grad_p: &mut [Vec<S>],
        parts: &[Part<S>],
        parallel: bool,
    ) {
        match levels.len() {
            0 => {}
            1 => {
                let l = levels.start;
                if self.weights[l] == 0.0 {
                    return;
                }
                let n = parts.iter().map(|p| p.b).sum::<usize>();
                let gp = &mut grad_p[0];
                grow(gp, 3 * n);
                gp[..3 * n].fill(S::ZERO);
                let gp = &mut gp[..3 * n];
                match (self.config.features, grad) {
                    (1, Some(g)) => self.backward_level::<1, true>(l, parts, g, gp),
                    (2, Some(g)) => self.backward_level::<2, true>(l, parts, g, gp),
                    (4, Some(g)) => self.backward_level::<4, true>(l, parts, g, gp),
                    (8, Some(g)) => self.backward_level::<8, true>(l, parts, g, gp),
                    (_, Some(g)) => self.backward_level::<0, true>(l, parts, g, gp),
                    (1, None) => self.backward_level::<1, false>(l, parts, &mut [], gp),
                    (2, None) => self.backward_level::<2, false>(l, parts, &mut [], gp),
                    (4, None) => self.backward_level::<4, false>(l, parts, &mut [], gp),
                    (8, None) => self.backward_level::<8, false>(l, parts, &mut [], gp),
                    (_, None) => self.backward_level::<0, false>(l, parts, &mut [], gp),
                }
            }
            len => {
                let (start, end) = (levels.start, levels.end);
                let mid = start + len / 2;
                let split = self.levels[mid].offset;
                let (left, right) = match grad {
                    Some(g) => {
                        let (left, right) = g.split_at_mut(split - grad_start);
                        (Some(left), Some(right))
                    }
                    None => (None, None),
                };
                let (gp_left, gp_right) = grad_p.split_at_mut(mid - start);
                let run_left = move || {
                    self.backward_levels(start..mid, left, grad_start, gp_left, parts, parallel)
                };
                let run_right =
                    move || self.backward_levels(mid..end, right, split, gp_right, parts, parallel);
                if parallel {
                    rayon::join(run_left, run_right);
                } else {
                    run_left();
                    run_right();
                }
            }
        }
    }

    /// Reverse pass of level `l` over all points of `parts`: scatter-adds `∂L/∂v` into the
    /// level's gradient `gtable` when `PARAMS` (else `gtable` is not touched) and adds `∂L/∂p`
    /// into `grad_p` (`n × 3`). `F` as in [`HashGridField::encode_level`].
    fn backward_level<const F: usize, const PARAMS: bool>(
        &self,
        l: usize,
        parts: &[Part<S>],
        gtable: &mut [S],
        grad_p: &mut [S],
    ) {
        let nf = if F == 0 { self.config.features } else { F };
        let level = &self.levels[l];
        let w = S::from_f64(self.weights[l]);
        let (extent, scale) = self.level_scale(l);
        let dim = self.input_dim();
        for (part, r) in parts
            .iter()
            .flat_map(|part| chunks(part.b).map(move |r| (part, r)))
        {
            let len = r.len();
            let gcols =
                &part.grad_enc[r.start * dim + l * nf * len..r.start * dim + (l + 1) * nf * len];
            let jac = &part.jac[3 * nf * part.b * l..3 * nf * part.b * (l + 1)];
            for (k, i) in r.enumerate() {
                // ∂L/∂f_l = w_l · ∂L/∂(w_l f_l).
                let mut gf = [S::ZERO; MAX_FEATURES];
                for f in 0..nf {
                    gf[f] = w * gcols[f * len + k];
                }
                if PARAMS {
                    let cell = self.cell(level, extent, scale, &part.p[3 * i..3 * i + 3]);
                    for (&e, &cw) in cell.corners.iter().zip(&cell.weights()) {
                        let gv = &mut gtable[e * nf..(e + 1) * nf];
                        for f in 0..nf {
                            gv[f] += cw * gf[f];
                        }
                    }
                }
                let jac = &jac[3 * nf * i..3 * nf * (i + 1)];
                let gp = &mut grad_p[3 * (part.start + i)..3 * (part.start + i) + 3];
                for d in 0..3 {
                    let mut g = S::ZERO;
                    for f in 0..nf {
                        g += gf[f] * jac[d * nf + f];
                    }
                    gp[d] += g;
                }
            }
        }
    }
}

impl<S: Real> RadianceField<S> for HashGridField<S> {
    fn num_params(&self) -> usize {
        self.params.len()
    }

    fn params(&self) -> &[S] {
        &self.params
    }

    fn params_mut(&mut self) -> &mut [S] {
        &mut self.params
    }

    fn param_groups(&self) -> Vec<(&'static str, Range<usize>)> {
        vec![("grid", self.grid_range()), ("mlp", self.mlp_range())]
    }

    fn set_progress(&mut self, progress: f64) {
        level_weights(progress, self.config.c2f, &mut self.weights);
    }

    fn kept_on_restart(&self) -> Range<usize> {
        self.level_range(0)
    }

    fn forward(&mut self, points: &[S], sigma: &mut [S], rgb: &mut [S]) {
        let n = batch_len(points, sigma, rgb);
        let parts = parts_for(n);
        self.mlp
            .params
            .copy_from_slice(&self.params[self.grid_len..]);
        let mut ws = std::mem::take(&mut self.ws);
        ws.n = n;
        ws.used = parts;
        if ws.parts.len() < parts {
            ws.parts.resize_with(parts, Part::default);
        }
        let this = &*self;
        run_parts(&mut ws.parts[..parts], |p, part| {
            let r = cpose_core::nn::part_range(n, parts, p);
            part.start = r.start;
            this.forward_part(part, &points[3 * r.start..3 * r.end]);
        });
        for part in &ws.parts[..parts] {
            let (s, b) = (part.start, part.b);
            sigma[s..s + b].copy_from_slice(&part.sigma[..b]);
            copy_colours(&part.rgb[..3 * b], &mut rgb[3 * s..3 * (s + b)]);
        }
        self.ws = ws;
    }

    fn backward(
        &mut self,
        grad_sigma: &[S],
        grad_rgb: &[S],
        grad: &mut [S],
        grad_points: &mut [S],
    ) {
        check_backward(
            self.ws.n,
            self.params.len(),
            grad_sigma,
            grad_rgb,
            grad,
            grad_points,
        );
        self.reverse(grad_sigma, grad_rgb, Some(grad), grad_points);
    }

    fn backward_points(&mut self, grad_sigma: &[S], grad_rgb: &[S], grad_points: &mut [S]) {
        let n = self.ws.n;
        assert!(
            grad_sigma.len() == n && grad_rgb.len() == 3 * n && grad_points.len() == 3 * n,
            "backward_points: cotangents and point gradient must match the last forward"
        );
        self.reverse(grad_sigma, grad_rgb, None, grad_points);
    }
}

impl<S: Real> HashGridField<S> {
    /// The reverse pass of [`RadianceField::backward`]; the parameter gradient (its grid
    /// scatter and the MLP's weight products) only when `grad` is given.
    fn reverse(
        &mut self,
        grad_sigma: &[S],
        grad_rgb: &[S],
        grad: Option<&mut [S]>,
        grad_points: &mut [S],
    ) {
        let used = self.ws.used;
        let mut ws = std::mem::take(&mut self.ws);
        let this = &*self;
        let grad_grid = match grad {
            Some(grad) => {
                let (grad_grid, grad_mlp) = grad.split_at_mut(self.grid_len);
                backward_parts(
                    &mut ws.parts[..used],
                    grad_mlp,
                    |part| &mut part.grad,
                    |part, g, accum| {
                        this.backward_mlp_part(part, grad_sigma, grad_rgb, Some((g, accum)))
                    },
                );
                Some(grad_grid)
            }
            None => {
                run_parts(&mut ws.parts[..used], |_, part| {
                    this.backward_mlp_part(part, grad_sigma, grad_rgb, None)
                });
                None
            }
        };
        let nl = self.levels.len();
        ws.level_grad_p.resize_with(nl, Vec::new);
        let Workspace {
            parts,
            level_grad_p,
            ..
        } = &mut ws;
        let parts = &parts[..used];
        self.backward_levels(0..nl, grad_grid, 0, level_grad_p, parts, used > 1);
        // ∂L/∂p = Σ_l ∂L/∂p|_l in level order, then ∂L/∂x = (∂p/∂y)ᵀ ∂L/∂p / r.
        grad_points.fill(S::ZERO);
        for (gp, &w) in level_grad_p.iter().zip(&self.weights) {
            if w != 0.0 {
                for (a, &g) in grad_points.iter_mut().zip(gp) {
                    *a += g;
                }
            }
        }
        for part in parts {
            for i in 0..part.b {
                let j = part.start + i;
                let y = [part.y[3 * i], part.y[3 * i + 1], part.y[3 * i + 2]];
                let gp = [
                    grad_points[3 * j],
                    grad_points[3 * j + 1],
                    grad_points[3 * j + 2],
                ];
                grad_points[3 * j..3 * j + 3].copy_from_slice(&self.map.backward(y, gp));
            }
        }
        self.ws = ws;
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use cpose_core::nn::Adam;
    use rand::seq::index::sample;

    use super::super::test_support::{
        assert_f32_matches_f64, check_batches_agree, check_gradients,
        check_parallel_matches_single_part, check_points_gradient_alone, points,
    };
    use super::*;

    /// Resolutions 3, 5, 8, 12 (three dense levels, then one hashed into T = 2¹⁰ = 1024
    /// entries); two features; MLP 8 → 16 → 16 → 4.
    fn small() -> HashGridConfig {
        HashGridConfig {
            levels: 4,
            features: 2,
            log2_table_size: 10,
            base_resolution: 3,
            finest_resolution: 12,
            width: 16,
            hidden_layers: 2,
            c2f: Some([0.05, 0.45]),
            init_scale: 1e-4,
            density_scale: 1.0,
            interpolation: Interpolation::Linear,
            seed: 3,
        }
    }

    fn scene(unbounded: bool) -> SceneBounds {
        SceneBounds {
            centre: [0.5, -0.25, 1.0],
            radius: 1.5,
            unbounded,
        }
    }

    /// Grid values `U(±0.5)` so that interpolation (and its point derivative) is not negligible.
    fn randomise_grid(field: &mut HashGridField<f64>, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let range = field.grid_range();
        for v in &mut field.params_mut()[range] {
            *v = rng.random_range(-0.5..0.5);
        }
    }

    /// Whether world point `x` lies within `1e-3` cells of a cell plane of any level (a kink
    /// of the trilinear interpolation, where central differences straddle two pieces), or
    /// within `1e-3` of the border of the bounded cube (where clamping starts).
    fn near_cell_plane(field: &HashGridField<f64>, scene: &SceneBounds, x: [f64; 3]) -> bool {
        let p = scene.field_point(x);
        let e = scene.extent();
        field.resolutions().iter().any(|&r| {
            p.iter().any(|&c| {
                let u = (c + e) / (2.0 * e) * r as f64;
                (u - u.round()).abs() < 1e-3
            })
        }) || p.iter().any(|&c| (c.abs() - e).abs() < 1e-3)
    }

    /// The parameter indices of feature 0 of the 8 corners of world point `x` on level `l`.
    fn corner_params(field: &HashGridField<f64>, l: usize, x: &[f64]) -> [usize; 8] {
        let level = field.levels[l];
        let (extent, scale) = field.level_scale(l);
        let p = field
            .map
            .field_point(field.map.normalise([x[0], x[1], x[2]]));
        let cell = field.cell(&level, extent, scale, &p);
        cell.corners.map(|e| level.offset + e * 2)
    }

    /// Grid values (those under the test points on every level, both features, and a random
    /// sample) and MLP parameters, and points, against central differences at progress 0.3
    /// (level 0 always on, `α = 0.625 · 3 = 1.875` over the others: weights
    /// `[1, 1, (1 − cos 0.875π)/2, 0]`) and with all levels on; bounded
    /// (with points beyond the cube, clamped) and contracted (points out to 4 radii); linear
    /// and smoothstep interpolation.
    #[test]
    fn gradients_match_central_differences() {
        use Interpolation::{Linear, Smoothstep};
        for (unbounded, progress, c2f, interpolation, density_scale) in [
            (false, 0.3, Some([0.05, 0.45]), Linear, 1.0),
            (true, 0.3, Some([0.05, 0.45]), Linear, 1.0),
            (true, 0.0, None, Linear, 1.0),
            (false, 0.3, Some([0.05, 0.45]), Smoothstep, 1.0),
            (true, 0.0, None, Smoothstep, 1.0),
            (false, 0.0, None, Smoothstep, 30.0),
        ] {
            let scene = scene(unbounded);
            let mut field = HashGridConfig {
                c2f,
                interpolation,
                density_scale,
                ..small()
            }
            .init::<f64>(scene)
            .expect("valid");
            field.set_progress(progress);
            if c2f.is_some() {
                let want = [
                    1.0,
                    1.0,
                    (1.0 - (0.875 * std::f64::consts::PI).cos()) / 2.0,
                    0.0,
                ];
                let w = field.level_weights();
                assert!(
                    w.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12),
                    "{w:?}"
                );
            }
            randomise_grid(&mut field, 11);
            let half = if unbounded { 6.0 } else { 1.3 };
            let mut pts = points(10, 6, scene.centre, half, |x| {
                near_cell_plane(&field, &scene, x)
            });
            if !unbounded {
                // Beyond the cube in x (clamped) and in y and z.
                pts.extend([
                    0.5 + 1.5 * 1.2,
                    -0.2,
                    1.1,
                    0.3,
                    -0.25 - 1.5 * 1.1,
                    1.0 + 1.5 * 1.3,
                ]);
                for x in pts[30..].chunks(3) {
                    assert!(!near_cell_plane(&field, &scene, [x[0], x[1], x[2]]));
                }
            }
            let mut rng = ChaCha8Rng::seed_from_u64(2);
            let mut idx: Vec<usize> = sample(&mut rng, field.grid_len, 40).into_vec();
            for x in pts.chunks(3).take(4) {
                for l in 0..4 {
                    for k in corner_params(&field, l, x) {
                        idx.extend([k, k + 1]);
                    }
                }
            }
            let mlp = field.mlp_range();
            idx.extend(
                sample(&mut rng, mlp.len(), 40)
                    .iter()
                    .map(|k| mlp.start + k),
            );
            // The MLP's last bias (density) and a colour bias.
            idx.extend([mlp.end - 4, mlp.end - 1]);
            // Trilinear in the grid, smooth elsewhere: truncation ~h²·|L'''| ≪ 1e-6.
            check_gradients(&mut field, &pts, &idx, 1e-6);
        }
    }

    /// A level is dense exactly when its `(R + 1)³` vertices fit the table; dense indices are
    /// a bijection onto `0..(R + 1)³`, hashed ones stay below `T` and fill most of the table.
    #[test]
    fn levels_are_dense_or_hashed_as_specified() {
        let t = 1024;
        assert!(!Level::new(9, t, 0).hashed); // 1000 vertices
        assert!(Level::new(10, t, 0).hashed); // 1331 vertices
        for r in [1, 4, 9] {
            let level = Level::new(r, t, 0);
            let s = r as u32 + 1;
            let mut seen = vec![false; level.entries];
            for k in 0..s {
                for j in 0..s {
                    for i in 0..s {
                        let e = level.index(i, j, k);
                        assert!(!seen[e], "entry {e} twice at R = {r}");
                        seen[e] = true;
                    }
                }
            }
            assert!(seen.iter().all(|&s| s) && level.entries == (r + 1).pow(3));
        }
        let level = Level::new(20, t, 0);
        assert_eq!(level.entries, t);
        let mut used = HashSet::new();
        for k in 0..21 {
            for j in 0..21 {
                for i in 0..21 {
                    let e = level.index(i, j, k);
                    assert!(e < t);
                    used.insert(e);
                }
            }
        }
        // 9261 vertices into 1024 entries: a good hash leaves almost none empty.
        assert!(used.len() > 1000, "{}", used.len());
        // The fused corner computation agrees with the per-vertex index on both kinds.
        for level in [Level::new(9, t, 0), level] {
            let c = level.corners(3, 5, 7);
            for (k, e) in c.iter().enumerate() {
                let (x, y, z) = (k as u32 & 1, (k as u32 >> 1) & 1, k as u32 >> 2);
                assert_eq!(*e, level.index(3 + x, 5 + y, 7 + z));
            }
        }
        // Hash of vertex (1, 2, 3) by hand: 1 ⊕ 2·2654435761 ⊕ 3·805459861 (mod 2³²), mod 1024.
        // (3·805459861 < 2³² needs no reduction.)
        let h = 1u64 ^ ((2 * 2_654_435_761u64) % (1 << 32)) ^ (3 * 805_459_861u64);
        assert_eq!(level.index(1, 2, 3), (h % 1024) as usize);
    }

    /// The default config: resolutions 16 … 256, the first five levels dense.
    #[test]
    fn default_layout() {
        let f = HashGridConfig::default()
            .init::<f32>(SceneBounds::UNIT)
            .expect("valid");
        assert_eq!(
            f.resolutions(),
            [16, 21, 26, 34, 44, 56, 73, 93, 120, 155, 199, 256]
        );
        let hashed: Vec<bool> = (0..12).map(|l| f.is_hashed(l)).collect();
        assert_eq!(hashed, [[false; 5].as_slice(), &[true; 7]].concat());
        let dense: usize = [16usize, 21, 26, 34, 44]
            .iter()
            .map(|r| (r + 1).pow(3))
            .sum();
        assert_eq!(f.grid_range(), 0..2 * (dense + 7 * (1 << 17)));
        assert_eq!(f.level_range(5).start, 2 * dense);
        assert_eq!(
            f.mlp_range().len(),
            24 * 64 + 64 + 64 * 64 + 64 + 64 * 4 + 4
        );
    }

    #[test]
    fn outputs_are_in_range_and_levels_follow_the_schedule() {
        let mut field = small().init::<f64>(scene(true)).expect("valid");
        assert_eq!(field.resolutions(), [3, 5, 8, 12]);
        assert_eq!(
            (0..4).map(|l| field.is_hashed(l)).collect::<Vec<_>>(),
            [false, false, false, true]
        );
        assert_eq!(field.level_weights(), [1.0, 0.0, 0.0, 0.0]);
        field.set_progress(1.0);
        assert!(field.level_weights().iter().all(|&w| w == 1.0));
        randomise_grid(&mut field, 3);
        // Output biases: density +30 (σ ≈ 29), red +20, blue −20.
        let np = field.num_params();
        field.params_mut()[np - 4] = 30.0;
        field.params_mut()[np - 3] = 20.0;
        field.params_mut()[np - 1] = -20.0;
        let pts = points(200, 9, [0.0; 3], 100.0, |_| false);
        let (mut sigma, mut rgb) = (vec![0.0; 200], vec![0.0; 600]);
        field.forward(&pts, &mut sigma, &mut rgb);
        assert!(sigma.iter().all(|&s| s > 25.0 && s < 35.0));
        assert!(rgb.iter().all(|&c| c > 0.0 && c < 1.0));
        assert!(rgb.chunks(3).all(|c| c[0] > 0.99 && c[2] < 0.01));
        // A smaller batch after a larger one, then its reverse pass.
        let (mut s2, mut c2) = (vec![0.0; 2], vec![0.0; 6]);
        field.forward(&pts[..6], &mut s2, &mut c2);
        assert_eq!(s2[..], sigma[..2]);
        assert_eq!(c2[..], rgb[..6]);
        let mut grad = vec![0.0; np];
        let mut gp = vec![0.0; 6];
        field.backward(&[1.0; 2], &[0.5; 6], &mut grad, &mut gp);
        assert!(gp.iter().all(|g| g.is_finite()) && grad.iter().any(|&g| g != 0.0));
        // An empty batch is fine.
        field.forward(&[], &mut [], &mut []);
        field.backward(&[], &[], &mut grad, &mut []);
    }

    /// In a bounded scene, with the MLP reading only the grid, a point beyond the cube has the
    /// values of its clamped point and no derivative along the clamped axes.
    #[test]
    fn points_outside_a_bounded_scene_are_clamped() {
        let scene = SceneBounds::UNIT;
        let mut field = small().init::<f64>(scene).expect("valid");
        field.set_progress(1.0);
        randomise_grid(&mut field, 1);
        let (mut a, mut b) = (([0.0; 2], [0.0; 6]), ([0.0; 2], [0.0; 6]));
        field.forward(&[1.4, 0.2, -0.3, -0.1, -2.0, 7.0], &mut a.0, &mut a.1);
        field.forward(&[1.0, 0.2, -0.3, -0.1, -1.0, 1.0], &mut b.0, &mut b.1);
        assert_eq!(a, b);
        field.forward(&[1.4, 0.2, -0.3, -0.1, -2.0, 7.0], &mut a.0, &mut a.1);
        let mut grad = vec![0.0; field.num_params()];
        let mut gp = [0.0; 6];
        field.backward(&[1.0; 2], &[1.0; 6], &mut grad, &mut gp);
        assert!(
            gp[0] == 0.0
                && gp[1] != 0.0
                && gp[2] != 0.0
                && gp[3] != 0.0
                && gp[4] == 0.0
                && gp[5] == 0.0,
            "{gp:?}"
        );
    }

    #[test]
    fn init_is_deterministic_and_grid_values_are_small() {
        let a = small().init::<f64>(scene(false)).expect("valid");
        let b = small().init::<f64>(scene(false)).expect("valid");
        assert_eq!(a.params(), b.params());
        let c = HashGridConfig { seed: 4, ..small() }
            .init::<f64>(scene(false))
            .expect("valid");
        assert_ne!(a.params()[a.grid_range()], c.params()[c.grid_range()]);
        assert_ne!(a.params()[a.mlp_range()], c.params()[c.mlp_range()]);
        let f = small().init::<f32>(scene(false)).expect("valid");
        assert!(
            a.params()
                .iter()
                .zip(f.params())
                .all(|(&a, &f)| a as f32 == f)
        );
        let grid = &a.params()[a.grid_range()];
        assert!(grid.iter().all(|v| v.abs() < 1e-4) && grid.iter().any(|&v| v != 0.0));
        // 4³ + 6³ + 9³ dense entries, then one table of 1024, two features each.
        assert_eq!(a.grid_range(), 0..2 * (64 + 216 + 729 + 1024));
        assert_eq!(a.mlp_range().len(), 8 * 16 + 16 + 16 * 16 + 16 + 16 * 4 + 4);
        assert_eq!(
            a.param_groups(),
            [("grid", a.grid_range()), ("mlp", a.mlp_range())]
        );
    }

    /// With the parameters held fixed the points' gradient is the full pass's, bit for bit, in
    /// one part and in two (5000 points).
    #[test]
    fn points_gradient_alone_matches_the_full_pass() {
        for n in [40, 5000] {
            let mut field = small().init::<f64>(scene(true)).expect("valid");
            randomise_grid(&mut field, 9);
            field.set_progress(0.6);
            let pts = points(n, 3, scene(true).centre, 3.0, |_| false);
            check_points_gradient_alone(&mut field, &pts);
        }
    }

    /// f32 and f64 fields with the same parameters agree (forward to 1e-5; backward relative
    /// to its scale), bounded and contracted.
    #[test]
    fn f32_agrees_with_f64() {
        for unbounded in [false, true] {
            let mut a = small().init::<f64>(scene(unbounded)).expect("valid");
            randomise_grid(&mut a, 5);
            let mut b = small().init::<f32>(scene(unbounded)).expect("valid");
            for (p32, &p64) in b.params_mut().iter_mut().zip(a.params()) {
                *p32 = p64 as f32;
            }
            a.set_progress(0.3);
            b.set_progress(0.3);
            let pts = points(64, 2, scene(unbounded).centre, 3.0, |_| false);
            assert_f32_matches_f64(&mut a, &mut b, &pts);
        }
    }

    /// Two parts (two threads, 5000 points) give the single-part result, contracted, with
    /// a fractional level weight.
    #[test]
    fn parallel_split_matches_single_part() {
        let make = || -> Box<dyn RadianceField<f64>> {
            let mut field = small().init::<f64>(scene(true)).expect("valid");
            randomise_grid(&mut field, 8);
            field.set_progress(0.3);
            Box::new(field)
        };
        let pts = points(5000, 12, scene(true).centre, 4.0, |_| false);
        check_parallel_matches_single_part(make, &pts);
    }

    /// A batch of several MLP chunks gives the results of small batches.
    #[test]
    fn chunked_batch_matches_small_batches() {
        let mut field = small().init::<f64>(scene(true)).expect("valid");
        randomise_grid(&mut field, 8);
        field.set_progress(0.3);
        let pts = points(3000, 13, scene(true).centre, 4.0, |_| false);
        check_batches_agree(&mut field, &pts, 700);
    }

    /// ~200 Adam steps fit a known density and colour function at 2048 fixed random points:
    /// the loss falls 10× below its start and 5× below the best constant's (the targets'
    /// variance), so it cannot pass by fitting a mean.
    #[test]
    fn fits_an_analytic_field() {
        let mut field = HashGridConfig {
            levels: 4,
            log2_table_size: 12,
            base_resolution: 4,
            finest_resolution: 24,
            width: 32,
            c2f: None,
            ..small()
        }
        .init::<f32>(SceneBounds::UNIT)
        .expect("valid");
        let n = 2048;
        let pts = points(n, 21, [0.0; 3], 1.0, |_| false);
        let target = |p: &[f64]| {
            let (x, y, z) = (p[0], p[1], p[2]);
            [
                1.5 + (2.0 * x).sin() * (1.5 * y).cos() + z * z,
                0.5 + 0.4 * (2.0 * x + y).sin(),
                0.5 + 0.4 * (3.0 * z).cos(),
                0.5 + 0.4 * (2.0 * x * y).sin(),
            ]
        };
        let targets: Vec<[f32; 4]> = pts.chunks(3).map(|p| target(p).map(|v| v as f32)).collect();
        let pts: Vec<f32> = pts.iter().map(|&p| p as f32).collect();
        let mut mean = [0.0f64; 4];
        for t in &targets {
            for c in 0..4 {
                mean[c] += f64::from(t[c]) / n as f64;
            }
        }
        let best_constant: f64 = targets
            .iter()
            .map(|t| {
                (0..4)
                    .map(|c| (f64::from(t[c]) - mean[c]).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / n as f64;
        let groups = field.param_groups();
        let mut adam = Adam::<f32>::new(field.num_params());
        let (mut sigma, mut rgb) = (vec![0.0f32; n], vec![0.0f32; 3 * n]);
        let (mut gs, mut gc) = (vec![0.0f32; n], vec![0.0f32; 3 * n]);
        let mut grad = vec![0.0f32; field.num_params()];
        let mut gp = vec![0.0f32; 3 * n];
        let mut losses = Vec::new();
        for _ in 0..200 {
            field.forward(&pts, &mut sigma, &mut rgb);
            // L = mean over points of (σ − σ*)² + ‖rgb − rgb*‖².
            let mut loss = 0.0f64;
            for (i, t) in targets.iter().enumerate() {
                let ds = sigma[i] - t[0];
                gs[i] = 2.0 * ds / n as f32;
                loss += f64::from(ds * ds);
                for c in 0..3 {
                    let dc = rgb[3 * i + c] - t[1 + c];
                    gc[3 * i + c] = 2.0 * dc / n as f32;
                    loss += f64::from(dc * dc);
                }
            }
            losses.push(loss / n as f64);
            grad.fill(0.0);
            field.backward(&gs, &gc, &mut grad, &mut gp);
            adam.begin_step();
            for (name, range) in &groups {
                let lr = if *name == "grid" { 3e-2 } else { 1e-2 };
                let r = range.clone();
                adam.update(r.start, &mut field.params_mut()[r.clone()], &grad[r], lr);
            }
        }
        let (first, last) = (losses[0], losses[losses.len() - 1]);
        assert!(
            last < first / 10.0 && last < best_constant / 5.0,
            "loss {first} → {last} (best constant {best_constant})"
        );
    }

    #[test]
    fn invalid_configs_name_the_key() {
        let cases = [
            (
                HashGridConfig {
                    levels: 0,
                    ..small()
                },
                "levels",
            ),
            (
                HashGridConfig {
                    levels: 33,
                    ..small()
                },
                "levels",
            ),
            (
                HashGridConfig {
                    features: 0,
                    ..small()
                },
                "features",
            ),
            (
                HashGridConfig {
                    features: 9,
                    ..small()
                },
                "features",
            ),
            (
                HashGridConfig {
                    log2_table_size: 9,
                    ..small()
                },
                "log2_table_size",
            ),
            (
                HashGridConfig {
                    log2_table_size: 25,
                    ..small()
                },
                "log2_table_size",
            ),
            (
                HashGridConfig {
                    base_resolution: 0,
                    ..small()
                },
                "base_resolution",
            ),
            (
                HashGridConfig {
                    finest_resolution: 2,
                    ..small()
                },
                "finest_resolution",
            ),
            (
                HashGridConfig {
                    finest_resolution: 70_000,
                    ..small()
                },
                "finest_resolution",
            ),
            (
                HashGridConfig {
                    levels: 1,
                    ..small()
                },
                "finest_resolution",
            ),
            (
                HashGridConfig {
                    width: 0,
                    ..small()
                },
                "width",
            ),
            (
                HashGridConfig {
                    hidden_layers: 0,
                    ..small()
                },
                "hidden_layers",
            ),
            (
                HashGridConfig {
                    init_scale: -1.0,
                    ..small()
                },
                "init_scale",
            ),
            (
                HashGridConfig {
                    init_scale: f64::NAN,
                    ..small()
                },
                "init_scale",
            ),
            (
                HashGridConfig {
                    density_scale: 0.0,
                    ..small()
                },
                "density_scale",
            ),
            (
                HashGridConfig {
                    c2f: Some([0.2, 1.2]),
                    ..small()
                },
                "c2f",
            ),
        ];
        for (bad, key) in cases {
            let err = bad
                .init::<f32>(SceneBounds::UNIT)
                .expect_err("invalid config");
            assert!(
                matches!(&err, Field3dError::Invalid { key: k, .. } if *k == key),
                "{err}"
            );
        }
        let e = HashGridConfig {
            finest_resolution: 2,
            ..small()
        }
        .init::<f32>(SceneBounds::UNIT)
        .expect_err("invalid");
        assert_eq!(
            e.to_string(),
            "invalid finest_resolution: expected ≥ base_resolution (3), got 2"
        );
    }

    #[test]
    fn config_parses_from_toml_and_rejects_typos() {
        let c: HashGridConfig =
            toml::from_str("levels = 6\nc2f = false\nlog2_table_size = 19").expect("valid toml");
        assert_eq!((c.levels, c.c2f, c.log2_table_size), (6, None, 19));
        assert_eq!(
            toml::from_str::<HashGridConfig>("").expect("empty"),
            HashGridConfig::default()
        );
        for text in [
            "level = 3",
            "c2f = true",
            "features = -1",
            "log2_table_size = 1.5",
        ] {
            assert!(toml::from_str::<HashGridConfig>(text).is_err(), "{text}");
        }
        for c in [HashGridConfig::default(), c] {
            let text = toml::to_string(&c).expect("serialises");
            assert_eq!(
                toml::from_str::<HashGridConfig>(&text).expect("round trip"),
                c
            );
        }
    }
}
