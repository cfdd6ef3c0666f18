//! `fdi-launch run`: a scenario (or `--replay` of a recorded run) into a run directory, its
//! report, its summary on stdout and its exit status.

use fdi_common::run_dir::RunDir;
use std::path::PathBuf;

use clap::Args;
use std::process::ExitCode;

use anyhow::Result;
use fdi_common::engine::RunSummary;
use fdi_common::stop::{Interrupted, Stop, BEFORE_THE_START, DURING_THE_RUN};
use fdi_orchestrator::run::runtime::Placement;
use fdi_orchestrator::run::{check_placement, volume};
use fdi_orchestrator::{execute, Engine, Overrides, RunRequest};
use fdi_report::output::{self, describe_error};
use fdi_report::report;
use fdi_report::traces::Traces;

/// `run`: a scenario, its overrides, the engine and what the run directory keeps.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scenario TOML file; without it the embedded paper scenario runs.
    pub scenario: Option<PathBuf>,
    /// A second argument: the address of a bare `--live` written with a space before it
    /// (`run --live 127.0.0.1:8765 FILE`, `run FILE --live 127.0.0.1:8765`).
    #[arg(hide = true)]
    pub live_addr: Option<String>,
    #[arg(long, value_parser = super::values::engine(), default_value_t = Engine::Ipc)]
    pub engine: Engine,
    #[command(flatten)]
    pub overrides: Overrides,
    /// Folder that receives the run directory.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// What the run directory keeps of the traces: `full`, `decimate=K` (every K-th tick) or
    /// `none`; the summary's metrics and digest cover every tick either way.
    #[arg(long, default_value_t = Traces::Full)]
    pub traces: Traces,
    /// Largest trace size a run may write (what `--traces` keeps, estimated before the start):
    /// `500MB`, `2GiB`, ...; a run over it, or over the free space of `--out`, is refused.
    #[arg(long, default_value = "10GB")]
    pub max_trace_size: bytesize::ByteSize,
    /// Start even when the estimated traces exceed the free space of `--out` (space that will
    /// be freed meanwhile; a full disk then stops the run naming the trace). The
    /// `--max-trace-size` limit still holds.
    #[arg(long)]
    pub no_space_check: bool,
    #[command(flatten)]
    pub placement: Placement,
    /// Split the run over hosts: a deployment file naming each host, its Zenoh endpoint and
    /// the processes it runs (docs/multi-host.md). Each other host runs `fdi-launch serve`.
    #[arg(long, value_name = "FILE")]
    pub hosts: Option<PathBuf>,
    /// Serve the run live over the Foxglove WebSocket protocol, at `--live=ADDR` (or
    /// `--live ADDR`, before or after the scenario file) or 127.0.0.1:8765 (port 0: a free port, printed): open it in Foxglove (Open connection →
    /// Foxglove WebSocket) with the layouts of examples/live (docs/traces.md). The run never
    /// waits for a viewer.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, require_equals = true, default_missing_value = "")]
    pub live: Option<LiveAt>,
    /// Ticks a second of wall time the live stream keeps at most: every K-th tick (a paced or
    /// realtime run: K from its pace; an unpaced lockstep run: K measured from its speed), and
    /// never more than HZ × 5 s (at most 500) at once.
    #[arg(long, value_name = "HZ", default_value_t = fdi_live::Options::DEFAULT_RATE_HZ, requires = "live")]
    pub live_rate: f64,
    /// Start the run once a viewer subscribed to a topic of `--live` (waiting at most SECONDS,
    /// then starting anyway), so that it sees the run from its first tick.
    #[arg(long, value_name = "SECONDS", requires = "live")]
    pub live_wait: Option<f64>,
    /// Slow a lockstep run to FACTOR × real time (1 = real time), to watch it; its numbers are
    /// the same.
    #[arg(long, value_name = "FACTOR")]
    pub pace: Option<f64>,
    /// Golden regression: re-run the control center of a recorded run directory on its recorded
    /// tampered measurements and compare the trace digest with the recording's (exit status 1
    /// when they differ). The scenario comes from RUN_DIR.
    #[arg(long, value_name = "RUN_DIR", conflicts_with_all = ["scenario", "engine", "clock", "attack", "controller", "duration_s", "seed", "rt_priority", "cpus", "hosts", "live", "live_wait", "pace", "observer_input", "leakage_w_per_s", "dead_zone_rad_s", "innovation_time_constant_s", "set"])]
    pub replay: Option<PathBuf>,
    /// The command that runs the scenario when it is not `run` itself (`detect`): the run
    /// directory's name starts with it (`<timestamp>-detect-paper`), apart from `run`'s.
    #[arg(skip)]
    pub run_by: Option<&'static str>,
}

