//! Experiment configs: one TOML file per run, read from text into typed structs.
//!
//! A config is `task = "name"`, an optional `[run]` table ([`RunConfig`]) and the task's own
//! tables:
//!
//! ```toml
//! task = "trajectory"
//!
//! [run]
//! seed = 3
//! iterations_scale = 0.1   # run every loop for 10% of its iterations
//!
//! [model]                  # a pose field chosen by name, see `registry::build_pose_field`
//! kind = "posenet"
//! width = 128
//! ```
//!
//! The text is kept as written (plus `--set key.path=value` overrides, applied with `toml_edit`
//! so comments and layout survive) and decoded as often as needed:
//! - [`Config::task_name`] reads only `task`;
//! - [`Config::parse`] decodes the whole document into a task's struct, and
//!   [`Config::parse_params`] the document without `task` and `[run]`;
//! - [`Config::section`] points at one table (e.g. `[model]`) that a registry decodes.
//!
//! Typed structs use `#[serde(deny_unknown_fields)]`, so a typo is reported with the file, line,
//! column, a caret under the key and the list of valid keys. Spans always refer to the resolved
//! text, which is what [`Config::text`] returns and what the run folder stores as `config.toml`.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde::de::DeserializeOwned;
use thiserror::Error;
use toml::de::{DeTable, DeValue, ValueDeserializer};
use toml_edit::{DocumentMut, Item, TableLike};

/// A 1-based line and column in a config's resolved text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Location {
    /// Line, starting at 1.
    pub line: usize,
    /// Column in characters, starting at 1.
    pub column: usize,
}

impl Location {
    /// The line and column of byte offset `offset` in `text` (clamped to the text's end).
    pub fn from_offset(text: &str, offset: usize) -> Self {
        let mut offset = offset.min(text.len());
        while !text.is_char_boundary(offset) {
            offset -= 1;
        }
        let before = &text[..offset];
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        Self {
            line: before.matches('\n').count() + 1,
            column: before[line_start..].chars().count() + 1,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.column)
    }
}

/// Errors of reading, overriding and decoding configs. Every message starts with the config's
/// path (and line and column where known), so the CLI prints it as it is.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config {}: {error}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// TOML syntax error, wrong type, missing field or unknown key (toml's message, with line,
    /// column, a caret and, for unknown keys, the valid keys).
    #[error("{}: {}", .path.display(), .error.to_string().trim_end())]
    Toml {
        /// The config file (for messages).
        path: PathBuf,
        /// Where in the resolved text, when toml reported a span.
        location: Option<Location>,
        /// toml's error, with the input set so that it renders the offending line.
        error: Box<toml::de::Error>,
    },
    /// A malformed `--set` override.
    #[error("invalid override {arg:?}: {message}")]
    Override {
        /// The override as given, `key.path=value`.
        arg: String,
        /// What is wrong.
        message: String,
    },
    /// Any other problem at a place in the file: an unknown name in a registry, a missing key, a
    /// value that a builder rejects.
    #[error("{}{}: {message}", .path.display(), .location.map(|l| format!(":{l}")).unwrap_or_default())]
    At {
        /// The config file (for messages).
        path: PathBuf,
        /// Where in the resolved text, if known.
        location: Option<Location>,
        /// What is wrong, lowercase, "expected …, got …" where it fits.
        message: String,
    },
}

impl ConfigError {
    /// Line and column of the error in the resolved text, when known.
    pub fn location(&self) -> Option<Location> {
        match self {
            Self::Toml { location, .. } | Self::At { location, .. } => *location,
            Self::Read { .. } | Self::Override { .. } => None,
        }
    }
}

/// The `[run]` table at its defaults, commented, as `cpose config show` ends every task's
/// default config.
pub const RUN_TABLE_DEFAULTS: &str = "\
[run]                          # how to run, not what to compute (every task)
seed = 0                       # seeds every random draw of the run
threads = 2                    # size of the thread pool (1..=1024)
# out_dir = \"runs/my-run\"      # run folder (default: runs/<task>-<date>-<time>; --out wins)
iterations_scale = 1.0         # multiplies every step count; 0.01 makes a smoke test
# report_every = 500           # steps between live reports of loss and errors (task default)
checkpoint_secs = 60.0         # seconds between checkpoints (0: at every chance)
";

