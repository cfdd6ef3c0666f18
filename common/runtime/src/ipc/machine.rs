//! What a run over shared memory needs of the machine, checked before anything is created:
//! room in the shared-memory folder, a writable iceoryx2 folder, and enough file descriptors.
//! Without them iceoryx2 fails far from the cause: a process dies of SIGBUS when it first
//! touches a page of a full tmpfs, node creation reports `InternalError`, a port
//! `InternalFailure`. The folders come from [`super::iceoryx`], the one place that knows them.

use std::path::{Path, PathBuf};

use super::iceoryx::{root_dir, shm_dir};
use super::msg::{AlarmMsg, ControlMsg, MeasurementMsg, StatusMsg, TorqueMsg};
use super::transport::{Sizing, Stream};

// The bounds below were measured on runs of 4, 16 and 32 agents (iceoryx2 0.10): the run's
// files in the shared-memory folder add up to 12.1 MB for 32 agents (2.5 MB of it touched),
// about 200 bytes per sample slot and 30 KB per service beyond its samples; the launcher holds
// about 12 file descriptors per agent, the control center 10, an agent 56 in all.

/// Bytes iceoryx2 adds to each sample slot (header, alignment), counted generously.
const SAMPLE_OVERHEAD: u64 = 64;
/// Bytes of shared memory per service beyond its samples (its configuration, the
/// connections' queues, the event's bookkeeping), counted generously.
const SERVICE_OVERHEAD: u64 = 64 * 1024;
/// Bytes of shared memory per node (process) of a run, beyond its services.
const NODE_OVERHEAD: u64 = 32 * 1024;
/// File descriptors a process of a run holds whatever the number of agents.
const FDS_BASE: u64 = 64;
/// File descriptors per agent of the process that holds the most (the launcher).
const FDS_PER_AGENT: u64 = 14;

/// The machine cannot carry the run: the cause, and what fixes it.
#[derive(Debug, thiserror::Error)]
pub enum MachineError {
    #[error(
        "{dir} has {} free, the run needs about {}: free space there (the files of other \
         programs; what dead runs left is removed at every start) or mount a larger one \
         (`mount -o remount,size=… {dir}`)",
        mb(*.free), mb(*.need), dir = .dir.display()
    )]
    NoSpace { dir: PathBuf, free: u64, need: u64 },
    #[error(
        "{what} {dir} is not writable ({source}): make it writable for this user, or remount \
         it read-write (`mount -o remount,rw …`)",
        dir = .dir.display()
    )]
    NotWritable {
        what: &'static str,
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "the open-file limit is {soft} (hard limit {hard}), a run of {agents} agents needs \
         about {need} file descriptors per process: raise it (`ulimit -n {need}` in the shell \
         that starts fdi-launch; beyond the hard limit as root or through \
         /etc/security/limits.conf)"
    )]
    FdLimit {
        soft: u64,
        hard: u64,
        need: u64,
        agents: usize,
    },
    #[error("checking {what} {dir}: {source}", dir = .dir.display())]
    Unreadable {
        what: &'static str,
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// `1.2 MB`.
fn mb(bytes: u64) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

/// The streams of a run of `sizing` and the payload each carries, bytes; with those of the
/// programs outside the project when `external`.
fn streams(sizing: Sizing, external: bool) -> Vec<(Stream, u64)> {
    let size = |n: usize| n as u64;
    let measurement = size(std::mem::size_of::<MeasurementMsg>());
    let torque = size(std::mem::size_of::<TorqueMsg>());
    let mut out = vec![
        (Stream::Measurement, measurement),
        (Stream::Tampered, measurement),
        (Stream::Actuation, torque),
        (Stream::Control, size(std::mem::size_of::<ControlMsg>())),
        (Stream::Status, size(std::mem::size_of::<StatusMsg>())),
    ];
    if external {
        out.extend([
            (Stream::ExternalIn, measurement),
            (Stream::ExternalOut, measurement),
            (Stream::Alarm, size(std::mem::size_of::<AlarmMsg>())),
        ]);
    }
    let agents = u32::try_from(sizing.agents.max(1)).unwrap_or(u32::MAX);
    out.extend((0..agents).map(|id| (Stream::Torque(id), torque)));
    out
}

/// Wake-up event services of a run: one per agent, and the run's other processes.
fn events(sizing: Sizing) -> u64 {
    sizing.agents.max(1) as u64 + 5
}

/// Shared memory a run of `sizing` may use at most, bytes: every sample slot of every
/// publisher of every stream (iceoryx2 sizes each publisher's segment for all of its
/// subscribers' buffers), with generous overheads per sample, service and node (`external`:
/// with the streams of programs outside the project). A stated bound, above the size of the
/// files a run makes (and far above what it touches).
pub fn shm_need(sizing: Sizing, external: bool) -> u64 {
    let samples: u64 = streams(sizing, external)
        .into_iter()
        .map(|(stream, payload)| {
            let (pubs, subs, buffer) = sizing.qos(stream);
            // Each subscriber's buffer plus the samples it and the publisher may hold.
            let slots = subs as u64 * (buffer as u64 + 2) + 2;
            pubs as u64 * slots * (payload + SAMPLE_OVERHEAD)
        })
        .sum();
    let services = streams(sizing, external).len() as u64 + events(sizing);
    let nodes = sizing.agents as u64 + 8;
    samples + services * SERVICE_OVERHEAD + nodes * NODE_OVERHEAD
}

/// File descriptors one process of a run of `sizing` may need, at most (the launcher holds
/// the most: ports on the run's streams and a bell for every process).
pub fn fd_need(sizing: Sizing) -> u64 {
    FDS_BASE + FDS_PER_AGENT * sizing.agents as u64
}

/// Checks that the machine can carry a run of `sizing` (`external`: with programs outside
/// the project): room in the shared-memory folder, a writable iceoryx2 folder, and the
/// open-file limit (raised to what the run needs when the hard limit allows it; the run's
/// processes inherit it). `probe` names the file the writability check makes and removes at
/// once (the run's prefix: a leftover is the run's).
pub fn check(sizing: Sizing, external: bool, probe: &str) -> Result<(), MachineError> {
    check_writable("the shared-memory folder", &shm_dir(), probe)?;
    check_space(&shm_dir(), shm_need(sizing, external))?;
    check_writable("iceoryx2's folder", &root_dir(), probe)?;
    check_fds(fd_need(sizing), sizing.agents)
}

/// `dir` has `need` bytes free (those available to unprivileged users).
pub fn check_space(dir: &Path, need: u64) -> Result<(), MachineError> {
    let st = rustix::fs::statvfs(dir).map_err(|e| MachineError::Unreadable {
        what: "the free space of",
        dir: dir.into(),
        source: e.into(),
    })?;
    let free = st.f_bavail.saturating_mul(st.f_frsize);
    if free < need {
        return Err(MachineError::NoSpace {
            dir: dir.into(),
            free,
            need,
        });
    }
    Ok(())
}

/// A file can be made in `dir`, or in the folder that would hold it when it does not exist
/// yet (iceoryx2 makes its folder): checked by making one, named `probe`, and removing it.
pub fn check_writable(what: &'static str, dir: &Path, probe: &str) -> Result<(), MachineError> {
    let mut at = dir;
    while !at.exists() {
        match at.parent() {
            Some(p) => at = p,
            None => break,
        }
    }
    let file = at.join(format!("{probe}.probe"));
    let made = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&file);
    match made {
        Ok(_) => {
            let _ = std::fs::remove_file(&file);
            Ok(())
        }
        Err(source) => Err(MachineError::NotWritable {
            what,
            dir: at.into(),
            source,
        }),
    }
}

