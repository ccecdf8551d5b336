//! Pieces shared by the 2-D and 3-D neural fields: config validation, the coarse-to-fine window
//! (its `[start, end]`-or-`false` serde, and `None` as the window that switches every band on)
//! and buffer growth.

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

/// The `[start, end]` of an optional coarse-to-fine window for
/// [`cpose_core::nn::coarse_to_fine_weights`]: `None` is the empty window `[1, 0]`, every band
/// (or level) fully on.
pub(crate) fn c2f_window(c2f: Option<[f64; 2]>) -> [f64; 2] {
    c2f.unwrap_or([1.0, 0.0])
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
    use super::*;

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
