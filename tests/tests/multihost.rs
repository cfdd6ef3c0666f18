//! Runs split over hosts (`fdi-launch run --hosts FILE`, `fdi-launch serve`), on "hosts" made
//! of network namespaces with their own shared memory (`fdi_tests::netns`): lockstep across
//! hosts equals the in-process engine, and a host cut off or a serve that dies is named (in
//! lockstep the run stops; in realtime its agents are lost and the rest finish), with nothing
//! left behind and the next run clean.
//!
//! These need root and iproute2; without them they say they are skipped, unless
//! `FDI_REQUIRE_NETNS` is set (CI), where they fail.

use std::path::PathBuf;
use std::process::{Child, Output, Stdio};
use std::time::{Duration, Instant};

use fdi_tests::netns::{self, Hosts};
use fdi_tests::{launcher, wait_with_watchdog, Scratch};

/// A few hosts, their serves, a scratch folder and the deployment file.
struct Lab {
    hosts: Hosts,
    serves: Vec<(Child, PathBuf)>,
    scratch: Scratch,
    file: Option<PathBuf>,
}

impl Lab {
    /// `n` hosts, or None (the test is skipped, said on stderr).
    fn new(n: usize, tag: &str) -> Option<Self> {
        match Hosts::create(n) {
            Ok(hosts) => Some(Self {
                hosts,
                serves: Vec::new(),
                scratch: Scratch::new(tag),
                file: None,
            }),
            Err(e) => {
                eprintln!("{}", netns::skip_reason(&e));
                None
            }
        }
    }

    /// Starts `fdi-launch serve --hosts FILE --name NAME` on host `i` (the deployment file
    /// written first) and waits until it listens.
    fn serve(&mut self, i: usize, name: &str) -> usize {
        let log = self.scratch.0.join(format!("serve-{name}.log"));
        let file = std::fs::File::create(&log).expect("serve log");
        let hosts = self
            .file
            .clone()
            .expect("the deployment file is written first");
        let work = self.scratch.0.join(format!("work-{name}"));
        let child = self
            .hosts
            .command(
                i,
                &launcher(),
                &[
                    "serve",
                    "--hosts",
                    &hosts.display().to_string(),
                    "--name",
                    name,
                    "--work-dir",
                    &work.display().to_string(),
                ],
            )
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(file)
            .spawn()
            .expect("spawning fdi-launch serve");
        self.serves.push((child, log));
        let k = self.serves.len() - 1;
        self.wait_log(k, "waiting for runs", Duration::from_secs(20));
        k
    }

    /// What serve `k` printed so far.
    fn log(&self, k: usize) -> String {
        std::fs::read_to_string(&self.serves[k].1).unwrap_or_default()
    }

