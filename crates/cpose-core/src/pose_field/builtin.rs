//! The built-in pose fields, registered by name so that a config selects one with
//! `kind = "<name>"` in its table (`cpose list` shows them). A downstream crate registers its own
//! the same way (see `crates/cpose-cli/examples/custom_pose_field.rs`).

use serde::Deserialize;
use serde::de::IgnoredAny;

use super::posenet::bands_for_spacing;
use super::{
    Composed, DiscretePosesConfig, PoseField, PoseFieldError, PoseNetConfig, SplineConfig,
    SplineKind,
};
use crate::config::{ConfigError, Section};
use crate::registry::{FieldContext, PoseFieldSpec, build_pose_field};

/// Turns a construction error into a config error located at the section.
fn located<'s>(section: &'s Section<'_>) -> impl Fn(PoseFieldError) -> ConfigError + 's {
    move |e| section.error(e.to_string())
}

fn posenet(section: &Section<'_>, ctx: &FieldContext) -> Result<Box<dyn PoseField>, ConfigError> {
    let mut config: PoseNetConfig = section.decode_params()?;
    // Without `bands`, the rule of the sample spacing (PoseNet's docs, "Choosing the bands").
    #[derive(Deserialize)]
    struct Bands {
        bands: Option<IgnoredAny>,
    }
    if section.decode::<Bands>()?.bands.is_none()
        && let Some(spacing) = median_spacing(&ctx.frame_times_secs)
    {
        config.bands = bands_for_spacing(ctx.time_range, spacing, config.time_span);
    }
    // The table's `seed` offsets the run's seed, so `[run] seed` varies every field of a run.
    config.seed = config.seed.wrapping_add(ctx.seed);
    Ok(Box::new(
        config
            .init::<f32>(ctx.time_range)
            .map_err(located(section))?,
    ))
}

/// The median interval between consecutive sorted times; none for fewer than two distinct times.
fn median_spacing(times: &[f64]) -> Option<f64> {
    let mut sorted = times.to_vec();
    sorted.sort_by(f64::total_cmp);
    let mut gaps: Vec<f64> = sorted
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|g| *g > 0.0)
        .collect();
    if gaps.is_empty() {
        return None;
    }
    gaps.sort_by(f64::total_cmp);
    Some(gaps[gaps.len() / 2])
}

fn discrete(section: &Section<'_>, ctx: &FieldContext) -> Result<Box<dyn PoseField>, ConfigError> {
    let config: DiscretePosesConfig = section.decode_params()?;
    let field = config.init::<f32>(ctx.time_range, &ctx.frame_times_secs);
    Ok(Box::new(field.map_err(located(section))?))
}

/// The keys of a spline table; the registry name chooses the variant.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SplineTable {
    /// Number of control points (default 5).
    #[serde(default = "default_control_points")]
    control_points: usize,
    /// Knot spacing, seconds; overrides `control_points`.
    knot_spacing_secs: Option<f64>,
}

fn default_control_points() -> usize {
    SplineConfig::default().control_points
}

fn spline_of(
    kind: SplineKind,
    section: &Section<'_>,
    ctx: &FieldContext,
) -> Result<Box<dyn PoseField>, ConfigError> {
    let table: SplineTable = section.decode_params()?;
    let config = SplineConfig {
        kind,
        control_points: table.control_points,
        knot_spacing_secs: table.knot_spacing_secs,
    };
    let field = config.init::<f32>(ctx.time_range, &ctx.frame_times_secs);
    Ok(Box::new(field.map_err(located(section))?))
}

fn spline(section: &Section<'_>, ctx: &FieldContext) -> Result<Box<dyn PoseField>, ConfigError> {
    spline_of(SplineKind::PerDimension, section, ctx)
}

fn lie_spline(
    section: &Section<'_>,
    ctx: &FieldContext,
) -> Result<Box<dyn PoseField>, ConfigError> {
    spline_of(SplineKind::Lie, section, ctx)
}

/// `[x]` with `kind = "composed"` holds two sub-tables `[x.a]` and `[x.b]`, each a pose field.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ComposedTable {
    #[allow(dead_code, reason = "decoded by the registry")]
    a: IgnoredAny,
    #[allow(dead_code, reason = "decoded by the registry")]
    b: IgnoredAny,
}

fn composed(section: &Section<'_>, ctx: &FieldContext) -> Result<Box<dyn PoseField>, ConfigError> {
    let _: ComposedTable = section.decode_params()?;
    let part = |name: &str| {
        section
            .config()
            .section(&format!("{}.{name}", section.dotted_path()))
    };
    let a = build_pose_field(&part("a"), ctx)?;
    let b = build_pose_field(&part("b"), ctx)?;
    Ok(Box::new(Composed::new(a, b).map_err(located(section))?))
}

