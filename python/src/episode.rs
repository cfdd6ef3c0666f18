//! An episode of the environments: the in-process engine ([`fdi_common::engine::Lockstep`]),
//! ticked a decision period at a time, with an attacker that adds the learning agent's
//! injection to the scenario's own attack profile. Pure Rust: the Python classes wrap it.

use fdi_common::attack::{Attacker, Injection, ProfileAttacker, Sent, TorqueInjection};
use fdi_common::engine::{Lockstep, RunSummary};
use fdi_common::model::Vector;
use fdi_common::plant::Measurement;
use fdi_common::records::TickRecord;
use fdi_common::scenario::Resolved;

/// The channels an action injects into, in the order of an action's middle axis.
pub const CHANNELS: [&str; 3] = ["position", "velocity", "torque"];
/// Index of the torque channel in [`CHANNELS`].
const TORQUE: usize = 2;
/// The defence's channel: a correction added to the torque each chosen robot's controller
/// commands, at the control center (before the torque path), after the attack channels of an
/// action.
pub const CORRECTION: &str = "correction";

/// What the learning agent acts on and how an episode is scored.
#[derive(Debug, Clone, PartialEq)]
pub struct Spec {
    /// The robots (ids) an action injects into, in the action's order.
    pub robots: Vec<u32>,
    /// The channels (indexes into [`CHANNELS`]) an action injects into, in its order.
    pub channels: Vec<usize>,
    /// The largest injection per channel of [`CHANNELS`]: rad, rad/s, N·m. An action of 1
    /// injects the budget.
    pub budget: [f64; 3],
    /// The detectors (indexes into `fdi_common::detect::names()`) whose alarms are counted.
    pub detectors: Vec<usize>,
    /// Ticks per step.
    pub decision_period: u64,
    /// The largest torque correction (N·m) of the [`CORRECTION`] channel, when an action has it.
    pub correction: Option<f64>,
}

/// The attacker of an episode: the scenario's attack profile, plus the action's injection on
/// the chosen robots and channels (added to what the profile delivers, and recorded as
/// injected).
#[derive(Debug)]
pub struct EnvAttacker {
    base: ProfileAttacker,
    name: String,
    /// Entries per channel of an injection: the team's largest joint count (a robot of fewer
    /// joints takes the first of them).
    links: usize,
    /// Per chosen robot: its id and its injection, `[position…, velocity…, torque…]`
    /// (`3 × links` entries, in rad, rad/s, N·m).
    injections: Vec<(u32, Vec<f64>)>,
    /// The action injects into torques.
    torque: bool,
}

impl EnvAttacker {
    fn new(resolved: &Resolved, spec: &Spec, links: usize) -> Self {
        let base = resolved.profile_attacker();
        let name = if spec.robots.is_empty() || spec.channels.is_empty() {
            base.name().to_owned()
        } else {
            format!("{} + the environment's actions", base.name())
        };
        Self {
            base,
            name,
            links,
            injections: spec
                .robots
                .iter()
                .map(|id| (*id, vec![0.0; 3 * links]))
                .collect(),
            torque: spec.channels.contains(&TORQUE),
        }
    }

    fn injection(&self, agent: u32) -> Option<&[f64]> {
        self.injections
            .iter()
            .find(|(id, _)| *id == agent)
            .map(|(_, v)| v.as_slice())
    }
}

/// Adds `add` to the delivered payload's entries and to the recorded `alpha`, where non-zero
/// (a zero adds nothing, not even a change of a zero's sign: an action of zeros leaves the run
/// bit for bit as the profile's).
fn add<const N: usize>(payload: &mut Vector<N>, alpha: &mut Vector<N>, add: &[f64]) {
    for (i, a) in add.iter().enumerate().take(N) {
        if *a != 0.0 {
            payload[i] += *a;
            alpha[i] += *a;
        }
    }
}

impl Attacker for EnvAttacker {
    fn name(&self) -> &str {
        &self.name
    }