/// The open-file limit covers `need`, raised to it when the hard limit allows.
pub fn check_fds(need: u64, agents: usize) -> Result<(), MachineError> {
    use rustix::process::{getrlimit, setrlimit, Resource, Rlimit};
    let limit = getrlimit(Resource::Nofile);
    let (soft, hard) = (limit.current, limit.maximum);
    if soft.is_none_or(|s| s >= need) {
        return Ok(());
    }
    if hard.is_none_or(|h| h >= need) {
        let raised = Rlimit {
            current: Some(need),
            maximum: hard,
        };
        if setrlimit(Resource::Nofile, raised).is_ok() {
            return Ok(());
        }
    }
    Err(MachineError::FdLimit {
        soft: soft.unwrap_or(0),
        hard: hard.unwrap_or(0),
        need,
        agents,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_needs_grow_with_the_agents() {
        let four = Sizing::new(4, 10);
        let forty = Sizing::new(40, 10);
        assert!(shm_need(forty, false) > shm_need(four, false));
        assert!(shm_need(four, true) > shm_need(four, false));
        assert!(fd_need(forty) > fd_need(four));
        // Above what was measured (see the bounds), below what a machine usually allows.
        let paper = Sizing::new(32, 7);
        let need = shm_need(paper, false);
        assert!((12_139_128..30_000_000).contains(&need), "{need}");
        assert!(fd_need(Sizing::new(32, 7)) >= 366 && fd_need(four) <= 256);
    }

    #[test]
    fn a_full_folder_and_a_missing_one_are_named() {
        let e = check_space(Path::new("/"), u64::MAX).expect_err("nothing has that much");
        let text = e.to_string();
        assert!(
            text.starts_with("/ has ") && text.contains("the run needs about"),
            "{text}"
        );
        assert!(text.contains("mount -o remount,size="), "{text}");

        let dir = std::env::temp_dir().join(format!("fdi-machine-{}", std::process::id()));
        // A folder that does not exist yet is checked where it would be made.
        check_writable("a folder", &dir.join("a/b"), "fdi-probe").expect("tmp is writable");
        assert!(!dir.exists(), "the check makes nothing");
    }
}
