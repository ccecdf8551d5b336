//! The run folder: everything one run writes, each file written atomically.
//!
//! Layout: `config.toml` (the resolved config), `metrics.json`, trajectories (TUM format), PNGs,
//! `log.txt` and `provenance.json` (see [`crate::provenance`]).
//!
//! Where it goes: the folder given explicitly (`cpose run --out DIR`), else `[run] out_dir`, else
//! `runs/<task>-<YYYYmmdd-HHMMSS>` (UTC) in the current directory; missing parents are created.
//! An explicit or configured folder must be missing or empty, so a run never mixes its files with
//! another's by accident: `cpose run --resume` keeps an interrupted run's files
//! ([`Existing::Keep`]), `cpose run --force` first clears an earlier run's folder
//! ([`Existing::Replace`]; a folder that holds no run is never cleared, and symbolic links in it
//! are removed, not followed). `[run] out_dir` must stay below the working folder (no absolute
//! path, no `..`); only `--out` may point elsewhere. A default folder that already exists (two
//! runs in the same second) gets a `-2`, `-3`, … suffix instead.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use thiserror::Error;

use crate::config::Config;
use crate::fs::write_atomic;

/// Errors of the run folder.
#[derive(Debug, Error)]
pub enum RunDirError {
    /// The folder exists and holds files, and reuse was not allowed.
    #[error("run folder is not empty (pass --force to replace the earlier run in it): {}", .path.display())]
    NotEmpty {
        /// The folder.
        path: PathBuf,
    },
    /// `--force` on a non-empty folder that holds no earlier run.
    #[error("not a run folder (no provenance.json or config.toml), so --force does not clear it; choose another --out: {}", .path.display())]
    NotARun {
        /// The folder.
        path: PathBuf,
    },
    /// `[run] out_dir` that leaves the working folder.
    #[error("[run] out_dir must stay below the working folder (no absolute path, no `..`), got {}; pass --out to write elsewhere", .path.display())]
    OutsideWorkingFolder {
        /// The configured folder.
        path: PathBuf,
    },
    /// An I/O error on a file or folder.
    #[error("{what} {}: {error}", .path.display())]
    Io {
        /// What was being done ("creating run folder", "writing").
        what: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// A value could not be serialised to JSON.
    #[error("serialising {}: {error}", .path.display())]
    Json {
        /// The file it was meant for.
        path: PathBuf,
        /// serde_json's error.
        error: serde_json::Error,
    },
}

/// Where a run folder should go; see the module docs for the rules.
#[derive(Clone, Debug, Default)]
pub struct RunDirOptions {
    /// `--out DIR`, which wins over the config.
    pub out: Option<PathBuf>,
    /// `[run] out_dir` of the config.
    pub config_out_dir: Option<PathBuf>,
    /// What to do with a non-empty explicit folder.
    pub existing: Existing,
    /// Echo log lines to stderr as well as to `log.txt`.
    pub echo_log: bool,
}

/// What [`RunDir::create`] does with an explicit folder that already holds files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Existing {
    /// Refuse it ([`RunDirError::NotEmpty`]).
    #[default]
    Refuse,
    /// Keep its files (resuming the run in it).
    Keep,
    /// Clear it first if it holds an earlier run (`provenance.json` or `config.toml`), else
    /// refuse ([`RunDirError::NotARun`]).
    Replace,
}

/// An open run folder.
#[derive(Debug)]
pub struct RunDir {
    path: PathBuf,
    started: Instant,
    echo_log: bool,
    log: Mutex<Option<std::fs::File>>,
}

