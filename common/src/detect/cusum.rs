//! The CUSUM detector: a two-sided Page CUSUM on each entry of the whitened residual.
//!
//! For every entry `z_i` of `z = L⁻¹ r` (unit variance and uncorrelated under the null
//! hypothesis): `S⁺_i = max(0, S⁺_i + z_i − ν)`, `S⁻_i = max(0, S⁻_i − z_i − ν)`; the statistic
//! is the largest of them, the alarm is on while it exceeds `h`. Linear in the residual, it
//! accumulates a persistent shift of the mean that a per-tick χ² (quadratic, one tick at a time)
//! cannot see: a shift δ (in standard deviations) above ν is flagged after about `h / (δ − ν)`
//! ticks.
//!
//! Each `S` is capped at `2 h`: without a cap a long attack drives `S` so high (the paper's
//! attacks are hundreds of standard deviations of the calibrated residual) that the alarm
//! would stay on for the rest of the run after the attack ends. With the cap it clears within
//! about `h / ν` ticks of the residual returning to its null.

use nalgebra::DVector;

use super::kind::{Kind, ResidualDetector};

/// The CUSUM: `cusum` in every table.
pub const KIND: Kind = Kind {
    name: "cusum",
    title: "CUSUM",
    phrase: "a CUSUM",
    statistic: "CUSUM statistic of the whitened residual",
    threshold_doc: "its configured threshold",
    describe: |d| format!("CUSUM (ν = {}, h = {})", d.cusum.drift, d.cusum.threshold),
    threshold: |d, _| Ok(d.cusum.threshold),
    build: |d, dim| Box::new(Cusum::new(dim, d.cusum.drift, d.cusum.threshold)),
};

#[derive(Debug, Clone)]
pub struct Cusum {
    pos: Vec<f64>,
    neg: Vec<f64>,
    drift: f64,
    h: f64,
}

impl Cusum {
    pub fn new(dim: usize, drift: f64, h: f64) -> Self {
        Self {
            pos: vec![0.0; dim],
            neg: vec![0.0; dim],
            drift,
            h,
        }
    }

    pub fn threshold(&self) -> f64 {
        self.h
    }

    /// Feeds one finite whitened residual; returns the largest `S` after the update.
    pub fn push(&mut self, z: &DVector<f64>) -> f64 {
        let cap = 2.0 * self.h;
        let mut top = 0.0f64;
        for ((p, n), zi) in self.pos.iter_mut().zip(&mut self.neg).zip(z.iter()) {
            *p = (*p + zi - self.drift).max(0.0).min(cap);
            *n = (*n - zi - self.drift).max(0.0).min(cap);
            top = top.max(*p).max(*n);
        }
        top
    }
}

impl ResidualDetector for Cusum {
    fn push(&mut self, z: &DVector<f64>) -> Option<f64> {
        Some(Cusum::push(self, z))
    }

    fn boxed_clone(&self) -> Box<dyn ResidualDetector> {
        Box::new(self.clone())
    }
}
