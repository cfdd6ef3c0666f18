//! The delayed torque channel: delay profiles `τ(t)` and the [`DelayLine`] of zero-order-held
//! commands, shared by the agent (`u(t − τ(t))` applied to the plant) and by the control center
//! (`u_τ` for the observer, `e_u = ∫_{t−τ}^{t} u ds` for the controller).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::model::Vector;

/// Known time-varying delay of the torque channel (docs/model.md, "Delayed torque channel"), in seconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum DelayProfile {
    /// `τ(t) = amplitude · sin(rate · t) + offset`. Paper: 2 ms · sin(t/2) + 3 ms.
    Sine {
        /// s.
        amplitude_s: f64,
        /// s.
        offset_s: f64,
        /// rad/s.
        rate_rad_s: f64,
    },
    /// `τ(t) = value`.
    Constant {
        /// s.
        value_s: f64,
    },
}

impl DelayProfile {
    /// Whether `other` is this delay to the bit (then `τ(t)` has the same bits at every `t`;
    /// `==` takes −0 for 0).
    pub fn same_bits(&self, other: &Self) -> bool {
        // The kind and its numbers (a constant's padded with zeros: the kinds are compared).
        let numbers = |d: &Self| match *d {
            Self::Sine {
                amplitude_s,
                offset_s,
                rate_rad_s,
            } => (true, [amplitude_s, offset_s, rate_rad_s]),
            Self::Constant { value_s } => (false, [value_s, 0.0, 0.0]),
        };
        let ((sine, a), (other_sine, b)) = (numbers(self), numbers(other));
        sine == other_sine && crate::memo::same_bits(a, b)
    }

    /// `τ(t)` in seconds.
    pub fn tau(&self, t: f64) -> f64 {
        match *self {
            Self::Sine {
                amplitude_s,
                offset_s,
                rate_rad_s,
            } => amplitude_s * (rate_rad_s * t).sin() + offset_s,
            Self::Constant { value_s } => value_s,
        }
    }

    /// Lower bound of `τ` over all `t`.
    pub fn min(&self) -> f64 {
        match *self {
            Self::Sine {
                amplitude_s,
                offset_s,
                ..
            } => offset_s - amplitude_s.abs(),
            Self::Constant { value_s } => value_s,
        }
    }

    /// Upper bound of `τ` over all `t`.
    pub fn max(&self) -> f64 {
        match *self {
            Self::Sine {
                amplitude_s,
                offset_s,
                ..
            } => offset_s + amplitude_s.abs(),
            Self::Constant { value_s } => value_s,
        }
    }

    /// `τ̇(t)`.
    pub fn rate(&self, t: f64) -> f64 {
        match *self {
            Self::Sine {
                amplitude_s,
                rate_rad_s,
                ..
            } => amplitude_s * rate_rad_s * (rate_rad_s * t).cos(),
            Self::Constant { .. } => 0.0,
        }
    }

    /// The instant `c ∈ [a, b]` at which the query `c − τ(c)` reaches `stamp`, given the queries
    /// `qa`, `qb` at `a`, `b` with `qa < stamp < qb`: where the command stamped `stamp` takes
    /// over inside an integration step. `c − τ(c)` increases (`|τ̇| < 1`), so Newton's method
    /// from the linear interpolation converges; at most four iterations, ended early at a fixed point
    /// (where the rest would repeat the same bits), keep it deterministic.
    pub fn takeover_time(&self, stamp: f64, (a, qa): (f64, f64), (b, qb): (f64, f64)) -> f64 {
        let c = match *self {
            Self::Constant { value_s } => stamp + value_s,
            Self::Sine { .. } => {
                let mut c = a + (b - a) * ((stamp - qa) / (qb - qa));
                for _ in 0..4 {
                    let next = c - (c - self.tau(c) - stamp) / (1.0 - self.rate(c));
                    // A fixed point: every further iteration would compute these same bits.
                    let fixed = next.to_bits() == c.to_bits();
                    c = next;
                    if fixed {
                        break;
                    }
                }
                c
            }
        };
        c.clamp(a, b)
    }

