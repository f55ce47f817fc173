//! Who may talk to whom between hosts: a deployment's certificates, the
//! checks of one before it is used, Zenoh's TLS and access control, and
//! the diagnosis of a handshake that fails.
//!
//! Every link between a coordinator and an agent is TLS with mutual
//! authentication: each side presents a certificate that the deployment's
//! CA signed, with its name as common name (`h1`, …, `coordinator`). On
//! top of it, Zenoh's access control, keyed by that common name:
//!
//! - an **agent** answers only the coordinator names it was given (`shoal
//!   host --coordinator`, default `coordinator`); any other peer, a host's
//!   certificate included, can neither publish, subscribe, query nor
//!   declare anything on it;
//! - the **coordinator** lets host `h` publish only `h`'s own keys (its
//!   alive token and answers, its fences and failures, the samples the
//!   placement has it export) and subscribe only to the run's clock, abort
//!   and coordinator token and to the samples placed to cross to it.
//!
//! Plain TCP is there only when asked for (`--insecure`), and an agent
//! that serves it says so when it starts.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use super::placement::Placement;

/// The scheme of a secured endpoint: Zenoh's QUIC link, TLS 1.3 with
/// mutual authentication. (Not Zenoh 1.10's `tls/` link: it reads and
/// writes one rustls connection from two tasks at once, zenoh issue 2557,
/// and under a lockstep run's traffic the link dies within a second with
/// "handshake not complete".)
pub const SECURE_SCHEME: &str = "quic";

/// The common name of the coordinator's certificate unless told otherwise.
pub const DEFAULT_COORDINATOR: &str = "coordinator";

/// The CA's files in a certificates directory.
pub const CA_CERT: &str = "ca.pem";
/// The CA's private key (stays with whoever makes certificates).
pub const CA_KEY: &str = "ca.key";

/// Errors of certificates.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// Not a PEM certificate or key.
    #[error("{path} is not a PEM {what}: {message}")]
    NotPem {
        /// The file.
        path: String,
        /// `certificate` or `private key`.
        what: &'static str,
        /// What the parser said.
        message: String,
    },
    /// The certificate is for another name.
    #[error("{path} is the certificate of `{found}`, not of `{expected}`")]
    WrongName {
        /// The file.
        path: String,
        /// The name it should carry.
        expected: String,
        /// The name it carries.
        found: String,
    },
    /// Expired, or not valid yet.
    #[error("{path} (`{name}`) is valid {validity}, not now ({now}): {hint}")]
    NotValidNow {
        /// The file.
        path: String,
        /// Its common name.
        name: String,
        /// `from … to …`.
        validity: String,
        /// Now.
        now: String,
        /// What to do.
        hint: &'static str,
    },
    /// Signed by another CA.
    #[error("{path} (`{name}`, issued by `{issuer}`) is not signed by the CA {ca} (`{ca_name}`): it belongs to another deployment")]
    ForeignCa {
        /// The file.
        path: String,
        /// Its common name.
        name: String,
        /// Its issuer's name.
        issuer: String,
        /// The CA file.
        ca: String,
        /// The CA's name.
        ca_name: String,
    },
    /// The key is not the certificate's.
    #[error("{key} is not the private key of {cert}")]
    KeyMismatch {
        /// The key file.
        key: String,
        /// The certificate file.
        cert: String,
    },
    /// A name that cannot be a certificate's.
    #[error("`{0}` cannot name a certificate: 1-32 characters of a-z, A-Z, 0-9, '-' or '_'")]
    BadName(String),
    /// rcgen failed.
    #[error("cannot make a certificate: {0}")]
    Make(#[from] rcgen::Error),
}

/// How a node's links are secured.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum Security {
    /// TLS with mutual authentication as this identity, access control by
    /// certificate name.
    Tls(Identity),
    /// Plain TCP: no authentication, no access control (`--insecure`).
    Insecure,
}

