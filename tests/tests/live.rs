//! The live view (`run --live`, docs/traces.md): a client that speaks the Foxglove WebSocket
//! protocol (`tests/python/live_client.py`, Python's `websockets`) watches real runs.
//!
//! * On both engines and both clocks it is told the run's channels with the MCAP export's
//!   encodings and schemas (the same bytes), and receives, on the topics it subscribed to,
//!   exactly the export's messages of the ticks the stream keeps (every K-th: the same log times,
//!   the same bytes), and the run's time broadcast at each.
//! * A client that never reads, one that leaves mid-run and garbage bytes on the port change
//!   nothing of the run: it ends normally, its digest is the in-process engine's, its traces are
//!   whole.
//!
//! Python comes from `FDI_PYTHON` (`cargo test-all` makes `target/py-venv` with
//! `tests/python/requirements.txt`); without it the tests say they are skipped, unless
//! `FDI_REQUIRE_PYTHON` is set (CI), where they fail.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use fdi_tests::{json, launch, launch_plain, python, repo_path, run_dir_of, spawn, Scratch};
use serde_json::Value;

const WATCHDOG: Duration = Duration::from_secs(300);

/// The arguments that make a run live for the tests: a free port, the run started once a viewer
/// subscribed, its summary in JSON.
pub(crate) const LIVE_ARGS: [&str; 4] = ["--live=127.0.0.1:0", "--live-wait", "60", "--json"];

/// A run of `fdi-launch` with [`LIVE_ARGS`]: its address, once it said it.
pub(crate) struct LiveRun {
    child: Child,
    pub(crate) addr: String,
    stderr: std::thread::JoinHandle<String>,
}

impl LiveRun {
    fn start(args: &[&str], out: &Path) -> Self {
        Self::of(spawn(&[args, &LIVE_ARGS[..]].concat(), out))
    }

    /// The run `child` started with [`LIVE_ARGS`] (its stderr piped).
    pub(crate) fn of(mut child: Child) -> Self {
        let stderr = child.stderr.take().expect("stderr");
        let (tx, rx) = mpsc::channel();
        let stderr = std::thread::spawn(move || {
            let mut all = String::new();
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if let Some(rest) = line.strip_prefix("fdi-launch: live at ws://") {
                    let addr = rest.split_whitespace().next().unwrap_or_default();
                    let _ = tx.send(addr.to_string());
                }
                all.push_str(&line);
                all.push('\n');
            }
            all
        });
        let addr = rx
            .recv_timeout(Duration::from_secs(120))
            .expect("the launcher says where it serves");
        Self {
            child,
            addr,
            stderr,
        }
    }

    /// Waits for the run's end; its summary.
    pub(crate) fn finish(self) -> Value {
        self.finish_with_stderr().0
    }

    /// Waits for the run's end; its summary, and what it printed on stderr.
    pub(crate) fn finish_with_stderr(self) -> (Value, String) {
        let out = fdi_tests::wait_with_watchdog(self.child, WATCHDOG);
        let stderr = self.stderr.join().expect("the stderr reader");
        // A realtime run may lose a robot for a while on a loaded machine (exit 3, said in
        // its summary): what the viewer saw is checked against the recording either way.
        let summary = fdi_tests::json_realtime(&Output {
            stderr: stderr.clone().into_bytes(),
            ..out
        });
        (summary, stderr)
    }
}

/// A test client, and the file it writes.
pub(crate) struct Client {
    child: Child,
    out: PathBuf,
}

/// Starts the test client on `addr` with `args`, writing into `dir`.
fn client(python: &Path, addr: &str, args: &[&str], dir: &Path) -> Client {
    client_by(Command::new(python), addr, args, dir)
}

