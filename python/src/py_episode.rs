//! `Episode` and `Batch`: the Python side of [`crate::episode`]. Arrays cross as bytes of
//! native-endian `f64` (numpy's `frombuffer` / `tobytes`), the interpreter released while the
//! engine runs.

use std::sync::{Arc, Mutex, PoisonError, RwLock};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes};

use crate::episode::{self, Outcome, Spec, CHANNELS};
use crate::errors::engine_error;
use crate::py_scenario::Scenario;
use fdi_common::team::Team;

/// `f64`s from native-endian bytes.
fn floats(bytes: &[u8], what: &str) -> PyResult<Vec<f64>> {
    if !bytes.len().is_multiple_of(8) {
        return Err(PyValueError::new_err(format!(
            "{what}: {} bytes is not a whole number of float64 values",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(8)
        .map(|c| {
            let mut b = [0u8; 8];
            b.copy_from_slice(c);
            f64::from_ne_bytes(b)
        })
        .collect())
}

fn to_bytes<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyBytes> {
    let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_ne_bytes()).collect();
    PyBytes::new(py, &bytes)
}

/// The spec of the constructor's arguments, every name checked.
fn spec(
    robots: Vec<u32>,
    channels: Vec<String>,
    budget: [f64; 3],
    detectors: Vec<String>,
    (decision_period, correction_budget): (u64, f64),
) -> PyResult<Spec> {
    // The correction, the defence's channel, comes after the attack's.
    let correction = channels
        .iter()
        .any(|c| c == episode::CORRECTION)
        .then_some(correction_budget);
    if correction.is_some() && channels.last().is_some_and(|c| c != episode::CORRECTION) {
        return Err(PyValueError::new_err(format!(
            "channels: {:?} comes after every attack channel",
            episode::CORRECTION
        )));
    }
    let channels = channels
        .iter()
        .filter(|c| *c != episode::CORRECTION)
        .map(|c| {
            CHANNELS.iter().position(|x| x == c).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "channels: no channel {c:?}; the channels are {CHANNELS:?} and {:?}",
                    episode::CORRECTION
                ))
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let names = fdi_common::detect::names();
    let detectors = detectors
        .iter()
        .map(|d| {
            names.iter().position(|x| x == d).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "detectors: no detector {d:?}; the detectors are {names:?}"
                ))
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok(Spec {
        robots,
        channels,
        budget,
        detectors,
        decision_period,
        correction,
    })
}

fn closed() -> PyErr {
    PyRuntimeError::new_err("the episode is closed: make a new environment")
}

/// A step's outcome for Python: `(ticks, damage, alarm_ticks, attacked per robot, terminated,
/// truncated, attacker view, center view)`.
type PyOutcome<'py> = (
    u64,
    f64,
    u64,
    Vec<u64>,
    bool,
    bool,
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
);

fn outcome<'py>(py: Python<'py>, o: Outcome, e: &episode::Episode) -> PyOutcome<'py> {
    let (mut a, mut c) = (Vec::new(), Vec::new());
    e.attacker_view(&mut a);
    e.center_view(&mut c);
    (
        o.ticks,
        o.damage,
        o.alarm_ticks,
        o.attacked,
        o.terminated,
        o.truncated,
        to_bytes(py, &a),
        to_bytes(py, &c),
    )
}

/// One episode: the engine ticked a decision period per step, the action's injection added
/// to the scenario's own attack.
#[pyclass(module = "fdi_mas._core")]
#[derive(Debug)]
pub struct Episode {
    inner: Mutex<Option<episode::Episode>>,
}

impl Episode {
    fn with<T>(&self, f: impl FnOnce(&mut episode::Episode) -> PyResult<T>) -> PyResult<T> {
        let mut guard = self
            .inner
            .lock()
            .map_err(|_| engine_error("the episode failed earlier (a panic inside the engine)"))?;
        match guard.as_mut() {
            Some(e) => f(e),
            None => Err(closed()),
        }
    }
}

