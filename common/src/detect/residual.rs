//! The residual of one tick, from the joined records the control center's data make up: the
//! tampered measurement it received (`AttackRecord::y`, `yd`) and its observer's state.
//!
//! **Which observer state.** `CenterRecord::q_hat`, `qd_hat` are the observer's state *after*
//! the tick's Euler step (`q̂̇ += Δ q̂̈`, then `q̂ += Δ q̂̇`): the record of tick `k − 1` already
//! holds the observer's estimate at `t_k`, the prediction `q̂_k⁻` of the measurement of tick `k`,
//! and the very state the observer compares it with (its `Ψ2`). Adding `Δ · q̂̇` and `Δ · q̂̈` to
//! it, as a one-step prediction from "the previous state" would, predicts `t_{k+1}` instead: one
//! period ahead of the measurement, an error of `Δ q̇` (up to 1.3e-3 rad on the paper's
//! trajectories, 13 sensor standard deviations). So the prediction is the previous record's
//! state itself.

use nalgebra::DVector;

use crate::records::{CenterRecord, TickRecord};

use super::config::ResidualKind;

/// Why no residual could be formed for a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Missing {
    /// No record of the tick before (the first tick, or a gap: the center computed nothing
    /// for the previous tick, or the records came out of order).
    NoPrevious,
    /// A record does not hold `links` entries.
    Length,
}

/// The residual of `cur` against the observer state of `prev` (the record of the tick before,
/// of the same agent), or why there is none. `beta`: the controller's β (for `Ψ2`).
pub fn residual(
    kind: ResidualKind,
    links: usize,
    beta: f64,
    prev: Option<&CenterRecord>,
    cur: &TickRecord,
) -> Result<DVector<f64>, Missing> {
    let mut out = DVector::zeros(kind.dimension(links));
    residual_into(kind, links, beta, prev, cur, &mut out).map(|()| out)
}

/// [`residual`] written into `out` (resized to the residual's dimension when it is not): what
/// the detectors use every tick without allocating. `out` is left as it was when there is none.
pub fn residual_into(
    kind: ResidualKind,
    links: usize,
    beta: f64,
    prev: Option<&CenterRecord>,
    cur: &TickRecord,
    out: &mut DVector<f64>,
) -> Result<(), Missing> {
    let prev = prev
        .filter(|p| p.agent == cur.center.agent && p.k.checked_add(1) == Some(cur.center.k))
        .ok_or(Missing::NoPrevious)?;
    let (y, yd) = (cur.attack.y.as_slice(), cur.attack.yd.as_slice());
    let (q, qd) = (prev.q_hat.as_slice(), prev.qd_hat.as_slice());
    let s_hat = cur.center.s_hat.as_slice();
    if [y, yd, q, qd, s_hat].iter().any(|v| v.len() != links) {
        return Err(Missing::Length);
    }
    let dim = kind.dimension(links);
    if out.len() != dim {
        *out = DVector::zeros(dim);
    }
    for i in 0..links {
        match kind {
            ResidualKind::Innovation => {
                out[i] = y[i] - q[i];
                out[links + i] = yd[i] - qd[i];
            }
            ResidualKind::Psi2 => {
                out[i] = yd[i] + y[i] * beta - qd[i] - q[i] * beta - s_hat[i];
            }
        }
    }
    Ok(())
}