/// [`client`], Python started by `python` (in a network namespace, say).
pub(crate) fn client_by(mut python: Command, addr: &str, args: &[&str], dir: &Path) -> Client {
    static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let out = dir.join(format!("client-{n}.json"));
    let child = python
        .arg(repo_path("tests/python/live_client.py"))
        .arg(addr)
        .args(args)
        .arg("--out")
        .arg(&out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting the live client");
    Client { child, out }
}

/// What a client wrote, once it ended (successfully).
pub(crate) fn client_output(c: Client) -> Value {
    let out = fdi_tests::wait_with_watchdog(c.child, WATCHDOG);
    assert!(
        out.status.success(),
        "the live client failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read(&c.out).expect("the client's file");
    serde_json::from_slice(&text).expect("the client's JSON")
}

/// A channel: encoding, schema name, schema encoding, schema text.
type Channel = (String, String, String, String);
/// Per topic, its messages: log time, text.
type Messages = BTreeMap<String, Vec<(u64, String)>>;

/// The MCAP export of `run_dir`: per topic its channel and its messages.
fn exported(run_dir: &Path) -> (BTreeMap<String, Channel>, Messages) {
    let run = run_dir.to_string_lossy();
    let out = launch_plain(&["trace", "export", &run, "--format", "mcap"], WATCHDOG);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(run_dir.join("export/run.mcap")).expect("run.mcap");
    let mut channels = BTreeMap::new();
    let mut messages = Messages::new();
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("a message");
        let c = &m.channel;
        let s = c.schema.as_ref().expect("a schema");
        channels.insert(
            c.topic.clone(),
            (
                c.message_encoding.clone(),
                s.name.clone(),
                s.encoding.clone(),
                String::from_utf8(s.data.to_vec()).expect("a JSON schema"),
            ),
        );
        messages.entry(c.topic.clone()).or_default().push((
            m.log_time,
            String::from_utf8(m.data.to_vec()).expect("JSON"),
        ));
    }
    (channels, messages)
}

/// What a client received on `topic`: log time, text.
fn received(seen: &Value, topic: &str) -> Vec<(u64, String)> {
    seen["messages"][topic]
        .as_array()
        .expect("messages")
        .iter()
        .map(|m| {
            (
                m[0].as_u64().expect("a log time"),
                m[1].as_str().expect("text").to_string(),
            )
        })
        .collect()
}

/// The tick of a message's text.
fn tick_of(text: &str) -> u64 {
    serde_json::from_str::<Value>(text).expect("JSON")["k"]
        .as_u64()
        .expect("k")
}

/// The ticks the join matched for each agent: those of its detector topic in the recording (the
/// live view publishes joined ticks; in realtime a tick may miss a record under load).
fn joined(messages: &Messages) -> BTreeMap<String, std::collections::BTreeSet<u64>> {
    messages
        .iter()
        .filter_map(|(topic, msgs)| {
            let agent = topic.strip_suffix("/detectors")?;
            Some((
                agent.to_string(),
                msgs.iter().map(|(_, text)| tick_of(text)).collect(),
            ))
        })
        .collect()
}

/// The test client's arguments: subscribed to `topics`, until the last tick of `ticks` the
/// stream keeps (every `every`-th).
pub(crate) fn client_args(topics: &[&str], (every, ticks): (u64, u64)) -> Vec<String> {
    let last = ((ticks - 1) / every * every).to_string();
    let mut args = vec!["--until-k".to_string(), last];
    for t in topics {
        args.extend(["--topic".to_string(), t.to_string()]);
    }
    args
}

/// Runs `args` live with a client subscribed to `topics` that offers `subprotocol`, and checks
/// what it saw ([`check_watched`]). The run's summary.
fn watched_run(
    python: &Path,
    (args, subprotocol): (&[&str], &str),
    topics: &[&str],
    (every, ticks, whole): (u64, u64, bool),
) -> Value {
    let out = Scratch::new("live");
    let run = LiveRun::start(args, &out.0);
    let mut client_args = client_args(topics, (every, ticks));
    client_args.extend(["--subprotocol".to_string(), subprotocol.to_string()]);
    let client_args: Vec<&str> = client_args.iter().map(String::as_str).collect();
    let seen = client_output(client(python, &run.addr, &client_args, &out.0));
    let summary = run.finish();
    check_watched(&seen, &summary, topics, (every, ticks, whole));
    summary
}

/// Checks what a client subscribed to `topics` saw (`seen`) of the run of `summary` against the
/// run's MCAP export, the stream keeping every `every`-th tick of `ticks` (every one of them
/// when `whole`: a lockstep run joins every tick).
pub(crate) fn check_watched(
    seen: &Value,
    summary: &Value,
    topics: &[&str],
    (every, ticks, whole): (u64, u64, bool),
) {
    let run_dir: PathBuf = run_dir_of(summary);
    let (channels, messages) = exported(&run_dir);

    // The channels: every topic of the recording, with its very encoding and schema.
    let advertised = seen["channels"].as_object().expect("channels");
    for (topic, (encoding, name, schema_encoding, schema)) in &channels {
        let c = advertised
            .get(topic)
            .unwrap_or_else(|| panic!("{topic}: recorded but not advertised"));
        assert_eq!(c["encoding"], encoding.as_str(), "{topic}");
        assert_eq!(c["schemaName"], name.as_str(), "{topic}");
        assert_eq!(c["schemaEncoding"], schema_encoding.as_str(), "{topic}");
        assert_eq!(c["schema"], schema.as_str(), "{topic}: another schema");
    }
    for topic in advertised.keys() {
        assert!(
            channels.contains_key(topic) || topic == "/events",
            "{topic}: advertised, not in the recording"
        );
    }

    // The messages: the recording's of the kept ticks the join matched, to the byte.
    let kept = ticks.div_ceil(every);
    let joined = joined(&messages);
    for topic in topics {
        let agent = &topic[..topic[1..].find('/').expect("an agent's topic") + 1];
        let want: Vec<(u64, String)> = messages[*topic]
            .iter()
            .filter(|(_, text)| {
                let k = tick_of(text);
                k.is_multiple_of(every)
                    && (topic.ends_with("/latency") || joined[agent].contains(&k))
            })
            .cloned()
            .collect();
        if whole {
            assert_eq!(
                want.len() as u64,
                kept,
                "{topic}: the recording's kept ticks"
            );
        } else {
            assert!(
                want.len() as u64 * 10 >= kept * 9,
                "{topic}: {} of {kept}",
                want.len()
            );
        }
        let got = received(seen, topic);
        assert_eq!(got.len(), want.len(), "{topic}: messages received");
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g, w, "{topic}");
        }
    }
    // The time, broadcast at each kept tick the join matched for some robot.
    let times: Vec<u64> = seen["times"]
        .as_array()
        .expect("times")
        .iter()
        .map(|t| t.as_u64().expect("ns"))
        .collect();
    let any: std::collections::BTreeSet<u64> = joined.values().flatten().copied().collect();
    let want: Vec<u64> = any
        .iter()
        .filter(|k| k.is_multiple_of(every))
        .map(|k| (fdi_common::engine::tick_time(*k, 1e-3) * 1e9).round() as u64)
        .collect();
    assert_eq!(times, want, "the time broadcasts");
    let live = &summary["live"];
    assert_eq!(live["clients"], 1, "{live}");
    assert_eq!(live["ticks_published"], want.len(), "{live}");
    assert_eq!(live["records_dropped"], 0, "{live}");
}

