//! A single-node Slurm cluster for a test: Debian's `munged`, `slurmctld` and `slurmd`, started
//! as the test's children with a configuration, a key, state and logs of their own in a scratch
//! folder (nothing under /etc, /var or /run is read or written), on loopback ports free at the
//! start. Stopped (every job cancelled, then the daemons) on drop.
//!
//! Where the daemons are missing or the test is not root, the tests that need them are
//! skipped, unless `FDI_REQUIRE_SLURM` is set (CI), where they fail.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use crate::wait_until;

/// The node's name in the cluster.
pub const NODE: &str = "fdi-node";

/// Why the Slurm tests cannot run here; panics instead when `FDI_REQUIRE_SLURM` is set.
pub fn skip_reason(e: &str) -> String {
    assert!(
        std::env::var_os("FDI_REQUIRE_SLURM").is_none(),
        "FDI_REQUIRE_SLURM is set but a Slurm cluster cannot be started: {e}"
    );
    format!(
        "skipped: a single-node Slurm cluster cannot be started here ({e}); run as root with Debian's slurmctld, slurmd and munge"
    )
}

/// A running single-node cluster.
pub struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
    daemons: Vec<(&'static str, Child)>,
}

/// The path of program `name` in PATH, /usr/sbin or /usr/bin.
fn program(name: &str) -> Result<PathBuf, String> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/usr/bin")])
        .map(|d| d.join(name))
        .find(|p| p.is_file())
        .ok_or_else(|| format!("no program {name}"))
}

/// A TCP port of loopback free now.
fn free_port() -> Result<u16, String> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| format!("a free port: {e}"))
}

fn is_root() -> bool {
    std::fs::read_to_string("/proc/self/status").is_ok_and(|s| {
        s.lines()
            .find_map(|l| l.strip_prefix("Uid:"))
            .and_then(|l| l.split_whitespace().nth(1))
            == Some("0")
    })
}

fn spawn_daemon(dir: &Path, name: &'static str, args: &[&str]) -> Result<Child, String> {
    let log = std::fs::File::create(dir.join(format!("{name}.out")))
        .map_err(|e| format!("{name}'s log: {e}"))?;
    let err = log.try_clone().map_err(|e| format!("{name}'s log: {e}"))?;
    Command::new(program(name)?)
        .args(args)
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(err)
        .spawn()
        .map_err(|e| format!("starting {name}: {e}"))
}

