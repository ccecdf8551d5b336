//! The `cpose` command line as a library, so that a program can register its own tasks or pose
//! fields (with `inventory::submit!`) and run the same CLI:
//!
//! ```no_run
//! fn main() -> std::process::ExitCode {
//!     cpose_cli::main_with_args(std::env::args_os())
//! }
//! ```
//!
//! No algorithms live here: commands parse arguments, load the config, look the task up in the
//! registry, create the run folder and call the task. Errors are printed once, as
//! `cpose: <error with context>`; the exit code is 2 for usage and config errors and 1 when a
//! run fails.

// Name every application crate so that rustc links it and its registrations are visible, also
// in programs that only call `main_with_args`.
use cpose_events as _;
use cpose_imu as _;
use cpose_nerf as _;
use cpose_slam as _;

use std::ffi::OsString;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use cpose_core::Config;
use cpose_core::eval::{self, Alignment, RpeDelta, Trajectory, TrajectoryFormat};
use cpose_core::fs::write_atomic;
use cpose_core::plot;
use cpose_core::pose_field::saved::SavedPoseField;
use cpose_core::provenance::{Build, Recorder, Session};
use cpose_core::registry::{self, TaskInput};
use cpose_core::run_dir::{Existing, RunDir, RunDirOptions};
use cpose_core::study;
use nalgebra::Isometry3;

mod table;

/// The git commit this binary was built from (40 hex digits), empty when unknown.
const GIT_COMMIT: &str = env!("CPOSE_GIT_COMMIT");
/// `true` or `false`: whether the build had uncommitted changes; empty when unknown.
const GIT_DIRTY: &str = env!("CPOSE_GIT_DIRTY");

/// The version and git commit of this build, for `provenance.json`.
pub fn build_info() -> Build {
    Build {
        version: env!("CARGO_PKG_VERSION").to_owned(),
        commit: (!GIT_COMMIT.is_empty()).then(|| GIT_COMMIT.to_owned()),
        dirty: match GIT_DIRTY {
            "true" => Some(true),
            "false" => Some(false),
            _ => None,
        },
    }
}

/// Continuous camera poses: run experiments, list tasks and pose fields.
#[derive(Debug, Parser)]
#[command(name = "cpose", version, long_version = env!("CPOSE_LONG_VERSION"))]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// List the registered tasks and pose fields.
    List,
    /// Run the experiment described by a config file.
    Run(RunArgs),
    /// Print a task's default config, or check a config without running it.
    #[command(subcommand)]
    Config(ConfigCommand),
    /// Evaluate trajectories.
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Print the metrics of run folders side by side as a Markdown table.
    Table(TableArgs),
    /// Convert a trajectory file between the TUM, EuRoC csv and KITTI formats.
    Convert(ConvertArgs),
    /// Poses (and velocities) of a saved pose field, a run's `field_*.safetensors`, at any times.
    Query(QueryArgs),
    /// Print the completion script of a shell, e.g. `cpose completions bash > cpose.bash`.
    Completions {
        /// The shell: bash, elvish, fish, powershell or zsh.
        shell: clap_complete::Shell,
    },
}

#[derive(Debug, Subcommand)]
enum ConfigCommand {
    /// Print the task's complete default config, every key commented; it runs as it is
    /// (`cpose config show nerf > my.toml && cpose run my.toml`).
    Show {
        /// The task, as `cpose list` names it.
        task: String,
    },
    /// Decode and check every table and value of a config, as `cpose run` does before it
    /// starts, without reading data or writing anything.
    Check {
        /// The config file.
        config: PathBuf,
        /// Override a config value, as `cpose run --set KEY=VALUE`. Repeatable.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
    },
}

#[derive(Debug, clap::Args)]
struct ConvertArgs {
    /// The trajectory to read.
    input: PathBuf,
    /// The file to write (never replaced without --force).
    output: PathBuf,
    /// Format of INPUT: tum, euroc or kitti (default: detected).
    #[arg(long, value_name = "FORMAT")]
    from: Option<TrajectoryFormat>,
    /// Format of OUTPUT (default: euroc for a `.csv` name, else tum).
    #[arg(long, value_name = "FORMAT")]
    to: Option<TrajectoryFormat>,
    /// Times file of a KITTI INPUT (one time in seconds per line, KITTI's times.txt).
    #[arg(long, value_name = "FILE")]
    times: Option<PathBuf>,
    /// Where a KITTI OUTPUT's times go (KITTI pose files have none; without it they are lost).
    #[arg(long, value_name = "FILE")]
    out_times: Option<PathBuf>,
    /// Replace OUTPUT (and --out-times) if they exist.
    #[arg(long)]
    force: bool,
}