/// The digest of the paper scenario for `seconds` on the in-process engine, without a viewer.
pub(crate) fn inproc_digest(seconds: &str) -> Value {
    let out = Scratch::new("live-ref");
    let s = json(&launch(
        &[
            "run",
            "--engine",
            "inproc",
            "--duration-s",
            seconds,
            "--json",
        ],
        &out.0,
        WATCHDOG,
    ));
    s["trace_digest"].clone()
}

#[test]
fn a_viewer_sees_the_recording_s_channels_and_every_kept_tick_on_both_engines_and_clocks() {
    let Some(py) = python() else { return };
    let topics = [
        "/agent1/tracking_error",
        "/agent1/estimate",
        "/agent1/detectors",
        "/agent4/attack",
    ];
    let reference = inproc_digest("1");
    // Paced at half real time, 500 ticks a second at most 100 kept: every 5th tick. The clients
    // offer the SDK's name of the protocol, or only its specification's (older viewers).
    let pace = ["--pace", "0.5", "--live-rate", "100", "--duration-s", "1"];
    let inproc = watched_run(
        &py,
        (
            &[&["run", "--engine", "inproc"][..], &pace].concat(),
            "foxglove.sdk.v1",
        ),
        &topics,
        (5, 1000, true),
    );
    assert_eq!(
        inproc["trace_digest"], reference,
        "watched, paced: the same run"
    );
    let ipc = watched_run(
        &py,
        (
            &[&["run", "--engine", "ipc"][..], &pace].concat(),
            "foxglove.websocket.v1",
        ),
        &topics,
        (5, 1000, true),
    );
    assert_eq!(
        ipc["trace_digest"], reference,
        "watched, paced: the same run"
    );
    // Realtime: 1000 ticks a second, 100 kept; the latency stamps too.
    let realtime = [
        "run",
        "--engine",
        "ipc",
        "--clock",
        "realtime",
        "--live-rate",
        "100",
        "--duration-s",
        "1",
    ];
    let mut rt_topics = topics.to_vec();
    rt_topics.push("/agent2/latency");
    watched_run(
        &py,
        (&realtime, "foxglove.websocket.v1"),
        &rt_topics,
        (10, 1000, false),
    );
}

