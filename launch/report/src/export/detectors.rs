//! The detectors' statistics of a run's traces, for both exports (`detectors.csv`, the
//! `/agent<id>/detectors` topics): the traces joined as `fdi-launch detect` joins them, each
//! joined tick's statistics ([`crate::topics::detectors::Stats`]) handed on at once.

use std::cell::Cell;
use std::path::Path;

use anyhow::{bail, Context, Result};
use fdi_common::records::TickRecord;

use crate::join;
use crate::topics::detectors::{Stats, Tick};
use crate::topics::RunInfo;
use crate::traces::{recorded, Recorded};

pub(super) use crate::topics::detectors::names;
pub(super) use crate::topics::fields_of;

/// Hands `emit` every joined tick of the traces of `run_dir` with its detectors' statistics,
/// in the join's order (tick, then robot). The number of ticks handed on, or the line that
/// says why there are none: traces that keep every K-th tick only (`--traces decimate=K`)
/// cannot give them (a detector's statistic follows every tick), and none is made up. The
/// first error of `emit` stops the join and is the error. The join's warnings go to stderr (a
/// damaged trace is named by the export of its own records).
pub(super) fn each_tick(
    run_dir: &Path,
    info: &RunInfo,
    mut emit: impl FnMut(&Tick) -> Result<()>,
) -> Result<Result<u64, String>> {
    if let Recorded::Decimated(k) = recorded(&fdi_common::run_dir::RunDir::new(run_dir))? {
        return Ok(Err(format!(
            "no detector statistics: the traces keep every {k}-th tick only \
             (`--traces decimate={k}`) and the detectors need every tick"
        )));
    }
    let mut stats = Stats::new(info);
    let mut n = 0;
    // The first error of `emit`: it stops the join and is the error.
    let mut failure: Option<anyhow::Error> = None;
    let stopped = Cell::new(false);
    let joined = join::join_run_until(
        &info.resolved,
        run_dir,
        f64::NAN,
        |r: &TickRecord| {
            if failure.is_some() {
                return;
            }
            let Some(tick) = stats.observe(info, r) else {
                return;
            };
            match emit(&tick) {
                Ok(()) => n += 1,
                Err(e) => {
                    failure = Some(e);
                    stopped.set(true);
                }
            }
        },
        || {
            if stopped.get() {
                bail!("a detector statistic could not be written");
            }
            Ok(())
        },
    );
    if let Some(e) = failure {
        return Err(e);
    }
    let joined = joined.with_context(|| {
        format!(
            "joining the traces in {} for the detector statistics",
            fdi_common::run_dir::RunDir::new(run_dir).traces().display()
        )
    })?;
    for warning in &joined.warnings {
        log::warn!("detector statistics: {warning}");
    }
    Ok(Ok(n))
}
