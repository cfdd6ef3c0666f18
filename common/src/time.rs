//! The time of a control tick: the one formula every process uses for it.

/// `t_k = k · Δ`, computed the same way in every process.
pub fn tick_time(k: u64, control_period_s: f64) -> f64 {
    k as f64 * control_period_s
}