    fn measurement<const N: usize>(
        &mut self,
        agent: u32,
        k: u64,
        t: f64,
        clean: &Measurement<N>,
    ) -> (Sent<Measurement<N>>, Injection<N>) {
        let (mut sent, mut inj) = self.base.measurement::<N>(agent, k, t, clean);
        let l = self.links;
        if let (Some(a), Sent::Delivered { payload, .. }) = (self.injection(agent), &mut sent) {
            add(&mut payload.y, &mut inj.position, &a[..l]);
            add(&mut payload.yd, &mut inj.velocity, &a[l..2 * l]);
        }
        (sent, inj)
    }

    fn on_torque_path(&self, agent: u32) -> bool {
        self.base.on_torque_path(agent) || (self.torque && self.injection(agent).is_some())
    }

    fn torque<const N: usize>(
        &mut self,
        agent: u32,
        k: u64,
        t: f64,
        u: &Vector<N>,
    ) -> (Sent<Vector<N>>, TorqueInjection<N>) {
        let (mut sent, mut inj) = if self.base.on_torque_path(agent) {
            self.base.torque::<N>(agent, k, t, u)
        } else {
            (Sent::on_time(*u), TorqueInjection::none())
        };
        let l = self.links;
        if let (true, Some(a), Sent::Delivered { payload, .. }) =
            (self.torque, self.injection(agent), &mut sent)
        {
            add(payload, &mut inj.u, &a[2 * l..3 * l]);
        }
        (sent, inj)
    }
}

/// What one step did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outcome {
    /// Ticks run.
    pub ticks: u64,
    /// Σ over the ticks of the mean tracking error `‖q_d − q‖` (rad) of the chosen robots.
    pub damage: f64,
    /// Ticks at whose end some chosen detector of some robot was alarming.
    pub alarm_ticks: u64,
    /// Per robot (scenario order): ticks with an attack in force on it (the ground truth).
    pub attacked: Vec<u64>,
    /// A robot diverged (its state left the bound or became non-finite).
    pub terminated: bool,
    /// The scenario's horizon was reached.
    pub truncated: bool,
}

/// The attacker's reward of a step (docs/python.md, "Rewards"): both terms are per tick, so
/// that a step's reward does not grow with its length, and each is of order one:
///
/// `damage_weight · (mean error / damage_scale_rad − 1) − stealth_weight · alarmed share`
///
/// where the mean error is the step's mean over its ticks of `‖q_d − q‖` averaged over the
/// chosen robots (rad) and `damage_scale_rad` the same mean over the whole attack-free run: a
/// step at twice the run's mean error scores 1. The scale is the run's mean, not the
/// attack-free error at the step's time: an attack-free step scores above 0 in the start-up
/// transient and below it later, and only a whole attack-free episode of equal steps returns 0.
/// The alarmed share is the step's
/// ticks at whose end a chosen detector alarmed, over its ticks (0 to 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttackerReward {
    pub damage_weight: f64,
    pub stealth_weight: f64,
    /// The attack-free run's mean tracking error (rad), > 0.
    pub damage_scale_rad: f64,
}

impl AttackerReward {
    /// The weights and scale, each checked: finite, and a scale above zero.
    pub fn new(
        damage_weight: f64,
        stealth_weight: f64,
        damage_scale_rad: f64,
    ) -> Result<Self, String> {
        if !(damage_weight.is_finite() && stealth_weight.is_finite()) {
            return Err(format!(
                "damage_weight and stealth_weight must be finite, got {damage_weight} and {stealth_weight}"
            ));
        }
        if !(damage_scale_rad.is_finite() && damage_scale_rad > 0.0) {
            return Err(format!(
                "damage_scale must be a finite error above 0 rad, got {damage_scale_rad}"
            ));
        }
        Ok(Self {
            damage_weight,
            stealth_weight,
            damage_scale_rad,
        })
    }

    /// The reward of a step that gave `o`; 0 for a step of no tick (a reset).
    pub fn of(&self, o: &Outcome) -> f64 {
        if o.ticks == 0 {
            return 0.0;
        }
        let n = o.ticks as f64;
        self.damage_weight * (o.damage / n / self.damage_scale_rad - 1.0)
            - self.stealth_weight * o.alarm_ticks as f64 / n
    }
}

