//! Cost of the math of one tick, on the paper's scenario (`cargo bench -p fdi-common`):
//!
//! * `center_tick_agent1`: the control center's pipeline for one agent ([`CenterAgent::tick`]),
//!   fed the tampered measurements agent 1 sees in the paper's run;
//! * `plant_step_agent1`: one agent's physics step ([`Plant::advance`]) after [`Plant::receive`]
//!   of that tick's torque, the torques of the same run;
//! * `paper_tick_4_agents`: one whole in-process tick of the paper's four agents (sensor,
//!   attack, control center, delay line, physics), as [`fdi_common::engine::run_inproc`] does it
//!   without the trace records.
//!
//! Every benchmark replays the run from `t = 0` in order (a fresh state, built outside the
//! timing, each time the run's end is reached), so each iteration is a real tick of the run.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use fdi_common::attack::AgentAttack;
use fdi_common::control::{CenterAgent, CenterParams};
use fdi_common::engine::{center_tick, tick_time};
use fdi_common::model::Vector;
use fdi_common::plant::Plant;
use fdi_common::scenario::{self, AgentConfig, Resolved};

/// One agent's pieces, fresh at `t = 0`.
struct AgentLoop {
    plant: Plant<2>,
    attack: AgentAttack,
    center: CenterAgent<2>,
}

impl AgentLoop {
    fn new(r: &Resolved, a: &AgentConfig) -> Self {
        let s = &r.scenario;
        Self {
            plant: Plant::<2>::new(s.plant_params(a)).expect("two-link plant"),
            attack: r.agent_attack(a.id),
            center: CenterAgent::<2>::new(center_params(r, a)).expect("two-link center"),
        }
    }

    /// Tick `k` at `t`; returns the tampered measurement the center saw and its torque.
    fn tick(&mut self, k: u64, t: f64) -> (Vector<2>, Vector<2>, Vector<2>) {
        let m = self.plant.measure();
        let (sent, _) = self.attack.measurement::<2>(k, t, &m);
        let tampered = sent.usable().map(|(m, _)| *m);
        let out = center_tick(&mut self.center, t, tampered.as_ref());
        let _ = self.plant.take_command(t, Some((out.u, 0.0)));
        self.plant.advance(k);
        let seen = tampered.unwrap_or(m);
        (seen.y, seen.yd, out.u)
    }
}

fn center_params(r: &Resolved, a: &AgentConfig) -> CenterParams {
    let s = &r.scenario;
    s.center_params(a)
}

/// Agent 1's inputs over the whole run: `(t, tampered y, tampered ẏ, torque)` per tick.
struct Recorded {
    t: Vec<f64>,
    y: Vec<Vector<2>>,
    yd: Vec<Vector<2>>,
    u: Vec<Vector<2>>,
}

fn record_agent1(r: &Resolved) -> Recorded {
    let a = agent1(r);
    let mut run = AgentLoop::new(r, a);
    let n = usize::try_from(r.ticks()).expect("ticks fit");
    let mut rec = Recorded {
        t: Vec::with_capacity(n),
        y: Vec::with_capacity(n),
        yd: Vec::with_capacity(n),
        u: Vec::with_capacity(n),
    };
    for k in 0..r.ticks() {
        let t = tick_time(k, r.scenario.control_period_s);
        let (y, yd, u) = run.tick(k, t);
        rec.t.push(t);
        rec.y.push(y);
        rec.yd.push(yd);
        rec.u.push(u);
    }
    rec
}

fn agent1(r: &Resolved) -> &AgentConfig {
    r.scenario
        .agents
        .iter()
        .find(|a| a.id == 1)
        .expect("the paper has agent 1")
}

/// Runs `iters` ticks in replays of the run: `fresh` builds the state (untimed), `step` runs
/// tick `k` of the run on it (timed).
fn replay<S>(
    iters: u64,
    ticks: usize,
    mut fresh: impl FnMut() -> S,
    mut step: impl FnMut(&mut S, usize),
) -> Duration {
    let mut total = Duration::ZERO;
    let mut left = iters;
    while left > 0 {
        let n = usize::try_from(left).unwrap_or(usize::MAX).min(ticks);
        let mut state = fresh();
        let began = Instant::now();
        for k in 0..n {
            step(&mut state, k);
        }
        total += began.elapsed();
        black_box(&state);
        left -= n as u64;
    }
    total
}

fn benches(c: &mut Criterion) {
    let r = scenario::paper().expect("the embedded paper scenario");
    let ticks = usize::try_from(r.ticks()).expect("ticks fit");
    let rec = record_agent1(&r);
    let a1 = agent1(&r);

    c.bench_function("center_tick_agent1", |b| {
        b.iter_custom(|iters| {
            replay(
                iters,
                ticks,
                || CenterAgent::<2>::new(center_params(&r, a1)).expect("two-link center"),
                |center, k| {
                    black_box(center.tick(
                        black_box(rec.t[k]),
                        black_box(&rec.y[k]),
                        black_box(&rec.yd[k]),
                    ));
                },
            )
        });
    });

    c.bench_function("plant_step_agent1", |b| {
        b.iter_custom(|iters| {
            replay(
                iters,
                ticks,
                || Plant::<2>::new(r.scenario.plant_params(a1)).expect("two-link plant"),
                |plant, k| {
                    let _ = plant.receive(black_box(rec.t[k]), black_box(rec.u[k]));
                    black_box(plant.advance(k as u64));
                },
            )
        });
    });

    c.bench_function("paper_tick_4_agents", |b| {
        b.iter_custom(|iters| {
            replay(
                iters,
                ticks,
                || {
                    r.scenario
                        .agents
                        .iter()
                        .map(|a| AgentLoop::new(&r, a))
                        .collect::<Vec<_>>()
                },
                |agents, k| {
                    let t = tick_time(k as u64, r.scenario.control_period_s);
                    for agent in agents.iter_mut() {
                        black_box(agent.tick(k as u64, t));
                    }
                },
            )
        });
    });
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .sample_size(50)
}

criterion_group! {
    name = math;
    config = config();
    targets = benches
}
criterion_main!(math);
