//! The χ² detector: `χ²_k = Σ over the last w ticks of zᵀ z` (`z` the whitened residual, so
//! `zᵀ z = rᵀ Σ⁻¹ r`), alarm while `χ²_k` exceeds its threshold.

use std::collections::VecDeque;

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
