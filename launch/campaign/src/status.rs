//! `fdi-launch sweep CAMPAIGN --status`: a campaign's progress across its shards, from the
//! folder they share (the stored results, the shards' records and leases), and the runs an
//! aggregate misses with the shard that owns each.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use fdi_common::engine::RunSummary;

use super::plan::Plan;
use super::shard::{self, Record, Shard, State};
use super::store::load_stored;
use super::tables::sig;
use fdi_orchestrator::run::Engine;

/// At most this many runs are named per shard; the others are counted.
const NAMED: usize = 8;

/// One shard's progress.
struct Progress {
    shard: Shard,
    /// Its runs (one per key) and how many of them have a stored result.
    runs: usize,
    done: usize,
    record: Option<Record>,
    live: shard::Liveness,
}

impl Progress {
    /// `running`, `finished`, `not started`, `stopped (…)`.
    fn state(&self) -> String {
        match (&self.record, &self.live) {
            (None, _) => "not started".into(),
            (Some(r), shard::Liveness::Live) if r.state == State::Running => "running".into(),
            (Some(r), shard::Liveness::Unknown) if r.state == State::Running => {
                "running? (its lease's age cannot be measured from here)".into()
            }
            (Some(r), _) if r.state == State::Running => {
                "stopped (its process is gone before its end)".into()
            }
            (Some(r), _) => match r.state {
                State::Finished if self.done < self.runs => "finished (with runs missing)".into(),
                State::Finished => "finished".into(),
                State::Failed => "ended with failed runs".into(),
                State::Interrupted => "interrupted".into(),
                State::Running => "running".into(),
            },
        }
    }
}

/// Says the campaign's progress in `out`, shard by shard.
pub(super) fn print(
    plan: &Plan,
    out: &Path,
    engine: Engine,
    said: &mut dyn FnMut(&str),
) -> Result<()> {
    let records = shard::records(out)?;
    let hash = shard::campaign_hash(plan);
    let expected = shard::Expected {
        hash: &hash,
        engine: engine.as_str(),
        count: None,
    };
    shard::check_records(&records, &expected, out)?;
    let results: Vec<Option<RunSummary>> =
        plan.jobs.iter().map(|j| load_stored(out, &j.key)).collect();
    // Runs of one key are one run.
    let unique = plan.unique_jobs(|_| true);
    let total = unique.len();
    let done = unique.iter().filter(|&&i| results[i].is_some()).count();
    let Some(count) = shard::count_of(&records, out)? else {
        said(&format!(
            "campaign {}: {done} of {total} runs done in {}; no shard has started there (no {}/K-of-N.json)",
            plan.name,
            out.display(),
            shard::SHARDS
        ));
        return Ok(());
    };
    let shards = progress(plan, out, &results, count, records)?;
    let walls: Vec<f64> = results.iter().flatten().map(|s| s.wall_s).collect();
    let mean = (!walls.is_empty()).then(|| walls.iter().sum::<f64>() / walls.len() as f64);
    let failed: usize = shards
        .iter()
        .filter_map(|p| p.record.as_ref())
        .map(|r| r.failures.len())
        .sum();
    said(&format!(
        "campaign {}: {done} of {total} runs done, {failed} failed, in {count} shards ({})",
        plan.name,
        out.display()
    ));
    said(&table(&shards, mean));
    for p in &shards {
        for f in p.record.iter().flat_map(|r| &r.failures) {
            said(&format!("shard {} failed: {}: {}", p.shard, f.run, f.error));
        }
    }
    said(&time_left(&shards, mean, walls.len()));
    Ok(())
}

/// Each shard's progress, in shard order.
fn progress(
    plan: &Plan,
    out: &Path,
    results: &[Option<RunSummary>],
    count: usize,
    records: Vec<Record>,
) -> Result<Vec<Progress>> {
    let owners = shard::owners(plan, count);
    let mut shards: Vec<Progress> = (1..=count)
        .map(|index| -> Result<Progress> {
            let shard = Shard::new(index, count)?;
            Ok(Progress {
                shard,
                runs: 0,
                done: 0,
                record: None,
                live: shard::liveness(out, shard),
            })
        })
        .collect::<Result<_>>()?;
    for i in plan.unique_jobs(|_| true) {
        let p = &mut shards[owners[i] - 1];
        p.runs += 1;
        p.done += usize::from(results[i].is_some());
    }
    for r in records {
        let i = r.shard.index - 1;
        shards[i].record = Some(r);
    }
    Ok(shards)
}

