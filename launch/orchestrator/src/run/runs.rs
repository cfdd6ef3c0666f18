//! `fdi-launch runs prune`: removing the older run directories of a folder (`runs list`, which
//! lists every kind of output folder, is [`super::outputs`]). Only folders that are run
//! directories are ever removed: a folder with a `scenario.toml` file and a `summary.json` file
//! or a `traces/` folder; anything else in the folder is left alone.
//!
//! Prune first renames a run directory `<name>` to `<name>.pruning` (one atomic rename: the
//! folder is a run directory or a tombstone, never something in between), then removes that.
//! What it cannot remove (a file it may not delete, a read-only mount) is named with the cause
//! and the tombstone stays: `runs list` shows it, the next `runs prune` tries it again, and
//! prune goes on with the other run directories. A rename that fails leaves the run directory
//! as it was (and named).

use std::io;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::disk::usage_of;

/// One run directory.
#[derive(Debug, Clone)]
pub struct RunDir {
    pub path: PathBuf,
    pub name: String,
    /// Its last modification (of the folder or of its summary), for the order.
    pub modified: std::time::SystemTime,
    /// The blocks it takes on disk, as `du -s` counts them.
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
        && is(&fdi_common::run_dir::RunDir::new(p).scenario(), false)
        && (is(&fdi_common::run_dir::RunDir::new(p).summary(), false)
            || is(&fdi_common::run_dir::RunDir::new(p).traces(), true))
}