#[test]
fn viewers_that_never_read_leave_or_send_garbage_change_nothing_of_the_run() {
    let Some(py) = python() else { return };
    let reference = inproc_digest("3");
    let out = Scratch::new("live-bad");
    // At real time, every tick kept: some 40 MB of messages for a client of every topic, more
    // than its socket and its queue in the server hold.
    let run = LiveRun::start(
        &[
            "run",
            "--engine",
            "ipc",
            "--duration-s",
            "3",
            "--pace",
            "1",
            "--live-rate",
            "1000",
        ],
        &out.0,
    );
    let every: Vec<String> = (1..=4)
        .flat_map(|a| {
            fdi_report::topics::topics()
                .into_iter()
                .filter(|(n, _)| !matches!(*n, "latency" | "actuation" | "monitor"))
                .map(move |(n, _)| format!("/agent{a}/{n}"))
        })
        .collect();
    // The client that leaves mid-run subscribes first: the run starts once it did.
    let leaves = client(
        &py,
        &run.addr,
        &[
            "--mode",
            "leave",
            "--leave-after",
            "5",
            "--topic",
            "/agent2/state",
        ],
        &out.0,
    );
    let mut args = vec!["--mode", "never-read"];
    for t in &every {
        args.extend(["--topic", t.as_str()]);
    }
    let never = client(&py, &run.addr, &args, &out.0);
    // Garbage: a request that is no HTTP, then bytes that are no WebSocket frame after a
    // handshake that asks for no subprotocol; and a connection that sends nothing, held open
    // past the run's end.
    for bytes in [
        &b"\x00\xff\x13garbage\r\n\r\n"[..],
        &b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
           Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n\
           \x82\xff\x00\x00\x00\x00\x00\x00\x00\x10garbage"[..],
    ] {
        if let Ok(mut s) = std::net::TcpStream::connect(&run.addr) {
            let _ = s.write_all(bytes);
        }
    }
    let silent = std::net::TcpStream::connect(&run.addr).expect("a connection");
    let summary = run.finish();
    assert_eq!(
        summary["trace_digest"], reference,
        "the run as without viewers"
    );
    assert_eq!(summary["ticks"], 3000);
    assert!(summary.get("partial").is_none(), "{summary}");
    let run_dir = run_dir_of(&summary);
    for p in ["agent-1", "agent-4", "attacker", "control-center"] {
        let trace = run_dir.join(format!("traces/{p}.trace"));
        assert!(trace.exists(), "{}: kept whole", trace.display());
    }
    assert!(summary["live"]["clients"].as_u64().expect("clients") >= 2);
    let left = client_output(leaves);
    assert_eq!(
        left["messages"]["/agent2/state"].as_array().map(Vec::len),
        Some(5),
        "the client that left read its 5 messages: {}",
        summary["live"]
    );
    // The one that never read was let go when the server stopped; what it could not take was
    // dropped and counted (some 40 MB against its socket's and its outbox's few).
    assert_eq!(client_output(never)["mode"], "never-read");
    let lost = summary["live"]["client_messages_dropped"]
        .as_u64()
        .expect("client_messages_dropped");
    assert!(lost > 0, "nothing counted lost: {}", summary["live"]);
    drop(silent);
}

/// Whether `path` (`/agent<id>/<topic>` then, after `sep`, `field` or `field[i]`) names a field
/// of a topic of a run of `robots` (their ids and joint counts); its index within the robot's
/// joints.
fn field_exists(path: &str, sep: char, robots: &BTreeMap<u32, usize>) -> Result<(), String> {
    use fdi_report::topics::{topics, Ty};
    let rest = path
        .strip_prefix("/agent")
        .ok_or_else(|| format!("{path}: not an agent's topic"))?;
    let (id, rest) = rest
        .split_once('/')
        .ok_or_else(|| format!("{path}: no topic"))?;
    let id: u32 = id.parse().map_err(|_| format!("{path}: agent {id}"))?;
    let joints = *robots
        .get(&id)
        .ok_or_else(|| format!("{path}: the run has no robot {id}"))?;
    let (topic, field) = rest
        .rsplit_once(sep)
        .ok_or_else(|| format!("{path}: no field"))?;
    let (field, index) = match field.split_once('[') {
        Some((f, i)) => {
            let i: usize = i
                .trim_end_matches(']')
                .parse()
                .map_err(|_| format!("{path}: index"))?;
            (f, Some(i))
        }
        None => (field, None),
    };
    let (_, schema) = topics()
        .into_iter()
        .find(|(n, _)| *n == topic)
        .ok_or_else(|| format!("{path}: no topic {topic}"))?;
    let (_, ty, _) = schema
        .fields
        .iter()
        .find(|(n, _, _)| *n == field)
        .ok_or_else(|| format!("{path}: {topic} has no field {field}"))?;
    match (ty, index) {
        (Ty::Nums, Some(i)) if i < joints => Ok(()),
        (Ty::Nums, _) => Err(format!("{path}: a joint of the robot's {joints}")),
        (_, None) => Ok(()),
        (_, Some(_)) => Err(format!("{path}: {field} is not an array")),
    }
}

