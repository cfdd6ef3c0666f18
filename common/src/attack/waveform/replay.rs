//! Replay: the classic replay attack. The clean signal of the channel is recorded over
//! `[record_from_s, record_from_s + record_for_s)` and, from the segment's start, played back in a
//! loop in place of the live signal (`α = recorded − clean`, so the center sees the recording).
//! The recording itself lives in the compiled channel ([`crate::attack::AgentAttack`]); this
//! file is the pure part: which recorded sample is played at a given time.

/// Index of the recorded sample played `elapsed` seconds after the segment began, for a
/// recording of `len` samples taken `spacing` seconds apart: sample `round(elapsed / spacing)`,
/// looped. `None` when nothing was recorded.
pub fn index(elapsed: f64, spacing: f64, len: usize) -> Option<usize> {
    if len == 0 {
        return None;
    }
    if len == 1 || spacing.is_nan() || spacing <= 0.0 || !elapsed.is_finite() || elapsed <= 0.0 {
        return Some(0);
    }
    let n = (elapsed / spacing).round();
    // `len` is far below 2^53: the float remainder is exact.
    Some((n % len as f64) as usize)
}

/// Spacing of a recording whose first and last samples were taken at `first` and `last`.
pub fn spacing(first: f64, last: f64, len: usize) -> f64 {
    if len < 2 {
        0.0
    } else {
        (last - first) / (len - 1) as f64
    }
}

#[cfg(test)]
mod tests;
