//! `cargo test-all [NEXTEST ARGS]`: the one test command of the project (the README's, and the
//! one CI runs). The tests run under cargo-nextest (one process per test, realtime tests alone:
//! `.config/nextest.toml`); on a machine that has only a Rust toolchain, this installs it first
//! (`cargo install --locked`, the version below), then runs
//! `cargo nextest run --workspace --release` with the arguments given.

use std::ffi::OsString;
use std::process::{Command, ExitCode};

/// The cargo-nextest release installed where none is found.
const NEXTEST_VERSION: &str = "0.9.143";

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
    let status = Command::new(&cargo)
        .args(["nextest", "run", "--workspace", "--release"])
        .args(std::env::args_os().skip(1))
        .status();
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
