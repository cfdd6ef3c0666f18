//! `fdi-launch certs`: the lab's certificate authority and a certificate per host of a
//! deployment file, for the mutually authenticated TLS between the hosts of a split run
//! (docs/security.md). A host's certificate has its host name as common name (what Zenoh's
//! access control knows it by) and its endpoint's address as subject alternative name (what
//! the hosts connecting to it check). A host's certificate is valid for `--days` (365 by
//! default), the CA for [`CA_DAYS`]; a split run checks both before it opens its session
//! ([`crate::hosts::check_validity`]).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose,
};

use crate::hosts::{CertFiles, Lab, LabSecurity};

/// How many days a CA made here is valid.
pub const CA_DAYS: u32 = 3650;

/// The validity of a certificate made now for `days`: from an hour ago to `days` from now.
fn validity(params: &mut CertificateParams, days: u32) {
    let now = time::OffsetDateTime::now_utc();
    params.not_before = now - time::Duration::hours(1);
    params.not_after = now + time::Duration::days(i64::from(days));
}

/// The CA's private key in a certificates folder (kept off the hosts but the one that makes
/// certificates).
fn ca_key(dir: &Path) -> PathBuf {
    dir.join("ca.key")
}

/// Writes `text` to the new file `path` (never over an existing one), readable by its owner
/// only when it is a private key.
fn write_new(path: &Path, text: &str, private: bool) -> Result<()> {
    use std::os::unix::fs::OpenOptionsExt as _;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(if private { 0o600 } else { 0o644 })
        .open(path)
        .with_context(|| format!("creating {}", path.display()))?;
    f.write_all(text.as_bytes())
        .and_then(|()| f.sync_all())
        .with_context(|| format!("writing {}", path.display()))
}

/// The lab's CA in `dir`: the one there, or a new one.
fn authority(dir: &Path, made: &mut Vec<PathBuf>) -> Result<Issuer<'static, KeyPair>> {
    let (cert, key) = (dir.join("ca.pem"), ca_key(dir));
    match (cert.is_file(), key.is_file()) {
        (true, true) => {
            let read = |p: &Path| {
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))
            };
            let key_pair = KeyPair::from_pem(&read(&key)?)
                .with_context(|| format!("{}: not a private key in PEM", key.display()))?;
            Issuer::from_ca_cert_pem(&read(&cert)?, key_pair)
                .with_context(|| format!("{}: not a CA certificate in PEM", cert.display()))
        }
        (false, false) => {
            let mut params = CertificateParams::new(Vec::<String>::new())?;
            let mut name = DistinguishedName::new();
            name.push(DnType::CommonName, "fdi-mas lab CA");
            params.distinguished_name = name;
            params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
            params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
            validity(&mut params, CA_DAYS);
            let key_pair = KeyPair::generate()?;
            let ca = params.self_signed(&key_pair)?;
            write_new(&key, &key_pair.serialize_pem(), true)?;
            write_new(&cert, &ca.pem(), false)?;
            made.extend([cert, key]);
            Ok(Issuer::new(params, key_pair))
        }
        _ => bail!(
            "{} holds one of `ca.pem` and `ca.key` without the other: a CA needs both (or \
             neither, to make a new one)",
            dir.display()
        ),
    }
}

/// Makes what is missing in `out` for the hosts of `lab`: the CA, and each host's certificate
/// and key, valid for `days`. Returns the files made.
pub fn make(lab: &Lab, out: &Path, days: u32) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut made = Vec::new();
    let ca = authority(out, &mut made)?;
    for h in &lab.hosts {
        let files = CertFiles::new(out, &h.name);
        match (files.cert.is_file(), files.key.is_file()) {
            (true, true) => continue,
            (false, false) => {}
            _ => bail!(
                "{} holds one of {} and {} without the other: remove it to make both again",
                out.display(),
                files.cert.display(),
                files.key.display()
            ),
        }
        let address = fdi_net::endpoint_address(&h.endpoint)
            .with_context(|| format!("host `{}`: endpoint `{}`", h.name, h.endpoint))?;
        let mut params = CertificateParams::new(vec![address.to_string(), h.name.clone()])
            .with_context(|| format!("host `{}`: the names {address}, {}", h.name, h.name))?;
        let mut name = DistinguishedName::new();
        name.push(DnType::CommonName, h.name.clone());
        params.distinguished_name = name;
        params.use_authority_key_identifier_extension = true;
        validity(&mut params, days);
        params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        params.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        let key_pair = KeyPair::generate()?;
        let cert = params.signed_by(&key_pair, &ca)?;
        write_new(&files.key, &key_pair.serialize_pem(), true)?;
        write_new(&files.cert, &cert.pem(), false)?;
        made.extend([files.cert, files.key]);
    }
    Ok(made)
}