    /// Waits until serve `k` printed `needle` (a watchdog, not a speed check).
    fn wait_log(&self, k: usize, needle: &str, limit: Duration) {
        let began = Instant::now();
        while !self.log(k).contains(needle) {
            assert!(
                began.elapsed() < limit,
                "serve {k} did not print `{needle}` within {limit:?}:\n{}",
                self.log(k)
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Writes the deployment file and, when it names `certs`, makes the lab's certificates
    /// with `fdi-launch certs`.
    fn deployment(&mut self, text: &str) -> String {
        let p = self.scratch.0.join("hosts.toml");
        std::fs::write(&p, text).expect("deployment file");
        if text.contains("certs = ") {
            let out = std::process::Command::new(launcher())
                .args(["certs", "--hosts", &p.display().to_string()])
                .output()
                .expect("fdi-launch certs");
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        self.file = Some(p.clone());
        p.display().to_string()
    }

    /// Starts `fdi-launch ARGS --out <scratch>/runs` on the coordinating host (host 0).
    fn start(&self, args: &[&str]) -> Child {
        let out = self.scratch.0.join("runs");
        let mut all: Vec<&str> = args.to_vec();
        let out = out.display().to_string();
        all.extend(["--out", &out]);
        self.hosts
            .command(0, &launcher(), &all)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawning fdi-launch run")
    }

    fn run(&self, args: &[&str]) -> Output {
        wait_with_watchdog(self.start(args), Duration::from_secs(120))
    }
}

impl Drop for Lab {
    fn drop(&mut self) {
        for (child, _) in &mut self.serves {
            let _ = child.kill();
            let _ = child.wait();
        }
        // A failed test shows what the serves said.
        if std::thread::panicking() {
            for k in 0..self.serves.len() {
                eprintln!("serve {k}:\n{}", self.log(k));
            }
        }
    }
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The digest a run printed.
fn digest(out: &Output) -> String {
    assert!(
        out.status.success(),
        "run failed ({}):\n{}",
        out.status,
        stderr(out)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    text.lines()
        .find_map(|l| l.strip_prefix("trace digest "))
        .unwrap_or_else(|| panic!("no digest in:\n{text}"))
        .trim()
        .to_string()
}

/// The digest of the in-process engine on one host, for the run `args`.
fn inproc_digest(args: &[&str]) -> String {
    let s = Scratch::new("multihost-inproc");
    let mut all = vec!["run", "--engine", "inproc"];
    all.extend(args);
    digest(&fdi_tests::launch(&all, &s.0, Duration::from_secs(120)))
}

const TWO_HOSTS: &str = r#"
coordinator = "control"
certs = "certs"
[hosts.control]
endpoint = "quic/10.77.0.1:7447"
[hosts.cell]
endpoint = "quic/10.77.0.2:7447"
agents = [3, 4]
"#;

/// The endpoints of both hosts of [`insecure_two_hosts`], for a rogue that connects to each.
const BOTH_HOSTS: &str = "tcp/10.77.0.1:7447,tcp/10.77.0.2:7447";

/// [`TWO_HOSTS`] over plain TCP.
fn insecure_two_hosts() -> String {
    TWO_HOSTS
        .replace("certs = \"certs\"", "insecure = true")
        .replace("quic/", "tcp/")
}

#[test]
fn lockstep_over_three_hosts_equals_the_in_process_engine() {
    let Some(mut lab) = Lab::new(3, "multihost-three") else {
        return;
    };
    // The agents 3 and 4 on a cell, the attacker on a host of its own: every stream of the
    // run crosses the network at least once.
    let file = lab.deployment(
        r#"
coordinator = "control"
certs = "certs"
[hosts.control]
endpoint = "quic/10.77.0.1:7447"
[hosts.cell]
endpoint = "quic/10.77.0.2:7447"
agents = [3, 4]
[hosts.adversary]
endpoint = "quic/10.77.0.3:7447"
roles = ["attacker"]
"#,
    );
    let cell = lab.serve(1, "cell");
    let adversary = lab.serve(2, "adversary");
    // An attack on the torques too: the attacker, on its host, forges them for the agents.
    let out = lab.run(&[
        "run",
        "--hosts",
        &file,
        "--duration-s",
        "2",
        "--attack",
        "actuator-bias",
    ]);
    assert_eq!(
        digest(&out),
        inproc_digest(&["--duration-s", "2", "--attack", "actuator-bias"]),
        "{}",
        stderr(&out)
    );
    std::fs::remove_dir_all(lab.scratch.0.join("runs")).expect("removing the first run");
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "3"]);
    assert_eq!(
        digest(&out),
        inproc_digest(&["--duration-s", "3"]),
        "{}",
        stderr(&out)
    );
    let err = stderr(&out);
    assert!(
        err.contains("host `cell` (quic/10.77.0.2:7447): agent 3, agent 4"),
        "{err}"
    );
    assert!(
        err.contains("host `adversary` (quic/10.77.0.3:7447): attacker"),
        "{err}"
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("network path: TLS with mutual authentication and per-host access control; no frame refused"),
        "{text}"
    );
    assert!(!err.contains("could not be removed"), "{err}");
    for k in [cell, adversary] {
        lab.wait_log(k, "nothing is left on this host", Duration::from_secs(10));
    }
    // The serve's release line says what its bridge carried each way, and why the two counts
    // differ (issue 33): the cell sends its agents' measurements, takes in their torques.
    let log = lab.log(cell);
    assert!(
        log.contains("payloads to the other hosts (on fdi/measurement, fdi/status")
            && log.contains("(on fdi/control, fdi/torque/3, fdi/torque/4)")
            && log.contains("the two counts are of different services, so they need not match"),
        "{log}"
    );
    // The run directory holds the whole run: the remote processes' traces were fetched. Its
    // name says the run was split (issue 33).
    let runs = lab.scratch.0.join("runs");
    let dir = std::fs::read_dir(&runs)
        .expect("runs")
        .flatten()
        .next()
        .expect("a run directory")
        .path();
    assert!(
        dir.to_string_lossy().ends_with("-paper-3s-hosts"),
        "{}",
        dir.display()
    );
    for name in ["agent-3", "agent-4", "attacker"] {
        let t = fdi_common::run_dir::RunDir::new(&dir)
            .traces()
            .join(format!("{name}.trace"));
        assert!(
            t.metadata().is_ok_and(|m| m.len() > 0),
            "{} missing",
            t.display()
        );
    }
}

/// Starts a run and cuts host 1 off once it has run for a while; returns the run's output and
/// how long after the cut it ended.
fn cut_mid_run(lab: &Lab, args: &[&str], after: Duration) -> (Output, Duration) {
    let child = lab.start(args);
    std::thread::sleep(after);
    lab.hosts.set_link(1, false);
    let cut = Instant::now();
    let out = wait_with_watchdog(child, Duration::from_secs(120));
    (out, cut.elapsed())
}

#[test]
fn a_cut_network_stops_a_lockstep_run_naming_the_host_and_the_next_run_is_clean() {
    let Some(mut lab) = Lab::new(2, "multihost-cut") else {
        return;
    };
    let file = lab.deployment(TWO_HOSTS);
    let cell = lab.serve(1, "cell");
    // Long enough to be cut in the middle: 40 simulated seconds take seconds across hosts.
    let (out, after) = cut_mid_run(
        &lab,
        &["run", "--hosts", &file, "--duration-s", "400"],
        Duration::from_secs(2),
    );
    let err = stderr(&out);
    eprintln!("ended {:.1} s after the cut:\n{err}", after.as_secs_f64());
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(
            "run stopped: host `cell` (quic/10.77.0.2:7447) is unreachable: its `fdi-launch \
             serve` died or the network to it was cut"
        ),
        "{err}"
    );
    assert!(err.contains("it ran agent 3, agent 4"), "{err}");
    // The serve notices the coordinator gone, stops its processes and removes their files.
    lab.wait_log(
        cell,
        "the coordinator `control` is unreachable",
        Duration::from_secs(20),
    );
    lab.wait_log(
        cell,
        "nothing is left on this host",
        Duration::from_secs(10),
    );
    let log = lab.log(cell);
    assert!(log.contains("stopped agent 3, agent 4"), "{log}");
    // Back on the network, the same serve takes the next run, which is clean. (Packets of the
    // dead coordinator, queued while its host looked for `cell`'s address, may reach the serve
    // once the link is back and hold its listener for up to QUIC's 30 s idle timeout: the
    // coordinator's wait for the serve, 40 s, rides it out; issue 51.)
    lab.hosts.set_link(1, true);
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "1"]);
    assert_eq!(
        digest(&out),
        inproc_digest(&["--duration-s", "1"]),
        "{}",
        stderr(&out)
    );
}

#[test]
fn a_cut_network_in_realtime_loses_the_hosts_agents_and_the_others_finish() {
    let Some(mut lab) = Lab::new(2, "multihost-rt-cut") else {
        return;
    };
    let file = lab.deployment(TWO_HOSTS);
    let cell = lab.serve(1, "cell");
    let (out, _) = cut_mid_run(
        &lab,
        &[
            "run",
            "--hosts",
            &file,
            "--clock",
            "realtime",
            "--duration-s",
            "6",
            "--json",
        ],
        Duration::from_millis(2500),
    );
    let err = stderr(&out);
    eprintln!("{err}");
    assert_eq!(out.status.code(), Some(3), "lost agents: exit 3\n{err}");
    assert!(
        err.contains("host `cell` (quic/10.77.0.2:7447) is unreachable")
            && err.contains("its agents are lost, the run goes on"),
        "{err}"
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .expect("JSON");
    let v: serde_json::Value = serde_json::from_str(line).expect("JSON");
    // In the order they were declared lost (by time): either may be first.
    let mut lost: Vec<u64> = v["lost_agents"]
        .as_array()
        .expect("lost agents")
        .iter()
        .filter_map(|l| l["agent"].as_u64())
        .collect();
    lost.sort_unstable();
    assert_eq!(lost, vec![3, 4], "{v}");
    for l in v["lost_agents"].as_array().into_iter().flatten() {
        let reason = l["reason"].as_str().unwrap_or_default();
        assert!(reason.contains("host `cell`"), "{reason}");
    }
    // The agents on the coordinating host were controlled to the end.
    for robot in ["1", "2"] {
        let m = &v["metrics"][robot];
        assert_eq!(m["ticks"], v["planned_ticks"], "robot {robot}: {m}");
        assert_eq!(m["uncontrolled_ticks"], 0, "robot {robot}: {m}");
    }
    lab.wait_log(
        cell,
        "nothing is left on this host",
        Duration::from_secs(20),
    );
}

#[test]
fn a_serve_that_dies_stops_a_lockstep_run_naming_its_host() {
    let Some(mut lab) = Lab::new(2, "multihost-serve-dies") else {
        return;
    };
    let file = lab.deployment(TWO_HOSTS);
    lab.serve(1, "cell");
    let mut child = lab.start(&["run", "--hosts", &file, "--duration-s", "400"]);
    std::thread::sleep(Duration::from_secs(2));
    let (serve, _) = &mut lab.serves[0];
    serve.kill().expect("SIGKILL to the serve");
    let _ = serve.wait();
    let began = Instant::now();
    while child.try_wait().expect("poll").is_none() && began.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = wait_with_watchdog(child, Duration::from_secs(10));
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("host `cell` (quic/10.77.0.2:7447) is unreachable")
            || err.contains("on host `cell`"),
        "the host is named:\n{err}"
    );
    // The killed serve left its run's work folder; the next serve removes it at its start.
    let work = lab.scratch.0.join("work-cell");
    let left = || std::fs::read_dir(&work).map(|d| d.count()).unwrap_or(0);
    assert_eq!(left(), 1, "the killed serve's run folder");
    let k = lab.serve(1, "cell");
    let log = lab.log(k);
    assert!(log.contains("left by a serve that is gone"), "{log}");
    assert_eq!(left(), 0, "removed:\n{log}");
}

/// The two-host deployment whose coordinator waits `seconds` for the serves.
fn two_hosts_reached_within(seconds: u32) -> String {
    TWO_HOSTS.replace(
        "certs = \"certs\"",
        &format!("certs = \"certs\"\nreach_timeout_s = {seconds}"),
    )
}

#[test]
fn a_host_without_a_serve_is_named_before_anything_starts() {
    let Some(mut lab) = Lab::new(2, "multihost-no-serve") else {
        return;
    };
    // The wait for the serves, shortened by the file (its default, 40 s, rides out a serve
    // that is deaf for a while after a cut network).
    let file = lab.deployment(&two_hosts_reached_within(6));
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "1"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(
            "no `fdi-launch serve` answers on host `cell` (quic/10.77.0.2:7447) within 6 s"
        ) && err.contains("fdi-launch: waiting for the serve of host `cell` (at most 6 s"),
        "{err}"
    );
    // Nothing started, nothing recorded: no run directory is left.
    let runs = lab.scratch.0.join("runs");
    let left = std::fs::read_dir(&runs).map(|d| d.count()).unwrap_or(0);
    assert_eq!(left, 0, "no run directory for a run that did not start");
}

