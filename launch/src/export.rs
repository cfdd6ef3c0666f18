//! Trace export. Being written: see the results issue.

use std::path::Path;

use anyhow::{bail, Result};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Csv,
}

/// `fdi-launch trace export RUN_DIR`.
pub fn export(run_dir: &Path, _format: Format) -> Result<()> {
    bail!("export of {}: not implemented yet", run_dir.display())
}
