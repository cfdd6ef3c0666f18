//! Before a run: the trace size it would write, and the refusal of a run over the limit or
//! over the free space of its folder.

use std::path::Path;

use anyhow::{bail, Context, Result};
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::trace::{self, HopStamps, TraceRecord};
use fdi_report::traces::Traces;

/// The trace size a run would write, from records of its own scenario encoded by the trace
/// encoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Estimate {
    /// Bytes of every trace file together.
    pub bytes: u64,
    /// Records of the run's processes.
    pub records: u64,
    /// Bytes per tick of the run (every process, every agent).
    pub bytes_per_tick: u64,
}

/// Ticks of the sample run whose records are encoded.
const SAMPLE_TICKS: u64 = 16;

/// Estimates what a run of `r` on `ipc` (else the in-process engine) keeps with `traces`:
/// records per kept tick (per agent an agent, an attack and a center record; a torque record
/// when the attacker relays its torques; over IPC in realtime a latency record) × their encoded
/// sizes, taken from the first ticks of `r` run in process, plus a header per process.
pub fn estimate(r: &Resolved, ipc: bool, traces: Traces) -> Result<Estimate> {
    let mut sample = r.clone();
    sample.scenario.clock = ClockMode::Lockstep;
    sample.scenario.duration_s = SAMPLE_TICKS as f64 * r.scenario.control_period_s;
    // A controller program is not asked in process; the records of a built-in law have its
    // records' sizes (the same fields, numbers of fixed size).
    let controller = &mut sample.scenario.controller;
    if controller.mode == fdi_common::control::ControllerMode::External {
        controller.mode = fdi_common::control::ControllerMode::Traditional;
    }
    let (mut bytes, mut records, mut ticks) = (0u64, 0u64, 0u64);
    let mut failure = None;
    let latency = ipc && r.scenario.clock == ClockMode::Realtime;
    let now = fdi_runtime::ipc::monotonic_ns();
    let encode = |rec: &TraceRecord| trace::record_frame_bytes(rec);
    fdi_common::engine::run_inproc_any(&sample, |t| {
        let mut add = |rec: TraceRecord| match encode(&rec) {
            Ok(n) => {
                bytes += n;
                records += 1;
            }
            Err(e) => {
                failure.get_or_insert(e);
            }
        };
        add(TraceRecord::Agent(t.agent));
        add(TraceRecord::Attack(t.attack));
        add(TraceRecord::Center(t.center));
        if let Some(a) = t.actuation {
            add(TraceRecord::Actuation(a));
        }
        if latency {
            add(TraceRecord::Latency {
                k: t.agent.k,
                agent: t.agent.agent,
                stamps: HopStamps {
                    agent_sent_ns: now,
                    attacker_received_ns: now,
                    attacker_sent_ns: now,
                    center_received_ns: now,
                    center_sent_ns: now,
                    agent_received_ns: now,
                },
            });
        }
        ticks = ticks.max(t.agent.k + 1);
    })
    .context("estimating the trace size: the first ticks of the scenario")?;
    if let Some(e) = failure {
        bail!("estimating the trace size: cannot encode a record: {e}");
    }
    if ticks == 0 {
        bail!("estimating the trace size: the scenario's first ticks gave no record");
    }
    let kept = traces.kept_ticks(r.ticks());
    let bytes_per_tick = bytes.div_ceil(ticks);
    let records_per_tick = records.div_ceil(ticks);
    let mut total = kept.saturating_mul(bytes_per_tick);
    if traces != Traces::None {
        let processes = r.agent_count() as u64 + 2;
        let header = fdi_runtime::process::trace_header(fdi_common::run_dir::Process::CENTER, r);
        let h = trace::header_bytes(&header)
            .map_err(|e| anyhow::anyhow!("estimating the trace size: {e}"))?;
        total = total.saturating_add(processes * h);
    }
    Ok(Estimate {
        bytes: total,
        records: kept.saturating_mul(records_per_tick),
        bytes_per_tick,
    })
}

