//! In-process engine: determinism, the attack-cancellation structure of the proposed
//! controller, and the paper's qualitative results on a shortened run.

use fdi_common::attack::{presets, AgentAttack};
use fdi_common::control::CenterAgent;
use fdi_common::engine::{run_inproc_any, tick_time};
use fdi_common::model::Vector;
use fdi_common::plant::Plant;
use fdi_common::records::TickRecord;
use fdi_common::scenario::{self, ControllerMode, Resolved};

fn paper(duration_s: f64) -> Resolved {
    let mut r = scenario::paper().expect("embedded paper scenario is valid");
    r.scenario.duration_s = duration_s;
    r
}

fn trace(r: &Resolved) -> (Vec<TickRecord>, String) {
    let mut v = Vec::new();
    let s = run_inproc_any(r, |rec| v.push(*rec)).expect("engine runs");
    (v, s.trace_digest)
}

#[test]
fn same_seed_gives_a_bit_identical_trace_and_digest() {
    let r = paper(2.0);
    let (a, da) = trace(&r);
    let (b, db) = trace(&r);
    assert_eq!(da, db);
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        // PartialEq on f64 would accept -0.0 == 0.0; compare the bit patterns.
        let bits = |r: &TickRecord| -> Vec<u64> {
            [
                r.agent.q,
                r.agent.qd,
                r.agent.y,
                r.attack.y,
                r.center.u,
                r.center.s_hat,
                r.center.q_hat,
            ]
            .iter()
            .flat_map(|j| j.as_slice().iter().map(|v| v.to_bits()).collect::<Vec<_>>())
            .collect()
        };
        assert_eq!(
            bits(x),
            bits(y),
            "tick {} agent {}",
            x.agent.k,
            x.agent.agent
        );
    }
}

#[test]
fn different_seed_gives_different_noise_and_digest() {
    let r1 = paper(0.5);
    let mut r2 = r1.clone();
    r2.scenario.seed = 2;
    let (a, da) = trace(&r1);
    let (b, db) = trace(&r2);
    assert_ne!(da, db);
    // The very first measurement differs only by its noise: q = 0 in both runs.
    assert_eq!(a[0].agent.q, b[0].agent.q);
    assert_ne!(a[0].agent.y, b[0].agent.y);
    let noise = a[0].agent.y.as_slice()[0];
    assert!(
        noise.abs() < 1e-3,
        "sensor noise of std 1e-4 rad, got {noise}"
    );
}

/// Runs agent 1 of the paper scenario with the control center's Ŝ replaced by `oracle(t)`.
fn run_with_oracle(r: &Resolved, oracle: impl Fn(&mut AgentAttack, f64) -> Vector<2>) -> f64 {
    let s = &r.scenario;
    let a = &s.agents[0];
    let mut plant = Plant::<2>::new(s.plant_params(a)).expect("2 links");
    let mut attack = AgentAttack::compile(&r.attack, a.id, s.seed);
    let mut oracle_attack = AgentAttack::compile(&r.attack, a.id, s.seed);
    let mut center = CenterAgent::<2>::new(s.center_params(a)).expect("2 links");
    let mut sum_sq = 0.0;
    for k in 0..r.ticks() {
        let t = tick_time(k, s.control_period_s);
        let e = center.reference(t).q - plant.q;
        sum_sq += e.norm_squared();
        let m = plant.measure();
        let (sent, _) = attack.measurement::<2>(k, t, &m);
        let tampered = *sent.usable().expect("only value channels: delivered").0;
        let s_true = oracle(&mut oracle_attack, t);
        let out = center.tick_with_estimate(t, &tampered.y, &tampered.yd, Some(&s_true));
        plant.receive(t, out.u).expect("increasing stamps");
        plant.advance(k);
    }
    (sum_sq / (2 * r.ticks()) as f64).sqrt()
}

#[test]
fn with_s_hat_forced_to_the_true_attack_the_controller_matches_the_attack_free_run() {
    // Ŝ = α2 + β α1 cancels the attack exactly in r̂ (12) and Ψ2 (23), so the attacked run must
    // follow the attack-free run with Ŝ = 0 up to round-off. Round-off of order 1e-16 · |α β|
    // per tick, integrated by a stable loop, stays far below 1e-9 rad.
    let attacked = paper(10.0);
    let beta = attacked.scenario.controller.beta;
    let clean = attacked
        .clone()
        .with_attack(presets::preset("none").expect("preset"))
        .expect("valid");
    let rmse_attacked = run_with_oracle(&attacked, |a, t| {
        let inj = a.injection::<2>(t);
        inj.velocity + inj.position * beta
    });
    let rmse_clean = run_with_oracle(&clean, |_, _| Vector::<2>::zeros());
    assert!(
        rmse_clean > 1e-4,
        "the clean run still has a tracking error: {rmse_clean}"
    );
    assert!(
        (rmse_attacked - rmse_clean).abs() < 1e-9,
        "attacked {rmse_attacked} vs clean {rmse_clean}"
    );
    // And without the oracle, the same attack does hurt the traditional controller.
    let mut trad = attacked.clone();
    trad.scenario.controller.mode = ControllerMode::Traditional;
    let rmse_trad = run_with_oracle(&trad, |_, _| Vector::<2>::zeros());
    assert!(
        rmse_trad > 1.2 * rmse_clean,
        "traditional {rmse_trad} vs clean {rmse_clean}"
    );
}

