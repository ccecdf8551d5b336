//! Learnt pose fields on disk, to query after the run (`cpose query`) or load elsewhere.
//!
//! The file is [safetensors](https://huggingface.co/docs/safetensors): an 8-byte little-endian
//! header length, a JSON header, then the data. One tensor, `params` (`F32`, shape `[n]`), holds
//! the field's parameters in the order of [`PoseField::params`]; the header's `__metadata__`
//! holds what rebuilds the field:
//!
//! | key | value |
//! |---|---|
//! | `format` | `cpose-pose-field/1` |
//! | `config` | the field's config table as TOML, under `[field]`, with its `kind` |
//! | `time_range` | `[start, end]`, seconds (JSON) |
//! | `frame_times` | the frames' times, seconds (JSON; per-frame fields such as `discrete`) |
//! | `seed` | the initialisation seed |
//! | `world_from_field` | `{"rotation": [qw, qx, qy, qz], "translation": [x, y, z], "scale": s}` |
//!
//! A field may be fitted in a normalised frame; `world_from_field` takes its poses to the world
//! (`p_world = s·R·p + t`, `R_world = R·R_field`). In Python, `safetensors.numpy.load_file`
//! (or `safetensors.torch`) reads `params`, and `safe_open(...).metadata()` the rest.

use std::path::Path;

use anyhow::{Context, bail, ensure};
use nalgebra::{Isometry3, Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::config::{Config, Section};
use crate::eval::Sim3;
use crate::fs::write_atomic;
use crate::registry::{FieldContext, build_pose_field};
use crate::{PoseField, TimeRange};

use super::{params_from_slice, params_to_vec};

/// The `format` of the files this version writes and reads.
pub const FORMAT: &str = "cpose-pose-field/1";

/// The largest JSON header read (the metadata of a field with ten million frame times).
const MAX_HEADER_BYTES: u64 = 256 << 20;

/// A pose field's config, context, frame and parameters: everything that rebuilds it.
#[derive(Clone, Debug)]
pub struct SavedPoseField {
    /// The field's table as TOML under `[field]` (with its `kind`).
    pub config: String,
    /// The times and seed it was built for.
    pub context: FieldContext,
    /// Its frame in the world: `p_world = s·R·p + t`, `R_world = R·R_field`.
    pub frame: Sim3,
    /// Its parameters in [`PoseField::params`] order.
    pub params: Vec<f32>,
}

/// The header's metadata (all strings, as safetensors requires).
#[derive(Serialize, Deserialize)]
struct Metadata {
    format: String,
    config: String,
    time_range: String,
    frame_times: String,
    seed: String,
    world_from_field: String,
}

#[derive(Serialize, Deserialize)]
struct FrameJson {
    rotation: [f64; 4],
    translation: [f64; 3],
    scale: f64,
}

#[derive(Serialize, Deserialize)]
struct TensorInfo {
    dtype: String,
    shape: Vec<u64>,
    data_offsets: [u64; 2],
}

#[derive(Serialize, Deserialize)]
struct Header {
    #[serde(rename = "__metadata__")]
    metadata: Metadata,
    params: TensorInfo,
}

/// A field rebuilt from a file, with its frame.
pub struct LoadedPoseField {
    /// The field, its parameters restored.
    pub field: Box<dyn PoseField>,
    /// Its frame in the world.
    pub frame: Sim3,
}

/// A field's pose and velocities at one time, in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldSample {
    /// Seconds.
    pub t_secs: f64,
    /// `world_from_body`.
    pub pose: Isometry3<f64>,
    /// Body angular velocity, rad/s.
    pub ang_vel_body: Vector3<f64>,
    /// Linear velocity in the world, m/s.
    pub lin_vel_world: Vector3<f64>,
}

impl SavedPoseField {
    /// Captures `field`, built from `section` in `context`, with its frame in the world.
    pub fn capture(
        section: &Section<'_>,
        context: &FieldContext,
        frame: Sim3,
        field: &dyn PoseField,
    ) -> anyhow::Result<Self> {
        let table: toml::Table = section.decode()?;
        let config = toml::to_string(&toml::Table::from_iter([(
            "field".to_owned(),
            toml::Value::Table(table),
        )]))?;
        Ok(Self {
            config,
            context: context.clone(),
            frame,
            params: params_to_vec(field),
        })
    }

