//! Studies: the one loop of every task — conditions × methods × seeds, each run one unit.
//!
//! A task lists its units ([`UnitKey`]: condition, method, seed) and supplies the function
//! that runs one of them; [`Study::run`] does the rest, the same way for every task:
//! - **progress**: one bar per running unit, the log printed above the bars;
//! - **live metrics**: [`Unit::report`] at every `report_every`-th step writes the loss and the
//!   task's key error to the log, the unit's bar and `curves.csv`;
//! - **checkpoints and resume**: [`Unit::checkpoint`] saves a unit's state (atomically, with a
//!   checksum) and [`Unit::resume`] hands it back after `cpose run --resume DIR`; a finished unit
//!   is never run again;
//! - **timing**: wall and CPU seconds per unit (summed over resumed sessions);
//! - **files**: names from [`Unit::file_name`] (`traj_<condition>_<method>.txt`), `metrics.json`
//!   nested condition → method, the training curves drawn as `curves.png` and the final table
//!   in the log.
//!
//! The run folder, besides the task's own files:
//!
//! | file | what |
//! |---|---|
//! | `study.json` | the task, a hash of the resolved config, the units, whether the study finished |
//! | `metrics.json` | condition → method → metrics, rewritten after every finished unit |
//! | `curves.csv` | `condition,method,seed,step,wall_s,metric,value`, one row per reported value |
//! | `curves.png` | `curves.csv` drawn, one panel per metric ([`crate::plot::curves`]) |
//! | `units/<unit>/result.json` | a finished unit's metrics (its presence means "finished") |
//! | `units/<unit>/checkpoint.bin` | an unfinished unit's last state, removed when it finishes |
//! | `units/<unit>/curves.csv` | that unit's rows of `curves.csv` |
//!
//! A unit is deterministic given its key (it seeds its own generators from [`UnitKey::seed`]),
//! so a resumed study ends with the same metrics as one that was never interrupted.
//!
//! ```no_run
//! use cpose_core::registry::TaskInput;
//! use cpose_core::study::{Metrics, Study, UnitKey};
//!
//! fn run(input: &TaskInput) -> anyhow::Result<()> {
//!     let units = UnitKey::grid(&["easy", "hard"], &["posenet", "barf"], &[input.run.seed]);
//!     Study::new(input, units)
//!         .columns(&["rot_err_deg"])
//!         .run(|unit| {
//!             let steps = 1000;
//!             unit.set_steps(steps);
//!             let mut error = 10.0;
//!             for step in 1..=steps {
//!                 error *= 0.99; // one optimiser step
//!                 if unit.report_due(step) {
//!                     unit.report(step, &[("loss", error * error), ("rot_err_deg", error)]);
//!                 }
//!             }
//!             Ok(Metrics::new().with("rot_err_deg", error))
//!         })?;
//!     Ok(())
//! }
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context as _, bail};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use thiserror::Error;

use crate::checkpoint::{Reader, Writer};
use crate::config::Config;
use crate::plot::{self, CURVES_HEADER};
use crate::progress::Progress;
use crate::provenance::{process_cpu_secs, thread_cpu_secs};
use crate::registry::TaskInput;
use crate::run_dir::RunDir;

/// Steps between two live reports unless the task or `[run] report_every` says otherwise.
pub const DEFAULT_REPORT_EVERY: usize = 100;

/// While a study runs, `curves.png` is redrawn after a finished unit when this many seconds
/// have passed since it was last drawn (and always at the end).
const CURVES_PNG_EVERY_SECS: f64 = 30.0;

/// One unit of a study: a condition (noise level, sequence, IMU mode…), a method (a pose model
/// such as `posenet` or `barf`) and a seed.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct UnitKey {
    /// The condition, e.g. `"rm60_tm10"` or `"tight"`.
    pub condition: String,
    /// The method, e.g. `"posenet"`.
    pub method: String,
    /// The seed (or replicate index) of the unit's own random generators.
    pub seed: u64,
}

impl UnitKey {
    /// A unit.
    pub fn new(condition: impl Into<String>, method: impl Into<String>, seed: u64) -> Self {
        Self {
            condition: condition.into(),
            method: method.into(),
            seed,
        }
    }

    /// Every combination, condition-major: `conditions × methods × seeds`.
    pub fn grid(conditions: &[&str], methods: &[&str], seeds: &[u64]) -> Vec<Self> {
        let mut units = Vec::new();
        for c in conditions {
            for m in methods {
                for &s in seeds {
                    units.push(Self::new(*c, *m, s));
                }
            }
        }
        units
    }

    /// `<condition>_<method>`, with `_s<seed>` when the study has several seeds; characters
    /// other than ASCII letters, digits, `.`, `+`, `-` and `_` become `-`.
    fn name(&self, with_seed: bool) -> String {
        let mut name = format!("{}_{}", clean(&self.condition), clean(&self.method));
        if with_seed {
            let _ = write!(name, "_s{}", self.seed);
        }
        name
    }
}

