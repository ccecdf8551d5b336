//! What a run folder records about the program, machine and process that made it:
//! `provenance.json`, and the process's CPU time and peak memory.
//!
//! [`Recorder::start`] writes `provenance.json` when a session of a run begins and
//! [`Recorder::finish`] writes it again when the session ends, finished or failed. The top level
//! describes the newest session (the one whose files the folder now holds); `sessions` lists
//! every session, oldest first, the newest included, so a run resumed with
//! `cpose run --resume DIR` keeps the record of the sessions before. What cannot be probed (no
//! `/proc`, no git at build time) is `null`.
//!
//! ```json
//! {
//!   "format": 1,
//!   "cpose_version": "0.1.0",
//!   "commit": "67bf937286361323eed8aff91ff8d3a04e08b18b",
//!   "dirty": false,
//!   "command_line": ["cpose", "run", "configs/trajectory_fit.toml"],
//!   "machine": { "cpu_model": "AMD EPYC", "logical_cpus": 2, "os": "linux", "arch": "x86_64" },
//!   "threads": 2,
//!   "started_utc": "2026-12-04T18:40:00.123Z",
//!   "finished_utc": "2026-12-04T18:42:10.456Z",
//!   "wall_s": 130.333,
//!   "cpu_s": 255.1,
//!   "peak_rss_bytes": 81264640,
//!   "outcome": "finished",
//!   "sessions": [{ "cpose_version": "0.1.0", "commit": "…", "…": "…", "outcome": "finished" }]
//! }
//! ```

use std::time::{Instant, SystemTime};

use serde::{Deserialize, Serialize};

use crate::run_dir::{RunDir, RunDirError, utc_iso};

/// The file name in the run folder.
pub const FILE: &str = "provenance.json";

/// Version of the layout of `provenance.json`.
pub const FORMAT: u32 = 1;

/// What the program running the tasks knows about its own build; the `cpose` binary fills it
/// in from its build script.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Build {
    /// The cpose version (`CARGO_PKG_VERSION`).
    pub version: String,
    /// The git commit of the source (40 hex digits); `None` when unknown.
    pub commit: Option<String>,
    /// Whether tracked files differed from that commit; `None` when unknown.
    pub dirty: Option<bool>,
}

impl Build {
    /// `"<version> (<short commit>[, dirty])"`, e.g. `0.1.0 (67bf937, dirty)`.
    pub fn describe(&self) -> String {
        let commit = match &self.commit {
            Some(c) => c.get(..7).unwrap_or(c),
            None => "unknown commit",
        };
        let dirty = match self.dirty {
            Some(true) => ", dirty",
            _ => "",
        };
        format!("{} ({commit}{dirty})", self.version)
    }
}

/// The machine a session runs on.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Machine {
    /// The CPU's `model name` in `/proc/cpuinfo`; `None` where there is none.
    pub cpu_model: Option<String>,
    /// Logical CPUs this process may use (`std::thread::available_parallelism`).
    pub logical_cpus: Option<usize>,
    /// Operating system (`std::env::consts::OS`, e.g. `linux`).
    pub os: String,
    /// CPU architecture (`std::env::consts::ARCH`, e.g. `x86_64`).
    pub arch: String,
}

impl Machine {
    /// Probes this machine; what cannot be read is `None`.
    pub fn probe() -> Self {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        Self {
            cpu_model: cpu_model(&cpuinfo),
            logical_cpus: std::thread::available_parallelism().ok().map(|n| n.get()),
            os: std::env::consts::OS.to_owned(),
            arch: std::env::consts::ARCH.to_owned(),
        }
    }
}

/// The first `model name` of a `/proc/cpuinfo` text.
fn cpu_model(cpuinfo: &str) -> Option<String> {
    cpuinfo.lines().find_map(|line| {
        let (key, value) = line.split_once(':')?;
        let value = value.trim();
        (key.trim() == "model name" && !value.is_empty()).then(|| value.to_owned())
    })
}

