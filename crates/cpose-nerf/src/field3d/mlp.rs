//! [`NerfMlpField`]: BARF's NeRF MLP (docs/methods.md §2.2; BARF `model/nerf.py`).

use std::fmt;
use std::ops::Range;

use cpose_core::Real;
use cpose_core::nn::{Accum, Activation, Embedding, Encoding, Init, Mlp, MlpSpec, MlpWorkspace};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::de::{self, Unexpected, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::{
    Field3dError, MLP_CHUNK, PointMap, RadianceField, SceneBounds, backward_parts, batch_len,
    check_backward, chunks, colour_backward, colour_forward, copy_colours, density_forward,
    parts_for, run_parts,
};
use crate::field_common::{c2f_serde, c2f_window, check_c2f, grow, invalid};

/// Most frequency bands accepted: band `k` has period `2^(1−k)` in field coordinates, at
/// `k = 15` 1/32768 of the unit ball's radius.
const MAX_BANDS: usize = 16;

/// PyTorch's `calculate_gain("relu")`, the Xavier gain of BARF's hidden layers.
const RELU_GAIN: f64 = std::f64::consts::SQRT_2;

/// Construction parameters of a [`NerfMlpField`] (a TOML table; unknown keys are errors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NerfMlpConfig {
    /// Frequency bands `L` per coordinate, `2^k π` for `k < L` (input width `3 + 6L`); 0 gives
    /// the no-encoding baseline. Default 10 (BARF's `L_3D`).
    pub bands: usize,
    /// Linear layers of the trunk (≥ 1); default 8 (BARF).
    pub depth: usize,
    /// Units per trunk layer; default 256 (BARF).
    pub width: usize,
    /// Trunk layer (`1..depth`) that reads `[h, γ(p)]` instead of `h`; `false` in TOML (`None`)
    /// for none. Default 4 (BARF).
    #[serde(with = "skip_serde")]
    pub skip_layer: Option<usize>,
    /// Units of the colour head's hidden layer; default 128 (BARF).
    pub rgb_width: usize,
    /// Coarse-to-fine window `[start, end]` in fractions of training, `0 ≤ start < end ≤ 1`;
    /// `false` in TOML (`None`) keeps all bands at weight 1. Default `[0.1, 0.5]` (BARF NeRF).
    /// Unlike the 2-D [`PeMlpConfig`](crate::field2d::PeMlpConfig), the first layer is not
    /// rescaled (BARF's NeRF does not).
    #[serde(with = "c2f_serde")]
    pub c2f: Option<[f64; 2]>,
    /// Seed of the weight initialisation (ChaCha8: the trunk, then the colour head); default 0.
    pub seed: u64,
}

impl Default for NerfMlpConfig {
    fn default() -> Self {
        Self {
            bands: 10,
            depth: 8,
            width: 256,
            skip_layer: Some(4),
            rgb_width: 128,
            c2f: Some([0.1, 0.5]),
            seed: 0,
        }
    }
}