/// The shared `[run]` table: how to run, not what to compute.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RunConfig {
    /// Seed of every random number generator of the run.
    pub seed: u64,
    /// Size of the global rayon pool (see [`RunConfig::init_thread_pool`]); tests and CI use 1.
    pub threads: usize,
    /// Run folder; `cpose run --out` wins over it, and without either the run goes to
    /// `runs/<task>-<YYYYmmdd-HHMMSS>` in the current directory.
    pub out_dir: Option<PathBuf>,
    /// Multiplies every iteration count of the task ([`RunConfig::iterations`]); `0.01` turns a
    /// long experiment into a smoke test.
    pub iterations_scale: f64,
    /// Steps between two live reports of a unit (loss and key error into the log and
    /// `curves.csv`); each task has its own default.
    pub report_every: Option<usize>,
    /// Seconds between two checkpoints of a unit that keeps them (for `cpose run --resume`).
    pub checkpoint_secs: f64,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            threads: 2,
            out_dir: None,
            iterations_scale: 1.0,
            report_every: None,
            checkpoint_secs: 60.0,
        }
    }
}

impl RunConfig {
    /// The most threads a run may ask for (more is a typo, and would abort the process when
    /// the system refuses to start them).
    pub const MAX_THREADS: usize = 1024;

    /// The largest `iterations_scale` (a longer run is a typo: raise the task's own counts).
    pub const MAX_ITERATIONS_SCALE: f64 = 100.0;

    /// Errors name the key and the range it must lie in.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !(1..=Self::MAX_THREADS).contains(&self.threads) {
            return Err((
                "threads",
                format!(
                    "threads = {} must lie in 1..={}",
                    self.threads,
                    Self::MAX_THREADS
                ),
            ));
        }
        let scale = self.iterations_scale;
        if !(scale > 0.0 && scale <= Self::MAX_ITERATIONS_SCALE) {
            return Err((
                "iterations_scale",
                format!(
                    "iterations_scale = {scale} must be a number in (0, {}]",
                    Self::MAX_ITERATIONS_SCALE
                ),
            ));
        }
        if self.report_every == Some(0) {
            return Err(("report_every", "report_every must be at least 1".into()));
        }
        if !(self.checkpoint_secs.is_finite() && self.checkpoint_secs >= 0.0) {
            return Err((
                "checkpoint_secs",
                format!(
                    "checkpoint_secs = {} must be a finite number ≥ 0",
                    self.checkpoint_secs
                ),
            ));
        }
        Ok(())
    }

    /// `max(1, round(n · iterations_scale))` (0 stays 0): the number of iterations a loop
    /// configured for `n` runs.
    pub fn iterations(&self, n: usize) -> usize {
        if n == 0 {
            return 0;
        }
        ((n as f64 * self.iterations_scale).round() as usize).max(1)
    }

    /// Builds rayon's global pool with [`RunConfig::threads`] threads, each (and the calling
    /// thread) flushing denormal floats to zero ([`flush_denormals`]). Returns `false` when the
    /// pool already existed (it cannot be rebuilt; the first size wins).
    pub fn init_thread_pool(&self) -> bool {
        flush_denormals();
        rayon::ThreadPoolBuilder::new()
            .num_threads(self.threads)
            .start_handler(|_| flush_denormals())
            .build_global()
            .is_ok()
    }
}

/// Makes the calling thread treat denormal floats (below 1.2e-38 in `f32`) as zero, in results
/// and operands. On Intel CPUs each operation on one takes a microcode assist, about a hundred
/// times the cost, and Adam's second moments of near-zero gradients live there (PoseNet's output
/// layers start at `U(0, 1e-6)`): on EuRoC at 10 Hz, `prev_tight` tracked 0.91 frames a second on
/// one thread without this and 3.1 with it, to the same trajectory. x86-64 only (MXCSR's FTZ and
/// DAZ bits); elsewhere a no-op.
#[allow(unsafe_code)]
pub fn flush_denormals() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: reads and writes the calling thread's MXCSR only (FTZ bit 15, DAZ bit 6).
    unsafe {
        let mut csr: u32 = 0;
        std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr);
        csr |= 0x8040;
        std::arch::asm!("ldmxcsr [{}]", in(reg) &csr);
    }
}

/// The minimal view of a config: only `task` is read, other keys are ignored.
#[derive(Deserialize)]
struct Header {
    task: String,
}

/// A config's resolved text and the path it came from (used in messages).
#[derive(Clone, Debug)]
pub struct Config {
    path: PathBuf,
    text: String,
}

impl Config {
    /// A config from its text; `path` only names it in messages (it need not exist).
    pub fn from_text(path: impl Into<PathBuf>, text: impl Into<String>) -> Self {
        Self {
            path: path.into(),
            text: text.into(),
        }
    }