impl Cluster {
    /// Starts munged, slurmctld and slurmd in `dir`, and waits (at most a minute) for the node
    /// to be idle.
    pub fn start(dir: &Path) -> Result<Self, String> {
        if !is_root() {
            return Err("not root".into());
        }
        for p in [
            "munged",
            "mungekey",
            "slurmctld",
            "slurmd",
            "sbatch",
            "sinfo",
            "scancel",
        ] {
            program(p)?;
        }
        let text = |p: &Path| p.to_string_lossy().into_owned();
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        // The munge socket's folder must be open to every user.
        set_mode(dir, 0o755)?;
        for sub in ["state", "spool"] {
            std::fs::create_dir_all(dir.join(sub)).map_err(|e| format!("{sub}: {e}"))?;
        }
        let key = dir.join("munge.key");
        let made = Command::new(program("mungekey")?)
            .args(["--create", "--keyfile", &text(&key)])
            .output()
            .map_err(|e| format!("mungekey: {e}"))?;
        if !made.status.success() {
            return Err(format!(
                "mungekey: {}",
                String::from_utf8_lossy(&made.stderr)
            ));
        }
        let socket = dir.join("munge.sock");
        let mut cluster = Self {
            dir: dir.to_path_buf(),
            conf: dir.join("slurm.conf"),
            daemons: Vec::new(),
        };
        let munged = spawn_daemon(
            dir,
            "munged",
            &[
                "--foreground",
                "--force",
                &format!("--key-file={}", text(&key)),
                &format!("--socket={}", text(&socket)),
                &format!("--pid-file={}", text(&dir.join("munged.pid"))),
                &format!("--log-file={}", text(&dir.join("munged.log"))),
                &format!("--seed-file={}", text(&dir.join("munged.seed"))),
            ],
        )?;
        cluster.daemons.push(("munged", munged));
        if !wait_until(Duration::from_secs(10), || socket.exists()) {
            return Err(format!("munged made no socket: {}", cluster.log("munged")));
        }
        std::fs::write(&cluster.conf, config(dir, &socket)?)
            .map_err(|e| format!("slurm.conf: {e}"))?;
        let conf = text(&cluster.conf);
        let ctld = spawn_daemon(dir, "slurmctld", &["-D", "-f", &conf])?;
        cluster.daemons.push(("slurmctld", ctld));
        let slurmd = spawn_daemon(dir, "slurmd", &["-D", "-N", NODE, "-f", &conf])?;
        cluster.daemons.push(("slurmd", slurmd));
        let idle = wait_until(Duration::from_secs(60), || {
            cluster
                .client("sinfo", &["-h", "-N", "-o", "%T"])
                .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "idle")
        });
        if !idle {
            return Err(format!(
                "the node never became idle:\n{}\n{}",
                cluster.log("slurmctld"),
                cluster.log("slurmd")
            ));
        }
        Ok(cluster)
    }

    /// The configuration clients need (`SLURM_CONF`).
    pub fn conf(&self) -> &Path {
        &self.conf
    }

    /// Runs a Slurm client (`squeue`, `scontrol`, …) of this cluster.
    pub fn client(&self, name: &str, args: &[&str]) -> Result<Output, String> {
        Command::new(program(name)?)
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .output()
            .map_err(|e| format!("{name}: {e}"))
    }

    /// What daemon `name` wrote.
    pub fn log(&self, name: &str) -> String {
        let out = std::fs::read_to_string(self.dir.join(format!("{name}.out"))).unwrap_or_default();
        let log = std::fs::read_to_string(self.dir.join(format!("{name}.log"))).unwrap_or_default();
        format!("--- {name}:\n{out}{log}")
    }

    /// `JobState` and `ExitCode` of job `id` once it is in a state a job ends in (`scontrol
    /// show job`), or `None` after `limit`.
    pub fn wait_for_end(&self, id: &str, limit: Duration) -> Option<(String, String)> {
        let mut ended = None;
        wait_until(limit, || {
            let Ok(o) = self.client("scontrol", &["show", "job", id]) else {
                return false;
            };
            let text = String::from_utf8_lossy(&o.stdout).into_owned();
            let field = |name: &str| {
                text.split_whitespace()
                    .find_map(|w| w.strip_prefix(name))
                    .map(str::to_string)
            };
            match (field("JobState="), field("ExitCode=")) {
                // The states a job ends in (COMPLETING is on its way to COMPLETED).
                (Some(state), Some(code))
                    if matches!(
                        state.as_str(),
                        "COMPLETED"
                            | "FAILED"
                            | "CANCELLED"
                            | "TIMEOUT"
                            | "NODE_FAIL"
                            | "OUT_OF_MEMORY"
                            | "BOOT_FAIL"
                            | "DEADLINE"
                            | "PREEMPTED"
                    ) =>
                {
                    ended = Some((state, code));
                    true
                }
                _ => false,
            }
        });
        ended
    }
}

fn set_mode(p: &Path, mode: u32) -> Result<(), String> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode))
        .map_err(|e| format!("chmod {}: {e}", p.display()))
}

/// slurm.conf of a cluster of one node, this host's controller, every path under `dir`.
fn config(dir: &Path, socket: &Path) -> Result<String, String> {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map_err(|e| format!("the host name: {e}"))?;
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let d = dir.display();
    Ok(format!(
        "ClusterName=fdi\n\
         SlurmctldHost={host}(127.0.0.1)\n\
         SlurmctldPort={ctld}\nSlurmdPort={slurmd}\n\
         AuthType=auth/munge\nAuthInfo=socket={socket}\nCredType=cred/munge\n\
         SlurmUser=root\nSlurmdUser=root\n\
         StateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\n\
         SlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n\
         SlurmctldLogFile={d}/slurmctld.log\nSlurmdLogFile={d}/slurmd.log\n\
         ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\n\
         JobAcctGatherType=jobacct_gather/none\nAccountingStorageType=accounting_storage/none\n\
         JobCompType=jobcomp/none\nMpiDefault=none\n\
         SchedulerType=sched/builtin\nSelectType=select/cons_tres\nSelectTypeParameters=CR_CPU\n\
         ReturnToService=2\n\
         NodeName={NODE} NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN\n\
         PartitionName=main Nodes=ALL Default=YES MaxTime=INFINITE State=UP\n",
        host = host.trim(),
        ctld = free_port()?,
        slurmd = free_port()?,
        socket = socket.display(),
    ))
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = self.client("scancel", &["--full", "--user=root"]);
        // The jobs' processes end before the daemons that track them.
        wait_until(Duration::from_secs(20), || {
            self.client("squeue", &["-h"])
                .is_ok_and(|o| o.status.success() && o.stdout.is_empty())
        });
        // The node first, the controller, then munge.
        for (_, child) in self.daemons.iter_mut().rev() {
            let _ = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status();
            let pid = child.id();
            if !wait_until(Duration::from_secs(10), || {
                child.try_wait().ok().flatten().is_some()
            }) {
                let _ = Command::new("kill")
                    .args(["-KILL", &pid.to_string()])
                    .status();
                let _ = child.wait();
            }
        }
    }
}
