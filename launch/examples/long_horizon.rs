//! Long-horizon behaviour of the controller (docs/model.md, "Long horizons"): runs scenarios in
//! process and measures, in windows of simulated time, what the NN estimate absorbs and how the
//! weights and the observer move.
//!
//! ```sh
//! cargo run --release -p fdi-launch --example long_horizon -- series --duration-s 300 --attack none
//! cargo run --release -p fdi-launch --example long_horizon -- summary --duration-s 300 --attack none --gamma-w 1000
//! cargo run --release -p fdi-launch --example long_horizon -- delay-sweep scenarios/table2-large-slow.toml
//! cargo run --release -p fdi-launch --example long_horizon -- figure docs/figures/long-horizon-robot1
//! ```
//!
//! `figure` writes a PNG and an SVG; docs/ keeps the PNG.
//!
//! The weights are not part of the trace: a shadow estimator, built like the control center's
//! and fed with `Ψ2` rebuilt from the records, follows them. It must reproduce the recorded `Ŝ`
//! bit for bit, or the program stops with an error.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, Parser, Subcommand};

use fdi_common::attack::presets;
use fdi_common::control::{NnEstimator, NnParams, Observer};
use fdi_common::delay::DelayProfile;
use fdi_common::engine::{run_inproc_any, RunSummary};
use fdi_common::model::Vector;
use fdi_common::records::TickRecord;
use fdi_common::rng::{stream, Purpose};
use fdi_common::scenario::{self, AgentConfig, ControllerMode, ObserverInput, Resolved, Scenario};
use fdi_common::trajectory::TrajectoryConfig;

use fdi_report::plot;

/// Links of the paper's robots.
const N: usize = 2;

#[derive(Debug, Parser)]
#[command(about = "Long-horizon measurements of the proposed controller (in-process runs)")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// One CSV row per agent and window: errors, attack-estimation error, weights, observer.
    Series {
        #[command(flatten)]
        setup: Setup,
        /// Window length, s.
        #[arg(long, default_value_t = 5.0)]
        window_s: f64,
    },
    /// One row per agent: RMSE, false alarms, first and last window of the series.
    Summary {
        #[command(flatten)]
        setup: Setup,
        /// Window length, s.
        #[arg(long, default_value_t = 5.0)]
        window_s: f64,
    },
    /// RMSE of the first agent under constant delays (ms), each a separate run. The defaults
    /// are the sweep of docs/model.md ("The large-slow delay"); whole multiples of Δ give the
    /// same values as their neighbours (docs/model.md, "Numerics of the delayed input").
    DelaySweep {
        #[command(flatten)]
        setup: Setup,
        /// Constant delays to try, ms.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "3.06,10.5,20.5,30.5,40.5,45.5,46.5,46.9,47.1,47.5,48,48.5,49,49.5,50.1,51,52"
        )]
        delays_ms: Vec<f64>,
    },
    /// The remedy's two acceptance checks for every combination of the lists (each list
    /// replaces the scenario's value; an empty list keeps it): per robot, the RMSE and false
    /// alarms over the long horizon without attack, against the traditional controller's, and
    /// Table I's RMSE (40 s, the paper's attack) against the paper's. One CSV row per
    /// combination; the traditional reference first.
    Grid {
        #[command(flatten)]
        setup: Setup,
        /// Long horizon, s.
        #[arg(long, default_value_t = 300.0)]
        horizon_s: f64,
        #[arg(long, value_delimiter = ',')]
        observer_inputs: Vec<String>,
        /// `innovation_time_constant_s` values, s.
        #[arg(long, value_delimiter = ',')]
        innovation_ts: Vec<f64>,
        /// `leakage_w_per_s` values, 1/s.
        #[arg(long, value_delimiter = ',')]
        leakages_w: Vec<f64>,
        /// `dead_zone_rad_s` values, rad/s.
        #[arg(long, value_delimiter = ',')]
        dead_zones: Vec<f64>,
    },
    /// The figure of docs/model.md: robot 1 over 300 s without attack, the paper's laws, the
    /// remedy of `scenarios/paper-long-horizon.toml` and the traditional controller.
    Figure {
        /// Output stem: writes STEM.png and STEM.svg.
        stem: PathBuf,
        /// The scenario with the remedy on.
        #[arg(long, default_value = "scenarios/paper-long-horizon.toml")]
        remedy: PathBuf,
        /// Simulated time, s.
        #[arg(long, default_value_t = 300.0)]
        duration_s: f64,
        /// Window length, s; default one period of robot 1's q_d (2π / 1.5 rad/s), so that the
        /// window means do not alias with the trajectory.
        #[arg(long, default_value_t = 2.0 * std::f64::consts::PI / 1.5)]
        window_s: f64,
    },
}

