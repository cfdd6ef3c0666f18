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

/// A few hosts, their serves and a scratch folder.
struct Lab {
    hosts: Hosts,
    serves: Vec<(Child, PathBuf)>,
    scratch: Scratch,
}

impl Lab {
    /// `n` hosts, or None (the test is skipped, said on stderr).
    fn new(n: usize, tag: &str) -> Option<Self> {
        match Hosts::create(n) {
            Ok(hosts) => Some(Self {
                hosts,
                serves: Vec::new(),
                scratch: Scratch::new(tag),
            }),
            Err(e) => {
                eprintln!("{}", netns::skip_reason(&e));
                None
            }
        }
    }

    /// Starts `fdi-launch serve --name NAME` on host `i` and waits until it listens.
    fn serve(&mut self, i: usize, name: &str) -> usize {
        let log = self.scratch.0.join(format!("serve-{name}.log"));
        let file = std::fs::File::create(&log).expect("serve log");
        let child = self
            .hosts
            .command(
                i,
                &launcher(),
                &["serve", "--name", name, "--listen", &netns::endpoint(i)],
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

    /// Writes a deployment file.
    fn deployment(&self, text: &str) -> String {
        let p = self.scratch.0.join("hosts.toml");
        std::fs::write(&p, text).expect("deployment file");
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
[hosts.control]
endpoint = "tcp/10.77.0.1:7447"
[hosts.cell]
endpoint = "tcp/10.77.0.2:7447"
agents = [3, 4]
"#;

#[test]
fn lockstep_over_three_hosts_equals_the_in_process_engine() {
    let Some(mut lab) = Lab::new(3, "multihost-three") else {
        return;
    };
    // The agents 3 and 4 on a cell, the attacker on a host of its own: every stream of the
    // run crosses the network at least once.
    let cell = lab.serve(1, "cell");
    let adversary = lab.serve(2, "adversary");
    let file = lab.deployment(
        r#"
coordinator = "control"
[hosts.control]
endpoint = "tcp/10.77.0.1:7447"
[hosts.cell]
endpoint = "tcp/10.77.0.2:7447"
agents = [3, 4]
[hosts.adversary]
endpoint = "tcp/10.77.0.3:7447"
roles = ["attacker"]
"#,
    );
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
        err.contains("host `cell` (tcp/10.77.0.2:7447): agent 3, agent 4"),
        "{err}"
    );
    assert!(
        err.contains("host `adversary` (tcp/10.77.0.3:7447): attacker"),
        "{err}"
    );
    assert!(!err.contains("could not be removed"), "{err}");
    for k in [cell, adversary] {
        lab.wait_log(k, "nothing is left on this host", Duration::from_secs(10));
    }
    // The run directory holds the whole run: the remote processes' traces were fetched.
    let runs = lab.scratch.0.join("runs");
    let dir = std::fs::read_dir(&runs)
        .expect("runs")
        .flatten()
        .next()
        .expect("a run directory")
        .path();
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
    let cell = lab.serve(1, "cell");
    let file = lab.deployment(TWO_HOSTS);
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
            "run stopped: host `cell` (tcp/10.77.0.2:7447) is unreachable: its `fdi-launch \
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
    // Back on the network, the same serve takes the next run, which is clean.
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
    let cell = lab.serve(1, "cell");
    let file = lab.deployment(TWO_HOSTS);
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
        err.contains("host `cell` (tcp/10.77.0.2:7447) is unreachable")
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
    let lost: Vec<u64> = v["lost_agents"]
        .as_array()
        .expect("lost agents")
        .iter()
        .filter_map(|l| l["agent"].as_u64())
        .collect();
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
    lab.serve(1, "cell");
    let file = lab.deployment(TWO_HOSTS);
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
        err.contains("host `cell` (tcp/10.77.0.2:7447) is unreachable")
            || err.contains("on host `cell`"),
        "the host is named:\n{err}"
    );
}

#[test]
fn a_host_without_a_serve_is_named_before_anything_starts() {
    let Some(lab) = Lab::new(2, "multihost-no-serve") else {
        return;
    };
    let file = lab.deployment(TWO_HOSTS);
    let out = lab.run(&["run", "--hosts", &file, "--duration-s", "1"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("no `fdi-launch serve` answers on host `cell` (tcp/10.77.0.2:7447)"),
        "{err}"
    );
    // Nothing started, nothing recorded: no run directory is left.
    let runs = lab.scratch.0.join("runs");
    let left = std::fs::read_dir(&runs).map(|d| d.count()).unwrap_or(0);
    assert_eq!(left, 0, "no run directory for a run that did not start");
}
