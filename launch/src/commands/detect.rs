//! `fdi-launch detect TARGET`: a run directory is swept as it is; a scenario is run first, by
//! `run`'s own code path, then its run directory is swept (`fdi_report::detect`).

use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use fdi_common::stop::Stop;
use fdi_report::detect::{sweep_run, WHILE_SWEEPING};

use crate::cli::DetectArgs;

/// `detect`.
pub fn detect(args: &DetectArgs, stop: &Stop) -> Result<ExitCode> {
    let target = &args.target;
    let meta = std::fs::metadata(target).with_context(|| format!("{}", target.display()))?;
    let (run_dir, run_code) = if meta.is_dir() {
        let flags = args.run_flags();
        if !flags.is_empty() {
            bail!(
                "{} apply to a scenario TARGET; {} is a run directory, whose recorded run is swept as it is",
                flags.join(", "),
                target.display()
            );
        }
        (target.clone(), None)
    } else {
        eprintln!(
            "fdi-launch: detect: running {} once (as `run` does), then sweeping its records",
            target.display()
        );
        let done = super::run::run_scenario(&args.run_args(), stop)?;
        stop.check(WHILE_SWEEPING)?;
        if !done.clean {
            eprintln!(
                "fdi-launch: detect: the run of {} was not a clean success; its records are swept all the same, and the run's exit status is kept",
                target.display()
            );
        }
        (done.dir, Some(done.code))
    };
    sweep_run(&run_dir, args.out.as_deref(), args.points, stop)?;
    Ok(run_code.unwrap_or(ExitCode::SUCCESS))
}