impl NerfMlpConfig {
    /// A field over `scene` at progress 0, initialised as BARF's `tf_init`: Xavier-uniform
    /// weights (`U(±gain·sqrt(6/(fan_in + fan_out)))`) with gain √2 on hidden layers, on the
    /// last trunk layer gain 1 for the density output (its own `fan_out = 1`) and √2 for the
    /// `width` features (`fan_out = width`), gain 1 on the colour output layer; biases 0.
    pub fn init<S: Real>(&self, scene: SceneBounds) -> Result<NerfMlpField<S>, Field3dError> {
        if self.bands > MAX_BANDS {
            return invalid("bands", "at most 16", self.bands);
        }
        if self.depth == 0 {
            return invalid("depth", "at least 1", self.depth);
        }
        if self.width == 0 {
            return invalid("width", "at least 1", self.width);
        }
        if let Some(skip) = self.skip_layer
            && !(1..self.depth).contains(&skip)
        {
            let want = format!("1 to depth − 1 ({}), or false", self.depth - 1);
            return invalid("skip_layer", &want, skip);
        }
        if self.rgb_width == 0 {
            return invalid("rgb_width", "at least 1", self.rgb_width);
        }
        check_c2f(self.c2f)?;
        scene.validate()?;

        let embedding = Embedding::new(Encoding::Sinusoidal, 3, self.bands);
        let input_dim = embedding.output_dim();
        let (width, depth) = (self.width, self.depth);
        let xavier = |gain| Init::XavierUniform { gain };
        let trunk_spec = MlpSpec {
            input_dim,
            width,
            depth,
            output_dim: width + 1,
            skip_layer: self.skip_layer,
            activation: Activation::Relu,
            hidden_init: xavier(RELU_GAIN),
            // Re-drawn below with BARF's split gains.
            output_init: xavier(RELU_GAIN),
        };
        let head_spec = MlpSpec {
            input_dim: width,
            width: self.rgb_width,
            depth: 2,
            output_dim: 3,
            skip_layer: None,
            activation: Activation::Relu,
            hidden_init: xavier(RELU_GAIN),
            output_init: xavier(1.0),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut trunk = Mlp::<S>::new(trunk_spec, &mut rng);
        // Last trunk layer: `W` (`[fan_in × (width + 1)]` column-major, column 0 = density)
        // then its bias (zero), at the end of the trunk's parameters.
        let from_h = if depth == 1 { 0 } else { width };
        let from_x = if depth == 1 || self.skip_layer == Some(depth - 1) {
            input_dim
        } else {
            0
        };
        let fan_in = (from_h + from_x) as f64;
        let w_start = trunk.num_params() - (width + 1) * (from_h + from_x + 1);
        let density_bound = (6.0 / (fan_in + 1.0)).sqrt();
        let feature_bound = RELU_GAIN * (6.0 / (fan_in + width as f64)).sqrt();
        let w_last = &mut trunk.params[w_start..w_start + (from_h + from_x) * (width + 1)];
        for (k, w) in w_last.iter_mut().enumerate() {
            let a = if k < from_h + from_x {
                density_bound
            } else {
                feature_bound
            };
            *w = S::from_f64(rng.random_range(-a..a));
        }
        let head = Mlp::<S>::new(head_spec, &mut rng);
        let mut params = Vec::with_capacity(trunk.num_params() + head.num_params());
        params.extend_from_slice(&trunk.params);
        params.extend_from_slice(&head.params);

        let mut field = NerfMlpField {
            config: self.clone(),
            map: PointMap::new(&scene),
            embedding,
            params,
            trunk,
            head,
            ws: Workspace::default(),
        };
        field.set_progress(0.0);
        Ok(field)
    }
}

/// BARF's NeRF MLP (docs/methods.md §2.2; BARF `model/nerf.py`) without view dependence: the
/// fidelity 3-D field.
///
/// On the field point `p` (normalised, contracted when unbounded; see the module docs):
/// `γ(p) = [p, w_k sin(2^k π p_d) (k < L), w_k cos(2^k π p_d) (k < L)]` per coordinate `d`
/// (the core [`Embedding`]: identity first, then for x all sines and all cosines, then y, z;
/// frequencies `ω_k = 2^k π`, the same layout and frequencies as BARF's
/// `positional_encoding`), `w_k` BARF's coarse-to-fine band weights. The trunk has `depth`
/// linear layers of `width` units with ReLU in between; the skip layer reads `[h, γ]`; the last
/// layer outputs `width + 1` values `z`: `σ = softplus(z₀)` (BARF's `density_activ`, no bias),
/// and `h = relu(z₁..)` feeds the colour head, `width → rgb_width` (ReLU) `→ 3`, then
/// `rgb = sigmoid(·)`.
///
/// Reverse pass to the point: `∂L/∂p = ∂L/∂γ · ∂γ/∂p` with
/// `∂/∂p [w sin(ωp), w cos(ωp)] = [w ω cos(ωp), −w ω sin(ωp)]` ([`Embedding::backward_input`],
/// in `f64`), then through the contraction and normalisation.
///
/// Parameters: the trunk's ([`Mlp::params`] layout: `W_0, b_0, W_1, b_1, …`, each `W`
/// `[fan_in × fan_out]` column-major, the skip layer's rows `[h; γ]`), then the colour head's.
/// The networks' copies of their weights are refreshed from this vector at every forward pass.
/// One parameter group, `("mlp", …)`.
#[derive(Clone, Debug)]
pub struct NerfMlpField<S: Real = f32> {
    config: NerfMlpConfig,
    /// World → field map, in `f64` (the embedding's input precision).
    map: PointMap<f64>,
    embedding: Embedding,
    params: Vec<S>,
    trunk: Mlp<S>,
    head: Mlp<S>,
    ws: Workspace<S>,
}

/// Buffers of one part of the batch (grow with the batch, never shrink). Per-point buffers that
/// feed the networks are chunk-blocked (see [`super::chunks`]); `[C × …]` buffers hold one
/// chunk at a time in the reverse pass.
#[derive(Clone, Debug, Default)]
struct Part<S: Real> {
    /// First point of the part in the batch.
    start: usize,
    /// Points in the part.
    b: usize,
    /// Normalised points `y`, `b × 3` interleaved.
    y: Vec<f64>,
    /// Field points `p` (the embedding's input), chunk-blocked `[len × 3]`.
    x: Vec<f64>,
    /// Encoding `γ`, chunk-blocked `[len × (3 + 6L)]`.
    enc: Vec<S>,
    /// One trunk workspace per chunk.
    trunk: Vec<MlpWorkspace<S>>,
    /// Colour-head input `relu(z₁..)`, chunk-blocked `[len × width]`.
    h: Vec<S>,
    /// One colour-head workspace per chunk.
    head: Vec<MlpWorkspace<S>>,
    /// `σ` and `dσ/dz₀`, `b` each.
    sigma: Vec<S>,
    slope: Vec<S>,
    /// Colours, chunk-blocked `[len × 3]`.
    rgb: Vec<S>,
    /// `∂L/∂(colour logits)`, `[C × 3]`.
    grad_z: Vec<S>,
    /// `∂L/∂h`, `[C × width]`.
    grad_h: Vec<S>,
    /// `∂L/∂(trunk output)`, `[C × (width + 1)]`.
    grad_trunk: Vec<S>,
    /// `∂L/∂γ`, `[C × (3 + 6L)]`.
    grad_enc: Vec<S>,
    /// `∂L/∂p`, `[C × 3]`.
    grad_x: Vec<f64>,
    /// `∂L/∂x` (world), `b × 3` interleaved.
    grad_points: Vec<f64>,
    /// The part's parameter gradient (parts after the first).
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
}

impl<S: Real> Workspace<S> {
    /// Writes the parts' `∂L/∂x` of the last reverse pass into `grad_points` (`n × 3`).
    fn write_grad_points(&self, grad_points: &mut [S]) {
        for part in &self.parts[..self.used] {
            let out = &mut grad_points[3 * part.start..3 * (part.start + part.b)];
            for (o, &g) in out.iter_mut().zip(&part.grad_points) {
                *o = S::from_f64(g);
            }
        }
    }
}

impl<S: Real> NerfMlpField<S> {
    /// The configuration it was built from.
    pub fn config(&self) -> &NerfMlpConfig {
        &self.config
    }