#[derive(Debug, clap::Args)]
struct QueryArgs {
    /// The saved field (`field_<condition>_<method>.safetensors`), or a run folder holding one.
    field: PathBuf,
    /// Times to sample, seconds, comma-separated (inside the field's time range).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "SECS",
        required_unless_present = "rate"
    )]
    times: Vec<f64>,
    /// Sample the field's whole time range at this rate instead, Hz.
    #[arg(long, value_name = "HZ", conflicts_with = "times")]
    rate: Option<f64>,
    /// Print velocities too, as CSV: `t,tx,ty,tz,qx,qy,qz,qw,wx,wy,wz,vx,vy,vz` (the body's
    /// angular velocity in rad/s, the linear velocity in the world in m/s).
    #[arg(long, conflicts_with = "format")]
    derivatives: bool,
    /// Format of the poses: tum, euroc or kitti (default: tum).
    #[arg(long, value_name = "FORMAT")]
    format: Option<TrajectoryFormat>,
    /// Write to FILE instead of stdout (never replaced without --force).
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Replace --out if it exists.
    #[arg(long, requires = "out")]
    force: bool,
}

/// The most samples `cpose query --rate` writes.
const MAX_QUERY_SAMPLES: f64 = 1e7;

/// How the two trajectories of `cpose eval` are read.
#[derive(Debug, clap::Args)]
struct TrajectoryInputs {
    /// Reference trajectory: TUM (`timestamp tx ty tz qx qy qz qw`), EuRoC csv or KITTI.
    gt: PathBuf,
    /// Estimated trajectory, in any of the same formats.
    est: PathBuf,
    /// Format of both files: tum, euroc or kitti (default: detected for each file).
    #[arg(long, value_name = "FORMAT")]
    format: Option<TrajectoryFormat>,
    /// Times file of a KITTI reference (one time in seconds per line).
    #[arg(long, value_name = "FILE")]
    gt_times: Option<PathBuf>,
    /// Times file of a KITTI estimate.
    #[arg(long, value_name = "FILE")]
    est_times: Option<PathBuf>,
    /// Largest timestamp difference of an associated pose pair, seconds (evo's default 0.01).
    #[arg(long, default_value_t = 0.01, value_name = "SECS")]
    max_diff: f64,
    /// Print the full report as JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Also draw plots into DIR (created; existing plots of the same names are refused), as
    /// evo's `--plot`: the aligned estimate against the reference, and the errors over time.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
}

impl TrajectoryInputs {
    /// Both trajectories, read; errors name the file. A bad `--max-diff` is refused first.
    fn read(&self) -> Result<(Trajectory, Trajectory), Failure> {
        if !(self.max_diff.is_finite() && self.max_diff >= 0.0) {
            return Err(Failure::Usage(anyhow::anyhow!(
                "--max-diff {}: expected a finite, non-negative time in seconds",
                self.max_diff
            )));
        }
        let read = |path: &Path, times: &Option<PathBuf>| {
            read_trajectory(path, self.format, times.as_deref())
        };
        Ok((
            read(&self.gt, &self.gt_times)?,
            read(&self.est, &self.est_times)?,
        ))
    }

    /// The paths of `names` in the `--plot` folder (created), refusing ones that exist.
    fn plot_files(&self, names: &[&str]) -> Result<Option<Vec<PathBuf>>, Failure> {
        let Some(dir) = &self.plot else {
            return Ok(None);
        };
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the plot folder {}", dir.display()))
            .map_err(Failure::Usage)?;
        let files: Vec<PathBuf> = names.iter().map(|n| dir.join(n)).collect();
        if let Some(taken) = files.iter().find(|f| f.exists()) {
            return Err(Failure::Usage(anyhow::anyhow!(
                "{} exists; choose another --plot folder",
                taken.display()
            )));
        }
        Ok(Some(files))
    }

