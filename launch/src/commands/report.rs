//! `fdi-launch report RUN_DIR` and `fdi-launch trace export RUN_DIR`: what `fdi-report` makes
//! of a run directory, named here.

use fdi_common::run_dir::RunDir;
use std::path::Path;
use std::process::ExitCode;

use anyhow::Result;
use clap::ValueEnum;
use fdi_common::stop::Stop;
use fdi_report::export;
use fdi_report::team::PerRobot;

/// `trace export --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// One CSV per process trace and record kind (pandas, MATLAB, a spreadsheet).
    Csv,
    /// One MCAP file per run, JSON messages with JSON schemas (Foxglove, PlotJuggler).
    Mcap,
}

/// `report`: the report made again, its `report.md` named.
pub fn report(run_dir: &Path, robots: &PerRobot, stop: &Stop) -> Result<ExitCode> {
    let md = fdi_report::report::report(&RunDir::new(run_dir), robots, stop)?;
    println!("report {}", md.display());
    Ok(ExitCode::SUCCESS)
}

/// `trace export`: a line per trace exported.
pub fn export(run_dir: &Path, format: ExportFormat) -> Result<ExitCode> {
    let format = match format {
        ExportFormat::Csv => export::Format::Csv,
        ExportFormat::Mcap => export::Format::Mcap,
    };
    export::export(&RunDir::new(run_dir), format, &mut |line| {
        println!("{line}")
    })?;
    Ok(ExitCode::SUCCESS)
}