/// One node's identity in a deployment: the CA it trusts, its certificate
/// and its private key, and the name the certificate carries.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Identity {
    /// The node's name (the certificate's common name).
    pub name: String,
    /// The deployment's CA certificate.
    pub ca: PathBuf,
    /// The node's certificate.
    pub cert: PathBuf,
    /// Its private key.
    pub key: PathBuf,
}

impl Identity {
    /// `name`'s identity in a directory that `shoal certs` wrote:
    /// `ca.pem`, `<name>.pem`, `<name>.key`.
    pub fn in_dir(dir: &Path, name: &str) -> Self {
        Self {
            name: name.to_string(),
            ca: dir.join(CA_CERT),
            cert: dir.join(format!("{name}.pem")),
            key: dir.join(format!("{name}.key")),
        }
    }

    /// Checks the identity before it is used: every file readable and
    /// PEM, the certificate `name`'s, valid now, signed by the CA, and
    /// the key its own. Returns the certificate's end of validity.
    pub fn check(&self) -> Result<String, TlsError> {
        let ca_pem = read(&self.ca)?;
        let cert_pem = read(&self.cert)?;
        let key_pem = read(&self.key)?;
        let ca = parse_pem(&ca_pem, &self.ca)?;
        let ca = parse_cert(&ca, &self.ca)?;
        let cert = parse_pem(&cert_pem, &self.cert)?;
        let cert = parse_cert(&cert, &self.cert)?;
        let name = common_name(cert.subject());
        if name != self.name {
            return Err(TlsError::WrongName {
                path: shown(&self.cert),
                expected: self.name.clone(),
                found: name,
            });
        }
        check_valid_now(&cert, &self.cert)?;
        check_valid_now(&ca, &self.ca)?;
        if cert.verify_signature(Some(ca.public_key())).is_err() {
            return Err(TlsError::ForeignCa {
                path: shown(&self.cert),
                name,
                issuer: common_name(cert.issuer()),
                ca: shown(&self.ca),
                ca_name: common_name(ca.subject()),
            });
        }
        let key = std::str::from_utf8(&key_pem)
            .ok()
            .and_then(|t| rcgen::KeyPair::from_pem(t).ok())
            .ok_or_else(|| TlsError::NotPem {
                path: shown(&self.key),
                what: "private key",
                message: "no PKCS#8 key in it".into(),
            })?;
        use rcgen::PublicKeyData as _;
        if key.subject_public_key_info() != cert.public_key().raw {
            return Err(TlsError::KeyMismatch {
                key: shown(&self.key),
                cert: shown(&self.cert),
            });
        }
        Ok(cert.validity().not_after.to_string())
    }

    /// Zenoh's TLS settings for this identity, as `(key, JSON value)`
    /// pairs under `transport/link/tls`: mutual authentication, the peer's
    /// name checked against its certificate when connecting.
    pub fn zenoh_settings(&self) -> Vec<(&'static str, String)> {
        let path = |p: &Path| {
            serde_json::to_string(&p.display().to_string()).unwrap_or_else(|_| "\"\"".into())
        };
        vec![
            ("transport/link/tls/root_ca_certificate", path(&self.ca)),
            ("transport/link/tls/listen_certificate", path(&self.cert)),
            ("transport/link/tls/listen_private_key", path(&self.key)),
            ("transport/link/tls/connect_certificate", path(&self.cert)),
            ("transport/link/tls/connect_private_key", path(&self.key)),
            ("transport/link/tls/enable_mtls", "true".into()),
            ("transport/link/tls/verify_name_on_connect", "true".into()),
            ("transport/link/tls/close_link_on_expiration", "true".into()),
        ]
    }
}

fn shown(p: &Path) -> String {
    p.display().to_string()
}

fn read(p: &Path) -> Result<Vec<u8>, TlsError> {
    std::fs::read(p).map_err(|source| TlsError::Io {
        path: shown(p),
        source,
    })
}

fn parse_pem(bytes: &[u8], path: &Path) -> Result<x509_parser::pem::Pem, TlsError> {
    x509_parser::pem::parse_x509_pem(bytes)
        .map(|(_, pem)| pem)
        .map_err(|e| TlsError::NotPem {
            path: shown(path),
            what: "certificate",
            message: e.to_string(),
        })
}