#[test]
fn proposed_beats_traditional_on_a_shortened_paper_run() {
    // 15 s covers robot 1's first two attack segments and robot 2's first switch.
    let prop = run_inproc_any(&paper(15.0), |_| {}).expect("runs");
    let mut t = paper(15.0);
    t.scenario.controller.mode = ControllerMode::Traditional;
    let trad = run_inproc_any(&t, |_| {}).expect("runs");
    for id in ["1", "2", "3"] {
        let (p, q) = (prop.rmse_rad[id], trad.rmse_rad[id]);
        assert!(q > 1.5 * p, "robot {id}: traditional {q} vs proposed {p}");
    }
}

/// Regression: with τ a whole number of control periods, the agent pruned the command in force
/// before the next step looked it up, applied zero torque without counting a miss (RMSE 2.4×
/// that of τ + 1e-7 s at 4 ms), and exact multiples picked the older or the newer command
/// depending on the rounding of `t − τ`. Results are now continuous in τ.
#[test]
fn constant_delays_on_the_tick_grid_equal_the_same_delay_plus_a_hair() {
    use fdi_common::delay::DelayProfile;
    // Under the `step-mean` observer input: the plant and the observer then integrate the same
    // delayed input, continuous in τ. The default `sample` input takes the command in force at
    // t_k − τ, which at a whole number of periods is a stamp itself: one period of difference in
    // what the observer sees, by construction (docs/model.md, "Numerics of the delayed input").
    let with_delay = |value_s: f64| {
        let mut r = paper(10.0);
        r.scenario.controller.observer_input = fdi_common::control::ObserverInput::StepMean;
        for a in &mut r.scenario.agents {
            a.delay = DelayProfile::Constant { value_s };
        }
        r
    };
    for ms in 1..=5u32 {
        let tau = f64::from(ms) * 1e-3;
        let (exact, _) = trace(&with_delay(tau));
        let (hair, _) = trace(&with_delay(tau + 1e-7));
        let rmse = |recs: &[TickRecord]| {
            let r = paper(10.0);
            let mut e = fdi_common::engine::evaluator_for(&r);
            for rec in recs {
                e.push(rec);
            }
            e.finish()
        };
        let (a, b) = (rmse(&exact), rmse(&hair));
        for (id, m) in &a {
            let other = b[id].rmse_rad;
            assert!(
                (m.rmse_rad - other).abs() <= 0.01 * other,
                "τ = {ms} ms, robot {id}: RMSE {} vs {other} at τ + 1e-7 s",
                m.rmse_rad
            );
            assert_eq!(m.deadline_misses, 0, "τ = {ms} ms, robot {id}");
        }
        // Once the first command is due (t ≥ τ), no step applies zero torque.
        for rec in exact.iter().filter(|r| r.agent.t >= tau) {
            assert!(
                rec.agent.u_applied.as_slice().iter().any(|u| *u != 0.0),
                "τ = {ms} ms: zero torque applied at t = {} (robot {})",
                rec.agent.t,
                rec.agent.agent
            );
        }
    }
}

/// Relays every message unchanged, and says so.
struct Relay;

impl fdi_common::attack::Attacker for Relay {
    fn name(&self) -> &str {
        "relay"
    }

    fn measurement<const N: usize>(
        &mut self,
        _agent: u32,
        _k: u64,
        _t: f64,
        clean: &fdi_common::plant::Measurement<N>,
    ) -> (
        fdi_common::attack::Sent<fdi_common::plant::Measurement<N>>,
        fdi_common::attack::Injection<N>,
    ) {
        (
            fdi_common::attack::Sent::Delivered {
                payload: *clean,
                held_s: 0.0,
            },
            fdi_common::attack::Injection::none(),
        )
    }
}

