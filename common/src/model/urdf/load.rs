//! A URDF file read into a [`Chain`]: every link's place on the arm, the fixed and locked joints
//! folded into the moving ones, every refusal naming the joint or link it is about.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use urdf_rs::JointType;

use super::chain::{Body, Chain, Frame, Joint, Motion, UrdfSpec, MAX_JOINTS};

/// Why a URDF file gives no arm.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UrdfError {
    #[error("{path}: {why}")]
    Read { path: PathBuf, why: String },
    #[error("{path}: not a URDF file: {why}")]
    Parse { path: PathBuf, why: String },
    #[error("{path}: joint `{joint}`: {why}")]
    Joint {
        path: PathBuf,
        joint: String,
        why: String,
    },
    #[error("{path}: link `{link}`: {why}")]
    Link {
        path: PathBuf,
        link: String,
        why: String,
    },
    #[error("{path}: {why}")]
    Arm { path: PathBuf, why: String },
}

/// What a joint's `<limit>` says.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Limits {
    /// Lower and upper, at least one finite (the other may be infinite: no limit there).
    Range(f64, f64),
    /// A continuous joint, or limits at infinity on both sides.
    Unbounded,
    /// No `<limit>` (or one of zeros) on a revolute or prismatic joint.
    Missing,
}

impl Chain {
    /// The arm `spec` names in its URDF file (`base`: the folder a relative `spec.path` is
    /// relative to, the scenario file's).
    pub fn load(spec: &UrdfSpec, base: &Path) -> Result<Chain, UrdfError> {
        let path = base.join(&spec.path);
        let text = crate::files::read_limited(&path).map_err(|why| UrdfError::Read {
            path: path.clone(),
            why,
        })?;
        Self::parse(&text, spec, &path)
    }

    /// The arm `spec` names in the URDF text `text` (of the file `path`, for the messages).
    pub fn parse(text: &str, spec: &UrdfSpec, path: &Path) -> Result<Chain, UrdfError> {
        let robot = urdf_rs::read_from_string(text).map_err(|e| UrdfError::Parse {
            path: path.to_path_buf(),
            why: e.to_string(),
        })?;
        Reader {
            path,
            spec,
            robot: &robot,
        }
        .chain()
    }
}

/// Where a link is: the moving joint it rides on (`None`: on the root, it does not move) and
/// its frame in the frame of that joint's child (of the root link).
#[derive(Debug, Clone, Copy)]
struct Place {
    rides_on: Option<usize>,
    frame: Frame,
}

struct Reader<'a> {
    path: &'a Path,
    spec: &'a UrdfSpec,
    robot: &'a urdf_rs::Robot,
}

