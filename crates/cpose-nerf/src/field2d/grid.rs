//! [`GridField`]: dense multi-resolution 2-D feature grids and a tiny MLP.

use std::ops::Range;

use cpose_core::Real;
use cpose_core::nn::{Accum, Activation, Init, Mlp, MlpSpec, MlpWorkspace, coarse_to_fine_weights};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{Field2dError, ImageField, batch_len, sigmoid_backward, sigmoid_forward};
use crate::field_common::{c2f_serde, c2f_window, check_c2f, grow, invalid};

/// Largest accepted `finest_resolution`: a dense level holds `(R + 1)² · F` values.
const MAX_RESOLUTION: usize = 4096;

/// Construction parameters of a [`GridField`] (a TOML table; unknown keys are errors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GridConfig {
    /// Number of grid levels `L`; default 8.
    pub levels: usize,
    /// Features `F` per vertex and level (network input `2 + L·F`); default 2.
    pub features: usize,
    /// Cells per side of the coarsest level over `[−1, 1]`; default 16 (cell = 1/8 of the
    /// long image side).
    pub base_resolution: usize,
    /// Cells per side of the finest level (≤ 4096; equal to `base_resolution` when
    /// `levels = 1`); default 512, about one cell per pixel of a 480-pixel-wide image.
    pub finest_resolution: usize,
    /// Units per hidden layer of the MLP; default 64.
    pub width: usize,
    /// Hidden ReLU layers of the MLP; default 2.
    pub hidden_layers: usize,
    /// Coarse-to-fine window `[start, end]` in fractions of training, `0 ≤ start < end ≤ 1`,
    /// over the levels; `false` in TOML (`None`) weights every level 1. Default `[0.0, 0.4]`.
    #[serde(with = "c2f_serde")]
    pub c2f: Option<[f64; 2]>,
    /// Grid values start as `U(±init_scale)`; default 1e-4 (instant-NGP).
    pub init_scale: f64,
    /// Seed of the initialisation (ChaCha8: the MLP, then the grid); default 0.
    pub seed: u64,
}

impl Default for GridConfig {
    fn default() -> Self {
        Self {
            levels: 8,
            features: 2,
            base_resolution: 16,
            finest_resolution: 512,
            width: 64,
            hidden_layers: 2,
            c2f: Some([0.0, 0.4]),
            init_scale: 1e-4,
            seed: 0,
        }
    }
}