/// The scenario of a run and what to change in it.
#[derive(Debug, Clone, Default, Args)]
struct Setup {
    /// Scenario file; without it the embedded paper scenario.
    scenario: Option<PathBuf>,
    #[arg(long)]
    duration_s: Option<f64>,
    /// Attack preset (paper, paper-linkwise, none).
    #[arg(long)]
    attack: Option<String>,
    /// `proposed` or `traditional`.
    #[arg(long)]
    controller: Option<String>,
    /// `Γ1` (learning_rate_w).
    #[arg(long)]
    gamma_w: Option<f64>,
    /// `Γ2` (learning_rate_v).
    #[arg(long)]
    gamma_v: Option<f64>,
    /// `L1` (observer_gain_l1).
    #[arg(long)]
    l1: Option<f64>,
    /// `L2` (observer_gain_l2).
    #[arg(long)]
    l2: Option<f64>,
    /// `controller.update_law.leakage_w_per_s`, 1/s.
    #[arg(long)]
    leakage_w: Option<f64>,
    /// `controller.update_law.innovation_time_constant_s`, s.
    #[arg(long)]
    innovation_t: Option<f64>,
    /// `controller.update_law.dead_zone_rad_s`, rad/s.
    #[arg(long)]
    dead_zone: Option<f64>,
    /// `controller.observer_input`: step-mean or sample.
    #[arg(long)]
    observer_input: Option<String>,
    /// Control period Δ, ms.
    #[arg(long)]
    period_ms: Option<f64>,
    /// Replace every agent's delay by this constant, ms.
    #[arg(long)]
    delay_ms: Option<f64>,
    /// Keep only these agent ids.
    #[arg(long, value_delimiter = ',')]
    agents: Vec<u32>,
}

impl Setup {
    fn resolve(&self) -> Result<Resolved> {
        let mut r = match &self.scenario {
            Some(p) => scenario::load_file(p)?,
            None => scenario::paper()?,
        };
        if let Some(name) = &self.attack {
            let p = presets::preset(name).ok_or_else(|| {
                anyhow!(
                    "unknown attack preset {name} (known: {})",
                    presets::names().join(", ")
                )
            })?;
            let p = p.for_agents(&r.scenario.agent_dofs());
            r = r.with_attack(p)?;
        }
        let s = &mut r.scenario;
        let c = &mut s.controller;
        match self.controller.as_deref() {
            None => {}
            Some("proposed") => c.mode = ControllerMode::Proposed,
            Some("traditional") => c.mode = ControllerMode::Traditional,
            Some(other) => bail!("--controller {other}: proposed or traditional"),
        }
        match self.observer_input.as_deref() {
            None => {}
            Some("step-mean") => c.observer_input = ObserverInput::StepMean,
            Some("sample") => c.observer_input = ObserverInput::Sample,
            Some(other) => bail!("--observer-input {other}: step-mean or sample"),
        }
        for (field, v) in [
            (&mut c.learning_rate_w, self.gamma_w),
            (&mut c.learning_rate_v, self.gamma_v),
            (&mut c.observer_gain_l1, self.l1),
            (&mut c.observer_gain_l2, self.l2),
            (&mut c.update_law.leakage_w_per_s, self.leakage_w),
            (&mut c.update_law.dead_zone_rad_s, self.dead_zone),
            (
                &mut c.update_law.innovation_time_constant_s,
                self.innovation_t,
            ),
            (&mut s.duration_s, self.duration_s),
            (&mut s.control_period_s, self.period_ms.map(|ms| ms * 1e-3)),
        ] {
            if let Some(v) = v {
                *field = v;
            }
        }
        if let Some(ms) = self.delay_ms {
            for a in &mut s.agents {
                a.delay = DelayProfile::Constant { value_s: ms * 1e-3 };
            }
        }
        if !self.agents.is_empty() {
            let keep = self.agents.clone();
            r = r.retain_agents(|a| keep.contains(&a.id));
        }
        let problems = r.scenario.validate();
        if !problems.is_empty() {
            let all: Vec<String> = problems.iter().map(ToString::to_string).collect();
            bail!("the changed scenario is invalid:\n{}", all.join("\n"));
        }
        Ok(r)
    }
}

