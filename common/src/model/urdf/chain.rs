//! What a URDF arm is once read: its moving joints, the links that move with them, and the
//! spec that names it in its file ([`super`] says what is read and refused).

use std::collections::BTreeMap;
use std::path::PathBuf;

use nalgebra::{Matrix3, Scalar, Vector3};
use serde::{Deserialize, Serialize};

use super::lanes::{mul3, mul33, Lane};

/// The most joints a URDF arm may move.
pub const MAX_JOINTS: usize = 12;

/// Standard gravity, m/s², along −z of the root link: the default gravity vector.
pub const GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// Which arm of a URDF file, and how it is held: `model = { kind = "urdf", path = …, … }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct UrdfSpec {
    /// The URDF file (relative to the scenario file).
    pub path: PathBuf,
    /// The link the arm is mounted by, the world frame (default: the URDF's root link).
    #[serde(default)]
    pub root: Option<String>,
    /// The last link of the arm: every moving joint lies between `root` and it (default: the
    /// moving joints form one chain, wherever it ends).
    #[serde(default)]
    pub tip: Option<String>,
    /// Joints held at a value (rad or m), as fixed joints: a gripper's fingers, a mimic joint.
    #[serde(default)]
    pub lock: BTreeMap<String, f64>,
    /// Gravity in the root link's frame, m/s².
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// The file's text, put in by the scenario's loader (read from `path`, or from the
    /// scenario's `urdf_files`); never written: a run's scenario holds each text once, in its
    /// `urdf_files`.
    #[serde(default, rename = "urdf_text", skip_serializing)]
    #[schemars(skip)]
    pub text: Option<String>,
}

fn default_gravity() -> [f64; 3] {
    GRAVITY
}

impl UrdfSpec {
    /// The arm of the URDF file at `path`, its root link, no tip, nothing locked, standard
    /// gravity.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            root: None,
            tip: None,
            lock: BTreeMap::new(),
            gravity: GRAVITY,
            text: None,
        }
    }
}

/// How a joint moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Motion {
    /// About its axis, rad (a revolute or continuous joint).
    Revolute,
    /// Along its axis, m.
    Prismatic,
}

/// A rigid transform: a rotation and a translation (`x ↦ r x + p`), of one arm (`f64`) or of
/// several side by side ([`Lane`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Frame<T: Scalar = f64> {
    pub r: Matrix3<T>,
    pub p: Vector3<T>,
}

impl<T: Lane> Frame<T> {
    /// `self ∘ other`: `other` expressed in `self`'s parent.
    #[inline(always)]
    pub(crate) fn then(&self, other: &Frame<T>) -> Frame<T> {
        Frame {
            r: mul33(&self.r, &other.r),
            p: mul3(&self.r, &other.p) + self.p,
        }
    }
}

impl Frame {
    pub(crate) const IDENTITY: Self = Self {
        r: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        p: Vector3::new(0.0, 0.0, 0.0),
    };

    /// This frame's numbers in every lane of `T`.
    #[inline(always)]
    pub(crate) fn lift<T: Lane>(&self) -> Frame<T> {
        Frame {
            r: self.r.map(T::splat),
            p: self.p.map(T::splat),
        }
    }

    /// A URDF `<origin xyz rpy>`: the rotation `Rz(yaw) Ry(pitch) Rx(roll)`, then the
    /// translation.
    pub(crate) fn origin(xyz: [f64; 3], rpy: [f64; 3]) -> Frame {
        let [roll, pitch, yaw] = rpy;
        Frame {
            r: *nalgebra::Rotation3::from_euler_angles(roll, pitch, yaw).matrix(),
            p: Vector3::from(xyz),
        }
    }

    /// The motion of a joint about or along its unit `axis` by `q`.
    pub(crate) fn motion(kind: Motion, axis: &Vector3<f64>, q: f64) -> Frame {
        match kind {
            Motion::Revolute => Frame {
                r: *nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(*axis), q)
                    .matrix(),
                p: Vector3::zeros(),
            },
            Motion::Prismatic => Frame {
                r: Matrix3::identity(),
                p: axis * q,
            },
        }
    }
}

/// A moving joint of the arm, in the order of `q`.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    pub name: String,
    pub motion: Motion,
    /// Lower and upper limit (rad or m; one of them infinite where the URDF puts that side at
    /// infinity); `None`: a continuous joint, or both sides at infinity.
    pub limits: Option<(f64, f64)>,
    /// Viscous damping, N·m·s/rad or N·s/m (`<dynamics damping>`).
    pub damping: f64,
    /// Coulomb friction, N·m or N (`<dynamics friction>`).
    pub friction: f64,
    /// The joint's frame in the frame of the previous moving joint's child (the root link's for
    /// the first): the fixed and locked joints between them folded in.
    pub(crate) placement: Frame,
    /// Its unit axis in its own frame.
    pub(crate) axis: Vector3<f64>,
}

/// A link that moves with the arm: its mass, centre of mass and inertia in the frame of the
/// child of the moving joint it rides on.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    pub link: String,
    pub mass: f64,
    /// The index in `q` of the last moving joint between the root and it.
    pub(crate) rides_on: usize,
    pub(crate) com: Vector3<f64>,
    pub(crate) inertia: Matrix3<f64>,
}

/// An arm read from a URDF file: its moving joints from root to tip and the links that move
/// with them. A link that no moving joint carries (the base) is not part of the dynamics.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    /// The robot's name in the URDF.
    pub name: String,
    pub joints: Vec<Joint>,
    pub bodies: Vec<Body>,
    /// Gravity in the root link's frame, m/s².
    pub gravity: Vector3<f64>,
    /// Every link of the URDF and its mass, kg, in the file's order.
    pub masses: Vec<(String, f64)>,
}

impl Chain {
    /// The number of moving joints, the length of `q`.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// The moving joints' names, in the order of `q`.
    pub fn joint_names(&self) -> Vec<&str> {
        self.joints.iter().map(|j| j.name.as_str()).collect()
    }
}
