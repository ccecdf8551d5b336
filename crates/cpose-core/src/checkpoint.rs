//! Checkpoints: a small binary format for the state of an interrupted run.
//!
//! A file is a text header line, little-endian values (`u64` counts and numbers, `f64`s,
//! length-prefixed arrays and strings) and a CRC-32 of everything before it. Files are written
//! atomically (temporary file, then rename), so a run killed at any moment keeps its last
//! complete checkpoint, and [`Reader::open`] refuses a file whose checksum does not match
//! (truncated, edited or from another program) before a single value is read.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use rand_chacha::ChaCha8Rng;

use crate::PoseField;
use crate::nn::Adam;

/// The first line of every checkpoint.
const HEADER: &[u8] = b"cpose checkpoint v3\n";
/// Bytes of the CRC-32 trailer.
const CRC_LEN: usize = 4;

/// Builds a checkpoint in memory.
#[derive(Debug)]
pub struct Writer(Vec<u8>);

impl Default for Writer {
    fn default() -> Self {
        Self::new()
    }
}

impl Writer {
    /// An empty checkpoint (with its header).
    pub fn new() -> Self {
        Self(HEADER.to_vec())
    }

    /// One number.
    pub fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    /// One float.
    pub fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    /// A length-prefixed UTF-8 string.
    pub fn str(&mut self, s: &str) {
        self.u64(s.len() as u64);
        self.0.extend_from_slice(s.as_bytes());
    }

    /// A length-prefixed array.
    pub fn f32s(&mut self, v: &[f32]) {
        self.u64(v.len() as u64);
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }

    /// A length-prefixed array.
    pub fn f64s(&mut self, v: &[f64]) {
        self.u64(v.len() as u64);
        for x in v {
            self.f64(*x);
        }
    }

    /// Poses as `[tx, ty, tz, qw, qx, qy, qz]` each.
    pub fn poses(&mut self, poses: &[Isometry3<f64>]) {
        let flat: Vec<f64> = poses
            .iter()
            .flat_map(|p| {
                let (t, q) = (p.translation.vector, p.rotation.into_inner());
                [t.x, t.y, t.z, q.w, q.i, q.j, q.k]
            })
            .collect();
        self.f64s(&flat);
    }

    /// A pose field's parameters, slice by slice.
    pub fn pose_field(&mut self, field: &dyn PoseField) {
        self.u64(field.num_params() as u64);
        field.params(&mut |_, p| self.f32s(p));
    }

    /// An optimiser's moments and step count.
    pub fn adam(&mut self, adam: &Adam<f32>) {
        let (m, v, t) = adam.state();
        self.f32s(m);
        self.f32s(v);
        self.u64(t);
    }

    /// A random generator's seed, stream and position, so that it continues exactly.
    pub fn rng(&mut self, rng: &ChaCha8Rng) {
        self.0.extend_from_slice(&rng.get_seed());
        self.u64(rng.get_stream());
        let pos = rng.get_word_pos();
        self.u64(pos as u64);
        self.u64((pos >> 64) as u64);
    }

    /// The file's bytes: everything written, then the CRC-32 trailer.
    pub fn into_bytes(mut self) -> Vec<u8> {
        let crc = crc32fast::hash(&self.0);
        self.0.extend_from_slice(&crc.to_le_bytes());
        self.0
    }

    /// Writes the checkpoint to `path` atomically.
    pub fn save(self, path: &Path) -> anyhow::Result<()> {
        crate::fs::write_atomic(path, self.into_bytes())
            .with_context(|| format!("cannot write the checkpoint {}", path.display()))
    }
}

/// Reads a checkpoint written by [`Writer`].
#[derive(Debug)]
pub struct Reader {
    bytes: Vec<u8>,
    pos: usize,
    path: PathBuf,
}

