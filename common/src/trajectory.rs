//! Desired trajectories `q_d(t)` with exact first and second derivatives.
//!
//! Each link follows `q_d = s + f(t) · g(t)` where `s` is the joint's start (the pose the robot
//! starts from at rest; the origin when `start` is left out, as in the paper), `f` is a cosine,
//! sine or constant and `g(t) = 1 − e^{−c t³}` is the paper's smooth start (c = 0.01;
//! `ramp_rate = 0` disables it). Derivatives follow the product rule exactly:
//! `q̇ = ḟg + fġ`, `q̈ = f̈g + 2ḟġ + fg̈`.

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

    /// The least and greatest `f(t)` over all `t`, in the trajectory's units.
    pub fn range(&self) -> (f64, f64) {
        match *self {
            Self::Cosine {
                amplitude, offset, ..
            }
            | Self::Sine {
                amplitude, offset, ..
            } => (offset - amplitude.abs(), offset + amplitude.abs()),
            Self::Constant { value } => (value, value),
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
    /// Where each joint starts, at rest, in the units above: `q_d = start + f(t) g(t)`, and the
    /// robot and the control center's observer begin there. Left out: every joint at 0 (the
    /// paper's robots). An arm whose joint limits exclude 0 (a Panda's fourth joint) needs it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub start: Vec<f64>,
}

/// Reference `(q_d, q̇_d, q̈_d)` at one instant, in rad, rad/s, rad/s².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference<const N: usize> {
    pub q: Vector<N>,
    pub qd: Vector<N>,
    pub qdd: Vector<N>,
}

impl TrajectoryConfig {
    /// `start` in rad (empty when it is left out).
    pub fn start_rad(&self) -> Vec<f64> {
        let scale = self.units.to_rad();
        self.start.iter().map(|s| scale * s).collect()
    }

    /// The pose the robot starts from at rest (rad): `start`, or the origin when it is left out;
    /// `None` when `start` has another number of joints than `N`.
    pub fn start_position<const N: usize>(&self) -> Option<Vector<N>> {
        pose(&self.start_rad())
    }

    /// The least and greatest `q_d` of link `l` over all `t` (rad): `start + f g` with `g` from
    /// 0 to 1 (only 1 without the ramp) and `f` over its range. `None` for a link the trajectory
    /// does not have.
    pub fn envelope(&self, l: usize) -> Option<(f64, f64)> {
        let (lo, hi) = self.links.get(l)?.range();
        let (lo, hi) = if self.ramp_rate > 0.0 {
            (lo.min(0.0), hi.max(0.0))
        } else {
            (lo, hi)
        };
        let start = match self.start.as_slice() {
            [] => 0.0,
            s => *s.get(l)?,
        };
        let scale = self.units.to_rad();
        Some((scale * (start + lo), scale * (start + hi)))
    }

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
            q[i] = scale * self.started(i, link.value(t) * g);
        }
        q
    }

    /// `start[i] + moved`, or `moved` when `start` is left out: the paper's `q_d` keeps its
    /// bits (`x + 0` is not `x` for `x = −0`). NaN (a non-finite reference, reported) for a
    /// joint a `start` lacks, which validation refuses.
    fn started(&self, i: usize, moved: f64) -> f64 {
        match self.start.as_slice() {
            [] => moved,
            s => s.get(i).map_or(f64::NAN, |s| s + moved),
        }
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
            r.q[i] = scale * self.started(i, f * g);
            r.qd[i] = scale * (fd * g + f * gd);
            r.qdd[i] = scale * (fdd * g + 2.0 * fd * gd + f * gdd);
        }
        r
    }
}

/// The pose of `rad` (one value per joint), or the origin when it is empty; `None` when it has
/// another number of joints than `N`.
pub fn pose<const N: usize>(rad: &[f64]) -> Option<Vector<N>> {
    match rad {
        [] => Some(Vector::<N>::zeros()),
        s if s.len() == N => Some(Vector::<N>::from_column_slice(s)),
        _ => None,
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
            start: Vec::new(),
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
            start: Vec::new(),
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
        /// shape, phase, offset, start, ramp and time (arguments far beyond `[−π, π]`
        /// included), and it stays within the envelope validation checks against joint limits.
        #[test]
        fn position_is_the_reference_s_q_to_the_bit_and_within_the_envelope(
            t in 0.0..5000.0f64,
            amplitude in -100.0..100.0f64,
            w in -20.0..20.0f64,
            phase in -7.0..7.0f64,
            offset in -50.0..50.0f64,
            start in proptest::option::of(proptest::collection::vec(-180.0..180.0f64, 3)),
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
                start: start.unwrap_or_default(),
            };
            let (p, r) = (traj.position::<3>(t), traj.reference::<3>(t).q);
            for i in 0..3 {
                proptest::prop_assert_eq!(p[i].to_bits(), r[i].to_bits());
                let (lo, hi) = traj.envelope(i).expect("a link of the trajectory");
                // Rounding of the scale's product: a few ulps of the values involved.
                let slack = 1e-12 * (1.0 + lo.abs().max(hi.abs()));
                proptest::prop_assert!(lo - slack <= p[i] && p[i] <= hi + slack, "{lo} {} {hi}", p[i]);
            }
        }
    }

    #[test]
    fn starts_at_rest_at_the_origin() {
        let r = paper_robot2().reference::<2>(0.0);
        assert_eq!(r.q, Vector::<2>::zeros());
        assert_eq!(r.qd, Vector::<2>::zeros());
        assert_eq!(
            paper_robot2().start_position::<2>(),
            Some(Vector::<2>::zeros())
        );
    }

    #[test]
    fn a_start_pose_moves_q_d_and_its_envelope_and_is_where_the_robot_begins() {
        let traj = TrajectoryConfig {
            start: vec![10.0, -20.0],
            ..paper_robot2()
        };
        let start = Vector::<2>::new(10f64.to_radians(), -20f64.to_radians());
        let r = traj.reference::<2>(0.0);
        assert_relative_eq!(r.q, start, epsilon = 1e-15);
        assert_eq!(r.qd, Vector::<2>::zeros());
        assert_eq!(traj.start_position::<2>().expect("two joints"), r.q);
        // Later the reference is the paper's plus the start, derivatives unchanged.
        let (moved, paper) = (traj.reference::<2>(7.3), paper_robot2().reference::<2>(7.3));
        assert_relative_eq!(moved.q, paper.q + start, epsilon = 1e-14);
        assert_eq!((moved.qd, moved.qdd), (paper.qd, paper.qdd));
        // Link 1: 30 sin + 20 in [−10, 50] deg, from 0 by the ramp, then + 10; link 2:
        // 20 sin + 10 in [−10, 30] deg, then − 20.
        let deg = |(lo, hi): (f64, f64)| (lo.to_degrees(), hi.to_degrees());
        let e0 = deg(traj.envelope(0).expect("link 1"));
        let e1 = deg(traj.envelope(1).expect("link 2"));
        assert_relative_eq!(e0.0, 0.0, epsilon = 1e-12);
        assert_relative_eq!(e0.1, 60.0, epsilon = 1e-12);
        assert_relative_eq!(e1.0, -30.0, epsilon = 1e-12);
        assert_relative_eq!(e1.1, 10.0, epsilon = 1e-12);
        assert_eq!(traj.envelope(2), None);
        // A start of another number of joints is no pose, and gives no reference either.
        let short = TrajectoryConfig {
            start: vec![1.0],
            ..paper_robot2()
        };
        assert_eq!(short.start_position::<2>(), None);
        assert!(short.reference::<2>(1.0).q[1].is_nan());
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
