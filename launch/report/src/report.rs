//! Reports of run directories: `RUN_DIR/report/` with, per robot, the figures of the paper's
//! Figs. 3–6 (position error, angular-velocity error, attack estimate against the true attack,
//! acceleration-estimate error) plus torque and delay/alarm timelines, each as PNG and SVG; the
//! detection metrics and per-segment error maxima as CSV; and `report.md` that shows it all.
//!
//! The figures are drawn from the joined traces ([`join::join_run`]), downsampled by min/max
//! envelopes (about [`BUCKETS`] buckets per curve) so that short spikes stay visible while the
//! files stay small. The per-segment table is computed at the full tick rate.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::traces::Recorded;
use anyhow::{bail, Context, Result};
use fdi_common::engine::RunSummary;
use fdi_common::records::{true_s, TickRecord};
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::{self, Resolved, MAX_DOF};
use fdi_common::stop::{Stop, WHILE_REPORTING};
use fdi_common::trajectory::TrajectoryConfig;

use crate::join;
use crate::output::{csv_bytes, md_table_head};
use crate::plot::{
    self, Band, Envelope, Figure, Guide, Intervals, Line, Panel, PanelKind, PALETTE,
};
use crate::team::{self, PerRobot};

/// Buckets per plotted curve (each gives its minimum and maximum).
pub const BUCKETS: u64 = 2000;
/// After an attack switch, the error maxima are split into this first window and the rest.
pub const SWITCH_WINDOW_S: f64 = 1.0;

/// Scenario names taken for the paper's experiment: their position- and velocity-error figures
/// show the bounds the paper states ([`PAPER_POSITION_BOUND_RAD`], [`PAPER_VELOCITY_BOUND_RAD_S`])
/// as a band. `paper` is the embedded default and `scenarios/paper.toml`; `paper-linkwise` is the
/// same experiment under the link-wise reading of the attack. Command-line overrides (attack,
/// controller, duration) keep the name, and the band, as a reference to compare with.
pub const PAPER_SCENARIOS: [&str; 2] = ["paper", "paper-linkwise"];
/// The paper's bound on the position error (Section VII: robot 1, Fig. 3(a); robot 4, Fig. 6(a)).
pub const PAPER_POSITION_BOUND_RAD: f64 = 0.02;
/// The paper's bound on the angular-velocity error (Section VII: robot 1, Fig. 3(b)).
pub const PAPER_VELOCITY_BOUND_RAD_S: f64 = 0.01;

/// Whether the report draws the paper's bounds for this scenario.
pub fn is_paper_scenario(r: &Resolved) -> bool {
    PAPER_SCENARIOS.contains(&r.scenario.name.as_str())
}

/// The paper's bands for robot `id`: (position, velocity). The paper states the position bound
/// for robots 1 and 4 and the velocity bound for robot 1; the other robots get robot 1's bound
/// as a reference, labelled as such.
fn paper_guides(id: u32) -> (Guide, Guide) {
    let b = PAPER_POSITION_BOUND_RAD;
    let v = PAPER_VELOCITY_BOUND_RAD_S;
    let pos = match id {
        1 => format!("paper, Fig. 3(a): ±{b} rad"),
        4 => format!("paper, Fig. 6(a): ±{b} rad"),
        _ => format!("paper (robot 1): ±{b} rad"),
    };
    let vel = match id {
        1 => format!("paper, Fig. 3(b): ±{v} rad/s"),
        _ => format!("paper (robot 1): ±{v} rad/s"),
    };
    (
        Guide {
            label: pos,
            lo: -b,
            hi: b,
        },
        Guide {
            label: vel,
            lo: -v,
            hi: v,
        },
    )
}

/// The figure kinds made for every robot: (file suffix, what it shows).
pub const FIGURES: [(&str, &str); 6] = [
    ("position-error", "(a) position error q_d − q"),
    ("velocity-error", "(b) angular-velocity error"),
    (
        "attack-estimate",
        "(c) attack estimate Ŝ against the true S",
    ),
    ("acceleration-error", "(d) acceleration-estimate error"),
    ("torque", "torque u sent by the control center"),
    ("delay-alarm", "delay τ(t), attack and alarm timeline"),
];

/// `fdi-launch report RUN_DIR`: joins the traces again and recomputes the summary; the engine
/// and the wall time, which the traces do not hold, come from `summary.json` when it is there.
/// `per_robot` chooses the robots that get their own figures (the team figure comes with a
/// team of more than [`team::HANDFUL`]).
/// Returns the path of the report's `report.md`.
pub fn report(run: &RunDir, per_robot: &PerRobot, stop: &Stop) -> Result<PathBuf> {
    let run_dir = run.path();
    let scenario_path = RunDir::new(run_dir).scenario();
    let resolved = scenario::load_written(&scenario_path)
        .with_context(|| format!("reading the scenario of run {}", run_dir.display()))?;
    let figured = figured(&resolved, per_robot)?;
    let mut warnings = Vec::new();
    let summary_path = RunDir::new(run_dir).summary();
    let stored = read_stored_summary(&summary_path, &mut warnings);
    let kept = crate::traces::recorded(run)?;
    if kept != Recorded::Full {
        // Decimated or no traces: only the run's summary covers every tick.
        let Some(s) = stored else {
            bail!(
                "{}: needed: the traces of run {} do not hold every tick ({}), so only its summary has the run's metrics",
                summary_path.display(),
                run_dir.display(),
                kept_words(kept)
            );
        };
        let (series, joined) = gather(run_dir, &resolved, kept, stop)?;
        warnings.extend(joined);
        let gathered = Gathered {
            series,
            warnings: &warnings,
            kept,
            figured,
        };
        return write_and_name(run_dir, (&resolved, &s), gathered, stop);
    }
    let (series, summary) = rejoin(run_dir, &resolved, stored.as_ref(), &mut warnings, stop)?;
    let gathered = Gathered {
        series,
        warnings: &warnings,
        kept,
        figured,
    };
    write_and_name(run_dir, (&resolved, &summary), gathered, stop)
}

/// The run's `summary.json`, if it can be read; why not is pushed onto `warnings`.
fn read_stored_summary(summary_path: &Path, warnings: &mut Vec<String>) -> Option<RunSummary> {
    match std::fs::read_to_string(summary_path) {
        Ok(text) => match serde_json::from_str::<RunSummary>(&text) {
            Ok(s) => Some(s),
            Err(e) => {
                warnings.push(format!(
                    "{}: cannot be read ({e}); engine and wall time are unknown",
                    summary_path.display()
                ));
                None
            }
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            warnings.push(format!(
                "{} is missing; engine and wall time are unknown",
                summary_path.display()
            ));
            None
        }
        // A directory, text that is not UTF-8, no permission: said as it is, not "missing".
        Err(e) => {
            let why = match e.kind() {
                std::io::ErrorKind::InvalidData => "it is not UTF-8 text".to_string(),
                std::io::ErrorKind::IsADirectory => "it is a directory".to_string(),
                _ => e.to_string(),
            };
            warnings.push(format!(
                "{} cannot be read ({why}); engine and wall time are unknown",
                summary_path.display()
            ));
            None
        }
    }
}

