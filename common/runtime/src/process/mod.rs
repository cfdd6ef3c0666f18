//! What every runtime process shares around its main loop, one module per concern: the
//! launcher's arguments ([`ProcessArgs`]), placement on CPUs and scheduling ([`Placement`]),
//! shutdown on SIGINT/SIGTERM or the launcher's death ([`Shutdown`]), waiting for peers
//! ([`WaitStrategy`]), the launcher handshake and status reports ([`LauncherLink`]), admission of
//! received messages ([`admit_measurement`], [`admit_torque`]), liveness ([`Liveness`]) and what
//! `/proc` says about processes ([`procfs`]).

use std::time::Duration;

use crate::ipc::IpcError;

mod admission;
mod args;
pub mod external;
mod launcher;
mod liveness;
mod placement;
pub mod procfs;
mod shutdown;
mod wait;

pub use admission::{admit_measurement, admit_torque, Admission, Command};
pub use args::ProcessArgs;
pub use launcher::{
    connect, finish, node_name, sizing_for, start, trace_header, Connection, LauncherLink, Start,
    HOLD_LIMIT,
};
pub use liveness::{lost_after_ns, realtime_end_ns, Liveness, LIVENESS_CHECK, LOST_AFTER_NS};
pub use placement::{use_fifo, use_idle, CpuList, Placement};
pub use shutdown::Shutdown;
pub use wait::{WaitStrategy, DEFAULT_SPIN_US, START_TIMEOUT, WAIT_SLICE};

/// Ticks between two progress reports of a process to the launcher (the control center's, and
/// a realtime agent's): the launcher takes a run that reports nothing for its stall timeout
/// for stalled.
pub const PROGRESS_EVERY: u64 = 500;

/// Why a process stopped early.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error("no start from the launcher within {0:?}")]
    NoStart(Duration),
    #[error("stopped by the launcher before the start")]
    StoppedBeforeStart,
}

/// Why a runtime process (agent, attacker, control center) failed: one type for all of them.
#[derive(Debug, thiserror::Error)]
pub enum RoleError {
    #[error(transparent)]
    Process(#[from] ProcessError),
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error(transparent)]
    Trace(#[from] fdi_common::trace::TraceError),
    #[error(transparent)]
    Scenario(#[from] fdi_common::scenario::ScenarioError),
    #[error("installing signal handlers: {0}")]
    Signals(std::io::Error),
    #[error("agent {0} is not in the scenario")]
    NotInScenario(u32),
    #[error("--agent is required")]
    MissingId,
    #[error("agent {0}: its model has another number of links than the run's first agent")]
    Dof(u32),
    #[error("the scenario has no agents")]
    NoAgents,
    /// What the role was given to read cannot be used (the replayer's recording); the message
    /// names the file.
    #[error("{0}")]
    Input(String),
    #[error("{0}")]
    Scheduling(String),
    /// A program that takes a role (`[roles]`) broke the protocol (docs/protocol.md); the
    /// message names it.
    #[error("{0}")]
    External(String),
}

/// Prints a child process's failure on its stderr, which the launcher relays. A write error
/// is ignored: the launcher that read the pipe may be gone (killed), and `eprintln!` would then
/// panic on the broken pipe instead of exiting with the failure's status.
pub fn print_failure(message: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{message}");
}
