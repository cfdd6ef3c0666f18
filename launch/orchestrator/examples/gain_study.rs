//! A small parameter study through the Rust API: the paper's experiment, in-process, under the
//! paper's attack, for four values of the controller's gain β, and the RMSE of every robot.
//!
//! ```sh
//! cargo run --release --example gain_study [DURATION_S]
//! ```
//!
//! Each run is a run directory (traces, summary) in a scratch folder that is removed at the end;
//! `fdi-launch sweep` does the same with statistics over seeds, resumably, from a campaign file.
//! The libraries print nothing: what they have to say (a warning, a note) goes through the `log`
//! facade, which this program prints on stderr ([`Warnings`]; any logger will do).

use anyhow::{Context, Result};
use fdi_common::scenario::ControllerMode;
use fdi_common::stop::Stop;
use fdi_orchestrator::{execute, Engine, Overrides, RunRequest};

/// The libraries' warnings and notes on stderr.
struct Warnings;

impl log::Log for Warnings {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Info && m.target().starts_with("fdi")
    }

    fn log(&self, record: &log::Record) {
        if self.enabled(record.metadata()) {
            eprintln!("gain_study: {}: {}", record.level(), record.args());
        }
    }

    fn flush(&self) {}
}

fn main() -> Result<()> {
    if log::set_logger(&Warnings).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
    let duration_s: f64 = match std::env::args().nth(1) {
        Some(a) => a
            .parse()
            .with_context(|| format!("DURATION_S: `{a}` is not a number"))?,
        None => 5.0,
    };
    let out = tempfile::tempdir()?;
    let stop = Stop::new();
    let overrides = Overrides {
        duration_s: Some(duration_s),
        controller: Some(ControllerMode::Proposed),
        ..Overrides::default()
    };
    println!(
        "RMSE (rad) of every robot over {duration_s} s under the paper's attack, in-process\n"
    );
    for (i, beta) in [2.0, 5.0, 10.0, 20.0].into_iter().enumerate() {
        let mut request = RunRequest::new(None, &overrides, Engine::Inproc)?
            .edit(|s| s.controller.beta = beta)?;
        request.name = format!("beta-{beta}");
        let dir = request.create_run_dir(out.path())?;
        let summary = execute(&request, &dir, &stop)?;
        if i == 0 {
            let robots: Vec<String> = summary
                .metrics
                .keys()
                .map(|id| format!("robot {id}"))
                .collect();
            println!("| β | {} |", robots.join(" | "));
            println!("|---|{}", "---|".repeat(robots.len()));
        }
        let cells: Vec<String> = summary
            .metrics
            .values()
            .map(|m| format!("{:.4}", m.rmse_rad))
            .collect();
        println!("| {beta} | {} |", cells.join(" | "));
    }
    Ok(())
}
