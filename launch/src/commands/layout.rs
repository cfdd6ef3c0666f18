//! `fdi-launch layout`: the layout of a run's figures for a viewer (Foxglove or PlotJuggler),
//! made for the robots of a scenario — their ids and joint counts (docs/traces.md, "Layouts").

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Args, ValueEnum};
use fdi_common::scenario;
use fdi_live::layout;

/// The viewer a layout is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Viewer {
    /// Foxglove (JSON: *Layouts* → *Import from file*).
    Foxglove,
    /// PlotJuggler (XML: *File* → *Load layout*).
    Plotjuggler,
}

#[derive(Debug, Args)]
pub struct LayoutArgs {
    /// Scenario TOML file, or a run directory's `scenario.toml`; the embedded default (the
    /// paper's experiment) when omitted.
    pub scenario: Option<PathBuf>,
    /// The viewer.
    #[arg(long, value_enum, default_value = "foxglove")]
    pub viewer: Viewer,
}

/// `layout`: the layout, on stdout.
pub fn layout(args: &LayoutArgs) -> Result<ExitCode> {
    let resolved = match &args.scenario {
        Some(path) => scenario::load_file(path)?,
        None => scenario::paper()?,
    };
    let tabs = layout::figures(&layout::robots(&resolved.scenario));
    match args.viewer {
        Viewer::Foxglove => println!(
            "{}",
            serde_json::to_string_pretty(&layout::foxglove(&tabs))?
        ),
        Viewer::Plotjuggler => print!("{}", layout::plotjuggler(&tabs)),
    }
    Ok(ExitCode::SUCCESS)
}