#[pymethods]
impl Episode {
    #[new]
    #[pyo3(signature = (scenario, robots, channels, budget, detectors, decision_period, correction_budget = 0.0))]
    fn new(
        scenario: &Scenario,
        robots: Vec<u32>,
        channels: Vec<String>,
        budget: [f64; 3],
        detectors: Vec<String>,
        decision_period: u64,
        correction_budget: f64,
    ) -> PyResult<Self> {
        let spec = spec(
            robots,
            channels,
            budget,
            detectors,
            (decision_period, correction_budget),
        )?;
        let e = episode::Episode::new(scenario.resolved.clone(), spec)
            .map_err(PyValueError::new_err)?;
        Ok(Self {
            inner: Mutex::new(Some(e)),
        })
    }

    /// Back to the start; of `scenario` when given (same robots and links).
    #[pyo3(signature = (scenario = None))]
    fn reset(&self, scenario: Option<&Scenario>) -> PyResult<()> {
        let resolved = scenario.map(|s| s.resolved.clone());
        self.with(|e| e.reset(resolved).map_err(PyValueError::new_err))
    }

    /// Sets the action (bytes of float64: robots × channels × links, in [−1, 1]) and runs one
    /// decision period; the outcome.
    fn step<'py>(&self, py: Python<'py>, action: &[u8]) -> PyResult<PyOutcome<'py>> {
        let action = floats(action, "action")?;
        let mut guard = self
            .inner
            .lock()
            .map_err(|_| engine_error("the episode failed earlier (a panic inside the engine)"))?;
        let e = guard.as_mut().ok_or_else(closed)?;
        e.act(&action).map_err(PyValueError::new_err)?;
        let o = py.detach(|| e.step());
        Ok(outcome(py, o, e))
    }

    /// The attacker's view and the control center's view after the last tick (bytes of
    /// float64).
    fn views<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>)> {
        self.with(|e| {
            let (mut a, mut c) = (Vec::new(), Vec::new());
            e.attacker_view(&mut a);
            e.center_view(&mut c);
            Ok((to_bytes(py, &a), to_bytes(py, &c)))
        })
    }

    /// `summary.json`'s fields of the episode (JSON), once it ended; else `None`.
    fn summary_json(&self) -> PyResult<Option<String>> {
        self.with(|e| {
            e.summary()
                .map(serde_json::to_string)
                .transpose()
                .map_err(engine_error)
        })
    }

    /// `(next tick, ticks of the horizon)`.
    fn progress(&self) -> PyResult<(u64, u64)> {
        self.with(|e| Ok(e.progress()))
    }

    /// Robot ids (scenario order), links (an action's entries per robot and channel: the
    /// team's largest joint count), entries of an action.
    fn shape(&self) -> PyResult<(Vec<u32>, usize, usize)> {
        self.with(|e| Ok((e.agents().to_vec(), e.links(), e.action_size())))
    }

    /// Each robot's joints (scenario order), and per entry of an action whether it acts (its
    /// link is a joint of its robot).
    fn joints(&self) -> PyResult<(Vec<usize>, Vec<bool>)> {
        self.with(|e| Ok((e.joints().to_vec(), e.action_mask().to_vec())))
    }

    /// Ends the episode and frees the engine; any later call raises.
    fn close(&self) -> PyResult<()> {
        let mut guard = self
            .inner
            .lock()
            .map_err(|_| engine_error("the episode failed earlier (a panic inside the engine)"))?;
        *guard = None;
        Ok(())
    }

    #[getter]
    fn closed(&self) -> bool {
        self.inner.lock().map_or(true, |g| g.is_none())
    }
}

/// Environments per chunk of a batch's work.
const CHUNK: usize = 4;

/// One environment of a batch: its episode and what its last step gave.
#[derive(Debug)]
struct Slot {
    episode: episode::Episode,
    /// Its episode ended at the last step: the next step resets it (next-step autoreset).
    ended: bool,
    reward: f64,
    terminated: bool,
    truncated: bool,
    /// The learner's view after the step (the attacker's, or the control center's).
    view: Vec<f64>,
    /// The vector defender's draw of each episode's attack and seed (`None`: every episode is
    /// the batch's scenario).
    draw: Option<Draw>,
    /// The trace digest of the episode that ended at this step.
    ended_digest: Option<String>,
    /// Why the step failed (a reset refused).
    error: Option<String>,
}

/// How an environment of a batch draws its next episode: one of `scenarios` (one per attack),
/// and with `vary_seed` a seed of its own, from its generator.
#[derive(Debug)]
struct Draw {
    scenarios: Arc<Vec<fdi_common::scenario::Resolved>>,
    vary_seed: bool,
    rng: rand_chacha::ChaCha12Rng,
}