/// The robots of `r` that get their own figures under `per_robot`.
fn figured(r: &Resolved, per_robot: &PerRobot) -> Result<std::collections::BTreeSet<u32>> {
    let ids: Vec<u32> = r.scenario.agents.iter().map(|a| a.id).collect();
    per_robot.robots(&ids).map_err(anyhow::Error::msg)
}

/// Joins a run's full traces again: the figures' series and the summary recomputed, with
/// what only the stored summary knows (engine, placement, hosts, lost robots, early end).
fn rejoin(
    run_dir: &Path,
    resolved: &Resolved,
    stored: Option<&RunSummary>,
    warnings: &mut Vec<String>,
    stop: &Stop,
) -> Result<(RunSeries, RunSummary)> {
    let report_interrupted = || interrupted(stop);
    let mut series = RunSeries::new(resolved);
    let joined = join::join_run_until(
        resolved,
        run_dir,
        stored.map_or(f64::NAN, |s| s.wall_s),
        |r| series.push(r),
        report_interrupted,
    )?;
    warnings.extend(joined.warnings);
    let mut summary = joined.summary;
    match stored {
        Some(s) => {
            summary.engine.clone_from(&s.engine);
            summary.placement.clone_from(&s.placement);
            summary.hosts.clone_from(&s.hosts);
            summary.network.clone_from(&s.network);
            // What only the run knew: which robots were lost, and why it ended early.
            summary.lost_agents.clone_from(&s.lost_agents);
            summary.partial.clone_from(&s.partial);
            if s.trace_digest != summary.trace_digest {
                warnings.push(format!(
                    "the traces' digest {} differs from the digest {} in summary.json",
                    summary.trace_digest, s.trace_digest
                ));
            }
        }
        None => summary.engine = "unknown".into(),
    }
    Ok((series, summary))
}

/// Says the report's warnings, writes it, and returns its `report.md`.
fn write_and_name(
    run_dir: &Path,
    run: (&Resolved, &RunSummary),
    gathered: Gathered<'_>,
    stop: &Stop,
) -> Result<PathBuf> {
    for w in gathered.warnings {
        log::warn!("{w}");
    }
    write(run_dir, run, gathered, stop)
}

/// `decimate=K` / `none`, in words.
fn kept_words(kept: Recorded) -> String {
    match kept {
        Recorded::Full => "every tick".into(),
        Recorded::Decimated(k) => format!("`--traces decimate={k}`: every {k}-th tick"),
        Recorded::None => "`--traces none`: no trace".into(),
    }
}

/// The figures' series of a run whose traces keep every K-th tick (or none), and the join's
/// warnings.
fn gather(
    run_dir: &Path,
    resolved: &Resolved,
    kept: Recorded,
    stop: &Stop,
) -> Result<(RunSeries, Vec<String>)> {
    let report_interrupted = || interrupted(stop);
    let mut series = RunSeries::new(resolved);
    match kept {
        Recorded::Decimated(k) => {
            series.every = u64::from(k.max(1));
            let joined =
                join::join_decimated(resolved, run_dir, k, |r| series.push(r), report_interrupted)?;
            Ok((series, joined.warnings))
        }
        Recorded::None => Ok((series, Vec::new())),
        Recorded::Full => {
            let joined = join::join_run_until(
                resolved,
                run_dir,
                f64::NAN,
                |r| series.push(r),
                report_interrupted,
            )?;
            Ok((series, joined.warnings))
        }
    }
}

/// Called at the end of every `run`, with the run's summary.
pub fn write_report(
    run: &RunDir,
    resolved: &Resolved,
    summary: &RunSummary,
    stop: &Stop,
) -> Result<()> {
    let run_dir = run.path();
    let kept = crate::traces::recorded(run)?;
    let figured = figured(resolved, &PerRobot::Auto)?;
    let (series, warnings) = gather(run_dir, resolved, kept, stop)?;
    let gathered = Gathered {
        series,
        warnings: &warnings,
        kept,
        figured,
    };
    write(run_dir, (resolved, summary), gathered, stop)?;
    Ok(())
}

/// `Err(Interrupted)` once the stop is raised (SIGINT, SIGTERM): the report stops at once.
fn interrupted(stop: &Stop) -> Result<()> {
    Ok(stop.check(WHILE_REPORTING)?)
}

/// What a report is made of: the figures' series, the join's warnings, and what the traces
/// kept.
struct Gathered<'a> {
    series: RunSeries,
    warnings: &'a [String],
    kept: Recorded,
    /// The robots that get their own figures.
    figured: std::collections::BTreeSet<u32>,
}

/// Maxima of one attack segment of one robot, at the full tick rate.
#[derive(Debug, Clone)]
struct SegmentStats {
    from_s: f64,
    to_s: f64,
    /// Per link, over `[from, from + SWITCH_WINDOW_S)` and over the rest.
    pos_first: Vec<f64>,
    pos_rest: Vec<f64>,
    vel_first: Vec<f64>,
    vel_rest: Vec<f64>,
    /// Sum of `‖Ŝ − S‖²` and ticks, for the RMS.
    s_err_sq: f64,
    ticks: u64,
}

impl SegmentStats {
    fn new(from_s: f64, to_s: f64, dof: usize) -> Self {
        Self {
            from_s,
            to_s,
            pos_first: vec![0.0; dof],
            pos_rest: vec![0.0; dof],
            vel_first: vec![0.0; dof],
            vel_rest: vec![0.0; dof],
            s_err_sq: 0.0,
            ticks: 0,
        }
    }
}

/// What the report draws of one robot, accumulated tick by tick.
struct AgentSeries {
    id: u32,
    dof: usize,
    trajectory: TrajectoryConfig,
    /// Attack switch times in `(0, duration)`.
    switches: Vec<f64>,
    pos: Vec<Envelope>,
    /// `‖q_d − q‖` over the links, for the team figure (coarser: [`team::TEAM_BUCKETS`]).
    pos_norm: Envelope,
    vel: Vec<Envelope>,
    s_hat: Vec<Envelope>,
    s_true: Vec<Envelope>,
    acc: Vec<Envelope>,
    u: Vec<Envelope>,
    tau_ms: Envelope,
    active: Intervals,
    alarm: Intervals,
    missed: Intervals,
    segments: Vec<SegmentStats>,
    last_t: f64,
    /// Ticks recorded (joined) for this robot.
    ticks: u64,
}

