//! Who may do what on the network: the access control of a TLS session (Zenoh's, by
//! certificate) and the kernel's socket filter on the QUIC listener (by address).

/// The access control of a TLS session: each host of `lab` (by its certificate's common
/// name) may put and hold liveliness tokens only under `fdi-mas/p/<h>/`, declare queryables and
/// reply only under `fdi-mas/q/<h>/`, ask only as `fdi-mas/q/*/<h>/`, and subscribe to
/// anything of fdi-mas; whatever else comes in is denied, and nothing goes out to a peer that
/// is not a host of `lab`.
pub fn access_control(lab: &[String]) -> String {
    use serde_json::json;
    let all = [
        "put",
        "delete",
        "declare_subscriber",
        "query",
        "declare_queryable",
        "reply",
        "liveliness_token",
        "declare_liveliness_subscriber",
        "liveliness_query",
    ];
    let rule = |id: String, messages: &[&str], flow: &str, keys: Vec<String>| {
        json!({"id": id, "messages": messages, "flows": [flow], "permission": "allow",
               "key_exprs": keys})
    };
    let mut rules = vec![
        rule(
            "listen".into(),
            &[
                "declare_subscriber",
                "declare_liveliness_subscriber",
                "liveliness_query",
            ],
            "ingress",
            vec!["fdi-mas/**".into()],
        ),
        rule("out".into(), &all, "egress", vec!["**".into()]),
    ];
    let (mut subjects, mut policies) = (Vec::new(), Vec::new());
    for (i, h) in lab.iter().enumerate() {
        let own = [
            rule(
                format!("says{i}"),
                &["put", "delete", "liveliness_token", "reply"],
                "ingress",
                vec![format!("fdi-mas/p/{h}/**")],
            ),
            rule(
                format!("answers{i}"),
                &["declare_queryable", "reply"],
                "ingress",
                vec![format!("fdi-mas/q/{h}/**")],
            ),
            rule(
                format!("asks{i}"),
                &["query"],
                "ingress",
                vec![format!("fdi-mas/q/*/{h}/**")],
            ),
        ];
        let mut ids = vec![json!("listen"), json!("out")];
        ids.extend(own.iter().map(|r| r["id"].clone()));
        rules.extend(own);
        subjects.push(json!({"id": format!("host{i}"), "cert_common_names": [h]}));
        policies.push(json!({"rules": ids, "subjects": [format!("host{i}")]}));
    }
    json!({"enabled": true, "default_permission": "deny", "rules": rules,
           "subjects": subjects, "policies": policies})
    .to_string()
}