    fn context(&self) -> String {
        format!(
            "comparing {} with {}",
            self.est.display(),
            self.gt.display()
        )
    }
}

#[derive(Debug, clap::Args)]
struct TableArgs {
    /// Run folders, each with a `metrics.json`.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Only these metrics, in this order (comma-separated), e.g. `rot_err_deg,psnr_db`.
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    metrics: Vec<String>,
}

#[derive(Debug, Subcommand)]
enum EvalCommand {
    /// Absolute trajectory error of the translation part, as `evo_ape tum GT EST [-a|-as]`.
    Ate(AteArgs),
    /// Relative pose error, as `evo_rpe tum GT EST --delta D --delta_unit f|m [-a|-as]`.
    Rpe(RpeArgs),
}

#[derive(Debug, clap::Args)]
struct AteArgs {
    #[command(flatten)]
    inputs: TrajectoryInputs,
    /// Alignment of the estimate before the error: `se3` (evo `-a`), `sim3` (evo `-as`) or `none`.
    #[arg(long, default_value = "se3")]
    align: Alignment,
}

#[derive(Debug, clap::Args)]
struct RpeArgs {
    #[command(flatten)]
    inputs: TrajectoryInputs,
    /// The step between the two poses of a pair, in --delta-unit.
    #[arg(long, default_value_t = 1.0, value_name = "D")]
    delta: f64,
    /// The unit of --delta: `f` (frames) or `m` (metres travelled), as evo's `--delta_unit`.
    #[arg(long, default_value = "f", value_parser = ["f", "m"])]
    delta_unit: String,
    /// Alignment of the estimate first: `none` (evo's default), `se3` or `sim3`.
    #[arg(long, default_value = "none")]
    align: Alignment,
}

#[derive(Debug, clap::Args)]
struct RunArgs {
    /// The config file (TOML: `task = "…"`, an optional `[run]` table, the task's tables).
    #[arg(required_unless_present = "resume")]
    config: Option<PathBuf>,
    /// Continue the interrupted run in DIR from its checkpoints, with its resolved
    /// `config.toml` (tasks without checkpoints run again from the start).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["config", "overrides", "out"])]
    resume: Option<PathBuf>,
    /// Override a config value, e.g. `--set run.seed=3 --set model.width=64` (the value is
    /// read as TOML, else as a string). Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Run folder (default: `[run] out_dir`, else `runs/<task>-<YYYYmmdd-HHMMSS>`).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Replace the earlier run in a non-empty run folder (its files are removed first; a
    /// folder that holds no run is never cleared).
    #[arg(long)]
    force: bool,
    /// Do not echo the log to stderr and draw no progress bars.
    #[arg(long, short)]
    quiet: bool,
}

/// Why a command failed; decides the exit code.
enum Failure {
    /// Bad arguments or a bad config: exit code 2.
    Usage(anyhow::Error),
    /// The task failed while running: exit code 1.
    Run(anyhow::Error),
}

/// Runs the CLI on `args` (the first one is the program name) and returns the exit code.
pub fn main_with_args<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args: Vec<OsString> = args.into_iter().map(Into::into).collect();
    let command_line: Vec<String> = args
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(err) => {
            // Help and version go to stdout with exit code 0; usage errors to stderr with 2.
            let _ = err.print();
            return ExitCode::from(u8::try_from(err.exit_code()).unwrap_or(2));
        }
    };
    let result = match cli.command {
        Command::List => list(),
        Command::Run(args) => run(&args, command_line),
        Command::Config(ConfigCommand::Show { task }) => config_show(&task),
        Command::Config(ConfigCommand::Check { config, overrides }) => {
            config_check(&config, &overrides)
        }
        Command::Eval(EvalCommand::Ate(args)) => eval_ate(&args),
        Command::Eval(EvalCommand::Rpe(args)) => eval_rpe(&args),
        Command::Convert(args) => convert(&args),
        Command::Query(args) => query(&args),
        Command::Completions { shell } => {
            let mut command = <Cli as clap::CommandFactory>::command();
            clap_complete::generate(shell, &mut command, "cpose", &mut std::io::stdout());
            Ok(())
        }
        Command::Table(args) => table::metrics_table(&args.runs, &args.metrics)
            .map(|text| {
                let _ = std::io::stdout().lock().write_all(text.as_bytes());
            })
            .map_err(Failure::Usage),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Usage(err)) => {
            eprintln!("cpose: {err:#}");
            ExitCode::from(2)
        }
        Err(Failure::Run(err)) => {
            eprintln!("cpose: {err:#}");
            ExitCode::from(1)
        }
    }
}

