//! NumPy `.npy` arrays: a reader for the little-endian, C-order arrays numpy writes, and a writer
//! (format 1.0) that numpy reads back. Used by the LLFF reader (`poses_bounds.npy`) and, inside
//! `.npz` archives, by the event readers of `cpose-events`.
//!
//! # Format
//!
//! `\x93NUMPY`, a major and a minor version byte, the header length (2 bytes little-endian in
//! version 1, 4 bytes in versions 2 and 3), the header — a Python dict literal such as
//! `{'descr': '<f8', 'fortran_order': False, 'shape': (20, 17), }` padded with spaces and a
//! newline — then the raw values.
//!
//! Supported element types ([`Dtype`]) are those numpy produces for numeric columns: booleans,
//! 8- to 64-bit integers and 32- or 64-bit floats, little endian (`<`; one-byte types are
//! written `|`). Big-endian data, Fortran order, structured and object arrays are rejected.

use std::fmt;

/// A failure to parse an NPY array, as "expected …, got …" (the caller adds the file name).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("expected {expected}, got {found}")]
pub struct NpyError {
    /// What the reader expected.
    pub expected: String,
    /// What it found.
    pub found: String,
}

impl NpyError {
    fn new(expected: impl Into<String>, found: impl Into<String>) -> Self {
        Self {
            expected: expected.into(),
            found: found.into(),
        }
    }
}

/// The element type of an NPY array (little endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dtype {
    /// `|b1`: one byte, 0 or 1.
    Bool,
    /// `|i1`.
    I8,
    /// `|u1`.
    U8,
    /// `<i2`.
    I16,
    /// `<u2`.
    U16,
    /// `<i4`.
    I32,
    /// `<u4`.
    U32,
    /// `<i8`.
    I64,
    /// `<u8`.
    U64,
    /// `<f4`.
    F32,
    /// `<f8`.
    F64,
}

impl Dtype {
    /// Every supported type, in the order of the enum.
    pub const ALL: [Dtype; 11] = [
        Dtype::Bool,
        Dtype::I8,
        Dtype::U8,
        Dtype::I16,
        Dtype::U16,
        Dtype::I32,
        Dtype::U32,
        Dtype::I64,
        Dtype::U64,
        Dtype::F32,
        Dtype::F64,
    ];

    /// The `descr` string numpy writes for this type (`'|b1'`, `'<i4'`, …, without quotes).
    pub fn descr(self) -> &'static str {
        match self {
            Dtype::Bool => "|b1",
            Dtype::I8 => "|i1",
            Dtype::U8 => "|u1",
            Dtype::I16 => "<i2",
            Dtype::U16 => "<u2",
            Dtype::I32 => "<i4",
            Dtype::U32 => "<u4",
            Dtype::I64 => "<i8",
            Dtype::U64 => "<u8",
            Dtype::F32 => "<f4",
            Dtype::F64 => "<f8",
        }
    }

    /// The type of a `descr` string (without quotes). One-byte types are accepted with either
    /// `|` or `<`; multi-byte types need `<` (little endian).
    pub fn from_descr(descr: &str) -> Option<Dtype> {
        let (order, code) = descr.split_at_checked(1)?;
        let one_byte = matches!(code, "b1" | "i1" | "u1");
        if !(order == "<" || (order == "|" && one_byte)) {
            return None;
        }
        Dtype::ALL.into_iter().find(|d| &d.descr()[1..] == code)
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Dtype::Bool | Dtype::I8 | Dtype::U8 => 1,
            Dtype::I16 | Dtype::U16 => 2,
            Dtype::I32 | Dtype::U32 | Dtype::F32 => 4,
            Dtype::I64 | Dtype::U64 | Dtype::F64 => 8,
        }
    }

    /// Whether the type is `F32` or `F64`.
    pub fn is_float(self) -> bool {
        matches!(self, Dtype::F32 | Dtype::F64)
    }
}

impl fmt::Display for Dtype {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.descr())
    }
}

/// The header of an NPY file: what the data is and where it starts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NpyHeader {
    /// The element type.
    pub dtype: Dtype,
    /// The shape (C order).
    pub shape: Vec<usize>,
    /// Offset of the first data byte in the file.
    pub data_offset: usize,
}

