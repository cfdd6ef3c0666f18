//! The stored results of a campaign: `points/<key>.json`, one per run, each written whole by
//! the one process that ran it.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fdi_common::engine::RunSummary;
use serde::{Deserialize, Serialize};

/// What `points/<key>.json` holds.
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct Stored {
    pub(super) key: String,
    pub(super) engine: String,
    pub(super) run: String,
    pub(super) summary: RunSummary,
}

pub(super) fn stored_path(out: &Path, key: &str) -> PathBuf {
    out.join("points").join(format!("{}.json", &key[..16]))
}

/// The stored result of a run, if there is a valid one for exactly this key.
pub(super) fn load_stored(out: &Path, key: &str) -> Option<RunSummary> {
    let p = stored_path(out, key);
    let text = std::fs::read_to_string(&p).ok()?;
    match serde_json::from_str::<Stored>(&text) {
        Ok(s) if s.key == key => Some(s.summary),
        Ok(_) => None,
        Err(e) => {
            log::warn!(
                "{} is not a result that can be read ({e}): its run counts as not done",
                p.display()
            );
            None
        }
    }
}

/// Writes `bytes` to `path` whole or not at all (a temporary file in the same folder, renamed).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("a temporary file in {}", dir.display()))?;
    // Flushed before the rename: on a shared file system another machine may open it next.
    tmp.write_all(bytes)
        .and_then(|()| tmp.as_file().sync_all())
        .with_context(|| format!("writing {}", path.display()))?;
    tmp.persist(path)
        .map_err(|e| anyhow::anyhow!("writing {}: {}", path.display(), e.error))?;
    Ok(())
}
