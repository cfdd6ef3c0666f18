//! `gated`: the traditional controller behind a residual gate (docs/model.md, "Controllers").
//! Each tick, the measurement is compared with the observer's prediction of it, the residual
//! `r = ‖y − q̂‖`; while `r` has stayed above `threshold_rad` for `hold_s`, the gate is shut:
//! the observer's prediction `(q̂, q̂̇)` stands in for the measurement, in the torque and in the
//! observer's own step (which then runs on the model and the torques sent alone), and the
//! gate's state is recorded as the control center's alarm. A residual-based detector gating
//! what a controller trusts, as in fault-tolerant control (M. Blanke, M. Kinnaert, J. Lunze,
//! M. Staroswiecki, *Diagnosis and Fault-Tolerant Control*, Springer, 3rd ed. 2016, ch. 7,
//! "sensor fault accommodation" by a virtual sensor); the observer is the paper's (22)–(24).

use crate::model::{EulerLagrange, Vector};

use super::config::CenterParams;
use super::controller::{Command, Controller, Estimate, Tick};
use super::detection::Detector;
use super::paper::Paper;

/// The gated controller of one robot.
#[derive(Debug)]
pub struct Gated<const N: usize> {
    inner: Paper<N>,
    gate: Detector,
    /// The measurement the inner controller is given this tick: the received one, or the
    /// observer's prediction while the gate is shut.
    trusted: (Vector<N>, Vector<N>),
}

impl<const N: usize> Gated<N> {
    pub fn new(params: &CenterParams, model: &dyn EulerLagrange<N>) -> Option<Self> {
        let c = params.controller.gated;
        let inner = Paper::traditional(params, model)?;
        let start = params.trajectory.start_position::<N>()?;
        Some(Self {
            inner,
            gate: Detector::new(c.threshold_rad, c.hold_s),
            trusted: (start, Vector::zeros()),
        })
    }

    /// `x` with the trusted measurement in place of the received one.
    fn trusted<'a>(x: &Tick<'a, N>, trusted: &'a (Vector<N>, Vector<N>)) -> Tick<'a, N> {
        Tick {
            y: &trusted.0,
            yd: &trusted.1,
            ..*x
        }
    }
}

impl<const N: usize> Controller<N> for Gated<N> {
    fn command(&mut self, x: &Tick<'_, N>) -> Command<N> {
        let (q_hat, qd_hat) = self.inner.prediction();
        let shut = self.gate.update(x.t, (x.y - q_hat).norm());
        self.trusted = if shut { (q_hat, qd_hat) } else { (*x.y, *x.yd) };
        self.inner.command(&Self::trusted(x, &self.trusted))
    }

    fn update(&mut self, x: &Tick<'_, N>, u_tau: &Vector<N>) -> Estimate<N> {
        let estimate = self.inner.update(&Self::trusted(x, &self.trusted), u_tau);
        Estimate {
            alarm: Some(self.gate.alarm()),
            ..estimate
        }
    }

    fn is_finite(&self) -> bool {
        self.inner.is_finite()
    }

    fn reset(&mut self, y: &Vector<N>, yd: &Vector<N>) -> Estimate<N> {
        Estimate {
            alarm: Some(self.gate.alarm()),
            ..self.inner.reset(y, yd)
        }
    }
}
