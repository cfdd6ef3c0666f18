//! The dynamics of a [`Chain`] for any number of joints, in the root link's frame:
//!
//! * `M(q)` by the composite-rigid-body algorithm: for each joint `j`, the links it carries
//!   (the composite body `j`) moved by a unit rate of `j` alone; their momentum, seen at joint
//!   `i ≤ j`, is `M_ij`;
//! * `V(q, q̇)` from the Christoffel symbols of `M`, `V_ij = Σ_k ½ (∂M_ij/∂q_k + ∂M_ik/∂q_j −
//!   ∂M_jk/∂q_i) q̇_k`, so that `Ṁ − 2V` is skew-symmetric; `∂M/∂q_k` is exact, from
//!   `M = Σ_b m_b J_vᵀ J_v + J_ωᵀ I_b J_ω` and the derivatives of the links' Jacobians;
//! * `G(q) = ∂U/∂q` for the potential `U = −Σ_b m_b gᵀ p_b`;
//! * `F(q̇)`: each joint's viscous damping and Coulomb friction, the latter smoothed over
//!   [`COULOMB_VELOCITY`] (`friction · tanh(q̇ / COULOMB_VELOCITY)`).

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3xX, Vector3};

use super::chain::{Chain, Frame, Motion};
use super::cholesky::Cholesky;
use super::lanes::{wide, F64x4, LANES};
use super::rigid::{felt, unit_rate_momentum, Rigid};
use crate::model::robot::{EulerLagrange, Forward, Matrix, Vector};

/// The joint speed, rad/s or m/s, over which a joint's Coulomb friction rises to its full
/// value (`tanh`): a step at zero would make the arm's equations stiff.
pub const COULOMB_VELOCITY: f64 = 0.01;

/// The arm's terms at one state `(q, q̇)`: what `fdi-launch model` shows.
#[derive(Debug, Clone, PartialEq)]
pub struct Dynamics {
    pub inertia: DMatrix<f64>,
    pub coriolis: DMatrix<f64>,
    pub gravity: DVector<f64>,
    pub friction: DVector<f64>,
}

/// Where everything is at one `q`, in the root link's frame.
struct Pose {
    /// Each moving joint's origin and unit axis.
    origin: Vec<Vector3<f64>>,
    axis: Vec<Vector3<f64>>,
    /// Each body's centre of mass and inertia about it.
    com: Vec<Vector3<f64>>,
    inertia: Vec<Matrix3<f64>>,
}

/// The skew matrix of `v`: `skew(v) x = v × x`.
fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

impl Chain {
    fn pose(&self, q: &[f64]) -> Pose {
        let mut child = Vec::with_capacity(self.joints.len());
        let (mut origin, mut axis) = (Vec::new(), Vec::new());
        let mut at = Frame::IDENTITY;
        for (j, &qj) in self.joints.iter().zip(q) {
            let frame = at.then(&j.placement);
            origin.push(frame.p);
            axis.push(frame.r * j.axis);
            at = frame.then(&Frame::motion(j.motion, &j.axis, qj));
            child.push(at);
        }
        let (com, inertia) = (self.bodies.iter())
            .map(|b| {
                let f = &child[b.rides_on];
                (f.r * b.com + f.p, f.r * b.inertia * f.r.transpose())
            })
            .unzip();
        Pose {
            origin,
            axis,
            com,
            inertia,
        }
    }

    /// `M(q)` by the composite-rigid-body algorithm.
    pub fn inertia(&self, q: &[f64]) -> DMatrix<f64> {
        let n = self.dof();
        let pose = self.pose(q);
        let mut m = DMatrix::zeros(n, n);
        // The composite body of joint j: mass, first moment and inertia about the root's origin.
        let (mut mass, mut first, mut second) = (0.0, Vector3::zeros(), Matrix3::zeros());
        let mut by_joint: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (b, body) in self.bodies.iter().enumerate() {
            by_joint[body.rides_on].push(b);
        }
        for j in (0..n).rev() {
            for &b in &by_joint[j] {
                let (mb, p) = (self.bodies[b].mass, pose.com[b]);
                mass += mb;
                first += mb * p;
                second += pose.inertia[b]
                    + mb * (p.norm_squared() * Matrix3::identity() - p * p.transpose());
            }
            let joint = |k: usize| {
                let (z, o) = (pose.axis[k], pose.origin[k]);
                (self.joints[k].motion, z, z.cross(&o))
            };
            let momentum = unit_rate_momentum(joint(j), (mass, &first, &second));
            for i in 0..=j {
                m[(i, j)] = felt(joint(i), momentum);
                m[(j, i)] = m[(i, j)];
            }
        }
        m
    }

