//! Campaigns in shards (`fdi-launch sweep CAMPAIGN --shard K/N`): which runs shard K of N owns,
//! the shard's number from a scheduler's environment (`--shard auto`), the lease that keeps two
//! copies of one shard from running at once, and the record each shard keeps of itself.
//!
//! Everything here is written for a folder shared by many machines (NFS included): a file is
//! written by one shard only, whole (a temporary file in the same folder, renamed); the lease is
//! made by an exclusive create, never by `flock`; and a lease's age is measured against the
//! file server's clock (the modification time of a file just written), never against this
//! machine's.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, SystemTime};

use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::plan::Plan;
use super::store::write_atomic;

/// The folder of a campaign's shard files (`<out>/shards`).
pub const SHARDS: &str = "shards";
/// How often a running shard renews its lease.
pub const RENEW_EVERY: Duration = Duration::from_secs(20);
/// A lease not renewed for this long (by the file server's clock) belongs to a shard that is
/// gone: another copy of the shard may take it over.
pub const STALE_AFTER: Duration = Duration::from_secs(90);

/// Shard `index` of `count` (1 ≤ index ≤ count).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// Shard `index` of `count`, or why not.
    pub fn new(index: usize, count: usize) -> Result<Self> {
        if count == 0 || count > super::plan::MAX_RUNS {
            bail!(
                "{index}/{count}: the number of shards N must be between 1 and {}",
                super::plan::MAX_RUNS
            );
        }
        if index == 0 || index > count {
            bail!("{index}/{count}: the shard K must be between 1 and N ({count})");
        }
        Ok(Self { index, count })
    }

    /// `K-of-N`: the stem of the shard's files.
    pub fn stem(&self) -> String {
        format!("{}-of-{}", self.index, self.count)
    }

    /// The shard from a scheduler's environment (`get` reads a variable): a Slurm array job or
    /// a Kubernetes Indexed Job (`JOB_COMPLETION_INDEX`, from 0, and `FDI_SHARD_COUNT`, which
    /// the job's manifest sets to its `completions`: Kubernetes gives no variable of it).
    ///
    /// In a Slurm array job with `FDI_SHARD_COUNT` set (as `submit.sh` does), the shard is
    /// `SLURM_ARRAY_TASK_ID` of `FDI_SHARD_COUNT`: a task sent again alone
    /// (`sbatch --array=K`) is still shard K of N. Without it, the shard is the task's place in
    /// the array (`SLURM_ARRAY_TASK_MIN`…`MAX` by `STEP`) of `SLURM_ARRAY_TASK_COUNT`.
    pub fn from_env(get: &dyn Fn(&str) -> Option<String>) -> Result<Self> {
        let number = |name: &str| -> Result<Option<usize>> {
            get(name)
                .map(|v| {
                    v.trim().parse::<usize>().map_err(|_| {
                        anyhow!("--shard auto: {name}={v:?} is not a whole number ≥ 0")
                    })
                })
                .transpose()
        };
        let need = |name: &str, why: &str| -> Result<usize> {
            number(name)?.ok_or_else(|| anyhow!("--shard auto: {why}, but {name} is not set"))
        };
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            if let Some(count) = number("FDI_SHARD_COUNT")? {
                return Self::new(id, count).context(
                    "--shard auto (a Slurm array job: SLURM_ARRAY_TASK_ID of FDI_SHARD_COUNT)",
                );
            }
            let why = "SLURM_ARRAY_TASK_ID is set (a Slurm array job)";
            let count = need("SLURM_ARRAY_TASK_COUNT", why)?;
            let min = need("SLURM_ARRAY_TASK_MIN", why)?;
            let max = need("SLURM_ARRAY_TASK_MAX", why)?;
            let step = number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            // A list of indices (`--array=1,4,9`) is not a range: the shard of a task would
            // not follow from its index.
            if max < min || (max - min) % step != 0 || (max - min) / step + 1 != count {
                bail!(
                    "--shard auto: the array job's indices ({min} to {max} by {step}, {count} tasks) are not one range: submit it with --array=1-N"
                );
            }
            if id < min || (id - min) % step != 0 {
                bail!("--shard auto: SLURM_ARRAY_TASK_ID={id} is not one of the array's indices ({min} to {max} by {step})");
            }
            return Self::new((id - min) / step + 1, count)
                .context("--shard auto (a Slurm array job)");
        }
        if let Some(index) = number("JOB_COMPLETION_INDEX")? {
            let count = need(
                "FDI_SHARD_COUNT",
                "JOB_COMPLETION_INDEX is set (a Kubernetes Indexed Job; its manifest sets FDI_SHARD_COUNT to the job's completions)",
            )?;
            return Self::new(index.saturating_add(1), count)
                .context("--shard auto (a Kubernetes Indexed Job)");
        }
        bail!(
            "--shard auto: neither SLURM_ARRAY_TASK_ID (a Slurm array job) nor JOB_COMPLETION_INDEX (a Kubernetes Indexed Job) is set: give the shard as --shard K/N"
        )
    }
}