impl Reader<'_> {
    fn joint_error(&self, joint: &str, why: impl Into<String>) -> UrdfError {
        UrdfError::Joint {
            path: self.path.to_path_buf(),
            joint: joint.into(),
            why: why.into(),
        }
    }

    fn link_error(&self, link: &str, why: impl Into<String>) -> UrdfError {
        UrdfError::Link {
            path: self.path.to_path_buf(),
            link: link.into(),
            why: why.into(),
        }
    }

    fn arm_error(&self, why: impl Into<String>) -> UrdfError {
        UrdfError::Arm {
            path: self.path.to_path_buf(),
            why: why.into(),
        }
    }

    fn chain(&self) -> Result<Chain, UrdfError> {
        let parent_joint = self.parent_joints()?;
        let root = self.root(&parent_joint)?;
        self.check_locks()?;
        let gravity = Vector3::from(self.spec.gravity);
        if !gravity.iter().all(|g| g.is_finite()) {
            return Err(self.arm_error(format!("gravity {:?} is not finite", self.spec.gravity)));
        }
        let mut joints = Vec::new();
        let mut bodies = Vec::new();
        // Depth first from the root, children in the file's order: a joint is taken (and a
        // moving one numbered) when its child is reached.
        let base = Place {
            rides_on: None,
            frame: Frame::IDENTITY,
        };
        let mut todo: Vec<(Option<&urdf_rs::Joint>, Place)> = vec![(None, base)];
        while let Some((joint, parent)) = todo.pop() {
            let (link, place) = match joint {
                Some(j) => (j.child.link.as_str(), self.step(j, &parent, &mut joints)?),
                None => (root.as_str(), parent),
            };
            if let Some(body) = self.body(link, &place)? {
                bodies.push(body);
            }
            let children = (self.robot.joints.iter()).filter(|j| j.parent.link == link);
            let children: Vec<&urdf_rs::Joint> = children.collect();
            todo.extend(children.into_iter().rev().map(|j| (Some(j), place)));
        }
        self.check_chain(&joints, &parent_joint)?;
        if joints.is_empty() {
            return Err(self.arm_error(format!("no joint below link `{root}` moves")));
        }
        if joints.len() > MAX_JOINTS {
            return Err(self.arm_error(format!(
                "{} joints move, at most {MAX_JOINTS} may: lock the others",
                joints.len()
            )));
        }
        Ok(Chain {
            name: self.robot.name.clone(),
            joints: joints.into_iter().map(|(j, _)| j).collect(),
            bodies,
            gravity,
            masses: (self.robot.links.iter())
                .map(|l| (l.name.clone(), l.inertial.mass.value))
                .collect(),
        })
    }

    /// The joint whose child each link is; a link with two is a closed chain.
    fn parent_joints(&self) -> Result<BTreeMap<&str, &urdf_rs::Joint>, UrdfError> {
        // One link or joint of a name: which of two a name meant (for its mass, a lock, a
        // trajectory's joint) would otherwise be the loader's guess.
        let mut links = BTreeSet::new();
        for l in &self.robot.links {
            if !links.insert(l.name.as_str()) {
                return Err(self.link_error(&l.name, "defined twice in the file"));
            }
        }
        let mut joints = BTreeSet::new();
        for j in &self.robot.joints {
            if !joints.insert(j.name.as_str()) {
                return Err(self.joint_error(&j.name, "defined twice in the file"));
            }
        }
        let mut parent = BTreeMap::new();
        for j in &self.robot.joints {
            for end in [&j.parent.link, &j.child.link] {
                if !links.contains(end.as_str()) {
                    return Err(self.joint_error(&j.name, format!("no link `{end}` in the file")));
                }
            }
            if let Some(other) = parent.insert(j.child.link.as_str(), j) {
                return Err(self.joint_error(
                    &j.name,
                    format!(
                        "link `{}` is already the child of joint `{}`: a closed chain",
                        j.child.link, other.name
                    ),
                ));
            }
        }
        Ok(parent)
    }

    /// The link the arm is mounted by: the spec's, or the one link that is no joint's child.
    fn root(&self, parent_joint: &BTreeMap<&str, &urdf_rs::Joint>) -> Result<String, UrdfError> {
        if let Some(root) = &self.spec.root {
            if !self.robot.links.iter().any(|l| &l.name == root) {
                return Err(self.link_error(root, "the root named is no link of the file"));
            }
            return Ok(root.clone());
        }
        let roots: Vec<&str> = (self.robot.links.iter())
            .map(|l| l.name.as_str())
            .filter(|l| !parent_joint.contains_key(l))
            .collect();
        match roots.as_slice() {
            [root] => Ok((*root).to_string()),
            [] => Err(self.arm_error("every link is a joint's child: no root link")),
            more => Err(self.arm_error(format!(
                "{} links are no joint's child ({}): name the arm's `root`",
                more.len(),
                more.join(", ")
            ))),
        }
    }

    fn check_locks(&self) -> Result<(), UrdfError> {
        for (name, value) in &self.spec.lock {
            let Some(j) = self.robot.joints.iter().find(|j| &j.name == name) else {
                return Err(self.joint_error(name, "locked, but no joint of the file"));
            };
            if !value.is_finite() {
                return Err(self.joint_error(name, format!("locked at {value}, not finite")));
            }
            if !matches!(
                j.joint_type,
                JointType::Revolute | JointType::Continuous | JointType::Prismatic
            ) {
                return Err(self.joint_error(
                    name,
                    format!("a {:?} joint cannot be locked at one value", j.joint_type),
                ));
            }
            if let Limits::Range(lo, hi) = self.limits(j)? {
                if !(lo..=hi).contains(value) {
                    return Err(self.joint_error(
                        name,
                        format!("locked at {value}, outside its limits [{lo}, {hi}]"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The limits `j`'s file gives it. A revolute or prismatic joint must have a `<limit>`;
    /// without one the parser fills in zeros (the same as a limit of zeros, which holds the
    /// joint at 0): [`Limits::Missing`], not a range.
    fn limits(&self, j: &urdf_rs::Joint) -> Result<Limits, UrdfError> {
        if j.joint_type == JointType::Continuous {
            return Ok(Limits::Unbounded);
        }
        if j.limit == urdf_rs::JointLimit::default() {
            return Ok(Limits::Missing);
        }
        let (lo, hi) = (j.limit.lower, j.limit.upper);
        if lo.is_nan() || hi.is_nan() {
            return Err(self.joint_error(&j.name, format!("limits [{lo}, {hi}]: not numbers")));
        }
        if lo > hi {
            return Err(self.joint_error(&j.name, format!("lower limit {lo} above upper {hi}")));
        }
        // Infinite: no limit on that side (URDF 1.2 writes an omitted limit so); the other
        // side still holds. Both infinite: none.
        Ok(if lo.is_finite() || hi.is_finite() {
            Limits::Range(lo, hi)
        } else {
            Limits::Unbounded
        })
    }

    /// The place of joint `j`'s child, from its parent's `place`; a moving joint is added to
    /// `joints` (with the joint it follows).
    fn step(
        &self,
        j: &urdf_rs::Joint,
        place: &Place,
        joints: &mut Vec<(Joint, Option<usize>)>,
    ) -> Result<Place, UrdfError> {
        let origin = self.finite(&j.name, "origin", j.origin.xyz.0, j.origin.rpy.0)?;
        let at = place.frame.then(&origin);
        let locked = self.spec.lock.get(&j.name).copied();
        let motion = match j.joint_type {
            JointType::Fixed => None,
            JointType::Revolute | JointType::Continuous => Some(Motion::Revolute),
            JointType::Prismatic => Some(Motion::Prismatic),
            ref other => {
                return Err(self.joint_error(
                    &j.name,
                    format!(
                        "a {other:?} joint (only revolute, continuous, prismatic and fixed \
                         joints are read; a floating base is not an arm's)"
                    ),
                ))
            }
        };
        let Some(motion) = motion else {
            return Ok(Place {
                rides_on: place.rides_on,
                frame: at,
            });
        };
        let axis = self.axis(j)?;
        if let Some(value) = locked {
            return Ok(Place {
                rides_on: place.rides_on,
                frame: at.then(&Frame::motion(motion, &axis, value)),
            });
        }
        if let Some(m) = &j.mimic {
            return Err(self.joint_error(
                &j.name,
                format!("mimics joint `{}`: lock it (hold it at a value)", m.joint),
            ));
        }
        let (damping, friction) = match &j.dynamics {
            Some(d) => (d.damping, d.friction),
            None => (0.0, 0.0),
        };
        for (what, v) in [("damping", damping), ("friction", friction)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(self.joint_error(&j.name, format!("{what} {v}: must be ≥ 0")));
            }
        }
        let limits = match self.limits(j)? {
            Limits::Range(lo, hi) => Some((lo, hi)),
            Limits::Unbounded => None,
            Limits::Missing => {
                return Err(self.joint_error(
                    &j.name,
                    format!(
                        "a {:?} joint without `<limit lower=\"…\" upper=\"…\" …>` (or with one \
                         of zeros, which holds it at 0): give its limits, lock it, or (a revolute \
                         joint that turns without end) make it `continuous`",
                        j.joint_type
                    ),
                ))
            }
        };
        joints.push((
            Joint {
                name: j.name.clone(),
                motion,
                limits,
                damping,
                friction,
                placement: at,
                axis,
            },
            place.rides_on,
        ));
        Ok(Place {
            rides_on: Some(joints.len() - 1),
            frame: Frame::IDENTITY,
        })
    }

    /// `j`'s axis, made unit.
    fn axis(&self, j: &urdf_rs::Joint) -> Result<Vector3<f64>, UrdfError> {
        let a = Vector3::from(j.axis.xyz.0);
        let n = a.norm();
        if !(n.is_finite() && n > 0.0) {
            return Err(self.joint_error(&j.name, format!("axis {:?} has no direction", a.data.0)));
        }
        Ok(a / n)
    }

    /// An `<origin>` of `what` (a joint or link), checked finite.
    fn finite(
        &self,
        what: &str,
        field: &str,
        xyz: [f64; 3],
        rpy: [f64; 3],
    ) -> Result<Frame, UrdfError> {
        if xyz.iter().chain(&rpy).all(|v| v.is_finite()) {
            Ok(Frame::origin(xyz, rpy))
        } else {
            Err(self.joint_error(
                what,
                format!("{field} xyz {xyz:?} rpy {rpy:?} is not finite"),
            ))
        }
    }

    /// The link `name` as a moving body at `place`; `None` when it does not move or has no
    /// mass and no inertia.
    fn body(&self, name: &str, place: &Place) -> Result<Option<Body>, UrdfError> {
        let Some(link) = self.robot.links.iter().find(|l| l.name == name) else {
            return Err(self.link_error(name, "no such link"));
        };
        let inertial = &link.inertial;
        let m = inertial.mass.value;
        let i = &inertial.inertia;
        let tensor = Matrix3::new(
            i.ixx, i.ixy, i.ixz, //
            i.ixy, i.iyy, i.iyz, //
            i.ixz, i.iyz, i.izz,
        );
        let (xyz, rpy) = (inertial.origin.xyz.0, inertial.origin.rpy.0);
        let finite = m.is_finite()
            && tensor.iter().all(|v| v.is_finite())
            && xyz.iter().chain(&rpy).all(|v| v.is_finite());
        if !finite {
            return Err(self.link_error(name, "its <inertial> has a number that is not finite"));
        }
        if m < 0.0 {
            return Err(self.link_error(name, format!("mass {m} kg is negative")));
        }
        // A rigid body's inertia about its centre of mass has no negative principal moment (a
        // point mass has three zeros); beyond the rounding of the eigenvalues, refused.
        let moments = tensor.symmetric_eigenvalues();
        let scale = moments.amax();
        if moments.min() < -1e-12 * scale {
            let mut sorted = moments.as_slice().to_vec();
            sorted.sort_by(f64::total_cmp);
            return Err(self.link_error(
                name,
                format!(
                    "its inertia is not positive semi-definite: principal moments {sorted:?} kg·m²"
                ),
            ));
        }
        let Some(rides_on) = place.rides_on else {
            return Ok(None);
        };
        if m == 0.0 && tensor == Matrix3::zeros() {
            return Ok(None);
        }
        let at = place.frame.then(&Frame::origin(xyz, rpy));
        Ok(Some(Body {
            link: name.to_string(),
            mass: m,
            rides_on,
            com: at.p,
            inertia: at.r * tensor * at.r.transpose(),
        }))
    }

    /// The moving joints lie between the root and the tip (when there is one) and form one
    /// chain, each following the one before.
    fn check_chain(
        &self,
        joints: &[(Joint, Option<usize>)],
        parent_joint: &BTreeMap<&str, &urdf_rs::Joint>,
    ) -> Result<(), UrdfError> {
        if let Some(tip) = &self.spec.tip {
            if !self.robot.links.iter().any(|l| &l.name == tip) {
                return Err(self.link_error(tip, "the tip named is no link of the file"));
            }
            let mut on_path = BTreeSet::new();
            let mut link = tip.as_str();
            while let Some(j) = parent_joint.get(link) {
                on_path.insert(j.name.as_str());
                link = &j.parent.link;
            }
            if let Some((j, _)) = joints
                .iter()
                .find(|(j, _)| !on_path.contains(j.name.as_str()))
            {
                return Err(self.joint_error(
                    &j.name,
                    format!("moves, but is not between the root and the tip `{tip}`: lock it"),
                ));
            }
        }
        for (k, (j, follows)) in joints.iter().enumerate() {
            if *follows == k.checked_sub(1) {
                continue;
            }
            let after = match follows {
                Some(f) => format!("after joint `{}`", joints[*f].0.name),
                None => "at the root".to_string(),
            };
            let also = (joints.iter())
                .find(|(_, f)| f == follows)
                .map_or("another", |(o, _)| o.name.as_str());
            return Err(self.joint_error(
                &j.name,
                format!(
                    "moves {after}, as joint `{also}` does: the arm branches (lock the joints \
                     that are not the arm's, or name its `tip`)"
                ),
            ));
        }
        Ok(())
    }
}