/// `s` with every character but ASCII letters, digits, `.`, `+`, `-` and `_` replaced by `-`
/// (no `=`, spaces or separators in file names).
fn clean(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '+' | '-' | '_') {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// The metrics of one unit (or of one condition and method): names with units, JSON values.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Metrics(pub serde_json::Map<String, Value>);

impl Metrics {
    /// No metrics.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `key` (anything that serialises; `None` is written as `null`).
    pub fn with(mut self, key: &str, value: impl Serialize) -> Self {
        self.insert(key, value);
        self
    }

    /// Sets `key`.
    pub fn insert(&mut self, key: &str, value: impl Serialize) {
        let value = serde_json::to_value(value).unwrap_or(Value::Null);
        self.0.insert(key.to_owned(), value);
    }

    /// Every field of a struct that serialises to a JSON object.
    pub fn from_serialize(value: &impl Serialize) -> anyhow::Result<Self> {
        match serde_json::to_value(value)? {
            Value::Object(map) => Ok(Self(map)),
            other => bail!("metrics must serialise to a JSON object, got {other}"),
        }
    }

    /// The number at `key`, if it is one.
    pub fn number(&self, key: &str) -> Option<f64> {
        self.0.get(key).and_then(Value::as_f64)
    }
}

/// How the metrics of several seeds of one condition and method become one entry.
pub type Summarise = fn(&[&Metrics]) -> Metrics;

/// The default [`Summarise`]: the mean of every key that is a number in all seeds, and `seeds`,
/// their count.
pub fn mean_over_seeds(runs: &[&Metrics]) -> Metrics {
    let mut out = Metrics::new();
    if let Some(first) = runs.first() {
        for key in first.0.keys() {
            let values: Option<Vec<f64>> = runs.iter().map(|m| m.number(key)).collect();
            if let Some(v) = values {
                out.insert(key, v.iter().sum::<f64>() / v.len() as f64);
            }
        }
    }
    out.insert("seeds", runs.len());
    out
}

/// Why a run folder cannot be resumed.
#[derive(Debug, Error)]
pub enum ResumeError {
    /// No `study.json`: not a run folder, or one from before studies.
    #[error(
        "{}: not a resumable run folder (no study.json; it was made by an older cpose or is not a run folder)",
        .0.display()
    )]
    NotAStudy(PathBuf),
    /// `study.json` is not what a study writes.
    #[error("{}: {message}", .path.display())]
    Corrupt {
        /// `study.json`.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The folder holds a run of another task.
    #[error("{}: holds a run of task {found:?}, but its config.toml names task {expected:?}", .path.display())]
    OtherTask {
        /// The run folder.
        path: PathBuf,
        /// The task in `study.json`.
        found: String,
        /// The task of the config.
        expected: String,
    },
    /// `config.toml` changed since the run started.
    #[error(
        "{}: config.toml was changed after the run started (its results would mix two configs); \
         start a new run with the changed config instead",
        .0.display()
    )]
    OtherConfig(PathBuf),
    /// Every unit finished.
    #[error("{}: the run finished; its results are in metrics.json (nothing to resume)", .0.display())]
    Finished(PathBuf),
}

/// `study.json`.
#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    task: String,
    /// FNV-1a of the resolved config's text, hexadecimal.
    config_hash: String,
    units: Vec<UnitKey>,
    finished: bool,
}

/// FNV-1a (64 bits) of the config's text: a stable fingerprint of the resolved config.
fn config_hash(config: &Config) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in config.text().bytes() {
        h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Checks that `dir` holds an unfinished study of `task` made with `config` (call before
/// resuming; [`Study::run`] calls it too).
pub fn check_resume(dir: &Path, task: &str, config: &Config) -> Result<(), ResumeError> {
    let path = dir.join("study.json");
    let Ok(text) = std::fs::read_to_string(&path) else {
        // Killed before its study began: nothing to keep, the study starts from the beginning.
        // Results without a manifest are an older cpose's.
        if dir.join("metrics.json").exists() {
            return Err(ResumeError::NotAStudy(dir.to_owned()));
        }
        return Ok(());
    };
    let manifest: Manifest = serde_json::from_str(&text).map_err(|e| ResumeError::Corrupt {
        path: path.clone(),
        message: format!("not a study manifest: {e}"),
    })?;
    if manifest.task != task {
        return Err(ResumeError::OtherTask {
            path: dir.to_owned(),
            found: manifest.task,
            expected: task.to_owned(),
        });
    }
    if manifest.config_hash != config_hash(config) {
        return Err(ResumeError::OtherConfig(dir.to_owned()));
    }
    if manifest.finished {
        return Err(ResumeError::Finished(dir.to_owned()));
    }
    Ok(())
}

/// A study: its units and how to report them. See the module docs.
pub struct Study<'a> {
    input: &'a TaskInput<'a>,
    units: Vec<UnitKey>,
    parallel: bool,
    report_every: usize,
    columns: Vec<String>,
    summarise: Summarise,
}

impl std::fmt::Debug for Study<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Study")
            .field("units", &self.units)
            .field("parallel", &self.parallel)
            .field("report_every", &self.report_every)
            .finish_non_exhaustive()
    }
}

/// The finished units' metrics, by unit.
pub type Results = BTreeMap<UnitKey, Metrics>;

