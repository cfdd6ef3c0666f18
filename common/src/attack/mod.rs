//! False-data-injection attack profiles as data (SPEC §3).
//!
//! A profile is a list of channels; a channel targets one agent, one signal (position or
//! velocity) and one or more links, and holds a time schedule of segments, each a
//! [`Waveform`]. A segment is in force from its `from_s` until the next segment begins.
//! Channels that target the same signal and link add up: every waveform, the transforms of the
//! clean signal (scale, sign flip, freeze) and replay included, is an injection `α` added to the
//! clean value, and `α` is what the attacker records.

pub mod presets;
pub mod waveform;

use std::collections::BTreeMap;

use rand_chacha::ChaCha12Rng;
use serde::{Deserialize, Serialize};

use crate::model::Vector;
use crate::plant::Measurement;
use crate::rng::{stream, Purpose};
use crate::units::AngleUnit;

pub use waveform::Waveform;

/// Which measured signal a channel tampers with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Signal {
    /// `y = q + S1`.
    Position,
    /// `ẏ = q̇ + S2`.
    Velocity,
}

/// One segment of a schedule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// Start time of the segment, s.
    pub from_s: f64,
    pub waveform: Waveform,
}

/// One attacked channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Channel {
    /// Agent id (as in the scenario's `[[agents]] id`).
    pub agent: u32,
    pub signal: Signal,
    /// 1-based link numbers this schedule is added to.
    pub links: Vec<u32>,
    /// Units of the waveform values: `deg` (deg, deg/s) or `rad` (rad, rad/s).
    pub units: AngleUnit,
    /// Segments in increasing `from_s`; before the first one nothing is injected.
    pub segments: Vec<Segment>,
}

/// A whole attack profile: what a `--attack FILE` holds, or a scenario's `[attack]` inline.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttackProfile {
    #[serde(default)]
    pub name: String,
    #[serde(default)]
    pub description: String,
    #[serde(default)]
    pub channels: Vec<Channel>,
}

impl AttackProfile {
    /// The profile without the channels of agents not in `agent_dofs` (used for presets, which
    /// are written for the paper's four robots, in scenarios with fewer agents).
    pub fn for_agents(mut self, agent_dofs: &BTreeMap<u32, usize>) -> Self {
        self.channels.retain(|c| agent_dofs.contains_key(&c.agent));
        self
    }