/// `cpose list`: tasks, then pose fields, each sorted by name with its one-line description.
fn list() -> Result<(), Failure> {
    registry::check_unique().map_err(|e| Failure::Run(e.into()))?;
    let tasks: Vec<_> = registry::tasks()
        .into_iter()
        .map(|t| (t.name, t.about))
        .collect();
    let fields: Vec<_> = registry::pose_fields()
        .into_iter()
        .map(|f| (f.name, f.about))
        .collect();
    let width = tasks
        .iter()
        .chain(&fields)
        .map(|(name, _)| name.len())
        .max()
        .unwrap_or(0);
    let mut text = String::new();
    for (title, entries) in [("tasks", &tasks), ("pose fields", &fields)] {
        text.push_str(title);
        text.push_str(":\n");
        if entries.is_empty() {
            text.push_str("  (none)\n");
        }
        for (name, about) in entries.iter() {
            text.push_str(&format!("  {name:<width$}  {about}\n"));
        }
    }
    // A closed pipe (`cpose list | head -1`) is not an error worth reporting.
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
    Ok(())
}

/// `cpose config show TASK`: the task's default config, to stdout.
fn config_show(name: &str) -> Result<(), Failure> {
    let task = registry::find_task(name).map_err(|e| Failure::Usage(e.into()))?;
    let text = format!(
        "{}\n{}",
        (task.default_config)(),
        cpose_core::config::RUN_TABLE_DEFAULTS
    );
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
    Ok(())
}

/// `cpose config check CONFIG`: load, look up the task, let it check every value.
fn config_check(path: &Path, overrides: &[String]) -> Result<(), Failure> {
    let usage = |e: anyhow::Error| Failure::Usage(e);
    let config = Config::load(path, overrides).map_err(|e| usage(e.into()))?;
    let run_config = config.run_config().map_err(|e| usage(e.into()))?;
    let task = registry::task_for(&config).map_err(|e| usage(e.into()))?;
    (task.check)(&config, &run_config).map_err(usage)?;
    let _ = writeln!(
        std::io::stdout().lock(),
        "{}: a valid {} config",
        path.display(),
        task.name
    );
    Ok(())
}