/// Makes the kernel drop every datagram that reaches this process's UDP sockets bound to the
/// endpoints `listen` (its QUIC listeners, Zenoh's sockets) unless it comes from one of `peers`
/// or from loopback: a socket filter (classic BPF) on each. Zenoh's QUIC listener takes
/// connections one at a time, and pauses a tenth of a second after each connection opener it
/// could not decrypt: a flood of them from anywhere (no certificate needed) kept the lab's own
/// hosts out (issue 51). The lab's hosts are known by their endpoints; anything else never
/// reaches Zenoh. Fails when a listener's socket is not found or the filter is not taken.
pub fn admit_only(listen: &[String], peers: &[std::net::IpAddr]) -> Result<(), String> {
    use std::net::ToSocketAddrs as _;
    // The program's jumps are a byte long: about 60 addresses at most.
    if peers.len() > MAX_FILTERED_PEERS {
        return Err(format!(
            "{} addresses, more than the {MAX_FILTERED_PEERS} a filter holds",
            peers.len()
        ));
    }
    let program = peer_filter(peers);
    let me = rustix::process::pidfd_open(
        rustix::process::getpid(),
        rustix::process::PidfdFlags::empty(),
    )
    .map_err(|e| format!("opening this process's pidfd: {e}"))?;
    let fds: Vec<i32> = std::fs::read_dir("/proc/self/fd")
        .map_err(|e| format!("reading /proc/self/fd: {e}"))?
        .flatten()
        .filter(|e| {
            std::fs::read_link(e.path()).is_ok_and(|l| l.to_string_lossy().starts_with("socket:"))
        })
        .filter_map(|e| e.file_name().to_str()?.parse().ok())
        .collect();
    for endpoint in listen {
        let (address, port) = endpoint
            .split_once('/')
            .and_then(|(_, rest)| rest.rsplit_once(':'))
            .ok_or_else(|| format!("endpoint `{endpoint}` has no address and port"))?;
        let address = address.trim_start_matches('[').trim_end_matches(']');
        let wanted: Vec<std::net::SocketAddr> = (address, port.parse::<u16>().unwrap_or(0))
            .to_socket_addrs()
            .map_err(|e| format!("endpoint `{endpoint}`: {e}"))?
            .collect();
        let mut filtered = 0;
        for &fd in &fds {
            // A copy of the descriptor: the filter is set on the socket both share.
            let Ok(copy) =
                rustix::process::pidfd_getfd(&me, fd, rustix::process::PidfdGetfdFlags::empty())
            else {
                continue;
            };
            let socket = socket2::SockRef::from(&copy);
            let datagram = socket.r#type().is_ok_and(|t| t == socket2::Type::DGRAM);
            let bound = socket
                .local_addr()
                .ok()
                .and_then(|a| a.as_socket())
                .is_some_and(|a| wanted.contains(&a));
            if datagram && bound {
                socket
                    .attach_filter(&program)
                    .map_err(|e| format!("filtering the socket of `{endpoint}`: {e}"))?;
                filtered += 1;
            }
        }
        if filtered == 0 {
            return Err(format!(
                "no UDP socket of this process is bound to `{endpoint}`"
            ));
        }
    }
    Ok(())
}

/// The most addresses [`admit_only`] filters on.
const MAX_FILTERED_PEERS: usize = 48;

/// A jump of a filter instruction being built: to the final accept, to an instruction, or none.
#[derive(Clone, Copy)]
enum Jump {
    Accept,
    To(usize),
    Fall,
}

/// The classic BPF program of [`admit_only`]: accepts a datagram whose IP source address is
/// one of `peers` or a loopback address, drops any other. It reads the network header (the
/// kernel's negative offset `SKF_NET_OFF`), IPv4 and IPv6 alike.
fn peer_filter(peers: &[std::net::IpAddr]) -> Vec<socket2::SockFilter> {
    use std::net::IpAddr;
    let v4: Vec<u32> = peers
        .iter()
        .filter_map(|p| match p {
            IpAddr::V4(a) => Some(u32::from(*a)),
            IpAddr::V6(a) => a.to_ipv4_mapped().map(u32::from),
        })
        .collect();
    let mut v6: Vec<[u32; 4]> = peers
        .iter()
        .filter_map(|p| match p {
            IpAddr::V6(a) if a.to_ipv4_mapped().is_none() => {
                let s = a.segments();
                Some(std::array::from_fn(|i| {
                    (u32::from(s[2 * i]) << 16) | u32::from(s[2 * i + 1])
                }))
            }
            _ => None,
        })
        .collect();
    v6.push([0, 0, 0, 1]); // ::1
    let mut code: Vec<(u16, Jump, Jump, u32)> = Vec::new();
    // The IP version: the high nibble of the header's first byte; 4 falls through to the
    // IPv4 part, anything else jumps to the IPv6 part (its place is known once the IPv4 part
    // is built).
    code.push((BPF_LD_B, Jump::Fall, Jump::Fall, SKF_NET_OFF));
    code.push((BPF_AND, Jump::Fall, Jump::Fall, 0xf0));
    let version_test = code.len();
    code.push((BPF_JEQ, Jump::Fall, Jump::Fall, 0x40));
    // IPv4: the source address, each peer's; then loopback (127.0.0.0/8).
    code.push((BPF_LD_W, Jump::Fall, Jump::Fall, SKF_NET_OFF + 12));
    code.extend(v4.iter().map(|a| (BPF_JEQ, Jump::Accept, Jump::Fall, *a)));
    code.push((BPF_AND, Jump::Fall, Jump::Fall, 0xff00_0000));
    code.push((BPF_JEQ, Jump::Accept, Jump::Fall, 0x7f00_0000));
    code.push((BPF_RET, Jump::Fall, Jump::Fall, 0));
    code[version_test].2 = Jump::To(code.len());
    // IPv6: each address in four words (the source at bytes 8..24).
    for words in &v6 {
        let test_end = code.len() + 8;
        for (i, w) in words.iter().enumerate() {
            code.push((
                BPF_LD_W,
                Jump::Fall,
                Jump::Fall,
                SKF_NET_OFF + 8 + 4 * i as u32,
            ));
            let matched = if i == 3 { Jump::Accept } else { Jump::Fall };
            code.push((BPF_JEQ, matched, Jump::To(test_end), *w));
        }
    }
    code.push((BPF_RET, Jump::Fall, Jump::Fall, 0));
    let accept = code.len();
    code.push((BPF_RET, Jump::Fall, Jump::Fall, 0xffff_ffff));
    // A jump is an offset past the next instruction.
    let offset = |from: usize, j: Jump| match j {
        Jump::Accept => u8::try_from(accept - from - 1).unwrap_or(u8::MAX),
        Jump::To(to) => u8::try_from(to - from - 1).unwrap_or(u8::MAX),
        Jump::Fall => 0,
    };
    code.iter()
        .enumerate()
        .map(|(i, &(op, t, f, k))| socket2::SockFilter::new(op, offset(i, t), offset(i, f), k))
        .collect()
}