    /// `∂M/∂q_k` for every `k`, exact.
    pub fn inertia_derivatives(&self, q: &[f64]) -> Vec<DMatrix<f64>> {
        let n = self.dof();
        let pose = self.pose(q);
        let mut d = vec![DMatrix::zeros(n, n); n];
        for (b, body) in self.bodies.iter().enumerate() {
            let a = body.rides_on;
            let (p, iw) = (pose.com[b], pose.inertia[b]);
            let (jv, jw) = self.jacobian(&pose, p, a);
            for (k, dk) in d.iter_mut().enumerate().take(a + 1) {
                let (zk, ok) = (pose.axis[k], pose.origin[k]);
                let revolute_k = self.joints[k].motion == Motion::Revolute;
                let dp = if revolute_k { zk.cross(&(p - ok)) } else { zk };
                let (mut djv, mut djw) = (Matrix3xX::zeros(n), Matrix3xX::zeros(n));
                for j in 0..=a {
                    let (zj, oj) = (pose.axis[j], pose.origin[j]);
                    let moved = k < j;
                    let dz = if moved && revolute_k {
                        zk.cross(&zj)
                    } else {
                        Vector3::zeros()
                    };
                    let d_o = match (moved, revolute_k) {
                        (false, _) => Vector3::zeros(),
                        (true, true) => zk.cross(&(oj - ok)),
                        (true, false) => zk,
                    };
                    match self.joints[j].motion {
                        Motion::Revolute => {
                            djv.set_column(j, &(dz.cross(&(p - oj)) + zj.cross(&(dp - d_o))));
                            djw.set_column(j, &dz);
                        }
                        Motion::Prismatic => djv.set_column(j, &dz),
                    }
                }
                let diw = if revolute_k {
                    skew(&zk) * iw - iw * skew(&zk)
                } else {
                    Matrix3::zeros()
                };
                let lin = jv.transpose() * &djv;
                let ang = jw.transpose() * iw * &djw;
                *dk += body.mass * (&lin + lin.transpose())
                    + &ang
                    + ang.transpose()
                    + jw.transpose() * diw * &jw;
            }
        }
        d
    }

    /// The linear and angular Jacobians of the point `p` of a body riding on joint `a`.
    fn jacobian(&self, pose: &Pose, p: Vector3<f64>, a: usize) -> (Matrix3xX<f64>, Matrix3xX<f64>) {
        let n = self.dof();
        let (mut jv, mut jw) = (Matrix3xX::zeros(n), Matrix3xX::zeros(n));
        for j in 0..=a {
            let z = pose.axis[j];
            match self.joints[j].motion {
                Motion::Revolute => {
                    jv.set_column(j, &z.cross(&(p - pose.origin[j])));
                    jw.set_column(j, &z);
                }
                Motion::Prismatic => jv.set_column(j, &z),
            }
        }
        (jv, jw)
    }

    /// `M(q)` from the links' Jacobians, `Σ_b m_b J_vᵀ J_v + J_ωᵀ I_b J_ω`: what
    /// [`Chain::inertia_derivatives`] differentiates (the tests hold it to
    /// [`Chain::inertia`]).
    pub fn inertia_from_jacobians(&self, q: &[f64]) -> DMatrix<f64> {
        let n = self.dof();
        let pose = self.pose(q);
        let mut m = DMatrix::zeros(n, n);
        for (b, body) in self.bodies.iter().enumerate() {
            let (jv, jw) = self.jacobian(&pose, pose.com[b], body.rides_on);
            m += body.mass * jv.transpose() * &jv + jw.transpose() * pose.inertia[b] * &jw;
        }
        m
    }

    /// `Ṁ(q, q̇) = Σ_k ∂M/∂q_k q̇_k`.
    pub fn inertia_rate(&self, q: &[f64], qd: &[f64]) -> DMatrix<f64> {
        let n = self.dof();
        (self.inertia_derivatives(q).iter())
            .zip(qd)
            .fold(DMatrix::zeros(n, n), |acc, (d, v)| acc + d * *v)
    }

