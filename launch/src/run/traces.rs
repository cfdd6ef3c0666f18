//! What a run keeps of its traces (`--traces`): every record, every K-th tick, or none. The
//! metrics and the digest of the summary cover every tick whichever is chosen.

use std::fmt;
use std::num::NonZeroU32;
use std::path::Path;
use std::str::FromStr;

use anyhow::{bail, Context, Result};
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::trace::{self, HopStamps, Kept, TraceReader, TraceRecord};

/// `--traces full|decimate=K|none`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Traces {
    /// Every record of every process.
    #[default]
    Full,
    /// The records of every K-th tick (ticks 0, K, 2K, …), and every event.
    Decimate(NonZeroU32),
    /// No trace files; the summary only.
    None,
}

impl FromStr for Traces {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "full" => Ok(Self::Full),
            "none" => Ok(Self::None),
            _ => match s.strip_prefix("decimate=") {
                Some(k) => k
                    .parse::<NonZeroU32>()
                    .map(Self::Decimate)
                    .map_err(|_| format!("decimate=K takes a whole number K ≥ 1, not {k:?}")),
                None => Err(format!("{s:?} is not full, decimate=K (K ≥ 1) or none")),
            },
        }
    }
}

impl fmt::Display for Traces {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Full => f.write_str("full"),
            Self::Decimate(k) => write!(f, "decimate={k}"),
            Self::None => f.write_str("none"),
        }
    }
}

impl Traces {
    /// How many of `ticks` ticks the run directory keeps records of.
    pub fn kept_ticks(self, ticks: u64) -> u64 {
        match self {
            Self::Full => ticks,
            Self::Decimate(k) => ticks.div_ceil(u64::from(k.get())),
            Self::None => 0,
        }
    }
}

/// What a run directory holds of its traces, as its trace headers and its summary say.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Recorded {
    /// Every record (or traces written before `--traces` existed).
    Full,
    /// The records of every K-th tick.
    Decimated(u32),
    /// None: the run was made with `--traces none`.
    None,
}

/// The `traces` field of a run directory's `summary.json`, if it has one.
fn summary_says(run_dir: &Path) -> Option<String> {
    let text = fdi_common::scenario::read_limited(&run_dir.join("summary.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v.get("traces")?.as_str().map(str::to_string)
}

/// What `run_dir` keeps of its traces: `none` when its summary says so, else what the headers
/// of its trace files say (they must agree). A trace that cannot be read is left to the reader
/// that needs it, which names the damage.
pub fn recorded(run_dir: &Path) -> Result<Recorded> {
    if summary_says(run_dir).as_deref() == Some("none") {
        return Ok(Recorded::None);
    }
    let dir = run_dir.join("traces");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(Recorded::Full);
    };
    let mut found: Option<(Kept, std::path::PathBuf)> = None;
    let mut paths: Vec<_> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "trace"))
        .collect();
    paths.sort();
    for p in paths {
        let Ok(r) = TraceReader::open(&p) else {
            continue;
        };
        let kept = r.header().kept;
        match &found {
            Some((k, first)) if *k != kept => bail!(
                "{} keeps {kept} but {} keeps {k}: the traces of run {} do not agree on what they kept",
                p.display(),
                first.display(),
                run_dir.display()
            ),
            Some(_) => {}
            None => found = Some((kept, p)),
        }
    }
    Ok(match found {
        Some((Kept::Decimate { every }, _)) => Recorded::Decimated(every),
        _ => Recorded::Full,
    })
}

/// Refuses a run directory whose traces do not hold every tick, for `what` (`detect`, `run
/// --replay`): they need every record.
pub fn require_every_tick(run_dir: &Path, what: &str) -> Result<()> {
    match recorded(run_dir)? {
        Recorded::Full => Ok(()),
        Recorded::Decimated(k) => bail!(
            "{}: its traces keep every {k}-th tick only (`--traces decimate={k}`); {what} needs every tick: run it again with `--traces full`",
            run_dir.display()
        ),
        Recorded::None => bail!(
            "{}: the run kept no traces (`--traces none`); {what} needs every tick: run it again with `--traces full`",
            run_dir.display()
        ),
    }
}

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
        let header = fdi_runtime::process::trace_header("control-center", r);
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

    #[test]
    fn kept_ticks_count_ticks_zero_k_2k() {
        let k = |n| Traces::Decimate(NonZeroU32::new(n).expect("non-zero"));
        assert_eq!(Traces::Full.kept_ticks(40_000), 40_000);
        assert_eq!(k(10).kept_ticks(40_000), 4_000);
        assert_eq!(k(10).kept_ticks(40_001), 4_001);
        assert_eq!(k(3).kept_ticks(1), 1);
        assert_eq!(Traces::None.kept_ticks(40_000), 0);
    }

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

    #[test]
    fn parses_what_it_prints_and_refuses_the_rest() {
        for t in [
            Traces::Full,
            Traces::None,
            Traces::Decimate(NonZeroU32::new(10).expect("non-zero")),
        ] {
            assert_eq!(t.to_string().parse::<Traces>(), Ok(t));
        }
        for bad in ["", "decimate=0", "decimate=", "decimate=-3", "some"] {
            assert!(bad.parse::<Traces>().is_err(), "{bad}");
        }
    }
}