/// The rogue test peer (`tests/src/bin/fdi-rogue.rs`), built beside the launcher.
fn rogue() -> PathBuf {
    launcher().with_file_name("fdi-rogue")
}

impl Lab {
    /// Runs the rogue on host `i` to its end; its stdout.
    fn rogue(&self, i: usize, args: &[&str]) -> String {
        wait_rogue(self.start_rogue(i, args))
    }

    /// Starts the rogue on host `i`; it is waited for with [`wait_rogue`].
    fn start_rogue(&self, i: usize, args: &[&str]) -> Child {
        self.hosts
            .command(i, &rogue(), args)
            .current_dir(&self.scratch.0)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawning fdi-rogue")
    }

    /// The prefixes of the runs serve `k` started so far (from its log).
    fn started(&self, k: usize) -> Vec<String> {
        self.log(k)
            .lines()
            .filter_map(|l| {
                l.strip_prefix("fdi-launch serve: run ")
                    .filter(|rest| rest.contains(": started "))
                    .and_then(|rest| rest.split(' ').next())
                    .map(str::to_string)
            })
            .collect()
    }

    /// The prefix of the next run serve `k` starts, after the `before` it started already.
    fn next_run_prefix(&self, k: usize, before: usize) -> String {
        let began = Instant::now();
        loop {
            if let Some(p) = self.started(k).get(before) {
                return p.clone();
            }
            assert!(
                began.elapsed() < Duration::from_secs(60),
                "serve {k} started no run:\n{}",
                self.log(k)
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Waits for a rogue to end; its stdout.
fn wait_rogue(child: Child) -> String {
    let out = wait_with_watchdog(child, Duration::from_secs(60));
    assert!(out.status.success(), "fdi-rogue: {}", stderr(&out));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// With QUIC and the lab's certificates (the default), a rogue peer on a third host gets
/// nowhere: without a certificate it cannot connect, with a certificate of another CA it is
/// refused, and with a valid certificate of a host that is not in the lab everything it
/// sends is denied; 200 sockets spraying garbage datagrams at the serve's port change
/// nothing. The run, fed by none of it, equals the in-process engine.
#[test]
fn quic_keeps_rogue_peers_out_and_the_run_equals_the_in_process_engine() {
    let Some(mut lab) = Lab::new(3, "multihost-rogues") else {
        return;
    };
    let file = lab.deployment(TWO_HOSTS);
    // A certificate of the lab's CA for a host the lab does not list, and one of another CA
    // that claims to be `cell`.
    for (name, text) in [
        (
            "rogue.toml",
            "coordinator = \"control\"\ncerts = \"certs\"\n[hosts.control]\nendpoint = \
             \"quic/10.77.0.1:7447\"\n[hosts.rogue]\nendpoint = \"quic/10.77.0.3:7447\"\n",
        ),
        (
            "other.toml",
            "coordinator = \"control\"\ncerts = \"other\"\n[hosts.control]\nendpoint = \
             \"quic/10.77.0.1:7447\"\n[hosts.cell]\nendpoint = \"quic/10.77.0.2:7447\"\n",
        ),
    ] {
        let p = lab.scratch.0.join(name);
        std::fs::write(&p, text).expect("a deployment file");
        let out = std::process::Command::new(launcher())
            .args(["certs", "--hosts", &p.display().to_string()])
            .output()
            .expect("fdi-launch certs");
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let cell = lab.serve(1, "cell");
    let mut spray = lab.start_rogue(2, &["hold", "200", "10.77.0.2:7447", "20", "udp"]);
    let run = lab.start(&["run", "--hosts", &file, "--duration-s", "30"]);
    let prefix = lab.next_run_prefix(cell, 0);
    let rogues = [
        lab.start_rogue(2, &["no-cert", "certs/ca.pem", "quic/10.77.0.2:7447", "3"]),
        lab.start_rogue(
            2,
            &[
                "--tls",
                "other/ca.pem",
                "other/cell.pem",
                "other/cell.key",
                "quic/10.77.0.2:7447",
                "impersonate",
                "cell",
                &prefix,
                "3",
            ],
        ),
        lab.start_rogue(
            2,
            &[
                "--tls",
                "certs/ca.pem",
                "certs/rogue.pem",
                "certs/rogue.key",
                "quic/10.77.0.1:7447,quic/10.77.0.2:7447",
                "impersonate",
                "cell",
                &prefix,
                "3",
            ],
        ),
    ];
    let said: Vec<String> = rogues.into_iter().map(wait_rogue).collect();
    assert!(said[0].contains("a serve seen: false"), "{}", said[0]);
    for s in &said[1..] {
        assert!(s.contains("the serve of `cell` seen: false"), "{s}");
        assert!(!s.starts_with("put 0 frames"), "{s}");
    }
    let out = wait_with_watchdog(run, Duration::from_secs(120));
    assert_eq!(
        digest(&out),
        inproc_digest(&["--duration-s", "30"]),
        "{}",
        stderr(&out)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("network path: TLS with mutual authentication and per-host access control; no frame refused"),
        "{text}"
    );
    let _ = spray.kill();
    let _ = spray.wait();
    // The positive control: the same rogue with `cell`'s own key is let in (which is why a
    // host's key stays on that host), from an address of the lab (issue 51: from any other,
    // the serve's socket does not even take its packets).
    let s = lab.rogue(
        0,
        &[
            "--tls",
            "certs/ca.pem",
            "certs/cell.pem",
            "certs/cell.key",
            "quic/10.77.0.2:7447",
            "impersonate",
            "cell",
            "none",
            "1",
        ],
    );
    assert!(s.contains("the serve of `cell` seen: true"), "{s}");
}

/// A run request as JSON, with `edit` applied to it.
fn request_file(lab: &Lab, name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let scenario = fdi_common::scenario::PAPER_SCENARIO.to_string();
    let mut v = serde_json::json!({
        "version": env!("CARGO_PKG_VERSION"),
        "prefix": "rogue1",
        "coordinator": "control",
        "host": "cell",
        "scenario": scenario,
        "layout": [
            ["launcher", "control"], ["center", "control"], ["attacker", "control"],
            ["agent/1", "control"], ["agent/2", "control"], ["agent/3", "cell"],
            ["agent/4", "cell"]
        ],
    });
    edit(&mut v);
    let p = lab.scratch.0.join(name);
    std::fs::write(&p, serde_json::to_vec(&v).expect("JSON")).expect("request file");
    name.to_string()
}

/// Regression (issue 51): a flood of datagrams shaped like QUIC connection openers from a
/// machine without a certificate (200 sockets, 2000 a second) kept every split run out for its
/// length and 20-60 s after: Zenoh's QUIC listener took each for a connection and paused a
/// tenth of a second after each failed one. The hosts take QUIC packets only from the addresses
/// of the deployment file: a run gets through during the flood and right after it.
#[test]
fn a_quic_initial_flood_from_outside_the_lab_keeps_no_run_out() {
    let Some(mut lab) = Lab::new(3, "multihost-flood") else {
        return;
    };
    // The serve must answer within 5 s, in the flood and right after it.
    let file = lab.deployment(&two_hosts_reached_within(5));
    lab.serve(1, "cell");
    let expected = inproc_digest(&["--duration-s", "1"]);
    let flood = lab.start_rogue(2, &["flood", "200", "10.77.0.2:7447", "12", "2000"]);
    // During the flood: the flood runs for 12 s, the run starts at once.
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "1"]);
    assert_eq!(digest(&out), expected, "{}", stderr(&out));
    let said = wait_rogue(flood);
    assert!(said.starts_with("sent "), "{said}");
    // Right after it.
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "1"]);
    assert_eq!(digest(&out), expected, "{}", stderr(&out));
}

/// Regression (issue 51): a host of the lab that is not its coordinator (here the attacker's,
/// with its own valid certificate) asked `cell`'s serve to start agents 3 and 4, naming itself
/// coordinator, and held the robots' host: the real coordinator was told "host `cell` is busy".
/// The serve takes run requests only from the file's coordinator; the refusal is answered and
/// written in the serve's log, and the coordinator's run goes through.
#[test]
fn a_host_that_is_not_the_coordinator_cannot_take_the_robots_host() {
    let Some(mut lab) = Lab::new(3, "multihost-takeover") else {
        return;
    };
    let file = lab.deployment(
        r#"
coordinator = "control"
certs = "certs"
[hosts.control]
endpoint = "quic/10.77.0.1:7447"
[hosts.cell]
endpoint = "quic/10.77.0.2:7447"
agents = [3, 4]
[hosts.adversary]
endpoint = "quic/10.77.0.3:7447"
roles = ["attacker"]
"#,
    );
    let cell = lab.serve(1, "cell");
    let request = request_file(&lab, "takeover.json", |v| {
        v["coordinator"] = serde_json::json!("adversary");
        v["layout"] = serde_json::json!([
            ["launcher", "adversary"],
            ["center", "adversary"],
            ["attacker", "adversary"],
            ["agent/1", "adversary"],
            ["agent/2", "adversary"],
            ["agent/3", "cell"],
            ["agent/4", "cell"]
        ]);
    });
    let s = lab.rogue(
        2,
        &[
            "--tls",
            "certs/ca.pem",
            "certs/adversary.pem",
            "certs/adversary.key",
            "quic/10.77.0.2:7447",
            "request",
            "cell",
            "adversary",
            &request,
        ],
    );
    let why = "a run request came from `adversary`, which";
    assert!(
        s.starts_with("refused:") && s.contains(why) && s.contains("(`control`)"),
        "{s}"
    );
    lab.wait_log(cell, why, Duration::from_secs(10));
    assert!(
        !lab.log(cell).contains("started agent"),
        "{}",
        lab.log(cell)
    );
    // The coordinator's run is not told the host is busy.
    lab.serve(2, "adversary");
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "1"]);
    assert_eq!(
        digest(&out),
        inproc_digest(&["--duration-s", "1"]),
        "{}",
        stderr(&out)
    );
}