/// One session of a run: one `cpose run` process, from start to end.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Session {
    /// The cpose version.
    pub cpose_version: String,
    /// The git commit cpose was built from; `None` when unknown.
    pub commit: Option<String>,
    /// Whether that build had uncommitted changes; `None` when unknown.
    pub dirty: Option<bool>,
    /// The command line, program name first.
    pub command_line: Vec<String>,
    /// The machine.
    pub machine: Machine,
    /// Worker threads of the run (`[run] threads`).
    pub threads: usize,
    /// When the session started, UTC (`YYYY-mm-ddTHH:MM:SS.mmmZ`).
    pub started_utc: String,
    /// When it ended, UTC; `None` while it runs.
    pub finished_utc: Option<String>,
    /// Wall-clock seconds of the session; `None` while it runs.
    pub wall_s: Option<f64>,
    /// CPU seconds (user + system) of the process during the session; `None` while it runs
    /// or where they cannot be read.
    pub cpu_s: Option<f64>,
    /// Peak resident memory of the process, bytes; `None` while it runs or where unknown.
    pub peak_rss_bytes: Option<u64>,
    /// `running`, `finished`, `failed: <error>`, or `interrupted` (killed before it could
    /// write its end; set when the run is resumed).
    pub outcome: String,
}

impl Session {
    /// A session starting now on this machine.
    pub fn begin(build: &Build, command_line: Vec<String>, threads: usize) -> Self {
        Self {
            cpose_version: build.version.clone(),
            commit: build.commit.clone(),
            dirty: build.dirty,
            command_line,
            machine: Machine::probe(),
            threads,
            started_utc: utc_iso(SystemTime::now()),
            finished_utc: None,
            wall_s: None,
            cpu_s: None,
            peak_rss_bytes: None,
            outcome: "running".to_owned(),
        }
    }
}

/// The content of `provenance.json`: the newest session at the top level, and every session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Layout version ([`FORMAT`]).
    pub format: u32,
    /// The newest session.
    #[serde(flatten)]
    pub latest: Session,
    /// Every session, oldest first; the last one is `latest`.
    pub sessions: Vec<Session>,
}

impl Provenance {
    /// A record whose only session is `session`.
    pub fn new(session: Session) -> Self {
        Self {
            format: FORMAT,
            latest: session.clone(),
            sessions: vec![session],
        }
    }

    /// Appends `session` as the newest; an earlier session still `running` was killed.
    pub fn push(&mut self, session: Session) {
        for earlier in &mut self.sessions {
            if earlier.outcome == "running" {
                earlier.outcome = "interrupted".to_owned();
            }
        }
        self.sessions.push(session.clone());
        self.latest = session;
    }
}

/// Keeps `provenance.json` of a run folder up to date during one session.
#[derive(Debug)]
pub struct Recorder {
    record: Provenance,
    started: Instant,
    cpu_at_start: Option<f64>,
}

impl Recorder {
    /// Writes `provenance.json` with `session` as its newest session: after the sessions
    /// already recorded there when `resume` is set (a record that cannot be read is kept as
    /// `provenance.json.unreadable` and said so in the log), else as the only one.
    pub fn start(run_dir: &RunDir, session: Session, resume: bool) -> Result<Self, RunDirError> {
        let path = run_dir.file(FILE);
        let earlier = match std::fs::read(&path) {
            Ok(bytes) if resume => match serde_json::from_slice::<Provenance>(&bytes) {
                Ok(record) => Some(record),
                Err(e) => {
                    let aside = run_dir.file(format!("{FILE}.unreadable"));
                    let _ = std::fs::rename(&path, &aside);
                    run_dir.log(format_args!(
                        "{FILE} of the earlier sessions is unreadable ({e}); kept as {}",
                        aside.display()
                    ));
                    None
                }
            },
            _ => None,
        };
        let record = match earlier {
            Some(mut record) => {
                record.push(session);
                record
            }
            None => Provenance::new(session),
        };
        let recorder = Self {
            record,
            started: Instant::now(),
            cpu_at_start: process_cpu_secs(),
        };
        run_dir.write_json(FILE, &recorder.record)?;
        Ok(recorder)
    }

    /// The session being recorded.
    pub fn session(&self) -> &Session {
        &self.record.latest
    }

    /// Records the end of the session — `Ok` if it finished, else the error message — and
    /// writes `provenance.json` again. Returns the completed session.
    pub fn finish(
        mut self,
        run_dir: &RunDir,
        outcome: Result<(), String>,
    ) -> Result<Session, RunDirError> {
        let session = &mut self.record.latest;
        session.finished_utc = Some(utc_iso(SystemTime::now()));
        session.wall_s = Some(self.started.elapsed().as_secs_f64());
        session.cpu_s = match (self.cpu_at_start, process_cpu_secs()) {
            (Some(a), Some(b)) => Some((b - a).max(0.0)),
            _ => None,
        };
        session.peak_rss_bytes = peak_rss_bytes();
        session.outcome = match outcome {
            Ok(()) => "finished".to_owned(),
            Err(message) => format!("failed: {message}"),
        };
        let session = session.clone();
        if let Some(last) = self.record.sessions.last_mut() {
            *last = session.clone();
        }
        run_dir.write_json(FILE, &self.record)?;
        Ok(session)
    }
}

