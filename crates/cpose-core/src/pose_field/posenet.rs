//! PoseNet (paper §3.1; the authors' `PoseNet.py`, docs/methods.md §1.1): a camera trajectory as
//! two small MLPs of normalised time.
//!
//! `t_n = w · (2(t − t_min)/(t_max − t_min) − 1)` with `w` = `time_span` (1 in the paper),
//! `γ(t_n) = [t_n, sin(2^k π t_n), cos(2^k π t_n)]` (`k < F`), then a translation network
//! `o = f_T(γ)` (3 outputs) and a rotation network `r = f_R(γ)` (4 outputs), each `depth`
//! linear layers of `width` units with `[h, γ]` fed to the skip layer. Heads: `p = s · tanh(o)`
//! and `q = a/‖a‖` with `a = (1 − tanh r_0, tanh r_1, tanh r_2, tanh r_3)` (w, x, y, z), so
//! `q_w > 0`. The last layers start at `U(0, 1e-6)`, which makes the field the identity pose at
//! initialisation.
//!
//! Time derivatives are exact: the networks carry the tangent streams `d/dt_n`, `d²/dt_n²` and
//! the chain rule gives `d/dt = rate · d/dt_n`, `d²/dt² = rate² · d²/dt_n²` with
//! `rate = 2w/(t_max − t_min)`.
//!
//! With `w = 1` each band repeats a whole number of times over the range, so the first and the
//! last time share every sine and cosine: the network starts out treating time as a circle.
//! An open trajectory whose ends must differ (noise that drifts from the first frame, a scan)
//! learns better with `w = 0.5` (measured in `docs/results/nerf.md`).
//!
//! # Choosing the bands
//!
//! Band `k` has a period of `T / (w · 2^k)` seconds over a range of `T` seconds. Fitted to poses
//! every `Δ` seconds, a band whose period is shorter than a few sample intervals can pass
//! through every sample and still swing between them: the fit is exact on the samples and
//! wrong everywhere else. Take the largest `F` whose finest band spans at least four sample
//! intervals, `T / (w · 2^(F−1)) ≥ 4Δ`, i.e. `F = ⌊1 + log2(T / (4wΔ))⌋`
//! ([`bands_for_spacing`]). Fewer bands interpolate positions more smoothly, more bands follow
//! fast turns; beyond the rule the held-out error grows several-fold while the samples are still
//! fitted exactly (measured on a synthetic and a real flight in `docs/results/trajectory.md`).
//! A config table of kind `"posenet"` without `bands` takes this rule from the times it is
//! fitted to ([`crate::registry::FieldContext::frame_times_secs`]).

use faer::Accum;
use nalgebra::{Quaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{Order, ParamKind, PoseBatch, PoseField, PoseFieldError, check_times};
use crate::nn::{self, Activation, Embedding, Encoding, Init, Mlp, MlpSpec, MlpWorkspace};
use crate::{Real, TimeRange};

/// Construction parameters of a [`PoseNet`] (a TOML table; unknown keys are errors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PoseNetConfig {
    /// Frequency bands `F` of the sinusoidal time embedding (width `1 + 2F`); default 5.
    pub bands: usize,
    /// Linear layers per network; default 8.
    pub depth: usize,
    /// Units per hidden layer; default 256.
    pub width: usize,
    /// Layer that reads `[h, γ]` (1 ≤ skip < depth); 0 disables the skip; default 4.
    pub skip_layer: usize,
    /// Hidden activation, `"relu"` (default) or `"softplus"` (use it when time derivatives are
    /// supervised; `"tanh"` and `"sigmoid"` also work).
    pub activation: Activation,
    /// Time encoding, `"sinusoidal"` (default) or `"linear"` (`γ(t) = t_n`, the ablation).
    pub encoding: Encoding,
    /// One network with 7 outputs (3 translation, 4 rotation) instead of two; default false.
    pub coupled: bool,
    /// Bound `s` of the translation head `p = s · tanh(o)`, in the trajectory's length unit
    /// (metres or scene units); default 1 (the authors' `(−1, 1)`).
    pub translation_scale: f64,
    /// Half-width `w` of the interval `[−w, w]` the time range maps to; default 1 (the
    /// authors'). 0.5 suits open trajectories (module docs).
    pub time_span: f64,
    /// Coarse-to-fine window `[start, end]` over the time bands (BARF's schedule applied to
    /// time, driven by [`PoseField::set_progress`]); `end ≤ start` (default `[0, 0]`) keeps every
    /// band on, as the paper.
    pub c2f: [f64; 2],
    /// Seed of the weight initialisation (ChaCha8); default 0.
    pub seed: u64,
}

impl Default for PoseNetConfig {
    fn default() -> Self {
        Self {
            bands: 5,
            depth: 8,
            width: 256,
            skip_layer: 4,
            activation: Activation::Relu,
            encoding: Encoding::Sinusoidal,
            coupled: false,
            translation_scale: 1.0,
            time_span: 1.0,
            c2f: [0.0, 0.0],
            seed: 0,
        }
    }
}

/// The bands `F` for poses every `spacing_secs` over `range`: the largest `F` in `1..=24` whose
/// finest period spans at least four sample intervals, `F = ⌊1 + log2(T / (4 w Δ))⌋` (module
/// docs, "Choosing the bands"); `time_span` is `w`.
pub fn bands_for_spacing(range: TimeRange, spacing_secs: f64, time_span: f64) -> usize {
    let ratio = range.duration_secs() / (4.0 * time_span * spacing_secs);
    if !(ratio.is_finite() && ratio > 0.0) {
        return 1;
    }
    (1.0 + ratio.log2()).floor().clamp(1.0, 24.0) as usize
}

impl PoseNetConfig {
    /// The `[posenet]` table at the defaults, commented, for tasks' default configs.
    pub const DEFAULT_TABLE: &str = include_str!("../../defaults/posenet.toml");

    /// These settings as a pose-field table (`kind = "posenet"` and every key), as the registry
    /// reads it: what a saved field records ([`crate::pose_field::saved`]).
    pub fn field_table(&self) -> String {
        let keys = toml::to_string(self).expect("PoseNet's settings serialise to TOML");
        format!("kind = \"posenet\"\n{keys}")
    }