/// Sums over one window of one agent.
#[derive(Debug, Clone, Default)]
struct Window {
    n: u64,
    /// Σ e (per link), Σ |e|² (over links), e = q_d − q.
    e_sum: [f64; N],
    e_sq: f64,
    /// Σ ‖Ŝ − S‖², Σ Ŝ (per link), Σ S (per link).
    s_err_sq: f64,
    s_hat_sum: [f64; N],
    s_sum: [f64; N],
    /// Σ ‖r̃‖² with r̃ = (ẏ − q̂̇) + β (y − q̂) of the tampered measurement, Σ ‖Ψ2‖².
    r_tilde_sq: f64,
    psi2_sq: f64,
    /// Σ (q − q̂) per link (observer position error against the true state).
    q_tilde_sum: [f64; N],
    /// Last ‖Ŵ‖, ‖bias row of Ŵ‖, ‖V̂ − V̂(0)‖.
    w_norm: f64,
    w_bias: f64,
    v_moved: f64,
}

/// One finished window, as printed.
#[derive(Debug, Clone, Copy)]
struct Row {
    t_end: f64,
    e_mean: [f64; N],
    e_rms: f64,
    s_err_rms: f64,
    s_hat_mean: [f64; N],
    s_mean: [f64; N],
    r_tilde_rms: f64,
    psi2_rms: f64,
    q_tilde_mean: [f64; N],
    w_norm: f64,
    w_bias: f64,
    v_moved: f64,
}

impl Window {
    fn row(&self, t_end: f64) -> Row {
        let n = self.n.max(1) as f64;
        let mean = |a: [f64; N]| a.map(|x| x / n);
        Row {
            t_end,
            e_mean: mean(self.e_sum),
            e_rms: (self.e_sq / (n * N as f64)).sqrt(),
            s_err_rms: (self.s_err_sq / n).sqrt(),
            s_hat_mean: mean(self.s_hat_sum),
            s_mean: mean(self.s_sum),
            r_tilde_rms: (self.r_tilde_sq / n).sqrt(),
            psi2_rms: (self.psi2_sq / n).sqrt(),
            q_tilde_mean: mean(self.q_tilde_sum),
            w_norm: self.w_norm,
            w_bias: self.w_bias,
            v_moved: self.v_moved,
        }
    }
}

/// Per-agent state of the measurement: the shadow estimator and the previous tick's observer.
struct Tracker {
    trajectory: TrajectoryConfig,
    nn: Option<NnEstimator<N>>,
    v0: Vec<f64>,
    prev_observer: Observer<N>,
    psi2_prev: Vector<N>,
    window: Window,
    rows: Vec<Row>,
    /// The run's `β`, control period Δ (s) and ticks per window.
    beta: f64,
    dt: f64,
    per_window: u64,
}