    /// The current band weights `w_k` (all 1 without coarse-to-fine).
    pub fn band_weights(&self) -> &[f64] {
        self.embedding.weights()
    }

    /// Indices of the trunk's parameters in [`RadianceField::params`].
    pub fn trunk_range(&self) -> Range<usize> {
        0..self.trunk.num_params()
    }

    /// Indices of the colour head's parameters in [`RadianceField::params`].
    pub fn head_range(&self) -> Range<usize> {
        self.trunk.num_params()..self.params.len()
    }

    /// Forward pass of one part, chunk by chunk.
    fn forward_part(&self, part: &mut Part<S>, points: &[S]) {
        let b = points.len() / 3;
        let (dim, width) = (self.embedding.output_dim(), self.config.width);
        part.b = b;
        for v in [&mut part.y, &mut part.x] {
            grow(v, 3 * b);
        }
        grow(&mut part.enc, b * dim);
        grow(&mut part.h, b * width);
        grow(&mut part.sigma, b);
        grow(&mut part.slope, b);
        grow(&mut part.rgb, 3 * b);
        let chunk_count = b.div_ceil(MLP_CHUNK);
        if part.trunk.len() < chunk_count {
            part.trunk.resize_with(chunk_count, MlpWorkspace::default);
            part.head.resize_with(chunk_count, MlpWorkspace::default);
        }
        for (r, (trunk, head)) in chunks(b).zip(part.trunk.iter_mut().zip(&mut part.head)) {
            let len = r.len();
            let x = &mut part.x[3 * r.start..3 * r.end];
            for (k, i) in r.clone().enumerate() {
                let y = self
                    .map
                    .normalise([0, 1, 2].map(|d| points[3 * i + d].to_f64()));
                let p = self.map.field_point(y);
                part.y[3 * i..3 * i + 3].copy_from_slice(&y);
                for d in 0..3 {
                    x[d * len + k] = p[d];
                }
            }
            let enc = &mut part.enc[r.start * dim..r.end * dim];
            self.embedding.encode(x, len, 1, enc);
            self.trunk.forward(enc, len, 1, trunk);
            let z = trunk.output();
            density_forward(
                &z[..len],
                S::ZERO,
                &mut part.sigma[r.clone()],
                &mut part.slope[r.clone()],
            );
            let h = &mut part.h[r.start * width..r.end * width];
            for (h, &z) in h.iter_mut().zip(&z[len..len * (width + 1)]) {
                *h = z.max(S::ZERO);
            }
            self.head.forward(h, len, 1, head);
            colour_forward(
                &head.output()[..3 * len],
                &mut part.rgb[3 * r.start..3 * r.end],
            );
        }
    }

