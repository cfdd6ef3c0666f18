//! A rogue peer on a lab network, for the tests of runs split over hosts: what an adversary
//! outside the run's hosts tries (tests/tests/multihost.rs). Not part of fdi-mas.
//!
//! ```text
//! fdi-rogue hold N ADDRESS:PORT SECONDS [udp]
//!     N plain TCP connections to the port (every other one half-closed), held, saying nothing;
//!     with `udp`, N UDP sockets sending a datagram of garbage to it every 100 ms
//! fdi-rogue flood N ADDRESS:PORT SECONDS RATE
//!     N UDP sockets sending, RATE a second in all, datagrams shaped like QUIC connection
//!     openers (long header, Initial, version 1, connection ids of 8 bytes, 1200 bytes, the rest
//!     random): what a QUIC server takes for a new connection until it tries to decrypt it
//! fdi-rogue no-cert CA ENDPOINT SECONDS
//!     a QUIC session that trusts the lab's CA but shows no certificate: says whether it
//!     ever reached a serve
//! fdi-rogue [--tls CA CERT KEY] ENDPOINT[,ENDPOINT...] forge-ahead JUMP SECONDS
//!     the first measurement frame seen goes back on its key numbered JUMP ahead (a payload
//!     is a batch of frames: each frame of it counts)
//! fdi-rogue [--tls CA CERT KEY] ENDPOINT bias AGENT RAD FRAMES SECONDS
//!     each measurement frame of AGENT seen goes back on its key with y[0] + RAD, FRAMES times
//!     (forge-ahead and bias end once their frames are forged and the stream went quiet for
//!     0.5 s, or after SECONDS)
//! fdi-rogue [--tls CA CERT KEY] ENDPOINT impersonate HOST PREFIX SECONDS
//!     measurement frames put every millisecond on HOST's key of run PREFIX, and on the
//!     rogue's own; says whether HOST's serve was ever seen
//! fdi-rogue [--tls CA CERT KEY] ENDPOINT request HOST FROM FILE
//!     the run request in FILE sent to HOST's serve as if from FROM; prints the answer
//! fdi-rogue [--tls CA CERT KEY] ENDPOINT ask HOST FROM PREFIX WHAT BODY
//!     BODY asked of HOST's serve on its key WHAT of run PREFIX as if from FROM
//! ```

use std::time::{Duration, Instant};

use fdi_net::{keys, Net, NetConfig, Security};
use fdi_runtime::ipc::{MeasurementMsg, Stream};
use zerocopy::{FromBytes, IntoBytes};

fn arg<T: std::str::FromStr>(args: &[String], i: usize, what: &str) -> T {
    args.get(i)
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| panic!("fdi-rogue: argument {i} ({what}) missing or malformed"))
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("hold") {
        hold(&args);
        return;
    }
    if args.first().map(String::as_str) == Some("flood") {
        flood(&args);
        return;
    }
    if args.first().map(String::as_str) == Some("no-cert") {
        no_cert(&args);
        return;
    }
    let security = if args.first().map(String::as_str) == Some("--tls") {
        let files: Vec<String> = args.drain(..4).skip(1).collect();
        Security::Tls {
            ca: files[0].clone().into(),
            cert: files[1].clone().into(),
            key: files[2].clone().into(),
            // The rogue knows the lab's names; its certificate decides what it may do.
            lab: vec!["control".into(), "cell".into(), "rogue".into()],
            // It listens nowhere.
            peers: Vec::new(),
        }
    } else {
        Security::Insecure
    };
    // One endpoint or several, separated by commas.
    let endpoints: String = arg(&args, 0, "endpoint");
    let net = Net::open(&NetConfig {
        listen: Vec::new(),
        connect: endpoints.split(',').map(str::to_string).collect(),
        security,
    })
    .expect("fdi-rogue: opening a session");
    match args.get(1).map(String::as_str) {
        Some("forge-ahead") => forge(
            &net,
            Forgery::Ahead(arg(&args, 2, "jump")),
            arg(&args, 3, "seconds"),
        ),
        Some("bias") => forge(
            &net,
            Forgery::Bias(
                arg(&args, 2, "agent"),
                arg(&args, 3, "rad"),
                arg(&args, 4, "frames"),
            ),
            arg(&args, 5, "seconds"),
        ),
        Some("impersonate") => impersonate(
            &net,
            &arg::<String>(&args, 2, "host"),
            &arg::<String>(&args, 3, "prefix"),
            arg(&args, 4, "seconds"),
        ),
        Some("request") => {
            let body = std::fs::read(arg::<String>(&args, 4, "file")).expect("request file");
            let key = keys::run_request(
                &arg::<String>(&args, 2, "host"),
                &arg::<String>(&args, 3, "from"),
            );
            match ask(&net, &key, &body) {
                Ok(answer) => println!("answered: {}", String::from_utf8_lossy(&answer)),
                Err(e) => println!("refused: {e}"),
            }
        }
        Some("ask") => {
            let key = keys::asked(
                &arg::<String>(&args, 2, "host"),
                &arg::<String>(&args, 3, "from"),
                &arg::<String>(&args, 4, "prefix"),
                &arg::<String>(&args, 5, "what"),
            );
            let body: String = arg(&args, 6, "body");
            match ask(&net, &key, body.as_bytes()) {
                Ok(answer) => println!("answered {} bytes", answer.len()),
                Err(e) => println!("refused: {e}"),
            }
        }
        other => panic!("fdi-rogue: no mode {other:?}"),
    }
}

