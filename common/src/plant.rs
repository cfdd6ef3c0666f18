//! The agent's side: the true robot, its sensor, and the delayed torque channel's receiving end
//! (docs/model.md, "Plant" and "Delayed torque channel"). Integration: classic RK4 over each control period (optionally sub-stepped),
//! each sub-step split where the zero-order-held delayed input `u(t − τ(t))` switches to a
//! newer command, so every RK stage sees the command in force over its whole piece.

use rand_chacha::ChaCha12Rng;
use rand_distr::{Distribution, Normal};

use crate::delay::{in_force_at, DelayLine, DelayProfile, PushError};
use crate::memo::Recent;
use crate::model::robot::{Forward, LANES, SIDE_BY_SIDE_MIN};
use crate::model::{EulerLagrange, ModelConfig, Vector};
use crate::rng::{stream, Purpose};
use crate::time::tick_time;
use crate::trajectory::pose;
use crate::units::AngleUnit;
use serde::{Deserialize, Serialize};

/// Everything that configures one agent's plant ([`crate::scenario::Scenario::plant_params`] takes
/// it from a scenario).
#[derive(Debug, Clone)]
pub struct PlantParams {
    pub agent_id: u32,
    pub run_seed: u64,
    pub control_period_s: f64,
    pub substeps: u32,
    pub model: ModelConfig,
    pub delay: DelayProfile,
    pub noise: NoiseConfig,
    pub disturbance: DisturbanceConfig,
    /// The pose the robot starts from at rest, rad, one value per joint (the trajectory's
    /// `start`); empty: the origin.
    pub start: Vec<f64>,
}

/// A measurement as the sensor produced it (before any attack).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement<const N: usize> {
    /// `y = q + θ1`, rad.
    pub y: Vector<N>,
    /// `ẏ = q̇ + θ2`, rad/s.
    pub yd: Vector<N>,
}

/// What one integration step reports about its start time `t_k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport<const N: usize> {
    /// Torque applied at `t_k`: `u(t_k − τ(t_k))`.
    pub u_applied: Vector<N>,
    /// True acceleration at `t_k`.
    pub qdd: Vector<N>,
    /// `τ(t_k)`, s.
    pub tau: f64,
    /// Some RK stage of this step needed a command that had not arrived (held the last one).
    pub missed: bool,
}

/// One agent's true robot.
#[derive(Debug)]
pub struct Plant<const N: usize> {
    params: PlantParams,
    model: Box<dyn EulerLagrange<N>>,
    /// True joint angles, rad.
    pub q: Vector<N>,
    /// True joint velocities, rad/s.
    pub qd: Vector<N>,
    commands: DelayLine<N>,
    noise_rng: ChaCha12Rng,
    noise_q: Option<Normal<f64>>,
    noise_qd: Option<Normal<f64>>,
    /// Steps with a deadline miss so far.
    pub deadline_misses: u64,
    /// Commands refused (out of order, duplicate, non-finite).
    pub refused_commands: u64,
    /// Ticks whose command never came (dropped, forged, replayed) or was refused.
    pub missing_commands: u64,
    /// `τ(t)` and `d(t)` at the instants the last steps evaluated them: a step's end is the next
    /// step's start, and a piece's end the next piece's start ([`Recent`]: same bits).
    recent_tau: Recent<f64, 4>,
    recent_disturbance: Recent<Vector<N>, 4>,
    /// The RK4 pieces of the step under way ([`Self::plan`]).
    pieces: Vec<Piece<N>>,
}

impl<const N: usize> Plant<N> {
    /// Starts at rest at `q = start`, `q̇ = 0`. `None` when the model or the start pose does not
    /// have `N` links.
    pub fn new(params: PlantParams) -> Option<Self> {
        let model = params.model.build::<N>()?;
        let q = pose::<N>(&params.start)?;
        let noise_rng = stream(params.run_seed, params.agent_id, Purpose::SensorNoise);
        let normal = |std: f64| (std > 0.0).then(|| Normal::new(0.0, std).ok()).flatten();
        Some(Self {
            noise_q: normal(params.noise.position_std_rad),
            noise_qd: normal(params.noise.velocity_std_rad_s),
            params,
            model,
            q,
            qd: Vector::<N>::zeros(),
            commands: DelayLine::new(),
            noise_rng,
            deadline_misses: 0,
            refused_commands: 0,
            missing_commands: 0,
            recent_tau: Recent::default(),
            recent_disturbance: Recent::default(),
            pieces: Vec::new(),
        })
    }
}