/// The vectors of one tick record that the measurement reads.
struct TickValues {
    t: f64,
    /// True state.
    q: Vector<N>,
    qd: Vector<N>,
    /// Tampered measurement.
    y: Vector<N>,
    yd: Vector<N>,
    s_hat: Vector<N>,
    /// The observer state after the tick's step.
    q_hat: Vector<N>,
    qd_hat: Vector<N>,
}

impl TickValues {
    fn of(rec: &TickRecord) -> Self {
        Self {
            t: rec.agent.t,
            q: rec.agent.q.to_vector::<N>(),
            qd: rec.agent.qd.to_vector::<N>(),
            y: rec.attack.y.to_vector::<N>(),
            yd: rec.attack.yd.to_vector::<N>(),
            s_hat: rec.center.s_hat.to_vector::<N>(),
            q_hat: rec.center.q_hat.to_vector::<N>(),
            qd_hat: rec.center.qd_hat.to_vector::<N>(),
        }
    }
}

impl Tracker {
    /// The tracker of agent `a` of `s`: its shadow estimator (proposed mode) seeded like the
    /// control center's, windows of `per_window` ticks.
    fn new(s: &Scenario, a: &AgentConfig, nn_params: NnParams, per_window: u64) -> Self {
        let c = s.controller;
        let nn = (c.mode == ControllerMode::Proposed).then(|| {
            let mut rng = stream(s.seed, a.id, Purpose::NnInit);
            NnEstimator::<N>::new(nn_params, c.initial_v_range, &mut rng)
        });
        let v0 = nn
            .as_ref()
            .map_or_else(Vec::new, |n| n.weights_v().to_vec());
        Tracker {
            trajectory: a.trajectory.clone(),
            nn,
            v0,
            prev_observer: Observer::default(),
            psi2_prev: Vector::<N>::zeros(),
            window: Window::default(),
            rows: Vec::new(),
            beta: c.beta,
            dt: s.control_period_s,
            per_window,
        }
    }

    /// Follows the control center through tick `x`: `Ψ2` and the innovation `r̃` from the
    /// observer state before the tick's step, the shadow estimator's `Ŝ` and update, then the
    /// observer state after the step. `(Ψ2, r̃, the shadow Ŝ if it differs from the recorded)`.
    fn follow(&mut self, x: &TickValues) -> (Vector<N>, Vector<N>, Option<Vector<N>>) {
        let (beta, dt) = (self.beta, self.dt);
        // Ψ2 as the center computed it: the observer state before this tick's step.
        let psi2 = self.prev_observer.psi2(&x.y, &x.yd, beta, &x.s_hat);
        let r_tilde = (x.yd - self.prev_observer.qd) + (x.y - self.prev_observer.q) * beta;
        let mut differs = None;
        if let Some(nn) = self.nn.as_mut() {
            let shadow = nn.estimate(&self.psi2_prev);
            if shadow != x.s_hat {
                differs = Some(shadow);
            }
            nn.update(&psi2, dt);
        }
        self.psi2_prev = psi2;
        self.prev_observer.q = x.q_hat;
        self.prev_observer.qd = x.qd_hat;
        (psi2, r_tilde, differs)
    }

    /// Adds tick `x` (after [`Self::follow`]) to the window; a full window becomes a row.
    fn accumulate(&mut self, x: &TickValues, psi2: &Vector<N>, r_tilde: &Vector<N>) {
        let beta = self.beta;
        let reference = self.trajectory.reference::<N>(x.t);
        let e = reference.q - x.q;
        let s_true = (x.yd - x.qd) + (x.y - x.q) * beta;
        let q_tilde = x.q - self.prev_observer.q;
        let w = &mut self.window;
        w.n += 1;
        for l in 0..N {
            w.e_sum[l] += e[l];
            w.s_hat_sum[l] += x.s_hat[l];
            w.s_sum[l] += s_true[l];
            w.q_tilde_sum[l] += q_tilde[l];
        }
        w.e_sq += e.norm_squared();
        w.s_err_sq += (x.s_hat - s_true).norm_squared();
        w.r_tilde_sq += r_tilde.norm_squared();
        w.psi2_sq += psi2.norm_squared();
        if let Some(nn) = &self.nn {
            w.note_weights(nn, &self.v0);
        }
        if w.n == self.per_window {
            let row = w.row(x.t + self.dt);
            self.rows.push(row);
            self.window = Window::default();
        }
    }
}

