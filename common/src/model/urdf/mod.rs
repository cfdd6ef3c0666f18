//! A robot model from a URDF file: the arm's joints from its `root` link to its `tip`, its
//! links' masses and inertias, and its dynamics `M(q)`, `V(q, q̇)`, `G(q)` and `F(q̇)` for any
//! number of joints up to [`MAX_JOINTS`] ([`Chain`]; [`UrdfArm`] is the [`EulerLagrange`](crate::model::EulerLagrange) of
//! `N` joints over it).
//!
//! Read: links with their `<inertial>`, joints with their `<origin>`, `<axis>`, `<limit>`,
//! `<dynamics damping friction>` and `<mimic>`. Ignored: visuals, collisions, meshes (a
//! `package://` file is never looked for), materials, transmissions, Gazebo tags. Revolute,
//! continuous and prismatic joints move; a fixed joint joins its child to its parent; a joint
//! named in `lock` is held at its value as a fixed joint. Refused, naming the joint or link: a
//! floating, planar or spherical joint, a mimic joint that is not locked, a link with two
//! parents (a closed chain), a moving joint that is not on the chain from `root` to `tip`, a
//! non-finite or negative number (docs/model.md, "Your own arm").

mod chain;
mod cholesky;
mod config;
mod dynamics;
mod lanes;
mod load;
mod rigid;

pub use chain::{Body, Chain, Joint, Motion, UrdfSpec, GRAVITY, MAX_JOINTS};
pub use config::{AnyArm, UrdfModel, JOINT_COUNTS};
pub use dynamics::{Dynamics, UrdfArm, COULOMB_VELOCITY};
pub use load::UrdfError;

#[cfg(test)]
mod tests;
