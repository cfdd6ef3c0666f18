//! The scenario: everything a run needs, as TOML (serde, `deny_unknown_fields`), then
//! [`Scenario::validate`] that returns every problem with its field path.
//!
//! Parameters carry their units in their names; typical values are the paper's (docs/model.md, "Gains (the calibration)").

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::attack::{presets, AgentAttack, AttackProfile, ProfileAttacker};
use crate::collect::Collected;
use crate::control::CenterParams;
pub use crate::control::{
    ControllerConfig, ControllerMode, DetectionConfig, ObserverInput, UpdateLaw,
};
use crate::delay::DelayProfile;
pub use crate::detect::DetectorsConfig;
use crate::field_path::Seg;
/// [`crate::files`]: the reader of scenario, attack, campaign and deployment files.
pub use crate::files::read_limited;
pub use crate::model::ModelConfig;
use crate::plant::PlantParams;
pub use crate::plant::{DisturbanceConfig, DisturbanceLink, NoiseConfig};
use crate::trajectory::TrajectoryConfig;

/// [`crate::limits`]: the largest robot and the largest input file.
pub use crate::limits::{MAX_DOF, MAX_FILE_BYTES};
/// [`crate::problem`]: one problem of the values, with its field path.
pub use crate::problem::Problem;

/// Largest number of agents a scenario may hold.
pub const MAX_AGENTS: usize = 256;
/// `validate` warns about a controller gain more than this many times its calibration.
pub const IMPLAUSIBLE_FACTOR: f64 = 100.0;
/// The paper calibration's `gain_k` (docs/model.md, "Gains (the calibration)").
const CALIBRATED_GAIN_K: f64 = 21.0;
/// `validate` warns about a reference turning more than this per control period, rad.
pub const MAX_PHASE_PER_PERIOD_RAD: f64 = 0.1;
/// `validate` warns about an attack injecting more than this, rad or rad/s.
pub const MAX_PLAUSIBLE_ATTACK_RAD: f64 = 10.0;

/// The embedded default scenario: the paper's experiment (identical to `scenarios/paper.toml`).
pub const PAPER_SCENARIO: &str = include_str!("../../scenarios/paper.toml");

/// How processes are clocked (docs/model.md, "Clocks").
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema, Default,
)]
#[serde(rename_all = "kebab-case")]
pub enum ClockMode {
    /// Deterministic, as fast as the machine allows.
    #[default]
    Lockstep,
    /// Physics paced by the wall clock.
    Realtime,
}

impl ClockMode {
    /// Every clock, in the order the help lists them.
    pub const ALL: [Self; 2] = [Self::Lockstep, Self::Realtime];

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Lockstep => "lockstep",
            Self::Realtime => "realtime",
        }
    }
}

impl std::str::FromStr for ClockMode {
    type Err = String;

    /// The names of a scenario file: `lockstep` or `realtime`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|c| c.as_str() == s)
            .ok_or_else(|| format!("`{s}` is not a clock: lockstep or realtime"))
    }
}

/// One agent (`[[agents]]`). `model`, `trajectory` and `delay` may be left out when
/// `[defaults]` sets them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = agent_keys_from_defaults)]
pub struct AgentConfig {
    /// Unique id ≥ 1; attack channels refer to it.
    #[schemars(range(min = 1))]
    pub id: u32,
    /// The robot: `{ kind = "two-link" | "three-link", … }`.
    pub model: ModelConfig,
    /// The desired trajectory `q_d(t)`.
    pub trajectory: TrajectoryConfig,
    /// The known time-varying delay `τ(t)` of the torque channel.
    pub delay: DelayProfile,
    /// `[agents.disturbance]`: this robot's own disturbance `d(t)`, one entry per joint, in
    /// place of the scenario's `[disturbance]` (a team that mixes robots of different joint
    /// counts gives one to each robot the scenario's does not fit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disturbance: Option<DisturbanceConfig>,
    /// `[agents.gains]`: this robot's own `gain_k` and `gain_scaling` in place of
    /// `[controller]`'s (a team of different robots needs gains per robot; `beta` stays the
    /// team's: the detectors' residual `S = S₂ + β S₁` is read with it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gains: Option<AgentGains>,
}

/// `[agents.gains]`: a robot's own gains; a field left out is `[controller]`'s.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AgentGains {
    /// `k` of `u = K r̂` for this robot.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_k: Option<f64>,
    /// How `k` becomes this robot's `K`: `"unit"` or `"inertia"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_scaling: Option<crate::control::GainScaling>,
}

/// The keys of an agent that `[defaults]` can supply.
const DEFAULTABLE_AGENT_KEYS: [&str; 3] = ["model", "trajectory", "delay"];

/// Schema of `[[agents]]` as a file holds it: only `id` is required of every agent; the
/// scenario's schema requires the others of each agent when `[defaults]` lacks them
/// ([`agents_need_what_defaults_lack`]).
fn agent_keys_from_defaults(schema: &mut schemars::Schema) {
    if let Some(serde_json::Value::Array(required)) = schema.get_mut("required") {
        required.retain(|k| !DEFAULTABLE_AGENT_KEYS.iter().any(|d| k == d));
    }
}

/// `[defaults]` supplies a key to every agent that lacks it, so each agent needs the key only
/// when `[defaults]` does not set it: one `if`/`else` per key.
fn agents_need_what_defaults_lack(schema: &mut schemars::Schema) {
    let rules: Vec<serde_json::Value> = DEFAULTABLE_AGENT_KEYS
        .iter()
        .map(|key| {
            serde_json::json!({
                "if": {
                    "required": ["defaults"],
                    "properties": { "defaults": { "type": "object", "required": [key] } }
                },
                "else": {
                    "properties": { "agents": { "items": { "required": [key] } } }
                }
            })
        })
        .collect();
    schema.insert("allOf".into(), serde_json::Value::Array(rules));
}

/// Bounds every integer of a schema by the range of its Rust type (schemars names the type in
/// `format` only, which validators take as an annotation): a value out of range is refused by
/// the schema as the loader refuses it.
fn bound_integers(schema: &mut schemars::Schema) {
    let max = match schema.get("format").and_then(serde_json::Value::as_str) {
        Some("uint8") => Some(u64::from(u8::MAX)),
        Some("uint16") => Some(u64::from(u16::MAX)),
        Some("uint32") => Some(u64::from(u32::MAX)),
        Some("uint64" | "uint") => Some(u64::MAX),
        _ => None,
    };
    if let Some(max) = max {
        schema.insert("maximum".into(), max.into());
    }
    schemars::transform::transform_subschemas(&mut bound_integers, schema);
}

/// Takes `null` out of the types an optional key accepts: TOML has no null (a key left out is
/// absent, which `required` already allows).
fn no_null(schema: &mut schemars::Schema) {
    use serde_json::Value;
    if let Some(Value::Array(types)) = schema.get_mut("type") {
        types.retain(|t| t != "null");
        if let [only] = types.as_slice() {
            let only = only.clone();
            schema.insert("type".into(), only);
        }
    }
    let is_null = |v: &Value| v.get("type").is_some_and(|t| t == "null");
    if let Some(Value::Array(any)) = schema.get_mut("anyOf") {
        any.retain(|v| !is_null(v));
        if any.len() == 1 {
            let only = any.clone();
            schema.remove("anyOf");
            schema.insert("allOf".into(), Value::Array(only));
        }
    }
    schemars::transform::transform_subschemas(&mut no_null, schema);
}

/// `attack.preset`: one of the shipped presets.
fn preset_names(schema: &mut schemars::Schema) {
    if let Some(preset) = schema
        .get_mut("properties")
        .and_then(|p| p.get_mut("preset"))
        .and_then(serde_json::Value::as_object_mut)
    {
        preset.insert("enum".into(), presets::names().into());
    }
}

/// A draft-7 schema (what TOML editors read) of `T`.
fn file_schema<T: schemars::JsonSchema>() -> serde_json::Value {
    let schema = schemars::generate::SchemaSettings::draft07()
        .with_transform(bound_integers)
        .with_transform(no_null)
        .into_generator()
        .into_root_schema_for::<T>();
    serde_json::Value::from(schema)
}

/// The JSON Schema (draft 7) of scenario files, from the types above and their doc comments
/// (`fdi-launch schema scenario`; shipped as `scenarios/schema/scenario.schema.json`). It
/// checks keys and types; the values' ranges and their consistency `validate` checks.
pub fn scenario_schema() -> serde_json::Value {
    file_schema::<Scenario>()
}

/// The JSON Schema (draft 7) of attack-profile files (`fdi-launch schema attack`; shipped as
/// `scenarios/schema/attack.schema.json`). It checks keys, types and the units' spellings; what
/// needs a scenario (that the agents and links exist) only `validate` checks.
pub fn attack_schema() -> serde_json::Value {
    file_schema::<AttackProfile>()
}

/// `[defaults]`: values every agent inherits unless it sets its own (handy for many identical
/// agents).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AgentDefaults {
    /// The model of every agent without its own `model`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelConfig>,
    /// The trajectory of every agent without its own `trajectory`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<TrajectoryConfig>,
    /// The delay of every agent without its own `delay`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay: Option<DelayProfile>,
}

