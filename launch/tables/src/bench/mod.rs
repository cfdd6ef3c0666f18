//! Measurements (`fdi-launch bench ...`): latency of the realtime runtime per hop, the transport
//! floor, and lockstep speed against the in-process engine. Results are printed and written to a
//! run directory; nothing here asserts a speed.

pub mod floor;
pub mod probe;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fdi_common::attack::{AttackProfile, Channel, CovertEntry, MessageAttack};
use fdi_common::engine::RunSummary;
use fdi_common::observe::Observer;
use fdi_common::scenario::{self, ClockMode, Resolved};
use fdi_common::stop::Stop;
use fdi_common::trace::{HopStamps, TraceReader, TraceRecord};
use hdrhistogram::Histogram;
use serde::Serialize;

use fdi_orchestrator::run::{execute, Engine};

/// `bench transport`: the transport floor and the runtime's hops against it.
#[derive(Debug, Clone)]
pub struct TransportOptions {
    /// Round trips per transport.
    pub iterations: u64,
    /// Spin before blocking, µs (0: the realtime runtime's event-driven strategy, which the
    /// runtime's latency is measured with).
    pub spin_us: u64,
    /// Agents and seconds of the realtime run measured beside the floor.
    pub agents: usize,
    pub duration_s: f64,
    /// Folder that receives the run directory.
    pub out: PathBuf,
}

/// `bench latency`: a realtime run measured.
#[derive(Debug, Clone)]
pub struct LatencyOptions {
    /// Number of agents (the paper's four robots, repeated).
    pub agents: usize,
    /// Simulated (= wall-clock) duration, s.
    pub duration_s: f64,
    /// Control rate, Hz.
    pub rate_hz: f64,
    /// Folder that receives the run directory.
    pub out: PathBuf,
    /// Placement of the run's processes (and of the timer probe beside them).
    pub placement: fdi_orchestrator::run::runtime::Placement,
    /// Split the measured run over the hosts of this deployment file (docs/multi-host.md).
    pub hosts: Option<fdi_orchestrator::run::split::HostsFile>,
    /// Serve the measured run live at this address (as `run --live`).
    pub live: Option<std::net::SocketAddr>,
    /// Start the measured run once a viewer subscribed, at most this many seconds.
    pub live_wait: Option<f64>,
    /// Told the run's ticks.
    pub progress: Observer,
}

/// `bench lockstep`: lockstep speed over IPC against the in-process engine.
#[derive(Debug, Clone)]
pub struct LockstepOptions {
    /// Agent counts to measure.
    pub agents: Vec<usize>,
    /// Simulated duration of each run, s.
    pub duration_s: f64,
    /// Keep the traces of the measured runs (otherwise only their summaries stay).
    pub keep_traces: bool,
    /// Folder that receives the benchmark's folder.
    pub out: PathBuf,
    /// Attack of the runs instead of the paper's: a preset name or a profile file for the
    /// paper's four robots.
    pub attack: Option<String>,
    /// Told the IPC runs' ticks.
    pub progress: Observer,
}

/// The paper scenario with `n` agents: agent `i` is a copy of paper robot `(i − 1) % 4 + 1`,
/// trajectory, delay and attack included (the paper's attack, or `attack`, a preset name or
/// profile file written for the paper's robots).
pub fn scaled_paper(n: usize, attack: Option<&str>) -> Result<Resolved> {
    if n == 0 || n > scenario::MAX_AGENTS {
        bail!("--agents must be in 1..={}", scenario::MAX_AGENTS);
    }
    let paper = scenario::paper()?;
    let profile = match attack {
        Some(arg) => scenario::attack_from_arg(arg, &paper.scenario)?,
        None => paper.attack.clone(),
    };
    let mut r = paper.clone();
    r.scenario.agents.clear();
    r.attack = AttackProfile {
        name: profile.name.clone(),
        description: profile.description.clone(),
        ..AttackProfile::default()
    };
    for i in 1..=n {
        let src = &paper.scenario.agents[(i - 1) % paper.scenario.agents.len()];
        let id = u32::try_from(i)?;
        let mut a = src.clone();
        a.id = id;
        r.scenario.agents.push(a);
        let of = |agent: u32| agent == src.id;
        for ch in profile.channels.iter().filter(|c| of(c.agent)) {
            r.attack.channels.push(Channel {
                agent: id,
                ..ch.clone()
            });
        }
        for m in profile.messages.iter().filter(|m| of(m.agent)) {
            r.attack.messages.push(MessageAttack {
                agent: id,
                ..m.clone()
            });
        }
        for c in profile.covert.iter().filter(|c| of(c.agent)) {
            r.attack.covert.push(CovertEntry { agent: id, ..*c });
        }
    }
    r.scenario.name = format!("paper-x{n}");
    Ok(r)
}