    /// Reverse pass of one part, chunk by chunk: `∂L/∂θ` into `g` when given (`accum` for the
    /// first chunk, then added), `∂L/∂x` into `part.grad_points`.
    fn backward_part(
        &self,
        part: &mut Part<S>,
        grad_sigma: &[S],
        grad_rgb: &[S],
        mut g: Option<(&mut [S], Accum)>,
    ) {
        let (b, start) = (part.b, part.start);
        let (dim, width) = (self.embedding.output_dim(), self.config.width);
        let c = MLP_CHUNK.min(b);
        grow(&mut part.grad_z, 3 * c);
        grow(&mut part.grad_h, c * width);
        grow(&mut part.grad_trunk, c * (width + 1));
        grow(&mut part.grad_enc, c * dim);
        grow(&mut part.grad_x, 3 * c);
        grow(&mut part.grad_points, 3 * b);
        let nt = self.trunk.num_params();
        for (k, (r, (trunk, head))) in chunks(b)
            .zip(part.trunk.iter_mut().zip(&mut part.head))
            .enumerate()
        {
            let len = r.len();
            // The first chunk writes or adds as asked; the others add.
            let mut g = g.as_mut().map(|(g, accum)| {
                let accum = if k == 0 { *accum } else { Accum::Add };
                let (g_trunk, g_head) = g.split_at_mut(nt);
                (g_trunk, g_head, accum)
            });
            let gz = &mut part.grad_z[..3 * len];
            colour_backward(
                &part.rgb[3 * r.start..3 * r.end],
                &grad_rgb[3 * (start + r.start)..3 * (start + r.end)],
                len,
                gz,
            );
            let h = &part.h[r.start * width..r.end * width];
            let gh = &mut part.grad_h[..len * width];
            gh.fill(S::ZERO);
            match g.as_mut() {
                Some((_, g_head, accum)) => {
                    self.head
                        .backward(h, head, gz, g_head, *accum, Some(&mut *gh))
                }
                None => self.head.backward_input(h, head, gz, gh),
            }
            // Trunk output: ∂L/∂z₀ = ∂L/∂σ · σ', ∂L/∂z_{1..} = ∂L/∂h · [h > 0].
            let (gz0, gzh) = part.grad_trunk[..len * (width + 1)].split_at_mut(len);
            let gs = &grad_sigma[start + r.start..start + r.end];
            for ((g, &gs), &s) in gz0.iter_mut().zip(gs).zip(&part.slope[r.clone()]) {
                *g = gs * s;
            }
            for ((g, &gh), &h) in gzh.iter_mut().zip(&*gh).zip(h) {
                *g = if h > S::ZERO { gh } else { S::ZERO };
            }
            let enc = &part.enc[r.start * dim..r.end * dim];
            let genc = &mut part.grad_enc[..len * dim];
            genc.fill(S::ZERO);
            let gt = &part.grad_trunk[..len * (width + 1)];
            match g {
                Some((g_trunk, _, accum)) => {
                    self.trunk
                        .backward(enc, trunk, gt, g_trunk, accum, Some(&mut *genc))
                }
                None => self.trunk.backward_input(enc, trunk, gt, genc),
            }
            let gx = &mut part.grad_x[..3 * len];
            gx.fill(0.0);
            let x = &part.x[3 * r.start..3 * r.end];
            self.embedding.backward_input(x, len, genc, len, gx);
            // ∂L/∂x = (∂p/∂y)ᵀ ∂L/∂p / r.
            for (k, i) in r.enumerate() {
                let y = [part.y[3 * i], part.y[3 * i + 1], part.y[3 * i + 2]];
                let gp = self.map.backward(y, [gx[k], gx[len + k], gx[2 * len + k]]);
                part.grad_points[3 * i..3 * i + 3].copy_from_slice(&gp);
            }
        }
    }
}

impl<S: Real> RadianceField<S> for NerfMlpField<S> {
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
        vec![("mlp", 0..self.params.len())]
    }

