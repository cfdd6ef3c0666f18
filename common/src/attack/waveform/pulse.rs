//! Pulse train `pulse(a, period, width %)`: high at the start of every period, like a
//! Simulink pulse generator with zero phase delay.

pub(super) fn value(t: f64, amplitude: f64, period: f64, width_percent: f64, delay: f64) -> f64 {
    if t < delay || period <= 0.0 {
        return 0.0;
    }
    let phase = (t - delay).rem_euclid(period);
    if phase < period * width_percent / 100.0 {
        amplitude
    } else {
        0.0
    }
}
