//! Cost of a URDF arm's dynamics (`cargo bench -p fdi-common --bench urdf`): `M(q)`, `V(q, q̇)`,
//! `G(q)`, `M⁻¹`, the bias forces `V q̇ + G + F` and the forward dynamics `q̈` (what the plant's
//! integrator asks four times a tick) of
//! the paper's two-link arm written as a URDF, beside the hand-written model, and of a Panda
//! (7 joints, `common/testdata/urdf/panda.urdf`, its fingers locked). Measured, not asserted:
//! docs/performance.md has the figures.

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use fdi_common::model::robot::{Forward, LANES};
use fdi_common::model::urdf::{Chain, UrdfArm, UrdfSpec};
use fdi_common::model::{EulerLagrange, TwoLink, TwoLinkParams, Vector};

fn arm<const N: usize>(rel: &str, locks: &[(&str, f64)]) -> UrdfArm<N> {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut spec = UrdfSpec::new(repo.join(rel));
    spec.lock = locks.iter().map(|(j, v)| (j.to_string(), *v)).collect();
    let chain = Chain::load(&spec, Path::new("")).expect("the arm reads");
    UrdfArm::new(chain).expect("its number of joints")
}

fn terms<const N: usize>(c: &mut Criterion, name: &str, model: &dyn EulerLagrange<N>) {
    let q = Vector::<N>::from_fn(|i, _| 0.1 + 0.2 * i as f64);
    let qd = Vector::<N>::from_fn(|i, _| 0.5 - 0.15 * i as f64);
    let u = Vector::<N>::from_element(1.0);
    let zero = Vector::<N>::zeros();
    c.bench_function(&format!("{name}/inertia"), |b| {
        b.iter(|| black_box(model.inertia(black_box(&q))));
    });
    c.bench_function(&format!("{name}/coriolis"), |b| {
        b.iter(|| black_box(model.coriolis(black_box(&q), black_box(&qd))));
    });
    c.bench_function(&format!("{name}/gravity"), |b| {
        b.iter(|| black_box(model.gravity(black_box(&q))));
    });
    c.bench_function(&format!("{name}/inverse inertia"), |b| {
        b.iter(|| black_box(model.inverse_inertia(black_box(&q))));
    });
    c.bench_function(&format!("{name}/bias forces"), |b| {
        b.iter(|| black_box(model.bias_forces(black_box(&q), black_box(&qd))));
    });
    c.bench_function(&format!("{name}/acceleration"), |b| {
        b.iter(|| black_box(model.acceleration(black_box(&q), black_box(&qd), &u, &zero)));
    });
    // Several states at once (the plants of a team of one robot step together).
    let qs: [Vector<N>; LANES] = std::array::from_fn(|l| q * (1.0 + 0.1 * l as f64));
    c.bench_function(
        &format!("{name}/acceleration x{LANES} (side by side)"),
        |b| {
            b.iter(|| {
                let qs = black_box(&qs);
                let states: [Forward<'_, N>; LANES] =
                    std::array::from_fn(|l| (&qs[l], &qd, &u, &zero));
                black_box(model.accelerations(&states))
            });
        },
    );
    c.bench_function(&format!("{name}/acceleration x{LANES} (one by one)"), |b| {
        b.iter(|| {
            let qs = black_box(&qs);
            let each: [Vector<N>; LANES] =
                std::array::from_fn(|l| model.acceleration(&qs[l], &qd, &u, &zero));
            black_box(each)
        });
    });
}

fn benches(c: &mut Criterion) {
    terms::<2>(
        c,
        "two-link (hand-written)",
        &TwoLink::new(TwoLinkParams::PAPER),
    );
    terms::<2>(
        c,
        "two-link (URDF)",
        &arm::<2>("scenarios/robots/paper-two-link.urdf", &[]),
    );
    let locks = [("panda_finger_joint1", 0.02), ("panda_finger_joint2", 0.02)];
    terms::<7>(
        c,
        "panda (URDF)",
        &arm::<7>("common/testdata/urdf/panda.urdf", &locks),
    );
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
        .sample_size(30)
}

criterion_group! {
    name = urdf;
    config = config();
    targets = benches
}
criterion_main!(urdf);
