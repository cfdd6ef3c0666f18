//! Attacks on whole messages, on either path (docs/attacks.md): denial of service (drop with a
//! probability, in bursts, or over a window), delay, stamp forgery and replay with the original
//! header. A profile's `[[messages]]` entry targets one agent and one path, with a time schedule
//! of segments, each an [`Effect`] in force from its `from_s` until the next segment begins.
//!
//! The effects act on the message after the value channels (`[[channels]]`) tampered it. What
//! reaches the receiver is a [`Sent`]; every receiver, in both engines, treats a tick whose
//! message is not [`Sent::Delivered`] the same way: the tick's input is missing (the control
//! center holds its last measurement, the agent holds its last torque and counts a miss).

use std::collections::VecDeque;

use rand::Rng;
use rand_chacha::ChaCha12Rng;
use serde::{Deserialize, Serialize};

use crate::records::Delivery;

/// Which path a message attack acts on.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum Path {
    /// Agent → control center: the measurements.
    Measurement,
    /// Control center → agent: the torque commands (the actuation path through the attacker).
    Torque,
}

/// What happens to each message of a segment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Effect {
    /// Every message goes through.
    Pass,
    /// Denial of service: each message is dropped with `probability` (drawn from the
    /// attacker's seeded stream); `probability = 1` drops the whole segment (a window).
    Drop {
        /// Probability that a message is dropped, in [0, 1].
        probability: f64,
    },
    /// Denial of service in bursts: a two-state (Gilbert) channel, sampled at each message.
    /// Bursts of drops last `mean_length_s` on average and come `mean_gap_s` apart on average
    /// (both exponentially distributed); the channel starts the segment in its good state.
    Burst {
        /// Mean time between bursts, s (> 0).
        mean_gap_s: f64,
        /// Mean length of a burst, s (> 0).
        mean_length_s: f64,
    },
    /// Hold messages back by `d(t) = by_s + amplitude_s · sin(rate_rad_s · t)` (≥ 0). On the
    /// torque path the command takes effect `d` later than the channel's known delay `τ`; on
    /// the measurement path the center gets, at each tick, the newest measurement delivered by
    /// then (sent `d` or more ago), under the tick's header.
    Delay {
        /// Mean hold-back, s (≥ |amplitude_s|).
        by_s: f64,
        /// Amplitude of its variation, s (default 0).
        #[serde(default)]
        amplitude_s: f64,
        /// Angular rate of its variation, rad/s (default 0).
        #[serde(default)]
        rate_rad_s: f64,
    },
    /// Timestamp forgery: the message's stamp (`t` of a measurement, `t_send` of a torque) is
    /// moved by `shift_s` (≠ 0). Receivers check the stamp against the sequence number and
    /// refuse the message: the tick's input is missing.
    ForgeStamp {
        /// Shift of the stamp, s (≠ 0).
        shift_s: f64,
    },
    /// Replay with the original header: the messages sent over
    /// `[record_from_s, record_from_s + record_for_s)` are re-sent in a loop, with their own
    /// sequence numbers and stamps, in place of the live ones from the segment's start.
    /// Receivers refuse them as stale: the tick's input is missing.
    ReplayOriginal {
        /// Start of the recording window, s (≥ 0).
        record_from_s: f64,
        /// Length of the recording window, s (> 0).
        record_for_s: f64,
    },
}

impl Path {
    /// The path as a file names it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Measurement => "measurement",
            Self::Torque => "torque",
        }
    }
}

impl Effect {
    /// Every problem of the effect's parameters, as `(field, message)`.
    pub fn problems(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        let mut check = |field: &str, v: f64, ok: bool, what: &str| {
            if !v.is_finite() || !ok {
                out.push((field.to_string(), format!("must be {what}, got {v}")));
            }
        };
        match *self {
            Self::Pass => {}
            Self::Drop { probability } => check(
                "probability",
                probability,
                (0.0..=1.0).contains(&probability),
                "a probability in [0, 1]",
            ),
            Self::Burst {
                mean_gap_s,
                mean_length_s,
            } => {
                check("mean_gap_s", mean_gap_s, mean_gap_s > 0.0, "finite and > 0");
                check(
                    "mean_length_s",
                    mean_length_s,
                    mean_length_s > 0.0,
                    "finite and > 0",
                );
            }
            Self::Delay {
                by_s,
                amplitude_s,
                rate_rad_s,
            } => {
                check(
                    "by_s",
                    by_s,
                    by_s >= amplitude_s.abs(),
                    "finite and ≥ |amplitude_s| (a delay is never negative)",
                );
                check("amplitude_s", amplitude_s, true, "finite");
                check("rate_rad_s", rate_rad_s, true, "finite");
            }
            Self::ForgeStamp { shift_s } => {
                check("shift_s", shift_s, shift_s != 0.0, "finite and ≠ 0");
            }
            Self::ReplayOriginal {
                record_from_s,
                record_for_s,
            } => {
                check(
                    "record_from_s",
                    record_from_s,
                    record_from_s >= 0.0,
                    "finite and ≥ 0",
                );
                check(
                    "record_for_s",
                    record_for_s,
                    record_for_s > 0.0,
                    "finite and > 0",
                );
            }
        }
        out
    }