    /// The settings of a config table (defaults when it is absent), the seed offset by the
    /// run's `seed`.
    pub fn from_section(
        section: &crate::Section<'_>,
        seed: u64,
    ) -> Result<Self, crate::ConfigError> {
        let mut config: Self = if section.exists()? {
            section.decode_params()?
        } else {
            Self::default()
        };
        config.seed = config.seed.wrapping_add(seed);
        Ok(config)
    }

    /// The most weights [`PoseNetConfig::init`] allocates (fifty million, 200 MB in `f32`).
    pub const MAX_WEIGHTS: usize = 50_000_000;

    /// A PoseNet over `range` with freshly initialised weights: Xavier-uniform (gain 1, bias 0)
    /// for all layers but the last, `U(0, 1e-6)` weights and zero bias for the last; translation
    /// network first, then rotation, from one seeded generator.
    pub fn init<S: Real>(&self, range: TimeRange) -> Result<PoseNet<S>, PoseFieldError> {
        let invalid = |m: String| Err(PoseFieldError::Invalid(m));
        if self.encoding == Encoding::Sinusoidal && !(1..=24).contains(&self.bands) {
            return invalid(format!("bands = {} must be in 1..=24", self.bands));
        }
        if self.depth < 2 || self.width == 0 {
            return invalid(format!(
                "depth = {} must be ≥ 2 and width = {} ≥ 1",
                self.depth, self.width
            ));
        }
        // Sizes are checked before the weights are allocated: two networks of about
        // depth × width² weights each.
        let weights = 2.0 * self.depth as f64 * self.width as f64 * (self.width as f64 + 1.0);
        if weights > Self::MAX_WEIGHTS as f64 {
            return invalid(format!(
                "depth = {} and width = {} give about {weights:.2e} weights; at most {} \
                 (the paper's 8 × 256 has about 1e6)",
                self.depth,
                self.width,
                Self::MAX_WEIGHTS
            ));
        }
        if self.skip_layer >= self.depth {
            return invalid(format!(
                "skip_layer = {} must be below depth = {}",
                self.skip_layer, self.depth
            ));
        }
        if !(self.translation_scale.is_finite() && self.translation_scale > 0.0) {
            return invalid(format!(
                "translation_scale = {} must be positive",
                self.translation_scale
            ));
        }
        if !(self.time_span.is_finite() && self.time_span > 0.0) {
            return invalid(format!("time_span = {} must be positive", self.time_span));
        }
        let [c2f_start, c2f_end] = self.c2f;
        if !(0.0..=1.0).contains(&c2f_start) || !(0.0..=1.0).contains(&c2f_end) {
            return invalid(format!(
                "c2f = [{c2f_start}, {c2f_end}] must lie in [0, 1] (fractions of training)"
            ));
        }
        let mut embedding = Embedding::new(self.encoding, 1, self.bands);
        embedding.set_coarse_to_fine(0.0, c2f_start, c2f_end);
        let spec = |output_dim| MlpSpec {
            input_dim: embedding.output_dim(),
            width: self.width,
            depth: self.depth,
            output_dim,
            skip_layer: (self.skip_layer > 0).then_some(self.skip_layer),
            activation: self.activation,
            hidden_init: Init::XavierUniform { gain: 1.0 },
            output_init: Init::Uniform { lo: 0.0, hi: 1e-6 },
        };
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let nets = if self.coupled {
            vec![Mlp::new(spec(7), &mut rng)]
        } else {
            vec![Mlp::new(spec(3), &mut rng), Mlp::new(spec(4), &mut rng)]
        };
        Ok(PoseNet {
            config: self.clone(),
            range,
            embedding,
            nets,
            ws: Workspace::default(),
        })
    }
}

/// The paper's continuous pose network; see the [module docs](self).
///
/// ```
/// use cpose_core::pose_field::posenet::bands_for_spacing;
/// use cpose_core::{Order, PoseBatch, PoseField, PoseNetConfig, TimeRange};
///
/// // Poses every 0.2 s over 4 s: the rule picks the bands, the rest are the paper's defaults.
/// let range = TimeRange::new(0.0, 4.0).expect("start < end");
/// let bands = bands_for_spacing(range, 0.2, 1.0);
/// let config = PoseNetConfig { bands, ..PoseNetConfig::default() };
/// let field = config.init::<f32>(range)?;
/// assert_eq!(bands, 3);
/// // Freshly initialised, it is the identity everywhere, with exact derivatives.
/// let mut out = PoseBatch::default();
/// field.evaluate(&[0.0, 1.7, 4.0], Order::Velocity, &mut out)?;
/// assert!(out.world_from_body(1).translation.vector.norm() < 1e-4);
/// assert!(out.ang_vel_body(1).norm() < 1e-3);
/// // Its parameters, for an optimiser: translation network first, then rotation.
/// assert_eq!(field.networks().len(), 2);
/// # Ok::<(), cpose_core::PoseFieldError>(())
/// ```
#[derive(Clone, Debug)]
pub struct PoseNet<S: Real = f32> {
    config: PoseNetConfig,
    range: TimeRange,
    embedding: Embedding,
    /// `[translation, rotation]`, or `[pose]` when coupled.
    nets: Vec<Mlp<S>>,
    ws: Workspace<S>,
}

/// One contiguous slice of the batch, processed on one thread.
#[derive(Clone, Debug, Default)]
struct Part<S: Real> {
    b: usize,
    /// Normalised time and its tangents `[t_n; 1; 0]`.
    x: Vec<f64>,
    embed: Vec<S>,
    nets: Vec<MlpWorkspace<S>>,
    /// Cotangents of the raw network outputs, per network.
    gout: Vec<Vec<S>>,
    /// This part's parameter gradient (parts after the first).
    grad: Vec<S>,
}

/// Buffers of the last forward pass.
#[derive(Clone, Debug, Default)]
struct Workspace<S: Real> {
    parts: Vec<Part<S>>,
    used: usize,
    times: Vec<f64>,
    /// Order of the cached forward pass over `times`; `None` if nothing is cached.
    order: Option<Order>,
}

type Streams<T> = [T; 3];