    /// `V(q, q̇)` from the Christoffel symbols of `M`.
    pub fn coriolis(&self, q: &[f64], qd: &[f64]) -> DMatrix<f64> {
        let n = self.dof();
        let d = self.inertia_derivatives(q);
        DMatrix::from_fn(n, n, |i, j| {
            (0..n)
                .map(|k| 0.5 * (d[k][(i, j)] + d[j][(i, k)] - d[i][(j, k)]) * qd[k])
                .sum()
        })
    }

    /// `G(q)` under the chain's gravity.
    pub fn gravity(&self, q: &[f64]) -> DVector<f64> {
        let n = self.dof();
        let pose = self.pose(q);
        let g = self.gravity;
        DVector::from_fn(n, |i, _| {
            let (z, o) = (pose.axis[i], pose.origin[i]);
            let carried = (self.bodies.iter().enumerate()).filter(|(_, b)| b.rides_on >= i);
            let force: f64 = carried
                .map(|(b, body)| {
                    let moved = match self.joints[i].motion {
                        Motion::Revolute => z.cross(&(pose.com[b] - o)),
                        Motion::Prismatic => z,
                    };
                    body.mass * g.dot(&moved)
                })
                .sum();
            -force
        })
    }

    /// The potential energy `U(q) = −Σ_b m_b gᵀ p_b` (zero with every centre of mass at the
    /// root's origin), whose gradient is `G`.
    pub fn potential_energy(&self, q: &[f64]) -> f64 {
        let pose = self.pose(q);
        (self.bodies.iter().zip(&pose.com))
            .map(|(b, p)| -b.mass * self.gravity.dot(p))
            .sum()
    }

    /// `F(q̇)`: viscous damping and smoothed Coulomb friction of each joint.
    pub fn friction(&self, qd: &[f64]) -> DVector<f64> {
        DVector::from_iterator(
            self.dof(),
            (self.joints.iter())
                .zip(qd)
                .map(|(j, v)| j.damping * v + j.friction * (v / COULOMB_VELOCITY).tanh()),
        )
    }

    /// Every term at `(q, q̇)`; refused when either has the wrong length or a value that is
    /// not finite.
    pub fn dynamics(&self, q: &[f64], qd: &[f64]) -> Result<Dynamics, String> {
        let n = self.dof();
        for (what, v) in [("q", q), ("q̇", qd)] {
            if v.len() != n {
                return Err(format!(
                    "{what} has {} values, the arm {n} joints ({})",
                    v.len(),
                    self.joint_names().join(", ")
                ));
            }
            if let Some(x) = v.iter().find(|x| !x.is_finite()) {
                return Err(format!("{what} has {x}, not finite"));
            }
        }
        Ok(Dynamics {
            inertia: self.inertia(q),
            coriolis: self.coriolis(q, qd),
            gravity: self.gravity(q),
            friction: self.friction(qd),
        })
    }
}

/// A URDF arm of `N` joints: the [`EulerLagrange`] dynamics of its [`Chain`]. `M`, `V`, `G`,
/// the bias forces, `M⁻¹` and the forward dynamics come from its [`Rigid`] form (no heap, one
/// placement of the links for `M` and the bias together, Cholesky for `M⁻¹`); `Ṁ` from the
/// chain's `∂M/∂q`.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfArm<const N: usize> {
    chain: Chain,
    rigid: Rigid<N>,
}

impl<const N: usize> UrdfArm<N> {
    /// The arm of `chain`; `None` when it does not move `N` joints.
    pub fn new(chain: Chain) -> Option<Self> {
        (chain.dof() == N).then(|| Self {
            rigid: Rigid::new(&chain),
            chain,
        })
    }

    pub fn chain(&self) -> &Chain {
        &self.chain
    }
}

fn fixed<const N: usize>(m: &DMatrix<f64>) -> Matrix<N> {
    Matrix::<N>::from_iterator(m.iter().copied())
}

impl<const N: usize> EulerLagrange<N> for UrdfArm<N> {
    fn problems(&self) -> Vec<(&'static str, String)> {
        let m = self.chain.inertia(&[0.0; N]);
        if m.clone().cholesky().is_none() {
            return vec![(
                "path",
                format!(
                    "the inertia of `{}` at q = 0 is not positive definite: a moving link \
                     without mass or inertia",
                    self.chain.name
                ),
            )];
        }
        Vec::new()
    }

