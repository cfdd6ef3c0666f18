//! The attack profile as data: what an attack file holds (`[[channels]]`, `[[messages]]`,
//! `[[covert]]`), with the checks of its values. [`super::AgentAttack`] compiles it for one agent.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::units::AngleUnit;

use super::covert;
use super::message::{MessageAttack, Path};
use super::waveform::Waveform;

/// Which measured signal a channel tampers with.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum Signal {
    /// `y = q + S1`.
    Position,
    /// `ẏ = q̇ + S2`.
    Velocity,
    /// The torque command `u` on its way to the agent (actuator FDI), N·m.
    Torque,
}

impl Signal {
    /// The path the signal travels on.
    pub fn path(self) -> Path {
        match self {
            Self::Position | Self::Velocity => Path::Measurement,
            Self::Torque => Path::Torque,
        }
    }
}

/// Units of a channel's values.
///
/// A position channel takes `deg` or `rad`, a velocity channel `deg/s` or `rad/s` (or, as the
/// shipped profiles long wrote them, `deg` and `rad` standing for deg/s and rad/s), a torque
/// channel `N·m` (also spelled `Nm` or `N*m`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ValueUnit {
    /// deg (positions; on a velocity channel it stands for deg/s).
    #[serde(rename = "deg")]
    Deg,
    /// rad (positions; on a velocity channel it stands for rad/s).
    #[serde(rename = "rad")]
    Rad,
    /// deg/s (velocities).
    #[serde(rename = "deg/s")]
    DegPerS,
    /// rad/s (velocities).
    #[serde(rename = "rad/s")]
    RadPerS,
    /// N·m (torques).
    #[serde(rename = "N·m", alias = "Nm", alias = "N*m")]
    NewtonMetre,
}

/// Every spelling `Deserialize` accepts (the derive would leave out the aliases of N·m).
impl schemars::JsonSchema for ValueUnit {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "ValueUnit".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "Units of the channel's values: \"deg\" or \"rad\" for a position channel; \"deg/s\" or \"rad/s\" for a velocity channel (\"deg\" and \"rad\" are accepted there too and mean deg/s and rad/s); \"N·m\" (or \"Nm\", \"N*m\") for a torque channel.",
            "type": "string",
            "enum": ["deg", "rad", "deg/s", "rad/s", "N·m", "Nm", "N*m"]
        })
    }
}

impl ValueUnit {
    /// Factor that converts a value in these units to the runtime's (rad, rad/s, N·m).
    pub fn factor(self) -> f64 {
        match self {
            Self::Deg | Self::DegPerS => AngleUnit::Deg.to_rad(),
            Self::Rad | Self::RadPerS => AngleUnit::Rad.to_rad(),
            Self::NewtonMetre => 1.0,
        }
    }

    /// Whether values of `signal` can be in these units.
    fn fits(self, signal: Signal) -> bool {
        match signal {
            Signal::Position => matches!(self, Self::Deg | Self::Rad),
            Signal::Velocity => {
                matches!(self, Self::Deg | Self::Rad | Self::DegPerS | Self::RadPerS)
            }
            Signal::Torque => self == Self::NewtonMetre,
        }
    }

    /// The units as a file spells them.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Deg => "deg",
            Self::Rad => "rad",
            Self::DegPerS => "deg/s",
            Self::RadPerS => "rad/s",
            Self::NewtonMetre => "N·m",
        }
    }
}

/// One segment of a schedule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// Start time of the segment, s.
    pub from_s: f64,
    /// What is injected: `{ kind = "…", … }`.
    pub waveform: Waveform,
}

/// One attacked channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Channel {
    /// Agent id (as in the scenario's `[[agents]] id`).
    pub agent: u32,
    /// `"position"`, `"velocity"` or `"torque"`.
    pub signal: Signal,
    /// 1-based link numbers this schedule is added to.
    pub links: Vec<u32>,
    /// Units of the waveform values: `deg` or `rad` for positions, `deg/s` or `rad/s` for
    /// velocities (`deg` and `rad` mean deg/s and rad/s there), `N·m` for torques.
    pub units: ValueUnit,
    /// Segments in increasing `from_s`; before the first one nothing is injected.
    pub segments: Vec<Segment>,
}

