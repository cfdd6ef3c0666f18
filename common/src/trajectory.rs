//! Desired trajectories `q_d(t)` with exact first and second derivatives.
//!
//! Each link follows `q_d = f(t) · g(t)` where `f` is a cosine, sine or constant and
//! `g(t) = 1 − e^{−c t³}` is the paper's smooth start (c = 0.01; `ramp_rate = 0` disables it).
//! Derivatives follow the product rule exactly: `q̇ = ḟg + fġ`, `q̈ = f̈g + 2ḟġ + fg̈`.

use serde::{Deserialize, Serialize};

use crate::model::Vector;
use crate::units::AngleUnit;

/// One link's base waveform `f(t)`, in the trajectory's units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "shape", rename_all = "kebab-case", deny_unknown_fields)]
pub enum LinkTrajectory {
    /// `amplitude · cos(omega t + phase) + offset`.
    Cosine {
        /// Trajectory units.
        amplitude: f64,
        /// Angular frequency, rad/s.
        omega_rad_s: f64,
        /// Phase, rad (default 0).
        #[serde(default)]
        phase_rad: f64,
        /// Trajectory units (default 0).
        #[serde(default)]
        offset: f64,
    },
    /// `amplitude · sin(omega t + phase) + offset`.
    Sine {
        /// Trajectory units.
        amplitude: f64,
        /// Angular frequency, rad/s.
        omega_rad_s: f64,
        /// Phase, rad (default 0).
        #[serde(default)]
        phase_rad: f64,
        /// Trajectory units (default 0).
        #[serde(default)]
        offset: f64,
    },
    /// A set point.
    Constant {
        /// Trajectory units.
        value: f64,
    },
}

impl LinkTrajectory {
    /// `(f, ḟ, f̈)` at `t`, in the trajectory's units.
    /// `f(t)` alone: [`Self::eval`]'s first value to the bit (`sin_cos` is `sin` and `cos`).
    fn value(&self, t: f64) -> f64 {
        match *self {
            Self::Cosine {
                amplitude,
                omega_rad_s: w,
                phase_rad,
                offset,
            } => amplitude * (w * t + phase_rad).cos() + offset,
            Self::Sine {
                amplitude,
                omega_rad_s: w,
                phase_rad,
                offset,
            } => amplitude * (w * t + phase_rad).sin() + offset,
            Self::Constant { value } => value,
        }
    }

    fn eval(&self, t: f64) -> (f64, f64, f64) {
        match *self {
            Self::Cosine {
                amplitude,
                omega_rad_s: w,
                phase_rad,
                offset,
            } => {
                let (s, c) = (w * t + phase_rad).sin_cos();
                (
                    amplitude * c + offset,
                    -amplitude * w * s,
                    -amplitude * w * w * c,
                )
            }
            Self::Sine {
                amplitude,
                omega_rad_s: w,
                phase_rad,
                offset,
            } => {
                let (s, c) = (w * t + phase_rad).sin_cos();
                (
                    amplitude * s + offset,
                    amplitude * w * c,
                    -amplitude * w * w * s,
                )
            }
            Self::Constant { value } => (value, 0.0, 0.0),
        }
    }

    /// Every parameter of the waveform, for validation.
    pub fn parameters(&self) -> Vec<(&'static str, f64)> {
        match *self {
            Self::Cosine {
                amplitude,
                omega_rad_s,
                phase_rad,
                offset,
            }
            | Self::Sine {
                amplitude,
                omega_rad_s,
                phase_rad,
                offset,
            } => vec![
                ("amplitude", amplitude),
                ("omega_rad_s", omega_rad_s),
                ("phase_rad", phase_rad),
                ("offset", offset),
            ],
            Self::Constant { value } => vec![("value", value)],
        }
    }
}

/// Scenario form of a desired trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TrajectoryConfig {
    /// Units of every amplitude, offset and value below (`deg` or `rad`).
    pub units: AngleUnit,
    /// `c` in `g(t) = 1 − e^{−c t³}`, 1/s³; the paper uses 0.01. Zero means `g ≡ 1`.
    #[serde(default)]
    pub ramp_rate: f64,
    /// One entry per link.
    pub links: Vec<LinkTrajectory>,
}

/// Reference `(q_d, q̇_d, q̈_d)` at one instant, in rad, rad/s, rad/s².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference<const N: usize> {
    pub q: Vector<N>,
    pub qd: Vector<N>,
    pub qdd: Vector<N>,
}

impl TrajectoryConfig {
    /// `q_d, q̇_d, q̈_d` at `t`. Links beyond `links.len()` stay at zero (validation forbids it).
    /// `q_d(t)` alone, what [`Self::reference`] gives as `q` (the same operations), without
    /// the derivatives: what the metrics compare the true state with every tick.
    pub fn position<const N: usize>(&self, t: f64) -> Vector<N> {
        let scale = self.units.to_rad();
        let g = if self.ramp_rate > 0.0 {
            let c = self.ramp_rate;
            1.0 - (-c * t * t * t).exp()
        } else {
            1.0
        };
        let mut q = Vector::<N>::zeros();
        for (i, link) in self.links.iter().take(N).enumerate() {
            q[i] = scale * (link.value(t) * g);
        }
        q
    }

