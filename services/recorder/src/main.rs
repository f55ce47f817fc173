//! `shoal-recorder`: subscribes to every channel of the run and writes one
//! MCAP file. In lockstep it writes, each frame, the samples stamped before
//! the frame in a fixed order (time, channel, sequence), so two runs of the
//! same scenario and seed give the same messages.
use clap::Parser;

mod live;
mod node;

/// Command line of the recorder.
#[derive(Debug, clap::Parser)]
#[command(about = "shoal's recorder process; started by `shoal run`, not by hand.")]
struct Cli {
    #[command(flatten)]
    run: shoal_runtime::RunArgs,
    /// The run's resolved scenario.
    #[arg(long)]
    scenario: std::path::PathBuf,
    /// The MCAP file to write.
    #[arg(long)]
    out: std::path::PathBuf,
    /// The scenario as every process runs it (defaults filled in), kept in
    /// the recording's `shoal.run` metadata as `effective_toml`.
    #[arg(long)]
    effective: Option<std::path::PathBuf>,
    #[command(flatten)]
    scope: node::Scope,
    /// Serve what is recorded, as it is recorded, over the Foxglove
    /// WebSocket protocol on this address (`shoal run --live`).
    #[arg(long, value_name = "HOST:PORT")]
    live: Option<String>,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    shoal_runtime::init_tracing();
    let text = std::fs::read_to_string(&cli.scenario)?;
    let scenario = shoal_scenario::Scenario::from_toml(&text)?;
    let effective = cli
        .effective
        .as_deref()
        .map(std::fs::read_to_string)
        .transpose()?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    let texts = node::ScenarioTexts {
        as_run: &text,
        effective: effective.as_deref(),
    };
    let task = node::RecorderTask::new(
        &rt,
        &scenario,
        &texts,
        &cli.scope,
        &cli.out,
        cli.live.as_deref(),
    )?;
    rt.run(task)?;
    Ok(())
}
