//! The agent's side: the true robot, its sensor, and the delayed torque channel's receiving end
//! (SPEC §2, §5). Integration: classic RK4 over each control period (optionally sub-stepped),
//! the delayed input `u(t − τ(t))` evaluated at every RK stage time through the delay line.

use rand_chacha::ChaCha12Rng;
use rand_distr::{Distribution, Normal};

use crate::delay::{DelayLine, DelayProfile, PushError};
use crate::model::{EulerLagrange, Vector};
use crate::rng::{stream, Purpose};
use crate::scenario::{AgentConfig, BuildModel, DisturbanceConfig, ModelConfig, NoiseConfig};

/// Everything that configures one agent's plant.
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
}

impl PlantParams {
    pub fn new(agent: &AgentConfig, scenario: &crate::scenario::Scenario) -> Self {
        Self {
            agent_id: agent.id,
            run_seed: scenario.seed,
            control_period_s: scenario.control_period_s,
            substeps: scenario.physics_substeps,
            model: agent.model,
            delay: agent.delay,
            noise: scenario.noise,
            disturbance: scenario.disturbance.clone(),
        }
    }
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
}

impl<const N: usize> Plant<N>
where
    ModelConfig: BuildModel<N>,
{
    /// Starts at rest at `q = q̇ = 0`. `None` when the model does not have `N` links.
    pub fn new(params: PlantParams) -> Option<Self> {
        let model = params.model.build_model()?;
        let noise_rng = stream(params.run_seed, params.agent_id, Purpose::SensorNoise);
        let normal = |std: f64| (std > 0.0).then(|| Normal::new(0.0, std).ok()).flatten();
        Some(Self {
            noise_q: normal(params.noise.position_std_rad),
            noise_qd: normal(params.noise.velocity_std_rad_s),
            params,
            model,
            q: Vector::<N>::zeros(),
            qd: Vector::<N>::zeros(),
            commands: DelayLine::new(),
            noise_rng,
            deadline_misses: 0,
            refused_commands: 0,
        })
    }
}

impl<const N: usize> Plant<N> {
    pub fn agent_id(&self) -> u32 {
        self.params.agent_id
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

    /// Stamp of the newest command received.
    pub fn newest_command_stamp(&self) -> Option<f64> {
        self.commands.newest_stamp()
    }

    fn disturbance(&self, t: f64) -> Vector<N> {
        let mut d = Vector::<N>::zeros();
        self.params.disturbance.value_into(t, d.as_mut_slice());
        d
    }

    /// `(q̈, u applied, missed)` at stage time `t`.
    fn dynamics(&self, t: f64, q: &Vector<N>, qd: &Vector<N>) -> (Vector<N>, Vector<N>, bool) {
        let tau = self.params.delay.tau(t);
        let look = self.commands.lookup(t - tau, self.params.control_period_s);
        let qdd = self
            .model
            .acceleration(q, qd, &look.value, &self.disturbance(t));
        (qdd, look.value, look.missed)
    }

    /// The latest instant `t − τ(t)` that [`Self::advance`]`(t_k)` will look a command up for,
    /// computed with the same operations as the RK stages. A step can run as soon as the
    /// command in force at that instant is known: lookahead without changing a single bit.
    pub fn latest_query(&self, t_k: f64) -> f64 {
        let m = self.params.substeps.max(1);
        let h = self.params.control_period_s / f64::from(m);
        let mut latest = f64::NEG_INFINITY;
        for s in 0..m {
            let t = t_k + f64::from(s) * h;
            for stage in [t, t + h / 2.0, t + h] {
                latest = latest.max(stage - self.params.delay.tau(stage));
            }
        }
        latest
    }

    /// Integrates `[t_k, t_k + Δ]` with RK4 (`substeps` sub-steps).
    pub fn advance(&mut self, t_k: f64) -> StepReport<N> {
        let dt_total = self.params.control_period_s;
        let m = self.params.substeps.max(1);
        let h = dt_total / f64::from(m);
        let mut report = None;
        let mut missed = false;
        for s in 0..m {
            let t = t_k + f64::from(s) * h;
            let (q, qd) = (self.q, self.qd);
            let (a1, u1, m1) = self.dynamics(t, &q, &qd);
            if report.is_none() {
                report = Some((u1, a1));
            }
            let (q2, qd2) = (q + qd * (h / 2.0), qd + a1 * (h / 2.0));
            let (a2, _, m2) = self.dynamics(t + h / 2.0, &q2, &qd2);
            let (q3, qd3) = (q + qd2 * (h / 2.0), qd + a2 * (h / 2.0));
            let (a3, _, m3) = self.dynamics(t + h / 2.0, &q3, &qd3);
            let (q4, qd4) = (q + qd3 * h, qd + a3 * h);
            let (a4, _, m4) = self.dynamics(t + h, &q4, &qd4);
            self.q = q + (qd + qd2 * 2.0 + qd3 * 2.0 + qd4) * (h / 6.0);
            self.qd = qd + (a1 + a2 * 2.0 + a3 * 2.0 + a4) * (h / 6.0);
            missed |= m1 || m2 || m3 || m4;
        }
        if missed {
            self.deadline_misses += 1;
        }
        let t_next = t_k + dt_total;
        self.commands
            .prune_before(t_next - self.params.delay.tau(t_next));
        let (u_applied, qdd) = report.unwrap_or((Vector::<N>::zeros(), Vector::<N>::zeros()));
        StepReport {
            u_applied,
            qdd,
            tau: self.params.delay.tau(t_k),
            missed,
        }
    }
}