    /// Upper bound of `|τ̇|`; Assumption 4 of the paper needs it below 1.
    pub fn max_rate(&self) -> f64 {
        match *self {
            Self::Sine {
                amplitude_s,
                rate_rad_s,
                ..
            } => (amplitude_s * rate_rad_s).abs(),
            Self::Constant { .. } => 0.0,
        }
    }

    /// Every parameter, for validation.
    pub fn parameters(&self) -> Vec<(&'static str, f64)> {
        match *self {
            Self::Sine {
                amplitude_s,
                offset_s,
                rate_rad_s,
            } => {
                vec![
                    ("amplitude_s", amplitude_s),
                    ("offset_s", offset_s),
                    ("rate_rad_s", rate_rad_s),
                ]
            }
            Self::Constant { value_s } => vec![("value_s", value_s)],
        }
    }

    /// Short human-readable form, in ms, as in the paper's Table II.
    pub fn describe_ms(&self) -> String {
        match *self {
            Self::Sine {
                amplitude_s,
                offset_s,
                rate_rad_s,
            } => format!(
                "{} sin({}t) + {}",
                fmt_num(amplitude_s * 1e3),
                fmt_num(rate_rad_s),
                fmt_num(offset_s * 1e3)
            ),
            Self::Constant { value_s } => fmt_num(value_s * 1e3),
        }
    }
}

fn fmt_num(x: f64) -> String {
    let s = format!("{x:.4}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Whether a command stamped `stamp` is in force at query time `t` (the one rule every
/// lookup, prune and lookahead decision uses): `stamp ≤ t`, where `t` may fall short of the
/// stamp by its rounding error. A delay that is a whole number of control periods puts the
/// query `t_k − τ` exactly on a stamp in exact arithmetic; computed in floating point it lands
/// an ulp above or below, and a plain `≤` would pick the older command in some ticks and the
/// newer one in others (an effective delay jittering by a whole period). The allowance,
/// `16 ε · max(|t|, 1 s)`, covers that rounding for delays up to several seconds and is far
/// below any real offset: at `t` = 40 s it is 1.4e-13 s, 1e-10 of a 1 ms period, so a delay of
/// `τ + 1e-7 s` is still told apart from `τ`.
pub fn in_force_at(stamp: f64, t: f64) -> bool {
    stamp <= t + rounding_allowance(t)
}

/// Whether a command stamped `stamp` takes over strictly after the query time `t`, beyond the
/// rounding allowance of [`in_force_at`] on both sides.
fn strictly_after(stamp: f64, t: f64) -> bool {
    stamp > t + rounding_allowance(t)
}

fn rounding_allowance(t: f64) -> f64 {
    16.0 * f64::EPSILON * t.abs().max(1.0)
}

/// Result of looking a command up for time `t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lookup<const N: usize> {
    /// The command in force (zero before the first one).
    pub value: Vector<N>,
    /// Stamp of that command, `None` before the first.
    pub stamp: Option<f64>,
    /// True when a newer command should have been in force but has not arrived: the last
    /// received command is held (a deadline miss: docs/model.md, "Delayed torque channel"). Also true when [`Self::pruned`].
    pub missed: bool,
    /// The query reached before the oldest command kept after pruning: the oldest kept
    /// command is held (never zero) and the lookup counts as a miss.
    pub pruned: bool,
}

/// History of `(t_send, u)` pairs, each command held from its stamp until the next one
/// (zero-order hold). Stamps must increase strictly; older entries are pruned once no query
/// can reach them (queries `t − τ(t)` never go back in time, because `|τ̇| < 1`).
///
/// Pruning keeps one entry more than the query it was given needs, so a later query that
/// lands a rounding error before the pruning instant still finds the command in force. A query
/// that reaches before the oldest kept entry after pruning has no answer in the history: it is
/// never answered with zero, but with the oldest kept command held and flagged
/// ([`Lookup::pruned`], a counted miss), or as an error ([`HistoryPruned`]) by
/// [`Self::integral`].
#[derive(Debug, Clone)]
pub struct DelayLine<const N: usize> {
    entries: VecDeque<(f64, Vector<N>)>,
    /// Some entry was pruned: the history no longer starts at the first command.
    pruned: bool,
    /// Stamps of commands known to be missing ([`Self::push_missing`]), increasing.
    holes: VecDeque<f64>,
}

/// A query of [`DelayLine::integral`] reached before the oldest command kept after pruning.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("query at {query} s reaches before the oldest kept command (stamp {oldest} s): that part of the history was pruned")]
pub struct HistoryPruned {
    pub query: f64,
    pub oldest: f64,
}

impl<const N: usize> Default for DelayLine<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// Why a command was refused by [`DelayLine::push`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PushError {
    #[error(
        "stamp {stamp} s is not after the newest stamp {newest} s (out of order or duplicate)"
    )]
    NotIncreasing { stamp: f64, newest: f64 },
    #[error("stamp or value is not finite")]
    NotFinite,
}

