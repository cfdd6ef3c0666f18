//! Run directories made for runs: `<root>/<timestamp>-<name>/` with the scenario as used and an
//! empty `traces/` ([`RunDir`] names the paths), and their removal when a run did not start.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fdi_common::run_dir::RunDir;
use fdi_common::scenario::{Resolved, MAX_FILE_BYTES};

/// `YYYYMMDD-HHMMSS` in UTC.
pub fn timestamp() -> String {
    jiff::Timestamp::now().strftime("%Y%m%d-%H%M%S").to_string()
}

/// Creates a fresh run directory under `root` and writes the scenario as used into it. A
/// scenario whose text as used (attack inlined) is over the size limit of scenario files is
/// refused before anything is created: the processes read it back from the run directory.
pub fn create_run_dir(root: &Path, resolved: &Resolved) -> Result<PathBuf> {
    create_named_run_dir(root, resolved, &resolved.scenario.name)
}

/// A name as one component of a path, the one rule for the folders of runs and campaigns:
/// every character other than an ASCII letter, a digit, `-` and `_` becomes `_`, so the result
/// never holds a `/`, never is `.` or `..`, and stays inside the folder it is joined to. An
/// empty name stays empty (a caller that joins it alone refuses it).
pub fn safe_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// [`create_run_dir`] named `<timestamp>-<name>` ([`safe_name`]).
pub fn create_named_run_dir(root: &Path, resolved: &Resolved, name: &str) -> Result<PathBuf> {
    let toml = resolved.to_toml();
    if toml.len() as u64 > MAX_FILE_BYTES {
        bail!(
            "the scenario as used (its attack inlined) is {} bytes, larger than the {MAX_FILE_BYTES} byte limit of scenario files (the processes read it back from the run directory)",
            toml.len()
        );
    }
    let name = safe_name(name);
    let base = root.join(format!("{}-{name}", timestamp()));
    if root.exists() && !root.is_dir() {
        bail!(
            "--out {} is not a folder: a run directory is made inside the folder --out names \
             (it is made if it does not exist)",
            root.display()
        );
    }
    std::fs::create_dir_all(root).with_context(|| format!("creating {}", root.display()))?;
    // `create_dir` fails if the folder exists, so two runs started in the same second (even from
    // two launchers) never share a folder.
    let mut dir = base.clone();
    let mut n = 1;
    loop {
        match std::fs::create_dir(&dir) {
            Ok(()) => break,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && n < 10_000 => {
                n += 1;
                dir = PathBuf::from(format!("{}-{n}", base.display()));
            }
            Err(e) => return Err(e).with_context(|| format!("creating {}", dir.display())),
        }
    }
    let run = RunDir::new(&dir);
    if let Err(e) = std::fs::create_dir(run.traces())
        .with_context(|| format!("creating {}", run.traces().display()))
        .and_then(|()| {
            std::fs::write(run.scenario(), toml)
                .with_context(|| format!("writing {}", run.scenario().display()))
        })
    {
        remove_run_dir(&dir);
        return Err(e);
    }
    Ok(dir)
}

/// Removes a run directory that holds nothing of a run (it was refused or failed before its
/// processes started). Best effort: a folder that cannot be removed is named in a warning.
pub fn remove_run_dir(dir: &Path) {
    if let Err(e) = std::fs::remove_dir_all(dir) {
        log::warn!(
            "the run directory {} of a run that did not start could not be removed: {e}",
            dir.display()
        );
    }
}

/// Passes `result` on; when it is the error of a run that did not start
/// ([`crate::run::error::RunError::NotStarted`]), removes the run directory `dir` made for it first.
pub fn discard_if_not_started<T>(
    dir: &Path,
    result: Result<T, crate::run::error::RunError>,
) -> Result<T> {
    if let Err(crate::run::error::RunError::NotStarted(_)) = &result {
        remove_run_dir(dir);
    }
    Ok(result?)
}

#[cfg(test)]
mod tests {
    #[test]
    fn run_dirs_created_at_once_never_collide() {
        let root = std::env::temp_dir().join(format!("fdi-rundir-{}", std::process::id()));
        let r = fdi_common::scenario::paper().expect("valid");
        let dirs: Vec<_> = std::thread::scope(|s| {
            let hs: Vec<_> = (0..8)
                .map(|_| s.spawn(|| super::create_run_dir(&root, &r).expect("created")))
                .collect();
            hs.into_iter().map(|h| h.join().expect("thread")).collect()
        });
        let mut unique = dirs.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), dirs.len(), "{dirs:?}");
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn timestamp_has_the_documented_shape() {
        let t = super::timestamp();
        assert_eq!(t.len(), 15, "{t}");
        assert_eq!(&t[8..9], "-");
        assert!(t[..4].parse::<u32>().is_ok_and(|y| y >= 2024));
    }
}