fn dot(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

/// `acc += s · v`.
fn axpy(acc: &mut [f64; 4], s: f64, v: &[f64; 4]) {
    for k in 0..4 {
        acc[k] += s * v[k];
    }
}

/// `q = a/‖a‖` with tangents: `n = ‖a‖`, `ṅ = q·ȧ`, `q̇ = (ȧ − q ṅ)/n`,
/// `n̈ = q̇·ȧ + q·ä`, `q̈ = (ä − 2 q̇ ṅ − q n̈)/n`.
fn normalize_forward(a: &Streams<[f64; 4]>, streams: usize) -> Streams<[f64; 4]> {
    let n = dot(&a[0], &a[0]).sqrt();
    let q = a[0].map(|v| v / n);
    let mut out = [q, [0.0; 4], [0.0; 4]];
    if streams >= 2 {
        let n1 = dot(&q, &a[1]);
        let q1: [f64; 4] = std::array::from_fn(|k| (a[1][k] - q[k] * n1) / n);
        out[1] = q1;
        if streams >= 3 {
            let n2 = dot(&q1, &a[1]) + dot(&q, &a[2]);
            out[2] = std::array::from_fn(|k| (a[2][k] - 2.0 * q1[k] * n1 - q[k] * n2) / n);
        }
    }
    out
}

/// Reverse of [`normalize_forward`]: cotangents `g` of `(q, q̇, q̈)` ↦ cotangents of `(a, ȧ, ä)`,
/// the steps of the forward pass adjoined in reverse order.
fn normalize_backward(
    a: &Streams<[f64; 4]>,
    g: &Streams<[f64; 4]>,
    streams: usize,
) -> Streams<[f64; 4]> {
    let n = dot(&a[0], &a[0]).sqrt();
    let q = a[0].map(|v| v / n);
    let [mut gq, mut gq1, gq2] = *g;
    let (mut gn, mut gn1) = (0.0, 0.0);
    let mut ga = [[0.0; 4]; 3];
    if streams >= 2 {
        let n1 = dot(&q, &a[1]);
        let q1: [f64; 4] = std::array::from_fn(|k| (a[1][k] - q[k] * n1) / n);
        if streams >= 3 {
            let n2 = dot(&q1, &a[1]) + dot(&q, &a[2]);
            let q2: [f64; 4] =
                std::array::from_fn(|k| (a[2][k] - 2.0 * q1[k] * n1 - q[k] * n2) / n);
            // q̈ = (ä − 2 q̇ ṅ − q n̈)/n
            axpy(&mut ga[2], 1.0 / n, &gq2);
            axpy(&mut gq1, -2.0 * n1 / n, &gq2);
            gn1 -= 2.0 * dot(&q1, &gq2) / n;
            axpy(&mut gq, -n2 / n, &gq2);
            let gn2 = -dot(&q, &gq2) / n;
            gn -= dot(&q2, &gq2) / n;
            // n̈ = q̇·ȧ + q·ä
            axpy(&mut gq1, gn2, &a[1]);
            axpy(&mut ga[1], gn2, &q1);
            axpy(&mut gq, gn2, &a[2]);
            axpy(&mut ga[2], gn2, &q);
        }
        // q̇ = (ȧ − q ṅ)/n
        axpy(&mut ga[1], 1.0 / n, &gq1);
        axpy(&mut gq, -n1 / n, &gq1);
        gn1 -= dot(&q, &gq1) / n;
        gn -= dot(&q1, &gq1) / n;
        // ṅ = q·ȧ
        axpy(&mut gq, gn1, &a[1]);
        axpy(&mut ga[1], gn1, &q);
    }
    // q = a/n, n = ‖a‖
    axpy(&mut ga[0], 1.0 / n, &gq);
    gn -= dot(&q, &gq) / n;
    axpy(&mut ga[0], gn, &q);
    ga
}

/// Where the heads read the raw outputs: `(network, first column)` of translation and rotation.
fn head_columns(coupled: bool) -> [(usize, usize); 2] {
    if coupled {
        [(0, 0), (0, 3)]
    } else {
        [(0, 0), (1, 0)]
    }
}

impl<S: Real> Part<S> {
    /// Raw output column `col` of network `net`, streams of local sample `i`.
    fn raw(&self, net: usize, col: usize, i: usize) -> Streams<f64> {
        let ws = &self.nets[net];
        let (b, streams) = ws.shape();
        let base = col * streams * b + i;
        std::array::from_fn(|s| {
            if s < streams {
                ws.output()[base + s * b].to_f64()
            } else {
                0.0
            }
        })
    }

    /// Heads at local sample `i` in normalised time: `(p, ṗ, p̈)` and `(a, ȧ, ä)` before the
    /// normalisation `q = a/‖a‖`.
    fn heads(
        &self,
        coupled: bool,
        scale: f64,
        streams: usize,
        i: usize,
    ) -> (Streams<[f64; 3]>, Streams<[f64; 4]>) {
        let [(tn, tc), (rn, rc)] = head_columns(coupled);
        let mut p = [[0.0; 3]; 3];
        for k in 0..3 {
            let u = Activation::Tanh.tangent_forward(self.raw(tn, tc + k, i), streams);
            for s in 0..3 {
                p[s][k] = scale * u[s];
            }
        }
        let mut a = [[0.0; 4]; 3];
        for k in 0..4 {
            let u = Activation::Tanh.tangent_forward(self.raw(rn, rc + k, i), streams);
            for s in 0..3 {
                // a_0 = 1 − tanh r_0, a_k = tanh r_k.
                a[s][k] = if k > 0 {
                    u[s]
                } else if s == 0 {
                    1.0 - u[0]
                } else {
                    -u[s]
                };
            }
        }
        (p, a)
    }

    /// Writes the cotangents of the raw outputs at local sample `i`, given those of
    /// `(p, ṗ, p̈)` and `(q, q̇, q̈)` in normalised time.
    fn heads_backward(
        &mut self,
        coupled: bool,
        scale: f64,
        streams: usize,
        i: usize,
        gp: &Streams<[f64; 3]>,
        gq: &Streams<[f64; 4]>,
    ) {
        let (_, a) = self.heads(coupled, scale, streams, i);
        let ga = normalize_backward(&a, gq, streams);
        let [(tn, tc), (rn, rc)] = head_columns(coupled);
        let b = self.b;
        for k in 0..3 {
            let gu = [0, 1, 2].map(|s| scale * gp[s][k]);
            let go = Activation::Tanh.tangent_backward(self.raw(tn, tc + k, i), gu, streams);
            for s in 0..streams {
                self.gout[tn][(tc + k) * streams * b + s * b + i] = S::from_f64(go[s]);
            }
        }
        for k in 0..4 {
            let gu = [0, 1, 2].map(|s| if k == 0 { -ga[s][k] } else { ga[s][k] });
            let gr = Activation::Tanh.tangent_backward(self.raw(rn, rc + k, i), gu, streams);
            for s in 0..streams {
                self.gout[rn][(rc + k) * streams * b + s * b + i] = S::from_f64(gr[s]);
            }
        }
    }
}

fn quat(v: &[f64; 4]) -> Quaternion<f64> {
    Quaternion::new(v[0], v[1], v[2], v[3])
}

/// `[w, x, y, z]` of entry `i`, zero if the vector is empty (a zero cotangent).
fn quat_or_zero(v: &[Quaternion<f64>], i: usize) -> [f64; 4] {
    v.get(i).map_or([0.0; 4], |q| [q.w, q.i, q.j, q.k])
}

fn vec_or_zero(v: &[Vector3<f64>], i: usize) -> [f64; 3] {
    v.get(i).map_or([0.0; 3], |p| [p.x, p.y, p.z])
}

impl<S: Real> PoseNet<S> {
    /// The configuration it was built from.
    pub fn config(&self) -> &PoseNetConfig {
        &self.config
    }

    /// The networks: `[translation, rotation]`, or `[pose]` when coupled.
    pub fn networks(&self) -> &[Mlp<S>] {
        &self.nets
    }

    /// Forward pass into `ws` and `out`, shared by `evaluate` (temporary workspace) and
    /// `forward` (cached workspace).
    fn run_forward(
        &self,
        ws: &mut Workspace<S>,
        times: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times)?;
        let n = times.len();
        let streams = order as usize + 1;
        // Two threads go to the two networks of the decoupled PoseNet (equal work, no partial
        // gradients to add); the coupled one splits its batch instead.
        let parts = if self.nets.len() > 1 && rayon::current_num_threads() > 1 {
            1
        } else {
            nn::batch_parts(n * streams)
        };
        if ws.parts.len() < parts {
            ws.parts.resize_with(parts, Part::default);
        }
        ws.used = parts;
        let (range, span) = (self.range, self.config.time_span);
        let run = |p: usize, part: &mut Part<S>| {
            let r = nn::part_range(n, parts, p);
            let b = r.len();
            part.b = b;
            part.x.clear();
            part.x
                .extend(times[r].iter().map(|&t| span * range.normalize(t)));
            part.x.resize(streams * b, 0.0);
            if streams >= 2 {
                part.x[b..2 * b].fill(1.0);
            }
            let e = streams * b * self.embedding.output_dim();
            if part.embed.len() < e {
                part.embed.resize(e, S::ZERO);
            }
            self.embedding.encode(&part.x, b, streams, &mut part.embed);
            part.nets
                .resize_with(self.nets.len(), MlpWorkspace::default);
            let embed = &part.embed;
            if parts == 1 && self.nets.len() > 1 {
                self.nets
                    .par_iter()
                    .zip(part.nets.par_iter_mut())
                    .for_each(|(mlp, w)| mlp.forward(embed, b, streams, w));
            } else {
                for (mlp, w) in self.nets.iter().zip(&mut part.nets) {
                    mlp.forward(embed, b, streams, w);
                }
            }
        };
        if parts == 1 {
            run(0, &mut ws.parts[0]);
        } else {
            ws.parts[..parts]
                .par_iter_mut()
                .enumerate()
                .for_each(|(p, part)| run(p, part));
        }
        out.reset(n, order);
        let rate = span * range.normalized_rate();
        let (coupled, scale) = (self.config.coupled, self.config.translation_scale);
        for (p, part) in ws.parts[..parts].iter().enumerate() {
            let start = nn::part_range(n, parts, p).start;
            for i in 0..part.b {
                let (pos, a) = part.heads(coupled, scale, streams, i);
                let q = normalize_forward(&a, streams);
                let j = start + i;
                out.rotation[j] = quat(&q[0]);
                out.translation[j] = Vector3::from(pos[0]);
                if streams >= 2 {
                    out.rotation_rate[j] = quat(&q[1]) * rate;
                    out.lin_vel_world[j] = Vector3::from(pos[1]) * rate;
                }
                if streams >= 3 {
                    out.rotation_acc[j] = quat(&q[2]) * (rate * rate);
                    out.lin_acc_world[j] = Vector3::from(pos[2]) * (rate * rate);
                }
            }
        }
        Ok(())
    }
}

