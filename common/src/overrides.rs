//! What the command line changes in a scenario (`--attack`, `--seed`, …): one struct for the
//! command line (with the `clap` feature, its flags), the Rust API and the Python package's
//! keyword arguments, applied and validated in one place ([`Overrides::apply`]).

use crate::control::ObserverInput;
use crate::detect::ResidualKind;
use crate::field_path::{Edit, FieldPath, Seg};
use crate::problem::Problem;
use crate::scenario::{self, ClockMode, ControllerMode, Resolved, Scenario, ScenarioError};

/// The name the problems of overrides are reported under.
pub const SOURCE_NAME: &str = "command-line overrides";

#[cfg(feature = "clap")]
mod parsers {
    use clap::builder::{PossibleValuesParser, TypedValueParser};

    use crate::detect::ResidualKind;
    use crate::scenario::{ClockMode, ControllerMode};

    /// `--clock`: the scenario's clock modes by their names, listed in the help.
    pub(super) fn clock() -> impl TypedValueParser<Value = ClockMode> {
        PossibleValuesParser::new(ClockMode::ALL.map(ClockMode::as_str))
            .try_map(|s| s.parse::<ClockMode>())
    }

    /// `--residual`: the detectors' residuals by their names, listed in the help.
    pub(super) fn residual() -> impl TypedValueParser<Value = ResidualKind> {
        PossibleValuesParser::new(ResidualKind::ALL.map(ResidualKind::as_str))
            .try_map(|s| s.parse::<ResidualKind>())
    }

    /// `--controller`: the controller's modes by their names, listed in the help.
    pub(super) fn controller() -> impl TypedValueParser<Value = ControllerMode> {
        PossibleValuesParser::new(ControllerMode::ALL.map(ControllerMode::as_str))
            .try_map(|s| s.parse::<ControllerMode>())
    }
}

/// The controller's numerics options of the command line: each replaces the scenario's value
/// (`[controller]`; docs/model.md, "Numerics of the delayed input" and "Long horizons").
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct NumericsArgs {
    /// Replace `controller.observer_input`: `sample` (the default; docs/model.md, "Numerics of the delayed input") or
    /// `step-mean`.
    #[cfg_attr(feature = "clap", arg(long, value_name = "INPUT"))]
    pub observer_input: Option<ObserverInput>,
    /// Replace `controller.update_law.leakage_w_per_s` (1/s; 0 = the paper's law).
    #[cfg_attr(
        feature = "clap",
        arg(long, value_name = "PER_S", allow_negative_numbers = true)
    )]
    pub leakage_w_per_s: Option<f64>,
    /// Replace `controller.update_law.dead_zone_rad_s` (rad/s; 0 = the paper's law).
    #[cfg_attr(
        feature = "clap",
        arg(long, value_name = "RAD_S", allow_negative_numbers = true)
    )]
    pub dead_zone_rad_s: Option<f64>,
    /// Replace `controller.update_law.innovation_time_constant_s` (s; 0 = the paper's law).
    #[cfg_attr(
        feature = "clap",
        arg(long, value_name = "S", allow_negative_numbers = true)
    )]
    pub innovation_time_constant_s: Option<f64>,
}

impl NumericsArgs {
    /// Writes the given options into the scenario (validated by the caller).
    pub fn apply(&self, s: &mut Scenario) {
        let c = &mut s.controller;
        if let Some(v) = self.observer_input {
            c.observer_input = v;
        }
        if let Some(v) = self.leakage_w_per_s {
            c.update_law.leakage_w_per_s = v;
        }
        if let Some(v) = self.dead_zone_rad_s {
            c.update_law.dead_zone_rad_s = v;
        }
        if let Some(v) = self.innovation_time_constant_s {
            c.update_law.innovation_time_constant_s = v;
        }
    }

    /// The flags given, each with the field path it sets.
    pub fn fields(&self) -> Vec<(&'static str, &'static str)> {
        [
            (
                "--observer-input",
                "controller.observer_input",
                self.observer_input.is_some(),
            ),
            (
                "--leakage-w-per-s",
                "controller.update_law.leakage_w_per_s",
                self.leakage_w_per_s.is_some(),
            ),
            (
                "--dead-zone-rad-s",
                "controller.update_law.dead_zone_rad_s",
                self.dead_zone_rad_s.is_some(),
            ),
            (
                "--innovation-time-constant-s",
                "controller.update_law.innovation_time_constant_s",
                self.innovation_time_constant_s.is_some(),
            ),
        ]
        .into_iter()
        .filter_map(|(flag, path, given)| given.then_some((flag, path)))
        .collect()
    }

    /// The flags given, by name.
    pub fn given(&self) -> Vec<&'static str> {
        self.fields().into_iter().map(|(flag, _)| flag).collect()
    }
}

