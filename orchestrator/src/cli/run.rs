//! `shoal run`: one scenario, its recording, summary and plots.

use std::path::PathBuf;

use shoal_runtime::Mode;

use crate::analysis::summary::Summary;
use crate::launch::{self, RunSettings};
use crate::{pipeline, preflight};

#[derive(Debug, clap::Args)]
pub struct RunCmd {
    /// Scenario TOML (default: the embedded `scenarios/paper.toml`).
    scenario: Option<PathBuf>,
    /// Output directory (default: runs/<scenario>-<unix time>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// lockstep: deterministic, as fast as the machine allows; realtime: every
    /// process on its own wall-clock rate.
    #[arg(long, value_enum, default_value = "lockstep")]
    mode: Mode,
    /// Seed of every random generator (overrides the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Simulated duration in seconds (overrides the scenario's).
    #[arg(long)]
    duration: Option<f64>,
    #[command(flatten)]
    processes: ProcessArgs,
    /// No progress bar and no closing table.
    #[arg(long, short)]
    quiet: bool,
    /// Adaptive wait: every process polls this long for its next wake-up
    /// before blocking, µs (0 = block at once, the default; worth it only
    /// with a spare core per busy process).
    #[arg(long, default_value_t = 0)]
    spin_us: u64,
}

/// Where the service binaries are and how long a tick may take: the options
/// of every command that runs scenarios with the full set of processes.
#[derive(Debug, Clone, clap::Args)]
pub struct ProcessArgs {
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// Longest a lockstep tick may take before a run is declared hung, s.
    #[arg(long, default_value_t = 30.0)]
    pub tick_timeout: f64,
}

impl ProcessArgs {
    /// The settings of runs in `mode`, with a progress bar unless `quiet`.
    pub fn settings(&self, mode: Mode, quiet: bool) -> anyhow::Result<RunSettings> {
        RunSettings::new(mode, self.bin_dir.clone(), quiet, self.tick_timeout)
    }
}

/// Runs the scenario, prints the closing table and the output directory.
pub fn run(cmd: RunCmd) -> anyhow::Result<()> {
    let mut scenario = preflight::load_scenario(&cmd.scenario)?;
    if let Some(s) = cmd.seed {
        scenario.seed = s;
    }
    if let Some(d) = cmd.duration {
        scenario.duration_s = d;
    }
    let out = cmd
        .out
        .clone()
        .unwrap_or_else(|| launch::default_out(&scenario));
    let mut settings = cmd.processes.settings(cmd.mode, cmd.quiet)?;
    settings.spin_us = cmd.spin_us;
    let summary = pipeline::run_and_summarize(scenario, &out, &settings)?.summary;
    if !cmd.quiet {
        print_table(&summary);
    }
    println!("{}", out.display());
    Ok(())
}

fn print_table(s: &Summary) {
    let safe = s.safety.safe_distance_m;
    let min_pair = s.safety.min_pair_distance_m.unwrap_or(f64::NAN);
    let collisions = s.safety.collisions;
    let mark = |ok: bool| if ok { "pass" } else { "FAIL" };
    eprintln!(
        "  run              {} ({}), {:.1} s simulated in {:.1} s ({:.1}x real time)",
        s.scenario, s.mode, s.sim_time_s, s.wall_time_s, s.real_time_factor
    );
    eprintln!(
        "  collisions       {collisions}  [{}]",
        mark(collisions == 0)
    );
    eprintln!(
        "  min pair dist    {min_pair:.2} m ({}) vs safe {safe:.2} m  [{}]",
        s.safety.min_pair,
        mark(min_pair >= safe)
    );
    eprintln!(
        "  min clearance    {:.2} m to obstacles",
        s.safety.min_obstacle_clearance_m.unwrap_or(f64::NAN)
    );
    let rms = &s.formation.slot_error_rms_m;
    eprintln!(
        "  slot error rms   before {:.2} m, during {:.2} m, after {:.2} m",
        rms.before, rms.during, rms.after
    );
    eprintln!(
        "  recording        {} messages, {} dropped",
        s.recording.messages, s.recording.dropped
    );
}