#[test]
fn execute_with_writes_the_run_directory_of_a_supplied_attacker_on_the_inproc_engine_only() {
    use fdi_common::run_dir::Process;
    use fdi_orchestrator::{execute_with, Engine, Overrides, RunRequest, Stop};
    let out = std::env::temp_dir().join(format!("fdi-execute-with-{}", std::process::id()));
    let overrides = Overrides {
        duration_s: Some(0.5),
        ..Overrides::default()
    };
    let request = RunRequest::new(None, &overrides, Engine::Inproc).expect("request");
    let dir = request.create_run_dir(&out).expect("run directory");
    let summary = execute_with(&request, &dir, &Stop::new(), &mut Relay).expect("runs");
    assert_eq!(summary.attack, "relay");
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.summary()).expect("summary.json"))
            .expect("JSON");
    assert_eq!(written["attack"], "relay");
    assert_eq!(written["trace_digest"], summary.trace_digest.as_str());
    assert!(dir.trace(Process::Attacker).is_file());

    let ipc = RunRequest::new(None, &overrides, Engine::Ipc).expect("request");
    let dir = ipc.create_run_dir(&out).expect("run directory");
    let e = execute_with(&ipc, &dir, &Stop::new(), &mut Relay).expect_err("refused");
    assert!(e.to_string().contains("ipc engine"), "{e:#}");
    assert!(
        !dir.path().exists(),
        "a refused run leaves no run directory"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// The engine ticked one tick at a time from outside (what the Python environments do) is
/// the whole run, record for record: same digest, same metrics; and the evaluator's per-tick
/// alarm of the paper's detector is the control center's recorded alarm. On a two-link and a
/// three-link scenario.
#[test]
fn the_engine_ticked_from_outside_is_the_whole_run_and_its_alarms_are_the_records() {
    use fdi_common::engine::{run_inproc_any, Lockstep};
    let three = scenario::load_file(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/three-link.toml"),
    )
    .expect("the three-link scenario is valid");
    for mut r in [paper(1.5), three] {
        r.scenario.duration_s = 1.5;
        let mut whole = Vec::new();
        let expected = run_inproc_any(&r, |rec| whole.push(*rec)).expect("runs");
        let mut attacker = r.profile_attacker();
        let mut engine = Lockstep::new(&r).expect("an engine");
        let mut stepped = Vec::new();
        let mut alarms = 0u64;
        let mut ticks = 0u64;
        while engine.tick(&mut attacker, |rec| stepped.push(*rec)) {
            ticks += 1;
            for a in &r.scenario.agents {
                let on = engine.evaluator().alarm(a.id, 0).expect("a known agent");
                alarms += u64::from(on);
                let (error, diverged) = engine.evaluator().tracking(a.id).expect("known");
                assert!(error.is_finite() && !diverged);
            }
        }
        assert_eq!(ticks, r.ticks());
        assert_eq!(engine.k(), r.ticks());
        assert!(
            !engine.tick(&mut attacker, |_| {}),
            "nothing runs after the end"
        );
        let got = engine.finish(&r, "paper");
        assert_eq!(got.trace_digest, expected.trace_digest);
        assert_eq!(got.metrics, expected.metrics);
        assert_eq!(stepped.len(), whole.len());
        let recorded = whole.iter().filter(|rec| rec.center.alarm).count() as u64;
        assert_eq!(alarms, recorded);
        let unknown = engine_unknown(&r);
        assert_eq!(unknown, (None, None));
    }
}

/// The engine's ticking with its books kept elsewhere (the command line's in-process run keeps
/// them on another thread, from the records it is handed) gives the whole run's summary: the
/// same ticks, digest and metrics, and the same records in the same order. On a two-link and a
/// three-link scenario, the second under the psi2 residual's detectors.
#[test]
fn books_kept_from_the_records_are_the_whole_run_s() {
    use fdi_common::engine::{run_inproc_any, tick_inproc_any_with, Books};
    let three = scenario::load_file(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/three-link.toml"),
    )
    .expect("the three-link scenario is valid");
    let mut psi2 = three;
    psi2.scenario.detectors.residual = fdi_common::detect::config::ResidualKind::Psi2;
    for mut r in [paper(2.5), psi2] {
        r.scenario.duration_s = 2.5;
        let mut whole = Vec::new();
        let expected = run_inproc_any(&r, |rec| whole.push(*rec)).expect("runs");
        let mut books = Books::new(&r);
        let mut handed = Vec::new();
        let mut attacker = r.profile_attacker();
        let ticked = tick_inproc_any_with(
            &r,
            &mut attacker,
            |rec| {
                books.push(rec);
                handed.push(*rec);
            },
            || true,
        )
        .expect("runs");
        assert_eq!(ticked.ticks, r.ticks());
        let got = books.summary(&r, ticked.ticks, ticked.wall_s, "paper");
        assert_eq!(got.ticks, expected.ticks);
        assert_eq!(got.trace_digest, expected.trace_digest);
        assert_eq!(got.metrics, expected.metrics);
        assert!(handed == whole, "the same records in the same order");
    }
}

/// The evaluator's answers for an agent and a detector it does not have.
fn engine_unknown(r: &Resolved) -> (Option<bool>, Option<(f64, bool)>) {
    let engine = fdi_common::engine::Lockstep::new(r).expect("an engine");
    let ev = engine.evaluator();
    let detectors = fdi_common::detect::names().len();
    assert_eq!(ev.alarm(r.scenario.agents[0].id, detectors), None);
    (ev.alarm(999, 0), ev.tracking(999))
}
