//! The paper's agent: a two-link revolute planar manipulator (eq. 67).
//!
//! `c2 = cos q2`, `s2 = sin q2` of the **true** state: the `cos(y2)` in the paper's eq. (67) is a
//! typo, physics does not see the attacked measurement (docs/model.md, "Plant"). Planar, so `G = 0`.

use serde::{Deserialize, Serialize};

use super::robot::{EulerLagrange, Matrix, Vector};

/// Inertia and friction parameters of [`TwoLink`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct TwoLinkParams {
    /// kg·m², typical 3.473 (paper).
    pub p1: f64,
    /// kg·m², typical 0.196 (paper).
    pub p2: f64,
    /// kg·m², typical 0.242 (paper).
    pub p3: f64,
    /// Viscous friction of link 1, N·m·s, typical 5.3 (paper).
    pub fd1: f64,
    /// Viscous friction of link 2, N·m·s, typical 1.1 (paper).
    pub fd2: f64,
}

impl TwoLinkParams {
    /// The values of the paper's Section VII.
    pub const PAPER: Self = Self {
        p1: 3.473,
        p2: 0.196,
        p3: 0.242,
        fd1: 5.3,
        fd2: 1.1,
    };

    /// `M(q)` is positive definite for every `q` iff `p2 > 0` and `p2 (p1 − p2) > p3²`.
    pub fn is_positive_definite(&self) -> bool {
        self.p2 > 0.0 && self.p2 * (self.p1 - self.p2) > self.p3 * self.p3
    }

    /// Every way the parameters are physically meaningless, as `(field, why)`: non-finite
    /// values, negative friction, an inertia that is not positive definite.
    pub fn problems(&self) -> Vec<(&'static str, String)> {
        let Self {
            p1,
            p2,
            p3,
            fd1,
            fd2,
        } = *self;
        let mut out = Vec::new();
        for (name, v) in [
            ("p1", p1),
            ("p2", p2),
            ("p3", p3),
            ("fd1", fd1),
            ("fd2", fd2),
        ] {
            if !v.is_finite() {
                out.push((name, format!("must be finite, got {v}")));
            }
        }
        for (name, v) in [("fd1", fd1), ("fd2", fd2)] {
            if v < 0.0 {
                out.push((name, format!("friction must be ≥ 0, got {v}")));
            }
        }
        if !self.is_positive_definite() {
            out.push((
                "p2",
                format!(
                    "inertia not positive definite: need p2 > 0 and p2(p1 − p2) > p3² \
                     (p1={p1}, p2={p2}, p3={p3})"
                ),
            ));
        }
        out
    }
}

impl Default for TwoLinkParams {
    fn default() -> Self {
        Self::PAPER
    }
}

/// Two-link planar manipulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoLink {
    pub params: TwoLinkParams,
}

impl TwoLink {
    pub fn new(params: TwoLinkParams) -> Self {
        Self { params }
    }

    /// `M(q)` from `c2 = cos q2`.
    fn inertia_at(&self, c2: f64) -> Matrix<2> {
        let TwoLinkParams { p1, p2, p3, .. } = self.params;
        let off = p2 + p3 * c2;
        Matrix::<2>::new(p1 + 2.0 * p3 * c2, off, off, p2)
    }

    /// `V(q, q̇)` from `s2 = sin q2`.
    fn coriolis_at(&self, s2: f64, qd: &Vector<2>) -> Matrix<2> {
        let p3 = self.params.p3;
        Matrix::<2>::new(
            -p3 * s2 * qd[1],
            -p3 * s2 * (qd[0] + qd[1]),
            p3 * s2 * qd[0],
            0.0,
        )
    }

    /// The inverse of an inertia matrix, in closed form: the operation order is fixed and there
    /// is no pivoting logic. Zeros for a singular or non-finite one.
    fn invert(m: Matrix<2>) -> Matrix<2> {
        let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
        // Computed whatever `det`, then chosen: no branch, so the callers' `sin q2` and
        // `cos q2` stay side by side and are evaluated together.
        let inv = 1.0 / det;
        let inverse = Matrix::<2>::new(
            m[(1, 1)] * inv,
            -m[(0, 1)] * inv,
            -m[(1, 0)] * inv,
            m[(0, 0)] * inv,
        );
        if det == 0.0 || !det.is_finite() {
            Matrix::<2>::zeros()
        } else {
            inverse
        }
    }

    /// `V q̇ + G + F` from `s2 = sin q2`: the trait's `bias_forces`, term for term.
    fn bias_at(&self, s2: f64, q: &Vector<2>, qd: &Vector<2>) -> Vector<2> {
        self.coriolis_at(s2, qd) * qd + self.gravity(q) + self.friction(qd)
    }
}

/// `sin q2` and `cos q2` are computed once per call of `acceleration` and `drift` (the hot paths
/// of the plant and the observer); every other operation is the trait's default, in its order,
/// so the results are the same to the bit.
impl EulerLagrange<2> for TwoLink {
    fn problems(&self) -> Vec<(&'static str, String)> {
        self.params.problems()
    }

    fn inertia(&self, q: &Vector<2>) -> Matrix<2> {
        self.inertia_at(q[1].cos())
    }

    fn inertia_rate(&self, q: &Vector<2>, qd: &Vector<2>) -> Matrix<2> {
        let p3 = self.params.p3;
        let s2 = q[1].sin();
        let off = -p3 * s2 * qd[1];
        Matrix::<2>::new(2.0 * off, off, off, 0.0)
    }

    fn coriolis(&self, q: &Vector<2>, qd: &Vector<2>) -> Matrix<2> {
        self.coriolis_at(q[1].sin(), qd)
    }

    fn gravity(&self, _q: &Vector<2>) -> Vector<2> {
        Vector::<2>::zeros()
    }

    fn friction(&self, qd: &Vector<2>) -> Vector<2> {
        Vector::<2>::new(self.params.fd1 * qd[0], self.params.fd2 * qd[1])
    }

    fn inverse_inertia(&self, q: &Vector<2>) -> Matrix<2> {
        Self::invert(self.inertia(q))
    }

    fn bias_forces(&self, q: &Vector<2>, qd: &Vector<2>) -> Vector<2> {
        self.bias_at(q[1].sin(), q, qd)
    }

    fn drift(&self, q: &Vector<2>, qd: &Vector<2>) -> Vector<2> {
        let (s2, c2) = q[1].sin_cos();
        -(Self::invert(self.inertia_at(c2)) * self.bias_at(s2, q, qd))
    }

    fn acceleration(
        &self,
        q: &Vector<2>,
        qd: &Vector<2>,
        torque: &Vector<2>,
        disturbance: &Vector<2>,
    ) -> Vector<2> {
        let (s2, c2) = q[1].sin_cos();
        Self::invert(self.inertia_at(c2)) * (torque - self.bias_at(s2, q, qd) - disturbance)
    }
}

#[cfg(test)]
mod tests;
