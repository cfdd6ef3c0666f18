//! What a run keeps of its traces (`--traces`): every record, every K-th tick, or none. The
//! metrics and the digest of the summary cover every tick whichever is chosen.

use std::fmt;
use std::num::NonZeroU32;
use std::path::Path;

use fdi_common::run_dir::RunDir;
use std::str::FromStr;

use anyhow::{bail, Result};
use fdi_common::trace::{Kept, TraceReader};

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
    let text =
        fdi_common::scenario::read_limited(&fdi_common::run_dir::RunDir::new(run_dir).summary())
            .ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v.get("traces")?.as_str().map(str::to_string)
}

/// What `run_dir` keeps of its traces: `none` when its summary says so, else what the headers
/// of its trace files say (they must agree). A trace that cannot be read is left to the reader
/// that needs it, which names the damage.
pub fn recorded(run: &RunDir) -> Result<Recorded> {
    let run_dir = run.path();
    if summary_says(run_dir).as_deref() == Some("none") {
        return Ok(Recorded::None);
    }
    let dir = run.traces();
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
pub fn require_every_tick(run: &RunDir, what: &str) -> Result<()> {
    let run_dir = run.path();
    match recorded(run)? {
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