    pub fn reference<const N: usize>(&self, t: f64) -> Reference<N> {
        let scale = self.units.to_rad();
        let (g, gd, gdd) = if self.ramp_rate > 0.0 {
            let c = self.ramp_rate;
            let e = (-c * t * t * t).exp();
            (
                1.0 - e,
                3.0 * c * t * t * e,
                (6.0 * c * t - 9.0 * c * c * t.powi(4)) * e,
            )
        } else {
            (1.0, 0.0, 0.0)
        };
        let mut r = Reference {
            q: Vector::<N>::zeros(),
            qd: Vector::<N>::zeros(),
            qdd: Vector::<N>::zeros(),
        };
        for (i, link) in self.links.iter().take(N).enumerate() {
            let (f, fd, fdd) = link.eval(t);
            r.q[i] = scale * (f * g);
            r.qd[i] = scale * (fd * g + f * gd);
            r.qdd[i] = scale * (fdd * g + 2.0 * fd * gd + f * gdd);
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn paper_robot2() -> TrajectoryConfig {
        TrajectoryConfig {
            units: AngleUnit::Deg,
            ramp_rate: 0.01,
            links: vec![
                LinkTrajectory::Sine {
                    amplitude: 30.0,
                    omega_rad_s: 1.5,
                    phase_rad: 0.0,
                    offset: 20.0,
                },
                LinkTrajectory::Sine {
                    amplitude: 20.0,
                    omega_rad_s: 0.5,
                    phase_rad: 0.0,
                    offset: 10.0,
                },
            ],
        }
    }

    fn paper_robot1() -> TrajectoryConfig {
        TrajectoryConfig {
            units: AngleUnit::Deg,
            ramp_rate: 0.01,
            links: vec![
                LinkTrajectory::Cosine {
                    amplitude: 50.0,
                    omega_rad_s: 1.5,
                    phase_rad: 0.0,
                    offset: 0.0,
                },
                LinkTrajectory::Cosine {
                    amplitude: 30.0,
                    omega_rad_s: 1.5,
                    phase_rad: 0.0,
                    offset: 0.0,
                },
            ],
        }
    }

    #[test]
    fn derivatives_match_central_differences() {
        // h = 1e-5 s: truncation O(h²) ≈ 1e-10 relative, round-off ≈ 1e-16/h ≈ 1e-11 for q̇ and
        // 1e-16/h² ≈ 1e-6 for q̈, hence the looser tolerance on the second derivative.
        let h = 1e-5;
        for traj in [paper_robot1(), paper_robot2()] {
            for i in 0..200 {
                let t = f64::from(i) * 0.21;
                let r = traj.reference::<2>(t);
                let (p, m) = (traj.reference::<2>(t + h), traj.reference::<2>(t - h));
                assert_relative_eq!(r.qd, (p.q - m.q) / (2.0 * h), epsilon = 1e-7);
                assert_relative_eq!(r.qdd, (p.qd - m.qd) / (2.0 * h), epsilon = 1e-6);
            }
        }
    }

    proptest::proptest! {
        /// The metrics' `position` is the controller's `reference().q` to the bit, whatever the
        /// shape, phase, offset, ramp and time (arguments far beyond `[−π, π]` included).
        #[test]
        fn position_is_the_reference_s_q_to_the_bit(
            t in 0.0..5000.0f64,
            amplitude in -100.0..100.0f64,
            w in -20.0..20.0f64,
            phase in -7.0..7.0f64,
            offset in -50.0..50.0f64,
            ramp in proptest::prop_oneof![proptest::strategy::Just(0.0), 0.0..1.0f64],
        ) {
            let traj = TrajectoryConfig {
                units: AngleUnit::Deg,
                ramp_rate: ramp,
                links: vec![
                    LinkTrajectory::Cosine { amplitude, omega_rad_s: w, phase_rad: phase, offset },
                    LinkTrajectory::Sine { amplitude, omega_rad_s: w, phase_rad: phase, offset },
                    LinkTrajectory::Constant { value: offset },
                ],
            };
            let (p, r) = (traj.position::<3>(t), traj.reference::<3>(t).q);
            for i in 0..3 {
                proptest::prop_assert_eq!(p[i].to_bits(), r[i].to_bits());
            }
        }
    }

    #[test]
    fn starts_at_rest_at_the_origin() {
        let r = paper_robot2().reference::<2>(0.0);
        assert_eq!(r.q, Vector::<2>::zeros());
        assert_eq!(r.qd, Vector::<2>::zeros());
    }

    #[test]
    fn paper_values_in_radians_after_the_ramp() {
        // At t = 40 s, g = 1 − e^{−640} = 1 to double precision.
        let r = paper_robot1().reference::<2>(40.0);
        assert_relative_eq!(
            r.q[0],
            50f64.to_radians() * (60.0f64).cos(),
            epsilon = 1e-12
        );
    }
}