/// Copies the keys of `[defaults]` into every `[[agents]]` table that lacks them, so that the
/// agents deserialize complete. The `defaults` table itself stays (it is validated too, so a
/// problem of a copied value is reported once, at `defaults.<key>`). Returns the paths of the
/// copies (`agents[2].trajectory`).
fn apply_agent_defaults(root: &mut toml::Table) -> Vec<Vec<Seg>> {
    let mut copied = Vec::new();
    let Some(toml::Value::Table(defaults)) = root.get("defaults").cloned() else {
        return copied;
    };
    let Some(toml::Value::Array(agents)) = root.get_mut("agents") else {
        return copied;
    };
    for (i, agent) in agents.iter_mut().enumerate() {
        if let toml::Value::Table(a) = agent {
            for (k, v) in &defaults {
                if !a.contains_key(k) {
                    a.insert(k.clone(), v.clone());
                    copied.push(vec![
                        Seg::Key("agents".into()),
                        Seg::Index(i),
                        Seg::Key(k.clone()),
                    ]);
                }
            }
        }
    }
    copied
}

fn delay_problems(at: &str, delay: &DelayProfile) -> Vec<Problem> {
    let mut out = Vec::new();
    let mut push = |path: String, message: String| out.push(Problem { path, message });
    let mut ok = true;
    for (name, v) in delay.parameters() {
        if !v.is_finite() {
            ok = false;
            push(format!("{at}.{name}"), format!("must be finite, got {v}"));
        }
    }
    if ok {
        if delay.min() <= 0.0 {
            push(at.into(), format!("delay must stay > 0 (Assumption 4), but its minimum is {} s (negative or zero delay)", delay.min()));
        }
        if delay.max_rate() >= 1.0 {
            push(
                at.into(),
                format!(
                    "|dτ/dt| must stay < 1 (Assumption 4), but it reaches {}",
                    delay.max_rate()
                ),
            );
        }
        if delay.max() > 10.0 {
            push(
                at.into(),
                format!("delay above 10 s ({} s) is not supported", delay.max()),
            );
        }
    }
    out
}

/// `[attack]`: where the attack comes from: exactly one of a preset name, a file, or an inline
/// profile.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(extend("minProperties" = 1, "maxProperties" = 1), transform = preset_names)]
pub struct AttackSource {
    /// A shipped preset, by name (`scenarios/attacks/NAME.toml`, embedded in the binary).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<String>,
    /// An attack-profile TOML file, relative to the scenario file's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// An inline profile, in the format of an attack-profile file (`[attack.profile]`,
    /// `[[attack.profile.channels]]`, …).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<AttackProfile>,
}

/// A scenario file of fdi-mas: everything a run needs (docs/scenarios.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "fdi-mas scenario", transform = agents_need_what_defaults_lack)]
pub struct Scenario {
    /// Name of the run (non-empty); the run directory is named after it.
    pub name: String,
    /// Run seed: sensor noise, V̂(0), attack noise all derive from it.
    pub seed: u64,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Control period Δ, s; typical 0.001.
    pub control_period_s: f64,
    /// RK4 sub-steps of the plant per control period; typical 1.
    pub physics_substeps: u32,
    /// `"lockstep"` (default: deterministic, as fast as the machine allows) or `"realtime"`
    /// (physics paced by the wall clock).
    #[serde(default)]
    pub clock: ClockMode,
    /// `[controller]`: the gains and choices of the control center.
    pub controller: ControllerConfig,
    /// `[noise]`: the Gaussian sensor noise.
    pub noise: NoiseConfig,
    /// `[disturbance]`: the additive disturbance `d(t)`, one entry per link.
    pub disturbance: DisturbanceConfig,
    /// Inherited by every agent that does not set the key itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub defaults: Option<AgentDefaults>,
    /// `[[agents]]`: the robots, 1 to 256 of them, each with its own number of links (a team
    /// may mix robots).
    pub agents: Vec<AgentConfig>,
    /// `[attack]`: the attack of the run.
    pub attack: AttackSource,
    /// `[detectors]`: the classical detectors beside the paper's alarm (optional; absent, they
    /// run with their defaults).
    #[serde(default, skip_serializing_if = "DetectorsConfig::is_default")]
    pub detectors: DetectorsConfig,
    /// `[roles]`: roles taken by external programs (docs/protocol.md; optional: without it the
    /// run's own processes take every role).
    #[serde(default, skip_serializing_if = "crate::roles::RolesConfig::is_default")]
    pub roles: crate::roles::RolesConfig,
    /// `[urdf_files]`: the texts of the URDF files the models name (`kind = "urdf"`), by their
    /// `path` as written. Filled when the scenario is read (each file once, however many agents
    /// share it), so that a run's scenario carries its robots; a file may also set it.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub urdf_files: BTreeMap<String, String>,
}

/// Every problem found in a scenario file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{source_name}: {} problem(s):\n{}", problems.len(), problems.iter().map(|p| format!("  - {p}")).collect::<Vec<_>>().join("\n"))]
pub struct ScenarioError {
    /// File name or `<embedded>`.
    pub source_name: String,
    pub problems: Vec<Problem>,
}

impl ScenarioError {
    fn one(source_name: &str, path: &str, message: impl Into<String>) -> Self {
        Self {
            source_name: source_name.into(),
            problems: vec![Problem {
                path: path.into(),
                message: message.into(),
            }],
        }
    }
}

/// How [`Resolved::attack_name`] starts for a run whose attacker is an external program.
pub const EXTERNAL_ATTACK_PREFIX: &str = "external program ";

/// A validated scenario with its attack profile resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved {
    pub scenario: Scenario,
    pub attack: AttackProfile,
}

impl Resolved {
    /// The number of links every robot of the run has; `None` for a team that mixes robots
    /// of different joint counts, or a run without agents.
    pub fn joint_count(&self) -> Option<usize> {
        let counts = self.scenario.joint_counts();
        (counts.len() == 1)
            .then(|| counts.first().copied())
            .flatten()
    }

    /// The attack on agent `agent_id` of the run: [`AgentAttack::compile`] of its profile, with
    /// the twins of a covert attack on the agent (which need the scenario: its model, delay and
    /// disturbance). What the attacker and the in-process engine evaluate.
    pub fn agent_attack(&self, agent_id: u32) -> AgentAttack {
        let attack = AgentAttack::compile(&self.attack, agent_id, self.scenario.seed);
        let entry = self.attack.covert.iter().find(|c| c.agent == agent_id);
        let agent = self.scenario.agents.iter().find(|a| a.id == agent_id);
        match (entry, agent) {
            (Some(entry), Some(agent)) => {
                attack.with_covert(entry, self.scenario.plant_params(agent))
            }
            _ => attack,
        }
    }

    /// The attacker of the run's attack profile: [`Self::agent_attack`] of every agent, in the
    /// scenario's agent order, on the torque path of the agents whose torques the profile
    /// attacks. What the in-process engine runs by default.
    pub fn profile_attacker(&self) -> ProfileAttacker {
        ProfileAttacker::new(
            self.attack.name.clone(),
            self.scenario.agents.iter().map(|a| {
                (
                    a.id,
                    self.agent_attack(a.id),
                    self.attack.attacks_torque_of(a.id),
                )
            }),
        )
    }

    /// Number of agents.
    pub fn agent_count(&self) -> usize {
        self.scenario.agents.len()
    }

    /// Number of control ticks of the run: `round(duration / Δ)`.
    pub fn ticks(&self) -> u64 {
        (self.scenario.duration_s / self.scenario.control_period_s).round() as u64
    }

    /// The scenario as TOML with the attack inlined (what a run directory stores).
    pub fn to_toml(&self) -> String {
        let mut s = self.scenario.clone();
        s.attack = AttackSource {
            preset: None,
            file: None,
            profile: Some(self.attack.clone()),
        };
        toml::to_string(&s).unwrap_or_else(|e| format!("# could not serialize scenario: {e}\n"))
    }

    /// The scenario as a TOML document with the attack inlined (`attack.profile`) and every
    /// field written, the ones left at their defaults included (`controller.update_law`,
    /// `controller.observer_input`, `[detectors]`): what `--set PATH=VALUE` edits.
    pub fn to_document(&self) -> Result<toml::Table, ScenarioError> {
        let mut s = self.scenario.clone();
        s.attack = AttackSource {
            preset: None,
            file: None,
            profile: Some(self.attack.clone()),
        };
        let not_toml = |e: toml::ser::Error| {
            ScenarioError::one(
                &s.name,
                "<document>",
                format!("cannot be written as TOML: {e}"),
            )
        };
        let toml::Value::Table(mut doc) = toml::Value::try_from(&s).map_err(not_toml)? else {
            return Err(ScenarioError::one(
                &s.name,
                "<document>",
                "is not a TOML table",
            ));
        };
        let c = &s.controller;
        let defaults = [
            (
                "update_law",
                toml::Value::try_from(c.update_law).map_err(not_toml)?,
            ),
            (
                "observer_input",
                toml::Value::try_from(c.observer_input).map_err(not_toml)?,
            ),
        ];
        if let Some(toml::Value::Table(controller)) = doc.get_mut("controller") {
            for (key, value) in defaults {
                controller.entry(key).or_insert(value);
            }
        }
        let detectors = toml::Value::try_from(s.detectors).map_err(not_toml)?;
        doc.entry("detectors").or_insert(detectors);
        Ok(doc)
    }

    /// Keeps only the agents `keep` accepts, and only the attack channels of those agents.
    pub fn retain_agents(mut self, keep: impl Fn(&AgentConfig) -> bool) -> Self {
        self.scenario.agents.retain(|a| keep(a));
        self.attack = self.attack.for_agents(&self.scenario.agent_dofs());
        self
    }