    /// A trajectory as a `discrete` field: `world_from_body` at `times` (exact there up to its
    /// `f32` parameters; between them the poses' se(3) tangents are interpolated), in the world
    /// frame. What a run that tracks frame by frame saves of its estimate.
    pub fn discrete(times: &[f64], world_from_body: &[Isometry3<f64>]) -> anyhow::Result<Self> {
        let field = super::DiscretePoses::<f32>::from_poses(times, world_from_body)?;
        Ok(Self {
            config: "[field]\nkind = \"discrete\"\n".to_owned(),
            context: FieldContext {
                time_range: TimeRange::new(times[0], times[times.len() - 1])?,
                frame_times_secs: times.to_vec(),
                seed: 0,
            },
            frame: Sim3::identity(),
            params: params_to_vec(&field),
        })
    }

    /// Writes the safetensors file, atomically.
    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        let TimeRange {
            start_secs,
            end_secs,
        } = self.context.time_range;
        let q = UnitQuaternion::from_rotation_matrix(&self.frame.rotation);
        let metadata = Metadata {
            format: FORMAT.to_owned(),
            config: self.config.clone(),
            time_range: serde_json::to_string(&[start_secs, end_secs])?,
            frame_times: serde_json::to_string(&self.context.frame_times_secs)?,
            seed: self.context.seed.to_string(),
            world_from_field: serde_json::to_string(&FrameJson {
                rotation: [q.w, q.i, q.j, q.k],
                translation: self.frame.translation.into(),
                scale: self.frame.scale,
            })?,
        };
        let bytes = 4 * self.params.len() as u64;
        let header = Header {
            metadata,
            params: TensorInfo {
                dtype: "F32".to_owned(),
                shape: vec![self.params.len() as u64],
                data_offsets: [0, bytes],
            },
        };
        let mut json = serde_json::to_vec(&header)?;
        // The data start 8-byte aligned; safetensors pads the header with spaces.
        json.resize(json.len().next_multiple_of(8), b' ');
        let mut out = Vec::with_capacity(8 + json.len() + bytes as usize);
        out.extend_from_slice(&(json.len() as u64).to_le_bytes());
        out.extend_from_slice(&json);
        for p in &self.params {
            out.extend_from_slice(&p.to_le_bytes());
        }
        write_atomic(path, out).with_context(|| format!("writing {}", path.display()))
    }

    /// Reads a file written by [`SavedPoseField::write`]; errors name the file and what was
    /// expected.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        Self::from_bytes(&bytes).with_context(|| {
            format!(
                "{}: expected a pose field saved by cpose ({FORMAT}, safetensors)",
                path.display()
            )
        })
    }

    fn from_bytes(bytes: &[u8]) -> anyhow::Result<Self> {
        let Some((len, rest)) = bytes.split_first_chunk::<8>() else {
            bail!("the file is shorter than safetensors' 8-byte header length");
        };
        let len = u64::from_le_bytes(*len);
        ensure!(
            len <= MAX_HEADER_BYTES.min(rest.len() as u64),
            "a header of {len} bytes, more than the file's {} remaining bytes (or {MAX_HEADER_BYTES})",
            rest.len()
        );
        let (json, data) = rest.split_at(len as usize);
        let header: Header =
            serde_json::from_slice(json).context("a JSON header with __metadata__ and params")?;
        let m = header.metadata;
        ensure!(
            m.format == FORMAT,
            "format {FORMAT:?}, found {:?}",
            m.format
        );
        let t = header.params;
        let n = data.len() as u64 / 4;
        ensure!(
            t.dtype == "F32" && t.shape == [n] && t.data_offsets == [0, 4 * n],
            "params as F32 of shape [{n}] over the file's {} data bytes, found {} {:?} at {:?}",
            data.len(),
            t.dtype,
            t.shape,
            t.data_offsets
        );
        let [start_secs, end_secs]: [f64; 2] =
            serde_json::from_str(&m.time_range).context("time_range as [start, end]")?;
        let time_range = TimeRange::new(start_secs, end_secs)
            .with_context(|| format!("a time range with start < end, found {}", m.time_range))?;
        let frame_times_secs: Vec<f64> =
            serde_json::from_str(&m.frame_times).context("frame_times as a list of seconds")?;
        let seed = m.seed.parse().context("seed as an integer")?;
        let f: FrameJson = serde_json::from_str(&m.world_from_field)
            .context("world_from_field with rotation, translation and scale")?;
        let rotation = Quaternion::new(f.rotation[0], f.rotation[1], f.rotation[2], f.rotation[3]);
        ensure!(
            (rotation.norm() - 1.0).abs() < 1e-6 && f.scale > 0.0 && f.scale.is_finite(),
            "world_from_field with a unit rotation and a positive scale"
        );
        Ok(Self {
            config: m.config,
            context: FieldContext {
                time_range,
                frame_times_secs,
                seed,
            },
            frame: Sim3 {
                rotation: UnitQuaternion::new_normalize(rotation).to_rotation_matrix(),
                translation: f.translation.into(),
                scale: f.scale,
            },
            params: data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
        })
    }

    /// Rebuilds the field through the registry and restores its parameters; `path` names the
    /// file in messages.
    pub fn load(&self, path: &Path) -> anyhow::Result<LoadedPoseField> {
        let config = Config::from_text(path, self.config.clone());
        let mut field = build_pose_field(&config.section("field"), &self.context)?;
        params_from_slice(field.as_mut(), &self.params)
            .with_context(|| format!("{}: the field its config builds", path.display()))?;
        // A saved field was trained to the end of its coarse-to-fine schedules.
        field.set_progress(1.0);
        Ok(LoadedPoseField {
            field,
            frame: self.frame,
        })
    }
}

