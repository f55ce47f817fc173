//! The command line: one file per command, each holding its clap arguments
//! and its printing; the work is in the library's other folders. The
//! benchmarks are the exception: each module of [`crate::bench`] is a whole
//! command whose only product is what it prints, so it keeps its arguments
//! and its tables, and this file only names them.

mod campaign;
mod certs;
mod check;
mod compare;
mod export;
mod gen;
mod host;
mod inspect;
mod recover;
mod replay;
mod run;
mod summarize;
mod top;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub use run::ProcessArgs;

use crate::{bench, launch};

/// A `--duration`: a finite number of seconds > 0 (one spelling and one check for
/// every command that takes one; `-5` reaches it instead of being taken for a flag).
pub fn parse_duration(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(d) if d.is_finite() && d > 0.0 => Ok(d),
        _ => Err(format!("`{s}` is not a positive number of seconds")),
    }
}

/// Leader–follower AUV formations as multi-process soft-real-time software.
#[derive(Debug, Parser)]
#[command(
    name = "shoal",
    version,
    about,
    long_about = None,
    after_help = "Environment:\n  RUST_LOG   what every process logs: a level (error, warn, info [default], debug, trace)\n             or per-target filters, e.g. RUST_LOG=debug or RUST_LOG=info,shoal_planner=debug;\n             the children of a run inherit it (their logs are in DIR/logs/).\n  NO_COLOR   set to plain text; colour is used only when stderr is a terminal."
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Run a scenario (default: the paper's) and leave DIR/recording.mcap,
    /// DIR/summary.json, DIR/plots/ and DIR/logs/.
    Run(run::RunCmd),
    /// Write summary.json and the plots from a recording alone (a finished
    /// run, one cut short, a recovered one).
    Summarize(summarize::SummarizeCmd),
    /// Validate a scenario without starting anything.
    Check {
        /// Scenario TOML (default: the embedded paper scenario).
        scenario: Option<PathBuf>,
        /// Print the scenario as every process runs it instead: every
        /// section with its defaults, D_a/D_b assigned (what a recording
        /// keeps as `shoal.run` / `effective_toml`).
        #[arg(long)]
        resolved: bool,
        /// Also place the group on the hosts of this file (as `shoal run
        /// --hosts` would) and print what crosses hosts and the bandwidth
        /// each link needs.
        #[arg(long)]
        hosts: Option<PathBuf>,
        /// Where the run would write (default: runs/, as `shoal run`):
        /// warns when that disk cannot hold the expected recording.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// Run the method, the paper's method as published, the acoustic-modem
    /// baseline and the no-vertical-shift ablation side by side; write
    /// DIR/compare.md and DIR/compare.json.
    Compare(compare::CompareCmd),
    /// List a recording's channels, schemas, counts, rates, time span, gaps.
    Inspect {
        /// The MCAP file.
        recording: PathBuf,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Also print the recording's digest: one SHA-256 over every
        /// message (topic, log time, payload without wall-clock fields),
        /// equal for two lockstep runs of the same scenario and seed.
        #[arg(long)]
        digest: bool,
    },
    /// Generate a large-group scenario or an obstacle course on stdout.
    Gen(gen::GenCmd),
    /// Run N generated courses x K seeds and report the pass rate per
    /// family, the worst figures and the failing runs.
    Campaign(campaign::CampaignCmd),
    /// Convert a recording for other viewers (Foxglove).
    Export(export::ExportCmd),
    /// Write a complete, indexed copy of a truncated recording.
    Recover(recover::RecoverCmd),
    /// Play a recording back onto iceoryx2, or re-run one process on its
    /// recorded inputs and report the first output that differs (exit
    /// status 3 when one does).
    Replay(replay::ReplayCmd),
    /// Serve as one host of runs spread over several (`shoal run --hosts`):
    /// start and reap this host's processes, bridge what crosses hosts onto
    /// Zenoh, follow the coordinator's lockstep clock.
    Host(host::HostCmd),
    /// Make a deployment's CA and a certificate per host and for the
    /// coordinator, for TLS with mutual authentication between hosts.
    Certs(certs::CertsCmd),
    /// A live table of a running run's processes: step times, CPU,
    /// memory, restarts, samples lost, per-input latency, the recorder's
    /// throughput, the latest events.
    Top(top::TopCmd),
    /// Benchmarks that print figures.
    #[command(subcommand)]
    Bench(BenchCmd),
}

#[derive(Debug, Subcommand)]
enum BenchCmd {
    /// Ping-pong latency: raw iceoryx2, shoal's runtime, Unix-domain sockets.
    Ipc(bench::ipc::IpcCmd),
    /// Real-time factor and CPU time of a scenario in lockstep (blocking and
    /// adaptive waits), end-to-end latency in realtime mode.
    Run(bench::run::RunBenchCmd),
    /// The runtime's CPU per lockstep step of each process kind and the
    /// orchestrator's per tick, apart from what a process costs once (long
    /// run minus short run); with --syscalls, system calls per step.
    Step(bench::step::StepCmd),
    /// Cost against group size: N = 5, 25, 50, 100 in lockstep (processes,
    /// real-time factor, CPU per vehicle-second, memory, recorder rate).
    Scale(bench::scale::ScaleCmd),
    /// What spreading a run over hosts costs, on network namespaces made
    /// for it (root): the cross-host hop against raw Zenoh, the lockstep
    /// tick over 1, 2 and 4 hosts, a large group over several hosts, and
    /// 1,000 vehicles over 16 hosts on paper.
    Hosts(bench::hosts::HostsBenchCmd),
    /// How fast, and in how much memory, `shoal check` refuses inputs far
    /// too large (10,000 vehicles, 100,000 obstacles, 100 MB, a million
    /// mesh triangles).
    Refuse(bench::refuse::RefuseCmd),
    /// A long realtime run (25 vehicles for an hour by default) watched
    /// from outside: memory, open descriptors and shared-memory files over
    /// time, and how much each grew after the first minute.
    Soak(bench::soak::SoakCmd),
    /// One end of `bench hosts`' hop, run inside a host (not by hand).
    #[command(hide = true)]
    HopPeer(bench::hosts::HopPeerCmd),
    /// The camera chain without processes: pose error from rendered images
    /// against the point model over ranges and turbidities, and the cost
    /// of a frame (render, detect, identify, PnP).
    Vision(bench::vision::VisionCmd),
}

/// Parses the command line, runs the command, prints an error chain.
pub fn main() -> ExitCode {
    launch::os::default_sigpipe();
    // Children inherit it: a run of many vehicles needs thousands of files.
    launch::os::raise_nofile_limit();
    shoal_runtime::init_tracing();
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Run(cmd) => run::run(cmd),
        Cmd::Check {
            scenario,
            resolved,
            hosts,
            out,
        } => check::run(scenario, resolved, hosts, out),
        Cmd::Host(cmd) => host::run(cmd),
        Cmd::Inspect {
            recording,
            json,
            digest,
        } => inspect::run(recording, json, digest),
        Cmd::Summarize(cmd) => summarize::run(cmd),
        Cmd::Compare(cmd) => compare::run(cmd),
        Cmd::Gen(cmd) => gen::run(cmd),
        Cmd::Campaign(cmd) => campaign::run(cmd),
        Cmd::Export(cmd) => export::run(cmd),
        Cmd::Recover(cmd) => recover::run(cmd),
        Cmd::Replay(cmd) => replay::run(cmd),
        Cmd::Top(cmd) => top::run(cmd),
        Cmd::Certs(cmd) => certs::run(cmd),
        Cmd::Bench(BenchCmd::Ipc(cmd)) => bench::ipc::run(cmd),
        Cmd::Bench(BenchCmd::Run(cmd)) => bench::run::run(cmd),
        Cmd::Bench(BenchCmd::Scale(cmd)) => bench::scale::run(cmd),
        Cmd::Bench(BenchCmd::Step(cmd)) => bench::step::run(cmd),
        Cmd::Bench(BenchCmd::Vision(cmd)) => bench::vision::run(cmd),
        Cmd::Bench(BenchCmd::Hosts(cmd)) => bench::hosts::run(cmd),
        Cmd::Bench(BenchCmd::Soak(cmd)) => bench::soak::run(cmd),
        Cmd::Bench(BenchCmd::Refuse(cmd)) => bench::refuse::run(cmd),
        Cmd::Bench(BenchCmd::HopPeer(cmd)) => bench::hosts::hop_peer(cmd),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            exit_code(&e)
        }
    }
}

