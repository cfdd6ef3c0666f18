//! Regression: the summary of an interrupted lockstep run called controlled ticks uncontrolled.
//! The control center computes each robot's tick as its measurement arrives, so SIGINT leaves
//! the robots at different ticks; the first robot whose records ended made the join count every
//! later tick of every robot as "after the control stopped" (711 uncontrolled ticks reported for
//! a robot with about 5). Each robot's counts must be what its traces show.

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use fdi_common::trace::TraceRecord;
use fdi_tests::{
    run_dir_of, signal, spawn, trace_records, wait_until, wait_with_watchdog, Scratch,
};

const WATCHDOG: Duration = Duration::from_secs(300);

#[test]
fn an_interrupted_runs_uncontrolled_ticks_are_what_its_traces_show() {
    let s = Scratch::new("interrupted-counts");
    let out = s.0.join("runs");
    // Long enough that the interrupt comes mid-run on any machine.
    let child = spawn(&["run", "--duration-s", "2000", "--json"], &out);
    let leader = child.id();
    let agent_trace_len = || -> u64 {
        std::fs::read_dir(&out)
            .into_iter()
            .flatten()
            .filter_map(Result::ok)
            .filter_map(|e| std::fs::metadata(e.path().join("traces/agent-1.trace")).ok())
            .map(|m| m.len())
            .sum()
    };
    assert!(
        wait_until(Duration::from_secs(120), || agent_trace_len() > 200_000),
        "the run never recorded"
    );
    signal(leader, "-INT");
    let o = wait_with_watchdog(child, WATCHDOG);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("summary JSON");
    assert!(v["partial"].is_object(), "{v}");
    let dir = run_dir_of(&v);

    // Per robot: the ticks the control center computed for it (and the attacker relayed).
    let mut center: BTreeMap<u32, BTreeSet<u64>> = BTreeMap::new();
    for r in trace_records(&dir.join("traces/control-center.trace")) {
        if let TraceRecord::Center(c) = r {
            center.entry(c.agent).or_default().insert(c.k);
        }
    }
    let mut relayed: BTreeMap<u32, BTreeSet<u64>> = BTreeMap::new();
    for r in trace_records(&dir.join("traces/attacker.trace")) {
        if let TraceRecord::Attack(x) = r {
            relayed.entry(x.agent).or_default().insert(x.k);
        }
    }
    let mut after_control = 0;
    let none = BTreeSet::new();
    for id in 1..=4u32 {
        // The robot's own ticks, controlled where both the attacker's and the center's records
        // of that tick exist.
        let ticks: Vec<u64> = trace_records(&dir.join(format!("traces/agent-{id}.trace")))
            .iter()
            .filter_map(|r| match r {
                TraceRecord::Agent(a) => Some(a.k),
                _ => None,
            })
            .collect();
        let (c, x) = (
            center.get(&id).unwrap_or(&none),
            relayed.get(&id).unwrap_or(&none),
        );
        let controlled = ticks
            .iter()
            .filter(|k| c.contains(k) && x.contains(k))
            .count() as u64;
        let uncontrolled = ticks.len() as u64 - controlled;
        let m = &v["metrics"][id.to_string()];
        assert_eq!(
            m["uncontrolled_ticks"].as_u64(),
            Some(uncontrolled),
            "robot {id}: {} ticks recorded, {controlled} controlled in the traces: {m}",
            ticks.len()
        );
        assert_eq!(m["ticks"].as_u64(), Some(controlled), "robot {id}: {m}");
        after_control += uncontrolled;
    }
    if after_control > 0 {
        assert!(
            stderr.contains(&format!(
                "{after_control} agent-ticks were recorded after the control stopped"
            )),
            "{stderr}"
        );
    }
}