impl<const N: usize> Plant<N> {
    pub fn agent_id(&self) -> u32 {
        self.params.agent_id
    }

    /// Whether its model computes several states side by side
    /// ([`EulerLagrange::side_by_side`]): [`Self::advance_side_by_side`] then gains.
    pub fn side_by_side(&self) -> bool {
        self.model.side_by_side()
    }

    /// The sensor: `y = q + θ1`, `ẏ = q̇ + θ2`. Draws θ1 for every link, then θ2.
    pub fn measure(&mut self) -> Measurement<N> {
        let mut m = Measurement {
            y: self.q,
            yd: self.qd,
        };
        if let Some(n) = self.noise_q {
            for i in 0..N {
                m.y[i] += n.sample(&mut self.noise_rng);
            }
        }
        if let Some(n) = self.noise_qd {
            for i in 0..N {
                m.yd[i] += n.sample(&mut self.noise_rng);
            }
        }
        m
    }

    /// A torque command sent at `stamp` arrived.
    pub fn receive(&mut self, stamp: f64, u: Vector<N>) -> Result<(), PushError> {
        let r = self.commands.push(stamp, u);
        if r.is_err() {
            self.refused_commands += 1;
        }
        r
    }

    /// The command of the tick stamped `t_send`, as it reached the agent: `Some((u, held_s))`
    /// takes effect `held_s` later than the channel's known delay; `None` (dropped, forged,
    /// replayed) never came. A missing or refused command is counted and leaves the one before
    /// in force; a step that needed it counts a deadline miss. The one rule both engines use.
    pub fn take_command(
        &mut self,
        t_send: f64,
        command: Option<(Vector<N>, f64)>,
    ) -> Result<(), PushError> {
        let result = match command {
            Some((u, held_s)) => self.receive(t_send + held_s, u),
            None => Ok(()),
        };
        if command.is_none() || result.is_err() {
            self.missing_commands += 1;
            self.commands.push_missing(t_send);
        }
        result
    }

    /// Stamp of the newest command received.
    pub fn newest_command_stamp(&self) -> Option<f64> {
        self.commands.newest_stamp()
    }

    fn disturbance(&mut self, t: f64) -> Vector<N> {
        let config = &self.params.disturbance;
        self.recent_disturbance.get_or(t, |t| {
            let mut d = Vector::<N>::zeros();
            config.value_into(t, d.as_mut_slice());
            d
        })
    }

    /// The delay line's query for time `t`: `t − τ(t)`. Every use (the integration, the
    /// lookahead bound, the pruning of the history) computes it here, so they agree to the bit.
    fn query(&self, t: f64) -> f64 {
        t - self.params.delay.tau(t)
    }

    /// `τ(t)` as the steps evaluate it (remembered, [`Recent`]).
    fn tau(&mut self, t: f64) -> f64 {
        let delay = &self.params.delay;
        self.recent_tau.get_or(t, |t| delay.tau(t))
    }

    /// [`Self::query`] for the step under way (its `τ` remembered).
    fn step_query(&mut self, t: f64) -> f64 {
        t - self.tau(t)
    }

    /// The sub-step boundaries of step `k`: `t_k + s·h` for `s = 0 ..= substeps`.
    fn boundaries(&self, k: u64) -> impl Iterator<Item = f64> + use<N> {
        let t_k = tick_time(k, self.params.control_period_s);
        let m = self.params.substeps.max(1);
        let h = self.params.control_period_s / f64::from(m);
        (0..=m).map(move |s| t_k + f64::from(s) * h)
    }

