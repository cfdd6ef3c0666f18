//! `fdi-launch runs list|prune`: the run directories of a folder, and removing the older ones.
//! Only folders that are run directories are ever listed or removed: a folder with a
//! `scenario.toml` file and a `summary.json` file or a `traces/` folder; anything else in the
//! folder is left alone.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use bytesize::ByteSize;

/// One run directory.
#[derive(Debug, Clone)]
pub struct RunDir {
    pub path: PathBuf,
    pub name: String,
    /// Its last modification (of the folder or of its summary), for the order.
    pub modified: std::time::SystemTime,
    pub bytes: u64,
    /// `done`, `partial (…)`, `no summary` or `summary unreadable`.
    pub status: String,
}

/// True for a folder that `fdi-launch run` made: `scenario.toml` and `summary.json` or
/// `traces/`. Symbolic links are not followed.
pub fn is_run_dir(p: &Path) -> bool {
    let is = |q: &Path, dir: bool| {
        std::fs::symlink_metadata(q).is_ok_and(|m| if dir { m.is_dir() } else { m.is_file() })
    };
    is(p, true)
        && is(&p.join("scenario.toml"), false)
        && (is(&p.join("summary.json"), false) || is(&p.join("traces"), true))
}

/// Bytes of the files under `p` (symbolic links not followed).
fn size_of(p: &Path) -> u64 {
    let Ok(m) = std::fs::symlink_metadata(p) else {
        return 0;
    };
    if !m.is_dir() {
        return m.len();
    }
    std::fs::read_dir(p)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| size_of(&e.path()))
        .sum()
}

fn status(p: &Path) -> String {
    let Ok(text) = fdi_common::scenario::read_limited(&p.join("summary.json")) else {
        return "no summary".into();
    };
    let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) else {
        return "summary unreadable".into();
    };
    let traces = v
        .get("traces")
        .and_then(|t| t.as_str())
        .map_or(String::new(), |t| format!(", traces {t}"));
    match v
        .get("partial")
        .and_then(|x| x.get("reason"))
        .and_then(|r| r.as_str())
    {
        Some(reason) => format!("partial ({reason}){traces}"),
        None => format!("done{traces}"),
    }
}

/// The run directories of `out`, newest first.
pub fn list(out: &Path) -> Result<Vec<RunDir>> {
    let entries = std::fs::read_dir(out)
        .with_context(|| format!("reading the runs folder {}", out.display()))?;
    let mut runs = Vec::new();
    for e in entries {
        let e = e.with_context(|| format!("reading the runs folder {}", out.display()))?;
        let path = e.path();
        if !is_run_dir(&path) {
            continue;
        }
        let stamp = |q: &Path| std::fs::metadata(q).and_then(|m| m.modified()).ok();
        let modified = stamp(&path.join("summary.json"))
            .or_else(|| stamp(&path.join("scenario.toml")))
            .or_else(|| stamp(&path))
            .unwrap_or(std::time::UNIX_EPOCH);
        runs.push(RunDir {
            name: e.file_name().to_string_lossy().into_owned(),
            bytes: size_of(&path),
            status: status(&path),
            path,
            modified,
        });
    }
    // Newest first; names (which start with the UTC time of the run) break ties.
    runs.sort_by(|a, b| b.modified.cmp(&a.modified).then(b.name.cmp(&a.name)));
    Ok(runs)
}

fn date(t: std::time::SystemTime) -> String {
    jiff::Timestamp::try_from(t)
        .map(|ts| ts.strftime("%Y-%m-%d %H:%M:%S UTC").to_string())
        .unwrap_or_else(|_| "?".into())
}

/// `runs list`: a line per run directory, newest first.
pub fn print_list(out: &Path) -> Result<()> {
    let runs = list(out)?;
    if runs.is_empty() {
        println!("no run directories in {}", out.display());
        return Ok(());
    }
    let total: u64 = runs.iter().map(|r| r.bytes).sum();
    for r in &runs {
        println!(
            "{}  {}  {:>10}  {}",
            r.name,
            date(r.modified),
            ByteSize::b(r.bytes).to_string(),
            r.status
        );
    }
    println!(
        "{} run directories in {}, {}",
        runs.len(),
        out.display(),
        ByteSize::b(total)
    );
    Ok(())
}

