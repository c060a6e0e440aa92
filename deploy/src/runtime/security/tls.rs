//! One process's TLS identity — the deployment's CA and its own certificate
//! and key — and what securing does to endpoints (they become QUIC).

use super::error::SecurityError;
use std::path::{Path, PathBuf};

/// The files a process needs for mutual TLS. The same certificate serves
/// both ends of a link: it listens with it and connects with it, so a peer
/// is known by one common name whichever side opened the link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tls {
    /// The CA that signed every certificate of the deployment.
    pub ca: PathBuf,
    pub cert: PathBuf,
    pub key: PathBuf,
    /// Check that a listener's certificate names the host it was reached
    /// at (its subject alternative names).
    pub verify_names: bool,
}

impl Tls {
    /// Checks that every file is there and is PEM, so that a mistake is
    /// reported naming the file rather than as a failed handshake.
    /// `field` says where the paths came from (`[security] certs`, `--ca`).
    pub(crate) fn new(
        ca: PathBuf,
        cert: PathBuf,
        key: PathBuf,
        verify_names: bool,
        field: &str,
    ) -> Result<Self, SecurityError> {
        check_pem(&ca, &format!("{field} (CA certificate)"))?;
        check_pem(&cert, &format!("{field} (certificate)"))?;
        check_pem(&key, &format!("{field} (private key)"))?;
        Ok(Tls {
            ca,
            cert,
            key,
            verify_names,
        })
    }

    /// For a client given `--ca`, `--cert` and `--key`: all three or none.
    pub fn from_options(
        ca: Option<&Path>,
        cert: Option<&Path>,
        key: Option<&Path>,
    ) -> Result<Option<Self>, SecurityError> {
        match (ca, cert, key) {
            (None, None, None) => Ok(None),
            (Some(ca), Some(cert), Some(key)) => Tls::new(
                ca.to_path_buf(),
                cert.to_path_buf(),
                key.to_path_buf(),
                true,
                "--ca/--cert/--key",
            )
            .map(Some),
            (None, _, _) => Err(SecurityError::Incomplete { missing: "--ca" }),
            (_, None, _) => Err(SecurityError::Incomplete { missing: "--cert" }),
            (_, _, None) => Err(SecurityError::Incomplete { missing: "--key" }),
        }
    }
}

fn check_pem(path: &Path, field: &str) -> Result<(), SecurityError> {
    let text = std::fs::read(path).map_err(|source| SecurityError::Unreadable {
        field: field.to_string(),
        path: path.to_path_buf(),
        source,
    })?;
    if !text.windows(10).any(|w| w == b"-----BEGIN") {
        return Err(SecurityError::NotPem {
            field: field.to_string(),
            path: path.to_path_buf(),
        });
    }
    Ok(())
}

/// The endpoint a secured process listens on or connects to: a topology
/// names `tcp/host:port` whether or not it is secured, so turning security
/// on is one section, not every endpoint edited.
///
/// Secured links are QUIC (TLS 1.3, mutual, over UDP on the same port
/// number), never Zenoh's `tls/` link: in Zenoh 1.10 that link lets its
/// reading and its writing task share one TLS session without a lock
/// (eclipse-zenoh/zenoh#2557). Under load its links failed and reopened
/// by themselves, and once a sensor aborted inside rustls on a corrupted
/// error value. Zenoh's QUIC link gives each direction its own stream.
pub(crate) fn secured_endpoint(endpoint: &str) -> Result<String, SecurityError> {
    if let Some(address) = endpoint.strip_prefix("tcp/") {
        Ok(format!("quic/{address}"))
    } else if endpoint.starts_with("quic/") {
        Ok(endpoint.to_string())
    } else {
        Err(SecurityError::Endpoint {
            endpoint: endpoint.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tcp_endpoints_become_quic_and_others_are_refused() {
        assert_eq!(
            secured_endpoint("tcp/10.0.0.2:7447").unwrap(),
            "quic/10.0.0.2:7447"
        );
        assert_eq!(secured_endpoint("quic/host:1").unwrap(), "quic/host:1");
        assert!(secured_endpoint("udp/host:1").is_err());
        let refused = secured_endpoint("tls/host:1").unwrap_err().to_string();
        assert!(refused.contains("#2557"), "{refused}");
    }

    #[test]
    fn a_missing_or_garbled_file_is_named() {
        let scratch = tempfile::Builder::new()
            .prefix("idmesh-tls-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let pem = dir.join("ok.pem");
        std::fs::write(&pem, "-----BEGIN CERTIFICATE-----\n").unwrap();
        let junk = dir.join("junk.key");
        std::fs::write(&junk, "junk").unwrap();
        let missing = dir.join("missing.pem");
        let e = Tls::new(
            missing.clone(),
            pem.clone(),
            pem.clone(),
            true,
            "[security] certs",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("CA certificate") && e.contains("missing.pem"),
            "{e}"
        );
        let e = Tls::new(pem.clone(), pem.clone(), junk, true, "[security] certs")
            .unwrap_err()
            .to_string();
        assert!(e.contains("private key") && e.contains("junk.key"), "{e}");
        let e = Tls::from_options(Some(&pem), None, Some(&pem)).unwrap_err();
        assert!(e.to_string().contains("--cert"), "{e}");
        assert_eq!(Tls::from_options(None, None, None).unwrap(), None);
    }
}
