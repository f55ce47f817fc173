//! `shoal certs`: a deployment's CA and a certificate per host and for the
//! coordinator.

use std::path::PathBuf;

use crate::hosts::tls::{self, CertRequest};

#[derive(Debug, clap::Args)]
pub struct CertsCmd {
    /// Directory to write into: ca.pem and ca.key (the CA, made unless the
    /// directory has one already), and NAME.pem and NAME.key for each
    /// host and the coordinator. A host needs only ca.pem, NAME.pem and
    /// NAME.key; ca.key stays with whoever makes certificates.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// A hosts file: a certificate for each of its hosts, for the address
    /// of its endpoint, and for its [tls] name (the coordinator's).
    #[arg(long, value_name = "FILE")]
    hosts: Option<PathBuf>,
    /// A host's certificate: its name and the addresses it is reached at
    /// (IPs or DNS names, comma separated), e.g. h1=169.254.10.1; repeat
    /// for several.
    #[arg(long, value_name = "NAME[=ADDR,...]")]
    host: Vec<String>,
    /// The coordinator's certificate name (what `shoal host --coordinator`
    /// and a hosts file's [tls] name say).
    #[arg(long, value_name = "NAME")]
    coordinator: Option<String>,
    /// Days the certificates are valid.
    #[arg(long, default_value_t = 365, value_parser = clap::value_parser!(i64).range(1..=3650))]
    days: i64,
    /// Days from now on which validity starts (negative: in the past).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    valid_from: i64,
}

/// `NAME[=ADDR,...]` of `--host`.
fn parse_host(spec: &str) -> CertRequest {
    let (name, addrs) = spec.split_once('=').unwrap_or((spec, ""));
    CertRequest {
        name: name.trim().to_string(),
        addresses: addrs
            .split(',')
            .map(str::trim)
            .filter(|a| !a.is_empty())
            .map(String::from)
            .collect(),
    }
}

/// The address of a Zenoh endpoint (`tls/ADDR:PORT#…` → `ADDR`).
fn endpoint_address(endpoint: &str) -> Option<String> {
    let rest = endpoint.split_once('/')?.1;
    let rest = rest.split('#').next()?;
    let (addr, _) = rest.rsplit_once(':')?;
    Some(
        addr.trim_start_matches('[')
            .trim_end_matches(']')
            .to_string(),
    )
}

/// Makes the certificates.
pub fn run(cmd: CertsCmd) -> anyhow::Result<()> {
    let mut requests: Vec<CertRequest> = Vec::new();
    let mut coordinator = cmd.coordinator.clone();
    if let Some(path) = &cmd.hosts {
        let file = crate::hosts::HostsFile::load(path)?;
        for h in &file.hosts {
            requests.push(CertRequest {
                name: h.name.clone(),
                addresses: endpoint_address(&h.endpoint).into_iter().collect(),
            });
        }
        if coordinator.is_none() {
            coordinator = file.tls.map(|t| t.name);
        }
    }
    requests.extend(cmd.host.iter().map(|h| parse_host(h)));
    let coordinator = coordinator.unwrap_or_else(|| tls::DEFAULT_COORDINATOR.to_string());
    anyhow::ensure!(
        !requests.iter().any(|r| r.name == coordinator),
        "`{coordinator}` names both a host and the coordinator"
    );
    requests.push(CertRequest {
        name: coordinator.clone(),
        addresses: Vec::new(),
    });
    let mut seen = std::collections::BTreeSet::new();
    for r in &requests {
        anyhow::ensure!(seen.insert(&r.name), "`{}` is named twice", r.name);
    }
    let made = tls::make_certs(&cmd.out, &requests, cmd.valid_from, cmd.days)?;
    println!(
        "{} CA in {}",
        if made.new_ca { "a new" } else { "the existing" },
        cmd.out.join(tls::CA_CERT).display()
    );
    for r in &requests {
        let addrs = if r.addresses.is_empty() {
            String::new()
        } else {
            format!(" for {}", r.addresses.join(", "))
        };
        println!(
            "{}: {}{addrs}",
            r.name,
            cmd.out.join(format!("{}.pem", r.name)).display()
        );
    }
    println!(
        "Give each host ca.pem, NAME.pem and NAME.key (`shoal host --name NAME --certs DIR --listen quic/ADDR:7447`); the coordinator's hosts file says [tls] certs = \"{}\" (name = \"{coordinator}\"). Keep ca.key apart.",
        cmd.out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_and_endpoints_give_names_and_addresses() {
        let r = parse_host("h1=169.254.10.1, h1.lan");
        assert_eq!(r.name, "h1");
        assert_eq!(r.addresses, vec!["169.254.10.1", "h1.lan"]);
        assert!(parse_host("h2").addresses.is_empty());
        assert_eq!(
            endpoint_address("quic/169.254.77.1:7447").as_deref(),
            Some("169.254.77.1")
        );
        assert_eq!(endpoint_address("quic/[::1]:7447").as_deref(), Some("::1"));
        assert_eq!(endpoint_address("nonsense"), None);
    }
}
