//! The shipped attack classes (docs/attacks.md): where each class's attack comes from, the
//! robots it attacks, and what a detector made of its onsets. The attack-class table
//! (`fdi-launch attacks`) and the scored benchmark ([`crate::score`]) run them.

use std::fmt::Write as _;

use anyhow::{anyhow, Result};
use fdi_common::metrics::DetectorMetrics;
use fdi_common::scenario::{self, Resolved};
use serde::Serialize;

/// Where a class's run comes from.
#[derive(Debug, Clone, Copy)]
pub enum Source {
    /// The paper scenario with this shipped preset (`scenarios/attacks/<name>.toml`).
    Preset(&'static str),
    /// The paper scenario with this attack-profile file (embedded; `path` names it).
    AttackFile {
        path: &'static str,
        text: &'static str,
    },
    /// A scenario file of its own (embedded; `path` names it), attack and detectors included.
    Scenario {
        path: &'static str,
        text: &'static str,
    },
}

impl Source {
    /// The shipped file the class's attack (or whole scenario) comes from.
    pub fn file(self) -> String {
        match self {
            Self::Preset(name) => format!("scenarios/attacks/{name}.toml"),
            Self::AttackFile { path, .. } | Self::Scenario { path, .. } => path.to_string(),
        }
    }

    /// The class's scenario on `base` (before the table's controller and duration): the base
    /// with the class's attack (and, for a scenario file of its own, its detectors).
    pub fn resolve(self, base: &Resolved) -> Result<Resolved> {
        Ok(match self {
            Self::Preset(name) => {
                let profile = scenario::attack_from_arg(name, &base.scenario)?;
                base.clone().with_attack(profile)?
            }
            Self::AttackFile { path, text } => {
                let profile = scenario::load_attack_text(text, path).map_err(|e| anyhow!("{e}"))?;
                base.clone().with_attack(profile)?
            }
            Self::Scenario { path, text } => {
                let own = scenario::load_str(text, path, None)?;
                let mut r = base
                    .clone()
                    .with_attack(own.attack.for_agents(&base.scenario.agent_dofs()))?;
                r.scenario.detectors = own.scenario.detectors;
                r.scenario.name = own.scenario.name;
                r
            }
        })
    }
}

/// One attack class of the table.
#[derive(Debug, Clone, Copy)]
pub struct Class {
    pub name: &'static str,
    pub source: Source,
    /// The robots the table reports: those attacked (robot 1 for `none`, the reference).
    pub robots: &'static [u32],
    /// One line: what the class does.
    pub what: &'static str,
}

/// Every class of the table, in its order. A new class is one row here.
pub const CLASSES: &[Class] = &[
    Class {
        name: "none",
        source: Source::Preset("none"),
        robots: &[1],
        what: "no attack: the reference",
    },
    Class {
        name: "paper",
        source: Source::Preset("paper"),
        robots: &[1, 2, 3, 4],
        what: "the paper's FDI on position and velocity measurements (Table I)",
    },
    Class {
        name: "scale",
        source: Source::Preset("scale"),
        robots: &[1],
        what: "position measurements scaled by 1.05 over 10-20 s",
    },
    Class {
        name: "sign-flip",
        source: Source::Preset("sign-flip"),
        robots: &[1],
        what: "velocity of link 1 with its sign flipped over 10-12 s",
    },
    Class {
        name: "freeze",
        source: Source::Preset("freeze"),
        robots: &[1],
        what: "position and velocity stuck at their 10 s values over 10-20 s",
    },
    Class {
        name: "replay-example",
        source: Source::AttackFile {
            path: "scenarios/attacks/replay-example.toml",
            text: include_str!("../../../scenarios/attacks/replay-example.toml"),
        },
        robots: &[1],
        what: "measurement values of 2-4 s played back in a loop from 6 s (fresh headers)",
    },
    Class {
        name: "actuator-bias",
        source: Source::Preset("actuator-bias"),
        robots: &[1],
        what: "+0.05 N·m on both torque commands over 10-20 s (actuator FDI)",
    },
    Class {
        name: "torque-delay",
        source: Source::Preset("torque-delay"),
        robots: &[1],
        what: "torque commands take effect 10 ms after the known delay, from 10 s on",
    },
    Class {
        name: "dos-drop",
        source: Source::Preset("dos-drop"),
        robots: &[1],
        what: "each measurement dropped with probability 0.5 over 10-20 s",
    },
    Class {
        name: "dos-burst",
        source: Source::Preset("dos-burst"),
        robots: &[1],
        what: "bursts of dropped measurements (50 ms, 1 s apart on average) over 10-30 s",
    },
    Class {
        name: "dos-window",
        source: Source::Preset("dos-window"),
        robots: &[1],
        what: "every torque command dropped over 10-10.2 s",
    },
    Class {
        name: "measurement-delay",
        source: Source::Preset("measurement-delay"),
        robots: &[1],
        what: "measurements 20 ms stale under the tick's header over 10-20 s",
    },
    Class {
        name: "forge-stamp",
        source: Source::Preset("forge-stamp"),
        robots: &[1],
        what: "torque send stamps forged (+5 ms) over 10-10.2 s",
    },
    Class {
        name: "replay-original",
        source: Source::Preset("replay-original"),
        robots: &[1],
        what: "measurements of 5-6 s re-sent with their original headers over 10-12 s",
    },
    Class {
        name: "covert",
        source: Source::Preset("covert"),
        robots: &[1],
        what: "actuator-bias hidden from the sensors by a twin-model correction from 10 s",
    },
    Class {
        name: "stealthy-bias",
        source: Source::Scenario {
            path: "scenarios/stealthy-bias.toml",
            text: include_str!("../../../scenarios/stealthy-bias.toml"),
        },
        robots: &[1],
        what: "position bias ramped under the χ² threshold on Ψ2 from 5 s (detectors on Ψ2)",
    },
];

/// One detector's outcome on one robot: its onsets sorted by what became of them.
#[derive(Debug, Clone, Serialize)]
pub struct Detection {
    pub onsets: usize,
    /// Detected by an alarm of the detector's own, after the onset.
    pub detected: usize,
    /// The alarm was already on at the tick before the onset (no detection of its own).
    pub already_on: usize,
    /// The attack ended before the detector started watching.
    pub not_watched: usize,
    /// Mean time to detect over the `detected` onsets, s; `None` when none was.
    pub mean_time_to_detect_s: Option<f64>,
    /// `None` when the detector watched no attack-free time.
    pub false_alarms_per_min: Option<f64>,
}

impl Detection {
    pub fn of(d: &DetectorMetrics) -> Self {
        let (mut detected, mut already_on, mut not_watched, mut sum) = (0, 0, 0, 0.0);
        for (i, o) in d.onsets.iter().enumerate() {
            match o.time_to_detect_s {
                Some(_) if d.alarm_on_at_onset.get(i) == Some(&true) => already_on += 1,
                Some(x) => {
                    detected += 1;
                    sum += x;
                }
                None => {
                    let unwatched = match (o.until_s, d.watched_from_s) {
                        (_, None) => true,
                        (Some(until), Some(from)) => until <= from,
                        (None, Some(_)) => false,
                    };
                    not_watched += usize::from(unwatched);
                }
            }
        }
        Self {
            onsets: d.onsets.len(),
            detected,
            already_on,
            not_watched,
            mean_time_to_detect_s: (detected > 0).then(|| sum / detected as f64),
            false_alarms_per_min: d.false_alarms_per_min,
        }
    }

