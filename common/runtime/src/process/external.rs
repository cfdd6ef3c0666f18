//! What the launcher gives a program that takes a role (`[roles]` of the scenario): its
//! environment, the one place its variables are named (docs/protocol.md lists them; the
//! protocol test checks the list).

use fdi_common::scenario::Resolved;

use crate::ipc::{Bell as _, IpcError, Transport, Wake};

/// How far (ticks) the control center may run ahead of a monitor's verdicts in lockstep: it
/// computes tick `k` of an agent once it holds the monitor's verdict on tick `k − MONITOR_LAG`.
pub const MONITOR_LAG: u64 = 64;

/// The environment variables of an external role, in the order docs/protocol.md lists them.
pub const ENV_VARS: [&str; 12] = [
    "FDI_PREFIX",
    "FDI_ROLE",
    "FDI_SCENARIO",
    "FDI_RUN_DIR",
    "FDI_AGENTS",
    "FDI_DOF",
    "FDI_TICKS",
    "FDI_CONTROL_PERIOD_S",
    "FDI_CLOCK",
    "FDI_MONITOR_LAG",
    "FDI_LAUNCHER_PID",
    "FDI_JOINTS",
];

/// The bell of a program's wake-up event, made at its first ring: the program opens its
/// listener after the run's processes are ready, and a bell made before the listener may not
/// reach it. `keep` holds the event service open until then (the program only opens services).
#[derive(Debug)]
pub struct LateBell<X: Transport> {
    wake: Wake,
    keep: X::Bell,
    bell: std::cell::OnceCell<X::Bell>,
}

impl<X: Transport> LateBell<X> {
    /// Opens the event service of `wake` (through a first bell that only holds it open).
    /// Before the process reports ready: the program opens the service after that.
    pub fn open(transport: &X, wake: Wake) -> Result<Self, IpcError> {
        Ok(Self {
            wake,
            keep: transport.notifier(wake)?,
            bell: std::cell::OnceCell::new(),
        })
    }

    /// Rings the program (after the start: its listener exists by then).
    pub fn ring(&self, transport: &X) -> Result<(), IpcError> {
        if self.bell.get().is_none() {
            let _ = self.bell.set(transport.notifier(self.wake)?);
        }
        self.bell.get().unwrap_or(&self.keep).ring()
    }
}

/// Which role an external program takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExternalKind {
    Attacker,
    Monitor,
    Controller,
}

impl ExternalKind {
    /// `FDI_ROLE`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Attacker => "attacker",
            Self::Monitor => "monitor",
            Self::Controller => "controller",
        }
    }
}

/// The environment of the program taking `kind` in the run `prefix` (its resolved scenario at
/// `scenario`, its directory `run_dir`), one value per entry of [`ENV_VARS`], in that order.
pub fn environment(
    kind: ExternalKind,
    prefix: &str,
    resolved: &Resolved,
    scenario: &std::path::Path,
    run_dir: &std::path::Path,
) -> Vec<(&'static str, String)> {
    let s = &resolved.scenario;
    let agents: Vec<String> = s.agents.iter().map(|a| a.id.to_string()).collect();
    let joints: Vec<String> = s.agents.iter().map(|a| a.model.dof().to_string()).collect();
    // One count for every robot, or `mixed` (a team of different robots: `FDI_JOINTS` has
    // each one's), never one robot's count standing for another's.
    let dof = match resolved.joint_count() {
        Some(n) => n.to_string(),
        None => "mixed".to_string(),
    };
    let values = [
        prefix.to_string(),
        kind.as_str().to_string(),
        scenario.display().to_string(),
        run_dir.display().to_string(),
        agents.join(","),
        dof,
        resolved.ticks().to_string(),
        // Rust's shortest round-trip form: a reader's float parser gets the very f64.
        format!("{:?}", s.control_period_s),
        s.clock.as_str().to_string(),
        MONITOR_LAG.to_string(),
        std::process::id().to_string(),
        joints.join(","),
    ];
    ENV_VARS.into_iter().zip(values).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_variable_gets_a_value() {
        let r = fdi_common::scenario::paper().expect("paper");
        let env = environment(
            ExternalKind::Monitor,
            "fdi1_x",
            &r,
            "run/scenario.toml".as_ref(),
            "run".as_ref(),
        );
        let names: Vec<&str> = env.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, ENV_VARS);
        let get = |n: &str| env.iter().find(|(k, _)| *k == n).map(|(_, v)| v.as_str());
        assert_eq!(get("FDI_AGENTS"), Some("1,2,3,4"));
        assert_eq!(get("FDI_ROLE"), Some("monitor"));
        assert_eq!(get("FDI_TICKS"), Some("40000"));
        assert_eq!(get("FDI_CONTROL_PERIOD_S"), Some("0.001"));
        assert_eq!(
            (get("FDI_DOF"), get("FDI_JOINTS")),
            (Some("2"), Some("2,2,2,2"))
        );
    }
}
