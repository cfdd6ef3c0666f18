//! The attacker as a value: the profile attacker through the engine's new entry point is the
//! engine's run of the profile, and an attacker that injects nothing is the profile `none`.

use fdi_common::attack::{presets, Attacker, Injection, Sent};
use fdi_common::engine::{run_inproc_any, run_inproc_any_with, RunSummary};
use fdi_common::plant::Measurement;
use fdi_common::records::TickRecord;
use fdi_common::scenario::{self, Resolved};

/// The paper scenario under the shipped preset `attack`, cut to 11 s: every preset below acts
/// from 10 s.
fn paper_with(attack: &str) -> Resolved {
    let mut r = scenario::paper().expect("embedded paper scenario");
    r.scenario.duration_s = 11.0;
    r.attack = presets::preset(attack)
        .expect("shipped preset")
        .for_agents(&r.scenario.agent_dofs());
    assert!(r.attack.problems(&r.scenario.agent_dofs()).is_empty());
    r
}

fn records(run: impl FnOnce(&mut dyn FnMut(&TickRecord)) -> RunSummary) -> (RunSummary, usize) {
    let mut actuations = 0;
    let summary = run(&mut |rec: &TickRecord| actuations += usize::from(rec.actuation.is_some()));
    (summary, actuations)
}

#[test]
fn the_profile_attacker_through_run_inproc_any_with_gives_the_digest_of_run_inproc_any() {
    let none = run_inproc_any(&paper_with("none"), |_| {}).expect("runs");
    for (preset, torque_path) in [
        ("paper", false),
        ("covert", true),
        ("freeze", false),
        ("torque-delay", true),
        ("dos-drop", false),
    ] {
        let r = paper_with(preset);
        let (before, before_actuations) = records(|sink| run_inproc_any(&r, sink).expect("runs"));
        let mut attacker = r.profile_attacker();
        assert_eq!(attacker.name(), preset);
        let (with, with_actuations) =
            records(|sink| run_inproc_any_with(&r, &mut attacker, sink).expect("runs"));
        assert_eq!(with.trace_digest, before.trace_digest, "{preset}");
        assert_eq!(with.attack, preset);
        assert_eq!(with.metrics, before.metrics, "{preset}");
        assert_eq!(with_actuations, before_actuations, "{preset}");
        assert_eq!(with_actuations > 0, torque_path, "{preset}: torque path");
        assert_ne!(
            with.trace_digest, none.trace_digest,
            "{preset} acts by 11 s"
        );
    }
}

/// Relays every message unchanged and says so.
struct Relay;

impl Attacker for Relay {
    fn name(&self) -> &str {
        "relay"
    }

    fn measurement<const N: usize>(
        &mut self,
        _agent: u32,
        _k: u64,
        _t: f64,
        clean: &Measurement<N>,
    ) -> (Sent<Measurement<N>>, Injection<N>) {
        (
            Sent::Delivered {
                payload: *clean,
                held_s: 0.0,
            },
            Injection::none(),
        )
    }
}

#[test]
fn an_attacker_that_injects_nothing_gives_the_digest_of_the_profile_none() {
    // The scenario's own profile (the paper's attack) is ignored: the supplied attacker decides.
    let r = paper_with("paper");
    let none = run_inproc_any(&paper_with("none"), |_| {}).expect("runs");
    let relay = run_inproc_any_with(&r, &mut Relay, |_| {}).expect("runs");
    assert_eq!(relay.trace_digest, none.trace_digest);
    assert_eq!(relay.metrics, none.metrics);
    assert_eq!(relay.attack, "relay");
    assert_eq!(none.attack, "none");
}
