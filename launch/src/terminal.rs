//! What the person at the terminal sees while a command works: the libraries' warnings and
//! notes (the `log` facade, printed on stderr as `fdi-launch: warning: …`) and their progress
//! ([`fdi_common::observe::Progress`], drawn as a bar on stderr when it is a terminal). A line
//! said while a bar is drawn goes above the bar, which is drawn again below it.

use std::sync::{Mutex, MutexGuard, OnceLock};

use fdi_common::observe::{Finish, Observer, Progress, Work, VERBATIM};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};

/// The bar being drawn, if any (one at a time: a run, or the runs of a table or campaign).
static BAR: Mutex<Option<ProgressBar>> = Mutex::new(None);
/// The program's name before each line (`fdi-launch`, `fdi-launch serve`).
static PROGRAM: OnceLock<&'static str> = OnceLock::new();

/// The program's name before each line.
fn program() -> &'static str {
    PROGRAM.get().copied().unwrap_or("fdi-launch")
}

fn bar() -> MutexGuard<'static, Option<ProgressBar>> {
    BAR.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Prints `line` on stderr, above the bar being drawn if there is one.
fn say(line: &str) {
    match &*bar() {
        Some(b) if !b.is_hidden() => b.println(line),
        _ => eprintln!("{line}"),
    }
}

/// The libraries' `log` records: those of fdi-mas's crates, warnings and notes; the rest
/// (the dependencies') are not shown.
struct Lines;

impl log::Log for Lines {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Info && m.target().starts_with("fdi")
    }

    fn log(&self, record: &log::Record) {
        if !self.enabled(record.metadata()) {
            return;
        }
        let program = program();
        let text = record.args();
        if record.target() == VERBATIM {
            say(&text.to_string());
            return;
        }
        match record.level() {
            log::Level::Error => say(&format!("{program}: error: {text}")),
            log::Level::Warn => say(&format!("{program}: warning: {text}")),
            _ => say(&format!("{program}: {text}")),
        }
    }

    fn flush(&self) {}
}

/// Prints the libraries' warnings and notes from now on, each line after `program`'s name.
/// Once per process; a second call changes nothing.
pub fn install(program: &'static str) {
    let _ = PROGRAM.set(program);
    if log::set_logger(&Lines).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
}

/// Progress drawn as a bar on stderr (when it is a terminal; indicatif hides it otherwise).
struct Bar;

impl Progress for Bar {
    fn begin(&self, work: Work) {
        let b = ProgressBar::with_draw_target(Some(work.total()), ProgressDrawTarget::stderr());
        b.set_style(style(&work));
        if let Work::Runs { what, .. } = &work {
            b.set_prefix(what.clone());
        }
        if let Some(old) = bar().replace(b) {
            old.finish_and_clear();
        }
    }

    fn at(&self, done: u64) {
        if let Some(b) = &*bar() {
            b.set_position(done);
        }
    }

    fn step(&self, what: &str) {
        if let Some(b) = &*bar() {
            b.set_message(what.to_string());
            b.inc(1);
        }
    }

    fn line(&self, text: &str) {
        say(&format!("{}: {text}", program()));
    }

    fn finish(&self, how: Finish) {
        if let Some(b) = bar().take() {
            match how {
                Finish::Done => b.finish_and_clear(),
                Finish::Stopped => b.abandon(),
            }
        }
    }
}

/// The progress of a command: a bar, or, with `shown` false (`--json`), only the lines said
/// beside it.
pub fn progress(shown: bool) -> Observer {
    if shown {
        Observer::new(Bar)
    } else {
        Observer::quiet()
    }
}

/// The bar of a run's ticks (its keys `sim` and `speed`: [`style`]).
const RUN_BAR: &str =
    "{spinner} [{elapsed_precise}] {bar:30} sim {sim} | {pos}/{len} ticks | {speed} | ETA {eta}";
/// The bar of the runs of a table, a campaign, a benchmark.
const RUNS_BAR: &str =
    "{prefix} [{elapsed_precise}] {bar:30} {pos}/{len} runs done, ETA {eta} | {msg}";

/// A run's bar shows the simulated time and the speed from its position (the control
/// center's last tick), so that the first frame shows them too (`sim 0.0 s`), and the speed is
/// a whole number of ticks per second with the share of real time (`33420 ticks/s, 33.4× real
/// time`; indicatif's own `{per_sec}` shows `33,420.1417/s`). Runs of a table or a campaign
/// show how many are done and the last one's name.
fn style(work: &Work) -> ProgressStyle {
    match *work {
        Work::Ticks { period_s, .. } => ProgressStyle::with_template(RUN_BAR).map(|s| {
            s.with_key(
                "sim",
                move |st: &ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = write!(w, "{:.1} s", st.pos() as f64 * period_s);
                },
            )
            .with_key(
                "speed",
                move |st: &ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = write!(w, "{}", speed(st.per_sec(), period_s));
                },
            )
        }),
        Work::Runs { .. } => ProgressStyle::with_template(RUNS_BAR),
    }
    .unwrap_or_else(|_| ProgressStyle::default_bar())
}

/// A run's speed in words: `33420 ticks/s, 33.4× real time` (`… ticks/s` alone before the
/// first estimate or with a period of 0).
fn speed(ticks_per_s: f64, dt: f64) -> String {
    let real = ticks_per_s * dt;
    if ticks_per_s.is_finite() && ticks_per_s > 0.0 && real.is_finite() && real > 0.0 {
        format!("{ticks_per_s:.0} ticks/s, {real:.1}× real time")
    } else {
        "… ticks/s".into()
    }
}

#[cfg(test)]
mod tests {
    /// Regression (issue 33): the bar showed `33,420.1417/s`.
    #[test]
    fn the_speed_is_whole_ticks_per_second_and_the_share_of_real_time() {
        assert_eq!(
            super::speed(33_420.141_7, 1e-3),
            "33420 ticks/s, 33.4× real time"
        );
        assert_eq!(super::speed(950.6, 1e-3), "951 ticks/s, 1.0× real time");
        assert_eq!(super::speed(0.0, 1e-3), "… ticks/s");
        assert_eq!(super::speed(f64::NAN, 1e-3), "… ticks/s");
    }

    /// Both templates parse (a bad one would fall back to indicatif's plain bar unseen).
    #[test]
    fn both_bars_templates_parse() {
        for template in [super::RUN_BAR, super::RUNS_BAR] {
            assert!(
                indicatif::ProgressStyle::with_template(template).is_ok(),
                "{template}"
            );
        }
    }
}
