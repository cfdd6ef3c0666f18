//! `Episode` and `Batch`: the Python side of [`crate::episode`]. Arrays cross as bytes of
//! native-endian `f64` (numpy's `frombuffer` / `tobytes`), the interpreter released while the
//! engine runs.

use std::sync::Mutex;

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::episode::{self, Outcome, Spec, CHANNELS};
use crate::errors::engine_error;
use crate::py_scenario::Scenario;

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
    decision_period: u64,
) -> PyResult<Spec> {
    let channels = channels
        .iter()
        .map(|c| {
            CHANNELS.iter().position(|x| x == c).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "channels: no channel {c:?}; the channels are {CHANNELS:?}"
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
    #[pyo3(signature = (scenario, robots, channels, budget, detectors, decision_period))]
    fn new(
        scenario: &Scenario,
        robots: Vec<u32>,
        channels: Vec<String>,
        budget: [f64; 3],
        detectors: Vec<String>,
        decision_period: u64,
    ) -> PyResult<Self> {
        let spec = spec(robots, channels, budget, detectors, decision_period)?;
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

    /// Robot ids (scenario order), links, entries of an action.
    fn shape(&self) -> PyResult<(Vec<u32>, usize, usize)> {
        self.with(|e| Ok((e.agents().to_vec(), e.links(), e.action_size())))
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

/// Many episodes of one spec stepped together on every core: the vector environment's engine.
#[pyclass(module = "fdi_mas._core")]
#[derive(Debug)]
pub struct Batch {
    inner: Mutex<Option<Envs>>,
    threads: usize,
    pool: rayon::ThreadPool,
}

/// The episodes of a batch, and each one's last ended episode's digest.
#[derive(Debug)]
struct Envs {
    episodes: Vec<episode::Episode>,
    digests: Vec<Option<String>>,
}

/// What a batch step returns: every env's attacker view, then per env damage, alarm ticks,
/// terminated, truncated (bytes of float64 / uint8).
type BatchOut<'py> = (
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
);

impl Batch {
    /// The batch's environments, locked.
    fn guard(&self) -> PyResult<std::sync::MutexGuard<'_, Option<Envs>>> {
        self.inner
            .lock()
            .map_err(|_| engine_error("the batch failed earlier (a panic inside the engine)"))
    }
}

#[pymethods]
impl Batch {
    #[new]
    #[pyo3(signature = (scenario, n, robots, channels, budget, detectors, decision_period, threads = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        scenario: &Scenario,
        n: usize,
        robots: Vec<u32>,
        channels: Vec<String>,
        budget: [f64; 3],
        detectors: Vec<String>,
        decision_period: u64,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        if n == 0 {
            return Err(PyValueError::new_err("n: at least one environment"));
        }
        let spec = spec(robots, channels, budget, detectors, decision_period)?;
        let episodes = (0..n)
            .map(|_| episode::Episode::new(scenario.resolved.clone(), spec.clone()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(PyValueError::new_err)?;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = threads.unwrap_or(cores).clamp(1, n);
        // The calling thread steps one share itself: the pool has the others' threads.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads((threads - 1).max(1))
            .thread_name(|i| format!("fdi-mas-vec-{i}"))
            .build()
            .map_err(engine_error)?;
        Ok(Self {
            inner: Mutex::new(Some(Envs {
                digests: vec![None; episodes.len()],
                episodes,
            })),
            threads,
            pool,
        })
    }

    /// Every environment back to its start; their attacker views.
    fn reset<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let mut guard = self.guard()?;
        let eps = &mut guard.as_mut().ok_or_else(closed)?.episodes;
        let mut view = Vec::new();
        for e in eps.iter_mut() {
            e.reset(None).map_err(PyValueError::new_err)?;
            e.attacker_view(&mut view);
        }
        Ok(to_bytes(py, &view))
    }

    /// Steps every environment with its action (bytes of float64, n × action entries), or
    /// resets those `reset` marks (bytes, one per environment; their action is ignored and
    /// their outcome is zero): the next-step autoreset of Gymnasium's vector environments.
    fn step<'py>(&self, py: Python<'py>, actions: &[u8], reset: &[u8]) -> PyResult<BatchOut<'py>> {
        let actions = floats(actions, "actions")?;
        let mut guard = self.guard()?;
        let envs = guard.as_mut().ok_or_else(closed)?;
        let eps = &mut envs.episodes;
        let n = eps.len();
        let per = eps.first().map_or(0, |e| e.action_size());
        if actions.len() != n * per || reset.len() != n {
            return Err(PyValueError::new_err(format!(
                "actions: {n} environments × {per} entries expected, got {} (and {} reset flags)",
                actions.len(),
                reset.len()
            )));
        }
        for (i, (e, a)) in eps.iter_mut().zip(actions.chunks(per.max(1))).enumerate() {
            if reset[i] == 0 {
                e.act(a)
                    .map_err(|m| PyValueError::new_err(format!("environment {i}: {m}")))?;
            }
        }
        let (pool, threads) = (&self.pool, self.threads);
        let outcomes = py.detach(|| step_all(pool, threads, eps, reset))?;
        let mut view = Vec::new();
        let (mut damage, mut alarms) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let (mut term, mut trunc) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for ((e, o), digest) in eps.iter().zip(&outcomes).zip(&mut envs.digests) {
            if o.terminated || o.truncated {
                *digest = e.summary().map(|s| s.trace_digest.clone());
            }
            e.attacker_view(&mut view);
            damage.push(o.damage);
            alarms.push(o.alarm_ticks as f64);
            term.push(u8::from(o.terminated));
            trunc.push(u8::from(o.truncated));
        }
        Ok((
            to_bytes(py, &view),
            to_bytes(py, &damage),
            to_bytes(py, &alarms),
            PyBytes::new(py, &term),
            PyBytes::new(py, &trunc),
        ))
    }

    /// Each environment's last ended episode's trace digest, or `None` while none ended.
    fn digests(&self) -> PyResult<Vec<Option<String>>> {
        let guard = self.guard()?;
        Ok(guard.as_ref().ok_or_else(closed)?.digests.clone())
    }

    /// Robot ids (scenario order), links, entries of one environment's action.
    fn shape(&self) -> PyResult<(Vec<u32>, usize, usize)> {
        let guard = self.guard()?;
        let envs = guard.as_ref().ok_or_else(closed)?;
        let e = envs.episodes.first().ok_or_else(closed)?;
        Ok((e.agents().to_vec(), e.links(), e.action_size()))
    }

    /// Frees every engine; any later call raises.
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

/// Steps (or resets) one episode.
fn step_one(e: &mut episode::Episode, reset: u8) -> Result<Outcome, String> {
    if reset != 0 {
        e.reset(None)?;
        Ok(Outcome {
            attacked: vec![0; e.agents().len()],
            ..Outcome::default()
        })
    } else {
        Ok(e.step())
    }
}

/// Steps (or resets) every episode, in small chunks taken in turn by the calling thread and
/// the pool's threads (a thread that wakes late takes fewer; which thread steps an episode
/// changes nothing in it). A panic is an error.
fn step_all(
    pool: &rayon::ThreadPool,
    threads: usize,
    eps: &mut [episode::Episode],
    reset: &[u8],
) -> PyResult<Vec<Outcome>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    const CHUNK: usize = 4;
    type Chunk<'a> = (
        &'a mut [episode::Episode],
        &'a [u8],
        Result<Vec<Outcome>, String>,
    );
    let n = eps.len();
    let chunks: Vec<Mutex<Chunk<'_>>> = eps
        .chunks_mut(CHUNK)
        .zip(reset.chunks(CHUNK))
        .map(|(es, rs)| Mutex::new((es, rs, Ok(Vec::new()))))
        .collect();
    let next = AtomicUsize::new(0);
    let work = || loop {
        let i = next.fetch_add(1, Ordering::Relaxed);
        let Some(chunk) = chunks.get(i) else {
            break;
        };
        // A chunk is taken by one thread only (the counter hands each index out once).
        if let Ok(mut c) = chunk.lock() {
            let (es, rs, out) = &mut *c;
            *out = es
                .iter_mut()
                .zip(rs.iter())
                .map(|(e, r)| step_one(e, *r))
                .collect();
        }
    };
    let run = std::panic::AssertUnwindSafe(|| {
        pool.in_place_scope(|scope| {
            for _ in 1..threads {
                scope.spawn(|_| work());
            }
            work();
        })
    });
    if std::panic::catch_unwind(run).is_err() {
        return Err(engine_error(
            "a panic inside the engine while stepping the batch",
        ));
    }
    let mut out = Vec::with_capacity(n);
    for chunk in chunks {
        let (_, _, r) = chunk
            .into_inner()
            .map_err(|_| engine_error("a panic inside the engine while stepping the batch"))?;
        out.extend(r.map_err(PyValueError::new_err)?);
    }
    if out.len() != n {
        return Err(engine_error(format!(
            "{} outcomes for {n} environments (a bug)",
            out.len()
        )));
    }
    Ok(out)
}
