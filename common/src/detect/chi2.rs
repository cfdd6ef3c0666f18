//! The χ² detector: `χ²_k = Σ over the last w ticks of zᵀ z` (`z` the whitened residual, so
//! `zᵀ z = rᵀ Σ⁻¹ r`), alarm while `χ²_k` exceeds its threshold.

use std::collections::VecDeque;

use nalgebra::DVector;

use super::config::DetectorsConfig;
use super::gamma;
use super::kind::{Kind, ResidualDetector};

/// The χ² test: `chi2` in every table.
pub const KIND: Kind = Kind {
    name: "chi2",
    title: "χ²",
    phrase: "a χ² test",
    statistic: "windowed χ² sum of the whitened residual",
    threshold_doc: "its configured threshold (null when none could be had)",
    describe,
    threshold,
    build,
};

/// `χ² over w tick(s) (threshold t | false-alarm probability p per tick)`.
fn describe(d: &DetectorsConfig) -> String {
    format!(
        "χ² over {} tick(s) ({})",
        d.chi2.window_ticks,
        d.chi2.threshold.map_or_else(
            || format!(
                "false-alarm probability {:e} per tick",
                d.chi2.false_alarm_probability
            ),
            |t| format!("threshold {t}")
        )
    )
}

/// The configured threshold, else the χ² quantile of `dim × w` degrees of freedom at the
/// configured false-alarm probability.
fn threshold(d: &DetectorsConfig, dim: usize) -> Result<f64, String> {
    let c = d.chi2;
    let w = c.window_ticks.max(1);
    match c.threshold {
        Some(t) => Ok(t),
        None => gamma::chi2_quantile_upper(dim * w, c.false_alarm_probability).ok_or_else(|| {
            format!(
                "no χ² quantile for {} degrees of freedom at probability {}",
                dim * w,
                c.false_alarm_probability
            )
        }),
    }
}

fn build(d: &DetectorsConfig, _dim: usize) -> Box<dyn ResidualDetector> {
    Box::new(Chi2::new(d.chi2.window_ticks.max(1)))
}

/// Sliding sum of the last `w` per-tick statistics.
#[derive(Debug, Clone)]
pub struct Chi2 {
    window: VecDeque<f64>,
    w: usize,
}

impl Chi2 {
    pub fn new(window_ticks: usize) -> Self {
        let w = window_ticks.max(1);
        Self {
            window: VecDeque::with_capacity(w),
            w,
        }
    }

    /// Feeds `zᵀ z` of one tick (finite); the window sum once it holds `w` values, `None`
    /// while it fills. The sum is taken afresh each tick, in tick order: no running sum to drift.
    pub fn push(&mut self, q: f64) -> Option<f64> {
        if self.window.len() == self.w {
            self.window.pop_front();
        }
        self.window.push_back(q);
        (self.window.len() == self.w).then(|| self.window.iter().sum())
    }
}

impl ResidualDetector for Chi2 {
    fn push(&mut self, z: &DVector<f64>) -> Option<f64> {
        Chi2::push(self, z.dot(z))
    }

    fn boxed_clone(&self) -> Box<dyn ResidualDetector> {
        Box::new(self.clone())
    }
}