/// The lab's certificates for the hosts of the deployment file `hosts`, made in `out` (`None`:
/// the file's `certs` folder), the hosts' valid for `days`: the files made (none when every
/// host has its certificate already).
pub fn certs(hosts: &Path, out: Option<&Path>, days: u32) -> Result<(PathBuf, Vec<PathBuf>)> {
    let lab = Lab::load(hosts)?;
    let out = match (out, &lab.security) {
        (Some(out), _) => out.to_path_buf(),
        (None, LabSecurity::Tls { certs }) => certs.clone(),
        (None, LabSecurity::Insecure) => bail!(
            "{} says `insecure = true` and names no `certs` folder: give --out",
            lab.source
        ),
    };
    let made = make(&lab, &out, days)?;
    Ok((out, made))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hosts::{check_validity, Host};

    fn lab(names: &[&str]) -> Lab {
        Lab {
            source: "hosts.toml".into(),
            coordinator: names[0].into(),
            hosts: names
                .iter()
                .enumerate()
                .map(|(i, n)| Host {
                    name: (*n).into(),
                    endpoint: format!("quic/10.0.0.{}:7447", i + 1),
                })
                .collect(),
            security: LabSecurity::Tls {
                certs: PathBuf::from("certs"),
            },
        }
    }

    #[test]
    fn a_lab_s_certificates_are_made_once_and_new_hosts_signed_by_its_ca() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let made = make(&lab(&["control", "cell"]), dir.path(), 365).expect("made");
        assert_eq!(made.len(), 6, "{made:?}");
        let ca = std::fs::read_to_string(dir.path().join("ca.pem")).expect("ca");
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(dir.path().join("cell.key"))
            .expect("key")
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "a private key is its owner's only");
        // Again, with one more host: only its files are made, the CA is the same.
        let made = make(&lab(&["control", "cell", "adversary"]), dir.path(), 365).expect("made");
        assert_eq!(
            made,
            vec![
                dir.path().join("adversary.pem"),
                dir.path().join("adversary.key")
            ]
        );
        let again = std::fs::read_to_string(dir.path().join("ca.pem")).expect("ca");
        assert_eq!(ca, again);
        // Half a pair is refused, not completed over.
        std::fs::remove_file(dir.path().join("cell.key")).expect("rm");
        let e = make(&lab(&["control", "cell"]), dir.path(), 365).expect_err("half a pair");
        assert!(e.to_string().contains("without the other"), "{e}");
    }

    #[test]
    fn certificates_are_valid_for_their_days_and_a_run_names_one_expired_or_not_yet_valid() {
        let dir = tempfile::tempdir().expect("temporary folder");
        make(&lab(&["control", "cell"]), dir.path(), 90).expect("made");
        let now = jiff::Timestamp::now().as_second();
        let day = 86_400;
        let cell = dir.path().join("cell.pem");
        let ca = dir.path().join("ca.pem");
        assert_eq!(check_validity(&cell, now).expect("valid"), None);
        assert_eq!(check_validity(&ca, now).expect("valid"), None);
        // 89 days on, it warns; after its 90 days, a run stops naming the file and the date.
        let warned = check_validity(&cell, now + 89 * day)
            .expect("still valid")
            .expect("a warning");
        assert!(
            warned.contains("cell.pem") && warned.contains("expires on"),
            "{warned}"
        );
        let e = check_validity(&cell, now + 91 * day).expect_err("expired");
        let e = format!("{e:#}");
        assert!(e.contains("cell.pem: the certificate expired on"), "{e}");
        assert!(e.contains("fdi-launch certs"), "{e}");
        // The CA lasts its ten years; a clock two hours behind is refused too.
        assert_eq!(check_validity(&ca, now + 3000 * day).expect("valid"), None);
        let e = format!(
            "{:#}",
            check_validity(&ca, now + 3651 * day).expect_err("expired")
        );
        assert!(
            e.contains("ca.pem") && e.contains("every host's pair"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            check_validity(&cell, now - 2 * 3600).expect_err("early")
        );
        assert!(e.contains("valid only from"), "{e}");
        // A file that holds no certificate is named.
        let key = dir.path().join("cell.key");
        let e = format!("{:#}", check_validity(&key, now).expect_err("a key"));
        assert!(e.contains("cell.key"), "{e}");
    }
}