impl<S: Real> PoseField<S> for PoseNet<S> {
    fn time_range(&self) -> TimeRange {
        self.range
    }

    fn set_progress(&mut self, progress: f64) {
        let [start, end] = self.config.c2f;
        self.embedding.set_coarse_to_fine(progress, start, end);
    }

    fn num_params(&self) -> usize {
        self.nets.iter().map(Mlp::num_params).sum()
    }

    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S])) {
        for (j, net) in self.nets.iter().enumerate() {
            visit(self.kind(j), &net.params);
        }
    }

    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S])) {
        for j in 0..self.nets.len() {
            let kind = self.kind(j);
            visit(kind, &mut self.nets[j].params);
        }
    }

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        self.run_forward(&mut Workspace::default(), times_secs, order, out)
    }

    fn forward(
        &mut self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        let mut ws = std::mem::take(&mut self.ws);
        ws.order = None;
        let res = self.run_forward(&mut ws, times_secs, order, out);
        if res.is_ok() {
            ws.times.clear();
            ws.times.extend_from_slice(times_secs);
            ws.order = Some(order);
        }
        self.ws = ws;
        res
    }

    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        let n = times_secs.len();
        if param_grad.len() != self.num_params() {
            return Err(PoseFieldError::Shape {
                what: "param_grad",
                expected: self.num_params(),
                got: param_grad.len(),
            });
        }
        let lens = [
            ("rotation", grad.rotation.len(), Order::Pose),
            ("translation", grad.translation.len(), Order::Pose),
            ("rotation_rate", grad.rotation_rate.len(), Order::Velocity),
            ("lin_vel_world", grad.lin_vel_world.len(), Order::Velocity),
            ("rotation_acc", grad.rotation_acc.len(), Order::Acceleration),
            (
                "lin_acc_world",
                grad.lin_acc_world.len(),
                Order::Acceleration,
            ),
        ];
        let mut needed = Order::Pose;
        for (what, got, order) in lens {
            if got != 0 && got != n {
                return Err(PoseFieldError::Shape {
                    what,
                    expected: n,
                    got,
                });
            }
            if got != 0 {
                needed = needed.max(order);
            }
        }
        let cached = self
            .ws
            .order
            .filter(|&o| o >= needed && self.ws.times == times_secs);
        let order = match cached {
            Some(o) => o,
            None => {
                self.forward(times_secs, needed, &mut PoseBatch::default())?;
                needed
            }
        };
        let streams = order as usize + 1;
        let rate = self.config.time_span * self.range.normalized_rate();
        let (coupled, scale) = (self.config.coupled, self.config.translation_scale);
        let parts = self.ws.used;
        for (p, part) in self.ws.parts[..parts].iter_mut().enumerate() {
            let start = nn::part_range(n, parts, p).start;
            let b = part.b;
            part.gout.resize_with(self.nets.len(), Vec::new);
            for (g, net) in part.gout.iter_mut().zip(&self.nets) {
                let len = streams * b * net.spec().output_dim;
                if g.len() < len {
                    g.resize(len, S::ZERO);
                }
            }
            let scales = [1.0, rate, rate * rate];
            for i in 0..b {
                let j = start + i;
                let gq = [
                    quat_or_zero(&grad.rotation, j),
                    quat_or_zero(&grad.rotation_rate, j),
                    quat_or_zero(&grad.rotation_acc, j),
                ];
                let gp = [
                    vec_or_zero(&grad.translation, j),
                    vec_or_zero(&grad.lin_vel_world, j),
                    vec_or_zero(&grad.lin_acc_world, j),
                ];
                let gq = [0, 1, 2].map(|s| gq[s].map(|v| v * scales[s]));
                let gp = [0, 1, 2].map(|s| gp[s].map(|v| v * scales[s]));
                part.heads_backward(coupled, scale, streams, i, &gp, &gq);
            }
        }
        let nets = &self.nets;
        let total = param_grad.len();
        // Part 0 adds into `param_grad`; the others write their own buffers, summed afterwards.
        let backward_part = |part: &mut Part<S>, grad: &mut [S], accum: Accum| {
            let mut offset = 0;
            for (j, net) in nets.iter().enumerate() {
                let len = net.num_params();
                let g = &mut grad[offset..offset + len];
                net.backward(
                    &part.embed,
                    &mut part.nets[j],
                    &part.gout[j],
                    g,
                    accum,
                    None,
                );
                offset += len;
            }
        };
        let (first, rest) = self.ws.parts[..parts]
            .split_first_mut()
            .expect("at least one part");
        if let ([translation, rotation], true) = (&nets[..], rest.is_empty()) {
            // Decoupled, one part: the two networks run in parallel on their own gradient slices.
            let (g_translation, g_rotation) = param_grad.split_at_mut(translation.num_params());
            let (w_translation, w_rotation) = first.nets.split_at_mut(1);
            let (embed, gout) = (&first.embed, &first.gout);
            rayon::join(
                || {
                    translation.backward(
                        embed,
                        &mut w_translation[0],
                        &gout[0],
                        g_translation,
                        Accum::Add,
                        None,
                    )
                },
                || {
                    rotation.backward(
                        embed,
                        &mut w_rotation[0],
                        &gout[1],
                        g_rotation,
                        Accum::Add,
                        None,
                    )
                },
            );
        } else if rest.is_empty() {
            backward_part(first, param_grad, Accum::Add);
        } else {
            rayon::join(
                || backward_part(first, param_grad, Accum::Add),
                || {
                    rest.par_iter_mut().for_each(|part| {
                        let mut g = std::mem::take(&mut part.grad);
                        g.resize(total, S::ZERO);
                        backward_part(part, &mut g, Accum::Replace);
                        part.grad = g;
                    })
                },
            );
            for part in rest.iter() {
                for (a, &g) in param_grad.iter_mut().zip(&part.grad) {
                    *a += g;
                }
            }
        }
        Ok(())
    }
}

