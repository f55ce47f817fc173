//! `shoal gen`: generates a large-group scenario (formation tree, D_a/D_b,
//! obstacles to squeeze through) that `shoal check` accepts.

/// Arguments of `shoal gen`.
#[derive(Debug, clap::Args)]
pub struct GenCmd {
    /// Number of vehicles, leader included.
    #[arg(long, default_value_t = 25)]
    pub vehicles: usize,
}

/// Runs `shoal gen`.
pub fn run(_cmd: GenCmd) -> anyhow::Result<()> {
    anyhow::bail!("shoal gen is not implemented yet")
}
