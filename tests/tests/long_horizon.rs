//! Long horizons (docs/model.md, "Long horizons"): over 150 s without attack the paper's update
//! laws let robot 1 drift away from the traditional controller's accuracy, and the robust update
//! law of `scenarios/paper-long-horizon.toml` keeps it there.

use std::path::Path;

use fdi_common::engine::{run_inproc, RunSummary};
use fdi_common::scenario::{self, ControllerMode, Resolved};

/// 150 s: the paper's laws are already 30–40 % worse than the traditional controller on robot 1
/// (and raise false alarms); at 40 s they are not (Table I hides the drift).
const HORIZON_S: f64 = 150.0;

fn robot1(mut r: Resolved, mode: ControllerMode) -> RunSummary {
    r.scenario.duration_s = HORIZON_S;
    r.scenario.controller.mode = mode;
    let r = r.retain_agents(|a| a.id == 1);
    run_inproc::<2>(&r, |_| {}).expect("the engine runs")
}

fn long_horizon_scenario() -> Resolved {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/paper-long-horizon.toml");
    scenario::load_file(&path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_robust_update_law_keeps_robot_1_as_accurate_as_the_traditional_controller() {
    let remedy = long_horizon_scenario();
    assert!(!remedy.scenario.controller.update_law.is_paper());
    assert!(
        remedy.attack.channels.is_empty(),
        "the scenario runs without attack"
    );
    let mut paper_laws = remedy.clone();
    paper_laws.scenario.controller.update_law = Default::default();

    let traditional = robot1(remedy.clone(), ControllerMode::Traditional);
    let with_remedy = robot1(remedy, ControllerMode::Proposed);
    let without = robot1(paper_laws, ControllerMode::Proposed);
    let rmse = |s: &RunSummary| s.metrics["1"].rmse_rad;
    let (t, r, p) = (rmse(&traditional), rmse(&with_remedy), rmse(&without));

    // The horizon must expose the drift, or the next assertion proves nothing. Measured:
    // paper's laws 0.0118 rad, traditional 0.0087 rad (+36 %).
    assert!(
        p > 1.25 * t,
        "paper's laws {p} vs traditional {t}: no drift to remove"
    );
    // The acceptance criterion of the remedy (measured 0.0093 rad, +7 %) and no false alarm.
    assert!(r <= 1.10 * t, "remedy {r} vs traditional {t}");
    assert_eq!(with_remedy.metrics["1"].false_alarms, 0);
}
