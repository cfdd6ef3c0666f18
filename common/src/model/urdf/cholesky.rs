//! `M⁻¹ b` and `M⁻¹` of an arm's inertia by Cholesky, `M = L Lᵀ`, on the stack and with plain
//! loops over `N` known at compile time: the plant's integrator, the observer and the
//! controller ask them every tick, where nalgebra's general factorization took an eighth of a
//! Panda's tick. `None` when `M` is not positive definite (or holds a number that is not one).

use super::lanes::Lane;
use crate::model::robot::Matrix;

/// The lower factor `L` of `M = L Lᵀ`, row by row, and the reciprocals of its diagonal: of
/// one arm's `M` (`f64`) or of several side by side ([`Lane`]).
pub(super) struct Cholesky<'a, const N: usize, T = f64> {
    l: &'a [[T; N]; N],
    inv_diag: [T; N],
}

// The factorization's textbook indices (row `i`, column `j`, the sum over `k`) read clearer
// than iterators over rows that two of them index at once.
#[allow(clippy::needless_range_loop)]
impl<'a, const N: usize, T: Lane> Cholesky<'a, N, T> {
    /// Factors the symmetric `m`, given by rows, in place (its lower triangle is read and
    /// becomes `L`; the upper one is never read); `None` when a pivot of some lane is not
    /// positive.
    #[inline(always)]
    pub(super) fn new(l: &'a mut [[T; N]; N]) -> Option<Self> {
        let mut inv_diag = [T::zero(); N];
        for j in 0..N {
            let mut d = l[j][j];
            for k in 0..j {
                d -= l[j][k] * l[j][k];
            }
            if !d.positive() {
                return None;
            }
            let d = d.sqrt();
            l[j][j] = d;
            inv_diag[j] = T::one() / d;
            for i in j + 1..N {
                let mut s = l[i][j];
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
    pub(super) fn solve(&self, b: &[T; N]) -> [T; N] {
        let l = &self.l;
        let mut x = [T::zero(); N];
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
        x
    }

    /// `M⁻¹ = L⁻ᵀ L⁻¹` by rows, from `W = L⁻¹` (lower triangular), exactly symmetric.
    #[inline(always)]
    pub(super) fn inverse_rows(&self) -> [[T; N]; N] {
        let l = &self.l;
        let mut w = [[T::zero(); N]; N];
        for j in 0..N {
            w[j][j] = self.inv_diag[j];
            for i in j + 1..N {
                let mut s = T::zero();
                for k in j..i {
                    s -= l[i][k] * w[k][j];
                }
                w[i][j] = s * self.inv_diag[i];
            }
        }
        let mut inv = [[T::zero(); N]; N];
        for j in 0..N {
            for i in j..N {
                let mut s = T::zero();
                for row in w.iter().skip(i) {
                    s += row[i] * row[j];
                }
                inv[i][j] = s;
                inv[j][i] = s;
            }
        }
        inv
    }
}

impl<const N: usize> Cholesky<'_, N> {
    /// `M⁻¹` ([`Self::inverse_rows`]).
    #[inline(always)]
    pub(super) fn inverse(&self) -> Matrix<N> {
        // Symmetric: its rows are its columns, which nalgebra's arrays of arrays hold.
        Matrix::<N>::from(self.inverse_rows())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Vector;
    use proptest::prelude::*;

    /// A symmetric positive definite matrix from `seed` values: `A Aᵀ + N I`.
    fn spd(values: &[f64]) -> Matrix<7> {
        let a = Matrix::<7>::from_fn(|i, j| values[(i * 7 + j) % values.len()]);
        a * a.transpose() + Matrix::<7>::identity() * 7.0
    }

    /// `m` by rows.
    fn rows<const N: usize>(m: &Matrix<N>) -> [[f64; N]; N] {
        std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
    }

    /// Whether `m` has a factor.
    fn factors<const N: usize>(m: &Matrix<N>) -> bool {
        Cholesky::new(&mut rows(m)).is_some()
    }

    proptest! {
        #[test]
        fn it_agrees_with_nalgebra_s_factorization(
            values in prop::collection::vec(-3.0f64..3.0, 49),
            b in prop::collection::vec(-10.0f64..10.0, 7),
        ) {
            let m = spd(&values);
            let b = Vector::<7>::from_column_slice(&b);
            let mut l = rows(&m);
            let ours = Cholesky::new(&mut l).expect("positive definite");
            let theirs = m.cholesky().expect("positive definite");
            let (x, y) = (Vector::<7>::from(ours.solve(&b.data.0[0])), theirs.solve(&b));
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
        assert!(!factors(&m));
        m[(2, 2)] = -1.0;
        assert!(!factors(&m));
        m[(2, 2)] = f64::NAN;
        assert!(!factors(&m));
        // Indefinite with a positive diagonal.
        assert!(!factors(&Matrix::<2>::new(1.0, 2.0, 2.0, 1.0)));
        assert!(factors(&Matrix::<2>::new(4.0, 2.0, 2.0, 3.0)));
    }
}