    fn set_progress(&mut self, progress: f64) {
        let [start, end] = c2f_window(self.config.c2f);
        self.embedding.set_coarse_to_fine(progress, start, end);
    }

    fn forward(&mut self, points: &[S], sigma: &mut [S], rgb: &mut [S]) {
        let n = batch_len(points, sigma, rgb);
        let parts = parts_for(n);
        let nt = self.trunk.num_params();
        self.trunk.params.copy_from_slice(&self.params[..nt]);
        self.head.params.copy_from_slice(&self.params[nt..]);
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
        let (n, used) = (self.ws.n, self.ws.used);
        check_backward(
            n,
            self.params.len(),
            grad_sigma,
            grad_rgb,
            grad,
            grad_points,
        );
        let mut ws = std::mem::take(&mut self.ws);
        let this = &*self;
        backward_parts(
            &mut ws.parts[..used],
            grad,
            |part| &mut part.grad,
            |part, g, accum| this.backward_part(part, grad_sigma, grad_rgb, Some((g, accum))),
        );
        ws.write_grad_points(grad_points);
        self.ws = ws;
    }

    fn backward_points(&mut self, grad_sigma: &[S], grad_rgb: &[S], grad_points: &mut [S]) {
        let n = self.ws.n;
        assert!(
            grad_sigma.len() == n && grad_rgb.len() == 3 * n && grad_points.len() == 3 * n,
            "backward_points: cotangents and point gradient must match the last forward"
        );
        let mut ws = std::mem::take(&mut self.ws);
        let this = &*self;
        run_parts(&mut ws.parts[..ws.used], |_, part| {
            this.backward_part(part, grad_sigma, grad_rgb, None)
        });
        ws.write_grad_points(grad_points);
        self.ws = ws;
    }
}

/// Serde of an optional layer index: an integer, or `false` for none (TOML has no null).
mod skip_serde {
    use super::*;

    /// `Some(l)` as `l`, `None` as `false`.
    pub fn serialize<Z: Serializer>(skip: &Option<usize>, s: Z) -> Result<Z::Ok, Z::Error> {
        match skip {
            Some(l) => s.serialize_u64(*l as u64),
            None => s.serialize_bool(false),
        }
    }

    /// A non-negative integer as `Some`; `false` (or null) as `None`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<usize>, D::Error> {
        d.deserialize_any(SkipVisitor)
    }

    struct SkipVisitor;

    impl Visitor<'_> for SkipVisitor {
        type Value = Option<usize>;

        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("a layer index or false")
        }

        fn visit_bool<E: de::Error>(self, v: bool) -> Result<Self::Value, E> {
            if v {
                Err(E::invalid_value(Unexpected::Bool(v), &self))
            } else {
                Ok(None)
            }
        }

        fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
            usize::try_from(v)
                .map(Some)
                .map_err(|_| E::invalid_value(Unexpected::Unsigned(v), &self))
        }

        fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
            usize::try_from(v)
                .map(Some)
                .map_err(|_| E::invalid_value(Unexpected::Signed(v), &self))
        }

        fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }

        fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
    }
}

#[cfg(test)]
mod tests {
    use rand::seq::index::sample;

    use super::super::test_support::{
        assert_f32_matches_f64, check_batches_agree, check_gradients,
        check_parallel_matches_single_part, check_points_gradient_alone, points,
    };
    use super::*;

    /// Input 3 + 6·4 = 27; trunk 27 → 16 → 16 → [16; 27] → 17; head 16 → 8 → 3.
    fn small() -> NerfMlpConfig {
        NerfMlpConfig {
            bands: 4,
            depth: 4,
            width: 16,
            skip_layer: Some(2),
            rgb_width: 8,
            c2f: Some([0.05, 0.45]),
            seed: 3,
        }
    }