/// Over plain TCP (said so by the file), what a rogue peer sends is refused, counted and
/// named: run requests that carry paths, programs, processes no run has or sizes no run needs
/// are refused before anything is written, a trace asked by a path is refused, 200 idle or
/// half-open connections do not keep a run out, a forged frame numbered ahead stops a lockstep
/// run within the stall timeout, naming the refused frames, and a realtime run whose stream
/// was biased by 1200 forged frames refuses them, says so in its summary and exits 6.
#[test]
fn an_insecure_run_refuses_names_and_counts_what_a_rogue_peer_sends() {
    let Some(mut lab) = Lab::new(3, "multihost-insecure") else {
        return;
    };
    let text =
        insecure_two_hosts().replace("insecure = true", "insecure = true\nstall_timeout_s = 3");
    let file = lab.deployment(&text);
    let cell = lab.serve(1, "cell");
    let to_cell = "tcp/10.77.0.2:7447";
    // Run requests: each refused, with why.
    let big = "#".repeat(2 << 20);
    for (name, edit, why) in [
        (
            "paths.json",
            Box::new(|v: &mut serde_json::Value| {
                v["processes"] =
                    serde_json::json!([{"role": "launch", "name": "../../../../tmp/x"}]);
            }) as Box<dyn FnOnce(&mut serde_json::Value)>,
            "unknown field `processes`",
        ),
        (
            "word.json",
            Box::new(|v: &mut serde_json::Value| {
                v["layout"][6] = serde_json::json!(["../../tmp/x", "cell"]);
            }),
            "names no process of a run",
        ),
        (
            "launcher.json",
            Box::new(|v: &mut serde_json::Value| {
                v["layout"][0] = serde_json::json!(["launcher", "cell"]);
            }),
            "does not put the launcher on its coordinator",
        ),
        (
            "many.json",
            Box::new(|v: &mut serde_json::Value| {
                let layout = v["layout"].as_array_mut().expect("layout");
                for id in 5..45 {
                    layout.push(serde_json::json!([format!("agent/{id}"), "cell"]));
                }
            }),
            "agent 5 is not an agent of the run's scenario",
        ),
        (
            "big.json",
            Box::new(move |v: &mut serde_json::Value| {
                v["scenario"] = serde_json::json!(big);
            }),
            "a run request of",
        ),
        (
            "stranger.json",
            Box::new(|v: &mut serde_json::Value| {
                v["coordinator"] = serde_json::json!("elsewhere");
            }),
            "only a host of",
        ),
    ] {
        let f = request_file(&lab, name, edit);
        let s = lab.rogue(2, &[to_cell, "request", "cell", "control", &f]);
        assert!(s.starts_with("refused:") && s.contains(why), "{name}: {s}");
    }
    // Nothing was written: the serve's work folder holds no run.
    let work = lab.scratch.0.join("work-cell");
    let runs = std::fs::read_dir(&work).map(|d| d.count()).unwrap_or(0);
    assert_eq!(
        runs,
        0,
        "a refused request leaves nothing in {}",
        work.display()
    );
    // 300 connections held on the serve's port, half of them half-closed, opened 2 s before
    // the run (issue 51: the run request then failed at once, "within 30.0 s" said after 1.4
    // s; a request nothing answers yet is sent again now): a run gets through.
    let mut held = lab.start_rogue(2, &["hold", "300", "10.77.0.2:7447", "30"]);
    std::thread::sleep(Duration::from_secs(2));
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "1"]);
    assert_eq!(
        digest(&out),
        inproc_digest(&["--duration-s", "1"]),
        "{}",
        stderr(&out)
    );
    let _ = held.kill();
    let _ = held.wait();
    // A long lockstep run: its traces are asked for by paths (refused), then one forged frame
    // numbered far ahead stops it, named, within the stall timeout.
    let before = lab.started(cell).len();
    let run = lab.start(&["run", "--hosts", &file, "--duration-s", "400"]);
    let prefix = lab.next_run_prefix(cell, before);
    for ask in [
        "../../../../etc/passwd 0",
        "/etc/passwd 0",
        "agent-1 0",
        "agent-3.trace 0",
    ] {
        let s = lab.rogue(
            2,
            &[to_cell, "ask", "cell", "control", &prefix, "traces", ask],
        );
        assert!(
            s.contains("refused:") && s.contains("no process"),
            "{ask}: {s}"
        );
    }
    let s = lab.rogue(
        2,
        &[
            to_cell,
            "ask",
            "cell",
            "control",
            &prefix,
            "traces",
            "agent-3 0",
        ],
    );
    assert!(
        s.starts_with("answered"),
        "the run's own trace is served: {s}"
    );
    let s = lab.rogue(2, &[BOTH_HOSTS, "forge-ahead", "1000", "5"]);
    assert!(s.starts_with("forged 1 frames"), "{s}");
    let out = wait_with_watchdog(run, Duration::from_secs(60));
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("run stalled: no progress for")
            && err.contains("refused")
            && err.contains("for agent"),
        "{err}"
    );
    // Realtime: the rogue biases agent 3's measurements; every forged frame comes after the
    // honest one of its number, and is refused and counted.
    let before = lab.started(cell).len();
    let run = lab.start(&[
        "run",
        "--hosts",
        &file,
        "--clock",
        "realtime",
        "--duration-s",
        "6",
        "--json",
    ]);
    let _ = lab.next_run_prefix(cell, before);
    // The rogue ends once it forged its frames and the run's stream went quiet (its session
    // outlives its puts); 12 s bound it (its session and the run's processes start first,
    // on a loaded machine slowly).
    let s = lab.rogue(2, &[BOTH_HOSTS, "bias", "3", "0.5", "1200", "12"]);
    assert!(s.starts_with("forged 1200 frames"), "{s}");
    let out = wait_with_watchdog(run, Duration::from_secs(60));
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(6), "{err}");
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .expect("JSON");
    let v: serde_json::Value = serde_json::from_str(line).expect("JSON");
    assert_eq!(v["network"]["authenticated"], false, "{v}");
    // Of a forged frame and the honest one of its number, the bridge lets in at most the
    // first to come: the other is refused. A forgery that overtakes the honest frames before
    // its own number (the rogue's path faster than the host's, on a loaded machine) makes
    // them refused too, so the count is at least the frames forged (issue 51: it was 1201
    // once, against an exact 1200 asserted).
    let refused = v["network"]["refused_frames"].as_u64().unwrap_or(0);
    assert!(refused >= 1200, "{refused} refused of 1200 forged: {v}");
    assert!(
        v["network"]["refusals"].to_string().contains("for agent 3"),
        "{v}"
    );
}