/// Where `--live` serves: a bare `--live` (its address is the default, or the argument written
/// after it with a space), or `--live=ADDR`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LiveAt {
    Bare,
    At(std::net::SocketAddr),
}

impl std::str::FromStr for LiveAt {
    type Err = std::net::AddrParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.is_empty() {
            Ok(Self::Bare)
        } else {
            s.parse().map(Self::At)
        }
    }
}

/// `run`.
pub fn run(args: &RunArgs, stop: &Stop) -> Result<ExitCode> {
    if let Some(recorded) = &args.replay {
        return replay(recorded, args, stop);
    }
    run_scenario(args, stop).map(|done| done.code)
}

/// `run --replay RUN_DIR`: the recorded run's control center again, its digest compared.
fn replay(recorded: &std::path::Path, args: &RunArgs, stop: &Stop) -> Result<ExitCode> {
    let progress = crate::terminal::progress(!args.json);
    let replayed =
        fdi_orchestrator::run::replayer::replay_run(recorded, &args.out, &progress, stop)?;
    let (want, got) = (
        &replayed.recorded_trace_digest,
        &replayed.summary.trace_digest,
    );
    if args.json {
        let mut v = serde_json::to_value(&replayed.summary)?;
        v["run_dir"] = serde_json::Value::String(replayed.dir.display().to_string());
        v["replay_of"] = serde_json::Value::String(recorded.display().to_string());
        v["recorded_trace_digest"] = serde_json::Value::String(want.clone());
        v["digests_match"] = serde_json::Value::Bool(replayed.matches());
        println!("{v}");
    } else {
        println!("recorded trace digest {want}");
        println!("replayed trace digest {got}");
        println!(
            "{}",
            ["digests DIFFER", "digests match"][usize::from(replayed.matches())]
        );
        println!("run directory {}", replayed.dir.display());
    }
    if replayed.matches() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!(
            "fdi-launch: the replayed control center differs from the recording ({got} ≠ {want})"
        );
        Ok(ExitCode::FAILURE)
    }
}

/// The request of `run`'s flags, checked before anything starts: the overrides, the placement,
/// the traces' volume, the hosts file.
fn request(args: &RunArgs) -> Result<RunRequest> {
    let (scenario, live) = scenario_and_live(args)?;
    let mut request = RunRequest::new(scenario, &args.overrides, args.engine)?;
    if let Some(command) = args.run_by {
        request.name = format!("{command}-{}", request.name);
    }
    let r = &request.resolved;
    check_placement(r, args.engine, &args.placement)?;
    volume::check_volume(
        r,
        args.engine == Engine::Ipc,
        args.traces,
        &args.out,
        args.max_trace_size,
        !args.no_space_check,
    )?;
    if let Some(path) = &args.hosts {
        let split = fdi_split::load(path, r)?;
        request = request.over_hosts(split);
    }
    request.traces = args.traces;
    request.placement = args.placement.clone();
    fdi_orchestrator::run::check_pace(&request.resolved, args.pace)?;
    request.live = live
        .map(|addr| fdi_orchestrator::run::LiveServe::new(addr, args.live_rate, args.live_wait))
        .transpose()?;
    request.pace = args.pace;
    request.progress = crate::terminal::progress(!args.json);
    Ok(request)
}