/// One condition's metrics, by method, then seed.
type BySeed<'a> = BTreeMap<&'a str, Vec<(u64, &'a Metrics)>>;

impl<'a> Study<'a> {
    /// A study of `units`, run in order, one at a time.
    pub fn new(input: &'a TaskInput<'a>, units: Vec<UnitKey>) -> Self {
        Self {
            input,
            units,
            parallel: false,
            report_every: input.run.report_every.unwrap_or(DEFAULT_REPORT_EVERY),
            columns: Vec::new(),
            summarise: mean_over_seeds,
        }
    }

    /// Runs units side by side on the thread pool (for units that are single-threaded inside).
    pub fn parallel(mut self, parallel: bool) -> Self {
        self.parallel = parallel;
        self
    }

    /// Steps between live reports when `[run] report_every` is not set.
    pub fn report_every(mut self, steps: usize) -> Self {
        if self.input.run.report_every.is_none() {
            self.report_every = steps.max(1);
        }
        self
    }

    /// The metrics shown in the final table, in this order.
    pub fn columns(mut self, columns: &[&str]) -> Self {
        self.columns = columns.iter().map(|c| (*c).to_owned()).collect();
        self
    }

    /// How seeds of one condition and method are combined in `metrics.json` (default
    /// [`mean_over_seeds`]; each seed's metrics are kept under `runs`).
    pub fn summarise(mut self, summarise: Summarise) -> Self {
        self.summarise = summarise;
        self
    }

    /// Runs every unit that has not finished, writes `metrics.json` after each and the final
    /// table at the end, and returns every unit's metrics.
    pub fn run<F>(self, run_unit: F) -> anyhow::Result<Results>
    where
        F: Fn(&mut Unit) -> anyhow::Result<Metrics> + Sync,
    {
        let input = self.input;
        let dir = input.run_dir;
        let mut seen = BTreeSet::new();
        for u in &self.units {
            if u.condition.is_empty() || u.method.is_empty() {
                bail!("study unit {u:?}: condition and method must not be empty");
            }
            if !seen.insert(u.name(true)) {
                bail!("study unit {u:?} is listed twice (or two keys share a file name)");
            }
        }
        let seeds: BTreeSet<u64> = self.units.iter().map(|u| u.seed).collect();
        let with_seed = seeds.len() > 1;
        let task = input.config.task_name()?;
        let config_name = input.config.path().file_name().map_or_else(
            || input.config.path().display().to_string(),
            |name| name.to_string_lossy().into_owned(),
        );
        let curves_title = format!("Training curves: task {task}, {config_name}");
        let hash = config_hash(input.config);
        if input.resume {
            check_resume(dir.path(), &task, input.config)?;
        }
        let mut manifest = Manifest {
            task,
            config_hash: hash.clone(),
            units: self.units.clone(),
            finished: false,
        };
        dir.write_json("study.json", &manifest)?;

        let mut results = Results::new();
        let mut pending = Vec::new();
        for key in &self.units {
            let name = key.name(with_seed);
            let result = dir.file(Path::new("units").join(&name).join("result.json"));
            if input.resume && result.is_file() {
                let text = std::fs::read_to_string(&result)
                    .with_context(|| format!("cannot read {}", result.display()))?;
                let metrics: Metrics = serde_json::from_str(&text).with_context(|| {
                    format!(
                        "{} is not a unit's result; remove it to run the unit again",
                        result.display()
                    )
                })?;
                dir.log(format_args!("{name}: finished before the resume"));
                results.insert(key.clone(), metrics);
            } else {
                pending.push((key.clone(), name));
            }
        }
        let shared = Shared {
            input,
            report_every: self.report_every,
            hash,
            results: Mutex::new(results),
            write: Mutex::new(()),
            study: &self,
            with_seed,
            curves_title,
            curves_plot_failed: AtomicBool::new(false),
            curves_drawn: Mutex::new(None),
        };
        let run_one = |(key, name): &(UnitKey, String)| -> anyhow::Result<()> {
            let metrics = shared
                .run_unit(key, name, &run_unit)
                .with_context(|| format!("unit {name}"))?;
            if let Ok(mut r) = shared.results.lock() {
                r.insert(key.clone(), metrics);
            }
            shared.write_outputs(false)
        };
        if self.parallel {
            pending.par_iter().try_for_each(run_one)?;
        } else {
            pending.iter().try_for_each(run_one)?;
        }
        shared.write_outputs(true)?;
        let results = shared.results.into_inner().unwrap_or_default();
        dir.log(self.table(&results));
        manifest.finished = true;
        dir.write_json("study.json", &manifest)?;
        Ok(results)
    }

    /// `metrics.json`: condition → method → metrics (seeds summarised, each kept under `runs`).
    fn metrics_json(&self, results: &Results) -> Value {
        let mut grouped: BTreeMap<&str, BySeed<'_>> = BTreeMap::new();
        for (k, m) in results {
            grouped
                .entry(&k.condition)
                .or_default()
                .entry(&k.method)
                .or_default()
                .push((k.seed, m));
        }
        let mut out = serde_json::Map::new();
        for (condition, methods) in grouped {
            let mut by_method = serde_json::Map::new();
            for (method, runs) in methods {
                let entry = if let [(_, only)] = runs.as_slice() {
                    Value::Object(only.0.clone())
                } else {
                    let all: Vec<&Metrics> = runs.iter().map(|(_, m)| *m).collect();
                    let mut summary = (self.summarise)(&all);
                    let per_seed: serde_json::Map<String, Value> = runs
                        .iter()
                        .map(|(s, m)| (s.to_string(), Value::Object(m.0.clone())))
                        .collect();
                    summary.0.insert("runs".into(), Value::Object(per_seed));
                    Value::Object(summary.0)
                };
                by_method.insert(method.to_owned(), entry);
            }
            out.insert(condition.to_owned(), Value::Object(by_method));
        }
        Value::Object(out)
    }

    /// The final table: one row per condition and method, the chosen columns (or every numeric
    /// metric), seeds summarised.
    fn table(&self, results: &Results) -> String {
        let json = self.metrics_json(results);
        let mut rows: Vec<(String, &serde_json::Map<String, Value>)> = Vec::new();
        if let Value::Object(conditions) = &json {
            for (c, methods) in conditions {
                if let Value::Object(methods) = methods {
                    for (m, metrics) in methods {
                        if let Value::Object(metrics) = metrics {
                            rows.push((format!("{c} / {m}"), metrics));
                        }
                    }
                }
            }
        }
        let columns: Vec<String> = if self.columns.is_empty() {
            let all: BTreeSet<&String> = rows
                .iter()
                .flat_map(|(_, m)| m.iter().filter(|(_, v)| v.is_number()).map(|(k, _)| k))
                .collect();
            all.into_iter().cloned().collect()
        } else {
            self.columns.clone()
        };
        let width = rows.iter().map(|(r, _)| r.len()).max().unwrap_or(0).max(4);
        let mut s = format!("results\n{:<width$}", "unit");
        for c in &columns {
            let _ = write!(s, "  {c:>10}");
        }
        for (name, metrics) in &rows {
            let _ = write!(s, "\n{name:<width$}");
            for c in &columns {
                let cell = metrics.get(c).map_or(String::new(), format_value);
                let w = c.len().max(10);
                let _ = write!(s, "  {cell:>w$}");
            }
        }
        s
    }
}

/// A value for a table cell: integers as integers, other numbers by [`format_number`].
pub fn format_value(v: &Value) -> String {
    match v {
        Value::Number(n) => format_json_number(n),
        Value::Null => "-".into(),
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// A JSON number: an integer as it is (`500`, not `500.0`), others by [`format_number`].
pub fn format_json_number(n: &serde_json::Number) -> String {
    if n.is_i64() || n.is_u64() {
        n.to_string()
    } else {
        n.as_f64().map_or_else(|| n.to_string(), format_number)
    }
}

/// Four significant digits, no exponent for ordinary magnitudes.
pub fn format_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return v.to_string();
    }
    let magnitude = v.abs().log10().floor() as i32;
    if (-3..6).contains(&magnitude) {
        let decimals = (3 - magnitude).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

/// What the units of one study share.
struct Shared<'s, 'a> {
    input: &'a TaskInput<'a>,
    report_every: usize,
    hash: String,
    results: Mutex<Results>,
    /// Serialises the writes of `metrics.json` and `curves.csv`.
    write: Mutex<()>,
    study: &'s Study<'a>,
    with_seed: bool,
    /// The title of `curves.png`.
    curves_title: String,
    /// Whether drawing `curves.png` failed (and was logged) already.
    curves_plot_failed: AtomicBool,
    /// When `curves.png` was last drawn.
    curves_drawn: Mutex<Option<Instant>>,
}

impl Shared<'_, '_> {
    fn run_unit<F>(&self, key: &UnitKey, name: &str, run: &F) -> anyhow::Result<Metrics>
    where
        F: Fn(&mut Unit) -> anyhow::Result<Metrics>,
    {
        let dir = self.input.run_dir;
        let unit_dir = PathBuf::from("units").join(name);
        std::fs::create_dir_all(dir.file(&unit_dir))
            .with_context(|| format!("cannot create {}", dir.file(&unit_dir).display()))?;
        // Units side by side are single-threaded inside: the thread's time is the unit's.
        let cpu_clock: fn() -> Option<f64> = if self.study.parallel {
            thread_cpu_secs
        } else {
            process_cpu_secs
        };
        let mut unit = Unit {
            key: key.clone(),
            name: name.to_owned(),
            with_seed: self.with_seed,
            dir: unit_dir,
            run_dir: dir,
            progress: self.input.progress(0, name.to_owned()),
            report_every: self.report_every,
            checkpoint_secs: self.input.run.checkpoint_secs,
            hash: self.hash.clone(),
            started: Instant::now(),
            cpu_clock,
            cpu_at_start: cpu_clock(),
            earlier_wall_s: 0.0,
            earlier_cpu_s: 0.0,
            last_checkpoint: Instant::now(),
            last_step: None,
            curves: Vec::new(),
            resumed: None,
        };
        if self.input.resume {
            unit.load_checkpoint()?;
        } else {
            // A fresh unit: nothing of an earlier run in this folder counts.
            let _ = std::fs::remove_file(unit.checkpoint_path());
        }
        unit.restore_curves()?;
        let mut metrics = run(&mut unit)?;
        unit.progress.finish();
        let (wall_s, cpu_s) = unit.elapsed();
        if !metrics.0.contains_key("wall_s") {
            metrics.insert("wall_s", wall_s);
        }
        if !metrics.0.contains_key("cpu_s")
            && let Some(cpu) = cpu_s
        {
            metrics.insert("cpu_s", cpu);
        }
        unit.flush_curves()?;
        dir.write_json(unit.dir.join("result.json"), &metrics)?;
        let _ = std::fs::remove_file(unit.checkpoint_path());
        let _ = std::fs::remove_file(with_suffix(&unit.checkpoint_path(), ".prev"));
        dir.log(format_args!(
            "{name}: finished in {wall_s:.1} s{}",
            metrics_line(&metrics, &self.study.columns)
        ));
        Ok(metrics)
    }

    /// Rewrites `metrics.json`, `curves.csv` and `curves.png` from the finished units; until
    /// the study has `finished`, `curves.png` at most every [`CURVES_PNG_EVERY_SECS`].
    fn write_outputs(&self, finished: bool) -> anyhow::Result<()> {
        let _guard = self.write.lock();
        let results = self
            .results
            .lock()
            .map_err(|_| anyhow::anyhow!("a unit panicked"))?
            .clone();
        let dir = self.input.run_dir;
        dir.write_json("metrics.json", &self.study.metrics_json(&results))?;
        let mut csv = format!("{CURVES_HEADER}\n");
        for key in self.study.units.iter() {
            let path = dir.file(
                Path::new("units")
                    .join(key.name(self.with_seed))
                    .join("curves.csv"),
            );
            if let Ok(text) = std::fs::read_to_string(&path) {
                csv.extend(text.lines().skip(1).flat_map(|l| [l, "\n"]));
            }
        }
        dir.write("curves.csv", csv.as_bytes())?;
        if let Ok(mut drawn) = self.curves_drawn.lock()
            && (finished
                || drawn.is_none_or(|t| t.elapsed().as_secs_f64() >= CURVES_PNG_EVERY_SECS))
        {
            self.write_curves_png(&csv);
            *drawn = Some(Instant::now());
        }
        Ok(())
    }

    /// Draws `curves.csv` (`csv`, when it has rows) as `curves.png`. A plot is not worth a
    /// study: a failure is logged (once) and the study goes on.
    fn write_curves_png(&self, csv: &str) {
        if csv.lines().nth(1).is_none() {
            return;
        }
        let dir = self.input.run_dir;
        if let Err(e) = plot::curves_csv(dir.file("curves.png"), &self.curves_title, csv)
            && !self.curves_plot_failed.swap(true, Ordering::Relaxed)
        {
            dir.log(format_args!("curves.png not drawn: {e}"));
        }
    }
}

/// ` — a 1.2, b 3` for the chosen columns (all numbers when none are chosen).
fn metrics_line(metrics: &Metrics, columns: &[String]) -> String {
    let mut s = String::new();
    for (k, v) in &metrics.0 {
        if (columns.is_empty() && v.is_number()) || columns.contains(k) {
            let _ = write!(
                s,
                "{}{k} {}",
                if s.is_empty() { " — " } else { ", " },
                format_value(v)
            );
        }
    }
    s
}

/// `path` with `suffix` appended to its file name.
fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(suffix);
    path.with_file_name(name)
}

/// One running unit: what its function may ask of the study.
#[derive(Debug)]
pub struct Unit<'a> {
    key: UnitKey,
    name: String,
    with_seed: bool,
    /// `units/<name>`, relative to the run folder.
    dir: PathBuf,
    run_dir: &'a RunDir,
    progress: Progress,
    report_every: usize,
    checkpoint_secs: f64,
    hash: String,
    started: Instant,
    /// The clock of the unit's CPU time: the process's, or the thread's for units side by side.
    cpu_clock: fn() -> Option<f64>,
    cpu_at_start: Option<f64>,
    earlier_wall_s: f64,
    earlier_cpu_s: f64,
    last_checkpoint: Instant,
    /// Steps completed at the newest checkpoint (written or resumed from).
    last_step: Option<u64>,
    /// Curve rows not yet flushed to `units/<name>/curves.csv`.
    curves: Vec<String>,
    /// The step and the task's part of the checkpoint this unit resumes from.
    resumed: Option<(u64, Reader)>,
}

impl Unit<'_> {
    /// The unit's condition, method and seed.
    pub fn key(&self) -> &UnitKey {
        &self.key
    }

    /// `<condition>_<method>` (with `_s<seed>` when the study has several seeds).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The run folder, for files shared by the units.
    pub fn run_dir(&self) -> &RunDir {
        self.run_dir
    }

    /// `<stem>_<condition>_<method>[_s<seed>].<ext>`, e.g. `traj_tight_posenet.txt`: the name of
    /// one of this unit's output files in the run folder.
    pub fn file_name(&self, stem: &str, ext: &str) -> String {
        format!("{}_{}.{ext}", clean(stem), self.key.name(self.with_seed))
    }

    /// The path of [`Unit::file_name`] in the run folder.
    pub fn file(&self, stem: &str, ext: &str) -> PathBuf {
        self.run_dir.file(self.file_name(stem, ext))
    }

    /// `<stem>_<condition>_<method>[_s<seed>]` in the run folder: one of this unit's output
    /// folders (e.g. a COLMAP model).
    pub fn folder(&self, stem: &str) -> PathBuf {
        self.run_dir
            .file(format!("{}_{}", clean(stem), self.key.name(self.with_seed)))
    }

    /// Logs `message`, prefixed by the unit's name.
    pub fn log(&self, message: impl std::fmt::Display) {
        self.run_dir.log(format_args!("{}: {message}", self.name));
    }

    /// Sets the number of steps of the unit's bar.
    pub fn set_steps(&self, steps: usize) {
        self.progress.set_length(steps as u64);
    }

    /// Moves the bar to `step`.
    pub fn set_step(&self, step: usize) {
        self.progress.set_position(step as u64);
    }

    /// Moves the bar to `step` and says whether the live metrics are due: every
    /// `report_every`-th step, the first and the last.
    pub fn report_due(&self, step: usize) -> bool {
        self.set_step(step);
        step == 1
            || step.is_multiple_of(self.report_every)
            || self.progress.length().is_some_and(|n| step as u64 == n)
    }

    /// Records the live metrics at `step` (e.g. `("loss", l)`, `("rot_err_deg", e)`): a line
    /// in the log, the bar's message and rows of `curves.csv`.
    pub fn report(&mut self, step: usize, values: &[(&str, f64)]) {
        let wall = self.elapsed().0;
        let mut line = format!("step {step}");
        for (name, v) in values {
            let _ = write!(line, "  {name} {}", format_number(*v));
            self.curves.push(format!(
                "{},{},{},{step},{wall:.3},{},{v:e}\n",
                clean(&self.key.condition),
                clean(&self.key.method),
                self.key.seed,
                clean(name),
            ));
        }
        self.progress.set_message(format!("{} {line}", self.name));
        self.log(line);
    }

    /// Wall seconds the unit has run, over every session.
    pub fn wall_secs(&self) -> f64 {
        self.elapsed().0
    }

    /// Whether a checkpoint is due: `[run] checkpoint_secs` have passed since the last one
    /// (or the unit's start).
    pub fn checkpoint_due(&self) -> bool {
        self.last_checkpoint.elapsed().as_secs_f64() >= self.checkpoint_secs
    }

    /// Saves the unit's state after `step` completed steps: `write` adds the task's values.
    /// The previous checkpoint is kept as `checkpoint.bin.prev`; when `write` fails (say, on a
    /// diverged state) nothing is written and its error returned.
    pub fn checkpoint(
        &mut self,
        step: u64,
        write: impl FnOnce(&mut Writer) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let (wall_s, cpu_s) = self.elapsed();
        let mut w = Writer::new();
        w.str(&self.hash);
        w.str(&self.name);
        w.u64(step);
        w.f64(wall_s);
        w.f64(cpu_s.unwrap_or(f64::NAN));
        write(&mut w)?;
        self.flush_curves()?;
        let path = self.checkpoint_path();
        if path.is_file() {
            std::fs::rename(&path, with_suffix(&path, ".prev")).with_context(|| {
                format!("cannot keep the previous checkpoint {}", path.display())
            })?;
        }
        w.save(&path)?;
        self.last_checkpoint = Instant::now();
        self.last_step = Some(step);
        Ok(())
    }

    /// The newest checkpoint of this unit and the steps it had completed, if there is one.
    pub fn last_checkpoint(&self) -> Option<(PathBuf, u64)> {
        self.last_step.map(|step| (self.checkpoint_path(), step))
    }

    /// After `cpose run --resume`: the number of steps the last checkpoint had completed and a
    /// reader at the task's values, once; `None` for a unit that starts from the beginning.
    pub fn resume(&mut self) -> Option<(u64, Reader)> {
        let resumed = self.resumed.take();
        if let Some((step, r)) = &resumed {
            self.log(format_args!(
                "resumed after step {step} from {}",
                r.path().display()
            ));
            self.set_step(*step as usize);
        }
        resumed
    }

    fn checkpoint_path(&self) -> PathBuf {
        self.run_dir.file(self.dir.join("checkpoint.bin"))
    }

    /// Wall and CPU seconds of the unit so far, over every session.
    fn elapsed(&self) -> (f64, Option<f64>) {
        let wall = self.earlier_wall_s + self.started.elapsed().as_secs_f64();
        let cpu = match (self.cpu_at_start, (self.cpu_clock)()) {
            (Some(a), Some(b)) if self.earlier_cpu_s.is_finite() => {
                Some(self.earlier_cpu_s + b - a)
            }
            _ => None,
        };
        (wall, cpu)
    }

    /// Reads the newest valid checkpoint; a damaged one is set aside as `….corrupt` (never
    /// loaded, never deleted) and the previous one used instead.
    fn load_checkpoint(&mut self) -> anyhow::Result<()> {
        let path = self.checkpoint_path();
        for candidate in [path.clone(), with_suffix(&path, ".prev")] {
            if !candidate.is_file() {
                continue;
            }
            match self.open_checkpoint(&candidate) {
                Ok(found) => {
                    self.last_step = Some(found.0);
                    if candidate != path {
                        // The damaged newest one is set aside; the older one takes its place.
                        std::fs::rename(&candidate, &path)
                            .with_context(|| format!("cannot restore {}", candidate.display()))?;
                    }
                    self.resumed = Some(found);
                    return Ok(());
                }
                Err(e) => {
                    let aside = with_suffix(&candidate, ".corrupt");
                    let _ = std::fs::rename(&candidate, &aside);
                    self.log(format_args!(
                        "{e:#}; not loaded, kept as {}",
                        aside.display()
                    ));
                }
            }
        }
        Ok(())
    }

    fn open_checkpoint(&mut self, path: &Path) -> anyhow::Result<(u64, Reader)> {
        let mut r = Reader::open(path)?;
        let (hash, name) = (r.str()?, r.str()?);
        if hash != self.hash || name != self.name {
            bail!(
                "{}: a checkpoint of unit {name:?} with another config",
                path.display()
            );
        }
        let step = r.u64()?;
        self.earlier_wall_s = r.f64()?;
        self.earlier_cpu_s = r.f64()?;
        Ok((step, r))
    }

    /// Keeps the rows of `units/<name>/curves.csv` up to the resumed step (a fresh unit: none).
    fn restore_curves(&mut self) -> anyhow::Result<()> {
        let path = self.run_dir.file(self.dir.join("curves.csv"));
        let upto = self.resumed.as_ref().map(|(s, _)| *s);
        let mut kept = format!("{CURVES_HEADER}\n");
        if let (Some(upto), Ok(text)) = (upto, std::fs::read_to_string(&path)) {
            for line in text.lines().skip(1) {
                let step = line.split(',').nth(3).and_then(|s| s.parse::<u64>().ok());
                if step.is_some_and(|s| s <= upto) {
                    kept.push_str(line);
                    kept.push('\n');
                }
            }
        }
        self.run_dir
            .write(self.dir.join("curves.csv"), kept.as_bytes())?;
        Ok(())
    }

    fn flush_curves(&mut self) -> anyhow::Result<()> {
        if self.curves.is_empty() {
            return Ok(());
        }
        let path = self.run_dir.file(self.dir.join("curves.csv"));
        let mut file = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .with_context(|| format!("cannot append to {}", path.display()))?;
        for row in self.curves.drain(..) {
            file.write_all(row.as_bytes())
                .with_context(|| format!("cannot append to {}", path.display()))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run_dir::RunDirOptions;
    use crate::testing::TempDir;
    use std::sync::atomic::{AtomicUsize, Ordering};

    const CONFIG: &str = "task = \"demo\"\n[run]\ncheckpoint_secs = 0.0\n";

    /// Runs the demo study in `dir`: a unit counts down from `10 · (seed + 1)` over 20 steps,
    /// checkpointing every step; `fail_at` makes unit `hard_b` fail at that step (a kill).
    fn demo(
        dir: &Path,
        resume: bool,
        fail_at: Option<usize>,
        calls: &AtomicUsize,
    ) -> anyhow::Result<Results> {
        let config = Config::from_text(dir.join("config.toml"), CONFIG);
        let run = config.run_config()?;
        let run_dir = RunDir::create(
            "demo",
            &RunDirOptions {
                out: Some(dir.to_owned()),
                existing: crate::run_dir::Existing::Keep,
                ..Default::default()
            },
        )?;
        let input = TaskInput {
            config: &config,
            run_dir: &run_dir,
            run: &run,
            show_progress: false,
            resume,
        };
        let units = UnitKey::grid(&["easy", "hard"], &["a", "b"], &[0, 1]);
        Study::new(&input, units)
            .report_every(5)
            .columns(&["error"])
            .run(|unit| {
                calls.fetch_add(1, Ordering::Relaxed);
                let steps = 20;
                unit.set_steps(steps);
                let (mut error, mut first) = (10.0 * (unit.key().seed + 1) as f64, 0);
                if let Some((done, mut r)) = unit.resume() {
                    error = r.f64()?;
                    first = done as usize;
                }
                for step in first + 1..=steps {
                    error *= 0.9;
                    if unit.report_due(step) {
                        unit.report(step, &[("error", error)]);
                    }
                    if fail_at == Some(step) && unit.name() == "hard_b_s1" {
                        bail!("killed");
                    }
                    if unit.checkpoint_due() {
                        unit.checkpoint(step as u64, |w| {
                            w.f64(error);
                            Ok(())
                        })?;
                    }
                }
                let file = unit.file("traj", "txt");
                std::fs::write(file, format!("{error}"))?;
                Ok(Metrics::new().with("error", error).with("steps", steps))
            })
    }

    fn strip_timing(v: &mut Value) {
        if let Value::Object(map) = v {
            map.remove("wall_s");
            map.remove("cpu_s");
            map.values_mut().for_each(strip_timing);
        }
    }

    fn metrics(dir: &Path) -> Value {
        let mut v: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap())
                .unwrap();
        strip_timing(&mut v);
        v
    }

    #[test]
    fn units_write_nested_metrics_curves_and_named_files() {
        let dir = TempDir::new("study");
        let calls = AtomicUsize::new(0);
        let results = demo(&dir, false, None, &calls).unwrap();
        assert_eq!(results.len(), 8);
        assert_eq!(calls.load(Ordering::Relaxed), 8);
        let m = metrics(&dir);
        let e0 = 10.0 * 0.9f64.powi(20);
        let hard_b = &m["hard"]["b"];
        assert!(
            (hard_b["error"].as_f64().unwrap() - 1.5 * e0).abs() < 1e-12,
            "{m}"
        );
        assert_eq!(hard_b["seeds"], 2);
        assert_eq!(hard_b["runs"]["1"]["steps"], 20);
        assert!(dir.join("traj_easy_a_s0.txt").is_file());
        let curves = std::fs::read_to_string(dir.join("curves.csv")).unwrap();
        let mut lines = curves.lines();
        assert_eq!(lines.next(), Some(CURVES_HEADER));
        // Steps 1, 5, 10, 15, 20 for each of 8 units.
        assert_eq!(lines.clone().count(), 40);
        assert!(lines.any(|l| l.starts_with("hard,b,1,20,")), "{curves}");
        let plot = image::open(dir.join("curves.png")).unwrap();
        assert!(
            plot.width() >= plot::CURVES_PANEL_SIZE.0,
            "{}",
            plot.width()
        );
        // No checkpoint is left behind by finished units.
        assert!(!dir.join("units/hard_b_s1/checkpoint.bin").exists());
        let log = std::fs::read_to_string(dir.join("log.txt")).unwrap();
        assert!(log.contains("easy_a_s0: step 5  error"), "{log}");
        assert!(log.contains("hard / b"), "{log}");
        // A finished run cannot be resumed.
        let e = demo(&dir, true, None, &calls).unwrap_err();
        assert!(
            e.downcast_ref::<ResumeError>()
                .is_some_and(|e| matches!(e, ResumeError::Finished(_))),
            "{e}"
        );
    }

    #[test]
    fn a_plot_that_cannot_be_written_is_logged_and_the_study_finishes() {
        let dir = TempDir::new("study-no-plot");
        // A folder in the way of curves.png.
        std::fs::create_dir_all(dir.join("curves.png")).unwrap();
        let calls = AtomicUsize::new(0);
        let results = demo(&dir, false, None, &calls).unwrap();
        assert_eq!(results.len(), 8);
        let log = std::fs::read_to_string(dir.join("log.txt")).unwrap();
        assert_eq!(log.matches("curves.png not drawn").count(), 1, "{log}");
    }

    #[test]
    fn a_killed_study_resumes_to_the_same_results_without_rerunning_finished_units() {
        let whole = TempDir::new("study-whole");
        let calls = AtomicUsize::new(0);
        demo(&whole, false, None, &calls).unwrap();
        let cut = TempDir::new("study-cut");
        let e = demo(&cut, false, Some(13), &calls).unwrap_err();
        assert!(format!("{e:#}").contains("unit hard_b_s1: killed"), "{e:#}");
        // Damage the newest checkpoint: it is set aside and the one before is used.
        let ckpt = cut.join("units/hard_b_s1/checkpoint.bin");
        let mut bytes = std::fs::read(&ckpt).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&ckpt, bytes).unwrap();
        // A checkpoint write killed half-way leaves its temporary file behind: never read.
        std::fs::write(
            cut.join("units/hard_b_s1/checkpoint.bin.tmp"),
            b"cpose checkpoint v3\n\x07",
        )
        .unwrap();
        calls.store(0, Ordering::Relaxed);
        demo(&cut, true, None, &calls).unwrap();
        assert_eq!(
            calls.load(Ordering::Relaxed),
            1,
            "only the unfinished unit runs"
        );
        assert_eq!(metrics(&cut), metrics(&whole));
        for f in ["traj_hard_b_s1.txt", "curves.csv"] {
            let strip = |d: &Path| -> Vec<String> {
                let text = std::fs::read_to_string(d.join(f)).unwrap();
                // curves.csv: all but the wall-clock column.
                text.lines()
                    .map(|l| {
                        let mut c: Vec<&str> = l.split(',').collect();
                        if c.len() == 7 {
                            c.remove(4);
                        }
                        c.join(",")
                    })
                    .collect()
            };
            assert_eq!(strip(&cut), strip(&whole), "{f}");
        }
        assert!(cut.join("units/hard_b_s1/checkpoint.bin.corrupt").is_file());
        let log = std::fs::read_to_string(cut.join("log.txt")).unwrap();
        assert!(log.contains("checksum does not match"), "{log}");
        assert!(log.contains("hard_b_s1: resumed after step 11"), "{log}");
        assert!(
            log.contains("easy_a_s0: finished before the resume"),
            "{log}"
        );
    }

    #[test]
    fn resume_refuses_other_tasks_configs_and_non_studies() {
        let dir = TempDir::new("study-refuse");
        let config = Config::from_text("c.toml", CONFIG);
        // Killed before the study began: it starts from the beginning.
        check_resume(&dir, "demo", &config).unwrap();
        std::fs::write(dir.join("metrics.json"), "{}").unwrap();
        let e = check_resume(&dir, "demo", &config).unwrap_err();
        assert!(e.to_string().contains("no study.json"), "{e}");
        std::fs::write(dir.join("study.json"), "{").unwrap();
        let e = check_resume(&dir, "demo", &config).unwrap_err();
        assert!(e.to_string().contains("not a study manifest"), "{e}");
        let manifest = Manifest {
            task: "demo".into(),
            config_hash: config_hash(&config),
            units: Vec::new(),
            finished: false,
        };
        std::fs::write(
            dir.join("study.json"),
            serde_json::to_string(&manifest).unwrap(),
        )
        .unwrap();
        check_resume(&dir, "demo", &config).unwrap();
        let e = check_resume(&dir, "slam", &config).unwrap_err();
        assert!(
            e.to_string().contains("holds a run of task \"demo\""),
            "{e}"
        );
        let edited = Config::from_text("c.toml", format!("{CONFIG}seed = 1\n"));
        let e = check_resume(&dir, "demo", &edited).unwrap_err();
        assert!(e.to_string().contains("config.toml was changed"), "{e}");
    }

    #[test]
    fn names_and_numbers_are_clean() {
        let k = UnitKey::new("rm=60 tm/10", "lie_spline", 3);
        assert_eq!(k.name(false), "rm-60-tm-10_lie_spline");
        assert_eq!(k.name(true), "rm-60-tm-10_lie_spline_s3");
        assert_eq!(format_value(&serde_json::json!(500)), "500");
        assert_eq!(format_value(&serde_json::json!(0.012345)), "0.01235");
        assert_eq!(format_value(&serde_json::json!(12.0)), "12.00");
        assert_eq!(format_value(&serde_json::json!(1.5e-7)), "1.500e-7");
        assert_eq!(format_value(&Value::Null), "-");
        let m = mean_over_seeds(&[
            &Metrics::new().with("e", 1.0).with("s", "x"),
            &Metrics::new().with("e", 3.0).with("s", "y"),
        ]);
        assert_eq!(m.number("e"), Some(2.0));
        assert_eq!(m.0.get("s"), None);
        assert_eq!(m.number("seeds"), Some(2.0));
    }
}