    /// Reads `path`, applies `overrides` (each `key.path=value`, see
    /// [`Config::with_overrides`]) and expands the variables of its strings from the environment
    /// ([`Config::with_variables`], [`environment_variable`]).
    pub fn load(path: &Path, overrides: &[impl AsRef<str>]) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Read {
            path: path.to_owned(),
            error,
        })?;
        Self::from_text(path, text)
            .with_overrides(overrides)?
            .with_variables(|name| environment_variable(name, path))
    }

    /// Replaces every `${NAME}` in the document's strings by `lookup(NAME)`, so that a config
    /// names its data wherever it is run from (`path = "${CPOSE_DATA_DIR}/llff/fern"`). The
    /// resolved text, which the run folder saves, holds the values, so a resume reads the same
    /// files. Errors name the key: a variable `lookup` does not know (its message says why) or a
    /// `${` without a name and a closing `}`.
    pub fn with_variables(
        self,
        lookup: impl Fn(&str) -> Result<String, String>,
    ) -> Result<Self, ConfigError> {
        if !self.text.contains("${") {
            return Ok(self);
        }
        let mut doc: DocumentMut = self.text.parse().map_err(|e: toml_edit::TomlError| {
            self.error_at(e.span().map(|s| s.start), e.to_string().trim_end())
        })?;
        let mut failure = None;
        expand_item(doc.as_item_mut(), "", &mut |key, text| {
            expand(text, &lookup).map_err(|message| {
                failure.get_or_insert_with(|| format!("{key}: {message}"));
            })
        });
        if let Some(message) = failure {
            return Err(ConfigError::At {
                path: self.path,
                location: None,
                message,
            });
        }
        Ok(Self {
            path: self.path,
            text: doc.to_string(),
        })
    }

    /// Applies `--set` overrides, each `key.path=value`, in order. The value is parsed as a
    /// TOML value (`3`, `0.5`, `true`, `[1, 2]`, `"text"`) and otherwise taken as a string
    /// (`kind=posenet`); missing tables on the dotted path are created. Keys are bare (no
    /// quoted keys containing dots). The document keeps its formatting and comments, and a
    /// replaced value keeps its trailing comment. Unknown keys are not rejected here: they
    /// fail later, when the task decodes the config, like a typo in the file.
    pub fn with_overrides(self, overrides: &[impl AsRef<str>]) -> Result<Self, ConfigError> {
        if overrides.is_empty() {
            return Ok(self);
        }
        let mut doc: DocumentMut =
            self.text
                .parse()
                .map_err(|e: toml_edit::TomlError| ConfigError::At {
                    path: self.path.clone(),
                    location: e.span().map(|s| Location::from_offset(&self.text, s.start)),
                    message: e.to_string().trim_end().to_owned(),
                })?;
        for arg in overrides {
            apply_override(&mut doc, arg.as_ref())?;
        }
        Ok(Self {
            path: self.path,
            text: doc.to_string(),
        })
    }

    /// The path that names the config in messages.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The resolved text (file plus overrides): what tasks decode and what the run folder saves.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The `task` key.
    pub fn task_name(&self) -> Result<String, ConfigError> {
        let Header { task } = toml::from_str(&self.text).map_err(|e| self.toml_error(e))?;
        Ok(task)
    }

    /// Line and column of the value of `task`, for messages about the task name.
    pub fn task_location(&self) -> Option<Location> {
        let root = DeTable::parse(&self.text).ok()?;
        let span = root.get_ref().get("task")?.span();
        Some(Location::from_offset(&self.text, span.start))
    }

    /// The `[run]` table, or its defaults when absent.
    /// Errors name the key: a typo, a wrong type or a value out of range
    /// ([`RunConfig::validate`]).
    pub fn run_config(&self) -> Result<RunConfig, ConfigError> {
        let section = self.section("run");
        if !section.exists()? {
            return Ok(RunConfig::default());
        }
        let run: RunConfig = section.decode()?;
        run.validate()
            .map_err(|(key, message)| self.section(&format!("run.{key}")).error(message))?;
        Ok(run)
    }

    /// Decodes the whole document into `T` (which then declares `task` and `run` itself, e.g.
    /// `task: String` and `#[serde(default)] run: RunConfig`).
    pub fn parse<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        toml::from_str(&self.text).map_err(|e| self.toml_error(e))
    }

    /// Decodes the document without its `task` key and `[run]` table into `T`, so a task's
    /// struct lists only its own tables. Tables that a registry decodes later (e.g. `[model]`)
    /// can be declared as [`serde::de::IgnoredAny`] so that `deny_unknown_fields` accepts them.
    pub fn parse_params<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        let mut root = DeTable::parse(&self.text).map_err(|e| self.toml_error(e))?;
        let span = root.span();
        let mut table = std::mem::take(root.get_mut());
        table.remove("task");
        table.remove("run");
        self.decode_value(toml::Spanned::new(span, DeValue::Table(table)))
    }

    /// The table at the dotted path `dotted` (e.g. `"model"` or `"scene.field"`), whether or
    /// not it exists; [`Section::decode`] reports a missing one.
    pub fn section(&self, dotted: &str) -> Section<'_> {
        Section {
            config: self,
            dotted: dotted.to_owned(),
        }
    }

    /// An error at byte offset `offset` of the resolved text.
    pub fn error_at(&self, offset: Option<usize>, message: impl Into<String>) -> ConfigError {
        ConfigError::At {
            path: self.path.clone(),
            location: offset.map(|o| Location::from_offset(&self.text, o)),
            message: message.into(),
        }
    }

    fn toml_error(&self, mut error: toml::de::Error) -> ConfigError {
        let location = error
            .span()
            .map(|s| Location::from_offset(&self.text, s.start));
        error.set_input(Some(&self.text));
        ConfigError::Toml {
            path: self.path.clone(),
            location,
            error: Box::new(error),
        }
    }

    /// Decodes a spanned value of this config's text, keeping the spans of errors.
    fn decode_value<T: DeserializeOwned>(
        &self,
        value: toml::Spanned<DeValue<'_>>,
    ) -> Result<T, ConfigError> {
        T::deserialize(ValueDeserializer::from(value)).map_err(|e| self.toml_error(e))
    }
}

