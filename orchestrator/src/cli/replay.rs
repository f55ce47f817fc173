//! `shoal replay`: play a recording back onto iceoryx2, or re-run one
//! process on its recorded inputs and report the first difference (exit
//! status 3 when there is one).

use std::path::PathBuf;

use recordings::Recording;

use crate::replay::{play, rerun, PlayOptions, RerunOptions};

/// Arguments of `shoal replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayCmd {
    /// The recording (MCAP written by `shoal run`).
    pub recording: PathBuf,
    /// Playback speed against the recording's simulated time (2 = twice as
    /// fast); 0 = as fast as possible.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Run id of the new domain (default: a fresh one, printed).
    #[arg(long)]
    pub run_id: Option<String>,
    /// Before playing, wait (up to 60 s) until this many subscribers are
    /// connected to the replayed channels.
    #[arg(long, default_value_t = 0)]
    pub wait_subscribers: usize,
    /// Re-run this process kind (sim-plant, world, camera-pose, sonar,
    /// planner, mpc) alone on its recorded inputs and compare its outputs.
    #[arg(long)]
    pub rerun: Option<String>,
    /// The vehicle whose process is re-run (not needed for `world`).
    #[arg(long, requires = "rerun")]
    pub vehicle: Option<String>,
    /// Override a scenario key for the re-run, `section.key=value` in TOML
    /// (e.g. `follower.beta=0.2`); repeatable; only with --rerun (playback
    /// sends what was recorded).
    #[arg(long = "set", requires = "rerun")]
    pub set: Vec<String>,
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// Print the re-run's report as JSON.
    #[arg(long, requires = "rerun")]
    pub json: bool,
    /// No progress bar while playing.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `shoal replay`.
pub fn run(cmd: ReplayCmd) -> anyhow::Result<()> {
    let rec = Recording::open(&cmd.recording)?;
    if rec.truncated() {
        tracing::warn!("the recording is truncated; replaying what it holds");
    }
    match cmd.rerun {
        Some(kind) => {
            let opts = RerunOptions {
                kind,
                vehicle: cmd.vehicle,
                set: cmd.set,
                bin_dir: cmd.bin_dir,
            };
            let report = rerun(&rec, &opts)?;
            if cmd.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                println!("{}", report.describe());
            }
            if report.difference.is_some() {
                std::process::exit(3);
            }
            Ok(())
        }
        None => play(
            &rec,
            &PlayOptions {
                speed: cmd.speed,
                run_id: cmd.run_id,
                wait_subscribers: cmd.wait_subscribers,
                progress: !cmd.quiet,
            },
        ),
    }
}