    fn scene(unbounded: bool) -> SceneBounds {
        SceneBounds {
            centre: [-0.5, 0.25, 2.0],
            radius: 2.0,
            unbounded,
        }
    }

    /// Biases `U(±0.3)` (they start at 0), so that every parameter kind gets a generic
    /// gradient.
    fn randomise_biases(field: &mut NerfMlpField<f64>, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (nt, w, r) = (field.trunk.num_params(), 16, 8);
        // Trunk biases sit after each W; here: b_0 at 27·16, b_1 at 27·16 + 16 + 16·16, …
        let mut biases: Vec<Range<usize>> = Vec::new();
        let mut off = 0;
        for fan_in_out in [(27, w), (w, w), (w + 27, w), (w, w + 1)] {
            off += fan_in_out.0 * fan_in_out.1;
            biases.push(off..off + fan_in_out.1);
            off += fan_in_out.1;
        }
        assert_eq!(off, nt);
        for (fi, fo) in [(w, r), (r, 3)] {
            off += fi * fo;
            biases.push(off..off + fo);
            off += fo;
        }
        assert_eq!(off, field.num_params());
        for range in biases {
            for v in &mut field.params_mut()[range] {
                assert_eq!(*v, 0.0);
                *v = rng.random_range(-0.3..0.3);
            }
        }
    }

    /// Parameters (a sample, plus the density and colour output biases and weights of the
    /// partly weighted band) and points against central differences at progress 0.3
    /// (`α = 0.625 · 4 = 2.5`: band 2 at weight 0.5, band 3 off), bounded (points beyond the
    /// radius read the unclamped encoding) and contracted, and with all bands on.
    #[test]
    fn gradients_match_central_differences() {
        for (unbounded, progress, c2f) in [
            (false, 0.3, Some([0.05, 0.45])),
            (true, 0.3, Some([0.05, 0.45])),
            (true, 0.0, None),
        ] {
            let scene = scene(unbounded);
            let mut field = NerfMlpConfig { c2f, ..small() }
                .init::<f64>(scene)
                .expect("valid");
            field.set_progress(progress);
            if c2f.is_some() {
                let w = field.band_weights();
                assert!((w[2] - 0.5).abs() < 1e-12 && w[3] == 0.0, "{w:?}");
            }
            randomise_biases(&mut field, 4);
            let half = if unbounded { 10.0 } else { 2.4 };
            let pts = points(12, 5, scene.centre, half, |_| false);
            let np = field.num_params();
            let mut idx = sample(&mut ChaCha8Rng::seed_from_u64(1), np, 60).into_vec();
            // First layer (`[27 × 16]`): x → unit 0, sin(2² π x) (band 2, weight 0.5) → unit 3;
            // the density bias; the last colour weight and bias.
            let nt = field.trunk.num_params();
            idx.extend([0, 27 * 3 + 3 + 2, nt - 17, np - 4, np - 1]);
            // ω ≤ 8π on |p| ≤ 2: truncation ~h²ω³/6 ≲ 1e-9 of the gradient scale.
            check_gradients(&mut field, &pts, &idx, 1e-6);
        }
    }

