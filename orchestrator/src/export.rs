//! `shoal export`: converts a shoal recording into channels other tools show
//! without a plug-in (Foxglove).

use std::path::PathBuf;

/// Arguments of `shoal export`.
#[derive(Debug, clap::Args)]
pub struct ExportCmd {
    /// The shoal recording (MCAP).
    pub recording: PathBuf,
    /// Write a Foxglove-ready MCAP here.
    #[arg(long)]
    pub foxglove: PathBuf,
}

/// Runs `shoal export`.
pub fn run(_cmd: ExportCmd) -> anyhow::Result<()> {
    anyhow::bail!("shoal export is not implemented yet")
}
