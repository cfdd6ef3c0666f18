//! Fault cases through the real `fdi-launch` binary (docs/faults.md lists them all):
//!
//! * non-finite and absurd values injected by the attacker (`scenarios/attacks/corrupt-values.toml`)
//!   are rejected by the control center, counted per agent, and never become a torque — on the
//!   in-process engine and over IPC alike;
//! * bad scenario files are refused with their field paths before anything is created or spawned.
//!
//! Malformed payloads and sequence numbers are unit- and property-tested in
//! `common/runtime/src/ipc/msg.rs`; the control center's input guard in `common/src/control/center.rs`.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::Path;
use std::time::Duration;

use fdi_common::attack::AgentAttack;
use fdi_common::control::center::MAX_ABS_MEASUREMENT;
use fdi_common::engine::tick_time;
use fdi_common::scenario::{self, MAX_FILE_BYTES, PAPER_SCENARIO};
use fdi_common::trace::TraceRecord;
use fdi_tests::{
    json, launch, launch_watching_children, leftovers_of, repo_path, trace_records, Scratch,
};

const WATCHDOG: Duration = Duration::from_secs(300);
const CORRUPT_PROFILE: &str = "scenarios/attacks/corrupt-values.toml";
const DURATION_S: f64 = 4.0;

fn absurd(v: f64) -> bool {
    !v.is_finite() || v.abs() > MAX_ABS_MEASUREMENT
}

/// Per agent of the paper's scenario, the ticks of a `DURATION_S` run whose tampered
/// measurement the profile makes non-finite or absurd, computed from the profile itself.
fn corrupted_ticks() -> BTreeMap<u32, BTreeSet<u64>> {
    let profile = scenario::load_attack_file(&repo_path(CORRUPT_PROFILE))
        .unwrap_or_else(|e| panic!("{CORRUPT_PROFILE}: {e}"));
    let r = scenario::paper()
        .and_then(|p| p.with_attack(profile))
        .unwrap_or_else(|e| panic!("{CORRUPT_PROFILE} against the paper scenario: {e}"));
    let dt = r.scenario.control_period_s;
    let ticks = (DURATION_S / dt).round() as u64;
    let mut out = BTreeMap::new();
    for a in &r.scenario.agents {
        let mut attack = AgentAttack::compile(&r.attack, a.id, r.scenario.seed);
        let bad: BTreeSet<u64> = (0..ticks)
            .filter(|&k| {
                let inj = attack.injection::<2>(tick_time(k, dt));
                inj.position
                    .iter()
                    .chain(inj.velocity.iter())
                    .any(|v| absurd(*v))
            })
            .collect();
        out.insert(a.id, bad);
    }
    out
}