/// Asks `key` (sent again while nobody answers, for up to 10 s: [`Net::request`]).
fn ask(net: &Net, key: &str, body: &[u8]) -> Result<Vec<u8>, fdi_net::NetError> {
    net.request(key, body, Duration::from_secs(10))
}

/// A Zenoh session without a certificate (Zenoh directly: fdi-mas never opens one).
fn no_cert(args: &[String]) {
    use zenoh::Wait as _;
    let (ca, endpoint, seconds): (String, String, f64) = (
        arg(args, 1, "ca"),
        arg(args, 2, "endpoint"),
        arg(args, 3, "seconds"),
    );
    let mut c = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("listen/endpoints", "[]".into()),
        ("connect/endpoints", format!("[\"{endpoint}\"]")),
        ("transport/link/protocols", "[\"quic\"]".into()),
        (
            "transport/link/tls/root_ca_certificate",
            format!("\"{ca}\""),
        ),
    ] {
        c.insert_json5(k, &v).expect("a Zenoh setting");
    }
    let session = zenoh::open(c).wait().expect("fdi-rogue: opening a session");
    let began = Instant::now();
    let mut seen = false;
    while began.elapsed().as_secs_f64() < seconds && !seen {
        seen = session
            .liveliness()
            .get("fdi-mas/p/*/serve")
            .timeout(Duration::from_millis(200))
            .wait()
            .is_ok_and(|r| r.recv().is_ok_and(|reply| reply.result().is_ok()));
        std::thread::sleep(Duration::from_millis(100));
    }
    println!("without a certificate, a serve seen: {seen}");
}