/// A whole attack profile: what a `--attack FILE` holds, or a scenario's `[attack]` inline.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AttackProfile {
    /// Name of the profile (shown in summaries and reports).
    #[serde(default)]
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// `[[channels]]`: value attacks, each on one agent, signal and set of links.
    #[serde(default)]
    pub channels: Vec<Channel>,
    /// Whole-message attacks, at most one per agent and path.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub messages: Vec<MessageAttack>,
    /// Covert attacks: the effect of an agent's torque channels hidden from its measurements
    /// ([`covert`]), at most one per agent.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub covert: Vec<covert::CovertEntry>,
}

impl AttackProfile {
    /// The profile without the channels of agents not in `agent_dofs` (used for presets, which
    /// are written for the paper's four robots, in scenarios with fewer agents).
    pub fn for_agents(mut self, agent_dofs: &BTreeMap<u32, usize>) -> Self {
        self.channels.retain(|c| agent_dofs.contains_key(&c.agent));
        self.messages.retain(|m| agent_dofs.contains_key(&m.agent));
        self.covert.retain(|c| agent_dofs.contains_key(&c.agent));
        self
    }

    /// Whether the profile attacks agent `agent`'s torque commands: then they travel control
    /// center → attacker → agent; otherwise straight to the agent.
    pub fn attacks_torque_of(&self, agent: u32) -> bool {
        self.channels
            .iter()
            .any(|c| c.agent == agent && c.signal == Signal::Torque)
            || self
                .messages
                .iter()
                .any(|m| m.agent == agent && m.path == Path::Torque)
    }

    /// Every problem [`Self::problems`] finds without a scenario: each agent the profile names
    /// is taken to exist with as many links as the profile names (what needs a scenario, that
    /// the agents and links exist, is left unchecked; link 0 is still refused).
    pub fn problems_alone(&self) -> Vec<(String, String)> {
        let agents = self
            .channels
            .iter()
            .map(|c| c.agent)
            .chain(self.messages.iter().map(|m| m.agent))
            .chain(self.covert.iter().map(|c| c.agent));
        self.problems(&agents.map(|a| (a, usize::MAX)).collect())
    }

