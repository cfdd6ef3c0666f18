//! Helpers shared by the integration tests: locating (and if needed building) the real
//! binaries, scratch folders, process and shared-memory inspection, a watchdog.

pub mod mounts;
pub mod netns;
pub mod slurm;
pub mod threads;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use fdi_runtime::process::procfs;

/// `target/<profile>` of the running test binary.
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test>-<hash>
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .to_path_buf()
}

/// The `fdi-launch` binary of this build, with `fdi-agent`, `fdi-attacker` and
/// `fdi-control-center` beside it. `cargo test`/`nextest` build the test targets, not the other
/// packages' executables, so this runs `cargo build --bins` once per test process (a no-op when
/// they are fresh): a test never runs a stale binary.
pub fn launcher() -> PathBuf {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT
        .get_or_init(|| {
            let dir = profile_dir();
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
            let mut cmd = Command::new(cargo);
            // With `--tests`, the binaries are built with the features the test build already
            // resolved (dev-dependencies unify features): the libraries the tests compiled are
            // reused, and only the binaries are compiled and linked. Without it, every crate
            // whose features differ (serde, zenoh, …) and all above it would be built twice.
            cmd.args(["build", "--quiet", "--workspace", "--bins", "--tests"]);
            if dir.file_name().is_some_and(|n| n == "release") {
                cmd.arg("--release");
            }
            cmd.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
            // Built in the environment the test command's build saw, not the test's.
            fdi_test_runner::clean_build_env(&mut cmd);
            let st = cmd.status().expect("running cargo build for the binaries");
            assert!(st.success(), "building the binaries failed");
            dir.join("fdi-launch")
        })
        .clone()
}

/// The Python interpreter with the iceoryx2 binding and the tests' packages (`cargo test-all`
/// makes it: `FDI_PYTHON`), or `None` (after saying so) when the
/// tests are to be skipped.
pub fn python() -> Option<PathBuf> {
    let found = std::env::var_os("FDI_PYTHON")
        .map(PathBuf::from)
        .or_else(|| Some(repo_path("target/py-venv/bin/python")).filter(|p| p.exists()));
    if found.is_none() {
        assert!(
            std::env::var_os("FDI_REQUIRE_PYTHON").is_none(),
            "FDI_REQUIRE_PYTHON is set but there is no Python: set FDI_PYTHON or run `cargo test-all`"
        );
        eprintln!(
            "skipped: no Python with the iceoryx2 binding (FDI_PYTHON unset, no target/py-venv): \
             `cargo test-all` sets one up"
        );
    }
    found
}

/// A fresh scratch folder, removed on drop.
#[derive(Debug)]
pub struct Scratch(pub PathBuf);

