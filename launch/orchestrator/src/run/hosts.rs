//! Runs split over hosts (`fdi-launch run --hosts FILE`): the deployment file, which says
//! where each process runs and how each host is reached, and the messages the coordinating
//! host and each host's `fdi-launch serve` exchange (JSON over Zenoh queries and samples,
//! `fdi_runtime::net`). docs/multi-host.md is the user's guide.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use anyhow::{bail, Result};
use fdi_common::scenario::{self, Resolved};
use fdi_runtime::ipc::Wake;
use fdi_runtime::net::{check_endpoint, check_host_name, Layout};
use serde::{Deserialize, Serialize};

/// The deployment file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct DeploymentFile {
    /// The host `fdi-launch run` runs on: the launcher, and whatever is not placed elsewhere.
    coordinator: String,
    hosts: BTreeMap<String, HostFile>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct HostFile {
    /// Zenoh endpoint the host listens on: `tcp/<address>:<port>`.
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

/// Where the processes of a split run are, checked against the scenario.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Deployment {
    /// The file it was read from (for messages).
    pub source: String,
    pub coordinator: Host,
    /// The other hosts, each with a `fdi-launch serve`.
    pub others: Vec<Host>,
    /// Every process of the run (and the launcher) with its host.
    pub layout: Layout,
}

/// The process roles a deployment can place with `roles`.
const PLACEABLE: [(&str, Wake); 2] = [
    ("attacker", Wake::Attacker),
    (fdi_common::run_dir::Process::CENTER, Wake::Center),
];

impl Deployment {
    /// Reads and checks `path` against the run's scenario: every problem names the file and
    /// the field. The file is read as scenario files are ([`scenario::read_limited`]): a
    /// regular file of at most [`scenario::MAX_FILE_BYTES`], refused otherwise without reading
    /// beyond the limit.
    pub fn load(path: &Path, resolved: &Resolved) -> Result<Self> {
        let text = scenario::read_limited(path)
            .map_err(|e| anyhow::anyhow!("the deployment file (--hosts): {e}"))?;
        let source = path.display().to_string();
        let file: DeploymentFile =
            toml::from_str(&text).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
        Self::check(file, &source, resolved)
    }

    /// Checks a parsed deployment file against the scenario and lays out every process.
    fn check(file: DeploymentFile, source: &str, resolved: &Resolved) -> Result<Self> {
        check_hosts_named(&file, source)?;
        let scenario_agents: BTreeSet<u32> =
            resolved.scenario.agents.iter().map(|a| a.id).collect();
        let mut host_of: BTreeMap<Wake, String> = BTreeMap::new();
        let mut endpoints: BTreeMap<&str, &str> = BTreeMap::new();
        for (name, h) in &file.hosts {
            check_host(name, h, &mut endpoints, source)?;
            place_agents(name, h, &scenario_agents, &mut host_of, source)?;
            place_roles(name, h, &mut host_of, source)?;
        }
        // What is not placed runs on the coordinating host, with the launcher.
        let coordinator = file.coordinator.clone();
        place_the_rest(&coordinator, &scenario_agents, resolved, &mut host_of);
        check_external_roles_stay(&coordinator, &host_of, resolved, source)?;
        let layout = Layout::new(host_of, resolved);
        for name in file.hosts.keys() {
            fdi_runtime::net::plan(&layout, name)
                .map_err(|e| problem(source, "hosts".into(), e))?;
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
        Ok(Self {
            source: source.into(),
            coordinator: host(&coordinator),
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
    check_endpoint(&h.endpoint)
        .map_err(|e| problem(source, format!("hosts.{name}.endpoint"), e))?;
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
        w => match w.strip_prefix("agent/").map(str::parse::<u32>) {
            Some(Ok(id)) => Wake::Agent(id),
            _ => bail!("`{w}` names no process of a run"),
        },
    })
}

/// Puts `value` as JSON on `outbox`, best effort: the messages of a run's control plane that
/// nobody waits for (a line, an exit, a stop); a lost one is covered by the host's liveliness.
pub fn put_json(outbox: &fdi_runtime::net::NetOutbox, value: &impl Serialize) {
    if let Ok(body) = serde_json::to_vec(value) {
        let _ = outbox.put(&body);
    }
}

/// One process a serve is to run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RemoteProcess {
    /// `agent`, `attacker` or `control-center` (the role binary).
    pub role: String,
    /// Its trace's name: `agent-3`, ...
    pub name: String,
    pub agent: Option<u32>,
    /// How messages name it: `agent 3`, ...
    pub label: String,
}

/// Coordinator → serve: run these processes of run `prefix`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
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
    pub processes: Vec<RemoteProcess>,
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
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> Resolved {
        fdi_common::scenario::paper().expect("paper")
    }

    fn check(text: &str) -> Result<Deployment> {
        let file: DeploymentFile = toml::from_str(text)?;
        Deployment::check(file, "hosts.toml", &paper())
    }

    const SPLIT: &str = r#"
        coordinator = "control"
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