    /// Replaces the attack (e.g. `--attack FILE|PRESET`) and re-checks it against the agents.
    pub fn with_attack(mut self, attack: AttackProfile) -> Result<Self, ScenarioError> {
        let problems: Vec<Problem> = attack
            .problems(&self.scenario.agent_dofs())
            .into_iter()
            .map(|(p, m)| Problem {
                path: format!("attack.{p}"),
                message: m,
            })
            .collect();
        if !problems.is_empty() {
            return Err(ScenarioError {
                source_name: "attack".into(),
                problems,
            });
        }
        self.attack = attack;
        let problems = self.roles_problems();
        if !problems.is_empty() {
            return Err(ScenarioError {
                source_name: "attack".into(),
                problems,
            });
        }
        Ok(self)
    }

    /// What the roles taken by external programs need of the rest: an external attacker
    /// decides every message itself, so the run's attack profile must be empty (the preset
    /// `none`); it would otherwise be silently unused.
    pub fn roles_problems(&self) -> Vec<Problem> {
        let attacker = self.scenario.roles.attacker.is_some();
        if attacker && !self.attack.agents().is_empty() {
            return vec![Problem {
                path: "roles.attacker".into(),
                message: format!(
                    "an external program takes the attacker role, so the attack profile `{}` \
                     (agents {:?}) would not be used: set `[attack] preset = \"none\"`",
                    self.attack.name,
                    self.attack.agents()
                ),
            }];
        }
        Vec::new()
    }

    /// The run's attack as summaries and headers name it: the attack profile's name, or
    /// `external program <label>` when a program takes the attacker role (the profile is then
    /// the empty `none` and says nothing of the attack the run had).
    pub fn attack_name(&self) -> String {
        match &self.scenario.roles.attacker {
            Some(role) => format!("{EXTERNAL_ATTACK_PREFIX}{}", role.label()),
            None => self.attack.name.clone(),
        }
    }

    /// Whether a program outside the project takes a role: only the multi-process engine can
    /// run it.
    pub fn has_external_roles(&self) -> bool {
        !self.scenario.roles.is_default()
    }
}