/// `cpose run CONFIG`: load, look up, check, create the run folder, record the provenance, save the
/// config, run, report.
fn run(args: &RunArgs, command_line: Vec<String>) -> Result<(), Failure> {
    registry::check_unique().map_err(|e| Failure::Run(e.into()))?;
    let usage = |e: anyhow::Error| Failure::Usage(e);
    let (config_path, out, existing) = match (&args.resume, &args.config) {
        (Some(dir), _) => (dir.join("config.toml"), Some(dir.clone()), Existing::Keep),
        (None, Some(config)) => (
            config.clone(),
            args.out.clone(),
            if args.force {
                Existing::Replace
            } else {
                Existing::Refuse
            },
        ),
        (None, None) => unreachable!("clap requires a config unless --resume is given"),
    };
    if args.resume.is_some() && !config_path.is_file() {
        return Err(usage(anyhow::anyhow!(
            "--resume {}: not a run folder (no config.toml in it)",
            out.as_deref().unwrap_or(Path::new("")).display()
        )));
    }
    let config = Config::load(&config_path, &args.overrides).map_err(|e| usage(e.into()))?;
    let run_config = config.run_config().map_err(|e| usage(e.into()))?;
    let task = registry::task_for(&config).map_err(|e| usage(e.into()))?;
    if let Some(dir) = &args.resume {
        // Whether the folder can be resumed (a study of this task and config, unfinished),
        // before anything runs.
        study::check_resume(dir, task.name, &config).map_err(|e| usage(e.into()))?;
    }
    (task.check)(&config, &run_config).map_err(usage)?;
    run_config.init_thread_pool();

    let options = RunDirOptions {
        out,
        config_out_dir: run_config.out_dir.clone(),
        existing,
        echo_log: !args.quiet,
    };
    let run_dir = RunDir::create(task.name, &options).map_err(|e| usage(e.into()))?;
    // The config first: a run killed at any later moment leaves a folder `--resume` accepts.
    run_dir
        .write_config(&config)
        .map_err(|e| Failure::Run(e.into()))?;
    let build = build_info();
    let session = Session::begin(&build, command_line, run_config.threads);
    let recorder = Recorder::start(&run_dir, session, args.resume.is_some())
        .map_err(|e| Failure::Run(e.into()))?;
    let machine = &recorder.session().machine;
    run_dir.log(format_args!(
        "cpose {} on {}, {} thread{}",
        build.describe(),
        machine.cpu_model.as_deref().unwrap_or("unknown CPU"),
        run_config.threads,
        if run_config.threads == 1 { "" } else { "s" }
    ));

    let result = run_task(args, task, &config, &config_path, &run_config, &run_dir);
    let outcome = result.as_ref().map(|_| ()).map_err(|e| format!("{e:#}"));
    let recorded = recorder.finish(&run_dir, outcome);
    match (result, recorded) {
        (Ok(()), Ok(session)) => {
            run_dir.log(format_args!(
                "done: {:.1} s wall, {} CPU, peak memory {}",
                session.wall_s.unwrap_or(0.0),
                session
                    .cpu_s
                    .map_or_else(|| "unknown".to_owned(), |s| format!("{s:.1} s")),
                session.peak_rss_bytes.map_or_else(
                    || "unknown".to_owned(),
                    |b| format!("{:.0} MiB", b as f64 / f64::from(1 << 20))
                )
            ));
            let _ = writeln!(std::io::stdout().lock(), "{}", run_dir.path().display());
            Ok(())
        }
        // The error is printed once, by `main_with_args`; the log keeps it too.
        (Ok(()), Err(e)) => {
            let err = anyhow::Error::from(e)
                .context("the run finished, but its provenance was not saved");
            run_dir.log_file_only(format_args!("failed: {err:#}"));
            Err(Failure::Run(err))
        }
        (Err(err), recorded) => {
            run_dir.log_file_only(format_args!("failed: {err:#}"));
            if let Err(e) = recorded {
                run_dir.log(format_args!("and its provenance was not saved: {e}"));
            }
            // A task that rejects its config (typo, unknown pose field) or its run folder is a
            // usage error.
            if err
                .chain()
                .any(|e| e.is::<cpose_core::ConfigError>() || e.is::<study::ResumeError>())
            {
                Err(Failure::Usage(err))
            } else {
                Err(Failure::Run(err))
            }
        }
    }
}

/// Runs the task in `run_dir`; errors carry the task's name and folder.
fn run_task(
    args: &RunArgs,
    task: &registry::Task,
    config: &Config,
    config_path: &Path,
    run_config: &cpose_core::RunConfig,
    run_dir: &RunDir,
) -> anyhow::Result<()> {
    run_dir.log(format_args!(
        "task {} with config {}{}",
        task.name,
        config_path.display(),
        if args.resume.is_some() {
            " (resumed)"
        } else {
            ""
        }
    ));
    let input = TaskInput {
        config,
        run_dir,
        run: run_config,
        show_progress: !args.quiet,
        resume: args.resume.is_some(),
    };
    (task.run)(&input).with_context(|| {
        format!(
            "task {} failed (run folder {})",
            task.name,
            run_dir.path().display()
        )
    })
}

/// `cpose eval ate GT EST`: association, alignment and translation-error statistics (metres).
fn eval_ate(args: &AteArgs) -> Result<(), Failure> {
    let (gt, est) = args.inputs.read()?;
    let plots = args
        .inputs
        .plot_files(&["ate_trajectories.png", "ate_error.png"])?;
    let report = eval::ate(&gt, &est, args.align, args.inputs.max_diff)
        .with_context(|| args.inputs.context())
        .map_err(Failure::Run)?;
    if let Some(files) = plots {
        plot_ate(&files, &gt, &est, args.align, args.inputs.max_diff)
            .with_context(|| args.inputs.context())
            .map_err(Failure::Run)?;
    }
    print_report(args.inputs.json, &report, || {
        format!(
            "matched {} pose pairs (max time difference {} s), alignment {}{}\n\
             rmse   {:.12} m\nmean   {:.12} m\nmedian {:.12} m\nstd    {:.12} m\nmin    {:.12} m\nmax    {:.12} m\n",
            report.num_matched,
            args.inputs.max_diff,
            report.alignment,
            if report.alignment == Alignment::Sim3 {
                format!(" (scale {:.9})", report.transform.scale)
            } else {
                String::new()
            },
            report.rmse_m,
            report.mean_m,
            report.median_m,
            report.std_m,
            report.min_m,
            report.max_m,
        )
    })
}