/// Per-robot series of a run.
struct RunSeries {
    beta: f64,
    period_s: f64,
    /// Ticks between two recorded ticks: 1, or K of `--traces decimate=K`.
    every: u64,
    duration_s: f64,
    agents: Vec<AgentSeries>,
}

impl RunSeries {
    fn new(r: &Resolved) -> Self {
        let s = &r.scenario;
        let ticks = r.ticks();
        let stride = usize::try_from(ticks.div_ceil(BUCKETS)).unwrap_or(1).max(1);
        let env = |n: usize| (0..n).map(|_| Envelope::new(stride, ticks)).collect();
        let team_stride = usize::try_from(ticks.div_ceil(team::TEAM_BUCKETS))
            .unwrap_or(1)
            .max(1);
        let agents = s
            .agents
            .iter()
            .map(|a| {
                let dof = a.model.dof().min(MAX_DOF);
                let switches = switch_times(r, a.id, s.duration_s);
                let mut bounds = vec![0.0];
                bounds.extend(&switches);
                bounds.push(s.duration_s);
                AgentSeries {
                    id: a.id,
                    dof,
                    trajectory: a.trajectory.clone(),
                    segments: bounds
                        .windows(2)
                        .map(|w| SegmentStats::new(w[0], w[1], dof))
                        .collect(),
                    switches,
                    pos: env(dof),
                    pos_norm: Envelope::new(team_stride, ticks),
                    vel: env(dof),
                    s_hat: env(dof),
                    s_true: env(dof),
                    acc: env(dof),
                    u: env(dof),
                    tau_ms: Envelope::new(stride, ticks),
                    active: Intervals::default(),
                    alarm: Intervals::default(),
                    missed: Intervals::default(),
                    last_t: 0.0,
                    ticks: 0,
                }
            })
            .collect();
        Self {
            beta: s.controller.beta,
            period_s: s.control_period_s,
            every: 1,
            duration_s: s.duration_s,
            agents,
        }
    }

    fn push(&mut self, r: &TickRecord) {
        let beta = self.beta;
        let Some(a) = self.agents.iter_mut().find(|a| a.id == r.agent.agent) else {
            return;
        };
        let t = r.agent.t;
        a.last_t = t;
        a.ticks += 1;
        let reference = a.trajectory.reference::<MAX_DOF>(t);
        let seg_index = a.switches.partition_point(|s| *s <= t);
        let seg = a.segments.get_mut(seg_index);
        let first = seg.as_ref().is_some_and(|s| t < s.from_s + SWITCH_WINDOW_S);
        let (q, qd, qdd) = (
            r.agent.q.as_slice(),
            r.agent.qd.as_slice(),
            r.agent.qdd.as_slice(),
        );
        let (ap, av) = (
            r.attack.alpha_position.as_slice(),
            r.attack.alpha_velocity.as_slice(),
        );
        let (s_hat, qdd_hat, u) = (
            r.center.s_hat.as_slice(),
            r.center.qdd_hat.as_slice(),
            r.center.u.as_slice(),
        );
        let get = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(f64::NAN);
        let mut s_err_sq = 0.0;
        let mut e_sq = 0.0;
        let mut seg = seg;
        for i in 0..a.dof {
            let e_pos = reference.q[i] - get(q, i);
            let e_vel = reference.qd[i] - get(qd, i);
            let s_true = true_s(get(ap, i), get(av, i), beta);
            let sh = get(s_hat, i);
            a.pos[i].push(t, e_pos);
            e_sq += e_pos * e_pos;
            a.vel[i].push(t, e_vel);
            a.s_hat[i].push(t, sh);
            a.s_true[i].push(t, s_true);
            a.acc[i].push(t, get(qdd, i) - get(qdd_hat, i));
            a.u[i].push(t, get(u, i));
            s_err_sq += (sh - s_true) * (sh - s_true);
            if let Some(s) = seg.as_deref_mut() {
                let (p, v) = if first {
                    (&mut s.pos_first[i], &mut s.vel_first[i])
                } else {
                    (&mut s.pos_rest[i], &mut s.vel_rest[i])
                };
                *p = p.max(e_pos.abs());
                *v = v.max(e_vel.abs());
            }
        }
        a.pos_norm.push(t, e_sq.sqrt());
        if let Some(s) = seg {
            s.s_err_sq += s_err_sq;
            s.ticks += 1;
        }
        a.tau_ms.push(t, r.agent.tau * 1e3);
        a.active.push(t, fdi_common::detect::in_force(r));
        a.alarm.push(t, r.center.alarm);
        a.missed.push(t, r.agent.missed);
    }
}

/// Attack segment boundaries of agent `id` strictly inside `(0, duration)`.
fn switch_times(r: &Resolved, id: u32, duration: f64) -> Vec<f64> {
    let mut v: Vec<f64> = r
        .attack
        .channels
        .iter()
        .filter(|c| c.agent == id)
        .flat_map(|c| c.segments.iter().map(|s| s.from_s))
        .filter(|t| *t > 0.0 && *t < duration)
        .collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

fn links(prefix: &str, envs: Vec<Envelope>) -> Vec<Line> {
    envs.into_iter()
        .enumerate()
        .map(|(i, e)| Line {
            label: format!("{prefix}link {}", i + 1),
            color: PALETTE[i % PALETTE.len()],
            points: e.finish(),
            keep: false,
            dashed: false,
        })
        .collect()
}

/// A figure to draw into `<stem>.png` and `<stem>.svg`.
struct Job {
    stem: String,
    figure: Figure,
    size: (u32, u32),
}

/// The legend entry of a robot's attack switch lines.
fn switch_label(switches: &[f64], x_end: f64) -> String {
    let shown: Vec<String> = switches
        .iter()
        .filter(|t| **t < x_end)
        .map(|t| format!("{t}"))
        .collect();
    match shown.len() {
        0 => String::new(),
        1 => format!("attack switch: {} s", shown[0]),
        2..=4 => format!("attack switches: {} s", shown.join(", ")),
        n => format!("attack switches ({n})"),
    }
}

/// How the figures are drawn: shared by every robot of a run.
struct Layout {
    beta: f64,
    /// The time axis: from 0 to the end of the recorded ticks.
    x_range: (f64, f64),
    /// Title suffix of a partial run.
    partial: String,
    paper: bool,
    period_s: f64,
}

/// The team figure (`team-position-error`): every robot's position error, the one with the
/// largest RMSE drawn over the others.
fn team_job(agents: &[AgentSeries], summary: &RunSummary, l: &Layout) -> Job {
    let worst = summary
        .metrics
        .iter()
        .filter(|(_, m)| m.rmse_rad.is_finite())
        .max_by(|a, b| a.1.rmse_rad.total_cmp(&b.1.rmse_rad))
        .and_then(|(id, m)| id.parse::<u32>().ok().map(|id| (id, m.rmse_rad)));
    let robots = agents
        .iter()
        .map(|a| (a.id, a.pos_norm.clone().finish()))
        .collect();
    Job {
        stem: TEAM_FIGURE.into(),
        figure: team::team_figure(robots, worst, l.x_range, &l.partial),
        size: (1000, 520),
    }
}

/// The stem of the team figure's files.
const TEAM_FIGURE: &str = "team-position-error";

/// The figures of one robot.
fn figures(a: AgentSeries, l: &Layout) -> Vec<Job> {
    let f = RobotFigures {
        id: a.id,
        layout: l,
        switches: &a.switches,
        marker_label: switch_label(&a.switches, l.x_range.1),
    };
    let (pos_guide, vel_guide) = paper_guides(a.id);
    // A sample holds until the next tick.
    let end = a.last_t + l.period_s;
    let wide = (1000, 440);
    let tall = (1000, 300 + 260 * a.dof.max(1) as u32);
    let beta = l.beta;
    vec![
        f.job(
            "position-error",
            "(a) position error",
            vec![f.guided(
                line_panel("q_d − q (true q)", "rad", links("", a.pos)),
                pos_guide,
            )],
            wide,
        ),
        f.job(
            "velocity-error",
            "(b) angular-velocity error",
            vec![f.guided(
                line_panel("dq_d/dt − dq/dt (true velocity)", "rad/s", links("", a.vel)),
                vel_guide,
            )],
            wide,
        ),
        f.job(
            "attack-estimate",
            &format!("(c) attack estimate Ŝ and true S = S₂ + β S₁ (β = {beta})"),
            attack_panels(a.s_hat, a.s_true),
            tall,
        ),
        f.job(
            "acceleration-error",
            "(d) acceleration-estimate error",
            vec![line_panel(
                "true acceleration − observer estimate",
                "rad/s²",
                links("", a.acc),
            )],
            wide,
        ),
        f.job(
            "torque",
            "torque sent by the control center",
            vec![line_panel("u", "N·m", links("", a.u))],
            wide,
        ),
        f.job(
            "delay-alarm",
            "delay, attack and detection",
            delay_alarm_panels(a.tau_ms, timeline_bands(a.active, a.alarm, a.missed, end)),
            (1000, 560),
        ),
    ]
}

/// What every figure of one robot shares: its title, time axis and attack switches.
struct RobotFigures<'a> {
    id: u32,
    layout: &'a Layout,
    switches: &'a [f64],
    marker_label: String,
}