/// Classic BPF: `SKF_NET_OFF` (-0x100000), the offset of the network header.
const SKF_NET_OFF: u32 = 0xfff0_0000;
/// Classic BPF opcodes: `BPF_LD | BPF_W | BPF_ABS`, `BPF_LD | BPF_B | BPF_ABS`,
/// `BPF_ALU | BPF_AND | BPF_K`, `BPF_JMP | BPF_JEQ | BPF_K`, `BPF_RET | BPF_K`.
const BPF_LD_W: u16 = 0x20;
const BPF_LD_B: u16 = 0x30;
const BPF_AND: u16 = 0x54;
const BPF_JEQ: u16 = 0x15;
const BPF_RET: u16 = 0x06;

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    /// The socket filter of [`admit_only`] is a program the kernel takes (it checks every
    /// jump), and a datagram from loopback passes it. (That those of other addresses do not is
    /// the flood test's, in network namespaces: `tests/tests/multihost.rs`.)
    #[test]
    fn the_peer_filter_is_taken_by_the_kernel_and_lets_loopback_through() {
        let peers: Vec<std::net::IpAddr> = ["10.0.0.1", "10.0.0.2", "fe80::1", "::ffff:10.0.0.3"]
            .iter()
            .map(|a| a.parse().expect("address"))
            .collect();
        let program = peer_filter(&peers);
        // 3 + 1 + 3 peers of IPv4 + 3, then 8 per IPv6 address (one, and ::1), and 2 returns.
        assert_eq!(program.len(), 3 + 1 + 3 + 3 + 16 + 2);
        let receiver = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
        socket2::SockRef::from(&receiver)
            .attach_filter(&program)
            .expect("the kernel takes the program");
        receiver
            .set_read_timeout(Some(Duration::from_secs(10)))
            .expect("timeout");
        let sender = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
        sender
            .send_to(b"hello", receiver.local_addr().expect("address"))
            .expect("send");
        let mut buf = [0u8; 8];
        assert_eq!(receiver.recv(&mut buf).expect("received"), 5);
        let too_many = vec![peers[0]; MAX_FILTERED_PEERS + 1];
        let e = admit_only(&["quic/127.0.0.1:1".into()], &too_many).expect_err("refused");
        assert!(e.contains("more than the 48"), "{e}");
    }
}
