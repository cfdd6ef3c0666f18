//! The seam of a run split over hosts: what the launcher's runtime asks of the other hosts,
//! and nothing of how it reaches them. `fdi-split` implements it over Zenoh (its deployment
//! file, the hosts' `fdi-launch serve`, the bridge and the certificates); a run on one host
//! never touches it, and a crate built on runs (campaigns, tables) does not link the network.

use std::collections::BTreeSet;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use anyhow::Result;
use fdi_common::engine::NetworkPath;
use fdi_common::run_dir::Process;
use fdi_common::scenario::Resolved;
use fdi_runtime::ipc::{Sizing, Wake};

use crate::run::supervisor::Remote as RemoteChild;

/// A piece of a remote trace as its host streams it: its offset in the trace and its bytes.
pub type Chunk = (u64, Vec<u8>);

/// The stream of one remote trace for one reader: its pieces in order, or why it stopped.
pub type Received = mpsc::Receiver<Result<Chunk, String>>;

/// Where each process of a split run runs, read against the run's scenario.
pub trait Split: Send + Sync + fmt::Debug {
    /// Whether the process that wakes on `wake` runs on this (the coordinating) host.
    fn is_local(&self, wake: Wake) -> bool;
    /// How long the run may make no progress before it is stopped (`None`: the runtime's).
    fn stall_timeout(&self) -> Option<Duration>;
    /// Reaches the other hosts for the run `prefix` and starts the bridge of its services
    /// (sized by `sizing`), before any local process sends.
    fn connect(&self, prefix: &str, sizing: Sizing) -> Result<Box<dyn Hosts>>;
}

/// A deployment file and the reader that makes a [`Split`] of it for a scenario
/// (`fdi_split::hosts_file`): what a library built on runs is given, so that it reads the file
/// only once it knows the scenario.
#[derive(Debug, Clone)]
pub struct HostsFile {
    pub path: PathBuf,
    pub read: fn(&Path, &Resolved) -> Result<Arc<dyn Split>>,
}

impl HostsFile {
    /// The split of a run of `r` over the file's hosts.
    pub fn split_for(&self, r: &Resolved) -> Result<Arc<dyn Split>> {
        (self.read)(&self.path, r)
    }
}

/// The coordinator's link to the other hosts of a run, once reached.
pub trait Hosts: Send {
    /// The traces of the processes on other hosts, for the live view.
    fn traces(&self) -> Arc<dyn RemoteTraces>;
    /// Asks each host to run its processes (`procs`: each process of the run that is not on
    /// this host, with how messages name it) and gives back each one it started, to be
    /// supervised through what its host reports: its wake-up event, its label, its handle.
    fn start_hosts(
        &mut self,
        scenario: &str,
        procs: Vec<(Wake, String)>,
    ) -> Result<Vec<(Wake, String, RemoteChild)>>;
    /// Waits until every route between the hosts carries the run's services.
    fn await_routes(&self) -> Result<()>;
    /// Why the run cannot go on across hosts, if it cannot.
    fn failure(&self) -> Option<String>;
    /// The frames refused so far on the network path, per host that refused any.
    fn refusals(&self) -> Vec<Refusals>;
    /// A host that is gone since the last call (each reported once).
    fn lost_host(&mut self) -> Option<LostHost>;
    /// The coordinating host's line for the report: the processes it ran.
    fn describe_coordinator(&self) -> String;
    /// One line per other host for the report: its processes and its clock against ours.
    fn describe(&self) -> Vec<String>;
    /// Fetches the traces of every reachable host into the run directory `run_dir`; the
    /// problems, one per trace.
    fn fetch_traces(&mut self, run_dir: &Path) -> Vec<String>;
    /// Releases the hosts (each removes what the run left there).
    fn release(self: Box<Self>) -> Released;
}

/// The frames one host refused on the network path: how many, and the first described.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusals {
    pub host: String,
    pub count: u64,
    pub first: String,
}

impl fmt::Display for Refusals {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "host `{}` refused {} frames, the first: {}",
            self.host, self.count, self.first
        )
    }
}

/// A host that is gone, with the processes it ran.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LostHost {
    pub name: String,
    pub endpoint: String,
    /// The agents it ran.
    pub agents: Vec<u32>,
    /// The message of a run stopped by it.
    pub message: String,
}

/// What the release of the hosts left.
#[derive(Debug)]
pub struct Released {
    /// Files that could not be removed, `host:path`.
    pub leftovers: Vec<String>,
    pub problems: Vec<String>,
    pub network: NetworkPath,
}

/// The traces of a run's processes on other hosts, as the live view subscribes to their
/// streams during the run.
pub trait RemoteTraces: Send + Sync + fmt::Debug {
    /// The processes that run on other hosts.
    fn processes(&self) -> BTreeSet<Process>;
    /// Subscribes to the stream of the trace of `process`, for `readers` readers.
    fn subscribe(&self, process: Process, readers: usize) -> Result<Subscribed>;
}

/// The streams of one remote trace, one per reader, and what keeps them coming.
pub struct Subscribed {
    pub readers: Vec<Received>,
    /// Held as long as the streams are read (the subscription).
    pub held: Box<dyn Send>,
}
