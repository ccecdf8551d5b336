//! A multilayer perceptron with an optional skip connection, tangent streams and a hand-written
//! reverse pass through them (docs/methods.md §5.2).
//!
//! Layout. Activations are `[rows × features]` column-major with `rows = streams · b`: the `b`
//! values first, then the `b` first derivatives, then the `b` second derivatives (with respect to
//! one scalar input parameter, e.g. time). One matrix product per layer serves all streams:
//! `[z; ż; z̈] = [x; ẋ; ẍ] W (+ b on the value block)`. Layer `l` has weights `W_l`
//! (`[fan_in × fan_out]`, column-major) followed by its bias; all layers live in one flat `Vec`.
//! The skip layer reads `[h, γ]` (h first): its weight rows split into a block for `h` and one
//! for the network input `γ`, so no concatenation is copied.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::activation::{Activation, tangent_adjoint};
use crate::Real;

/// Weight initialisation of a linear layer (`fan_in` counts every input, skip included).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Init {
    /// Xavier/Glorot uniform: `W ~ U(±gain·sqrt(6/(fan_in + fan_out)))`, bias 0.
    XavierUniform {
        /// Gain (1 for PoseNet).
        gain: f64,
    },
    /// PyTorch's default `Linear` init: `W, b ~ U(±1/sqrt(fan_in))`.
    TorchDefault,
    /// `W ~ U(lo, hi)`, bias 0 (PoseNet's last layer: `U(0, 1e-6)`).
    Uniform {
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
}

/// Shape of an [`Mlp`]: `depth` linear layers, ReLU-like activation after all but the last.
#[derive(Clone, Debug, PartialEq)]
pub struct MlpSpec {
    /// Width of the (encoded) input.
    pub input_dim: usize,
    /// Width of every hidden layer.
    pub width: usize,
    /// Number of linear layers (≥ 1).
    pub depth: usize,
    /// Width of the output.
    pub output_dim: usize,
    /// Layer (1..depth) that reads `[h, input]` instead of `h`; `None` for no skip.
    pub skip_layer: Option<usize>,
    /// Activation after every layer but the last.
    pub activation: Activation,
    /// Initialisation of all layers but the last.
    pub hidden_init: Init,
    /// Initialisation of the last layer.
    pub output_init: Init,
}

/// One linear layer inside the flat parameter vector.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Layer {
    /// Inputs from the previous hidden layer (0 for the first layer).
    from_h: usize,
    /// Inputs from the network input (first layer and skip layer, else 0).
    from_x: usize,
    out: usize,
    /// Offset of `W` (`[from_h + from_x] × out`); the bias follows it.
    offset: usize,
}

impl Layer {
    fn fan_in(&self) -> usize {
        self.from_h + self.from_x
    }
    fn bias_offset(&self) -> usize {
        self.offset + self.fan_in() * self.out
    }
    fn end(&self) -> usize {
        self.bias_offset() + self.out
    }
}

/// A multilayer perceptron whose parameters are one contiguous vector.
#[derive(Clone, Debug)]
pub struct Mlp<S: Real> {
    spec: MlpSpec,
    layers: Vec<Layer>,
    /// All weights and biases, layer by layer (`W_0, b_0, W_1, b_1, …`).
    pub params: Vec<S>,
}

/// Activations of one forward pass (reused between calls; grows, never shrinks).
#[derive(Clone, Debug, Default)]
pub struct MlpWorkspace<S: Real> {
    b: usize,
    streams: usize,
    /// Per layer: the product `[xW; ẋW; ẍW]`; for the last layer (the output) with the bias.
    z: Vec<Vec<S>>,
    /// Per hidden layer: `[h; ḣ; ḧ]`.
    h: Vec<Vec<S>>,
    /// Per hidden layer: `σ'(z)` of the value block (`[b × width]`).
    s1: Vec<Vec<S>>,
    /// Two gradient buffers (`[rows × max width]`), swapped layer by layer.
    g: Vec<S>,
    g2: Vec<S>,
}

