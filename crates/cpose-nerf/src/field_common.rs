//! Pieces shared by the 2-D and 3-D neural fields: config validation, BARF's coarse-to-fine
//! weights, the `[start, end]`-or-`false` serde of a coarse-to-fine window and buffer growth.

use std::fmt;

use serde::de::{self, SeqAccess, Unexpected, Visitor};
use serde::{Deserializer, Serializer};

/// A configuration value out of its valid range; each field module's error converts from it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Invalid {
    /// The config key (as spelled in TOML).
    pub key: &'static str,
    /// What the key accepts.
    pub expected: String,
    /// The value given.
    pub got: String,
}

/// `Err(Invalid { … }.into())` for `key`.
pub(crate) fn invalid<T, E: From<Invalid>>(
    key: &'static str,
    expected: &str,
    got: impl fmt::Display,
) -> Result<T, E> {
    Err(Invalid {
        key,
        expected: expected.to_owned(),
        got: got.to_string(),
    }
    .into())
}

/// Checks a coarse-to-fine window: `0 ≤ start < end ≤ 1`.
pub(crate) fn check_c2f(c2f: Option<[f64; 2]>) -> Result<(), Invalid> {
    match c2f {
        Some([start, end]) if !(0.0 <= start && start < end && end <= 1.0) => invalid(
            "c2f",
            "[start, end] with 0 ≤ start < end ≤ 1, or false",
            format_args!("[{start}, {end}]"),
        ),
        _ => Ok(()),
    }
}

/// BARF's coarse-to-fine weights over `F = weights.len()` bands (or levels):
/// `α = (progress − start)/(end − start) · F`, `w_k = (1 − cos(π · clamp(α − k, 0, 1)))/2`;
/// all 1 when `c2f` is `None`.
pub(crate) fn coarse_to_fine_weights(progress: f64, c2f: Option<[f64; 2]>, weights: &mut [f64]) {
    let Some([start, end]) = c2f else {
        weights.fill(1.0);
        return;
    };
    let alpha = (progress - start) / (end - start) * weights.len() as f64;
    for (k, w) in weights.iter_mut().enumerate() {
        let a = (alpha - k as f64).clamp(0.0, 1.0);
        *w = (1.0 - (std::f64::consts::PI * a).cos()) / 2.0;
    }
}

/// Grows `v` to at least `n` entries (never shrinks, so buffers are reused).
pub(crate) fn grow<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
    if v.len() < n {
        v.resize(n, T::default());
    }
}

/// Serde of a coarse-to-fine window: `[start, end]` or `false` (off), so that TOML, which has
/// no null, can switch it off.
pub(crate) mod c2f_serde {
    use super::*;

    /// `Some([a, b])` as `[a, b]`, `None` as `false`.
    pub fn serialize<Z: Serializer>(c2f: &Option<[f64; 2]>, s: Z) -> Result<Z::Ok, Z::Error> {
        match c2f {
            Some(range) => serde::Serialize::serialize(range, s),
            None => s.serialize_bool(false),
        }
    }

    /// `[a, b]` as `Some([a, b])`; `false` (or null) as `None`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<[f64; 2]>, D::Error> {
        d.deserialize_any(C2fVisitor)
    }

    struct C2fVisitor;

    impl<'de> Visitor<'de> for C2fVisitor {
        type Value = Option<[f64; 2]>;

        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("[start, end] (fractions of training) or false")
        }

        fn visit_bool<E: de::Error>(self, v: bool) -> Result<Self::Value, E> {
            if v {
                Err(E::invalid_value(Unexpected::Bool(v), &self))
            } else {
                Ok(None)
            }
        }

        fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }

        fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
            let start = seq
                .next_element::<f64>()?
                .ok_or_else(|| de::Error::invalid_length(0, &self))?;
            let end = seq
                .next_element::<f64>()?
                .ok_or_else(|| de::Error::invalid_length(1, &self))?;
            if seq.next_element::<de::IgnoredAny>()?.is_some() {
                return Err(de::Error::invalid_length(3, &self));
            }
            Ok(Some([start, end]))
        }
    }
}

#[cfg(test)]
mod tests {
    use cpose_core::nn::{Embedding, Encoding};

    use super::*;

    /// The level weights use the same schedule as the embedding's band weights.
    #[test]
    fn coarse_to_fine_weights_match_the_embedding_schedule() {
        let mut e = Embedding::new(Encoding::Sinusoidal, 2, 6);
        let mut w = [0.0; 6];
        for progress in [0.0, 0.05, 0.13, 0.3, 0.41, 0.9] {
            e.set_coarse_to_fine(progress, 0.05, 0.45);
            coarse_to_fine_weights(progress, Some([0.05, 0.45]), &mut w);
            assert_eq!(w, e.weights());
        }
        coarse_to_fine_weights(0.0, None, &mut w);
        assert!(w.iter().all(|&w| w == 1.0));
    }

    #[test]
    fn c2f_window_is_validated() {
        assert!(check_c2f(None).is_ok());
        assert!(check_c2f(Some([0.0, 0.4])).is_ok());
        for bad in [
            [0.4, 0.4],
            [0.5, 0.1],
            [-0.1, 0.4],
            [0.0, 1.5],
            [f64::NAN, 0.4],
        ] {
            let err = check_c2f(Some(bad)).expect_err("invalid window");
            assert_eq!(err.key, "c2f", "{err:?}");
        }
    }
}