/// CPU seconds (user + system) this process has used so far, from `/proc/self/stat`; `None`
/// where that file does not exist (not Linux).
pub fn process_cpu_secs() -> Option<f64> {
    cpu_secs_of("/proc/self/stat")
}

/// CPU seconds (user + system) the calling thread has used so far, from
/// `/proc/thread-self/stat`; `None` where that file does not exist.
pub fn thread_cpu_secs() -> Option<f64> {
    cpu_secs_of("/proc/thread-self/stat")
}

/// utime + stime of a `stat` file of proc(5), seconds.
fn cpu_secs_of(path: &str) -> Option<f64> {
    let stat = std::fs::read_to_string(path).ok()?;
    // Fields after the parenthesised command name (which may hold spaces); utime and stime are
    // fields 14 and 15 of proc(5), in clock ticks of USER_HZ = 100 on Linux.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_ascii_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<f64>().ok();
    Some((ticks(11)? + ticks(12)?) / 100.0)
}

/// The largest resident memory of this process so far, bytes (`VmHWM` of `/proc/self/status`);
/// `None` where that file does not exist.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_ascii_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run_dir::RunDirOptions;

    fn build() -> Build {
        Build {
            version: "0.1.0".into(),
            commit: Some("67bf937286361323eed8aff91ff8d3a04e08b18b".into()),
            dirty: Some(true),
        }
    }

    fn read(run_dir: &RunDir) -> (Provenance, serde_json::Value) {
        let text = std::fs::read_to_string(run_dir.file(FILE)).unwrap();
        (
            serde_json::from_str(&text).unwrap(),
            serde_json::from_str(&text).unwrap(),
        )
    }

    #[test]
    fn machine_probe_is_plausible() {
        let m = Machine::probe();
        assert_eq!(m.os, std::env::consts::OS);
        assert_eq!(m.arch, std::env::consts::ARCH);
        assert!(
            m.logical_cpus.is_some_and(|n| (1..100_000).contains(&n)),
            "{m:?}"
        );
        if cfg!(all(target_os = "linux", target_arch = "x86_64")) {
            assert!(m.cpu_model.as_ref().is_some_and(|c| !c.is_empty()), "{m:?}");
        }
        let cpuinfo = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel\t\t: 85\n\
                       model name\t: Intel(R) Xeon(R) Gold 6130 CPU @ 2.10GHz\n\n\
                       processor\t: 1\nmodel name\t: other\n";
        assert_eq!(
            cpu_model(cpuinfo).as_deref(),
            Some("Intel(R) Xeon(R) Gold 6130 CPU @ 2.10GHz")
        );
        assert_eq!(cpu_model("processor : 0\nCPU part : 0xd0c\n"), None);
    }

    #[test]
    fn build_is_described_by_short_commit_and_dirty_flag() {
        assert_eq!(build().describe(), "0.1.0 (67bf937, dirty)");
        let clean = Build {
            dirty: Some(false),
            ..build()
        };
        assert_eq!(clean.describe(), "0.1.0 (67bf937)");
        let unknown = Build {
            version: "0.1.0".into(),
            ..Default::default()
        };
        assert_eq!(unknown.describe(), "0.1.0 (unknown commit)");
    }

    #[test]
    fn json_round_trips_with_the_newest_session_at_the_top() {
        let mut record = Provenance::new(Session::begin(&build(), vec!["cpose".into()], 2));
        let mut second = Session::begin(&Build::default(), vec!["cpose".into(), "run".into()], 1);
        second.machine.cpu_model = None;
        second.wall_s = Some(1.5);
        second.peak_rss_bytes = Some(1 << 30);
        record.push(second);
        let text = serde_json::to_string_pretty(&record).unwrap();
        let back: Provenance = serde_json::from_str(&text).unwrap();
        assert_eq!(back, record);
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(value["format"], FORMAT);
        assert_eq!(value["commit"], serde_json::Value::Null);
        assert_eq!(value["machine"]["cpu_model"], serde_json::Value::Null);
        assert_eq!(value["command_line"][1], "run");
        assert_eq!(value["wall_s"], 1.5);
        assert_eq!(value["sessions"][0]["outcome"], "interrupted");
        assert_eq!(value["sessions"][0]["dirty"], true);
        assert_eq!(back.sessions.last(), Some(&back.latest));
        assert_eq!(value["sessions"].as_array().unwrap().len(), 2);
    }

    #[test]
    fn sessions_are_appended_on_resume_and_replaced_otherwise() {
        let dir = crate::testing::TempDir::new("provenance");
        let options = RunDirOptions {
            out: Some(dir.join("run")),
            existing: crate::run_dir::Existing::Keep,
            ..Default::default()
        };
        let run_dir = RunDir::create("demo", &options).unwrap();
        let session = |arg: &str| Session::begin(&build(), vec!["cpose".into(), arg.into()], 2);

        let first = Recorder::start(&run_dir, session("first"), true).unwrap();
        let (record, value) = read(&run_dir);
        assert_eq!(record.sessions.len(), 1);
        assert_eq!(value["outcome"], "running");
        assert_eq!(value["wall_s"], serde_json::Value::Null);
        assert!(
            value["started_utc"].as_str().unwrap().ends_with('Z'),
            "{value}"
        );
        let done = first.finish(&run_dir, Ok(())).unwrap();
        assert_eq!(done.outcome, "finished");
        let (record, _) = read(&run_dir);
        assert_eq!(record.latest, done);
        assert_eq!(record.sessions, std::slice::from_ref(&done));
        assert!(done.wall_s.unwrap() >= 0.0);
        if process_cpu_secs().is_some() {
            assert!(
                done.cpu_s.is_some() && done.peak_rss_bytes.unwrap() > 1 << 20,
                "{done:?}"
            );
        }

        // Resumed: the first session stays; a second one killed before its end is marked.
        let second = Recorder::start(&run_dir, session("second"), true).unwrap();
        assert_eq!(second.session().command_line[1], "second");
        drop(second);
        let third = Recorder::start(&run_dir, session("third"), true).unwrap();
        third.finish(&run_dir, Err("diverged".into())).unwrap();
        let (record, value) = read(&run_dir);
        let outcomes: Vec<&str> = record.sessions.iter().map(|s| s.outcome.as_str()).collect();
        assert_eq!(outcomes, ["finished", "interrupted", "failed: diverged"]);
        assert_eq!(record.sessions[0], done);
        assert_eq!(value["command_line"][1], "third");
        assert_eq!(value["outcome"], "failed: diverged");

        // A new run in the folder starts a new record; an unreadable one is kept aside.
        Recorder::start(&run_dir, session("new"), false).unwrap();
        assert_eq!(read(&run_dir).0.sessions.len(), 1);
        std::fs::write(run_dir.file(FILE), "{").unwrap();
        Recorder::start(&run_dir, session("after"), true).unwrap();
        assert_eq!(read(&run_dir).0.sessions.len(), 1);
        assert_eq!(
            std::fs::read_to_string(run_dir.file("provenance.json.unreadable")).unwrap(),
            "{"
        );
    }

    #[test]
    fn cpu_time_grows_and_memory_is_plausible() {
        let (Some(before), Some(peak)) = (process_cpu_secs(), peak_rss_bytes()) else {
            eprintln!("skipped: no /proc on this system");
            return;
        };
        // Busy until 0.2 s of CPU are used: on a loaded machine that takes longer than 0.2 s.
        let start = Instant::now();
        let (mut x, mut after) = (0u64, before);
        while after - before < 0.2 && start.elapsed().as_secs() < 60 {
            for _ in 0..100_000 {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
            after = process_cpu_secs().unwrap();
        }
        assert!(after - before >= 0.2, "{before} → {after}");
        assert!(peak > 1 << 20 && peak < 1 << 40, "{peak}");
    }

    /// A thread's own clock counts its work, not another thread's: a busy thread's time grows
    /// while an idle one's stays.
    #[test]
    fn thread_cpu_time_is_the_threads_own() {
        let Some(idle_before) = thread_cpu_secs() else {
            eprintln!("skipped: no /proc/thread-self on this system");
            return;
        };
        let busy = std::thread::spawn(|| {
            let before = thread_cpu_secs().unwrap();
            let start = Instant::now();
            let (mut x, mut after) = (0u64, before);
            while after - before < 0.2 && start.elapsed().as_secs() < 60 {
                for _ in 0..100_000 {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
                after = thread_cpu_secs().unwrap();
            }
            after - before
        })
        .join()
        .unwrap();
        assert!(busy >= 0.2, "{busy}");
        assert!(thread_cpu_secs().unwrap() - idle_before < 0.1);
    }
}
