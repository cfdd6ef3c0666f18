//! Runs split over hosts (`fdi-launch run --hosts FILE`): the deployment file, which says
//! where each process runs and how each host is reached, and the messages the coordinating
//! host and each host's `fdi-launch serve` exchange (JSON over Zenoh queries and samples,
//! `fdi_net`). docs/multi-host.md is the user's guide.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context as _, Result};
use fdi_common::scenario::{self, Resolved};
use fdi_net::{check_endpoint, check_host_name, Layout, Link, Security};
use fdi_runtime::ipc::Wake;
use serde::{Deserialize, Serialize};

/// The deployment file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct DeploymentFile {
    /// The host `fdi-launch run` runs on: the launcher, and whatever is not placed elsewhere.
    coordinator: String,
    /// The folder of the lab's certificates (`fdi-launch certs`), relative to the file.
    #[serde(default)]
    certs: Option<String>,
    /// Plain TCP between the hosts, neither encrypted nor authenticated: only when said.
    #[serde(default)]
    insecure: bool,
    /// How long a run may make no progress before it is stopped, named (s).
    #[serde(default)]
    stall_timeout_s: Option<f64>,
    /// How long the coordinator waits for every other host's serve before it names those it
    /// does not hear (s).
    #[serde(default)]
    reach_timeout_s: Option<f64>,
    hosts: BTreeMap<String, HostFile>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct HostFile {
    /// Zenoh endpoint the host listens on: `quic/<address>:<port>` (`tcp/` when insecure).
    endpoint: String,
    /// Agents that run on this host.
    #[serde(default)]
    agents: Vec<u32>,
    /// Other processes that run on this host: `attacker`, `control-center`.
    #[serde(default)]
    roles: Vec<String>,
}

/// One host of a deployment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Host {
    pub name: String,
    pub endpoint: String,
}

/// The files of a host in a certificates folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CertFiles {
    pub ca: PathBuf,
    pub cert: PathBuf,
    pub key: PathBuf,
}

impl CertFiles {
    /// `ca.pem`, `<host>.pem` and `<host>.key` of `dir`.
    pub fn new(dir: &Path, host: &str) -> Self {
        Self {
            ca: dir.join("ca.pem"),
            cert: dir.join(format!("{host}.pem")),
            key: dir.join(format!("{host}.key")),
        }
    }
}

/// How the hosts of a deployment reach one another.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LabSecurity {
    /// TLS with mutual authentication, the certificates in this folder: `ca.pem`, and
    /// `<host>.pem` with `<host>.key` for each host (`fdi-launch certs`).
    Tls { certs: PathBuf },
    /// Plain TCP (`insecure = true`).
    Insecure,
}

/// The hosts of a deployment file and how they reach one another: what a serve reads of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lab {
    /// The file it was read from (for messages).
    pub source: String,
    pub coordinator: String,
    pub hosts: Vec<Host>,
    pub security: LabSecurity,
}

impl Lab {
    /// Reads the hosts of the deployment file `path` (its placements are not looked at).
    pub fn load(path: &Path) -> Result<Self> {
        Ok(Self::read(path)?.0)
    }

    fn read(path: &Path) -> Result<(Self, DeploymentFile)> {
        let text = scenario::read_limited(path)
            .map_err(|e| anyhow::anyhow!("the deployment file (--hosts): {e}"))?;
        let source = path.display().to_string();
        let file: DeploymentFile =
            toml::from_str(&text).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
        let base = path.parent().unwrap_or(Path::new("."));
        let lab = Self::check(&file, &source, base)?;
        Ok((lab, file))
    }

    /// Checks host names, endpoints and the security of `file`.
    fn check(file: &DeploymentFile, source: &str, base: &Path) -> Result<Self> {
        check_hosts_named(file, source)?;
        check_endpoints(file, source)?;
        Ok(Self {
            source: source.into(),
            coordinator: file.coordinator.clone(),
            hosts: file
                .hosts
                .iter()
                .map(|(name, h)| Host {
                    name: name.clone(),
                    endpoint: h.endpoint.clone(),
                })
                .collect(),
            security: lab_security(file, source, base)?,
        })
    }