/// Prints `report` to stdout as JSON, or as the `text` it gives.
fn print_report(
    json: bool,
    report: &impl serde::Serialize,
    text: impl FnOnce() -> String,
) -> Result<(), Failure> {
    let text = if json {
        serde_json::to_string_pretty(report).map_err(|e| Failure::Run(e.into()))? + "\n"
    } else {
        text()
    };
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
    Ok(())
}

/// `cpose eval rpe`: [`eval::rpe_report`] of two trajectory files.
fn eval_rpe(args: &RpeArgs) -> Result<(), Failure> {
    let delta = match args.delta_unit.as_str() {
        "m" if args.delta.is_finite() && args.delta > 0.0 => RpeDelta::Metres(args.delta),
        "m" => {
            return Err(Failure::Usage(anyhow::anyhow!(
                "--delta {} with --delta-unit m: expected a finite distance above 0 metres",
                args.delta
            )));
        }
        _ if args.delta >= 1.0 && args.delta.fract() == 0.0 => {
            RpeDelta::Frames(args.delta as usize)
        }
        _ => {
            return Err(Failure::Usage(anyhow::anyhow!(
                "--delta {} with --delta-unit f: expected a whole number of frames of at least 1",
                args.delta
            )));
        }
    };
    let (gt, est) = args.inputs.read()?;
    let plots = args.inputs.plot_files(&["rpe_error.png"])?;
    let report = eval::rpe_report(&gt, &est, args.inputs.max_diff, delta, args.align)
        .with_context(|| args.inputs.context())
        .map_err(Failure::Run)?;
    if let Some(files) = plots {
        plot_rpe(&files[0], &gt, &est, args, delta)
            .with_context(|| args.inputs.context())
            .map_err(Failure::Run)?;
    }
    print_report(args.inputs.json, &report, || {
        format!(
            "matched {} poses (max time difference {} s), {} pairs {} {} apart, alignment {}\n\
             translation  rmse {:.12} m  mean {:.12} m  median {:.12} m  max {:.12} m\n\
             rotation     rmse {:.12}°  mean {:.12}°  median {:.12}°  max {:.12}°\n",
            report.num_matched,
            args.inputs.max_diff,
            report.num_pairs,
            args.delta,
            if args.delta_unit == "m" {
                "m"
            } else {
                "frames"
            },
            report.alignment,
            report.trans_rmse_m,
            report.trans_mean_m,
            report.trans_median_m,
            report.trans_max_m,
            report.rot_rmse_deg,
            report.rot_mean_deg,
            report.rot_median_deg,
            report.rot_max_deg,
        )
    })
}

/// [`eval::read_trajectory`], saying on stderr how many repeated timestamps it dropped.
fn read_trajectory(
    path: &Path,
    format: Option<TrajectoryFormat>,
    times: Option<&Path>,
) -> Result<Trajectory, Failure> {
    let (trajectory, duplicates) =
        eval::read_trajectory(path, format, times).map_err(|e| Failure::Usage(e.into()))?;
    if let Some(first) = duplicates.lines.first() {
        eprintln!(
            "cpose: {}: {} repeated timestamp(s) (first on line {first}); kept the later pose of each",
            path.display(),
            duplicates.lines.len()
        );
    }
    Ok(trajectory)
}