fn parse_cert<'a>(
    pem: &'a x509_parser::pem::Pem,
    path: &Path,
) -> Result<x509_parser::certificate::X509Certificate<'a>, TlsError> {
    pem.parse_x509().map_err(|e| TlsError::NotPem {
        path: shown(path),
        what: "certificate",
        message: e.to_string(),
    })
}

/// The common name of a certificate's subject or issuer ("" if none).
fn common_name(name: &x509_parser::x509::X509Name<'_>) -> String {
    name.iter_common_name()
        .next()
        .and_then(|c| c.as_str().ok())
        .unwrap_or("")
        .to_string()
}

fn check_valid_now(
    cert: &x509_parser::certificate::X509Certificate<'_>,
    path: &Path,
) -> Result<(), TlsError> {
    if cert.validity().is_valid() {
        return Ok(());
    }
    let now = x509_parser::time::ASN1Time::now();
    Err(TlsError::NotValidNow {
        path: shown(path),
        name: common_name(cert.subject()),
        validity: format!(
            "from {} to {}",
            cert.validity().not_before,
            cert.validity().not_after
        ),
        now: now.to_string(),
        hint: if now > cert.validity().not_after {
            "it has expired; make a new one with `shoal certs`"
        } else {
            "it is not valid yet; check this host's clock"
        },
    })
}

/// A name that can be a host's or a certificate's: a Zenoh key chunk and a
/// file name (1-32 characters of a-z, A-Z, 0-9, '-' or '_').
pub fn valid_name(name: &str) -> bool {
    (1..=32).contains(&name.len())
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// One certificate to make: a name and the addresses (IPs or DNS names)
/// the node is reached at.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CertRequest {
    /// The common name.
    pub name: String,
    /// Subject alternative names (the name itself is added).
    pub addresses: Vec<String>,
}

/// What [`make_certs`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Made {
    /// `true` if the CA was made now, `false` if the directory's was used.
    pub new_ca: bool,
    /// Every file written.
    pub files: Vec<PathBuf>,
}