impl RobotFigures<'_> {
    /// The figure `robot<id>-<suffix>` of `panels`.
    fn job(&self, suffix: &str, title: &str, panels: Vec<Panel>, size: (u32, u32)) -> Job {
        let (id, l) = (self.id, self.layout);
        Job {
            stem: format!("robot{id}-{suffix}"),
            figure: Figure {
                title: format!("Robot {id}: {title}{}", l.partial),
                x_label: "t (s)".into(),
                x_range: l.x_range,
                markers: self.switches.to_vec(),
                marker_label: self.marker_label.clone(),
                panels,
            },
            size,
        }
    }

    /// `p` with the paper's band `g`, on the paper's scenario.
    fn guided(&self, mut p: Panel, g: Guide) -> Panel {
        if self.layout.paper {
            p.guides.push(g);
        }
        p
    }
}

/// A panel of curves, without reference bands.
fn line_panel(title: &str, y_label: &str, curves: Vec<Line>) -> Panel {
    Panel {
        title: title.into(),
        y_label: y_label.into(),
        kind: PanelKind::Lines(curves),
        guides: Vec::new(),
    }
}

/// One panel per link: the true attack S and its estimate Ŝ.
fn attack_panels(s_hat: Vec<Envelope>, s_true: Vec<Envelope>) -> Vec<Panel> {
    s_hat
        .into_iter()
        .zip(s_true)
        .enumerate()
        .map(|(i, (sh, st))| {
            line_panel(
                &format!("link {}", i + 1),
                "rad/s",
                vec![
                    Line {
                        label: "true S".into(),
                        color: PALETTE[1],
                        points: st.finish(),
                        keep: true,
                        dashed: false,
                    },
                    Line {
                        label: "estimate Ŝ".into(),
                        color: PALETTE[0],
                        points: sh.finish(),
                        keep: false,
                        dashed: false,
                    },
                ],
            )
        })
        .collect()
}

/// The timeline's rows: attack in force, detection alarm and, if any, deadline misses; each
/// interval still open at `end` closes there.
fn timeline_bands(active: Intervals, alarm: Intervals, missed: Intervals, end: f64) -> Vec<Band> {
    let mut bands = vec![
        Band {
            label: "attack in force".into(),
            color: PALETTE[1],
            intervals: active.finish(end),
        },
        Band {
            label: "detection alarm".into(),
            color: PALETTE[0],
            intervals: alarm.finish(end),
        },
    ];
    let missed = missed.finish(end);
    if !missed.is_empty() {
        bands.push(Band {
            label: "deadline miss".into(),
            color: PALETTE[3],
            intervals: missed,
        });
    }
    bands
}

/// The input delay τ(t) above the timeline of `bands`.
fn delay_alarm_panels(tau_ms: Envelope, bands: Vec<Band>) -> Vec<Panel> {
    vec![
        line_panel(
            "input delay τ(t)",
            "ms",
            vec![Line {
                label: "τ".into(),
                color: PALETTE[2],
                points: tau_ms.finish(),
                keep: true,
                dashed: false,
            }],
        ),
        Panel {
            title: "timeline".into(),
            y_label: String::new(),
            kind: PanelKind::Timeline(bands),
            guides: Vec::new(),
        },
    ]
}