/// The shell's convention for a run stopped by a signal: 128 + its number
/// (130 after Ctrl-C, 143 after SIGTERM); 1 for any other error.
fn exit_code(e: &anyhow::Error) -> ExitCode {
    let signal = e.chain().find_map(|c| match c.downcast_ref() {
        Some(launch::RunError::Interrupted("SIGINT")) => Some(libc::SIGINT),
        Some(launch::RunError::Interrupted("SIGTERM")) => Some(libc::SIGTERM),
        _ => None,
    });
    signal.map_or(ExitCode::FAILURE, |s| ExitCode::from(128 + s as u8))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_negative_or_zero_duration_is_refused_with_its_reason() {
        for cmd in [["run"].as_slice(), &["bench", "scale"], &["bench", "run"]] {
            for bad in ["-5", "0", "nan", "x"] {
                let args = [&["shoal"], cmd, &["--duration", bad]].concat();
                let err = Cli::try_parse_from(args).unwrap_err().to_string();
                assert!(
                    err.contains("not a positive number of seconds"),
                    "{cmd:?} {bad}: {err}"
                );
            }
            let args = [&["shoal"], cmd, &["--duration", "2.5"]].concat();
            assert!(Cli::try_parse_from(args).is_ok(), "{cmd:?}");
        }
    }

    #[test]
    fn rerun_only_options_are_refused_without_rerun() {
        for extra in [
            ["--set", "follower.beta=0.2"].as_slice(),
            &["--vehicle", "F1"],
            &["--json"],
        ] {
            let args = [&["shoal", "replay", "r.mcap"], extra].concat();
            let err = Cli::try_parse_from(args).unwrap_err().to_string();
            assert!(err.contains("--rerun"), "{extra:?}: {err}");
            let args = [&["shoal", "replay", "r.mcap", "--rerun", "mpc"], extra].concat();
            assert!(Cli::try_parse_from(args).is_ok(), "{extra:?}");
        }
    }

    #[test]
    fn the_help_names_every_command_and_the_environment() {
        use clap::CommandFactory as _;
        let help = Cli::command().render_long_help().to_string();
        for name in [
            "run",
            "summarize",
            "check",
            "compare",
            "inspect",
            "gen",
            "campaign",
            "export",
            "recover",
            "replay",
            "host",
            "bench",
        ] {
            assert!(help.contains(&format!("  {name}")), "{name}: {help}");
        }
        assert!(
            help.contains("RUST_LOG") && help.contains("NO_COLOR"),
            "{help}"
        );
    }
}
