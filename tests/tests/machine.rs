//! A machine that cannot carry a run over shared memory, through the real `fdi-launch`: a full
//! shared-memory folder, a read-only iceoryx2 folder, a low open-file limit. Each is named
//! before the start, with its fix, and nothing of the run is left behind (issue 29: they were
//! "killed by signal 7 SIGBUS", "NodeCreationFailure::InternalError",
//! "PublishSubscribeCreateError(InternalFailure)").
//!
//! The folders are those of the transport layer (`fdi_runtime::ipc::{shm_dir, root_dir}`),
//! replaced by a small or read-only tmpfs in a mount namespace of the launcher's own
//! (`unshare -m`): root only. Without it those tests say they are skipped, unless
//! `FDI_REQUIRE_ROOT` is set (CI), where they fail.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use fdi_tests::{launcher, leftovers_of, wait_with_watchdog, Scratch};

const WATCHDOG: Duration = Duration::from_secs(120);

/// Why a mount namespace cannot be made here, if it cannot (after saying so); panics when
/// `FDI_REQUIRE_ROOT` is set.
fn mount_namespaces_missing() -> Option<String> {
    let tried = Command::new("unshare")
        .args(["-m", "--propagation", "private", "true"])
        .stdin(Stdio::null())
        .output();
    let why = match tried {
        Ok(out) if out.status.success() => return None,
        Ok(out) => String::from_utf8_lossy(&out.stderr).trim().to_string(),
        Err(e) => format!("running `unshare`: {e}"),
    };
    assert!(
        std::env::var_os("FDI_REQUIRE_ROOT").is_none(),
        "FDI_REQUIRE_ROOT is set but a mount namespace cannot be made: {why}"
    );
    eprintln!("skipped: a mount namespace cannot be made here ({why}); run as root");
    Some(why)
}

/// `fdi-launch run --engine ipc` of a short paper run (output in `out`), started by `sh -c
/// setup`, which ends with `exec` of it; `unshare`'d when `namespace`. Returns its output and
/// pid (the `exec`s keep it).
fn run_after(setup: &str, namespace: bool, out: &Path) -> (Output, u32) {
    let mut cmd = if namespace {
        let mut c = Command::new("unshare");
        c.args(["-m", "--propagation", "private", "sh", "-c"]);
        c
    } else {
        let mut c = Command::new("sh");
        c.arg("-c");
        c
    };
    cmd.arg(format!("{setup} && exec \"$@\""))
        .arg("sh")
        .arg(launcher())
        .args(["run", "--engine", "ipc", "--duration-s", "0.2", "--out"])
        .arg(out)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let child = cmd.spawn().expect("spawning the launcher");
    let pid = child.id();
    (wait_with_watchdog(child, WATCHDOG), pid)
}

/// The run did not start, and said `what`, with no signal and no iceoryx2 error.
fn assert_named(out: &Output, what: &[&str]) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    eprintln!("{err}");
    assert_eq!(out.status.code(), Some(1), "{err}");
    for w in what {
        assert!(err.contains(w), "no `{w}` in: {err}");
    }
    for bad in [
        "SIGBUS",
        "InternalError",
        "InternalFailure",
        "killed by signal",
    ] {
        assert!(!err.contains(bad), "`{bad}` in: {err}");
    }
    err
}

/// Regression (issue 29): a full `/dev/shm` gave "attacker was killed by signal 7 SIGBUS before
/// the start".
#[test]
fn a_full_dev_shm_is_named_before_the_start() {
    if mount_namespaces_missing().is_some() {
        return;
    }
    let s = Scratch::new("full-shm");
    let shm = fdi_runtime::ipc::shm_dir();
    let setup = format!("mount -t tmpfs -o size=1m tmpfs {}", shm.display());
    let (out, _) = run_after(&setup, true, &s.0);
    assert_named(
        &out,
        &[
            &format!("{} has 1.0 MB free, the run needs about", shm.display()),
            "mount -o remount,size=",
        ],
    );
}

/// Regression (issue 29): a read-only iceoryx2 folder gave "NodeCreationFailure::InternalError"
/// and left a file in `/dev/shm`.
#[test]
fn a_read_only_iceoryx2_folder_is_named() {
    if mount_namespaces_missing().is_some() {
        return;
    }
    let s = Scratch::new("ro-iceoryx2");
    let root = fdi_runtime::ipc::root_dir();
    let setup = format!(
        "mkdir -p {root} && mount -t tmpfs -o ro,size=1m tmpfs {root}",
        root = root.display()
    );
    let (out, pid) = run_after(&setup, true, &s.0);
    assert_named(
        &out,
        &[
            &format!("iceoryx2's folder {} is not writable", root.display()),
            "Read-only file system",
        ],
    );
    // The namespace shares the shared-memory folder with this one.
    let left = leftovers_of(pid);
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// Regression (issue 29): `ulimit -n 64` gave "PublishSubscribeCreateError(InternalFailure)".
/// Needs no root: the limit is the shell's.
#[test]
fn a_low_fd_limit_is_named() {
    let s = Scratch::new("fd-limit");
    let (out, pid) = run_after("ulimit -n 64", false, &s.0);
    assert_named(
        &out,
        &[
            "the open-file limit is 64 (hard limit 64)",
            "file descriptors per process",
            "ulimit -n",
        ],
    );
    let left = leftovers_of(pid);
    assert!(left.is_empty(), "left behind: {left:?}");
}