/// `cpose convert`: reads a trajectory in one format and writes it in another, never over an
/// existing file unless `--force`.
fn convert(args: &ConvertArgs) -> Result<(), Failure> {
    let usage = |e: anyhow::Error| Failure::Usage(e);
    let to = args.to.unwrap_or_else(|| {
        let csv = args
            .output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        if csv {
            TrajectoryFormat::Euroc
        } else {
            TrajectoryFormat::Tum
        }
    });
    let targets = std::iter::once(&args.output).chain(args.out_times.iter());
    for target in targets {
        if !args.force && target.exists() {
            return Err(usage(anyhow::anyhow!(
                "{} exists; give --force to replace it",
                target.display()
            )));
        }
    }
    let trajectory = read_trajectory(&args.input, args.from, args.times.as_deref())?;
    eval::write_trajectory(&args.output, &trajectory, to, args.out_times.as_deref())
        .map_err(|e| Failure::Run(e.into()))?;
    let lost = if to == TrajectoryFormat::Kitti && args.out_times.is_none() {
        " (KITTI keeps no timestamps: give --out-times FILE to keep them)"
    } else {
        ""
    };
    eprintln!(
        "cpose: wrote {} poses to {} as {to}{lost}",
        trajectory.len(),
        args.output.display()
    );
    Ok(())
}

