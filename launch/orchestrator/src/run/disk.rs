//! The space a folder takes on disk, counted as `du` counts it.

use std::collections::HashSet;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// What [`usage`] found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Usage {
    /// Bytes of the blocks allocated (`st_blocks` × 512).
    pub bytes: u64,
    /// Paths that could not be read (their space, and that of what is under them, is not in
    /// `bytes`).
    pub unreadable: Vec<PathBuf>,
}

impl Usage {
    fn add(&mut self, other: Usage) {
        self.bytes += other.bytes;
        self.unreadable.extend(other.unreadable);
    }
}

/// The space `p` takes on disk as `du -s` counts it: the blocks allocated to it and, for a
/// folder, to everything under it (a symbolic link's own blocks, never what it points to), a
/// file with several hard links once (`seen`, shared by the calls whose total this is). Sparse
/// and compressed files count what they take, not their length.
pub fn usage(p: &Path, seen: &mut HashSet<(u64, u64)>) -> Usage {
    let m = match std::fs::symlink_metadata(p) {
        Ok(m) => m,
        Err(_) => {
            return Usage {
                bytes: 0,
                unreadable: vec![p.to_path_buf()],
            }
        }
    };
    if !m.is_dir() && m.nlink() > 1 && !seen.insert((m.dev(), m.ino())) {
        return Usage::default();
    }
    let mut total = Usage {
        bytes: m.blocks() * 512,
        unreadable: Vec::new(),
    };
    if m.is_dir() {
        match std::fs::read_dir(p) {
            Ok(entries) => {
                for e in entries {
                    match e {
                        Ok(e) => total.add(usage(&e.path(), seen)),
                        Err(_) => total.unreadable.push(p.to_path_buf()),
                    }
                }
            }
            Err(_) => total.unreadable.push(p.to_path_buf()),
        }
    }
    total
}

/// [`usage`] of `p` alone (its hard links counted once within it).
pub fn usage_of(p: &Path) -> Usage {
    usage(p, &mut HashSet::new())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hard_linked_file_counts_once_and_a_sparse_one_for_its_blocks() {
        let dir = tempfile::tempdir().expect("tmp");
        let a = dir.path().join("a");
        std::fs::write(&a, vec![7u8; 100_000]).expect("write");
        let one = usage_of(dir.path()).bytes;
        std::fs::hard_link(&a, dir.path().join("b")).expect("link");
        assert_eq!(
            usage_of(dir.path()).bytes,
            one,
            "the second link adds nothing"
        );
        let blocks = std::fs::metadata(&a).expect("meta").blocks() * 512;
        assert!(blocks >= 100_000 && one >= blocks, "{one} {blocks}");
        // 1 GB long, nothing written: a few blocks at most.
        let sparse = std::fs::File::create(dir.path().join("sparse")).expect("create");
        sparse.set_len(1 << 30).expect("set_len");
        assert!(usage_of(dir.path()).bytes < one + (1 << 20));
    }

    #[test]
    fn what_cannot_be_read_is_named_not_counted_as_nothing() {
        let u = usage_of(Path::new("/nonexistent/fdi-mas/folder"));
        assert_eq!(u.bytes, 0);
        assert_eq!(
            u.unreadable,
            vec![PathBuf::from("/nonexistent/fdi-mas/folder")]
        );
    }
}
