//! [`PeMlpField`]: BARF's neural image (docs/methods.md §2.1; BARF `model/planar.py`).

use cpose_core::Real;
use cpose_core::nn::{Accum, Activation, Embedding, Encoding, Init, Mlp, MlpSpec, MlpWorkspace};
use serde::{Deserialize, Serialize};

use super::{Field2dError, ImageField, batch_len, sigmoid_backward, sigmoid_forward};
use crate::field_common::{c2f_serde, c2f_window, check_c2f, grow, invalid};

/// Most frequency bands accepted: band `k` has period `2^(1−k)`, at `k = 15` 1/32768 of the
/// image side (far below a pixel), and the `f32` argument `2^k π x` has lost most digits.
const MAX_BANDS: usize = 16;

/// Construction parameters of a [`PeMlpField`] (a TOML table; unknown keys are errors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PeMlpConfig {
    /// Frequency bands `L` per coordinate, `2^k π` for `k < L` (input width `2 + 4L`); 0 gives
    /// the no-encoding baseline. Default 8 (BARF).
    pub bands: usize,
    /// Units per hidden layer; default 256 (BARF).
    pub width: usize,
    /// Hidden ReLU layers (linear layers = `hidden_layers + 1`); default 4 (BARF).
    pub hidden_layers: usize,
    /// Coarse-to-fine window `[start, end]` in fractions of training, `0 ≤ start < end ≤ 1`;
    /// `false` in TOML (`None`) keeps all bands at weight 1. Default `[0.0, 0.4]` (BARF planar).
    /// When on, the first layer's initial weights and bias are scaled by `sqrt((2 + 4L)/2)`
    /// (BARF: the init was sized for the whole encoding, but early on only `x, y` are active).
    #[serde(with = "c2f_serde")]
    pub c2f: Option<[f64; 2]>,
    /// Seed of the weight initialisation (ChaCha8); default 0.
    pub seed: u64,
}

impl Default for PeMlpConfig {
    fn default() -> Self {
        Self {
            bands: 8,
            width: 256,
            hidden_layers: 4,
            c2f: Some([0.0, 0.4]),
            seed: 0,
        }
    }
}

impl PeMlpConfig {
    /// A field with PyTorch's default `Linear` init (`W, b ~ U(±1/sqrt(fan_in))`), the first
    /// layer scaled as described at [`PeMlpConfig::c2f`], at progress 0.
    pub fn init<S: Real>(&self) -> Result<PeMlpField<S>, Field2dError> {
        if self.bands > MAX_BANDS {
            return invalid("bands", "at most 16", self.bands);
        }
        if self.width == 0 {
            return invalid("width", "at least 1", self.width);
        }
        if self.hidden_layers == 0 {
            return invalid("hidden_layers", "at least 1", self.hidden_layers);
        }
        check_c2f(self.c2f)?;
        let embedding = Embedding::new(Encoding::Sinusoidal, 2, self.bands);
        let input_dim = embedding.output_dim();
        let spec = MlpSpec {
            input_dim,
            width: self.width,
            depth: self.hidden_layers + 1,
            output_dim: 3,
            skip_layer: None,
            activation: Activation::Relu,
            hidden_init: Init::TorchDefault,
            output_init: Init::TorchDefault,
        };
        let mut mlp = Mlp::<S>::seeded(spec.clone(), self.seed);
        if self.c2f.is_some() {
            // First layer: W_0 ([input_dim × width]) then b_0, at the start of the vector.
            // Scaled in f64 and rounded once, so f32 and f64 fields from one seed agree.
            let first = (input_dim + 1) * self.width;
            let scale = (input_dim as f64 / 2.0).sqrt();
            let wide = Mlp::<f64>::seeded(spec, self.seed);
            for (p, &w) in mlp.params[..first].iter_mut().zip(&wide.params) {
                *p = S::from_f64(w * scale);
            }
        }
        let mut field = PeMlpField {
            config: self.clone(),
            embedding,
            mlp,
            ws: Workspace::default(),
        };
        field.set_progress(0.0);
        Ok(field)
    }
}

