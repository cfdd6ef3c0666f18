//! What the test command and the tests' own builds share: the environment a cargo build must
//! not inherit from the cargo command that started it.

use std::process::Command;

/// A variable cargo sets for one crate's compilation or run (`cargo run` of this runner, a test
/// under nextest), never one a user sets for the whole build (`CARGO_HOME`, `CARGO_TARGET_DIR`,
/// `CARGO_PROFILE_*`, … are not).
pub fn crate_variable(key: &str) -> bool {
    const EXACT: [&str; 7] = [
        "CARGO_MANIFEST_DIR",
        "CARGO_MANIFEST_PATH",
        "CARGO_MANIFEST_LINKS",
        "CARGO_CRATE_NAME",
        "CARGO_PRIMARY_PACKAGE",
        "CARGO_TARGET_TMPDIR",
        "CARGO_RUSTC_CURRENT_DIR",
    ];
    EXACT.contains(&key) || key.starts_with("CARGO_PKG_") || key.starts_with("CARGO_BIN_")
}

/// Removes from `cmd`'s environment every [`crate_variable`] of this process's. Build scripts
/// that rerun when one changes (ring's reads `CARGO_MANIFEST_DIR` and the `CARGO_PKG_*` of its
/// own crate) would otherwise see the runner's or the test's values in one build and not in
/// the next, and rebuild half the tree (zenoh, QUIC, TLS and every crate above them).
pub fn clean_build_env(cmd: &mut Command) -> &mut Command {
    for (key, _) in std::env::vars_os() {
        if key.to_str().is_some_and(crate_variable) {
            cmd.env_remove(key);
        }
    }
    cmd
}

#[cfg(test)]
mod tests {
    use super::crate_variable;

    #[test]
    fn a_crate_s_variables_go_and_the_build_s_stay() {
        for gone in [
            "CARGO_MANIFEST_DIR",
            "CARGO_PKG_NAME",
            "CARGO_BIN_EXE_fdi-rogue",
        ] {
            assert!(crate_variable(gone), "{gone}");
        }
        for kept in [
            "CARGO_HOME",
            "CARGO_TARGET_DIR",
            "CARGO_PROFILE_RELEASE_DEBUG",
            "CARGO",
            "PATH",
        ] {
            assert!(!crate_variable(kept), "{kept}");
        }
    }
}