    /// Onsets the detector watched and did not find on already.
    pub fn judged(&self) -> usize {
        self.onsets - self.already_on - self.not_watched
    }

    /// `detected / judged`, with the onsets left out said; `no onset` without any.
    pub fn detected_cell(&self) -> String {
        if self.onsets == 0 {
            return "no onset".into();
        }
        let mut cell = format!("{}/{}", self.detected, self.judged());
        let mut notes = Vec::new();
        if self.already_on > 0 {
            notes.push(format!("{} already on", self.already_on));
        }
        if self.not_watched > 0 {
            notes.push(format!("{} not watched", self.not_watched));
        }
        if !notes.is_empty() {
            let _ = write!(cell, " ({})", notes.join(", "));
        }
        cell
    }

    /// The mean time to detect, s; `missed`, `no onset` or `—` where it has no value.
    pub fn time_cell(&self) -> String {
        match self.mean_time_to_detect_s {
            Some(x) => format!("{x:.3}"),
            None if self.onsets == 0 => "no onset".into(),
            None if self.judged() > 0 => "missed".into(),
            None => "—".into(),
        }
    }

    pub fn false_alarm_cell(&self) -> String {
        self.false_alarms_per_min
            .map_or_else(|| "—".into(), |x| format!("{x:.2}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_class_resolves_and_names_robots_of_its_scenario() {
        for c in CLASSES {
            let paper = scenario::paper().expect("the embedded scenario");
            let r = c
                .source
                .resolve(&paper)
                .unwrap_or_else(|e| panic!("{}: {e}", c.name));
            assert!(!c.robots.is_empty(), "{}", c.name);
            for id in c.robots {
                assert!(
                    r.scenario.agents.iter().any(|a| a.id == *id),
                    "{}: robot {id}",
                    c.name
                );
            }
        }
        let names: std::collections::BTreeSet<_> = CLASSES.iter().map(|c| c.name).collect();
        assert_eq!(names.len(), CLASSES.len(), "class names are unique");
    }

    #[test]
    fn undefined_detection_values_are_not_zero() {
        let none = Detection {
            onsets: 0,
            detected: 0,
            already_on: 0,
            not_watched: 0,
            mean_time_to_detect_s: None,
            false_alarms_per_min: None,
        };
        assert_eq!(none.detected_cell(), "no onset");
        assert_eq!(none.time_cell(), "no onset");
        assert_eq!(none.false_alarm_cell(), "—");
        let missed = Detection {
            onsets: 2,
            already_on: 1,
            ..none.clone()
        };
        assert_eq!(missed.detected_cell(), "0/1 (1 already on)");
        assert_eq!(missed.time_cell(), "missed");
        let only_on = Detection {
            onsets: 1,
            already_on: 1,
            ..none
        };
        assert_eq!(only_on.time_cell(), "—");
    }
}
