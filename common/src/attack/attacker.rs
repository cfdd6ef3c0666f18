//! The attacker as a value: what the man in the middle does to each agent's messages at each
//! tick. The in-process engine takes one ([`crate::engine::run_inproc_any_with`],
//! [`crate::engine::tick_inproc_any_with`]); the scenario's attack profile is one
//! ([`super::ProfileAttacker`], what the engine runs by default).

use crate::attack::injection::{Injection, TorqueInjection};
use crate::attack::message::Sent;
use crate::model::Vector;
use crate::plant::Measurement;

/// What the attacker does, agent by agent and tick by tick: the measurement the control center
/// receives in place of the robot's clean one, and, on the agents whose torque path it sits on,
/// the torque the robot receives in place of the center's command.
///
/// The engine calls it, at every tick `k` (time `t = k·Δ`) and for every agent in the
/// scenario's agent order, in this order: [`Self::measurement`] with the agent's clean
/// measurement; the control center's tick on what was delivered; [`Self::on_torque_path`];
/// and, when that says yes, [`Self::torque`] with the center's command. The calls of one run
/// come in that order only, so an attacker may keep state between them (a recording, a held
/// value, a random stream of its own); for a run to be reproducible, that state must depend on
/// nothing but what the calls show it (and a seed of its own).
///
/// # What the answers must say
///
/// Each answer is a pair. The first value is what reaches the receiver, a [`Sent`]:
/// [`Sent::Delivered`] with the payload the receiver takes as the tick's input (`held_s`: how
/// much later than the channel's known delay a torque takes effect, 0 for no hold-back; the
/// measurement path ignores it); [`Sent::Missing`] when nothing arrives; [`Sent::Forged`] and
/// [`Sent::Replayed`] for a message the receiver refuses (stamp moved, or an old message
/// re-sent under its original header). Anything but `Delivered` is a missing input for the
/// receiver: the control center holds its last measurement, the robot holds its last torque and
/// counts a miss.
///
/// The second value is the injection, what the attacker's records say it did
/// ([`crate::records::AttackRecord`], [`crate::records::ActuationRecord`]). The trace digest,
/// the metrics and the detectors' scores are computed from those records, not from a
/// comparison of the payload with the clean value: a tick is attacked exactly when
/// [`Injection::in_force`] (or [`TorqueInjection::in_force`]) says so. So an attacker that
/// changes a value must say so in its injection:
///
/// - the payload of a `Delivered` measurement should be `clean + α`, with `α` the injection's
///   `position` and `velocity` (rad, rad/s); of a torque, `u + α_u` with `α_u` its `u` (N·m);
/// - a change that is not an added constant (a scale, a sign flip, a frozen or replayed value)
///   still records `α = payload − clean`, and sets `transforming`;
/// - any answer other than `Sent::Delivered { held_s: 0.0, .. }` (a drop, a delay, a forged or
///   replayed message) sets `message`.
///
/// An attacker that tampers with a value and returns [`Injection::none`] runs the tampering all
/// the same, but its records and metrics count the tick as clean: every alarm it raises is
/// counted as a false alarm and no onset is ever detected. An attacker that injects nothing
/// answers `Sent::Delivered { payload: *clean, held_s: 0.0 }` with [`Injection::none`]; its
/// run is, record for record, the run of the attack profile `none`.
///
/// # Example
///
/// A constant bias of 0.05 rad on robot 2's measured positions from t = 2 s, declared in its
/// injection, on the first 4 s of the paper scenario; robot 2 tracks worse than without the
/// attack.
///
/// ```
/// use fdi_common::attack::{presets, Attacker, Injection, Sent};
/// use fdi_common::engine::run_inproc_any_with;
/// use fdi_common::model::Vector;
/// use fdi_common::plant::Measurement;
///
/// struct Bias;
///
/// impl Attacker for Bias {
///     fn name(&self) -> &str {
///         "bias on robot 2"
///     }
///     fn measurement<const N: usize>(
///         &mut self,
///         agent: u32,
///         _k: u64,
///         t: f64,
///         clean: &Measurement<N>,
///     ) -> (Sent<Measurement<N>>, Injection<N>) {
///         let mut inj = Injection::none();
///         if agent == 2 && t >= 2.0 {
///             inj.position = Vector::<N>::repeat(0.05);
///         }
///         let payload = Measurement { y: clean.y + inj.position, yd: clean.yd + inj.velocity };
///         (Sent::Delivered { payload, held_s: 0.0 }, inj)
///     }
/// }
///
/// let mut r = fdi_common::scenario::paper().expect("the embedded scenario is valid");
/// r.scenario.duration_s = 4.0;
/// r.attack = presets::preset("none").expect("a shipped preset");
/// let clean = fdi_common::engine::run_inproc_any(&r, |_| {}).expect("runs");
/// let biased = run_inproc_any_with(&r, &mut Bias, |_| {}).expect("runs");
/// assert_eq!(biased.attack, "bias on robot 2");
/// assert!(biased.rmse_rad["2"] > clean.rmse_rad["2"]);
/// assert_eq!(biased.rmse_rad["1"], clean.rmse_rad["1"]);
/// assert!(biased.metrics["2"].attacked_ticks > 0, "the injection says the tick is attacked");
/// ```
pub trait Attacker {
    /// The attack's name: the `attack` field of the run's summary.
    fn name(&self) -> &str;

    /// The measurement of agent `agent` at tick `k` (time `t`) that the control center
    /// receives, from the robot's `clean` one (sensor noise included, no attack), and the
    /// injection the attacker records for it (see the trait's docs).
    fn measurement<const N: usize>(
        &mut self,
        agent: u32,
        k: u64,
        t: f64,
        clean: &Measurement<N>,
    ) -> (Sent<Measurement<N>>, Injection<N>);

    /// The attacker sits on agent `agent`'s torque path: the engine passes its commands
    /// through [`Self::torque`] (and records an [`crate::records::ActuationRecord`] for each);
    /// otherwise they go straight to the robot. Asked at every tick, after
    /// [`Self::measurement`]; it should not change during a run. Default: on no agent's path.
    fn on_torque_path(&self, agent: u32) -> bool {
        let _ = agent;
        false
    }

    /// The torque agent `agent` receives at tick `k` (stamped `t`) in place of the control
    /// center's command `u`, and the injection recorded for it (see the trait's docs). Called
    /// only for the agents [`Self::on_torque_path`] names. Default: `u` delivered unchanged,
    /// nothing injected.
    fn torque<const N: usize>(
        &mut self,
        agent: u32,
        k: u64,
        t: f64,
        u: &Vector<N>,
    ) -> (Sent<Vector<N>>, TorqueInjection<N>) {
        let _ = (agent, k, t);
        (Sent::on_time(*u), TorqueInjection::none())
    }
}
