//! A three-link revolute planar arm: three rigid links in a chain, joint angles relative to the
//! previous link, viscous friction at each joint and gravity along −y of the arm's plane
//! (`gravity_m_s2 = 0`, the default, is an arm moving in a horizontal plane like the paper's).
//!
//! With absolute link angles `θ_i = q_1 + … + q_i` and `ℓ_a` the length of link `a` (or, for the
//! link whose centre of mass is meant, its distance `c_a` from its joint), the centre of mass of
//! link `i` moves with `∂p_i/∂q_k = Σ_{a=k..i} ℓ_a (−sin θ_a, cos θ_a)`, so
//!
//! * `M_kl = Σ_i [ m_i Σ_{a≥k, b≥l; a,b≤i} ℓ_a ℓ_b cos(θ_a − θ_b) + I_i [k ≤ i][l ≤ i] ]`,
//! * `V` from the Christoffel symbols of `M` (which makes `Ṁ − 2V` skew-symmetric),
//! * `G_k = g Σ_i m_i Σ_{a=k..i} ℓ_a cos θ_a`, `F = diag(f_i) q̇`.

use serde::{Deserialize, Serialize};

use super::robot::{EulerLagrange, Matrix, Vector};

/// Mass, geometry and friction of [`ThreeLink`]; each array is indexed by link, base first.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ThreeLinkParams {
    /// Link masses, kg.
    pub mass_kg: [f64; 3],
    /// Link lengths (joint to joint), m.
    pub length_m: [f64; 3],
    /// Distance of each link's centre of mass from its joint, m (within the link).
    pub com_m: [f64; 3],
    /// Moment of inertia of each link about its centre of mass, kg·m².
    pub inertia_kg_m2: [f64; 3],
    /// Viscous friction at each joint, N·m·s.
    pub friction_n_m_s: [f64; 3],
    /// Gravity along −y of the arm's plane, m/s²; 0 for a horizontal arm.
    pub gravity_m_s2: f64,
}

impl ThreeLinkParams {
    /// A horizontal arm of about the paper's two-link size: 1 m in all, base link heaviest.
    pub const DEFAULT: Self = Self {
        mass_kg: [6.0, 4.0, 2.5],
        length_m: [0.45, 0.35, 0.25],
        com_m: [0.225, 0.175, 0.125],
        inertia_kg_m2: [0.5, 0.4, 0.3],
        friction_n_m_s: [5.3, 1.1, 0.8],
        gravity_m_s2: 0.0,
    };

    /// Every way the parameters can be physically meaningless, as `(field, why)`: masses,
    /// lengths and inertias positive, centres of mass within their links, friction and gravity
    /// non-negative, all finite. Positive masses and inertias make `M(q)` positive definite for
    /// every `q` (each link adds `m_i J_iᵀJ_i + I_i ω_iᵀω_i`, and the rotational terms alone span
    /// every direction).
    pub fn problems(&self) -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        let mut check = |field: &'static str, values: &[f64], ok: fn(f64) -> bool, want: &str| {
            for (i, v) in values.iter().enumerate() {
                if !(v.is_finite() && ok(*v)) {
                    out.push((field, format!("link {} is {v}, must be {want}", i + 1)));
                }
            }
        };
        check("mass_kg", &self.mass_kg, |v| v > 0.0, "> 0");
        check("length_m", &self.length_m, |v| v > 0.0, "> 0");
        check("inertia_kg_m2", &self.inertia_kg_m2, |v| v > 0.0, "> 0");
        check("friction_n_m_s", &self.friction_n_m_s, |v| v >= 0.0, ">= 0");
        check("com_m", &self.com_m, |v| v >= 0.0, ">= 0");
        check("gravity_m_s2", &[self.gravity_m_s2], |v| v >= 0.0, ">= 0");
        for i in 0..3 {
            if self.com_m[i] > self.length_m[i] {
                out.push((
                    "com_m",
                    format!(
                        "link {} is {}, beyond the link's length {}",
                        i + 1,
                        self.com_m[i],
                        self.length_m[i]
                    ),
                ));
            }
        }
        out
    }
}

impl Default for ThreeLinkParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Three-link planar arm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThreeLink {
    pub params: ThreeLinkParams,
}

impl ThreeLink {
    pub fn new(params: ThreeLinkParams) -> Self {
        Self { params }
    }

    /// Absolute link angles `θ_i = q_1 + … + q_i`.
    fn absolute(q: &Vector<3>) -> [f64; 3] {
        [q[0], q[0] + q[1], q[0] + q[1] + q[2]]
    }