impl Window {
    /// The weights now: `‖Ŵ‖`, the norm of `Ŵ`'s bias row, `‖V̂ − V̂(0)‖` with `V̂(0) = v0`.
    fn note_weights(&mut self, nn: &NnEstimator<N>, v0: &[f64]) {
        self.w_norm = nn.norm_w();
        self.w_bias = nn.weights_w()[..N]
            .iter()
            .map(|x| x * x)
            .sum::<f64>()
            .sqrt();
        self.v_moved = nn
            .weights_v()
            .iter()
            .zip(v0)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
    }
}

struct Measured {
    summary: RunSummary,
    /// Per agent id, the windows in time order.
    rows: BTreeMap<u32, Vec<Row>>,
}

fn measure(r: &Resolved, window_s: f64) -> Result<Measured> {
    if !(window_s.is_finite() && window_s > 0.0) {
        bail!("--window-s must be > 0, got {window_s}");
    }
    let s = &r.scenario;
    let per_window = ((window_s / s.control_period_s).round() as u64).max(1);
    let nn_params = NnParams::from_controller(&s.controller);
    let mut trackers: BTreeMap<u32, Tracker> = s
        .agents
        .iter()
        .map(|a| (a.id, Tracker::new(s, a, nn_params, per_window)))
        .collect();
    let mut mismatch: Option<String> = None;
    let summary = run_inproc_any(r, |rec: &TickRecord| {
        let id = rec.agent.agent;
        let Some(tr) = trackers.get_mut(&id) else {
            return;
        };
        let x = TickValues::of(rec);
        let (psi2, r_tilde, differs) = tr.follow(&x);
        if let (Some(shadow), None) = (differs, &mismatch) {
            let (t, s_hat) = (x.t, x.s_hat);
            mismatch = Some(format!(
                "agent {id}, t = {t}: shadow Ŝ {shadow:?} differs from the recorded {s_hat:?}"
            ));
        }
        tr.accumulate(&x, &psi2, &r_tilde);
    })?;
    if let Some(m) = mismatch {
        bail!("the shadow estimator does not follow the control center: {m}");
    }
    Ok(Measured {
        summary,
        rows: trackers.into_iter().map(|(id, t)| (id, t.rows)).collect(),
    })
}

/// The columns of a [`Row`].
const COLUMNS: &str = "t_end_s,e1_mean_rad,e2_mean_rad,e_rms_rad,s_err_rms_rad_s,s_hat1_mean,s_hat2_mean,s1_mean,s2_mean,r_tilde_rms_rad_s,psi2_rms_rad_s,q_tilde1_mean_rad,q_tilde2_mean_rad,w_norm,w_bias_norm,v_moved";

fn csv_fields(r: &Row) -> String {
    format!(
        "{:.1},{:.5},{:.5},{:.5},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.5},{:.5},{:.4},{:.4},{:.4}",
        r.t_end,
        r.e_mean[0],
        r.e_mean[1],
        r.e_rms,
        r.s_err_rms,
        r.s_hat_mean[0],
        r.s_hat_mean[1],
        r.s_mean[0],
        r.s_mean[1],
        r.r_tilde_rms,
        r.psi2_rms,
        r.q_tilde_mean[0],
        r.q_tilde_mean[1],
        r.w_norm,
        r.w_bias,
        r.v_moved
    )
}

fn series(setup: &Setup, window_s: f64) -> Result<()> {
    let m = measure(&setup.resolve()?, window_s)?;
    println!("agent,{COLUMNS}");
    for (id, rows) in &m.rows {
        for r in rows {
            println!("{id},{}", csv_fields(r));
        }
    }
    Ok(())
}

