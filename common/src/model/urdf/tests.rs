use std::path::Path;

use nalgebra::DMatrix;
use proptest::prelude::*;
use rand::Rng as _;

use super::*;
use crate::model::robot::{free_motion, EulerLagrange, Forward, Vector};
use crate::model::{ThreeLink, ThreeLinkParams, TwoLink, TwoLinkParams};

const PAPER: &str = include_str!("../../../../scenarios/robots/paper-two-link.urdf");
const THREE: &str = include_str!("../../../../scenarios/robots/three-link.urdf");

/// A spatial arm that uses what a real arm's file does: origins with rotations, axes that are
/// not unit, a prismatic joint, fixed joints (a flange, a tool), a locked finger, inertias off
/// their principal axes, a mesh behind `package://` (never looked for), limits and friction.
const SPATIAL: &str = r#"<?xml version="1.0"?>
<robot name="spatial">
  <link name="world"/>
  <link name="base"><inertial><mass value="4"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l1">
    <visual><geometry><mesh filename="package://nowhere/l1.dae"/></geometry></visual>
    <inertial><origin xyz="0.01 -0.02 0.1" rpy="0.1 0.2 0.3"/><mass value="3.2"/>
      <inertia ixx="0.04" ixy="0.001" ixz="-0.002" iyy="0.05" iyz="0.003" izz="0.02"/></inertial>
  </link>
  <link name="l2"><inertial><origin xyz="0.15 0 0.02" rpy="0 0.4 0"/><mass value="2.1"/>
      <inertia ixx="0.02" ixy="0" ixz="0.001" iyy="0.03" iyz="0" izz="0.025"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0 0.05 0.1"/><mass value="1.4"/>
      <inertia ixx="0.01" ixy="0.0005" ixz="0" iyy="0.012" iyz="0" izz="0.008"/></inertial></link>
  <link name="flange"><inertial><origin xyz="0 0 0.03"/><mass value="0.3"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <link name="l4"><inertial><origin xyz="0.02 0 0.05" rpy="-0.3 0 0.2"/><mass value="0.9"/>
      <inertia ixx="0.004" ixy="0" ixz="0.0002" iyy="0.005" iyz="0" izz="0.003"/></inertial></link>
  <link name="slider"><inertial><origin xyz="0 0 0.04"/><mass value="0.5"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <link name="finger"><inertial><origin xyz="0 0.01 0"/><mass value="0.1"/>
      <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/></inertial></link>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0.1 0.2 0.3" rpy="0 0 0.5"/></joint>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 2"/><limit lower="-2.8" upper="2.8" effort="80" velocity="2"/><dynamics damping="0.5" friction="0.2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2" rpy="-1.5707963 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1.7" upper="1.7" effort="80" velocity="2"/></joint>
  <joint name="j3" type="continuous"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0" rpy="0.3 -0.2 0.1"/>
    <axis xyz="1 1 0"/></joint>
  <joint name="tool" type="fixed"><parent link="l3"/><child link="flange"/><origin xyz="0 0 0.2" rpy="0 0.1 0"/></joint>
  <joint name="j4" type="revolute"><parent link="flange"/><child link="l4"/><origin xyz="0 0 0.05" rpy="1.5707963 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="10" velocity="3"/><dynamics damping="0.1"/></joint>
  <joint name="j5" type="prismatic"><parent link="l4"/><child link="slider"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.2" effort="50" velocity="0.5"/></joint>
  <joint name="finger_joint" type="prismatic"><parent link="slider"/><child link="finger"/><origin xyz="0 0 0.05"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="5" velocity="0.1"/></joint>
</robot>
"#;

fn spec() -> UrdfSpec {
    UrdfSpec::new("test.urdf")
}

fn chain(text: &str, spec: &UrdfSpec) -> Chain {
    Chain::parse(text, spec, Path::new("test.urdf")).expect("the arm reads")
}

fn spatial() -> Chain {
    let mut s = spec();
    s.lock.insert("finger_joint".into(), 0.02);
    chain(SPATIAL, &s)
}

fn refusal(text: &str, spec: &UrdfSpec) -> String {
    Chain::parse(text, spec, Path::new("test.urdf"))
        .expect_err("refused")
        .to_string()
}