/// The table of shards: runs, done, failed, state, host and time left.
fn table(shards: &[Progress], mean: Option<f64>) -> String {
    let mut rows = vec![[
        "shard".to_string(),
        "runs".into(),
        "done".into(),
        "failed".into(),
        "state".into(),
        "host".into(),
        "time left".into(),
    ]];
    for p in shards {
        let r = p.record.as_ref();
        rows.push([
            p.shard.to_string(),
            p.runs.to_string(),
            p.done.to_string(),
            r.map_or(0, |r| r.failures.len()).to_string(),
            p.state(),
            r.map_or("-".into(), |r| format!("{} (pid {})", r.host, r.pid)),
            match (left_s(p, mean), &p.live) {
                (Some(s), shard::Liveness::Live) => format!("~{} s", sig(s)),
                _ => "-".into(),
            },
        ]);
    }
    let widths: Vec<usize> = (0..7)
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut s = String::new();
    for r in rows {
        let cells: Vec<String> = r
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c:<w$}"))
            .collect();
        let _ = writeln!(s, "{}", cells.join("  ").trim_end());
    }
    s.trim_end().to_string()
}

/// The seconds a shard still needs: its runs not done, in rounds of its runs at a time, × the
/// mean time of a finished run (of the whole campaign: runs of unequal cost make it rough).
fn left_s(p: &Progress, mean: Option<f64>) -> Option<f64> {
    let jobs = p.record.as_ref().map_or(1, |r| r.jobs.max(1));
    Some((p.runs - p.done).div_ceil(jobs) as f64 * mean?)
}

/// The line of the time left: the slowest running shard's, and what the shards not running
/// hold.
fn time_left(shards: &[Progress], mean: Option<f64>, finished: usize) -> String {
    if shards.iter().all(|p| p.done == p.runs) {
        return "every run is done: `--aggregate` makes the tables".into();
    }
    let Some(mean) = mean else {
        return "time left: unknown until a run has finished".into();
    };
    let running = shards
        .iter()
        .filter(|p| matches!(p.live, shard::Liveness::Live))
        .filter_map(|p| left_s(p, Some(mean)))
        .fold(None, |m: Option<f64>, s| Some(m.map_or(s, |m| m.max(s))));
    let idle: usize = shards
        .iter()
        .filter(|p| !matches!(p.live, shard::Liveness::Live))
        .map(|p| p.runs - p.done)
        .sum();
    let mut line = format!(
        "time left (from {finished} finished runs, {} s each on average):",
        sig(mean)
    );
    match running {
        Some(s) => {
            let _ = write!(line, " ~{} s for the running shards", sig(s));
        }
        None => line.push_str(" no shard is running"),
    }
    if idle > 0 {
        let _ = write!(
            line,
            "; {idle} runs of shards not running (~{} s of one core)",
            sig(idle as f64 * mean)
        );
    }
    line
}

/// The runs without a result, grouped by the shard that owns each (when the number of shards
/// is known), a few named per shard.
pub(super) fn missing(
    plan: &Plan,
    results: &[Option<RunSummary>],
    count: Option<usize>,
    records: &[Record],
    out: &Path,
) -> String {
    let owners = count.map(|n| shard::owners(plan, n));
    let mut groups: std::collections::BTreeMap<usize, Vec<&str>> = Default::default();
    for (i, (job, r)) in plan.jobs.iter().zip(results).enumerate() {
        if r.is_none() {
            let owner = owners.as_ref().map_or(0, |o| o[i]);
            groups.entry(owner).or_default().push(job.label.as_str());
        }
    }
    let mut s = String::new();
    for (owner, runs) in groups {
        let who = match count {
            Some(n) => {
                let record = records.iter().find(|r| r.shard.index == owner);
                let state = match Shard::new(owner, n) {
                    Ok(shard) => Progress {
                        shard,
                        runs: 0,
                        done: 0,
                        record: record.cloned(),
                        live: shard::liveness(out, shard),
                    }
                    .state(),
                    Err(_) => "?".into(),
                };
                let host = record.map_or(String::new(), |r| format!(" on {}", r.host));
                format!("shard {owner}/{n} ({state}{host})")
            }
            None => "no shard record in the folder: the campaign's unsharded run".into(),
        };
        let named: Vec<&str> = runs.iter().take(NAMED).copied().collect();
        let more = runs.len().saturating_sub(NAMED);
        let _ = writeln!(
            s,
            "  {who}: {} runs: {}{}",
            runs.len(),
            named.join("; "),
            if more > 0 {
                format!("; … and {more} more")
            } else {
                String::new()
            }
        );
    }
    s.trim_end().to_string()
}