/// Percentiles of one latency, µs.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Percentiles {
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
    pub count: u64,
}

fn histogram() -> Result<Histogram<u64>> {
    // 1 ns .. 100 s at 3 significant digits.
    Histogram::new_with_bounds(1, 100_000_000_000, 3).context("creating a latency histogram")
}

fn percentiles(h: &Histogram<u64>) -> Percentiles {
    let us = |ns: u64| ns as f64 / 1000.0;
    Percentiles {
        p50: us(h.value_at_quantile(0.5)),
        p90: us(h.value_at_quantile(0.9)),
        p99: us(h.value_at_quantile(0.99)),
        p999: us(h.value_at_quantile(0.999)),
        max: us(h.max()),
        count: h.len(),
    }
}

/// Per-hop latencies.
#[derive(Debug, Serialize)]
pub struct Hops {
    pub agent_to_attacker: Percentiles,
    pub attacker_to_center: Percentiles,
    pub center_to_agent: Percentiles,
}

#[derive(Debug, Serialize)]
/// What `bench latency` measured (`latency.json`).
pub struct LatencyReport {
    pub agents: usize,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub ticks: u64,
    pub e2e_us: Percentiles,
    pub hops_us: Hops,
    pub attacker_processing_us: Percentiles,
    pub center_compute_us: Percentiles,
    /// |actual − nominal| interval between two consecutive measurements of an agent.
    pub period_jitter_us: Percentiles,
    pub deadline_misses: u64,
    pub deadline_miss_ratio: f64,
    /// Torques that never reached their agent (of every tick but the last, whose torque no
    /// step uses and which is left out of the latencies).
    pub lost_ticks: u64,
    /// Scheduling of the run's processes: `SCHED_OTHER` or `SCHED_FIFO <priority>`, and
    /// `on CPUs <list>` when confined.
    pub scheduling: String,
    /// The machine beside the run: how late a timer thread of the launcher woke at every
    /// period boundary (same scheduling as the run).
    pub timer_probe_late_us: Percentiles,
    /// Wake-ups of that thread late by 1 ms or more: stalls of the machine itself.
    pub timer_probe_stalls_over_1ms: u64,
    /// Deadline misses whose window (from the due command's measurement to the step that
    /// missed it) overlaps a stall of the timer thread of 0.5 ms or more.
    pub deadline_misses_in_machine_stalls: u64,
    /// Share of all steps whose window overlaps such a stall (what chance alone would give).
    pub steps_in_machine_stalls_ratio: f64,
    pub run_dir: String,
}

/// Measures a realtime run and returns its latency report (written into its run directory:
/// `latency.json`, `latency.csv`, the histogram figure).
pub fn latency(a: &LatencyOptions, stop: &Stop) -> Result<LatencyReport> {
    let r = latency_scenario(a)?;
    let period_ns = (r.scenario.control_period_s * 1e9) as i64;
    let run = run_beside_probe(a, &r, period_ns, stop)?;
    let mut lat = Latencies::new()?;
    for agent in &r.scenario.agents {
        let path = fdi_common::run_dir::RunDir::new(&run.dir)
            .trace(fdi_common::run_dir::Process::Agent(agent.id));
        lat.read_agent(&path, run.summary.ticks, period_ns)?;
    }
    let stalls = lat.stalls(&run.wakeups, period_ns.unsigned_abs())?;
    let report = latency_report(a, &run, &lat, &stalls);
    write_latency(&run.dir, &report)?;
    latency_histogram_png(
        &run.dir,
        &[
            ("end-to-end", &lat.e2e),
            ("agent -> attacker", &lat.agent_to_attacker),
            ("attacker -> center", &lat.attacker_to_center),
            ("center -> agent", &lat.center_to_agent),
        ],
    )?;
    Ok(report)
}

