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
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::stop::Stop;
use fdi_common::trace::TraceReader;
use fdi_report::join::{Feed, Sources};

/// How long a follower sleeps when it reached what was written so far.
const POLL: Duration = Duration::from_millis(20);
/// How long after the run's end the follower may still read (a viewer that came late, a machine
/// too busy for its idle thread): then it stops, and the launcher goes on.
const FINISH: Duration = Duration::from_secs(5);
/// In a realtime run, a trace that has not grown for this long is taken to have ended (its
/// process was lost; a live process's trace writer flushes every 100 ms, but the processes may
/// take seconds to start on a loaded machine after writing their headers): the others go on.
const REALTIME_SILENCE: Duration = Duration::from_secs(10);

/// The end of the run, as the follower sees it.
#[derive(Debug, Default)]
pub struct Over {
    at: OnceLock<Instant>,
    flag: AtomicBool,
}

impl Over {
    /// The run is over: every trace is whole.
    pub fn set(&self) {
        let _ = self.at.set(Instant::now());
        self.flag.store(true, Ordering::Release);
    }

    fn is_set(&self) -> bool {
        self.flag.load(Ordering::Acquire)
    }

    fn overdue(&self) -> bool {
        self.at.get().is_some_and(|t| t.elapsed() > FINISH)
    }
}

/// A trace file read as its process writes it: at its end, a read waits for more until the run
/// is over (or, in realtime, the file is silent for [`REALTIME_SILENCE`]), then the file's end
/// is the trace's.
struct Growing {
    file: File,
    over: Arc<Over>,
    silence: Option<Duration>,
    grew: Instant,
}

impl Read for Growing {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        loop {
            // Whether the run was over before this read: then what it finds is all there is.
            let over = self.over.is_set();
            let n = self.file.read(buf)?;
            if n > 0 {
                self.grew = Instant::now();
                return Ok(n);
            }
            if over || self.silence.is_some_and(|s| self.grew.elapsed() > s) {
                return Ok(0);
            }
            std::thread::sleep(POLL);
        }
    }
}

/// The trace file `path`, once it exists (a process makes it after it starts); `None` if the
/// run is over without it.
fn open_when_made(path: &Path, over: &Over) -> Option<File> {
    loop {
        let was_over = over.is_set();
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
    (over, silence): (&Arc<Over>, Option<Duration>),
    mut records: Option<fdi_live::RecordFeed>,
) -> Feed {
    let Some(file) = open_when_made(&path, over) else {
        let missing = format!("{}: the process wrote no trace", path.display());
        return Box::new(std::iter::once(Err(missing)));
    };
    let growing = Growing {
        file,
        over: over.clone(),
        silence,
        grew: Instant::now(),
    };
    match TraceReader::follow(growing, &path) {
        Ok(reader) => Box::new(reader.map(move |r| {
            // (It takes the events and latency stamps only.)
            if let (Ok(rec), Some(to)) = (&r, &mut records) {
                to.record(&stem, rec);
            }
            r.map_err(|e| e.to_string())
        })),
        Err(e) => Box::new(std::iter::once(Err(e.to_string()))),
    }
}

/// Follows the traces of the run of `r` in `run_dir` once `watcher` says a viewer subscribed,
/// until the run is over (`over`) and every trace read, at most [`FINISH`] after; the joined
/// ticks into `feed`. Returns at once, reading nothing, if the run is over before anyone
/// watched. `actuation`: the attacker's trace holds the torque path's records (the ipc engine;
/// the in-process engine's traces have none).
pub fn follow_run(
    r: &Resolved,
    run_dir: &Path,
    (mut feed, watcher): (fdi_live::Feed, &fdi_live::Watcher),
    over: &Arc<Over>,
    actuation: bool,
    stop: &Stop,
) -> Result<()> {
    fdi_live::yield_to_the_run();
    while !watcher.wait(POLL * 5) {
        if over.is_set() {
            return Ok(());
        }
    }
    let dir = RunDir::new(run_dir);
    let records = feed.records();
    let s = &r.scenario;
    let silence = (s.clock == ClockMode::Realtime).then_some(REALTIME_SILENCE);
    let feed_of = |p: Process| {
        followed(
            dir.trace(p),
            p.to_string(),
            (over, silence),
            Some(records.clone()),
        )
    };
    // A second reader of a trace, for its second stream of records.
    let second = |p: Process| followed(dir.trace(p), p.to_string(), (over, silence), None);
    let agents = s
        .agents
        .iter()
        .map(|a| (a.id, feed_of(Process::Agent(a.id))))
        .collect();
    let routed = actuation && s.agents.iter().any(|a| r.attack.attacks_torque_of(a.id));
    let sources = Sources::from_feeds(
        agents,
        feed_of(Process::Attacker),
        routed.then(|| second(Process::Attacker)),
        feed_of(Process::Center),
        s.roles.monitor.is_some().then(|| second(Process::Center)),
    );
    let walked = fdi_report::join::walk(
        r,
        sources,
        1,
        |rec| feed.tick(rec),
        || {
            stop.check(fdi_common::stop::DURING_THE_RUN)?;
            if over.overdue() {
                bail!(
                    "it had not caught up with the run {} s after its end",
                    FINISH.as_secs()
                );
            }
            Ok(())
        },
    )?;
    for w in walked.warnings() {
        eprintln!("fdi-launch: warning: live view: {w}");
    }
    Ok(())
}
