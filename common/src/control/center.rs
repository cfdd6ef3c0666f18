//! The control center's per-agent pipeline for one tick (docs/model.md, "Control center", steps 1–10).

use crate::delay::{DelayLine, DelayProfile};
use crate::model::{EulerLagrange, Matrix, ModelConfig, Vector};
use crate::rng::{stream, Purpose};
use crate::trajectory::{Reference, TrajectoryConfig};

use super::config::{
    ControllerConfig, ControllerMode, GainScaling, ObserverInput as ObserverInputMode,
};
use super::detection::Detector;
use super::estimator::{NnEstimator, NnParams};
use super::observer::{Observer, ObserverInput};

/// Largest measurement magnitude accepted (rad, rad/s); larger values are treated like
/// non-finite ones: rejected, counted, last good value held.
pub const MAX_ABS_MEASUREMENT: f64 = 1e6;

/// Everything that configures one agent's pipeline ([`crate::scenario::Scenario::center_params`]
/// takes it from a scenario).
#[derive(Debug, Clone)]
pub struct CenterParams {
    pub agent_id: u32,
    pub run_seed: u64,
    pub control_period_s: f64,
    pub controller: ControllerConfig,
    pub model: ModelConfig,
    pub trajectory: TrajectoryConfig,
    pub delay: DelayProfile,
}

/// What one tick produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CenterOutput<const N: usize> {
    /// Torque `u_k` to send, stamped `t_k`; always finite.
    pub u: Vector<N>,
    /// Attack estimate `Ŝ` used in this tick (zero in traditional mode).
    pub s_hat: Vector<N>,
    /// Observer estimate after this tick's step.
    pub q_hat: Vector<N>,
    pub qd_hat: Vector<N>,
    pub qdd_hat: Vector<N>,
    /// `e_u` used in this tick, and `u_τ`: the delayed input averaged over the observer's
    /// step `[t_k, t_k + Δ]` (or its sample at `t_k − τ(t_k)`, per `observer_input`).
    pub e_u: Vector<N>,
    pub u_tau: Vector<N>,
    pub alarm: bool,
    /// The measurement was rejected (non-finite or absurd) and the last good one used.
    pub rejected_input: bool,
    /// The computed torque was non-finite and the last good one was sent instead.
    pub rejected_torque: bool,
    /// The observer or estimator state became non-finite in this tick and was reset
    /// ([`CenterAgent`]'s recovery policy).
    pub state_reset: bool,
    /// The history of sent torques did not reach back to `t − τ(t)`: `e_u` and `u_τ` of the
    /// previous tick were held (a counted miss; cannot happen with `|τ̇| < 1`).
    pub history_miss: bool,
    /// The tick had no measurement ([`CenterAgent::tick_missing`]): the last good one was used.
    pub missing_input: bool,
}

/// Per-agent state of the control center.
#[derive(Debug)]
pub struct CenterAgent<const N: usize> {
    /// The diagonal of `K` in `u = K r̂`.
    gains: Vector<N>,
    params: CenterParams,
    model: Box<dyn EulerLagrange<N>>,
    sent: DelayLine<N>,
    observer: Observer<N>,
    estimator: NnEstimator<N>,
    detector: Detector,
    psi2_prev: Vector<N>,
    last_good: (Vector<N>, Vector<N>),
    last_u: Vector<N>,
    /// `(e_u, u_τ)` of the last tick whose history lookup succeeded.
    last_history: (Vector<N>, Vector<N>),
    /// Number of measurements rejected so far.
    pub rejected_inputs: u64,
    /// Number of torques replaced because they were non-finite.
    pub rejected_torques: u64,
    /// Number of resets of non-finite observer or estimator state.
    pub state_resets: u64,
    /// Number of ticks whose `e_u`, `u_τ` were held because the history was pruned too far.
    pub history_misses: u64,
    /// Number of ticks without a measurement ([`CenterAgent::tick_missing`]).
    pub missing_inputs: u64,
}