/// `--shard`: `K/N` or `auto`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShardArg {
    Part(Shard),
    Auto,
}

impl FromStr for ShardArg {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Self> {
        if s == "auto" {
            return Ok(Self::Auto);
        }
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| anyhow!("{s:?}: give K/N (shard K of N, from 1) or `auto`"))?;
        let whole = |x: &str| {
            x.parse::<usize>()
                .map_err(|_| anyhow!("{s:?}: {x:?} is not a whole number"))
        };
        Ok(Self::Part(Shard::new(whole(k)?, whole(n)?)?))
    }
}

impl ShardArg {
    /// The shard this process runs: the one given, or the scheduler's.
    pub fn resolve(self) -> Result<Shard> {
        match self {
            Self::Part(s) => Ok(s),
            Self::Auto => Shard::from_env(&|name| std::env::var(name).ok()),
        }
    }
}

/// The shard (1 … `count`) that owns each run of `plan`, in the order of its jobs.
///
/// Runs with one key are one run (they write one result) and go to one shard. The runs are
/// dealt largest first (expected cost: ticks × agents) to the shard with the least cost so
/// far ([`deal`]). The partition depends on the campaign's runs only: not on which results
/// exist, nor on the machine.
pub(super) fn owners(plan: &Plan, count: usize) -> Vec<usize> {
    let mut units: Vec<(u128, &str)> = Vec::new();
    let mut first: std::collections::BTreeMap<&str, usize> = Default::default();
    for job in &plan.jobs {
        first.entry(job.key.as_str()).or_insert_with(|| {
            let cost = u128::from(job.resolved.ticks()) * job.resolved.agent_count() as u128;
            units.push((cost, job.key.as_str()));
            units.len() - 1
        });
    }
    let owner_of_unit = deal(&units, count);
    plan.jobs
        .iter()
        .map(|j| owner_of_unit[first[j.key.as_str()]])
        .collect()
}

/// The shard (1 … `count`) of each unit `(cost, key)` (keys distinct): largest cost first
/// (ties: the smaller key), each to the shard with the least cost so far (ties: the lowest
/// index); a cost of 0 counts as 1. Every shard's total is within the largest cost of every
/// other's.
fn deal(units: &[(u128, &str)], count: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..units.len()).collect();
    order.sort_by(|&a, &b| units[b].0.cmp(&units[a].0).then(units[a].1.cmp(units[b].1)));
    // The least loaded shard first, the lowest index among equals.
    let mut load: std::collections::BinaryHeap<std::cmp::Reverse<(u128, usize)>> = (0..count
        .max(1))
        .map(|i| std::cmp::Reverse((0, i)))
        .collect();
    let mut owner = vec![0usize; units.len()];
    for u in order {
        if let Some(std::cmp::Reverse((l, shard))) = load.pop() {
            load.push(std::cmp::Reverse((l + units[u].0.max(1), shard)));
            owner[u] = shard + 1;
        }
    }
    owner
}

/// The hash of a campaign as its shards see it: SHA-256 over its name, its axes, its plots and
/// the key of every run (each key covers the run's resolved scenario, engine and the
/// launcher's version). An edit that changes no run and no output (a comment) keeps it.
pub(super) fn campaign_hash(plan: &Plan) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    h.update(format!("campaign {}\n", plan.name));
    for a in &plan.axes {
        h.update(format!("axis {}\n", a.label));
    }
    h.update(format!("plots {:?}\n", plan.plots));
    for j in &plan.jobs {
        h.update(format!("run {} {} {}\n", j.point, j.key, j.label));
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// How a shard's run ended, or that it runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum State {
    Running,
    Finished,
    Failed,
    Interrupted,
}