impl Scenario {
    /// Values that validate but are implausible for a research run (a gain far beyond the
    /// calibration, a reference the control period under-samples, an attack of many radians):
    /// `validate` prints them as warnings and still accepts the scenario. Each names its field.
    pub fn warnings(&self, attack: &AttackProfile) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        let c = &self.controller;
        for (field, value, calibrated) in [
            ("gain_k", c.gain_k, CALIBRATED_GAIN_K),
            ("beta", c.beta, 30.0),
            ("observer_gain_l1", c.observer_gain_l1, 0.01),
            ("observer_gain_l2", c.observer_gain_l2, 0.012),
            ("learning_rate_w", c.learning_rate_w, 5000.0),
            ("learning_rate_v", c.learning_rate_v, 10.0),
        ] {
            if value.abs() > IMPLAUSIBLE_FACTOR * calibrated {
                push(
                    format!("controller.{field}"),
                    format!("{value} is more than {IMPLAUSIBLE_FACTOR}× the calibration ({calibrated}): the closed loop may diverge (a run says so, and exits 4)"),
                );
            }
        }
        for (i, a) in self.agents.iter().enumerate() {
            // A robot's own `k` stands in for `[controller]`'s: held to the same bound.
            if let Some(k) = a.gains.and_then(|g| g.gain_k) {
                if k.abs() > IMPLAUSIBLE_FACTOR * CALIBRATED_GAIN_K {
                    push(
                        format!("agents[{i}].gains.gain_k"),
                        format!("{k} is more than {IMPLAUSIBLE_FACTOR}× the calibration ({CALIBRATED_GAIN_K}): the closed loop may diverge (a run says so, and exits 4)"),
                    );
                }
            }
        }
        let dt = self.control_period_s;
        for (i, a) in self.agents.iter().enumerate() {
            for (j, link) in a.trajectory.links.iter().enumerate() {
                for (name, value) in link.parameters() {
                    if name == "omega_rad_s" && (value * dt).abs() > MAX_PHASE_PER_PERIOD_RAD {
                        push(
                            format!("agents[{i}].trajectory.links[{j}].omega_rad_s"),
                            format!("{value} rad/s turns {:.3} rad per control period ({dt} s): the reference is under-sampled (more than {MAX_PHASE_PER_PERIOD_RAD} rad per period)", value * dt),
                        );
                    }
                }
            }
        }
        for (i, ch) in attack.channels.iter().enumerate() {
            if ch.signal == crate::attack::Signal::Torque {
                continue;
            }
            for (j, seg) in ch.segments.iter().enumerate() {
                let rad = seg.waveform.magnitude() * ch.units.factor();
                if rad > MAX_PLAUSIBLE_ATTACK_RAD {
                    push(
                        format!("attack.channels[{i}].segments[{j}].waveform"),
                        format!("injects up to {rad:.3e} rad (or rad/s), more than {MAX_PLAUSIBLE_ATTACK_RAD}: measurements that far off may drive the plant beyond any bound"),
                    );
                }
            }
        }
        out.extend(self.late_attack_warnings(attack));
        out
    }

    /// The attacks of `attack` that never act within the run: per robot when none of its
    /// attacks does, else per segment.
    fn late_attack_warnings(&self, attack: &AttackProfile) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        let end = self.duration_s;
        let late = |from_s: f64| end.is_finite() && from_s >= end;
        let never = |from_s: f64| {
            format!("starts at {from_s} s, at or after the end of the run (duration_s = {end} s): it never acts")
        };
        // Per robot: an attack that never acts within the run (issue 55: a 10 s run of a
        // profile whose only attack starts at 10 s ran with no attacked tick and no word).
        // The late segments of such a robot are not listed one by one.
        let mut silent_agents = Vec::new();
        for agent in attack.agents() {
            let silent = match attack.first_action_s(agent) {
                Some(first) if late(first) => format!(
                    "robot {agent} is never attacked within the run: its first attack starts at {first} s, at or after the end (duration_s = {end} s)"
                ),
                Some(_) => continue,
                None => format!(
                    "robot {agent} is named but never attacked: every segment of its attack is `none` or `pass`"
                ),
            };
            silent_agents.push(agent);
            push("attack".into(), silent);
        }
        for (i, ch) in attack.channels.iter().enumerate() {
            for (j, seg) in ch.segments.iter().enumerate() {
                if late(seg.from_s) && !silent_agents.contains(&ch.agent) {
                    push(
                        format!("attack.channels[{i}].segments[{j}].from_s"),
                        never(seg.from_s),
                    );
                }
            }
        }
        for (i, m) in attack.messages.iter().enumerate() {
            for (j, seg) in m.segments.iter().enumerate() {
                if late(seg.from_s) && !silent_agents.contains(&m.agent) {
                    push(
                        format!("attack.messages[{i}].segments[{j}].from_s"),
                        never(seg.from_s),
                    );
                }
            }
        }
        for (i, c) in attack.covert.iter().enumerate() {
            if late(c.from_s) && !silent_agents.contains(&c.agent) {
                push(format!("attack.covert[{i}].from_s"), never(c.from_s));
            }
        }
        out
    }

    /// The numbers of links the team's robots have, each once.
    pub fn joint_counts(&self) -> std::collections::BTreeSet<usize> {
        self.agents.iter().map(|a| a.model.dof()).collect()
    }

    /// Ids and link counts of the agents.
    pub fn agent_dofs(&self) -> BTreeMap<u32, usize> {
        self.agents.iter().map(|a| (a.id, a.model.dof())).collect()
    }

    /// The plant of `agent` in this scenario (its seed, period, sub-steps, sensor noise,
    /// disturbance and start pose): what the agent process integrates.
    pub fn plant_params(&self, agent: &AgentConfig) -> PlantParams {
        PlantParams {
            agent_id: agent.id,
            run_seed: self.seed,
            control_period_s: self.control_period_s,
            substeps: self.physics_substeps,
            model: agent.model.clone(),
            delay: agent.delay,
            noise: self.noise,
            disturbance: self.disturbance_of(agent).clone(),
            start: agent.trajectory.start_rad(),
        }
    }

    /// The controller of `agent`'s robot: `[controller]` with the robot's own
    /// `[agents.gains]`.
    pub fn controller_of(&self, agent: &AgentConfig) -> crate::control::ControllerConfig {
        let mut c = self.controller;
        if let Some(g) = agent.gains {
            c.gain_k = g.gain_k.unwrap_or(c.gain_k);
            c.gain_scaling = g.gain_scaling.unwrap_or(c.gain_scaling);
        }
        c
    }

    /// The disturbance `agent`'s robot feels: its own `[agents.disturbance]`, or the
    /// scenario's `[disturbance]`.
    pub fn disturbance_of<'a>(&'a self, agent: &'a AgentConfig) -> &'a DisturbanceConfig {
        agent.disturbance.as_ref().unwrap_or(&self.disturbance)
    }

    /// The control-center side of `agent` in this scenario (its controller, seed and period).
    pub fn center_params(&self, agent: &AgentConfig) -> CenterParams {
        CenterParams {
            agent_id: agent.id,
            run_seed: self.seed,
            control_period_s: self.control_period_s,
            controller: self.controller_of(agent),
            model: agent.model.clone(),
            trajectory: agent.trajectory.clone(),
            delay: agent.delay,
        }
    }

    /// Every problem of the scenario's values (parsing has already checked keys and types), in
    /// the order of the checks below: the run's own fields, the controller, the noise, the
    /// disturbance's values, the agents, the defaults, the disturbance's length, the attack.
    pub fn validate(&self) -> Vec<Problem> {
        let mut out = self.top_level_problems();
        out.extend(self.controller_problems());
        out.extend(self.noise_problems());
        out.extend(self.disturbance_value_problems());
        out.extend(self.agents_problems());
        out.extend(self.defaults_problems());
        out.extend(self.disturbance_length_problems());
        out.extend(self.attack_problems());
        out.extend(self.detectors.problems(
            "detectors",
            self.duration_s,
            self.control_period_s,
            self.agents.iter().map(|a| a.model.dof()).max(),
        ));
        out.extend(self.roles.problems("roles"));
        out.extend(self.mixed_team_role_problems());
        out
    }

    /// The run's own fields: name, duration, control period, physics sub-steps.
    fn top_level_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        if self.name.trim().is_empty() {
            push("name".into(), "must not be empty".into());
        }
        if let Some(why) = crate::files::unprintable(&self.name) {
            push("name".into(), why);
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            push(
                "duration_s".into(),
                format!("must be finite and > 0, got {}", self.duration_s),
            );
        }
        if !(self.control_period_s.is_finite() && self.control_period_s > 0.0) {
            push(
                "control_period_s".into(),
                format!("must be finite and > 0, got {}", self.control_period_s),
            );
        } else if self.duration_s.is_finite() && self.control_period_s > self.duration_s {
            push(
                "control_period_s".into(),
                format!(
                    "must not exceed duration_s ({} > {})",
                    self.control_period_s, self.duration_s
                ),
            );
        } else if self.duration_s.is_finite() && self.duration_s / self.control_period_s > 1e9 {
            push("duration_s".into(), "more than 1e9 control ticks".into());
        }
        if !(1..=1000).contains(&self.physics_substeps) {
            push(
                "physics_substeps".into(),
                format!("must be in 1..=1000, got {}", self.physics_substeps),
            );
        }
        out
    }

    /// `[controller]`: gains, rates and bounds > 0, ranges and hold time ≥ 0, the update law,
    /// the number of hidden neurons.
    fn controller_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        let c = &self.controller;
        for (name, v) in [
            ("gain_k", c.gain_k),
            ("beta", c.beta),
            ("observer_gain_l1", c.observer_gain_l1),
            ("observer_gain_l2", c.observer_gain_l2),
            ("learning_rate_w", c.learning_rate_w),
            ("learning_rate_v", c.learning_rate_v),
            ("weight_bound_w", c.weight_bound_w),
            ("weight_bound_v", c.weight_bound_v),
            ("detection.threshold", c.detection.threshold),
        ] {
            if !(v.is_finite() && v > 0.0) {
                push(
                    format!("controller.{name}"),
                    format!("must be finite and > 0, got {v}"),
                );
            }
        }
        for (name, v) in [
            ("initial_v_range", c.initial_v_range),
            ("detection.hold_s", c.detection.hold_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                push(
                    format!("controller.{name}"),
                    format!("must be finite and ≥ 0, got {v}"),
                );
            }
        }
        for p in c
            .update_law
            .problems("controller.update_law", self.control_period_s)
            .into_iter()
            .chain(c.computed_torque.problems("controller.computed_torque"))
            .chain(c.gated.problems("controller.gated"))
        {
            push(p.path, p.message);
        }
        if !(1..=64).contains(&c.hidden_neurons) {
            push(
                "controller.hidden_neurons".into(),
                format!("must be in 1..=64, got {}", c.hidden_neurons),
            );
        }
        let external = c.mode == crate::control::ControllerMode::External;
        match (external, self.roles.controller.is_some()) {
            (true, false) => push(
                "controller.mode".into(),
                "`external` takes its torques from a program: name it in `[roles.controller] \
                 command` (docs/protocol.md, \"The controller program\")"
                    .into(),
            ),
            (false, true) => push(
                "roles.controller".into(),
                format!(
                    "a program takes the controller role, so `controller.mode = \"{}\"` would \
                     not be used: set `mode = \"external\"`",
                    c.mode.as_str()
                ),
            ),
            _ => {}
        }
        out
    }

    /// `[noise]`: the sensor's standard deviations.
    fn noise_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        for (name, v) in [
            ("position_std_rad", self.noise.position_std_rad),
            ("velocity_std_rad_s", self.noise.velocity_std_rad_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                push(
                    format!("noise.{name}"),
                    format!("must be finite and ≥ 0, got {v}"),
                );
            }
        }
        out
    }

    /// `[disturbance]`: every link's amplitude and frequency finite (its length against the
    /// agents' links is [`Self::disturbance_length_problems`]).
    fn disturbance_value_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        let own = (self.agents.iter().enumerate()).filter_map(|(i, a)| {
            Some((format!("agents[{i}].disturbance"), a.disturbance.as_ref()?))
        });
        for (at, d) in std::iter::once(("disturbance".to_string(), &self.disturbance)).chain(own) {
            for (i, l) in d.links.iter().enumerate() {
                for (name, v) in [("amplitude", l.amplitude), ("omega_rad_s", l.omega_rad_s)] {
                    if !v.is_finite() {
                        push(
                            format!("{at}.links[{i}].{name}"),
                            format!("must be finite, got {v}"),
                        );
                    }
                }
            }
        }
        out
    }

    /// `[[agents]]`: their number, then each agent in turn (ids unique, each its own number
    /// of links).
    fn agents_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        if self.agents.is_empty() {
            push(
                "agents".into(),
                "at least one agent is required (found zero)".into(),
            );
        }
        if self.agents.len() > MAX_AGENTS {
            push(
                "agents".into(),
                format!("at most {MAX_AGENTS} agents, found {}", self.agents.len()),
            );
        }
        let mut seen = BTreeMap::new();
        for (i, a) in self.agents.iter().enumerate() {
            out.extend(agent_id_model_problems(i, a, &mut seen));
            if let Some(k) = a.gains.and_then(|g| g.gain_k) {
                if !(k.is_finite() && k > 0.0) {
                    out.push(Problem {
                        path: format!("agents[{i}].gains.gain_k"),
                        message: format!("must be finite and > 0, got {k}"),
                    });
                }
            }
            out.extend(agent_trajectory_problems(i, a));
            out.extend(delay_problems(&format!("agents[{i}].delay"), &a.delay));
        }
        out
    }

    /// `[defaults]`: its delay (its model and trajectory are checked in the agents that
    /// inherit them).
    fn defaults_problems(&self) -> Vec<Problem> {
        match self.defaults.as_ref().and_then(|d| d.delay.as_ref()) {
            Some(delay) => delay_problems("defaults.delay", delay),
            None => Vec::new(),
        }
    }

    /// Each robot's disturbance: one entry per link of the robot. The scenario's
    /// `[disturbance]` is named once, for the first robot it does not fit.
    fn disturbance_length_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut shared_named = false;
        for (i, a) in self.agents.iter().enumerate() {
            let (d, found) = (a.model.dof(), self.disturbance_of(a).links.len());
            if found == d {
                continue;
            }
            let (path, message) = match &a.disturbance {
                Some(_) => (
                    format!("agents[{i}].disturbance.links"),
                    format!("needs {d} entries (one per link), found {found}"),
                ),
                None if !std::mem::replace(&mut shared_named, true) => (
                    "disturbance.links".into(),
                    format!(
                        "needs {d} entries (one per link of agents[{i}]), found {found}; a robot \
                         of another joint count takes its own `[agents.disturbance]`"
                    ),
                ),
                None => continue,
            };
            out.push(Problem { path, message });
        }
        out
    }

    /// An attacker or monitor program (`[roles]`) is told one joint count for every robot
    /// (docs/protocol.md): a team that mixes joint counts runs without one. A controller
    /// program is asked each robot's ticks with its own joints (`FDI_JOINTS`).
    fn mixed_team_role_problems(&self) -> Vec<Problem> {
        let dofs = self.joint_counts();
        if dofs.len() < 2 {
            return Vec::new();
        }
        let counts: Vec<String> = dofs.iter().map(ToString::to_string).collect();
        let roles = [
            ("roles.attacker", self.roles.attacker.is_some()),
            ("roles.monitor", self.roles.monitor.is_some()),
        ];
        (roles.iter().filter(|(_, set)| *set))
            .map(|(path, _)| Problem {
                path: (*path).into(),
                message: format!(
                    "an attacker or monitor program is told one joint count for every robot, \
                     and this team mixes {} joints: run it with robots of one joint count (a \
                     controller program takes a team of different robots)",
                    counts.join(" and ")
                ),
            })
            .collect()
    }

    /// `[attack]`: exactly one source, a known preset, an inline profile that fits the agents.
    fn attack_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |path: String, message: String| out.push(Problem { path, message });
        let sources = [
            self.attack.preset.is_some(),
            self.attack.file.is_some(),
            self.attack.profile.is_some(),
        ];
        if sources.iter().filter(|s| **s).count() != 1 {
            push(
                "attack".into(),
                "set exactly one of `preset`, `file` or `profile`".into(),
            );
        }
        if let Some(p) = &self.attack.preset {
            if presets::preset(p).is_none() {
                push(
                    "attack.preset".into(),
                    format!(
                        "unknown preset `{p}` (known: {})",
                        presets::names().join(", ")
                    ),
                );
            }
        }
        if let Some(profile) = &self.attack.profile {
            for (p, m) in profile.problems(&self.agent_dofs()) {
                push(format!("attack.profile.{p}"), m);
            }
        }
        out
    }
}

