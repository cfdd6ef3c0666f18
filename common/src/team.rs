//! A team of threads that stays for a batch's life and runs one round of work per call of
//! [`Team::round`]: the step of the Python package's vector environment. Each member (the calling thread is one)
//! starts on its own share of the chunks, so that the same environments stay in the same core's
//! cache step after step, then takes what is left of the others'. Between rounds a member spins
//! for [`SPIN`] (a vector step follows the last one within tens of microseconds when Python
//! only passes the arrays on) before it sleeps on a condition variable: waking a sleeping thread
//! every step cost more than the step's share of work it then did. Every wait is bounded.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a member spins for the next round (and the caller for the round's end) before it
/// sleeps. Measured with the bench (`python -m fdi_mas.bench`): see docs/python.md.
pub const SPIN: Duration = Duration::from_micros(200);
/// A sleeping member looks again at least this often.
const NAP: Duration = Duration::from_millis(100);
/// A round whose chunks stop getting done for this long is reported as stuck.
const STUCK: Duration = Duration::from_secs(60);

/// The work of a round: called once per chunk index, from any member.
pub type Work = dyn Fn(usize) + Send + Sync;

#[derive(Debug, Default)]
struct Sleepers {
    /// Members asleep waiting for a round.
    members: usize,
    /// The caller asleep waiting for the round's end.
    caller: bool,
}

struct Shared {
    work: Box<Work>,
    chunks: usize,
    members: usize,
    /// One flag per chunk: taken in this round.
    taken: Vec<AtomicBool>,
    done: AtomicUsize,
    round: AtomicU64,
    stop: AtomicBool,
    panicked: AtomicBool,
    sleepers: Mutex<Sleepers>,
    started: Condvar,
    finished: Condvar,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared")
            .field("chunks", &self.chunks)
            .field("members", &self.members)
            .finish_non_exhaustive()
    }
}

/// The lock of the sleepers, whatever a panic left in it (two counters, always consistent).
fn lock(m: &Mutex<Sleepers>) -> MutexGuard<'_, Sleepers> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Shared {
    /// Member `me`'s part of a round: its own share first, then whatever the others left.
    fn take_chunks(&self, me: usize) {
        let first = me * self.chunks / self.members;
        for j in 0..self.chunks {
            let i = (first + j) % self.chunks;
            if self.taken[i].swap(true, Ordering::AcqRel) {
                continue;
            }
            if catch_unwind(AssertUnwindSafe(|| (self.work)(i))).is_err() {
                self.panicked.store(true, Ordering::Release);
            }
            if self.done.fetch_add(1, Ordering::AcqRel) + 1 == self.chunks {
                let sleepers = lock(&self.sleepers);
                if sleepers.caller {
                    self.finished.notify_all();
                }
            }
        }
    }

    /// Member `me` (not the caller) from its start to the team's end.
    fn member(&self, me: usize) {
        let mut seen = 0;
        loop {
            let spin_until = Instant::now() + SPIN;
            loop {
                if self.stop.load(Ordering::Acquire) {
                    return;
                }
                let round = self.round.load(Ordering::Acquire);
                if round != seen {
                    seen = round;
                    break;
                }
                if Instant::now() < spin_until {
                    std::hint::spin_loop();
                    continue;
                }
                let mut sleepers = lock(&self.sleepers);
                if self.round.load(Ordering::Acquire) == seen && !self.stop.load(Ordering::Acquire)
                {
                    sleepers.members += 1;
                    sleepers = self
                        .started
                        .wait_timeout(sleepers, NAP)
                        .map_or_else(|e| e.into_inner().0, |(g, _)| g);
                    sleepers.members -= 1;
                }
            }
            self.take_chunks(me);
        }
    }
}

