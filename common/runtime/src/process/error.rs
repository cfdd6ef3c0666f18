//! Why a process stopped early, and the one constant of its reports.

use std::time::Duration;

use crate::ipc::IpcError;

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