/// Agent `i`'s id (≥ 1, not in `seen` yet, which records it) and model (at most [`MAX_DOF`]
/// links, its own parameters).
fn agent_id_model_problems(
    i: usize,
    a: &AgentConfig,
    seen: &mut BTreeMap<u32, usize>,
) -> Vec<Problem> {
    let mut out = Vec::new();
    let mut push = |path: String, message: String| out.push(Problem { path, message });
    let at = |f: &str| format!("agents[{i}].{f}");
    if a.id == 0 {
        push(at("id"), "must be ≥ 1".into());
    }
    if let Some(j) = seen.insert(a.id, i) {
        push(
            at("id"),
            format!("duplicate agent id {} (also agents[{j}])", a.id),
        );
    }
    let dof = a.model.dof();
    if dof > MAX_DOF {
        push(
            at("model"),
            format!("{dof} links exceed the maximum {MAX_DOF}"),
        );
    }
    for (f, m) in a.model.problems() {
        push(at(&format!("model.{f}")), m);
    }
    out
}

/// Agent `i`'s trajectory: one entry per link of its model, a finite ramp rate ≥ 0, finite
/// link parameters.
fn agent_trajectory_problems(i: usize, a: &AgentConfig) -> Vec<Problem> {
    let mut out = Vec::new();
    let mut push = |path: String, message: String| out.push(Problem { path, message });
    let at = |f: &str| format!("agents[{i}].{f}");
    let dof = a.model.dof();
    if a.trajectory.links.len() != dof {
        push(
            at("trajectory.links"),
            format!(
                "needs {dof} entries (one per link), found {}",
                a.trajectory.links.len()
            ),
        );
    }
    if !(a.trajectory.ramp_rate.is_finite() && a.trajectory.ramp_rate >= 0.0) {
        push(
            at("trajectory.ramp_rate"),
            format!("must be finite and ≥ 0, got {}", a.trajectory.ramp_rate),
        );
    }
    for (l, link) in a.trajectory.links.iter().enumerate() {
        for (name, v) in link.parameters() {
            if !v.is_finite() {
                push(
                    at(&format!("trajectory.links[{l}].{name}")),
                    format!("must be finite, got {v}"),
                );
            }
        }
    }
    let start = &a.trajectory.start;
    if !start.is_empty() && start.len() != dof {
        push(
            at("trajectory.start"),
            format!(
                "needs {dof} entries (one per joint) or none, found {}",
                start.len()
            ),
        );
    }
    for (l, v) in start.iter().enumerate() {
        if !v.is_finite() {
            push(
                at(&format!("trajectory.start[{l}]")),
                format!("must be finite, got {v}"),
            );
        }
    }
    out.extend(joint_limit_problems(i, a));
    out
}

/// Agent `i`'s trajectory within its arm's joint limits (a URDF arm's): the least and greatest
/// `q_d` of each joint over all time ([`TrajectoryConfig::envelope`]).
fn joint_limit_problems(i: usize, a: &AgentConfig) -> Vec<Problem> {
    let mut out = Vec::new();
    for (l, (joint, limits)) in a.model.joint_limits().into_iter().enumerate() {
        let (Some((lo, hi)), Some((min, max))) = (limits, a.trajectory.envelope(l)) else {
            continue;
        };
        if min < lo || max > hi {
            out.push(Problem {
                path: format!("agents[{i}].trajectory.links[{l}]"),
                message: format!(
                    "q_d of joint `{joint}` goes from {min:.4} to {max:.4} (start + f(t) g(t) \
                     over the run), outside the joint's limits [{lo:.4}, {hi:.4}] in the URDF; \
                     move it with `trajectory.start` or a smaller amplitude"
                ),
            });
        }
    }
    out
}

/// A TOML syntax error of `text` as `TOML syntax at line L, column C: <what>`.
pub fn toml_syntax_error(text: &str, e: &toml::de::Error) -> String {
    let at = e.span().map_or(String::new(), |span| {
        let (line, column) = line_column(text, span.start);
        format!(" at line {line}, column {column}")
    });
    format!("TOML syntax{at}: {}", e.message().trim_end())
}

/// Deserializes `text`, collecting every problem of every table in one pass ([`collect`]): a
/// syntax error first (then nothing else), with its line and column. `reference` is a valid
/// document of the same kind, whose values stand in for wrong or missing ones so that the
/// reading reaches every table (never a result: a document with problems is refused).
fn parse_collecting<T: serde::de::DeserializeOwned>(
    text: &str,
    source_name: &str,
    reference: Option<&toml::Table>,
) -> Result<Collected<T>, ScenarioError> {
    parse_prepared(text, source_name, reference, |_| {})
}

/// [`parse_collecting`], `prepare` changing the document before `[defaults]` is applied.
fn parse_prepared<T: serde::de::DeserializeOwned>(
    text: &str,
    source_name: &str,
    reference: Option<&toml::Table>,
    prepare: impl FnOnce(&mut toml::Table),
) -> Result<Collected<T>, ScenarioError> {
    let mut value: toml::Table = toml::from_str(text)
        .map_err(|e| ScenarioError::one(source_name, "<file>", toml_syntax_error(text, &e)))?;
    prepare(&mut value);
    let inherited = apply_agent_defaults(&mut value);
    Ok(crate::collect::collect(value, reference, &inherited))
}

/// Parses and validates scenario text: every problem of every table, each with its path and
/// its line and column in `text`. `base_dir` resolves `attack.file`.
pub fn load_str(
    text: &str,
    source_name: &str,
    base_dir: Option<&Path>,
) -> Result<Resolved, ScenarioError> {
    load_text(text, source_name, base_dir, Some(text))
}

/// [`load_str`] of a document made by the program (a scenario edited by `--set`): its
/// problems without a line and column, which would be of text the user never saw.
pub fn load_document(doc: &toml::Table, source_name: &str) -> Result<Resolved, ScenarioError> {
    let text = toml::to_string(doc).map_err(|e| {
        ScenarioError::one(
            source_name,
            "<document>",
            format!("cannot be written as TOML: {e}"),
        )
    })?;
    load_text(&text, source_name, None, None)
}

/// [`load_str`], the problems located in `located` when given.
fn load_text(
    text: &str,
    source_name: &str,
    base_dir: Option<&Path>,
    located: Option<&str>,
) -> Result<Resolved, ScenarioError> {
    let locate = |problems: Vec<Problem>| match located {
        Some(t) => with_locations(problems, t, None),
        None => problems,
    };
    // The embedded paper scenario stands in for wrong or missing values, to read on.
    let reference = toml::from_str::<toml::Table>(PAPER_SCENARIO).ok();
    // The models' URDF files, read first: a model is made from its file's text.
    let (mut urdf_problems, mut unread) = (Vec::new(), Vec::new());
    let mut read = parse_prepared::<Scenario>(text, source_name, reference.as_ref(), |doc| {
        (urdf_problems, unread) = crate::urdf_files::read_into(doc, base_dir);
    })?;
    // A model left without its text fails to read: its file's problem says why, once.
    read.problems.retain(|p| !unread.contains(&p.path));
    let mut problems = locate(urdf_problems);
    problems.extend(locate(std::mem::take(&mut read.problems)));
    let Some(scenario) = read.value.take() else {
        return Err(ScenarioError {
            source_name: source_name.into(),
            problems,
        });
    };
    let own = |p: &Problem| !read.touches_replaced(&p.path);
    problems.extend(locate(
        scenario.validate().into_iter().filter(own).collect(),
    ));
    let (attack, attack_problems) = resolve_attack(&scenario, base_dir);
    problems.extend(attack_problems);
    let resolved = Resolved { scenario, attack };
    problems.extend(locate(
        resolved.roles_problems().into_iter().filter(own).collect(),
    ));
    if problems.is_empty() {
        Ok(resolved)
    } else {
        Err(ScenarioError {
            source_name: source_name.into(),
            problems,
        })
    }
}

/// The attack profile `[attack]` names (a preset, inline, or a file relative to `base_dir`)
/// and the problems of an attack file (located in it, named `attack.file(FILE).…`).
fn resolve_attack(scenario: &Scenario, base_dir: Option<&Path>) -> (AttackProfile, Vec<Problem>) {
    let mut problems = Vec::new();
    let mut attack = AttackProfile::default();
    if let Some(name) = &scenario.attack.preset {
        if let Some(p) = presets::preset(name) {
            let (p, found) = preset_for(p, name, scenario);
            attack = p;
            problems.extend(found.into_iter().map(|p| Problem {
                path: format!("attack.{}", p.path),
                message: p.message,
            }));
        }
    } else if let Some(p) = &scenario.attack.profile {
        attack = p.clone();
    } else if let Some(file) = &scenario.attack.file {
        let path = base_dir.map_or_else(|| file.clone(), |b| b.join(file));
        let prefixed = |p: Problem| Problem {
            path: format!("attack.file({}).{}", file.display(), p.path),
            message: p.message,
        };
        let shown = file.display().to_string();
        match read_limited(&path) {
            Err(e) => problems.push(prefixed(Problem {
                path: "<file>".into(),
                message: e,
            })),
            Ok(text) => match parse_attack(&text, &shown, Some(&shown)) {
                Ok(p) => {
                    let found = attack_problems(&p.problems(&scenario.agent_dofs()));
                    problems.extend(
                        with_locations(found, &text, Some(&shown))
                            .into_iter()
                            .map(prefixed),
                    );
                    attack = p;
                }
                Err(e) => problems.extend(e.problems.into_iter().map(prefixed)),
            },
        }
    }
    (attack, problems)
}

/// Loads and validates a scenario a run wrote (a run directory's `scenario.toml`, the scenario
/// a split run sends its hosts): read without its folder, so that it reads no other file (its
/// attack is inline, its URDF texts are in its `urdf_files`).
pub fn load_written(path: &Path) -> Result<Resolved, ScenarioError> {
    load_path(path, None)
}

