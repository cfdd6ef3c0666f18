//! fdi-orchestrator: runs. A scenario (the embedded paper scenario or a file) with the command
//! line's [`Overrides`] becomes a [`RunRequest`]; [`execute`] runs it on an engine — in-process,
//! or as processes over shared memory on one host or several ([`run`]) — into a run directory
//! ([`fdi_common::run_dir::RunDir`]), and stops at once when its [`Stop`] is raised. The tables
//! ([`tables`], [`attacks`]), campaigns ([`campaign`]) and the
//! benchmarks ([`bench`]) are built on runs; what they write is made by `fdi-report`.
//!
//! The paper's experiment, in-process, its RMSE per robot:
//!
//! ```
//! use fdi_common::stop::Stop;
//! use fdi_orchestrator::{execute, Engine, Overrides, RunRequest};
//!
//! # fn main() -> anyhow::Result<()> {
//! let overrides = Overrides { duration_s: Some(2.0), ..Overrides::default() };
//! let request = RunRequest::new(None, &overrides, Engine::Inproc)?;
//! let out = tempfile::tempdir()?;
//! let dir = request.create_run_dir(out.path())?;
//! let summary = execute(&request, &dir, &Stop::new())?;
//! for (robot, m) in &summary.metrics {
//!     println!("robot {robot}: RMSE {:.4} rad", m.rmse_rad);
//! }
//! assert_eq!(summary.metrics.len(), 4);
//! # Ok(())
//! # }
//! ```

pub mod attacks;
pub mod bench;
pub mod campaign;
pub mod request;
pub mod run;
pub mod run_dirs;
pub mod tables;

#[cfg(test)]
mod damage_tests;

pub use fdi_common::stop::Stop;
pub use request::{execute, Clock, Controller, NumericsArgs, Overrides, RunRequest};
pub use run::Engine;
