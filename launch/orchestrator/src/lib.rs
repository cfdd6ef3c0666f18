//! fdi-orchestrator: runs. A scenario (the embedded paper scenario or a file) with the command
//! line's [`Overrides`] becomes a [`RunRequest`]; [`execute`] runs it on an engine — in-process,
//! or as processes over shared memory on one host or several ([`run`]) — into a run directory
//! ([`fdi_common::run_dir::RunDir`]), and stops at once when its [`Stop`] is raised. The tables
//! and benchmarks (`fdi-tables`) and the campaigns (`fdi-campaign`) are built on runs; what
//! they all write is made by `fdi-report`.
//!
//! The paper's experiment under another attack, in-process, and its RMSE per robot:
//!
//! ```
//! use fdi_common::stop::Stop;
//! use fdi_orchestrator::{execute, Engine, Overrides, RunRequest};
//!
//! # fn main() -> anyhow::Result<()> {
//! let overrides = Overrides {
//!     attack: Some("freeze".into()), // a shipped preset, or a profile file
//!     duration_s: Some(2.0),
//!     ..Overrides::default()
//! };
//! // `None`: the embedded paper scenario; `Some(path)`: a scenario file.
//! let request = RunRequest::new(None, &overrides, Engine::Inproc)?
//!     .edit(|s| s.controller.beta = 8.0)?;
//! let out = tempfile::tempdir()?;
//! let dir = request.create_run_dir(out.path())?;
//! let summary = execute(&request, &dir, &Stop::new())?;
//! for (robot, m) in &summary.metrics {
//!     println!("robot {robot}: RMSE {:.4} rad", m.rmse_rad);
//! }
//! assert_eq!(summary.metrics.len(), 4);
//! assert!(dir.trace(fdi_common::run_dir::Process::Center).is_file());
//! # Ok(())
//! # }
//! ```
//!
//! [`Engine::Ipc`] runs the same request as processes over shared memory; it spawns the role
//! binaries (`fdi-agent`, `fdi-attacker`, `fdi-control-center`) found beside the running
//! executable, so a program of your own needs them installed there (`cargo build --release`
//! puts them in `target/release/`). `examples/gain_study.rs` is a small parameter study.

pub mod request;
pub mod run;
pub mod run_dirs;

#[cfg(test)]
mod damage_tests;

pub use fdi_common::stop::Stop;
pub use request::{
    execute, execute_with, NumericsArgs, Overrides, OverridesOn, RunRequest, SetArgs,
};
pub use run::Engine;
