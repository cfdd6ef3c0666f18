//! The covert attack (docs/attacks.md): an actuator injection (the agent's `torque` channels)
//! combined with a sensor correction that hides its effect from the control center's observer.
//!
//! The attacker is white-box: it knows the robot's model, the known delay `τ(t)` and the
//! disturbance. It runs two noise-free twins of the robot, fed every torque command it relays:
//! the *attacked* twin gets the command with the injection, the *nominal* twin the command as
//! the center sent it. At the entry's `from_s` both twins are put at the measured state; from
//! then on the correction `nominal − attacked` (position and velocity) is added to every
//! measurement, so the center sees (to the twins' accuracy) the robot as it would move without
//! the injection.

use serde::{Deserialize, Serialize};

use crate::model::{EulerLagrange, ForLinks, Vector};
use crate::plant::{Measurement, NoiseConfig, Plant, PlantParams};

/// `[[covert]]` of a profile: from `from_s` on, hide the effect of agent `agent`'s torque
/// channels from its measurements.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CovertEntry {
    /// Agent id (as in the scenario's `[[agents]] id`); it needs a torque channel.
    pub agent: u32,
    /// When the sensor correction starts (the twins are put at the measured state), s.
    pub from_s: f64,
}

/// The twins of one agent, whatever its number of links.
pub(super) trait Twins: std::fmt::Debug + Send {
    /// The correction to add to the measurement of tick `k` at `t` (position then velocity,
    /// `2N` entries into `out`), given the clean measurement `y`, `ẏ` (`2N` entries): zero
    /// before `from_s`; at the first tick from then on the twins start at the measurement.
    /// The twins first integrate every step before `k` whose commands they have, by the
    /// robot's own lookahead rule: exactly the steps the robot had integrated when it measured
    /// tick `k` (it publishes a measurement only after the step before), so the twins run the
    /// same whether their torques come before or after the measurement.
    fn correction(&mut self, k: u64, t: f64, clean: &[f64], out: &mut [f64]);
    /// The torque of tick `k` stamped `t`: `sent` as the center sent it, `delivered` with the
    /// injection. Each twin takes its command.
    fn receive(&mut self, k: u64, t: f64, sent: &[f64], delivered: &[f64]);
}

#[derive(Debug)]
struct Twin<const N: usize> {
    from_s: f64,
    control_period_s: f64,
    engaged: bool,
    attacked: Plant<N>,
    nominal: Plant<N>,
    /// Steps integrated, commands received.
    advanced: u64,
    received: u64,
}

impl<const N: usize> Twin<N> {
    /// Integrates the steps before `k` that the commands received so far determine.
    fn catch_up(&mut self, k: u64) {
        let next = crate::time::tick_time(self.received, self.control_period_s);
        while self.advanced < k && self.attacked.can_advance_without(self.advanced, next) {
            self.attacked.advance(self.advanced);
            self.nominal.advance(self.advanced);
            self.advanced += 1;
        }
    }
}

impl<const N: usize> Twins for Twin<N> {
    fn correction(&mut self, k: u64, t: f64, clean: &[f64], out: &mut [f64]) {
        out.iter_mut().for_each(|x| *x = 0.0);
        self.catch_up(k);
        if t < self.from_s || clean.len() < 2 * N || out.len() < 2 * N {
            return;
        }
        if !self.engaged {
            self.engaged = true;
            for twin in [&mut self.attacked, &mut self.nominal] {
                twin.q = Vector::<N>::from_column_slice(&clean[..N]);
                twin.qd = Vector::<N>::from_column_slice(&clean[N..2 * N]);
            }
        }
        let dq = self.nominal.q - self.attacked.q;
        let dqd = self.nominal.qd - self.attacked.qd;
        out[..N].copy_from_slice(dq.as_slice());
        out[N..2 * N].copy_from_slice(dqd.as_slice());
    }

    fn receive(&mut self, k: u64, t: f64, sent: &[f64], delivered: &[f64]) {
        if sent.len() < N || delivered.len() < N {
            return;
        }
        let u = |s: &[f64]| Vector::<N>::from_column_slice(&s[..N]);
        // A refused command (non-finite) is counted by the twin and leaves the last in force,
        // as on the robot.
        let _ = self.attacked.take_command(t, Some((u(delivered), 0.0)));
        let _ = self.nominal.take_command(t, Some((u(sent), 0.0)));
        self.received = k + 1;
    }
}

/// The twins for `entry` of the agent whose plant `params` configures (its sensor noise left
/// out); `None` when its model cannot be built.
pub(super) fn twins(mut params: PlantParams, entry: &CovertEntry) -> Option<Box<dyn Twins>> {
    struct Build<'a> {
        params: PlantParams,
        entry: &'a CovertEntry,
    }
    impl ForLinks for Build<'_> {
        type Output = Option<Box<dyn Twins>>;
        fn call<const N: usize>(self, _: Box<dyn EulerLagrange<N>>) -> Self::Output {
            let twin = Twin::<N> {
                from_s: self.entry.from_s,
                control_period_s: self.params.control_period_s,
                engaged: false,
                attacked: Plant::<N>::new(self.params.clone())?,
                nominal: Plant::<N>::new(self.params)?,
                advanced: 0,
                received: 0,
            };
            Some(Box::new(twin))
        }
    }
    params.noise = NoiseConfig {
        position_std_rad: 0.0,
        velocity_std_rad_s: 0.0,
    };
    let model = params.model.clone();
    model.with_links(Build { params, entry })
}

/// The correction for a measurement of `N` links, as vectors.
pub(super) fn correct<const N: usize>(
    twins: &mut dyn Twins,
    (k, t): (u64, f64),
    clean: &Measurement<N>,
) -> (Vector<N>, Vector<N>) {
    let mut input = vec![0.0; 2 * N];
    input[..N].copy_from_slice(clean.y.as_slice());
    input[N..].copy_from_slice(clean.yd.as_slice());
    let mut out = vec![0.0; 2 * N];
    twins.correction(k, t, &input, &mut out);
    (
        Vector::<N>::from_column_slice(&out[..N]),
        Vector::<N>::from_column_slice(&out[N..]),
    )
}
