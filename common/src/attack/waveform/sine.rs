//! Sinusoidal injection `a sin(ωt + φ) + c`, in absolute time.

pub(super) fn value(t: f64, amplitude: f64, omega: f64, phase: f64, offset: f64) -> f64 {
    amplitude * (omega * t + phase).sin() + offset
}