/// BARF's neural image (docs/methods.md §2.1; BARF `model/planar.py`): a ReLU MLP on the
/// positional encoding of the point, with coarse-to-fine weighted bands.
///
/// `γ(p) = [x, y, w_k sin(2^k π x), w_k cos(2^k π x), w_k sin(2^k π y), w_k cos(2^k π y)]`
/// (`k < L`, per coordinate all sines then all cosines; width `2 + 4L`), then `hidden_layers`
/// ReLU layers of `width` units and a linear layer to 3, and `rgb = sigmoid(·)`.
/// `w_k` are BARF's coarse-to-fine weights; the raw coordinates are never weighted.
///
/// Reverse pass to the point: `∂L/∂p = ∂L/∂γ · ∂γ/∂p` with
/// `∂/∂x [w sin(ωx), w cos(ωx)] = [w ω cos(ωx), −w ω sin(ωx)]`
/// ([`Embedding::backward_input`]).
///
/// Parameters are the MLP's ([`Mlp::params`] layout: `W_0, b_0, W_1, b_1, …`, each `W`
/// `[fan_in × fan_out]` column-major).
#[derive(Clone, Debug)]
pub struct PeMlpField<S: Real = f32> {
    config: PeMlpConfig,
    embedding: Embedding,
    mlp: Mlp<S>,
    ws: Workspace<S>,
}

/// Buffers of one forward/backward pair (grow with the batch, never shrink).
#[derive(Clone, Debug, Default)]
struct Workspace<S: Real> {
    /// Batch size of the last forward pass.
    n: usize,
    /// Points `[n × 2]` column-major, in `f64` (the embedding's input).
    x: Vec<f64>,
    /// Encoding `γ` `[n × (2 + 4L)]` column-major (the MLP's input).
    enc: Vec<S>,
    mlp: MlpWorkspace<S>,
    /// Colours `[n × 3]` column-major.
    rgb: Vec<S>,
    /// `∂L/∂z` of the sigmoid's input, `[n × 3]`.
    grad_z: Vec<S>,
    /// `∂L/∂γ`, `[n × (2 + 4L)]`.
    grad_enc: Vec<S>,
    /// `∂L/∂p`, `[n × 2]` column-major.
    grad_x: Vec<f64>,
}

impl<S: Real> PeMlpField<S> {
    /// The configuration it was built from.
    pub fn config(&self) -> &PeMlpConfig {
        &self.config
    }

    /// The current band weights `w_k` (all 1 without coarse-to-fine).
    pub fn band_weights(&self) -> &[f64] {
        self.embedding.weights()
    }
}

impl<S: Real> ImageField<S> for PeMlpField<S> {
    fn num_params(&self) -> usize {
        self.mlp.num_params()
    }

    fn params(&self) -> &[S] {
        &self.mlp.params
    }

    fn params_mut(&mut self) -> &mut [S] {
        &mut self.mlp.params
    }

    fn set_progress(&mut self, progress: f64) {
        let [start, end] = c2f_window(self.config.c2f);
        self.embedding.set_coarse_to_fine(progress, start, end);
    }

    fn forward(&mut self, points: &[S], rgb: &mut [S]) {
        let n = batch_len(points, rgb);
        let ws = &mut self.ws;
        let dim = self.embedding.output_dim();
        ws.n = n;
        grow(&mut ws.x, 2 * n);
        grow(&mut ws.enc, n * dim);
        grow(&mut ws.rgb, 3 * n);
        for i in 0..n {
            ws.x[i] = points[2 * i].to_f64();
            ws.x[n + i] = points[2 * i + 1].to_f64();
        }
        self.embedding.encode(&ws.x, n, 1, &mut ws.enc);
        self.mlp.forward(&ws.enc, n, 1, &mut ws.mlp);
        sigmoid_forward(ws.mlp.output(), n, &mut ws.rgb, rgb);
    }

