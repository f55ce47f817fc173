//! `shoal host`: the agent of one host in runs spread over hosts.

use std::path::PathBuf;

use crate::hosts::agent::{self, AgentOptions};
use crate::launch;

#[derive(Debug, clap::Args)]
pub struct HostCmd {
    /// Zenoh endpoint to listen on for coordinators (`shoal run --hosts`),
    /// e.g. tcp/169.254.10.1:7447; repeat for several.
    #[arg(long, required = true)]
    listen: Vec<String>,
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
    };
    // The same rule as the hosts file's names.
    crate::hosts::HostsFile::parse(&toml::to_string(&file)?)?;
    agent::serve(&AgentOptions {
        listen: cmd.listen,
        name,
        work: cmd.work,
        bin_dir: launch::bin_dir_or_default(cmd.bin_dir)?,
        once: cmd.once,
    })
}
