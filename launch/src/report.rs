//! Reports of run directories (figures, tables, detection metrics). Being written: see the
//! results issue.

use std::path::Path;

use anyhow::{bail, Result};
use fdi_common::engine::RunSummary;
use fdi_common::scenario::Resolved;

/// `fdi-launch report RUN_DIR`.
pub fn report(run_dir: &Path) -> Result<()> {
    bail!("report of {}: not implemented yet", run_dir.display())
}

/// Called at the end of every `run`.
pub fn write_report(_run_dir: &Path, _resolved: &Resolved, _summary: &RunSummary) -> Result<()> {
    Ok(())
}
