//! Linear drift from the segment's start: the slow attack that evades fixed thresholds.

pub(super) fn value(elapsed: f64, slope: f64, start: f64) -> f64 {
    start + slope * elapsed
}
