//! `shoal bench ipc`: raw iceoryx2, shoal's runtime and Unix-domain sockets,
//! ping-pong side by side in separate processes.

/// Arguments of `shoal bench ipc`.
#[derive(Debug, clap::Args)]
pub struct IpcCmd {
    /// Round trips per case.
    #[arg(long, default_value_t = 20_000)]
    pub iterations: u64,
}

/// Runs `shoal bench ipc`.
pub fn run(_cmd: IpcCmd) -> anyhow::Result<()> {
    anyhow::bail!("shoal bench ipc is not implemented yet")
}
