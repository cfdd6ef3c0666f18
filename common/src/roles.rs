//! `[roles]` of a scenario: roles taken by programs outside the project (docs/protocol.md).
//! Optional: without the table the run's own processes take every role.
//!
//! * `[roles.attacker]`: a program decides what the control center receives of each
//!   measurement. The run's attacker process still sits on the wire: it hands each clean
//!   measurement to the program, checks and records each answer, and relays it.
//! * `[roles.monitor]`: a program taps the tampered measurements and the torques and publishes
//!   one verdict (alarm, statistic) per agent and tick; the control center records them and
//!   the report lists the monitor beside the built-in detectors.
//! * `[roles.controller]`: a program decides the control center's torques (`[controller] mode
//!   = "external"`): the control center shows it each tick (the measurement in use, the
//!   reference, `e_u`, the model's terms) and sends the torque it answers.

use serde::{Deserialize, Serialize};

use crate::problem::Problem;

/// Default longest wait in lockstep for an external role's next message, s.
pub const DEFAULT_TIMEOUT_S: f64 = 10.0;
/// Default realtime deadline of an external role's answer, ms after the message it answers.
pub const DEFAULT_DEADLINE_MS: f64 = 5.0;
/// Name of the monitor in the report when `[roles.monitor]` gives none.
pub const DEFAULT_MONITOR_NAME: &str = "monitor";

/// `[roles]`: which roles external programs take.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RolesConfig {
    /// `[roles.attacker]`: a program takes the attacker role (on the measurement path; the
    /// scenario's `[attack]` must then be the preset `none`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attacker: Option<ExternalRole>,
    /// `[roles.monitor]`: a program judges every tick of every agent (a detector).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub monitor: Option<ExternalRole>,
    /// `[roles.controller]`: a program decides the control center's torques (with
    /// `[controller] mode = "external"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller: Option<ExternalRole>,
}

impl RolesConfig {
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Every problem of the table, each naming its field under `at` (`roles`).
    pub fn problems(&self, at: &str) -> Vec<Problem> {
        let mut out = Vec::new();
        for (name, role) in [
            ("attacker", &self.attacker),
            ("monitor", &self.monitor),
            ("controller", &self.controller),
        ] {
            if let Some(r) = role {
                out.extend(r.problems(&format!("{at}.{name}")));
            }
        }
        if let Some(name) = self.monitor.as_ref().and_then(|m| m.name.as_deref()) {
            if crate::detect::names().contains(&name) {
                out.push(Problem {
                    path: format!("{at}.monitor.name"),
                    message: format!(
                        "`{name}` is a built-in detector's name; the report lists the monitor \
                         beside them under its own"
                    ),
                });
            }
        }
        out
    }

    /// The monitor's name in the metrics and the report, when the run has one.
    pub fn monitor_name(&self) -> Option<&str> {
        self.monitor
            .as_ref()
            .map(|m| m.name.as_deref().unwrap_or(DEFAULT_MONITOR_NAME))
    }
}

/// A role taken by an external program.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExternalRole {
    /// The program and its arguments, e.g. `["python3", "examples/python/attacker.py"]`. The
    /// program is looked up on `PATH`; it runs in the folder `fdi-launch` runs in, with the run's
    /// prefix and parameters in its environment (`FDI_*`, docs/protocol.md).
    pub command: Vec<String>,
    /// Its name in messages and, for a monitor, in the report (default: `monitor` for a
    /// monitor, the program and its first argument otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Lockstep: longest wait for its next message before the run stops naming it, s (default
    /// 10).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout_s: Option<f64>,
    /// Realtime: how late after the message it answers its answer may come, ms (default 5);
    /// later ones are counted and reported (an attacker's tick goes to the control center as
    /// a gap marker instead; a controller's tick holds the last good torque).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deadline_ms: Option<f64>,
}

impl ExternalRole {
    fn problems(&self, at: &str) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |name: &str, message: String| {
            out.push(Problem {
                path: format!("{at}.{name}"),
                message,
            })
        };
        match self.command.first() {
            None => push(
                "command",
                "must name a program, e.g. [\"python3\", \"my_attacker.py\"]".into(),
            ),
            Some(p) if p.trim().is_empty() => push("command", "its program is empty".into()),
            _ => {}
        }
        if let Some(name) = &self.name {
            if name.trim().is_empty() || name.len() > 64 || name.chars().any(char::is_control) {
                push(
                    "name",
                    format!("must be 1 to 64 printable characters, got {name:?}"),
                );
            }
        }
        if let Some(t) = self.timeout_s {
            if !(t.is_finite() && t > 0.0) {
                push("timeout_s", format!("must be finite and > 0, got {t}"));
            }
        }
        if let Some(d) = self.deadline_ms {
            if !(d.is_finite() && d > 0.0) {
                push("deadline_ms", format!("must be finite and > 0, got {d}"));
            }
        }
        out
    }

    /// How messages name it: `name`, or the program and its first argument
    /// (`python3 attacker.py`).
    pub fn label(&self) -> String {
        if let Some(n) = &self.name {
            return n.clone();
        }
        let file = |s: &String| {
            std::path::Path::new(s)
                .file_name()
                .map_or_else(|| s.clone(), |f| f.to_string_lossy().into_owned())
        };
        self.command
            .iter()
            .take(2)
            .map(file)
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// The lockstep timeout.
    pub fn timeout(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.timeout_s.unwrap_or(DEFAULT_TIMEOUT_S))
    }

    /// The realtime deadline, ns.
    pub fn deadline_ns(&self) -> u64 {
        (self.deadline_ms.unwrap_or(DEFAULT_DEADLINE_MS) * 1e6) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn role(command: &[&str]) -> ExternalRole {
        ExternalRole {
            command: command.iter().map(|s| s.to_string()).collect(),
            name: None,
            timeout_s: None,
            deadline_ms: None,
        }
    }

    #[test]
    fn problems_name_the_field() {
        let roles = RolesConfig {
            attacker: Some(ExternalRole {
                timeout_s: Some(0.0),
                ..role(&[])
            }),
            monitor: Some(ExternalRole {
                name: Some("chi2".into()),
                deadline_ms: Some(f64::NAN),
                ..role(&["python3", "m.py"])
            }),
            controller: Some(ExternalRole {
                timeout_s: Some(-1.0),
                ..role(&["python3", "c.py"])
            }),
        };
        let paths: Vec<String> = roles
            .problems("roles")
            .into_iter()
            .map(|p| p.path)
            .collect();
        assert_eq!(
            paths,
            [
                "roles.attacker.command",
                "roles.attacker.timeout_s",
                "roles.monitor.deadline_ms",
                "roles.controller.timeout_s",
                "roles.monitor.name"
            ]
        );
        assert!(RolesConfig::default().problems("roles").is_empty());
    }

    #[test]
    fn labels_and_defaults() {
        let r = role(&["/usr/bin/python3", "examples/python/attacker.py", "--bias"]);
        assert_eq!(r.label(), "python3 attacker.py");
        assert_eq!(r.timeout(), std::time::Duration::from_secs(10));
        assert_eq!(r.deadline_ns(), 5_000_000);
        let roles = RolesConfig {
            attacker: None,
            monitor: Some(r),
            controller: None,
        };
        assert_eq!(roles.monitor_name(), Some(DEFAULT_MONITOR_NAME));
    }
}
