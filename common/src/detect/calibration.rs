//! The residual's covariance over the calibration window, and the whitening it gives.
//!
//! `Σ = (1/n) Σ r rᵀ` over the window's finite residuals: the second moment about zero, not
//! about the window's mean. Under the null hypothesis the observer's residual has zero mean, and
//! a mean in the window (a bias of the model, or an attack already in force) is kept in `Σ`
//! (a wider null, fewer alarms) rather than subtracted as the normal offset (which would make
//! the detectors alarm when an attack present during calibration stops).
//!
//! Regularisation: `Σ_reg = Σ + ε (tr Σ / dim) I`, a ridge relative to the mean variance, so
//! that a channel without noise (a link that never moves, noise set to 0) leaves `Σ_reg`
//! positive definite; its condition number stays below about `dim / ε`. The whitening is
//! `z = L⁻¹ r` with `L Lᵀ = Σ_reg` (Cholesky), so `zᵀ z = rᵀ Σ_reg⁻¹ r`.

use nalgebra::{DMatrix, DVector};

use super::config::MIN_SAMPLES_PER_DIMENSION;

/// Sums over the calibration window.
#[derive(Debug, Clone)]
pub struct Accumulator {
    sum: DMatrix<f64>,
    samples: u64,
}

/// The calibrated whitening `r ↦ L⁻¹ r`.
#[derive(Debug, Clone)]
pub struct Whitener {
    l: DMatrix<f64>,
    /// `sqrt(diag Σ)` before regularisation, per residual entry.
    pub rms: Vec<f64>,
}

impl Accumulator {
    pub fn new(dim: usize) -> Self {
        Self {
            sum: DMatrix::zeros(dim, dim),
            samples: 0,
        }
    }

    /// Adds one finite residual.
    pub fn push(&mut self, r: &DVector<f64>) {
        self.sum.ger(1.0, r, r, 1.0);
        self.samples += 1;
    }

    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// The whitening, or why the window gives none.
    pub fn finish(&self, regularization: f64) -> Result<Whitener, String> {
        let dim = self.sum.nrows();
        let need = MIN_SAMPLES_PER_DIMENSION * dim as u64;
        if self.samples < need {
            return Err(format!(
                "{} usable residuals in the calibration window, fewer than the {need} a {dim}-entry covariance needs",
                self.samples
            ));
        }
        let sigma = &self.sum / self.samples as f64;
        if sigma.iter().any(|x| !x.is_finite()) {
            return Err("the calibrated covariance is not finite".into());
        }
        let rms = (0..dim).map(|i| sigma[(i, i)].sqrt()).collect();
        let trace = sigma.trace();
        if trace <= 0.0 {
            return Err("every residual of the calibration window is zero".into());
        }
        let ridge = regularization * trace / dim as f64;
        let reg = sigma + DMatrix::identity(dim, dim) * ridge;
        match reg.cholesky() {
            Some(c) => Ok(Whitener { l: c.l(), rms }),
            None => Err(format!(
                "the calibrated covariance is not positive definite (regularization {regularization})"
            )),
        }
    }
}

impl Whitener {
    /// `L⁻¹ r`; `None` when it is not finite.
    pub fn whiten(&self, r: &DVector<f64>) -> Option<DVector<f64>> {
        let mut z = r.clone();
        self.whiten_into(r, &mut z).then_some(z)
    }

    /// [`Self::whiten`] into `z` (resized to `r`'s length when it is not), without allocating:
    /// whether `z` is finite.
    pub fn whiten_into(&self, r: &DVector<f64>, z: &mut DVector<f64>) -> bool {
        if z.len() == r.len() {
            z.copy_from(r);
        } else {
            *z = r.clone();
        }
        self.l.solve_lower_triangular_mut(z) && z.iter().all(|x| x.is_finite())
    }
}
