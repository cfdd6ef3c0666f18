//! Stealthy bias: a bias that grows from zero at the fastest rate a χ² test on the observer's
//! residual cannot see, then holds (docs/stealthy.md).
//!
//! The attacker is white-box: it knows the χ² detector's threshold `τ` and window `w`, the
//! residual's attack-free standard deviation `σ` (from the sensor noise the scenario states),
//! and how the residual answers a slowly growing bias: a bias of slope `s` shifts each residual
//! entry it reaches by a steady `κ s` (for `Ψ2`, the lag of the NN estimate behind a ramp of
//! `S`). If the attack-free statistic stays under `q`, a steady whitened offset `μ` keeps the
//! attacked one under `τ` as long as `√w ‖μ‖ ≤ √τ − √q` (Minkowski's inequality on the `w`
//! whitened residuals of the window), whatever the noise does. Shifting `m` entries by `r`
//! each gives `‖μ‖ = √m r / σ`, hence the largest offset and slope
//!
//! `r = σ (√τ − √q) / √(w m)`, `s = r / κ`,
//!
//! and the bias `b(t) = sign(B) · min(s (t − t₀), |B|)` from the segment's start `t₀` to the
//! level `B`.

/// The largest steady whitened offset norm `‖μ‖` that keeps the χ² window sum under
/// `threshold` while the attack-free sum stays under `noise_peak`: `(√τ − √q) / √w`. Zero when
/// `q ≥ τ` (no room under the threshold).
pub fn offset_budget(threshold: f64, noise_peak: f64, window_ticks: u32) -> f64 {
    ((threshold.sqrt() - noise_peak.sqrt()) / f64::from(window_ticks.max(1)).sqrt()).max(0.0)
}

/// The largest steady offset of each of `shifted_entries` residual entries, in the residual's
/// units: `σ ‖μ‖ / √m`.
pub fn residual_offset(
    threshold: f64,
    noise_peak: f64,
    window_ticks: u32,
    shifted_entries: u32,
    residual_std: f64,
) -> f64 {
    residual_std * offset_budget(threshold, noise_peak, window_ticks)
        / f64::from(shifted_entries.max(1)).sqrt()
}

/// The bias's slope, channel units per s: the residual offset over the residual's sensitivity
/// `κ` (residual units per channel unit per s).
pub fn slope(
    threshold: f64,
    noise_peak: f64,
    window_ticks: u32,
    shifted_entries: u32,
    residual_std: f64,
    sensitivity: f64,
) -> f64 {
    residual_offset(
        threshold,
        noise_peak,
        window_ticks,
        shifted_entries,
        residual_std,
    ) / sensitivity
}

/// `sign(bias) · min(slope · elapsed, |bias|)`; zero before the segment starts.
pub(super) fn value(elapsed: f64, slope: f64, bias: f64) -> f64 {
    if elapsed <= 0.0 {
        return 0.0;
    }
    bias.signum() * (slope * elapsed).min(bias.abs())
}

/// The window of the χ² test when a profile does not say: one tick (the detector's default).
pub(super) fn one_tick() -> u32 {
    1
}

#[cfg(test)]
mod tests;