    /// BARF's `tf_init`: zero biases; Xavier bounds with gain √2 on hidden layers, gain 1 on the
    /// density column and the colour output; the bounds are nearly reached.
    #[test]
    fn init_follows_barf_tf_init() {
        let config = NerfMlpConfig {
            bands: 2,
            depth: 3,
            width: 64,
            skip_layer: Some(2),
            rgb_width: 32,
            c2f: None,
            seed: 9,
        };
        let f = config.init::<f64>(SceneBounds::UNIT).expect("valid");
        let p = f.params();
        let xavier = |gain: f64, fi: usize, fo: usize| gain * (6.0 / (fi + fo) as f64).sqrt();
        let g = RELU_GAIN;
        // (offset, fan_in, fan_out, bound): layer 0 (15 → 64), layer 1 (64 → 64), layer 2 skip
        // ([64 + 15] → 65: density column, then features), head (64 → 32 → 3).
        let l1 = 15 * 64 + 64;
        let l2 = l1 + 64 * 64 + 64;
        let density = l2 + 79;
        let l2_end = l2 + 79 * 65;
        let h0 = l2_end + 65;
        let h1 = h0 + 64 * 32 + 32;
        let blocks = [
            (0..15 * 64, xavier(g, 15, 64)),
            (l1..l1 + 64 * 64, xavier(g, 64, 64)),
            (l2..density, xavier(1.0, 79, 1)),
            (density..l2_end, xavier(g, 79, 64)),
            (h0..h0 + 64 * 32, xavier(g, 64, 32)),
            (h1..h1 + 32 * 3, xavier(1.0, 32, 3)),
        ];
        for (range, bound) in blocks {
            let max = p[range.clone()].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(
                max <= bound && max > 0.9 * bound,
                "{range:?}: max {max}, bound {bound}"
            );
        }
        for bias in [
            15 * 64..l1,
            l1 + 64 * 64..l2,
            l2_end..h0,
            h0 + 64 * 32..h1,
            h1 + 96..h1 + 99,
        ] {
            assert!(p[bias].iter().all(|&b| b == 0.0));
        }
        assert_eq!(f.num_params(), h1 + 99);
        assert_eq!((f.trunk_range(), f.head_range()), (0..h0, h0..h1 + 99));
        assert_eq!(f.param_groups(), [("mlp", 0..h1 + 99)]);
        // Deterministic, seeded, and f32 rounds the f64 draws.
        let again = config.init::<f64>(SceneBounds::UNIT).expect("valid");
        assert_eq!(f.params(), again.params());
        let other = NerfMlpConfig {
            seed: 10,
            ..config.clone()
        }
        .init::<f64>(SceneBounds::UNIT)
        .expect("valid");
        assert_ne!(f.params(), other.params());
        let single = config.init::<f32>(SceneBounds::UNIT).expect("valid");
        assert!(
            f.params()
                .iter()
                .zip(single.params())
                .all(|(&a, &b)| a as f32 == b)
        );
    }

    #[test]
    fn default_size_and_outputs() {
        let d = NerfMlpConfig::default()
            .init::<f32>(SceneBounds::UNIT)
            .expect("valid");
        let w = 256;
        let trunk = 63 * w + w + 5 * (w * w + w) + (w + 63) * w + w + w * (w + 1) + w + 1;
        let head = w * 128 + 128 + 128 * 3 + 3;
        assert_eq!(d.num_params(), trunk + head);
        assert_eq!(d.trunk_range(), 0..trunk);
        let mut field = small().init::<f64>(scene(true)).expect("valid");
        assert!(field.band_weights().iter().all(|&w| w == 0.0));
        field.set_progress(1.0);
        assert!(field.band_weights().iter().all(|&w| w == 1.0));
        // Output biases: density +30 (σ ≈ 30), red +20, blue −20.
        let (nt, np) = (field.trunk.num_params(), field.num_params());
        field.params_mut()[nt - 17] = 30.0;
        field.params_mut()[np - 3] = 20.0;
        field.params_mut()[np - 1] = -20.0;
        let pts = points(100, 9, [0.0; 3], 50.0, |_| false);
        let (mut sigma, mut rgb) = (vec![0.0; 100], vec![0.0; 300]);
        field.forward(&pts, &mut sigma, &mut rgb);
        assert!(sigma.iter().all(|&s| s > 20.0 && s < 40.0), "{sigma:?}");
        assert!(
            rgb.chunks(3)
                .all(|c| c[0] > 0.99 && c[2] < 0.01 && c[1] > 0.0 && c[1] < 1.0)
        );
        let (mut s2, mut c2) = (vec![0.0; 2], vec![0.0; 6]);
        field.forward(&pts[..6], &mut s2, &mut c2);
        assert_eq!(s2[..], sigma[..2]);
        assert_eq!(c2[..], rgb[..6]);
    }

    /// f32 and f64 fields from one seed agree (forward, and backward relative to its scale).
    #[test]
    fn f32_agrees_with_f64() {
        for unbounded in [false, true] {
            let mut a = small().init::<f64>(scene(unbounded)).expect("valid");
            let mut b = small().init::<f32>(scene(unbounded)).expect("valid");
            a.set_progress(0.3);
            b.set_progress(0.3);
            let pts = points(64, 2, scene(unbounded).centre, 5.0, |_| false);
            assert_f32_matches_f64(&mut a, &mut b, &pts);
        }
    }

