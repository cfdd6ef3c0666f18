//! `fdi-launch serve`: this host's share of split runs (`fdi_split::serve`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Args;
use fdi_common::stop::Stop;
use fdi_split::serve::ServeOptions;

/// `serve`.
#[derive(Debug, Clone, Args)]
pub struct ServeArgs {
    /// The deployment file: the lab's hosts, their endpoints and certificates. The serve
    /// listens on its own host's endpoint and takes runs only from the lab's hosts.
    #[arg(long)]
    pub hosts: PathBuf,
    /// This host's name, as the deployment file names it (`hosts.<name>`).
    #[arg(long)]
    pub name: String,
    /// Where a run's processes keep their traces until the coordinator has them (a folder per
    /// run, removed at its release, or by the next serve if this one is killed). Default: the
    /// system's temporary folder.
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Serve this many runs, then exit (default: until interrupted).
    #[arg(long)]
    pub runs: Option<u64>,
}

/// `serve`.
pub fn serve(args: &ServeArgs, stop: &Stop) -> Result<ExitCode> {
    fdi_split::serve::serve(
        &ServeOptions {
            hosts: args.hosts.clone(),
            name: args.name.clone(),
            work_dir: args.work_dir.clone(),
            runs: args.runs,
        },
        stop,
    )?;
    Ok(ExitCode::SUCCESS)
}