/// `|a − b| ≤ tol · max(1, |b|)` entry by entry.
fn close(a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64, what: &str) {
    assert_eq!(a.shape(), b.shape(), "{what}");
    for (x, y) in a.iter().zip(b.iter()) {
        assert!(
            (x - y).abs() <= tol * y.abs().max(1.0),
            "{what}: {x} vs {y}\n{a}\n{b}"
        );
    }
}

fn dyn_of<const N: usize>(m: &nalgebra::SMatrix<f64, N, N>) -> DMatrix<f64> {
    DMatrix::from_iterator(N, N, m.iter().copied())
}

#[test]
fn the_paper_arm_as_a_urdf_is_the_hand_written_model() {
    let urdf = UrdfArm::<2>::new(chain(PAPER, &spec())).expect("two joints");
    let paper = TwoLink::new(TwoLinkParams::PAPER);
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(7);
    for _ in 0..200 {
        let q = Vector::<2>::from_fn(|_, _| rng.random_range(-3.0..3.0));
        let qd = Vector::<2>::from_fn(|_, _| rng.random_range(-4.0..4.0));
        close(
            &dyn_of(&urdf.inertia(&q)),
            &dyn_of(&paper.inertia(&q)),
            1e-12,
            "M",
        );
        close(
            &dyn_of(&urdf.coriolis(&q, &qd)),
            &dyn_of(&paper.coriolis(&q, &qd)),
            1e-12,
            "V",
        );
        close(
            &dyn_of(&urdf.inertia_rate(&q, &qd)),
            &dyn_of(&paper.inertia_rate(&q, &qd)),
            1e-12,
            "Ṁ",
        );
        assert_eq!(urdf.gravity(&q), Vector::<2>::zeros(), "G");
        let (f, g) = (urdf.friction(&qd), paper.friction(&qd));
        assert!(
            (f - g).abs().max() <= 1e-12 * g.abs().max().max(1.0),
            "F {f} {g}"
        );
    }
}

#[test]
fn the_three_link_arm_as_a_urdf_is_the_hand_written_model_with_and_without_gravity() {
    for g in [0.0, 9.81] {
        let mut s = spec();
        s.gravity = [0.0, -g, 0.0];
        let urdf = UrdfArm::<3>::new(chain(THREE, &s)).expect("three joints");
        let hand = ThreeLink::new(ThreeLinkParams {
            gravity_m_s2: g,
            ..ThreeLinkParams::DEFAULT
        });
        let q = Vector::<3>::new(0.3, -1.1, 2.0);
        let qd = Vector::<3>::new(-0.7, 1.5, 0.4);
        close(
            &dyn_of(&urdf.inertia(&q)),
            &dyn_of(&hand.inertia(&q)),
            1e-12,
            "M",
        );
        close(
            &dyn_of(&urdf.coriolis(&q, &qd)),
            &dyn_of(&hand.coriolis(&q, &qd)),
            1e-12,
            "V",
        );
        let (a, b) = (urdf.gravity(&q), hand.gravity(&q));
        assert!(
            (a - b).abs().max() <= 1e-12 * b.abs().max().max(1.0),
            "G {a} {b}"
        );
    }
}

#[test]
fn the_loader_reads_joints_limits_masses_and_folds_fixed_and_locked_joints() {
    let c = spatial();
    assert_eq!(c.joint_names(), ["j1", "j2", "j3", "j4", "j5"]);
    assert_eq!(c.joints[0].limits, Some((-2.8, 2.8)));
    assert_eq!(c.joints[2].limits, None, "continuous");
    assert_eq!(c.joints[4].motion, Motion::Prismatic);
    assert_eq!((c.joints[0].damping, c.joints[0].friction), (0.5, 0.2));
    assert!(
        (c.joints[0].axis.norm() - 1.0).abs() < 1e-15,
        "axes are made unit"
    );
    // The base does not move: not a body. The flange rides on j3, the finger on j5.
    let riding: Vec<(&str, usize)> = (c.bodies.iter())
        .map(|b| (b.link.as_str(), b.rides_on))
        .collect();
    assert_eq!(
        riding,
        [
            ("l1", 0),
            ("l2", 1),
            ("l3", 2),
            ("flange", 2),
            ("l4", 3),
            ("slider", 4),
            ("finger", 4)
        ]
    );
    assert_eq!(c.masses.len(), 9);
    // The lock's value moves the finger's mass: the inertia differs.
    let mut other = spec();
    other.lock.insert("finger_joint".into(), 0.0);
    let q = [0.1, 0.2, 0.3, 0.4, 0.05];
    assert_ne!(chain(SPATIAL, &other).inertia(&q), c.inertia(&q));
}