/// A team of `members` threads (the caller of [`Team::round`] and `members − 1` others).
#[derive(Debug)]
pub struct Team {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl Team {
    /// A team of `members` (at least 1) over `chunks` chunks of `work`.
    pub fn new(members: usize, chunks: usize, work: Box<Work>) -> std::io::Result<Self> {
        let members = members.max(1);
        let shared = Arc::new(Shared {
            work,
            chunks,
            members,
            taken: (0..chunks).map(|_| AtomicBool::new(true)).collect(),
            done: AtomicUsize::new(chunks),
            round: AtomicU64::new(0),
            stop: AtomicBool::new(false),
            panicked: AtomicBool::new(false),
            sleepers: Mutex::new(Sleepers::default()),
            started: Condvar::new(),
            finished: Condvar::new(),
        });
        let mut team = Self {
            shared,
            threads: Vec::new(),
        };
        for me in 1..members {
            let shared = Arc::clone(&team.shared);
            let thread = std::thread::Builder::new()
                .name(format!("fdi-mas-vec-{me}"))
                .spawn(move || shared.member(me))?;
            team.threads.push(thread);
        }
        Ok(team)
    }

    /// Runs every chunk once, this thread among the members; returns when all are done. An
    /// error when a chunk panicked, or when the round stopped advancing for a minute.
    pub fn round(&self) -> Result<(), String> {
        let s = &self.shared;
        s.done.store(0, Ordering::Release);
        for t in &s.taken {
            t.store(false, Ordering::Release);
        }
        s.round.fetch_add(1, Ordering::AcqRel);
        if lock(&s.sleepers).members > 0 {
            s.started.notify_all();
        }
        s.take_chunks(0);
        let spin_until = Instant::now() + SPIN;
        let (mut progress, mut last) = (s.done.load(Ordering::Acquire), Instant::now());
        while s.done.load(Ordering::Acquire) < s.chunks {
            if Instant::now() < spin_until {
                std::hint::spin_loop();
                continue;
            }
            let mut sleepers = lock(&s.sleepers);
            let done = s.done.load(Ordering::Acquire);
            if done < s.chunks {
                sleepers.caller = true;
                sleepers = s
                    .finished
                    .wait_timeout(sleepers, NAP)
                    .map_or_else(|e| e.into_inner().0, |(g, _)| g);
                sleepers.caller = false;
            }
            if done != progress {
                (progress, last) = (done, Instant::now());
            } else if last.elapsed() > STUCK {
                return Err(format!(
                    "the batch's threads stopped: {done} of {} chunks done after {} s without progress",
                    s.chunks,
                    STUCK.as_secs()
                ));
            }
        }
        if s.panicked.swap(false, Ordering::AcqRel) {
            return Err("a panic inside the engine while stepping the batch".into());
        }
        Ok(())
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        {
            let _sleepers = lock(&self.shared.sleepers);
            self.shared.started.notify_all();
        }
        for t in self.threads.drain(..) {
            // A member ends within one chunk's work or one nap; a panic was caught in it.
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_chunk_runs_once_per_round_whatever_the_members() {
        for members in [1, 2, 3, 8] {
            let counts: Arc<Vec<AtomicUsize>> =
                Arc::new((0..17).map(|_| AtomicUsize::new(0)).collect());
            let c = Arc::clone(&counts);
            let team = Team::new(
                members,
                17,
                Box::new(move |i| {
                    c[i].fetch_add(1, Ordering::Relaxed);
                }),
            )
            .expect("threads");
            for _ in 0..50 {
                team.round().expect("a round");
            }
            for (i, n) in counts.iter().enumerate() {
                assert_eq!(
                    n.load(Ordering::Relaxed),
                    50,
                    "chunk {i}, {members} members"
                );
            }
        }
    }

    #[test]
    fn a_panicking_chunk_is_an_error_and_the_team_goes_on() {
        let team =
            Team::new(2, 4, Box::new(|i| assert!(i != 2, "chunk 2 fails"))).expect("threads");
        assert!(team.round().is_err());
        assert!(team.round().is_err());
        let fine = Team::new(2, 4, Box::new(|_| {})).expect("threads");
        assert!(fine.round().is_ok());
    }
}
