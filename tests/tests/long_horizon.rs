//! Long horizons (docs/model.md, "Long horizons"), without attack: what the paper's update laws
//! do over hundreds of seconds against the traditional controller, and what the robust update
//! law of `scenarios/paper-long-horizon.toml` changes.

use std::path::Path;

use fdi_common::engine::{run_inproc_any, RunSummary};
use fdi_common::scenario::{self, ControllerMode, Resolved};

/// RMSE (rad) and false alarms of one robot of `r`, run alone for `duration_s`.
fn run_robot(mut r: Resolved, id: u32, mode: ControllerMode, duration_s: f64) -> (f64, u64) {
    r.scenario.duration_s = duration_s;
    r.scenario.controller.mode = mode;
    let r = r.retain_agents(|a| a.id == id);
    let s: RunSummary = run_inproc_any(&r, |_| {}).expect("the engine runs");
    let m = &s.metrics[&id.to_string()];
    (m.rmse_rad, m.false_alarms)
}

/// The scenario file with the remedy on (300 s, no attack).
fn with_remedy() -> Resolved {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/paper-long-horizon.toml");
    let r = scenario::load_file(&path).unwrap_or_else(|e| panic!("{e}"));
    assert!(!r.scenario.controller.update_law.is_paper());
    assert!(
        r.attack.channels.is_empty(),
        "the scenario runs without attack"
    );
    r
}

/// The same scenario with the paper's update laws (37)-(38) and the `step-mean` observer input
/// (the numerics under which the drift of robots 1, 3, 4 is gone; with the default `sample`
/// input the paper's laws drift over 300 s: docs/model.md, "Long horizons").
fn paper_laws() -> Resolved {
    let mut r = with_remedy();
    r.scenario.controller.update_law = Default::default();
    r.scenario.controller.observer_input = fdi_common::control::ObserverInput::StepMean;
    r
}

#[test]
fn robot_1_under_the_paper_laws_does_not_drift_between_150_and_300_s() {
    // Before the observer's input was the delayed input's mean over its step, this grew from
    // 0.0118 rad at 150 s to 0.0207 rad at 300 s. Measured now: 0.0101 and 0.0103 rad.
    let (at_150, _) = run_robot(paper_laws(), 1, ControllerMode::Proposed, 150.0);
    let (at_300, alarms) = run_robot(paper_laws(), 1, ControllerMode::Proposed, 300.0);
    assert!(
        at_300 <= 1.05 * at_150,
        "robot 1 drifts: RMSE {at_150} at 150 s, {at_300} at 300 s"
    );
    assert_eq!(alarms, 0, "false alarms over 300 s without attack");
}

/// Table I of the paper, proposed controller (docs/model.md, "Reproduction").
const PAPER_TABLE1: [(u32, f64); 4] = [(1, 0.008), (2, 0.013), (3, 0.009), (4, 0.010)];

#[test]
fn the_remedy_meets_both_acceptance_bounds_of_issue_10() {
    // Measured: 300 s without attack, remedy / traditional 0.00901 / 0.00880, 0.00548 / 0.00509,
    // 0.00905 / 0.00880, 0.00908 / 0.00880 rad (worst 1.077, robot 2), no false alarm; Table I
    // with the remedy 0.00996 / 0.01045 / 0.01026 / 0.00830 rad, 0.80–1.245 of the paper. The
    // margin is thin on robot 1's Table I value (bound 0.0100): docs/model.md, "Long horizons".
    for (id, _) in PAPER_TABLE1 {
        let (traditional, _) = run_robot(with_remedy(), id, ControllerMode::Traditional, 300.0);
        let (remedy, alarms) = run_robot(with_remedy(), id, ControllerMode::Proposed, 300.0);
        assert!(
            remedy <= 1.10 * traditional,
            "robot {id}: remedy {remedy} vs traditional {traditional}"
        );
        assert_eq!(alarms, 0, "robot {id}: false alarms with the remedy");
    }
    let mut table1 = with_remedy();
    table1.scenario.duration_s = 40.0;
    let paper_attack = fdi_common::attack::presets::preset("paper")
        .expect("the paper's attack preset")
        .for_agents(&table1.scenario.agent_dofs());
    let table1 = table1
        .with_attack(paper_attack)
        .expect("valid with the paper's attack");
    let s = run_inproc_any(&table1, |_| {}).expect("the engine runs");
    for (id, paper) in PAPER_TABLE1 {
        let rmse = s.metrics[&id.to_string()].rmse_rad;
        assert!(
            (rmse / paper - 1.0).abs() <= 0.25,
            "robot {id}: Table I with the remedy {rmse}, paper {paper}"
        );
    }
}

#[test]
fn robot_2_drifts_under_the_paper_laws_over_1000_s_and_the_robust_update_law_stops_it() {
    // Measured at 1000 s: paper's laws 0.0113 rad with 28 false alarms (the error keeps
    // growing: 0.0189 rad and 68 false alarms at 3000 s), remedy 0.00548 rad with none,
    // traditional 0.00511 rad.
    const HORIZON_S: f64 = 1000.0;
    let (traditional, _) = run_robot(with_remedy(), 2, ControllerMode::Traditional, HORIZON_S);
    let (paper, paper_alarms) = run_robot(paper_laws(), 2, ControllerMode::Proposed, HORIZON_S);
    let (remedy, remedy_alarms) = run_robot(with_remedy(), 2, ControllerMode::Proposed, HORIZON_S);
    // The documented remaining drift of the paper's laws (docs/model.md): if this fails, the
    // drift is gone and the documentation is out of date.
    assert!(
        paper > 1.5 * traditional && paper_alarms > 0,
        "paper's laws {paper} ({paper_alarms} false alarms) vs traditional {traditional}"
    );
    assert!(
        remedy <= 1.3 * traditional,
        "remedy {remedy} vs traditional {traditional}"
    );
    assert_eq!(remedy_alarms, 0, "false alarms with the remedy");
}