/// Makes a certificate and key for each request in `dir`, signed by the
/// directory's CA (made first if it has none), valid from `valid_from_days`
/// days from now (negative: in the past) for `days` days. Private keys are
/// written readable by their owner only.
pub fn make_certs(
    dir: &Path,
    requests: &[CertRequest],
    valid_from_days: i64,
    days: i64,
) -> Result<Made, TlsError> {
    for r in requests {
        if !valid_name(&r.name) || r.name == "ca" {
            return Err(TlsError::BadName(r.name.clone()));
        }
    }
    std::fs::create_dir_all(dir).map_err(|source| TlsError::Io {
        path: shown(dir),
        source,
    })?;
    let ca_cert = dir.join(CA_CERT);
    let ca_key = dir.join(CA_KEY);
    let now = time::OffsetDateTime::now_utc();
    let mut files = Vec::new();
    let new_ca = !(ca_cert.is_file() && ca_key.is_file());
    let issuer = if new_ca {
        let key = rcgen::KeyPair::generate()?;
        let mut p = rcgen::CertificateParams::new(Vec::<String>::new())?;
        let tag = crate::launch::os::random_id();
        p.distinguished_name
            .push(rcgen::DnType::CommonName, format!("shoal CA {tag}"));
        p.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
        p.key_usages = vec![
            rcgen::KeyUsagePurpose::KeyCertSign,
            rcgen::KeyUsagePurpose::CrlSign,
            rcgen::KeyUsagePurpose::DigitalSignature,
        ];
        p.not_before = now - time::Duration::hours(1);
        p.not_after = now + time::Duration::days(3650);
        let cert = p.self_signed(&key)?;
        write(&ca_cert, cert.pem().as_bytes(), false)?;
        write(&ca_key, key.serialize_pem().as_bytes(), true)?;
        files.extend([ca_cert.clone(), ca_key.clone()]);
        rcgen::Issuer::new(p, key)
    } else {
        let key_text = String::from_utf8_lossy(&read(&ca_key)?).into_owned();
        let key = rcgen::KeyPair::from_pem(&key_text).map_err(|e| TlsError::NotPem {
            path: shown(&ca_key),
            what: "private key",
            message: e.to_string(),
        })?;
        let cert_text = String::from_utf8_lossy(&read(&ca_cert)?).into_owned();
        rcgen::Issuer::from_ca_cert_pem(&cert_text, key).map_err(|e| TlsError::NotPem {
            path: shown(&ca_cert),
            what: "certificate",
            message: e.to_string(),
        })?
    };
    for r in requests {
        let mut sans = vec![r.name.clone()];
        sans.extend(r.addresses.iter().filter(|a| **a != r.name).cloned());
        let mut p = rcgen::CertificateParams::new(sans)?;
        p.distinguished_name
            .push(rcgen::DnType::CommonName, r.name.clone());
        p.is_ca = rcgen::IsCa::ExplicitNoCa;
        p.key_usages = vec![rcgen::KeyUsagePurpose::DigitalSignature];
        p.extended_key_usages = vec![
            rcgen::ExtendedKeyUsagePurpose::ServerAuth,
            rcgen::ExtendedKeyUsagePurpose::ClientAuth,
        ];
        p.not_before = now + time::Duration::days(valid_from_days) - time::Duration::hours(1);
        p.not_after = p.not_before + time::Duration::days(days) + time::Duration::hours(1);
        let key = rcgen::KeyPair::generate()?;
        let cert = p.signed_by(&key, &issuer)?;
        let (c, k) = (
            dir.join(format!("{}.pem", r.name)),
            dir.join(format!("{}.key", r.name)),
        );
        write(&c, cert.pem().as_bytes(), false)?;
        write(&k, key.serialize_pem().as_bytes(), true)?;
        files.extend([c, k]);
    }
    Ok(Made { new_ca, files })
}

fn write(path: &Path, bytes: &[u8], private: bool) -> Result<(), TlsError> {
    use std::io::Write as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let io = |source| TlsError::Io {
        path: shown(path),
        source,
    };
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(if private { 0o600 } else { 0o644 })
        .open(path)
        .map_err(io)?;
    f.write_all(bytes).map_err(io)
}

/// Every kind of message Zenoh's access control knows.
const ALL_MESSAGES: [&str; 9] = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
];

fn rule(id: &str, flow: &str, messages: &[&str], keys: &[String]) -> Value {
    json!({
        "id": id,
        "messages": messages,
        "flows": [flow],
        "permission": "allow",
        "key_exprs": keys,
    })
}

/// Access control that answers only the certificate `names` given: they
/// may do anything on shoal's keys, nobody else anything. An agent's, with
/// its coordinators' names (and the hop bench's router, with its hosts').
pub fn answer_only(names: &[String]) -> Value {
    let keys = ["shoal-host/**", "shoal-ctl/**", "shoal/**"].map(String::from);
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": [
            rule("coordinator-in", "ingress", &ALL_MESSAGES, &keys),
            rule("coordinator-out", "egress", &ALL_MESSAGES, &keys),
        ],
        "subjects": [{ "id": "coordinator", "cert_common_names": names }],
        "policies": [{ "rules": ["coordinator-in", "coordinator-out"], "subjects": ["coordinator"] }],
    })
}