impl<const N: usize> DelayLine<N> {
    pub fn new() -> Self {
        Self {
            entries: VecDeque::with_capacity(256),
            pruned: false,
            holes: VecDeque::new(),
        }
    }

    /// Number of commands kept.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Stamp of the newest command.
    pub fn newest_stamp(&self) -> Option<f64> {
        self.entries.back().map(|e| e.0)
    }

    /// Appends a command sent at `stamp`.
    pub fn push(&mut self, stamp: f64, value: Vector<N>) -> Result<(), PushError> {
        if !stamp.is_finite() || value.iter().any(|v| !v.is_finite()) {
            return Err(PushError::NotFinite);
        }
        if let Some(newest) = self.newest_stamp() {
            if stamp <= newest {
                return Err(PushError::NotIncreasing { stamp, newest });
            }
        }
        self.entries.push_back((stamp, value));
        Ok(())
    }

    /// Notes that the command stamped `stamp` will never come (dropped, refused): the one before
    /// stays in force, and a lookup that should find this one counts a miss. A stamp not after
    /// the newest hole is ignored.
    pub fn push_missing(&mut self, stamp: f64) {
        if stamp.is_finite() && self.holes.back().is_none_or(|h| stamp > *h) {
            self.holes.push_back(stamp);
        }
    }

    /// Some missing command (a hole) stamped after `after` is in force at `t`.
    fn hole_between(&self, after: Option<f64>, t: f64) -> bool {
        self.holes
            .iter()
            .any(|&h| after.is_none_or(|a| h > a) && in_force_at(h, t))
    }

    /// Index of the newest entry with `stamp ≤ t`.
    fn index_at(&self, t: f64) -> Option<usize> {
        let n = self.entries.partition_point(|e| in_force_at(e.0, t));
        n.checked_sub(1)
    }

    /// Like [`Self::lookup`] without the deadline check: the command in force at `t`, zero
    /// before the first one, the oldest kept one held (and flagged) before the pruned horizon.
    pub fn value_at(&self, t: f64) -> Lookup<N> {
        self.lookup(t, f64::INFINITY)
    }

    /// The command in force at `t` — the one with the largest stamp `≤ t`, zero before the
    /// first — and whether a deadline was missed, when commands are expected every `period`
    /// seconds and the one due at `t` has not arrived. The tolerance of 1e-6 periods errs on
    /// the side of "not yet due": a query a hair below the next stamp `k·Δ` (round-off of
    /// `t − τ(t)` when τ ≈ Δ) is not a miss — the agent's lookahead steps exactly then.
    pub fn lookup(&self, t: f64, period: f64) -> Lookup<N> {
        match (self.index_at(t), self.entries.front()) {
            (Some(i), _) => {
                let (stamp, value) = self.entries[i];
                let is_newest = i + 1 == self.entries.len();
                let missed = (is_newest && stamp + period * (1.0 + 1e-6) <= t)
                    || self.hole_between(Some(stamp), t);
                Lookup {
                    value,
                    stamp: Some(stamp),
                    missed,
                    pruned: false,
                }
            }
            (None, Some(&(stamp, value))) if self.pruned => Lookup {
                value,
                stamp: Some(stamp),
                missed: true,
                pruned: true,
            },
            (None, _) => Lookup {
                value: Vector::<N>::zeros(),
                stamp: None,
                missed: self.hole_between(None, t),
                pruned: false,
            },
        }
    }

