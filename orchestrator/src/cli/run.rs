//! `shoal run`: one scenario, its recording, summary and plots.

use anyhow::Context as _;
use std::path::PathBuf;

use shoal_runtime::Mode;

use crate::analysis::summary::{fmt_or_na, Summary, PARENT_LOST_LIMIT_S};
use crate::launch::{self, RunSettings};
use crate::{pipeline, preflight};

#[derive(Debug, clap::Args)]
pub struct RunCmd {
    /// Scenario TOML (default: the embedded `scenarios/paper.toml`).
    scenario: Option<PathBuf>,
    /// Output directory (default: runs/<scenario>-<unix time>); it receives
    /// recording.mcap, summary.json, plots/, logs/, run.json and scenario.toml.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace what an earlier run left in `--out` (the files above; nothing
    /// else in the directory is touched). Without it a directory that holds a
    /// recording is refused and nothing is overwritten.
    #[arg(long)]
    force: bool,
    /// lockstep: deterministic, as fast as the machine allows; realtime: every
    /// process on its own wall-clock rate, phased like a lockstep frame;
    /// dataflow: on the wall clock, each stage woken by its inputs (camera
    /// frame → camera-pose → planner → mpc → thrust), the plant applying
    /// thrust when it comes, the phased timers as deadlines (one host only).
    #[arg(long, value_enum, default_value = "lockstep")]
    mode: Mode,
    /// Seed of every random generator (overrides the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Simulated duration in seconds (overrides the scenario's; > 0).
    #[arg(long, allow_negative_numbers = true, value_parser = super::parse_duration)]
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
    /// Spread the run over the hosts of this file (TOML: `[[host]]` with
    /// `name`, `endpoint` and optional `vehicles`; `[placement] world`),
    /// each running `shoal host`; or over `netns:K`, K hosts made here as
    /// network namespaces that share nothing, each with its agent (root;
    /// OUT/hosts.toml and OUT/agents/ keep the file and the agents' logs).
    /// In realtime every host starts at the run's epoch on its own clock,
    /// corrected by the offset measured from query round trips
    /// (hosts.json gives it).
    #[arg(long, value_name = "FILE|netns:K")]
    hosts: Option<PathBuf>,
    /// With --hosts: reach the hosts over plain TCP (tcp/ endpoints), with
    /// no authentication and no access control. Without it, every link is
    /// QUIC (TLS 1.3) with mutual authentication: quic/ endpoints and a
    /// [tls] section naming the coordinator's certificates (`shoal certs`).
    #[arg(long, requires = "hosts")]
    insecure: bool,
    /// Watch the run while it runs: the recorder serves every channel it
    /// records, as it records it (same topics, schemas and CDR bodies), over
    /// the Foxglove WebSocket protocol on this address (default
    /// 127.0.0.1:8765; loopback unless told otherwise; port 0 picks a free
    /// one, named in logs/run.recorder.log). In Foxglove: Open connection →
    /// Foxglove WebSocket → ws://127.0.0.1:8765. A lockstep run is paced to
    /// real time unless --pace says otherwise. One host only.
    #[arg(
        long,
        value_name = "HOST:PORT",
        num_args = 0..=1,
        default_missing_value = "127.0.0.1:8765"
    )]
    live: Option<String>,
    /// Pace a lockstep run at FACTOR simulated seconds per wall-clock second
    /// (1 = real time, the default with --live; 0 = as fast as the machine
    /// allows, the default otherwise). Realtime and dataflow runs keep the
    /// wall clock's pace.
    #[arg(long, value_name = "FACTOR")]
    pace: Option<f64>,
    /// Run a process kind of some or all vehicles with your own program
    /// instead of shoal's: PROCESS[@VEHICLES]=COMMAND, where PROCESS is
    /// camera-pose, sonar, planner or mpc, VEHICLES is all (the default),
    /// followers, leader or names separated by commas, and COMMAND is split
    /// as a shell splits it; the run's arguments follow it. Repeatable;
    /// after the scenario's `[[replace]]` entries, so it overrides them.
    /// Example: --replace 'planner@followers=python3 examples/python/paper_follower.py'
    #[arg(long, value_name = "PROCESS[@VEHICLES]=COMMAND", value_parser = parse_replace)]
    replace: Vec<shoal_scenario::replace::Replace>,
}