/// The values of attribute `attr` of every element `<tag …>` of `xml`.
fn xml_values(xml: &str, tag: &str, attr: &str) -> Vec<String> {
    let open = format!("<{tag} ");
    let key = format!("{attr}=\"");
    xml.match_indices(&open)
        .filter_map(|(at, _)| {
            let rest = &xml[at..];
            let end = rest.find('>')?;
            let el = &rest[..end];
            let v = el.find(&key)? + key.len();
            Some(el[v..v + el[v..].find('"')?].to_string())
        })
        .collect()
}

/// The text of every element `<tag>…</tag>` of `xml`.
fn xml_texts(xml: &str, tag: &str) -> Vec<String> {
    let (open, close) = (format!("<{tag}>"), format!("</{tag}>"));
    xml.match_indices(&open)
        .filter_map(|(at, _)| {
            let from = at + open.len();
            Some(xml[from..from + xml[from..].find(&close)?].to_string())
        })
        .collect()
}

/// The number of field paths and of bound lines of a Foxglove layout, every path checked
/// against the topics of `robots` and every bound against the paper's.
fn check_foxglove(text: &str, robots: &BTreeMap<u32, usize>, bounds: &[f64]) -> (usize, usize) {
    let layout: Value = serde_json::from_str(text).expect("JSON");
    let mut fields = 0;
    let mut lines = 0;
    for (id, config) in layout["configById"].as_object().expect("configById") {
        for p in config["paths"].as_array().into_iter().flatten() {
            let value = p["value"].as_str().expect("a path");
            match value.parse::<f64>() {
                Ok(x) => {
                    assert!(bounds.contains(&x), "{id}: {x} is no bound of the paper");
                    lines += 1;
                }
                Err(_) => {
                    field_exists(value, '.', robots).unwrap_or_else(|e| panic!("{id}: {e}"));
                    fields += 1;
                }
            }
        }
    }
    (fields, lines)
}

/// The number of curves and of bound series of a PlotJuggler layout, checked as
/// [`check_foxglove`] does.
fn check_plotjuggler(xml: &str, robots: &BTreeMap<u32, usize>, bounds: &[f64]) -> (usize, usize) {
    let snippets = xml_values(xml, "snippet", "name");
    for source in xml_texts(xml, "linked_source") {
        field_exists(&source, '/', robots).unwrap_or_else(|e| panic!("{e}"));
    }
    for f in xml_texts(xml, "function") {
        let x: f64 = f
            .trim()
            .strip_prefix("return ")
            .and_then(|x| x.parse().ok())
            .unwrap_or_else(|| panic!("{f}: a bound"));
        assert!(bounds.contains(&x), "{x} is no bound of the paper");
    }
    let curves = xml_values(xml, "curve", "name");
    for c in &curves {
        if !snippets.contains(c) {
            field_exists(c, '/', robots).unwrap_or_else(|e| panic!("{e}"));
        }
    }
    (curves.len(), snippets.len())
}

/// `fdi-launch layout` with `args`: its stdout.
fn layout(args: &[&str]) -> String {
    let mut all = vec!["layout"];
    all.extend_from_slice(args);
    let out = launch_plain(&all, WATCHDOG);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("UTF-8")
}