/// The status of the run directory `p`: `done`, `partial (…)`, `no summary` or `summary
/// unreadable`, and what its traces keep.
pub(super) fn run_status(p: &Path) -> String {
    let Ok(text) =
        fdi_common::scenario::read_limited(&fdi_common::run_dir::RunDir::new(p).summary())
    else {
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

/// The suffix of a run directory that prune renamed before removing it.
const TOMBSTONE: &str = ".pruning";

/// True for a folder that prune began to remove (`<name>.pruning`, not a symbolic link).
pub(super) fn is_tombstone(p: &Path) -> bool {
    p.file_name()
        .is_some_and(|n| n.to_string_lossy().ends_with(TOMBSTONE))
        && std::fs::symlink_metadata(p).is_ok_and(|m| m.is_dir())
}

/// The folders of `out` that an earlier prune could not remove whole, by name.
pub fn tombstones(out: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(out)
        .with_context(|| format!("reading the runs folder {}", out.display()))?;
    let mut found = Vec::new();
    for e in entries {
        let e = e.with_context(|| format!("reading the runs folder {}", out.display()))?;
        if is_tombstone(&e.path()) {
            found.push(e.path());
        }
    }
    found.sort();
    Ok(found)
}

/// The last modification of the run directory `p`: of its summary, else of its scenario, else
/// of the folder.
pub(super) fn run_modified(p: &Path) -> std::time::SystemTime {
    let stamp = |q: &Path| std::fs::metadata(q).and_then(|m| m.modified()).ok();
    stamp(&fdi_common::run_dir::RunDir::new(p).summary())
        .or_else(|| stamp(&fdi_common::run_dir::RunDir::new(p).scenario()))
        .or_else(|| stamp(p))
        .unwrap_or(std::time::UNIX_EPOCH)
}

/// The run directories of `out`, newest first (tombstones left out: [`tombstones`]).
pub fn list(out: &Path) -> Result<Vec<RunDir>> {
    let entries = std::fs::read_dir(out)
        .with_context(|| format!("reading the runs folder {}", out.display()))?;
    let mut runs = Vec::new();
    for e in entries {
        let e = e.with_context(|| format!("reading the runs folder {}", out.display()))?;
        let path = e.path();
        if !is_run_dir(&path) || is_tombstone(&path) {
            continue;
        }
        runs.push(RunDir {
            name: e.file_name().to_string_lossy().into_owned(),
            bytes: usage_of(&path).bytes,
            status: run_status(&path),
            modified: run_modified(&path),
            path,
        });
    }
    // Newest first; names (which start with the UTC time of the run) break ties.
    runs.sort_by(|a, b| b.modified.cmp(&a.modified).then(b.name.cmp(&a.name)));
    Ok(runs)
}

/// What `prune` removed (or would remove, on a dry run), and what it could not.
#[derive(Debug)]
pub struct Pruned {
    pub removed: Vec<RunDir>,
    pub kept: usize,
    /// Tombstones of earlier prunes, removed now (or to be, on a dry run).
    pub cleared: Vec<PathBuf>,
    /// What could not be removed whole.
    pub failed: Vec<Unremoved>,
}

/// A run directory (or the tombstone of one) that prune could not remove whole.
#[derive(Debug)]
pub struct Unremoved {
    /// The run directory as it was listed, or the tombstone of an earlier prune.
    pub path: PathBuf,
    /// Where what is left of it stays: the tombstone, or `path` itself when even the rename
    /// failed (then nothing of it was removed).
    pub left: PathBuf,
    /// Each path that could not be removed, and why.
    pub causes: Vec<(PathBuf, io::Error)>,
}

/// Removes the tree at `p` (symbolic links are removed, never followed) as far as it can: past a
/// file it cannot delete it goes on with the others. Each path it could not remove goes to
/// `causes` with the error (a folder left because something in it stays is not repeated).
fn remove_tree(p: &Path, causes: &mut Vec<(PathBuf, io::Error)>) -> bool {
    let meta = match std::fs::symlink_metadata(p) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return true,
        Err(e) => {
            causes.push((p.to_path_buf(), e));
            return false;
        }
    };
    let removed = if meta.is_dir() {
        let entries = match std::fs::read_dir(p) {
            Ok(entries) => entries,
            Err(e) => {
                causes.push((p.to_path_buf(), e));
                return false;
            }
        };
        let mut whole = true;
        for e in entries {
            match e {
                Ok(e) => whole &= remove_tree(&e.path(), causes),
                Err(e) => {
                    causes.push((p.to_path_buf(), e));
                    whole = false;
                }
            }
        }
        if !whole {
            return false;
        }
        std::fs::remove_dir(p)
    } else {
        std::fs::remove_file(p)
    };
    match removed {
        Ok(()) => true,
        Err(e) if e.kind() == io::ErrorKind::NotFound => true,
        Err(e) => {
            causes.push((p.to_path_buf(), e));
            false
        }
    }
}

/// The tombstone name of the run directory `p`: `<name>.pruning`, or `<name>.<i>.pruning` when
/// an earlier tombstone of the same name is still there.
fn tombstone_for(p: &Path) -> PathBuf {
    let name = p
        .file_name()
        .map_or_else(|| "run".into(), |n| n.to_string_lossy().into_owned());
    let mut t = p.with_file_name(format!("{name}{TOMBSTONE}"));
    let mut i = 1;
    while std::fs::symlink_metadata(&t).is_ok() {
        t = p.with_file_name(format!("{name}.{i}{TOMBSTONE}"));
        i += 1;
    }
    t
}

/// `runs prune`: keeps the `keep` newest run directories of `out`, removes the others (only
/// run directories) and the tombstones of earlier prunes; `dry_run` removes nothing and says
/// what it would. One that cannot be removed whole is in [`Pruned::failed`], and the others
/// are removed all the same.
pub fn prune(out: &Path, keep: usize, dry_run: bool) -> Result<Pruned> {
    let runs = list(out)?;
    let earlier = tombstones(out)?;
    let kept = runs.len().min(keep);
    let mut pruned = Pruned {
        removed: Vec::new(),
        kept,
        cleared: Vec::new(),
        failed: Vec::new(),
    };
    for r in runs.into_iter().skip(keep) {
        // Checked again at the moment of removal: only a run directory goes.
        if !is_run_dir(&r.path) {
            continue;
        }
        if dry_run {
            pruned.removed.push(r);
            continue;
        }
        let tomb = tombstone_for(&r.path);
        if let Err(e) = std::fs::rename(&r.path, &tomb) {
            pruned.failed.push(Unremoved {
                left: r.path.clone(),
                causes: vec![(r.path.clone(), e)],
                path: r.path,
            });
            continue;
        }
        let mut causes = Vec::new();
        if remove_tree(&tomb, &mut causes) {
            pruned.removed.push(r);
        } else {
            pruned.failed.push(Unremoved {
                path: r.path,
                left: tomb,
                causes,
            });
        }
    }
    for t in earlier {
        let mut causes = Vec::new();
        if dry_run || remove_tree(&t, &mut causes) {
            pruned.cleared.push(t);
        } else {
            pruned.failed.push(Unremoved {
                left: t.clone(),
                path: t,
                causes,
            });
        }
    }
    Ok(pruned)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_dir(root: &Path, name: &str, summary: bool) -> PathBuf {
        let d = root.join(name);
        std::fs::create_dir_all(fdi_common::run_dir::RunDir::new(&d).traces()).expect("mkdir");
        std::fs::write(
            fdi_common::run_dir::RunDir::new(&d).scenario(),
            "name = \"x\"\n",
        )
        .expect("scenario");
        std::fs::write(
            fdi_common::run_dir::RunDir::new(&d)
                .traces()
                .join("agent-1.trace"),
            vec![0u8; 1000],
        )
        .expect("trace");
        if summary {
            std::fs::write(fdi_common::run_dir::RunDir::new(&d).summary(), "{}").expect("summary");
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
        std::fs::write(
            fdi_common::run_dir::RunDir::new(r.join("notes")).scenario(),
            "x",
        )
        .expect("w");
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

    /// A tombstone (a run directory an earlier prune renamed and could not remove whole) is no
    /// run directory, however whole its files: it is listed apart, never counted among the kept,
    /// and the next prune removes it.
    #[test]
    fn a_tombstone_of_an_earlier_prune_is_listed_apart_and_removed_by_the_next() {
        let root = tempfile::tempdir().expect("tmp");
        let r = root.path();
        let run = run_dir(r, "20240102-000000-b", true);
        let tomb = run_dir(r, "20240101-000000-a.pruning", true);
        assert!(is_run_dir(&tomb));
        let runs = list(r).expect("list");
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].path, run);
        assert_eq!(tombstones(r).expect("tombstones"), vec![tomb.clone()]);
        let dry = prune(r, 1, true).expect("dry run");
        assert_eq!((dry.removed.len(), dry.cleared.len()), (0, 1));
        assert!(tomb.is_dir(), "a dry run removes nothing");
        let p = prune(r, 1, false).expect("prune");
        assert_eq!(p.kept, 1);
        assert!(p.removed.is_empty() && p.failed.is_empty(), "{p:?}");
        assert_eq!(p.cleared, vec![tomb.clone()]);
        assert!(!tomb.exists() && run.is_dir());
        // A tombstone name already taken gets a number.
        std::fs::create_dir(r.join("20240102-000000-b.pruning")).expect("mkdir");
        assert_eq!(tombstone_for(&run), r.join("20240102-000000-b.1.pruning"));
    }
}