    /// The oldest command that takes over strictly between the queries `after` and `before`
    /// (beyond the rounding allowance at both ends): where the held input next switches inside
    /// an integration step whose queries span `[after, before]`.
    pub fn next_switch(&self, after: f64, before: f64) -> Option<(f64, Vector<N>)> {
        let first = self
            .entries
            .partition_point(|e| !strictly_after(e.0, after));
        self.entries
            .get(first)
            .filter(|e| e.0 < before - rounding_allowance(before))
            .copied()
    }

    /// `∫_a^b u(s) ds` over the zero-order-held history; zero before the first command, the
    /// newest command extends to `b`. Sums segment by segment in time order. An error when
    /// `a` reaches before the oldest command kept after pruning.
    pub fn integral(&self, a: f64, b: f64) -> Result<Vector<N>, HistoryPruned> {
        let mut acc = Vector::<N>::zeros();
        if b <= a {
            return Ok(acc);
        }
        let start = match (self.index_at(a), self.entries.front()) {
            (Some(i), _) => i,
            (None, Some(&(oldest, _))) if self.pruned => {
                return Err(HistoryPruned { query: a, oldest })
            }
            (None, _) => 0,
        };
        for i in start..self.entries.len() {
            let (s0, value) = self.entries[i];
            let s1 = self.entries.get(i + 1).map_or(f64::INFINITY, |e| e.0);
            let lo = s0.max(a);
            let hi = s1.min(b);
            if hi > lo {
                acc += value * (hi - lo);
            }
            if s1 >= b {
                break;
            }
        }
        Ok(acc)
    }