fn grow<S: Real>(v: &mut Vec<S>, n: usize) {
    if v.len() < n {
        v.resize(n, S::ZERO);
    }
}

fn mat<S: Real>(s: &[S], rows: usize, cols: usize) -> MatRef<'_, S> {
    MatRef::from_column_major_slice(&s[..rows * cols], rows, cols)
}

fn mat_mut<S: Real>(s: &mut [S], rows: usize, cols: usize) -> MatMut<'_, S> {
    MatMut::from_column_major_slice_mut(&mut s[..rows * cols], rows, cols)
}

impl<S: Real> MlpWorkspace<S> {
    /// Batch size `b` and stream count of the last forward pass.
    pub fn shape(&self) -> (usize, usize) {
        (self.b, self.streams)
    }

    /// The output `[streams·b × output_dim]` (column-major) of the last forward pass.
    pub fn output(&self) -> &[S] {
        self.z.last().map_or(&[], |z| &z[..])
    }
}

impl<S: Real> Mlp<S> {
    /// A network of shape `spec`, initialised from `rng`. Weights are drawn in `f64` in storage
    /// order (layer by layer, `W` column-major, then `b`) and rounded to `S`, so `f32` and `f64`
    /// networks from the same seed agree.
    pub fn new(spec: MlpSpec, rng: &mut ChaCha8Rng) -> Self {
        assert!(
            spec.depth >= 1 && spec.width >= 1,
            "an MLP needs at least one layer and unit"
        );
        let mut layers = Vec::with_capacity(spec.depth);
        let mut offset = 0;
        for l in 0..spec.depth {
            let from_h = if l == 0 { 0 } else { spec.width };
            let from_x = if l == 0 || spec.skip_layer == Some(l) {
                spec.input_dim
            } else {
                0
            };
            let out = if l + 1 == spec.depth {
                spec.output_dim
            } else {
                spec.width
            };
            let layer = Layer {
                from_h,
                from_x,
                out,
                offset,
            };
            offset = layer.end();
            layers.push(layer);
        }
        let mut params = vec![S::ZERO; offset];
        for (l, layer) in layers.iter().enumerate() {
            let init = if l + 1 == spec.depth {
                spec.output_init
            } else {
                spec.hidden_init
            };
            let (fi, fo) = (layer.fan_in() as f64, layer.out as f64);
            let (w_lo, w_hi, b_bound) = match init {
                Init::XavierUniform { gain } => {
                    let a = gain * (6.0 / (fi + fo)).sqrt();
                    (-a, a, 0.0)
                }
                Init::TorchDefault => (-1.0 / fi.sqrt(), 1.0 / fi.sqrt(), 1.0 / fi.sqrt()),
                Init::Uniform { lo, hi } => (lo, hi, 0.0),
            };
            let mut draw = |lo: f64, hi: f64| {
                if lo < hi {
                    S::from_f64(rng.random_range(lo..hi))
                } else {
                    S::from_f64(lo)
                }
            };
            for p in &mut params[layer.offset..layer.bias_offset()] {
                *p = draw(w_lo, w_hi);
            }
            for p in &mut params[layer.bias_offset()..layer.end()] {
                *p = draw(-b_bound, b_bound);
            }
        }
        Self {
            spec,
            layers,
            params,
        }
    }

    /// A network from a seed (`ChaCha8Rng::seed_from_u64`).
    pub fn seeded(spec: MlpSpec, seed: u64) -> Self {
        Self::new(spec, &mut ChaCha8Rng::seed_from_u64(seed))
    }

    /// The shape.
    pub fn spec(&self) -> &MlpSpec {
        &self.spec
    }

    /// Number of parameters.
    pub fn num_params(&self) -> usize {
        self.params.len()
    }