    /// The host `name` of the file, or an error naming the file.
    pub fn host(&self, name: &str) -> Result<&Host> {
        self.hosts.iter().find(|h| h.name == name).ok_or_else(|| {
            anyhow::anyhow!(
                "{}: names no host `{name}` (its hosts: {})",
                self.source,
                self.hosts
                    .iter()
                    .map(|h| h.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
    }

    /// How host `name` opens its Zenoh session: with TLS, its certificate and key, the lab's
    /// CA, and the lab's hosts (checked to exist, and the certificates to be valid now, named
    /// otherwise; one that expires within 30 days is said on stderr).
    pub fn security_of(&self, name: &str) -> Result<Security> {
        match &self.security {
            LabSecurity::Insecure => Ok(Security::Insecure),
            LabSecurity::Tls { certs } => {
                let files = CertFiles::new(certs, name);
                for p in [&files.ca, &files.cert, &files.key] {
                    if !p.is_file() {
                        bail!(
                            "{}: `certs`: {} is missing on this host (make the \
                             certificates of the lab with `fdi-launch certs --hosts {}`, then \
                             copy ca.pem and the pair of this host here: docs/security.md)",
                            self.source,
                            p.display(),
                            self.source
                        );
                    }
                }
                let now = jiff::Timestamp::now().as_second();
                for p in [&files.ca, &files.cert] {
                    let checked = check_validity(p, now)
                        .with_context(|| format!("{}: `certs`", self.source))?;
                    if let Some(warning) = checked {
                        log::warn!("{warning}");
                    }
                }
                Ok(Security::Tls {
                    ca: files.ca,
                    cert: files.cert,
                    key: files.key,
                    lab: self.hosts.iter().map(|h| h.name.clone()).collect(),
                    peers: self.addresses()?,
                })
            }
        }
    }

    /// The addresses of the hosts' endpoints (a name resolved to each of its addresses): where
    /// the lab's QUIC packets come from.
    fn addresses(&self) -> Result<Vec<std::net::IpAddr>> {
        use std::net::ToSocketAddrs as _;
        let mut out = Vec::new();
        for h in &self.hosts {
            let address = fdi_net::endpoint_address(&h.endpoint).with_context(|| {
                format!(
                    "{}: host `{}`: endpoint {}",
                    self.source, h.name, h.endpoint
                )
            })?;
            let resolved = (address, 0).to_socket_addrs().with_context(|| {
                format!(
                    "{}: host `{}`: the address of endpoint {} cannot be resolved",
                    self.source, h.name, h.endpoint
                )
            })?;
            out.extend(resolved.map(|a| a.ip()));
        }
        out.sort();
        out.dedup();
        Ok(out)
    }

    /// Whether the hosts authenticate one another.
    pub fn authenticated(&self) -> bool {
        matches!(self.security, LabSecurity::Tls { .. })
    }
}

/// Where the processes of a split run are, checked against the scenario.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Deployment {
    /// Its hosts and how they reach one another (and the file it was read from).
    pub lab: Lab,
    pub coordinator: Host,
    /// The other hosts, each with a `fdi-launch serve`.
    pub others: Vec<Host>,
    /// Every process of the run (and the launcher) with its host.
    pub layout: Layout,
    /// How long the run may make no progress before it is stopped, named (None: the
    /// runtime's default).
    pub stall_timeout: Option<std::time::Duration>,
    /// How long the coordinator waits for the other hosts' serves
    /// ([`Deployment::REACH_TIMEOUT`] unless the file says).
    pub reach_timeout: std::time::Duration,
}

/// The process roles a deployment can place with `roles`.
const PLACEABLE: [(&str, Wake); 2] = [
    ("attacker", Wake::Attacker),
    (fdi_common::run_dir::Process::CENTER, Wake::Center),
];

impl Deployment {
    /// How long the coordinator waits for the other hosts' serves by default: longer than a
    /// serve can stay deaf to a new coordinator. A serve's Zenoh listener takes connections one
    /// handshake at a time, and a handshake whose client is gone holds it for QUIC's idle
    /// timeout (30 s): packets of a coordinator that died in a network cut, delivered once the
    /// network is back (issue 51), start such a handshake.
    pub const REACH_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(40);

    /// Reads and checks `path` against the run's scenario: every problem names the file and
    /// the field. The file is read as scenario files are ([`scenario::read_limited`]): a
    /// regular file of at most [`scenario::MAX_FILE_BYTES`], refused otherwise without reading
    /// beyond the limit.
    pub fn load(path: &Path, resolved: &Resolved) -> Result<Self> {
        let (lab, file) = Lab::read(path)?;
        Self::check(file, lab, resolved)
    }

    /// Checks a parsed deployment file against the scenario and lays out every process.
    fn check(file: DeploymentFile, lab: Lab, resolved: &Resolved) -> Result<Self> {
        let source = lab.source.as_str();
        let scenario_agents: BTreeSet<u32> =
            resolved.scenario.agents.iter().map(|a| a.id).collect();
        let mut host_of: BTreeMap<Wake, String> = BTreeMap::new();
        for (name, h) in &file.hosts {
            place_agents(name, h, &scenario_agents, &mut host_of, source)?;
            place_roles(name, h, &mut host_of, source)?;
        }
        // What is not placed runs on the coordinating host, with the launcher.
        let coordinator = file.coordinator.clone();
        place_the_rest(&coordinator, &scenario_agents, resolved, &mut host_of);
        check_external_roles_stay(&coordinator, &host_of, resolved, source)?;
        let layout = Layout::new(host_of, resolved);
        for name in file.hosts.keys() {
            fdi_net::plan(&layout, name).map_err(|e| problem(source, "hosts".into(), e))?;
        }
        let host = |name: &String| Host {
            name: name.clone(),
            endpoint: file.hosts[name].endpoint.clone(),
        };
        let others: Vec<Host> = file
            .hosts
            .keys()
            .filter(|n| **n != coordinator)
            .map(host)
            .collect();
        check_hosts_run_something(&others, &layout, source)?;
        let seconds = |field: &str, value: Option<f64>| match value {
            None => Ok(None),
            Some(t) if t.is_finite() && (1.0..=3600.0).contains(&t) => {
                Ok(Some(std::time::Duration::from_secs_f64(t)))
            }
            Some(t) => Err(problem(
                source,
                field.into(),
                format!("must be 1 to 3600 s, got {t}"),
            )),
        };
        let stall_timeout = seconds("stall_timeout_s", file.stall_timeout_s)?;
        let reach_timeout =
            seconds("reach_timeout_s", file.reach_timeout_s)?.unwrap_or(Self::REACH_TIMEOUT);
        Ok(Self {
            coordinator: host(&coordinator),
            lab: lab.clone(),
            stall_timeout,
            reach_timeout,
            others,
            layout,
        })
    }

    /// The host `wake` runs on.
    pub fn host_of(&self, wake: Wake) -> &str {
        self.layout
            .host_of
            .get(&wake)
            .map_or(self.coordinator.name.as_str(), String::as_str)
    }

    /// Whether `wake` runs on the coordinating host.
    pub fn is_local(&self, wake: Wake) -> bool {
        self.host_of(wake) == self.coordinator.name
    }
}

/// Checks every host's name and endpoint: unique, and of the link the file's security asks
/// for (`quic/`, or `tcp/` with `insecure = true`).
fn check_endpoints(file: &DeploymentFile, source: &str) -> Result<()> {
    let mut endpoints: BTreeMap<&str, &str> = BTreeMap::new();
    let want = if file.insecure { Link::Tcp } else { Link::Quic };
    for (name, h) in &file.hosts {
        check_host(name, h, &mut endpoints, source)?;
        let link = check_endpoint(&h.endpoint)
            .map_err(|e| problem(source, format!("hosts.{name}.endpoint"), e))?;
        if link != want {
            let why = if file.insecure {
                "the file says `insecure = true`: endpoints are `tcp/<address>:<port>`"
            } else {
                "hosts talk over QUIC with mutual TLS authentication unless the file says \
                 `insecure = true` (docs/security.md): endpoints are `quic/<address>:<port>`"
            };
            return Err(problem(
                source,
                format!("hosts.{name}.endpoint"),
                format!("`{}`: {why}", h.endpoint),
            ));
        }
    }
    Ok(())
}

/// How the hosts of `file` reach one another: its `certs` folder (relative to `base`, the
/// file's folder), or plain TCP when it says `insecure = true`; one of the two, said.
fn lab_security(file: &DeploymentFile, source: &str, base: &Path) -> Result<LabSecurity> {
    match (&file.certs, file.insecure) {
        (Some(_), true) => Err(problem(
            source,
            "insecure".into(),
            "the file names `certs` and says `insecure = true`: choose one".into(),
        )),
        (None, true) => Ok(LabSecurity::Insecure),
        (Some(dir), false) => Ok(LabSecurity::Tls {
            certs: base.join(dir),
        }),
        (None, false) => Err(problem(
            source,
            "certs".into(),
            format!(
                "missing: the hosts authenticate one another with the lab's certificates; make \
                 them with `fdi-launch certs --hosts {source}` and write `certs = \"certs\"`, or \
                 write `insecure = true` to run over plain TCP (docs/security.md)"
            ),
        )),
    }
}

/// A problem of the deployment file `source`, naming its `field`.
fn problem(source: &str, field: String, what: String) -> anyhow::Error {
    anyhow::anyhow!("{source}: `{field}`: {what}")
}

/// Checks that the coordinator is one of the hosts and that there are at least two hosts.
fn check_hosts_named(file: &DeploymentFile, source: &str) -> Result<()> {
    if !file.hosts.contains_key(&file.coordinator) {
        return Err(problem(
            source,
            "coordinator".into(),
            format!(
                "names `{}`, which is not one of the hosts ({})",
                file.coordinator,
                file.hosts.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        ));
    }
    if file.hosts.len() < 2 {
        return Err(problem(
            source,
            "hosts".into(),
            "names one host: a run on one host needs no deployment file".into(),
        ));
    }
    Ok(())
}

/// Checks host `name`'s name and endpoint, and that no other host has the same endpoint.
fn check_host<'a>(
    name: &'a str,
    h: &'a HostFile,
    endpoints: &mut BTreeMap<&'a str, &'a str>,
    source: &str,
) -> Result<()> {
    check_host_name(name).map_err(|e| problem(source, format!("hosts.{name}"), e))?;
    if let Some(other) = endpoints.insert(&h.endpoint, name) {
        return Err(problem(
            source,
            format!("hosts.{name}.endpoint"),
            format!("`{}` is also the endpoint of host `{other}`", h.endpoint),
        ));
    }
    Ok(())
}

/// Places host `name`'s agents, each an agent of the scenario placed on no other host.
fn place_agents(
    name: &str,
    h: &HostFile,
    scenario_agents: &BTreeSet<u32>,
    host_of: &mut BTreeMap<Wake, String>,
    source: &str,
) -> Result<()> {
    for (i, id) in h.agents.iter().enumerate() {
        let field = format!("hosts.{name}.agents[{i}]");
        if !scenario_agents.contains(id) {
            return Err(problem(
                source,
                field,
                format!(
                    "agent {id} is not an agent of the scenario (its agents: {})",
                    scenario_agents
                        .iter()
                        .map(u32::to_string)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        if let Some(other) = host_of.insert(Wake::Agent(*id), name.to_string()) {
            return Err(problem(
                source,
                field,
                format!("agent {id} is placed on `{other}` too"),
            ));
        }
    }
    Ok(())
}

/// Places host `name`'s roles, each a placeable role placed on no other host.
fn place_roles(
    name: &str,
    h: &HostFile,
    host_of: &mut BTreeMap<Wake, String>,
    source: &str,
) -> Result<()> {
    for (i, role) in h.roles.iter().enumerate() {
        let field = format!("hosts.{name}.roles[{i}]");
        let Some((_, wake)) = PLACEABLE.iter().find(|(n, _)| n == role) else {
            return Err(problem(
                source,
                field,
                format!("`{role}` is not a role that can be placed (`attacker`, `control-center`)"),
            ));
        };
        if let Some(other) = host_of.insert(*wake, name.to_string()) {
            return Err(problem(
                source,
                field,
                format!("`{role}` is placed on `{other}` too"),
            ));
        }
    }
    Ok(())
}

/// Places every process of the run not placed yet on the coordinating host.
fn place_the_rest(
    coordinator: &str,
    scenario_agents: &BTreeSet<u32>,
    resolved: &Resolved,
    host_of: &mut BTreeMap<Wake, String>,
) {
    let mut all = vec![Wake::Launcher, Wake::Center, Wake::Attacker];
    all.extend(scenario_agents.iter().map(|&id| Wake::Agent(id)));
    let roles = &resolved.scenario.roles;
    if roles.attacker.is_some() {
        all.push(Wake::ExternalAttacker);
    }
    if roles.monitor.is_some() {
        all.push(Wake::Monitor);
    }
    if roles.controller.is_some() {
        all.push(Wake::ExternalController);
    }
    for w in all {
        host_of.entry(w).or_insert_with(|| coordinator.to_string());
    }
}

/// With `[roles]` in the scenario, checks that the attacker and the control center stay on
/// the coordinating host.
fn check_external_roles_stay(
    coordinator: &str,
    host_of: &BTreeMap<Wake, String>,
    resolved: &Resolved,
    source: &str,
) -> Result<()> {
    if resolved.has_external_roles() {
        for (wake, role) in [
            (Wake::Attacker, "attacker"),
            (Wake::Center, fdi_common::run_dir::Process::CENTER),
        ] {
            if host_of[&wake] != coordinator {
                return Err(problem(
                    source,
                    format!("hosts.{}.roles", host_of[&wake]),
                    format!(
                        "the scenario has `[roles]` (programs that take a role run on the coordinating host, beside the attacker and the control center): `{role}` must stay on `{coordinator}`"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks that every host other than the coordinator runs at least one process.
fn check_hosts_run_something(others: &[Host], layout: &Layout, source: &str) -> Result<()> {
    for h in others {
        if !layout.host_of.values().any(|v| *v == h.name) {
            return Err(problem(
                source,
                format!("hosts.{}", h.name),
                "runs nothing: give it `agents` or `roles`, or leave it out".into(),
            ));
        }
    }
    Ok(())
}

/// A process's wake-up event as a word of the messages: `agent/3`, `attacker`, ...
pub fn wake_word(w: Wake) -> String {
    match w {
        Wake::Agent(id) => format!("agent/{id}"),
        Wake::Attacker => "attacker".into(),
        Wake::Center => "center".into(),
        Wake::Launcher => "launcher".into(),
        Wake::ExternalAttacker => "external-attacker".into(),
        Wake::Monitor => "monitor".into(),
        Wake::ExternalController => "external-controller".into(),
    }
}

/// [`wake_word`] read back.
pub fn parse_wake(word: &str) -> Result<Wake> {
    Ok(match word {
        "attacker" => Wake::Attacker,
        "center" => Wake::Center,
        "launcher" => Wake::Launcher,
        "external-attacker" => Wake::ExternalAttacker,
        "monitor" => Wake::Monitor,
        "external-controller" => Wake::ExternalController,
        w => match w.strip_prefix("agent/").map(str::parse::<u32>) {
            Some(Ok(id)) => Wake::Agent(id),
            _ => bail!("`{w}` names no process of a run"),
        },
    })
}

/// Puts `value` as JSON on `outbox`, best effort: the messages of a run's control plane that
/// nobody waits for (a line, an exit, a stop); a lost one is covered by the host's liveliness.
pub fn put_json(outbox: &fdi_net::NetOutbox, value: &impl Serialize) {
    if let Ok(body) = serde_json::to_vec(value) {
        let _ = outbox.put(&body);
    }
}

/// One process a serve runs: what both ends know it by, derived from its [`Process`] (never
/// taken from a request as a string).
///
/// [`Process`]: fdi_common::run_dir::Process
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RemoteProcess {
    pub process: fdi_common::run_dir::Process,
    /// `agent`, `attacker` or `control-center` (the role binary).
    pub role: &'static str,
    /// How messages name it: `agent 3`, ...
    pub label: String,
}

impl RemoteProcess {
    /// The process of a run that wakes on `wake`, if that process may run on a host other than
    /// the coordinating one (an agent, the attacker, the control center).
    pub fn of(wake: Wake) -> Option<Self> {
        use fdi_common::run_dir::Process;
        let (process, role) = match wake {
            Wake::Agent(id) => (Process::Agent(id), "agent"),
            Wake::Attacker => (Process::Attacker, Process::ATTACKER),
            Wake::Center => (Process::Center, Process::CENTER),
            Wake::Launcher | Wake::ExternalAttacker | Wake::Monitor | Wake::ExternalController => {
                return None
            }
        };
        let label = match process {
            Process::Agent(id) => format!("agent {id}"),
            _ => role.to_string(),
        };
        Some(Self {
            process,
            role,
            label,
        })
    }
}

/// Coordinator → serve: run your share of the run `prefix`. The serve derives which processes
/// are its share from `layout` (every process with its host).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunRequest {
    /// The fdi-mas version of the coordinator: both ends must run the same layouts.
    pub version: String,
    pub prefix: String,
    pub coordinator: String,
    /// The host asked.
    pub host: String,
    /// The run's scenario file as the coordinator wrote it.
    pub scenario: String,
    /// Every process of the run with its host ([`wake_word`], host name).
    pub layout: Vec<(String, String)>,
}

/// Serve → coordinator: the processes are started, their ports open on that host.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunReply {
    /// (label, pid on that host).
    pub pids: Vec<(String, u32)>,
    /// The coordinator's clock minus the host's, ns, and the round trip it was measured in.
    pub offset_ns: i64,
    pub rtt_ns: u64,
}

/// Serve → coordinator, during the run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum HostEvent {
    /// A line a process printed.
    Line { text: String },
    /// A process exited: its wait status, and how the serve describes its end.
    Exited {
        label: String,
        raw: i32,
        ended: String,
    },
    /// A process has been stopped (SIGSTOP) for too long.
    Stalled { label: String, text: String },
    /// The host cannot go on with the run (its bridge stopped).
    Failed { text: String },
    /// Its bridge refused `count` frames so far; the first is described.
    Refused { count: u64, first: String },
}

/// Coordinator → serve, during the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum HostCommand {
    /// SIGTERM to every process still running.
    Term,
    /// SIGKILL to every process still running.
    Kill,
}

/// Serve → coordinator, at the release of a run: what is left on that host.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Released {
    /// Files of the run removed.
    pub removed: usize,
    /// Files of the run that could not be removed.
    pub leftovers: Vec<String>,
    /// Payloads its bridge sent and received.
    pub sent: u64,
    pub received: u64,
    /// Frames its bridge refused, and the first, described.
    pub refused: u64,
    pub first_refusal: Option<String>,
}

/// A certificate's warning time: a split run says so when one expires within this many days.
pub const WARN_DAYS: i64 = 30;

/// Whether the certificate in the PEM file `path` is valid at `now` (Unix seconds): an error
/// naming the file and the date when it is not yet or no longer valid, or when the file holds no
/// certificate; a warning when it expires within [`WARN_DAYS`].
pub fn check_validity(path: &Path, now: i64) -> Result<Option<String>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let (_, pem) = x509_parser::pem::parse_x509_pem(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a certificate in PEM ({e})", path.display()))?;
    let cert = pem
        .parse_x509()
        .map_err(|e| anyhow::anyhow!("{}: not an X.509 certificate ({e})", path.display()))?;
    let (from, until) = (
        cert.validity().not_before.timestamp(),
        cert.validity().not_after.timestamp(),
    );
    let date = |t: i64| {
        jiff::Timestamp::from_second(t).map_or_else(|_| format!("{t} s"), |d| d.to_string())
    };
    let renew = if cert.is_ca() {
        "make a new lab CA: remove ca.pem, ca.key and every host's pair, run `fdi-launch certs \
         --hosts FILE` and give every host its new files (docs/security.md)"
    } else {
        "make a new one: remove it (and its key) and run `fdi-launch certs --hosts FILE` \
         (docs/security.md)"
    };
    if now < from {
        bail!(
            "{}: the certificate is valid only from {} (this host's clock says {}): {renew}, or \
             set the clock",
            path.display(),
            date(from),
            date(now)
        );
    }
    if now > until {
        bail!(
            "{}: the certificate expired on {}: {renew}",
            path.display(),
            date(until)
        );
    }
    let left = (until - now) / 86_400;
    Ok((left < WARN_DAYS).then(|| {
        format!(
            "{}: the certificate expires on {} (in {left} days): {renew}",
            path.display(),
            date(until)
        )
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> Resolved {
        fdi_common::scenario::paper().expect("paper")
    }

    fn check(text: &str) -> Result<Deployment> {
        let file: DeploymentFile = toml::from_str(text)?;
        let lab = Lab::check(&file, "hosts.toml", Path::new("lab"))?;
        Deployment::check(file, lab, &paper())
    }

    const SPLIT: &str = r#"
        coordinator = "control"
        insecure = true
        [hosts.control]
        endpoint = "tcp/10.0.0.1:7447"
        [hosts.cell-a]
        endpoint = "tcp/10.0.0.2:7447"
        agents = [1, 2]
        [hosts.cell-b]
        endpoint = "tcp/10.0.0.3:7447"
        agents = [3, 4]
    "#;

    #[test]
    fn unplaced_processes_run_on_the_coordinator() {
        let d = check(SPLIT).expect("valid");
        assert_eq!(d.host_of(Wake::Agent(1)), "cell-a");
        assert_eq!(d.host_of(Wake::Agent(4)), "cell-b");
        assert_eq!(d.host_of(Wake::Center), "control");
        assert_eq!(d.host_of(Wake::Attacker), "control");
        assert_eq!(d.host_of(Wake::Launcher), "control");
        assert_eq!(d.others.len(), 2);
    }

    #[test]
    fn every_problem_names_its_field() {
        for (text, field) in [
            (
                SPLIT.replace("\"control\"\n", "\"nowhere\"\n"),
                "`coordinator`",
            ),
            (
                SPLIT.replace("agents = [3, 4]", "agents = [3, 9]"),
                "`hosts.cell-b.agents[1]`",
            ),
            (
                SPLIT.replace("agents = [3, 4]", "agents = [2, 4]"),
                "`hosts.cell-b.agents[0]`",
            ),
            (
                SPLIT.replace("tcp/10.0.0.3:7447", "udp/10.0.0.3:7447"),
                "`hosts.cell-b.endpoint`",
            ),
            (
                SPLIT.replace("tcp/10.0.0.3:7447", "tcp/10.0.0.2:7447"),
                "`hosts.cell-b.endpoint`",
            ),
            (
                SPLIT.replace("agents = [3, 4]", "roles = [\"planner\"]"),
                "`hosts.cell-b.roles[0]`",
            ),
            (SPLIT.replace("agents = [3, 4]", ""), "`hosts.cell-b`"),
            (
                SPLIT.replace("tcp/10.0.0.3:7447", "quic/10.0.0.3:7447"),
                "`hosts.cell-b.endpoint`",
            ),
            (
                SPLIT
                    .replace("insecure = true", "")
                    .replace("tcp/", "quic/"),
                "`certs`: missing",
            ),
            (
                SPLIT.replace("insecure = true", "certs = \"c\"\ninsecure = true"),
                "`insecure`",
            ),
            (
                SPLIT.replace("insecure = true", "insecure = true\nstall_timeout_s = 0.1"),
                "`stall_timeout_s`",
            ),
        ] {
            let e = check(&text).expect_err(&text).to_string();
            assert!(e.contains(field), "{field} in {e}");
            assert!(e.starts_with("hosts.toml: "), "{e}");
        }
        assert!(check(&SPLIT.replace("agents = [1, 2]", "agent = [1, 2]")).is_err());
    }

    #[test]
    fn deployment_file_from_dev_zero_is_refused() {
        // `/dev/zero` never ends: it used to be read until memory ran out.
        let e = Deployment::load(Path::new("/dev/zero"), &paper())
            .expect_err("a device is not a deployment file")
            .to_string();
        assert!(
            e.contains("the deployment file (--hosts): /dev/zero is not a regular file")
                && e.contains("must be regular files of at most"),
            "{e}"
        );
        let dir = tempfile::tempdir().expect("temporary folder");
        let e = Deployment::load(dir.path(), &paper())
            .expect_err("a folder is not a deployment file")
            .to_string();
        assert!(e.contains("is not a regular file"), "{e}");
        let big = dir.path().join("hosts.toml");
        let mut text = SPLIT.to_string();
        while text.len() as u64 <= scenario::MAX_FILE_BYTES {
            text.push_str("# padding padding padding padding padding padding padding\n");
        }
        std::fs::write(&big, &text).expect("write the oversized file");
        let e = Deployment::load(&big, &paper())
            .expect_err("an oversized deployment file")
            .to_string();
        assert!(
            e.contains(&format!(
                "larger than the {} byte limit",
                scenario::MAX_FILE_BYTES
            )),
            "{e}"
        );
    }

    #[test]
    fn tls_is_the_default_and_each_host_finds_its_certificates_in_the_folder() {
        let text = SPLIT
            .replace("insecure = true", "certs = \"lab-certs\"")
            .replace("tcp/", "quic/");
        let d = check(&text).expect("valid");
        assert!(d.lab.authenticated());
        assert_eq!(
            d.lab.security,
            LabSecurity::Tls {
                certs: PathBuf::from("lab/lab-certs")
            }
        );
        // Not made yet: named with the command that makes them.
        let e = d
            .lab
            .security_of("cell-a")
            .expect_err("no files")
            .to_string();
        assert!(
            e.contains("lab/lab-certs/ca.pem is missing") && e.contains("fdi-launch certs"),
            "{e}"
        );
        assert_eq!(
            check(SPLIT)
                .expect("insecure")
                .lab
                .security_of("cell-a")
                .expect("insecure"),
            Security::Insecure
        );
    }

    #[test]
    fn wake_words_read_back() {
        for w in [
            Wake::Agent(12),
            Wake::Attacker,
            Wake::Center,
            Wake::Launcher,
            Wake::ExternalAttacker,
            Wake::Monitor,
        ] {
            assert_eq!(parse_wake(&wake_word(w)).expect("word"), w);
        }
        assert!(parse_wake("agent/x").is_err());
    }
}