/// The tracking term of a defence's step in which a robot diverged (its error is not a
/// number): the ratio the scored benchmark counts for a diverged robot (docs/score.md).
pub const DIVERGED_RATIO: f64 = 100.0;

/// The defence's reward of a step (docs/python.md, "Rewards"):
///
/// `− e / error_scale_rad − effort_weight · mean(action²)`
///
/// where `e` is the step's mean over its ticks of `‖q_d − q‖` averaged over the robots (rad)
/// and `error_scale_rad` the same mean over the whole attack-free run; `−DIVERGED_RATIO` for a
/// step in which a robot diverged; 0 for a step of no tick (a reset).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DefenderReward {
    pub error_scale_rad: f64,
    pub effort_weight: f64,
}

impl DefenderReward {
    /// The scale and weight, each checked: a finite scale above 0, a finite weight ≥ 0.
    pub fn new(error_scale_rad: f64, effort_weight: f64) -> Result<Self, String> {
        if !(error_scale_rad.is_finite() && error_scale_rad > 0.0) {
            return Err(format!(
                "error_scale must be a finite error above 0 rad, got {error_scale_rad}"
            ));
        }
        if !(effort_weight.is_finite() && effort_weight >= 0.0) {
            return Err(format!(
                "effort_weight must be finite and ≥ 0, got {effort_weight}"
            ));
        }
        Ok(Self {
            error_scale_rad,
            effort_weight,
        })
    }

    /// The reward of a step that gave `o` under `action` (its entries in [−1, 1]).
    pub fn of(&self, o: &Outcome, action: &[f64]) -> f64 {
        if o.ticks == 0 {
            return 0.0;
        }
        let e = o.damage / o.ticks as f64;
        if !e.is_finite() {
            return -DIVERGED_RATIO;
        }
        let effort = if action.is_empty() {
            0.0
        } else {
            action.iter().map(|a| a * a).sum::<f64>() / action.len() as f64
        };
        -e / self.error_scale_rad - self.effort_weight * effort
    }
}

/// The latest values each observer has seen, per robot in the scenario's order, each with its
/// own number of joints.
#[derive(Debug, Clone)]
struct Seen {
    t: f64,
    /// The attacker's view: per robot the clean `y`, `ẏ`, and the center's command `u` where
    /// the attacker sits on the torque path (zeros elsewhere): `3 × joints`.
    attacker: Vec<f64>,
    /// The control center's view: per robot the received `y`, `ẏ`, `Ŝ`, and the observer's
    /// residuals `y − q̂`, `ẏ − q̂̇`: `5 × joints`.
    center: Vec<f64>,
    /// Per robot: where its entries start in `attacker` and in `center` (its `3 ×` and
    /// `5 × joints` entries follow), and its joints.
    at: Vec<(usize, usize, usize)>,
}

impl Seen {
    /// Nothing seen yet, of robots with `joints` each.
    fn new(joints: &[usize]) -> Self {
        let mut at = Vec::with_capacity(joints.len());
        let (mut a, mut c) = (0, 0);
        for &l in joints {
            at.push((a, c, l));
            a += 3 * l;
            c += 5 * l;
        }
        Self {
            t: 0.0,
            attacker: vec![0.0; a],
            center: vec![0.0; c],
            at,
        }
    }
}

/// An episode of a scenario.
#[derive(Debug)]
pub struct Episode {
    resolved: Resolved,
    spec: Spec,
    /// The action's entries per robot and channel: the team's largest joint count.
    links: usize,
    /// Each robot's joints, in the scenario's order.
    joints: Vec<usize>,
    /// Per entry of an action: whether it acts ([`Self::action_mask`]).
    mask: Vec<bool>,
    agents: Vec<u32>,
    engine: Option<Lockstep>,
    attacker: EnvAttacker,
    seen: Seen,
    summary: Option<RunSummary>,
}