/// The scenario file and the live address of `run`'s flags. `--live 127.0.0.1:8765` (with a
/// space, as most tools take an option's value) reaches clap as a bare `--live` and an
/// argument `127.0.0.1:8765`, before or after the scenario file: an argument that is an address
/// and no file is then the address of `--live`. After `--live=ADDR` it is refused, naming both;
/// so is a second argument that is no address of `--live`.
fn scenario_and_live(
    args: &RunArgs,
) -> Result<(Option<&std::path::Path>, Option<std::net::SocketAddr>)> {
    let address = |p: &std::path::Path| {
        p.to_str()
            .and_then(|s| s.parse::<std::net::SocketAddr>().ok())
            .filter(|_| !p.exists())
    };
    let given: Vec<&std::path::Path> = args
        .scenario
        .as_deref()
        .into_iter()
        .chain(args.live_addr.as_deref().map(std::path::Path::new))
        .collect();
    let Some(live) = args.live else {
        if let Some(extra) = &args.live_addr {
            anyhow::bail!("`{extra}`: `run` takes one scenario file");
        }
        return Ok((args.scenario.as_deref(), None));
    };
    let default: std::net::SocketAddr = fdi_live::Options::DEFAULT_ADDR
        .parse()
        .map_err(|e| anyhow::anyhow!("the default live address: {e}"))?;
    let addrs: Vec<std::net::SocketAddr> = given.iter().filter_map(|p| address(p)).collect();
    let files: Vec<&std::path::Path> = given
        .iter()
        .copied()
        .filter(|p| address(p).is_none())
        .collect();
    match (addrs.as_slice(), files.as_slice()) {
        ([], [_, second]) => {
            anyhow::bail!("`{}`: `run` takes one scenario file", second.display())
        }
        ([], _) => Ok((
            files.first().copied(),
            Some(match live {
                LiveAt::Bare => default,
                LiveAt::At(a) => a,
            }),
        )),
        ([addr], _) => match live {
            LiveAt::Bare => Ok((files.first().copied(), Some(*addr))),
            LiveAt::At(given) => anyhow::bail!(
                "`{addr}` is an address, not a scenario file, and --live has its address already ({given}): \
                 give one address, as `--live=ADDR`"
            ),
        },
        _ => anyhow::bail!(
            "two addresses for --live ({}): give one, as `--live=ADDR`",
            addrs
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// What [`run_scenario`] left: the run directory, and the exit status of the run.
#[derive(Debug)]
pub struct RunDone {
    pub dir: PathBuf,
    pub code: ExitCode,
    /// The run was a clean success (exit status 0).
    pub clean: bool,
}

/// `run` of a scenario (not `--replay`): runs it, writes the run directory and its report,
/// prints the summary.
pub fn run_scenario(args: &RunArgs, stop: &Stop) -> Result<RunDone> {
    let request = request(args)?;
    // What `validate` warns of, said before the run (an attack that never acts, a gain far
    // from the calibration, …): the run goes on.
    let r = &request.resolved;
    for w in r.scenario.warnings(&r.attack) {
        eprintln!("fdi-launch: warning: {}: {}", w.path, w.message);
    }
    stop.check(BEFORE_THE_START)?;
    let run_dir = request.create_run_dir(&args.out)?;
    let summary = execute(&request, &run_dir, stop)?;
    let (r, dir) = (&request.resolved, run_dir.path().to_path_buf());
    for lost in &summary.lost_agents {
        let when = lost
            .t_s
            .map_or(String::new(), |t| format!(" after t = {t:.3} s"));
        let uncontrolled = summary
            .metrics
            .get(&lost.agent.to_string())
            .map_or(String::new(), |m| {
                format!(
                    "; it ran uncontrolled for {} of its {} ticks, with {} deadline misses; its metrics cover {}",
                    m.uncontrolled_ticks,
                    m.agent_ticks,
                    m.deadline_misses,
                    output::coverage(m.ticks, summary.planned_ticks)
                )
            });
        match lost.rejoined_t_s {
            Some(back) => eprintln!(
                "fdi-launch: agent {} was lost{when} ({}) and rejoined at t = {back:.3} s{uncontrolled}",
                lost.agent, lost.reason
            ),
            None => eprintln!(
                "fdi-launch: agent {} was lost{when}: {}{uncontrolled}",
                lost.agent, lost.reason
            ),
        }
    }
    // The report is written whole or not at all; an interrupt stops it at once.
    let report = match report::write_report(&RunDir::new(&dir), r, &summary, stop) {
        Err(e) if e.downcast_ref::<Interrupted>().is_some() => return Err(e),
        other => other,
    };
    if args.json {
        let mut v = serde_json::to_value(&summary)?;
        v["run_dir"] = serde_json::Value::String(dir.display().to_string());
        println!("{v}");
    } else {
        print_summary(&summary);
        println!("run directory {}", dir.display());
        let md = run_dir.report().join("report.md");
        if md.is_file() {
            println!("report {}", md.display());
        }
    }
    if let Err(e) = report {
        eprintln!(
            "fdi-launch: error: the report of {} could not be made: {}; summary.json, rmse.md and the traces are kept (`fdi-launch report {}` makes it)",
            dir.display(),
            describe_error(&e),
            dir.display()
        );
        return Ok(RunDone {
            dir,
            code: ExitCode::FAILURE,
            clean: false,
        });
    }
    let code = exit_code(&summary);
    if let Some(verdict) = verdict(&summary) {
        eprintln!("fdi-launch: {verdict}");
    }
    let clean = code == ExitCode::SUCCESS;
    Ok(RunDone { dir, code, clean })
}

/// What a run that is not a clean success amounts to, in words (printed last), for the exit
/// codes 5 and 3: which robots ran without control and for how long.
fn verdict(s: &RunSummary) -> Option<String> {
    if s.partial.is_some() {
        return None;
    }
    if s.lost_agents.is_empty() {
        return behind(s);
    }
    // Per robot that was lost: the ticks the center never computed, and the steps the robot
    // itself found without the command due (late commands after a stall count there).
    let mut ids: Vec<u32> = s.lost_agents.iter().map(|l| l.agent).collect();
    ids.sort_unstable();
    ids.dedup();
    let robots: Vec<String> = ids
        .iter()
        .filter_map(|id| s.metrics.get(&id.to_string()).map(|m| (id, m)))
        .map(|(id, m)| {
            format!(
                "robot {id} {} ticks never controlled and {} deadline misses in {} steps",
                m.uncontrolled_ticks, m.deadline_misses, m.agent_ticks
            )
        })
        .collect();
    if s.lost_every_agent() {
        Some(format!(
            "run failed (exit 5): the control center lost every robot for good, none was controlled to the end ({})",
            robots.join("; ")
        ))
    } else if s.diverged().is_empty() {
        Some(format!(
            "not a clean run (exit 3): {} of {} robots were lost for a while and ran without control meanwhile ({}); the tracking metrics cover only the controlled ticks",
            ids.len(),
            s.agents,
            robots.join("; ")
        ))
    } else {
        None
    }
}

/// What a run whose robots were never lost but ran uncontrolled for some ticks, or fell behind
/// their clock, amounts to (exit 3).
fn behind(s: &RunSummary) -> Option<String> {
    if !s.diverged().is_empty() || !s.not_clean() {
        return None;
    }
    let mut said: Vec<String> = s
        .uncontrolled()
        .iter()
        .map(|(id, n, of)| format!("robot {id} ran uncontrolled for {n} of its {of} ticks"))
        .collect();
    said.extend(s.fell_behind().iter().map(|(id, n, of)| {
        format!(
            "robot {id} missed {n} of its {of} deadlines ({:.1} %)",
            100.0 * *n as f64 / (*of).max(1) as f64
        )
    }));
    Some(format!(
        "not a clean run (exit 3): the run fell behind its clock ({}; more than {:.0} % of a robot's deadlines missed, or any tick uncontrolled, is not clean): its numbers are results of an overloaded run, not of the scenario's timing",
        said.join("; "),
        100.0 * fdi_common::engine::MISSES_TOLERATED
    ))
}

/// The exit status of a run that produced a summary: 128 + signal when interrupted, 6 when the
/// bridges between hosts refused frames on the run's keys (its data may have been altered
/// outside the attacker: its results cannot be attributed), 5 when the
/// control center lost every robot for good (the run failed: none was controlled to its end),
/// 4 when a robot diverged, 3 when a realtime run lost a robot for a while, rejoined or not (it
/// ran uncontrolled meanwhile: not a clean run), or fell behind its clock (a robot ran
/// uncontrolled for some ticks, or missed more than
/// [`MISSES_TOLERATED`](fdi_common::engine::MISSES_TOLERATED) of its deadlines), else 0.
pub fn exit_code(summary: &RunSummary) -> ExitCode {
    if let Some(signal) = summary.partial.as_ref().and_then(|p| p.signal) {
        ExitCode::from(
            Interrupted {
                signal,
                phase: DURING_THE_RUN,
            }
            .exit_code(),
        )
    } else if summary
        .network
        .as_ref()
        .is_some_and(|n| n.refused_frames > 0)
    {
        ExitCode::from(6)
    } else if summary.lost_every_agent() {
        ExitCode::from(5)
    } else if !summary.diverged().is_empty() {
        ExitCode::from(4)
    } else if summary.not_clean() {
        ExitCode::from(3)
    } else {
        ExitCode::SUCCESS
    }
}

fn print_summary(s: &RunSummary) {
    println!(
        "scenario {} | engine {} | clock {} | controller {} | {} | {} agents | {:.1} s simulated in {:.2} s wall",
        s.scenario,
        s.engine,
        s.clock,
        s.controller,
        output::attack_words(s),
        s.agents,
        s.sim_s,
        s.wall_s
    );
    println!("numerics: {}", output::numerics_line(s));
    if let Some(p) = &s.placement {
        println!("processes: {p}");
    }
    if let Some(line) = output::network_line(s) {
        println!("{line}");
    }
    if let Some(line) = output::live_line(s) {
        println!("{line}");
    }
    if let Some(notice) = output::partial_notice(s) {
        println!("{}", notice.to_uppercase());
    }
    print!("{}", output::metrics_table(s));
    for (id, t) in s.diverged() {
        eprintln!("fdi-launch: robot {id} diverged at t = {t:.3} s (its state left the bound of {} rad or became non-finite): its metrics are not results", fdi_common::metrics::DIVERGENCE_BOUND_RAD);
    }
    for line in output::state_reset_warnings(s)
        .into_iter()
        .chain(output::rejected_torque_warnings(s))
    {
        eprintln!("fdi-launch: warning: {line}");
    }
    println!("trace digest {}", s.trace_digest);
}

#[cfg(test)]
mod tests {
    use std::process::ExitCode;

    use clap::Parser;

    fn run_args(argv: &[&str]) -> super::RunArgs {
        let cli = crate::cli::Cli::try_parse_from([&["fdi-launch", "run"], argv].concat())
            .expect("parses");
        let crate::cli::Command::Run(args) = cli.command else {
            panic!("not run")
        };
        args
    }

    /// Regression (issue 55): `run --live 127.0.0.1:8765` read the address as the scenario
    /// file ("cannot read 127.0.0.1:8765").
    #[test]
    fn live_with_a_space_before_its_address_serves_there_and_a_second_address_is_refused() {
        let args = run_args(&["--live", "127.0.0.1:8799"]);
        let (scenario, live) = super::scenario_and_live(&args).expect("accepted");
        assert_eq!(scenario, None);
        assert_eq!(live, Some("127.0.0.1:8799".parse().expect("an address")));
        for given in ["--live=127.0.0.1:8798", "--live=127.0.0.1:8765"] {
            let args = run_args(&[given, "127.0.0.1:8799"]);
            let e = super::scenario_and_live(&args).expect_err("two addresses");
            assert!(
                e.to_string().contains("`127.0.0.1:8799` is an address"),
                "{e}"
            );
        }
        let args = run_args(&["--live=127.0.0.1:8798"]);
        let (_, live) = super::scenario_and_live(&args).expect("accepted");
        assert_eq!(live, Some("127.0.0.1:8798".parse().expect("an address")));
        let args = run_args(&["--live=127.0.0.1:8798", "127.0.0.1:8799"]);
        let e = super::scenario_and_live(&args).expect_err("two addresses");
        assert!(
            e.to_string().contains("`127.0.0.1:8799` is an address"),
            "{e}"
        );
        // A scenario file stays one, and without --live an address is a file name.
        let args = run_args(&["--live", "scenarios/paper.toml"]);
        let (scenario, live) = super::scenario_and_live(&args).expect("accepted");
        assert_eq!(scenario, Some(std::path::Path::new("scenarios/paper.toml")));
        assert_eq!(
            live.map(|a| a.to_string()).as_deref(),
            Some("127.0.0.1:8765")
        );
        let args = run_args(&["127.0.0.1:8799"]);
        let (scenario, live) = super::scenario_and_live(&args).expect("accepted");
        assert_eq!(scenario, Some(std::path::Path::new("127.0.0.1:8799")));
        assert_eq!(live, None);
        // With a scenario file, before or after it.
        for argv in [
            ["--live", "127.0.0.1:8797", "x.toml"],
            ["x.toml", "--live", "127.0.0.1:8797"],
        ] {
            let args = run_args(&argv);
            let (scenario, live) = super::scenario_and_live(&args).expect("accepted");
            assert_eq!(scenario, Some(std::path::Path::new("x.toml")), "{argv:?}");
            assert_eq!(live, Some("127.0.0.1:8797".parse().expect("an address")));
        }
        let e = super::scenario_and_live(&run_args(&["a.toml", "b.toml"])).expect_err("two files");
        assert!(
            e.to_string()
                .contains("`b.toml`: `run` takes one scenario file"),
            "{e}"
        );
    }

    /// Regression (issue 51): a realtime run that fell behind its clock (a 1 MHz run with 90 %
    /// of its deadlines missed, its robots uncontrolled 44 % of the time) exited 0. Any tick
    /// uncontrolled, or more than a tenth of a robot's deadlines missed, is not a clean run:
    /// exit 3, said in words; a diverged robot still comes first (4).
    #[test]
    fn a_run_that_fell_behind_its_clock_exits_3_and_says_so() {
        let mut s = fdi_report::output::sample_summary();
        s.metrics.remove("2");
        let m = s.metrics.get_mut("1").expect("robot 1");
        (m.uncontrolled_ticks, m.deadline_misses, m.agent_ticks) = (0, 10, 100);
        assert_eq!(super::exit_code(&s), ExitCode::SUCCESS, "10 % is tolerated");
        assert_eq!(super::verdict(&s), None);
        let m = s.metrics.get_mut("1").expect("robot 1");
        m.deadline_misses = 11;
        assert_eq!(super::exit_code(&s), ExitCode::from(3));
        let said = super::verdict(&s).expect("a verdict");
        assert!(
            said.starts_with("not a clean run (exit 3): the run fell behind its clock (robot 1 missed 11 of its 100 deadlines (11.0 %)"),
            "{said}"
        );
        let m = s.metrics.get_mut("1").expect("robot 1");
        (m.deadline_misses, m.uncontrolled_ticks) = (0, 1);
        assert_eq!(super::exit_code(&s), ExitCode::from(3));
        assert!(super::verdict(&s)
            .is_some_and(|v| v.contains("robot 1 ran uncontrolled for 1 of its 100 ticks")));
        s.metrics.get_mut("1").expect("robot 1").diverged_at_s = Some(0.5);
        assert_eq!(super::exit_code(&s), ExitCode::from(4));
    }

    /// Regression (issue 18): an I/O error that is both the tail of its context's message and
    /// that context's source was printed twice (`No space left on device (os error 28): No
    /// space left on device (os error 28)`).
    #[test]
    fn an_error_whose_cause_is_already_in_its_message_is_described_once() {
        #[derive(Debug, thiserror::Error)]
        #[error("writing report.png: {0}")]
        struct Writing(#[source] std::io::Error);
        let io = std::io::Error::from_raw_os_error(28);
        let e = anyhow::Error::new(Writing(io)).context("figure robot1");
        let text = fdi_report::output::describe_error(&e);
        assert_eq!(text.matches("os error 28").count(), 1, "{text}");
        assert!(
            text.starts_with("figure robot1: writing report.png: "),
            "{text}"
        );
        let plain = anyhow::anyhow!("a").context("b");
        assert_eq!(fdi_report::output::describe_error(&plain), "b: a");
    }
}