    fn inertia(&self, q: &Vector<N>) -> Matrix<N> {
        self.rigid.inertia(q)
    }

    fn inertia_rate(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N> {
        fixed(&self.chain.inertia_rate(q.as_slice(), qd.as_slice()))
    }

    fn coriolis(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N> {
        self.rigid.coriolis(q, qd)
    }

    fn gravity(&self, q: &Vector<N>) -> Vector<N> {
        self.rigid.coriolis_and_gravity(q, &Vector::<N>::zeros())
    }

    fn friction(&self, qd: &Vector<N>) -> Vector<N> {
        Vector::<N>::from_fn(|i, _| {
            let j = &self.chain.joints[i];
            // Without Coulomb friction its term is a signed zero, which leaves the sum as it
            // is: the same bits without the `tanh` (a few per cent of a Panda's tick).
            if j.friction == 0.0 && j.friction.is_sign_positive() {
                j.damping * qd[i]
            } else {
                j.damping * qd[i] + j.friction * (qd[i] / COULOMB_VELOCITY).tanh()
            }
        })
    }

    wide!(fn inverse_inertia / inverse_inertia_wide / inverse_inertia_here (&self, q: &Vector<N>) -> Matrix<N>);

    fn bias_forces(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        self.rigid.coriolis_and_gravity(q, qd) + self.friction(qd)
    }

    wide!(fn drift / drift_wide / drift_here (&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N>);

    wide!(fn acceleration / acceleration_wide / acceleration_here (
        &self,
        q: &Vector<N>,
        qd: &Vector<N>,
        torque: &Vector<N>,
        disturbance: &Vector<N>
    ) -> Vector<N>);

    fn side_by_side(&self) -> bool {
        true
    }

    wide!(fn drifts / drifts_wide / drifts_here (
        &self,
        states: &[(&Vector<N>, &Vector<N>); LANES]
    ) -> [Vector<N>; LANES]);

    wide!(fn inverse_inertias / inverse_inertias_wide / inverse_inertias_here (
        &self,
        qs: &[&Vector<N>; LANES]
    ) -> [Matrix<N>; LANES]);

    wide!(
        /// The states' `M` and `V q̇ + G` side by side ([`F64x4`]), and their `q̈`, each to
        /// the bit as [`Self::acceleration`] gives it; where one of the `M` is not positive
        /// definite, each state alone.
        fn accelerations / accelerations_wide / accelerations_here (
            &self,
            states: &[Forward<'_, N>; LANES]
        ) -> [Vector<N>; LANES]
    );
}

/// The hot paths of the [`EulerLagrange`] implementation, for whichever instructions their
/// caller is compiled for, and compiled for AVX2 ([`wide!`]).
impl<const N: usize> UrdfArm<N> {
    wide!(@wide fn inverse_inertia_wide / inverse_inertia_here (&self, q: &Vector<N>) -> Matrix<N>);
    wide!(@wide fn drift_wide / drift_here (&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N>);
    wide!(@wide fn acceleration_wide / acceleration_here (
        &self,
        q: &Vector<N>,
        qd: &Vector<N>,
        torque: &Vector<N>,
        disturbance: &Vector<N>
    ) -> Vector<N>);
    wide!(@wide fn accelerations_wide / accelerations_here (
        &self,
        states: &[Forward<'_, N>; LANES]
    ) -> [Vector<N>; LANES]);

    wide!(@wide fn drifts_wide / drifts_here (
        &self,
        states: &[(&Vector<N>, &Vector<N>); LANES]
    ) -> [Vector<N>; LANES]);
    wide!(@wide fn inverse_inertias_wide / inverse_inertias_here (
        &self,
        qs: &[&Vector<N>; LANES]
    ) -> [Matrix<N>; LANES]);

    /// The poses' `M` side by side ([`F64x4`]) and their inverses; where one of them is not
    /// positive definite, each pose alone.
    #[inline(always)]
    pub(super) fn inverse_inertias_here(&self, qs: &[&Vector<N>; LANES]) -> [Matrix<N>; LANES] {
        let q: [F64x4; N] = std::array::from_fn(|j| F64x4(qs.map(|q| q[j])));
        let mut m = self.rigid.inertia_rows_of(&q);
        let Some(m) = Cholesky::new(&mut m) else {
            return qs.map(|q| self.inverse_inertia_here(q));
        };
        let inv = m.inverse_rows();
        // Symmetric: its rows are its columns, which nalgebra's arrays of arrays hold.
        std::array::from_fn(|l| Matrix::<N>::from(inv.map(|row| row.map(|x| x.0[l]))))
    }

    /// The states' `M` and `V q̇ + G` side by side ([`F64x4`]), and their drifts; where one
    /// `M` is not positive definite, each state alone.
    #[inline(always)]
    pub(super) fn drifts_here(
        &self,
        states: &[(&Vector<N>, &Vector<N>); LANES],
    ) -> [Vector<N>; LANES] {
        let q: [F64x4; N] = std::array::from_fn(|j| F64x4(states.map(|s| s.0[j])));
        let qd: [F64x4; N] = std::array::from_fn(|j| F64x4(states.map(|s| s.1[j])));
        let (mut m, bias) = self.rigid.inertia_and_bias(&q, &qd);
        let Some(m) = Cholesky::new(&mut m) else {
            return states.map(|(q, qd)| self.drift_here(q, qd));
        };
        // `(V q̇ + G) + F` of each state, as `Self::drift` forms it.
        let friction = states.map(|(_, qd)| self.friction(qd));
        let rhs: [F64x4; N] =
            std::array::from_fn(|j| F64x4(std::array::from_fn(|l| bias[j].0[l] + friction[l][j])));
        let x = m.solve(&rhs);
        std::array::from_fn(|l| -Vector::<N>::from(std::array::from_fn(|j| x[j].0[l])))
    }

    #[inline(always)]
    pub(super) fn inverse_inertia_here(&self, q: &Vector<N>) -> Matrix<N> {
        let mut m = self.rigid.inertia_rows(q);
        match Cholesky::new(&mut m) {
            Some(c) => c.inverse(),
            // Not positive definite: no number stands in for it (the run reports the
            // non-finite state).
            None => Matrix::<N>::from_element(f64::NAN),
        }
    }

    #[inline(always)]
    pub(super) fn drift_here(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        let (mut m, bias) = self.rigid.inertia_and_bias(&q.data.0[0], &qd.data.0[0]);
        -solve(&mut m, Vector::<N>::from(bias) + self.friction(qd))
    }

    #[inline(always)]
    pub(super) fn acceleration_here(
        &self,
        q: &Vector<N>,
        qd: &Vector<N>,
        torque: &Vector<N>,
        disturbance: &Vector<N>,
    ) -> Vector<N> {
        let (mut m, bias) = self.rigid.inertia_and_bias(&q.data.0[0], &qd.data.0[0]);
        solve(
            &mut m,
            torque - Vector::<N>::from(bias) - self.friction(qd) - disturbance,
        )
    }

    #[inline(always)]
    pub(super) fn accelerations_here(
        &self,
        states: &[Forward<'_, N>; LANES],
    ) -> [Vector<N>; LANES] {
        let q: [F64x4; N] = std::array::from_fn(|j| F64x4(states.map(|s| s.0[j])));
        let qd: [F64x4; N] = std::array::from_fn(|j| F64x4(states.map(|s| s.1[j])));
        let (mut m, bias) = self.rigid.inertia_and_bias(&q, &qd);
        let Some(m) = Cholesky::new(&mut m) else {
            return states.map(|(q, qd, u, d)| self.acceleration_here(q, qd, u, d));
        };
        // `u − (V q̇ + G) − F − d` of each state, as `Self::acceleration` forms it.
        let friction = states.map(|(_, qd, _, _)| self.friction(qd));
        let rhs: [F64x4; N] = std::array::from_fn(|j| {
            F64x4(std::array::from_fn(|l| {
                let (_, _, u, d) = states[l];
                u[j] - bias[j].0[l] - friction[l][j] - d[j]
            }))
        });
        let x = m.solve(&rhs);
        std::array::from_fn(|l| Vector::<N>::from(std::array::from_fn(|j| x[j].0[l])))
    }
}

/// `M⁻¹ b` by Cholesky, `M` by rows (overwritten by its factor); not a number when `M` is not
/// positive definite.
#[inline(always)]
fn solve<const N: usize>(m: &mut [[f64; N]; N], b: Vector<N>) -> Vector<N> {
    match Cholesky::new(m) {
        Some(c) => Vector::<N>::from(c.solve(&b.data.0[0])),
        None => Vector::<N>::from_element(f64::NAN),
    }
}