impl RunDir {
    /// Creates (or, if allowed, reuses) the run folder for `task`.
    pub fn create(task: &str, options: &RunDirOptions) -> Result<Self, RunDirError> {
        if let (None, Some(dir)) = (&options.out, &options.config_out_dir) {
            let escapes = dir.components().any(|c| {
                !matches!(
                    c,
                    std::path::Component::Normal(_) | std::path::Component::CurDir
                )
            });
            if escapes {
                return Err(RunDirError::OutsideWorkingFolder { path: dir.clone() });
            }
        }
        let explicit = options.out.as_ref().or(options.config_out_dir.as_ref());
        let path = match explicit {
            Some(dir) => {
                if is_non_empty_dir(dir) {
                    match options.existing {
                        Existing::Refuse => {
                            return Err(RunDirError::NotEmpty { path: dir.clone() });
                        }
                        Existing::Keep => {}
                        Existing::Replace => clear_run_folder(dir)?,
                    }
                }
                dir.clone()
            }
            None => default_path(Path::new("runs"), task, SystemTime::now()),
        };
        std::fs::create_dir_all(&path).map_err(|error| RunDirError::Io {
            what: "creating run folder",
            path: path.clone(),
            error,
        })?;
        Ok(Self {
            path,
            started: Instant::now(),
            echo_log: options.echo_log,
            log: Mutex::new(None),
        })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The path of `name` inside the folder.
    pub fn file(&self, name: impl AsRef<Path>) -> PathBuf {
        self.path.join(name)
    }

    /// Writes `bytes` to `name` atomically (creating sub-folders of the run folder as needed).
    pub fn write(&self, name: impl AsRef<Path>, bytes: &[u8]) -> Result<PathBuf, RunDirError> {
        let path = self.file(name);
        let io = |error| RunDirError::Io {
            what: "writing",
            path: path.clone(),
            error,
        };
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        write_atomic(&path, bytes).map_err(io)?;
        Ok(path)
    }

    /// Writes `value` as pretty JSON (e.g. `metrics.json`).
    pub fn write_json<T: serde::Serialize + ?Sized>(
        &self,
        name: impl AsRef<Path>,
        value: &T,
    ) -> Result<PathBuf, RunDirError> {
        let mut bytes = serde_json::to_vec_pretty(value).map_err(|error| RunDirError::Json {
            path: self.file(name.as_ref()),
            error,
        })?;
        bytes.push(b'\n');
        self.write(name, &bytes)
    }

    /// Writes the resolved config as `config.toml`.
    pub fn write_config(&self, config: &Config) -> Result<PathBuf, RunDirError> {
        self.write("config.toml", config.text().as_bytes())
    }

    /// Appends `<UTC time> [<seconds since start>] message` to `log.txt` and, if enabled, echoes
    /// the line to stderr. Logging never fails a run: I/O errors on the log are ignored.
    pub fn log(&self, message: impl std::fmt::Display) {
        self.append_log(message, self.echo_log);
    }

    /// Appends to `log.txt` only, never echoing: for a message the caller prints itself (the
    /// error that ends a run).
    pub fn log_file_only(&self, message: impl std::fmt::Display) {
        self.append_log(message, false);
    }

    fn append_log(&self, message: impl std::fmt::Display, echo: bool) {
        let line = format!(
            "{} [{:>8.3} s] {message}",
            utc_iso(SystemTime::now()),
            self.started.elapsed().as_secs_f64()
        );
        if echo {
            crate::progress::eprint_line(&line);
        }
        let Ok(mut guard) = self.log.lock() else {
            return;
        };
        if guard.is_none() {
            *guard = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(self.file("log.txt"))
                .ok();
        }
        if let Some(file) = guard.as_mut() {
            let _ = writeln!(file, "{line}");
        }
    }
}

/// `<runs>/<task>-<YYYYmmdd-HHMMSS>`, with `-2`, `-3`, … appended while that exists.
fn default_path(runs: &Path, task: &str, now: SystemTime) -> PathBuf {
    let base = runs.join(format!("{task}-{}", utc_compact(now)));
    let mut path = base.clone();
    let mut n = 2;
    while path.exists() {
        let mut name = base.clone().into_os_string();
        name.push(format!("-{n}"));
        path = PathBuf::from(name);
        n += 1;
    }
    path
}

fn is_non_empty_dir(path: &Path) -> bool {
    std::fs::read_dir(path).is_ok_and(|mut entries| entries.next().is_some())
}

/// UTC calendar date and time of `t`: (year, month, day, hour, minute, second, millisecond).
fn utc_parts(t: SystemTime) -> (i64, u32, u32, u32, u32, u32, u32) {
    let since = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = since.as_secs() as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400) as u32);
    // Civil date from days since 1970-01-01 in the proleptic Gregorian calendar, counting in
    // 400-year eras that start on 0000-03-01 (so the leap day is the last day of a year).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let day_of_era = z.rem_euclid(146_097);
    let year_of_era =
        (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
    let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
    let month_from_march = (5 * day_of_year + 2) / 153;
    let day = (day_of_year - (153 * month_from_march + 2) / 5 + 1) as u32;
    let month = if month_from_march < 10 {
        month_from_march + 3
    } else {
        month_from_march - 9
    } as u32;
    let year = year_of_era + era * 400 + i64::from(month <= 2);
    (
        year,
        month,
        day,
        rem / 3600,
        rem / 60 % 60,
        rem % 60,
        since.subsec_millis(),
    )
}

