//! `fdi-launch score`: the scored benchmark of a controller (docs/score.md), run as a campaign
//! of the suite (`fdi_campaign::score`): whole, one shard of it, its aggregation or its status.

use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use fdi_campaign::score;
use fdi_campaign::suite::{SuiteFile, DEFAULT_DETECTOR};
use fdi_campaign::{shard::ShardArg, Ended, SweepOptions};
use fdi_common::control::ControllerMode;
use fdi_common::stop::Stop;
use fdi_orchestrator::Engine;
use fdi_report::traces::Traces;

use super::values::one_of;

/// `score`.
#[derive(Debug, clap::Args)]
pub struct ScoreArgs {
    /// The controller to score.
    #[arg(long, default_value = "proposed", value_parser = one_of(ControllerMode::ALL, ControllerMode::as_str, |_| None))]
    pub controller: ControllerMode,
    /// The detector whose alarms are judged: `s_hat_norm` (the control center's own alarm; the
    /// `gated` controller's gate), `chi2`, `cusum`, `window_mean`.
    #[arg(long, default_value = DEFAULT_DETECTOR)]
    pub detector: String,
    /// The teams to run (comma-separated: `paper`, `panda`, `mixed`; default every one): a row
    /// of some teams compares only with rows of the same teams.
    #[arg(long, value_delimiter = ',')]
    pub teams: Option<Vec<String>>,
    /// The suite's folder (its campaign file, its runs' results, its tables, `score.json` and
    /// `score.md`); default `runs/<timestamp>-score-<controller>`. Required with `--shard`,
    /// `--aggregate` and `--status`, which work on one folder.
    #[arg(long, required_if_eq_any = [("aggregate", "true"), ("status", "true")])]
    pub out: Option<PathBuf>,
    /// Runs at a time (default: the number of CPUs).
    #[arg(long)]
    pub jobs: Option<NonZeroUsize>,
    /// Run only shard K of N of the suite (`K/N`, or `auto` under Slurm or Kubernetes), as
    /// `fdi-launch sweep --shard` does; `--aggregate` then makes the row.
    #[arg(long, value_name = "K/N|auto", requires = "out", conflicts_with_all = ["aggregate", "status", "compare", "json"])]
    pub shard: Option<ShardArg>,
    /// Run nothing: the row from the results the shards stored in `--out` (the runs missing
    /// are named with the shard that owns each).
    #[arg(long, conflicts_with = "status")]
    pub aggregate: bool,
    /// Run nothing: per shard, its runs done of its total and the time left.
    #[arg(long, conflicts_with_all = ["compare", "json"])]
    pub status: bool,
    /// Print the suite as a campaign file and run nothing (for `fdi-launch sweep` and the
    /// cluster scripts of examples/cluster/).
    #[arg(long, conflicts_with_all = ["shard", "aggregate", "status", "compare", "json"])]
    pub campaign: bool,
    /// Print the row as JSON (one line) instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// A row written before (`score.json`): print both side by side.
    #[arg(long, value_name = "SCORE_JSON", conflicts_with = "json")]
    pub compare: Option<PathBuf>,
}

/// Runs the suite (or a shard of it, or makes its row from what the shards stored), prints its
/// row (and, with `--compare`, both rows side by side); exit status 1 when runs failed or are
/// missing.
pub fn score(args: &ScoreArgs, stop: &Stop) -> Result<ExitCode> {
    let suite = SuiteFile::new(args.controller, &args.detector, args.teams.as_deref());
    suite.checked()?;
    let name = format!("score-{}", args.controller.as_str());
    let text = suite.campaign_text(&name)?;
    if args.campaign {
        print!("{text}");
        return Ok(ExitCode::SUCCESS);
    }
    // The other row is read first: a wrong file stops before the suite runs.
    let other = args.compare.as_deref().map(score::read_row).transpose()?;
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!(
            "{}-score-{}",
            fdi_orchestrator::run_dirs::timestamp(),
            args.controller.as_str()
        ))
    });
    let campaign = place_campaign(&out, &text, args.aggregate || args.status)?;
    let options = SweepOptions {
        campaign,
        jobs: args.jobs,
        engine: Engine::Inproc,
        out: Some(out.clone()),
        traces: Traces::None,
        shard: args.shard,
        aggregate: args.aggregate,
        status: args.status,
        progress: crate::terminal::progress(true),
    };
    // What the campaign says goes to the standard error: the standard output is the row's.
    let ended = fdi_campaign::sweep(&options, stop, &mut |line| eprintln!("{line}"))?;
    if ended == Ended::Incomplete {
        return Ok(ExitCode::FAILURE);
    }
    if args.shard.is_some() || args.status {
        return Ok(ExitCode::SUCCESS);
    }
    let row = score::read_row(&out.join("score.json"))?;
    if args.json {
        println!("{}", serde_json::to_string(&row)?);
    } else {
        print!("{}", score::markdown(&row));
        println!("\nrow written to {}", out.join("score.json").display());
    }
    if let Some(other) = other {
        print!("\n{}", score::compare(&row, &other)?);
    }
    Ok(ExitCode::SUCCESS)
}

/// The suite's campaign file in its folder `out` (written, or found there as the same text); a
/// folder of another campaign is refused, naming it, and so is a folder without the file when
/// it must be there (`existing`: `--aggregate`, `--status`, which run nothing). Written
/// atomically: the shards of an array job start at once, and one must not read another's half
/// file.
fn place_campaign(out: &Path, text: &str, existing: bool) -> Result<PathBuf> {
    let file = out.join("campaign.toml");
    let read = || match std::fs::read_to_string(&file) {
        Ok(there) => Ok(Some(there)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e).with_context(|| format!("reading {}", file.display())),
    };
    match read()? {
        Some(there) if there == text => return Ok(file),
        Some(_) => bail!(
            "{} holds another campaign than this suite's (another controller, detector or teams, or another launcher's suite): score into another --out, or run it with `fdi-launch sweep {}`",
            file.display(),
            file.display()
        ),
        None if existing => bail!(
            "{} holds no suite (no campaign.toml): run the suite or its shards into it first",
            out.display()
        ),
        None => {}
    }
    if out.exists() && !out.is_dir() {
        bail!("--out {} is not a folder", out.display());
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    fdi_campaign::store::write_atomic(&file, text.as_bytes())?;
    Ok(file)
}
