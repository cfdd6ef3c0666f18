//! Euler–Lagrange robot models, `M(q) q̈ + V(q, q̇) q̇ + G(q) + F(q̇) + d(t) = u` (paper eq. 1).
//!
//! A new robot is one new file implementing [`EulerLagrange`] for its number of links, one
//! variant of [`ModelConfig`] and one arm of [`ModelConfig::with_links`]: everything else (the
//! plant, the control center, the processes, the launcher) is generic over the number of links.

pub mod three_link;
pub mod two_link;

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

pub use three_link::{ThreeLink, ThreeLinkParams};
pub use two_link::{TwoLink, TwoLinkParams};

/// The robot of one agent (`model = { kind = "…", … }` in a scenario): one variant per model
/// file, its parameters defaulting field by field.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum ModelConfig {
    /// Two-link planar manipulator (eq. 67); parameters default to the paper's.
    TwoLink(TwoLinkParams),
    /// Three-link planar arm; parameters default to [`ThreeLinkParams::DEFAULT`].
    ThreeLink(ThreeLinkParams),
}

/// Work that is generic over the number of links, run by [`ModelConfig::with_links`] with the
/// model's own `N` and the model built.
pub trait ForLinks {
    type Output;
    fn call<const N: usize>(self, model: Box<dyn EulerLagrange<N>>) -> Self::Output;
}

impl ModelConfig {
    /// Runs `work` with this model's number of links and the model: the one place that maps a
    /// model kind to its number of links.
    pub fn with_links<W: ForLinks>(&self, work: W) -> W::Output {
        match *self {
            Self::TwoLink(p) => work.call::<2>(Box::new(TwoLink::new(p))),
            Self::ThreeLink(p) => work.call::<3>(Box::new(ThreeLink::new(p))),
        }
    }

    /// Number of links.
    pub fn dof(&self) -> usize {
        struct Links;
        impl ForLinks for Links {
            type Output = usize;
            fn call<const N: usize>(self, _: Box<dyn EulerLagrange<N>>) -> usize {
                N
            }
        }
        self.with_links(Links)
    }

    /// The model for robots with `N` links; `None` when it has another number of links
    /// (validation makes every agent of a run share one link count).
    pub fn build<const N: usize>(&self) -> Option<Box<dyn EulerLagrange<N>>> {
        struct Build<const N: usize>;
        impl<const N: usize> ForLinks for Build<N> {
            type Output = Option<Box<dyn EulerLagrange<N>>>;
            fn call<const M: usize>(self, model: Box<dyn EulerLagrange<M>>) -> Self::Output {
                // `Box<dyn EulerLagrange<M>>` is a `Box<dyn EulerLagrange<N>>` exactly when M = N.
                let any: Box<dyn std::any::Any> = Box::new(model);
                any.downcast::<Box<dyn EulerLagrange<N>>>().ok().map(|m| *m)
            }
        }
        self.with_links(Build::<N>)
    }