    /// The recording window `[from, to)` of a `replay-original`, s.
    pub fn replay_window(&self) -> Option<(f64, f64)> {
        match *self {
            Self::ReplayOriginal {
                record_from_s,
                record_for_s,
            } => Some((record_from_s, record_from_s + record_for_s)),
            _ => None,
        }
    }

    /// `d(t)` of a `delay`, s.
    fn delay(&self, t: f64) -> Option<f64> {
        match *self {
            Self::Delay {
                by_s,
                amplitude_s,
                rate_rad_s,
            } => Some(by_s + amplitude_s * (rate_rad_s * t).sin()),
            _ => None,
        }
    }
}

/// One segment of a message schedule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MessageSegment {
    /// Start time of the segment, s.
    pub from_s: f64,
    /// What happens to the messages: `{ kind = "…", … }`.
    pub effect: Effect,
}

/// One agent's messages on one path, attacked.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MessageAttack {
    /// Agent id (as in the scenario's `[[agents]] id`).
    pub agent: u32,
    /// `"measurement"` (agent → center) or `"torque"` (center → agent).
    pub path: Path,
    /// Segments in increasing `from_s`; before the first one every message goes through.
    pub segments: Vec<MessageSegment>,
}

impl MessageAttack {
    /// Every problem of the schedule, as `(field path relative to the entry, message)`.
    pub fn problems(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        if self.segments.is_empty() {
            out.push(("segments".into(), "must hold at least one segment".into()));
        }
        let mut prev = f64::NEG_INFINITY;
        for (s, seg) in self.segments.iter().enumerate() {
            let at = |f: &str| format!("segments[{s}].{f}");
            if !seg.from_s.is_finite() || seg.from_s < 0.0 {
                out.push((
                    at("from_s"),
                    format!("must be finite and ≥ 0, got {}", seg.from_s),
                ));
            } else if seg.from_s <= prev {
                out.push((
                    at("from_s"),
                    format!("must increase: {} after {prev}", seg.from_s),
                ));
            }
            prev = seg.from_s;
            for (field, msg) in seg.effect.problems() {
                out.push((at(&format!("effect.{field}")), msg));
            }
            if let Some((_, end)) = seg.effect.replay_window() {
                if seg.from_s < end {
                    out.push((
                        at("from_s"),
                        format!(
                            "a replay must start at or after the end of its recording \
                             (record_from_s + record_for_s = {end}), got {}",
                            seg.from_s
                        ),
                    ));
                }
            }
        }
        out
    }
}

/// What the attacker sends on for the message of one tick, and what the receiver makes of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sent<P> {
    /// The receiver takes `payload` as the tick's input; on the torque path it takes effect
    /// `held_s` later than the channel's known delay.
    Delivered { payload: P, held_s: f64 },
    /// Nothing arrives for the tick (dropped, or nothing delivered yet under a delay).
    Missing,
    /// `payload` is sent with its stamp moved by `shift_s`; the receiver refuses it.
    Forged { payload: P, shift_s: f64 },
    /// The message of tick `k` is re-sent with its original header; the receiver refuses it.
    Replayed { k: u64, payload: P },
}

impl<P> Sent<P> {
    /// `payload` delivered on time, as it is.
    pub fn on_time(payload: P) -> Self {
        Self::Delivered {
            payload,
            held_s: 0.0,
        }
    }

    /// What the record says about it.
    pub fn delivery(&self) -> Delivery {
        match self {
            Self::Delivered { .. } => Delivery::Delivered,
            Self::Missing => Delivery::Missing,
            Self::Forged { .. } => Delivery::Forged,
            Self::Replayed { .. } => Delivery::Replayed,
        }
    }

    /// The tick's input, when the receiver has one: the payload and how much later than the
    /// channel's delay it takes effect.
    pub fn usable(&self) -> Option<(&P, f64)> {
        match self {
            Self::Delivered { payload, held_s } => Some((payload, *held_s)),
            _ => None,
        }
    }
}

/// A compiled message schedule: one agent, one path.
#[derive(Debug, Clone)]
pub(super) struct MessageLine<P> {
    pub(super) path: Path,
    segments: Vec<MessageSegment>,
    rng: ChaCha12Rng,
    /// Burst: the channel is in its bad state; `last_t`: time of the previous message.
    bad: bool,
    /// Burst: the segment the channel's state belongs to (a new segment starts good).
    burst_segment: Option<usize>,
    last_t: Option<f64>,
    /// Per segment, the messages a `replay-original` recorded: `(k, payload)`.
    recordings: Vec<Vec<(u64, P)>>,
    /// Per segment, the messages a `replay-original` has re-sent so far.
    played: Vec<u64>,
    /// Measurement path under a delay: messages not yet delivered, `(arrival time, k,
    /// payload)`, and the newest delivered so far.
    in_transit: VecDeque<(f64, u64, P)>,
    newest: Option<(u64, P)>,
}