#[test]
fn corrupt_values_are_rejected_counted_and_never_become_a_torque_on_both_engines() {
    let expected = corrupted_ticks();
    // The profile is what its comment says: 0.5 s of NaN, 0.2 s of +Inf, 0.1 s of 1e300 on
    // robot 1 at 1 kHz, nothing elsewhere.
    assert_eq!(expected[&1].len(), 800, "robot 1's corrupted ticks");
    assert!(expected[&1].contains(&1000) && !expected[&1].contains(&999));
    for id in [2, 3, 4] {
        assert!(expected[&id].is_empty(), "robot {id} must stay clean");
    }

    let dir = Scratch::new("corrupt");
    let profile = repo_path(CORRUPT_PROFILE);
    let profile = profile.to_string_lossy();
    let duration = DURATION_S.to_string();
    let mut digests = Vec::new();
    for engine in ["inproc", "ipc"] {
        let out = launch(
            &[
                "run",
                "--engine",
                engine,
                "--duration-s",
                &duration,
                "--attack",
                &profile,
                "--json",
            ],
            &dir.0,
            WATCHDOG,
        );
        let v = json(&out);
        assert_eq!(v["engine"], engine);
        for (id, ticks) in &expected {
            let m = &v["metrics"][id.to_string()];
            assert_eq!(
                m["rejected_inputs"].as_u64(),
                Some(ticks.len() as u64),
                "{engine}: rejected inputs of robot {id}: {m}"
            );
            let rmse = v["rmse_rad"][id.to_string()].as_f64();
            assert!(
                rmse.is_some_and(f64::is_finite),
                "{engine}: robot {id} RMSE {rmse:?}"
            );
        }

        let run_dir = Path::new(v["run_dir"].as_str().expect("run_dir in the JSON"));
        // The center: every torque finite, and exactly the corrupted ticks flagged.
        let mut rejected: BTreeMap<u32, BTreeSet<u64>> = BTreeMap::new();
        let mut torques = 0;
        for rec in trace_records(&run_dir.join("traces/control-center.trace")) {
            if let TraceRecord::Center(c) = rec {
                torques += 1;
                assert!(
                    c.u.as_slice().iter().all(|u| u.is_finite()),
                    "{engine}: non-finite torque {:?} for robot {} at tick {}",
                    c.u.as_slice(),
                    c.agent,
                    c.k
                );
                if c.rejected_input {
                    rejected.entry(c.agent).or_default().insert(c.k);
                }
            }
        }
        assert_eq!(torques, 4 * 4000, "{engine}: one torque per robot and tick");
        for (id, ticks) in &expected {
            assert_eq!(
                rejected.get(id).cloned().unwrap_or_default(),
                *ticks,
                "{engine}: ticks flagged for robot {id}"
            );
        }
        // The attacker really relayed the values: its tampered measurements hold them.
        let mut relayed: BTreeMap<u32, u64> = BTreeMap::new();
        for rec in trace_records(&run_dir.join("traces/attacker.trace")) {
            if let TraceRecord::Attack(a) = rec {
                if a.y
                    .as_slice()
                    .iter()
                    .chain(a.yd.as_slice())
                    .any(|v| absurd(*v))
                {
                    *relayed.entry(a.agent).or_default() += 1;
                }
            }
        }
        assert_eq!(relayed.get(&1).copied(), Some(800), "{engine}: {relayed:?}");
        assert_eq!(relayed.len(), 1, "{engine}: {relayed:?}");
        digests.push(v["trace_digest"].clone());
    }
    assert_eq!(
        digests[0], digests[1],
        "NaN and infinities travel bit for bit: same digest on both engines"
    );
}

/// Cases of `tests/scenario-cases/` run through `fdi-launch run`, one of each kind.
const REFUSED_CASES: &[&str] = &[
    "unknown-key-top-level",
    "wrong-type-duration",
    "nan-gain",
    "zero-control-period",
    "negative-control-period",
    "delay-rate-too-fast",
    "zero-agents",
    "duplicate-agent-ids",
    "attack-file-missing",
    "attack-corrupt-bad-value",
];