#[test]
fn the_layouts_name_only_fields_of_the_run_s_topics_and_the_paper_s_bounds() {
    use fdi_report::report::{PAPER_POSITION_BOUND_RAD, PAPER_VELOCITY_BOUND_RAD_S};
    let bounds = [
        PAPER_POSITION_BOUND_RAD,
        -PAPER_POSITION_BOUND_RAD,
        PAPER_VELOCITY_BOUND_RAD_S,
        -PAPER_VELOCITY_BOUND_RAD_S,
    ];
    let paper: BTreeMap<u32, usize> = (1..=4).map(|id| (id, 2)).collect();
    // The shipped layouts are what the command makes for the paper's scenario.
    let text = std::fs::read_to_string(repo_path("examples/live/paper-figures.foxglove.json"))
        .expect("the Foxglove layout");
    assert_eq!(
        text,
        layout(&[]),
        "regenerate: fdi-launch layout > examples/live/…"
    );
    let xml = std::fs::read_to_string(repo_path("examples/live/paper-figures.plotjuggler.xml"))
        .expect("the PlotJuggler layout");
    assert_eq!(xml, layout(&["--viewer", "plotjuggler"]));
    // Foxglove: every plot path is a field of a topic, or a reference line at a paper bound;
    // PlotJuggler: every curve is a field of a topic, or a series made from one (the bounds).
    assert_eq!(
        check_foxglove(&text, &paper, &bounds),
        (64, 16),
        "every robot's four figures"
    );
    assert_eq!(check_plotjuggler(&xml, &paper, &bounds), (80, 16));
    // A team of Pandas: seven joints in every robot's plots.
    let pandas: BTreeMap<u32, usize> = (1..=4).map(|id| (id, 7)).collect();
    let team = repo_path("scenarios/panda-team.toml");
    let team = team.to_str().expect("a UTF-8 path");
    let text = layout(&[team]);
    assert_eq!(
        check_foxglove(&text, &pandas, &bounds),
        (4 * 7 * 6 + 4 * 4, 16)
    );
    assert!(text.contains("/agent4/torque/applied.u_nm[6]"));
    let xml = layout(&[team, "--viewer", "plotjuggler"]);
    assert_eq!(
        check_plotjuggler(&xml, &pandas, &bounds),
        (4 * 7 * 6 + 4 * 4 + 16, 16)
    );
    // The check can fail: a renamed topic or field, a robot or a joint the run lacks.
    assert!(field_exists("/agent1/tracking_error.e_rad[0]", '.', &paper).is_ok());
    assert!(field_exists("/agent1/tracking_errors.e_rad[0]", '.', &paper).is_err());
    assert!(field_exists("/agent1/tracking_error/e_rads[0]", '/', &paper).is_err());
    assert!(field_exists("/agent5/estimate.s_hat_rad_s[0]", '.', &paper).is_err());
    assert!(field_exists("/agent1/estimate.s_hat_rad_s[2]", '.', &paper).is_err());
    assert!(field_exists("/agent1/estimate.s_hat_rad_s[6]", '.', &pandas).is_ok());
    assert!(field_exists("/agent1/estimate.s_hat_rad_s[7]", '.', &pandas).is_err());
    // The Panda team's layout is not the paper's: the paper's check refuses it.
    let refused = std::panic::catch_unwind(|| check_foxglove(&text, &paper, &bounds));
    assert!(refused.is_err(), "the paper's robots have two joints");
}

/// A run that keeps no traces is served from the records as they are made: the launcher's join
/// of the processes' pipes (ipc), the engine's own records (in-process). What the viewer gets is
/// the recording of the same run with whole traces, to the byte.
#[test]
fn a_run_that_keeps_no_traces_is_served_from_its_records_as_they_are_made() {
    let Some(py) = python() else { return };
    // The reference: the same run, whole traces, exported.
    let out = Scratch::new("live-ref-export");
    let reference = json(&launch(
        &["run", "--engine", "inproc", "--duration-s", "1", "--json"],
        &out.0,
        WATCHDOG,
    ));
    let (_, recorded) = exported(&run_dir_of(&reference));
    let topic = "/agent3/estimate";
    let every = 5;
    let want: Vec<(u64, String)> = recorded[topic]
        .iter()
        .filter(|(_, text)| tick_of(text).is_multiple_of(every))
        .cloned()
        .collect();
    assert_eq!(want.len(), 200);
    for engine in ["ipc", "inproc"] {
        let out = Scratch::new("live-none");
        let run = LiveRun::start(
            &[
                "run",
                "--engine",
                engine,
                "--traces",
                "none",
                "--pace",
                "0.5",
                "--live-rate",
                "100",
                "--duration-s",
                "1",
            ],
            &out.0,
        );
        let seen = client_output(client(
            &py,
            &run.addr,
            &["--until-k", "995", "--topic", topic],
            &out.0,
        ));
        let summary = run.finish();
        assert_eq!(
            summary["trace_digest"], reference["trace_digest"],
            "{engine}"
        );
        let got = received(&seen, topic);
        assert_eq!(
            got, want,
            "{engine}: what the viewer got is the recording's"
        );
    }
}
