//! `fdi-launch model FILE.urdf`: a URDF arm's joints and its dynamics at a state, as text and
//! as JSON, the same as the hand-written model of the same arm; bad input named.

use std::time::Duration;

use fdi_common::model::{EulerLagrange, TwoLink, TwoLinkParams, Vector};
use fdi_tests::{launch_plain, repo_path, Scratch};

const WATCHDOG: Duration = Duration::from_secs(60);

fn paper_urdf() -> String {
    repo_path("scenarios/robots/paper-two-link.urdf")
        .to_string_lossy()
        .into_owned()
}

#[test]
fn the_json_of_the_paper_arm_s_file_is_the_hand_written_model_at_that_state() {
    let file = paper_urdf();
    let out = launch_plain(
        &[
            "model", &file, "--q", "0.3,-1.2", "--qd", "0.7,2.5", "--json",
        ],
        WATCHDOG,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["joints"], serde_json::json!(["joint1", "joint2"]));
    assert_eq!(v["inertia_positive_definite"], serde_json::json!(true));
    let paper = TwoLink::new(TwoLinkParams::PAPER);
    let (q, qd) = (Vector::<2>::new(0.3, -1.2), Vector::<2>::new(0.7, 2.5));
    let rows = |key: &str| -> Vec<Vec<f64>> {
        serde_json::from_value(v[key].clone()).unwrap_or_else(|e| panic!("{key}: {e}"))
    };
    let list = |key: &str| -> Vec<f64> {
        serde_json::from_value(v[key].clone()).unwrap_or_else(|e| panic!("{key}: {e}"))
    };
    let (m, c) = (paper.inertia(&q), paper.coriolis(&q, &qd));
    let (inertia, coriolis) = (rows("inertia"), rows("coriolis"));
    for i in 0..2 {
        for j in 0..2 {
            assert!(
                (inertia[i][j] - m[(i, j)]).abs() <= 1e-12,
                "M {inertia:?} vs {m}"
            );
            assert!(
                (coriolis[i][j] - c[(i, j)]).abs() <= 1e-12,
                "V {coriolis:?} vs {c}"
            );
        }
    }
    assert_eq!(list("gravity"), [0.0, 0.0]);
    let (f, friction) = (paper.friction(&qd), list("friction"));
    for i in 0..2 {
        assert!((friction[i] - f[i]).abs() <= 1e-12, "F {friction:?} vs {f}");
    }
}

/// `fdi-launch model FILE`'s text, the command having succeeded.
fn model_text(file: &str) -> String {
    let out = launch_plain(&["model", file], WATCHDOG);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn the_text_names_the_joints_and_the_terms_and_bad_input_is_named() {
    let file = paper_urdf();
    let text = model_text(&file);
    for want in [
        "2 moving joints",
        "joint1",
        "joint2",
        "M(q) =",
        "V(q, q̇) =",
        "G(q) =",
        "F(q̇) =",
    ] {
        assert!(text.contains(want), "{want} missing:\n{text}");
    }
    for (args, want) in [
        (
            vec!["--q", "0.1"],
            "q has 1 values, the arm 2 joints (joint1, joint2)",
        ),
        (vec!["--q", "0.1,x"], "`x` is not a number"),
        (
            vec!["--lock", "elbow=0"],
            "joint `elbow`: locked, but no joint of the file",
        ),
        (vec!["--lock", "joint2"], "a lock is JOINT=VALUE"),
        (vec!["--gravity", "0,0"], "--gravity: 3 values"),
    ] {
        let mut all = vec!["model", file.as_str()];
        all.extend(args);
        let out = launch_plain(&all, WATCHDOG);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(want),
            "{all:?}: {err}"
        );
    }
    let out = launch_plain(&["model", "no/such.urdf"], WATCHDOG);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("no/such.urdf"),
        "{err}"
    );
}

#[test]
fn an_arm_without_a_forward_dynamics_at_the_state_is_said_so() {
    // The moving link has no <inertial>: M = 0 at every state.
    let dir = Scratch::new("model-massless");
    let file = dir.0.join("massless.urdf");
    std::fs::write(
        &file,
        r#"<robot name="massless"><link name="base"/><link name="arm"/>
        <joint name="turn" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/></joint></robot>"#,
    )
    .expect("write the URDF");
    let file = file.to_string_lossy().into_owned();
    let text = model_text(&file);
    assert!(
        text.contains("moving with the joints: 0.000000 kg")
            && text.contains("M(q) is not positive definite at this state"),
        "{text}"
    );
    let out = launch_plain(&["model", &file, "--json"], WATCHDOG);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["inertia_positive_definite"], serde_json::json!(false));

    // The paper's arm has one.
    let text = model_text(&paper_urdf());
    assert!(!text.contains("not positive definite"), "{text}");
}