impl<S: Real> PoseNet<S> {
    fn kind(&self, net: usize) -> ParamKind {
        match (self.config.coupled, net) {
            (true, _) => ParamKind::Pose,
            (false, 0) => ParamKind::Translation,
            (false, _) => ParamKind::Rotation,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose_field::params_to_vec;
    use rand::RngExt;

    fn small(activation: Activation) -> PoseNetConfig {
        PoseNetConfig {
            depth: 4,
            width: 16,
            skip_layer: 2,
            activation,
            seed: 11,
            ..PoseNetConfig::default()
        }
    }

    fn range() -> TimeRange {
        TimeRange::new(1.0, 6.0).expect("valid range")
    }

    /// Moves every parameter by U(±0.4) so that the heads see outputs of order 1.
    fn perturb<S: Real>(net: &mut PoseNet<S>, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        net.params_mut(&mut |_, p| {
            for v in p {
                *v += S::from_f64(rng.random_range(-0.4..0.4));
            }
        });
    }

    fn eval(net: &PoseNet<f64>, ts: &[f64], order: Order) -> PoseBatch {
        let mut out = PoseBatch::default();
        net.evaluate(ts, order, &mut out).expect("in range");
        out
    }

    const TIMES: [f64; 5] = [1.3, 2.2, 3.05, 4.7, 5.9];

    /// q̇, q̈, ṗ, p̈ against central differences of evaluated poses (h = 1e-5 s for first, error
    /// ~h²|q'''| ≈ 1e-9; h = 1e-4 s for second, error ~h² + ε/h² ≈ 1e-8).
    fn check_time_derivatives(config: PoseNetConfig) {
        let mut net = config.init::<f64>(range()).expect("valid config");
        perturb(&mut net, 5);
        let out = eval(&net, &TIMES, Order::Acceleration);
        let shifted = |dt: f64| eval(&net, &TIMES.map(|t| t + dt), Order::Pose);
        let (h1, h2) = (1e-5, 1e-4);
        let (p1, m1, p2, m2, c) = (
            shifted(h1),
            shifted(-h1),
            shifted(h2),
            shifted(-h2),
            shifted(0.0),
        );
        for i in 0..TIMES.len() {
            assert!(
                (out.rotation[i].norm() - 1.0).abs() < 1e-12,
                "unit quaternion"
            );
            let fd_q1 = (p1.rotation[i] - m1.rotation[i]) / (2.0 * h1);
            let fd_q2 = (p2.rotation[i] - c.rotation[i] * 2.0 + m2.rotation[i]) / (h2 * h2);
            let fd_p1 = (p1.translation[i] - m1.translation[i]) / (2.0 * h1);
            let fd_p2 =
                (p2.translation[i] - c.translation[i] * 2.0 + m2.translation[i]) / (h2 * h2);
            let tol = |x: f64| 1e-6 * (1.0 + x);
            assert!(
                (fd_q1 - out.rotation_rate[i]).norm() < tol(fd_q1.norm()),
                "q̇ {i}: {fd_q1} vs {}",
                out.rotation_rate[i]
            );
            assert!(
                (fd_p1 - out.lin_vel_world[i]).norm() < tol(fd_p1.norm()),
                "ṗ {i}"
            );
            if config.activation != Activation::Relu {
                assert!(
                    (fd_q2 - out.rotation_acc[i]).norm() < 1e3 * tol(fd_q2.norm()),
                    "q̈ {i}: {fd_q2} vs {}",
                    out.rotation_acc[i]
                );
                assert!(
                    (fd_p2 - out.lin_acc_world[i]).norm() < 1e3 * tol(fd_p2.norm()),
                    "p̈ {i}"
                );
            }
        }
    }

    /// ∂L/∂θ for L = Σ ⟨c, (q, q̇, q̈, p, ṗ, p̈)⟩ with fixed random c, against central differences
    /// (h = 1e-6; tolerance 1e-6 relative).
    fn check_param_gradients(config: PoseNetConfig, order: Order) {
        let mut net = config.init::<f64>(range()).expect("valid config");
        perturb(&mut net, 6);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut cot = PoseBatch::zeros(TIMES.len(), order);
        let mut r = || rng.random_range(-1.0..1.0);
        for i in 0..TIMES.len() {
            cot.rotation[i] = Quaternion::new(r(), r(), r(), r());
            cot.translation[i] = Vector3::new(r(), r(), r());
            if order >= Order::Velocity {
                cot.rotation_rate[i] = Quaternion::new(r(), r(), r(), r());
                cot.lin_vel_world[i] = Vector3::new(r(), r(), r());
            }
            if order >= Order::Acceleration {
                cot.rotation_acc[i] = Quaternion::new(r(), r(), r(), r()) * 0.1;
                cot.lin_acc_world[i] = Vector3::new(r(), r(), r()) * 0.1;
            }
        }
        let loss = |net: &PoseNet<f64>| {
            let o = eval(net, &TIMES, order);
            let mut l = 0.0;
            for i in 0..TIMES.len() {
                l += o.rotation[i].coords.dot(&cot.rotation[i].coords)
                    + o.translation[i].dot(&cot.translation[i]);
                if order >= Order::Velocity {
                    l += o.rotation_rate[i].coords.dot(&cot.rotation_rate[i].coords);
                    l += o.lin_vel_world[i].dot(&cot.lin_vel_world[i]);
                }
                if order >= Order::Acceleration {
                    l += o.rotation_acc[i].coords.dot(&cot.rotation_acc[i].coords);
                    l += o.lin_acc_world[i].dot(&cot.lin_acc_world[i]);
                }
            }
            l
        };
        let mut out = PoseBatch::default();
        net.forward(&TIMES, order, &mut out).expect("in range");
        let mut grad = vec![0.0; net.num_params()];
        net.backward(&TIMES, &cot, &mut grad).expect("shapes match");
        let theta = params_to_vec(&net);
        let h = 1e-6;
        for k in (0..theta.len()).step_by(5) {
            let mut at = |v: f64| {
                let mut th = theta.clone();
                th[k] = v;
                crate::pose_field::params_from_slice(&mut net, &th).expect("length");
                loss(&net)
            };
            let fd = (at(theta[k] + h) - at(theta[k] - h)) / (2.0 * h);
            assert!(
                (fd - grad[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "{order:?} param {k}: {fd} vs {}",
                grad[k]
            );
        }
    }

    /// The shared conformance suite on the smooth variants (ReLU's derivatives jump at kinks,
    /// which central differences across a kink cannot match; its tangents are checked above and
    /// below away from kinks). F = 5 bands over 5 s give periods down to 0.31 s, so the
    /// time-derivative tolerance allows the suite's O(h²) truncation at h = 5e-4 s.
    #[test]
    fn conformance_suite() {
        let tol = crate::testing::Tolerances {
            time_derivative: 1e-4,
            ..Default::default()
        };
        for config in [
            small(Activation::Softplus),
            PoseNetConfig {
                coupled: true,
                ..small(Activation::Tanh)
            },
            PoseNetConfig {
                encoding: Encoding::Linear,
                skip_layer: 0,
                ..small(Activation::Softplus)
            },
            PoseNetConfig {
                time_span: 0.5,
                ..small(Activation::Softplus)
            },
        ] {
            let mut net = config.init::<f64>(range()).expect("valid config");
            perturb(&mut net, 9);
            crate::testing::check_pose_field_with(&mut net, &TIMES, &tol);
        }
    }

    /// Coarse-to-fine on the time bands: all bands off at progress 0, fractional in between
    /// (and still exact derivatives and gradients), and the plain network from `end` on.
    #[test]
    fn coarse_to_fine_schedule_on_time_bands() {
        let plain = small(Activation::Softplus);
        let c2f = PoseNetConfig {
            c2f: [0.1, 0.6],
            ..plain.clone()
        };
        let mut net = c2f.init::<f64>(range()).unwrap();
        let mut reference = plain.init::<f64>(range()).unwrap();
        perturb(&mut net, 3);
        perturb(&mut reference, 3);
        let eval = |n: &PoseNet<f64>| {
            let mut out = PoseBatch::default();
            n.evaluate(&TIMES, Order::Velocity, &mut out).unwrap();
            out
        };
        assert!(net.embedding.weights().iter().all(|&w| w == 0.0));
        assert_ne!(eval(&net).translation, eval(&reference).translation);
        net.set_progress(0.35);
        assert!(net.embedding.weights().iter().any(|&w| w > 0.0 && w < 1.0));
        let tol = crate::testing::Tolerances {
            time_derivative: 1e-4,
            ..Default::default()
        };
        crate::testing::check_pose_field_with(&mut net, &TIMES, &tol);
        net.set_progress(0.6);
        assert_eq!(eval(&net).translation, eval(&reference).translation);
        assert!(
            PoseNetConfig {
                c2f: [0.0, 1.5],
                ..plain
            }
            .init::<f64>(range())
            .is_err()
        );
    }

    #[test]
    fn time_derivatives_softplus() {
        check_time_derivatives(small(Activation::Softplus));
    }

    #[test]
    fn time_derivatives_relu_coupled_linear() {
        check_time_derivatives(small(Activation::Relu));
        check_time_derivatives(PoseNetConfig {
            coupled: true,
            ..small(Activation::Tanh)
        });
        check_time_derivatives(PoseNetConfig {
            encoding: Encoding::Linear,
            translation_scale: 2.5,
            ..small(Activation::Softplus)
        });
    }

    #[test]
    fn parameter_gradients_match_central_differences() {
        check_param_gradients(small(Activation::Softplus), Order::Acceleration);
        check_param_gradients(small(Activation::Relu), Order::Velocity);
        check_param_gradients(
            PoseNetConfig {
                coupled: true,
                ..small(Activation::Softplus)
            },
            Order::Acceleration,
        );
        check_param_gradients(
            PoseNetConfig {
                encoding: Encoding::Linear,
                skip_layer: 0,
                ..small(Activation::Tanh)
            },
            Order::Pose,
        );
    }

    /// The 4-vector normalisation's reverse pass against central differences.
    #[test]
    fn normalisation_adjoint_matches_central_differences() {
        let a = [
            [0.3, -1.2, 0.5, 0.8],
            [0.7, 0.1, -0.4, 0.2],
            [-0.5, 0.9, 0.3, -0.6],
        ];
        let g = [
            [0.2, -0.1, 0.7, 0.4],
            [-0.3, 0.5, 0.1, 0.9],
            [0.6, -0.8, 0.2, 0.3],
        ];
        let loss = |a: &Streams<[f64; 4]>| {
            let q = normalize_forward(a, 3);
            (0..3).map(|s| dot(&q[s], &g[s])).sum::<f64>()
        };
        let ga = normalize_backward(&a, &g, 3);
        for s in 0..3 {
            for k in 0..4 {
                let (mut ap, mut am) = (a, a);
                ap[s][k] += 1e-6;
                am[s][k] -= 1e-6;
                let fd = (loss(&ap) - loss(&am)) / 2e-6;
                assert!(
                    (fd - ga[s][k]).abs() < 1e-8,
                    "stream {s} comp {k}: {fd} vs {}",
                    ga[s][k]
                );
            }
        }
    }

    #[test]
    fn identity_at_init_default_size() {
        let net = PoseNetConfig::default()
            .init::<f64>(range())
            .expect("default config");
        assert_eq!(net.num_params(), 401_411 + 401_668);
        let out = eval(&net, &TIMES, Order::Velocity);
        for i in 0..TIMES.len() {
            let q = out.rotation[i];
            assert!((q.w - 1.0).abs() < 1e-6 && q.imag().norm() < 2e-3, "{q}");
            assert!(out.translation[i].norm() < 2e-3);
        }
    }

    #[test]
    fn f32_agrees_with_f64() {
        let config = small(Activation::Softplus);
        let mut n32 = config.init::<f32>(range()).expect("valid");
        let mut n64 = config.init::<f64>(range()).expect("valid");
        perturb(&mut n32, 3);
        perturb(&mut n64, 3);
        let (mut o32, mut o64) = (PoseBatch::default(), PoseBatch::default());
        n32.forward(&TIMES, Order::Acceleration, &mut o32)
            .expect("in range");
        n64.forward(&TIMES, Order::Acceleration, &mut o64)
            .expect("in range");
        for i in 0..TIMES.len() {
            assert!((o32.rotation[i] - o64.rotation[i]).norm() < 1e-5);
            assert!((o32.translation[i] - o64.translation[i]).norm() < 1e-5);
            assert!(
                (o32.rotation_rate[i] - o64.rotation_rate[i]).norm()
                    < 1e-5 * (1.0 + o64.rotation_rate[i].norm())
            );
            assert!(
                (o32.lin_acc_world[i] - o64.lin_acc_world[i]).norm()
                    < 1e-5 * (1.0 + o64.lin_acc_world[i].norm())
            );
        }
        let mut cot = PoseBatch::zeros(TIMES.len(), Order::Acceleration);
        cot.rotation_acc
            .iter_mut()
            .for_each(|q| *q = Quaternion::new(0.1, 0.2, -0.3, 0.4));
        cot.translation
            .iter_mut()
            .for_each(|p| *p = Vector3::new(1.0, -1.0, 0.5));
        let mut g32 = vec![0.0f32; n32.num_params()];
        let mut g64 = vec![0.0f64; n64.num_params()];
        n32.backward(&TIMES, &cot, &mut g32).expect("shapes");
        n64.backward(&TIMES, &cot, &mut g64).expect("shapes");
        let scale = g64.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        for (a, b) in g32.iter().zip(&g64) {
            assert!((*a as f64 - b).abs() < 1e-4 * scale);
        }
    }

    #[test]
    fn backward_recomputes_or_reuses_forward() {
        let mut net = small(Activation::Softplus)
            .init::<f64>(range())
            .expect("valid");
        perturb(&mut net, 8);
        let mut cot = PoseBatch::zeros(TIMES.len(), Order::Velocity);
        cot.rotation_rate
            .iter_mut()
            .for_each(|q| *q = Quaternion::new(0.3, -0.2, 0.1, 0.5));
        cot.translation
            .iter_mut()
            .for_each(|p| *p = Vector3::new(0.5, 1.0, -2.0));
        // No forward before: recomputed at the cotangents' order.
        let mut g1 = vec![0.0; net.num_params()];
        net.backward(&TIMES, &cot, &mut g1).expect("recomputes");
        // A cached forward of higher order gives the same gradient.
        let mut out = PoseBatch::default();
        net.forward(&TIMES, Order::Acceleration, &mut out)
            .expect("in range");
        let mut g2 = vec![0.0; net.num_params()];
        net.backward(&TIMES, &cot, &mut g2).expect("cached");
        assert!(g1.iter().zip(&g2).all(|(a, b)| (a - b).abs() < 1e-12));
        // Wrong lengths are errors.
        let mut bad = cot.clone();
        bad.translation.pop();
        assert!(matches!(
            net.backward(&TIMES, &bad, &mut g2),
            Err(PoseFieldError::Shape { .. })
        ));
    }

    /// Two threads (the decoupled networks in parallel, or the coupled network's batch split
    /// with its parts summed) give the single-thread result.
    #[test]
    fn parallel_paths_match_single_thread() {
        for (config, parts) in [
            (small(Activation::Softplus), 1),
            (
                PoseNetConfig {
                    coupled: true,
                    ..small(Activation::Softplus)
                },
                2,
            ),
        ] {
            check_parallel_matches_single_thread(config, parts);
        }
    }

    fn check_parallel_matches_single_thread(config: PoseNetConfig, parts_with_two_threads: usize) {
        let ts: Vec<f64> = (0..300).map(|i| 1.0 + 5.0 * i as f64 / 299.0).collect();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            pool.install(|| {
                let mut net = config.init::<f64>(range()).expect("valid");
                perturb(&mut net, 4);
                let mut out = PoseBatch::default();
                net.forward(&ts, Order::Acceleration, &mut out)
                    .expect("in range");
                let mut grad = vec![0.0; net.num_params()];
                net.backward(&ts, &out.clone(), &mut grad).expect("shapes");
                (net.ws.used, out, grad)
            })
        };
        let (parts1, out1, g1) = run(1);
        let (parts2, out2, g2) = run(2);
        assert_eq!((parts1, parts2), (1, parts_with_two_threads));
        assert!(
            out1.rotation_acc
                .iter()
                .zip(&out2.rotation_acc)
                .all(|(a, b)| (a - b).norm() < 1e-12)
        );
        assert!(
            out1.lin_vel_world
                .iter()
                .zip(&out2.lin_vel_world)
                .all(|(a, b)| (a - b).norm() < 1e-12)
        );
        assert!(
            g1.iter()
                .zip(&g2)
                .all(|(a, b)| (a - b).abs() < 1e-9 * (1.0 + a.abs()))
        );
    }

    #[test]
    fn out_of_range_and_invalid_configs_are_errors() {
        let net = small(Activation::Relu).init::<f32>(range()).expect("valid");
        let mut out = PoseBatch::default();
        let err = net.evaluate(&[2.0, 6.5], Order::Pose, &mut out);
        assert_eq!(
            err,
            Err(PoseFieldError::OutOfRange {
                t_secs: 6.5,
                range: range()
            })
        );
        net.evaluate(&[], Order::Acceleration, &mut out)
            .expect("empty batch");
        assert!(out.is_empty());
        for bad in [
            PoseNetConfig {
                skip_layer: 8,
                ..PoseNetConfig::default()
            },
            PoseNetConfig {
                bands: 0,
                ..PoseNetConfig::default()
            },
            PoseNetConfig {
                translation_scale: 0.0,
                ..PoseNetConfig::default()
            },
            PoseNetConfig {
                time_span: f64::NAN,
                ..PoseNetConfig::default()
            },
            PoseNetConfig {
                depth: 1,
                skip_layer: 0,
                ..PoseNetConfig::default()
            },
        ] {
            assert!(matches!(
                bad.init::<f32>(range()),
                Err(PoseFieldError::Invalid(_))
            ));
        }
        // A width of a million is refused before 24 TB of weights are asked for.
        let huge = PoseNetConfig {
            width: 1_000_000,
            ..PoseNetConfig::default()
        };
        match huge.init::<f32>(range()) {
            Err(PoseFieldError::Invalid(m)) => assert!(m.contains("width = 1000000"), "{m}"),
            other => panic!("{:?}", other.map(|n| n.num_params())),
        }
    }

    #[test]
    fn config_parses_from_toml_and_rejects_typos() {
        let c: PoseNetConfig =
            toml::from_str("bands = 6\nactivation = \"softplus\"\ncoupled = true")
                .expect("valid toml");
        assert_eq!(
            (c.bands, c.activation, c.coupled, c.width),
            (6, Activation::Softplus, true, 256)
        );
        assert!(toml::from_str::<PoseNetConfig>("band = 6").is_err());
        assert!(toml::from_str::<PoseNetConfig>("encoding = \"linear\"").is_ok());
    }

    #[test]
    fn parameter_kinds_and_adam_step() {
        let mut net = small(Activation::Relu).init::<f32>(range()).expect("valid");
        let mut kinds = Vec::new();
        net.params(&mut |k, p| kinds.push((k, p.len())));
        assert_eq!(
            kinds.iter().map(|k| k.0).collect::<Vec<_>>(),
            [ParamKind::Translation, ParamKind::Rotation]
        );
        let before = params_to_vec(&net);
        let grad = vec![1.0f32; net.num_params()];
        let mut adam = nn::Adam::new(net.num_params());
        adam.step_pose_field(&mut net, &grad, |k| {
            if k == ParamKind::Rotation { 2e-4 } else { 1e-3 }
        });
        let after = params_to_vec(&net);
        let n_t = kinds[0].1;
        assert!((before[0] - after[0] - 1e-3).abs() < 1e-6);
        assert!((before[n_t] - after[n_t] - 2e-4).abs() < 1e-6);
    }
}