impl State {
    /// `running`, `finished`, `failed`, `interrupted`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Running => "running",
            Self::Finished => "finished",
            Self::Failed => "failed",
            Self::Interrupted => "interrupted",
        }
    }
}

/// A run of the shard that failed.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Failure {
    pub run: String,
    pub key: String,
    pub error: String,
}

/// `shards/K-of-N.json`: what shard K of N is doing or did, written by that shard only.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Record {
    pub campaign: String,
    pub campaign_hash: String,
    /// The engine of its runs and the launcher's version: both are in every run's key.
    pub engine: String,
    pub launcher: String,
    pub shard: Shard,
    /// The runs the shard owns (runs of one key are one).
    pub runs: usize,
    pub jobs: usize,
    pub host: String,
    pub pid: u32,
    pub started_unix_s: f64,
    pub updated_unix_s: f64,
    pub state: State,
    pub ran: usize,
    pub skipped: usize,
    pub failures: Vec<Failure>,
}

/// Seconds since the Unix epoch by this machine's clock (shown, never compared across
/// machines).
pub fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

impl Record {
    pub fn path(out: &Path, shard: Shard) -> PathBuf {
        out.join(SHARDS).join(format!("{}.json", shard.stem()))
    }

    /// Writes the record whole.
    pub fn save(&mut self, out: &Path) -> Result<()> {
        self.updated_unix_s = unix_now();
        write_atomic(
            &Self::path(out, self.shard),
            (serde_json::to_string_pretty(self)? + "\n").as_bytes(),
        )
    }
}

/// Every shard record in `out/shards` (files named `K-of-N.json`), in shard order. A record
/// that cannot be read is left out with a warning naming it and why (its shard writes it anew
/// when it runs).
pub fn records(out: &Path) -> Result<Vec<Record>> {
    let dir = out.join(SHARDS);
    let entries = match std::fs::read_dir(&dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(anyhow!("reading {}: {e}", dir.display())),
    };
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry.with_context(|| format!("reading {}", dir.display()))?;
        let name = entry.file_name();
        let Some(stem) = name.to_str().and_then(|n| n.strip_suffix(".json")) else {
            continue;
        };
        let Some(shard) = parse_stem(stem) else {
            continue;
        };
        let path = entry.path();
        let read = std::fs::read_to_string(&path)
            .map_err(|e| e.to_string())
            .and_then(|t| serde_json::from_str::<Record>(&t).map_err(|e| e.to_string()));
        match read {
            Ok(r) if r.shard == shard => out.push(r),
            Ok(r) => log::warn!(
                "{} holds the record of shard {}, not of {shard}: left out",
                path.display(),
                r.shard
            ),
            Err(e) => log::warn!(
                "{} is not a shard record that can be read ({e}): left out (its shard writes it anew)",
                path.display()
            ),
        }
    }
    out.sort_by_key(|r| (r.shard.count, r.shard.index));
    Ok(out)
}

/// `K-of-N` as a shard.
fn parse_stem(stem: &str) -> Option<Shard> {
    let (k, n) = stem.split_once("-of-")?;
    Shard::new(k.parse().ok()?, n.parse().ok()?).ok()
}

/// What the records of a folder must say to be of this campaign.
pub struct Expected<'a> {
    pub hash: &'a str,
    pub engine: &'a str,
    /// The number of shards, where it is known.
    pub count: Option<usize>,
}

/// This launcher's version (`fdi-launch 0.1.0`), which is in every run's key.
pub fn launcher_version() -> String {
    format!("fdi-launch {}", env!("CARGO_PKG_VERSION"))
}

