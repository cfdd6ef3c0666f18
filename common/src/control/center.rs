//! The control center's per-agent pipeline for one tick (docs/model.md, "Control center", steps
//! 1–10): what every controller shares around the scenario's [`Controller`] (`[controller]
//! mode`).

use crate::delay::DelayLine;
use crate::memo::Recent;
use crate::model::primed::{Primed, Primes, Wants};
use crate::model::{EulerLagrange, Matrix, Vector};
use crate::trajectory::Reference;

pub use super::config::CenterParams;
use super::config::{ControllerMode, ObserverInput as ObserverInputMode};
use super::controller::{Answer, Controller, Estimate, Tick};
use super::detection::Detector;
use super::list::with_controllers;

/// Declares [`build`] of the list of controllers.
macro_rules! declare_build {
    ($($(#[$doc:meta])* $variant:ident = $name:literal => $module:ident :: $ty:ident :: $make:ident;)*) => {
        /// The controller `mode` of `params` for a robot of `model`; `None` when its state
        /// cannot be made for the robot (a start pose of another number of joints).
        fn build<const N: usize>(
            mode: ControllerMode,
            params: &CenterParams,
            model: &dyn EulerLagrange<N>,
        ) -> Option<Box<dyn Controller<N>>> {
            match mode {
                $(ControllerMode::$variant => {
                    super::$module::$ty::$make(params, model)
                        .map(|c| Box::new(c) as Box<dyn Controller<N>>)
                })*
            }
        }
    };
}
with_controllers!(declare_build);

/// Largest measurement magnitude accepted (rad, rad/s); larger values are treated like
/// non-finite ones: rejected, counted, last good value held.
pub const MAX_ABS_MEASUREMENT: f64 = 1e6;

/// What one tick produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CenterOutput<const N: usize> {
    /// Torque `u_k` to send, stamped `t_k`; always finite.
    pub u: Vector<N>,
    /// Attack estimate `Ŝ` used in this tick (zero for a controller without one).
    pub s_hat: Vector<N>,
    /// The controller's estimate of the state after this tick (its observer's, or the state
    /// it predicted).
    pub q_hat: Vector<N>,
    pub qd_hat: Vector<N>,
    pub qdd_hat: Vector<N>,
    /// `e_u` used in this tick, and `u_τ`: the delayed input averaged over the observer's
    /// step `[t_k, t_k + Δ]` (or its sample at `t_k − τ(t_k)`, per `observer_input`).
    pub e_u: Vector<N>,
    pub u_tau: Vector<N>,
    /// The alarm: on `‖Ŝ‖` (docs/model.md, step 9), or the controller's own (the `gated`
    /// controller's gate).
    pub alarm: bool,
    /// The measurement was rejected (non-finite or absurd) and the last good one used.
    pub rejected_input: bool,
    /// The computed torque was non-finite and the last good one was sent instead.
    pub rejected_torque: bool,
    /// The controller's state (observer, estimator) became non-finite in this tick and was
    /// reset ([`Controller::reset`]).
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
    params: CenterParams,
    model: Box<dyn EulerLagrange<N>>,
    controller: Box<dyn Controller<N>>,
    sent: DelayLine<N>,
    detector: Detector,
    last_good: (Vector<N>, Vector<N>),
    last_u: Vector<N>,
    /// `(e_u, u_τ)` of the last tick whose history lookup succeeded.
    last_history: (Vector<N>, Vector<N>),
    /// Number of measurements rejected so far.
    pub rejected_inputs: u64,
    /// Number of torques replaced because they were non-finite.
    pub rejected_torques: u64,
    /// Number of resets of the controller's non-finite state.
    pub state_resets: u64,
    /// Number of ticks whose `e_u`, `u_τ` were held because the history was pruned too far.
    pub history_misses: u64,
    /// Number of ticks without a measurement ([`CenterAgent::tick_missing`]).
    pub missing_inputs: u64,
    /// The tick asked of a controller program and not answered yet ([`CenterAgent::ask`]).
    asked: Option<OpenTick<N>>,
    /// A correction added to every torque the controller commands, until changed
    /// ([`CenterAgent::set_correction`]: a learned defence's action).
    correction: Option<Vector<N>>,
    /// Answers of the model computed ahead for the next tick ([`Self::prime`]).
    primes: Option<Primes<N>>,
    /// The last reference computed ([`Self::wants`] and the tick ask for the same instant).
    recent_reference: Recent<Reference<N>, 1>,
}

impl<const N: usize> CenterAgent<N> {
    /// The scenario's controller for this robot (an observer starts at the trajectory's start
    /// pose). `None` when the model or the start pose has another number of links than `N`.
    pub fn new(params: CenterParams) -> Option<Self> {
        let model = params.model.build::<N>()?;
        let controller = build::<N>(params.controller.mode, &params, model.as_ref())?;
        let c = &params.controller;
        let detector = Detector::new(c.detection.threshold, c.detection.hold_s);
        Some(Self {
            params,
            model,
            controller,
            sent: DelayLine::new(),
            detector,
            last_good: (Vector::<N>::zeros(), Vector::<N>::zeros()),
            last_u: Vector::<N>::zeros(),
            last_history: (Vector::<N>::zeros(), Vector::<N>::zeros()),
            rejected_inputs: 0,
            rejected_torques: 0,
            state_resets: 0,
            history_misses: 0,
            missing_inputs: 0,
            asked: None,
            correction: None,
            primes: None,
            recent_reference: Recent::default(),
        })
    }
}

impl<const N: usize> CenterAgent<N> {
    pub fn agent_id(&self) -> u32 {
        self.params.agent_id
    }

    /// Adds `correction` (N·m per joint) to every torque the controller commands from the next
    /// tick on, before the torque is checked and sent (`None`: none, the controller's torque
    /// as it is). A learned defence acting at the control center (`fdi_mas/Defender-v0`).
    pub fn set_correction(&mut self, correction: Option<Vector<N>>) {
        self.correction = correction;
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
    /// ablations: a controller that estimates the attack then does not learn).
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
        self.tick_on(t, None, None)
    }

    /// What its controller will ask the model in the tick at `t` ([`Controller::wants`]).
    pub fn wants(&mut self, t: f64) -> Wants<N> {
        let reference = self.reference_at(t);
        self.controller.wants(&reference)
    }

    /// The reference at `t` as the tick computes it (remembered, [`Recent`]: the same bits).
    fn reference_at(&mut self, t: f64) -> Reference<N> {
        let trajectory = &self.params.trajectory;
        (self.recent_reference).get_or(t, |t| trajectory.reference::<N>(t))
    }

    /// Its robot's model.
    pub fn model(&self) -> &dyn EulerLagrange<N> {
        self.model.as_ref()
    }

    /// Answers of the model computed ahead for its next tick (of [`Self::wants`]): the tick
    /// uses each for its very arguments only ([`Primed`]).
    pub fn prime(&mut self, primes: Primes<N>) {
        self.primes = Some(primes);
    }

    /// A tick whose torque a controller program decides (`[roles.controller]`), first half:
    /// takes the measurement of the tick at `t` (`None`: missing) and returns what the program
    /// is shown. The tick stays open until [`Self::answer`]; asking again first drops it.
    pub fn ask(&mut self, t: f64, input: Option<(&Vector<N>, &Vector<N>)>) -> Question<N> {
        let open = self.open_tick(t, input);
        let x = &open.x;
        let m = self.model.as_ref();
        let question = Question {
            t,
            tau: self.params.delay.tau(t),
            y: x.y,
            yd: x.yd,
            reference: x.reference,
            e_u: x.e_u,
            inertia_ref: m.inertia(&x.reference.q),
            inverse_inertia_ref: m.inverse_inertia(&x.reference.q),
            inertia: m.inertia(&x.y),
            bias: m.bias_forces(&x.y, &x.yd),
            missing: open.missing,
            rejected: open.rejected_input,
        };
        self.asked = Some(open);
        question
    }

    /// Second half: the program's answer to the open tick (`None`: no usable answer came, the
    /// last good torque is held and counted). `None` when no tick is open.
    pub fn answer(&mut self, answer: Option<&Answer<N>>) -> Option<CenterOutput<N>> {
        let open = self.asked.take()?;
        Some(self.close_tick(open, None, answer))
    }

    /// One tick from the measurement `input` (`None`: missing).
    fn tick_on(
        &mut self,
        t: f64,
        input: Option<(&Vector<N>, &Vector<N>)>,
        s_override: Option<&Vector<N>>,
    ) -> CenterOutput<N> {
        let open = self.open_tick(t, input);
        self.close_tick(open, s_override, None)
    }

    /// Steps 1 and 3 of a tick: the measurement taken (rejected or missing ones counted, the
    /// last good one in use), the reference and `e_u`.
    fn open_tick(&mut self, t: f64, input: Option<(&Vector<N>, &Vector<N>)>) -> OpenTick<N> {
        let rejected_input = input.is_some_and(|(y, yd)| self.accept_measurement(y, yd));
        if input.is_none() {
            self.missing_inputs += 1;
        }
        OpenTick {
            x: self.tick_inputs(t),
            rejected_input,
            missing: input.is_none(),
        }
    }

    /// The rest of the tick opened as `open`: the controller's command, the history, its
    /// update, the resets and the alarm.
    fn close_tick(
        &mut self,
        open: OpenTick<N>,
        s_override: Option<&Vector<N>>,
        answer: Option<&Answer<N>>,
    ) -> CenterOutput<N> {
        let OpenTick {
            x,
            rejected_input,
            missing,
        } = open;
        let t = x.t;
        // The answers computed ahead for this tick serve it alone.
        let (primes, model) = (self.primes.take(), self.model.as_ref());
        let primed = primes.as_ref().map(|primes| Primed { model, primes });
        let tick = Tick {
            t,
            dt: self.params.control_period_s,
            y: &x.y,
            yd: &x.yd,
            reference: &x.reference,
            trajectory: &self.params.trajectory,
            e_u: &x.e_u,
            delay: &self.params.delay,
            model: primed
                .as_ref()
                .map_or(model, |p| p as &dyn EulerLagrange<N>),
            s_override,
            answer,
        };
        let mut command = self.controller.command(&tick);
        if let Some(c) = &self.correction {
            // A zero adds nothing, not even a change of a zero's sign: a correction of zeros
            // leaves the run bit for bit as the controller's.
            for (u, c) in command
                .u
                .iter_mut()
                .zip(c.iter())
                .filter(|(_, c)| **c != 0.0)
            {
                *u += c;
            }
        }
        // 5: a non-finite torque is counted and replaced by the last one sent.
        let rejected_torque = command.u.iter().any(|v| !v.is_finite());
        let u = if rejected_torque {
            self.rejected_torques += 1;
            self.last_u
        } else {
            command.u
        };

        // History of sent torques: u_k is in force from t_k on (the controller's input below
        // may reach it when τ < Δ).
        if self.sent.push(t, u).is_ok() {
            self.last_u = u;
        }

        let u_tau = self.delayed_input_over_step(&x);
        // The last good history, or the miss counted.
        if !x.history_miss {
            self.last_history = (x.e_u, u_tau);
        } else {
            self.history_misses += 1;
        }
        let mut estimate = self.controller.update(&tick, &u_tau);
        // 10: non-finite state never sticks.
        let state_reset = !self.controller.is_finite();
        if state_reset {
            self.state_resets += 1;
            estimate = self.controller.reset(&x.y, &x.yd);
        }

        // Drop what no future query reaches: the next tick's query `t' − τ(t')` is later than
        // this one's (`|τ̇| < 1`), and the line keeps one entry of margin besides.
        self.sent.prune_before(x.query);

        // 9: detection.
        let s_alarm = self.detector.update(t, command.s_hat.norm());
        let Estimate {
            q_hat,
            qd_hat,
            qdd_hat,
            alarm,
        } = estimate;

        CenterOutput {
            u,
            s_hat: command.s_hat,
            q_hat,
            qd_hat,
            qdd_hat,
            e_u: x.e_u,
            u_tau,
            alarm: alarm.unwrap_or(s_alarm),
            rejected_input,
            rejected_torque,
            state_reset,
            history_miss: x.history_miss,
            missing_input: missing,
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

    /// Steps 1 and 3 at `t` with the measurement in use: the reference and `e_u` over the
    /// zero-order-held history of sent `u`.
    fn tick_inputs(&mut self, t: f64) -> TickInputs<N> {
        let (y, yd) = self.last_good;
        let reference = self.reference_at(t);
        let query = t - self.params.delay.tau(t);
        let (e_u, history_miss) = match self.sent.integral(query, t) {
            Ok(e_u) => (e_u, false),
            Err(_) => (self.last_history.0, true),
        };
        TickInputs {
            t,
            y,
            yd,
            reference,
            query,
            e_u,
            history_miss,
        }
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

/// A tick opened (steps 1 and 3) and not closed yet.
#[derive(Debug)]
struct OpenTick<const N: usize> {
    x: TickInputs<N>,
    rejected_input: bool,
    missing: bool,
}

/// What a controller program is shown of a tick ([`CenterAgent::ask`]; docs/protocol.md,
/// "The controller program").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Question<const N: usize> {
    pub t: f64,
    /// The known delay `τ(t)`.
    pub tau: f64,
    /// The measurement in use (this tick's, or the last good one).
    pub y: Vector<N>,
    pub yd: Vector<N>,
    pub reference: Reference<N>,
    pub e_u: Vector<N>,
    /// `M(q_d)` and `A = M(q_d)⁻¹`.
    pub inertia_ref: Matrix<N>,
    pub inverse_inertia_ref: Matrix<N>,
    /// `M(y)` and `V(y, ẏ) ẏ + G(y) + F(ẏ)` at the measurement in use.
    pub inertia: Matrix<N>,
    pub bias: Vector<N>,
    /// The tick had no measurement / its measurement was rejected: `y`, `ẏ` are the last good
    /// ones.
    pub missing: bool,
    pub rejected: bool,
}

/// What steps 1 and 3 of a tick work out, for the steps after them.
#[derive(Debug)]
struct TickInputs<const N: usize> {
    t: f64,
    /// The measurement in use: this tick's, or the last good one if this tick's was rejected.
    y: Vector<N>,
    yd: Vector<N>,
    reference: Reference<N>,
    /// `t − τ(t)`: where `e_u`'s integral starts.
    query: f64,
    e_u: Vector<N>,
    /// The history did not reach back to `query`: `e_u` is the last good one.
    history_miss: bool,
}

#[cfg(test)]
mod tests;