/// The coordinator's access control for run `run_id` over `placement`:
/// each host publishes only its own keys and subscribes only to what is
/// meant for it.
pub fn coordinator_acl(
    run_id: &str,
    placement: &Placement,
    crossings: &[super::placement::Crossing],
) -> Value {
    use super::wire;
    let mut rules = Vec::new();
    let mut subjects = Vec::new();
    let mut policies = Vec::new();
    for (h, name) in placement.hosts.iter().enumerate() {
        let exports: Vec<String> = crossings
            .iter()
            .filter(|c| c.from == h)
            .map(|c| c.service.clone())
            .collect();
        let imports: Vec<String> = crossings
            .iter()
            .filter(|c| c.to.contains(&h))
            .map(|c| c.service.clone())
            .collect();
        let own = [
            format!("shoal-host/{name}/**"),
            wire::fence(run_id, name),
            wire::failed(run_id, name),
        ];
        let control = [
            wire::clock(run_id),
            wire::abort(run_id),
            wire::coordinator(run_id),
        ];
        // What the host may send: its own keys.
        let publishes: Vec<String> = own.iter().chain(&exports).cloned().collect();
        // What the host may ask for: the run's control and its imports.
        let subscribes: Vec<String> = control.iter().chain(&imports).cloned().collect();
        // What may go to it: the run's control and its imports; queries
        // of its own keys; the declarations that make it send.
        let puts_to: Vec<String> = subscribes.clone();
        let asks: Vec<String> = vec![format!("shoal-host/{name}/**"), wire::ALL_ALIVE.to_string()];
        let declares_to: Vec<String> = [
            wire::fence(run_id, "*"),
            wire::failed(run_id, "*"),
            wire::ALL_ALIVE.to_string(),
            wire::coordinator(run_id),
        ]
        .into_iter()
        .chain(exports.iter().cloned())
        .collect();
        let id = |what: &str| format!("{name}-{what}");
        rules.push(rule(
            &id("publishes"),
            "ingress",
            &[
                "put",
                "delete",
                "reply",
                "declare_queryable",
                "liveliness_token",
            ],
            &publishes,
        ));
        rules.push(rule(
            &id("subscribes"),
            "ingress",
            &["declare_subscriber", "declare_liveliness_subscriber"],
            &subscribes,
        ));
        rules.push(rule(&id("puts-to"), "egress", &["put", "delete"], &puts_to));
        rules.push(rule(
            &id("asks"),
            "egress",
            &["query", "liveliness_query"],
            &asks,
        ));
        rules.push(rule(
            &id("declares-to"),
            "egress",
            &[
                "declare_subscriber",
                "declare_liveliness_subscriber",
                "liveliness_token",
            ],
            &declares_to,
        ));
        subjects.push(json!({ "id": name, "cert_common_names": [name] }));
        let ids = ["publishes", "subscribes", "puts-to", "asks", "declares-to"].map(id);
        policies.push(json!({
            "rules": ids,
            "subjects": [name],
        }));
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

/// Why a handshake with the agent at `endpoint` (`quic/ADDR:PORT`) fails,
/// or that it succeeds, from a QUIC handshake of our own as `id` (Zenoh
/// does not say why a link it retries does not come up).
pub fn probe(endpoint: &str, id: &Identity) -> String {
    match try_probe(endpoint, id) {
        Ok(()) => "the TLS handshake succeeds (if the agent does not answer, it does not take this coordinator's name as its coordinator: `shoal host --coordinator`)".into(),
        Err(e) => e,
    }
}

/// Zenoh's QUIC application protocols (ALPN), as its links offer them.
const ZENOH_ALPN: [&[u8]; 4] = [b"zenoh-ms-mr", b"zenoh-ms", b"zenoh-mr", b"hq-29"];

fn try_probe(endpoint: &str, id: &Identity) -> Result<(), String> {
    use rustls::pki_types::pem::PemObject as _;
    use rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let addr = endpoint
        .strip_prefix(&format!("{SECURE_SCHEME}/"))
        .ok_or_else(|| format!("{endpoint} is not a {SECURE_SCHEME}/ endpoint"))?;
    let addr = addr.split('#').next().unwrap_or(addr);
    let (host, _) = addr
        .rsplit_once(':')
        .ok_or_else(|| format!("{endpoint} has no port"))?;
    let host = host
        .trim_start_matches('[')
        .trim_end_matches(']')
        .to_string();
    let file = |p: &Path, e: &dyn std::fmt::Display| format!("{}: {e}", shown(p));
    let mut roots = rustls::RootCertStore::empty();
    for c in CertificateDer::pem_file_iter(&id.ca).map_err(|e| file(&id.ca, &e))? {
        let c = c.map_err(|e| file(&id.ca, &e))?;
        roots.add(c).map_err(|e| file(&id.ca, &e))?;
    }
    let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&id.cert)
        .map_err(|e| file(&id.cert, &e))?
        .filter_map(Result::ok)
        .collect();
    let key = PrivateKeyDer::from_pem_file(&id.key).map_err(|e| file(&id.key, &e))?;
    // ring, as Zenoh's links use it.
    #[allow(deprecated)]
    let provider = std::sync::Arc::new(rustls::crypto::ring::default_provider());
    let mut config = rustls::ClientConfig::builder_with_provider(provider)
        .with_protocol_versions(&[&rustls::version::TLS13])
        .map_err(|e| e.to_string())?
        .with_root_certificates(roots)
        .with_client_auth_cert(chain, key)
        .map_err(|e| format!("our certificate: {e}"))?;
    config.alpn_protocols = ZENOH_ALPN.iter().map(|p| p.to_vec()).collect();
    let quic =
        quinn::crypto::rustls::QuicClientConfig::try_from(config).map_err(|e| e.to_string())?;
    let sock = std::net::ToSocketAddrs::to_socket_addrs(addr)
        .map_err(|e| format!("{addr}: {e}"))?
        .next()
        .ok_or_else(|| format!("{addr}: no address"))?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    let outcome: Result<(), String> = rt.block_on(async move {
        let bind: std::net::SocketAddr = if sock.is_ipv6() {
            "[::]:0".parse().map_err(|e| format!("{e}"))?
        } else {
            "0.0.0.0:0".parse().map_err(|e| format!("{e}"))?
        };
        let mut endpoint = quinn::Endpoint::client(bind).map_err(|e| e.to_string())?;
        endpoint.set_default_client_config(quinn::ClientConfig::new(std::sync::Arc::new(quic)));
        let connecting = endpoint.connect(sock, &host).map_err(|e| e.to_string())?;
        let conn = tokio::time::timeout(Duration::from_secs(3), connecting)
            .await
            .map_err(|_| {
                format!("no answer from {addr} in 3 s (nothing listens, or the link is cut)")
            })?
            .map_err(|e| e.to_string())?;
        // TLS 1.3: a server that refuses the client's certificate says so
        // after the client's handshake is over.
        match tokio::time::timeout(Duration::from_millis(500), conn.closed()).await {
            Ok(reason) => Err(reason.to_string()),
            Err(_) => Ok(()),
        }
    });
    outcome.map_err(|text| {
        let why = if text.contains("UnknownIssuer") {
            "the agent's certificate is not signed by our CA (another deployment's)"
        } else if text.contains("xpired") {
            "a certificate has expired"
        } else if text.contains("NotValidForName") {
            "the agent's certificate does not name this address (make it with the address: `shoal certs --host NAME=ADDR`)"
        } else if text.contains("crypto") || text.contains("certificate") {
            "the agent refused our certificate (another deployment's CA, expired, or none)"
        } else {
            "the handshake failed"
        };
        format!("{why}: {text}")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(name: &str, addr: &str) -> CertRequest {
        CertRequest {
            name: name.into(),
            addresses: vec![addr.into()],
        }
    }

    #[test]
    fn certificates_made_here_check_and_others_are_named() {
        let dir =
            std::env::temp_dir().join(format!("shoal-tls-{}", crate::launch::os::random_id()));
        let made = make_certs(
            &dir,
            &[req("h1", "127.0.0.1"), req("coordinator", "")],
            0,
            30,
        )
        .unwrap();
        assert!(made.new_ca);
        assert_eq!(made.files.len(), 6);
        let h1 = Identity::in_dir(&dir, "h1");
        assert!(h1.check().is_ok(), "{:?}", h1.check());
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(&h1.key).unwrap().permissions().mode();
        assert_eq!(mode & 0o077, 0, "a private key readable by others");
        // A second call reuses the CA.
        let again = make_certs(&dir, &[req("h2", "127.0.0.2")], 0, 30).unwrap();
        assert!(!again.new_ca);
        assert!(Identity::in_dir(&dir, "h2").check().is_ok());
        // The wrong name.
        let mut wrong = h1.clone();
        wrong.name = "h2".into();
        assert!(matches!(wrong.check(), Err(TlsError::WrongName { .. })));
        // Expired.
        let old = dir.join("old");
        std::fs::create_dir_all(&old).unwrap();
        std::fs::copy(dir.join(CA_CERT), old.join(CA_CERT)).unwrap();
        std::fs::copy(dir.join(CA_KEY), old.join(CA_KEY)).unwrap();
        make_certs(&old, &[req("h1", "")], -40, 30).unwrap();
        let e = Identity::in_dir(&old, "h1").check().unwrap_err();
        assert!(e.to_string().contains("expired"), "{e}");
        // Another deployment's CA.
        let other = dir.join("other");
        make_certs(&other, &[req("h1", "")], 0, 30).unwrap();
        let mut foreign = Identity::in_dir(&other, "h1");
        foreign.ca = dir.join(CA_CERT);
        let e = foreign.check().unwrap_err();
        assert!(matches!(e, TlsError::ForeignCa { .. }), "{e}");
        assert!(e.to_string().contains("another deployment"), "{e}");
        // A key that is not the certificate's.
        let mut swapped = h1.clone();
        swapped.key = dir.join("h2.key");
        assert!(matches!(swapped.check(), Err(TlsError::KeyMismatch { .. })));
        assert!(matches!(
            make_certs(&dir, &[req("no/slash", "")], 0, 1),
            Err(TlsError::BadName(_))
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_host_may_publish_only_its_own_keys() {
        let placement = Placement {
            hosts: vec!["h1".into(), "h2".into()],
            endpoints: vec!["quic/a:1".into(), "quic/b:1".into()],
            vehicle_host: vec![0, 1],
            world_host: 0,
        };
        let crossings = vec![
            super::super::placement::Crossing {
                service: "shoal/r/run/world".into(),
                vehicle: "run".into(),
                what: "world",
                from: 0,
                to: vec![1],
                sample_bytes: 1,
                rate_hz: 1.0,
            },
            super::super::placement::Crossing {
                service: "shoal/r/f1/truth".into(),
                vehicle: "f1".into(),
                what: "truth",
                from: 1,
                to: vec![0],
                sample_bytes: 1,
                rate_hz: 1.0,
            },
        ];
        let acl = coordinator_acl("r", &placement, &crossings);
        let rule = |id: &str| {
            acl["rules"]
                .as_array()
                .unwrap()
                .iter()
                .find(|r| r["id"] == id)
                .unwrap()
                .clone()
        };
        let keys = |id: &str| -> Vec<String> {
            rule(id)["key_exprs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|k| k.as_str().unwrap().to_string())
                .collect()
        };
        let h2_pub = keys("h2-publishes");
        assert!(h2_pub.contains(&"shoal/r/f1/truth".to_string()));
        assert!(h2_pub.contains(&"shoal-ctl/r/fence/h2".to_string()));
        for forbidden in [
            "shoal/r/run/world",
            "shoal-ctl/r/clock",
            "shoal-ctl/r/abort",
            "shoal-ctl/r/fence/h1",
        ] {
            assert!(!h2_pub.contains(&forbidden.to_string()), "{forbidden}");
        }
        assert!(keys("h2-subscribes").contains(&"shoal/r/run/world".to_string()));
        assert!(!keys("h2-subscribes").contains(&"shoal/r/f1/truth".to_string()));
        assert!(keys("h1-publishes").contains(&"shoal/r/run/world".to_string()));
        assert_eq!(acl["default_permission"], "deny");
        assert_eq!(acl["policies"].as_array().unwrap().len(), 2);
        let agent = answer_only(&["coordinator".into()]);
        assert_eq!(agent["subjects"][0]["cert_common_names"][0], "coordinator");
    }
}
