//! How a run's numbers were made: the controller and numerics options of a scenario that
//! differ from the paper's calibration (the embedded paper scenario; docs/model.md, "Gains (the calibration)").
//!
//! Tables, summaries and reports name these beside every number they show, so a result is
//! never shown without the choices that produced it.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use serde::{Deserialize, Serialize};

use crate::scenario::{self, Scenario};

/// One option whose value differs from the paper's calibration.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Difference {
    /// The scenario's field path, e.g. `controller.observer_input`.
    pub field: String,
    /// Its value in this scenario, as written in a scenario file.
    pub value: String,
    /// Its value in the paper's calibration.
    pub paper: String,
}

impl Difference {
    /// `field = value (paper: p)`.
    pub fn describe(&self) -> String {
        format!("{} = {} (paper: {})", self.field, self.value, self.paper)
    }
}

/// Which options [`differences_from_paper`] compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compare {
    /// Every controller and numerics option, the controller's mode included (a run).
    WithMode,
    /// The same without the controller's mode (a table that runs both modes itself).
    WithoutMode,
}

/// The controller and numerics options of `s` (`control_period_s`, `physics_substeps`, every
/// field of `[controller]` with its `update_law` and `observer_input`, and the experiment's
/// `[noise]` and `[disturbance]`) whose values differ from the paper's calibration, in field
/// order. Empty for the paper's own numerics.
pub fn differences_from_paper(s: &Scenario, compare: Compare) -> Vec<Difference> {
    let paper = paper_options();
    let mine = options(s);
    mine.into_iter()
        .filter(|(field, _)| compare == Compare::WithMode || field != "controller.mode")
        .filter_map(|(field, value)| {
            let p = paper.get(&field).cloned().unwrap_or_else(|| "none".into());
            (p != value).then_some(Difference {
                field,
                value,
                paper: p,
            })
        })
        .collect()
}

/// One line: `the paper's numerics` or `controller.x = 1 (paper: 2); …`.
pub fn describe(differences: &[Difference]) -> String {
    if differences.is_empty() {
        "the paper's calibration (docs/model.md, \"Gains\")".into()
    } else {
        differences
            .iter()
            .map(Difference::describe)
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// The options of the embedded paper scenario, computed once.
fn paper_options() -> &'static BTreeMap<String, String> {
    static PAPER: OnceLock<BTreeMap<String, String>> = OnceLock::new();
    PAPER.get_or_init(|| match scenario::paper() {
        Ok(r) => options(&r.scenario),
        // The embedded scenario is checked by the tests; without it, every option is shown.
        Err(_) => BTreeMap::new(),
    })
}

/// Every compared option of `s` as (field path, value as in a scenario file).
fn options(s: &Scenario) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    out.insert("control_period_s".into(), s.control_period_s.to_string());
    out.insert("physics_substeps".into(), s.physics_substeps.to_string());
    let c = &s.controller;
    // Serialized, so that a new field of `[controller]` is compared without a change here. The
    // fields that a scenario file may leave out (their defaults are not written) are added
    // explicitly with their values.
    match (serde_json::to_value(c), serde_json::to_value(c.update_law)) {
        (Ok(mut value), Ok(law)) => {
            if let serde_json::Value::Object(map) = &mut value {
                map.insert("update_law".into(), law);
                map.insert(
                    "observer_input".into(),
                    serde_json::Value::String(c.observer_input.as_str().into()),
                );
            }
            flatten("controller", &value, &mut out);
        }
        // Never silently "as the paper": an option that cannot be read differs.
        (Err(e), _) | (_, Err(e)) => {
            out.insert("controller".into(), format!("(unreadable: {e})"));
        }
    }
    // A robot's own gains and disturbance stand in for the scenario's: compared too, or a run
    // of other gains would be shown as the paper's.
    let own = (s.agents.iter().enumerate()).flat_map(|(i, a)| {
        [
            (a.gains.is_some())
                .then(|| (format!("agents[{i}].gains"), serde_json::to_value(a.gains))),
            (a.disturbance.as_ref())
                .map(|d| (format!("agents[{i}].disturbance"), serde_json::to_value(d))),
        ]
        .into_iter()
        .flatten()
    });
    for (at, value) in [
        ("noise".to_string(), serde_json::to_value(s.noise)),
        (
            "disturbance".to_string(),
            serde_json::to_value(&s.disturbance),
        ),
    ]
    .into_iter()
    .chain(own)
    {
        let at = at.as_str();
        match value {
            Ok(v) => flatten(at, &v, &mut out),
            Err(e) => {
                out.insert(at.into(), format!("(unreadable: {e})"));
            }
        }
    }
    out
}