/// Whether the spec's robots are robots of the scenario and its channels and detectors exist.
fn check(resolved: &Resolved, spec: &Spec) -> Result<(), String> {
    let agents: Vec<u32> = resolved.scenario.agents.iter().map(|a| a.id).collect();
    if let Some(r) = spec.robots.iter().find(|r| !agents.contains(r)) {
        return Err(format!(
            "robots: {r} is not a robot of the scenario (its robots are {agents:?})"
        ));
    }
    if spec.channels.iter().any(|c| *c >= CHANNELS.len()) {
        return Err(format!("channels: the channels are {CHANNELS:?}"));
    }
    let names = fdi_common::detect::names();
    if spec.detectors.iter().any(|d| *d >= names.len()) {
        return Err(format!("detectors: the detectors are {names:?}"));
    }
    if let Some(b) = spec.budget.iter().find(|b| !(b.is_finite() && **b >= 0.0)) {
        return Err(format!(
            "budget: every channel's budget must be finite and ≥ 0, got {b}"
        ));
    }
    if spec.decision_period == 0 {
        return Err("decision_period: at least 1 tick".into());
    }
    if let Some(b) = spec.correction.filter(|b| !(b.is_finite() && *b >= 0.0)) {
        return Err(format!(
            "correction_budget: must be finite and ≥ 0 N·m, got {b}"
        ));
    }
    Ok(())
}

impl Episode {
    /// An episode of `resolved` at its start.
    pub fn new(resolved: Resolved, spec: Spec) -> Result<Self, String> {
        check(&resolved, &spec)?;
        let engine = Lockstep::new(&resolved).map_err(|e| e.to_string())?;
        // A team may mix robots: each view has each robot's own joints, an action the largest
        // count's entries per robot and channel (a robot of fewer joints ignores the rest).
        let joints: Vec<usize> = resolved
            .scenario
            .agents
            .iter()
            .map(|a| a.model.dof())
            .collect();
        let links = joints.iter().copied().max().unwrap_or(0);
        let agents: Vec<u32> = resolved.scenario.agents.iter().map(|a| a.id).collect();
        let attacker = EnvAttacker::new(&resolved, &spec, links);
        // Per chosen robot (`check` made sure each is the scenario's), each channel: its
        // joints act, the rest of the team's largest count does not.
        let channels = spec.channels.len() + usize::from(spec.correction.is_some());
        let mut mask = Vec::with_capacity(spec.robots.len() * channels * links);
        for id in &spec.robots {
            let n = agents.iter().position(|a| a == id).map_or(0, |i| joints[i]);
            for _ in 0..channels {
                mask.extend((0..links).map(|j| j < n));
            }
        }
        Ok(Self {
            seen: Seen::new(&joints),
            resolved,
            spec,
            links,
            joints,
            mask,
            agents,
            engine: Some(engine),
            attacker,
            summary: None,
        })
    }

    /// The episode again from its start, of `resolved` when given (same robots and links).
    pub fn reset(&mut self, resolved: Option<Resolved>) -> Result<(), String> {
        let resolved = resolved.unwrap_or_else(|| self.resolved.clone());
        let fresh = Self::new(resolved, self.spec.clone())?;
        if fresh.agents != self.agents || fresh.joints != self.joints {
            return Err(format!(
                "the new scenario's robots ({:?}, joints {:?}) are not the episode's ({:?}, joints \
                 {:?})",
                fresh.agents, fresh.joints, self.agents, self.joints
            ));
        }
        *self = fresh;
        Ok(())
    }

    /// The action's entries per robot and channel: the team's largest joint count.
    pub fn links(&self) -> usize {
        self.links
    }

    /// Each robot's joints, in the scenario's order (its entries in each view).
    pub fn joints(&self) -> &[usize] {
        &self.joints
    }

    /// Per entry of an action (robots × channels × links): whether it acts, that is whether
    /// its link is a joint of its robot (a robot of fewer joints than the team's largest
    /// ignores the rest).
    pub fn action_mask(&self) -> &[bool] {
        &self.mask
    }

