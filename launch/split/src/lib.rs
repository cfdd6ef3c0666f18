//! fdi-split: runs split over hosts. The deployment file says where each process runs and how
//! each host is reached ([`hosts`]); the coordinating host reaches the others and supervises
//! their processes ([`remote`], which implements fdi-orchestrator's
//! [`Split`](fdi_orchestrator::run::split::Split) seam); each other host runs `fdi-launch
//! serve` ([`serve`]); their traces stream to the coordinator for the live view
//! ([`trace_stream`]); `fdi-launch certs` makes the lab's certificates ([`certs`]). Everything
//! network is Zenoh through `fdi-net`: the crates that only run on one host do not link it.
//!
//! A run over the hosts of a deployment file:
//!
//! ```no_run
//! # fn main() -> anyhow::Result<()> {
//! use fdi_orchestrator::{Engine, Overrides, RunRequest};
//! let request = RunRequest::new(None, &Overrides::default(), Engine::Ipc)?;
//! let split = fdi_split::load(std::path::Path::new("lab.toml"), &request.resolved)?;
//! let request = request.over_hosts(split);
//! # Ok(())
//! # }
//! ```

use std::path::Path;
use std::sync::Arc;

use anyhow::Result;
use fdi_common::scenario::Resolved;
use fdi_orchestrator::run::split::{HostsFile, Split};

pub mod certs;
pub mod hosts;
pub mod remote;
pub mod serve;
pub mod trace_stream;

/// The split of a run of `resolved` over the hosts of the deployment file at `path`, every
/// problem of the file named.
pub fn load(path: &Path, resolved: &Resolved) -> Result<Arc<dyn Split>> {
    Ok(Arc::new(hosts::Deployment::load(path, resolved)?))
}

/// The deployment file at `path`, read once the scenario it is for is known (what a library
/// built on runs takes, e.g. a benchmark's `--hosts`).
pub fn hosts_file(path: &Path) -> HostsFile {
    HostsFile {
        path: path.to_path_buf(),
        read: load,
    }
}
