//! What long work tells whoever started it while it runs: how far it is ([`Progress`]). The
//! libraries never draw or print; the command line renders progress as a bar on the terminal,
//! a program of its own renders it as it likes or not at all ([`Quiet`]). Warnings and notes go
//! through the `log` facade (`log::warn!`, `log::info!`), which the command line prints as
//! `fdi-launch: warning: …` and `fdi-launch: …`.

/// The `log` target of a line printed as it is, without the program's name before it: a line
/// another host or program said, which names itself (`log::info!(target: VERBATIM, …)`).
pub const VERBATIM: &str = "fdi::verbatim";

/// What is counted.
#[derive(Debug, Clone, PartialEq)]
pub enum Work {
    /// The ticks of one run of `period_s` per tick: the position is the control center's last
    /// tick, so the simulated time is `position × period_s`.
    Ticks { total: u64, period_s: f64 },
    /// Runs of a table, a campaign or a benchmark, named by `what` (`attack table`).
    Runs { total: u64, what: String },
}

impl Work {
    /// How many steps make the whole.
    pub fn total(&self) -> u64 {
        match self {
            Self::Ticks { total, .. } | Self::Runs { total, .. } => *total,
        }
    }
}

/// How a piece of work ended, for its display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Finish {
    /// Done: the display goes.
    Done,
    /// Stopped before its end (a failure, an interrupt): the display stays as it was.
    Stopped,
}

/// The progress of long work, told to whoever started it. Every method is called from the
/// thread that does the work; the work opens one [`Progress::begin`] … [`Progress::finish`]
/// at a time.
pub trait Progress: Send + Sync {
    /// The work starts: `work` says what is counted and how many.
    fn begin(&self, work: Work);
    /// `done` of the steps are done (the position, not an increment).
    fn at(&self, done: u64);
    /// One more step is done: `what` (a run's name, shown beside the bar; may be empty).
    fn step(&self, what: &str);
    /// A line to show with the progress (above a bar), e.g. that a host of a run is lost.
    fn line(&self, text: &str);
    /// The work ended.
    fn finish(&self, how: Finish);
}

/// Progress told to no one: lines go to the `log` facade as notes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Quiet;

impl Progress for Quiet {
    fn begin(&self, _: Work) {}
    fn at(&self, _: u64) {}
    fn step(&self, _: &str) {}
    fn line(&self, text: &str) {
        log::info!("{text}");
    }
    fn finish(&self, _: Finish) {}
}

/// Who is told the progress of a piece of work: a [`Progress`] shared by the work's threads
/// (cheap to clone). The default tells no one ([`Quiet`]).
#[derive(Clone)]
pub struct Observer(std::sync::Arc<dyn Progress>);

impl Observer {
    pub fn new(progress: impl Progress + 'static) -> Self {
        Self(std::sync::Arc::new(progress))
    }

    /// Tells no one ([`Quiet`]).
    pub fn quiet() -> Self {
        Self::new(Quiet)
    }
}

impl Default for Observer {
    fn default() -> Self {
        Self::quiet()
    }
}

impl std::fmt::Debug for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Observer")
    }
}

impl std::ops::Deref for Observer {
    type Target = dyn Progress;

    fn deref(&self) -> &Self::Target {
        &*self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[derive(Default)]
    struct Recorded(Mutex<Vec<String>>);

    impl Recorded {
        fn push(&self, line: String) {
            self.0.lock().expect("not poisoned").push(line);
        }
    }

    impl Progress for std::sync::Arc<Recorded> {
        fn begin(&self, work: Work) {
            self.push(format!("begin {}", work.total()));
        }
        fn at(&self, done: u64) {
            self.push(format!("at {done}"));
        }
        fn step(&self, what: &str) {
            self.push(format!("step {what}"));
        }
        fn line(&self, text: &str) {
            self.push(text.into());
        }
        fn finish(&self, how: Finish) {
            self.push(format!("{how:?}"));
        }
    }

    /// A clone of an observer tells the same progress: the work's threads share one.
    #[test]
    fn an_observer_s_clones_tell_one_progress() {
        let seen = std::sync::Arc::new(Recorded::default());
        let o = Observer::new(seen.clone());
        let o2 = o.clone();
        o.begin(Work::Runs {
            total: 2,
            what: "runs".into(),
        });
        o2.step("one");
        o.at(2);
        o2.line("a host is lost");
        o.finish(Finish::Done);
        assert_eq!(
            *seen.0.lock().expect("not poisoned"),
            ["begin 2", "step one", "at 2", "a host is lost", "Done"]
        );
        assert_eq!(format!("{o:?}"), "Observer");
    }
}