fn flatten(at: &str, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
    match v {
        serde_json::Value::Object(map) => {
            for (k, v) in map {
                flatten(&format!("{at}.{k}"), v, out);
            }
        }
        serde_json::Value::Array(items) => {
            out.insert(format!("{at}.len"), items.len().to_string());
            for (i, v) in items.iter().enumerate() {
                flatten(&format!("{at}[{i}]"), v, out);
            }
        }
        serde_json::Value::String(s) => {
            out.insert(at.into(), format!("\"{s}\""));
        }
        other => {
            out.insert(at.into(), other.to_string());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::ObserverInput;

    fn paper() -> Scenario {
        scenario::paper().expect("the embedded scenario").scenario
    }

    #[test]
    fn the_paper_scenario_differs_in_nothing() {
        assert!(differences_from_paper(&paper(), Compare::WithMode).is_empty());
        assert_eq!(
            describe(&[]),
            "the paper's calibration (docs/model.md, \"Gains\")"
        );
    }

    #[test]
    fn every_changed_option_is_named_with_both_values() {
        let mut s = paper();
        s.controller.observer_input = ObserverInput::StepMean;
        s.controller.update_law.leakage_w_per_s = 10.0;
        s.controller.update_law.dead_zone_rad_s = 0.17;
        s.controller.gain_k = 40.0;
        s.controller.detection.hold_s = 0.1;
        s.control_period_s = 0.0005;
        s.noise.position_std_rad = 0.0;
        s.controller.mode = crate::control::ControllerMode::Traditional;
        let d = differences_from_paper(&s, Compare::WithMode);
        let fields: Vec<&str> = d.iter().map(|d| d.field.as_str()).collect();
        assert_eq!(
            fields,
            [
                "control_period_s",
                "controller.detection.hold_s",
                "controller.gain_k",
                "controller.mode",
                "controller.observer_input",
                "controller.update_law.dead_zone_rad_s",
                "controller.update_law.leakage_w_per_s",
                "noise.position_std_rad",
            ]
        );
        assert_eq!(
            d[4].describe(),
            "controller.observer_input = \"step-mean\" (paper: \"sample\")"
        );
        assert_eq!(d[2].describe(), "controller.gain_k = 40.0 (paper: 21.0)");
        let without_mode = differences_from_paper(&s, Compare::WithoutMode);
        assert_eq!(without_mode.len(), d.len() - 1);
        assert!(without_mode.iter().all(|d| d.field != "controller.mode"));
    }

    #[test]
    fn a_robot_s_own_gains_and_disturbance_are_named() {
        let mut s = paper();
        s.agents[2].gains = Some(crate::scenario::AgentGains {
            gain_k: Some(40.0),
            gain_scaling: None,
        });
        s.agents[1].disturbance = Some(s.disturbance.clone());
        let d = differences_from_paper(&s, Compare::WithMode);
        let described: Vec<String> = d.iter().map(Difference::describe).collect();
        assert!(
            described.contains(&"agents[2].gains.gain_k = 40.0 (paper: none)".to_string()),
            "{described:?}"
        );
        assert!(
            described
                .iter()
                .any(|d| d.starts_with("agents[1].disturbance.")),
            "{described:?}"
        );
    }

    #[test]
    fn options_outside_the_numerics_are_not_compared() {
        let mut s = paper();
        s.seed = 7;
        s.duration_s = 300.0;
        s.name = "other".into();
        assert!(differences_from_paper(&s, Compare::WithMode).is_empty());
    }
}