impl<const N: usize> CenterAgent<N> {
    /// The observer starts at the trajectory's start pose. `None` when the model or the start
    /// pose has another number of links than `N`.
    pub fn new(params: CenterParams) -> Option<Self> {
        let model = params.model.build::<N>()?;
        let c = &params.controller;
        let mut rng = stream(params.run_seed, params.agent_id, Purpose::NnInit);
        let estimator = NnEstimator::new(NnParams::from_controller(c), c.initial_v_range, &mut rng);
        let detector = Detector::new(c.detection.threshold, c.detection.hold_s);
        let gains = match c.gain_scaling {
            GainScaling::Unit => Vector::<N>::from_element(c.gain_k),
            GainScaling::Inertia => {
                let q0 = params.trajectory.reference::<N>(0.0).q;
                model.inertia(&q0).diagonal() * c.gain_k
            }
        };
        let observer = Observer::at(params.trajectory.start_position::<N>()?, Vector::zeros());
        Some(Self {
            gains,
            params,
            model,
            sent: DelayLine::new(),
            observer,
            estimator,
            detector,
            psi2_prev: Vector::<N>::zeros(),
            last_good: (Vector::<N>::zeros(), Vector::<N>::zeros()),
            last_u: Vector::<N>::zeros(),
            last_history: (Vector::<N>::zeros(), Vector::<N>::zeros()),
            rejected_inputs: 0,
            rejected_torques: 0,
            state_resets: 0,
            history_misses: 0,
            missing_inputs: 0,
        })
    }
}

impl<const N: usize> CenterAgent<N> {
    /// The observer's state (tests).
    #[cfg(test)]
    pub(crate) fn observer(&self) -> &Observer<N> {
        &self.observer
    }

    pub fn agent_id(&self) -> u32 {
        self.params.agent_id
    }

    /// Desired trajectory at `t`.
    pub fn reference(&self, t: f64) -> Reference<N> {
        self.params.trajectory.reference(t)
    }

    /// One control tick at `t` from the (possibly tampered) measurement `(y, ẏ)`.
    pub fn tick(&mut self, t: f64, y: &Vector<N>, yd: &Vector<N>) -> CenterOutput<N> {
        self.tick_with_estimate(t, y, yd, None)
    }

    /// [`Self::tick`] with `Ŝ` replaced by `s_override` when given (an oracle for tests and
    /// ablations: the weights are then not updated).
    pub fn tick_with_estimate(
        &mut self,
        t: f64,
        y: &Vector<N>,
        yd: &Vector<N>,
        s_override: Option<&Vector<N>>,
    ) -> CenterOutput<N> {
        self.tick_on(t, Some((y, yd)), s_override)
    }

    /// The tick at `t` when its measurement is missing (dropped, forged, replayed, not yet
    /// delivered): the documented rule is to hold the last good measurement, as for a rejected
    /// one, and count the tick.
    pub fn tick_missing(&mut self, t: f64) -> CenterOutput<N> {
        self.missing_inputs += 1;
        self.tick_on(t, None, None)
    }

    /// One tick from the measurement `input` (`None`: missing).
    fn tick_on(
        &mut self,
        t: f64,
        input: Option<(&Vector<N>, &Vector<N>)>,
        s_override: Option<&Vector<N>>,
    ) -> CenterOutput<N> {
        let rejected_input = input.is_some_and(|(y, yd)| self.accept_measurement(y, yd));
        let x = self.tick_inputs(t, s_override);
        let (u, rejected_torque) = self.torque(&x);

        // History of sent torques: u_k is in force from t_k on (the observer's input below
        // may reach it when τ < Δ).
        if self.sent.push(t, u).is_ok() {
            self.last_u = u;
        }

        let u_tau = self.delayed_input_over_step(&x);
        self.note_history(&x, u_tau);
        let psi2 = self.observe(&x, &u_tau);
        self.learn(&psi2, s_override);
        let state_reset = self.recover_non_finite_state(&psi2, &x);

        // Drop what no future query reaches: the next tick's query `t' − τ(t')` is later than
        // this one's (`|τ̇| < 1`), and the line keeps one entry of margin besides.
        self.sent.prune_before(x.query);

        // 9: detection.
        let alarm = self.detector.update(t, x.s_hat.norm());

        CenterOutput {
            u,
            s_hat: x.s_hat,
            q_hat: self.observer.q,
            qd_hat: self.observer.qd,
            qdd_hat: self.observer.qdd,
            e_u: x.e_u,
            u_tau,
            alarm,
            rejected_input,
            rejected_torque,
            state_reset,
            history_miss: x.history_miss,
            missing_input: input.is_none(),
        }
    }

