//! False-data-injection attack profiles as data (docs/attacks.md).
//!
//! A profile is a list of channels; a channel targets one agent, one signal (position or
//! velocity) and one or more links, and holds a time schedule of segments, each a
//! [`Waveform`]. A segment is in force from its `from_s` until the next segment begins.
//! Channels that target the same signal and link add up: every waveform, the transforms of the
//! clean signal (scale, sign flip, freeze) and replay included, is an injection `α` added to the
//! clean value, and `α` is what the attacker records.
//!
//! A channel on the `torque` signal tampers with the commands on their way from the control
//! center to the agent: a run whose profile attacks an agent's torques routes that agent's
//! commands through the attacker ([`AttackProfile::attacks_torque_of`]); the others keep the
//! direct path. Whole-message attacks (denial of service, delay, stamp forgery, replay with the
//! original header) are the profile's `[[messages]]` ([`message`]).
//!
//! What an attacker does at each tick, for each agent, is the [`Attacker`] trait
//! ([`attacker`]); the attacker of a profile is [`ProfileAttacker`], the [`AgentAttack`] of
//! each agent. The in-process engine runs any [`Attacker`] a caller supplies.

pub mod attacker;
pub mod covert;
pub mod injection;
pub mod message;
pub mod presets;
pub mod profile;
pub mod waveform;

use rand_chacha::ChaCha12Rng;

use crate::model::Vector;
use crate::plant::{Measurement, PlantParams};
use crate::records::Joints;
use crate::rng::{stream, Purpose};

pub use attacker::Attacker;
pub use covert::CovertEntry;
pub use injection::{Injection, TorqueInjection};
pub use message::{Effect, MessageAttack, MessageSegment, Path, Sent};
pub use profile::{AttackProfile, Channel, Segment, Signal, ValueUnit};
pub use waveform::Waveform;

use message::MessageLine;

/// A channel ready to evaluate: one link, one signal, values scaled to rad, rad/s or N·m.
#[derive(Debug, Clone)]
struct LinkChannel {
    signal: Signal,
    link: usize,
    scale: f64,
    segments: Vec<Segment>,
    rng: ChaCha12Rng,
    /// Per segment, what a `replay` segment recorded (empty for the other waveforms).
    recordings: Vec<Recording>,
    /// Per segment, the clean value a `freeze` segment holds, from its first tick on.
    frozen: Vec<Option<f64>>,
    /// The clean value of this signal and link at the last observation.
    clean: f64,
}

/// Clean samples of one channel recorded for a `replay` segment.
#[derive(Debug, Clone, Default)]
struct Recording {
    times: Vec<f64>,
    values: Vec<f64>,
}

impl Recording {
    /// The sample played `elapsed` seconds after the replay began.
    fn played(&self, elapsed: f64) -> Option<f64> {
        let len = self.values.len();
        let (first, last) = (*self.times.first()?, *self.times.last()?);
        waveform::replay::index(elapsed, waveform::replay::spacing(first, last, len), len)
            .map(|i| self.values[i])
    }
}

impl LinkChannel {
    fn segment_index(&self, t: f64) -> Option<usize> {
        let n = self.segments.partition_point(|s| s.from_s <= t);
        n.checked_sub(1)
    }

    fn segment_at(&self, t: f64) -> Option<&Segment> {
        self.segment_index(t).map(|i| &self.segments[i])
    }

    /// Shows the channel the clean value `v` of time `t`.
    fn observe(&mut self, t: f64, v: f64) {
        self.clean = v;
        if let Some(i) = self.segment_index(t) {
            if self.segments[i].waveform == Waveform::Freeze && self.frozen[i].is_none() {
                self.frozen[i] = Some(v);
            }
        }
        for (seg, rec) in self.segments.iter().zip(&mut self.recordings) {
            if let Some((from, to)) = seg.waveform.replay_window() {
                if from <= t && t < to {
                    rec.times.push(t);
                    rec.values.push(v);
                }
            }
        }
    }

    /// The injection at `t` against the last observed clean value, and whether a transforming
    /// segment is in force; `None` before the first segment.
    fn injection(&mut self, t: f64) -> Option<(f64, bool)> {
        let i = self.segment_index(t)?;
        let seg = self.segments[i];
        let v = match seg.waveform {
            Waveform::Replay { .. } => self.recordings[i]
                .played(t - seg.from_s)
                .map_or(0.0, |r| r - self.clean),
            Waveform::Scale { factor } => waveform::transform::scale(self.clean, factor),
            Waveform::SignFlip => waveform::transform::sign_flip(self.clean),
            // Observed at this tick or before: never missing once the segment is in force.
            Waveform::Freeze => {
                self.frozen[i].map_or(0.0, |h| waveform::transform::freeze(self.clean, h))
            }
            w => self.scale * w.value(t, seg.from_s, &mut self.rng),
        };
        Some((v, seg.waveform.transforms()))
    }
}

/// The attack on one agent, compiled from a profile: what the attacker process evaluates.
#[derive(Debug)]
pub struct AgentAttack {
    channels: Vec<LinkChannel>,
    measurements: Option<MessageLine<(Joints, Joints)>>,
    torques: Option<MessageLine<Joints>>,
    /// The twins of a covert attack ([`Self::with_covert`]).
    covert: Option<Box<dyn covert::Twins>>,
}