impl Draw {
    fn next(&mut self) -> fdi_common::scenario::Resolved {
        use rand::Rng as _;
        // `Batch::defender` makes a draw of one scenario at least.
        let i = self.rng.random_range(0..self.scenarios.len());
        let mut r = self.scenarios[i].clone();
        if self.vary_seed {
            r.scenario.seed = self.rng.random_range(0..(1u64 << 63));
        }
        r
    }
}

/// A batch's learner, and so its reward and view.
#[derive(Debug, Clone, Copy)]
enum Learner {
    Attacker(episode::AttackerReward),
    Defender(episode::DefenderReward),
}

impl Learner {
    fn reward(&self, o: &Outcome, action: &[f64]) -> f64 {
        match self {
            Self::Attacker(r) => r.of(o),
            Self::Defender(r) => r.of(o, action),
        }
    }

    /// Its view of `e` after the last tick, appended to `out`.
    fn view(&self, e: &episode::Episode, out: &mut Vec<f64>) {
        match self {
            Self::Attacker(_) => e.attacker_view(out),
            Self::Defender(_) => e.center_view(out),
        }
    }
}

/// What the batch's threads share: the environments, the step's actions, the learner.
#[derive(Debug)]
struct Envs {
    slots: Vec<Mutex<Slot>>,
    actions: RwLock<Vec<f64>>,
    /// Entries of one environment's action.
    per: usize,
    learner: Learner,
}

impl Envs {
    /// Steps (or, when its episode ended at the step before, resets) the environments of chunk
    /// `c`, each with its action.
    fn step_chunk(&self, c: usize) {
        let actions = self.actions.read().unwrap_or_else(PoisonError::into_inner);
        for i in c * CHUNK..((c + 1) * CHUNK).min(self.slots.len()) {
            let Ok(mut slot) = self.slots[i].lock() else {
                continue; // a panic before: `step` reports the poisoned slot
            };
            let action = actions.get(i * self.per..(i + 1) * self.per).unwrap_or(&[]);
            step_slot(&mut slot, action, &self.learner);
        }
    }
}

/// An environment back to its start, on its next draw when it draws its episodes.
fn reset_slot(slot: &mut Slot) -> Result<(), String> {
    slot.ended = false;
    let next = slot.draw.as_mut().map(Draw::next);
    slot.episode.reset(next)
}

/// One environment's step: its reward (zero for a reset), its end, its view.
fn step_slot(slot: &mut Slot, action: &[f64], learner: &Learner) {
    let o = if slot.ended {
        if let Err(e) = reset_slot(slot) {
            slot.error = Some(e);
        }
        Outcome::default()
    } else {
        slot.episode.apply_action(action);
        slot.episode.step()
    };
    // The defence's effort counts the entries that act (a robot of fewer joints than the
    // team's largest ignores the rest).
    slot.reward = learner.reward(&o, &slot.episode.acting(action));
    (slot.terminated, slot.truncated) = (o.terminated, o.truncated);
    slot.ended_digest = None;
    if o.terminated || o.truncated {
        slot.ended = true;
        slot.ended_digest = slot.episode.summary().map(|s| s.trace_digest.clone());
    }
    slot.view.clear();
    learner.view(&slot.episode, &mut slot.view);
}

/// The attacker's reward of a step of `ticks` ticks with `damage` and `alarm_ticks`
/// (`episode::AttackerReward`): the one formula of `AttackerEnv`, the vector environment and
/// the attack-defend environment.
#[pyfunction]
pub fn attacker_reward(
    ticks: u64,
    damage: f64,
    alarm_ticks: u64,
    damage_weight: f64,
    stealth_weight: f64,
    damage_scale_rad: f64,
) -> PyResult<f64> {
    let reward = episode::AttackerReward::new(damage_weight, stealth_weight, damage_scale_rad)
        .map_err(PyValueError::new_err)?;
    Ok(reward.of(&episode::Outcome {
        ticks,
        damage,
        alarm_ticks,
        ..episode::Outcome::default()
    }))
}