    /// Keeps a sane measurement `(y, ẏ)` as the last good one; a non-finite or absurd one is
    /// rejected and counted, and the last good one stays in use. Whether it was rejected.
    fn accept_measurement(&mut self, y: &Vector<N>, yd: &Vector<N>) -> bool {
        let sane = |v: &Vector<N>| {
            v.iter()
                .all(|x| x.is_finite() && x.abs() <= MAX_ABS_MEASUREMENT)
        };
        let rejected_input = !(sane(y) && sane(yd));
        if rejected_input {
            self.rejected_inputs += 1;
        } else {
            self.last_good = (*y, *yd);
        }
        rejected_input
    }

    /// Steps 1–4 at `t` with the measurement in use: the reference, `A`, `e_u` and `Ŝ`.
    fn tick_inputs(&mut self, t: f64, s_override: Option<&Vector<N>>) -> TickInputs<N> {
        let (y, yd) = self.last_good;

        // 1–3: reference, A = M(q_d)⁻¹, e_u over the zero-order-held history of sent u.
        let reference = self.params.trajectory.reference::<N>(t);
        let a: Matrix<N> = self.model.inverse_inertia(&reference.q);
        let query = t - self.params.delay.tau(t);
        let (e_u, history_miss) = match self.sent.integral(query, t) {
            Ok(e_u) => (e_u, false),
            Err(_) => (self.last_history.0, true),
        };

        // 4: NN estimate from the previous tick's Ψ2 (no algebraic loop).
        let s_hat = match (s_override, self.params.controller.mode) {
            (Some(s), _) => *s,
            (None, ControllerMode::Proposed) => self.estimator.estimate(&self.psi2_prev),
            (None, ControllerMode::Traditional) => Vector::<N>::zeros(),
        };

        TickInputs {
            t,
            y,
            yd,
            reference,
            a,
            query,
            e_u,
            history_miss,
            s_hat,
        }
    }

    /// 5: r̂ = Ψ̇1 + β Ψ1 − A e_u + Ŝ, u = k r̂. A non-finite u is counted and replaced by the
    /// last one sent. The torque, and whether it was replaced.
    fn torque(&mut self, x: &TickInputs<N>) -> (Vector<N>, bool) {
        let c = self.params.controller;
        let psi1 = x.reference.q - x.y;
        let psi1_dot = x.reference.qd - x.yd;
        let r_hat = psi1_dot + psi1 * c.beta - x.a * x.e_u + x.s_hat;
        let mut u = r_hat.component_mul(&self.gains);
        let rejected_torque = u.iter().any(|x| !x.is_finite());
        if rejected_torque {
            self.rejected_torques += 1;
            u = self.last_u;
        }
        (u, rejected_torque)
    }

    /// The observer's input `u_τ` for its step over [t_k, t_k + Δ] (step 6); the last good one
    /// when the history does not reach back far enough.
    fn delayed_input_over_step(&self, x: &TickInputs<N>) -> Vector<N> {
        let t = x.t;
        let dt = self.params.control_period_s;
        let query = x.query;

        // 6: observer step over [t_k, t_k + Δ]. Its input u_τ is the mean of the delayed input
        // u(s − τ(s)) over the step: `∫ u` between the queries at both ends, over their span.
        // Sampling u at the single instant t − τ(t) instead would pick the older or the newer
        // command when that instant falls on a stamp (τ a multiple of Δ), a whole period of
        // effective delay that a hair of τ more or less would flip.
        // With `observer_input = "sample"` (the default: docs/model.md, "Numerics of the delayed input"), u_τ is the command in force
        // at `t − τ(t)`, held over the step.
        let query_next = (t + dt) - self.params.delay.tau(t + dt);
        match self.params.controller.observer_input {
            ObserverInputMode::StepMean => match self.sent.integral(query, query_next) {
                Ok(sum) if !x.history_miss && query_next > query => sum / (query_next - query),
                _ => self.last_history.1,
            },
            ObserverInputMode::Sample => match self.sent.value_at(query) {
                l if !x.history_miss && !l.pruned => l.value,
                _ => self.last_history.1,
            },
        }
    }