impl Reader {
    /// Opens `path` and checks its header and checksum.
    pub fn open(path: &Path) -> anyhow::Result<Self> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        Self::from_bytes(path, bytes)
    }

    /// Checks the header and checksum of `bytes` read from `path` (named in errors).
    pub fn from_bytes(path: &Path, mut bytes: Vec<u8>) -> anyhow::Result<Self> {
        if !bytes.starts_with(HEADER) {
            bail!(
                "{}: not a cpose checkpoint (expected the header {:?})",
                path.display(),
                String::from_utf8_lossy(HEADER).trim()
            );
        }
        let body = bytes.len().saturating_sub(CRC_LEN).max(HEADER.len());
        let stored = bytes
            .get(body..)
            .and_then(|t| <[u8; CRC_LEN]>::try_from(t).ok())
            .map(u32::from_le_bytes);
        if stored != Some(crc32fast::hash(&bytes[..body])) {
            bail!(
                "{}: the checkpoint is corrupt or truncated (its checksum does not match)",
                path.display()
            );
        }
        bytes.truncate(body);
        Ok(Self {
            pos: HEADER.len(),
            bytes,
            path: path.to_path_buf(),
        })
    }

    /// The file it was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn take(&mut self, n: usize) -> anyhow::Result<&[u8]> {
        if n > self.bytes.len() - self.pos {
            bail!(
                "{}: the checkpoint ends early (written by another config or version)",
                self.path.display()
            );
        }
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    /// One number.
    pub fn u64(&mut self) -> anyhow::Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    /// One float.
    pub fn f64(&mut self) -> anyhow::Result<f64> {
        Ok(f64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    /// A length of `size`-byte items, checked against what is left of the file.
    fn len(&mut self, size: usize) -> anyhow::Result<usize> {
        let n = self.u64()?;
        usize::try_from(n)
            .ok()
            .filter(|&n| n.checked_mul(size).is_some_and(|b| b <= self.bytes.len()))
            .with_context(|| format!("{}: corrupt array length {n}", self.path.display()))
    }

    /// A string written by [`Writer::str`].
    pub fn str(&mut self) -> anyhow::Result<String> {
        let n = self.len(1)?;
        let path = self.path.clone();
        String::from_utf8(self.take(n)?.to_vec())
            .with_context(|| format!("{}: corrupt string", path.display()))
    }

    /// A length-prefixed array.
    pub fn f32s(&mut self) -> anyhow::Result<Vec<f32>> {
        let n = self.len(4)?;
        let raw = self.take(4 * n)?;
        Ok(raw
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }

    /// A length-prefixed array.
    pub fn f64s(&mut self) -> anyhow::Result<Vec<f64>> {
        let n = self.len(8)?;
        let raw = self.take(8 * n)?;
        Ok(raw
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
    }

    /// An array written by [`Writer::f32s`] into `out`, which must have its length; `what` names
    /// the array in the error.
    pub fn f32s_into(&mut self, out: &mut [f32], what: &str) -> anyhow::Result<()> {
        let v = self.f32s()?;
        if v.len() != out.len() {
            bail!(
                "{}: the checkpoint's {what} has {} parameters, this one {}",
                self.path.display(),
                v.len(),
                out.len()
            );
        }
        out.copy_from_slice(&v);
        Ok(())
    }

    /// Restores parameters written by [`Writer::pose_field`] into a field of the same shape.
    pub fn pose_field(&mut self, field: &mut dyn PoseField) -> anyhow::Result<()> {
        let n = self.u64()?;
        if n != field.num_params() as u64 {
            bail!(
                "{}: the checkpoint's pose field has {n} parameters, this one {}",
                self.path.display(),
                field.num_params()
            );
        }
        let mut result = Ok(());
        field.params_mut(&mut |_, p| {
            if result.is_ok() {
                result = self.f32s_into(p, "pose field");
            }
        });
        result
    }

    /// Restores an optimiser written by [`Writer::adam`] into one of the same size.
    pub fn adam(&mut self, adam: &mut Adam<f32>) -> anyhow::Result<()> {
        let (m, v, t) = (self.f32s()?, self.f32s()?, self.u64()?);
        if !adam.set_state(&m, &v, t) {
            bail!(
                "{}: the checkpoint's optimiser does not match this model",
                self.path.display()
            );
        }
        Ok(())
    }

    /// A random generator written by [`Writer::rng`], at the position it had.
    pub fn rng(&mut self) -> anyhow::Result<ChaCha8Rng> {
        use rand::SeedableRng as _;
        let seed: [u8; 32] = self.take(32)?.try_into().expect("32 bytes");
        let mut rng = ChaCha8Rng::from_seed(seed);
        rng.set_stream(self.u64()?);
        let (lo, hi) = (self.u64()?, self.u64()?);
        rng.set_word_pos(u128::from(lo) | (u128::from(hi) << 64));
        Ok(rng)
    }

    /// Poses written by [`Writer::poses`].
    pub fn poses(&mut self) -> anyhow::Result<Vec<Isometry3<f64>>> {
        let flat = self.f64s()?;
        if flat.len() % 7 != 0 {
            bail!("{}: corrupt pose array", self.path.display());
        }
        // Bit for bit (a resumed run continues exactly); a quaternion that is not unit is
        // corruption.
        flat.chunks_exact(7)
            .map(|p| {
                let q = Quaternion::new(p[3], p[4], p[5], p[6]);
                if (q.norm() - 1.0).abs() > 1e-9 {
                    bail!(
                        "{}: corrupt pose (quaternion norm {})",
                        self.path.display(),
                        q.norm()
                    );
                }
                Ok(Isometry3::from_parts(
                    Translation3::new(p[0], p[1], p[2]),
                    UnitQuaternion::new_unchecked(q),
                ))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::TempDir;

    #[test]
    fn values_round_trip_and_damage_is_refused_before_reading() {
        let dir = TempDir::new("checkpoint");
        let path = dir.join("c.bin");
        let pose = Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 0.5),
            UnitQuaternion::from_euler_angles(0.1, 0.2, -0.3),
        );
        let mut w = Writer::new();
        w.u64(42);
        w.str("seq-01/posenet");
        w.f32s(&[1.5, -2.25]);
        w.poses(&[pose]);
        let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(7);
        let _: u64 = rand::RngExt::random(&mut rng);
        w.rng(&rng);
        w.save(&path).unwrap();
        let mut r = Reader::open(&path).unwrap();
        assert_eq!(r.u64().unwrap(), 42);
        assert_eq!(r.str().unwrap(), "seq-01/posenet");
        assert_eq!(r.f32s().unwrap(), vec![1.5, -2.25]);
        assert_eq!(r.poses().unwrap()[0], pose);
        let mut back = r.rng().unwrap();
        let next = |g: &mut ChaCha8Rng| -> u64 { rand::RngExt::random(g) };
        assert_eq!(next(&mut back), next(&mut rng));
        let err = r.u64().unwrap_err().to_string();
        assert!(err.contains("ends early"), "{err}");

        let bytes = std::fs::read(&path).unwrap();
        // Truncated at any length, or one bit flipped anywhere: refused at open.
        for cut in [HEADER.len(), HEADER.len() + 1, bytes.len() - 1] {
            let err = Reader::from_bytes(&path, bytes[..cut].to_vec()).unwrap_err();
            assert!(err.to_string().contains("corrupt or truncated"), "{err}");
        }
        for at in [HEADER.len(), bytes.len() / 2, bytes.len() - 1] {
            let mut flipped = bytes.clone();
            flipped[at] ^= 0x10;
            assert!(Reader::from_bytes(&path, flipped).is_err());
        }
        let err = Reader::from_bytes(&path, b"something else".to_vec()).unwrap_err();
        assert!(err.to_string().contains("not a cpose checkpoint"), "{err}");
    }
}