impl AgentAttack {
    /// Compiles every channel and message attack of `profile` that targets `agent_id`;
    /// Gaussian waveforms draw from the stream `(run_seed, agent, AttackNoise { channel
    /// index })`, message attacks from `(run_seed, agent, AttackMessages { path })`.
    pub fn compile(profile: &AttackProfile, agent_id: u32, run_seed: u64) -> Self {
        let mut channels = Vec::new();
        for (c, ch) in profile
            .channels
            .iter()
            .enumerate()
            .filter(|(_, ch)| ch.agent == agent_id)
        {
            for &link in &ch.links {
                let channel = u32::try_from(c * 64 + link as usize).unwrap_or(u32::MAX);
                let mut segments = ch.segments.clone();
                segments.sort_by(|a, b| a.from_s.total_cmp(&b.from_s));
                channels.push(LinkChannel {
                    signal: ch.signal,
                    link: (link as usize).saturating_sub(1),
                    scale: ch.units.factor(),
                    recordings: vec![Recording::default(); segments.len()],
                    frozen: vec![None; segments.len()],
                    segments,
                    rng: stream(run_seed, agent_id, Purpose::AttackNoise { channel }),
                    clean: 0.0,
                });
            }
        }
        Self {
            channels,
            measurements: message_line(profile, agent_id, run_seed, Path::Measurement),
            torques: message_line(profile, agent_id, run_seed, Path::Torque),
            covert: None,
        }
    }

    /// This attack with the twins of the covert attack `entry` on the agent: noise-free copies
    /// of its plant as `plant` configures it (its model, delay and disturbance; none when the
    /// model cannot be built). [`crate::scenario::Resolved::agent_attack`] adds them from the
    /// run's scenario.
    pub fn with_covert(mut self, entry: &CovertEntry, plant: PlantParams) -> Self {
        self.covert = covert::twins(plant, entry);
        self
    }

    /// Shows the attacker the clean measurement of time `t`, before [`Self::injection`] of the
    /// same tick: `replay` channels record it inside their window and play back against it, a
    /// `freeze` segment in force keeps the value of its first tick, and the other transforms
    /// act on it.
    pub fn observe<const N: usize>(&mut self, t: f64, clean: &Measurement<N>) {
        for ch in &mut self.channels {
            let v = match ch.signal {
                Signal::Position if ch.link < N => clean.y[ch.link],
                Signal::Velocity if ch.link < N => clean.yd[ch.link],
                _ => continue,
            };
            ch.observe(t, v);
        }
    }

    /// `α(t)` for position and velocity, rad and rad/s. Channels are summed in profile order.
    /// A `replay` channel injects `recorded − clean` against the last [`Self::observe`]d clean
    /// value (nothing while its recording is empty).
    pub fn injection<const N: usize>(&mut self, t: f64) -> Injection<N> {
        let mut inj = Injection {
            position: Vector::<N>::zeros(),
            velocity: Vector::<N>::zeros(),
            transforming: false,
            message: self.measurements.as_ref().is_some_and(|l| l.in_force(t)),
        };
        for ch in &mut self.channels {
            if ch.link >= N || ch.signal == Signal::Torque {
                continue;
            }
            let Some((v, transforming)) = ch.injection(t) else {
                continue;
            };
            inj.transforming |= transforming;
            match ch.signal {
                Signal::Position => inj.position[ch.link] += v,
                Signal::Velocity => inj.velocity[ch.link] += v,
                Signal::Torque => {}
            }
        }
        inj
    }

    /// The attacker's step on the measurement of tick `k` (time `t`): the value channels add
    /// `α` to the clean measurement, then the message attack decides what the center gets.
    pub fn measurement<const N: usize>(
        &mut self,
        k: u64,
        t: f64,
        clean: &Measurement<N>,
    ) -> (Sent<Measurement<N>>, Injection<N>) {
        self.observe(t, clean);
        let mut inj = self.injection::<N>(t);
        if let Some(twins) = &mut self.covert {
            let (dq, dqd) = covert::correct::<N>(twins.as_mut(), (k, t), clean);
            inj.position += dq;
            inj.velocity += dqd;
        }
        let out = Measurement {
            y: clean.y + inj.position,
            yd: clean.yd + inj.velocity,
        };
        let Some(line) = &mut self.measurements else {
            return (Sent::on_time(out), inj);
        };
        let sent = line.send(k, t, (Joints::from(&out.y), Joints::from(&out.yd)));
        (
            map_sent(sent, |(y, yd)| Measurement {
                y: y.to_vector::<N>(),
                yd: yd.to_vector::<N>(),
            }),
            inj,
        )
    }

    /// The attacker's step on the torque `u` of tick `k` (stamped `t`), when the run routes
    /// this agent's torques through it: the torque channels add `α_u` (transforms act on the
    /// clean `u`), then the message attack decides what the agent gets.
    pub fn torque<const N: usize>(
        &mut self,
        k: u64,
        t: f64,
        u: &Vector<N>,
    ) -> (Sent<Vector<N>>, TorqueInjection<N>) {
        let mut inj = TorqueInjection {
            u: Vector::<N>::zeros(),
            transforming: false,
            message: self.torques.as_ref().is_some_and(|l| l.in_force(t)),
        };
        for ch in &mut self.channels {
            if ch.link >= N || ch.signal != Signal::Torque {
                continue;
            }
            ch.observe(t, u[ch.link]);
            if let Some((v, transforming)) = ch.injection(t) {
                inj.u[ch.link] += v;
                inj.transforming |= transforming;
            }
        }
        let out = u + inj.u;
        if let Some(twins) = &mut self.covert {
            twins.receive(k, t, u.as_slice(), out.as_slice());
        }
        let Some(line) = &mut self.torques else {
            return (Sent::on_time(out), inj);
        };
        let sent = line.send(k, t, Joints::from(&out));
        (map_sent(sent, |u| u.to_vector::<N>()), inj)
    }

