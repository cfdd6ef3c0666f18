//! The live view of a multi-process run that keeps its traces whole: its processes write their
//! trace files as always, and once a viewer subscribed, a thread of the launcher follows those
//! files from their first byte as they grow and joins them ([`fdi_report::join::walk`]) into the
//! live server's feed. Nobody watching, nothing is read: the run costs what it costs without
//! `--live`. The processes never wait for the follower (it reads what their writers flushed:
//! every 100 ms or 64 KiB), and a viewer that comes late sees the run from its start.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Result;
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::Resolved;
use fdi_common::stop::Stop;
use fdi_common::trace::{TraceReader, TraceRecord};
use fdi_report::join::{Feed, Sources};

/// How long a follower sleeps when it reached what was written so far.
const POLL: Duration = Duration::from_millis(20);

/// A trace file read as its process writes it: at its end, a read waits for more until the run
/// is over, then the file's end is the trace's.
struct Growing {
    file: File,
    over: Arc<AtomicBool>,
}

impl Read for Growing {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        loop {
            // Whether the run was over before this read: then what it finds is all there is.
            let over = self.over.load(Ordering::Acquire);
            let n = self.file.read(buf)?;
            if n > 0 || over {
                return Ok(n);
            }
            std::thread::sleep(POLL);
        }
    }
}

/// The trace file `path`, once it exists (a process makes it after it starts); `None` if the
/// run is over without it.
fn open_when_made(path: &Path, over: &AtomicBool) -> Option<File> {
    loop {
        let was_over = over.load(Ordering::Acquire);
        if let Ok(f) = File::open(path) {
            return Some(f);
        }
        if was_over {
            return None;
        }
        std::thread::sleep(POLL);
    }
}

/// The records of the trace at `path`, followed as it grows; its events and latency stamps
/// also to the live server (`records`: once per trace, a second reader of it has none).
fn followed(
    path: PathBuf,
    stem: String,
    over: &Arc<AtomicBool>,
    mut records: Option<fdi_live::RecordFeed>,
) -> Feed {
    let Some(file) = open_when_made(&path, over) else {
        let missing = format!("{}: the process wrote no trace", path.display());
        return Box::new(std::iter::once(Err(missing)));
    };
    let growing = Growing {
        file,
        over: over.clone(),
    };
    match TraceReader::follow(growing, &path) {
        Ok(reader) => Box::new(reader.map(move |r| {
            if let (Ok(rec @ (TraceRecord::Event { .. } | TraceRecord::Latency { .. })), Some(to)) =
                (&r, &mut records)
            {
                to.record(&stem, rec);
            }
            r.map_err(|e| e.to_string())
        })),
        Err(e) => Box::new(std::iter::once(Err(e.to_string()))),
    }
}

/// Follows the traces of the run of `r` in `run_dir` once `watcher` says a viewer subscribed,
/// until the run is over (`over`) and every trace read; the joined ticks into `feed`. Returns
/// at once, reading nothing, if the run is over before anyone watched.
pub fn follow_run(
    r: &Resolved,
    run_dir: &Path,
    mut feed: fdi_live::Feed,
    watcher: &fdi_live::Watcher,
    over: &Arc<AtomicBool>,
    stop: &Stop,
) -> Result<()> {
    fdi_live::yield_to_the_run();
    while !watcher.wait(POLL * 5) {
        if over.load(Ordering::Acquire) {
            return Ok(());
        }
    }
    let dir = RunDir::new(run_dir);
    let records = feed.records();
    let feed_of = |p: Process| followed(dir.trace(p), p.to_string(), over, Some(records.clone()));
    // A second reader of a trace, for its second stream of records.
    let second = |p: Process| followed(dir.trace(p), p.to_string(), over, None);
    let s = &r.scenario;
    let agents = s
        .agents
        .iter()
        .map(|a| (a.id, feed_of(Process::Agent(a.id))))
        .collect();
    let routed = s.agents.iter().any(|a| r.attack.attacks_torque_of(a.id));
    let sources = Sources::from_feeds(
        agents,
        feed_of(Process::Attacker),
        routed.then(|| second(Process::Attacker)),
        feed_of(Process::Center),
        s.roles.monitor.is_some().then(|| second(Process::Center)),
    );
    fdi_report::join::walk(
        r,
        sources,
        1,
        |rec| feed.tick(rec),
        || Ok(stop.check(fdi_common::stop::DURING_THE_RUN)?),
    )?;
    Ok(())
}
