//! `shoal host`: the agent of one host in runs spread over hosts.

use std::path::PathBuf;

use anyhow::Context as _;

use crate::hosts::agent::{self, AgentOptions};
use crate::hosts::tls::{Identity, Security};
use crate::launch;

#[derive(Debug, clap::Args)]
pub struct HostCmd {
    /// Zenoh endpoint to listen on for coordinators (`shoal run --hosts`),
    /// e.g. quic/169.254.10.1:7447 (QUIC, TLS 1.3 with mutual
    /// authentication, with --certs), or tcp/… with --insecure; repeat for
    /// several.
    #[arg(long, required = true)]
    listen: Vec<String>,
    /// The directory of this host's certificates, as `shoal certs` writes
    /// them: ca.pem (the deployment's CA), NAME.pem and NAME.key (this
    /// host's certificate and key, NAME as --name). Peers must present a
    /// certificate the CA signed.
    #[arg(long, value_name = "DIR")]
    certs: Option<PathBuf>,
    /// The certificate name of the coordinator this host answers (repeat
    /// for several); every other peer is refused everything.
    #[arg(long, value_name = "NAME", default_value = crate::hosts::tls::DEFAULT_COORDINATOR)]
    coordinator: Vec<String>,
    /// Listen on plain TCP: no authentication, no access control; anyone
    /// who reaches the port can start, read and abort runs. Announced at
    /// start.
    #[arg(long, conflicts_with = "certs")]
    insecure: bool,
    /// This host's name, as the hosts file names it (default: the system's
    /// host name).
    #[arg(long)]
    name: Option<String>,
    /// Where a run keeps its files until the coordinator has taken them.
    #[arg(long, default_value = "/tmp/shoal-host")]
    work: PathBuf,
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
    /// Serve one run, then exit (default: serve runs until SIGINT/SIGTERM).
    #[arg(long)]
    once: bool,
}

/// Serves runs.
pub fn run(cmd: HostCmd) -> anyhow::Result<()> {
    let name = match cmd.name {
        Some(n) => n,
        None => std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_string())
            .unwrap_or_else(|_| "host".into()),
    };
    let file = crate::hosts::HostsFile {
        hosts: vec![crate::hosts::placement::HostEntry {
            name: name.clone(),
            endpoint: String::new(),
            vehicles: Vec::new(),
        }],
        placement: Default::default(),
        tls: None,
        insecure: false,
    };
    // The same rule as the hosts file's names.
    crate::hosts::HostsFile::parse(&toml::to_string(&file)?)?;
    let security = security(&cmd.listen, cmd.certs.as_deref(), &name, cmd.insecure)?;
    agent::serve(&AgentOptions {
        security,
        coordinators: cmd.coordinator,
        listen: cmd.listen,
        name,
        work: cmd.work,
        bin_dir: launch::bin_dir_or_default(cmd.bin_dir)?,
        once: cmd.once,
    })
}

/// TLS as `name` from `certs` for tls/ endpoints, checked before the agent
/// listens; plain TCP only with `insecure`.
fn security(
    listen: &[String],
    certs: Option<&std::path::Path>,
    name: &str,
    insecure: bool,
) -> anyhow::Result<Security> {
    let tcp = listen.iter().filter(|e| e.starts_with("tcp/")).count();
    let tls = listen.iter().filter(|e| e.starts_with("quic/")).count();
    anyhow::ensure!(
        tcp + tls == listen.len(),
        "--listen takes quic/ADDR:PORT (TLS 1.3 with --certs; or tcp/ADDR:PORT with --insecure), not {listen:?}. Zenoh's tls/ link is not used: in Zenoh 1.10 it breaks under a run's traffic (zenoh issue 2557)"
    );
    if insecure {
        anyhow::ensure!(
            tls == 0,
            "--insecure listens on plain TCP: give tcp/ endpoints, not {listen:?}"
        );
        return Ok(Security::Insecure);
    }
    anyhow::ensure!(
        tcp == 0,
        "--listen {listen:?} is plain TCP: anyone who reaches it could start, read and abort runs. Listen on quic/ADDR:PORT (TLS 1.3) with --certs DIR (`shoal certs` makes them), or say --insecure"
    );
    let dir = certs.ok_or_else(|| {
        anyhow::anyhow!(
            "--listen on QUIC (TLS 1.3) needs --certs DIR holding ca.pem, {name}.pem and {name}.key (`shoal certs --out DIR --host {name}=ADDR` makes them)"
        )
    })?;
    let id = Identity::in_dir(dir, name);
    let until = id
        .check()
        .with_context(|| format!("this host's certificate ({name})"))?;
    tracing::info!(cert = %id.cert.display(), valid_until = %until, "certificate checked");
    Ok(Security::Tls(id))
}
