//! The files of a run directory and the names of a run's processes: the one place that spells
//! them. Every command that writes or reads a run directory (`run`, `report`, `detect`, `trace
//! export`, `runs`, a serving host's work folder) goes through [`RunDir`]; every trace, pipe and
//! node is named by a [`Process`].
//!
//! ```text
//! RUN_DIR/
//!   scenario.toml          the resolved scenario (overrides applied)
//!   summary.json           the run's summary (metrics, digest, counts)
//!   rmse.md, rmse.csv      the RMSE table
//!   traces/<process>.trace one binary trace per process (`agent-1`, `attacker`, `control-center`)
//!   traces/<process>.pipe  while a run records: the named pipes of the live join
//!   report/                figures, report.md, detection.csv, segments.csv
//!   export/                `trace export`: CSV, Parquet-ready CSV, MCAP
//! ```

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// A process of a run, by the name its trace, its pipe and its transport node carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Process {
    /// The agent (robot) with this id: `agent-<id>`.
    Agent(u32),
    /// The attacker (or the replayer standing in for it): `attacker`.
    Attacker,
    /// The control center: `control-center`.
    Center,
}

impl Process {
    /// The name of the attacker's trace, pipe and node.
    pub const ATTACKER: &'static str = "attacker";
    /// The name of the control center's trace, pipe and node.
    pub const CENTER: &'static str = "control-center";
    /// The prefix of an agent's name (`agent-<id>`).
    pub const AGENT_PREFIX: &'static str = "agent-";

    /// The processes of a run with these agents, in the order runs list them: the agents, the
    /// attacker, the control center.
    pub fn of_run(agents: impl IntoIterator<Item = u32>) -> Vec<Process> {
        let mut all: Vec<Process> = agents.into_iter().map(Process::Agent).collect();
        all.push(Process::Attacker);
        all.push(Process::Center);
        all
    }

    /// The agent's id, for an agent.
    pub fn agent(self) -> Option<u32> {
        match self {
            Process::Agent(id) => Some(id),
            _ => None,
        }
    }
}

impl fmt::Display for Process {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Process::Agent(id) => write!(f, "{}{id}", Self::AGENT_PREFIX),
            Process::Attacker => f.write_str(Self::ATTACKER),
            Process::Center => f.write_str(Self::CENTER),
        }
    }
}

/// A name that is not a process of a run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a process of a run (agent-<id>, attacker, control-center)")]
pub struct NotAProcess(pub String);

impl FromStr for Process {
    type Err = NotAProcess;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            Self::ATTACKER => Ok(Process::Attacker),
            Self::CENTER => Ok(Process::Center),
            _ => s
                .strip_prefix(Self::AGENT_PREFIX)
                .filter(|id| !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()))
                .and_then(|id| id.parse().ok())
                .map(Process::Agent)
                .ok_or_else(|| NotAProcess(s.to_string())),
        }
    }
}

/// A run directory: every path inside it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    /// The resolved scenario's file name.
    pub const SCENARIO: &'static str = "scenario.toml";
    /// The summary's file name.
    pub const SUMMARY: &'static str = "summary.json";
    /// The traces' folder name.
    pub const TRACES: &'static str = "traces";
    /// The report's folder name.
    pub const REPORT: &'static str = "report";
    /// The exports' folder name.
    pub const EXPORT: &'static str = "export";
    /// The extension of a trace file.
    pub const TRACE_EXT: &'static str = "trace";
    /// The extension of a live join's named pipe.
    pub const PIPE_EXT: &'static str = "pipe";

    /// The run directory at `root` (nothing is created or checked).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The directory itself.
    pub fn path(&self) -> &Path {
        &self.root
    }

    /// `scenario.toml`: the resolved scenario.
    pub fn scenario(&self) -> PathBuf {
        self.root.join(Self::SCENARIO)
    }

    /// `summary.json`.
    pub fn summary(&self) -> PathBuf {
        self.root.join(Self::SUMMARY)
    }

    /// `traces/`.
    pub fn traces(&self) -> PathBuf {
        self.root.join(Self::TRACES)
    }

    /// `traces/<process>.trace`.
    pub fn trace(&self, process: Process) -> PathBuf {
        self.trace_named(&process.to_string())
    }

    /// `traces/<name>.trace` for a process named by a string (a serving host's list).
    pub fn trace_named(&self, name: &str) -> PathBuf {
        self.traces().join(format!("{name}.{}", Self::TRACE_EXT))
    }

    /// `traces/<process>.pipe`: the named pipe a recording process writes while the launcher
    /// joins live.
    pub fn pipe(&self, process: Process) -> PathBuf {
        self.traces().join(format!("{process}.{}", Self::PIPE_EXT))
    }

    /// `report/`.
    pub fn report(&self) -> PathBuf {
        self.root.join(Self::REPORT)
    }

    /// `export/`.
    pub fn export(&self) -> PathBuf {
        self.root.join(Self::EXPORT)
    }

    /// A file directly in the run directory (`rmse.md`, …).
    pub fn file(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }
}

impl AsRef<Path> for RunDir {
    fn as_ref(&self) -> &Path {
        &self.root
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn process_names_round_trip() {
        for p in Process::of_run([1, 2, 17]) {
            assert_eq!(p.to_string().parse::<Process>(), Ok(p));
        }
        assert_eq!(Process::Center.to_string(), "control-center");
        assert_eq!(Process::Agent(3).to_string(), "agent-3");
    }

    #[test]
    fn names_that_are_not_processes_are_refused() {
        for bad in [
            "agent-",
            "agent--1",
            "agent-x",
            "Attacker",
            "../attacker",
            "agent-1.d",
            "",
        ] {
            assert!(bad.parse::<Process>().is_err(), "{bad}");
        }
    }

    #[test]
    fn paths_sit_under_the_run_directory() {
        let d = RunDir::new("/r");
        assert_eq!(d.scenario(), Path::new("/r/scenario.toml"));
        assert_eq!(
            d.trace(Process::Agent(2)),
            Path::new("/r/traces/agent-2.trace")
        );
        assert_eq!(
            d.pipe(Process::Center),
            Path::new("/r/traces/control-center.pipe")
        );
        assert_eq!(d.summary(), Path::new("/r/summary.json"));
    }
}