    /// Every problem of the profile, as `(field path relative to the profile, message)`.
    /// `agent_dofs` maps each agent id of the scenario to its number of links.
    pub fn problems(&self, agent_dofs: &BTreeMap<u32, usize>) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for (c, ch) in self.channels.iter().enumerate() {
            let at = |f: &str| format!("channels[{c}].{f}");
            let dof = agent_dofs.get(&ch.agent).copied();
            if dof.is_none() {
                out.push((
                    at("agent"),
                    format!(
                        "agent {} is not in the scenario (its agents: {})",
                        ch.agent,
                        agent_dofs
                            .keys()
                            .map(u32::to_string)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
            if ch.links.is_empty() {
                out.push((at("links"), "must name at least one link".into()));
            }
            for (l, &link) in ch.links.iter().enumerate() {
                if link == 0 || dof.is_some_and(|d| link as usize > d) {
                    out.push((
                        at(&format!("links[{l}]")),
                        format!(
                            "link {link} does not exist (links are 1-based, agent has {} links)",
                            dof.unwrap_or(0)
                        ),
                    ));
                }
            }
            if ch.segments.is_empty() {
                out.push((at("segments"), "must hold at least one segment".into()));
            }
            let mut prev = f64::NEG_INFINITY;
            for (s, seg) in ch.segments.iter().enumerate() {
                if !seg.from_s.is_finite() || seg.from_s < 0.0 {
                    out.push((
                        at(&format!("segments[{s}].from_s")),
                        format!("must be finite and ≥ 0, got {}", seg.from_s),
                    ));
                } else if seg.from_s <= prev {
                    out.push((
                        at(&format!("segments[{s}].from_s")),
                        format!("must increase: {} after {prev}", seg.from_s),
                    ));
                }
                prev = seg.from_s;
                for (field, msg) in seg.waveform.problems() {
                    out.push((at(&format!("segments[{s}].waveform.{field}")), msg));
                }
                if let Some((_, end)) = seg.waveform.replay_window() {
                    if seg.from_s < end {
                        out.push((
                            at(&format!("segments[{s}].from_s")),
                            format!(
                                "a replay must start at or after the end of its recording \
                                 (record_from_s + record_for_s = {end}), got {}: it cannot play \
                                 back what is not recorded yet",
                                seg.from_s
                            ),
                        ));
                    }
                }
            }
        }
        out
    }
}

/// A channel ready to evaluate: one link, one signal, values scaled to rad.
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
    /// The clean value of this signal and link at the last [`AgentAttack::observe`], rad or
    /// rad/s.
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
}

/// Injected values `α` at one tick, in rad and rad/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Injection<const N: usize> {
    pub position: Vector<N>,
    pub velocity: Vector<N>,
    /// A transforming segment (scale, sign flip, freeze) is in force on some link.
    pub transforming: bool,
}

impl<const N: usize> Injection<N> {
    /// The attack is in force: the injected value is non-zero on some link of either signal, or
    /// a transforming segment is in force. Every rising edge of this is an attack onset (a
    /// pulse train has one per pulse).
    pub fn in_force(&self) -> bool {
        self.transforming
            || self
                .position
                .iter()
                .chain(self.velocity.iter())
                .any(|x| *x != 0.0)
    }
}

/// The attack on one agent, compiled from a profile: what the attacker process evaluates.
#[derive(Debug, Clone)]
pub struct AgentAttack {
    channels: Vec<LinkChannel>,
}

impl AgentAttack {
    /// Compiles every channel of `profile` that targets `agent_id`; Gaussian waveforms draw from
    /// the stream `(run_seed, agent, AttackNoise { channel index })`.
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
                    scale: ch.units.to_rad(),
                    recordings: vec![Recording::default(); segments.len()],
                    frozen: vec![None; segments.len()],
                    segments,
                    rng: stream(run_seed, agent_id, Purpose::AttackNoise { channel }),
                    clean: 0.0,
                });
            }
        }
        Self { channels }
    }

    /// Shows the attacker the clean measurement of time `t`, before [`Self::injection`] of the
    /// same tick: `replay` channels record it inside their window and play back against it, a
    /// `freeze` segment in force keeps the value of its first tick, and the other transforms
    /// act on it.
    pub fn observe<const N: usize>(&mut self, t: f64, clean: &Measurement<N>) {
        for ch in &mut self.channels {
            if ch.link >= N {
                continue;
            }
            let v = match ch.signal {
                Signal::Position => clean.y[ch.link],
                Signal::Velocity => clean.yd[ch.link],
            };
            ch.clean = v;
            if let Some(i) = ch.segment_index(t) {
                if ch.segments[i].waveform == Waveform::Freeze && ch.frozen[i].is_none() {
                    ch.frozen[i] = Some(v);
                }
            }
            for (seg, rec) in ch.segments.iter().zip(&mut ch.recordings) {
                if let Some((from, to)) = seg.waveform.replay_window() {
                    if from <= t && t < to {
                        rec.times.push(t);
                        rec.values.push(v);
                    }
                }
            }
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
        };
        for ch in &mut self.channels {
            let Some(i) = ch.segment_index(t) else {
                continue;
            };
            let seg = ch.segments[i];
            if ch.link >= N {
                continue;
            }
            inj.transforming |= seg.waveform.transforms();
            let v = match seg.waveform {
                Waveform::Replay { .. } => ch.recordings[i]
                    .played(t - seg.from_s)
                    .map_or(0.0, |r| r - ch.clean),
                Waveform::Scale { factor } => waveform::transform::scale(ch.clean, factor),
                Waveform::SignFlip => waveform::transform::sign_flip(ch.clean),
                // Observed at this tick or before: never missing once the segment is in force.
                Waveform::Freeze => {
                    ch.frozen[i].map_or(0.0, |h| waveform::transform::freeze(ch.clean, h))
                }
                w => ch.scale * w.value(t, seg.from_s, &mut ch.rng),
            };
            match ch.signal {
                Signal::Position => inj.position[ch.link] += v,
                Signal::Velocity => inj.velocity[ch.link] += v,
            }
        }
        inj
    }

    /// True when some channel has a non-`none` segment in force at `t`.
    pub fn is_active(&self, t: f64) -> bool {
        self.channels
            .iter()
            .any(|ch| ch.segment_at(t).is_some_and(|s| !s.waveform.is_none()))
    }
}

#[cfg(test)]
mod tests {
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
                units: AngleUnit::Rad,
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
                units: AngleUnit::Deg,
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
            let (out, inj) = crate::engine::tamper(&mut a, t, &m);
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
}