fn summary(setup: &Setup, window_s: f64) -> Result<()> {
    let m = measure(&setup.resolve()?, window_s)?;
    println!("digest {}", m.summary.trace_digest);
    println!("agent,rmse_rad,false_alarms,window,{COLUMNS}");
    for (id, rows) in &m.rows {
        let metrics = m
            .summary
            .metrics
            .get(&id.to_string())
            .context("an agent without metrics")?;
        for (which, r) in [("first", rows.first()), ("last", rows.last())] {
            if let Some(r) = r {
                println!(
                    "{id},{:.4},{},{which},{}",
                    metrics.rmse_rad,
                    metrics.false_alarms,
                    csv_fields(r)
                );
            }
        }
    }
    Ok(())
}

fn delay_sweep(setup: &Setup, delays_ms: &[f64]) -> Result<()> {
    println!("delay_ms,agent,rmse_rad,max_abs_error_rad");
    for &ms in delays_ms {
        let mut s = setup.clone();
        s.delay_ms = Some(ms);
        let r = s.resolve()?;
        let summary = run_inproc_any(&r, |_| {})?;
        let (id, m) = summary
            .metrics
            .iter()
            .next()
            .context("a scenario without agents")?;
        println!("{ms},{id},{:.4},{:.4}", m.rmse_rad, m.max_abs_error_rad);
    }
    Ok(())
}

/// Table I of the paper, proposed controller, robots 1–4 (docs/model.md, "Reproduction").
const PAPER_TABLE1_PROPOSED: [(u32, f64); 4] = [(1, 0.008), (2, 0.013), (3, 0.009), (4, 0.010)];

/// Per agent id, RMSE (rad) and false alarms of one in-process run.
fn rmse_and_alarms(setup: &Setup) -> Result<BTreeMap<u32, (f64, u64)>> {
    let summary = run_inproc_any(&setup.resolve()?, |_| {})?;
    summary
        .metrics
        .iter()
        .map(|(id, m)| {
            let id: u32 = id
                .parse()
                .context("a non-numeric agent id in the metrics")?;
            Ok((id, (m.rmse_rad, m.false_alarms)))
        })
        .collect()
}

/// A list of values to try, or the scenario's own when the list is empty.
fn or_keep<T: Clone>(list: &[T]) -> Vec<Option<T>> {
    if list.is_empty() {
        vec![None]
    } else {
        list.iter().cloned().map(Some).collect()
    }
}

fn grid(
    setup: &Setup,
    horizon_s: f64,
    observer_inputs: &[String],
    innovation_ts: &[f64],
    leakages_w: &[f64],
    dead_zones: &[f64],
) -> Result<()> {
    let long = Setup {
        duration_s: Some(horizon_s),
        attack: Some("none".into()),
        ..setup.clone()
    };
    let table1 = Setup {
        duration_s: Some(40.0),
        attack: Some("paper".into()),
        ..setup.clone()
    };
    let traditional = rmse_and_alarms(&Setup {
        controller: Some("traditional".into()),
        ..long.clone()
    })?;
    let ids: Vec<u32> = traditional.keys().copied().collect();
    print_grid_head(&ids, &traditional);
    for input in or_keep(observer_inputs) {
        for t in or_keep(innovation_ts) {
            for l in or_keep(leakages_w) {
                for dz in or_keep(dead_zones) {
                    let with = |s: &Setup| Setup {
                        controller: Some("proposed".into()),
                        observer_input: input.clone().or_else(|| s.observer_input.clone()),
                        innovation_t: t.or(s.innovation_t),
                        leakage_w: l.or(s.leakage_w),
                        dead_zone: dz.or(s.dead_zone),
                        ..s.clone()
                    };
                    print_grid_row(&with(&long), &with(&table1), &ids, &traditional)?;
                }
            }
        }
    }
    Ok(())
}