    /// True when some channel has a non-`none` segment, or a message attack a non-`pass`
    /// effect, in force at `t`.
    pub fn is_active(&self, t: f64) -> bool {
        self.channels
            .iter()
            .any(|ch| ch.segment_at(t).is_some_and(|s| !s.waveform.is_none()))
            || self.measurements.as_ref().is_some_and(|l| l.in_force(t))
            || self.torques.as_ref().is_some_and(|l| l.in_force(t))
    }
}

/// The attacker of a scenario's attack profile: the [`AgentAttack`] of each agent, and whether
/// the profile attacks its torques ([`AttackProfile::attacks_torque_of`]). What the in-process
/// engine runs unless given another [`Attacker`];
/// [`crate::scenario::Resolved::profile_attacker`] builds it for a run.
#[derive(Debug)]
pub struct ProfileAttacker {
    name: String,
    /// `(agent id, its attack, the profile attacks its torques)`, in the scenario's order.
    agents: Vec<(u32, AgentAttack, bool)>,
}

impl ProfileAttacker {
    /// The attacker called `name` (the profile's) of `agents`: `(agent id, its attack, the
    /// profile attacks its torques)`, in the scenario's agent order.
    pub fn new(
        name: impl Into<String>,
        agents: impl IntoIterator<Item = (u32, AgentAttack, bool)>,
    ) -> Self {
        Self {
            name: name.into(),
            agents: agents.into_iter().collect(),
        }
    }

    /// The attack on agent `id`, if it is one of this attacker's agents.
    pub fn agent(&self, id: u32) -> Option<&AgentAttack> {
        self.agents.iter().find(|a| a.0 == id).map(|a| &a.1)
    }

    fn agent_mut(&mut self, id: u32) -> Option<&mut AgentAttack> {
        self.agents.iter_mut().find(|a| a.0 == id).map(|a| &mut a.1)
    }
}

/// Each call is the [`AgentAttack`] call of the agent; an agent the attacker does not know gets
/// its messages unchanged.
impl Attacker for ProfileAttacker {
    fn name(&self) -> &str {
        &self.name
    }

    fn measurement<const N: usize>(
        &mut self,
        agent: u32,
        k: u64,
        t: f64,
        clean: &Measurement<N>,
    ) -> (Sent<Measurement<N>>, Injection<N>) {
        match self.agent_mut(agent) {
            Some(attack) => attack.measurement::<N>(k, t, clean),
            None => (Sent::on_time(*clean), Injection::none()),
        }
    }

    fn on_torque_path(&self, agent: u32) -> bool {
        self.agents.iter().any(|a| a.0 == agent && a.2)
    }

    fn torque<const N: usize>(
        &mut self,
        agent: u32,
        k: u64,
        t: f64,
        u: &Vector<N>,
    ) -> (Sent<Vector<N>>, TorqueInjection<N>) {
        match self.agent_mut(agent) {
            Some(attack) => attack.torque::<N>(k, t, u),
            None => (Sent::on_time(*u), TorqueInjection::none()),
        }
    }
}

/// The compiled message attack of `profile` on agent `agent_id`'s `path`, if any.
fn message_line<P: Copy>(
    profile: &AttackProfile,
    agent_id: u32,
    run_seed: u64,
    path: Path,
) -> Option<MessageLine<P>> {
    let torque = path == Path::Torque;
    profile
        .messages
        .iter()
        .find(|m| m.agent == agent_id && m.path == path)
        .map(|m| {
            MessageLine::compile(
                m,
                stream(run_seed, agent_id, Purpose::AttackMessages { torque }),
            )
        })
}

