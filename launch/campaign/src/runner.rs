//! The parallel runner of campaigns and of the seeded tables: jobs on `--jobs` worker threads
//! (each in-process run is single-threaded; an ipc run is its own processes), its progress told
//! (done of total), and a clean stop on SIGINT/SIGTERM: no job starts once a signal is
//! pending, the jobs in flight end (an ipc run is stopped by its runtime, an in-process run
//! finishes), and every result that came back is handed to `done`.

use std::num::NonZeroUsize;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;

use anyhow::Result;
use fdi_common::observe::{Finish, Progress, Work};
use fdi_common::stop::Stop;

/// The default of `--jobs`: the number of CPUs this process may use.
pub fn default_jobs() -> NonZeroUsize {
    std::thread::available_parallelism().unwrap_or(NonZeroUsize::MIN)
}

/// How a batch ended.
#[derive(Debug, Default)]
pub struct Outcome {
    /// The signal that stopped it before every job ran.
    pub interrupted: Option<i32>,
    /// Jobs that were never started.
    pub not_started: usize,
}

/// Runs `run` on every job, `workers` at a time, and hands each result to `done` (on this
/// thread, in the order they finish). An error from `done` stops the batch (no new job starts)
/// and is returned once the jobs in flight are back.
pub fn run_parallel<J: Sync, T: Send>(
    jobs: &[J],
    workers: NonZeroUsize,
    what: &str,
    progress: &dyn Progress,
    stop: &Stop,
    run: impl Fn(&J) -> T + Sync,
    mut done: impl FnMut(usize, T) -> Result<()>,
) -> Result<Outcome> {
    progress.begin(Work::Runs {
        total: jobs.len() as u64,
        what: what.to_string(),
    });
    let stop_run = stop;
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let started = AtomicUsize::new(0);
    let mut failure = None;
    let workers = workers.get().min(jobs.len()).max(1);
    std::thread::scope(|scope| {
        let (tx, rx) = mpsc::channel::<(usize, T)>();
        for _ in 0..workers {
            let tx = tx.clone();
            let (next, stop, started, run, stop_run) = (&next, &stop, &started, &run, stop_run);
            scope.spawn(move || loop {
                if stop.load(Ordering::SeqCst) || stop_run.pending().is_some() {
                    break;
                }
                let i = next.fetch_add(1, Ordering::SeqCst);
                let Some(job) = jobs.get(i) else { break };
                started.fetch_add(1, Ordering::SeqCst);
                let result = run(job);
                if tx.send((i, result)).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        for (i, result) in rx {
            progress.step("");
            if failure.is_none() {
                if let Err(e) = done(i, result) {
                    stop.store(true, Ordering::SeqCst);
                    failure = Some(e);
                }
            }
        }
    });
    if let Some(e) = failure {
        progress.finish(Finish::Stopped);
        return Err(e);
    }
    progress.finish(if stop_run.pending().is_some() {
        Finish::Stopped
    } else {
        Finish::Done
    });
    let not_started = jobs.len() - started.load(Ordering::SeqCst).min(jobs.len());
    Ok(Outcome {
        interrupted: stop_run.pending(),
        not_started,
    })
}