/// The defence's reward of a step of `ticks` ticks with `damage` under `action`
/// (`episode::DefenderReward`): the one formula of `DefenderEnv` and the vector defender.
#[pyfunction]
pub fn defender_reward(
    ticks: u64,
    damage: f64,
    action: Vec<f64>,
    error_scale_rad: f64,
    effort_weight: f64,
) -> PyResult<f64> {
    let reward = episode::DefenderReward::new(error_scale_rad, effort_weight)
        .map_err(PyValueError::new_err)?;
    Ok(reward.of(
        &episode::Outcome {
            ticks,
            damage,
            ..episode::Outcome::default()
        },
        &action,
    ))
}

/// Many episodes of one spec stepped together on every core: the vector environment's engine.
#[pyclass(module = "fdi_mas._core")]
#[derive(Debug)]
pub struct Batch {
    inner: Mutex<Option<Stepping>>,
    threads: usize,
}

/// An open batch: its environments, the threads that step them, each environment's last ended
/// episode's digest.
#[derive(Debug)]
struct Stepping {
    envs: Arc<Envs>,
    team: Team,
    digests: Vec<Option<String>>,
}

/// What a batch step returns, each a bytearray: every env's attacker view, then per env the
/// reward (float64), terminated, truncated (bool).
type BatchOut<'py> = (
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
);

fn failed_earlier() -> PyErr {
    engine_error("the batch failed earlier (a panic inside the engine)")
}

fn float_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_ne_bytes()).collect()
}

impl Batch {
    /// `f` of the batch's first environment's episode (every one has the same spec and team).
    fn first<T>(&self, f: impl FnOnce(&episode::Episode) -> T) -> PyResult<T> {
        let guard = self.guard()?;
        let stepping = guard.as_ref().ok_or_else(closed)?;
        let slot = stepping.envs.slots.first().ok_or_else(closed)?;
        let slot = slot.lock().map_err(|_| failed_earlier())?;
        Ok(f(&slot.episode))
    }

    /// A batch of `slots` (episodes and their draws) for `learner`, stepped on `threads`
    /// threads (every core by default).
    fn of_slots(
        slots: Vec<(episode::Episode, Option<Draw>)>,
        learner: Learner,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let n = slots.len();
        let per = slots.first().map_or(0, |(e, _)| e.action_size());
        let envs = Arc::new(Envs {
            slots: slots
                .into_iter()
                .map(|(episode, draw)| {
                    Mutex::new(Slot {
                        episode,
                        ended: false,
                        reward: 0.0,
                        terminated: false,
                        truncated: false,
                        view: Vec::new(),
                        draw,
                        ended_digest: None,
                        error: None,
                    })
                })
                .collect(),
            actions: RwLock::new(vec![0.0; n * per]),
            per,
            learner,
        });
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let chunks = n.div_ceil(CHUNK);
        let threads = threads.unwrap_or(cores).clamp(1, chunks);
        let work = Arc::clone(&envs);
        let team = Team::new(threads, chunks, Box::new(move |c| work.step_chunk(c)))
            .map_err(engine_error)?;
        Ok(Self {
            inner: Mutex::new(Some(Stepping {
                envs,
                team,
                digests: vec![None; n],
            })),
            threads,
        })
    }

    /// The open batch, locked.
    fn guard(&self) -> PyResult<std::sync::MutexGuard<'_, Option<Stepping>>> {
        self.inner.lock().map_err(|_| failed_earlier())
    }
}

/// Environments made before their memory is measured and the whole batch's is projected.
const PROBE: usize = 64;

