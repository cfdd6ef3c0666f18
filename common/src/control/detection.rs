//! Detection alarm (beyond the paper, which estimates but never alarms): raised when `‖Ŝ‖`
//! stays above a threshold for a hold time, cleared as soon as it drops to the threshold.

/// Alarm state of one agent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detector {
    threshold: f64,
    hold_s: f64,
    above_since: Option<f64>,
    alarm: bool,
}

impl Detector {
    pub fn new(threshold: f64, hold_s: f64) -> Self {
        Self {
            threshold,
            hold_s,
            above_since: None,
            alarm: false,
        }
    }

    /// Feeds `‖Ŝ‖` at time `t`; returns whether the alarm is on.
    pub fn update(&mut self, t: f64, norm: f64) -> bool {
        if norm > self.threshold {
            let since = *self.above_since.get_or_insert(t);
            self.alarm = t - since >= self.hold_s;
        } else {
            self.above_since = None;
            self.alarm = false;
        }
        self.alarm
    }

    pub fn alarm(&self) -> bool {
        self.alarm
    }
}

#[cfg(test)]
mod tests;
