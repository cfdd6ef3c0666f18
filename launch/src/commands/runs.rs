//! `fdi-launch runs list` and `runs prune`: the output folders of a folder
//! (`fdi_orchestrator::run::outputs`) and the removal of the older run directories
//! (`fdi_orchestrator::run::runs`), printed.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{bail, Result};
use bytesize::ByteSize;
use fdi_orchestrator::run::{outputs, runs};

/// `runs list`: the table, what else the folder holds, and the total as `du -s` counts it.
pub fn list(out: &Path, json: bool) -> Result<ExitCode> {
    let listing = outputs::list(out)?;
    if json {
        println!("{}", serde_json::to_string(&listing)?);
        return Ok(ExitCode::SUCCESS);
    }
    if listing.outputs.is_empty() {
        println!("no output folders of fdi-launch in {}", out.display());
    } else {
        print!("{}", outputs::table(&listing));
    }
    if !listing.other.is_empty() {
        let bytes: u64 = listing.other.iter().map(|o| o.bytes).sum();
        println!(
            "{} other entries ({}), not made by fdi-launch: `runs prune` leaves them alone",
            listing.other.len(),
            ByteSize::b(bytes)
        );
    }
    for p in &listing.unreadable {
        eprintln!(
            "fdi-launch: warning: {} could not be read: its space is not counted",
            p.display()
        );
    }
    println!(
        "{} output folders in {} ({}); {} on disk in all, as `du -s` counts it (the blocks \
         allocated, a file with several hard links once)",
        listing.outputs.len(),
        out.display(),
        if listing.outputs.is_empty() {
            "none".into()
        } else {
            outputs::counts(&listing.outputs)
        },
        ByteSize::b(listing.bytes)
    );
    Ok(ExitCode::SUCCESS)
}

/// How many causes of one run directory are printed (the rest are counted).
const CAUSES_SHOWN: usize = 5;

/// `runs prune`, printed. An error at the end when something could not be removed whole (each
/// named on stderr with its cause).
pub fn prune(out: &Path, keep: usize, dry_run: bool) -> Result<ExitCode> {
    if !out.is_dir() {
        bail!("{}: not a folder of run directories", out.display());
    }
    let p = runs::prune(out, keep, dry_run)?;
    let verb = if dry_run { "would remove" } else { "removed" };
    for r in &p.removed {
        println!(
            "{verb} {} ({}, {})",
            r.path.display(),
            ByteSize::b(r.bytes),
            r.status
        );
    }
    for t in &p.cleared {
        println!(
            "{verb} {} (left half-removed by an earlier prune)",
            t.display()
        );
    }
    for f in &p.failed {
        for (path, e) in f.causes.iter().take(CAUSES_SHOWN) {
            eprintln!(
                "fdi-launch: could not remove {}: {}",
                path.display(),
                fdi_report::io_cause::describe(e)
            );
        }
        if f.causes.len() > CAUSES_SHOWN {
            eprintln!(
                "fdi-launch: … and {} more paths under {}",
                f.causes.len() - CAUSES_SHOWN,
                f.left.display()
            );
        }
        if f.left == f.path {
            eprintln!("fdi-launch: {} is left as it was", f.path.display());
        } else {
            eprintln!(
                "fdi-launch: what is left of {} stays as {} (`runs list` shows it, the next `runs prune` tries again)",
                f.path.display(),
                f.left.display()
            );
        }
    }
    let freed: u64 = p.removed.iter().map(|r| r.bytes).sum();
    println!(
        "{verb} {} run directories, {} {}; kept the {} newest",
        p.removed.len(),
        ByteSize::b(freed),
        if dry_run { "would be freed" } else { "freed" },
        p.kept
    );
    if !p.failed.is_empty() {
        let names: Vec<String> = p
            .failed
            .iter()
            .map(|f| f.left.display().to_string())
            .collect();
        bail!(
            "{} run directories could not be removed whole (the paths and causes are above): {}",
            p.failed.len(),
            names.join(", ")
        );
    }
    Ok(ExitCode::SUCCESS)
}