/// `n` episodes of `scenario`. The first [`PROBE`] are made, what they took (the growth of the
/// process's resident memory) is projected to `n`, and a batch that would not fit in the
/// memory this process may still use is refused with `MemoryError` before it is made (issue
/// 51: `VectorAttackerEnv(100000)`, about 8 GB, aborted the interpreter under a memory limit).
fn episodes(scenario: &Scenario, spec: &Spec, n: usize) -> PyResult<Vec<episode::Episode>> {
    let make = |k: usize, out: &mut Vec<episode::Episode>| -> PyResult<()> {
        for _ in 0..k {
            out.push(
                episode::Episode::new(scenario.resolved.clone(), spec.clone())
                    .map_err(PyValueError::new_err)?,
            );
        }
        Ok(())
    };
    let mut out = Vec::new();
    let before = crate::memory::resident();
    make(n.min(PROBE), &mut out)?;
    if n > PROBE {
        if let (Some(before), Some(after)) = (before, crate::memory::resident()) {
            let each = after.saturating_sub(before) / PROBE as u64;
            let need = each.saturating_mul((n - PROBE) as u64);
            if let Some(free) = crate::memory::available() {
                if need > free {
                    return Err(pyo3::exceptions::PyMemoryError::new_err(format!(
                        "{n} environments need about {} ({} each, measured on the first {PROBE}), \
                         more than the {} this process may still use (the machine's available \
                         memory, its memory limits): make fewer",
                        crate::memory::human(each.saturating_mul(n as u64)),
                        crate::memory::human(each),
                        crate::memory::human(free.saturating_add(each * PROBE as u64))
                    )));
                }
            }
        }
        out.try_reserve_exact(n - out.len())
            .map_err(|_| pyo3::exceptions::PyMemoryError::new_err(format!("{n} environments")))?;
        make(n - PROBE, &mut out)?;
    }
    Ok(out)
}

