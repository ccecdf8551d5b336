//! Adam over a radiance field's parameters, one learning-rate schedule per parameter group: the
//! field's optimiser in every task that trains a [`RadianceField`] (`nerf`, `events`).

use std::collections::BTreeMap;

use anyhow::bail;
use cpose_core::nn::{Adam, ExponentialDecay};

use super::RadianceField;

/// Adam over a radiance field's parameters with one exponentially decaying learning rate per
/// parameter group (`[start, end]` over `iterations` steps).
pub struct FieldOptimizer {
    groups: Vec<(std::ops::Range<usize>, ExponentialDecay)>,
    adam: Adam<f32>,
}

impl FieldOptimizer {
    /// Errors naming the group when `field_lr` has no rate for one of the field's groups.
    pub fn new(
        field: &dyn RadianceField,
        field_lr: &BTreeMap<String, [f64; 2]>,
        iterations: u64,
    ) -> anyhow::Result<Self> {
        let mut groups = Vec::new();
        for (name, range) in field.param_groups() {
            let Some(&[lr0, lr_end]) = field_lr.get(name) else {
                bail!(
                    "no learning rate for the field's parameter group {name:?} (groups: {})",
                    field
                        .param_groups()
                        .iter()
                        .map(|(n, _)| *n)
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            };
            let decay = ExponentialDecay {
                lr0,
                lr_end,
                max_iter: iterations,
            };
            groups.push((range, decay));
        }
        Ok(Self {
            groups,
            adam: Adam::new(field.num_params()),
        })
    }

    /// Starts afresh for a round of `iterations` steps: Adam's moments cleared, every decay
    /// stretched over the round.
    pub fn restart(&mut self, iterations: u64) {
        self.adam.reset();
        for (_, decay) in &mut self.groups {
            decay.max_iter = iterations;
        }
    }

    /// Adam's moments and step count (for checkpoints).
    pub fn adam(&self) -> &Adam<f32> {
        &self.adam
    }

    /// Adam's state, to restore a checkpoint.
    pub fn adam_mut(&mut self) -> &mut Adam<f32> {
        &mut self.adam
    }

    /// One Adam step of every group from the gradient `grad` at iteration `it`.
    pub fn step(&mut self, field: &mut dyn RadianceField, grad: &[f32], it: u64) {
        self.adam.begin_step();
        let params = field.params_mut();
        for (range, decay) in &self.groups {
            self.adam.update(
                range.start,
                &mut params[range.clone()],
                &grad[range.clone()],
                decay.lr(it),
            );
        }
    }
}