/// Refuses the records of a campaign other than this one: another engine, another launcher
/// version, another campaign (its hash differs), or a number of shards other than theirs.
pub fn check_records(records: &[Record], expected: &Expected, out: &Path) -> Result<()> {
    let short = |h: &str| h.chars().take(12).collect::<String>();
    for r in records {
        let path = Record::path(out, r.shard);
        if r.engine != expected.engine {
            bail!(
                "{} is the record of shard {}, whose runs are of --engine {}: give --engine {} (the engine is part of every run's key)",
                path.display(),
                r.shard,
                r.engine,
                r.engine
            );
        }
        if r.launcher != launcher_version() {
            bail!(
                "{} is the record of shard {}, run by {}; this is {}: every run's key holds the launcher's version, so the shards of a folder must all be run by one version",
                path.display(),
                r.shard,
                r.launcher,
                launcher_version()
            );
        }
        if r.campaign_hash != expected.hash {
            bail!(
                "{} was written by shard {} for another version of the campaign (hash {}…, this campaign's is {}…): its runs are not this campaign's. Run the campaign it was made with, or another --out (the results stored under points/ are kept by their keys: a new folder can take them)",
                path.display(),
                r.shard,
                short(&r.campaign_hash),
                short(expected.hash)
            );
        }
        if let Some(n) = expected.count.filter(|&n| n != r.shard.count) {
            bail!(
                "{} is the record of shard {}: this folder's campaign is cut in {} shards, not {n}. Every shard of a folder uses one N (to cut it anew, remove {})",
                path.display(),
                r.shard,
                r.shard.count,
                out.join(SHARDS).display()
            );
        }
    }
    Ok(())
}

/// The number of shards the records in `out` agree on (`None` when there is none).
pub fn count_of(records: &[Record], out: &Path) -> Result<Option<usize>> {
    let Some(first) = records.first() else {
        return Ok(None);
    };
    let expected = Expected {
        hash: &first.campaign_hash,
        engine: &first.engine,
        count: Some(first.shard.count),
    };
    check_records(records, &expected, out)?;
    Ok(Some(first.shard.count))
}

/// A process: its machine (host name, boot id), its pid namespace, pid and start time.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Holder {
    pub host: String,
    pub boot_id: String,
    /// `/proc/self/ns/pid`: containers on one machine may share its host name and boot id.
    pub pid_ns: String,
    pub pid: u32,
    /// The process's start time (`/proc/PID/stat` field 22): a pid used again is not it.
    pub start: String,
    /// Unique to this lease.
    pub token: String,
}

/// The host name of this machine.
pub fn host_name() -> String {
    read_trimmed("/proc/sys/kernel/hostname").unwrap_or_else(|| "unknown".into())
}

fn read_trimmed(path: &str) -> Option<String> {
    std::fs::read_to_string(path)
        .ok()
        .map(|s| s.trim().to_string())
}

fn start_of(pid: u32) -> Option<String> {
    fdi_runtime::process::procfs::stat(pid)
        .ok()?
        .field(22)
        .map(str::to_string)
}

impl Holder {
    fn me() -> Self {
        let pid = std::process::id();
        Self {
            host: host_name(),
            boot_id: read_trimmed("/proc/sys/kernel/random/boot_id").unwrap_or_default(),
            pid_ns: std::fs::read_link("/proc/self/ns/pid")
                .map(|p| p.display().to_string())
                .unwrap_or_default(),
            pid,
            start: start_of(pid).unwrap_or_default(),
            token: format!("{pid}-{}", unix_now()),
        }
    }

    /// Whether this holder is a process that this one can see, and it has ended (it is not
    /// there, another process has its pid, or it is a zombie). A holder whose machine or pid
    /// namespace is not this one's, or not known, is never judged gone from here.
    fn gone_from_here(&self, me: &Self) -> bool {
        let known = |a: &str, b: &str| !a.is_empty() && a != "unknown" && a == b;
        if !(known(&self.host, &me.host)
            && known(&self.boot_id, &me.boot_id)
            && known(&self.pid_ns, &me.pid_ns)
            && !self.start.is_empty())
        {
            return false;
        }
        let zombie =
            fdi_runtime::process::procfs::state(self.pid).is_ok_and(|s| matches!(s, 'Z' | 'X'));
        start_of(self.pid).as_deref() != Some(self.start.as_str()) || zombie
    }
}

/// The lease of a running shard (`shards/K-of-N.lease`): made by an exclusive create, renewed
/// every [`RENEW_EVERY`] through the file it created, removed when dropped. A lease found
/// taken over or removed is lost: [`Lease::lost`] says so, and the shard starts no more runs.
pub struct Lease {
    path: PathBuf,
    token: String,
    lost: Arc<AtomicBool>,
    stop: Option<mpsc::Sender<()>>,
    renewer: Option<std::thread::JoinHandle<()>>,
}

