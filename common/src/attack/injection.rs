//! What an attacker injected at one tick, as its records say it ([`crate::records::AttackRecord`],
//! [`crate::records::ActuationRecord`]): the values `α` added to the clean signals and whether a
//! transform or a message attack was in force. The metrics count a tick as attacked from these.

use crate::model::Vector;

/// Injected values `α` at one tick, in rad and rad/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Injection<const N: usize> {
    pub position: Vector<N>,
    pub velocity: Vector<N>,
    /// A transforming segment (scale, sign flip, freeze) is in force on some link.
    pub transforming: bool,
    /// A whole-message attack other than `pass` is in force on the path.
    pub message: bool,
}

impl<const N: usize> Injection<N> {
    /// Nothing injected: zero `α` on every link, no transform, no message attack (the tick is
    /// clean, as far as the records say).
    pub fn none() -> Self {
        Self {
            position: Vector::<N>::zeros(),
            velocity: Vector::<N>::zeros(),
            transforming: false,
            message: false,
        }
    }

    /// The attack is in force: the injected value is non-zero on some link of either signal, or
    /// a transforming segment or a message attack is in force. Every rising edge of this is an
    /// attack onset (a pulse train has one per pulse).
    pub fn in_force(&self) -> bool {
        self.transforming
            || self.message
            || self
                .position
                .iter()
                .chain(self.velocity.iter())
                .any(|x| *x != 0.0)
    }
}

/// Injected torque `α_u` at one tick, N·m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueInjection<const N: usize> {
    pub u: Vector<N>,
    /// A transforming segment (scale, sign flip, freeze) is in force on some link.
    pub transforming: bool,
    /// A whole-message attack other than `pass` is in force on the torque path.
    pub message: bool,
}

impl<const N: usize> TorqueInjection<N> {
    /// Nothing injected on the torque: zero `α_u`, no transform, no message attack.
    pub fn none() -> Self {
        Self {
            u: Vector::<N>::zeros(),
            transforming: false,
            message: false,
        }
    }

    /// The attack on the torque path is in force (as [`Injection::in_force`]).
    pub fn in_force(&self) -> bool {
        self.transforming || self.message || self.u.iter().any(|x| *x != 0.0)
    }
}