/// `--set PATH=VALUE`, repeatable: values of the scenario changed at their field paths, in the
/// language of a campaign's `[set]` and axes ([`crate::field_path`]; docs/scenarios.md).
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct SetArgs {
    /// Set the value at a field path of the scenario (repeatable), as a campaign's `[set]`
    /// does: `controller.beta=10`, `agents[1].delay.offset_s=0.005`, `detectors.residual=psi2`.
    /// VALUE is a TOML value (`10`, `0.5`, `"x"`, `[1, 2]`, `{ kind = "constant", value_s =
    /// 0.003 }`); a word that is none (`traditional`) is a string. The path must name a field
    /// of the scenario, the value must have its type; the scenario as changed is validated as a
    /// file is.
    #[cfg_attr(feature = "clap", arg(long = "set", value_name = "PATH=VALUE"))]
    pub set: Vec<Edit>,
}

impl SetArgs {
    /// `r` with the edits made (none: `r` as it is) and validated. An edit that another flag
    /// given makes too (`fields`: the flags' names and paths) or that reaches the value of
    /// another edit is refused: one of them would silently undo the other.
    pub fn apply(&self, r: Resolved, fields: &[(&str, &str)]) -> Result<Resolved, ScenarioError> {
        if self.set.is_empty() {
            return Ok(r);
        }
        let problems = self.overlaps(fields);
        if !problems.is_empty() {
            return Err(ScenarioError {
                source_name: SOURCE_NAME.into(),
                problems,
            });
        }
        let mut doc = r.to_document()?;
        // Every path first (an edit of `[defaults]` reaches the agents that inherit it, as
        // they were before any edit), then the edits.
        let mut targets: Vec<(&Edit, Result<FieldPath, String>)> = Vec::new();
        for e in &self.set {
            match inheritors(&doc, &e.path, &self.set) {
                Ok(paths) => targets.extend(paths.into_iter().map(|p| (e, Ok(p)))),
                Err(message) => targets.push((e, Err(message))),
            }
        }
        let problems: Vec<Problem> = targets
            .into_iter()
            .filter_map(|(e, p)| {
                let message = match p {
                    Ok(p) => p.set(&mut doc, &e.value).err()?.to_string(),
                    Err(message) => message,
                };
                Some(Problem {
                    path: format!("--set {e}"),
                    message,
                })
            })
            .collect();
        if !problems.is_empty() {
            return Err(ScenarioError {
                source_name: SOURCE_NAME.into(),
                problems,
            });
        }
        let mut edited =
            scenario::load_document(&doc, &format!("{SOURCE_NAME} ({})", self.shown()))?;
        let attack = |e: &Edit| matches!(e.path.segs.first(), Some(Seg::Key(k)) if k == "attack");
        if !self.set.iter().any(attack) {
            // The attack is as it was: say where it came from as the scenario did.
            edited.scenario.attack = r.scenario.attack;
        }
        Ok(edited)
    }

    /// The edits that reach one value: two of them, or one and a flag of `fields`.
    fn overlaps(&self, fields: &[(&str, &str)]) -> Vec<Problem> {
        let mut out = Vec::new();
        for (n, e) in self.set.iter().enumerate() {
            for (flag, path) in fields {
                if FieldPath::parse(path).is_ok_and(|p| p.overlaps(&e.path)) {
                    out.push(Problem {
                        path: format!("--set {e}"),
                        message: format!("{flag} sets `{path}` too: give the value once"),
                    });
                }
            }
            for f in &self.set[n + 1..] {
                if f.path.overlaps(&e.path) {
                    out.push(Problem {
                        path: format!("--set {e}"),
                        message: format!("--set {f} reaches the same value: give it once"),
                    });
                }
            }
        }
        out
    }

