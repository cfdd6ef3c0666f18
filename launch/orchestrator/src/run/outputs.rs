//! `fdi-launch runs list`: every output folder the commands made in a folder (`--out`, default
//! `runs`), each with its kind, and the space they take as `du` counts it.
//!
//! A folder is told by what its command writes (symbolic links are not followed):
//!
//! | kind | made by | told by |
//! |---|---|---|
//! | `run` | `run`, `detect SCENARIO`, `run --replay`, `bench latency` | [`is_run_dir`] |
//! | `table1`, `table2` | `table1`, `table2` | `table1.json` (`table2.json`), or the name `<timestamp>-table1` of one not finished |
//! | `attacks` | `attacks` | `attacks.json`, or the name `<timestamp>-attacks` |
//! | `bench-lockstep` | `bench lockstep` | `lockstep.json`, or the name `<timestamp>-bench-lockstep` |
//! | `campaign` | `sweep` | `campaign.toml` and `points/`; the campaigns of `campaigns/` (sweep's default folder) are listed as `campaigns/<name>` |
//! | `detect` | `detect --out DIR` | `roc.csv` |
//! | `half-removed` | an interrupted `runs prune` | the name `<run>.pruning` |
//!
//! Anything else is counted apart ("other"), never listed as an output: `runs prune` leaves it
//! alone.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use anyhow::{Context, Result};
use bytesize::ByteSize;
use serde::Serialize;

use super::disk::{usage, usage_of};
use super::runs::{is_run_dir, is_tombstone, run_modified, run_status};

/// What made an output folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    Run,
    Table1,
    Table2,
    Attacks,
    BenchLockstep,
    Campaign,
    Detect,
    /// A run directory that `runs prune` began to remove.
    HalfRemoved,
}

impl Kind {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Run => "run",
            Self::Table1 => "table1",
            Self::Table2 => "table2",
            Self::Attacks => "attacks",
            Self::BenchLockstep => "bench-lockstep",
            Self::Campaign => "campaign",
            Self::Detect => "detect",
            Self::HalfRemoved => "half-removed",
        }
    }
}

/// The folders a command writes whole at its end: the kind, the file that says it is done,
/// and the name its folder gets (`<timestamp>-<name>`) when `--out` does not name it.
const FINISHED_BY: [(Kind, &str, Option<&str>); 5] = [
    (Kind::Table1, "table1.json", Some("table1")),
    (Kind::Table2, "table2.json", Some("table2")),
    (Kind::Attacks, "attacks.json", Some("attacks")),
    (Kind::BenchLockstep, "lockstep.json", Some("bench-lockstep")),
    (Kind::Detect, "roc.csv", None),
];

/// The folder of `sweep`'s campaigns when `--out` does not name one.
const CAMPAIGNS: &str = "campaigns";

/// One output folder.
#[derive(Debug, Clone, Serialize)]
pub struct Output {
    /// Its path under the listed folder: `<name>`, or `campaigns/<name>`.
    pub name: String,
    pub kind: Kind,
    pub path: PathBuf,
    /// Its last modification (of the file that finished it, or of the folder), UTC.
    pub modified: String,
    #[serde(skip)]
    modified_at: SystemTime,
    /// The blocks it takes on disk, bytes, as `du -s` counts them.
    pub bytes: u64,
    /// `done`, `partial (…)`, `unfinished: no table1.json`, `12 runs stored, tables written`, ….
    pub status: String,
}

/// An entry of the listed folder that no command made.
#[derive(Debug, Clone, Serialize)]
pub struct Other {
    pub path: PathBuf,
    pub bytes: u64,
}

/// What [`list`] found in a folder.
#[derive(Debug, Clone, Serialize)]
pub struct Listing {
    pub folder: PathBuf,
    /// Newest first.
    pub outputs: Vec<Output>,
    pub other: Vec<Other>,
    /// The whole folder as `du -s` counts it (its own blocks included, hard links once).
    pub bytes: u64,
    /// Paths that could not be read: their space is left out of the sizes (and said so).
    pub unreadable: Vec<PathBuf>,
}

/// `<timestamp>-<name>`, the timestamp `YYYYMMDD-HHMMSS` ([`crate::run_dirs::timestamp`]).
fn stamped(file_name: &str, name: &str) -> bool {
    let b = file_name.as_bytes();
    file_name.len() == 16 + name.len()
        && file_name.ends_with(name)
        && b[..8].iter().all(u8::is_ascii_digit)
        && b[8] == b'-'
        && b[9..15].iter().all(u8::is_ascii_digit)
        && b[15] == b'-'
}

fn is(p: &Path, dir: bool) -> bool {
    std::fs::symlink_metadata(p).is_ok_and(|m| if dir { m.is_dir() } else { m.is_file() })
}

/// The kind of folder `p` is, if a command made it.
pub fn kind_of(p: &Path) -> Option<Kind> {
    if !is(p, true) {
        return None;
    }
    if is_tombstone(p) {
        return Some(Kind::HalfRemoved);
    }
    if is_run_dir(p) {
        return Some(Kind::Run);
    }
    if is(&p.join("campaign.toml"), false) && is(&p.join("points"), true) {
        return Some(Kind::Campaign);
    }
    let name = p.file_name()?.to_string_lossy();
    FINISHED_BY
        .iter()
        .find(|(_, marker, named)| {
            is(&p.join(marker), false) || named.is_some_and(|n| stamped(&name, n))
        })
        .map(|(kind, _, _)| *kind)
}

/// The run directories directly in `p`.
fn runs_in(p: &Path) -> usize {
    std::fs::read_dir(p)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| is_run_dir(&e.path()))
        .count()
}