    /// Drops every entry that no query at or after `t` can reach. Keeps the one in force at
    /// `t` and, as a margin against round-off in the caller's next query, the one before it.
    pub fn prune_before(&mut self, t: f64) {
        while self.entries.len() >= 3 && self.entries[2].0 <= t {
            self.entries.pop_front();
            self.pruned = true;
        }
        if let Some(&(oldest, _)) = self.entries.front().filter(|_| self.pruned) {
            while self.holes.front().is_some_and(|h| *h <= oldest) {
                self.holes.pop_front();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    fn v(x: f64) -> Vector<2> {
        Vector::<2>::new(x, -2.0 * x)
    }

    /// Delays the same to the bit give `τ`'s bits at every instant; `==` is not that (−0 is 0).
    #[test]
    fn the_same_delay_to_the_bit_and_only_that() {
        let sine = |offset_s: f64| DelayProfile::Sine {
            amplitude_s: 0.002,
            offset_s,
            rate_rad_s: 0.5,
        };
        let constant = |value_s: f64| DelayProfile::Constant { value_s };
        assert!(sine(0.003).same_bits(&sine(0.003)) && constant(0.01).same_bits(&constant(0.01)));
        assert!(!sine(0.003).same_bits(&sine(0.0031)) && !sine(0.0).same_bits(&constant(0.0)));
        assert!(constant(0.0) == constant(-0.0) && !constant(0.0).same_bits(&constant(-0.0)));
        assert!(sine(0.0) == sine(-0.0) && !sine(0.0).same_bits(&sine(-0.0)));
        assert_ne!(
            constant(0.0).tau(1.0).to_bits(),
            constant(-0.0).tau(1.0).to_bits()
        );
    }

    fn line(n: usize, dt: f64) -> DelayLine<2> {
        let mut d = DelayLine::new();
        for k in 0..n {
            d.push(k as f64 * dt, v(k as f64 + 1.0))
                .expect("increasing stamps");
        }
        d
    }

    #[test]
    fn lookup_is_exact_at_and_between_stamps_and_zero_before_the_first() {
        let d = line(10, 0.001);
        assert_eq!(d.value_at(-1e-9).value, Vector::<2>::zeros());
        for k in 0..10 {
            let t = k as f64 * 0.001;
            assert_eq!(d.value_at(t).value, v(k as f64 + 1.0), "at stamp {k}");
            assert_eq!(
                d.value_at(t + 0.0004).value,
                v(k as f64 + 1.0),
                "between {k} and {}",
                k + 1
            );
        }
    }

    #[test]
    fn lookup_with_time_varying_delay_picks_the_newest_due_command() {
        let dt = 0.001;
        let d = line(100, dt);
        let tau = DelayProfile::Sine {
            amplitude_s: 0.002,
            offset_s: 0.003,
            rate_rad_s: 0.5 * 1000.0,
        };
        for i in 10..100 {
            let t = i as f64 * dt + 0.0003;
            let q = t - tau.tau(t);
            let k = (q / dt).floor() as usize;
            assert_eq!(
                d.value_at(q).value,
                v(k as f64 + 1.0),
                "t = {t}, t − τ = {q}"
            );
        }
    }

    #[test]
    fn deadline_miss_only_when_a_newer_command_is_overdue() {
        let d = line(5, 0.001); // stamps 0 .. 4 ms
        assert!(!d.lookup(0.0045, 0.001).missed);
        assert!(d.lookup(0.0051, 0.001).missed);
        assert!(!d.lookup(0.0021, 0.001).missed);
        assert!(!DelayLine::<2>::new().lookup(1.0, 0.001).missed);
    }

    #[test]
    fn integral_matches_the_analytic_value_for_a_known_input() {
        // u(t) = t held on a 1 ms grid: ∫_a^b u = Σ k·Δ over whole cells + partial cells.
        let dt = 0.001;
        let mut d = DelayLine::<2>::new();
        for k in 0..1000 {
            let t = k as f64 * dt;
            d.push(t, Vector::<2>::new(t, 1.0)).expect("increasing");
        }
        let (a, b) = (0.1234, 0.5678);
        // Analytic integral of the staircase floor(s/Δ)·Δ.
        let stair = |x: f64| {
            let n = (x / dt).floor();
            dt * dt * n * (n - 1.0) / 2.0 + n * dt * (x - n * dt)
        };
        let got = d.integral(a, b).expect("nothing pruned");
        // Summation of ~440 terms of size 1e-4: round-off well below 1e-12.
        assert_relative_eq!(got[0], stair(b) - stair(a), epsilon = 1e-12);
        assert_relative_eq!(got[1], b - a, epsilon = 1e-12);
        // Before the first command the integrand is zero.
        let mut late = DelayLine::<2>::new();
        late.push(1.0, Vector::<2>::new(2.0, 2.0)).expect("first");
        assert_relative_eq!(
            late.integral(0.5, 1.5).expect("nothing pruned")[0],
            1.0,
            epsilon = 1e-15
        );
        assert_eq!(late.integral(0.2, 0.9), Ok(Vector::<2>::zeros()));
    }

    #[test]
    fn refuses_out_of_order_duplicate_and_non_finite_commands() {
        let mut d = line(3, 0.001);
        assert!(matches!(
            d.push(0.001, v(1.0)),
            Err(PushError::NotIncreasing { .. })
        ));
        assert!(matches!(
            d.push(0.002, v(1.0)),
            Err(PushError::NotIncreasing { .. })
        ));
        assert_eq!(d.push(0.005, v(f64::NAN)), Err(PushError::NotFinite));
        assert_eq!(d.len(), 3);
    }

    #[test]
    fn pruning_keeps_the_command_in_force() {
        let mut d = line(100, 0.001);
        d.prune_before(0.0505);
        assert_eq!(d.value_at(0.0505).value, v(51.0));
        // The command in force (stamp 50 ms) and one more before it (49 ms) are kept.
        assert_eq!(d.len(), 51);
        assert_relative_eq!(
            d.integral(0.0505, 0.0515).expect("in the kept history")[0],
            0.5e-3 * 51.0 + 0.5e-3 * 52.0,
            epsilon = 1e-15
        );
    }

    /// Regression: pruning at `(t_k + Δ) − τ` and querying at `tick_time(k + 1) − τ` — one ulp
    /// smaller when τ is a multiple of Δ — found no command and applied zero torque.
    #[test]
    fn a_query_just_before_the_pruning_instant_still_finds_the_command_in_force() {
        let dt = 0.001;
        let mut d = line(100, dt);
        let at = 50.0 * dt; // exactly a stamp
        d.prune_before(at);
        // One ulp short of a stamp is the rounding of `t − τ`: the stamp is reached.
        let one_ulp_short = f64::from_bits(at.to_bits() - 1);
        let l = d.lookup(one_ulp_short, dt);
        assert_eq!(l.value, v(51.0), "the command stamped 50 ms is in force");
        assert!(!l.pruned && !l.missed);
        // Really before the stamp: the command before it, still kept.
        let before = at - 1e-9;
        let l = d.lookup(before, dt);
        assert_eq!(l.value, v(50.0), "the command stamped 49 ms is in force");
        assert!(!l.pruned && !l.missed);
        assert!(d.integral(before, at).is_ok());
    }

    #[test]
    fn a_query_on_a_stamp_picks_that_command_whichever_way_the_query_rounded() {
        let dt = 0.001;
        let d = line(10_000, dt);
        for k in 10..10_000u64 {
            for m in 1..7u64 {
                // The rounding of t_k − τ for τ = m·Δ, against the stamp of command k − m.
                let q = k as f64 * dt - m as f64 * dt;
                let want = v((k - m) as f64 + 1.0);
                assert_eq!(d.value_at(q).value, want, "k {k}, τ = {m} Δ");
            }
        }
    }

    #[test]
    fn a_query_before_the_kept_history_holds_the_oldest_command_and_counts_a_miss() {
        let dt = 0.001;
        let mut d = line(100, dt);
        d.prune_before(0.0505);
        let l = d.lookup(0.0300, dt);
        assert!(l.pruned && l.missed, "{l:?}");
        assert_eq!(l.value, v(50.0), "the oldest kept command, never zero");
        assert_eq!(
            d.integral(0.0300, 0.0505),
            Err(HistoryPruned {
                query: 0.0300,
                oldest: 0.049
            })
        );
        // Before any pruning, a query before the first command is zero and no miss.
        let fresh = line(3, dt);
        let l = fresh.lookup(-0.5, dt);
        assert_eq!(l.value, Vector::<2>::zeros());
        assert!(!l.pruned && !l.missed);
    }

    #[test]
    fn delay_bounds_and_description() {
        let p = DelayProfile::Sine {
            amplitude_s: 0.02,
            offset_s: 0.03,
            rate_rad_s: 0.05,
        };
        assert_relative_eq!(p.min(), 0.01);
        assert_relative_eq!(p.max(), 0.05);
        assert_relative_eq!(p.max_rate(), 0.001);
        assert_eq!(p.describe_ms(), "20 sin(0.05t) + 30");
    }

    /// Commands `v(k + 1)` stamped `k·Δ` for `k < n` except the `missing` ones, each of which
    /// is a hole when `holes` (the line as the plant builds it) and simply absent otherwise.
    fn line_without(n: usize, dt: f64, missing: &[bool], holes: bool) -> DelayLine<2> {
        let mut d = DelayLine::new();
        for k in 0..n {
            let stamp = k as f64 * dt;
            if missing.get(k).copied().unwrap_or(false) {
                if holes {
                    d.push_missing(stamp);
                }
            } else {
                d.push(stamp, v(k as f64 + 1.0)).expect("increasing stamps");
            }
        }
        d
    }

    fn mask(n: usize, missing: &[usize]) -> Vec<bool> {
        (0..n).map(|k| missing.contains(&k)).collect()
    }

    #[test]
    fn a_hole_is_a_miss_only_where_the_missing_command_would_be_in_force() {
        let dt = 0.001;
        let n = 20;
        let missing = mask(n, &[5, 12, 13]);
        let with = line_without(n, dt, &missing, true);
        let without = line_without(n, dt, &missing, false);
        for i in -5..215i32 {
            let t = f64::from(i) * 1e-4;
            for q in [t, f64::from_bits(t.to_bits().wrapping_sub(1))] {
                let (a, b) = (with.lookup(q, dt), without.lookup(q, dt));
                assert_eq!(
                    (a.value, a.stamp, a.pruned),
                    (b.value, b.stamp, b.pruned),
                    "{q}"
                );
                let in_hole = (in_force_at(5.0 * dt, q) && !in_force_at(6.0 * dt, q))
                    || (in_force_at(12.0 * dt, q) && !in_force_at(14.0 * dt, q));
                assert_eq!(a.missed, b.missed || in_hole, "query {q}");
                if in_hole {
                    assert!(a.missed, "query {q}");
                }
            }
        }
        // Where the command stamped 5 Δ should be in force, the one before it is held.
        let l = with.lookup(5.5 * dt, dt);
        assert_eq!((l.value, l.stamp, l.missed), (v(5.0), Some(4.0 * dt), true));
        let l = with.lookup(6.0 * dt, dt);
        assert_eq!((l.value, l.missed), (v(7.0), false));
        assert!(!with.lookup(4.9 * dt, dt).missed);
        // Two holes in a row: the command stamped 11 Δ is held over both.
        let l = with.lookup(13.9 * dt, dt);
        assert_eq!((l.value, l.missed), (v(12.0), true));
        assert!(!without.lookup(13.9 * dt, dt).missed);
    }

    #[test]
    fn a_hole_does_not_change_switches_or_integrals() {
        let dt = 0.001;
        let n = 20;
        let missing = mask(n, &[0, 5, 12, 13, 19]);
        let with = line_without(n, dt, &missing, true);
        let without = line_without(n, dt, &missing, false);
        for i in -3..230i32 {
            for j in i..i + 40 {
                let (a, b) = (f64::from(i) * 1e-4, f64::from(j) * 1e-4);
                assert_eq!(
                    with.next_switch(a, b),
                    without.next_switch(a, b),
                    "{a} .. {b}"
                );
                assert_eq!(with.integral(a, b), without.integral(a, b), "{a} .. {b}");
            }
        }
    }

    #[test]
    fn holes_before_the_first_and_after_the_newest_command() {
        let dt = 0.001;
        // The first command never came: zero until the second one, and a miss meanwhile.
        let first = line_without(5, dt, &mask(5, &[0]), true);
        let l = first.lookup(0.5 * dt, dt);
        assert_eq!(
            (l.value, l.stamp, l.missed),
            (Vector::<2>::zeros(), None, true)
        );
        assert!(!first.lookup(-0.5 * dt, dt).missed, "not yet due");
        assert!(
            !line_without(5, dt, &mask(5, &[0]), false)
                .lookup(0.5 * dt, dt)
                .missed
        );
        // The newest command never came: a miss even without a deadline (`value_at`).
        let last = line_without(10, dt, &mask(10, &[9]), true);
        let l = last.value_at(9.5 * dt);
        assert_eq!((l.value, l.missed), (v(9.0), true));
        assert!(!last.value_at(8.5 * dt).missed);
        assert!(
            !line_without(10, dt, &mask(10, &[9]), false)
                .value_at(9.5 * dt)
                .missed
        );
    }

    #[test]
    fn holes_that_do_not_increase_or_are_not_finite_are_ignored() {
        let mut d = line(3, 0.001);
        d.push_missing(0.005);
        d.push_missing(0.004);
        d.push_missing(0.005);
        d.push_missing(f64::NAN);
        d.push_missing(f64::INFINITY);
        assert_eq!(d.holes, [0.005]);
        assert_eq!(d.len(), 3, "a hole is not a command");
    }

    #[test]
    fn holes_are_pruned_with_the_entries() {
        let dt = 0.001;
        let n = 20;
        let missing = mask(n, &[5, 12]);
        let mut d = line_without(n, dt, &missing, true);
        let before: Vec<_> = (135..200)
            .map(|i| d.lookup(f64::from(i) * 1e-4, dt))
            .collect();
        d.prune_before(13.5 * dt);
        // Kept: the command in force (13 Δ) and the one before it (11 Δ; 12 Δ is missing).
        assert_eq!(d.entries.front().map(|e| e.0), Some(11.0 * dt));
        assert_eq!(
            d.holes,
            [12.0 * dt],
            "the hole at 5 Δ went with its entries"
        );
        let after: Vec<_> = (135..200)
            .map(|i| d.lookup(f64::from(i) * 1e-4, dt))
            .collect();
        assert_eq!(before, after);
        // The kept hole still counts in the kept history.
        assert!(d.lookup(12.5 * dt, dt).missed);
        // Pruning past every entry but two drops every hole at or before the oldest kept one.
        d.prune_before(30.0 * dt);
        assert_eq!(d.entries.front().map(|e| e.0), Some(18.0 * dt));
        assert!(d.holes.is_empty());
    }

    proptest! {
        /// For any pattern of missing commands: the line with holes answers every query as the
        /// line without them (value, stamp, switches, integrals), with a miss added exactly where
        /// the full line would have a missing command in force; after any pruning, queries at or
        /// after the pruning instant are answered as before and no hole is left at or before the
        /// oldest kept entry.
        #[test]
        fn holes_only_add_misses_where_a_missing_command_is_due(
            missing in prop::collection::vec(prop::bool::weighted(0.3), 2..60),
            queries in prop::collection::vec(-30i32..650, 1..40),
            prune_at in 0i32..650,
        ) {
            let dt = 0.001;
            let n = missing.len();
            let full = line(n, dt);
            let mut with = line_without(n, dt, &missing, true);
            let mut without = line_without(n, dt, &missing, false);
            let is_missing = |stamp: Option<f64>| {
                stamp.is_some_and(|s| missing[(s / dt).round() as usize])
            };
            let at = |i: i32| f64::from(i) * 1e-4;
            for &i in &queries {
                // Anywhere, an ulp short of that, and exactly on a stamp `k·Δ`.
                let on_stamp = f64::from(i.div_euclid(10)) * dt;
                for q in [at(i), f64::from_bits(at(i).to_bits().wrapping_sub(1)), on_stamp] {
                    let (a, b) = (with.lookup(q, dt), without.lookup(q, dt));
                    prop_assert_eq!((a.value, a.stamp, a.pruned), (b.value, b.stamp, b.pruned));
                    let due = is_missing(full.value_at(q).stamp);
                    prop_assert_eq!(a.missed, b.missed || due, "query {}", q);
                    prop_assert_eq!(with.value_at(q).missed, due, "query {}", q);
                    for &j in &queries {
                        prop_assert_eq!(with.next_switch(q, at(j)), without.next_switch(q, at(j)));
                        prop_assert_eq!(with.integral(q, at(j)), without.integral(q, at(j)));
                    }
                }
            }
            let p = at(prune_at);
            let later: Vec<f64> = queries.iter().map(|&i| p + at(i.abs())).collect();
            let before: Vec<_> = later.iter().map(|&q| with.lookup(q, dt)).collect();
            with.prune_before(p);
            without.prune_before(p);
            let after: Vec<_> = later.iter().map(|&q| with.lookup(q, dt)).collect();
            prop_assert_eq!(before, after);
            prop_assert_eq!(with.len(), without.len());
            if with.pruned {
                let oldest = with.entries.front().map_or(f64::INFINITY, |e| e.0);
                prop_assert!(with.holes.iter().all(|h| *h > oldest), "{:?} vs {}", with.holes, oldest);
            }
        }
    }
}
