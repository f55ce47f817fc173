//! `shoal`: runs a group of AUVs in leader–follower formation as real
//! processes over iceoryx2, records every channel to MCAP, and inspects the
//! recordings. See `shoal --help`.

mod bench_ipc;
mod bench_run;
mod bench_scale;
mod check;
mod compare;
mod export;
mod gen;
mod plots;
mod recover;
mod recovery;
mod replay;
mod run;
mod summary;
mod supervisor;
mod sys;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, Subcommand};
use shoal_runtime::Mode;
use shoal_scenario::Scenario;

/// Leader–follower AUV formations as multi-process soft-real-time software.
#[derive(Debug, Parser)]
#[command(name = "shoal", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Run a scenario (default: the paper's) and leave DIR/recording.mcap,
    /// DIR/summary.json and DIR/logs/.
    Run(RunCmd),
    /// Validate a scenario without starting anything.
    Check {
        /// Scenario TOML (default: the embedded paper scenario).
        scenario: Option<PathBuf>,
    },
    /// Run the method, the acoustic-modem baseline and the no-vertical-shift
    /// ablation side by side; write DIR/compare.md and DIR/compare.json.
    Compare(CompareCmd),
    /// List a recording's channels, schemas, counts, rates, time span, gaps.
    Inspect {
        /// The MCAP file.
        recording: PathBuf,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Generate a large-group scenario on stdout.
    Gen(gen::GenCmd),
    /// Convert a recording for other viewers (Foxglove).
    Export(export::ExportCmd),
    /// Write a complete, indexed copy of a truncated recording.
    Recover(recover::RecoverCmd),
    /// Play a recording back onto iceoryx2, or re-run one process on its
    /// recorded inputs and report the first output that differs.
    Replay(replay::ReplayCmd),
    /// Benchmarks that print figures.
    #[command(subcommand)]
    Bench(BenchCmd),
}

#[derive(Debug, Subcommand)]
enum BenchCmd {
    /// Ping-pong latency: raw iceoryx2, shoal's runtime, Unix-domain sockets.
    Ipc(bench_ipc::IpcCmd),
    /// Real-time factor and CPU time of a scenario in lockstep (blocking and
    /// adaptive waits), end-to-end latency in realtime mode.
    Run(bench_run::RunBenchCmd),
    /// Cost against group size: N = 5, 25, 50, 100 in lockstep (processes,
    /// real-time factor, CPU per vehicle-second, memory, recorder rate).
    Scale(bench_scale::ScaleCmd),
}

#[derive(Debug, clap::Args)]
struct RunCmd {
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

#[derive(Debug, clap::Args)]
struct CompareCmd {
    /// Scenario TOML (default: the embedded paper scenario).
    scenario: Option<PathBuf>,
    /// Output directory (default: runs/compare-<scenario>-<unix time>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Seed (overrides the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
    /// No progress bars.
    #[arg(long, short)]
    quiet: bool,
}

fn load_scenario(path: &Option<PathBuf>) -> anyhow::Result<Scenario> {
    match path {
        Some(p) => {
            Scenario::from_file(p).with_context(|| format!("scenario {} refused", p.display()))
        }
        None => Scenario::paper().context("the embedded paper scenario is invalid"),
    }
}

/// Where the service binaries are: `--bin-dir`, else the directory of the
/// running `shoal` (cargo builds them side by side).
fn bin_dir_or_default(bin_dir: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    match bin_dir {
        Some(d) => Ok(d),
        None => std::env::current_exe()?
            .parent()
            .map(PathBuf::from)
            .context("cannot locate the directory of the shoal binary"),
    }
}

/// Everything one run needs besides its scenario.
struct RunSettings {
    mode: Mode,
    bin_dir: PathBuf,
    progress: bool,
    tick_timeout: Duration,
    spin_us: u64,
}

/// Where the service binaries are and how long a tick may take: the options
/// of every command that runs scenarios with the full set of processes.
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct ProcessArgs {
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// Longest a lockstep tick may take before a run is declared hung, s.
    #[arg(long, default_value_t = 30.0)]
    pub tick_timeout: f64,
}

impl ProcessArgs {
    /// The settings of runs in `mode`, with a progress bar unless `quiet`.
    fn settings(&self, mode: Mode, quiet: bool) -> anyhow::Result<RunSettings> {
        RunSettings::new(mode, self.bin_dir.clone(), quiet, self.tick_timeout)
    }
}

impl RunSettings {
    fn new(
        mode: Mode,
        bin_dir: Option<PathBuf>,
        quiet: bool,
        tick_timeout: f64,
    ) -> anyhow::Result<Self> {
        let bin_dir = bin_dir_or_default(bin_dir)?;
        Ok(Self {
            mode,
            bin_dir,
            progress: !quiet,
            tick_timeout: Duration::from_secs_f64(tick_timeout.max(0.1)),
            spin_us: 0,
        })
    }