    /// Multiply-adds per batch row of one pass (`Σ fan_in · fan_out`); a forward pass costs
    /// `2 · rows · macs` FLOPs in matrix products, a backward twice that.
    pub fn macs_per_row(&self) -> usize {
        self.layers.iter().map(|l| l.fan_in() * l.out).sum()
    }

    fn weights(&self, layer: &Layer) -> MatRef<'_, S> {
        mat(
            &self.params[layer.offset..layer.bias_offset()],
            layer.fan_in(),
            layer.out,
        )
    }

    /// Forward pass of `b` samples with `streams` (1–3) stacked streams. `input` is
    /// `[streams·b × input_dim]` column-major (values, then tangents of the input); the output
    /// is [`MlpWorkspace::output`]. Allocates only when the batch grows.
    pub fn forward(&self, input: &[S], b: usize, streams: usize, ws: &mut MlpWorkspace<S>) {
        assert!((1..=3).contains(&streams), "1 to 3 streams");
        let rows = streams * b;
        let nl = self.layers.len();
        let x = mat(input, rows, self.spec.input_dim);
        ws.b = b;
        ws.streams = streams;
        ws.z.resize_with(nl, Vec::new);
        ws.h.resize_with(nl - 1, Vec::new);
        ws.s1.resize_with(nl - 1, Vec::new);
        let act = self.spec.activation;
        for (l, layer) in self.layers.iter().enumerate() {
            grow(&mut ws.z[l], rows * layer.out);
            let w = self.weights(layer);
            {
                let mut z = mat_mut(&mut ws.z[l], rows, layer.out);
                let mut accum = Accum::Replace;
                if layer.from_h > 0 {
                    let hp = mat(&ws.h[l - 1], rows, layer.from_h);
                    matmul(
                        z.as_mut(),
                        accum,
                        hp,
                        w.subrows(0, layer.from_h),
                        S::ONE,
                        Par::Seq,
                    );
                    accum = Accum::Add;
                }
                if layer.from_x > 0 {
                    matmul(
                        z.as_mut(),
                        accum,
                        x,
                        w.subrows(layer.from_h, layer.from_x),
                        S::ONE,
                        Par::Seq,
                    );
                }
            }
            let bias = &self.params[layer.bias_offset()..layer.end()];
            let z = &mut ws.z[l];
            if l + 1 == nl {
                for (c, &bc) in bias.iter().enumerate() {
                    for v in &mut z[c * rows..c * rows + b] {
                        *v += bc;
                    }
                }
                break;
            }
            grow(&mut ws.h[l], rows * layer.out);
            let slopes = if act.is_piecewise_linear() { 0 } else { b };
            grow(&mut ws.s1[l], slopes * layer.out);
            let (h, s1) = (&mut ws.h[l], &mut ws.s1[l]);
            for (c, &bc) in bias.iter().enumerate() {
                let zc = &z[c * rows..(c + 1) * rows];
                let hc = &mut h[c * rows..(c + 1) * rows];
                let sc = &mut s1[c * slopes..(c + 1) * slopes];
                activate_column(act, b, streams, bc, zc, hc, sc);
            }
        }
    }

    /// Reverse pass of the last [`Mlp::forward`] on `input`. `grad_out` is `∂L/∂output` with the
    /// output's layout (all streams). Writes (`Accum::Replace`) or adds (`Accum::Add`) `∂L/∂θ`
    /// into `grad` (length [`Mlp::num_params`]), and adds `∂L/∂input` (all streams) into
    /// `input_grad` when given. Per hidden layer, with `G` the cotangent of `[h; ḣ; ḧ]`:
    /// `[gz; gż; gz̈]` from [`Activation::tangent_backward`]'s formulas,
    /// `dW = [x; ẋ; ẍ]ᵀ [gz; gż; gz̈]` (one product, `k = rows`), `db = Σ gz`,
    /// `[gx; gẋ; gẍ] = [gz; gż; gz̈] Wᵀ`.
    pub fn backward(
        &self,
        input: &[S],
        ws: &mut MlpWorkspace<S>,
        grad_out: &[S],
        grad: &mut [S],
        accum: Accum,
        input_grad: Option<&mut [S]>,
    ) {
        assert!(grad.len() == self.params.len(), "gradient length");
        self.reverse(input, ws, grad_out, Some((grad, accum)), input_grad);
    }

    /// [`Mlp::backward`] without `∂L/∂θ`: adds only `∂L/∂input` into `input_grad` (the
    /// parameters held fixed, e.g. a pose tracked against a trained map).
    pub fn backward_input(
        &self,
        input: &[S],
        ws: &mut MlpWorkspace<S>,
        grad_out: &[S],
        input_grad: &mut [S],
    ) {
        self.reverse(input, ws, grad_out, None, Some(input_grad));
    }

    /// The reverse pass of [`Mlp::backward`], `∂L/∂θ` only when `grad` is given.
    fn reverse(
        &self,
        input: &[S],
        ws: &mut MlpWorkspace<S>,
        grad_out: &[S],
        mut grad: Option<(&mut [S], Accum)>,
        mut input_grad: Option<&mut [S]>,
    ) {
        let (b, streams) = (ws.b, ws.streams);
        let rows = streams * b;
        let nl = self.layers.len();
        assert!(
            grad_out.len() >= rows * self.spec.output_dim,
            "output gradient length"
        );
        let maxw = self.spec.width.max(self.spec.output_dim);
        grow(&mut ws.g, rows * maxw);
        grow(&mut ws.g2, rows * maxw);
        let x = mat(input, rows, self.spec.input_dim);
        let act = self.spec.activation;
        for l in (0..nl).rev() {
            let layer = self.layers[l];
            let out = layer.out;
            // Cotangent of this layer's pre-activation, in `gz` (`grad_out` for the last layer).
            let gz: &[S] = if l + 1 == nl {
                &grad_out[..rows * out]
            } else {
                let g = &mut ws.g[..rows * out];
                let (h, s1, z) = (&ws.h[l], &ws.s1[l], &ws.z[l]);
                let slopes = if act.is_piecewise_linear() { 0 } else { b };
                for c in 0..out {
                    let r = c * rows..(c + 1) * rows;
                    adjoint_column(
                        act,
                        b,
                        streams,
                        &z[r.clone()],
                        &h[r.clone()],
                        &s1[c * slopes..(c + 1) * slopes],
                        &mut g[r],
                    );
                }
                &ws.g[..rows * out]
            };
            let gzm = mat(gz, rows, out);
            if let Some((grad, accum)) = grad.as_mut() {
                let accum = *accum;
                // Bias: Σ over the value rows.
                let gb = &mut grad[layer.bias_offset()..layer.end()];
                for (c, gbc) in gb.iter_mut().enumerate() {
                    let s: S = gz[c * rows..c * rows + b].iter().copied().sum();
                    match accum {
                        Accum::Replace => *gbc = s,
                        Accum::Add => *gbc += s,
                    }
                }
                let gw_slice = &mut grad[layer.offset..layer.bias_offset()];
                let mut gw = mat_mut(gw_slice, layer.fan_in(), out);
                if layer.from_h > 0 {
                    let hp = mat(&ws.h[l - 1], rows, layer.from_h);
                    matmul(
                        gw.as_mut().subrows_mut(0, layer.from_h),
                        accum,
                        hp.transpose(),
                        gzm,
                        S::ONE,
                        Par::Seq,
                    );
                }
                if layer.from_x > 0 {
                    let gwx = gw.as_mut().subrows_mut(layer.from_h, layer.from_x);
                    matmul(gwx, accum, x.transpose(), gzm, S::ONE, Par::Seq);
                }
            }
            if layer.from_x > 0
                && let Some(gi) = input_grad.as_deref_mut()
            {
                let gi = mat_mut(gi, rows, self.spec.input_dim);
                let wx = self.weights(&layer).subrows(layer.from_h, layer.from_x);
                matmul(gi, Accum::Add, gzm, wx.transpose(), S::ONE, Par::Seq);
            }
            if layer.from_h > 0 {
                let wh = self.weights(&layer).subrows(0, layer.from_h);
                let gh = mat_mut(&mut ws.g2, rows, layer.from_h);
                matmul(gh, Accum::Replace, gzm, wh.transpose(), S::ONE, Par::Seq);
                std::mem::swap(&mut ws.g, &mut ws.g2);
            }
        }
    }
}

