//! Measurements. Being written: see the performance issue.

use std::process::ExitCode;

use anyhow::{bail, Result};
use clap::Subcommand;

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Per-hop latency of the realtime runtime.
    Latency,
}

pub fn bench(_b: &BenchCommand) -> Result<ExitCode> {
    bail!("not implemented yet")
}