/// Why a lease could not be taken at once.
enum Held {
    /// By a live process: who, and how long ago it was renewed.
    Live(String, Duration),
}

impl Lease {
    /// Takes the lease of `shard` in `out`. A lease whose holder is gone (a process this one
    /// can see that ended, or a lease not renewed for [`STALE_AFTER`] by the file server's
    /// clock) is taken over, saying so. One held by a live copy of the shard is a refusal
    /// naming its holder; with `wait` (under a scheduler, where a retried task may start
    /// before its failed predecessor's lease is stale) it is waited for until it is stale,
    /// at most [`STALE_AFTER`] and a renewal, then refused.
    pub fn take(out: &Path, shard: Shard, wait: bool) -> Result<Self> {
        let dir = out.join(SHARDS);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = lease_path(out, shard);
        let me = Holder::me();
        let deadline = std::time::Instant::now() + STALE_AFTER + RENEW_EVERY;
        let mut said = false;
        loop {
            match Self::try_take(&path, &dir, shard, &me)? {
                Ok(lease) => return Ok(lease),
                Err(Held::Live(who, age)) => {
                    let refusal = format!(
                        "shard {shard} is being run by {who} (its lease {} was renewed {:.0} s ago): a second copy of a shard is refused. If that process is gone, its lease goes stale {} s after its last renewal, or remove the file",
                        path.display(),
                        age.as_secs_f64(),
                        STALE_AFTER.as_secs()
                    );
                    if !wait || std::time::Instant::now() >= deadline {
                        bail!(refusal);
                    }
                    if !said {
                        log::info!("{refusal}; waiting for it to go stale (--shard auto)");
                        said = true;
                    }
                    std::thread::sleep(Duration::from_secs(5));
                }
            }
        }
    }

    /// One attempt at the lease: taken, taken over from a holder that is gone, or held.
    fn try_take(
        path: &Path,
        dir: &Path,
        shard: Shard,
        me: &Holder,
    ) -> Result<std::result::Result<Self, Held>> {
        for _ in 0..3 {
            match create_new(path, me) {
                Ok(file) => {
                    return Ok(Ok(Self::renewed(
                        path.to_path_buf(),
                        me.token.clone(),
                        file,
                    )?))
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(anyhow!("creating {}: {e}", path.display())),
            }
            // Bytes, not text: a lease of any content is judged (one that is not UTF-8 too).
            let Ok(bytes) = std::fs::read(path) else {
                continue; // released since: try again
            };
            let held = serde_json::from_slice::<Holder>(&bytes).ok();
            let age = match lease_age(path, dir) {
                Ok(age) => age,
                Err(_) if !path.exists() => continue,
                Err(e) => return Err(e),
            };
            let why = match (&held, age) {
                (Some(h), _) if h.gone_from_here(me) => {
                    format!("its holder (pid {} on this host) is gone", h.pid)
                }
                (_, LeaseAge::Ago(d)) if d >= STALE_AFTER => {
                    format!("it was not renewed for {:.0} s", d.as_secs_f64())
                }
                (_, LeaseAge::Ahead(d)) if d >= STALE_AFTER => format!(
                    "its time is {:.0} s ahead of the file server's clock, which no renewal \
                     makes",
                    d.as_secs_f64()
                ),
                (Some(h), _) => {
                    return Ok(Err(Held::Live(
                        format!("pid {} on {}", h.pid, h.host),
                        age.since(),
                    )))
                }
                (None, _) => {
                    return Ok(Err(Held::Live(
                        "a process whose lease is being written or is not a lease".into(),
                        age.since(),
                    )))
                }
            };
            // Only the lease judged: another copy may have taken it over meanwhile.
            if std::fs::read(path).ok().as_deref() != Some(bytes.as_slice()) {
                continue;
            }
            log::info!(
                "shard {shard}: taking over the lease {}: {why}",
                path.display()
            );
            match std::fs::remove_file(path) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(anyhow!("removing {}: {e}", path.display())),
            }
        }
        bail!(
            "shard {shard}: the lease {} changed hands three times while it was taken: another copy of the shard is starting",
            path.display()
        )
    }