impl Scratch {
    pub fn new(tag: &str) -> Self {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let p = std::env::temp_dir().join(format!("fdi-test-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&p).expect("scratch folder");
        Self(p)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Runs `fdi-launch` with `args` (output under `out`) and waits, killing it after `limit` (a
/// watchdog against hangs, not a speed check).
pub fn launch(args: &[&str], out: &Path, limit: Duration) -> Output {
    let child = spawn(args, out);
    wait_with_watchdog(child, limit)
}

/// Starts `fdi-launch` with `args`, output under `out`.
pub fn spawn(args: &[&str], out: &Path) -> Child {
    let out = out.to_string_lossy();
    let mut all = args.to_vec();
    all.extend(["--out", &out]);
    spawn_plain(&all)
}

/// Starts `fdi-launch` with exactly `args`; stdout and stderr are captured.
fn spawn_plain(args: &[&str]) -> Child {
    Command::new(launcher())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawning fdi-launch")
}

/// Waits for `child`, killing it (and failing the test) after `limit`. Its piped output is
/// read meanwhile: a child that writes more than a pipe holds (64 KiB: the summary of a run
/// of many robots) would otherwise block on its write until the watchdog fires.
pub fn wait_with_watchdog(child: Child, limit: Duration) -> Output {
    wait_polling(child, limit, Duration::from_millis(20), || {})
}

/// [`wait_with_watchdog`] calling `each` every `every` while it waits.
fn wait_polling(
    mut child: Child,
    limit: Duration,
    every: Duration,
    mut each: impl FnMut(),
) -> Output {
    fn drain(
        pipe: Option<impl std::io::Read + Send + 'static>,
    ) -> std::thread::JoinHandle<Vec<u8>> {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut bytes);
            }
            bytes
        })
    }
    let readers = (drain(child.stdout.take()), drain(child.stderr.take()));
    let collect = |status,
                   (stdout, stderr): (
        std::thread::JoinHandle<Vec<u8>>,
        std::thread::JoinHandle<Vec<u8>>,
    )| Output {
        status,
        stdout: stdout.join().expect("reading stdout"),
        stderr: stderr.join().expect("reading stderr"),
    };
    let began = Instant::now();
    loop {
        each();
        if let Some(status) = child.try_wait().expect("polling fdi-launch") {
            return collect(status, readers);
        }
        if began.elapsed() > limit {
            let pid = child.id();
            let _ = child.kill();
            let status = child.wait().expect("reaping fdi-launch");
            let out = collect(status, readers);
            panic!(
                "watchdog: fdi-launch (pid {pid}) still running after {limit:?}; stderr:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(every);
    }
}

/// The JSON object a completed realtime `run --json` printed: exit 0, or 3 when some agent was
/// lost for a while and rejoined (on a loaded machine a live agent may go silent for the 40 ms
/// loss limit; it ran uncontrolled meanwhile, so the run is not a clean one) or the run fell
/// behind its clock (a machine busier still). Any other exit, or an agent lost to the end,
/// fails.
pub fn json_realtime(out: &Output) -> serde_json::Value {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().rev().find(|l| l.starts_with('{'));
    match (out.status.code(), line) {
        (Some(0), _) => json(out),
        (Some(3), Some(line)) => {
            let v: serde_json::Value = serde_json::from_str(line).expect("valid JSON");
            let lost = v["lost_agents"].as_array().cloned().unwrap_or_default();
            // Or, no robot lost, the run fell behind its clock (issue 51): a robot uncontrolled
            // for some ticks, or more than a tenth of its deadlines missed.
            let behind = v["metrics"].as_object().is_some_and(|m| {
                m.values().any(|m| {
                    let n = |f: &str| m[f].as_u64().unwrap_or(0);
                    n("uncontrolled_ticks") > 0 || n("deadline_misses") * 10 > n("agent_ticks")
                })
            });
            assert!(
                (!lost.is_empty() && lost.iter().all(|l| l["rejoined_t_s"].is_f64()))
                    || (lost.is_empty() && behind),
                "exit 3 without every lost agent rejoined, nor a run behind its clock: \
                 {lost:?}\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
            v
        }
        _ => json(out),
    }
}

/// The JSON object `run --json` printed.
pub fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "fdi-launch failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no JSON in output:\n{text}"));
    serde_json::from_str(line).expect("valid JSON")
}

/// Pids of the processes whose parent is `pid`.
pub fn children_of(pid: u32) -> Vec<(u32, String)> {
    let Ok(pids) = procfs::pids() else {
        return Vec::new();
    };
    pids.into_iter()
        .filter(|&p| procfs::parent(p).is_ok_and(|parent| parent == pid))
        .map(|p| {
            let cmdline = procfs::cmdline(p).unwrap_or_default();
            (p, String::from_utf8_lossy(&cmdline).replace('\0', " "))
        })
        .collect()
}

/// Shared-memory and iceoryx2 files left by runs of the launcher `pid` (its run prefixes are
/// `fdi<pid>_…`).
pub fn leftovers_of(launcher_pid: u32) -> Vec<PathBuf> {
    use fdi_runtime::ipc::{RunPrefix, Shm, Transport};
    Shm::leftovers(&RunPrefix::of_launcher(launcher_pid))
}

/// Asserts that runs of the launcher `pid` left no shared-memory or iceoryx2 file behind.
pub fn assert_no_leftovers(launcher_pid: u32) {
    let left = leftovers_of(launcher_pid);
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// True while the process `pid` exists (and is not a zombie).
pub fn alive(pid: u32) -> bool {
    procfs::state(pid).is_ok_and(|s| s != 'Z')
}

/// Sends `signal` (e.g. "-KILL") to `pid` with kill(1).
pub fn signal(pid: u32, signal: &str) {
    let st = Command::new("kill")
        .arg(signal)
        .arg(pid.to_string())
        .status()
        .expect("kill(1)");
    assert!(st.success(), "kill {signal} {pid} failed");
}

/// Polls `cond` every 10 ms until it holds or `limit` passes.
pub fn wait_until(limit: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let began = Instant::now();
    while began.elapsed() < limit {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    cond()
}

/// Runs `fdi-launch` with exactly `args` (no `--out`: for `report` and `trace export`, which
/// take a run directory) and waits, killing it after `limit`.
pub fn launch_plain(args: &[&str], limit: Duration) -> Output {
    wait_with_watchdog(spawn_plain(args), limit)
}

/// The run directory that `run --json` printed.
pub fn run_dir_of(summary: &serde_json::Value) -> PathBuf {
    PathBuf::from(
        summary["run_dir"]
            .as_str()
            .expect("run_dir in the JSON summary"),
    )
}

/// A path inside the repository (`rel` relative to the workspace root).
pub fn repo_path(rel: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join(rel)
}

/// Every record of a binary trace, failing the test on a damaged one.
pub fn trace_records(path: &Path) -> Vec<fdi_common::trace::TraceRecord> {
    let reader = fdi_common::trace::TraceReader::open(path)
        .unwrap_or_else(|e| panic!("cannot open {}: {e}", path.display()));
    reader
        .map(|r| r.unwrap_or_else(|e| panic!("damaged {}: {e}", path.display())))
        .collect()
}

/// What [`launch_watching_children`] saw.
#[derive(Debug)]
pub struct Watched {
    pub output: Output,
    /// The launcher's pid (its run prefix is `fdi<pid>_…`).
    pub pid: u32,
    /// Every child process seen while it ran: `(pid, command line)`.
    pub children: Vec<(u32, String)>,
}

/// Runs `fdi-launch` with `args` (no `--out` added) and waits, killing it after `limit`, while
/// polling every millisecond for processes it starts.
pub fn launch_watching_children(args: &[&str], limit: Duration) -> Watched {
    let child = spawn_plain(args);
    let pid = child.id();
    let mut seen = Vec::new();
    let output = wait_polling(child, limit, Duration::from_millis(1), || {
        for c in children_of(pid) {
            if !seen.contains(&c) {
                seen.push(c);
            }
        }
    });
    Watched {
        output,
        pid,
        children: seen,
    }
}

/// A tmpfs of `size` mounted at a fresh folder, unmounted on drop: a file system that fills up.
#[derive(Debug)]
pub struct Tmpfs(pub Scratch);

impl Tmpfs {
    /// `Err` (with the reason) when this user may not mount.
    pub fn mount(tag: &str, size: &str) -> Result<Self, String> {
        let dir = Scratch::new(&format!("tmpfs-{tag}"));
        let st = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(&dir.0)
            .stderr(Stdio::piped())
            .output()
            .map_err(|e| format!("mount: {e}"))?;
        if st.status.success() {
            Ok(Self(dir))
        } else {
            Err(String::from_utf8_lossy(&st.stderr).trim().to_string())
        }
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0 .0).status();
    }
}

/// The paper's scenario with `n` robots: its four agents' tables again and again, numbered
/// 1..=n (the attack stays on the first four).
pub fn paper_team(n: u32) -> String {
    let paper = fdi_common::scenario::PAPER_SCENARIO;
    let (head, agents) = paper.split_once("[[agents]]").expect("the paper's agents");
    let tables: Vec<&str> = agents.split("[[agents]]").collect();
    let mut out = head.replacen("name = \"paper\"", &format!("name = \"team{n}\""), 1);
    for i in 1..=n {
        let table = tables[(i as usize - 1) % tables.len()];
        let (id_line, rest) = table.split_once('\n').map_or(("", table), |(a, b)| (a, b));
        let (_, tail) = rest.split_once('\n').expect("the id line");
        assert!(rest.starts_with("id = "), "{id_line}{rest}");
        out.push_str(&format!("[[agents]]{id_line}\nid = {i}\n{tail}"));
    }
    out
}