/// The head of [`grid`]'s CSV and its first row, the traditional reference of the robots `ids`.
fn print_grid_head(ids: &[u32], traditional: &BTreeMap<u32, (f64, u64)>) {
    let head: Vec<String> = ids
        .iter()
        .map(|id| format!("r{id}_long,r{id}_alarms,r{id}_vs_trad,r{id}_table1,r{id}_vs_paper"))
        .collect();
    println!(
        "observer_input,innovation_t_s,leakage_w_per_s,dead_zone_rad_s,{},worst_vs_trad,worst_vs_paper",
        head.join(",")
    );
    let trad: Vec<String> = ids
        .iter()
        .map(|id| format!("{:.5},{},1.000,,", traditional[id].0, traditional[id].1))
        .collect();
    println!("traditional,,,,{},,", trad.join(","));
}

/// One combination's row of [`grid`]: its long run (`long`) against the traditional one and
/// its Table I run (`table1`) against the paper, per robot of `ids`, and the worst of each.
fn print_grid_row(
    long: &Setup,
    table1: &Setup,
    ids: &[u32],
    traditional: &BTreeMap<u32, (f64, u64)>,
) -> Result<()> {
    let r = long.resolve()?;
    let c = r.scenario.controller;
    let long_m = rmse_and_alarms(long)?;
    let t1 = rmse_and_alarms(table1)?;
    let (mut worst_trad, mut worst_paper) = (0.0_f64, 0.0_f64);
    let mut cells = Vec::new();
    for id in ids {
        let (rmse, alarms) = long_m[id];
        let vs_trad = rmse / traditional[id].0;
        worst_trad = worst_trad.max(vs_trad);
        let paper = PAPER_TABLE1_PROPOSED.iter().find(|(i, _)| i == id);
        let (t1_rmse, vs_paper) = match (t1.get(id), paper) {
            (Some(&(x, _)), Some(&(_, p))) => {
                worst_paper = worst_paper.max((x / p - 1.0).abs());
                (format!("{x:.5}"), format!("{:.3}", x / p))
            }
            _ => (String::new(), String::new()),
        };
        cells.push(format!(
            "{rmse:.5},{alarms},{vs_trad:.3},{t1_rmse},{vs_paper}"
        ));
    }
    println!(
        "{},{},{},{},{},{worst_trad:.3},{:.3}",
        c.observer_input.as_str(),
        c.update_law.innovation_time_constant_s,
        c.update_law.leakage_w_per_s,
        c.update_law.dead_zone_rad_s,
        cells.join(","),
        1.0 + worst_paper
    );
    Ok(())
}

fn figure(
    stem: &std::path::Path,
    remedy: &std::path::Path,
    duration_s: f64,
    window_s: f64,
) -> Result<()> {
    let mut lines = FigureLines::default();
    for (i, (label, setup)) in figure_runs(remedy, duration_s).iter().enumerate() {
        let m = measure(&setup.resolve()?, window_s)?;
        let rows = m.rows.get(&1).context("robot 1 not in the run")?;
        lines.add(i, label, setup, rows);
    }
    let fig = lines.figure(duration_s, window_s);
    let written = plot::save_figure(&fig, stem, (1100, 1600))?;
    for p in written {
        println!("{}", p.display());
    }
    Ok(())
}

