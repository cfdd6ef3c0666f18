//! The agent, attacker and control-center loops as threads over the in-process transport: the
//! runtime's own code (lookahead, sequence tracking, admission), no binary spawned.

use fdi_common::attack::{presets, AttackProfile};
use fdi_common::scenario::{self, Resolved};
use fdi_tests::threads::{self, inproc_records, Middle, ThreadRun};

fn paper(duration_s: f64) -> Resolved {
    let mut r = scenario::paper().expect("embedded paper scenario");
    r.scenario.duration_s = duration_s;
    r
}

/// With the paper's delay (1–5 ms) above the 1 ms period for most of the run, an agent integrates ahead of its
/// torques (lookahead) and the roles exchange batches; the trace is still the in-process one,
/// bit for bit, for the two-link and the three-link robot.
#[test]
fn threaded_roles_equal_the_in_process_engine_with_lookahead() {
    let three_link = {
        let mut r = scenario::load_file(&fdi_tests::repo_path("scenarios/three-link.toml"))
            .expect("three-link scenario");
        r.scenario.duration_s = 1.0;
        r
    };
    for (tag, r) in [("paper", paper(1.0)), ("three", three_link)] {
        let dt = r.scenario.control_period_s;
        assert!(
            r.scenario.agents.iter().all(|a| a.delay.max() > 2.0 * dt),
            "{tag}: the delay must exceed the period for lookahead"
        );
        let (_, expected) = inproc_records(&r);
        let out = threads::run(
            ThreadRun {
                resolved: r.clone(),
                middle: Middle::Attacker,
                forged_torques: Vec::new(),
            },
            tag,
        );
        assert_eq!(out.digest(&r), expected, "{tag}");
        assert!(
            out.events(fdi_common::run_dir::Process::CENTER).is_empty(),
            "{tag}: {:?}",
            out.events(fdi_common::run_dir::Process::CENTER)
        );
    }
}

/// A man in the middle that sends every measurement twice, replays the one three ticks back,
/// and every 100th tick adds one from an unknown agent and one numbered beyond the run: the
/// center's sequence tracking refuses every extra message (and says how many), and controls as
/// if they never came.
#[test]
fn the_center_refuses_duplicated_replayed_and_forged_measurements() {
    let mut r = paper(0.3);
    r.attack = AttackProfile::default();
    let ticks = r.ticks();
    let mut history: Vec<fdi_runtime::ipc::MeasurementMsg> = Vec::new();
    let mut expected_extra = 0u64;
    for k in 0..ticks {
        expected_extra +=
            r.agent_count() as u64 * (1 + u64::from(k >= 3) + 2 * u64::from(k.is_multiple_of(100)));
    }
    let forward = move |m: fdi_runtime::ipc::MeasurementMsg| {
        let mut out = vec![m, m];
        if let Some(old) = history
            .iter()
            .rev()
            .find(|h| h.agent == m.agent && h.seq + 3 == m.seq)
        {
            out.push(*old);
        }
        if m.seq.is_multiple_of(100) {
            out.push(fdi_runtime::ipc::MeasurementMsg { agent: 99, ..m });
            out.push(fdi_runtime::ipc::MeasurementMsg {
                seq: ticks + 7,
                ..m
            });
        }
        history.push(m);
        out
    };
    let out = threads::run(
        ThreadRun {
            resolved: r.clone(),
            middle: Middle::Relay(Box::new(forward)),
            forged_torques: Vec::new(),
        },
        "mitm",
    );
    let (expected, _) = inproc_records(&r);
    let joined = out.joined(&r);
    assert_eq!(joined.len(), expected.len());
    for ((agent, _, center), e) in joined.iter().zip(&expected) {
        // Debug prints every f64 exactly (shortest round trip): equal text, equal bits.
        assert_eq!(format!("{agent:?}"), format!("{:?}", e.agent));
        assert_eq!(format!("{center:?}"), format!("{:?}", e.center));
    }
    let events = out.events(fdi_common::run_dir::Process::CENTER);
    let summary = format!("{expected_extra} messages refused, 0 measurements rejected");
    assert!(
        events.iter().any(|e| e.starts_with(&summary)),
        "expected `{summary}` among {} events, last: {:?}",
        events.len(),
        events.last()
    );
}

/// Torques forged on agent 1's channel before the start — another agent's, the wrong number
/// of links, a non-finite stamp, a number beyond the run, one from the future — are refused
/// and counted, and the run is the in-process one.
#[test]
fn the_agent_refuses_forged_torques() {
    let r = paper(0.3);
    let dt = r.scenario.control_period_s;
    let mut nan = threads::torque(1, 2, 0, dt);
    nan.t_send = f64::NAN;
    let forged = vec![
        (1, threads::torque(2, 2, 0, dt)),
        (1, threads::torque(1, 3, 0, dt)),
        (1, nan),
        (1, threads::torque(1, 2, u64::MAX, dt)),
        (1, threads::torque(1, 2, 3, dt)),
    ];
    let n = forged.len();
    let (_, expected) = inproc_records(&r);
    let out = threads::run(
        ThreadRun {
            resolved: r.clone(),
            middle: Middle::Attacker,
            forged_torques: forged,
        },
        "forged",
    );
    assert_eq!(out.digest(&r), expected);
    let events = out.events("agent-1");
    assert!(
        events
            .iter()
            .any(|e| e.starts_with(&format!("{n} torque messages refused"))),
        "{events:?}"
    );
    assert!(
        out.events("agent-2").is_empty(),
        "{:?}",
        out.events("agent-2")
    );
}

/// Each transform of the clean signal (scale, sign flip, freeze), moved to start 0.3 s into a
/// 1 s run: the threaded roles equal the in-process engine bit for bit, and the attack changes
/// the run.
#[test]
fn each_transform_attack_is_bit_identical_between_threads_and_in_process() {
    let (_, clean_digest) = inproc_records(&{
        let mut r = paper(1.0);
        r.attack = AttackProfile::default();
        r
    });
    for name in ["scale", "sign-flip", "freeze"] {
        let mut r = paper(1.0);
        let mut profile = presets::preset(name).expect("shipped preset");
        for seg in profile
            .channels
            .iter_mut()
            .flat_map(|c| c.segments.iter_mut())
        {
            seg.from_s -= 9.7;
        }
        r.attack = profile;
        let (records, expected) = inproc_records(&r);
        assert_ne!(expected, clean_digest, "{name}: the attack changes the run");
        let attacked = records.iter().filter(|x| x.attack.active).count();
        assert!(attacked >= 600, "{name}: {attacked} attacked agent-ticks");
        let out = threads::run(
            ThreadRun {
                resolved: r.clone(),
                middle: Middle::Attacker,
                forged_torques: Vec::new(),
            },
            name,
        );
        assert_eq!(out.digest(&r), expected, "{name}");
    }
}