/// The scenario of `bench latency`: the scaled paper scenario on the realtime clock, at the
/// asked rate and duration.
fn latency_scenario(a: &LatencyOptions) -> Result<Resolved> {
    if !(a.rate_hz.is_finite() && a.rate_hz > 0.0) {
        bail!("--rate-hz must be a positive number, got {}", a.rate_hz);
    }
    let mut r = scaled_paper(a.agents, None)?;
    r.scenario.clock = ClockMode::Realtime;
    r.scenario.duration_s = a.duration_s;
    r.scenario.control_period_s = 1.0 / a.rate_hz;
    let problems = r.scenario.validate();
    if !problems.is_empty() {
        bail!(scenario::ScenarioError {
            source_name: "bench latency".into(),
            problems
        });
    }
    Ok(r)
}

/// The live server `a` asks for.
fn live_serve(a: &LatencyOptions) -> Result<Option<fdi_orchestrator::run::LiveServe>> {
    a.live
        .map(|addr| {
            fdi_orchestrator::run::LiveServe::new(
                addr,
                fdi_live::Options::DEFAULT_RATE_HZ,
                a.live_wait,
            )
        })
        .transpose()
}

/// A whole realtime run and the timer probe's wake-ups beside it.
struct MeasuredRun {
    dir: PathBuf,
    summary: RunSummary,
    wakeups: crate::bench::probe::Wakeups,
}

/// Runs `r` over IPC in a run directory of its own, with the timer probe running beside it
/// under the same placement.
fn run_beside_probe(
    a: &LatencyOptions,
    r: &Resolved,
    period_ns: i64,
    stop: &Stop,
) -> Result<MeasuredRun> {
    let placement = &a.placement;
    fdi_orchestrator::run::check_placement(r, Engine::Ipc, placement)?;
    let dir = fdi_orchestrator::run_dirs::create_run_dir(&a.out, r)?;
    let split = a.hosts.as_ref().map(|h| h.split_for(r)).transpose()?;
    let probe = crate::bench::probe::TimerProbe::start(period_ns.unsigned_abs(), placement);
    let summary = fdi_orchestrator::run_dirs::discard_if_not_started(
        &dir,
        fdi_orchestrator::run::execute_on(
            r,
            Engine::Ipc,
            Some(&dir),
            &fdi_orchestrator::run::Options {
                progress: a.progress.clone(),
                placement: placement.clone(),
                traces: fdi_orchestrator::run::Traces::Full,
                stop: stop.clone(),
                live: live_serve(a)?,
                pace: None,
            },
            split.as_ref(),
        ),
    );
    let wakeups = probe.finish();
    let (summary, wakeups) = (fdi_orchestrator::run::require_whole(summary?)?, wakeups?);
    Ok(MeasuredRun {
        dir,
        summary,
        wakeups,
    })
}

/// What the agents' traces of a realtime run tell of its latencies (ns) and its steps.
struct Latencies {
    /// Sensor → actuation: a measurement sent to its torque received.
    e2e: Histogram<u64>,
    agent_to_attacker: Histogram<u64>,
    attacker_processing: Histogram<u64>,
    attacker_to_center: Histogram<u64>,
    center_compute: Histogram<u64>,
    center_to_agent: Histogram<u64>,
    /// |actual − nominal| interval between two consecutive measurements of an agent.
    jitter: Histogram<u64>,
    /// Every step as a wall-clock window `[ran − τ − 2Δ, ran]`: from when the command due
    /// could have been measured to when the step ran (and missed it, or not).
    step_windows: Vec<(u64, u64)>,
    /// The windows of the steps that missed their deadline.
    miss_windows: Vec<(u64, u64)>,
}

