//! "Hosts" on one machine for the tests of runs split over hosts: network namespaces joined by
//! veth pairs to a bridge in the first one, each with its own shared memory (a tmpfs on
//! `/dev/shm` and on iceoryx2's root folder, in the mount namespace `ip netns exec` makes), so
//! that each host's iceoryx2 sees only its own processes. The addresses (10.77.0.0/24) exist
//! only inside the namespaces the test made; everything is removed on drop.
//!
//! Needs root and `ip` (iproute2). Without them [`Hosts::create`] says why, and the tests say
//! they are skipped, unless `FDI_REQUIRE_NETNS` is set (CI), where they fail.

use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};

/// The hosts of one test.
#[derive(Debug)]
pub struct Hosts {
    /// Namespace names; the first is the coordinating host, where the bridge is.
    pub names: Vec<String>,
    /// Interface of each host (in its namespace); the first host has the bridge.
    devices: Vec<String>,
    /// The bridge's end of each other host's veth pair (in the first namespace), by host;
    /// empty for the first.
    ports: Vec<String>,
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("running `ip`: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`ip {}`: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// The address of host `i` (0-based).
pub fn address(i: usize) -> String {
    format!("10.77.0.{}", i + 1)
}

/// The Zenoh endpoint of host `i`.
pub fn endpoint(i: usize) -> String {
    format!("tcp/{}:7447", address(i))
}

/// Why the multi-host tests cannot run here, if they cannot; panics instead when
/// `FDI_REQUIRE_NETNS` is set.
pub fn skip_reason(e: &str) -> String {
    assert!(
        std::env::var_os("FDI_REQUIRE_NETNS").is_none(),
        "FDI_REQUIRE_NETNS is set but network namespaces cannot be made: {e}"
    );
    format!("skipped: network namespaces cannot be made here ({e}); run as root with iproute2")
}

impl Hosts {
    /// `n` hosts, or why they cannot be made.
    pub fn create(n: usize) -> Result<Self, String> {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let tag = format!(
            "{}{}",
            std::process::id() % 100_000,
            NEXT.fetch_add(1, Ordering::SeqCst)
        );
        let mut hosts = Self {
            names: Vec::new(),
            devices: Vec::new(),
            ports: vec![String::new()],
        };
        for i in 0..n {
            let name = format!("fdi-{tag}-{i}");
            ip(&["netns", "add", &name])?;
            hosts.names.push(name);
        }
        let c = hosts.names[0].clone();
        ip(&["-n", &c, "link", "set", "lo", "up"])?;
        ip(&["-n", &c, "link", "add", "br0", "type", "bridge"])?;
        ip(&[
            "-n",
            &c,
            "addr",
            "add",
            &format!("{}/24", address(0)),
            "dev",
            "br0",
        ])?;
        ip(&["-n", &c, "link", "set", "br0", "up"])?;
        hosts.devices.push("br0".into());
        for i in 1..n {
            let (outer, inner) = (format!("fv{tag}o{i}"), format!("fv{tag}i{i}"));
            let h = hosts.names[i].clone();
            ip(&[
                "link", "add", &outer, "type", "veth", "peer", "name", &inner,
            ])?;
            ip(&["link", "set", &outer, "netns", &c])?;
            ip(&["link", "set", &inner, "netns", &h])?;
            ip(&["-n", &c, "link", "set", &outer, "master", "br0"])?;
            ip(&["-n", &c, "link", "set", &outer, "up"])?;
            ip(&[
                "-n",
                &h,
                "addr",
                "add",
                &format!("{}/24", address(i)),
                "dev",
                &inner,
            ])?;
            ip(&["-n", &h, "link", "set", "lo", "up"])?;
            ip(&["-n", &h, "link", "set", &inner, "up"])?;
            hosts.devices.push(inner);
            hosts.ports.push(outer);
        }
        for i in 1..n {
            hosts.wait_carried(i)?;
        }
        Ok(hosts)
    }

    /// Waits until both ends of host `i`'s link carry packets: the kernel reports a link
    /// brought up as operationally up only once it has activated it (its queue discipline,
    /// `linkwatch`), which it may put off for up to a second, longer on a loaded machine; a
    /// packet sent meanwhile is dropped. A QUIC client whose first packets were dropped waits
    /// seconds before it sends them again (issue 51: the run after a healed cut found no serve
    /// within its 5 s). A watchdog bounds the wait, not a speed check.
    fn wait_carried(&self, i: usize) -> Result<(), String> {
        let up = |ns: &str, dev: &str| {
            Command::new("ip")
                .args(["-n", ns, "-o", "link", "show", "dev", dev])
                .output()
                .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains(" state UP "))
        };
        let began = std::time::Instant::now();
        while !(up(&self.names[i], &self.devices[i]) && up(&self.names[0], &self.ports[i])) {
            if began.elapsed() > std::time::Duration::from_secs(60) {
                return Err(format!(
                    "the link of host {i} ({}) was not up within 60 s",
                    self.devices[i]
                ));
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        Ok(())
    }

    /// `program args` on host `i`, with the host's own shared memory.
    pub fn command(&self, i: usize, program: &std::path::Path, args: &[&str]) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.names[i], "sh", "-c"]).arg(
            "mount -t tmpfs -o size=1g tmpfs /dev/shm && mkdir -p /tmp/iceoryx2 && \
             mount -t tmpfs -o size=64m tmpfs /tmp/iceoryx2 && exec \"$@\"",
        );
        c.arg("sh").arg(program).args(args);
        c
    }

    /// Cuts host `i` (> 0) off the network, or joins it again.
    /// Joining waits until the link carries packets again.
    pub fn set_link(&self, i: usize, up: bool) {
        let state = if up { "up" } else { "down" };
        ip(&["-n", &self.names[i], "link", "set", &self.devices[i], state]).expect("link state");
        if up {
            self.wait_carried(i).expect("the link back up");
        }
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for name in &self.names {
            let _ = ip(&["netns", "del", name]);
        }
    }
}