/// The runs of [`figure`], with their labels: robot 1 without attack for `duration_s`, under
/// the paper's laws, with the remedy of the scenario `remedy`, and the traditional controller.
fn figure_runs(remedy: &std::path::Path, duration_s: f64) -> [(&'static str, Setup); 3] {
    let base = Setup {
        duration_s: Some(duration_s),
        attack: Some("none".into()),
        agents: vec![1],
        ..Setup::default()
    };
    [
        ("proposed, paper's laws (37)-(38)", base.clone()),
        (
            "proposed, with the remedy",
            Setup {
                scenario: Some(remedy.to_path_buf()),
                ..base.clone()
            },
        ),
        (
            "traditional",
            Setup {
                controller: Some("traditional".into()),
                ..base
            },
        ),
    ]
}

/// The curves of [`figure`]'s panels, gathered run by run.
#[derive(Default)]
struct FigureLines {
    e1: Vec<plot::Line>,
    s_err: Vec<plot::Line>,
    weights: Vec<plot::Line>,
    q_tilde: Vec<plot::Line>,
    innovation: Vec<plot::Line>,
}

impl FigureLines {
    /// The curves of the `i`-th run (`label`, `setup`) from robot 1's windows `rows`: every run's
    /// position and observer errors, the first run's innovation and Ψ2, and the proposed runs'
    /// attack-estimation error and weights.
    fn add(&mut self, i: usize, label: &str, setup: &Setup, rows: &[Row]) {
        let color = plot::PALETTE[i];
        let line = |f: &dyn Fn(&Row) -> f64, label: String| plot::Line {
            label,
            color,
            points: rows.iter().map(|r| (r.t_end, f(r))).collect(),
            keep: true,
            dashed: false,
        };
        self.e1.push(line(&|r| r.e_mean[0], label.to_string()));
        self.q_tilde
            .push(line(&|r| r.q_tilde_mean[0], label.to_string()));
        if i == 0 {
            self.innovation.push(line(
                &|r| r.r_tilde_rms,
                "innovation ẏ + βy − (observer's)".into(),
            ));
            self.innovation.push(plot::Line {
                color: plot::PALETTE[3],
                ..line(&|r| r.psi2_rms, "Ψ2 = innovation − Ŝ".into())
            });
        }
        if setup.controller.is_none() {
            self.s_err.push(line(&|r| r.s_err_rms, label.to_string()));
            self.weights
                .push(line(&|r| r.w_bias, format!("{label}: bias row of Ŵ")));
            self.weights.push(plot::Line {
                color: plot::PALETTE[i + 3],
                ..line(
                    &|r| r.v_moved,
                    format!("{label}: inner weights, distance from V(0)"),
                )
            });
        }
    }

    /// The figure of runs of `duration_s` in windows of `window_s`: one panel per curve kind.
    fn figure(self, duration_s: f64, window_s: f64) -> plot::Figure {
        let panel = |title: &str, y_label: &str, lines: Vec<plot::Line>| plot::Panel {
            title: title.into(),
            y_label: y_label.into(),
            kind: plot::PanelKind::Lines(lines),
            guides: Vec::new(),
        };
        plot::Figure {
            title: format!(
                "Robot 1, no attack, {duration_s} s: means and RMS over windows of {window_s:.2} s"
            ),
            x_label: "t (s)".into(),
            x_range: (0.0, duration_s),
            markers: vec![40.0],
            marker_label: "end of Table I's 40 s".into(),
            panels: vec![
                panel("link-1 position error q_d1 − q1 (mean)", "rad", self.e1),
                panel("attack-estimation error ‖Ŝ − S‖ (RMS)", "rad/s", self.s_err),
                panel(
                    "paper's laws: the innovation and what Ŝ leaves of it, Ψ2 (RMS; Ψ2 stays at the noise floor)",
                    "rad/s",
                    self.innovation,
                ),
                panel(
                    "output-layer bias and inner-weight change",
                    "rad/s, 1",
                    self.weights,
                ),
                panel("observer error: q1 minus the observer's estimate (mean)", "rad", self.q_tilde),
            ],
        }
    }
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Series { setup, window_s } => series(&setup, window_s),
        Command::Summary { setup, window_s } => summary(&setup, window_s),
        Command::DelaySweep { setup, delays_ms } => delay_sweep(&setup, &delays_ms),
        Command::Grid {
            setup,
            horizon_s,
            observer_inputs,
            innovation_ts,
            leakages_w,
            dead_zones,
        } => grid(
            &setup,
            horizon_s,
            &observer_inputs,
            &innovation_ts,
            &leakages_w,
            &dead_zones,
        ),
        Command::Figure {
            stem,
            remedy,
            duration_s,
            window_s,
        } => figure(&stem, &remedy, duration_s, window_s),
    }
}