    /// Keeps this tick's `(e_u, u_τ)` as the last good history, or counts the miss.
    fn note_history(&mut self, x: &TickInputs<N>, u_tau: Vector<N>) {
        if !x.history_miss {
            self.last_history = (x.e_u, u_tau);
        } else {
            self.history_misses += 1;
        }
    }

    /// 6: the observer's step over [t_k, t_k + Δ] with the delayed input `u_tau`; its Ψ2.
    fn observe(&mut self, x: &TickInputs<N>, u_tau: &Vector<N>) -> Vector<N> {
        let c = self.params.controller;
        let input = ObserverInput {
            y: &x.y,
            yd: &x.yd,
            s_hat: &x.s_hat,
            reference: &x.reference,
            a: &x.a,
            e_u: &x.e_u,
            u_tau,
            beta: c.beta,
            l1: c.observer_gain_l1,
            l2: c.observer_gain_l2,
        };
        self.observer
            .step(self.model.as_ref(), &input, self.params.control_period_s)
    }

    /// 7: weights (proposed mode, unless `Ŝ` is overridden); `psi2` is the next tick's NN input.
    fn learn(&mut self, psi2: &Vector<N>, s_override: Option<&Vector<N>>) {
        if self.params.controller.mode == ControllerMode::Proposed && s_override.is_none() {
            self.estimator.update(psi2, self.params.control_period_s);
        }
        self.psi2_prev = *psi2;
    }

    /// 10: non-finite observer or estimator state never sticks. Recovery policy: the
    /// estimator restarts from its initial weights (Ŵ = 0, V̂ = V̂(0)), the observer from the
    /// measurement in use (q̂ = y, q̂̇ = ẏ), and the next NN input from Ψ2 = 0. Whether it
    /// reset.
    fn recover_non_finite_state(&mut self, psi2: &Vector<N>, x: &TickInputs<N>) -> bool {
        let state_reset = !(self.observer.is_finite()
            && self.estimator.is_finite()
            && psi2.iter().all(|x| x.is_finite()));
        if state_reset {
            self.state_resets += 1;
            self.estimator.reset();
            self.observer = Observer::at(x.y, x.yd);
            self.psi2_prev = Vector::<N>::zeros();
        }
        state_reset
    }
}

crate::per_joint_count!(
    /// A [`CenterAgent`] of any number of links: the control center of a team that mixes
    /// robots holds one per robot.
    #[derive(Debug)]
    pub enum AnyCenterAgent = CenterAgent
);

impl AnyCenterAgent {
    /// [`CenterAgent::new`] with the number of links of `params`' model.
    pub fn new(params: CenterParams) -> Option<Self> {
        let dof = params.model.dof();
        crate::with_joint_count!(dof, N => CenterAgent::<N>::new(params).map(Self::from)).flatten()
    }

    pub fn agent_id(&self) -> u32 {
        crate::on_joint_count!(AnyCenterAgent, self, c => c.agent_id())
    }

    /// [`CenterAgent::rejected_inputs`].
    pub fn rejected_inputs(&self) -> u64 {
        crate::on_joint_count!(AnyCenterAgent, self, c => c.rejected_inputs)
    }

    /// [`CenterAgent::missing_inputs`].
    pub fn missing_inputs(&self) -> u64 {
        crate::on_joint_count!(AnyCenterAgent, self, c => c.missing_inputs)
    }
}

/// What steps 1–4 of a tick work out, for the steps after them.
struct TickInputs<const N: usize> {
    t: f64,
    /// The measurement in use: this tick's, or the last good one if this tick's was rejected.
    y: Vector<N>,
    yd: Vector<N>,
    reference: Reference<N>,
    /// `A = M(q_d)⁻¹`.
    a: Matrix<N>,
    /// `t − τ(t)`: where `e_u`'s integral starts.
    query: f64,
    e_u: Vector<N>,
    /// The history did not reach back to `query`: `e_u` is the last good one.
    history_miss: bool,
    s_hat: Vector<N>,
}

#[cfg(test)]
mod tests;