/// Parses one `--replace` (for `shoal run` and `shoal campaign`).
pub fn parse_replace(flag: &str) -> Result<shoal_scenario::replace::Replace, String> {
    shoal_scenario::replace::Replace::parse_flag(flag)
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
    /// Keep idle CPUs polling while the run goes (`/dev/cpu_dma_latency`
    /// held at 0, as cyclictest does; needs root). A wake-up then needs no
    /// interrupt to a halted CPU, which on a virtual machine costs tens of
    /// µs; the idle cores spin in the kernel's idle loop meanwhile.
    #[arg(long)]
    pub idle_poll: bool,
}

impl ProcessArgs {
    /// The settings of runs in `mode`, with a progress bar unless `quiet`.
    pub fn settings(&self, mode: Mode, quiet: bool) -> anyhow::Result<RunSettings> {
        let mut s = RunSettings::new(mode, self.bin_dir.clone(), quiet, self.tick_timeout)?;
        s.idle_poll = self.idle_poll;
        Ok(s)
    }
}

/// Runs the scenario, prints the closing table and the output directory.
pub fn run(cmd: RunCmd) -> anyhow::Result<()> {
    let scenario = preflight::load_scenario_with(&cmd.scenario, |s| {
        if let Some(seed) = cmd.seed {
            s.seed = seed;
        }
        if let Some(d) = cmd.duration {
            s.duration_s = d;
        }
        s.replace.extend(cmd.replace.iter().cloned());
    })?;
    let out = cmd
        .out
        .clone()
        .unwrap_or_else(|| launch::default_out(&scenario));
    let mut settings = cmd.processes.settings(cmd.mode, cmd.quiet)?;
    settings.spin_us = cmd.spin_us;
    settings.pace = pace_of(&cmd)?;
    if let Some(addr) = &cmd.live {
        if cmd.hosts.is_some() {
            anyhow::bail!(
                "--live serves one host's recorder: run without --hosts to watch it live"
            );
        }
        addr.parse::<std::net::SocketAddr>().map_err(|e| {
            anyhow::anyhow!("--live {addr}: not an address such as 127.0.0.1:8765 ({e})")
        })?;
        settings.live = Some(addr.clone());
        if !cmd.quiet {
            eprintln!(
                "live view on ws://{addr} (Foxglove: Open connection, Foxglove WebSocket){}",
                match settings.pace {
                    Some(p) => format!(", paced at {p}x real time"),
                    None => String::new(),
                }
            );
        }
    }
    let local = cmd
        .hosts
        .as_ref()
        .and_then(|p| p.to_str())
        .and_then(crate::hosts::netns::parse_local)
        .transpose()
        .map_err(anyhow::Error::msg)?;
    if cmd.hosts.is_some() && cmd.mode == Mode::Dataflow {
        anyhow::bail!(
            "--mode dataflow runs on one host (its arrival events are iceoryx2's, which the hosts' bridge does not carry): use realtime with --hosts"
        );
    }
    if let (Some(path), None) = (&cmd.hosts, local) {
        let mut file = crate::hosts::HostsFile::load(path)?;
        file.insecure = cmd.insecure;
        // Refused here, before anything starts, if it is not secured (or
        // plainly said insecure), or its certificate is not good.
        if let crate::hosts::tls::Security::Tls(id) = file.security()? {
            id.check()
                .context("the coordinator's certificate ([tls] of the hosts file)")?;
        }
        // Refused here, before anything starts, if it cannot place the group.
        crate::hosts::Placement::new(&file, &scenario)?;
        settings.hosts = Some(file);
    }
    if cmd.force {
        pipeline::clear_outputs(&out)?;
    }
    // netns:K: the hosts are made here and removed when the run is over
    // (the guard first: this thread goes home before the net goes).
    let _local = match local {
        Some(k) => {
            std::fs::create_dir_all(&out)?;
            let bin = launch::bin_dir_or_default(cmd.processes.bin_dir.clone())?;
            let hosts_toml = out.join("hosts.toml");
            let (net, guard) = crate::hosts::netns::local_hosts(
                k,
                &bin,
                &out.join("agents"),
                &hosts_toml,
                cmd.insecure,
            )?;
            let mut file = crate::hosts::HostsFile::load(&hosts_toml)?;
            file.insecure = cmd.insecure;
            crate::hosts::Placement::new(&file, &scenario)?;
            settings.hosts = Some(file);
            Some((guard, net))
        }
        None => None,
    };
    let summary = pipeline::run_and_summarize(scenario, &out, &settings)?.summary;
    if !cmd.quiet {
        print_table(&summary);
    }
    println!("{}", out.display());
    Ok(())
}