    /// The entries of `action` that act ([`Self::action_mask`]), in order.
    pub fn acting(&self, action: &[f64]) -> Vec<f64> {
        action
            .iter()
            .zip(&self.mask)
            .filter_map(|(a, acts)| acts.then_some(*a))
            .collect()
    }

    pub fn agents(&self) -> &[u32] {
        &self.agents
    }

    /// Channels of an action: the attack's, and the correction when the spec has it.
    fn action_channels(&self) -> usize {
        self.spec.channels.len() + usize::from(self.spec.correction.is_some())
    }

    /// Entries of an action: robots × channels (the correction last) × links.
    pub fn action_size(&self) -> usize {
        self.spec.robots.len() * self.action_channels() * self.links
    }

    /// The next tick to run, and the ticks of the horizon.
    pub fn progress(&self) -> (u64, u64) {
        match &self.engine {
            Some(e) => (e.k(), e.ticks()),
            None => {
                let t = self.resolved.ticks();
                (self.summary.as_ref().map_or(t, |s| s.ticks), t)
            }
        }
    }

    /// The summary of the episode, once it ended.
    pub fn summary(&self) -> Option<&RunSummary> {
        self.summary.as_ref()
    }

    /// The attacker's view after the last tick: `[t, per robot y…, ẏ…, u…]`.
    pub fn attacker_view(&self, out: &mut Vec<f64>) {
        out.push(self.seen.t);
        out.extend_from_slice(&self.seen.attacker);
    }

    /// The control center's view after the last tick: `[t, per robot y…, ẏ…, Ŝ…, y − q̂…,
    /// ẏ − q̂̇…]` (what it received).
    pub fn center_view(&self, out: &mut Vec<f64>) {
        out.push(self.seen.t);
        out.extend_from_slice(&self.seen.center);
    }

    /// Why `action` cannot be an action of this episode, if it cannot: another length than
    /// robots × channels × links, a non-finite entry, an entry outside [−1, 1].
    pub fn check_action(&self, action: &[f64]) -> Result<(), String> {
        let want = self.action_size();
        if action.len() != want {
            return Err(format!(
                "an action has {want} entries ({} robots × {} channels × {} links), got {}",
                self.spec.robots.len(),
                self.action_channels(),
                self.links,
                action.len()
            ));
        }
        if let Some((i, a)) = action.iter().enumerate().find(|(_, a)| !a.is_finite()) {
            return Err(format!(
                "action entry {i} is {a}: every entry must be finite"
            ));
        }
        if let Some((i, a)) = action.iter().enumerate().find(|(_, a)| a.abs() > 1.0) {
            return Err(format!(
                "action entry {i} is {a}: outside [-1, 1] (1 injects the channel's budget)"
            ));
        }
        Ok(())
    }

    /// Sets the injection of the next steps from `action` (robots × channels × links, each in
    /// [−1, 1], scaled by the channel's budget). Refused, and the injection unchanged, when
    /// [`Self::check_action`] refuses it.
    pub fn act(&mut self, action: &[f64]) -> Result<(), String> {
        self.check_action(action)?;
        self.apply_action(action);
        Ok(())
    }

    /// [`Self::act`] for an action [`Self::check_action`] accepted.
    pub fn apply_action(&mut self, action: &[f64]) {
        let l = self.links;
        let per_robot = self.action_channels() * l;
        for (r, a) in action.chunks(per_robot.max(1)).enumerate() {
            let (_, inj) = &mut self.attacker.injections[r];
            for (c, values) in self.spec.channels.iter().zip(a.chunks(l.max(1))) {
                let budget = self.spec.budget[*c];
                for (dst, v) in inj[c * l..(c + 1) * l].iter_mut().zip(values) {
                    *dst = v * budget;
                }
            }
            if let (Some(budget), Some(engine), Some(id)) = (
                self.spec.correction,
                self.engine.as_mut(),
                self.spec.robots.get(r),
            ) {
                // The correction's entries that act: the robot's joints.
                let from = self.spec.channels.len() * l;
                let acts = &self.mask[r * per_robot + from..(r + 1) * per_robot];
                let c: Vec<f64> = a[from..]
                    .iter()
                    .zip(acts)
                    .filter_map(|(v, acts)| acts.then_some(v * budget))
                    .collect();
                // The robots and their links were checked when the episode was made.
                let _ = engine.set_correction(*id, &c);
            }
        }
    }