inventory::submit! {
    PoseFieldSpec { name: "posenet", about: "PoseNet (paper §3.1): MLPs of sinusoidally embedded time, decoupled or coupled", build: posenet }
}
inventory::submit! {
    PoseFieldSpec { name: "discrete", about: "BARF: one se(3) per frame, tangents linearly interpolated between frames", build: discrete }
}
inventory::submit! {
    PoseFieldSpec { name: "spline", about: "the paper's B-spline baseline: a clamped cubic B-spline per pose dimension", build: spline }
}
inventory::submit! {
    PoseFieldSpec { name: "lie_spline", about: "cumulative cubic B-spline on SO(3)×R³ with uniform knots", build: lie_spline }
}
inventory::submit! {
    PoseFieldSpec { name: "composed", about: "T_a(t) ∘ T_b(t) of two pose fields in sub-tables a and b", build: composed }
}

#[cfg(test)]
pub(super) mod tests {
    use crate::config::Config;
    use crate::registry::{FieldContext, build_pose_field, pose_fields};
    use crate::{Order, PoseBatch, TimeRange};

    /// Two seconds with a frame every half second (also the saved-field tests' context).
    pub(in crate::pose_field) fn ctx() -> FieldContext {
        FieldContext {
            time_range: TimeRange::new(0.0, 2.0).unwrap(),
            frame_times_secs: vec![0.0, 0.5, 1.0, 1.5, 2.0],
            seed: 3,
        }
    }

    #[test]
    fn every_builtin_builds_from_a_config() {
        let text = r#"
task = "none"
[p]
kind = "posenet"
width = 16
depth = 3
skip_layer = 0
[d]
kind = "discrete"
[s]
kind = "spline"
control_points = 6
[l]
kind = "lie_spline"
knot_spacing_secs = 0.25
[c]
kind = "composed"
[c.a]
kind = "discrete"
[c.b]
kind = "posenet"
width = 8
depth = 2
skip_layer = 0
"#;
        let config = Config::from_text("test.toml", text);
        for name in ["p", "d", "s", "l", "c"] {
            let mut field = build_pose_field(&config.section(name), &ctx()).unwrap();
            let mut out = PoseBatch::default();
            field
                .forward(&[0.0, 0.7, 2.0], Order::Acceleration, &mut out)
                .unwrap();
            assert_eq!(out.len(), 3, "{name}");
            assert!(field.num_params() > 0, "{name}");
        }
        let names: Vec<_> = pose_fields().iter().map(|f| f.name).collect();
        for name in ["composed", "discrete", "lie_spline", "posenet", "spline"] {
            assert!(names.contains(&name), "{name} is not registered: {names:?}");
        }
    }

    /// Without `bands`, a PoseNet table takes them from the spacing of the times it is fitted
    /// to: 10 s sampled every 0.2 s gives `⌊1 + log2(10 / 0.8)⌋ = 4`; given, they stay.
    #[test]
    fn posenet_bands_default_to_the_rule_of_the_sample_spacing() {
        let ctx = FieldContext {
            time_range: TimeRange::new(0.0, 10.0).unwrap(),
            frame_times_secs: (0..=50).map(|k| 0.2 * k as f64).collect(),
            seed: 0,
        };
        let params = |table: &str| {
            let config = Config::from_text("test.toml", format!("task = \"none\"\n[p]\n{table}"));
            build_pose_field(&config.section("p"), &ctx)
                .unwrap()
                .num_params()
        };
        let small = "kind = \"posenet\"\nwidth = 8\ndepth = 2\nskip_layer = 0\n";
        assert_eq!(params(small), params(&format!("{small}bands = 4")));
        assert_ne!(params(small), params(&format!("{small}bands = 5")));
        assert_eq!(
            super::bands_for_spacing(ctx.time_range, 0.2, 0.5),
            5,
            "w = 0.5 halves every frequency"
        );
    }

    #[test]
    fn bad_tables_are_located_errors() {
        let config = Config::from_text(
            "test.toml",
            "task = \"none\"\n[p]\nkind = \"posenet\"\nwidht = 3\n[q]\nkind = \"posenet\"\nbands = 99\n[s]\nkind = \"spline\"\ncontrol_points = 2\n",
        );
        let err = build_pose_field(&config.section("p"), &ctx())
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("line 4") && err.contains("widht") && err.contains("width"),
            "{err}"
        );
        let err = build_pose_field(&config.section("q"), &ctx())
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("bands = 99"), "{err}");
        let err = build_pose_field(&config.section("s"), &ctx())
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("[s]") && err.contains("test.toml"), "{err}");
    }
}
