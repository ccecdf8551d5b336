//! A minimal binary format for SLAM checkpoints: a text header line, then little-endian
//! values — `u64` counts and numbers, length-prefixed `f32`/`f64` arrays. Written atomically
//! (temporary file, then rename), so a run killed at any moment keeps its last checkpoint.

use std::path::Path;

use anyhow::{Context as _, bail};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// The first line of every checkpoint.
const HEADER: &[u8] = b"cpose-slam checkpoint v2\n";

/// Builds a checkpoint in memory.
#[derive(Default)]
pub struct Writer(Vec<u8>);

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

    /// Writes the checkpoint to `path` atomically.
    pub fn save(&self, path: &Path) -> anyhow::Result<()> {
        cpose_core::fs::write_atomic(path, &self.0)
            .with_context(|| format!("cannot write the checkpoint {}", path.display()))
    }
}

/// Reads a checkpoint written by [`Writer`].
pub struct Reader {
    bytes: Vec<u8>,
    pos: usize,
    path: std::path::PathBuf,
}

impl Reader {
    /// Opens `path` and checks its header.
    pub fn open(path: &Path) -> anyhow::Result<Self> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        if !bytes.starts_with(HEADER) {
            bail!(
                "{}: not a cpose-slam checkpoint (expected the header {:?})",
                path.display(),
                String::from_utf8_lossy(HEADER).trim()
            );
        }
        Ok(Self {
            pos: HEADER.len(),
            bytes,
            path: path.to_path_buf(),
        })
    }

    fn take(&mut self, n: usize) -> anyhow::Result<&[u8]> {
        if self.pos + n > self.bytes.len() {
            bail!(
                "{}: the checkpoint ends early (truncated or from another config)",
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

    fn len(&mut self) -> anyhow::Result<usize> {
        let n = self.u64()?;
        usize::try_from(n)
            .ok()
            .filter(|&n| n <= self.bytes.len())
            .with_context(|| format!("{}: corrupt array length {n}", self.path.display()))
    }

    /// A length-prefixed array.
    pub fn f32s(&mut self) -> anyhow::Result<Vec<f32>> {
        let n = self.len()?;
        let raw = self.take(4 * n)?;
        Ok(raw
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }

    /// A length-prefixed array.
    pub fn f64s(&mut self) -> anyhow::Result<Vec<f64>> {
        let n = self.len()?;
        let raw = self.take(8 * n)?;
        Ok(raw
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
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

    #[test]
    fn values_round_trip_and_truncation_is_an_error() {
        let dir = crate::data::test_dir("checkpoint");
        let path = dir.join("c.bin");
        let pose = Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 0.5),
            UnitQuaternion::from_euler_angles(0.1, 0.2, -0.3),
        );
        let mut w = Writer::new();
        w.u64(42);
        w.f32s(&[1.5, -2.25]);
        w.poses(&[pose]);
        w.save(&path).unwrap();
        let mut r = Reader::open(&path).unwrap();
        assert_eq!(r.u64().unwrap(), 42);
        assert_eq!(r.f32s().unwrap(), vec![1.5, -2.25]);
        let back = r.poses().unwrap()[0];
        assert_eq!(back, pose);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        let mut r = Reader::open(&path).unwrap();
        r.u64().unwrap();
        r.f32s().unwrap();
        let err = r.poses().unwrap_err().to_string();
        assert!(err.contains("ends early"), "{err}");
        std::fs::write(&path, b"something else").unwrap();
        let err = Reader::open(&path).err().unwrap().to_string();
        assert!(err.contains("not a cpose-slam checkpoint"), "{err}");
    }
}