/// Bias, activation and tangents of one column: `h = σ(z + b)` (value rows),
/// `ḣ = σ'(z) ż`, `ḧ = σ'(z) z̈ + σ''(z) ż²`; stores `σ'(z)` in `s1` (unused for ReLU, whose
/// slope is `h > 0`). The value block of `z` is not needed later and is left without the bias.
#[inline]
fn activate_column<S: Real>(
    act: Activation,
    b: usize,
    streams: usize,
    bias: S,
    z: &[S],
    h: &mut [S],
    s1: &mut [S],
) {
    let (z0, zt) = z.split_at(b);
    let (h0, ht) = h.split_at_mut(b);
    if act.is_piecewise_linear() {
        for i in 0..b {
            h0[i] = (z0[i] + bias).max(S::ZERO);
        }
        for s in 0..streams - 1 {
            let (zs, hs) = (&zt[s * b..(s + 1) * b], &mut ht[s * b..(s + 1) * b]);
            for i in 0..b {
                hs[i] = if h0[i] > S::ZERO { zs[i] } else { S::ZERO };
            }
        }
        return;
    }
    for i in 0..b {
        let (hi, si) = act.value_and_slope(z0[i] + bias);
        h0[i] = hi;
        s1[i] = si;
    }
    if streams >= 2 {
        for i in 0..b {
            ht[i] = s1[i] * zt[i];
        }
    }
    if streams >= 3 {
        let (zd, zdd) = zt.split_at(b);
        let hdd = &mut ht[b..2 * b];
        for i in 0..b {
            let (s2, _) = act.curvature(h0[i], s1[i]);
            hdd[i] = s1[i] * zdd[i] + s2 * zd[i] * zd[i];
        }
    }
}