    /// Runs one decision period (fewer at the horizon, or when a robot diverges). An episode
    /// that ended runs nothing.
    pub fn step(&mut self) -> Outcome {
        let mut out = Outcome {
            attacked: vec![0; self.agents.len()],
            ..Outcome::default()
        };
        let Some(engine) = self.engine.as_mut() else {
            out.truncated = self.summary.as_ref().is_some_and(|s| s.partial.is_none());
            return out;
        };
        let agents = &self.agents;
        let seen = &mut self.seen;
        let mut attacked = vec![0u64; agents.len()];
        for _ in 0..self.spec.decision_period {
            let mut i = 0;
            let ran = engine.tick(&mut self.attacker, |r: &TickRecord| {
                seen_record(seen, i, r);
                attacked[i] += u64::from(fdi_common::detect::in_force(r));
                i += 1;
            });
            if !ran {
                break;
            }
            out.ticks += 1;
            let ev = engine.evaluator();
            let mut errors = 0.0;
            for id in &self.spec.robots {
                errors += ev.tracking(*id).map_or(f64::NAN, |(e, _)| e);
            }
            if !self.spec.robots.is_empty() {
                out.damage += errors / self.spec.robots.len() as f64;
            }
            let alarm = agents.iter().any(|id| {
                self.spec
                    .detectors
                    .iter()
                    .any(|d| ev.alarm(*id, *d).unwrap_or(false))
            });
            out.alarm_ticks += u64::from(alarm);
            if agents
                .iter()
                .any(|id| ev.tracking(*id).is_none_or(|(_, diverged)| diverged))
            {
                out.terminated = true;
                break;
            }
        }
        out.attacked = attacked;
        let (k, ticks) = (engine.k(), engine.ticks());
        out.truncated = !out.terminated && k >= ticks;
        if out.terminated || out.truncated {
            if let Some(engine) = self.engine.take() {
                self.summary = Some(engine.finish(&self.resolved, self.attacker.name()));
            }
        }
        out
    }
}

/// Stores what robot `i`'s record of a tick shows each observer.
fn seen_record(seen: &mut Seen, i: usize, r: &TickRecord) {
    seen.t = r.agent.t;
    let (at_a, at_c, l) = seen.at[i];
    let a = &mut seen.attacker[at_a..at_a + 3 * l];
    copy(&mut a[..l], r.agent.y.as_slice());
    copy(&mut a[l..2 * l], r.agent.yd.as_slice());
    match &r.actuation {
        Some(_) => copy(&mut a[2 * l..], r.center.u.as_slice()),
        None => a[2 * l..].fill(0.0),
    }
    let c = &mut seen.center[at_c..at_c + 5 * l];
    let (y, yd) = (r.attack.y.as_slice(), r.attack.yd.as_slice());
    copy(&mut c[..l], y);
    copy(&mut c[l..2 * l], yd);
    copy(&mut c[2 * l..3 * l], r.center.s_hat.as_slice());
    for (j, (dst, q)) in c[3 * l..4 * l]
        .iter_mut()
        .zip(r.center.q_hat.as_slice())
        .enumerate()
    {
        *dst = y.get(j).map_or(0.0, |y| y - q);
    }
    for (j, (dst, q)) in c[4 * l..5 * l]
        .iter_mut()
        .zip(r.center.qd_hat.as_slice())
        .enumerate()
    {
        *dst = yd.get(j).map_or(0.0, |y| y - q);
    }
}

/// `src` into `dst` entry by entry; entries `src` lacks are zero (a measurement that never
/// arrived).
fn copy(dst: &mut [f64], src: &[f64]) {
    for (i, d) in dst.iter_mut().enumerate() {
        *d = src.get(i).copied().unwrap_or(0.0);
    }
}
