//! How a run failed: before its start or after.

/// What a run that did not start says first (a refused run, a machine that cannot carry it,
/// a stop before the start).
pub const DID_NOT_START: &str = "the run did not start";

/// A run that failed: before its start was broadcast (nothing of it was recorded: the caller
/// removes the run directory it made for it, [`crate::run_dirs::discard_if_not_started`]) or
/// after. It becomes its cause when it meets an `anyhow::Error` (`?`), whose text says which
/// ([`DID_NOT_START`]), and whose chain still holds what the cause holds (an
/// `fdi_common::stop::Interrupted`, say).
#[derive(Debug)]
pub enum RunError {
    /// Refused or failed before its start.
    NotStarted(anyhow::Error),
    /// Failed once started (or before, without anything to remove).
    Failed(anyhow::Error),
}

impl RunError {
    /// `e`, the cause of a run that did not start, said so.
    pub fn not_started(e: impl Into<anyhow::Error>) -> Self {
        Self::NotStarted(e.into().context(DID_NOT_START))
    }
}

impl From<anyhow::Error> for RunError {
    fn from(e: anyhow::Error) -> Self {
        Self::Failed(e)
    }
}

impl From<RunError> for anyhow::Error {
    fn from(e: RunError) -> Self {
        match e {
            RunError::NotStarted(e) | RunError::Failed(e) => e,
        }
    }
}
