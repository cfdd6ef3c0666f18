//! The covert attack hides an actuator injection from the control center: the same injection
//! without the sensor correction drives the paper's ‖Ŝ‖ alarm, with it the alarm stays off while
//! the robot is driven off its trajectory.

use fdi_common::attack::presets;
use fdi_common::engine::run_inproc_any;
use fdi_common::scenario::{self, Resolved};

fn paper_with(attack: &str) -> Resolved {
    let mut r = scenario::paper().expect("embedded paper scenario");
    r.scenario.duration_s = 21.0;
    r.attack = presets::preset(attack)
        .expect("shipped preset")
        .for_agents(&r.scenario.agent_dofs());
    assert!(r.attack.problems(&r.scenario.agent_dofs()).is_empty());
    r
}

#[test]
fn the_covert_correction_hides_the_actuator_injection_from_the_paper_alarm() {
    let run = |attack: &str| run_inproc_any(&paper_with(attack), |_| {}).expect("runs");
    let (clean, open, covert) = (run("none"), run("actuator-bias"), run("covert"));
    let robot1 = |s: &fdi_common::engine::RunSummary| s.metrics["1"].clone();
    assert!(
        robot1(&open).alarm_coverage > 0.5,
        "the open injection is seen: coverage {}",
        robot1(&open).alarm_coverage
    );
    assert_eq!(robot1(&covert).alarm_coverage, 0.0, "hidden from ‖Ŝ‖");
    assert!(
        covert.rmse_rad["1"] > 3.0 * clean.rmse_rad["1"],
        "the hidden injection still moves the robot: {} vs {}",
        covert.rmse_rad["1"],
        clean.rmse_rad["1"]
    );
    // The others are untouched.
    for id in ["2", "3", "4"] {
        assert_eq!(covert.rmse_rad[id], clean.rmse_rad[id], "robot {id}");
    }
}