/// `path` itself, or the one `field_*.safetensors` of the run folder `path`; a folder with none or
/// several is an error listing what it holds.
fn field_file(path: &Path) -> anyhow::Result<PathBuf> {
    if !path.is_dir() {
        return Ok(path.to_path_buf());
    }
    let mut fields: Vec<PathBuf> = std::fs::read_dir(path)
        .with_context(|| format!("reading the run folder {}", path.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("field_") && n.ends_with(".safetensors"))
        })
        .collect();
    fields.sort();
    match fields.as_slice() {
        [one] => Ok(one.clone()),
        [] => anyhow::bail!(
            "{}: expected a run folder holding a saved pose field (field_<condition>_<method>.safetensors), found none",
            path.display()
        ),
        many => anyhow::bail!(
            "{}: the run folder holds {} saved pose fields; name one: {}",
            path.display(),
            many.len(),
            many.iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

fn query(args: &QueryArgs) -> Result<(), Failure> {
    let usage = |e: anyhow::Error| Failure::Usage(e);
    if let Some(out) = &args.out
        && !args.force
        && out.exists()
    {
        return Err(usage(anyhow::anyhow!(
            "{} exists; give --force to replace it",
            out.display()
        )));
    }
    let field = field_file(&args.field).map_err(usage)?;
    let loaded = SavedPoseField::read(&field)
        .and_then(|saved| saved.load(&field))
        .map_err(usage)?;
    let range = loaded.field.time_range();
    let times = match args.rate {
        Some(hz) => {
            let samples = (range.duration_secs() * hz).floor() + 1.0;
            if !(hz > 0.0 && samples <= MAX_QUERY_SAMPLES) {
                return Err(usage(anyhow::anyhow!(
                    "--rate {hz}: expected a positive rate giving at most {MAX_QUERY_SAMPLES} \
                     samples over the field's {range}"
                )));
            }
            (0..samples as usize)
                .map(|i| range.start_secs + i as f64 / hz)
                .collect()
        }
        None => args.times.clone(),
    };
    let samples = loaded
        .sample(&times)
        .with_context(|| format!("querying {}", args.field.display()))
        .map_err(usage)?;
    let text = if args.derivatives {
        let mut text = "t,tx,ty,tz,qx,qy,qz,qw,wx,wy,wz,vx,vy,vz\n".to_owned();
        for s in &samples {
            let (p, q) = (s.pose.translation.vector, s.pose.rotation.quaternion());
            let (w, v) = (s.ang_vel_body, s.lin_vel_world);
            let row = [
                s.t_secs, p.x, p.y, p.z, q.i, q.j, q.k, q.w, w.x, w.y, w.z, v.x, v.y, v.z,
            ];
            let row: Vec<String> = row.iter().map(|x| format!("{x:.9}")).collect();
            text.push_str(&row.join(","));
            text.push('\n');
        }
        text
    } else {
        let trajectory = Trajectory::new(times, samples.iter().map(|s| s.pose).collect())
            .map_err(|e| Failure::Run(e.into()))?;
        match args.format.unwrap_or(TrajectoryFormat::Tum) {
            TrajectoryFormat::Tum => eval::to_tum_string(&trajectory),
            TrajectoryFormat::Euroc => eval::to_euroc_string(&trajectory),
            TrajectoryFormat::Kitti => eval::to_kitti_string(&trajectory),
        }
    };
    match &args.out {
        Some(out) => {
            write_atomic(out, text)
                .with_context(|| format!("writing {}", out.display()))
                .map_err(Failure::Run)?;
            eprintln!(
                "cpose: wrote {} samples to {}",
                samples.len(),
                out.display()
            );
        }
        None => {
            let _ = std::io::stdout().lock().write_all(text.as_bytes());
        }
    }
    Ok(())
}

/// How a plot title names an alignment.
fn aligned_how(align: Alignment) -> &'static str {
    match align {
        Alignment::None => "not aligned",
        Alignment::Se3 => "SE(3)-aligned",
        Alignment::Sim3 => "Sim(3)-aligned",
    }
}

/// The associated reference poses, the estimate aligned onto them, and their times (the
/// reference's), as `cpose eval` compares them.
struct Compared {
    times: Vec<f64>,
    reference: Vec<Isometry3<f64>>,
    aligned: Vec<Isometry3<f64>>,
}

fn aligned_pairs(
    gt: &Trajectory,
    est: &Trajectory,
    align: Alignment,
    max_diff: f64,
) -> anyhow::Result<Compared> {
    let association = eval::associate(gt, est, max_diff)?;
    let (reference, estimate) = association.poses(gt, est);
    let (_, aligned) = eval::align_poses(&reference, &estimate, align)?;
    let times = association
        .pairs
        .iter()
        .map(|&(i, _)| gt.timestamps_secs()[i])
        .collect();
    Ok(Compared {
        times,
        reference,
        aligned,
    })
}

/// `eval ate --plot`: the aligned estimate against the reference (top view, x y z, roll pitch
/// yaw over time) and the position error over time.
fn plot_ate(
    files: &[PathBuf],
    gt: &Trajectory,
    est: &Trajectory,
    align: Alignment,
    max_diff: f64,
) -> anyhow::Result<()> {
    let Compared {
        times,
        reference,
        aligned,
    } = aligned_pairs(gt, est, align, max_diff)?;
    plot::trajectory_comparison(
        &files[0],
        &format!("estimate ({}) against the reference", aligned_how(align)),
        &times,
        Some(&reference),
        None,
        ("estimate", &aligned),
    )?;
    let errors = eval::ape_translation(&reference, &aligned)?;
    let t0 = times[0];
    plot::errors_over_time(
        &files[1],
        &format!("absolute position error ({})", aligned_how(align)),
        "position error (m)",
        &[plot::Line {
            label: "estimate".to_owned(),
            x: times.iter().map(|t| t - t0).collect(),
            y: errors,
            style: plot::SeriesStyle::Estimate(0),
        }],
    )?;
    Ok(())
}

/// `eval rpe --plot`: the relative translation and rotation errors against the time of each
/// pair's second pose.
fn plot_rpe(
    file: &Path,
    gt: &Trajectory,
    est: &Trajectory,
    args: &RpeArgs,
    delta: RpeDelta,
) -> anyhow::Result<()> {
    let Compared {
        times,
        reference,
        aligned,
    } = aligned_pairs(gt, est, args.align, args.inputs.max_diff)?;
    let errors = eval::rpe_with(&reference, &aligned, delta)?;
    let t0 = times[0];
    let x: Vec<f64> = errors.pairs.iter().map(|&(_, j)| times[j] - t0).collect();
    let line = |y: Vec<f64>| plot::Line {
        label: "estimate".to_owned(),
        x: x.clone(),
        y,
        style: plot::SeriesStyle::Estimate(0),
    };
    let unit = if args.delta_unit == "m" {
        "m"
    } else {
        "frames"
    };
    plot::stacked_line_charts(
        file,
        &format!(
            "relative pose error, pairs {} {unit} apart ({})",
            args.delta,
            aligned_how(args.align)
        ),
        "time of the pair's second pose (s)",
        &[
            plot::Panel {
                y_label: "translation error (m)".to_owned(),
                y_scale: plot::YScale::LinearFromZero,
                lines: vec![line(errors.translation.clone())],
            },
            plot::Panel {
                y_label: "rotation error (°)".to_owned(),
                y_scale: plot::YScale::LinearFromZero,
                lines: vec![line(
                    errors
                        .rotation_angle_rad
                        .iter()
                        .map(|a| a.to_degrees())
                        .collect(),
                )],
            },
        ],
    )?;
    Ok(())
}
