//! `fdi-launch table1`, `table2` and `attacks`: the paper's tables and the attack-class table,
//! made by `fdi_tables::tables` and `fdi_tables::attacks`, printed here.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Args;
use fdi_common::stop::Stop;
use fdi_orchestrator::{Engine, NumericsArgs, SetArgs};
use fdi_tables::attacks::AttacksOptions;
use fdi_tables::tables::{Table, TableOptions};

/// `table1`, `table2`.
#[derive(Debug, Args)]
pub struct TableArgs {
    #[arg(long, value_parser = super::values::engine(), default_value_t = Engine::Ipc)]
    pub engine: Engine,
    /// Base scenario (default: the embedded paper scenario): its robots, gains and numerics. Its
    /// attack and duration are replaced by the table's (the paper's attack, 40 s), and the header
    /// names what differs from the paper's calibration.
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    #[command(flatten)]
    pub numerics: NumericsArgs,
    #[command(flatten)]
    pub set: SetArgs,
    /// Print JSON instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// Shorten every run to this many seconds (the paper's tables use 40 s).
    #[arg(long, allow_negative_numbers = true)]
    pub duration_s: Option<f64>,
    /// Folder that receives the table's run directories.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Run every entry with N seeds (the scenario's seed, seed + 1, …, seed + N − 1) and give
    /// each cell as mean ± 95 % confidence interval (Student t) over them.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub seeds: Option<u32>,
    /// With --seeds: runs at a time (default: the number of CPUs).
    #[arg(long, requires = "seeds")]
    pub jobs: Option<std::num::NonZeroUsize>,
}

impl TableArgs {
    fn options(&self) -> TableOptions {
        TableOptions {
            engine: self.engine,
            scenario: self.scenario.clone(),
            numerics: self.numerics.clone(),
            set: self.set.clone(),
            duration_s: self.duration_s,
            out: self.out.clone(),
            seeds: self.seeds,
            jobs: self.jobs,
            progress: crate::terminal::progress(!self.json),
        }
    }
}

/// `attacks`.
#[derive(Debug, Args)]
pub struct AttacksArgs {
    /// Folder that receives `attacks.md`, `.csv`, `.json` and the bar chart; default a new
    /// folder `runs/<timestamp>-attacks`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Shorten every run to this many seconds (default: each scenario's own, 40 s). Most
    /// classes start at 10 s: a shorter run shows them without an onset.
    #[arg(long, allow_negative_numbers = true)]
    pub duration_s: Option<f64>,
    /// Print JSON instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// Base scenario (default: the embedded paper scenario): its robots, gains and numerics
    /// under every class (a class's own scenario file gives its attack and detectors only).
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    #[command(flatten)]
    pub numerics: NumericsArgs,
    #[command(flatten)]
    pub set: SetArgs,
}

/// `table1`.
pub fn table1(args: &TableArgs, stop: &Stop) -> Result<ExitCode> {
    let table = fdi_tables::tables::table1(&args.options(), stop)?;
    print(&table, args.json)
}

/// `table2`.
pub fn table2(args: &TableArgs, stop: &Stop) -> Result<ExitCode> {
    let table = fdi_tables::tables::table2(&args.options(), stop)?;
    print(&table, args.json)
}

/// `attacks`.
pub fn attacks(args: &AttacksArgs, stop: &Stop) -> Result<ExitCode> {
    let options = AttacksOptions {
        out: args.out.clone(),
        duration_s: args.duration_s,
        scenario: args.scenario.clone(),
        numerics: args.numerics.clone(),
        set: args.set.clone(),
        progress: crate::terminal::progress(!args.json),
    };
    let table = fdi_tables::attacks::attacks(&options, stop)?;
    print(&table, args.json)
}

/// A table written: its JSON with `--json`, else its markdown and where it was written.
fn print(table: &Table, json: bool) -> Result<ExitCode> {
    if json {
        println!("{}", table.json);
    } else {
        print!("{}", table.md);
        println!("\ntable written to {}", table.dir.display());
    }
    Ok(ExitCode::SUCCESS)
}