    /// `--set A=1 --set B=x`, as the edits were given (`show`n).
    pub fn shown(&self) -> String {
        self.set
            .iter()
            .map(|e| format!("--set {e}"))
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// The edits as parts of a run directory's name: `controller.beta=10`.
    pub fn name_parts(&self) -> Vec<String> {
        self.set.iter().map(ToString::to_string).collect()
    }
}

/// The paths an edit at `path` makes in `doc`, the scenario as resolved: `path` itself, and for
/// an edit of `defaults.KEY…` the same edit in every agent whose `KEY` is `[defaults]`' (the
/// agents that inherit it: a resolved scenario holds a copy in each, which the run reads), but
/// not in an agent that an edit of `edits` gives its own (`agents[2].KEY…`), whatever the
/// edits' order. An edit of `[defaults]` that no agent inherits would change nothing: refused.
fn inheritors(
    doc: &toml::Table,
    path: &FieldPath,
    edits: &[Edit],
) -> Result<Vec<FieldPath>, String> {
    if !matches!(path.segs.first(), Some(Seg::Key(root)) if root == "defaults") {
        return Ok(vec![path.clone()]);
    }
    let Some(Seg::Key(key)) = path.segs.get(1) else {
        // Which agents would inherit a table written whole is not the file's to say.
        return Err(
            "edits `[defaults]` whole: set one of its keys (`defaults.model…`, `defaults.delay…`)"
                .into(),
        );
    };
    let inherited = doc.get("defaults").and_then(|d| d.get(key.as_str()));
    let agents = doc.get("agents").and_then(toml::Value::as_array);
    let (Some(inherited), Some(agents)) = (inherited, agents) else {
        return Ok(vec![path.clone()]);
    };
    let heirs: Vec<usize> = agents
        .iter()
        .enumerate()
        .filter(|(_, a)| a.get(key.as_str()) == Some(inherited))
        .map(|(i, _)| i)
        .filter(|i| {
            let own = [
                Seg::Key("agents".into()),
                Seg::Index(*i),
                Seg::Key(key.clone()),
            ];
            !edits.iter().any(|e| e.path.segs.starts_with(&own))
        })
        .collect();
    if heirs.is_empty() {
        return Err(format!(
            "no agent inherits `defaults.{key}` (each sets its own `{key}`): the edit would change nothing; set `agents[i].{key}…`"
        ));
    }
    let mut out = vec![path.clone()];
    for i in heirs {
        let mut segs = vec![Seg::Key("agents".into()), Seg::Index(i)];
        segs.extend(path.segs[1..].iter().cloned());
        out.push(FieldPath {
            text: crate::field_path::segs_text(&segs),
            segs,
        });
    }
    Ok(out)
}

/// What the command line changes in a scenario: one struct for `run`, `detect`, the API and
/// the Python package.
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct Overrides {
    /// Replace the scenario's clock (realtime needs the ipc engine).
    #[cfg_attr(feature = "clap", arg(long, value_parser = parsers::clock()))]
    pub clock: Option<ClockMode>,
    /// Replace the scenario's attack: a preset (the profiles in scenarios/attacks/, see
    /// docs/attacks.md; an unknown name lists them) or a profile file.
    #[cfg_attr(feature = "clap", arg(long))]
    pub attack: Option<String>,
    /// Replace the scenario's controller mode.
    #[cfg_attr(feature = "clap", arg(long, value_parser = parsers::controller()))]
    pub controller: Option<ControllerMode>,
    /// Replace the scenario's duration, s.
    #[cfg_attr(feature = "clap", arg(long, allow_negative_numbers = true))]
    pub duration_s: Option<f64>,
    /// Replace the scenario's seed.
    #[cfg_attr(feature = "clap", arg(long, allow_negative_numbers = true))]
    pub seed: Option<u64>,
    /// Replace `detectors.residual`, the residual the χ², CUSUM and windowed-mean detectors
    /// test (docs/detectors.md).
    #[cfg_attr(feature = "clap", arg(long, value_parser = parsers::residual()))]
    pub residual: Option<ResidualKind>,
    #[cfg_attr(feature = "clap", command(flatten))]
    pub numerics: NumericsArgs,
    #[cfg_attr(feature = "clap", command(flatten))]
    pub set: SetArgs,
}

impl Overrides {
    /// Applies the overrides to `r` and validates the result: every problem of the scenario
    /// as changed, named under [`SOURCE_NAME`].
    pub fn apply(&self, r: Resolved) -> Result<Resolved, ScenarioError> {
        let mut r = self.set.apply(r, &self.fields())?;
        if let Some(a) = &self.attack {
            let profile = scenario::attack_from_arg(a, &r.scenario)?;
            r = r.with_attack(profile)?;
        }
        if let Some(c) = self.controller {
            r.scenario.controller.mode = c;
        }
        if let Some(d) = self.duration_s {
            r.scenario.duration_s = d;
        }
        if let Some(s) = self.seed {
            r.scenario.seed = s;
        }
        if let Some(k) = self.residual {
            r.scenario.detectors.residual = k;
        }
        self.numerics.apply(&mut r.scenario);
        if let Some(c) = self.clock {
            r.scenario.clock = c;
        }
        validated(r)
    }

    /// The flags given other than `--set`, each with the field path it sets.
    pub fn fields(&self) -> Vec<(&'static str, &'static str)> {
        [
            ("--clock", "clock", self.clock.is_some()),
            ("--attack", "attack", self.attack.is_some()),
            ("--controller", "controller.mode", self.controller.is_some()),
            ("--duration-s", "duration_s", self.duration_s.is_some()),
            ("--seed", "seed", self.seed.is_some()),
            ("--residual", "detectors.residual", self.residual.is_some()),
        ]
        .into_iter()
        .filter_map(|(flag, path, given)| given.then_some((flag, path)))
        .chain(self.numerics.fields())
        .collect()
    }

    /// The flags given, by name (`--set` once however often it is given).
    pub fn given(&self) -> Vec<&'static str> {
        let set = (!self.set.set.is_empty()).then_some("--set");
        self.fields()
            .into_iter()
            .map(|(flag, _)| flag)
            .chain(set)
            .collect()
    }
}

/// `r` when its scenario is valid; otherwise every problem, named under [`SOURCE_NAME`].
pub fn validated(r: Resolved) -> Result<Resolved, ScenarioError> {
    let problems = r.scenario.validate();
    if problems.is_empty() {
        Ok(r)
    } else {
        Err(ScenarioError {
            source_name: SOURCE_NAME.into(),
            problems,
        })
    }
}