#[test]
fn what_is_not_an_arm_is_refused_naming_the_joint_or_link() {
    // The finger moves too: two joints after j5's child... it follows j5, so it is the arm's
    // sixth joint; named as a branch once the tip is the slider.
    let mut s = spec();
    s.tip = Some("slider".into());
    let e = refusal(SPATIAL, &s);
    assert!(
        e.contains("joint `finger_joint`") && e.contains("tip `slider`"),
        "{e}"
    );

    let floating = SPATIAL.replace(
        r#"name="mount" type="fixed""#,
        r#"name="mount" type="floating""#,
    );
    let e = refusal(&floating, &spec());
    assert!(e.contains("joint `mount`") && e.contains("Floating"), "{e}");

    let mimic = SPATIAL.replace(
        r#"<axis xyz="0 1 0"/><limit lower="0" upper="0.04""#,
        r#"<mimic joint="j5"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04""#,
    );
    let e = refusal(&mimic, &spec());
    assert!(
        e.contains("joint `finger_joint`") && e.contains("mimics joint `j5`"),
        "{e}"
    );
    let mut locked = spec();
    locked.lock.insert("finger_joint".into(), 0.0);
    assert_eq!(
        chain(&mimic, &locked).dof(),
        5,
        "a locked mimic joint is held"
    );

    let closed = SPATIAL.replace(
        "</robot>",
        r#"<joint name="loop" type="fixed"><parent link="l1"/><child link="l3"/></joint></robot>"#,
    );
    let e = refusal(&closed, &spec());
    assert!(
        e.contains("joint `loop`") && e.contains("closed chain"),
        "{e}"
    );

    let branch = SPATIAL.replace(
        "</robot>",
        r#"<link name="side"><inertial><mass value="0.1"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
        <joint name="side_joint" type="revolute"><parent link="l1"/><child link="side"/><axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"#,
    );
    let e = refusal(&branch, &locked);
    assert!(
        e.contains("branches") && e.contains("after joint `j1`"),
        "{e}"
    );

    let mut unknown = spec();
    unknown.lock.insert("elbow".into(), 0.0);
    let e = refusal(SPATIAL, &unknown);
    assert!(e.contains("joint `elbow`") && e.contains("locked"), "{e}");

    let negative = SPATIAL.replace(r#"<mass value="2.1"/>"#, r#"<mass value="-2.1"/>"#);
    let e = refusal(&negative, &locked);
    assert!(e.contains("link `l2`") && e.contains("negative"), "{e}");

    let e = refusal("<robot name='x'><link name='a'/></robot>", &spec());
    assert!(e.contains("no joint below link `a` moves"), "{e}");
    let e = refusal("not xml", &spec());
    assert!(e.contains("not a URDF file"), "{e}");
}

#[test]
fn a_joint_s_limits_are_its_file_s_and_a_lock_stays_inside_them() {
    let finger = |value: f64| {
        let mut s = spec();
        s.lock.insert("finger_joint".into(), value);
        s
    };
    let c = spatial();
    assert_eq!(c.joints[1].limits, Some((-1.7, 1.7)), "j2's, as written");
    assert_eq!(c.joints[2].limits, None, "j3 is continuous");

    // Without `<limit>` the parser reads zeros, which would hold the joint at 0: a moving
    // revolute joint without one is refused, naming it; locked, it needs none.
    let no_limit = SPATIAL.replace(
        r#"<limit lower="-1.7" upper="1.7" effort="80" velocity="2"/>"#,
        "",
    );
    let e = refusal(&no_limit, &finger(0.02));
    assert!(
        e.contains("joint `j2`") && e.contains("without `<limit") && e.contains("Revolute"),
        "{e}"
    );
    let mut held = finger(0.02);
    held.lock.insert("j2".into(), 0.3);
    assert_eq!(chain(&no_limit, &held).dof(), 4);

    // A lock outside the joint's limits is refused; at a limit it holds.
    let e = refusal(SPATIAL, &finger(0.5));
    assert!(
        e.contains("joint `finger_joint`")
            && e.contains("locked at 0.5, outside its limits [0, 0.04]"),
        "{e}"
    );
    assert_eq!(chain(SPATIAL, &finger(0.04)).dof(), 5);
    assert_eq!(chain(SPATIAL, &finger(0.0)).dof(), 5);

    // A side at infinity has no limit; the other side still holds, for a lock as for a
    // trajectory.
    let one_sided = SPATIAL.replace(r#"lower="-1.7" upper="1.7""#, r#"lower="-inf" upper="1.7""#);
    let c = chain(&one_sided, &finger(0.02));
    assert_eq!(c.joints[1].limits, Some((f64::NEG_INFINITY, 1.7)));
    let mut past = finger(0.02);
    past.lock.insert("j2".into(), 1.8);
    let e = refusal(&one_sided, &past);
    assert!(
        e.contains("joint `j2`") && e.contains("locked at 1.8, outside"),
        "{e}"
    );
    past.lock.insert("j2".into(), -1e6);
    assert_eq!(chain(&one_sided, &past).dof(), 4);
    let both = SPATIAL.replace(r#"lower="-1.7" upper="1.7""#, r#"lower="-inf" upper="inf""#);
    assert_eq!(chain(&both, &finger(0.02)).joints[1].limits, None);

    let nan = SPATIAL.replace(r#"lower="-1.7""#, r#"lower="nan""#);
    let e = refusal(&nan, &finger(0.02));
    assert!(e.contains("joint `j2`") && e.contains("not numbers"), "{e}");
    let inverted = SPATIAL.replace(r#"lower="-1.7" upper="1.7""#, r#"lower="1.7" upper="-1.7""#);
    let e = refusal(&inverted, &finger(0.02));
    assert!(
        e.contains("joint `j2`") && e.contains("lower limit 1.7 above upper -1.7"),
        "{e}"
    );
}

#[test]
fn a_name_given_twice_or_an_inertia_no_body_has_is_refused_naming_it() {
    let mut locked = spec();
    locked.lock.insert("finger_joint".into(), 0.02);
    let twice = SPATIAL.replace(
        "</robot>",
        r#"<link name="l3"><inertial><mass value="9"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link></robot>"#,
    );
    let e = refusal(&twice, &locked);
    assert!(
        e.contains("link `l3`") && e.contains("defined twice"),
        "{e}"
    );
    let twice = SPATIAL.replace(r#"<joint name="j4""#, r#"<joint name="j2""#);
    let e = refusal(&twice, &locked);
    assert!(
        e.contains("joint `j2`") && e.contains("defined twice"),
        "{e}"
    );

    // Positive definite at q = 0 for the arm as a whole, but no rigid body has this inertia
    // (a negative principal moment): M would lose its definiteness elsewhere.
    let negative = SPATIAL.replace(
        r#"<inertia ixx="0.02" ixy="0" ixz="0.001" iyy="0.03""#,
        r#"<inertia ixx="0.02" ixy="0.05" ixz="0.001" iyy="0.03""#,
    );
    assert_ne!(negative, SPATIAL);
    let e = refusal(&negative, &locked);
    assert!(
        e.contains("link `l2`") && e.contains("not positive semi-definite"),
        "{e}"
    );
    // A point mass (no inertia about its centre) is a body.
    let point = SPATIAL.replace(
        r#"<inertia ixx="0.02" ixy="0" ixz="0.001" iyy="0.03" iyz="0" izz="0.025"/>"#,
        r#"<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>"#,
    );
    assert_ne!(point, SPATIAL);
    assert_eq!(chain(&point, &locked).dof(), 5);
}

#[test]
fn the_composite_rigid_body_inertia_is_the_jacobians_sum() {
    let c = spatial();
    let q = [0.4, -0.9, 1.3, 0.2, 0.07];
    close(&c.inertia(&q), &c.inertia_from_jacobians(&q), 1e-12, "M");
}

fn state(n: usize) -> impl Strategy<Value = (Vec<f64>, Vec<f64>)> {
    (
        proptest::collection::vec(-3.0..3.0f64, n),
        proptest::collection::vec(-3.0..3.0f64, n),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn inertia_is_symmetric_positive_definite((q, _) in state(5)) {
        let m = spatial().inertia(&q);
        prop_assert!((&m - m.transpose()).abs().max() <= 1e-14 * m.abs().max());
        prop_assert!(m.cholesky().is_some(), "not positive definite at {q:?}");
    }

    #[test]
    fn inertia_rate_minus_twice_coriolis_is_skew_symmetric((q, qd) in state(5)) {
        let c = spatial();
        let n = c.inertia_rate(&q, &qd) - 2.0 * c.coriolis(&q, &qd);
        prop_assert!((&n + n.transpose()).abs().max() <= 1e-12 * n.abs().max().max(1.0));
    }

    #[test]
    fn the_derivatives_of_inertia_and_potential_are_those_of_finite_differences((q, _) in state(5)) {
        let c = spatial();
        let h = 1e-6;
        let d = c.inertia_derivatives(&q);
        let g = c.gravity(&q);
        for k in 0..5 {
            let (mut up, mut down) = (q.clone(), q.clone());
            up[k] += h;
            down[k] -= h;
            let numeric = (c.inertia(&up) - c.inertia(&down)) / (2.0 * h);
            prop_assert!((&numeric - &d[k]).abs().max() <= 1e-7, "∂M/∂q{k}");
            let du = (c.potential_energy(&up) - c.potential_energy(&down)) / (2.0 * h);
            prop_assert!((du - g[k]).abs() <= 1e-6 * g[k].abs().max(1.0), "G{k}: {du} vs {}", g[k]);
        }
    }
}

/// `‖a − b‖∞ ≤ tol · max(‖b‖∞, 1)`.
fn near(a: &[f64], b: &[f64], tol: f64) -> bool {
    let scale = b.iter().fold(1.0f64, |m, x| m.max(x.abs()));
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol * scale)
}

/// The arm's hot path (its rigid form: `M`, `G`, the bias forces, the forward dynamics and
/// `M⁻¹`) against the chain's reference methods at `(q, q̇)`; the first term that differs.
fn rigid_differs<const N: usize>(c: &Chain, q: &[f64], qd: &[f64]) -> Option<&'static str> {
    let arm = UrdfArm::<N>::new(c.clone()).expect("N joints");
    let (qv, qdv) = (
        Vector::<N>::from_column_slice(q),
        Vector::<N>::from_column_slice(qd),
    );
    let m = c.inertia(q);
    let bias = c.coriolis(q, qd) * nalgebra::DVector::from_column_slice(qd)
        + c.gravity(q)
        + c.friction(qd);
    let u = nalgebra::DVector::from_fn(N, |i, _| 1.0 - 0.3 * i as f64);
    let d = nalgebra::DVector::from_fn(N, |i, _| 0.05 * i as f64);
    let qdd = m
        .clone()
        .lu()
        .solve(&(&u - &bias - &d))
        .expect("M invertible");
    let inv = m.clone().try_inverse().expect("M invertible");
    let uv = Vector::<N>::from_column_slice(u.as_slice());
    let dv = Vector::<N>::from_column_slice(d.as_slice());
    let own = |v: &[f64]| v.to_vec();
    let checks: [(&'static str, Vec<f64>, Vec<f64>); 7] = [
        ("M", own(arm.inertia(&qv).as_slice()), own(m.as_slice())),
        (
            "G",
            own(arm.gravity(&qv).as_slice()),
            own(c.gravity(q).as_slice()),
        ),
        (
            "V q̇ + G + F",
            own(arm.bias_forces(&qv, &qdv).as_slice()),
            own(bias.as_slice()),
        ),
        (
            "q̈",
            own(arm.acceleration(&qv, &qdv, &uv, &dv).as_slice()),
            own(qdd.as_slice()),
        ),
        (
            "drift",
            own((-arm.drift(&qv, &qdv)).as_slice()),
            own((&inv * &bias).as_slice()),
        ),
        (
            "M⁻¹",
            own(arm.inverse_inertia(&qv).as_slice()),
            own(inv.as_slice()),
        ),
        (
            "V",
            own(arm.coriolis(&qv, &qdv).as_slice()),
            own(c.coriolis(q, qd).as_slice()),
        ),
    ];
    // M and V to rounding; what goes through M⁻¹ within what its condition number allows.
    let tol = |what: &str| {
        if what == "M" || what == "V" {
            1e-12
        } else {
            1e-9
        }
    };
    let differs = checks
        .iter()
        .find(|(what, ours, theirs)| !near(ours, theirs, tol(what)))
        .map(|(what, _, _)| *what);
    differs
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn the_rigid_form_is_the_chain_s_reference((q, qd) in state(5)) {
        let c = spatial();
        prop_assert_eq!(rigid_differs::<5>(&c, &q, &qd), None);
        // The rigid form turns a joint about its frame's own x, y or z by mixing two columns,
        // any other axis by a general rotation: the arm has z, y and (1, 1, 0); with j3 about
        // x, every kind.
        let mut s = spec();
        s.lock.insert("finger_joint".into(), 0.02);
        let about_x = chain(&SPATIAL.replace(r#"<axis xyz="1 1 0"/>"#, r#"<axis xyz="1 0 0"/>"#), &s);
        prop_assert_ne!(&about_x, &c);
        prop_assert_eq!(rigid_differs::<5>(&about_x, &q, &qd), None);
        let paper = chain(PAPER, &spec());
        prop_assert_eq!(rigid_differs::<2>(&paper, &q[..2], &qd[..2]), None);
    }
}

#[test]
fn the_free_arm_keeps_its_energy() {
    let mut s = spec();
    s.lock.insert("finger_joint".into(), 0.02);
    let mut text = SPATIAL.to_string();
    // No friction: a conservative arm.
    text = text.replace(r#"<dynamics damping="0.5" friction="0.2"/>"#, "");
    text = text.replace(r#"<dynamics damping="0.1"/>"#, "");
    let c = chain(&text, &s);
    let arm = UrdfArm::<5>::new(c.clone()).expect("five joints");
    let q0 = Vector::<5>::new(0.3, -0.5, 0.8, 0.1, 0.05);
    let qd0 = Vector::<5>::new(0.5, -0.4, 0.9, -1.0, 0.1);
    let energy = |q: &Vector<5>, qd: &Vector<5>| {
        arm.kinetic_energy(q, qd) + c.potential_energy(q.as_slice())
    };
    let e0 = energy(&q0, &qd0);
    let path = free_motion(&arm, (q0, qd0), 1e-4, 5000);
    let worst = (path.iter())
        .map(|(q, qd)| (energy(q, qd) - e0).abs())
        .fold(0.0, f64::max);
    assert!(
        worst <= 1e-6 * e0.abs().max(1.0),
        "energy drifted by {worst} J of {e0} J"
    );
}

#[test]
fn the_terms_at_a_state_refuse_a_state_of_the_wrong_length_or_not_finite() {
    let c = spatial();
    let e = c.dynamics(&[0.0; 4], &[0.0; 5]).expect_err("four values");
    assert!(
        e.contains("q has 4 values") && e.contains("j1, j2, j3, j4, j5"),
        "{e}"
    );
    let e = c
        .dynamics(&[0.0; 5], &[0.0, f64::NAN, 0.0, 0.0, 0.0])
        .expect_err("NaN");
    assert!(e.contains("not finite"), "{e}");
    let d = c.dynamics(&[0.0; 5], &[0.0; 5]).expect("a state");
    assert_eq!(d.coriolis, DMatrix::zeros(5, 5));
    assert!(d.gravity.iter().any(|g| *g != 0.0));
}

/// One arm of `common/testdata/urdf/arms.json`: its URDF (relative to the repository) and how
/// it is held.
#[derive(Debug, serde::Deserialize)]
struct OracleArm {
    name: String,
    path: std::path::PathBuf,
    #[serde(default)]
    lock: std::collections::BTreeMap<String, f64>,
    gravity: Option<[f64; 3]>,
}

/// Pinocchio's values for one arm (`tests/python/pinocchio_reference.py`).
#[derive(Debug, serde::Deserialize)]
struct Reference {
    pinocchio: String,
    joints: Vec<String>,
    states: Vec<ReferenceState>,
}

#[derive(Debug, serde::Deserialize)]
struct ReferenceState {
    q: Vec<f64>,
    qd: Vec<f64>,
    tau: Vec<f64>,
    inertia: Vec<Vec<f64>>,
    coriolis_qd: Vec<f64>,
    gravity: Vec<f64>,
    acceleration: Vec<f64>,
}

/// `‖a − b‖∞ ≤ 1e-9 ‖b‖∞`.
fn agrees(a: &[f64], b: &[f64], what: &str) {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let worst = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(
        worst <= 1e-9 * scale,
        "{what}: off by {worst:e} of {scale:e}\nours       {a:?}\nPinocchio  {b:?}"
    );
}

#[test]
fn every_arm_agrees_with_pinocchio_at_its_reference_states() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the repository");
    let data = repo.join("common/testdata/urdf");
    let arms: Vec<OracleArm> =
        serde_json::from_str(&std::fs::read_to_string(data.join("arms.json")).expect("arms.json"))
            .expect("arms.json reads");
    assert!(arms.len() >= 4, "the shipped arms and real ones");
    for arm in &arms {
        let mut spec = UrdfSpec::new(repo.join(&arm.path));
        spec.lock.clone_from(&arm.lock);
        spec.gravity = arm.gravity.unwrap_or(GRAVITY);
        let c = Chain::load(&spec, Path::new("")).expect("the arm reads");
        let file = data.join(format!("{}.ref.json", arm.name));
        let r: Reference =
            serde_json::from_str(&std::fs::read_to_string(&file).expect("its reference"))
                .expect("the reference reads");
        // Pinocchio's order of the joints in ours.
        let ours = c.joint_names();
        let at: Vec<usize> = (r.joints.iter())
            .map(|n| ours.iter().position(|o| o == n).expect("the same joints"))
            .collect();
        assert_eq!(
            at.len(),
            c.dof(),
            "{}: {:?} vs {ours:?}",
            arm.name,
            r.joints
        );
        let n = c.dof();
        for (s, st) in r.states.iter().enumerate() {
            let what =
                |t: &str| format!("{} (Pinocchio {}), state {s}: {t}", arm.name, r.pinocchio);
            let mut q = vec![0.0; n];
            let mut qd = vec![0.0; n];
            let mut tau = nalgebra::DVector::zeros(n);
            for (i, &k) in at.iter().enumerate() {
                (q[k], qd[k], tau[k]) = (st.q[i], st.qd[i], st.tau[i]);
            }
            let m = c.inertia(&q);
            let ours_m: Vec<f64> = (0..n)
                .flat_map(|i| (0..n).map(move |j| (i, j)))
                .map(|(i, j)| m[(at[i], at[j])])
                .collect();
            let theirs_m: Vec<f64> = st.inertia.iter().flatten().copied().collect();
            agrees(&ours_m, &theirs_m, &what("M"));
            let v = c.coriolis(&q, &qd) * nalgebra::DVector::from_column_slice(&qd);
            let g = c.gravity(&q);
            let qdd = m
                .clone()
                .lu()
                .solve(&(&tau - &v - &g))
                .expect("M invertible");
            let pick =
                |x: &nalgebra::DVector<f64>| -> Vec<f64> { at.iter().map(|&k| x[k]).collect() };
            agrees(&pick(&v), &st.coriolis_qd, &what("V q̇"));
            agrees(&pick(&g), &st.gravity, &what("G"));
            agrees(&pick(&qdd), &st.acceleration, &what("q̈"));
            // The hot path a run takes is the chain's reference, so Pinocchio's too.
            let differs = crate::with_joint_count!(n, N => rigid_differs::<N>(&c, &q, &qd))
                .unwrap_or_else(|| panic!("{}: {n} joints, not a joint count", arm.name));
            assert_eq!(differs, None, "{}", what("the rigid form"));
        }
    }
}

/// Every bit of `a` and `b`, entry by entry (a `−0` is not a `0`; a NaN is a NaN).
fn bits(a: &[f64]) -> Vec<u64> {
    a.iter().map(|x| x.to_bits()).collect()
}

/// The four states' `q̈`, drifts and `M⁻¹` side by side, as the arm computes them for
/// processors with 256-bit vectors and for others, against each state's alone: the same bits.
fn side_by_side_differs<const N: usize>(
    arm: &UrdfArm<N>,
    states: &[(Vector<N>, Vector<N>); 4],
) -> Option<String> {
    let u: [Vector<N>; 4] =
        std::array::from_fn(|l| Vector::<N>::from_fn(|i, _| 1.0 - 0.3 * (i + l) as f64));
    let d: [Vector<N>; 4] =
        std::array::from_fn(|l| Vector::<N>::from_fn(|i, _| 0.05 * (i * l) as f64));
    let forward: [Forward<'_, N>; 4] =
        std::array::from_fn(|l| (&states[l].0, &states[l].1, &u[l], &d[l]));
    let pairs: [(&Vector<N>, &Vector<N>); 4] =
        std::array::from_fn(|l| (&states[l].0, &states[l].1));
    let qs: [&Vector<N>; 4] = std::array::from_fn(|l| &states[l].0);
    for l in 0..4 {
        let (q, qd) = &states[l];
        let alone = [
            bits(arm.acceleration(q, qd, &u[l], &d[l]).as_slice()),
            bits(arm.drift(q, qd).as_slice()),
            bits(arm.inverse_inertia(q).as_slice()),
        ];
        let together = [
            (
                "q̈",
                arm.accelerations(&forward)[l].as_slice().to_vec(),
                arm.accelerations_here(&forward)[l].as_slice().to_vec(),
            ),
            (
                "drift",
                arm.drifts(&pairs)[l].as_slice().to_vec(),
                arm.drifts_here(&pairs)[l].as_slice().to_vec(),
            ),
            (
                "M⁻¹",
                arm.inverse_inertias(&qs)[l].as_slice().to_vec(),
                arm.inverse_inertias_here(&qs)[l].as_slice().to_vec(),
            ),
        ];
        for ((what, wide, here), alone) in together.iter().zip(&alone) {
            if bits(wide) != *alone || bits(here) != *alone {
                return Some(format!("{what} of state {l}"));
            }
        }
    }
    None
}

fn states<const N: usize>(values: &[(Vec<f64>, Vec<f64>)]) -> [(Vector<N>, Vector<N>); 4] {
    std::array::from_fn(|l| {
        let (q, qd) = &values[l];
        (
            Vector::<N>::from_column_slice(&q[..N]),
            Vector::<N>::from_column_slice(&qd[..N]),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn side_by_side_the_arm_computes_each_state_s_bits(values in proptest::collection::vec(state(7), 4)) {
        // Every kind of joint (about a frame's own axis and another, prismatic), and the Panda.
        let spatial = UrdfArm::<5>::new(spatial()).expect("five joints");
        prop_assert_eq!(side_by_side_differs(&spatial, &states::<5>(&values)), None);
        let mut spec = UrdfSpec::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("testdata/urdf/panda.urdf"));
        spec.lock = [("panda_finger_joint1", 0.02), ("panda_finger_joint2", 0.02)]
            .map(|(j, v)| (j.to_string(), v))
            .into();
        let panda = UrdfArm::<7>::new(Chain::load(&spec, Path::new("")).expect("the Panda reads")).expect("seven joints");
        prop_assert_eq!(side_by_side_differs(&panda, &states::<7>(&values)), None);
    }
}

#[test]
fn side_by_side_a_state_without_forward_dynamics_leaves_the_others_bits() {
    // A NaN in one state: its `M` has no factor, and each state is then computed alone.
    let arm = UrdfArm::<5>::new(spatial()).expect("five joints");
    let mut values: Vec<(Vec<f64>, Vec<f64>)> = (0..4)
        .map(|l| (vec![0.1 * l as f64; 7], vec![-0.2; 7]))
        .collect();
    values[2].0[1] = f64::NAN;
    let states = states::<5>(&values);
    assert_eq!(side_by_side_differs(&arm, &states), None);
    assert!(arm
        .drift(&states[2].0, &states[2].1)
        .iter()
        .all(|x| x.is_nan()));
    assert!(arm
        .drift(&states[1].0, &states[1].1)
        .iter()
        .all(|x| x.is_finite()));
}