/// Connections that say nothing (or UDP garbage), held for a while.
fn hold(args: &[String]) {
    let (n, address, seconds): (usize, String, f64) = (
        arg(args, 1, "connections"),
        arg(args, 2, "address"),
        arg(args, 3, "seconds"),
    );
    if args.get(4).map(String::as_str) == Some("udp") {
        let sockets: Vec<std::net::UdpSocket> = (0..n)
            .filter_map(|_| std::net::UdpSocket::bind("0.0.0.0:0").ok())
            .collect();
        println!("holding {} connections", sockets.len());
        let garbage = [0xc3u8; 1200];
        let began = Instant::now();
        while began.elapsed().as_secs_f64() < seconds {
            for s in &sockets {
                let _ = s.send_to(&garbage, &address);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        return;
    }
    let mut held = Vec::new();
    for i in 0..n {
        match std::net::TcpStream::connect(&address) {
            Ok(s) => {
                if i % 2 == 1 {
                    let _ = s.shutdown(std::net::Shutdown::Write);
                }
                held.push(s);
            }
            Err(e) => println!("connection {i}: {e}"),
        }
    }
    println!("holding {} connections", held.len());
    std::thread::sleep(Duration::from_secs_f64(seconds));
}

/// QUIC Initial-shaped datagrams from many sockets at a rate.
fn flood(args: &[String]) {
    let (n, address, seconds, rate): (usize, String, f64, f64) = (
        arg(args, 1, "sockets"),
        arg(args, 2, "address"),
        arg(args, 3, "seconds"),
        arg(args, 4, "rate"),
    );
    let sockets: Vec<std::net::UdpSocket> = (0..n)
        .filter_map(|_| std::net::UdpSocket::bind("0.0.0.0:0").ok())
        .collect();
    assert!(!sockets.is_empty(), "fdi-rogue: no socket");
    // xorshift64: random enough for garbage, no dependency.
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15 ^ u64::from(std::process::id());
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let mut packet = [0u8; 1200];
    let began = Instant::now();
    let mut sent = 0u64;
    while began.elapsed().as_secs_f64() < seconds {
        // Paced: the packets due by now.
        let due = (began.elapsed().as_secs_f64() * rate) as u64;
        while sent < due {
            for b in packet.iter_mut() {
                *b = next() as u8;
            }
            // Long header, fixed bit, type Initial, packet number length in the low bits.
            packet[0] = 0xc0 | (packet[0] & 0x03);
            packet[1..5].copy_from_slice(&1u32.to_be_bytes());
            packet[5] = 8; // destination connection id, 8 random bytes
            packet[14] = 8; // source connection id, 8 random bytes
            packet[23] = 0; // no token
            let length = (1200 - 26) as u16 | 0x4000; // two-byte varint
            packet[24..26].copy_from_slice(&length.to_be_bytes());
            let s = &sockets[(sent as usize) % sockets.len()];
            let _ = s.send_to(&packet, &address);
            sent += 1;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    println!(
        "sent {sent} QUIC-Initial-shaped datagrams from {} sockets",
        sockets.len()
    );
}

/// What the rogue forges.
#[derive(Clone, Copy)]
enum Forgery {
    /// One frame, numbered this far ahead of the one seen.
    Ahead(u64),
    /// Copies of an agent's frames (agent, bias on y[0] in rad, how many).
    Bias(u32, f64, u64),
}

/// Forged measurement frames put back on the keys they were seen on. The frames seen are handed to this
/// thread, which puts the forgeries (a Zenoh callback must not declare or block).
fn forge(net: &Net, forgery: Forgery, seconds: f64) {
    let (tx, rx) = std::sync::mpsc::channel::<(String, Vec<u8>)>();
    let _sub = net
        .subscribe(
            &keys::stream_any("*", Stream::Measurement),
            move |key, bytes| {
                let _ = tx.send((key.to_string(), bytes));
            },
        )
        .expect("fdi-rogue: subscribing");
    let limit = match forgery {
        Forgery::Ahead(_) => 1,
        Forgery::Bias(_, _, frames) => frames,
    };
    let mut outboxes: Vec<(String, fdi_net::NetOutbox)> = Vec::new();
    let (mut forged, mut seen) = (0u64, 0u64);
    let began = Instant::now();
    // Until the frames asked for are forged and the run's stream has gone quiet (the session
    // lives on while the run does, so that what it put goes out: a rogue that exited right
    // after its last put lost the frames still queued), or at most `seconds`.
    let mut quiet_since = Instant::now();
    while began.elapsed().as_secs_f64() < seconds {
        if forged >= limit && quiet_since.elapsed() > Duration::from_millis(500) {
            break;
        }
        let Ok((key, bytes)) = rx.recv_timeout(Duration::from_millis(50)) else {
            continue;
        };
        quiet_since = Instant::now();
        // A payload is a batch of one or more frames (what the bridge drained at once).
        let size = std::mem::size_of::<MeasurementMsg>();
        if bytes.is_empty() || bytes.len() % size != 0 {
            continue;
        }
        for frame in bytes.chunks_exact(size) {
            seen += 1;
            let Ok(mut m) = MeasurementMsg::read_from_bytes(frame) else {
                continue;
            };
            if forged >= limit {
                continue;
            }
            match forgery {
                Forgery::Ahead(jump) => m.seq += jump,
                Forgery::Bias(agent, rad, _) if m.agent == agent => m.y[0] += rad,
                Forgery::Bias(..) => continue,
            }
            if !outboxes.iter().any(|(k, _)| *k == key) {
                outboxes.push((key.clone(), net.outbox(&key).expect("outbox")));
            }
            if let Some((_, o)) = outboxes.iter().find(|(k, _)| *k == key) {
                if o.put(m.as_bytes()).is_ok() {
                    forged += 1;
                }
            }
        }
    }
    println!("forged {forged} frames of {seen} seen");
}

/// Frames put as if from `host`, and from the rogue itself, for a while.
fn impersonate(net: &Net, host: &str, prefix: &str, seconds: f64) {
    let theirs = net
        .outbox(&keys::stream(host, prefix, Stream::Measurement))
        .expect("outbox");
    let own = net
        .outbox(&keys::stream("rogue", prefix, Stream::Measurement))
        .expect("outbox");
    let frame = MeasurementMsg {
        seq: 1 << 40,
        agent: 3,
        dof: 2,
        t: 0.0,
        y: [0.5; fdi_common::scenario::MAX_DOF],
        yd: [0.0; fdi_common::scenario::MAX_DOF],
        agent_sent_ns: 0,
        attacker_received_ns: 0,
        attacker_sent_ns: 0,
        flags: 0,
        reserved: 0,
    };
    let began = Instant::now();
    let mut seen = false;
    let mut puts = 0u64;
    while began.elapsed().as_secs_f64() < seconds {
        for o in [&theirs, &own] {
            if o.put(frame.as_bytes()).is_ok() {
                puts += 1;
            }
        }
        if puts.is_multiple_of(200) {
            seen |= net
                .alive(&keys::serve(host), Duration::from_millis(50))
                .unwrap_or(false);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    println!("put {puts} frames; the serve of `{host}` seen: {seen}");
}