impl Latencies {
    fn new() -> Result<Self> {
        Ok(Self {
            e2e: histogram()?,
            agent_to_attacker: histogram()?,
            attacker_processing: histogram()?,
            attacker_to_center: histogram()?,
            center_compute: histogram()?,
            center_to_agent: histogram()?,
            jitter: histogram()?,
            step_windows: Vec::new(),
            miss_windows: Vec::new(),
        })
    }

    /// Adds the trace of one agent of a run of `ticks` ticks: the hops and the jitter of its
    /// measurements, and the window of each of its steps.
    fn read_agent(&mut self, path: &Path, ticks: u64, period_ns: i64) -> Result<()> {
        let mut last_sent: Option<u64> = None;
        let mut sent_at = HashMap::new();
        let mut steps = Vec::new();
        for rec in TraceReader::open(path)? {
            let rec = rec?;
            if let TraceRecord::Agent(a) = &rec {
                steps.push((a.k, a.tau, a.missed));
            }
            if let TraceRecord::Latency { stamps: s, k, .. } = rec {
                sent_at.insert(k, s.agent_sent_ns);
                // No step uses the last measurement's torque: the agent stamps it whenever it
                // next looks, which may be in the run's teardown. Not a latency.
                if k + 1 >= ticks {
                    continue;
                }
                self.record_hops(&s);
                // The first interval includes the realtime start lead (measurement 0 goes out on
                // the start message, measurement 1 at the epoch): not jitter.
                if let Some(prev) = last_sent.filter(|_| k > 1) {
                    let dev = (s.agent_sent_ns as i64 - prev as i64 - period_ns).unsigned_abs();
                    let _ = self.jitter.record(dev.max(1));
                }
                last_sent = Some(s.agent_sent_ns);
            }
        }
        self.record_steps(&steps, &sent_at, period_ns.unsigned_abs());
        Ok(())
    }

    /// The hops of one measurement, and its end-to-end latency.
    fn record_hops(&mut self, s: &HopStamps) {
        let rec_ns = |h: &mut Histogram<u64>, from: u64, to: u64| {
            if from > 0 && to >= from {
                let _ = h.record((to - from).max(1));
            }
        };
        rec_ns(&mut self.e2e, s.agent_sent_ns, s.agent_received_ns);
        rec_ns(
            &mut self.agent_to_attacker,
            s.agent_sent_ns,
            s.attacker_received_ns,
        );
        rec_ns(
            &mut self.attacker_processing,
            s.attacker_received_ns,
            s.attacker_sent_ns,
        );
        rec_ns(
            &mut self.attacker_to_center,
            s.attacker_sent_ns,
            s.center_received_ns,
        );
        rec_ns(
            &mut self.center_compute,
            s.center_received_ns,
            s.center_sent_ns,
        );
        rec_ns(
            &mut self.center_to_agent,
            s.center_sent_ns,
            s.agent_received_ns,
        );
    }

    /// The window of each step `(k, τ, missed)`, from the times its agent sent measurements.
    fn record_steps(
        &mut self,
        steps: &[(u64, f64, bool)],
        sent_at: &HashMap<u64, u64>,
        period_ns: u64,
    ) {
        for &(k, tau, missed) in steps {
            // The step from t_k ran just before measurement k + 1 went out.
            let ran = sent_at
                .get(&(k + 1))
                .copied()
                .or_else(|| sent_at.get(&k).map(|s| s + period_ns));
            if let Some(ran) = ran {
                let reach = (tau * 1e9) as u64 + 2 * period_ns;
                let window = (ran.saturating_sub(reach), ran);
                self.step_windows.push(window);
                if missed {
                    self.miss_windows.push(window);
                }
            }
        }
    }