/// Runs `args` live on the coordinating host of `lab` with a client there subscribed to
/// `topics`, and checks what it saw against the run's recording
/// ([`crate::live::check_watched`]). The run's summary.
fn watched(
    lab: &Lab,
    python: &std::path::Path,
    args: &[&str],
    topics: &[&str],
    keep: (u64, u64, bool),
) -> serde_json::Value {
    use crate::live::{check_watched, client_args, client_by, client_output, LiveRun, LIVE_ARGS};
    let run = LiveRun::of(lab.start(&[args, &LIVE_ARGS[..]].concat()));
    let client_args = client_args(topics, (keep.0, keep.1));
    let client_args: Vec<&str> = client_args.iter().map(String::as_str).collect();
    let python = lab.hosts.command(0, python, &[]);
    let seen = client_output(client_by(python, &run.addr, &client_args, &lab.scratch.0));
    let (summary, stderr) = run.finish_with_stderr();
    check_watched(&seen, &summary, topics, keep);
    // The remote robots came during the run, streamed by their host.
    assert!(!stderr.contains("live view: the stream"), "{stderr}");
    summary
}

/// The live view of a split run (issue 35): a viewer on the coordinating host sees the robots of
/// every host as the run makes them, those on another host too (their traces streamed by its
/// serve as they grow), the same messages as the run's recording.
#[test]
fn a_viewer_of_a_split_run_sees_the_robots_of_every_host() {
    let Some(python) = fdi_tests::python() else {
        return;
    };
    let Some(mut lab) = Lab::new(2, "multihost-live") else {
        return;
    };
    // Agents 3 and 4 and the attacker run on `cell`, agent 1 and the control center on the
    // coordinating host.
    let file = lab.deployment(
        &TWO_HOSTS.replace("agents = [3, 4]", "agents = [3, 4]\nroles = [\"attacker\"]"),
    );
    lab.serve(1, "cell");
    let topics = [
        "/agent3/tracking_error",
        "/agent3/estimate",
        "/agent4/detectors",
        "/agent1/tracking_error",
        "/agent2/torque/applied",
    ];
    // Paced at half real time, every 5th tick kept: each of them, as recorded. An attack on the
    // torques too: the attacker's trace, on `cell`, is read twice (its torque path).
    let attack = ["--duration-s", "1", "--attack", "actuator-bias"];
    let paced = ["--pace", "0.5", "--live-rate", "100"];
    let lockstep = [&["run", "--hosts", &file][..], &attack, &paced].concat();
    let summary = watched(&lab, &python, &lockstep, &topics, (5, 1000, true));
    assert_eq!(
        summary["trace_digest"].as_str(),
        Some(inproc_digest(&attack).as_str()),
        "watched, paced, split: the same run"
    );
    // Realtime: every 10th tick of those the join matched.
    let realtime = [
        "run",
        "--hosts",
        &file,
        "--clock",
        "realtime",
        "--duration-s",
        "1",
        "--live-rate",
        "100",
    ];
    watched(&lab, &python, &realtime, &topics, (10, 1000, false));
}