    /// `ℓ_a` as seen from link `i`'s centre of mass: the full length of the links before it,
    /// the centre-of-mass distance of link `i` itself.
    fn lever(&self, a: usize, i: usize) -> f64 {
        if a == i {
            self.params.com_m[a]
        } else {
            self.params.length_m[a]
        }
    }

    /// `Σ_i [ m_i Σ_{a≥k, b≥l; a,b≤i} term(a, b, ℓ_a ℓ_b, θ_a − θ_b) + own(i) ]` for each
    /// `(k, l)`: the shape of `M` and of its partial derivatives.
    fn chain_sum(
        &self,
        q: &Vector<3>,
        term: impl Fn(usize, usize, f64, f64) -> f64,
        own: impl Fn(usize) -> f64,
    ) -> Matrix<3> {
        let th = Self::absolute(q);
        let mut out = Matrix::<3>::zeros();
        for i in 0..3 {
            let mass = self.params.mass_kg[i];
            for k in 0..=i {
                for l in 0..=i {
                    let mut sum = 0.0;
                    for a in k..=i {
                        for b in l..=i {
                            let levers = self.lever(a, i) * self.lever(b, i);
                            sum += term(a, b, levers, th[a] - th[b]);
                        }
                    }
                    out[(k, l)] += mass * sum + own(i);
                }
            }
        }
        out
    }

    /// `∂M/∂q_m`: `∂cos(θ_a − θ_b)/∂q_m = −sin(θ_a − θ_b) ([m ≤ a] − [m ≤ b])`.
    fn inertia_partial(&self, q: &Vector<3>, m: usize) -> Matrix<3> {
        let term = |a: usize, b: usize, levers: f64, dth: f64| {
            let d = f64::from(u8::from(m <= a)) - f64::from(u8::from(m <= b));
            if d == 0.0 {
                0.0
            } else {
                -(levers * dth.sin() * d)
            }
        };
        self.chain_sum(q, term, |_| 0.0)
    }

    /// Potential energy `g Σ m_i y_i` of the centres of mass (zero at `q = 0`'s height, the base).
    pub fn potential_energy(&self, q: &Vector<3>) -> f64 {
        let th = Self::absolute(q);
        (0..3)
            .map(|i| {
                let height: f64 = (0..=i).map(|a| self.lever(a, i) * th[a].sin()).sum();
                self.params.mass_kg[i] * self.params.gravity_m_s2 * height
            })
            .sum()
    }
}

impl EulerLagrange<3> for ThreeLink {
    fn problems(&self) -> Vec<(&'static str, String)> {
        self.params.problems()
    }

    fn inertia(&self, q: &Vector<3>) -> Matrix<3> {
        self.chain_sum(
            q,
            |_, _, levers, dth| levers * dth.cos(),
            |i| self.params.inertia_kg_m2[i],
        )
    }

    fn inertia_rate(&self, q: &Vector<3>, qd: &Vector<3>) -> Matrix<3> {
        (0..3).fold(Matrix::<3>::zeros(), |acc, m| {
            acc + self.inertia_partial(q, m) * qd[m]
        })
    }

    /// `V_kj = Σ_i Γ_kij q̇_i`, `Γ_kij = ½ (∂M_kj/∂q_i + ∂M_ki/∂q_j − ∂M_ij/∂q_k)`.
    fn coriolis(&self, q: &Vector<3>, qd: &Vector<3>) -> Matrix<3> {
        let partial = [
            self.inertia_partial(q, 0),
            self.inertia_partial(q, 1),
            self.inertia_partial(q, 2),
        ];
        Matrix::<3>::from_fn(|k, j| {
            (0..3)
                .map(|i| {
                    0.5 * (partial[i][(k, j)] + partial[j][(k, i)] - partial[k][(i, j)]) * qd[i]
                })
                .sum()
        })
    }

    fn gravity(&self, q: &Vector<3>) -> Vector<3> {
        let th = Self::absolute(q);
        let g = self.params.gravity_m_s2;
        Vector::<3>::from_fn(|k, _| {
            (k..3)
                .map(|i| {
                    let arm: f64 = (k..=i).map(|a| self.lever(a, i) * th[a].cos()).sum();
                    self.params.mass_kg[i] * g * arm
                })
                .sum()
        })
    }

    fn friction(&self, qd: &Vector<3>) -> Vector<3> {
        Vector::<3>::from_fn(|i, _| self.params.friction_n_m_s[i] * qd[i])
    }
}

#[cfg(test)]
mod tests;