impl NpyHeader {
    /// Parses the header of an NPY file's bytes: format versions 1.0, 2.0 and 3.0; a header dict
    /// with `descr` one of [`Dtype::descr`], `'fortran_order': False` and `shape` a tuple of
    /// integers. The data is not checked. Anything else is an [`NpyError`].
    pub fn parse(bytes: &[u8]) -> Result<NpyHeader, NpyError> {
        if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
            return Err(NpyError::new(
                "an NPY file (magic \\x93NUMPY)",
                format!("{} bytes without that magic", bytes.len()),
            ));
        }
        let (header_len, header_start): (usize, usize) = match bytes[6] {
            1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
            2 | 3 if bytes.len() >= 12 => (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            ),
            v => {
                return Err(NpyError::new(
                    "NPY format version 1, 2 or 3",
                    format!("version {v}.{}", bytes[7]),
                ));
            }
        };
        let data_offset = header_start.saturating_add(header_len);
        let header = bytes
            .get(header_start..data_offset)
            .and_then(|h| std::str::from_utf8(h).ok())
            .ok_or_else(|| {
                NpyError::new(
                    "a complete text NPY header",
                    "a truncated header".to_owned(),
                )
            })?;
        let descr = dict_value(header, "descr");
        let dtype = descr
            .and_then(|d| d.strip_prefix(['\'', '"'])?.strip_suffix(['\'', '"']))
            .and_then(Dtype::from_descr)
            .ok_or_else(|| {
                NpyError::new(
                    "'descr' a little-endian bool, integer or float type \
                     (|b1, |i1, |u1, <i2, <u2, <i4, <u4, <i8, <u8, <f4, <f8)",
                    format!("header {}", header.trim()),
                )
            })?;
        if dict_value(header, "fortran_order") != Some("False") {
            return Err(NpyError::new(
                "'fortran_order': False",
                format!("header {}", header.trim()),
            ));
        }
        let shape: Vec<usize> = dict_value(header, "shape")
            .and_then(|s| {
                s.strip_prefix('(')?
                    .strip_suffix(')')?
                    .split(',')
                    .map(str::trim)
                    .filter(|p| !p.is_empty())
                    .map(|p| p.parse().ok())
                    .collect()
            })
            .ok_or_else(|| {
                NpyError::new(
                    "'shape' a tuple of integers",
                    format!("header {}", header.trim()),
                )
            })?;
        Ok(NpyHeader {
            dtype,
            shape,
            data_offset,
        })
    }
}

/// An n-dimensional array read from or written to NPY: its type, shape (C order) and raw
/// little-endian bytes. Invariant: `data.len() == dtype.size() · Π shape`.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    dtype: Dtype,
    shape: Vec<usize>,
    data: Vec<u8>,
}

/// One value of an NPY array, exactly as stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NpyValue {
    /// Booleans and integers of every width (`u64` above `i64::MAX` become `i128` here too).
    Int(i128),
    /// Floats (`f32` widened exactly).
    Float(f64),
}

impl NpyArray {
    /// Parses an NPY file's bytes: the header ([`NpyHeader::parse`]), then exactly
    /// `size · Π shape` data bytes. Anything else is an [`NpyError`] saying what was expected.
    pub fn parse(bytes: &[u8]) -> Result<NpyArray, NpyError> {
        let NpyHeader {
            dtype,
            shape,
            data_offset,
        } = NpyHeader::parse(bytes)?;
        let data = &bytes[data_offset..];
        let expected = shape
            .iter()
            .try_fold(dtype.size(), |n, &d| n.checked_mul(d));
        if expected != Some(data.len()) {
            return Err(NpyError::new(
                format!(
                    "{} data bytes for {dtype} values of shape {}",
                    expected.map_or("more than usize::MAX".to_owned(), |n| n.to_string()),
                    shape_str(&shape)
                ),
                format!("{} bytes", data.len()),
            ));
        }
        Ok(NpyArray {
            dtype,
            shape,
            data: data.to_vec(),
        })
    }

    /// The element type.
    pub fn dtype(&self) -> Dtype {
        self.dtype
    }

