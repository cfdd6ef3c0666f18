//! Host names and endpoints of a deployment, checked.

/// Checks a host name: 1 to 40 bytes of ASCII letters, digits, `_` and `-` (it becomes part of
/// Zenoh keys and of labels).
pub fn check_host_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > 40 {
        return Err(format!("host name `{name}` must be 1..=40 bytes"));
    }
    if !name
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
    {
        return Err(format!(
            "host name `{name}`: only ASCII letters, digits, `_` and `-` are allowed"
        ));
    }
    Ok(())
}

/// The transport of an endpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// QUIC (over UDP): TLS 1.3 with mutual authentication (`quic/<address>:<port>`).
    Quic,
    /// Plain TCP, neither encrypted nor authenticated (`tcp/<address>:<port>`).
    Tcp,
}

/// Checks a Zenoh endpoint of a host, `quic/<address>:<port>` or `tcp/<address>:<port>`, and
/// says which.
pub fn check_endpoint(endpoint: &str) -> Result<Link, String> {
    let (link, rest) = if let Some(rest) = endpoint.strip_prefix("quic/") {
        (Link::Quic, rest)
    } else if let Some(rest) = endpoint.strip_prefix("tcp/") {
        (Link::Tcp, rest)
    } else {
        return Err(format!(
            "endpoint `{endpoint}` must be `quic/<address>:<port>` (or `tcp/<address>:<port>` \
             in a deployment that says `insecure = true`)"
        ));
    };
    let Some((host, port)) = rest.rsplit_once(':') else {
        return Err(format!("endpoint `{endpoint}` has no `:<port>`"));
    };
    if host.is_empty() || port.parse::<u16>().map_or(true, |p| p == 0) {
        return Err(format!(
            "endpoint `{endpoint}` must be `<quic|tcp>/<address>:<port>` with a port in \
             1..=65535"
        ));
    }
    Ok(link)
}

/// The address part of an endpoint (`10.0.0.2` of `quic/10.0.0.2:7447`, without brackets).
pub fn endpoint_address(endpoint: &str) -> Option<&str> {
    let rest = endpoint.split_once('/')?.1;
    let host = rest.rsplit_once(':')?.0;
    Some(host.trim_start_matches('[').trim_end_matches(']'))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::keys;

    #[test]
    fn host_names_and_endpoints_are_checked() {
        assert!(check_host_name("cell-a").is_ok());
        assert!(check_host_name("cell a").is_err());
        assert!(check_host_name("").is_err());
        assert_eq!(check_endpoint("tcp/10.0.0.2:7447"), Ok(Link::Tcp));
        assert_eq!(check_endpoint("quic/10.0.0.2:7447"), Ok(Link::Quic));
        assert!(check_endpoint("tls/10.0.0.2:7447").is_err());
        assert!(check_endpoint("tcp/[::1]:7447").is_ok());
        assert_eq!(endpoint_address("quic/[::1]:7447"), Some("::1"));
        assert_eq!(endpoint_address("quic/10.0.0.2:7447"), Some("10.0.0.2"));
        assert_eq!(
            keys::sender("fdi-mas/p/cell/run/x/s/fdi/torque/3"),
            Some("cell")
        );
        assert_eq!(
            keys::sender("fdi-mas/q/cell/control/run/x/release"),
            Some("control")
        );
        assert_eq!(keys::sender("other/p/cell"), None);
        assert!(check_endpoint("udp/10.0.0.2:7447").is_err());
        assert!(check_endpoint("tcp/10.0.0.2").is_err());
        assert!(check_endpoint("tcp/10.0.0.2:0").is_err());
    }
}