/// The value of `${name}` in the config at `config_path`: `CONFIG_DIR` is the config file's
/// folder, made absolute; `CPOSE_DATA_DIR` the shared data folder, canonical
/// ([`crate::fs::shared_data_dir`]: the environment variable, else the folder `../shared/data`
/// beside the workspace cpose was built in); any other name an environment variable.
pub fn environment_variable(name: &str, config_path: &Path) -> Result<String, String> {
    let absolute = |dir: &Path| {
        std::path::absolute(dir)
            .map(|d| d.to_string_lossy().into_owned())
            .map_err(|e| format!("cannot make {} absolute: {e}", dir.display()))
    };
    match name {
        "CONFIG_DIR" => absolute(config_path.parent().unwrap_or(Path::new(""))),
        "CPOSE_DATA_DIR" => match crate::fs::shared_data_dir() {
            Some(dir) => std::fs::canonicalize(&dir)
                .map(|d| d.to_string_lossy().into_owned())
                .map_err(|e| format!("cannot resolve {}: {e}", dir.display())),
            None => Err(format!(
                "${{CPOSE_DATA_DIR}}: no shared data folder at {}; set the environment variable \
                 CPOSE_DATA_DIR to the folder that holds the data (see the README's set-up)",
                crate::fs::shared_data_candidate().display()
            )),
        },
        _ => std::env::var(name)
            .map_err(|_| format!("${{{name}}}: no environment variable {name} is set")),
    }
}

