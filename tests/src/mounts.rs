//! Mounts for the tests of full disks and of files that cannot be removed: a small tmpfs (a
//! disk that fills up) and a read-only bind mount of a folder (whose files not even root can
//! delete). Both need root and `mount`; without them [`Mount`] says why, and the tests say they
//! are skipped, unless `FDI_REQUIRE_ROOT` is set (CI), where they fail. Every mount is undone
//! on drop, also when the test fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn run(program: &str, args: &[&str]) -> Result<(), String> {
    let out = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("running `{program}`: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`{program} {}`: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Why the tests that mount cannot run here; panics instead when `FDI_REQUIRE_ROOT` is set.
pub fn skip_reason(e: &str) -> String {
    assert!(
        std::env::var_os("FDI_REQUIRE_ROOT").is_none(),
        "FDI_REQUIRE_ROOT is set but the test cannot mount: {e}"
    );
    format!("skipped: the test cannot mount here ({e}); run as root")
}

/// A mount made by a test, undone on drop.
#[derive(Debug)]
pub struct Mount {
    /// Where it may be by the time it is undone (the test may rename a folder above it).
    at: Vec<PathBuf>,
}

impl Mount {
    /// A tmpfs of `bytes` (rounded up to whole pages) on the folder `at`, made if need be.
    pub fn tmpfs(at: &Path, bytes: u64) -> Result<Self, String> {
        std::fs::create_dir_all(at).map_err(|e| format!("creating {}: {e}", at.display()))?;
        let size = format!("size={bytes}");
        run("mount", &["-t", "tmpfs", "-o", &size, "tmpfs", &text(at)])?;
        Ok(Self {
            at: vec![at.to_path_buf()],
        })
    }

    /// The folder `dir` mounted read-only on itself: nothing in it can be created, changed or
    /// removed, by root either (`EROFS`).
    pub fn read_only(dir: &Path) -> Result<Self, String> {
        let d = text(dir);
        run("mount", &["--bind", &d, &d])?;
        let mount = Self {
            at: vec![dir.to_path_buf()],
        };
        run("mount", &["-o", "remount,bind,ro", &d, &d])?;
        Ok(mount)
    }

    /// The mount may also be at `p` when it is undone (its folder was moved there).
    pub fn also_at(&mut self, p: PathBuf) {
        self.at.push(p);
    }
}

fn text(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

impl Drop for Mount {
    fn drop(&mut self) {
        for p in &self.at {
            let p = text(p);
            if run("umount", &[&p]).is_ok() || run("umount", &["-l", &p]).is_ok() {
                return;
            }
        }
        eprintln!("could not undo the test's mount at any of {:?}", self.at);
    }
}