    /// The latest instant `t − τ(t)` that [`Self::advance`]`(k)` will look a command up for,
    /// computed with the same operations as the integration. A step can run as soon as the
    /// command in force at that instant is known: lookahead without changing a single bit.
    pub fn latest_query(&self, k: u64) -> f64 {
        self.boundaries(k)
            .map(|t| self.query(t))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// Whether step `k` can run although the command stamped `missing` (and every later one)
    /// has not arrived: it is not in force at any query of the step, by the delay line's own
    /// rule ([`in_force_at`]). The step then looks up exactly what it looks up in strict
    /// lockstep.
    pub fn can_advance_without(&self, k: u64, missing: f64) -> bool {
        !in_force_at(missing, self.latest_query(k))
    }

    /// The earliest instant that [`Self::advance`]`(k)` will look a command up for.
    pub fn earliest_query(&self, k: u64) -> f64 {
        self.boundaries(k)
            .map(|t| self.query(t))
            .fold(f64::INFINITY, f64::min)
    }

    /// [`Self::earliest_query`] as the step under way computes it (`τ` remembered).
    fn earliest_step_query(&mut self, k: u64) -> f64 {
        let mut earliest = f64::INFINITY;
        for t in self.boundaries(k) {
            earliest = earliest.min(self.step_query(t));
        }
        earliest
    }

    /// The RK4 step of `piece` from the plant's state, its disturbances evaluated.
    fn start(&mut self, piece: &Piece<N>) -> Rk4<N> {
        let (t, len) = (piece.from, piece.len);
        // The disturbance at the midpoint serves the two midpoint stages (one evaluation).
        let mid = self.disturbance(t + len / 2.0);
        let (start, end) = (self.disturbance(t), self.disturbance(t + len));
        self.start_seeing(piece, [start, mid, mid, end])
    }

    /// The RK4 step of `piece` from the plant's state, its stages seeing the disturbances `d`.
    fn start_seeing(&self, piece: &Piece<N>, d: [Vector<N>; 4]) -> Rk4<N> {
        Rk4 {
            len: piece.len,
            u: piece.u,
            d,
            q: self.q,
            qd: [self.qd; 4],
            a: [Vector::<N>::zeros(); 4],
        }
    }

    /// One classic RK4 step of `piece`: the plant's state moves to its end; the acceleration
    /// at its start.
    fn rk4(&mut self, piece: &Piece<N>) -> Vector<N> {
        let mut rk = self.start(piece);
        for s in 0..4 {
            let (q, qd) = rk.stage(s);
            rk.a[s] = self.model.acceleration(&q, &qd, &rk.u, &rk.d[s]);
        }
        (self.q, self.qd) = rk.end();
        rk.a[0]
    }

    /// Step `k`'s pieces in `self.pieces`, `[t_k, t_k + Δ]` with `t_k =` [`tick_time`]`(k)`,
    /// sub-step by sub-step. The delayed input `u(t − τ(t))` is piecewise constant: each
    /// sub-step is split at the instants where a newer command takes over (its stamp reached
    /// by `t − τ(t)`), and each piece is one RK4 step with its own held command. No RK stage
    /// straddles a switch, so the result depends continuously on τ: a delay of exactly `m·Δ`
    /// and one a hair longer integrate the same input over all but a hair of the step. True
    /// when some piece needed a command that had not arrived.
    fn plan(&mut self, k: u64) -> bool {
        self.plan_sharing(k, &mut Takeovers::default())
    }

    /// [`Self::plan`], the instants where a newer command takes over looked up in `takeovers`
    /// first and kept there: plants whose delay is one to the bit find there the instants the
    /// others computed (the same bits: the same function of the same arguments).
    fn plan_sharing(&mut self, k: u64, takeovers: &mut Takeovers) -> bool {
        let period = self.params.control_period_s;
        let t_k = tick_time(k, period);
        let m = self.params.substeps.max(1);
        let h = period / f64::from(m);
        let mut missed = false;
        self.pieces.clear();
        for s in 0..m {
            let (a, b) = (t_k + f64::from(s) * h, t_k + f64::from(s + 1) * h);
            let (qa, qb) = (self.step_query(a), self.step_query(b));
            let start = self.commands.lookup(qa, period);
            missed |= start.missed || self.commands.lookup(qb, period).missed;
            let (mut from, mut from_query, mut u) = (a, qa, start.value);
            loop {
                let next = self.commands.next_switch(from_query, qb);
                let to = next.map_or(b, |(stamp, _)| {
                    let delay = &self.params.delay;
                    takeovers.get_or([stamp, a, b], |_| {
                        delay.takeover_time(stamp, (a, qa), (b, qb))
                    })
                });
                if to > from {
                    self.pieces.push(Piece {
                        from,
                        len: to - from,
                        u,
                    });
                }
                let Some((stamp, value)) = next else { break };
                (from, from_query, u) = (to.max(from), stamp, value);
            }
        }
        missed
    }

    /// The end of step `k` once its pieces ran: the miss counted, the delay line pruned, the
    /// report (`first`: the first piece's command and acceleration).
    fn finish(
        &mut self,
        k: u64,
        missed: bool,
        first: Option<(Vector<N>, Vector<N>)>,
    ) -> StepReport<N> {
        if missed {
            self.deadline_misses += 1;
        }
        // Prune at the very instant the next step's first query computes.
        let next = self.earliest_step_query(k + 1);
        self.commands.prune_before(next);
        let (u_applied, qdd) = first.unwrap_or((Vector::<N>::zeros(), Vector::<N>::zeros()));
        StepReport {
            u_applied,
            qdd,
            tau: self.tau(tick_time(k, self.params.control_period_s)),
            missed,
        }
    }

    /// Integrates step `k` ([`Self::plan`] says how it is cut into RK4 pieces).
    pub fn advance(&mut self, k: u64) -> StepReport<N> {
        let missed = self.plan(k);
        let mut first = None;
        for i in 0..self.pieces.len() {
            let piece = self.pieces[i];
            let a1 = self.rk4(&piece);
            first.get_or_insert((piece.u, a1));
        }
        self.finish(k, missed, first)
    }

    /// [`Self::advance`] of several plants of one model (the caller's word, which the engine
    /// gives from their equal model configurations: the first plant's model serves them all;
    /// hence not public), side by side: [`LANES`] at a time (fewer than
    /// [`SIDE_BY_SIDE_MIN`] left over, each alone), their RK4 pieces run
    /// together, the model asked for their forward dynamics at once
    /// ([`EulerLagrange::accelerations`]). Each plant ends where its own [`Self::advance`]
    /// would, to the bit, and its report is the same.
    pub(crate) fn advance_side_by_side(plants: &mut [&mut Plant<N>], k: u64) -> Vec<StepReport<N>> {
        let mut reports = Vec::with_capacity(plants.len());
        for lanes in plants.chunks_mut(LANES) {
            if lanes.len() < SIDE_BY_SIDE_MIN {
                reports.extend(lanes.iter_mut().map(|p| p.advance(k)));
            } else {
                Self::advance_lanes(lanes, k, &mut reports);
            }
        }
        reports
    }

    /// [`Self::advance_side_by_side`] of at most [`LANES`] plants, their reports pushed.
    fn advance_lanes(plants: &mut [&mut Plant<N>], k: u64, reports: &mut Vec<StepReport<N>>) {
        let mut missed = [false; LANES];
        // `t − τ(t)` and so the instants where commands take over are the delay's: the plants
        // whose delay is the first plant's, to the bit, share them.
        let (delay, mut takeovers) = (plants[0].params.delay, Takeovers::default());
        for (plant, missed) in plants.iter_mut().zip(&mut missed) {
            *missed = if plant.params.delay.same_bits(&delay) {
                plant.plan_sharing(k, &mut takeovers)
            } else {
                plant.plan(k)
            };
        }
        let mut first = [None; LANES];
        // The plants whose disturbance is the first plant's, to the bit: a piece over the same
        // instants sees the same `d(t)`, evaluated once for them all.
        let shares: [bool; LANES] = std::array::from_fn(|l| {
            (plants.get(l)).is_some_and(|p| {
                p.params
                    .disturbance
                    .same_bits(&plants[0].params.disturbance)
            })
        });
        let pieces = plants.iter().map(|p| p.pieces.len()).max().unwrap_or(0);
        for i in 0..pieces {
            // The plants with an `i`-th piece; a lane without one repeats the first such
            // plant's step (its result unused).
            let running: [bool; LANES] =
                std::array::from_fn(|l| plants.get(l).is_some_and(|p| p.pieces.len() > i));
            let Some(lead) = running.iter().position(|r| *r) else {
                continue;
            };
            let mut shared: Option<(Piece<N>, [Vector<N>; 4])> = None;
            let mut rk: [Rk4<N>; LANES] = std::array::from_fn(|l| {
                let l = if running[l] { l } else { lead };
                let plant = &mut plants[l];
                let piece = plant.pieces[i];
                match shared {
                    Some((seen, d)) if shares[l] && seen.spans_the_instants_of(&piece) => {
                        plant.start_seeing(&piece, d)
                    }
                    _ => {
                        let rk = plant.start(&piece);
                        if shares[l] {
                            shared.get_or_insert((piece, rk.d));
                        }
                        rk
                    }
                }
            });
            for s in 0..4 {
                let stage: [(Vector<N>, Vector<N>); LANES] =
                    std::array::from_fn(|l| rk[l].stage(s));
                let states: [Forward<'_, N>; LANES] =
                    std::array::from_fn(|l| (&stage[l].0, &stage[l].1, &rk[l].u, &rk[l].d[s]));
                let a = plants[lead].model.accelerations(&states);
                for (r, a) in rk.iter_mut().zip(a) {
                    r.a[s] = a;
                }
            }
            for (l, plant) in plants.iter_mut().enumerate().filter(|(l, _)| running[*l]) {
                (plant.q, plant.qd) = rk[l].end();
                first[l].get_or_insert((rk[l].u, rk[l].a[0]));
            }
        }
        for (l, plant) in plants.iter_mut().enumerate() {
            reports.push(plant.finish(k, missed[l], first[l]));
        }
    }
}

/// One RK4 piece of a step: from `from`, `len` long, the command `u` held over it.
#[derive(Debug, Clone, Copy)]
struct Piece<const N: usize> {
    from: f64,
    len: f64,
    u: Vector<N>,
}

/// The instants computed by [`crate::delay::DelayProfile::takeover_time`] for one delay, by
/// their `[stamp, a, b]` (the plan of a step asks a few).
type Takeovers = Recent<f64, 8, [f64; 3]>;

impl<const N: usize> Piece<N> {
    /// Whether `other` starts and ends at the very instants of this piece (bit for bit: the
    /// disturbance at its start, midpoint and end then is this one's).
    fn spans_the_instants_of(&self, other: &Self) -> bool {
        crate::memo::same_bits([self.from, self.len], [other.from, other.len])
    }
}

/// A classic RK4 step under way from `(q, q̇)`: the disturbance each stage sees (the
/// midpoint's twice), each stage's velocity and, once asked of the model, acceleration.
struct Rk4<const N: usize> {
    len: f64,
    u: Vector<N>,
    d: [Vector<N>; 4],
    q: Vector<N>,
    qd: [Vector<N>; 4],
    a: [Vector<N>; 4],
}

impl<const N: usize> Rk4<N> {
    /// The state at which stage `s` (0–3) asks for the acceleration, from the stages before
    /// it; its velocity is kept for the end.
    fn stage(&mut self, s: usize) -> (Vector<N>, Vector<N>) {
        let (q, qd, len) = (self.q, self.qd[0], self.len);
        let (q_s, qd_s) = match s {
            0 => (q, qd),
            1 => (q + qd * (len / 2.0), qd + self.a[0] * (len / 2.0)),
            2 => (q + self.qd[1] * (len / 2.0), qd + self.a[1] * (len / 2.0)),
            _ => (q + self.qd[2] * len, qd + self.a[2] * len),
        };
        self.qd[s] = qd_s;
        (q_s, qd_s)
    }

    /// The state at the end of the step.
    fn end(&self) -> (Vector<N>, Vector<N>) {
        let (q, qd, a, len) = (self.q, &self.qd, &self.a, self.len);
        (
            q + (qd[0] + qd[1] * 2.0 + qd[2] * 2.0 + qd[3]) * (len / 6.0),
            qd[0] + (a[0] + a[1] * 2.0 + a[2] * 2.0 + a[3]) * (len / 6.0),
        )
    }
}
// `[noise]` and `[disturbance]` of a scenario: read by the plant only.

/// Gaussian sensor noise θ (docs/model.md, "Plant").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseConfig {
    /// Standard deviation of θ1, rad; typical 1e-4.
    pub position_std_rad: f64,
    /// Standard deviation of θ2, rad/s; typical 1e-4.
    pub velocity_std_rad_s: f64,
}

/// One link's additive disturbance `amplitude · sin(omega t)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceLink {
    /// Amplitude: N·m under `units = "rad"`; under `units = "deg"` it is multiplied by π/180
    /// (the paper's reading).
    pub amplitude: f64,
    /// Angular frequency, rad/s.
    pub omega_rad_s: f64,
}

/// Exogenous disturbance `d(t)` of (1), N·m.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceConfig {
    /// `deg` multiplies the amplitudes by π/180, the paper's reading ("0.2 sin(0.1t) deg");
    /// `rad` takes them as N·m.
    pub units: AngleUnit,
    /// One entry per link.
    pub links: Vec<DisturbanceLink>,
}

impl DisturbanceConfig {
    /// Whether `other` is this disturbance to the bit (then `d(t)` has the same bits at every
    /// `t`; `==` takes −0 for 0).
    pub fn same_bits(&self, other: &Self) -> bool {
        fn numbers(d: &DisturbanceConfig) -> impl Iterator<Item = f64> + '_ {
            (d.links.iter()).flat_map(|l| [l.amplitude, l.omega_rad_s])
        }
        self.units == other.units && crate::memo::same_bits(numbers(self), numbers(other))
    }

    /// `d(t)` into `out`, N·m.
    pub fn value_into(&self, t: f64, out: &mut [f64]) {
        let scale = self.units.to_rad();
        for (o, l) in out.iter_mut().zip(&self.links) {
            *o = scale * l.amplitude * (l.omega_rad_s * t).sin();
        }
    }
}

#[cfg(test)]
mod tests;