impl<P: Copy> MessageLine<P> {
    pub(super) fn compile(attack: &MessageAttack, rng: ChaCha12Rng) -> Self {
        let mut segments = attack.segments.clone();
        segments.sort_by(|a, b| a.from_s.total_cmp(&b.from_s));
        Self {
            path: attack.path,
            recordings: vec![Vec::new(); segments.len()],
            played: vec![0; segments.len()],
            segments,
            rng,
            bad: false,
            burst_segment: None,
            last_t: None,
            in_transit: VecDeque::new(),
            newest: None,
        }
    }

    fn segment_index(&self, t: f64) -> Option<usize> {
        self.segments
            .partition_point(|s| s.from_s <= t)
            .checked_sub(1)
    }

    /// A segment with an effect other than `pass` is in force at `t`.
    pub(super) fn in_force(&self, t: f64) -> bool {
        self.segment_index(t)
            .is_some_and(|i| self.segments[i].effect != Effect::Pass)
    }

    /// The fate of the message of tick `k` (time `t`), already tampered by the value channels.
    /// Called once per tick, in tick order.
    pub(super) fn send(&mut self, k: u64, t: f64, payload: P) -> Sent<P> {
        for (seg, rec) in self.segments.iter().zip(&mut self.recordings) {
            if let Some((from, to)) = seg.effect.replay_window() {
                if from <= t && t < to {
                    rec.push((k, payload));
                }
            }
        }
        let since = self.last_t.map_or(0.0, |p| t - p);
        self.last_t = Some(t);
        let Some(i) = self.segment_index(t) else {
            return self.delivered(t, k, payload, None);
        };
        let seg = self.segments[i];
        match seg.effect {
            Effect::Pass => self.delivered(t, k, payload, None),
            Effect::Drop { probability } => {
                // One draw per message, dropped or not: the stream stays aligned with the ticks.
                let u: f64 = self.rng.random();
                if u < probability {
                    Sent::Missing
                } else {
                    self.delivered(t, k, payload, None)
                }
            }
            Effect::Burst {
                mean_gap_s,
                mean_length_s,
            } => {
                if self.burst_segment != Some(i) {
                    self.burst_segment = Some(i);
                    self.bad = false;
                }
                let mean = if self.bad { mean_length_s } else { mean_gap_s };
                let u: f64 = self.rng.random();
                if u < 1.0 - (-since / mean).exp() {
                    self.bad = !self.bad;
                }
                if self.bad {
                    Sent::Missing
                } else {
                    self.delivered(t, k, payload, None)
                }
            }
            Effect::Delay { .. } => self.delivered(t, k, payload, seg.effect.delay(t)),
            Effect::ForgeStamp { shift_s } => Sent::Forged { payload, shift_s },
            Effect::ReplayOriginal { .. } => {
                // One recorded message per tick from the segment's start, in a loop.
                let played = self.played[i];
                self.played[i] += 1;
                let rec = &self.recordings[i];
                match rec.get((played % rec.len().max(1) as u64) as usize) {
                    Some(&(k, payload)) => Sent::Replayed { k, payload },
                    None => Sent::Missing,
                }
            }
        }
    }

    /// A message that goes through, `held` back by a delay (none: `None`).
    fn delivered(&mut self, t: f64, k: u64, payload: P, held: Option<f64>) -> Sent<P> {
        match (self.path, held) {
            (Path::Torque, held) => Sent::Delivered {
                payload,
                held_s: held.unwrap_or(0.0),
            },
            (Path::Measurement, None) if self.in_transit.is_empty() => {
                self.newest = Some((k, payload));
                Sent::Delivered {
                    payload,
                    held_s: 0.0,
                }
            }
            (Path::Measurement, held) => {
                self.in_transit
                    .push_back((t + held.unwrap_or(0.0), k, payload));
                // Delivered by now: every message whose arrival is not later than `t`; the
                // newest of them (by tick) is what the center gets.
                let mut i = 0;
                while i < self.in_transit.len() {
                    let (arrival, mk, mp) = self.in_transit[i];
                    if arrival <= t {
                        if self.newest.is_none_or(|(nk, _)| mk > nk) {
                            self.newest = Some((mk, mp));
                        }
                        self.in_transit.remove(i);
                    } else {
                        i += 1;
                    }
                }
                match self.newest {
                    Some((_, payload)) => Sent::Delivered {
                        payload,
                        held_s: 0.0,
                    },
                    None => Sent::Missing,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
