//! How a run is launched, besides its scenario: mode, binaries, progress,
//! the lockstep tick's time limit, the adaptive wait.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use shoal_runtime::Mode;
use shoal_scenario::Scenario;

use super::RunOptions;

/// Everything one run needs besides its scenario.
#[derive(Debug, Clone)]
pub struct RunSettings {
    /// Lockstep or realtime.
    pub mode: Mode,
    /// Where the service binaries are.
    pub bin_dir: PathBuf,
    /// Show a progress bar (only on a terminal).
    pub progress: bool,
    /// Longest a lockstep tick may take before the run is declared hung.
    pub tick_timeout: Duration,
    /// Adaptive wait budget of every process, µs; 0 = block at once.
    pub spin_us: u64,
    /// Spread runs over these hosts; `None`: run here.
    pub hosts: Option<crate::hosts::HostsFile>,
    /// Keep idle CPUs polling during each run (`--idle-poll`).
    pub idle_poll: bool,
    /// Vehicle processes take part without working (`--no-work`).
    pub no_work: bool,
    /// Serve a live view on this address (`shoal run --live`).
    pub live: Option<String>,
    /// Pace a lockstep run at this many simulated seconds per wall-clock
    /// second (`--pace`); `None`: as fast as the machine allows.
    pub pace: Option<f64>,
}

/// Where the service binaries are: `bin_dir`, else the directory of the
/// running `shoal` (cargo builds them side by side).
pub fn bin_dir_or_default(bin_dir: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    match bin_dir {
        Some(d) => Ok(d),
        None => std::env::current_exe()?
            .parent()
            .map(PathBuf::from)
            .context("cannot locate the directory of the shoal binary"),
    }
}

impl RunSettings {
    /// Runs in `mode` with the binaries in `bin_dir` (default: beside
    /// `shoal`), a progress bar unless `quiet`, ticks of at most
    /// `tick_timeout` s (at least 0.1 s).
    pub fn new(
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
            hosts: None,
            idle_poll: false,
            no_work: false,
            live: None,
            pace: None,
        })
    }

    /// The options of a run of `scenario` (resolved) into `out`.
    pub fn options(&self, scenario: &Scenario, out: &Path) -> RunOptions {
        RunOptions {
            scenario: scenario.clone(),
            out: out.to_path_buf(),
            mode: self.mode,
            bin_dir: self.bin_dir.clone(),
            progress: self.progress,
            tick_timeout: self.tick_timeout,
            spin_us: self.spin_us,
            hosts: self.hosts.clone(),
            idle_poll: self.idle_poll,
            no_work: self.no_work,
            live: self.live.clone(),
            pace: self.pace,
        }
    }
}
