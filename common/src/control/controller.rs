//! The control center's defence of one robot, as a plug-in: a [`Controller`] computes each
//! tick's torque, and what it estimates, from the measurement in use, the reference and the
//! history of the torques sent over the known delay. The pipeline around it
//! ([`super::CenterAgent`]) keeps what every controller shares: the last good measurement held
//! when one is rejected or missing, the history of sent torques and its lookups (`e_u`, `u_τ`),
//! a non-finite torque replaced by the last good one, state that turned non-finite reset, the
//! alarm on `‖Ŝ‖`, and the counts of each.
//!
//! **Adding a controller** (docs/model.md, "Adding a controller"): a file in this folder with a
//! type implementing [`Controller`] and a constructor `fn(&CenterParams, &dyn EulerLagrange<N>)
//! -> Option<Self>`, and one line in the list of `with_controllers!` (`control/list.rs`). Its
//! parameters, if it has any, go under its own table of `[controller]` (a field of
//! [`super::config::ControllerConfig`], as `computed_torque` and `gated`).
//!
//! [`CenterParams`]: super::config::CenterParams

use crate::delay::DelayProfile;
use crate::model::primed::Wants;
use crate::model::{EulerLagrange, Vector};
use crate::trajectory::{Reference, TrajectoryConfig};

/// What a controller is shown at tick `t`.
#[derive(Clone, Copy)]
pub struct Tick<'a, const N: usize> {
    pub t: f64,
    /// The control period Δ, s.
    pub dt: f64,
    /// The measurement in use: this tick's, or the last good one when this tick's was rejected
    /// or is missing.
    pub y: &'a Vector<N>,
    pub yd: &'a Vector<N>,
    /// `q_d`, `q̇_d`, `q̈_d` at `t`.
    pub reference: &'a Reference<N>,
    /// The desired trajectory, for a controller that looks ahead (to `t + τ(t)`).
    pub trajectory: &'a TrajectoryConfig,
    /// `e_u = ∫_{t−τ(t)}^{t} u ds` over the torques sent (the last good one when the history did
    /// not reach back).
    pub e_u: &'a Vector<N>,
    /// The known delay `τ(t)` of the torque channel.
    pub delay: &'a DelayProfile,
    /// The robot's model.
    pub model: &'a dyn EulerLagrange<N>,
    /// `Ŝ` forced to this value (an oracle for tests and ablations): a controller that
    /// estimates the attack uses it in place of its estimate and does not learn.
    pub s_override: Option<&'a Vector<N>>,
    /// A controller program's answer to this tick (`[roles.controller]`): what the `external`
    /// controller sends. `None` for the others, and when no usable answer came (the last good
    /// torque is then held).
    pub answer: Option<&'a Answer<N>>,
}

/// A controller program's answer to a tick (`[roles.controller]`, docs/protocol.md, "The
/// controller program").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Answer<const N: usize> {
    pub command: Command<N>,
    /// Its own alarm, if it has one.
    pub alarm: Option<bool>,
}

/// A controller's command at a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command<const N: usize> {
    /// The torque to send, N·m (the pipeline replaces a non-finite one).
    pub u: Vector<N>,
    /// Its attack estimate `Ŝ` (zero for a controller without one).
    pub s_hat: Vector<N>,
}

/// What a controller estimates of its robot once the tick's torque is in the history.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate<const N: usize> {
    /// Its estimate of `q`, `q̇`, `q̈` (an observer's, or the state it predicted).
    pub q_hat: Vector<N>,
    pub qd_hat: Vector<N>,
    pub qdd_hat: Vector<N>,
    /// Its own alarm, recorded in place of the pipeline's alarm on `‖Ŝ‖` (`None`: it has none).
    pub alarm: Option<bool>,
}

/// The defence of one robot at the control center.
pub trait Controller<const N: usize>: std::fmt::Debug + Send {
    /// The torque to send at `x.t`, and `Ŝ`.
    fn command(&mut self, x: &Tick<'_, N>) -> Command<N>;
    /// After the torque entered the history: `u_tau` is the delayed input `u(s − τ(s))` over
    /// `[t, t + Δ]` (the scenario's `observer_input`). Steps its state to the next tick.
    fn update(&mut self, x: &Tick<'_, N>, u_tau: &Vector<N>) -> Estimate<N>;
    /// Every number of its state is finite (asked after [`Self::update`]).
    fn is_finite(&self) -> bool;
    /// Starts again from the measurement `(y, ẏ)` after its state turned non-finite; its
    /// estimate then.
    fn reset(&mut self, y: &Vector<N>, yd: &Vector<N>) -> Estimate<N>;
    /// What it will ask its model in the next tick, whose reference is `reference`, as far as
    /// it knows before the tick ([`Wants`]): the in-process engine may compute it ahead, side
    /// by side with other robots' ([`crate::model::primed`]). Nothing by default.
    fn wants(&self, reference: &Reference<N>) -> Wants<N> {
        let _ = reference;
        Wants::default()
    }
}
