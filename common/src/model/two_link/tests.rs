use super::*;
use approx::assert_relative_eq;

fn arm() -> TwoLink {
    TwoLink::new(TwoLinkParams::PAPER)
}

fn grid() -> impl Iterator<Item = Vector<2>> {
    (-12..=12).flat_map(|i| {
        (-12..=12).map(move |j| Vector::<2>::new(f64::from(i) * 0.27, f64::from(j) * 0.27))
    })
}

#[test]
fn inertia_is_symmetric_positive_definite_over_a_grid() {
    let arm = arm();
    for q in grid() {
        let m = arm.inertia(&q);
        assert_eq!(m[(0, 1)], m[(1, 0)], "M not symmetric at {q:?}");
        let eig = m.symmetric_eigenvalues();
        assert!(eig.min() > 0.0, "M not PD at {q:?}: {eig:?}");
    }
    assert!(TwoLinkParams::PAPER.is_positive_definite());
}

#[test]
fn inertia_rate_minus_twice_coriolis_is_skew_symmetric() {
    // ẋᵀ(Ṁ − 2V)ẋ = 0 for every x: passivity of the Euler–Lagrange form. Only round-off
    // separates the sum from zero, hence the absolute 1e-12 tolerance.
    let arm = arm();
    for q in grid() {
        for qd in grid().step_by(37) {
            let s = arm.inertia_rate(&q, &qd) - 2.0 * arm.coriolis(&q, &qd);
            for x in grid().step_by(53) {
                let v = x.dot(&(s * x));
                assert!(v.abs() < 1e-12, "xᵀ(Ṁ−2V)x = {v} at q={q:?} q̇={qd:?}");
            }
        }
    }
}

#[test]
fn inertia_rate_matches_finite_difference() {
    let arm = arm();
    let q = Vector::<2>::new(0.3, -0.8);
    let qd = Vector::<2>::new(1.1, 2.3);
    let h = 1e-6;
    let fd = (arm.inertia(&(q + qd * h)) - arm.inertia(&(q - qd * h))) / (2.0 * h);
    // Central difference: O(h²) truncation, ~1e-10 round-off for entries of order 1.
    assert_relative_eq!(arm.inertia_rate(&q, &qd), fd, epsilon = 1e-8);
}

#[test]
fn closed_form_inverse_matches_lu() {
    let arm = arm();
    for q in grid().step_by(7) {
        let lu = arm.inertia(&q).try_inverse().expect("PD matrix inverts");
        assert_relative_eq!(arm.inverse_inertia(&q), lu, epsilon = 1e-12);
    }
}

#[test]
fn unforced_arm_with_friction_loses_energy() {
    // Integrate the free arm (u = 0, d = 0) with small RK4 steps: kinetic energy must fall
    // monotonically, since dE/dt = −q̇ᵀ F q̇ < 0 for q̇ ≠ 0 (G = 0, Ṁ − 2V skew).
    let arm = arm();
    let (q, qd) = (Vector::<2>::new(0.4, -1.0), Vector::<2>::new(2.0, -3.0));
    let mut energy = arm.kinetic_energy(&q, &qd);
    let e0 = energy;
    for (q, qd) in crate::model::robot::free_motion(&arm, (q, qd), 1e-3, 2000) {
        let e = arm.kinetic_energy(&q, &qd);
        assert!(e < energy, "energy rose from {energy} to {e}");
        energy = e;
    }
    assert!(
        energy < 0.01 * e0,
        "after 2 s friction should remove >99% of {e0}, left {energy}"
    );
}