impl LoadedPoseField {
    /// Poses and velocities in the world at `times_secs` (each inside the field's range).
    pub fn sample(&self, times_secs: &[f64]) -> anyhow::Result<Vec<FieldSample>> {
        crate::fit::sample(self.field.as_ref(), &self.frame, times_secs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose_field::builtin::tests::ctx as context;
    use crate::testing::TempDir;
    use crate::{Order, PoseBatch};

    const FIELDS: &str = r#"
task = "none"
[p]
kind = "posenet"
width = 16
depth = 3
skip_layer = 0
[c]
kind = "composed"
[c.a]
kind = "discrete"
[c.b]
kind = "spline"
control_points = 6
"#;

    /// Perturbs every parameter so that a restored field differs from a freshly built one.
    fn trained(section: &Section<'_>) -> Box<dyn PoseField> {
        let mut field = build_pose_field(section, &context()).unwrap();
        let mut k = 0.0f32;
        field.params_mut(&mut |_, p| {
            for v in p {
                k += 1.0;
                *v += 0.01 * (k * 0.7).sin();
            }
        });
        field
    }

    #[test]
    fn a_saved_field_samples_as_the_original_in_the_world() {
        let dir = TempDir::new("saved-field");
        let config = Config::from_text("test.toml", FIELDS);
        let frame = Sim3 {
            rotation: nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3),
            translation: Vector3::new(1.0, -2.0, 0.5),
            scale: 2.5,
        };
        for name in ["p", "c"] {
            let section = config.section(name);
            let field = trained(&section);
            let saved =
                SavedPoseField::capture(&section, &context(), frame, field.as_ref()).unwrap();
            let path = dir.join(format!("{name}.safetensors"));
            saved.write(&path).unwrap();
            let loaded = SavedPoseField::read(&path).unwrap().load(&path).unwrap();
            let times = [0.0, 0.3, 1.7, 2.0];
            let samples = loaded.sample(&times).unwrap();
            let mut out = PoseBatch::default();
            field.evaluate(&times, Order::Velocity, &mut out).unwrap();
            for (i, s) in samples.iter().enumerate() {
                let want = frame.transform_pose(&out.world_from_body(i));
                assert!((s.pose.translation.vector - want.translation.vector).norm() < 1e-12);
                assert!(s.pose.rotation.angle_to(&want.rotation) < 1e-12);
                assert!((s.ang_vel_body - out.ang_vel_body(i)).norm() < 1e-12);
                let v = frame.rotation * out.lin_vel_world[i] * frame.scale;
                assert!((s.lin_vel_world - v).norm() < 1e-12, "{name}");
            }
        }
    }

    #[test]
    fn the_world_velocity_is_the_derivative_of_the_world_position() {
        let config = Config::from_text("test.toml", FIELDS);
        let section = config.section("p");
        let frame = Sim3 {
            rotation: nalgebra::Rotation3::from_euler_angles(0.4, 0.1, -0.3),
            translation: Vector3::new(0.2, 0.0, -1.0),
            scale: 3.0,
        };
        let field = trained(&section);
        let saved = SavedPoseField::capture(&section, &context(), frame, field.as_ref()).unwrap();
        let loaded = saved.load(Path::new("test")).unwrap();
        // The fields compute in f32: a step of 1e-3 s keeps rounding below the check.
        let (t, h) = (0.9, 1e-3);
        let s = loaded.sample(&[t - h, t, t + h]).unwrap();
        let numeric = (s[2].pose.translation.vector - s[0].pose.translation.vector) / (2.0 * h);
        let v = s[1].lin_vel_world;
        assert!((numeric - v).norm() < 1e-3 * v.norm(), "{numeric} vs {v}");
        // ω_body from R_world(t): [ω]× = Rᵀ Ṙ.
        let r_dot = (s[2].pose.rotation.to_rotation_matrix().into_inner()
            - s[0].pose.rotation.to_rotation_matrix().into_inner())
            / (2.0 * h);
        let omega = s[1]
            .pose
            .rotation
            .to_rotation_matrix()
            .into_inner()
            .transpose()
            * r_dot;
        let numeric = Vector3::new(omega[(2, 1)], omega[(0, 2)], omega[(1, 0)]);
        let w = s[1].ang_vel_body;
        assert!((numeric - w).norm() < 1e-3 * w.norm(), "{numeric} vs {w}");
    }

    #[test]
    fn bad_files_name_the_file_and_what_was_expected() {
        let dir = TempDir::new("saved-field-bad");
        let config = Config::from_text("test.toml", FIELDS);
        let section = config.section("p");
        let field = trained(&section);
        let saved = SavedPoseField::capture(&section, &context(), Sim3::identity(), field.as_ref())
            .unwrap();
        let path = dir.join("p.safetensors");
        saved.write(&path).unwrap();
        let good = std::fs::read(&path).unwrap();
        let header_len = u64::from_le_bytes(good[..8].try_into().unwrap()) as usize;
        let error = |bytes: &[u8]| {
            let bad = dir.join("bad.safetensors");
            std::fs::write(&bad, bytes).unwrap();
            let e = SavedPoseField::read(&bad)
                .and_then(|s| s.load(&bad).map(|_| ()))
                .unwrap_err();
            let text = format!("{e:#}");
            assert!(text.contains("bad.safetensors"), "{text}");
            text
        };
        assert!(error(&good[..5]).contains("shorter than"));
        // A header length beyond the file.
        let mut lying = good.clone();
        lying[..8].copy_from_slice(&(1u64 << 40).to_le_bytes());
        assert!(error(&lying).contains("more than the file"));
        // Data cut short: the shape no longer matches.
        assert!(error(&good[..good.len() - 4]).contains("params as F32"));
        // Another format.
        let text = String::from_utf8(good[8..8 + header_len].to_vec()).unwrap();
        let other = text.replace(FORMAT, "cpose-pose-field/9");
        let mut bytes = (other.len() as u64).to_le_bytes().to_vec();
        bytes.extend_from_slice(other.as_bytes());
        bytes.extend_from_slice(&good[8 + header_len..]);
        assert!(error(&bytes).contains("cpose-pose-field/9"));
        // A config that builds a field of another size.
        let wider = text.replace("width = 16", "width = 17");
        let mut bytes = (wider.len() as u64).to_le_bytes().to_vec();
        bytes.extend_from_slice(wider.as_bytes());
        bytes.extend_from_slice(&good[8 + header_len..]);
        assert!(error(&bytes).contains("parameters"));
    }
}
