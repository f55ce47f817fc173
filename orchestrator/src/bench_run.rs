//! `shoal bench run`: the real-time factor and CPU time of a scenario in
//! lockstep (blocking and adaptive waits), and its end-to-end latency in
//! realtime mode.

/// Arguments of `shoal bench run`.
#[derive(Debug, clap::Args)]
pub struct RunBenchCmd {
    /// Scenario TOML (default: the embedded paper scenario).
    pub scenario: Option<std::path::PathBuf>,
}

/// Runs the benchmark.
pub fn run(_cmd: RunBenchCmd) -> anyhow::Result<()> {
    anyhow::bail!("shoal bench run is not written yet")
}