/// `sent` with its payload converted by `f`.
fn map_sent<P, Q>(sent: Sent<P>, f: impl Fn(P) -> Q) -> Sent<Q> {
    match sent {
        Sent::Delivered { payload, held_s } => Sent::Delivered {
            payload: f(payload),
            held_s,
        },
        Sent::Missing => Sent::Missing,
        Sent::Forged { payload, shift_s } => Sent::Forged {
            payload: f(payload),
            shift_s,
        },
        Sent::Replayed { k, payload } => Sent::Replayed {
            k,
            payload: f(payload),
        },
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    fn dofs() -> BTreeMap<u32, usize> {
        (1..=4).map(|i| (i, 2)).collect()
    }

    #[test]
    fn paper_preset_robot1_values_in_radians() {
        let p = presets::preset("paper").expect("paper preset");
        assert!(p.problems(&dofs()).is_empty(), "{:?}", p.problems(&dofs()));
        let mut a = AgentAttack::compile(&p, 1, 1);
        let d = std::f64::consts::PI / 180.0;
        let i5 = a.injection::<2>(5.0);
        assert_eq!(i5.position[0], d * (-0.5 * 5.0f64.sin()));
        assert_eq!(i5.position[1], i5.position[0], "signal-wise: both links");
        assert_eq!(i5.velocity[0], d * (-4.0 * 5.0f64.sin()));
        let i12 = a.injection::<2>(12.0);
        assert_eq!((i12.position[0], i12.velocity[1]), (d, 7.0 * d));
        assert!(
            !a.injection::<2>(0.0).in_force(),
            "sin 0 = 0: not yet in force"
        );
        assert!(a.injection::<2>(0.001).in_force());
    }

    fn clean(y: [f64; 2], yd: [f64; 2]) -> Measurement<2> {
        Measurement {
            y: Vector::<2>::from(y),
            yd: Vector::<2>::from(yd),
        }
    }

    /// The shipped transform presets: scale, sign flip and freeze act on the clean signal of
    /// their segment only, and are in force for the whole segment (a scaled zero injects zero).
    #[test]
    fn transform_presets_act_on_the_clean_signal_during_their_segment() {
        let tamper = |a: &mut AgentAttack, t: f64, m: &Measurement<2>| {
            a.observe(t, m);
            let inj = a.injection::<2>(t);
            (m.y + inj.position, m.yd + inj.velocity, inj.in_force())
        };
        let scale = presets::preset("scale").expect("scale preset");
        assert!(scale.problems(&dofs()).is_empty());
        let mut a = AgentAttack::compile(&scale, 1, 1);
        let m = clean([0.4, -0.2], [0.1, 0.3]);
        assert_eq!(tamper(&mut a, 9.999, &m), (m.y, m.yd, false));
        let (y, yd, on) = tamper(&mut a, 15.0, &m);
        assert!((y[0] - 1.05 * 0.4).abs() < 1e-15 && (y[1] + 1.05 * 0.2).abs() < 1e-15);
        assert_eq!((yd, on), (m.yd, true));
        let zero = clean([0.0, 0.0], [0.0, 0.0]);
        assert_eq!(tamper(&mut a, 15.001, &zero), (zero.y, zero.yd, true));
        assert_eq!(tamper(&mut a, 20.0, &m), (m.y, m.yd, false));

        let flip = presets::preset("sign-flip").expect("sign-flip preset");
        let mut a = AgentAttack::compile(&flip, 1, 1);
        let (y, yd, on) = tamper(&mut a, 11.0, &m);
        assert_eq!((y, yd[0], yd[1], on), (m.y, -0.1, 0.3, true));
        assert!(!tamper(&mut a, 12.0, &m).2);

        let freeze = presets::preset("freeze").expect("freeze preset");
        let mut a = AgentAttack::compile(&freeze, 1, 1);
        let before = clean([0.9, 0.8], [0.7, 0.6]);
        assert_eq!(tamper(&mut a, 9.999, &before), (before.y, before.yd, false));
        let (y, yd, on) = tamper(&mut a, 10.0, &m);
        assert_eq!(
            (y, yd, on),
            (m.y, m.yd, true),
            "the first tick is the held value"
        );
        let later = clean([0.45, -0.25], [0.15, 0.35]);
        let (y, yd, _) = tamper(&mut a, 14.0, &later);
        for (got, held) in y.iter().chain(yd.iter()).zip(m.y.iter().chain(m.yd.iter())) {
            assert!((got - held).abs() < 1e-15, "{got} vs {held}");
        }
        assert_eq!(tamper(&mut a, 20.0, &later), (later.y, later.yd, false));
    }

    #[test]
    fn a_scale_factor_must_be_finite() {
        let text = r#"
            [[channels]]
            agent = 1
            signal = "position"
            links = [1]
            units = "rad"
            segments = [{ from_s = 1.0, waveform = { kind = "scale", factor = inf } }]
        "#;
        let p: AttackProfile = toml::from_str(text).expect("parses");
        let problems = p.problems(&dofs());
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert_eq!(problems[0].0, "channels[0].segments[0].waveform.factor");
    }

    #[test]
    fn linkwise_preset_puts_s2_on_link_two_position() {
        let p = presets::preset("paper-linkwise").expect("linkwise preset");
        let mut a = AgentAttack::compile(&p, 1, 1);
        let i = a.injection::<2>(12.0);
        let d = std::f64::consts::PI / 180.0;
        assert_eq!((i.position[0], i.position[1]), (d, 7.0 * d));
        assert_eq!(i.velocity, Vector::<2>::zeros());
    }

    #[test]
    fn onsets_and_activity_of_robots_2_and_3() {
        let p = presets::preset("paper").expect("paper preset");
        let mut a2 = AgentAttack::compile(&p, 2, 1);
        assert!(!a2.injection::<2>(4.999).in_force() && a2.injection::<2>(5.0).in_force());
        assert!(!a2.is_active(4.999) && a2.is_active(5.0));
        let a3 = AgentAttack::compile(&p, 3, 1);
        assert!(a3.is_active(29.9) && !a3.is_active(30.0));
    }

    #[test]
    fn problems_name_the_field_path() {
        let p = AttackProfile {
            channels: vec![Channel {
                agent: 9,
                signal: Signal::Position,
                links: vec![0, 3],
                units: ValueUnit::Rad,
                segments: vec![
                    Segment {
                        from_s: 1.0,
                        waveform: Waveform::Constant { value: 1.0 },
                    },
                    Segment {
                        from_s: 0.5,
                        waveform: Waveform::Constant {
                            value: f64::INFINITY,
                        },
                    },
                ],
            }],
            ..AttackProfile::default()
        };
        let paths: Vec<String> = p.problems(&dofs()).into_iter().map(|p| p.0).collect();
        for want in [
            "channels[0].agent",
            "channels[0].links[0]",
            "channels[0].segments[1].from_s",
            "channels[0].segments[1].waveform.value",
        ] {
            assert!(
                paths.iter().any(|p| p == want),
                "missing {want} in {paths:?}"
            );
        }
    }

    fn replay_profile(from_s: f64, record_for_s: f64) -> AttackProfile {
        AttackProfile {
            channels: vec![Channel {
                agent: 1,
                signal: Signal::Velocity,
                links: vec![2],
                units: ValueUnit::Deg,
                segments: vec![Segment {
                    from_s,
                    waveform: Waveform::Replay {
                        record_from_s: 0.5,
                        record_for_s,
                    },
                }],
            }],
            ..AttackProfile::default()
        }
    }

    #[test]
    fn replay_plays_back_the_recorded_clean_values_in_a_loop() {
        let p = replay_profile(2.0, 0.5);
        assert!(p.problems(&dofs()).is_empty(), "{:?}", p.problems(&dofs()));
        let mut a = AgentAttack::compile(&p, 1, 1);
        let dt = 1e-3;
        let clean = |k: u64| Measurement::<2> {
            y: Vector::<2>::new(0.1, 0.2),
            yd: Vector::<2>::new(-(k as f64), k as f64 * 0.5 + 1.0),
        };
        let mut seen = Vec::new();
        for k in 0..4000u64 {
            let t = k as f64 * dt;
            let m = clean(k);
            let (sent, inj) = a.measurement::<2>(k, t, &m);
            let out = *sent.usable().expect("delivered").0;
            assert_eq!(out.y, m.y, "positions untouched");
            assert_eq!(out.yd[0], m.yd[0], "link 1 untouched");
            if k < 2000 {
                assert_eq!(inj.velocity[1], 0.0, "relay before the replay, tick {k}");
            } else {
                // Recorded ticks 500..1000, looped from tick 2000.
                let recorded = clean(500 + (k - 2000) % 500).yd[1];
                assert_eq!(inj.velocity[1], recorded - m.yd[1], "tick {k}");
                assert!((out.yd[1] - recorded).abs() < 1e-12, "tick {k}");
                seen.push(out.yd[1]);
            }
        }
        assert!(a.is_active(2.0) && !a.is_active(1.999));
        assert_eq!(seen.len(), 2000);
    }

    #[test]
    fn replay_problems_name_the_field_path() {
        let paths = |p: AttackProfile| -> Vec<String> {
            p.problems(&dofs()).into_iter().map(|p| p.0).collect()
        };
        assert_eq!(
            paths(replay_profile(0.9, 0.5)),
            vec!["channels[0].segments[0].from_s".to_string()],
            "a replay cannot start before its recording ends"
        );
        assert!(paths(replay_profile(1.0, 0.5)).is_empty());
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(
                paths(replay_profile(10.0, bad))
                    .iter()
                    .any(|p| p == "channels[0].segments[0].waveform.record_for_s"),
                "record_for_s = {bad}"
            );
        }
    }

    fn torque_channel(links: Vec<u32>, segments: Vec<Segment>) -> Channel {
        Channel {
            agent: 1,
            signal: Signal::Torque,
            links,
            units: ValueUnit::NewtonMetre,
            segments,
        }
    }

    fn seg(from_s: f64, waveform: Waveform) -> Segment {
        Segment { from_s, waveform }
    }

    fn with_channels(channels: Vec<Channel>) -> AttackProfile {
        AttackProfile {
            channels,
            ..AttackProfile::default()
        }
    }

    const DT: f64 = 1e-3;

    fn tick(k: u64) -> f64 {
        k as f64 * DT
    }

    /// A clean torque that differs from tick to tick and link to link.
    fn clean_u(k: u64) -> Vector<2> {
        let t = tick(k);
        Vector::<2>::new(0.3 * (3.0 * t).sin() + 0.1, -0.2 * (5.0 * t).cos())
    }

    /// The torque the agent gets at tick `k` (no message attack on the path: delivered now).
    fn tampered(a: &mut AgentAttack, k: u64, u: &Vector<2>) -> (Vector<2>, TorqueInjection<2>) {
        let (sent, inj) = a.torque::<2>(k, tick(k), u);
        let (out, held) = sent.usable().expect("delivered");
        assert_eq!(held, 0.0);
        assert_eq!(*out, u + inj.u, "what is sent is u + α_u");
        (*out, inj)
    }

    /// Whatever the profile does to torques, it leaves the measurement of tick `k` untouched.
    fn measurement_untouched(a: &mut AgentAttack, k: u64) {
        let m = clean([0.1 + tick(k), -0.3], [0.02, tick(k)]);
        let (sent, inj) = a.measurement::<2>(k, tick(k), &m);
        assert_eq!(
            sent,
            Sent::Delivered {
                payload: m,
                held_s: 0.0
            }
        );
        assert!(!inj.in_force(), "tick {k}: {inj:?}");
    }

    #[test]
    fn torque_channels_tamper_the_commands_with_every_waveform_and_leave_measurements_alone() {
        let win = |w: Waveform| vec![seg(tick(100), w), seg(tick(200), Waveform::None)];
        let kinds: Vec<(&str, Waveform)> = vec![
            ("constant", Waveform::Constant { value: 0.05 }),
            (
                "sine",
                Waveform::Sine {
                    amplitude: 0.1,
                    omega_rad_s: 20.0,
                    phase_rad: 0.3,
                    offset: 0.01,
                },
            ),
            ("scale", Waveform::Scale { factor: 1.5 }),
            ("sign-flip", Waveform::SignFlip),
            ("freeze", Waveform::Freeze),
        ];
        for (name, w) in kinds {
            // Link 2 only: link 1 goes through untouched.
            let p = with_channels(vec![torque_channel(vec![2], win(w))]);
            assert!(
                p.problems(&dofs()).is_empty(),
                "{name}: {:?}",
                p.problems(&dofs())
            );
            assert!(p.attacks_torque_of(1) && !p.attacks_torque_of(2));
            let mut a = AgentAttack::compile(&p, 1, 1);
            for k in 0..300u64 {
                measurement_untouched(&mut a, k);
                let u = clean_u(k);
                let (out, inj) = tampered(&mut a, k, &u);
                assert_eq!(out[0], u[0], "{name}, tick {k}: link 1");
                let t = tick(k);
                if !(100..200).contains(&k) {
                    assert_eq!(out, u, "{name}, tick {k}: outside the segment");
                    assert!(!inj.in_force(), "{name}, tick {k}");
                    continue;
                }
                let want = match w {
                    Waveform::Constant { value } => u[1] + value,
                    Waveform::Sine { .. } => u[1] + 0.1 * (20.0 * t + 0.3).sin() + 0.01,
                    Waveform::Scale { factor } => factor * u[1],
                    Waveform::SignFlip => -u[1],
                    Waveform::Freeze => clean_u(100)[1],
                    _ => unreachable!(),
                };
                assert!(
                    (out[1] - want).abs() <= 4.0 * f64::EPSILON * want.abs().max(u[1].abs()),
                    "{name}, tick {k}: {} vs {want}",
                    out[1]
                );
                assert!(inj.in_force(), "{name}, tick {k}");
                assert_eq!(inj.transforming, w.transforms(), "{name}");
                assert!(!inj.message);
                assert!(a.is_active(t));
            }
        }
    }

    #[test]
    fn a_torque_replay_plays_back_the_recorded_commands_in_a_loop() {
        let p = with_channels(vec![torque_channel(
            vec![1, 2],
            vec![seg(
                tick(300),
                Waveform::Replay {
                    record_from_s: tick(100),
                    record_for_s: 0.05,
                },
            )],
        )]);
        assert!(p.problems(&dofs()).is_empty(), "{:?}", p.problems(&dofs()));
        let mut a = AgentAttack::compile(&p, 1, 1);
        let recorded: Vec<u64> = (0..300)
            .filter(|&j| tick(100) <= tick(j) && tick(j) < tick(100) + 0.05)
            .collect();
        let n = recorded.len() as u64;
        assert!((50..=51).contains(&n), "{n}");
        for k in 0..500u64 {
            measurement_untouched(&mut a, k);
            let u = clean_u(k);
            let (out, inj) = tampered(&mut a, k, &u);
            if k < 300 {
                assert_eq!(out, u, "tick {k}");
                continue;
            }
            let want = clean_u(recorded[((k - 300) % n) as usize]);
            assert!((out - want).norm() < 1e-15, "tick {k}: {out:?} vs {want:?}");
            assert!(inj.in_force());
        }
    }

    #[test]
    fn position_and_velocity_channels_leave_the_torques_alone() {
        let mk = |signal, w| Channel {
            agent: 1,
            signal,
            links: vec![1, 2],
            units: ValueUnit::Rad,
            segments: vec![seg(0.0, w)],
        };
        let p = with_channels(vec![
            mk(Signal::Position, Waveform::Constant { value: 0.1 }),
            mk(Signal::Velocity, Waveform::SignFlip),
            mk(Signal::Position, Waveform::Scale { factor: 3.0 }),
        ]);
        assert!(p.problems(&dofs()).is_empty(), "{:?}", p.problems(&dofs()));
        assert!(!p.attacks_torque_of(1));
        let mut a = AgentAttack::compile(&p, 1, 1);
        for k in 0..100u64 {
            let m = clean([0.2, -0.1], [0.3, 0.4]);
            let (sent, inj) = a.measurement::<2>(k, tick(k), &m);
            assert!(inj.in_force() && inj.transforming);
            let got = sent.usable().expect("delivered").0;
            assert!((got.yd + m.yd).norm() == 0.0, "the velocity is flipped");
            assert!((got.y - (m.y * 3.0 + Vector::<2>::repeat(0.1))).norm() < 1e-15);
            let u = clean_u(k);
            let (out, inj) = tampered(&mut a, k, &u);
            assert_eq!(out, u, "tick {k}");
            assert_eq!(inj.u, Vector::<2>::zeros());
            assert!(!inj.in_force());
        }
    }

    #[test]
    fn value_channels_act_before_the_message_line_on_both_paths() {
        let text = r#"
            [[channels]]
            agent = 1
            signal = "position"
            links = [1]
            units = "rad"
            segments = [{ from_s = 0.0, waveform = { kind = "constant", value = 0.25 } }]

            [[channels]]
            agent = 1
            signal = "torque"
            links = [2]
            units = "Nm"
            segments = [{ from_s = 0.0, waveform = { kind = "constant", value = -0.5 } }]

            [[messages]]
            agent = 1
            path = "measurement"
            segments = [{ from_s = 0.01, effect = { kind = "forge-stamp", shift_s = 0.004 } }]

            [[messages]]
            agent = 1
            path = "torque"
            segments = [{ from_s = 0.01, effect = { kind = "delay", by_s = 0.002 } }]
        "#;
        let p: AttackProfile = toml::from_str(text).expect("parses");
        assert!(p.problems(&dofs()).is_empty(), "{:?}", p.problems(&dofs()));
        let mut a = AgentAttack::compile(&p, 1, 1);
        let m = clean([0.5, 0.6], [0.7, 0.8]);
        let u = Vector::<2>::new(1.0, 2.0);
        let (m_want, u_want) = (clean([0.75, 0.6], [0.7, 0.8]), Vector::<2>::new(1.0, 1.5));
        for k in [0u64, 9, 10, 11, 50] {
            let t = tick(k);
            let late = t >= 0.01;
            let (sent, inj) = a.measurement::<2>(k, t, &m);
            let want = if late {
                Sent::Forged {
                    payload: m_want,
                    shift_s: 0.004,
                }
            } else {
                Sent::on_time(m_want)
            };
            assert_eq!(sent, want, "tick {k}");
            assert_eq!(inj.message, late, "tick {k}");
            let (sent, inj) = a.torque::<2>(k, t, &u);
            let held_s = if late { 0.002 } else { 0.0 };
            assert_eq!(
                sent,
                Sent::Delivered {
                    payload: u_want,
                    held_s
                },
                "tick {k}"
            );
            assert_eq!(inj.message, late, "tick {k}");
            assert!(inj.in_force());
        }
    }

    #[test]
    fn units_that_do_not_fit_the_signal_are_reported_with_their_field_path() {
        let mk = |signal, units| Channel {
            agent: 1,
            signal,
            links: vec![1],
            units,
            segments: vec![seg(0.0, Waveform::Constant { value: 0.1 })],
        };
        let cases = [
            (Signal::Torque, ValueUnit::NewtonMetre, true),
            (Signal::Torque, ValueUnit::Rad, false),
            (Signal::Torque, ValueUnit::Deg, false),
            (Signal::Position, ValueUnit::Rad, true),
            (Signal::Position, ValueUnit::Deg, true),
            (Signal::Position, ValueUnit::NewtonMetre, false),
            (Signal::Velocity, ValueUnit::NewtonMetre, false),
            (Signal::Velocity, ValueUnit::Deg, true),
            (Signal::Velocity, ValueUnit::Rad, true),
            (Signal::Velocity, ValueUnit::DegPerS, true),
            (Signal::Velocity, ValueUnit::RadPerS, true),
            (Signal::Position, ValueUnit::DegPerS, false),
            (Signal::Position, ValueUnit::RadPerS, false),
            (Signal::Torque, ValueUnit::RadPerS, false),
        ];
        for (signal, units, fits) in cases {
            // Second in the list, so the index in the path is checked too.
            let p = with_channels(vec![
                mk(Signal::Position, ValueUnit::Rad),
                mk(signal, units),
            ]);
            let problems = p.problems(&dofs());
            let paths: Vec<&str> = problems.iter().map(|p| p.0.as_str()).collect();
            if fits {
                assert!(paths.is_empty(), "{signal:?} in {units:?}: {problems:?}");
            } else {
                assert_eq!(paths, ["channels[1].units"], "{signal:?} in {units:?}");
            }
        }
        // The refusal says which units the signal takes and what the file said.
        let p = with_channels(vec![mk(Signal::Position, ValueUnit::DegPerS)]);
        let problems = p.problems(&dofs());
        assert!(
            problems[0]
                .1
                .contains("a position channel's units are \"deg\" or \"rad\", got \"deg/s\""),
            "{problems:?}"
        );
        let p = with_channels(vec![mk(Signal::Velocity, ValueUnit::NewtonMetre)]);
        let problems = p.problems(&dofs());
        assert!(
            problems[0].1.contains("\"deg/s\" or \"rad/s\"")
                && problems[0].1.contains("got \"N·m\""),
            "{problems:?}"
        );
        // `deg/s` and `deg` on a velocity channel are one factor, π/180; `rad/s` and `rad` 1.
        assert_eq!(ValueUnit::DegPerS.factor(), ValueUnit::Deg.factor());
        assert_eq!(ValueUnit::RadPerS.factor(), ValueUnit::Rad.factor());
        for (spelling, units) in [("deg/s", ValueUnit::DegPerS), ("rad/s", ValueUnit::RadPerS)] {
            let text = format!(
                "[[channels]]\nagent = 1\nsignal = \"velocity\"\nlinks = [1]\nunits = \"{spelling}\"\n\
                 segments = [{{ from_s = 0.0, waveform = {{ kind = \"constant\", value = 1.0 }} }}]\n"
            );
            let p: AttackProfile = toml::from_str(&text).expect(spelling);
            assert_eq!(p.channels[0].units, units);
            assert!(p.problems(&dofs()).is_empty());
            assert_eq!(units.as_str(), spelling);
        }
        // The spellings of N·m.
        for spelling in ["N·m", "Nm", "N*m"] {
            let text = format!(
                "[[channels]]\nagent = 1\nsignal = \"torque\"\nlinks = [1]\nunits = \"{spelling}\"\n\
                 segments = [{{ from_s = 0.0, waveform = {{ kind = \"constant\", value = 1.0 }} }}]\n"
            );
            let p: AttackProfile = toml::from_str(&text).expect(spelling);
            assert_eq!(p.channels[0].units, ValueUnit::NewtonMetre);
            assert!(p.problems(&dofs()).is_empty());
        }
    }

    fn messages(entries: &[(u32, Path, Effect)]) -> AttackProfile {
        AttackProfile {
            messages: entries
                .iter()
                .map(|&(agent, path, effect)| MessageAttack {
                    agent,
                    path,
                    segments: vec![MessageSegment {
                        from_s: 1.0,
                        effect,
                    }],
                })
                .collect(),
            ..AttackProfile::default()
        }
    }

    #[test]
    fn message_entry_problems_are_reported_with_their_field_paths() {
        let drop = Effect::Drop { probability: 0.5 };
        let paths = |p: AttackProfile| -> Vec<String> {
            p.problems(&dofs()).into_iter().map(|p| p.0).collect()
        };
        // One entry per agent and path: fine.
        assert!(paths(messages(&[
            (1, Path::Measurement, drop),
            (1, Path::Torque, drop),
            (2, Path::Measurement, drop),
        ]))
        .is_empty());
        // The same agent and path twice: the second entry is reported, once per earlier entry.
        assert_eq!(
            paths(messages(&[
                (1, Path::Measurement, drop),
                (2, Path::Torque, drop),
                (1, Path::Measurement, Effect::Pass),
            ])),
            ["messages[2].path"]
        );
        let p = messages(&[(1, Path::Torque, drop), (1, Path::Torque, drop)]);
        let problems = p.problems(&dofs());
        assert!(problems[0].1.contains("messages[0]"), "{problems:?}");
        // An agent not in the scenario, and a bad value inside an entry.
        assert_eq!(
            paths(messages(&[
                (7, Path::Measurement, drop),
                (3, Path::Torque, Effect::Drop { probability: 1.5 }),
            ])),
            [
                "messages[0].agent",
                "messages[1].segments[0].effect.probability"
            ]
        );
        // `for_agents` keeps only the entries of the scenario's agents.
        let p = messages(&[(7, Path::Measurement, drop), (3, Path::Torque, drop)]);
        let kept = p.for_agents(&dofs());
        assert_eq!(kept.messages.len(), 1);
        assert!(paths(kept).is_empty());
    }

    #[test]
    fn torques_are_routed_through_the_attacker_exactly_for_the_agents_it_attacks_there() {
        let mut p = messages(&[
            (2, Path::Torque, Effect::Pass),
            (3, Path::Measurement, Effect::Drop { probability: 1.0 }),
        ]);
        p.channels = vec![
            torque_channel(vec![1], vec![seg(0.0, Waveform::Constant { value: 1.0 })]),
            Channel {
                agent: 4,
                signal: Signal::Velocity,
                links: vec![1],
                units: ValueUnit::Rad,
                segments: vec![seg(0.0, Waveform::Constant { value: 1.0 })],
            },
        ];
        for (agent, routed) in [(1, true), (2, true), (3, false), (4, false), (5, false)] {
            assert_eq!(p.attacks_torque_of(agent), routed, "agent {agent}");
        }
        assert!(!AttackProfile::default().attacks_torque_of(1));
    }

    #[test]
    fn every_shipped_preset_parses_and_has_no_problems_for_the_papers_four_robots() {
        // The presets that act on the torque path, and so route robot 1's commands through the
        // attacker.
        let torque_path = [
            "actuator-bias",
            "torque-delay",
            "dos-window",
            "forge-stamp",
            "covert",
        ];
        for (name, _) in presets::PRESETS {
            let p = presets::preset(name).unwrap_or_else(|| panic!("preset {name} parses"));
            let problems = p.problems(&dofs());
            assert!(problems.is_empty(), "preset {name}: {problems:?}");
            assert_eq!(
                p.clone().for_agents(&dofs()),
                p,
                "preset {name} only names the four robots"
            );
            for agent in 1..=4 {
                assert_eq!(
                    p.attacks_torque_of(agent),
                    agent == 1 && torque_path.contains(name),
                    "preset {name}, agent {agent}"
                );
            }
        }
        for name in [
            "actuator-bias",
            "torque-delay",
            "dos-drop",
            "dos-burst",
            "dos-window",
            "measurement-delay",
            "forge-stamp",
            "replay-original",
        ] {
            assert!(presets::names().contains(&name), "{name} is shipped");
            let p = presets::preset(name).expect("parses");
            let a = AgentAttack::compile(&p, 1, 1);
            assert!(
                !a.is_active(9.999) && a.is_active(10.0),
                "{name} starts at 10 s"
            );
            // Robot 2 is not attacked by any of them.
            let mut b = AgentAttack::compile(&p, 2, 1);
            for k in [10_000u64, 10_100] {
                measurement_untouched(&mut b, k);
                let u = clean_u(k);
                assert_eq!(tampered(&mut b, k, &u).0, u, "{name}: robot 2's torques");
            }
        }
    }

    #[test]
    fn the_message_flag_of_the_injections_follows_the_schedule() {
        let p = presets::preset("dos-window").expect("parses");
        let mut a = AgentAttack::compile(&p, 1, 1);
        let u = clean_u(0);
        for (t, on) in [(9.999, false), (10.0, true), (10.1, true), (10.2, false)] {
            let (sent, inj) = a.torque::<2>(0, t, &u);
            assert_eq!(inj.message, on, "t = {t}");
            assert_eq!(inj.in_force(), on, "t = {t}");
            assert_eq!(sent.usable().is_none(), on, "t = {t}");
            assert!(
                !a.injection::<2>(t).message,
                "the measurement path is not attacked"
            );
        }
        let p = presets::preset("dos-drop").expect("parses");
        let mut a = AgentAttack::compile(&p, 1, 1);
        for (t, on) in [(9.999, false), (10.0, true), (19.999, true), (20.0, false)] {
            let inj = a.injection::<2>(t);
            assert_eq!((inj.message, inj.in_force()), (on, on), "t = {t}");
            let (_, tinj) = a.torque::<2>(0, t, &u);
            assert!(
                !tinj.message && !tinj.in_force(),
                "the torque path is not attacked"
            );
        }
    }
}