    /// What the timer probe saw during the run's steps, and how the steps' windows (the
    /// missed ones and all) fall in the machine's stalls.
    fn stalls(&self, wakeups: &crate::bench::probe::Wakeups, period_ns: u64) -> Result<Stalls> {
        let steps = &self.step_windows;
        // The probe's view of the run itself (its steps), not of start-up or teardown.
        let run_from = steps
            .iter()
            .map(|w| w.1)
            .min()
            .unwrap_or(0)
            .saturating_sub(period_ns);
        let run_to = steps.iter().map(|w| w.1).max().unwrap_or(u64::MAX);
        let probe = wakeups.within(run_from, run_to)?;
        let misses_in_stalls =
            crate::bench::probe::overlapping(&self.miss_windows, &probe.stalls) as u64;
        // What share of all steps a stall touches: the rate at which misses would fall in
        // stalls by chance alone.
        let step_share = if steps.is_empty() {
            0.0
        } else {
            crate::bench::probe::overlapping(steps, &probe.stalls) as f64 / steps.len() as f64
        };
        Ok(Stalls {
            probe,
            misses_in_stalls,
            step_share,
        })
    }
}

/// The machine's stalls during a realtime run, against the run's steps.
struct Stalls {
    probe: crate::bench::probe::ProbeResult,
    /// Deadline misses whose window overlaps a stall.
    misses_in_stalls: u64,
    /// Share of all steps whose window overlaps a stall.
    step_share: f64,
}

/// The latency report of a measured run, as printed and written to `latency.json`.
fn latency_report(
    a: &LatencyOptions,
    run: &MeasuredRun,
    lat: &Latencies,
    stalls: &Stalls,
) -> LatencyReport {
    let summary = &run.summary;
    let misses: u64 = summary.metrics.values().map(|m| m.deadline_misses).sum();
    let agent_ticks = summary.ticks * a.agents as u64;
    LatencyReport {
        agents: a.agents,
        rate_hz: a.rate_hz,
        duration_s: a.duration_s,
        ticks: summary.ticks,
        e2e_us: percentiles(&lat.e2e),
        hops_us: Hops {
            agent_to_attacker: percentiles(&lat.agent_to_attacker),
            attacker_to_center: percentiles(&lat.attacker_to_center),
            center_to_agent: percentiles(&lat.center_to_agent),
        },
        attacker_processing_us: percentiles(&lat.attacker_processing),
        center_compute_us: percentiles(&lat.center_compute),
        period_jitter_us: percentiles(&lat.jitter),
        deadline_misses: misses,
        deadline_miss_ratio: if agent_ticks > 0 {
            misses as f64 / agent_ticks as f64
        } else {
            0.0
        },
        lost_ticks: (summary.ticks.saturating_sub(1) * a.agents as u64)
            .saturating_sub(lat.e2e.len()),
        scheduling: a.placement.describe(),
        timer_probe_late_us: percentiles(&stalls.probe.late),
        timer_probe_stalls_over_1ms: stalls.probe.stalls_over(1_000_000) as u64,
        deadline_misses_in_machine_stalls: stalls.misses_in_stalls,
        steps_in_machine_stalls_ratio: stalls.step_share,
        run_dir: run.dir.display().to_string(),
    }
}

#[derive(Debug, Serialize)]
/// What `bench transport` measured.
pub struct TransportReport {
    pub floor: crate::bench::floor::FloorResult,
    /// The iceoryx2 3-hop chain at the runtime's rate (one round trip per 1 ms period): its
    /// processes sleep between messages, as the runtime's do between ticks.
    pub paced_chain: crate::bench::floor::FloorCase,
    pub runtime_hops_p50_us: [f64; 3],
    /// Runtime per-hop p50 over the back-to-back 3-hop chain's per-hop p50, per hop.
    pub runtime_over_floor: [f64; 3],
    /// Runtime per-hop p50 over the paced 3-hop chain's per-hop p50, per hop.
    pub runtime_over_paced_floor: [f64; 3],
    pub runtime_run_dir: String,
    /// Round trips of the paced chain (as many as the runtime run has ticks).
    pub paced_round_trips: u64,
}