    /// Physically meaningless parameters, as `(field, why)`.
    pub fn problems(&self) -> Vec<(&'static str, String)> {
        struct Problems;
        impl ForLinks for Problems {
            type Output = Vec<(&'static str, String)>;
            fn call<const N: usize>(self, model: Box<dyn EulerLagrange<N>>) -> Self::Output {
                model.problems()
            }
        }
        self.with_links(Problems)
    }
}

/// Column vector of generalized coordinates (or torques) of an `N`-dof robot.
pub type Vector<const N: usize> = SVector<f64, N>;
/// Square matrix over the generalized coordinates of an `N`-dof robot.
pub type Matrix<const N: usize> = SMatrix<f64, N, N>;

/// The known dynamics of one agent. Pure: no state, no I/O.
pub trait EulerLagrange<const N: usize>: Send + Sync + std::fmt::Debug {
    /// Every way the parameters are physically meaningless, as `(field, why)`; empty for a
    /// model whose inertia is positive definite everywhere and whose friction is dissipative.
    fn problems(&self) -> Vec<(&'static str, String)>;
    /// Generalized inertia `M(q)`, symmetric positive definite.
    fn inertia(&self, q: &Vector<N>) -> Matrix<N>;
    /// Time derivative `Ṁ(q, q̇)` (used by the passivity property tests).
    fn inertia_rate(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N>;
    /// Centripetal–Coriolis matrix `V(q, q̇)`.
    fn coriolis(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N>;
    /// Gravity vector `G(q)`.
    fn gravity(&self, q: &Vector<N>) -> Vector<N>;
    /// Friction `F(q̇)`.
    fn friction(&self, qd: &Vector<N>) -> Vector<N>;

    /// `M(q)⁻¹`. A validated model is positive definite everywhere, so the inverse exists; a
    /// singular matrix (only reachable with unvalidated parameters) yields zeros rather than NaN.
    fn inverse_inertia(&self, q: &Vector<N>) -> Matrix<N> {
        self.inertia(q)
            .try_inverse()
            .unwrap_or_else(Matrix::<N>::zeros)
    }

    /// Non-input terms `V q̇ + G + F`.
    fn bias_forces(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        self.coriolis(q, qd) * qd + self.gravity(q) + self.friction(qd)
    }

    /// `f(q, q̇) = −M⁻¹ (V q̇ + G + F)` (paper eq. 21), the drift the observer uses.
    fn drift(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        -(self.inverse_inertia(q) * self.bias_forces(q, qd))
    }

    /// `q̈ = M⁻¹ (u − V q̇ − G − F − d)`: the plant's forward dynamics.
    fn acceleration(
        &self,
        q: &Vector<N>,
        qd: &Vector<N>,
        torque: &Vector<N>,
        disturbance: &Vector<N>,
    ) -> Vector<N> {
        self.inverse_inertia(q) * (torque - self.bias_forces(q, qd) - disturbance)
    }

    /// Kinetic energy `½ q̇ᵀ M q̇`.
    fn kinetic_energy(&self, q: &Vector<N>, qd: &Vector<N>) -> f64 {
        0.5 * qd.dot(&(self.inertia(q) * qd))
    }
}

/// The states `(q, q̇)` of the free arm (`u = 0`, `d = 0`) from `(q0, q̇0)` after each of
/// `steps` classic RK4 steps of `dt`: what the models' energy property tests integrate.
#[cfg(test)]
pub(crate) fn free_motion<const N: usize>(
    arm: &dyn EulerLagrange<N>,
    (q0, qd0): (Vector<N>, Vector<N>),
    dt: f64,
    steps: usize,
) -> Vec<(Vector<N>, Vector<N>)> {
    let zero = Vector::<N>::zeros();
    let f = |q: &Vector<N>, qd: &Vector<N>| arm.acceleration(q, qd, &zero, &zero);
    let (mut q, mut qd) = (q0, qd0);
    let mut out = Vec::with_capacity(steps);
    for _ in 0..steps {
        let k1 = (qd, f(&q, &qd));
        let k2 = (
            qd + k1.1 * (dt / 2.0),
            f(&(q + k1.0 * (dt / 2.0)), &(qd + k1.1 * (dt / 2.0))),
        );
        let k3 = (
            qd + k2.1 * (dt / 2.0),
            f(&(q + k2.0 * (dt / 2.0)), &(qd + k2.1 * (dt / 2.0))),
        );
        let k4 = (qd + k3.1 * dt, f(&(q + k3.0 * dt), &(qd + k3.1 * dt)));
        q += (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0) * (dt / 6.0);
        qd += (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1) * (dt / 6.0);
        out.push((q, qd));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(toml_text: &str) -> Result<ModelConfig, String> {
        toml::from_str(toml_text).map_err(|e| e.to_string())
    }

    #[test]
    fn each_kind_dispatches_to_its_own_number_of_links_and_no_other() {
        let two = parse(r#"kind = "two-link""#).expect("two-link");
        let three = parse(r#"kind = "three-link""#).expect("three-link");
        assert_eq!(two, ModelConfig::TwoLink(TwoLinkParams::PAPER));
        assert_eq!(three, ModelConfig::ThreeLink(ThreeLinkParams::DEFAULT));
        assert_eq!((two.dof(), three.dof()), (2, 3));
        assert!(two.build::<2>().is_some() && two.build::<3>().is_none());
        assert!(three.build::<3>().is_some() && three.build::<2>().is_none());
        // The model built is the one configured, not a default.
        let q = Vector::<3>::new(0.1, 0.2, 0.3);
        let heavy = ModelConfig::ThreeLink(ThreeLinkParams {
            mass_kg: [6.0, 4.0, 3.0],
            ..ThreeLinkParams::DEFAULT
        });
        let built = heavy.build::<3>().expect("three links");
        assert_ne!(
            built.inertia(&q),
            three.build::<3>().expect("three links").inertia(&q)
        );
    }

    #[test]
    fn parameters_default_field_by_field_and_unknown_fields_are_named() {
        let m = parse("kind = \"three-link\"\nmass_kg = [1.0, 1.0, 1.0]").expect("valid");
        let ModelConfig::ThreeLink(p) = m else {
            panic!("three-link expected, got {m:?}");
        };
        assert_eq!(p.mass_kg, [1.0; 3]);
        assert_eq!(p.length_m, ThreeLinkParams::DEFAULT.length_m);
        let e = parse("kind = \"two-link\"\np4 = 1.0").expect_err("p4 is no field");
        assert!(e.contains("p4"), "{e}");
        let e = parse("kind = \"four-link\"").expect_err("no such kind");
        assert!(e.contains("four-link"), "{e}");
        let bad = parse("kind = \"three-link\"\nmass_kg = [1.0, -1.0, 1.0]").expect("parses");
        assert_eq!(bad.problems().first().map(|p| p.0), Some("mass_kg"));
    }
}
