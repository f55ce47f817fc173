//! `shoal-ipc-peer`: one peer of a `shoal bench ipc` case (see the
//! `shoal_bench_ipc` crate). Every role prints one JSON line on stdout;
//! errors go to stderr with a non-zero exit code.

use std::process::ExitCode;

use clap::Parser;
use shoal_bench_ipc::{run_peer, PeerConfig, PeerOutput};

fn main() -> ExitCode {
    shoal_runtime::init_tracing();
    let cfg = PeerConfig::parse();
    let printed = match run_peer(&cfg) {
        Ok(PeerOutput::Ping(report)) => serde_json::to_string(&report),
        Ok(PeerOutput::Costs(costs)) => serde_json::to_string(&costs),
        Ok(PeerOutput::Pong(report)) => serde_json::to_string(&report),
        Err(e) => {
            eprintln!("shoal-ipc-peer {:?} {}: {e}", cfg.role, cfg.case.name());
            return ExitCode::FAILURE;
        }
    };
    match printed {
        Ok(line) => {
            println!("{line}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("shoal-ipc-peer: cannot encode the report: {e}");
            ExitCode::FAILURE
        }
    }
}