/// The transport floor, the paced chain and a realtime run's hops against them.
pub fn transport(a: &TransportOptions, stop: &Stop) -> Result<TransportReport> {
    let floor = crate::bench::floor::run_floor(&crate::bench::floor::FloorOptions {
        iterations: a.iterations,
        warmup: (a.iterations / 20).max(100),
        spin: std::time::Duration::from_micros(a.spin_us),
        pace: None,
    })?;
    // As many round trips as the runtime run has ticks.
    let paced_trips = ((a.duration_s * 1000.0) as u64).max(1);
    let paced_chain = crate::bench::floor::run_paced_chain(&crate::bench::floor::FloorOptions {
        iterations: paced_trips,
        warmup: (paced_trips / 20).max(10),
        spin: std::time::Duration::from_micros(a.spin_us),
        pace: Some(std::time::Duration::from_millis(1)),
    })?;
    let rt = latency(
        &LatencyOptions {
            agents: a.agents,
            duration_s: a.duration_s,
            rate_hz: 1000.0,
            out: a.out.clone(),
            placement: Default::default(),
            hosts: None,
            live: None,
            live_wait: None,
            progress: Observer::quiet(),
        },
        stop,
    )?;
    let hops = [
        rt.hops_us.agent_to_attacker.p50,
        rt.hops_us.attacker_to_center.p50,
        rt.hops_us.center_to_agent.p50,
    ];
    let base = floor.ipc_chain.per_hop.p50_us;
    let paced = paced_chain.per_hop.p50_us;
    Ok(TransportReport {
        runtime_over_floor: hops.map(|h| h / base),
        runtime_over_paced_floor: hops.map(|h| h / paced),
        runtime_hops_p50_us: hops,
        floor,
        paced_chain,
        runtime_run_dir: rt.run_dir,
        paced_round_trips: paced_trips,
    })
}

/// The report's latencies by name, in the order of its table and CSV.
pub fn latency_rows(r: &LatencyReport) -> Vec<(&'static str, Percentiles)> {
    vec![
        ("end-to-end sensor -> actuation", r.e2e_us),
        ("hop agent -> attacker", r.hops_us.agent_to_attacker),
        ("attacker processing", r.attacker_processing_us),
        (
            "hop attacker -> control center",
            r.hops_us.attacker_to_center,
        ),
        ("control-center compute", r.center_compute_us),
        ("hop control center -> agent", r.hops_us.center_to_agent),
        ("control-period jitter", r.period_jitter_us),
        ("machine: timer wake-up lateness", r.timer_probe_late_us),
    ]
}

fn write_latency(dir: &Path, r: &LatencyReport) -> Result<()> {
    std::fs::write(
        dir.join("latency.json"),
        serde_json::to_string_pretty(r)? + "\n",
    )
    .context("writing latency.json")?;
    std::fs::write(dir.join("latency.csv"), latency_csv(r)?).context("writing latency.csv")
}

/// `latency.csv`: one row per measured latency, in µs.
fn latency_csv(r: &LatencyReport) -> Result<Vec<u8>> {
    const HEADER: [&str; 7] = [
        "metric", "p50_us", "p90_us", "p99_us", "p999_us", "max_us", "count",
    ];
    let rows = latency_rows(r).into_iter().map(|(name, p)| {
        [
            name.to_string(),
            p.p50.to_string(),
            p.p90.to_string(),
            p.p99.to_string(),
            p.p999.to_string(),
            p.max.to_string(),
            p.count.to_string(),
        ]
    });
    fdi_report::output::csv_bytes(&HEADER, rows).context("writing latency.csv")
}

/// `latency.png` / `latency.svg`: share of messages per latency bucket (log-spaced), per hop, on
/// a logarithmic axis so that the tail (a few messages in 10⁵) shows beside the bulk.
fn latency_histogram_png(dir: &Path, hists: &[(&str, &Histogram<u64>)]) -> Result<()> {
    const EDGES_US: [u64; 11] = [
        0,
        10,
        20,
        50,
        100,
        200,
        500,
        1_000,
        2_000,
        5_000,
        u64::MAX / 1_000,
    ];
    let categories = EDGES_US
        .windows(2)
        .map(|w| {
            if w[1] >= u64::MAX / 1_000 {
                format!("≥{} µs", w[0])
            } else {
                format!("{}–{} µs", w[0], w[1])
            }
        })
        .collect();
    let series = hists
        .iter()
        .zip(fdi_report::plot::PALETTE)
        .map(|((name, h), color)| {
            let total = h.len().max(1) as f64;
            let shares = EDGES_US
                .windows(2)
                .map(|w| {
                    100.0 * h.count_between(w[0] * 1_000, (w[1] * 1_000).saturating_sub(1)) as f64
                        / total
                })
                .collect();
            (format!("{name} ({} messages)", h.len()), color, shares)
        })
        .collect();
    let chart = fdi_report::plot::BarChart {
        title: "Realtime latency per hop".into(),
        y_label: "share of messages (%)".into(),
        categories,
        series,
        log_y: true,
    };
    fdi_report::plot::save_bars(&chart, &dir.join("latency"), (1100, 600))?;
    Ok(())
}

