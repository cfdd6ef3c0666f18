//! `external`: the torque of each tick decided by a program outside the project
//! (`[roles.controller]`, docs/protocol.md, "The controller program"). The control center shows
//! the program the tick (the measurement in use, the reference, `e_u`, the delay, the model's
//! terms) and sends the torque it answers; the program's `Ŝ` and its own alarm, if it has one,
//! are recorded. What the run records as the estimate of the state is the paper's observer
//! (22)–(24), stepped with the torques sent and the program's `Ŝ`, as for `traditional`: the
//! residual detectors read it. The control-center process asks the program over IPC
//! ([`super::CenterAgent::ask`], then [`super::CenterAgent::answer`]), and so does the in-process
//! engine in lockstep ([`crate::engine::Asking`]).

use crate::model::{EulerLagrange, Vector};

use super::config::CenterParams;
use super::controller::{Command, Controller, Estimate, Tick};
use super::paper::Paper;

/// A controller program's side in the control center: the observer that gives the estimate.
#[derive(Debug)]
pub struct External<const N: usize> {
    observer: Paper<N>,
    /// The program's alarm of the tick under way.
    alarm: Option<bool>,
}

impl<const N: usize> External<N> {
    pub fn new(params: &CenterParams, model: &dyn EulerLagrange<N>) -> Option<Self> {
        Some(Self {
            observer: Paper::traditional(params, model)?,
            alarm: None,
        })
    }
}

impl<const N: usize> Controller<N> for External<N> {
    /// The program's answer, `Ŝ` handed to the observer; without a usable answer a non-finite
    /// torque, which the pipeline replaces by the last good one and counts.
    fn command(&mut self, x: &Tick<'_, N>) -> Command<N> {
        let zero = Vector::<N>::zeros();
        let s_hat = x.answer.map_or(&zero, |a| &a.command.s_hat);
        // The observer's A = M(q_d)⁻¹ and Ŝ of this tick, for its step in `update`.
        self.observer.command(&Tick {
            s_override: Some(s_hat),
            ..*x
        });
        self.alarm = x.answer.and_then(|a| a.alarm);
        match x.answer {
            Some(a) => a.command,
            None => Command {
                u: Vector::from_element(f64::NAN),
                s_hat: zero,
            },
        }
    }

    fn update(&mut self, x: &Tick<'_, N>, u_tau: &Vector<N>) -> Estimate<N> {
        Estimate {
            alarm: self.alarm,
            ..self.observer.update(x, u_tau)
        }
    }

    fn is_finite(&self) -> bool {
        self.observer.is_finite()
    }

    fn reset(&mut self, y: &Vector<N>, yd: &Vector<N>) -> Estimate<N> {
        Estimate {
            alarm: self.alarm,
            ..self.observer.reset(y, yd)
        }
    }
}