#[pymethods]
impl Batch {
    #[new]
    #[pyo3(signature = (scenario, n, robots, channels, budget, detectors, decision_period, damage_weight, stealth_weight, damage_scale_rad, threads = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        scenario: &Scenario,
        n: usize,
        robots: Vec<u32>,
        channels: Vec<String>,
        budget: [f64; 3],
        detectors: Vec<String>,
        decision_period: u64,
        damage_weight: f64,
        stealth_weight: f64,
        damage_scale_rad: f64,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        if n == 0 {
            return Err(PyValueError::new_err("n: at least one environment"));
        }
        let reward = episode::AttackerReward::new(damage_weight, stealth_weight, damage_scale_rad)
            .map_err(PyValueError::new_err)?;
        if channels.iter().any(|c| c == episode::CORRECTION) {
            return Err(PyValueError::new_err(format!(
                "channels: the vector attacker environment takes attack channels, not {:?}",
                episode::CORRECTION
            )));
        }
        let spec = spec(robots, channels, budget, detectors, (decision_period, 0.0))?;
        let episodes = episodes(scenario, &spec, n)?;
        let slots = episodes.into_iter().map(|e| (e, None)).collect();
        Self::of_slots(slots, Learner::Attacker(reward), threads)
    }

    /// The vector defender's batch: `n` episodes whose robots' torques the action corrects
    /// (`correction_budget` N·m for an action of 1), each episode's attack drawn from
    /// `scenarios` (one per attack) and, with `vary_seed`, its seed, by each environment's
    /// generator (seeded from `seed` and its index).
    #[staticmethod]
    #[pyo3(signature = (scenarios, n, correction_budget, decision_period, error_scale_rad, effort_weight, seed, vary_seed, threads = None))]
    #[allow(clippy::too_many_arguments)]
    fn defender(
        scenarios: Vec<PyRef<'_, Scenario>>,
        n: usize,
        correction_budget: f64,
        decision_period: u64,
        error_scale_rad: f64,
        effort_weight: f64,
        seed: u64,
        vary_seed: bool,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        use rand::SeedableRng as _;
        if n == 0 {
            return Err(PyValueError::new_err("n: at least one environment"));
        }
        let Some(first) = scenarios.first() else {
            return Err(PyValueError::new_err("scenarios: at least one"));
        };
        let reward = episode::DefenderReward::new(error_scale_rad, effort_weight)
            .map_err(PyValueError::new_err)?;
        let robots = first
            .resolved
            .scenario
            .agents
            .iter()
            .map(|a| a.id)
            .collect();
        let channels = vec![episode::CORRECTION.to_string()];
        let spec = spec(
            robots,
            channels,
            [0.0; 3],
            Vec::new(),
            (decision_period, correction_budget),
        )?;
        let all: Arc<Vec<_>> = Arc::new(scenarios.iter().map(|s| s.resolved.clone()).collect());
        let episodes = episodes(first, &spec, n)?;
        let mut slots = Vec::with_capacity(n);
        for (i, episode) in episodes.into_iter().enumerate() {
            let mut rng = rand_chacha::ChaCha12Rng::seed_from_u64(seed);
            rng.set_stream(i as u64);
            let mut draw = Draw {
                scenarios: Arc::clone(&all),
                vary_seed,
                rng,
            };
            let mut episode = episode;
            episode
                .reset(Some(draw.next()))
                .map_err(PyValueError::new_err)?;
            slots.push((episode, Some(draw)));
        }
        Self::of_slots(slots, Learner::Defender(reward), threads)
    }

    /// Every environment back to its start (the defender's on a new draw); their views.
    fn reset<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let guard = self.guard()?;
        let stepping = guard.as_ref().ok_or_else(closed)?;
        let mut view = Vec::new();
        for slot in &stepping.envs.slots {
            let mut slot = slot.lock().map_err(|_| failed_earlier())?;
            reset_slot(&mut slot).map_err(PyValueError::new_err)?;
            stepping.envs.learner.view(&slot.episode, &mut view);
        }
        Ok(to_bytes(py, &view))
    }

    /// Steps every environment with its action (bytes of float64, n × action entries); an
    /// environment whose episode ended at the step before is reset instead (its action is
    /// ignored, its reward 0, its end false): the next-step autoreset of Gymnasium's vector
    /// environments. A bad action of a stepped environment is refused, naming it, before any
    /// environment steps.
    fn step<'py>(&self, py: Python<'py>, actions: &[u8]) -> PyResult<BatchOut<'py>> {
        let actions = floats(actions, "actions")?;
        let mut guard = self.guard()?;
        let stepping = guard.as_mut().ok_or_else(closed)?;
        let envs = &stepping.envs;
        let (n, per) = (envs.slots.len(), envs.per);
        if actions.len() != n * per {
            return Err(PyValueError::new_err(format!(
                "actions: {n} environments × {per} entries expected, got {}",
                actions.len()
            )));
        }
        for (i, (slot, a)) in envs
            .slots
            .iter()
            .zip(actions.chunks(per.max(1)))
            .enumerate()
        {
            let slot = slot.lock().map_err(|_| failed_earlier())?;
            if !slot.ended {
                slot.episode
                    .check_action(a)
                    .map_err(|m| PyValueError::new_err(format!("environment {i}: {m}")))?;
            }
        }
        envs.actions
            .write()
            .map_err(|_| failed_earlier())?
            .copy_from_slice(&actions);
        let team = &stepping.team;
        py.detach(|| team.round()).map_err(engine_error)?;
        let mut view = Vec::new();
        let (mut rewards, mut term, mut trunc) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for (slot, digest) in envs.slots.iter().zip(&mut stepping.digests) {
            let mut slot = slot.lock().map_err(|_| failed_earlier())?;
            if let Some(e) = slot.error.take() {
                return Err(PyValueError::new_err(e));
            }
            if let Some(d) = slot.ended_digest.take() {
                *digest = Some(d);
            }
            view.extend_from_slice(&slot.view);
            rewards.push(slot.reward);
            term.push(u8::from(slot.terminated));
            trunc.push(u8::from(slot.truncated));
        }
        Ok((
            PyByteArray::new(py, &float_bytes(&view)),
            PyByteArray::new(py, &float_bytes(&rewards)),
            PyByteArray::new(py, &term),
            PyByteArray::new(py, &trunc),
        ))
    }

    /// Each environment's last ended episode's trace digest, or `None` while none ended.
    fn digests(&self) -> PyResult<Vec<Option<String>>> {
        let guard = self.guard()?;
        Ok(guard.as_ref().ok_or_else(closed)?.digests.clone())
    }

    /// Robot ids (scenario order), links, entries of one environment's action.
    fn shape(&self) -> PyResult<(Vec<u32>, usize, usize)> {
        self.first(|e| (e.agents().to_vec(), e.links(), e.action_size()))
    }

    /// Each robot's joints (scenario order), and per entry of one environment's action whether
    /// it acts.
    fn joints(&self) -> PyResult<(Vec<usize>, Vec<bool>)> {
        self.first(|e| (e.joints().to_vec(), e.action_mask().to_vec()))
    }

    /// Frees every engine and stops the threads; any later call raises.
    fn close(&self) -> PyResult<()> {
        let mut guard = self.guard()?;
        *guard = None;
        Ok(())
    }

    #[getter]
    fn threads(&self) -> usize {
        self.threads
    }
}