/// What `prune` removed (or would remove, on a dry run).
#[derive(Debug)]
pub struct Pruned {
    pub removed: Vec<RunDir>,
    pub kept: usize,
}

/// `runs prune`: keeps the `keep` newest run directories of `out`, removes the others (only
/// run directories); `dry_run` removes nothing and says what it would.
pub fn prune(out: &Path, keep: usize, dry_run: bool) -> Result<Pruned> {
    let runs = list(out)?;
    let kept = runs.len().min(keep);
    let mut removed = Vec::new();
    for r in runs.into_iter().skip(keep) {
        // Checked again at the moment of removal: only a run directory goes.
        if !is_run_dir(&r.path) {
            continue;
        }
        if !dry_run {
            std::fs::remove_dir_all(&r.path)
                .with_context(|| format!("removing the run directory {}", r.path.display()))?;
        }
        removed.push(r);
    }
    Ok(Pruned { removed, kept })
}

/// `runs prune`, printed.
pub fn print_prune(out: &Path, keep: usize, dry_run: bool) -> Result<()> {
    if !out.is_dir() {
        bail!("{}: not a folder of run directories", out.display());
    }
    let p = prune(out, keep, dry_run)?;
    let verb = if dry_run { "would remove" } else { "removed" };
    for r in &p.removed {
        println!(
            "{verb} {} ({}, {})",
            r.path.display(),
            ByteSize::b(r.bytes),
            r.status
        );
    }
    let freed: u64 = p.removed.iter().map(|r| r.bytes).sum();
    println!(
        "{verb} {} run directories, {} {}; kept the {} newest",
        p.removed.len(),
        ByteSize::b(freed),
        if dry_run { "would be freed" } else { "freed" },
        p.kept
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_dir(root: &Path, name: &str, summary: bool) -> PathBuf {
        let d = root.join(name);
        std::fs::create_dir_all(d.join("traces")).expect("mkdir");
        std::fs::write(d.join("scenario.toml"), "name = \"x\"\n").expect("scenario");
        std::fs::write(d.join("traces").join("agent-1.trace"), vec![0u8; 1000]).expect("trace");
        if summary {
            std::fs::write(d.join("summary.json"), "{}").expect("summary");
        }
        d
    }

    #[test]
    fn prune_keeps_the_newest_and_never_touches_what_is_not_a_run_directory() {
        let root = tempfile::tempdir().expect("tmp");
        let r = root.path();
        let mut made = Vec::new();
        for (i, name) in [
            "20240101-000000-a",
            "20240102-000000-b",
            "20240103-000000-c",
        ]
        .iter()
        .enumerate()
        {
            let d = run_dir(r, name, i != 1);
            made.push(d);
            // Distinct modification times, oldest first.
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        // Not run directories: a folder with a scenario only, one with data, a file.
        std::fs::create_dir_all(r.join("notes")).expect("mkdir");
        std::fs::write(r.join("notes").join("scenario.toml"), "x").expect("w");
        std::fs::create_dir_all(r.join("data/traces")).expect("mkdir");
        std::fs::write(r.join("README"), "keep me").expect("w");

        let dry = prune(r, 1, true).expect("dry run");
        assert_eq!(dry.removed.len(), 2);
        assert!(made.iter().all(|d| d.is_dir()), "a dry run removes nothing");

        let p = prune(r, 1, false).expect("prune");
        let names: Vec<&str> = p.removed.iter().map(|x| x.name.as_str()).collect();
        assert_eq!(names, vec!["20240102-000000-b", "20240101-000000-a"]);
        assert!(p.removed.iter().all(|x| x.bytes >= 1000));
        assert!(made[2].is_dir() && !made[1].exists() && !made[0].exists());
        assert!(r.join("notes/scenario.toml").is_file());
        assert!(r.join("data/traces").is_dir());
        assert!(r.join("README").is_file());
        assert_eq!(prune(r, 0, false).expect("all").removed.len(), 1);
        assert!(r.join("notes").is_dir() && r.join("data").is_dir());
    }
}