/// `YYYYmmdd-HHMMSS` in UTC, for folder names.
fn utc_compact(t: SystemTime) -> String {
    let (y, mo, d, h, mi, s, _) = utc_parts(t);
    format!("{y:04}{mo:02}{d:02}-{h:02}{mi:02}{s:02}")
}

/// Removes everything in `dir`, an earlier run's folder; symbolic links are removed, never
/// followed.
fn clear_run_folder(dir: &Path) -> Result<(), RunDirError> {
    if !dir.join("provenance.json").is_file() && !dir.join("config.toml").is_file() {
        return Err(RunDirError::NotARun {
            path: dir.to_path_buf(),
        });
    }
    let io = |path: &Path, error| RunDirError::Io {
        what: "clearing the earlier run",
        path: path.to_path_buf(),
        error,
    };
    for entry in std::fs::read_dir(dir).map_err(|e| io(dir, e))? {
        let path = entry.map_err(|e| io(dir, e))?.path();
        // `symlink_metadata` does not follow a link; `remove_dir_all` does not follow links
        // inside the folders it removes.
        let is_dir = std::fs::symlink_metadata(&path)
            .map_err(|e| io(&path, e))?
            .is_dir();
        let removed = if is_dir {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed.map_err(|e| io(&path, e))?;
    }
    Ok(())
}

/// `YYYY-mm-ddTHH:MM:SS.mmmZ`, for log lines.
pub(crate) fn utc_iso(t: SystemTime) -> String {
    let (y, mo, d, h, mi, s, ms) = utc_parts(t);
    format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}.{ms:03}Z")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("cpose-rundir-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn dates_match_known_values() {
        let at = |secs| UNIX_EPOCH + Duration::from_secs(secs);
        assert_eq!(utc_compact(at(0)), "19700101-000000");
        // 2000-02-29 12:34:56 UTC (a leap day in a century leap year), from `date -u -d @951827696`.
        assert_eq!(utc_compact(at(951_827_696)), "20000229-123456");
        // 2026-11-23 03:15:35 UTC.
        assert_eq!(
            utc_iso(at(1_795_403_735) + Duration::from_millis(7)),
            "2026-11-23T03:15:35.007Z"
        );
        assert_eq!(utc_compact(at(4_107_542_400)), "21000301-000000");
    }

    #[test]
    fn writes_files_atomically_and_logs() {
        let dir = temp("write");
        let run = RunDir::create(
            "demo",
            &RunDirOptions {
                out: Some(dir.join("a/b")),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(run.path(), dir.join("a/b"));
        run.write_config(&Config::from_text("x.toml", "task = \"demo\"\n"))
            .unwrap();
        run.write_json(
            "metrics.json",
            &serde_json::json!({ "posenet": { "ate_rmse_cm": 1.5 } }),
        )
        .unwrap();
        run.write("plots/x.png", b"png").unwrap();
        run.log("hello");
        run.log("world");
        assert_eq!(
            std::fs::read_to_string(run.file("config.toml")).unwrap(),
            "task = \"demo\"\n"
        );
        let metrics: serde_json::Value =
            serde_json::from_slice(&std::fs::read(run.file("metrics.json")).unwrap()).unwrap();
        assert_eq!(metrics["posenet"]["ate_rmse_cm"], 1.5);
        assert!(run.file("plots/x.png").exists());
        let log = std::fs::read_to_string(run.file("log.txt")).unwrap();
        let lines: Vec<_> = log.lines().collect();
        assert_eq!(lines.len(), 2);
        assert!(
            lines[0].ends_with("hello") && lines[0].contains("Z ["),
            "{log}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn default_folder_is_named_by_task_and_time_and_never_reused() {
        let runs = temp("default");
        let now = UNIX_EPOCH + Duration::from_secs(951_827_696);
        let first = default_path(&runs, "nerf", now);
        assert_eq!(first, runs.join("nerf-20000229-123456"));
        std::fs::create_dir_all(&first).unwrap();
        assert_eq!(
            default_path(&runs, "nerf", now),
            runs.join("nerf-20000229-123456-2")
        );
        std::fs::remove_dir_all(&runs).unwrap();
    }

    #[test]
    fn refuses_non_empty_folder_keeps_it_to_resume_and_clears_only_a_run_with_force() {
        let dir = temp("reuse");
        std::fs::create_dir_all(&dir).unwrap();
        // Empty: fine.
        RunDir::create(
            "demo",
            &RunDirOptions {
                out: Some(dir.clone()),
                ..Default::default()
            },
        )
        .unwrap();
        std::fs::write(dir.join("old.txt"), "x").unwrap();
        let e = RunDir::create(
            "demo",
            &RunDirOptions {
                out: Some(dir.clone()),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(matches!(e, RunDirError::NotEmpty { .. }), "{e}");
        assert!(e.to_string().contains("--force"), "{e}");
        // --force clears only an earlier run's folder.
        let replace = RunDirOptions {
            out: Some(dir.clone()),
            existing: Existing::Replace,
            ..Default::default()
        };
        let e = RunDir::create("demo", &replace).unwrap_err();
        assert!(matches!(e, RunDirError::NotARun { .. }), "{e}");
        assert!(dir.join("old.txt").exists());
        let keep = RunDirOptions {
            out: Some(dir.clone()),
            existing: Existing::Keep,
            ..Default::default()
        };
        RunDir::create("demo", &keep).unwrap();
        assert!(dir.join("old.txt").exists());
        std::fs::write(dir.join("provenance.json"), "{}").unwrap();
        #[cfg(unix)]
        {
            // A planted link is removed, its target left alone.
            let outside = temp("outside");
            std::fs::create_dir_all(&outside).unwrap();
            std::fs::write(outside.join("keep.txt"), "mine").unwrap();
            std::os::unix::fs::symlink(&outside, dir.join("link")).unwrap();
            std::os::unix::fs::symlink(outside.join("keep.txt"), dir.join("metrics.json")).unwrap();
            RunDir::create("demo", &replace).unwrap();
            assert_eq!(
                std::fs::read_to_string(outside.join("keep.txt")).unwrap(),
                "mine"
            );
            std::fs::remove_dir_all(&outside).unwrap();
        }
        #[cfg(not(unix))]
        RunDir::create("demo", &replace).unwrap();
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            0,
            "stale files are gone"
        );
        // [run] out_dir stays below the working folder; --out may go anywhere.
        let absolute = std::env::temp_dir().join("x");
        for outside in [Path::new("../x"), &absolute, Path::new("a/../../x")] {
            let options = RunDirOptions {
                config_out_dir: Some(outside.to_path_buf()),
                ..Default::default()
            };
            let e = RunDir::create("demo", &options).unwrap_err();
            assert!(matches!(e, RunDirError::OutsideWorkingFolder { .. }), "{e}");
        }
        // --out wins over [run] out_dir.
        let other = dir.join("other");
        let options = RunDirOptions {
            out: Some(other.clone()),
            config_out_dir: Some(dir.clone()),
            ..Default::default()
        };
        assert_eq!(RunDir::create("demo", &options).unwrap().path(), other);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
