//! Euler–Lagrange robot models, `M(q) q̈ + V(q, q̇) q̇ + G(q) + F(q̇) + d(t) = u` (paper eq. 1).
//!
//! A new robot is one new file implementing [`EulerLagrange`] for its number of links, one
//! variant of [`ModelConfig`] and one arm of [`ModelConfig::with_links`]: everything else (the
//! plant, the control center, the processes, the launcher) is generic over the number of links.
//! A robot of a URDF file needs none of that ([`urdf`], `kind = "urdf"`).

pub mod joint_count;
pub mod primed;
pub mod robot;
pub mod three_link;
pub mod two_link;
#[cfg(feature = "urdf")]
pub mod urdf;

use serde::{Deserialize, Serialize};

pub use robot::{EulerLagrange, Matrix, Vector};
pub use three_link::{ThreeLink, ThreeLinkParams};
pub use two_link::{TwoLink, TwoLinkParams};

/// The robot of one agent (`model = { kind = "…", … }` in a scenario): one variant per model
/// file, its parameters defaulting field by field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum ModelConfig {
    /// Two-link planar manipulator (eq. 67); parameters default to the paper's.
    TwoLink(TwoLinkParams),
    /// Three-link planar arm; parameters default to [`ThreeLinkParams::DEFAULT`].
    ThreeLink(ThreeLinkParams),
    /// An arm of a URDF file (`path` relative to the scenario file; docs/model.md, "Your own
    /// arm"), moving one of [`urdf::JOINT_COUNTS`] joints.
    #[cfg(feature = "urdf")]
    Urdf(urdf::UrdfModel),
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
        match self {
            Self::TwoLink(p) => work.call::<2>(Box::new(TwoLink::new(*p))),
            Self::ThreeLink(p) => work.call::<3>(Box::new(ThreeLink::new(*p))),
            #[cfg(feature = "urdf")]
            Self::Urdf(m) => {
                use urdf::AnyArm;
                crate::on_joint_count!(AnyArm, m.arm(), a => work.call(a.clone()))
            }
        }
    }

    /// The name and limits (rad, or m for a prismatic joint) of each joint, in the order of
    /// `q`, of an arm that has them: a URDF arm's (`None` for a joint the URDF gives none); the
    /// hand-written arms' joints turn freely (empty).
    pub fn joint_limits(&self) -> Vec<(String, Option<(f64, f64)>)> {
        match self {
            Self::TwoLink(_) | Self::ThreeLink(_) => Vec::new(),
            #[cfg(feature = "urdf")]
            Self::Urdf(m) => m
                .arm()
                .chain()
                .joints
                .iter()
                .map(|j| (j.name.clone(), j.limits))
                .collect(),
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