    /// The shape (C order: the last index varies fastest).
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// The number of elements, `Π shape` (1 for a 0-d array).
    pub fn len(&self) -> usize {
        self.data.len() / self.dtype.size()
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Element `i` in storage order.
    ///
    /// # Panics
    /// If `i ≥ len()`.
    pub fn value(&self, i: usize) -> NpyValue {
        let s = self.dtype.size();
        let b = &self.data[i * s..(i + 1) * s];
        let mut le = [0u8; 8];
        le[..s].copy_from_slice(b);
        let u = u64::from_le_bytes(le);
        match self.dtype {
            Dtype::Bool | Dtype::U8 | Dtype::U16 | Dtype::U32 | Dtype::U64 => {
                NpyValue::Int(i128::from(u))
            }
            Dtype::I8 => NpyValue::Int(i128::from(b[0] as i8)),
            Dtype::I16 => NpyValue::Int(i128::from(i16::from_le_bytes([b[0], b[1]]))),
            Dtype::I32 => NpyValue::Int(i128::from(u as u32 as i32)),
            Dtype::I64 => NpyValue::Int(i128::from(u as i64)),
            Dtype::F32 => NpyValue::Float(f64::from(f32::from_bits(u as u32))),
            Dtype::F64 => NpyValue::Float(f64::from_bits(u)),
        }
    }

    /// All elements as `f64` (integers above 2⁵³ in magnitude are rounded).
    pub fn to_f64_vec(&self) -> Vec<f64> {
        (0..self.len())
            .map(|i| match self.value(i) {
                NpyValue::Int(v) => v as f64,
                NpyValue::Float(v) => v,
            })
            .collect()
    }

    /// The raw little-endian bytes.
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// An array of `dtype` and `shape` from raw little-endian bytes; `None` unless
    /// `data.len() == dtype.size() · Π shape`.
    pub fn from_raw(dtype: Dtype, shape: Vec<usize>, data: Vec<u8>) -> Option<NpyArray> {
        let expected = shape
            .iter()
            .try_fold(dtype.size(), |n, &d| n.checked_mul(d))?;
        (expected == data.len()).then_some(NpyArray { dtype, shape, data })
    }

    /// A 1-D `<f8` array.
    pub fn from_f64(values: &[f64]) -> NpyArray {
        Self::from_le(
            Dtype::F64,
            values.len(),
            values.iter().map(|v| v.to_le_bytes()),
        )
    }

    /// A 1-D `<i8` array.
    pub fn from_i64(values: &[i64]) -> NpyArray {
        Self::from_le(
            Dtype::I64,
            values.len(),
            values.iter().map(|v| v.to_le_bytes()),
        )
    }

    /// A 1-D `<u2` array.
    pub fn from_u16(values: &[u16]) -> NpyArray {
        Self::from_le(
            Dtype::U16,
            values.len(),
            values.iter().map(|v| v.to_le_bytes()),
        )
    }

    /// A 1-D `|i1` array.
    pub fn from_i8(values: &[i8]) -> NpyArray {
        Self::from_le(
            Dtype::I8,
            values.len(),
            values.iter().map(|v| v.to_le_bytes()),
        )
    }

    fn from_le<const N: usize>(
        dtype: Dtype,
        len: usize,
        values: impl Iterator<Item = [u8; N]>,
    ) -> NpyArray {
        let mut data = Vec::with_capacity(N * len);
        values.for_each(|b| data.extend_from_slice(&b));
        NpyArray {
            dtype,
            shape: vec![len],
            data,
        }
    }

    /// The same values with another shape of the same number of elements (`None` otherwise).
    pub fn reshaped(self, shape: Vec<usize>) -> Option<NpyArray> {
        Self::from_raw(self.dtype, shape, self.data)
    }

    /// The NPY 1.0 file (version 2.0 if the header exceeds 65535 bytes): magic, version, header
    /// length, the header dict padded with spaces and a newline so that the data starts at a
    /// multiple of 64 bytes, then the data.
    pub fn to_bytes(&self) -> Vec<u8> {
        let dict = format!(
            "{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}",
            self.dtype.descr(),
            shape_str(&self.shape)
        );
        let mut bytes = npy_header_bytes(&dict);
        bytes.extend_from_slice(&self.data);
        bytes
    }
}

/// A shape as numpy prints it: `(3,)`, `(2, 17)`, `()`.
pub fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The bytes before the data of an NPY file with header dict `dict` (see [`NpyArray::to_bytes`]).
pub(crate) fn npy_header_bytes(dict: &str) -> Vec<u8> {
    let mut header = dict.to_owned();
    let long = header.len() + 12 > usize::from(u16::MAX);
    let prefix = if long { 12 } else { 10 };
    while !(prefix + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY".to_vec();
    match u16::try_from(header.len()) {
        Ok(len) if !long => {
            bytes.extend_from_slice(&[1, 0]);
            bytes.extend_from_slice(&len.to_le_bytes());
        }
        _ => {
            let len = u32::try_from(header.len()).expect("an NPY header dict below 4 GiB");
            bytes.extend_from_slice(&[2, 0]);
            bytes.extend_from_slice(&len.to_le_bytes());
        }
    }
    bytes.extend_from_slice(header.as_bytes());
    bytes
}

/// The raw text of `key`'s value in a Python dict literal such as
/// `{'descr': '<f8', 'fortran_order': False, 'shape': (20, 17), }`: up to the next top-level
/// comma (commas inside parentheses belong to the value), trimmed.
pub(crate) fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let start = ["'", "\""].iter().find_map(|q| {
        header
            .find(&format!("{q}{key}{q}"))
            .map(|i| i + key.len() + 2)
    })?;
    let rest = header[start..].trim_start().strip_prefix(':')?;
    let mut depth = 0i32;
    let end = rest
        .char_indices()
        .find(|&(_, ch)| {
            match ch {
                '(' => depth += 1,
                ')' => depth -= 1,
                _ => {}
            }
            (ch == ',' && depth == 0) || ch == '}'
        })
        .map_or(rest.len(), |(i, _)| i);
    Some(rest[..end].trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_dtype_round_trips_and_reads_its_values() {
        for dtype in Dtype::ALL {
            assert_eq!(Dtype::from_descr(dtype.descr()), Some(dtype));
            // Bytes 0x01, 0x02, … per element.
            let n = 3;
            let data: Vec<u8> = (1..=(n * dtype.size()) as u8).collect();
            let a = NpyArray::from_raw(dtype, vec![n], data.clone()).unwrap();
            let back = NpyArray::parse(&a.to_bytes()).unwrap();
            assert_eq!(back, a, "{dtype}");
            assert_eq!(back.to_bytes().len() % 64, (n * dtype.size()) % 64);
        }
        assert_eq!(Dtype::from_descr("<u1"), Some(Dtype::U8));
        assert_eq!(Dtype::from_descr(">f8"), None);
        assert_eq!(Dtype::from_descr("|f8"), None);
        assert_eq!(Dtype::from_descr("<c16"), None);
        // Signs and widths.
        let a = NpyArray::from_raw(Dtype::I16, vec![2], vec![0xfe, 0xff, 0x34, 0x12]).unwrap();
        assert_eq!(a.value(0), NpyValue::Int(-2));
        assert_eq!(a.value(1), NpyValue::Int(0x1234));
        let a = NpyArray::from_raw(Dtype::I8, vec![1], vec![0xff]).unwrap();
        assert_eq!(a.value(0), NpyValue::Int(-1));
        let a = NpyArray::from_raw(Dtype::U64, vec![1], vec![0xff; 8]).unwrap();
        assert_eq!(a.value(0), NpyValue::Int(i128::from(u64::MAX)));
        let a = NpyArray::from_raw(Dtype::F32, vec![1], 1.5f32.to_le_bytes().to_vec()).unwrap();
        assert_eq!(a.to_f64_vec(), [1.5]);
        assert_eq!(NpyArray::from_i64(&[-3, 7]).to_f64_vec(), [-3.0, 7.0]);
    }

    #[test]
    fn shapes_print_and_parse_as_numpy_does() {
        assert_eq!(shape_str(&[3]), "(3,)");
        assert_eq!(shape_str(&[2, 17]), "(2, 17)");
        assert_eq!(shape_str(&[]), "()");
        let a = NpyArray::from_f64(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
            .reshaped(vec![2, 3])
            .unwrap();
        let back = NpyArray::parse(&a.to_bytes()).unwrap();
        assert_eq!(back.shape(), [2, 3]);
        let scalar = NpyArray::from_f64(&[4.0]).reshaped(vec![]).unwrap();
        assert_eq!(NpyArray::parse(&scalar.to_bytes()).unwrap().len(), 1);
        assert!(NpyArray::from_f64(&[1.0]).reshaped(vec![2]).is_none());
    }

    /// `bytes` with the first occurrence of `from` replaced by `to` (same length).
    fn replaced(bytes: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
        let i = bytes.windows(from.len()).position(|w| w == from).unwrap();
        let mut out = bytes.to_vec();
        out[i..i + to.len()].copy_from_slice(to);
        out
    }

    #[test]
    fn bad_files_say_what_was_expected() {
        let good = NpyArray::from_u16(&[1, 2, 3]).to_bytes();
        let err = NpyArray::parse(b"PK\x03\x04 not npy").unwrap_err();
        assert!(err.expected.contains("magic"), "{err}");
        let err = NpyArray::parse(&good[..good.len() - 1]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "expected 6 data bytes for <u2 values of shape (3,), got 5 bytes"
        );
        let err = NpyArray::parse(&replaced(&good, b"<u2", b">u2")).unwrap_err();
        assert!(err.expected.contains("little-endian"), "{err}");
        let err = NpyArray::parse(&replaced(&good, b"False", b"True ")).unwrap_err();
        assert!(err.expected.contains("fortran_order"), "{err}");
        let mut v9 = good.clone();
        v9[6] = 9;
        assert!(
            NpyArray::parse(&v9)
                .unwrap_err()
                .expected
                .contains("version")
        );
        let mut truncated = good.clone();
        truncated.truncate(20);
        assert!(NpyArray::parse(&truncated).is_err());
    }
}
