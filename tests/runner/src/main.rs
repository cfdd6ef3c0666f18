//! `cargo test-all [NEXTEST ARGS]`: the one test command of the project (the README's, and the
//! one CI runs). The tests run under cargo-nextest (one process per test, realtime tests alone:
//! `.config/nextest.toml`); on a machine that has only a Rust toolchain, this installs it first
//! (`cargo install --locked`, the version below), then runs
//! `cargo nextest run --workspace --release` with the arguments given.
//!
//! The tests of roles taken by Python programs (`tests/tests/external.rs`) need Python with the
//! pinned iceoryx2 binding, those of the live view (`tests/tests/live.rs`) a WebSocket client:
//! this makes a virtual environment in `target/py-venv` with `examples/python/requirements.txt`
//! and `tests/python/requirements.txt` (once; pip keeps it current) and hands its interpreter to
//! the tests in `FDI_PYTHON`. Without `python3` they say they are skipped, unless
//! `FDI_REQUIRE_PYTHON` is set (CI), where they fail.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// The cargo-nextest release installed where none is found.
const NEXTEST_VERSION: &str = "0.9.143";

/// The workspace root (this crate is `tests/runner`).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The interpreter of `target/py-venv` with the examples' requirements installed, or why
/// there is none.
fn python_venv() -> Result<PathBuf, String> {
    let root = root();
    let venv = root.join("target/py-venv");
    let python = venv.join("bin/python");
    if !python.exists() {
        let made = Command::new("python3")
            .arg("-m")
            .arg("venv")
            .arg(&venv)
            .status()
            .map_err(|e| format!("python3 could not be run ({e})"))?;
        if !made.success() {
            return Err(format!(
                "python3 -m venv {} failed ({made})",
                venv.display()
            ));
        }
    }
    let examples = root.join("examples/python/requirements.txt");
    let tests = root.join("tests/python/requirements.txt");
    let installed = Command::new(&python)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "-r",
        ])
        .arg(&examples)
        .arg("-r")
        .arg(&tests)
        .status()
        .map_err(|e| format!("{} could not be run ({e})", python.display()))?;
    if !installed.success() {
        return Err(format!(
            "pip install -r {} -r {} failed ({installed})",
            examples.display(),
            tests.display()
        ));
    }
    Ok(python)
}

fn main() -> ExitCode {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| OsString::from("cargo"));
    let found = Command::new(&cargo)
        .args(["nextest", "--version"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        eprintln!(
            "test-all: cargo-nextest is not installed; installing cargo-nextest {NEXTEST_VERSION} (cargo install --locked, once)"
        );
        let installed = Command::new(&cargo)
            .args([
                "install",
                "--locked",
                "cargo-nextest",
                "--version",
                NEXTEST_VERSION,
            ])
            .status();
        match installed {
            Ok(s) if s.success() => {}
            Ok(s) => {
                eprintln!("test-all: installing cargo-nextest failed ({s})");
                return ExitCode::FAILURE;
            }
            Err(e) => {
                eprintln!("test-all: could not run {}: {e}", cargo.to_string_lossy());
                return ExitCode::FAILURE;
            }
        }
    }
    let mut nextest = Command::new(&cargo);
    // `cargo run` set this runner's own variables: the tests' build must not see them, or the
    // binaries' build inside the tests (without them) would rebuild half the tree.
    fdi_test_runner::clean_build_env(&mut nextest);
    nextest
        .args(["nextest", "run", "--workspace", "--release"])
        .args(std::env::args_os().skip(1));
    if std::env::var_os("FDI_PYTHON").is_none() {
        match python_venv() {
            Ok(python) => {
                nextest.env("FDI_PYTHON", python);
            }
            Err(why) => eprintln!(
                "test-all: warning: no Python for the external-role tests: {why}; they will \
                 report themselves skipped (or fail where FDI_REQUIRE_PYTHON is set)"
            ),
        }
    }
    let status = nextest.status();
    match status {
        Ok(s) => match s.code() {
            Some(0) => ExitCode::SUCCESS,
            Some(c) => ExitCode::from(u8::try_from(c).unwrap_or(1)),
            None => {
                eprintln!("test-all: cargo nextest was stopped by a signal ({s})");
                ExitCode::FAILURE
            }
        },
        Err(e) => {
            eprintln!(
                "test-all: could not run {} nextest: {e}",
                cargo.to_string_lossy()
            );
            ExitCode::FAILURE
        }
    }
}