/// Loads and validates a scenario file.
pub fn load_file(path: &Path) -> Result<Resolved, ScenarioError> {
    load_path(path, path.parent())
}

/// The scenario file at `path`, its other files read from `base_dir` ([`load_str`]).
fn load_path(path: &Path, base_dir: Option<&Path>) -> Result<Resolved, ScenarioError> {
    let name = path.display().to_string();
    let text = read_limited(path).map_err(|e| ScenarioError::one(&name, "<file>", e))?;
    load_str(&text, &name, base_dir)
}

/// The embedded paper scenario.
pub fn paper() -> Result<Resolved, ScenarioError> {
    load_str(PAPER_SCENARIO, "<embedded paper scenario>", None)
}

/// Loads an attack-profile file (checked for keys and types; agent references are checked
/// against a scenario by [`Resolved::with_attack`]).
pub fn load_attack_file(path: &Path) -> Result<AttackProfile, ScenarioError> {
    let name = path.display().to_string();
    let text = read_limited(path).map_err(|e| ScenarioError::one(&name, "<file>", e))?;
    load_attack_text(&text, &name)
}

/// Parses attack-profile text (keys and types), its problems located in it.
pub fn load_attack_text(text: &str, name: &str) -> Result<AttackProfile, ScenarioError> {
    parse_attack(text, name, None)
}

/// [`load_attack_text`], the locations said to be `of` a file when given (an attack file that
/// a scenario names).
fn parse_attack(text: &str, name: &str, of: Option<&str>) -> Result<AttackProfile, ScenarioError> {
    let read = parse_collecting::<AttackProfile>(text, name, None)?;
    match read.value {
        Some(p) if read.problems.is_empty() => Ok(p),
        _ => Err(ScenarioError {
            source_name: name.into(),
            problems: with_locations(read.problems, text, of),
        }),
    }
}

/// `(path, message)` pairs of [`AttackProfile::problems`] as problems.
fn attack_problems(found: &[(String, String)]) -> Vec<Problem> {
    found
        .iter()
        .map(|(path, message)| Problem {
            path: path.clone(),
            message: message.clone(),
        })
        .collect()
}

/// What a file holds, told apart by its top-level keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    Scenario,
    AttackProfile,
}

/// Whether `text` is an attack profile (it has `channels`, `messages` or `covert` and none of a
/// scenario's own keys) or else a scenario (whose loader then says what is wrong with it).
pub fn file_kind(text: &str) -> FileKind {
    let Ok(table) = toml::from_str::<toml::Table>(text) else {
        return FileKind::Scenario;
    };
    let scenario_keys = [
        "seed",
        "duration_s",
        "control_period_s",
        "physics_substeps",
        "clock",
        "controller",
        "noise",
        "disturbance",
        "defaults",
        "agents",
        "attack",
        "detectors",
    ];
    let profile_keys = ["channels", "messages", "covert"];
    if profile_keys.iter().any(|k| table.contains_key(*k))
        && !scenario_keys.iter().any(|k| table.contains_key(*k))
    {
        FileKind::AttackProfile
    } else {
        FileKind::Scenario
    }
}

/// Validates an attack profile without a scenario: keys, types and every value that needs no
/// scenario (the agents it names are taken to exist, with as many links as it names).
pub fn validate_attack_alone(path: &Path) -> Result<AttackProfile, ScenarioError> {
    let name = path.display().to_string();
    let text = read_limited(path).map_err(|e| ScenarioError::one(&name, "<file>", e))?;
    let profile = load_attack_text(&text, &name)?;
    let problems = with_locations(attack_problems(&profile.problems_alone()), &text, None);
    if problems.is_empty() {
        Ok(profile)
    } else {
        Err(ScenarioError {
            source_name: name,
            problems,
        })
    }
}

/// The preset `name` (`profile`) on the agents of `scenario`: the channels of its agents, and
/// a problem for each that names a link the agent's robot does not have (a preset written for
/// two-link arms on a one-joint pendulum), at `preset(NAME).channels[i]…`.
fn preset_for(
    profile: AttackProfile,
    name: &str,
    scenario: &Scenario,
) -> (AttackProfile, Vec<Problem>) {
    let profile = profile.for_agents(&scenario.agent_dofs());
    let problems = (profile.problems(&scenario.agent_dofs()).into_iter())
        .map(|(path, message)| Problem {
            path: format!("preset({name}).{path}"),
            message,
        })
        .collect();
    (profile, problems)
}

