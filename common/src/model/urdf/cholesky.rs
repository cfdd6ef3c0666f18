//! `M⁻¹ b` and `M⁻¹` of an arm's inertia by Cholesky, `M = L Lᵀ`, on the stack and with plain
//! loops over `N` known at compile time: the plant's integrator, the observer and the
//! controller ask them every tick, where nalgebra's general factorization took an eighth of a
//! Panda's tick. `None` when `M` is not positive definite (or holds a number that is not one).

use crate::model::robot::{Matrix, Vector};

/// The lower factor `L` of `M = L Lᵀ`, row by row, and the reciprocals of its diagonal.
pub(super) struct Cholesky<const N: usize> {
    l: [[f64; N]; N],
    inv_diag: [f64; N],
}

// The factorization's textbook indices (row `i`, column `j`, the sum over `k`) read clearer
// than iterators over rows that two of them index at once.
#[allow(clippy::needless_range_loop)]
impl<const N: usize> Cholesky<N> {
    /// Factors the symmetric `m` (its lower triangle is read).
    #[inline(always)]
    pub(super) fn new(m: &Matrix<N>) -> Option<Self> {
        let mut l = [[0.0; N]; N];
        let mut inv_diag = [0.0; N];
        for j in 0..N {
            let mut d = m[(j, j)];
            for k in 0..j {
                d -= l[j][k] * l[j][k];
            }
            if d.is_nan() || d <= 0.0 {
                return None;
            }
            let d = d.sqrt();
            l[j][j] = d;
            inv_diag[j] = 1.0 / d;
            for i in j + 1..N {
                let mut s = m[(i, j)];
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                l[i][j] = s * inv_diag[j];
            }
        }
        Some(Self { l, inv_diag })
    }

    /// `M⁻¹ b`: `L y = b` forward, then `Lᵀ x = y` back.
    #[inline(always)]
    pub(super) fn solve(&self, b: &Vector<N>) -> Vector<N> {
        let l = &self.l;
        let mut x = [0.0; N];
        for i in 0..N {
            let mut s = b[i];
            for k in 0..i {
                s -= l[i][k] * x[k];
            }
            x[i] = s * self.inv_diag[i];
        }
        for i in (0..N).rev() {
            let mut s = x[i];
            for k in i + 1..N {
                s -= l[k][i] * x[k];
            }
            x[i] = s * self.inv_diag[i];
        }
        Vector::<N>::from(x)
    }

    /// `M⁻¹ = L⁻ᵀ L⁻¹`, from `W = L⁻¹` (lower triangular), exactly symmetric.
    #[inline(always)]
    pub(super) fn inverse(&self) -> Matrix<N> {
        let l = &self.l;
        let mut w = [[0.0; N]; N];
        for j in 0..N {
            w[j][j] = self.inv_diag[j];
            for i in j + 1..N {
                let mut s = 0.0;
                for k in j..i {
                    s -= l[i][k] * w[k][j];
                }
                w[i][j] = s * self.inv_diag[i];
            }
        }
        let mut inv = Matrix::<N>::zeros();
        for j in 0..N {
            for i in j..N {
                let mut s = 0.0;
                for row in w.iter().skip(i) {
                    s += row[i] * row[j];
                }
                inv[(i, j)] = s;
                inv[(j, i)] = s;
            }
        }
        inv
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A symmetric positive definite matrix from `seed` values: `A Aᵀ + N I`.
    fn spd(values: &[f64]) -> Matrix<7> {
        let a = Matrix::<7>::from_fn(|i, j| values[(i * 7 + j) % values.len()]);
        a * a.transpose() + Matrix::<7>::identity() * 7.0
    }

    proptest! {
        #[test]
        fn it_agrees_with_nalgebra_s_factorization(
            values in prop::collection::vec(-3.0f64..3.0, 49),
            b in prop::collection::vec(-10.0f64..10.0, 7),
        ) {
            let m = spd(&values);
            let b = Vector::<7>::from_column_slice(&b);
            let ours = Cholesky::new(&m).expect("positive definite");
            let theirs = m.cholesky().expect("positive definite");
            let (x, y) = (ours.solve(&b), theirs.solve(&b));
            prop_assert!((x - y).norm() <= 1e-12 * y.norm().max(1.0), "{x} vs {y}");
            let (inv, reference) = (ours.inverse(), theirs.inverse());
            prop_assert!((inv - reference).norm() <= 1e-12 * reference.norm());
            prop_assert_eq!(inv, inv.transpose());
            prop_assert!((m * x - b).norm() <= 1e-9 * b.norm().max(1.0));
        }
    }

    #[test]
    fn a_matrix_that_is_not_positive_definite_has_no_factor() {
        let mut m = Matrix::<3>::identity();
        m[(2, 2)] = 0.0;
        assert!(Cholesky::new(&m).is_none());
        m[(2, 2)] = -1.0;
        assert!(Cholesky::new(&m).is_none());
        m[(2, 2)] = f64::NAN;
        assert!(Cholesky::new(&m).is_none());
        // Indefinite with a positive diagonal.
        let m = Matrix::<2>::new(1.0, 2.0, 2.0, 1.0);
        assert!(Cholesky::new(&m).is_none());
        assert!(Cholesky::new(&Matrix::<2>::new(4.0, 2.0, 2.0, 3.0)).is_some());
    }
}
