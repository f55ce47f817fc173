//! `shoal recover`: rewrites a truncated recording as a complete, indexed MCAP.

use std::path::PathBuf;

/// Arguments of `shoal recover`.
#[derive(Debug, clap::Args)]
pub struct RecoverCmd {
    /// The truncated recording.
    pub recording: PathBuf,
    /// Where to write the complete copy (default: REC.recovered.mcap).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs `shoal recover`.
pub fn run(_cmd: RecoverCmd) -> anyhow::Result<()> {
    anyhow::bail!("shoal recover is not implemented yet")
}