/// `text` with every `${NAME}` replaced by `lookup(NAME)`.
fn expand(text: &str, lookup: &impl Fn(&str) -> Result<String, String>) -> Result<String, String> {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(start) = rest.find("${") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let name = after
            .find('}')
            .map(|end| &after[..end])
            .filter(|n| {
                n.chars()
                    .next()
                    .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                    && n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            })
            .ok_or_else(|| format!("expected ${{NAME}} (letters, digits, _) in {text:?}"))?;
        out.push_str(&lookup(name)?);
        rest = &after[name.len() + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

/// Calls `f(dotted key, text)` on every string of `item` that holds `${`, replacing it by the
/// result (left as it is on an error, which `f` records).
fn expand_item(item: &mut Item, key: &str, f: &mut impl FnMut(&str, &str) -> Result<String, ()>) {
    match item {
        Item::Value(value) => expand_value(value, key, f),
        Item::Table(table) => {
            for (k, item) in table.iter_mut() {
                expand_item(item, &join_key(key, &k), f);
            }
        }
        Item::ArrayOfTables(tables) => {
            for (i, table) in tables.iter_mut().enumerate() {
                for (k, item) in table.iter_mut() {
                    expand_item(item, &join_key(&format!("{key}[{i}]"), &k), f);
                }
            }
        }
        Item::None => {}
    }
}

fn expand_value(
    value: &mut toml_edit::Value,
    key: &str,
    f: &mut impl FnMut(&str, &str) -> Result<String, ()>,
) {
    match value {
        toml_edit::Value::String(s) if s.value().contains("${") => {
            if let Ok(expanded) = f(key, s.value()) {
                let decor = s.decor().clone();
                *s = toml_edit::Formatted::new(expanded);
                *s.decor_mut() = decor;
            }
        }
        toml_edit::Value::Array(array) => {
            for (i, v) in array.iter_mut().enumerate() {
                expand_value(v, &format!("{key}[{i}]"), f);
            }
        }
        toml_edit::Value::InlineTable(table) => {
            for (k, v) in table.iter_mut() {
                expand_value(v, &join_key(key, &k), f);
            }
        }
        _ => {}
    }
}

fn join_key(parent: &str, key: &str) -> String {
    if parent.is_empty() {
        key.to_owned()
    } else {
        format!("{parent}.{key}")
    }
}

/// Applies one `key.path=value` override to `doc`.
fn apply_override(doc: &mut DocumentMut, arg: &str) -> Result<(), ConfigError> {
    let fail = |message: &str| ConfigError::Override {
        arg: arg.to_owned(),
        message: message.to_owned(),
    };
    let (key_path, raw) = arg
        .split_once('=')
        .ok_or_else(|| fail("expected key.path=value"))?;
    let keys: Vec<&str> = key_path.trim().split('.').map(str::trim).collect();
    if keys.iter().any(|k| k.is_empty()) {
        return Err(fail("expected a dotted key such as model.width"));
    }
    let (last, parents) = keys.split_last().ok_or_else(|| fail("empty key"))?;
    let mut value = match raw.trim().parse::<toml_edit::Value>() {
        Ok(v) => v,
        Err(_) => toml_edit::Value::from(raw.trim()),
    };
    value.decor_mut().clear();

    let mut table: &mut dyn TableLike = doc.as_table_mut();
    for key in parents {
        if !table.contains_key(key) {
            let mut new = toml_edit::Table::new();
            new.set_implicit(true);
            table.insert(key, Item::Table(new));
        }
        table = table
            .get_mut(key)
            .and_then(Item::as_table_like_mut)
            .ok_or_else(|| fail(&format!("{key:?} is not a table")))?;
    }
    if let Some(old) = table.get(last).and_then(Item::as_value) {
        *value.decor_mut() = old.decor().clone();
    }
    if table.get(last).is_some_and(|item| item.is_table_like()) {
        return Err(fail(&format!(
            "{last:?} is a table; set its keys one by one"
        )));
    }
    table.insert(last, Item::Value(value));
    Ok(())
}

/// One table of a config, by dotted path, decoded on demand with errors located in the file.
///
/// A registry reads the selecting key with [`Section::kind`] and hands the section to the chosen
/// builder, which decodes the remaining keys with [`Section::decode_params`] into its own
/// `deny_unknown_fields` struct.
#[derive(Clone, Debug)]
pub struct Section<'a> {
    config: &'a Config,
    dotted: String,
}

impl<'a> Section<'a> {
    /// The config the section belongs to.
    pub fn config(&self) -> &'a Config {
        self.config
    }

    /// The dotted path of the section (`"model"`).
    pub fn dotted_path(&self) -> &str {
        &self.dotted
    }

    /// Whether the table exists (an error only for a syntax error in the document).
    pub fn exists(&self) -> Result<bool, ConfigError> {
        Ok(self.find(&self.parse_root()?)?.is_some())
    }

    /// Decodes the whole table (including `kind`, if present) into `T`.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        let root = self.parse_root()?;
        let value = self.require(&root)?;
        self.config.decode_value(value)
    }

    /// Decodes the table without its `kind` key into `T`: what a registry's builder calls.
    pub fn decode_params<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        let root = self.parse_root()?;
        let value = self.require(&root)?;
        let span = value.span();
        match value.into_inner() {
            DeValue::Table(mut table) => {
                table.remove("kind");
                self.config
                    .decode_value(toml::Spanned::new(span, DeValue::Table(table)))
            }
            other => self.config.decode_value(toml::Spanned::new(span, other)),
        }
    }

    /// The `kind` string that selects a registry entry, and the byte offset of its value in the
    /// resolved text (for messages about an unknown kind).
    pub fn kind(&self) -> Result<(String, usize), ConfigError> {
        #[derive(Deserialize)]
        struct Kind {
            kind: toml::Spanned<String>,
        }
        let Kind { kind } = self.decode()?;
        Ok((kind.get_ref().clone(), kind.span().start))
    }

    /// An error located at the start of this section (its header, or its key in an inline table).
    pub fn error(&self, message: impl Into<String>) -> ConfigError {
        let offset = self
            .parse_root()
            .ok()
            .and_then(|root| self.find(&root).ok().flatten())
            .map(|v| v.span().start);
        self.config
            .error_at(offset, format!("[{}]: {}", self.dotted, message.into()))
    }

    fn parse_root(&self) -> Result<toml::Spanned<DeTable<'a>>, ConfigError> {
        DeTable::parse(&self.config.text).map_err(|e| self.config.toml_error(e))
    }

    /// The value at the dotted path, `None` if a key is missing; an error if a parent is not a
    /// table.
    fn find(
        &self,
        root: &toml::Spanned<DeTable<'a>>,
    ) -> Result<Option<toml::Spanned<DeValue<'a>>>, ConfigError> {
        let mut table = root.get_ref();
        let mut keys = self.dotted.split('.').peekable();
        while let Some(key) = keys.next() {
            let Some(value) = table.get(key) else {
                return Ok(None);
            };
            if keys.peek().is_none() {
                return Ok(Some(value.clone()));
            }
            table = match value.get_ref() {
                DeValue::Table(t) => t,
                other => {
                    return Err(self.config.error_at(
                        Some(value.span().start),
                        format!("expected a table at {key:?}, got a {}", other.type_str()),
                    ));
                }
            };
        }
        Ok(None)
    }

    fn require(
        &self,
        root: &toml::Spanned<DeTable<'a>>,
    ) -> Result<toml::Spanned<DeValue<'a>>, ConfigError> {
        self.find(root)?.ok_or_else(|| {
            self.config
                .error_at(None, format!("missing table [{}]", self.dotted))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn denormals_are_flushed_to_zero_on_x86_64() {
        let tiny = || std::hint::black_box(1e-30f32);
        let product = std::thread::spawn(move || {
            let before = std::hint::black_box(tiny() * 1e-10);
            flush_denormals();
            (before, std::hint::black_box(tiny() * 1e-10))
        })
        .join()
        .unwrap();
        assert!(
            product.0 > 0.0 && product.0 < f32::MIN_POSITIVE,
            "{product:?}"
        );
        if cfg!(target_arch = "x86_64") {
            assert_eq!(product.1, 0.0);
        }
    }
    use serde::de::IgnoredAny;

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Model {
        width: usize,
        #[serde(default)]
        depth: usize,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Experiment {
        task: String,
        #[serde(default)]
        run: RunConfig,
        model: KindModel,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct KindModel {
        kind: String,
        width: usize,
        #[serde(default)]
        depth: usize,
    }

    const TEXT: &str = "\
# an experiment
task = \"demo\"

[run]
seed = 7 # lucky

[model]
kind = \"posenet\"
width = 128
";

    #[test]
    fn task_name_ignores_other_keys() {
        let c = Config::from_text("x.toml", TEXT);
        assert_eq!(c.task_name().unwrap(), "demo");
        assert_eq!(c.task_location(), Some(Location { line: 2, column: 8 }));
        let e = Config::from_text("x.toml", "seed = 1\n")
            .task_name()
            .unwrap_err();
        assert!(e.to_string().starts_with("x.toml: "), "{e}");
        assert!(e.to_string().contains("missing field `task`"), "{e}");
    }

    #[test]
    fn run_config_values_out_of_range_name_their_line() {
        for (value, expect) in [
            ("threads = 0", "threads = 0 must lie in 1..=1024"),
            ("threads = 100000", "threads = 100000 must lie in 1..=1024"),
            (
                "iterations_scale = -1.0",
                "iterations_scale = -1 must be a number in (0, 100]",
            ),
            ("iterations_scale = nan", "iterations_scale = NaN must be"),
            ("iterations_scale = 0.0", "iterations_scale = 0 must be"),
            ("report_every = 0", "report_every must be at least 1"),
            ("checkpoint_secs = inf", "checkpoint_secs = inf must be"),
        ] {
            let text = format!("task = \"a\"\n[run]\nseed = 1\n{value}\n");
            let e = Config::from_text("x.toml", text).run_config().unwrap_err();
            assert_eq!(e.location().map(|l| l.line), Some(4), "{value}: {e}");
            assert!(e.to_string().contains(expect), "{value}: {e}");
        }
        let ok = "task = \"a\"\n[run]\nthreads = 1024\niterations_scale = 0.001\n";
        assert!(Config::from_text("x.toml", ok).run_config().is_ok());
    }

    #[test]
    fn run_config_defaults_and_typos() {
        let run = Config::from_text("x.toml", "task = \"a\"\n")
            .run_config()
            .unwrap();
        assert_eq!(run, RunConfig::default());
        assert_eq!(run.threads, 2);
        let run = Config::from_text("x.toml", TEXT).run_config().unwrap();
        assert_eq!(run.seed, 7);
        let e = Config::from_text("x.toml", "task = \"a\"\n[run]\nsed = 1\n")
            .run_config()
            .unwrap_err();
        assert_eq!(e.location(), Some(Location { line: 3, column: 1 }));
        let msg = e.to_string();
        assert!(msg.contains("unknown field `sed`"), "{msg}");
        assert!(
            msg.contains("seed") && msg.contains("iterations_scale"),
            "{msg}"
        );
    }

    #[test]
    fn iterations_scale_rounds_and_keeps_one() {
        let run = RunConfig {
            iterations_scale: 0.01,
            ..RunConfig::default()
        };
        assert_eq!(run.iterations(1000), 10);
        assert_eq!(run.iterations(10), 1);
        assert_eq!(run.iterations(0), 0);
    }

    #[test]
    fn typo_in_whole_document_has_path_line_column_and_valid_keys() {
        let text = TEXT.replace("width = 128", "widht = 128");
        let e = Config::from_text("configs/x.toml", text)
            .parse::<Experiment>()
            .unwrap_err();
        assert_eq!(e.location(), Some(Location { line: 9, column: 1 }));
        let msg = e.to_string();
        assert!(
            msg.starts_with("configs/x.toml: TOML parse error at line 9, column 1"),
            "{msg}"
        );
        assert!(msg.contains("unknown field `widht`, expected"), "{msg}");
        assert!(msg.contains("`kind`, `width`, `depth`"), "{msg}");
        assert!(msg.contains("9 | widht = 128"), "{msg}");
    }

    #[test]
    fn syntax_error_has_path_and_line() {
        let e = Config::from_text("configs/x.toml", "task = \"a\"\nseed = = 1\n")
            .task_name()
            .unwrap_err();
        assert_eq!(e.location().map(|l| l.line), Some(2));
        assert!(
            e.to_string()
                .starts_with("configs/x.toml: TOML parse error at line 2"),
            "{e}"
        );
    }

    #[test]
    fn parse_params_skips_task_and_run() {
        #[derive(Debug, Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Params {
            #[allow(dead_code)]
            model: IgnoredAny,
        }
        let c = Config::from_text("x.toml", TEXT);
        let _: Params = c.parse_params().unwrap();
        let c = Config::from_text("x.toml", format!("{TEXT}\n[extra]\na = 1\n"));
        let e = c.parse_params::<Params>().unwrap_err();
        assert_eq!(
            e.location(),
            Some(Location {
                line: 11,
                column: 2
            })
        );
        assert!(
            e.to_string()
                .contains("unknown field `extra`, expected `model`"),
            "{e}"
        );
    }

    #[test]
    fn section_typo_reports_line_column_and_valid_keys() {
        let text = TEXT.replace("width = 128", "width = 128\ndpeth = 3");
        let c = Config::from_text("configs/x.toml", text);
        let s = c.section("model");
        assert_eq!(s.kind().unwrap().0, "posenet");
        let e = s.decode_params::<Model>().unwrap_err();
        assert_eq!(
            e.location(),
            Some(Location {
                line: 10,
                column: 1
            })
        );
        let msg = e.to_string();
        assert!(
            msg.starts_with("configs/x.toml: TOML parse error at line 10, column 1"),
            "{msg}"
        );
        assert!(
            msg.contains("unknown field `dpeth`, expected `width` or `depth`"),
            "{msg}"
        );
        assert!(msg.contains("10 | dpeth = 3"), "{msg}");
    }

    #[test]
    fn nested_and_inline_sections_decode_with_spans() {
        let text = "task = \"a\"\n[scene]\nname = \"room\"\n[scene.field]\nkind = \"grid\"\nwidth = 4\n\
                    [other]\nmodel = { kind = \"posenet\", widht = 3 }\n";
        let c = Config::from_text("x.toml", text);
        assert_eq!(
            c.section("scene.field").decode_params::<Model>().unwrap(),
            Model { width: 4, depth: 0 }
        );
        let e = c
            .section("other.model")
            .decode_params::<Model>()
            .unwrap_err();
        assert_eq!(
            e.location(),
            Some(Location {
                line: 8,
                column: 29
            })
        );
        assert!(e.to_string().contains("unknown field `widht`"), "{e}");
        // A wrong type is located at the value.
        let c = Config::from_text("x.toml", "[model]\nwidth = \"wide\"\n");
        let e = c.section("model").decode_params::<Model>().unwrap_err();
        assert_eq!(e.location(), Some(Location { line: 2, column: 9 }));
    }

    #[test]
    fn missing_section_and_missing_kind_are_errors() {
        let c = Config::from_text("x.toml", "task = \"a\"\n[model]\nwidth = 1\n");
        assert!(!c.section("nope").exists().unwrap());
        let e = c.section("nope").decode::<Model>().unwrap_err();
        assert_eq!(e.to_string(), "x.toml: missing table [nope]");
        let e = c.section("model").kind().unwrap_err();
        assert!(e.to_string().contains("missing field `kind`"), "{e}");
        let e = c.section("task.x").exists().unwrap_err();
        assert!(
            e.to_string().contains("expected a table at \"task\""),
            "{e}"
        );
        assert_eq!(
            c.section("model").error("bad").to_string(),
            "x.toml:2:1: [model]: bad"
        );
    }

    #[test]
    fn overrides_edit_the_document_and_keep_comments() {
        let c = Config::from_text("x.toml", TEXT)
            .with_overrides(&[
                "run.seed=9",
                "model.width=64",
                "model.kind=spline",
                "run.out_dir=out/a b",
                "new.deep.x=[1, 2]",
            ])
            .unwrap();
        let text = c.text();
        assert!(text.starts_with("# an experiment\n"), "{text}");
        assert!(text.contains("seed = 9 # lucky"), "{text}");
        assert!(text.contains("width = 64"), "{text}");
        assert!(text.contains("kind = \"spline\""), "{text}");
        let run = c.run_config().unwrap();
        assert_eq!(run.seed, 9);
        assert_eq!(run.out_dir, Some(PathBuf::from("out/a b")));
        #[derive(Deserialize)]
        struct Deep {
            x: Vec<i64>,
        }
        assert_eq!(
            c.section("new.deep").decode::<Deep>().unwrap().x,
            vec![1, 2]
        );
    }

    #[test]
    fn override_of_unknown_key_fails_when_decoded() {
        let c = Config::from_text("x.toml", TEXT)
            .with_overrides(&["model.widht=3"])
            .unwrap();
        let e = c.parse::<Experiment>().unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("unknown field `widht`"), "{msg}");
        assert!(msg.contains("widht = 3"), "{msg}");
    }

    #[test]
    fn malformed_overrides_are_errors() {
        let c = || Config::from_text("x.toml", TEXT);
        for bad in ["noequals", "a..b=1", "=3", "task.x=1", "model=3"] {
            let e = c().with_overrides(&[bad]).unwrap_err();
            assert!(matches!(e, ConfigError::Override { .. }), "{bad}: {e}");
            assert!(e.to_string().starts_with("invalid override"), "{e}");
        }
    }

    #[test]
    fn load_reports_missing_file() {
        let e = Config::load(Path::new("/nonexistent/x.toml"), &[] as &[&str]).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("cannot read config /nonexistent/x.toml: "),
            "{e}"
        );
    }

    #[test]
    fn location_counts_characters() {
        assert_eq!(
            Location::from_offset("ab\nçd", 5),
            Location { line: 2, column: 2 }
        );
        assert_eq!(
            Location::from_offset("", 3),
            Location { line: 1, column: 1 }
        );
    }

    #[test]
    fn variables_expand_in_every_string_and_keep_the_layout() {
        let text = "task = \"a\"\n[data]\npath = \"${DATA}/fern\" # the images\nlist = [\"${DATA}\", 3]\n\
                    inline = { p = \"x${DATA}y\" }\nplain = \"$DATA {x}\"\n";
        let lookup = |name: &str| match name {
            "DATA" => Ok("/d".to_owned()),
            _ => Err(format!("no {name}")),
        };
        let c = Config::from_text("x.toml", text)
            .with_variables(lookup)
            .unwrap();
        assert_eq!(
            c.text(),
            "task = \"a\"\n[data]\npath = \"/d/fern\" # the images\nlist = [\"/d\", 3]\n\
             inline = { p = \"x/dy\" }\nplain = \"$DATA {x}\"\n"
        );
        // Without a variable the text is left alone, byte for byte.
        let plain = "task = \"a\"   # as written\n";
        let c = Config::from_text("x.toml", plain)
            .with_variables(lookup)
            .unwrap();
        assert_eq!(c.text(), plain);
        // An unknown or malformed variable names the key.
        let e = Config::from_text("x.toml", "[data]\npath = \"${NOPE}/a\"\n")
            .with_variables(lookup)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.toml") && e.contains("data.path: no NOPE"),
            "{e}"
        );
        for bad in ["${}", "${DATA", "${1A}", "${A-B}"] {
            let e = Config::from_text("x.toml", format!("[m]\nlist = [1, \"{bad}\"]\n"))
                .with_variables(lookup)
                .unwrap_err()
                .to_string();
            assert!(e.contains("m.list[1]: expected ${NAME}"), "{bad}: {e}");
        }
    }

    #[test]
    fn config_dir_is_the_config_files_absolute_folder() {
        let dir = environment_variable("CONFIG_DIR", Path::new("configs/x.toml")).unwrap();
        assert!(
            Path::new(&dir).is_absolute() && dir.ends_with("configs"),
            "{dir}"
        );
        let e =
            environment_variable("CPOSE_SURELY_UNSET_VARIABLE", Path::new("x.toml")).unwrap_err();
        assert!(
            e.contains("no environment variable CPOSE_SURELY_UNSET_VARIABLE"),
            "{e}"
        );
    }
}