#[derive(Debug, Serialize)]
/// One agent count of `bench lockstep`.
pub struct LockstepRow {
    pub agents: usize,
    pub processes: usize,
    pub sim_s: f64,
    pub ticks: u64,
    pub inproc_wall_s: f64,
    pub ipc_wall_s: f64,
    pub ipc_over_inproc: f64,
    pub ipc_realtime_factor: f64,
    pub ipc_ticks_per_s: f64,
    pub bit_identical: bool,
}

/// What `bench lockstep` measured: a row per agent count, and the folder of its runs
/// (`lockstep.json` there).
#[derive(Debug)]
pub struct Lockstep {
    pub rows: Vec<LockstepRow>,
    pub dir: PathBuf,
}

/// Each agent count on both engines, one after the other (`lockstep.json` written).
pub fn lockstep(a: &LockstepOptions, stop: &Stop) -> Result<Lockstep> {
    let root = a.out.join(format!(
        "{}-bench-lockstep",
        fdi_orchestrator::run_dirs::timestamp()
    ));
    let mut rows = Vec::new();
    for &n in &a.agents {
        let row = lockstep_row(a, &root, n, stop)?;
        log::info!(
            "bench lockstep: {n} agents: ipc {:.3} s, inproc {:.3} s",
            row.ipc_wall_s,
            row.inproc_wall_s
        );
        rows.push(row);
    }
    std::fs::write(
        root.join("lockstep.json"),
        serde_json::to_string_pretty(&rows)? + "\n",
    )
    .context("writing lockstep.json")?;
    Ok(Lockstep { rows, dir: root })
}

/// Runs the scaled paper scenario with `n` agents on the in-process engine, then over IPC, each
/// into a run directory under `root` (without its traces unless `--keep-traces`).
fn lockstep_row(a: &LockstepOptions, root: &Path, n: usize, stop: &Stop) -> Result<LockstepRow> {
    let mut r = scaled_paper(n, a.attack.as_deref())?;
    r.scenario.duration_s = a.duration_s;
    let dir_in = fdi_orchestrator::run_dirs::create_run_dir(root, &named(&r, "inproc"))?;
    let inproc = execute(
        &r,
        Engine::Inproc,
        Some(&dir_in),
        &fdi_orchestrator::run::Options::quiet(fdi_orchestrator::run::Traces::Full, stop),
    )?;
    let dir_ipc = fdi_orchestrator::run_dirs::create_run_dir(root, &named(&r, "ipc"))?;
    let ipc = execute(
        &r,
        Engine::Ipc,
        Some(&dir_ipc),
        &fdi_orchestrator::run::Options {
            progress: a.progress.clone(),
            ..fdi_orchestrator::run::Options::quiet(fdi_orchestrator::run::Traces::Full, stop)
        },
    )
    .map_err(anyhow::Error::from)
    .and_then(fdi_orchestrator::run::require_whole)?;
    if !a.keep_traces {
        for d in [&dir_in, &dir_ipc] {
            let _ = std::fs::remove_dir_all(fdi_common::run_dir::RunDir::new(d).traces());
        }
    }
    Ok(LockstepRow {
        agents: n,
        processes: n + 2,
        sim_s: ipc.sim_s,
        ticks: ipc.ticks,
        inproc_wall_s: inproc.wall_s,
        ipc_wall_s: ipc.wall_s,
        ipc_over_inproc: ipc.wall_s / inproc.wall_s,
        ipc_realtime_factor: ipc.sim_s / ipc.wall_s,
        ipc_ticks_per_s: ipc.ticks as f64 / ipc.wall_s,
        bit_identical: ipc.trace_digest == inproc.trace_digest,
    })
}