    fn backward(&mut self, grad_rgb: &[S], grad: &mut [S], grad_points: &mut [S]) {
        let ws = &mut self.ws;
        let n = ws.n;
        let dim = self.embedding.output_dim();
        assert!(
            grad_rgb.len() == 3 * n && grad_points.len() == 2 * n,
            "backward needs n × 3 colour and n × 2 point gradients for n = {n}"
        );
        grow(&mut ws.grad_z, 3 * n);
        grow(&mut ws.grad_enc, n * dim);
        grow(&mut ws.grad_x, 2 * n);
        sigmoid_backward(&ws.rgb, grad_rgb, n, &mut ws.grad_z);
        ws.grad_enc[..n * dim].fill(S::ZERO);
        self.mlp.backward(
            &ws.enc,
            &mut ws.mlp,
            &ws.grad_z,
            grad,
            Accum::Add,
            Some(&mut ws.grad_enc),
        );
        ws.grad_x[..2 * n].fill(0.0);
        self.embedding
            .backward_input(&ws.x, n, &ws.grad_enc, n, &mut ws.grad_x);
        for i in 0..n {
            grad_points[2 * i] = S::from_f64(ws.grad_x[i]);
            grad_points[2 * i + 1] = S::from_f64(ws.grad_x[n + i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand::seq::index::sample;
    use rand_chacha::ChaCha8Rng;

    use super::super::test_support::{assert_f32_matches_f64, check_gradients, points};
    use super::*;

    fn small() -> PeMlpConfig {
        PeMlpConfig {
            bands: 6,
            width: 16,
            hidden_layers: 3,
            c2f: Some([0.05, 0.45]),
            seed: 3,
        }
    }

    /// Parameters (weights and biases of every layer, sampled) and points against central
    /// differences at progress 0.3, where `α = 0.625 · 6 = 3.75` (band 3 at weight ≈ 0.85,
    /// bands 4, 5 off), and with all bands on.
    #[test]
    fn gradients_match_central_differences() {
        for (progress, c2f) in [(0.3, Some([0.05, 0.45])), (0.0, None)] {
            let mut field = PeMlpConfig { c2f, ..small() }.init::<f64>().expect("valid");
            field.set_progress(progress);
            if c2f.is_some() {
                let w = field.band_weights();
                assert!(w[3] > 0.5 && w[3] < 1.0 && w[4] == 0.0, "{w:?}");
            }
            let pts = points(12, 5, |_, _| false);
            let mut idx =
                sample(&mut ChaCha8Rng::seed_from_u64(1), field.num_params(), 60).into_vec();
            // First layer (`[26 × 16]` column-major): x → unit 0, sin(2^3 π x) (the partly
            // weighted band) → unit 2; then a last-layer weight and the last bias.
            let np = field.num_params();
            idx.extend([0, 26 * 2 + 5, np - 4, np - 1]);
            // ω ≤ 32π: truncation ~h²ω³/6 ≲ 1e-7 of the gradient scale.
            check_gradients(&mut field, &pts, &idx, 1e-6);
        }
    }

    #[test]
    fn colours_lie_in_the_unit_interval_and_follow_the_schedule() {
        let mut field = small().init::<f64>().expect("valid");
        assert!(field.band_weights().iter().all(|&w| w == 0.0));
        field.set_progress(1.0);
        assert!(field.band_weights().iter().all(|&w| w == 1.0));
        // Output biases (the last 3 parameters) of ±20 push red and blue towards 1 and 0.
        let np = field.num_params();
        field.params_mut()[np - 3] = 20.0;
        field.params_mut()[np - 1] = -20.0;
        let pts = points(200, 9, |_, _| false);
        let mut rgb = vec![0.0; 600];
        field.forward(&pts, &mut rgb);
        assert!(rgb.iter().all(|&c| c > 0.0 && c < 1.0));
        assert!(rgb.chunks(3).all(|c| c[0] > 0.99 && c[2] < 0.01));
    }

    #[test]
    fn init_is_deterministic_and_scales_the_first_layer_with_c2f() {
        let a = small().init::<f64>().expect("valid");
        let b = small().init::<f64>().expect("valid");
        assert_eq!(a.params(), b.params());
        let c = PeMlpConfig { seed: 4, ..small() }
            .init::<f64>()
            .expect("valid");
        assert_ne!(a.params(), c.params());
        let f = small().init::<f32>().expect("valid");
        assert!(
            a.params()
                .iter()
                .zip(f.params())
                .all(|(&a, &f)| a as f32 == f)
        );
        // With c2f the first layer (input 26, width 16) is sqrt(13) times larger, the rest equal.
        let off = PeMlpConfig {
            c2f: None,
            ..small()
        }
        .init::<f64>()
        .expect("valid");
        let first = 27 * 16;
        let s = 13f64.sqrt();
        for (k, (&on, &off)) in a.params().iter().zip(off.params()).enumerate() {
            let want = if k < first { off * s } else { off };
            assert!((on - want).abs() < 1e-15, "param {k}");
        }
        assert_eq!(
            PeMlpConfig::default()
                .init::<f32>()
                .expect("valid")
                .num_params(),
            34 * 256 + 256 + 3 * (256 * 256 + 256) + 256 * 3 + 3
        );
    }

    /// f32 and f64 fields from one seed agree (forward, and backward relative to its scale).
    #[test]
    fn f32_agrees_with_f64() {
        let mut a = small().init::<f64>().expect("valid");
        let mut b = small().init::<f32>().expect("valid");
        a.set_progress(0.3);
        b.set_progress(0.3);
        assert_f32_matches_f64(&mut a, &mut b, &points(64, 2, |_, _| false));
    }

    #[test]
    fn batch_size_may_change_between_calls() {
        let mut field = small().init::<f64>().expect("valid");
        field.set_progress(0.3);
        let pts = points(20, 4, |_, _| false);
        let mut big = vec![0.0; 60];
        field.forward(&pts, &mut big);
        let mut few = vec![0.0; 9];
        field.forward(&pts[..6], &mut few);
        assert_eq!(few, big[..9]);
        let mut gp = vec![0.0; 6];
        let mut grad = vec![0.0; field.num_params()];
        field.backward(&[0.1; 9], &mut grad, &mut gp);
        assert!(gp.iter().all(|g| g.is_finite()));
    }

    #[test]
    fn invalid_configs_name_the_key() {
        for (bad, key) in [
            (
                PeMlpConfig {
                    width: 0,
                    ..small()
                },
                "width",
            ),
            (
                PeMlpConfig {
                    hidden_layers: 0,
                    ..small()
                },
                "hidden_layers",
            ),
            (
                PeMlpConfig {
                    bands: 17,
                    ..small()
                },
                "bands",
            ),
            (
                PeMlpConfig {
                    c2f: Some([0.4, 0.2]),
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
            assert!(err.to_string().contains(key), "{err}");
        }
        let e = PeMlpConfig {
            width: 0,
            ..small()
        }
        .init::<f32>()
        .expect_err("invalid");
        assert_eq!(e.to_string(), "invalid width: expected at least 1, got 0");
    }

    #[test]
    fn config_parses_from_toml_and_rejects_typos() {
        let c: PeMlpConfig = toml::from_str("bands = 6\nc2f = [0, 0.5]").expect("valid toml");
        assert_eq!((c.bands, c.c2f, c.width), (6, Some([0.0, 0.5]), 256));
        let off: PeMlpConfig = toml::from_str("c2f = false").expect("valid toml");
        assert_eq!(off.c2f, None);
        assert_eq!(
            toml::from_str::<PeMlpConfig>("").expect("empty"),
            PeMlpConfig::default()
        );
        for text in [
            "widht = 3",
            "c2f = true",
            "c2f = [0.1]",
            "c2f = [0, 0.2, 0.4]",
        ] {
            assert!(toml::from_str::<PeMlpConfig>(text).is_err(), "{text}");
        }
        for c in [PeMlpConfig::default(), off] {
            let text = toml::to_string(&c).expect("serialises");
            assert_eq!(toml::from_str::<PeMlpConfig>(&text).expect("round trip"), c);
        }
    }
}