    /// The agents the profile names, in increasing order, each once.
    pub fn agents(&self) -> Vec<u32> {
        let mut out: Vec<u32> = self
            .channels
            .iter()
            .map(|c| c.agent)
            .chain(self.messages.iter().map(|m| m.agent))
            .chain(self.covert.iter().map(|c| c.agent))
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// When the first attack on `agent` starts acting, s: the earliest start of a segment that
    /// injects something (a waveform other than `none`), of a message segment other than
    /// `pass`, or of a covert attack. `None`: the profile never attacks it.
    pub fn first_action_s(&self, agent: u32) -> Option<f64> {
        let channels = self
            .channels
            .iter()
            .filter(|c| c.agent == agent)
            .flat_map(|c| &c.segments)
            .filter(|s| !s.waveform.is_none())
            .map(|s| s.from_s);
        let messages = self
            .messages
            .iter()
            .filter(|m| m.agent == agent)
            .flat_map(|m| &m.segments)
            .filter(|s| s.effect != super::message::Effect::Pass)
            .map(|s| s.from_s);
        let covert = self
            .covert
            .iter()
            .filter(|c| c.agent == agent)
            .map(|c| c.from_s);
        channels.chain(messages).chain(covert).reduce(f64::min)
    }

    /// Every problem of the profile, as `(field path relative to the profile, message)`.
    /// `agent_dofs` maps each agent id of the scenario to its number of links.
    pub fn problems(&self, agent_dofs: &BTreeMap<u32, usize>) -> Vec<(String, String)> {
        let mut out = Vec::new();
        if let Some(why) = crate::files::unprintable(&self.name) {
            out.push(("name".into(), why));
        }
        self.covert_problems(agent_dofs, &mut out);
        self.message_problems(agent_dofs, &mut out);
        self.channel_problems(agent_dofs, &mut out);
        out
    }

    /// The problems of `covert`.
    fn covert_problems(&self, agent_dofs: &BTreeMap<u32, usize>, out: &mut Vec<(String, String)>) {
        let unknown = |agent: u32| unknown_agent(agent, agent_dofs);
        for (i, c) in self.covert.iter().enumerate() {
            let at = |f: &str| format!("covert[{i}].{f}");
            if !agent_dofs.contains_key(&c.agent) {
                out.push((at("agent"), unknown(c.agent)));
            } else if !self
                .channels
                .iter()
                .any(|ch| ch.agent == c.agent && ch.signal == Signal::Torque)
            {
                out.push((
                    at("agent"),
                    format!(
                        "a covert attack hides a torque injection, and agent {} has no torque \
                         channel",
                        c.agent
                    ),
                ));
            }
            if self.covert[..i].iter().any(|o| o.agent == c.agent) {
                out.push((at("agent"), format!("agent {} is covered twice", c.agent)));
            }
            if !c.from_s.is_finite() || c.from_s < 0.0 {
                out.push((
                    at("from_s"),
                    format!("must be finite and ≥ 0, got {}", c.from_s),
                ));
            }
        }
    }

    /// The problems of `messages`.
    fn message_problems(&self, agent_dofs: &BTreeMap<u32, usize>, out: &mut Vec<(String, String)>) {
        let unknown = |agent: u32| unknown_agent(agent, agent_dofs);
        for (m, msg) in self.messages.iter().enumerate() {
            if !agent_dofs.contains_key(&msg.agent) {
                out.push((format!("messages[{m}].agent"), unknown(msg.agent)));
            }
            if let Some(first) = self.messages[..m]
                .iter()
                .position(|o| o.agent == msg.agent && o.path == msg.path)
            {
                out.push((
                    format!("messages[{m}].path"),
                    format!(
                        "agent {}'s {} path is already attacked by messages[{first}]: put \
                         both schedules' segments in one entry",
                        msg.agent,
                        msg.path.as_str()
                    ),
                ));
            }
            for (field, problem) in msg.problems() {
                out.push((format!("messages[{m}].{field}"), problem));
            }
        }
    }

    /// The problems of `channels`.
    fn channel_problems(&self, agent_dofs: &BTreeMap<u32, usize>, out: &mut Vec<(String, String)>) {
        let unknown = |agent: u32| unknown_agent(agent, agent_dofs);
        for (c, ch) in self.channels.iter().enumerate() {
            let at = |f: &str| format!("channels[{c}].{f}");
            let dof = agent_dofs.get(&ch.agent).copied();
            if dof.is_none() {
                out.push((at("agent"), unknown(ch.agent)));
            }
            if !ch.units.fits(ch.signal) {
                out.push((
                    at("units"),
                    match ch.signal {
                        Signal::Torque => format!(
                            "a torque channel's units are \"N·m\", got \"{}\"",
                            ch.units.as_str()
                        ),
                        Signal::Position => format!(
                            "a position channel's units are \"deg\" or \"rad\", got \"{}\"",
                            ch.units.as_str()
                        ),
                        Signal::Velocity => format!(
                            "a velocity channel's units are \"deg/s\" or \"rad/s\" (\"deg\" \
                             and \"rad\" also mean deg/s and rad/s there), got \"{}\"",
                            ch.units.as_str()
                        ),
                    },
                ));
            }
            if ch.links.is_empty() {
                out.push((at("links"), "must name at least one link".into()));
            }
            for (l, &link) in ch.links.iter().enumerate() {
                let message = match dof {
                    _ if link == 0 => Some("link 0 does not exist (links are 1-based)".to_string()),
                    Some(d) if link as usize > d => Some(format!(
                        "link {link} does not exist (links are 1-based, agent {} has {d} link{})",
                        ch.agent,
                        if d == 1 { "" } else { "s" }
                    )),
                    _ => None,
                };
                if let Some(message) = message {
                    out.push((at(&format!("links[{l}]")), message));
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
    }
}

/// `agent N is not in the scenario (its agents: …)`.
fn unknown_agent(agent: u32, agent_dofs: &BTreeMap<u32, usize>) -> String {
    format!(
        "agent {agent} is not in the scenario (its agents: {})",
        agent_dofs
            .keys()
            .map(u32::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    )
}