fn named(r: &Resolved, engine: &str) -> Resolved {
    let mut n = r.clone();
    n.scenario.name = format!("{}-{engine}", r.scenario.name);
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_paper_repeats_the_four_robots_with_their_attacks() {
        let r = scaled_paper(9, None).expect("valid");
        assert_eq!(r.agent_count(), 9);
        assert_eq!(
            r.scenario.agents[4].trajectory,
            r.scenario.agents[0].trajectory
        );
        assert_eq!(
            r.scenario.agents[5].trajectory,
            r.scenario.agents[1].trajectory
        );
        // Every agent has the attack of the robot it copies (two channels each).
        for id in 1..=9u32 {
            assert_eq!(
                r.attack.channels.iter().filter(|c| c.agent == id).count(),
                2,
                "agent {id}"
            );
        }
        assert!(r.scenario.validate().is_empty());
        assert!(r.attack.problems(&r.scenario.agent_dofs()).is_empty());
        assert!(scaled_paper(0, None).is_err());
        let covert = scaled_paper(5, Some("covert")).expect("valid");
        assert_eq!(covert.attack.name, "covert");
        for id in [1, 5] {
            assert!(covert.attack.attacks_torque_of(id), "copies of robot 1");
            assert!(covert.attack.covert.iter().any(|c| c.agent == id));
        }
        assert!(!covert.attack.attacks_torque_of(2));
        assert!(covert
            .attack
            .problems(&covert.scenario.agent_dofs())
            .is_empty());
    }

    #[test]
    fn latency_csv_has_a_header_and_a_row_per_latency() {
        let mut h = histogram().expect("histogram");
        for ns in [1_000u64, 2_000, 3_000, 100_000] {
            h.record(ns).expect("record");
        }
        let p = percentiles(&h);
        let report = LatencyReport {
            agents: 1,
            rate_hz: 1000.0,
            duration_s: 1.0,
            ticks: 1000,
            e2e_us: p,
            hops_us: Hops {
                agent_to_attacker: p,
                attacker_to_center: p,
                center_to_agent: p,
            },
            attacker_processing_us: p,
            center_compute_us: p,
            period_jitter_us: p,
            deadline_misses: 0,
            deadline_miss_ratio: 0.0,
            lost_ticks: 0,
            scheduling: "SCHED_OTHER".into(),
            timer_probe_late_us: p,
            timer_probe_stalls_over_1ms: 0,
            deadline_misses_in_machine_stalls: 0,
            steps_in_machine_stalls_ratio: 0.0,
            run_dir: String::new(),
        };
        let bytes = latency_csv(&report).expect("csv");
        let mut r = csv::Reader::from_reader(bytes.as_slice());
        assert_eq!(
            r.headers().expect("header"),
            vec!["metric", "p50_us", "p90_us", "p99_us", "p999_us", "max_us", "count"]
        );
        let rows: Vec<csv::StringRecord> = r.records().map(|x| x.expect("row")).collect();
        assert_eq!(rows.len(), latency_rows(&report).len());
        assert_eq!(&rows[0][0], "end-to-end sensor -> actuation");
        assert_eq!(rows[0][1].parse::<f64>().ok(), Some(p.p50));
        assert_eq!(rows[0][5].parse::<f64>().ok(), Some(p.max));
        assert_eq!(&rows[0][6], "4");
    }

    #[test]
    fn percentiles_are_in_microseconds() {
        let mut h = histogram().expect("histogram");
        for ns in [1_000u64, 2_000, 3_000, 100_000] {
            h.record(ns).expect("record");
        }
        let p = percentiles(&h);
        assert!((p.p50 - 2.0).abs() < 0.01, "{p:?}");
        assert!((p.max - 100.0).abs() < 0.1, "{p:?}");
        assert_eq!(p.count, 4);
    }
}