    /// The lease just made (`file`), with its renewing thread started.
    fn renewed(path: PathBuf, token: String, file: std::fs::File) -> Result<Self> {
        let (tx, rx) = mpsc::channel::<()>();
        let lost = Arc::new(AtomicBool::new(false));
        let (p, l) = (path.clone(), lost.clone());
        let renewer = std::thread::Builder::new()
            .name("lease".into())
            .spawn(move || {
                // Woken by the drop (or its sender going away), else every RENEW_EVERY.
                while let Err(mpsc::RecvTimeoutError::Timeout) = rx.recv_timeout(RENEW_EVERY) {
                    if let Err(e) = renew(&p, &file) {
                        log::info!("{e}; this shard starts no more runs");
                        l.store(true, Ordering::SeqCst);
                        break;
                    }
                }
            })
            .context("starting the thread that renews the shard's lease")?;
        Ok(Self {
            path,
            token,
            lost,
            stop: Some(tx),
            renewer: Some(renewer),
        })
    }

    /// Whether the lease was found taken over or removed.
    pub fn lost(&self) -> Arc<AtomicBool> {
        self.lost.clone()
    }
}

impl Drop for Lease {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(h) = self.renewer.take() {
            let _ = h.join();
        }
        // Only a lease that is still ours.
        if holds(&self.path, &self.token) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

fn holds(path: &Path, token: &str) -> bool {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<Holder>(&t).ok())
        .is_some_and(|h| h.token == token)
}

/// Creates `path` only if it does not exist, holding `who`, written and flushed; a file
/// created but not written is removed.
fn create_new(path: &Path, who: &Holder) -> std::io::Result<std::fs::File> {
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create_new(true)
        .open(path)?;
    let text = serde_json::to_string(who).map_err(std::io::Error::other)?;
    match f.write_all(text.as_bytes()).and_then(|()| f.sync_all()) {
        Ok(()) => Ok(f),
        Err(e) => {
            let _ = std::fs::remove_file(path);
            Err(e)
        }
    }
}

/// Renews the lease through `file`, the one this shard created, if `path` is still that file
/// (same device and inode): rewrites its first byte in place (its modification time is the
/// renewal) and flushes it.
fn renew(path: &Path, file: &std::fs::File) -> Result<()> {
    use std::os::unix::fs::{FileExt, MetadataExt};
    let lost = || {
        anyhow!(
            "the lease {} is no longer this shard's (taken over, or removed)",
            path.display()
        )
    };
    let ours = file
        .metadata()
        .with_context(|| format!("renewing {}", path.display()))?;
    let there = std::fs::metadata(path).map_err(|_| lost())?;
    if (ours.dev(), ours.ino()) != (there.dev(), there.ino()) {
        return Err(lost());
    }
    let mut first = [0u8; 1];
    file.read_exact_at(&mut first, 0)
        .and_then(|()| file.write_all_at(&first, 0))
        .and_then(|()| file.sync_all())
        .with_context(|| format!("renewing {}", path.display()))
}

/// Whether a shard's process is alive, by its lease.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Liveness {
    /// Its lease is held and renewed.
    Live,
    /// Its lease is stale, or its holder a process of this machine that is gone.
    Gone,
    /// It has no lease.
    Absent,
    /// Its lease's age cannot be measured here (the folder cannot be written).
    Unknown,
}

/// `out/shards/K-of-N.lease`: the lease of shard K of N.
fn lease_path(out: &Path, shard: Shard) -> PathBuf {
    out.join(SHARDS).join(format!("{}.lease", shard.stem()))
}

/// Whether shard `shard` of the campaign in `out` runs now.
pub fn liveness(out: &Path, shard: Shard) -> Liveness {
    let dir = out.join(SHARDS);
    let path = lease_path(out, shard);
    let Ok(bytes) = std::fs::read(&path) else {
        return Liveness::Absent;
    };
    if serde_json::from_slice::<Holder>(&bytes).is_ok_and(|h| h.gone_from_here(&Holder::me())) {
        return Liveness::Gone;
    }
    match lease_age(&path, &dir) {
        Ok(LeaseAge::Ago(d) | LeaseAge::Ahead(d)) if d >= STALE_AFTER => Liveness::Gone,
        Ok(_) => Liveness::Live,
        Err(_) if !path.exists() => Liveness::Absent,
        Err(_) => Liveness::Unknown,
    }
}