/// Writes everything into `run_dir/report/`; returns the path of `report.md`.
/// Writes the report whole or not at all: into a folder of its own beside `report/`, which
/// replaces `report/` once every file is written. A failure (disk full) or an interrupt
/// removes that folder and leaves any earlier `report/` as it was.
fn write(
    run_dir: &Path,
    run: (&Resolved, &RunSummary),
    gathered: Gathered<'_>,
    stop: &Stop,
) -> Result<PathBuf> {
    let staging = run_dir.join(format!(".report-partial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&staging);
    let written =
        write_into(&staging, run_dir, run, gathered, stop).and_then(|()| interrupted(stop));
    if let Err(e) = written {
        let _ = std::fs::remove_dir_all(&staging);
        return Err(e);
    }
    let dir = RunDir::new(run_dir).report();
    match std::fs::remove_dir_all(&dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(e).with_context(|| format!("replacing {}", dir.display()));
        }
    }
    if let Err(e) = std::fs::rename(&staging, &dir) {
        let _ = std::fs::remove_dir_all(&staging);
        return Err(e).with_context(|| format!("moving the report to {}", dir.display()));
    }
    Ok(dir.join("report.md"))
}

fn write_into(
    dir: &Path,
    run_dir: &Path,
    (resolved, summary): (&Resolved, &RunSummary),
    gathered: Gathered<'_>,
    stop: &Stop,
) -> Result<()> {
    let Gathered {
        series,
        warnings,
        kept,
        figured,
    } = gathered;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    fdi_common::stop::hold("report", stop);
    // A decimated trace records a tick every K: its last recorded tick stands for K ticks.
    let recorded = series
        .agents
        .iter()
        .filter(|a| a.ticks > 0)
        .map(|a| a.last_t + series.period_s * series.every as f64)
        .fold(0.0, f64::max);
    let (x_end, partial) = match kept {
        // No trace: the summary says how much of the run there is.
        Recorded::None => (series.duration_s, None),
        _ => recorded_span(recorded, series.period_s, series.duration_s),
    };
    let layout = Layout {
        beta: series.beta,
        x_range: (0.0, x_end),
        partial: partial
            .as_ref()
            .map_or_else(String::new, |p| format!(" ({p})")),
        paper: is_paper_scenario(resolved),
        period_s: series.period_s,
    };
    let mut segments = Vec::new();
    let mut jobs = Vec::new();
    let team_figure = kept != Recorded::None && team::has_team_figure(series.agents.len());
    if kept != Recorded::None {
        if team_figure {
            jobs.push(team_job(&series.agents, summary, &layout));
        }
        for a in series.agents {
            segments.push((a.id, a.segments.clone()));
            if figured.contains(&a.id) {
                jobs.extend(figures(a, &layout));
            }
        }
        render_all(dir, jobs, stop)?;
    }
    let md = markdown(
        run_dir,
        (resolved, summary),
        (&segments, &figured, team_figure),
        warnings,
        partial.as_deref(),
        kept,
    );
    let md_path = dir.join("report.md");
    std::fs::write(&md_path, md).with_context(|| format!("writing {}", md_path.display()))?;
    let det = dir.join("detection.csv");
    detection_csv(summary)
        .and_then(|csv| Ok(std::fs::write(&det, csv)?))
        .with_context(|| format!("writing {}", det.display()))?;
    let seg = dir.join("segments.csv");
    segments_csv(&segments)
        .and_then(|csv| Ok(std::fs::write(&seg, csv)?))
        .with_context(|| format!("writing {}", seg.display()))?;
    Ok(())
}

/// The end of the time axis of a run whose last recorded tick ends at `recorded` s: the
/// scenario's duration when the run is complete, else `recorded` (never `duration_s` of a run
/// that stopped early); and, for a partial run, the note that its figure titles carry.
fn recorded_span(recorded: f64, period_s: f64, duration_s: f64) -> (f64, Option<String>) {
    if recorded >= duration_s - 0.5 * period_s {
        (duration_s.max(period_s), None)
    } else {
        // To the millisecond, without the float noise of a sum of periods.
        let shown = (recorded * 1e3).round() / 1e3;
        (
            recorded.max(period_s),
            Some(format!("partial run: {shown} s of {duration_s} s recorded")),
        )
    }
}

/// Renders the figures on every core (a thread per core, at most one per figure).
fn render_all(dir: &Path, jobs: Vec<Job>, stop: &Stop) -> Result<()> {
    let workers = std::thread::available_parallelism()
        .map_or(1, std::num::NonZero::get)
        .min(jobs.len().max(1));
    let mut shares: Vec<Vec<Job>> = (0..workers).map(|_| vec![]).collect();
    for (i, j) in jobs.into_iter().enumerate() {
        shares[i % workers].push(j);
    }
    std::thread::scope(|s| {
        let handles: Vec<_> = shares
            .into_iter()
            .map(|share| {
                s.spawn(move || -> Result<()> {
                    for job in share {
                        interrupted(stop)?;
                        plot::save_figure(&job.figure, &dir.join(&job.stem), job.size)
                            .with_context(|| format!("figure {}", job.stem))?;
                    }
                    Ok(())
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(r) => r?,
                Err(_) => anyhow::bail!("a figure thread panicked"),
            }
        }
        Ok(())
    })
}

fn fmt_opt_s(v: Option<f64>) -> String {
    v.map_or_else(|| "never".into(), |d| format!("{d:.3}"))
}

/// What the figures of `report.md` are: each robot's segment maxima, the robots with their own
/// figures, whether the team figure is drawn.
type Drawn<'a> = (
    &'a [(u32, Vec<SegmentStats>)],
    &'a std::collections::BTreeSet<u32>,
    bool,
);

/// `report.md`: one section after the other.
fn markdown(
    run_dir: &Path,
    (r, s): (&Resolved, &RunSummary),
    (segments, figured, team_figure): Drawn<'_>,
    warnings: &[String],
    partial: Option<&str>,
    kept: Recorded,
) -> String {
    let mut md = String::new();
    run_section(&mut md, run_dir, r, s);
    notices(&mut md, s);
    rmse_section(&mut md, run_dir, s);
    detection_section(&mut md, s);
    external_section(&mut md, run_dir, r);
    match kept {
        Recorded::None => {
            md.push_str("\n## Figures\n\nNo figures: the run kept no traces (`--traces none`). The tables above come from its summary, which covers every tick; run it again with `--traces full` or `--traces decimate=K` for figures.\n");
        }
        Recorded::Decimated(k) => {
            let _ = writeln!(
                md,
                "\n**The figures and the segment table are drawn from decimated traces (`--traces decimate={k}`): every {k}-th tick, so a spike between two kept ticks may not show. The tables of metrics come from the run's summary and cover every tick.**"
            );
            segments_section(&mut md, segments);
            figures_section(&mut md, r, partial, (figured, team_figure));
        }
        Recorded::Full => {
            segments_section(&mut md, segments);
            figures_section(&mut md, r, partial, (figured, team_figure));
        }
    }
    warnings_section(&mut md, warnings);
    md
}

/// The programs that took a role (`[roles]`): what each was, and what the run's processes said
/// of it at the end (answers, replays, late ones; verdicts received, late), from their traces.
fn external_section(md: &mut String, run_dir: &Path, r: &Resolved) {
    let roles = &r.scenario.roles;
    if !r.has_external_roles() {
        return;
    }
    md.push_str(
        "
## Roles taken by external programs

",
    );
    for (what, role) in [("attacker", &roles.attacker), ("monitor", &roles.monitor)] {
        if let Some(role) = role {
            let _ = writeln!(
                md,
                "* {what} `{}`: `{}`",
                role.label(),
                role.command.join(" ")
            );
        }
    }
    let mut notes = Vec::new();
    for process in [Process::Attacker, Process::Center] {
        let path = RunDir::new(run_dir).trace(process);
        let Ok(reader) = fdi_common::trace::TraceReader::open(&path) else {
            continue;
        };
        for rec in reader.flatten() {
            if let fdi_common::trace::TraceRecord::Event { message, .. } = rec {
                for part in message.split("; ") {
                    if part.starts_with("external attacker `") || part.starts_with("monitor `") {
                        notes.push(part.to_string());
                    }
                }
            }
        }
    }
    if notes.is_empty() {
        md.push_str(
            "
No closing note of the run's processes on them (the traces were not kept, or the \
             run ended early).
",
        );
    } else {
        md.push('\n');
        for n in notes {
            let _ = writeln!(md, "* {n}");
        }
    }
    md.push_str(
        "
Their contract is docs/protocol.md; what the attacker program sent is the attacker's \
         record (`traces/attacker.trace`), the monitor's verdicts are in the control center's \
         (`fdi-launch trace export` writes them to `control-center-monitor.csv`).
",
    );
}

/// The title, where the run lives, and the table of its parameters.
fn run_section(md: &mut String, run_dir: &Path, r: &Resolved, s: &RunSummary) {
    let _ = writeln!(md, "# Report of run `{}`\n", s.scenario);
    let _ = writeln!(
        md,
        "Run directory `{}`. Regenerate with `fdi-launch report {}`.\n",
        run_dir.display(),
        run_dir.display()
    );
    md.push_str(&md_table_head(&["parameter", "value"]));
    for (k, v) in parameters(r, s) {
        let _ = writeln!(md, "| {k} | {v} |");
    }
    if let Some(p) = &s.placement {
        let _ = writeln!(md, "| processes | {p} |");
    }
    if !s.hosts.is_empty() {
        let _ = writeln!(md, "| hosts | {} |", s.hosts.join("<br>"));
    }
    if let Some(line) = crate::output::network_line(s) {
        let _ = writeln!(md, "| {} |", line.replacen(": ", " | ", 1));
    }
    if let Some(line) = crate::output::live_line(s) {
        let _ = writeln!(md, "| {} |", line.replacen(": ", " | ", 1));
    }
}

/// The rows of the parameter table: (parameter, value).
fn parameters(r: &Resolved, s: &RunSummary) -> [(&'static str, String); 13] {
    let c = &r.scenario.controller;
    let d = &r.scenario.detectors;
    [
        ("scenario", s.scenario.clone()),
        ("engine", s.engine.clone()),
        ("clock", s.clock.clone()),
        (
            "controller",
            match c.gain_scaling {
                fdi_common::control::GainScaling::Unit => {
                    format!("{} (k = {}, β = {})", s.controller, c.gain_k, c.beta)
                }
                fdi_common::control::GainScaling::Inertia => format!(
                    "{} (K = {} · diag M(q_d(0)), β = {})",
                    s.controller, c.gain_k, c.beta
                ),
            },
        ),
        (
            "numerics",
            // From the run's scenario, not its summary: a summary written before it was
            // recorded would read as the paper's.
            fdi_common::numerics::describe(&fdi_common::numerics::differences_from_paper(
                &r.scenario,
                fdi_common::numerics::Compare::WithoutMode,
            )),
        ),
        ("attack", format!("`{}`", s.attack)),
        ("seed", s.seed.to_string()),
        (
            "simulated",
            format!(
                "{} s: {} ticks of {} ms, {} robots",
                s.sim_s,
                s.ticks,
                r.scenario.control_period_s * 1e3,
                s.agents
            ),
        ),
        (
            "detection",
            format!(
                "alarm when ‖Ŝ‖ > {} for {} s",
                c.detection.threshold, c.detection.hold_s
            ),
        ),
        (
            "detectors",
            format!(
                "{} on the `{}` residual, calibrated over the first {} s",
                crate::output::join_words(
                    &fdi_common::detect::RESIDUAL
                        .iter()
                        .map(|k| (k.describe)(d))
                        .collect::<Vec<_>>()
                ),
                d.residual.as_str(),
                d.calibration_s()
            ),
        ),
        (
            "wall time",
            if s.wall_s.is_finite() {
                format!("{:.2} s", s.wall_s)
            } else {
                "unknown".into()
            },
        ),
        ("trace digest", format!("`{}`", s.trace_digest)),
        (
            "figures",
            format!(
                "min/max envelope of about {BUCKETS} buckets per curve; robust y-axis, values beyond \
                 it clipped and marked ▲▼ (see below)"
            ),
        ),
    ]
}

/// What keeps the metrics from covering a whole run: a partial run, diverged robots, lost ones.
fn notices(md: &mut String, s: &RunSummary) {
    if let Some(notice) = crate::output::partial_notice(s) {
        let _ = writeln!(md, "\n**{notice}.**");
    }
    for (id, t) in s.diverged() {
        let _ = writeln!(
            md,
            "\n**Robot {id} diverged at t = {t:.3} s**: its state left the bound of {} rad or became non-finite; its metrics are not results.",
            fdi_common::metrics::DIVERGENCE_BOUND_RAD
        );
    }
    for l in &s.lost_agents {
        let from = l.t_s.map_or("?".into(), |t| format!("{t:.3} s"));
        let _ = match l.rejoined_t_s {
            Some(back) => writeln!(
                md,
                "\nAgent {} was lost after t = {from} ({}) and rejoined at t = {back:.3} s.",
                l.agent, l.reason
            ),
            None => writeln!(
                md,
                "\nAgent {} was lost after t = {from} ({}) and stayed lost.",
                l.agent, l.reason
            ),
        };
    }
}

/// The RMSE table: the run's `rmse.md` when it holds one, else the summary's.
fn rmse_section(md: &mut String, run_dir: &Path, s: &RunSummary) {
    md.push_str("\n## RMSE\n\n");
    let stored = std::fs::read_to_string(run_dir.join("rmse.md")).ok();
    // Its first table only: the detector tables that follow it have their own section.
    let table: Vec<&str> = stored
        .as_deref()
        .map(|t| {
            t.lines()
                .skip_while(|l| !l.starts_with('|'))
                .take_while(|l| l.starts_with('|'))
                .collect()
        })
        .unwrap_or_default();
    if table.is_empty() {
        md.push_str(&md_table_head(&[
            "robot",
            "RMSE (rad)",
            "max abs error (rad)",
        ]));
        for (id, m) in &s.metrics {
            let _ = writeln!(
                md,
                "| {id} | {:.5} | {:.5} |",
                m.rmse_rad, m.max_abs_error_rad
            );
        }
    } else {
        for l in table {
            md.push_str(l);
            md.push('\n');
        }
        md.push_str("\n(from [`rmse.md`](../rmse.md), also [`rmse.csv`](../rmse.csv))\n");
    }
}

/// The time to detect every attack onset, then false alarms and the other counts per robot.
fn detection_section(md: &mut String, s: &RunSummary) {
    md.push_str("\n## Detection\n\n");
    md.push_str(&md_table_head(&[
        "robot",
        "attack onset (s)",
        "time to detect (s)",
    ]));
    for (id, m) in &s.metrics {
        if m.onsets.is_empty() {
            let _ = writeln!(md, "| {id} | none | |");
        }
        for o in &m.onsets {
            let _ = writeln!(
                md,
                "| {id} | {:.3} | {} |",
                o.t_s,
                fmt_opt_s(o.time_to_detect_s)
            );
        }
    }
    md.push('\n');
    md.push_str(&md_table_head(&[
        "robot",
        "false alarms",
        "alarm coverage of attacked ticks",
        "rejected inputs",
        "rejected torques",
        "deadline misses",
        "uncontrolled ticks",
        "metrics cover",
    ]));
    for (id, m) in &s.metrics {
        let _ = writeln!(
            md,
            "| {id} | {} | {:.1} % | {} | {} | {} | {} | {} |",
            m.false_alarms,
            m.alarm_coverage * 100.0,
            m.rejected_inputs,
            m.rejected_torques,
            m.deadline_misses,
            m.uncontrolled_ticks,
            crate::output::coverage(m.ticks, s.planned_ticks)
        );
    }
    md.push_str("\n(also [`detection.csv`](detection.csv))\n");
    md.push_str(&crate::output::detector_tables(s, 3));
}

/// The error maxima of every attack segment that holds ticks.
fn segments_section(md: &mut String, segments: &[(u32, Vec<SegmentStats>)]) {
    md.push_str("\n## Tracking error per attack segment\n\n");
    let _ = writeln!(
        md,
        "Largest |q_d − q| (rad) and |q̇_d − q̇| (rad/s) per link, in the first {SWITCH_WINDOW_S} s of each \
         segment (the spike after a switch; for the first segment, the start-up) and over the rest of \
         it, and the RMS of ‖Ŝ − S‖ (rad/s), at the full tick rate. Also [`segments.csv`](segments.csv).\n"
    );
    md.push_str(&md_table_head(&[
        "robot",
        "segment (s)",
        "max \\|e\\| first 1 s",
        "max \\|e\\| rest",
        "max \\|ė\\| first 1 s",
        "max \\|ė\\| rest",
        "RMS ‖Ŝ − S‖",
    ]));
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.4}"))
            .collect::<Vec<_>>()
            .join(" / ")
    };
    for (id, segs) in segments {
        for sg in segs.iter().filter(|sg| sg.ticks > 0) {
            let _ = writeln!(
                md,
                "| {id} | {}–{} | {} | {} | {} | {} | {:.4} |",
                sg.from_s,
                sg.to_s,
                list(&sg.pos_first),
                list(&sg.pos_rest),
                list(&sg.vel_first),
                list(&sg.vel_rest),
                (sg.s_err_sq / sg.ticks as f64).sqrt()
            );
        }
    }
}

/// How the figures are drawn, then every robot's figures.
fn figures_section(
    md: &mut String,
    r: &Resolved,
    partial: Option<&str>,
    (figured, team_figure): (&std::collections::BTreeSet<u32>, bool),
) {
    md.push_str("\n## Reading the figures\n\n");
    md.push_str(&figure_notes(r, partial));
    let ids: Vec<u32> = r.scenario.agents.iter().map(|a| a.id).collect();
    if team_figure {
        let _ = writeln!(
            md,
            "\n## Team\n\n**Every robot's position error** ‖q_d − q‖, the robot with the largest \
             RMSE drawn over the others; the RMSE of each robot is the table above \
             ([SVG]({TEAM_FIGURE}.svg))\n\n![the team's position errors]({TEAM_FIGURE}.png)\n"
        );
    }
    let left = ids.len() - figured.len();
    if left > 0 {
        let _ = writeln!(
            md,
            "\nPer-robot figures are drawn for {} of the {} robots (a team of more than {} leads \
             with the team figure): `fdi-launch report RUN_DIR --robots 3,7` draws those of the \
             robots named, `--robots all` every robot's.",
            figured.len(),
            ids.len(),
            team::HANDFUL
        );
    }
    for a in r.scenario.agents.iter().filter(|a| figured.contains(&a.id)) {
        let id = a.id;
        let _ = writeln!(md, "\n## Robot {id}\n");
        for (suffix, what) in FIGURES {
            let stem = format!("robot{id}-{suffix}");
            let _ = writeln!(
                md,
                "**{what}** ([SVG]({stem}.svg))\n\n![robot {id}: {what}]({stem}.png)\n"
            );
        }
    }
}

/// The warnings of the join and of the report's reading of the run, if any.
fn warnings_section(md: &mut String, warnings: &[String]) {
    if !warnings.is_empty() {
        md.push_str("\n## Warnings\n\n");
        for w in warnings {
            let _ = writeln!(md, "* {w}");
        }
    }
}

/// How the figures were drawn, for `report.md`.
fn figure_notes(r: &Resolved, partial: Option<&str>) -> String {
    let (lo, hi) = plot::ROBUST_QUANTILES;
    let mut md = format!(
        "* Time axis: the recorded ticks, from 0 to the end of the last one. Grey vertical \
         lines: the robot's attack switches (segment boundaries of its attack schedule), listed \
         in the legend.\n\
         * Y-axis: when a few spikes (attack switches) would squash the rest, the axis spans the \
         {} % to {} % quantiles of the plotted points, plus {} % of that span on each side, \
         widened to hold the true attack S, the delay τ and the paper's band, which are never \
         clipped. This robust range is used only when the full range is more than {}× larger. \
         Values beyond it are drawn at the edge and marked ▲ (above) or ▼ (below), one marker \
         per spike (excursions less than {} % of the time axis apart share one), with the value \
         of the farthest point written beside it (beside every marker when there are at most {}, \
         else beside the farthest on each side); the legend gives how many of the plotted points \
         were clipped and the range of all values. Points are those of the min/max envelope \
         (each the smallest or largest of a bucket of ticks).\n\
         * Timeline: the attack row is drawn from the attacker's per-tick `active` flag, one bar \
         per interval in which it held (at least two pixels wide), with the number of intervals \
         and the share of the time in the legend; likewise the alarm and, if any, the deadline \
         misses.\n",
        lo * 100.0,
        hi * 100.0,
        plot::ROBUST_MARGIN * 100.0,
        plot::CLIP_RATIO,
        plot::MERGE_SHARE * 100.0,
        plot::LABELLED_EXCURSIONS,
    );
    if is_paper_scenario(r) {
        let _ = writeln!(
            md,
            "* Green band (scenario `{}`, the paper's experiment): the bounds the paper states in \
             Section VII, |q_d − q| ≤ {PAPER_POSITION_BOUND_RAD} rad (robot 1, Fig. 3(a); robot \
             4, Fig. 6(a)) and |q̇_d − q̇| ≤ {PAPER_VELOCITY_BOUND_RAD_S} rad/s (robot 1, Fig. \
             3(b)). The other robots show robot 1's bound as a reference, labelled \"paper (robot \
             1)\".",
            r.scenario.name
        );
    }
    if let Some(p) = partial {
        let _ = writeln!(
            md,
            "* This run is partial ({p}): its figures end where its traces end."
        );
    }
    md
}

/// `detection.csv`: one row per attack onset of each robot (a robot without onsets: one row with
/// the onset columns empty).
fn detection_csv(s: &RunSummary) -> Result<Vec<u8>> {
    const HEADER: [&str; 5] = [
        "robot",
        "onset_s",
        "time_to_detect_s",
        "false_alarms",
        "alarm_coverage",
    ];
    let mut rows = Vec::new();
    for (id, m) in &s.metrics {
        let row = |onset: String, detect: String| {
            [
                id.clone(),
                onset,
                detect,
                m.false_alarms.to_string(),
                m.alarm_coverage.to_string(),
            ]
        };
        if m.onsets.is_empty() {
            rows.push(row(String::new(), String::new()));
        }
        for o in &m.onsets {
            rows.push(row(
                o.t_s.to_string(),
                o.time_to_detect_s.map_or(String::new(), |d| d.to_string()),
            ));
        }
    }
    csv_bytes(&HEADER, rows)
}

/// `segments.csv`: one row per link of each robot's attack segments that hold ticks.
fn segments_csv(segments: &[(u32, Vec<SegmentStats>)]) -> Result<Vec<u8>> {
    const HEADER: [&str; 9] = [
        "robot",
        "from_s",
        "to_s",
        "link",
        "max_abs_pos_err_first_rad",
        "max_abs_pos_err_rest_rad",
        "max_abs_vel_err_first_rad_s",
        "max_abs_vel_err_rest_rad_s",
        "rms_s_err_rad_s",
    ];
    let mut rows = Vec::new();
    for (id, segs) in segments {
        for sg in segs.iter().filter(|sg| sg.ticks > 0) {
            let rms = (sg.s_err_sq / sg.ticks as f64).sqrt();
            for i in 0..sg.pos_first.len() {
                rows.push([
                    id.to_string(),
                    sg.from_s.to_string(),
                    sg.to_s.to_string(),
                    (i + 1).to_string(),
                    sg.pos_first[i].to_string(),
                    sg.pos_rest[i].to_string(),
                    sg.vel_first[i].to_string(),
                    sg.vel_rest[i].to_string(),
                    rms.to_string(),
                ]);
            }
        }
    }
    csv_bytes(&HEADER, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detection_csv_has_a_row_per_onset_and_one_for_a_robot_without() {
        let bytes = detection_csv(&crate::output::sample_summary()).expect("csv");
        assert_eq!(
            std::str::from_utf8(&bytes).expect("utf-8"),
            "robot,onset_s,time_to_detect_s,false_alarms,alarm_coverage\n\
             1,,,2,0.5\n2,0.001,0.061,2,0.5\n2,0.05,,2,0.5\n"
        );
        let mut r = csv::Reader::from_reader(bytes.as_slice());
        assert_eq!(r.headers().expect("header").len(), 5);
        let rows: Vec<csv::StringRecord> = r.records().map(|x| x.expect("row")).collect();
        assert_eq!(rows.len(), 3);
        assert_eq!((&rows[1][0], &rows[1][2]), ("2", "0.061"));
    }

    #[test]
    fn segments_csv_has_a_row_per_link_of_each_segment_with_ticks() {
        let mut seg = SegmentStats::new(0.0, 2.5, 2);
        seg.pos_first = vec![0.1, 1e-300];
        seg.pos_rest = vec![0.2, 0.3];
        seg.vel_first = vec![0.4, 0.5];
        seg.vel_rest = vec![0.6, -0.0];
        seg.s_err_sq = 4.0;
        seg.ticks = 4;
        let empty = SegmentStats::new(2.5, 4.0, 2);
        let bytes = segments_csv(&[(3, vec![seg, empty])]).expect("csv");
        let mut r = csv::Reader::from_reader(bytes.as_slice());
        assert_eq!(
            r.headers().expect("header"),
            vec![
                "robot",
                "from_s",
                "to_s",
                "link",
                "max_abs_pos_err_first_rad",
                "max_abs_pos_err_rest_rad",
                "max_abs_vel_err_first_rad_s",
                "max_abs_vel_err_rest_rad_s",
                "rms_s_err_rad_s"
            ]
        );
        let rows: Vec<csv::StringRecord> = r.records().map(|x| x.expect("row")).collect();
        assert_eq!(
            rows.len(),
            2,
            "one row per link, none for the empty segment"
        );
        assert_eq!(
            rows[0].iter().collect::<Vec<_>>(),
            ["3", "0", "2.5", "1", "0.1", "0.2", "0.4", "0.6", "1"]
        );
        assert_eq!(&rows[1][3], "2");
        assert_eq!(
            rows[1][4].parse::<f64>().expect("number").to_bits(),
            1e-300_f64.to_bits()
        );
        assert_eq!(&rows[1][7], "-0");
    }

    #[test]
    fn time_axis_ends_with_the_recorded_ticks() {
        assert_eq!(recorded_span(40.0, 0.001, 40.0), (40.0, None));
        // A sum of periods a hair short of the duration is the whole run.
        assert_eq!(recorded_span(39.999_999_9, 0.001, 40.0), (40.0, None));
        let (end, note) = recorded_span(12.345_000_000_01, 0.001, 40.0);
        assert!((end - 12.345).abs() < 1e-9, "{end}");
        assert_eq!(
            note.as_deref(),
            Some("partial run: 12.345 s of 40 s recorded")
        );
        // Nothing recorded: an axis of one period, not of the duration.
        assert_eq!(recorded_span(0.0, 0.001, 40.0).0, 0.001);
    }

    #[test]
    fn switch_legend_lists_the_switches_on_the_axis() {
        assert_eq!(switch_label(&[], 40.0), "");
        assert_eq!(switch_label(&[5.0, 20.0], 40.0), "attack switches: 5, 20 s");
        assert_eq!(switch_label(&[5.0, 20.0], 10.0), "attack switch: 5 s");
        assert_eq!(
            switch_label(&[1.0, 2.0, 3.0, 4.0, 5.0], 40.0),
            "attack switches (5)"
        );
    }

    #[test]
    fn paper_guides_name_the_figure_that_states_them() {
        let (p1, v1) = paper_guides(1);
        assert!(p1.label.contains("Fig. 3(a)") && v1.label.contains("Fig. 3(b)"));
        assert_eq!((p1.lo, p1.hi), (-0.02, 0.02));
        assert_eq!((v1.lo, v1.hi), (-0.01, 0.01));
        assert!(paper_guides(4).0.label.contains("Fig. 6(a)"));
        assert!(paper_guides(2).0.label.contains("robot 1"));
    }
}