    /// The options of a run of `scenario` (resolved) into `out`.
    fn options(&self, scenario: &Scenario, out: &std::path::Path) -> run::RunOptions {
        run::RunOptions {
            scenario: scenario.clone(),
            out: out.to_path_buf(),
            mode: self.mode,
            bin_dir: self.bin_dir.clone(),
            progress: self.progress,
            tick_timeout: self.tick_timeout,
            spin_us: self.spin_us,
        }
    }
}

/// A finished, summarised run.
struct Finished {
    /// What summary.json holds.
    summary: serde_json::Value,
    /// The scenario as resolved and run (D_a/D_b assigned).
    scenario: Scenario,
    /// The run's recording, read.
    recording: recordings::Recording,
}

/// Resolves, runs and summarises one scenario into `out` (summary.json and
/// plots written).
fn run_and_summarize(
    mut scenario: Scenario,
    out: &std::path::Path,
    settings: &RunSettings,
) -> anyhow::Result<Finished> {
    check::resolve(&mut scenario).context("scenario refused")?;
    for line in check::advice(&scenario) {
        tracing::warn!("{line}");
    }
    if out.join("recording.mcap").exists() {
        anyhow::bail!(
            "{} already holds a recording; choose another --out (nothing was overwritten)",
            out.display()
        );
    }
    let outcome = run::run(&settings.options(&scenario, out))?;
    let rec = recordings::Recording::open(&outcome.recording)?;
    let summary = summary::summarize(&scenario, &rec, &outcome, settings.mode.as_str());
    let path = out.join("summary.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    plots::write_plots(&scenario, &rec, &out.join("plots")).context("writing the plots")?;
    Ok(Finished {
        summary,
        scenario,
        recording: rec,
    })
}

fn cmd_run(cmd: RunCmd) -> anyhow::Result<()> {
    let mut scenario = load_scenario(&cmd.scenario)?;
    if let Some(s) = cmd.seed {
        scenario.seed = s;
    }
    if let Some(d) = cmd.duration {
        scenario.duration_s = d;
    }
    let out = cmd
        .out
        .clone()
        .unwrap_or_else(|| run::default_out(&scenario));
    let mut settings = cmd.processes.settings(cmd.mode, cmd.quiet)?;
    settings.spin_us = cmd.spin_us;
    let summary = run_and_summarize(scenario, &out, &settings)?.summary;
    if !cmd.quiet {
        print_table(&summary);
    }
    println!("{}", out.display());
    Ok(())
}

fn print_table(s: &serde_json::Value) {
    let f = |p: &str| s.pointer(p).and_then(|v| v.as_f64()).unwrap_or(f64::NAN);
    let safe = f("/safety/safe_distance_m");
    let min_pair = f("/safety/min_pair_distance_m");
    let collisions = f("/safety/collisions");
    let mark = |ok: bool| if ok { "pass" } else { "FAIL" };
    eprintln!(
        "  run              {} ({}), {:.1} s simulated in {:.1} s ({:.1}x real time)",
        s["scenario"].as_str().unwrap_or(""),
        s["mode"].as_str().unwrap_or(""),
        f("/sim_time_s"),
        f("/wall_time_s"),
        f("/real_time_factor")
    );
    eprintln!(
        "  collisions       {collisions:.0}  [{}]",
        mark(collisions == 0.0)
    );
    eprintln!(
        "  min pair dist    {min_pair:.2} m ({}) vs safe {safe:.2} m  [{}]",
        s.pointer("/safety/min_pair")
            .and_then(|v| v.as_str())
            .unwrap_or(""),
        mark(min_pair >= safe)
    );
    eprintln!(
        "  min clearance    {:.2} m to obstacles",
        f("/safety/min_obstacle_clearance_m")
    );
    eprintln!(
        "  slot error rms   before {:.2} m, during {:.2} m, after {:.2} m",
        f("/formation/slot_error_rms_m/before"),
        f("/formation/slot_error_rms_m/during"),
        f("/formation/slot_error_rms_m/after")
    );
    eprintln!(
        "  recording        {:.0} messages, {:.0} dropped",
        f("/recording/messages"),
        f("/recording/dropped")
    );
}

fn cmd_inspect(path: PathBuf, json: bool) -> anyhow::Result<()> {
    let rec = recordings::Recording::open(&path)?;
    let report = rec.inspect();
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "{}: {} messages, {:.3} s .. {:.3} s{}",
        report.path,
        report.messages,
        report.start_s,
        report.end_s,
        if report.truncated {
            "  [TRUNCATED: read up to the last complete chunk]"
        } else {
            ""
        }
    );
    println!(
        "{:<26} {:<20} {:>8} {:>9} {:>6} {:>9}",
        "topic", "schema", "count", "rate Hz", "gaps", "max gap s"
    );
    for c in &report.channels {
        println!(
            "{:<26} {:<20} {:>8} {:>9.2} {:>6} {:>9.3}",
            c.topic, c.schema, c.messages, c.rate_hz, c.gaps, c.max_interval_s
        );
    }
    if let Some(m) = report.metadata.get("shoal.run") {
        println!(
            "run: scenario {} seed {} mode {}",
            m.get("scenario").map_or("?", String::as_str),
            m.get("seed").map_or("?", String::as_str),
            m.get("mode").map_or("?", String::as_str)
        );
    }
    Ok(())
}

fn main() -> ExitCode {
    sys::default_sigpipe();
    // Children inherit it: a run of many vehicles needs thousands of files.
    sys::raise_nofile_limit();
    shoal_runtime::init_tracing();
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Run(cmd) => cmd_run(cmd),
        Cmd::Check { scenario } => load_scenario(&scenario).and_then(|mut s| {
            check::resolve(&mut s)?;
            println!(
                "{}: ok ({} vehicles, {} processes)",
                s.name,
                s.vehicles.len(),
                s.processes().len()
            );
            for line in check::advice(&s) {
                println!("warning: {line}");
            }
            for v in s.vehicles.iter().filter(|v| v.parent.is_some()) {
                println!(
                    "  {:<8} follows {:<8} slot {:?} m  D_a {:.2} m  D_b {:+.2} m",
                    v.name,
                    v.parent.as_deref().unwrap_or(""),
                    v.slot_m.unwrap_or_default(),
                    v.d_a_m.unwrap_or(0.0),
                    v.d_b_m.unwrap_or(0.0)
                );
            }
            Ok(())
        }),
        Cmd::Inspect { recording, json } => cmd_inspect(recording, json),
        Cmd::Compare(cmd) => compare::cmd_compare(cmd),
        Cmd::Gen(cmd) => gen::run(cmd),
        Cmd::Export(cmd) => export::run(cmd),
        Cmd::Recover(cmd) => recover::run(cmd),
        Cmd::Replay(cmd) => replay::run(cmd),
        Cmd::Bench(BenchCmd::Ipc(cmd)) => bench_ipc::run(cmd),
        Cmd::Bench(BenchCmd::Run(cmd)) => bench_run::run(cmd),
        Cmd::Bench(BenchCmd::Scale(cmd)) => bench_scale::run(cmd),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