/// How long ago a lease was last written, by the clock of the file system that holds it; or
/// how far ahead of that clock its time is (a lease dated in the future: no renewal makes one,
/// so one far ahead is not a live lease, whatever the clock of its writer's machine).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LeaseAge {
    Ago(Duration),
    Ahead(Duration),
}

impl LeaseAge {
    /// How long ago it was renewed, for messages (0 for a lease dated ahead).
    fn since(self) -> Duration {
        match self {
            Self::Ago(d) => d,
            Self::Ahead(_) => Duration::ZERO,
        }
    }
}

/// How long ago `path` was last written, by the clock of the file system holding `dir`: the
/// difference of its modification time and that of a file written in `dir` now.
fn lease_age(path: &Path, dir: &Path) -> Result<LeaseAge> {
    let then = std::fs::metadata(path)
        .and_then(|m| m.modified())
        .with_context(|| format!("reading {}", path.display()))?;
    let probe = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("a file in {}", dir.display()))?;
    probe
        .as_file()
        .write_all(b"now")
        .with_context(|| format!("writing in {}", dir.display()))?;
    let now = probe
        .as_file()
        .metadata()
        .and_then(|m| m.modified())
        .with_context(|| format!("reading a file in {}", dir.display()))?;
    Ok(match now.duration_since(then) {
        Ok(ago) => LeaseAge::Ago(ago),
        Err(ahead) => LeaseAge::Ahead(ahead.duration()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| {
            vars.iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn shards_are_parsed_and_refused_out_of_range() {
        assert_eq!(
            "2/3".parse::<ShardArg>().expect("2/3"),
            ShardArg::Part(Shard { index: 2, count: 3 })
        );
        assert_eq!("auto".parse::<ShardArg>().expect("auto"), ShardArg::Auto);
        for (bad, says) in [
            ("4/3", "between 1 and N (3)"),
            ("0/3", "between 1 and N (3)"),
            ("1/0", "N must be between 1"),
            ("3", "give K/N"),
            ("a/3", "\"a\" is not a whole number"),
            ("-1/3", "is not a whole number"),
        ] {
            let e = format!("{:#}", bad.parse::<ShardArg>().expect_err(bad));
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn the_shard_comes_from_slurm_or_kubernetes() {
        let slurm = [
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "5"),
            ("SLURM_ARRAY_TASK_MAX", "9"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ];
        assert_eq!(
            Shard::from_env(&env(&slurm)).expect("slurm"),
            Shard { index: 2, count: 3 }
        );
        // A task sent again alone (`--array=2`) with N from FDI_SHARD_COUNT.
        let again = [
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_MIN", "2"),
            ("SLURM_ARRAY_TASK_MAX", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "1"),
            ("FDI_SHARD_COUNT", "3"),
        ];
        assert_eq!(
            Shard::from_env(&env(&again)).expect("slurm, one task again"),
            Shard { index: 2, count: 3 }
        );
        let k8s = [("JOB_COMPLETION_INDEX", "0"), ("FDI_SHARD_COUNT", "4")];
        assert_eq!(
            Shard::from_env(&env(&k8s)).expect("k8s"),
            Shard { index: 1, count: 4 }
        );
        let list = [
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "9"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ];
        for (vars, says) in [
            (&list[..], "not one range"),
            (&k8s[..1], "FDI_SHARD_COUNT is not set"),
            (
                &[("JOB_COMPLETION_INDEX", "4"), ("FDI_SHARD_COUNT", "4")][..],
                "between 1 and N",
            ),
            (
                &[("SLURM_ARRAY_TASK_ID", "x")][..],
                "SLURM_ARRAY_TASK_ID=\"x\"",
            ),
            (&[][..], "neither SLURM_ARRAY_TASK_ID"),
        ] {
            let e = format!("{:#}", Shard::from_env(&env(vars)).expect_err(says));
            assert!(e.contains(says), "{vars:?}: {e}");
        }
    }

    proptest::proptest! {
        /// Every unit has one shard in range; the dealing is the same whatever the order the
        /// units come in; and the totals of any two shards differ by at most the largest cost.
        #[test]
        fn dealing_is_deterministic_and_balanced(
            costs in proptest::collection::vec(0u128..1000, 0..60),
            count in 1usize..8,
            rotate in 0usize..60,
        ) {
            let keys: Vec<String> = (0..costs.len()).map(|i| format!("{i:04}")).collect();
            let units: Vec<(u128, &str)> =
                costs.iter().zip(&keys).map(|(c, k)| (*c, k.as_str())).collect();
            let owner = deal(&units, count);
            proptest::prop_assert!(owner.iter().all(|&o| (1..=count).contains(&o)));
            let mut turned = units.clone();
            turned.rotate_left(rotate.min(units.len()));
            let again = deal(&turned, count);
            for (u, o) in turned.iter().zip(&again) {
                let i = keys.iter().position(|k| k == u.1).expect("key");
                proptest::prop_assert_eq!(owner[i], *o);
            }
            let mut load = vec![0u128; count];
            for (u, o) in units.iter().zip(&owner) {
                load[o - 1] += u.0.max(1);
            }
            let largest = units.iter().map(|u| u.0.max(1)).max().unwrap_or(0);
            let (lo, hi) = (load.iter().min().copied().unwrap_or(0), load.iter().max().copied().unwrap_or(0));
            proptest::prop_assert!(hi - lo <= largest, "{load:?}, largest {largest}");
        }
    }

    #[test]
    fn a_lease_is_refused_to_a_second_copy_and_taken_over_from_a_gone_holder() {
        let dir = tempfile::tempdir().expect("dir");
        let shard = Shard { index: 1, count: 2 };
        let lease = Lease::take(dir.path(), shard, false).expect("first");
        let e = format!(
            "{:#}",
            Lease::take(dir.path(), shard, false).err().expect("second")
        );
        assert!(e.contains("a second copy of a shard is refused"), "{e}");
        drop(lease);
        assert!(!dir.path().join("shards/1-of-2.lease").exists());
        // A holder of this host that is gone: pid 1's start time is not this one.
        let mut gone = Holder::me();
        gone.start = "0".into();
        gone.pid = 1;
        drop(create_new(&dir.path().join("shards/1-of-2.lease"), &gone).expect("stale lease"));
        let taken = Lease::take(dir.path(), shard, false).expect("taken over");
        assert!(holds(&taken.path, &taken.token));
    }

    /// Regression (issue 51): a lease of random bytes 100 s old was never taken over ("changed
    /// hands three times": it was read as text, which failed, as if it had been released), and
    /// a lease dated a year ahead (written by a machine whose clock ran fast) blocked its shard
    /// until that date. Neither can be a live lease: both are taken over, saying why; one
    /// renewed a moment ago, or dated a few seconds ahead, is still refused.
    #[test]
    fn a_lease_that_cannot_be_live_is_taken_over_one_just_renewed_is_not() {
        let shard = Shard { index: 2, count: 3 };
        let day = Duration::from_secs(86_400);
        let now = SystemTime::now();
        for (content, mtime, taken) in [
            (
                vec![0xff, 0x00, 0x9c, 0xfe],
                now - Duration::from_secs(100),
                true,
            ),
            (b"{\"pid\":".to_vec(), now - Duration::from_secs(100), true),
            (vec![0xff, 0x00, 0x9c, 0xfe], now + 365 * day, true),
            (
                vec![0xff, 0x00, 0x9c, 0xfe],
                now - Duration::from_secs(5),
                false,
            ),
            (
                vec![0xff, 0x00, 0x9c, 0xfe],
                now + Duration::from_secs(5),
                false,
            ),
        ] {
            let dir = tempfile::tempdir().expect("dir");
            let path = lease_path(dir.path(), shard);
            std::fs::create_dir_all(path.parent().expect("shards/")).expect("shards/");
            std::fs::write(&path, &content).expect("lease");
            std::fs::File::options()
                .write(true)
                .open(&path)
                .and_then(|f| f.set_modified(mtime))
                .expect("mtime");
            let live = liveness(dir.path(), shard);
            match Lease::take(dir.path(), shard, false) {
                Ok(lease) => {
                    assert!(taken, "{content:?} at {mtime:?}: taken over");
                    assert!(holds(&lease.path, &lease.token));
                    assert_eq!(live, Liveness::Gone);
                }
                Err(e) => {
                    assert!(!taken, "{content:?} at {mtime:?}: {e:#}");
                    assert!(format!("{e:#}").contains("is not a lease"), "{e:#}");
                    assert_eq!(live, Liveness::Live);
                }
            }
        }
    }
}
