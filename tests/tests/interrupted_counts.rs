//! Regression: the summary of an interrupted lockstep run called controlled ticks uncontrolled.
//! The control center computes each robot's tick as its measurement arrives, so SIGINT leaves
//! the robots at different ticks; the first robot whose records ended made the join count every
//! later tick of every robot as "after the control stopped" (711 uncontrolled ticks reported for
//! a robot with about 5). Each robot's counts must be what its traces show.

use std::collections::BTreeMap;
use std::time::Duration;

use fdi_common::trace::TraceRecord;
use fdi_tests::{run_dir_of, signal, spawn, trace_records, wait_until, wait_with_watchdog, Scratch};

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

    // Per robot: the ticks it recorded, and the ticks the control center computed for it.
    let mut center: BTreeMap<u32, u64> = BTreeMap::new();
    for r in trace_records(&dir.join("traces/control-center.trace")) {
        if let TraceRecord::Center(c) = r {
            *center.entry(c.agent).or_default() += 1;
        }
    }
    let mut after_control = 0;
    for id in 1..=4u32 {
        let recorded = trace_records(&dir.join(format!("traces/agent-{id}.trace")))
            .iter()
            .filter(|r| matches!(r, TraceRecord::Agent(_)))
            .count() as u64;
        let controlled = center.get(&id).copied().unwrap_or(0);
        assert!(controlled <= recorded, "robot {id}: {controlled} > {recorded}");
        let m = &v["metrics"][id.to_string()];
        assert_eq!(
            m["uncontrolled_ticks"].as_u64(),
            Some(recorded - controlled),
            "robot {id}: recorded {recorded} ticks, the center computed {controlled}: {m}"
        );
        assert_eq!(m["ticks"].as_u64(), Some(controlled), "robot {id}: {m}");
        after_control += recorded - controlled;
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