/// In place, `g ← [gz; gż; gz̈]` from `g = [gh; gḣ; gḧ]` for one column (docs/methods.md §5.2).
#[inline]
fn adjoint_column<S: Real>(
    act: Activation,
    b: usize,
    streams: usize,
    z: &[S],
    h: &[S],
    s1: &[S],
    g: &mut [S],
) {
    if act.is_piecewise_linear() {
        // σ'' = 0: every stream is masked by σ' = [h > 0].
        for s in 0..streams {
            let gs = &mut g[s * b..(s + 1) * b];
            for i in 0..b {
                if h[i] <= S::ZERO {
                    gs[i] = S::ZERO;
                }
            }
        }
        return;
    }
    match streams {
        1 => {
            for i in 0..b {
                g[i] *= s1[i];
            }
        }
        _ => {
            for i in 0..b {
                let (s2, s3) = act.curvature(h[i], s1[i]);
                let zt = [z[b + i], if streams >= 3 { z[2 * b + i] } else { S::ZERO }];
                let gi = [
                    g[i],
                    g[b + i],
                    if streams >= 3 { g[2 * b + i] } else { S::ZERO },
                ];
                let r = tangent_adjoint(s1[i], s2, s3, zt, gi, streams);
                for s in 0..streams {
                    g[s * b + i] = r[s];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(act: Activation, skip: Option<usize>) -> MlpSpec {
        MlpSpec {
            input_dim: 3,
            width: 16,
            depth: 4,
            output_dim: 2,
            skip_layer: skip,
            activation: act,
            hidden_init: Init::XavierUniform { gain: 1.0 },
            output_init: Init::TorchDefault,
        }
    }

    /// Input curves x(t) = (t, sin 2t, t³ − t) for samples t_i, with exact tangents.
    fn input(ts: &[f64], streams: usize) -> Vec<f64> {
        let b = ts.len();
        let mut x = vec![0.0; 3 * streams * b];
        for (i, &t) in ts.iter().enumerate() {
            let vals = [
                [t, 1.0, 0.0],
                [
                    (2.0 * t).sin(),
                    2.0 * (2.0 * t).cos(),
                    -4.0 * (2.0 * t).sin(),
                ],
                [t * t * t - t, 3.0 * t * t - 1.0, 6.0 * t],
            ];
            for d in 0..3 {
                for s in 0..streams {
                    x[d * streams * b + s * b + i] = vals[d][s];
                }
            }
        }
        x
    }

    fn run(mlp: &Mlp<f64>, ts: &[f64], streams: usize) -> Vec<f64> {
        let mut ws = MlpWorkspace::default();
        mlp.forward(&input(ts, streams), ts.len(), streams, &mut ws);
        ws.output().to_vec()
    }

    /// First and second output tangents against central differences of the value stream in t
    /// (h = 1e-5 for d/dt: error ~h² ≈ 1e-10; h = 1e-4 for d²/dt²: error ~h² + ε/h² ≈ 1e-8;
    /// tolerances 1e-7 and 1e-5 leave room for the network's larger higher derivatives).
    #[test]
    fn tangents_match_central_differences() {
        for act in [
            Activation::Softplus,
            Activation::Tanh,
            Activation::Sigmoid,
            Activation::Relu,
        ] {
            let mlp = Mlp::<f64>::seeded(spec(act, Some(2)), 7);
            let ts = [-0.83, -0.2, 0.15, 0.61, 0.97];
            let b = ts.len();
            let out = run(&mlp, &ts, 3);
            let at = |dt: f64| run(&mlp, &ts.map(|t| t + dt), 1);
            let (h1, h2) = (1e-5, 1e-4);
            let (p1, m1, p2, m2, c) = (at(h1), at(-h1), at(h2), at(-h2), at(0.0));
            for o in 0..2 {
                for i in 0..b {
                    let j = o * b + i;
                    let fd1 = (p1[j] - m1[j]) / (2.0 * h1);
                    let fd2 = (p2[j] - 2.0 * c[j] + m2[j]) / (h2 * h2);
                    let (d1, d2) = (out[o * 3 * b + b + i], out[o * 3 * b + 2 * b + i]);
                    assert!((out[o * 3 * b + i] - c[j]).abs() < 1e-14);
                    assert!(
                        (fd1 - d1).abs() < 1e-7,
                        "{act:?} d1 out {o} sample {i}: {fd1} vs {d1}"
                    );
                    if act != Activation::Relu {
                        assert!(
                            (fd2 - d2).abs() < 1e-5,
                            "{act:?} d2 out {o} sample {i}: {fd2} vs {d2}"
                        );
                    }
                }
            }
        }
    }

    /// ∂L/∂θ and ∂L/∂x for L = Σ c ⊙ [o; ȯ; ö] (weights c fixed) against central differences
    /// (h = 1e-6, error ~h²·|L'''| + ε/h ≈ 1e-10; tolerance 1e-7 relative).
    #[test]
    fn parameter_gradients_match_central_differences() {
        for (act, streams) in [
            (Activation::Softplus, 3),
            (Activation::Tanh, 2),
            (Activation::Relu, 1),
            (Activation::Sigmoid, 3),
        ] {
            let mut mlp = Mlp::<f64>::seeded(spec(act, Some(2)), 3);
            let ts = [-0.5, 0.1, 0.4, 0.9];
            let b = ts.len();
            let rows = streams * b;
            let c: Vec<f64> = (0..rows * 2)
                .map(|k| ((k * 7 % 11) as f64 - 5.0) * 0.1)
                .collect();
            let x = input(&ts, streams);
            let loss = |mlp: &Mlp<f64>, x: &[f64]| {
                let mut ws = MlpWorkspace::default();
                mlp.forward(x, b, streams, &mut ws);
                ws.output().iter().zip(&c).map(|(a, b)| a * b).sum::<f64>()
            };
            let mut ws = MlpWorkspace::default();
            mlp.forward(&x, b, streams, &mut ws);
            let mut grad = vec![1.0; mlp.num_params()];
            let mut gx = vec![0.0; x.len()];
            mlp.backward(&x, &mut ws, &c, &mut grad, Accum::Replace, Some(&mut gx));
            let h = 1e-6;
            for k in (0..mlp.num_params()).step_by(7) {
                let p0 = mlp.params[k];
                mlp.params[k] = p0 + h;
                let lp = loss(&mlp, &x);
                mlp.params[k] = p0 - h;
                let lm = loss(&mlp, &x);
                mlp.params[k] = p0;
                let fd = (lp - lm) / (2.0 * h);
                assert!(
                    (fd - grad[k]).abs() < 1e-7 * (1.0 + fd.abs()),
                    "{act:?} param {k}: {fd} vs {}",
                    grad[k]
                );
            }
            for k in 0..x.len() {
                let mut xp = x.clone();
                xp[k] += h;
                let mut xm = x.clone();
                xm[k] -= h;
                let fd = (loss(&mlp, &xp) - loss(&mlp, &xm)) / (2.0 * h);
                assert!(
                    (fd - gx[k]).abs() < 1e-7 * (1.0 + fd.abs()),
                    "{act:?} input {k}: {fd} vs {}",
                    gx[k]
                );
            }
            // The input gradient alone is the same, bit for bit.
            let mut gx_only = vec![0.0; x.len()];
            mlp.backward_input(&x, &mut ws, &c, &mut gx_only);
            assert_eq!(gx_only, gx, "{act:?} backward_input");
            // Accumulation adds onto what is there.
            let mut grad2 = grad.clone();
            mlp.backward(&x, &mut ws, &c, &mut grad2, Accum::Add, None);
            assert!(
                grad2
                    .iter()
                    .zip(&grad)
                    .all(|(a, b)| (a - 2.0 * b).abs() < 1e-12)
            );
        }
    }

    #[test]
    fn init_bounds_and_layout() {
        let s = MlpSpec {
            output_init: Init::Uniform { lo: 0.0, hi: 1e-6 },
            ..spec(Activation::Relu, Some(2))
        };
        let mlp = Mlp::<f32>::seeded(s, 1);
        // Layers: 3→16, 16→16, (16+3)→16, 16→2.
        assert_eq!(
            mlp.num_params(),
            3 * 16 + 16 + 16 * 16 + 16 + 19 * 16 + 16 + 16 * 2 + 2
        );
        let last = &mlp.params[mlp.num_params() - 34..];
        assert!(last[..32].iter().all(|&w| (0.0..1e-6).contains(&w)));
        assert!(last[32..].iter().all(|&b| b == 0.0));
        let a = (6.0f32 / 19.0).sqrt();
        assert!(
            mlp.params[..48].iter().all(|w| w.abs() <= a)
                && mlp.params[48..64].iter().all(|&b| b == 0.0)
        );
        let t = Mlp::<f64>::seeded(
            MlpSpec {
                hidden_init: Init::TorchDefault,
                ..spec(Activation::Relu, None)
            },
            1,
        );
        assert!(
            t.params[48..64]
                .iter()
                .all(|b| b.abs() <= 1.0 / 3f64.sqrt())
                && t.params[48] != 0.0
        );
    }
}