/// Free bytes for an unprivileged writer in the file system of `folder`, or of its nearest
/// existing ancestor (the folder may not exist yet).
pub fn free_space(folder: &Path) -> Result<u64> {
    let mut at = if folder.as_os_str().is_empty() {
        Path::new(".")
    } else {
        folder
    };
    loop {
        if at.exists() {
            break;
        }
        match at.parent() {
            Some(p) if !p.as_os_str().is_empty() => at = p,
            _ => {
                at = Path::new(".");
                break;
            }
        }
    }
    let st = rustix::fs::statvfs(at)
        .with_context(|| format!("reading the free space of {} (statvfs)", at.display()))?;
    Ok(st.f_bavail.saturating_mul(st.f_frsize))
}

/// Refuses, before anything of the run exists, a run whose traces would not fit: over `limit`
/// (`--max-trace-size`) or, unless `free_space_check` is off (`--no-space-check`), over the
/// free space of `out`.
pub fn check_volume(
    r: &Resolved,
    ipc: bool,
    traces: Traces,
    out: &Path,
    limit: bytesize::ByteSize,
    free_space_check: bool,
) -> Result<Estimate> {
    let e = estimate(r, ipc, traces)?;
    if traces == Traces::None {
        return Ok(e);
    }
    let free = free_space(out)?;
    let size = bytesize::ByteSize::b(e.bytes);
    let what = format!(
        "its traces would take about {size} ({} records of {} ticks kept, {} bytes per tick, `--traces {traces}`)",
        e.records,
        traces.kept_ticks(r.ticks()),
        e.bytes_per_tick
    );
    let ways = "`--traces decimate=K` keeps every K-th tick, `--traces none` no trace (the summary still covers every tick), a shorter `--duration-s`";
    if free_space_check && e.bytes > free {
        bail!(
            "refused before the start: {what}, more than the {} free in {}; {ways}, another `--out`, or `--no-space-check` (start anyway)",
            bytesize::ByteSize::b(free),
            out.display()
        );
    }
    if e.bytes > limit.as_u64() {
        bail!(
            "refused before the start: {what}, over the limit of {limit} (`--max-trace-size`, {} free in {}); {ways}, or a larger `--max-trace-size`",
            bytesize::ByteSize::b(free),
            out.display()
        );
    }
    Ok(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::num::NonZeroU32;

    #[test]
    fn the_estimate_of_the_paper_run_is_its_trace_size_and_decimation_divides_it() {
        let r = fdi_common::scenario::paper().expect("paper");
        let full = estimate(&r, false, Traces::Full).expect("estimate");
        // 40 000 ticks, 4 robots: tens of MB (an agent, an attack and a center record each).
        assert!((10_000_000..200_000_000).contains(&full.bytes), "{full:?}");
        let ten = estimate(
            &r,
            false,
            Traces::Decimate(NonZeroU32::new(10).expect("10")),
        )
        .expect("estimate");
        assert!(
            ten.bytes * 9 < full.bytes && ten.bytes * 11 > full.bytes,
            "{ten:?} {full:?}"
        );
        assert_eq!(estimate(&r, false, Traces::None).expect("none").bytes, 0);
    }

    #[test]
    fn an_oversized_run_is_refused_naming_its_estimate_the_free_space_and_the_flags() {
        let mut r = fdi_common::scenario::paper().expect("paper");
        r.scenario.duration_s = 1e6;
        let limit: bytesize::ByteSize = "10GB".parse().expect("size");
        let e = check_volume(&r, true, Traces::Full, Path::new("."), limit, true)
            .expect_err("1e6 s is over 10 GB");
        let text = e.to_string();
        for frag in [
            "refused before the start",
            "free in",
            "--traces none",
            "decimate=K",
        ] {
            assert!(text.contains(frag), "{frag}: {text}");
        }
        check_volume(&r, true, Traces::None, Path::new("."), limit, true)
            .expect("none keeps nothing");
    }
}