impl GridConfig {
    /// A field at progress 0: the MLP with PyTorch's default `Linear` init
    /// (`W, b ~ U(±1/sqrt(fan_in))`), grid values `U(±init_scale)`.
    pub fn init<S: Real>(&self) -> Result<GridField<S>, Field2dError> {
        if !(1..=32).contains(&self.levels) {
            return invalid("levels", "1 to 32", self.levels);
        }
        if !(1..=64).contains(&self.features) {
            return invalid("features", "1 to 64", self.features);
        }
        if self.base_resolution == 0 {
            return invalid("base_resolution", "at least 1", self.base_resolution);
        }
        if self.finest_resolution > MAX_RESOLUTION {
            return invalid("finest_resolution", "at most 4096", self.finest_resolution);
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
        check_c2f(self.c2f)?;

        let (base, finest) = (self.base_resolution as f64, self.finest_resolution as f64);
        let growth = if self.levels > 1 {
            (finest / base).powf(1.0 / (self.levels - 1) as f64)
        } else {
            1.0
        };
        let mut resolutions = Vec::with_capacity(self.levels);
        let mut offsets = Vec::with_capacity(self.levels + 1);
        offsets.push(0);
        for l in 0..self.levels {
            let r = ((base * growth.powi(l as i32)).round() as usize).max(1);
            resolutions.push(r);
            offsets.push(offsets[l] + (r + 1) * (r + 1) * self.features);
        }
        let grid_len = offsets[self.levels];

        let spec = MlpSpec {
            input_dim: 2 + self.levels * self.features,
            width: self.width,
            depth: self.hidden_layers + 1,
            output_dim: 3,
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

        let mut field = GridField {
            config: self.clone(),
            resolutions,
            offsets,
            weights: vec![0.0; self.levels],
            params,
            mlp,
            ws: Workspace::default(),
        };
        field.set_progress(0.0);
        Ok(field)
    }
}

/// Dense multi-resolution 2-D feature grids with bilinear interpolation and a tiny MLP: a
/// faster neural image than BARF's (instant-NGP's multi-resolution encoding, Müller et al.
/// 2022, without hashing: a dense 2-D grid of a few hundred cells per side is small).
///
/// Level `l < L` has `R_l` cells per side over `[−1, 1]²` (`R_l + 1` vertices), with
/// `R_l = round(R_0 · g^l)`, `g = (R_{L−1}/R_0)^{1/(L−1)}`, and `F` features per vertex. For a
/// point `p = (x, y)`, `u = (clamp(x, −1, 1) + 1)/2 · R_l`, cell `i_0 = min(⌊u⌋, R_l − 1)`,
/// `t_x = u − i_0` (same for `y`), and
/// `f_l(p) = (1−t_x)(1−t_y) v_00 + t_x(1−t_y) v_10 + (1−t_x) t_y v_01 + t_x t_y v_11`.
/// Points outside `[−1, 1]²` read the grid at the nearest border point (clamped, like
/// `grid_sample`'s `padding_mode="border"`): bounded colours, and zero grid derivative along a
/// clamped axis. The network input is `[x, y, w_0 f_0(p), …, w_{L−1} f_{L−1}(p)]` (raw,
/// unclamped `x, y`), then `hidden_layers` ReLU layers of `width` units, a linear layer to 3
/// and a sigmoid. `w_l` are BARF's coarse-to-fine weights with the levels as bands.
///
/// Alignment. The point derivative of a level, `∂f_l/∂x = R_l/2 · ((1−t_y)(v_10 − v_00) +
/// t_y(v_11 − v_01))`, is constant inside a cell and jumps across cell lines, and its scale
/// grows with `R_l`. Early in training only the coarse levels (and the raw coordinates) are
/// weighted in, so the warp gradients come from smooth, wide cells; fine levels — sharper
/// colours, noisier point gradients — enter as `w_l` rises. Grid values typically want a
/// larger learning rate than the MLP (instant-NGP uses 1e-2); [`GridField::grid_range`] and
/// [`GridField::mlp_range`] give the two parameter groups.
///
/// Parameters: the grid values, level by level, vertex `(i, j)` (column `i` along x, row `j`
/// along y) of level `l` at `offset_l + (j·(R_l + 1) + i)·F`, its `F` features contiguous;
/// then the MLP's parameters ([`Mlp::params`] layout). The MLP's own copy of its weights is
/// refreshed from this vector at every forward pass (a few thousand values), so
/// [`ImageField::params_mut`] needs no synchronisation.
#[derive(Clone, Debug)]
pub struct GridField<S: Real = f32> {
    config: GridConfig,
    /// `R_l`, cells per side.
    resolutions: Vec<usize>,
    /// Start of each level in `params` (and the grid's end last).
    offsets: Vec<usize>,
    /// Coarse-to-fine weight `w_l` of each level.
    weights: Vec<f64>,
    params: Vec<S>,
    mlp: Mlp<S>,
    ws: Workspace<S>,
}

/// Buffers of one forward/backward pair (grow with the batch, never shrink).
#[derive(Clone, Debug, Default)]
struct Workspace<S: Real> {
    /// Batch size of the last forward pass.
    n: usize,
    /// Network input `[x, y, w_l f_l]`, `[n × (2 + L·F)]` column-major.
    enc: Vec<S>,
    mlp: MlpWorkspace<S>,
    /// Colours `[n × 3]` column-major.
    rgb: Vec<S>,
    /// `∂L/∂z` of the sigmoid's input, `[n × 3]`.
    grad_z: Vec<S>,
    /// `∂L/∂(network input)`, `[n × (2 + L·F)]`.
    grad_enc: Vec<S>,
}

/// Where a point falls on one level: the index of corner `v_00` and the fractional position.
#[derive(Clone, Copy, Debug)]
struct Cell<S> {
    /// Index of `v_00` in the parameter vector.
    v00: usize,
    /// `(t_x, t_y) ∈ [0, 1]²`.
    t: [S; 2],
    /// Per axis, whether the coordinate was inside `[−1, 1]` (else clamped: zero derivative).
    inside: [bool; 2],
}

/// `u = (clamp(x, −1, 1) + 1)/2 · R`, `i_0 = min(⌊u⌋, R − 1)`; returns `(i_0, u − i_0, inside)`.
#[inline(always)]
fn locate<S: Real>(x: S, res: usize, half_res: S) -> (usize, S, bool) {
    let inside = x >= -S::ONE && x <= S::ONE;
    // `max` first maps NaN to −1, so the index is always valid.
    let u = (x.max(-S::ONE).min(S::ONE) + S::ONE) * half_res;
    // u ≥ 0, so truncation is ⌊u⌋.
    let i0 = (u.to_f64() as usize).min(res - 1);
    (i0, u - S::from_f64(i0 as f64), inside)
}

impl<S: Real> GridField<S> {
    /// The configuration it was built from.
    pub fn config(&self) -> &GridConfig {
        &self.config
    }

    /// Cells per side `R_l` of each level, coarse to fine.
    pub fn resolutions(&self) -> &[usize] {
        &self.resolutions
    }

    /// The current coarse-to-fine weight `w_l` of each level (all 1 without coarse-to-fine).
    pub fn level_weights(&self) -> &[f64] {
        &self.weights
    }

    /// Indices of the grid values in [`ImageField::params`].
    pub fn grid_range(&self) -> Range<usize> {
        0..self.grid_len()
    }

    /// Indices of the MLP's parameters in [`ImageField::params`].
    pub fn mlp_range(&self) -> Range<usize> {
        self.grid_len()..self.params.len()
    }

    fn grid_len(&self) -> usize {
        self.offsets[self.resolutions.len()]
    }

    /// Width of the network input, `2 + L·F`.
    fn input_dim(&self) -> usize {
        2 + self.resolutions.len() * self.config.features
    }

    /// The cell of `(x, y)` on level `l` (`half_res = R_l / 2`).
    #[inline(always)]
    fn cell(&self, l: usize, half_res: S, x: S, y: S) -> Cell<S> {
        let r = self.resolutions[l];
        let (i0, tx, in_x) = locate(x, r, half_res);
        let (j0, ty, in_y) = locate(y, r, half_res);
        Cell {
            v00: self.offsets[l] + (j0 * (r + 1) + i0) * self.config.features,
            t: [tx, ty],
            inside: [in_x, in_y],
        }
    }
}

impl<S: Real> ImageField<S> for GridField<S> {
    fn num_params(&self) -> usize {
        self.params.len()
    }

    fn params(&self) -> &[S] {
        &self.params
    }

    fn params_mut(&mut self) -> &mut [S] {
        &mut self.params
    }

    fn set_progress(&mut self, progress: f64) {
        let [start, end] = c2f_window(self.config.c2f);
        coarse_to_fine_weights(progress, start, end, &mut self.weights);
    }

    fn forward(&mut self, points: &[S], rgb: &mut [S]) {
        let n = batch_len(points, rgb);
        let (dim, nf, grid_len) = (self.input_dim(), self.config.features, self.grid_len());
        self.mlp.params.copy_from_slice(&self.params[grid_len..]);
        let mut ws = std::mem::take(&mut self.ws);
        ws.n = n;
        grow(&mut ws.enc, n * dim);
        grow(&mut ws.rgb, 3 * n);
        let enc = &mut ws.enc[..n * dim];
        for i in 0..n {
            enc[i] = points[2 * i];
            enc[n + i] = points[2 * i + 1];
        }
        let g = &self.params;
        for l in 0..self.resolutions.len() {
            // Columns `2 + l·F ..` hold `w_l f_l(p)`.
            let cols = &mut enc[(2 + l * nf) * n..(2 + (l + 1) * nf) * n];
            if self.weights[l] == 0.0 {
                cols.fill(S::ZERO);
                continue;
            }
            let w = S::from_f64(self.weights[l]);
            let r = self.resolutions[l];
            let half_res = S::from_f64(0.5 * r as f64);
            let row = (r + 1) * nf;
            for i in 0..n {
                let c = self.cell(l, half_res, points[2 * i], points[2 * i + 1]);
                let [tx, ty] = c.t;
                // Bilinear weights of v_00, v_10, v_01, v_11, times w_l.
                let (a, b) = (w * (S::ONE - ty), w * ty);
                let k = [a * (S::ONE - tx), a * tx, b * (S::ONE - tx), b * tx];
                for f in 0..nf {
                    let v = c.v00 + f;
                    cols[f * n + i] =
                        k[0] * g[v] + k[1] * g[v + nf] + k[2] * g[v + row] + k[3] * g[v + row + nf];
                }
            }
        }
        self.mlp.forward(&ws.enc, n, 1, &mut ws.mlp);
        sigmoid_forward(ws.mlp.output(), n, &mut ws.rgb, rgb);
        self.ws = ws;
    }

    fn backward(&mut self, grad_rgb: &[S], grad: &mut [S], grad_points: &mut [S]) {
        let n = self.ws.n;
        let (dim, nf, grid_len) = (self.input_dim(), self.config.features, self.grid_len());
        assert!(
            grad_rgb.len() == 3 * n
                && grad_points.len() == 2 * n
                && grad.len() == self.params.len(),
            "backward needs n × 3 colour, n × 2 point and num_params gradients for n = {n}"
        );
        let mut ws = std::mem::take(&mut self.ws);
        grow(&mut ws.grad_z, 3 * n);
        grow(&mut ws.grad_enc, n * dim);
        sigmoid_backward(&ws.rgb, grad_rgb, n, &mut ws.grad_z);
        ws.grad_enc[..n * dim].fill(S::ZERO);
        let (grad_grid, grad_mlp) = grad.split_at_mut(grid_len);
        self.mlp.backward(
            &ws.enc,
            &mut ws.mlp,
            &ws.grad_z,
            grad_mlp,
            Accum::Add,
            Some(&mut ws.grad_enc),
        );
        // Raw coordinates: ∂L/∂p starts as the network's input gradient of x, y.
        for i in 0..n {
            grad_points[2 * i] = ws.grad_enc[i];
            grad_points[2 * i + 1] = ws.grad_enc[n + i];
        }
        let g = &self.params;
        for l in 0..self.resolutions.len() {
            if self.weights[l] == 0.0 {
                continue;
            }
            let gcols = &ws.grad_enc[(2 + l * nf) * n..(2 + (l + 1) * nf) * n];
            let w = S::from_f64(self.weights[l]);
            let r = self.resolutions[l];
            let half_res = S::from_f64(0.5 * r as f64);
            let row = (r + 1) * nf;
            for i in 0..n {
                let (x, y) = (ws.enc[i], ws.enc[n + i]);
                let c = self.cell(l, half_res, x, y);
                let [tx, ty] = c.t;
                let (sx, sy) = (S::ONE - tx, S::ONE - ty);
                let (mut gtx, mut gty) = (S::ZERO, S::ZERO);
                for f in 0..nf {
                    // g = ∂L/∂f_l = w_l · ∂L/∂(w_l f_l).
                    let gf = w * gcols[f * n + i];
                    let v = [
                        c.v00 + f,
                        c.v00 + f + nf,
                        c.v00 + f + row,
                        c.v00 + f + row + nf,
                    ];
                    // Scatter-add ∂f_l/∂v = bilinear weights.
                    grad_grid[v[0]] += gf * sx * sy;
                    grad_grid[v[1]] += gf * tx * sy;
                    grad_grid[v[2]] += gf * sx * ty;
                    grad_grid[v[3]] += gf * tx * ty;
                    // ∂f_l/∂t_x = (1−t_y)(v_10 − v_00) + t_y(v_11 − v_01); ∂f_l/∂t_y likewise.
                    let (v00, v10, v01, v11) = (g[v[0]], g[v[1]], g[v[2]], g[v[3]]);
                    gtx += gf * (sy * (v10 - v00) + ty * (v11 - v01));
                    gty += gf * (sx * (v01 - v00) + tx * (v11 - v10));
                }
                // ∂t/∂x = R_l/2 inside [−1, 1], 0 where the coordinate was clamped.
                if c.inside[0] {
                    grad_points[2 * i] += gtx * half_res;
                }
                if c.inside[1] {
                    grad_points[2 * i + 1] += gty * half_res;
                }
            }
        }
        self.ws = ws;
    }
}

#[cfg(test)]
mod tests {
    use rand::seq::index::sample;

    use super::super::test_support::{assert_f32_matches_f64, check_gradients, points};
    use super::*;

    /// Resolutions 4, 8, 16, 32; two features; MLP 10 → 16 → 16 → 3.
    fn small() -> GridConfig {
        GridConfig {
            levels: 4,
            features: 2,
            base_resolution: 4,
            finest_resolution: 32,
            width: 16,
            hidden_layers: 2,
            c2f: Some([0.05, 0.45]),
            init_scale: 1e-4,
            seed: 3,
        }
    }

    /// Grid values `U(±0.5)` so that interpolation (and its point derivative) is not
    /// negligible next to the raw-coordinate path.
    fn randomise_grid(field: &mut GridField<f64>, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let range = field.grid_range();
        for v in &mut field.params_mut()[range] {
            *v = rng.random_range(-0.5..0.5);
        }
    }

    /// Whether `(x, y)` lies within `1e-3` cells of a cell line of any level of `field` (a kink
    /// of the bilinear interpolation, where central differences straddle two pieces).
    fn near_cell_line(field: &GridField<f64>, x: f64, y: f64) -> bool {
        field.resolutions().iter().any(|&r| {
            [x, y].iter().any(|&c| {
                let u = (c + 1.0) / 2.0 * r as f64;
                (u - u.round()).abs() < 1e-3
            })
        })
    }

    /// Grid values (those under the test points on every level, and a random sample) and MLP
    /// parameters, and points, against central differences at progress 0.3: `α = 0.625 · 4 =
    /// 2.5`, weights `[1, 1, 0.5, 0]`. Two points lie outside `[−1, 1]` in x (clamped).
    #[test]
    fn gradients_match_central_differences() {
        for (progress, c2f) in [(0.3, Some([0.05, 0.45])), (0.0, None)] {
            let mut field = GridConfig { c2f, ..small() }.init::<f64>().expect("valid");
            field.set_progress(progress);
            if c2f.is_some() {
                let want = [1.0, 1.0, 0.5, 0.0];
                let w = field.level_weights();
                assert!(
                    w.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12),
                    "{w:?}"
                );
            }
            randomise_grid(&mut field, 11);
            let mut pts = points(10, 6, |x, y| near_cell_line(&field, x, y));
            pts.extend([1.13, 0.31, -1.2, -0.43]);
            let mut rng = ChaCha8Rng::seed_from_u64(2);
            let mut idx: Vec<usize> = sample(&mut rng, field.grid_len(), 40).into_vec();
            for p in pts.chunks(2).take(4) {
                for l in 0..4 {
                    let half = 0.5 * field.resolutions()[l] as f64;
                    let c = field.cell(l, half, p[0], p[1]);
                    let row = (field.resolutions()[l] + 1) * 2;
                    idx.extend([c.v00, c.v00 + 3, c.v00 + row, c.v00 + row + 3]);
                }
            }
            let mlp = field.mlp_range();
            idx.extend(
                sample(&mut rng, mlp.len(), 40)
                    .iter()
                    .map(|k| mlp.start + k),
            );
            // Bilinear in the grid, smooth elsewhere: truncation ~h²·|L'''| ≪ 1e-6.
            check_gradients(&mut field, &pts, &idx, 1e-6);
        }
    }

    /// With the raw coordinates cut from the network, a point beyond the border has the
    /// colour of the clamped point.
    #[test]
    fn points_outside_are_clamped_to_the_border() {
        let mut field = small().init::<f64>().expect("valid");
        field.set_progress(1.0);
        randomise_grid(&mut field, 1);
        let (start, dim) = (field.mlp_range().start, field.input_dim());
        for unit in 0..16 {
            field.params_mut()[start + unit * dim] = 0.0;
            field.params_mut()[start + unit * dim + 1] = 0.0;
        }
        let mut a = [0.0; 6];
        let mut b = [0.0; 6];
        field.forward(&[1.4, 0.2, -0.3, -2.0], &mut a);
        field.forward(&[1.0, 0.2, -0.3, -1.0], &mut b);
        assert_eq!(a, b);
        let mut grad = vec![0.0; field.num_params()];
        let mut gp = [0.0; 4];
        field.forward(&[1.4, 0.2, -0.3, -2.0], &mut a);
        field.backward(&[1.0; 6], &mut grad, &mut gp);
        assert!(
            gp[0] == 0.0 && gp[3] == 0.0 && gp[1] != 0.0 && gp[2] != 0.0,
            "{gp:?}"
        );
    }

    #[test]
    fn colours_lie_in_the_unit_interval_and_levels_follow_the_schedule() {
        let mut field = small().init::<f64>().expect("valid");
        assert_eq!(field.resolutions(), [4, 8, 16, 32]);
        assert!(field.level_weights().iter().all(|&w| w == 0.0));
        field.set_progress(1.0);
        assert!(field.level_weights().iter().all(|&w| w == 1.0));
        let np = field.num_params();
        field.params_mut()[np - 3] = 20.0;
        field.params_mut()[np - 1] = -20.0;
        randomise_grid(&mut field, 3);
        let pts = points(200, 9, |_, _| false);
        let mut rgb = vec![0.0; 600];
        field.forward(&pts, &mut rgb);
        assert!(rgb.iter().all(|&c| c > 0.0 && c < 1.0));
        assert!(rgb.chunks(3).all(|c| c[0] > 0.99 && c[2] < 0.01));
        let d = GridConfig::default().init::<f32>().expect("valid");
        assert_eq!(d.resolutions(), [16, 26, 43, 71, 116, 190, 312, 512]);
    }

    #[test]
    fn init_is_deterministic_and_grid_values_are_small() {
        let a = small().init::<f64>().expect("valid");
        let b = small().init::<f64>().expect("valid");
        assert_eq!(a.params(), b.params());
        let c = GridConfig { seed: 4, ..small() }
            .init::<f64>()
            .expect("valid");
        assert_ne!(a.params()[a.grid_range()], c.params()[c.grid_range()]);
        assert_ne!(a.params()[a.mlp_range()], c.params()[c.mlp_range()]);
        let f = small().init::<f32>().expect("valid");
        assert!(
            a.params()
                .iter()
                .zip(f.params())
                .all(|(&a, &f)| a as f32 == f)
        );
        let grid = &a.params()[a.grid_range()];
        assert!(grid.iter().all(|v| v.abs() < 1e-4) && grid.iter().any(|&v| v != 0.0));
        let vertices: usize = [4, 8, 16, 32].iter().map(|r| (r + 1) * (r + 1)).sum();
        assert_eq!(a.grid_range(), 0..vertices * 2);
        assert_eq!(
            a.mlp_range().len(),
            10 * 16 + 16 + 16 * 16 + 16 + 16 * 3 + 3
        );
    }

    /// f32 and f64 fields with the same parameters agree (forward to 1e-5; backward relative
    /// to its scale).
    #[test]
    fn f32_agrees_with_f64() {
        let mut a = small().init::<f64>().expect("valid");
        randomise_grid(&mut a, 5);
        let mut b = small().init::<f32>().expect("valid");
        for (p32, &p64) in b.params_mut().iter_mut().zip(a.params()) {
            *p32 = p64 as f32;
        }
        a.set_progress(0.3);
        b.set_progress(0.3);
        assert_f32_matches_f64(&mut a, &mut b, &points(64, 2, |_, _| false));
    }

    #[test]
    fn invalid_configs_name_the_key() {
        for (bad, key) in [
            (
                GridConfig {
                    levels: 0,
                    ..small()
                },
                "levels",
            ),
            (
                GridConfig {
                    features: 0,
                    ..small()
                },
                "features",
            ),
            (
                GridConfig {
                    base_resolution: 0,
                    ..small()
                },
                "base_resolution",
            ),
            (
                GridConfig {
                    finest_resolution: 2,
                    ..small()
                },
                "finest_resolution",
            ),
            (
                GridConfig {
                    finest_resolution: 5000,
                    ..small()
                },
                "finest_resolution",
            ),
            (
                GridConfig {
                    levels: 1,
                    ..small()
                },
                "finest_resolution",
            ),
            (
                GridConfig {
                    width: 0,
                    ..small()
                },
                "width",
            ),
            (
                GridConfig {
                    hidden_layers: 0,
                    ..small()
                },
                "hidden_layers",
            ),
            (
                GridConfig {
                    init_scale: -1.0,
                    ..small()
                },
                "init_scale",
            ),
            (
                GridConfig {
                    c2f: Some([0.2, 1.2]),
                    ..small()
                },
                "c2f",
            ),
        ] {
            let err = bad.init::<f32>().expect_err("invalid config");
            assert!(
                matches!(&err, Field2dError::Invalid { key: k, .. } if *k == key),
                "{err}"
            );
        }
        let e = GridConfig {
            finest_resolution: 2,
            ..small()
        }
        .init::<f32>()
        .expect_err("invalid");
        assert_eq!(
            e.to_string(),
            "invalid finest_resolution: expected ≥ base_resolution (4), got 2"
        );
    }

    #[test]
    fn config_parses_from_toml_and_rejects_typos() {
        let c: GridConfig =
            toml::from_str("levels = 6\nc2f = false\ninit_scale = 1e-3").expect("valid toml");
        assert_eq!((c.levels, c.c2f, c.init_scale), (6, None, 1e-3));
        assert_eq!(
            toml::from_str::<GridConfig>("").expect("empty"),
            GridConfig::default()
        );
        for text in ["level = 3", "c2f = true", "features = -1"] {
            assert!(toml::from_str::<GridConfig>(text).is_err(), "{text}");
        }
        for c in [GridConfig::default(), c] {
            let text = toml::to_string(&c).expect("serialises");
            assert_eq!(toml::from_str::<GridConfig>(&text).expect("round trip"), c);
        }
    }
}