/// `--attack` argument: a preset name or a file path. A preset keeps only the channels of
/// agents in the scenario (the shipped presets are written for the paper's four robots); a file
/// must name only agents of the scenario.
pub fn attack_from_arg(arg: &str, scenario: &Scenario) -> Result<AttackProfile, ScenarioError> {
    if let Some(p) = presets::preset(arg) {
        let (p, problems) = preset_for(p, arg, scenario);
        return match problems.is_empty() {
            true => Ok(p),
            false => Err(ScenarioError {
                source_name: format!("--attack {arg}"),
                problems,
            }),
        };
    }
    let path = Path::new(arg);
    // `Path::exists` is false for any error (a symlink loop, no permission): only a name that
    // is truly absent is "neither"; any other failure is said as the system says it.
    match std::fs::metadata(path) {
        Ok(_) => {
            let name = path.display().to_string();
            let text = read_limited(path).map_err(|e| ScenarioError::one(&name, "<file>", e))?;
            let profile = load_attack_text(&text, &name)?;
            let found = attack_problems(&profile.problems(&scenario.agent_dofs()));
            if found.is_empty() {
                Ok(profile)
            } else {
                Err(ScenarioError {
                    source_name: name.clone(),
                    problems: with_locations(found, &text, None),
                })
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let message = if std::fs::symlink_metadata(path).is_ok() {
                "a symbolic link whose target does not exist".to_string()
            } else {
                let names = presets::names();
                let near = crate::collect::nearest(arg, names.iter().copied())
                    .map(|n| format!("; did you mean `{n}`?"))
                    .unwrap_or_default();
                format!(
                    "neither a preset ({}) nor an existing file{near}",
                    names.join(", ")
                )
            };
            Err(ScenarioError::one(arg, "--attack", message))
        }
        Err(e) => Err(ScenarioError::one(
            arg,
            "--attack",
            format!("cannot be read as an attack file: {e}"),
        )),
    }
}

/// Where in `text` the field at `path` (`a.b[2].c`, as [`Problem::path`] names it) is written:
/// the byte offset of its key (of its value, for an array element). A field the text does not
/// hold (a missing key, one inherited from `[defaults]`) gives the place of the nearest table
/// above it that the text holds; `None` when the text does not parse or nothing of the path is
/// in it.
pub fn locate(text: &str, path: &str) -> Option<usize> {
    use toml::de::{DeTable, DeValue};
    let root = DeTable::parse(text).ok()?;
    let mut segments: Vec<Result<&str, usize>> = Vec::new();
    for part in path.split('.').filter(|p| !p.is_empty()) {
        let (key, mut rest) = part.split_at(part.find('[').unwrap_or(part.len()));
        if !key.is_empty() {
            segments.push(Ok(key));
        }
        while let Some(inner) = rest.strip_prefix('[') {
            let end = inner.find(']')?;
            segments.push(Err(inner[..end].parse().ok()?));
            rest = &inner[end + 1..];
        }
    }
    let mut found = None;
    let mut table = Some(root.get_ref());
    let mut array: Option<&toml::de::DeArray<'_>> = None;
    for seg in segments {
        let value = match (seg, table, array) {
            (Ok(key), Some(t), _) => t.iter().find(|(k, _)| k.get_ref() == key).map(|(k, v)| {
                found = Some(k.span().start);
                v
            }),
            (Err(i), _, Some(a)) => a.get(i).inspect(|v| found = Some(v.span().start)),
            _ => None,
        };
        let Some(value) = value else { break };
        (table, array) = match value.get_ref() {
            DeValue::Table(t) => (Some(t), None),
            DeValue::Array(a) => (None, Some(a)),
            _ => (None, None),
        };
    }
    found
}

/// The problems with the place of each in `text` appended: `line L, column C of NAME`, or
/// without `of NAME` when `name` is `None` (the file the error is headed with).
fn with_locations(problems: Vec<Problem>, text: &str, name: Option<&str>) -> Vec<Problem> {
    problems
        .into_iter()
        .map(|mut p| {
            if let Some(offset) = locate(text, &p.path) {
                let (line, column) = line_column(text, offset);
                let of = name.map_or(String::new(), |n| format!(" of {n}"));
                p.message = format!("{} (line {line}, column {column}{of})", p.message);
            }
            p
        })
        .collect()
}

/// `line L, column C` (1-based, columns in characters) of byte `offset` of `text`.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut end = offset.min(text.len());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    let before = &text[..end];
    let line = before.matches('\n').count() + 1;
    let column = before
        .rsplit_once('\n')
        .map_or(before, |(_, tail)| tail)
        .chars()
        .count()
        + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A team may mix robots of different joint counts: the paper's first two arms and the
    /// three-link scenario's two. The scenario's two-entry disturbance does not fit the
    /// three-link arms (named once, at the first), until they bring their own; gains per robot
    /// are checked; a program in a role is refused for a mixed team.
    #[test]
    fn a_team_of_different_robots_validates_with_a_disturbance_and_gains_per_robot() {
        let three_text = include_str!("../../scenarios/three-link.toml");
        let three = load_str(three_text, "three-link.toml", None).expect("three-link");
        let mut s = paper().expect("paper").scenario;
        s.agents.truncate(2);
        s.agents
            .extend(three.scenario.agents.iter().take(2).cloned().map(|mut a| {
                a.id += 2;
                a
            }));
        let paths = |s: &Scenario| -> Vec<String> {
            s.validate()
                .iter()
                .map(|p| format!("{}: {}", p.path, p.message))
                .collect()
        };
        let said = paths(&s);
        assert_eq!(said.len(), 1, "{said:#?}");
        assert!(
            said[0].starts_with(
                "disturbance.links: needs 3 entries (one per link of agents[2]), found 2"
            ),
            "{said:#?}"
        );
        for a in &mut s.agents[2..] {
            a.disturbance = Some(three.scenario.disturbance.clone());
        }
        assert_eq!(paths(&s), Vec::<String>::new());
        let mut resolved = Resolved {
            scenario: s.clone(),
            attack: AttackProfile::default(),
        };
        assert_eq!(resolved.joint_count(), None);
        resolved.scenario.agents.truncate(2);
        assert_eq!(resolved.joint_count(), Some(2));
        let center = |s: &Scenario, i: usize| s.center_params(&s.agents[i]).controller;
        s.agents[3].gains = Some(AgentGains {
            gain_k: Some(40.0),
            gain_scaling: Some(crate::control::GainScaling::Inertia),
        });
        assert_eq!(center(&s, 2), s.controller);
        assert_eq!(
            (
                center(&s, 3).gain_k,
                center(&s, 3).gain_scaling,
                center(&s, 3).beta
            ),
            (
                40.0,
                crate::control::GainScaling::Inertia,
                s.controller.beta
            )
        );
        s.agents[2].gains = Some(AgentGains {
            gain_k: Some(-1.0),
            gain_scaling: None,
        });
        s.agents[2].disturbance.as_mut().expect("set").links.pop();
        s.roles.monitor = Some(toml::from_str("command = [\"judge\"]").expect("a role"));
        s.roles.controller = Some(toml::from_str("command = [\"decide\"]").expect("a role"));
        let said = paths(&s);
        for expected in [
            "agents[2].gains.gain_k: must be finite and > 0, got -1",
            "agents[2].disturbance.links: needs 3 entries (one per link), found 2",
            "roles.monitor: an attacker or monitor program is told one joint count for every robot, and this team mixes 2 and 3 joints",
        ] {
            assert!(said.iter().any(|p| p.starts_with(expected)), "{expected}: {said:#?}");
        }
        // A controller program takes the team (each robot's ticks with its own joints).
        assert!(
            !said
                .iter()
                .any(|p| p.starts_with("roles.controller: an attacker")),
            "{said:#?}"
        );
    }

    /// Regression (issue 18): syntax errors said only `TOML syntax: invalid float`, without
    /// where, although the code said they carried their line and column.
    #[test]
    fn a_toml_syntax_error_names_its_line_and_column() {
        let text = "name = \"x\"\nseed = 1\nduration_s = 1.0.0\n";
        let e = parse_collecting::<toml::Table>(text, "case.toml", None).expect_err("refused");
        let msg = e.to_string();
        assert!(msg.contains("TOML syntax at line 3, column 17:"), "{msg}");
        assert_eq!(line_column("ab\ncdé\nx", 7), (2, 4));
        assert_eq!(line_column("", 5), (1, 1));
    }

    /// Regression (issue 18): `--attack` naming a symlink loop said "neither a preset nor an
    /// existing file" (`Path::exists` is false for any error).
    #[test]
    fn an_attack_argument_that_cannot_be_read_says_why_not_that_it_is_missing() {
        let dir = std::env::temp_dir().join(format!("fdi-attack-arg-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        let a = dir.join("a.toml");
        let b = dir.join("b.toml");
        std::os::unix::fs::symlink(&b, &a).expect("link");
        std::os::unix::fs::symlink(&a, &b).expect("link");
        let dangling = dir.join("dangling.toml");
        std::os::unix::fs::symlink(dir.join("absent"), &dangling).expect("link");
        let scenario = paper().expect("paper").scenario;
        let msg = |p: &Path| {
            attack_from_arg(p.to_str().expect("utf-8"), &scenario)
                .expect_err("refused")
                .to_string()
        };
        let looped = msg(&a);
        assert!(
            looped.contains("cannot be read as an attack file")
                && looped.contains("symbolic links")
                && !looped.contains("neither a preset"),
            "{looped}"
        );
        assert!(
            msg(&dangling).contains("a symbolic link whose target does not exist"),
            "{}",
            msg(&dangling)
        );
        assert!(msg(&dir.join("absent.toml")).contains("neither a preset"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_device_or_a_directory_as_scenario_or_attack_file_is_refused_without_reading_it() {
        // `/dev/zero` claims 0 bytes and never ends: it used to be read until memory ran out.
        for (path, kind) in [
            ("/dev/zero", "a character device"),
            ("/dev/null", "a character device"),
            ("/", "a directory"),
        ] {
            let e = load_file(Path::new(path)).expect_err("refused");
            let msg = e.to_string();
            assert!(
                msg.contains(&format!("{path} is not a regular file ({kind})"))
                    && msg.contains(&format!("at most {MAX_FILE_BYTES} bytes")),
                "{msg}"
            );
            let e = load_attack_file(Path::new(path)).expect_err("refused");
            assert!(e.to_string().contains("not a regular file"), "{e}");
        }
    }

    #[test]
    fn a_file_that_is_not_utf8_is_refused_naming_the_offset() {
        let p = std::env::temp_dir().join(format!("fdi-scenario-utf8-{}", std::process::id()));
        std::fs::write(&p, b"name = \"x\xff\"\n").expect("write");
        let e = load_file(&p).expect_err("not UTF-8");
        assert!(
            e.to_string().contains("not UTF-8 text (byte offset 9)"),
            "{e}"
        );
        let _ = std::fs::remove_file(&p);
    }

    /// Regression (issue 51): a name holding a control character (NUL, ESC) reached figure
    /// titles, which no SVG reader takes, and the terminal. The scenario's and its attack
    /// profile's are refused, named with their field path.
    #[test]
    fn a_name_with_a_control_character_is_refused_naming_the_field() {
        let paper = PAPER_SCENARIO.replacen("name = \"paper\"", "name = \"pa\\u001bper\"", 1);
        assert_ne!(
            paper, PAPER_SCENARIO,
            "the paper scenario names itself `paper`"
        );
        let e = load_str(&paper, "s.toml", None)
            .expect_err("refused")
            .to_string();
        assert!(
            e.contains("- name: holds the control character U+001B at byte 2")
                && e.contains("(line 8, column 1)"),
            "{e}"
        );
        let attack =
            PAPER_SCENARIO.replacen("preset = \"paper\"", "profile = { name = \"x\\u0000\" }", 1);
        let e = load_str(&attack, "s.toml", None)
            .expect_err("refused")
            .to_string();
        assert!(
            e.contains("- attack.profile.name: holds the control character U+0000 at byte 1"),
            "{e}"
        );
    }

    #[test]
    fn a_field_is_located_by_its_path_and_a_missing_one_by_its_nearest_table() {
        let text = "name = \"x\"\n[[channels]]\nagent = 9\nlinks = [1, 0]\n\n[[channels]]\n  signal = \"velocity\"\n";
        let at = |path: &str| locate(text, path).map(|o| line_column(text, o));
        assert_eq!(at("name"), Some((1, 1)));
        assert_eq!(at("channels[0].agent"), Some((3, 1)));
        assert_eq!(at("channels[0].links[1]"), Some((4, 13)));
        assert_eq!(at("channels[1].signal"), Some((7, 3)));
        // Absent: the nearest table the text holds.
        assert_eq!(at("channels[1].units"), at("channels[1]"));
        assert!(at("channels[1]").is_some());
        assert_eq!(at("nothing.here"), None);
        assert_eq!(locate("not = [toml", "not"), None);
    }

    #[test]
    fn a_robot_s_own_implausible_gain_is_a_warning_naming_it() {
        let mut r = paper().expect("paper");
        r.scenario.agents[1].gains = Some(AgentGains {
            gain_k: Some(1e5),
            gain_scaling: None,
        });
        let w = r.scenario.warnings(&r.attack);
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].path, "agents[1].gains.gain_k");
        assert!(
            w[0].message
                .contains("100000 is more than 100× the calibration (21)"),
            "{}",
            w[0].message
        );
    }

    #[test]
    fn attack_segments_that_start_at_or_after_the_run_s_end_are_warnings() {
        let r = paper().expect("paper");
        assert!(
            r.scenario.warnings(&r.attack).is_empty(),
            "{:?}",
            r.scenario.warnings(&r.attack)
        );
        let mut attack = r.attack.clone();
        let last = attack.channels[0].segments.len() - 1;
        attack.channels[0].segments[last].from_s = 40.0;
        attack.messages = vec![crate::attack::MessageAttack {
            agent: 1,
            path: crate::attack::Path::Torque,
            segments: vec![
                crate::attack::MessageSegment {
                    from_s: 39.0,
                    effect: crate::attack::Effect::Pass,
                },
                crate::attack::MessageSegment {
                    from_s: 50.0,
                    effect: crate::attack::Effect::Pass,
                },
            ],
        }];
        let w = r.scenario.warnings(&attack);
        let paths: Vec<String> = w.iter().map(|p| p.path.clone()).collect();
        assert_eq!(
            paths,
            [
                format!("attack.channels[0].segments[{last}].from_s"),
                "attack.messages[0].segments[1].from_s".to_string()
            ]
        );
        assert!(
            w[0].message.contains(
                "starts at 40 s, at or after the end of the run (duration_s = 40 s): it never acts"
            ),
            "{w:?}"
        );
        // A warning, not a problem: the scenario stays valid.
        let problems = r.clone().with_attack(attack).err();
        assert!(problems.is_none(), "{problems:?}");
    }

    #[test]
    fn a_robot_whose_attack_never_acts_within_the_run_is_a_warning_naming_it() {
        let mut r = paper().expect("paper");
        let freeze = presets::preset("freeze").expect("the freeze preset");
        let robot_1 = |w: &[Problem]| -> Vec<String> {
            w.iter()
                .filter(|p| p.path == "attack")
                .map(|p| p.message.clone())
                .collect()
        };
        // The freeze starts at 10 s: a 10 s run never sees it, an 11 s run does.
        r.scenario.duration_s = 10.0;
        assert_eq!(
            robot_1(&r.scenario.warnings(&freeze)),
            ["robot 1 is never attacked within the run: its first attack starts at 10 s, at or after the end (duration_s = 10 s)"]
        );
        r.scenario.duration_s = 11.0;
        assert!(robot_1(&r.scenario.warnings(&freeze)).is_empty());
        // A robot named with nothing but `none`.
        let mut idle = freeze.clone();
        for ch in &mut idle.channels {
            ch.agent = 2;
            for seg in &mut ch.segments {
                seg.waveform = crate::attack::Waveform::None;
            }
        }
        assert_eq!(
            robot_1(&r.scenario.warnings(&idle)),
            ["robot 2 is named but never attacked: every segment of its attack is `none` or `pass`"]
        );
    }

    #[test]
    fn an_attack_file_is_told_apart_from_a_scenario_by_its_keys() {
        assert_eq!(file_kind(PAPER_SCENARIO), FileKind::Scenario);
        for (_, text) in presets::PRESETS {
            let kind = file_kind(text);
            // `none` has no channels: it is read as a scenario only if it has none of the
            // profile's lists.
            if text.contains("[[channels]]") || text.contains("[[messages]]") {
                assert_eq!(kind, FileKind::AttackProfile, "{text}");
            }
        }
        assert_eq!(file_kind("channels = []\nseed = 1\n"), FileKind::Scenario);
        assert_eq!(file_kind("not toml ["), FileKind::Scenario);
    }

    #[test]
    fn an_attack_argument_naming_a_missing_agent_names_the_file_its_line_and_the_agents() {
        let dir = std::env::temp_dir().join(format!("fdi-attack-agent-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let f = dir.join("agent-7.toml");
        std::fs::write(
            &f,
            "name = \"x\"\n[[channels]]\nagent = 7\nsignal = \"position\"\nlinks = [1]\nunits = \"rad\"\nsegments = [{ from_s = 0.0, waveform = { kind = \"none\" } }]\n",
        )
        .expect("write");
        let scenario = paper().expect("paper").scenario;
        let e = attack_from_arg(f.to_str().expect("utf-8"), &scenario).expect_err("agent 7");
        let msg = e.to_string();
        assert!(
            msg.starts_with(&format!("{}: 1 problem(s)", f.display()))
                && msg.contains("channels[0].agent: agent 7 is not in the scenario (its agents: 1, 2, 3, 4) (line 3, column 1)"),
            "{msg}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn embedded_paper_scenario_validates() {
        let r = paper().expect("paper scenario is valid");
        assert_eq!(r.agent_count(), 4);
        assert_eq!(r.ticks(), 40_000);
        assert_eq!(r.attack.name, "paper");
    }

    #[test]
    fn unknown_key_negative_delay_and_zero_agents_are_all_reported() {
        let text = PAPER_SCENARIO.replace("seed = 1\n", "seed = 1\nfrobnicate = true\n");
        let r = load_str(&text, "t", None);
        assert!(r.is_err());
        let bad = text.replace("offset_s = 0.003", "offset_s = -0.003");
        let err = load_str(&bad, "t", None).expect_err("invalid");
        let all = err.to_string();
        assert!(all.contains("frobnicate"), "{all}");
        assert!(all.contains("agents[0].delay"), "{all}");
    }

    /// Every problem `load_str` reports on `text`, as `validate` prints them.
    fn problems_of(text: &str) -> Vec<String> {
        load_str(text, "t", None)
            .expect_err("invalid")
            .problems
            .iter()
            .map(ToString::to_string)
            .collect()
    }

    /// Regression (issue 33): `validate` stopped at the first table that failed to read: an
    /// unknown key in `[controller]` hid a misspelt top-level key, and one `shape = "cosin"`
    /// hid the two others and an unknown key.
    #[test]
    fn every_table_s_problems_are_reported_in_one_pass() {
        let text = PAPER_SCENARIO
            .replace("duration_s = 40.0", "duraton_s = 40.0")
            .replace("learning_rate_w = 5000.0", "learning_rate_W = 5000.0");
        let said: Vec<String> = problems_of(&text);
        for fragment in [
            "controller.learning_rate_W: unknown field `learning_rate_W` (did you mean `learning_rate_w`?)",
            "duraton_s: unknown field `duraton_s` (did you mean `duration_s`?)",
        ] {
            assert!(
                said.iter().any(|s| s.contains(fragment)),
                "{fragment} not in {said:#?}"
            );
        }
        // A misspelt key is one problem: the key it meant is not reported missing as well.
        assert_eq!(said.len(), 2, "{said:#?}");
        let cosine = "shape = \"cosine\", amplitude = 50.0";
        let text = PAPER_SCENARIO
            .replace(cosine, "shape = \"cosin\", amplitude = 50.0")
            .replacen("ramp_rate = 0.01\n", "ramp_rate = 0.01\nbogus = 1\n", 1);
        let said: Vec<String> = problems_of(&text);
        assert_eq!(
            said.iter()
                .filter(|s| s.contains("unknown variant `cosin`"))
                .count(),
            PAPER_SCENARIO.matches(cosine).count(),
            "{said:#?}"
        );
        assert!(
            said.iter()
                .any(|s| s.starts_with("agents[0].trajectory.bogus: unknown field")),
            "{said:#?}"
        );
        assert_eq!(said.len(), 4, "nothing beyond them: {said:#?}");
    }

    /// A value that cannot be read is replaced to read on; its own checks then judge the
    /// replacement, not the file, and are left out, while the file's other values are checked.
    #[test]
    fn a_value_that_cannot_be_read_hides_neither_other_values_nor_itself() {
        let text = PAPER_SCENARIO
            .replace("beta = 30.0", "beta = \"high\"")
            .replacen("offset_s = 0.003", "offset_s = -0.003", 1);
        let said: Vec<String> = problems_of(&text);
        assert_eq!(said.len(), 2, "{said:#?}");
        assert!(
            said[0].starts_with("controller.beta: invalid type"),
            "{said:#?}"
        );
        assert!(said[1].starts_with("agents[0].delay:"), "{said:#?}");
    }

    /// A wrong value in `[defaults]` is copied into every agent without its own: it is
    /// reported once, where it is written.
    #[test]
    fn a_wrong_default_is_reported_once_at_defaults() {
        let mut lines: Vec<&str> = PAPER_SCENARIO
            .lines()
            .filter(|l| !l.starts_with("delay = "))
            .collect();
        lines.push("[defaults]");
        lines.push(
            "delay = { kind = \"sin\", amplitude_s = 0.002, offset_s = 0.003, rate_rad_s = 0.5 }",
        );
        lines.push("");
        let text = lines.join("\n");
        let said: Vec<String> = problems_of(&text);
        assert_eq!(said.len(), 1, "{said:#?}");
        assert!(
            said[0].starts_with("defaults.delay.kind: unknown variant `sin`"),
            "{said:#?}"
        );
    }

    #[test]
    fn retaining_agents_drops_their_attack_channels_and_stays_valid() {
        let r = paper().expect("valid").retain_agents(|a| a.id == 1);
        assert_eq!(r.agent_count(), 1);
        assert!(r.attack.channels.iter().all(|c| c.agent == 1));
        load_str(&r.to_toml(), "robot 1 only", None).expect("still valid once written out");
    }

    #[test]
    fn observer_input_parses_round_trips_and_a_bad_value_names_the_field() {
        assert_eq!(
            paper().expect("valid").scenario.controller.observer_input,
            ObserverInput::Sample,
            "absent means sample (the default)"
        );
        let anchor = "detection = { threshold = 0.6, hold_s = 0.05 }\n";
        assert!(PAPER_SCENARIO.contains(anchor));
        let with =
            |v: &str| PAPER_SCENARIO.replace(anchor, &format!("{anchor}observer_input = {v}\n"));
        let r = load_str(&with("\"step-mean\""), "t", None).expect("valid");
        assert_eq!(
            r.scenario.controller.observer_input,
            ObserverInput::StepMean
        );
        let again = load_str(&r.to_toml(), "again", None).expect("round trip");
        assert_eq!(again.scenario.controller, r.scenario.controller);
        assert!(
            !paper().expect("valid").to_toml().contains("observer_input"),
            "the default is not written out"
        );
        for bad in ["\"midpoint\"", "1"] {
            let err = load_str(&with(bad), "t", None).expect_err("invalid");
            let all = err.to_string();
            assert!(all.contains("observer_input"), "{bad}: {all}");
        }
    }

    #[test]
    fn resolved_scenario_round_trips_through_toml() {
        let r = paper().expect("valid");
        let again = load_str(&r.to_toml(), "again", None).expect("round trip");
        assert_eq!(again.attack, r.attack);
        let mut s = again.scenario.clone();
        s.attack = r.scenario.attack.clone();
        assert_eq!(s, r.scenario);
    }
}