/// Runs `fdi-launch run ARGS --out OUT` where OUT does not exist yet, and asserts: non-zero
/// exit, every fragment in stderr, OUT still absent (no run directory, hence no scenario for a
/// process to load), no process started, no shared-memory file of the launcher's run prefix.
fn assert_refused_before_anything_is_created(args: &[&str], fragments: &[String], tag: &str) {
    let dir = Scratch::new(tag);
    let out_dir = dir.0.join("out");
    let out_arg = out_dir.to_string_lossy().into_owned();
    let mut all: Vec<&str> = vec!["run"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", &out_arg]);
    let w = launch_watching_children(&all, WATCHDOG);
    let stderr = String::from_utf8_lossy(&w.output.stderr);
    assert!(
        !w.output.status.success(),
        "{tag}: `fdi-launch {}` succeeded; stdout:\n{}",
        all.join(" "),
        String::from_utf8_lossy(&w.output.stdout)
    );
    assert!(
        !stderr.contains("panicked"),
        "{tag}: the launcher panicked:\n{stderr}"
    );
    for f in fragments {
        assert!(
            stderr.contains(f.as_str()),
            "{tag}: stderr lacks `{f}`:\n{stderr}"
        );
    }
    let created: Vec<_> = fs::read_dir(&out_dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    assert!(
        created.is_empty(),
        "{tag}: the refused run created {} holding {created:?}",
        out_dir.display()
    );
    assert!(
        w.children.is_empty(),
        "{tag}: processes started: {:?}",
        w.children
    );
    let shm = leftovers_of(w.pid);
    assert!(
        shm.is_empty(),
        "{tag}: iceoryx2 files of the run prefix: {shm:?}"
    );
}

#[test]
fn bad_scenario_files_are_refused_with_their_field_paths_before_anything_is_spawned() {
    // Control: the watcher does see the processes of a valid (short) run, so an empty list
    // below means none was started.
    let ok = Scratch::new("refusal-control");
    let ok_out = ok.0.join("out").to_string_lossy().into_owned();
    let w = launch_watching_children(
        &["run", "--duration-s", "0.05", "--out", &ok_out, "--json"],
        WATCHDOG,
    );
    assert!(
        w.output.status.success(),
        "{}",
        String::from_utf8_lossy(&w.output.stderr)
    );
    assert!(
        w.children.iter().any(|c| c.1.contains("agent")),
        "the watcher saw no agent process of a valid run: {:?}",
        w.children
    );

    let cases = repo_path("tests/scenario-cases");
    for name in REFUSED_CASES {
        let toml = cases.join(format!("{name}.toml"));
        let expect = fs::read_to_string(cases.join(format!("{name}.expect")))
            .unwrap_or_else(|e| panic!("{name}.expect: {e}"));
        let fragments: Vec<String> = expect
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
            .map(String::from)
            .collect();
        assert!(!fragments.is_empty(), "{name}.expect is empty");
        let path = toml.to_string_lossy().into_owned();
        assert_refused_before_anything_is_created(&[&path], &fragments, name);
    }

    // Oversized: a valid scenario padded past the limit.
    let tmp = Scratch::new("oversized-input");
    let limit = usize::try_from(MAX_FILE_BYTES).expect("limit fits in usize");
    let mut text = String::from(PAPER_SCENARIO);
    text.push('#');
    text.push_str(&"x".repeat(limit + 1 - text.len()));
    text.push('\n');
    let huge = tmp.0.join("huge.toml");
    fs::write(&huge, text).expect("writing the oversized scenario");
    let huge = huge.to_string_lossy().into_owned();
    assert_refused_before_anything_is_created(
        &[&huge],
        &["huge.toml".into(), format!("{MAX_FILE_BYTES} byte limit")],
        "oversized",
    );

    // A missing attack file given on the command line.
    assert_refused_before_anything_is_created(
        &["--attack", "/nonexistent/attack.toml"],
        &["--attack".into(), "neither a preset".into()],
        "attack-arg-missing",
    );
}

/// Regression: a scenario that validates but makes the plant blow up (max |error| 1e72 rad)
/// ran to the end and exited 0 with RMSE `NaN`. Each robot's divergence is named with its
/// time, the run exits 4 on both engines, and `validate` warns about the implausible value
/// while still accepting it.
#[test]
fn a_diverging_scenario_names_each_robot_and_its_time_and_exits_non_zero() {
    let dir = Scratch::new("diverging");
    let text = PAPER_SCENARIO
        .replace("beta = 30.0", "beta = 1e9")
        .replace("duration_s = 40.0", "duration_s = 0.2");
    assert_ne!(text, PAPER_SCENARIO, "the paper scenario's beta line moved");
    let path = dir.0.join("huge-beta.toml");
    fs::write(&path, text).expect("writing the scenario");
    let file = path.to_string_lossy();

    let validated = fdi_tests::launch_plain(&["validate", &file], Duration::from_secs(60));
    let said = String::from_utf8_lossy(&validated.stdout);
    assert!(validated.status.success(), "{said}");
    assert!(said.contains("warning: controller.beta"), "{said}");

    for engine in ["inproc", "ipc"] {
        let out = fdi_tests::launch(
            &["run", &file, "--engine", engine],
            &dir.0,
            Duration::from_secs(300),
        );
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        assert_eq!(out.status.code(), Some(4), "{engine}: {stdout}{stderr}");
        for robot in 1..=4 {
            assert!(
                stderr.contains(&format!("robot {robot} diverged at t = ")),
                "{engine}: {stderr}"
            );
        }
        assert!(stdout.contains("| diverged at t = "), "{engine}: {stdout}");
    }
    // The shipped paper scenario draws no warning.
    let paper = fdi_tests::launch_plain(
        &[
            "validate",
            &fdi_tests::repo_path("scenarios/paper.toml").to_string_lossy(),
        ],
        Duration::from_secs(60),
    );
    assert!(!String::from_utf8_lossy(&paper.stdout).contains("warning"));
}
