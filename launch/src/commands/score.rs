//! `fdi-launch score`: the scored benchmark of a controller (docs/score.md).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use fdi_common::control::ControllerMode;
use fdi_common::stop::Stop;
use fdi_tables::score::{self, Row, ScoreOptions};

use super::values::one_of;

/// `score`.
#[derive(Debug, clap::Args)]
pub struct ScoreArgs {
    /// The controller to score.
    #[arg(long, default_value = "proposed", value_parser = one_of(ControllerMode::ALL, ControllerMode::as_str, |_| None))]
    pub controller: ControllerMode,
    /// The detector whose alarms are judged: `s_hat_norm` (the control center's own alarm; the
    /// `gated` controller's gate), `chi2`, `cusum`, `window_mean`.
    #[arg(long, default_value = "s_hat_norm")]
    pub detector: String,
    /// Folder that receives `score.json` and `score.md`; default `runs/<timestamp>-score-<controller>`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print the row as JSON (one line) instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// A row written before (`score.json`): print both side by side.
    #[arg(long, value_name = "SCORE_JSON", conflicts_with = "json")]
    pub compare: Option<PathBuf>,
}

/// Runs the suite, prints its row (and, with `--compare`, both rows side by side).
pub fn score(args: &ScoreArgs, stop: &Stop) -> Result<ExitCode> {
    // The other row is read first: a wrong file stops before the suite runs.
    let other: Option<Row> = match &args.compare {
        Some(path) => {
            let text = fdi_common::files::read_limited(path)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            Some(
                serde_json::from_str(&text)
                    .with_context(|| format!("{}: not a score row", path.display()))?,
            )
        }
        None => None,
    };
    let options = ScoreOptions {
        controller: args.controller,
        detector: args.detector.clone(),
        out: args.out.clone(),
    };
    let scored = score::score(&options, stop)?;
    if args.json {
        println!("{}", serde_json::to_string(&scored.row)?);
    } else {
        print!("{}", scored.md);
        println!(
            "\nrow written to {}",
            scored.dir.join("score.json").display()
        );
    }
    if let Some(other) = other {
        print!("\n{}", score::compare(&scored.row, &other)?);
    }
    Ok(ExitCode::SUCCESS)
}