    /// Two parts (two threads, 4500 points) give the single-part result.
    #[test]
    fn parallel_split_matches_single_part() {
        let make = || -> Box<dyn RadianceField<f64>> {
            let mut field = small().init::<f64>(scene(true)).expect("valid");
            randomise_biases(&mut field, 2);
            field.set_progress(0.3);
            Box::new(field)
        };
        let pts = points(4500, 12, scene(true).centre, 6.0, |_| false);
        check_parallel_matches_single_part(make, &pts);
    }

    /// With the parameters held fixed the points' gradient is the full pass's, bit for bit, in
    /// one part and in two (4500 points), with coarse-to-fine partly on.
    #[test]
    fn points_gradient_alone_matches_the_full_pass() {
        for n in [40, 4500] {
            let mut field = small().init::<f64>(scene(true)).expect("valid");
            randomise_biases(&mut field, 6);
            field.set_progress(0.3);
            let pts = points(n, 3, scene(true).centre, 6.0, |_| false);
            check_points_gradient_alone(&mut field, &pts);
        }
    }

    /// A batch of several MLP chunks gives the results of small batches.
    #[test]
    fn chunked_batch_matches_small_batches() {
        let mut field = small().init::<f64>(scene(false)).expect("valid");
        randomise_biases(&mut field, 5);
        field.set_progress(0.3);
        let pts = points(2500, 14, scene(false).centre, 3.0, |_| false);
        check_batches_agree(&mut field, &pts, 600);
    }

    #[test]
    fn invalid_configs_name_the_key() {
        let cases = [
            (
                NerfMlpConfig {
                    bands: 17,
                    ..small()
                },
                "bands",
            ),
            (
                NerfMlpConfig {
                    depth: 0,
                    ..small()
                },
                "depth",
            ),
            (
                NerfMlpConfig {
                    width: 0,
                    ..small()
                },
                "width",
            ),
            (
                NerfMlpConfig {
                    skip_layer: Some(0),
                    ..small()
                },
                "skip_layer",
            ),
            (
                NerfMlpConfig {
                    skip_layer: Some(4),
                    ..small()
                },
                "skip_layer",
            ),
            (
                NerfMlpConfig {
                    rgb_width: 0,
                    ..small()
                },
                "rgb_width",
            ),
            (
                NerfMlpConfig {
                    c2f: Some([0.4, 0.2]),
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
        let e = NerfMlpConfig {
            skip_layer: Some(4),
            ..small()
        }
        .init::<f32>(SceneBounds::UNIT)
        .expect_err("invalid");
        assert_eq!(
            e.to_string(),
            "invalid skip_layer: expected 1 to depth − 1 (3), or false, got 4"
        );
        // Without a skip layer, and a single trunk layer, are valid.
        for c in [
            NerfMlpConfig {
                skip_layer: None,
                ..small()
            },
            NerfMlpConfig {
                depth: 1,
                skip_layer: None,
                ..small()
            },
        ] {
            assert!(c.init::<f32>(SceneBounds::UNIT).is_ok());
        }
    }

    #[test]
    fn config_parses_from_toml_and_rejects_typos() {
        let c: NerfMlpConfig =
            toml::from_str("bands = 6\nskip_layer = false\nc2f = [0, 0.5]").expect("valid toml");
        assert_eq!((c.bands, c.skip_layer, c.c2f), (6, None, Some([0.0, 0.5])));
        let s: NerfMlpConfig = toml::from_str("skip_layer = 2\ndepth = 4").expect("valid toml");
        assert_eq!((s.skip_layer, s.depth), (Some(2), 4));
        assert_eq!(
            toml::from_str::<NerfMlpConfig>("").expect("empty"),
            NerfMlpConfig::default()
        );
        for text in [
            "widht = 3",
            "skip_layer = true",
            "skip_layer = -1",
            "c2f = [0.1]",
        ] {
            assert!(toml::from_str::<NerfMlpConfig>(text).is_err(), "{text}");
        }
        for c in [NerfMlpConfig::default(), c, s] {
            let text = toml::to_string(&c).expect("serialises");
            assert_eq!(
                toml::from_str::<NerfMlpConfig>(&text).expect("round trip"),
                c
            );
        }
    }
}