/// The pace of a lockstep run: `--pace`, else real time with `--live`;
/// `None` (as fast as the machine allows) for 0 or a wall-clock mode.
fn pace_of(cmd: &RunCmd) -> anyhow::Result<Option<f64>> {
    if let Some(p) = cmd.pace {
        anyhow::ensure!(
            p.is_finite() && p >= 0.0,
            "--pace {p}: a factor >= 0 (1 = real time, 0 = as fast as the machine allows)"
        );
        anyhow::ensure!(
            cmd.mode == Mode::Lockstep || p == 0.0,
            "--pace applies to lockstep runs: a {} run keeps the wall clock's pace",
            cmd.mode.as_str()
        );
    }
    let pace = match (cmd.pace, &cmd.live) {
        (Some(p), _) => p,
        (None, Some(_)) if cmd.mode == Mode::Lockstep => 1.0,
        _ => 0.0,
    };
    Ok((pace > 0.0).then_some(pace))
}

/// The closing table of a run (also `shoal summarize`'s), on stderr.
pub(super) fn print_table(s: &Summary) {
    let f = &s.safety;
    let mark = |ok: bool| if ok { "pass" } else { "FAIL" };
    let na = fmt_or_na;
    eprintln!(
        "  run              {} ({}), {:.1} s simulated in {:.1} s ({:.1}x real time)",
        s.scenario, s.mode, s.sim_time_s, s.wall_time_s, s.real_time_factor
    );
    eprintln!(
        "  collisions       {} between vehicles, {} with obstacles  [{}]",
        f.collisions,
        f.obstacle_contacts.len(),
        mark(f.collisions == 0 && f.obstacle_contacts.is_empty())
    );
    eprintln!(
        "  min pair dist    {} m ({}) vs safe {:.2} m  [{}]",
        na(f.min_pair_distance_m, 2),
        f.min_pair,
        f.safe_distance_m,
        mark(f.min_pair_distance_m.is_none_or(|m| m >= f.safe_distance_m))
    );
    let half = f.safe_distance_m / 2.0;
    eprintln!(
        "  min clearance    {} m to obstacles vs {half:.2} m (half the safe distance){}  [{}]",
        na(f.min_obstacle_clearance_m, 2),
        if f.clearance_below_d_min {
            "; below the planners' D_min"
        } else {
            ""
        },
        mark(f.min_obstacle_clearance_m.is_none_or(|m| m >= half))
    );
    eprintln!(
        "  parent lost      {} follower(s) over {PARENT_LOST_LIMIT_S} s  [{}]",
        s.perception.parent_lost.len(),
        mark(s.perception.parent_lost.is_empty())
    );
    let rms = &s.formation.slot_error_rms_m;
    eprintln!(
        "  slot error rms   before {} m, during {} m, after {} m; last 30 s {} m",
        na(rms.before, 2),
        na(rms.during, 2),
        na(rms.after, 2),
        na(s.formation.slot_error_rms_final_m, 2)
    );
    eprintln!(
        "  recording        {} messages, {} dropped",
        s.recording.messages, s.recording.dropped
    );
    if s.verdict.pass {
        eprintln!("  verdict          pass");
    } else {
        eprintln!("  verdict          FAIL:");
        for line in &s.verdict.failed {
            eprintln!("                   - {line}");
        }
    }
}