fn modified(p: &Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

/// The status and last modification of the output `p` of `kind`.
fn status(p: &Path, kind: Kind) -> (String, SystemTime) {
    let folder = modified(p).unwrap_or(SystemTime::UNIX_EPOCH);
    let with_runs = |s: String| match runs_in(p) {
        0 => s,
        n => format!("{s}, {n} run directories in it"),
    };
    match kind {
        Kind::Run => (run_status(p), run_modified(p)),
        Kind::HalfRemoved => (
            "an earlier `runs prune` could not remove it whole; the next one tries again".into(),
            folder,
        ),
        Kind::Campaign => {
            let stored = std::fs::read_dir(p.join("points"))
                .into_iter()
                .flatten()
                .flatten()
                .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
                .count();
            let tables = if is(&p.join("aggregate.csv"), false) {
                "tables written"
            } else {
                "no tables yet"
            };
            (
                with_runs(format!("{stored} runs stored, {tables}")),
                modified(&p.join("aggregate.csv")).unwrap_or(folder),
            )
        }
        _ => {
            let marker = FINISHED_BY
                .iter()
                .find(|(k, _, _)| *k == kind)
                .map_or("", |(_, m, _)| *m);
            match modified(&p.join(marker)) {
                Some(t) if is(&p.join(marker), false) => (with_runs("done".into()), t),
                _ => (with_runs(format!("unfinished: no {marker}")), folder),
            }
        }
    }
}

fn output(name: String, path: PathBuf, kind: Kind) -> Output {
    let bytes = usage_of(&path).bytes;
    let (status, modified_at) = status(&path, kind);
    Output {
        name,
        kind,
        modified: date(modified_at),
        modified_at,
        bytes,
        status,
        path,
    }
}

/// The entries of `dir`, by name.
fn entries(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        found.push(
            e.with_context(|| format!("reading {}", dir.display()))?
                .path(),
        );
    }
    found.sort();
    Ok(found)
}

/// Every output folder of `out` (and of its `campaigns/`), newest first, and what else is there.
pub fn list(out: &Path) -> Result<Listing> {
    let mut listing = Listing {
        folder: out.to_path_buf(),
        outputs: Vec::new(),
        other: Vec::new(),
        bytes: 0,
        unreadable: Vec::new(),
    };
    let name_of = |p: &Path| {
        p.file_name().map_or_else(
            || p.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    };
    for p in entries(out)? {
        if let Some(kind) = kind_of(&p) {
            listing.outputs.push(output(name_of(&p), p, kind));
        } else if name_of(&p) == CAMPAIGNS && is(&p, true) {
            for c in entries(&p)? {
                match kind_of(&c) {
                    Some(Kind::Campaign) => {
                        let name = format!("{CAMPAIGNS}/{}", name_of(&c));
                        listing.outputs.push(output(name, c, Kind::Campaign));
                    }
                    _ => listing.other.push(Other {
                        bytes: usage_of(&c).bytes,
                        path: c,
                    }),
                }
            }
        } else {
            listing.other.push(Other {
                bytes: usage_of(&p).bytes,
                path: p,
            });
        }
    }
    // Once more as a whole: a file hard-linked into two of its folders counts once here.
    let whole = usage(out, &mut HashSet::new());
    listing.bytes = whole.bytes;
    listing.unreadable = whole.unreadable;
    // Newest first; names (which start with the UTC time of the command) break ties.
    listing
        .outputs
        .sort_by(|a, b| b.modified_at.cmp(&a.modified_at).then(b.name.cmp(&a.name)));
    Ok(listing)
}

pub(super) fn date(t: SystemTime) -> String {
    jiff::Timestamp::try_from(t)
        .map(|ts| ts.strftime("%Y-%m-%d %H:%M:%S").to_string())
        .unwrap_or_else(|_| "?".into())
}

/// The count of each kind, in the order of [`Kind`]: `3 run, 1 table1`.
pub fn counts(outputs: &[Output]) -> String {
    let mut kinds: Vec<Kind> = outputs.iter().map(|o| o.kind).collect();
    kinds.sort();
    kinds.dedup();
    kinds
        .iter()
        .map(|k| {
            let n = outputs.iter().filter(|o| o.kind == *k).count();
            format!("{n} {}", k.as_str())
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The table of `runs list`: a header, then a row per output, columns aligned.
pub fn table(listing: &Listing) -> String {
    let head = ["NAME", "KIND", "MODIFIED (UTC)", "SIZE", "STATUS"];
    let rows: Vec<[String; 5]> = listing
        .outputs
        .iter()
        .map(|o| {
            [
                o.name.clone(),
                o.kind.as_str().into(),
                o.modified.clone(),
                ByteSize::b(o.bytes).to_string(),
                o.status.clone(),
            ]
        })
        .collect();
    let width = |i: usize| {
        rows.iter()
            .map(|r| r[i].chars().count())
            .chain([head[i].len()])
            .max()
            .unwrap_or(0)
    };
    let (w0, w1, w2, w3) = (width(0), width(1), width(2), width(3));
    let mut text = String::new();
    let mut line = |c: [&str; 5]| {
        text.push_str(
            format!(
                "{:<w0$}  {:<w1$}  {:<w2$}  {:>w3$}  {}",
                c[0], c[1], c[2], c[3], c[4]
            )
            .trim_end(),
        );
        text.push('\n');
    };
    line(head);
    for r in &rows {
        line([&r[0], &r[1], &r[2], &r[3], &r[4]]);
    }
    text
}
