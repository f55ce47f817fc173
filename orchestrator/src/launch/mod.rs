//! `shoal run`: spawn the group, drive the clock, stop, reap, clean up.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use ipc_types::{Clock, EventKind, Header, RunChannel};
use shoal_runtime::{ChannelLimits, Mode, Publisher, Rung};
use shoal_scenario::{ProcessKind, ProcessSpec, Scenario};

pub mod os;
pub mod restart;
pub mod settings;
pub mod supervisor;

pub use settings::{bin_dir_or_default, RunSettings};

use os as sys;
use restart::{Happening, Journal, Launch, Recovery};
use supervisor::{Death, Supervisor};

/// Options of one run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// The scenario (overrides applied).
    pub scenario: Scenario,
    /// Output directory.
    pub out: PathBuf,
    /// Lockstep or realtime.
    pub mode: Mode,
    /// Where the service binaries are.
    pub bin_dir: PathBuf,
    /// Show a progress bar (only on a terminal).
    pub progress: bool,
    /// Longest a lockstep tick may take before the run is declared hung, s.
    pub tick_timeout: Duration,
    /// Adaptive wait budget of every process (and of the orchestrator's wait
    /// for a tick's end), µs; 0 = block at once.
    pub spin_us: u64,
    /// Spread the run over these hosts (`shoal run --hosts`); `None`: here.
    pub hosts: Option<crate::hosts::HostsFile>,
    /// Keep idle CPUs polling while the run goes (`--idle-poll`).
    pub idle_poll: bool,
    /// Start every vehicle process with `--no-work` (the runtime's floor:
    /// `shoal bench scale --floor`); the world and the recorder work.
    pub no_work: bool,
    /// Serve a live view on this address: the recorder's Foxglove
    /// WebSocket server (`shoal run --live`).
    pub live: Option<String>,
    /// Pace lockstep ticks at this many simulated seconds per wall-clock
    /// second (`--pace`); `None`: as fast as the machine allows.
    pub pace: Option<f64>,
}

/// What a run produced.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// Run id (names the iceoryx2 domain).
    pub run_id: String,
    /// The recording.
    pub recording: PathBuf,
    /// Wall time of the run proper (first tick to last), s.
    pub wall_time_s: f64,
    /// Simulated time, s.
    pub sim_time_s: f64,
    /// CPU time by process kind, s.
    pub cpu_time_s: BTreeMap<String, f64>,
    /// Peak RSS by process kind, KiB (largest single process).
    pub max_rss_kib: BTreeMap<String, i64>,
    /// Processes spawned.
    pub processes: usize,
    /// Ticks driven (lockstep).
    pub ticks: u64,
    /// Every process's runtime statistics (its exit file).
    pub stats: Vec<shoal_runtime::stats::StatsFile>,
    /// Injected faults and process deaths, in order.
    pub events: Vec<serde_json::Value>,
}

/// Why a run ended early.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A child died while the run needed it.
    #[error("process {} ended unexpectedly at t = {sim_time_s:.2} s ({}); last lines of its log:\n{}", .death.label, .death.exit.describe(), .death.log_tail)]
    ChildDied {
        /// Who died, how, and its log's end.
        death: Death,
        /// Simulated time of the tick it died in, s.
        sim_time_s: f64,
    },
    /// Processes did not finish a step in time.
    #[error(
        "no progress for {timeout_s:.0} s at t = {sim_time_s:.2} s: still waiting for {waiting:?}"
    )]
    Hung {
        /// Timeout, s.
        timeout_s: f64,
        /// Simulation time of the stuck tick.
        sim_time_s: f64,
        /// Who did not report.
        waiting: Vec<String>,
    },
    /// SIGINT or SIGTERM.
    #[error("interrupted by {0}")]
    Interrupted(&'static str),
}

/// The orchestrator's ports of a run: the clock, the lockstep doorbell,
/// `done`, the `events` channel; and what it does when a process dies.
pub(crate) struct Ports {
    pub(crate) node: Node<ipc::Service>,
    pub(crate) clock: Publisher<Clock>,
    pub(crate) done: Listener<ipc::Service>,
    /// The socket `done` wakes up on.
    done_fd: i32,
    /// The lockstep doorbell: how the processes of a tick are woken.
    bell: shoal_runtime::Doorbell,
    /// By process index: true for a process this host runs (it rings only those).
    local: Vec<bool>,
    /// By process index: true for a process whose step a tick's end does
    /// not wait for ([`ProcessKind::detached`]); it must be over before the
    /// process is rung again. All false unless [`Ports::detach`] set them.
    detached: Vec<bool>,
    /// The tick rung last.
    rung: Rung,
    /// Sequence number of the next clock sample.
    clock_seq: u64,
    /// The run's events.
    pub(crate) journal: Journal,
    /// The supervision policy at work (abort unless the run sets another).
    pub(crate) recovery: Recovery,
}

impl Ports {
    /// Opens the ports of a run whose processes are `procs`, all run here.
    pub(crate) fn open(run_id: &str, procs: &[ProcessSpec]) -> anyhow::Result<Self> {
        Self::open_local(run_id, procs, |_| true)
    }

    /// Opens the ports of a run whose processes are `procs`, of which this
    /// host runs those for which `local` holds (it wakes only those).
    pub(crate) fn open_local(
        run_id: &str,
        procs: &[ProcessSpec],
        local: impl Fn(&ProcessSpec) -> bool,
    ) -> anyhow::Result<Self> {
        let node = shoal_runtime::domain_node(run_id, "run/orchestrator")?;
        let clock = shoal_runtime::node_publisher::<Clock, _>(
            &node,
            &ipc_types::run_service_name(run_id, RunChannel::Clock),
            &ChannelLimits::clock(procs.len()),
        )?;
        let done = shoal_runtime::open_done(&node, run_id, procs.len())?
            .listener_builder()
            .create()
            .context("done listener")?;
        let done_fd = shoal_runtime::listener_fd(&done);
        let bell =
            shoal_runtime::Doorbell::create(run_id, procs.len()).context("lockstep doorbell")?;
        // Processes due at the same ticks (same rate and phase) sleep on one
        // gate, so that a tick wakes each such group in one system call.
        // (By position: a replay's one process keeps its index in the run.)
        for (i, p) in procs.iter().enumerate() {
            let leader = procs
                .iter()
                .position(|q| (q.divisor, q.phase) == (p.divisor, p.phase))
                .unwrap_or(i);
            bell.join(i, leader);
        }
        let local = procs.iter().map(local).collect();
        let detached = vec![false; procs.len()];
        let journal = Journal::open(&node, run_id)?;
        Ok(Self {
            node,
            clock,
            done_fd,
            done,
            bell,
            local,
            detached,
            rung: Rung::default(),
            clock_seq: 0,
            journal,
            recovery: Recovery::abort(procs.len()),
        })
    }

    /// Starts lockstep tick `tick` of `ticks` (each `tick_ns` long): publishes
    /// the clock (for outside readers: a process of the run takes its tick
    /// from its doorbell slot), then wakes the processes in `due` (indices
    /// into `procs`).
    pub(crate) fn start_tick(
        &mut self,
        tick: u64,
        ticks: u64,
        tick_ns: u64,
        due: &[usize],
        procs: &[ProcessSpec],
    ) -> anyhow::Result<()> {
        let sim = tick * tick_ns;
        let clock = Clock {
            header: Header {
                seq: self.clock_seq,
                sim_time_ns: sim,
                publish_mono_ns: shoal_runtime::mono_ns(),
                origin_mono_ns: 0,
                origin_sim_time_ns: sim,
            },
            tick,
            tick_ns,
            last: u64::from(tick + 1 == ticks),
        };
        self.clock_seq += 1;
        self.clock.publish_stamped(clock)?;
        self.rung = Rung {
            tick,
            sim_time_ns: sim,
            last: clock.last != 0,
        };
        self.bell
            .arm(due.iter().filter(|&&i| !self.detached[i]).count());
        for &i in due {
            self.ensure_local(i, procs)?;
        }
        self.bell.ring_all(due, self.rung, |i| !self.detached[i]);
        Ok(())
    }

    /// Wakes process `i` (a process of this host) for the tick rung last.
    pub(crate) fn wake(&self, i: usize, procs: &[ProcessSpec]) -> anyhow::Result<()> {
        self.ensure_local(i, procs)?;
        self.bell.ring(i, self.rung, !self.detached[i]);
        Ok(())
    }

    /// Fails unless process `i` runs on this host (only those have a
    /// doorbell slot here).
    fn ensure_local(&self, i: usize, procs: &[ProcessSpec]) -> anyhow::Result<()> {
        if !self.local.get(i).copied().unwrap_or(false) {
            anyhow::bail!("{} does not run on this host", procs[i].label());
        }
        Ok(())
    }

    /// Lets the ticks' ends not wait for the steps of `procs`' detached
    /// kinds (a whole run on one host; see [`ProcessKind::detached`]).
    pub(crate) fn detach(&mut self, procs: &[ProcessSpec]) {
        for p in procs {
            self.detached[p.index] = p.kind.detached();
        }
    }

    /// True when `i` is detached and was rung for a step it has not
    /// finished (a restarted one never will, until it is rung again).
    fn owes(&self, i: usize) -> bool {
        self.detached[i] && !self.bell.is_done(i)
    }

    /// Waits until no detached process among `among` owes a step. What
    /// happens meanwhile (a death) is dated at the earliest step owed.
    fn settle_detached(
        &mut self,
        sup: &mut Supervisor,
        procs: &[ProcessSpec],
        among: impl IntoIterator<Item = usize>,
        opts: &RunOptions,
    ) -> anyhow::Result<()> {
        let owed: Vec<usize> = among.into_iter().filter(|&i| self.owes(i)).collect();
        let Some(tick) = owed.iter().map(|&i| self.bell.tick(i)).min() else {
            return Ok(());
        };
        let sim_time_s = tick as f64 * opts.scenario.rates.tick_s;
        wait_done(
            self,
            sup,
            procs,
            &owed,
            opts.tick_timeout,
            sim_time_s,
            Duration::from_micros(opts.spin_us),
        )
    }
}

/// Fails, naming it, on a service binary that `bin_dir` lacks or a
/// replacing command (`[[replace]]`) whose program cannot be found, before
/// anything starts; `host` names the host in a run over hosts.
pub(crate) fn check_programs(
    bin_dir: &Path,
    scenario: &Scenario,
    host: Option<&str>,
) -> anyhow::Result<()> {
    let on = host.map(|h| format!(" on host {h}")).unwrap_or_default();
    for kind in ProcessKind::ALL {
        let bin = bin_dir.join(kind.binary());
        if !bin.is_file() {
            bail!(
                "service binary {} not found{on} (build with `cargo build --release`, or pass --bin-dir)",
                bin.display()
            );
        }
    }
    for r in &scenario.replace {
        let program = &r.command[0];
        if sys::find_program(program).is_none() {
            bail!(
                "the command that replaces {} ({}) names a program that cannot be found{on}: `{program}`",
                r.process.name(),
                r.command.join(" ")
            );
        }
    }
    Ok(())
}

/// With `on`, keeps idle CPUs polling until the returned guard drops
/// (`--idle-poll`); an error names what stopped it.
pub fn idle_poll_guard(on: bool) -> anyhow::Result<Option<std::fs::File>> {
    if !on {
        return Ok(None);
    }
    sys::hold_cpu_latency()
        .map(Some)
        .context("--idle-poll: cannot write /dev/cpu_dma_latency (it needs root)")
}

/// Runs a scenario to the end and leaves the recording in `opts.out`.
pub fn run(opts: &RunOptions) -> anyhow::Result<RunOutcome> {
    // Held until the run returns: idle CPUs poll instead of halting.
    let _idle_poll = idle_poll_guard(opts.idle_poll)?;
    if let Some(hosts) = &opts.hosts {
        return crate::hosts::coordinator::run(opts, hosts);
    }
    let scenario = &opts.scenario;
    std::fs::create_dir_all(opts.out.join("logs"))
        .with_context(|| format!("cannot create {}", opts.out.display()))?;
    let scenario_path = opts.out.join("scenario.toml");
    std::fs::write(&scenario_path, scenario.to_toml()?)
        .with_context(|| format!("cannot write {}", scenario_path.display()))?;
    let recording = opts.out.join("recording.mcap");
    let procs = scenario.processes();
    check_programs(&opts.bin_dir, scenario, None)?;

    // A run that died (SIGKILL, power loss) left its domain behind: remove it.
    for (dead, files) in shoal_runtime::sweep_stale_domains() {
        tracing::warn!(run = %dead, files, "removed the shared memory of a dead run");
    }
    let run_id = sys::random_id();
    shoal_runtime::domain::claim_domain(&run_id, std::process::id())
        .context("cannot create the run's domain directory")?;
    // Written first, so tools and tests can find the live run's domain.
    let run_json = serde_json::json!({
        "run_id": run_id,
        "pid": std::process::id(),
        "domain_prefix": shoal_runtime::domain::domain_prefix(&run_id),
        "domain_root": shoal_runtime::domain::domain_root(&run_id),
        "mode": opts.mode.as_str(),
    });
    std::fs::write(
        opts.out.join("run.json"),
        serde_json::to_string_pretty(&run_json)?,
    )?;
    let mut ports = Ports::open(&run_id, &procs)?;
    let mut sup = Supervisor::default();
    let epoch = shoal_runtime::mono_ns() + epoch_margin_ns(procs.len());
    let launch = Launch {
        bin_dir: opts.bin_dir.clone(),
        out: opts.out.clone(),
        run_id: run_id.clone(),
        processes: procs.len(),
        mode: opts.mode,
        epoch_mono_ns: epoch,
        spin_us: opts.spin_us,
        no_work: opts.no_work,
        live: opts.live.clone(),
        scenario_path: scenario_path.clone(),
        scenario: scenario.clone(),
        scope: None,
    };
    let effective = launch.effective_scenario();
    std::fs::write(&effective, crate::preflight::effective_toml(scenario)?)
        .with_context(|| format!("cannot write {}", effective.display()))?;

    let result = (|| -> anyhow::Result<(f64, u64)> {
        ports.recovery = Recovery::for_run(&ports.node, &procs, launch.clone())?;
        for p in &procs {
            sup.spawn(
                p,
                &launch.binary(p),
                &launch.args(p, 0, None),
                &launch.log(p),
                0,
            )
            .with_context(|| format!("cannot start {}", p.label()))?;
        }
        // Ready: every process reports once its ports exist.
        let all: Vec<usize> = (0..procs.len()).collect();
        wait_ready(
            &mut ports,
            &mut sup,
            &procs,
            &all,
            Duration::from_secs(60).max(opts.tick_timeout),
        )?;
        match opts.mode {
            Mode::Lockstep => lockstep(opts, &mut ports, &mut sup, &procs),
            Mode::Realtime | Mode::Dataflow => realtime(opts, &mut ports, &mut sup, &procs, epoch),
        }
    })();

    // Stop: the recorder first (it finishes the file), then everyone; reap all.
    sup.stop_all(
        |c| c.spec.kind == ProcessKind::Recorder,
        Duration::from_secs(5),
    );
    let events = std::mem::take(&mut ports.journal.list);
    let parts = std::mem::take(&mut ports.recovery.recording_parts);
    drop(ports);
    let stats = shoal_runtime::stats::read_stats_files(&run_id);
    if let shoal_runtime::Release::LeftTo(nodes) = shoal_runtime::release_domain(&run_id) {
        tracing::info!(
            "{} outside node(s) still use run {run_id}'s services ({}): they end cleanly when they leave, and the next run removes what remains",
            nodes.len(),
            nodes.join(", ")
        );
    }
    // A restarted recorder wrote the rest of the run into new files: join them.
    let joined = if parts.is_empty() {
        Ok(())
    } else {
        join_recordings(&recording, &parts)
    };

    let (wall_time_s, ticks) = result?;
    joined?;
    let (mut cpu_time_s, max_rss_kib) = usage_by_kind(&child_usage(&sup), &stats);
    cpu_time_s.insert("orchestrator".into(), sys::self_cpu_s());
    let failed: Vec<String> = sup
        .latest()
        .filter(|c| c.spec.kind == ProcessKind::Recorder && !c.exit.is_some_and(|e| e.success()))
        .map(|c| {
            format!(
                "{} ({})",
                c.spec.label(),
                c.exit.map(|e| e.describe()).unwrap_or_default()
            )
        })
        .collect();
    if !failed.is_empty() {
        bail!(
            "the recorder did not finish cleanly: {failed:?}; see {}/logs",
            opts.out.display()
        );
    }
    Ok(RunOutcome {
        run_id,
        recording,
        wall_time_s,
        sim_time_s: ticks as f64 * scenario.rates.tick_s,
        cpu_time_s,
        max_rss_kib,
        processes: procs.len(),
        ticks,
        stats,
        events,
    })
}

/// What one reaped process used: its kind, CPU time and peak RSS.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProcessUsage {
    /// Process kind (`sim-plant`, ...).
    pub kind: String,
    /// User + system CPU time, s.
    pub cpu_s: f64,
    /// Peak RSS as `wait4` counts it, KiB.
    pub max_rss_kib: i64,
}

/// The usage of every child `sup` has reaped.
pub(crate) fn child_usage(sup: &Supervisor) -> Vec<ProcessUsage> {
    sup.children()
        .iter()
        .filter_map(|c| {
            c.exit.map(|e| ProcessUsage {
                kind: c.spec.kind.name().to_string(),
                cpu_s: e.cpu_s,
                max_rss_kib: e.max_rss_kib,
            })
        })
        .collect()
}

/// CPU time summed and peak RSS (largest single process) by process kind.
/// A process's own peak (its exit file) replaces `wait4`'s where it wrote
/// one: `wait4`'s counts the orchestrator's pages a child holds between
/// fork and exec.
pub(crate) fn usage_by_kind(
    usage: &[ProcessUsage],
    stats: &[shoal_runtime::stats::StatsFile],
) -> (BTreeMap<String, f64>, BTreeMap<String, i64>) {
    let mut cpu_time_s: BTreeMap<String, f64> = BTreeMap::new();
    let mut max_rss_kib: BTreeMap<String, i64> = BTreeMap::new();
    for u in usage {
        *cpu_time_s.entry(u.kind.clone()).or_default() += u.cpu_s;
        let m = max_rss_kib.entry(u.kind.clone()).or_default();
        *m = (*m).max(u.max_rss_kib);
    }
    let mut own_peak: BTreeMap<String, i64> = BTreeMap::new();
    for f in stats {
        if let Some(k) = f.peak_rss_kib.and_then(|k| i64::try_from(k).ok()) {
            let m = own_peak.entry(f.process.clone()).or_default();
            *m = (*m).max(k);
        }
    }
    max_rss_kib.extend(own_peak);
    (cpu_time_s, max_rss_kib)
}

/// Joins the first recording and those of restarted recorders (`parts`, in
/// order) into `recording`; the parts are removed once the joined file has
/// been read back whole.
pub(crate) fn join_recordings(recording: &Path, parts: &[PathBuf]) -> anyhow::Result<()> {
    let mut inputs: Vec<&Path> = vec![recording];
    inputs.extend(parts.iter().map(PathBuf::as_path).filter(|p| p.is_file()));
    let joined = recording.with_extension("joined.mcap");
    let _ = std::fs::remove_file(&joined);
    let report = recordings::merge(&inputs, &joined)
        .with_context(|| format!("cannot join the recordings {inputs:?}"))?;
    std::fs::rename(&joined, recording)
        .with_context(|| format!("cannot move {} into place", joined.display()))?;
    for p in parts {
        let _ = std::fs::remove_file(p);
    }
    tracing::info!(
        parts = inputs.len(),
        messages = report.messages,
        dropped_bytes = report.dropped_bytes,
        "joined the recordings of a restarted recorder"
    );
    Ok(())
}

fn lockstep(
    opts: &RunOptions,
    ports: &mut Ports,
    sup: &mut Supervisor,
    procs: &[ProcessSpec],
) -> anyhow::Result<(f64, u64)> {
    let scenario = &opts.scenario;
    let ticks = scenario.ticks();
    let tick_ns = (scenario.rates.tick_s * 1e9).round() as u64;
    let bar = crate::progress::bar(
        opts.progress,
        scenario.duration_s.ceil() as u64,
        "s simulated",
    );
    let start = Instant::now();
    let mut due: Vec<usize> = Vec::with_capacity(procs.len());
    let mut awaited: Vec<usize> = Vec::with_capacity(procs.len());
    let injections = injections(scenario);
    let mut next_injection = 0;
    ports.detach(procs);
    for tick in 0..ticks {
        let sim = tick * tick_ns;
        let sim_s = sim as f64 / 1e9;
        if next_injection < injections.len() && injections[next_injection].0 <= tick {
            // A fault strikes a process between its steps, detached or not.
            ports.settle_detached(sup, procs, 0..procs.len(), opts)?;
        }
        while next_injection < injections.len() && injections[next_injection].0 <= tick {
            inject(
                injections[next_injection].1,
                procs,
                sup,
                &mut ports.journal,
                sim,
            );
            next_injection += 1;
        }
        due.clear();
        due.extend(procs.iter().filter(|p| p.due(tick)).map(|p| p.index));
        if due.is_empty() {
            continue;
        }
        // A detached process's last step must be over before its next.
        ports.settle_detached(sup, procs, due.iter().copied(), opts)?;
        if let Some(pace) = opts.pace {
            // Paced (a live view): no tick before its simulated time, scaled.
            let due_at = start + Duration::from_secs_f64(sim_s / pace);
            if let Some(wait) = due_at.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        ports.start_tick(tick, ticks, tick_ns, &due, procs)?;
        awaited.clear();
        awaited.extend(due.iter().copied().filter(|&i| !ports.detached[i]));
        wait_done(
            ports,
            sup,
            procs,
            &awaited,
            opts.tick_timeout,
            sim_s,
            Duration::from_micros(opts.spin_us),
        )?;
        ports.recovery.track_truths();
        if tick % 50 == 0 {
            bar.set_position((sim as f64 * 1e-9) as u64);
        }
    }
    // The run's steps are over when the detached ones are too.
    ports.settle_detached(sup, procs, 0..procs.len(), opts)?;
    bar.finish_and_clear();
    Ok((start.elapsed().as_secs_f64(), ticks))
}

/// The scenario's kills and stalls, by the tick at which they strike.
pub(crate) fn injections(scenario: &Scenario) -> Vec<(u64, &shoal_scenario::faults::Fault)> {
    let mut injections: Vec<(u64, &shoal_scenario::faults::Fault)> = scenario
        .faults
        .iter()
        .filter_map(|f| {
            let at = f.at_s?;
            Some(((at / scenario.rates.tick_s).ceil() as u64, f))
        })
        .collect();
    injections.sort_by_key(|(t, _)| *t);
    injections
}

/// Strikes a kill or stall fault (scenario `[[faults]]`) at simulation time `sim_ns`.
pub(crate) fn inject(
    fault: &shoal_scenario::faults::Fault,
    procs: &[ProcessSpec],
    sup: &mut Supervisor,
    journal: &mut Journal,
    sim_ns: u64,
) {
    use shoal_scenario::faults::FaultAction;
    let Some(kind) = fault.process_kind() else {
        return;
    };
    let Some(spec) = procs
        .iter()
        .find(|p| p.kind == kind && p.vehicle == fault.vehicle)
    else {
        return;
    };
    let Some(pid) = sup.pid_of(spec.index) else {
        return;
    };
    let action = match fault.action {
        FaultAction::Kill => {
            sys::send_signal(pid, libc::SIGKILL);
            "kill"
        }
        FaultAction::Stall => {
            let d = Duration::from_secs_f64(fault.duration_s.unwrap_or(0.0).max(0.0));
            sys::send_signal(pid, libc::SIGSTOP);
            sup.signal_later(pid, libc::SIGCONT, d);
            "stall"
        }
        FaultAction::Drop | FaultAction::Blind => return,
    };
    tracing::warn!(process = %spec.label(), action, t_s = sim_ns as f64 / 1e9, "fault injected");
    let mut h = Happening::new(EventKind::FaultInjected, sim_ns as f64 / 1e9, Some(spec));
    h.duration_s = fault.duration_s.unwrap_or(0.0);
    h.detail = action.to_string();
    journal.emit(
        h,
        serde_json::json!({ "action": action, "duration_s": fault.duration_s }),
    );
}

/// How far ahead a realtime run's epoch lies: time for `processes` to start.
pub(crate) fn epoch_margin_ns(processes: usize) -> u64 {
    1_000_000_000 + 20_000_000 * processes as u64
}

fn realtime(
    opts: &RunOptions,
    ports: &mut Ports,
    sup: &mut Supervisor,
    procs: &[ProcessSpec],
    epoch: u64,
) -> anyhow::Result<(f64, u64)> {
    let scenario = &opts.scenario;
    let end = epoch + (scenario.duration_s * 1e9) as u64;
    let bar = crate::progress::bar(
        opts.progress,
        scenario.duration_s.ceil() as u64,
        "s simulated",
    );
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .context("waitset")?;
    let _ = &ports.node;
    let _tick = waitset
        .attach_interval(Duration::from_millis(100))
        .context("waitset")?;
    // Kills and stalls strike on the wall clock, within this loop's 100 ms.
    let injections = injections(scenario);
    let mut next_injection = 0;
    loop {
        let now = shoal_runtime::mono_ns();
        if now >= end {
            break;
        }
        let sim = now.saturating_sub(epoch);
        while let Some((_, fault)) = injections
            .get(next_injection)
            .filter(|(_, f)| f.at_s.is_some_and(|at| at * 1e9 <= sim as f64))
        {
            inject(fault, procs, sup, &mut ports.journal, sim);
            next_injection += 1;
        }
        let r = waitset
            .wait_and_process_once_with_timeout(
                |_| CallbackProgression::Continue,
                Duration::from_millis(100),
            )
            .context("waitset")?;
        check_signal(r)?;
        let t_s = now.saturating_sub(epoch) as f64 * 1e-9;
        ports.keep_realtime(procs, sup, t_s)?;
        if now > epoch {
            bar.set_position((now - epoch) / 1_000_000_000);
        }
    }
    bar.finish_and_clear();
    Ok((
        (end - epoch) as f64 * 1e-9,
        (scenario.duration_s / scenario.rates.tick_s).round() as u64,
    ))
}

fn check_signal(r: WaitSetRunResult) -> Result<(), RunError> {
    match r {
        WaitSetRunResult::Interrupt => Err(RunError::Interrupted("SIGINT")),
        WaitSetRunResult::TerminationRequest => Err(RunError::Interrupted("SIGTERM")),
        _ => Ok(()),
    }
}

/// What [`wait_done`] has heard: finished steps and ready reports.
struct Tally {
    n: usize,
    pending: Vec<bool>,
    remaining: usize,
    ready: Vec<usize>,
}

impl Tally {
    /// An event on `done`: ready ids follow the process indices (finished
    /// steps are read from the doorbell, whose done counter wakes the wait).
    fn on(&mut self, id: usize) {
        if let Some(i) = id.checked_sub(self.n).filter(|i| *i < self.n) {
            self.ready.push(i);
        }
    }

    /// Process `i` has finished its step.
    fn settle(&mut self, i: usize) {
        if self.pending[i] {
            self.pending[i] = false;
            self.remaining -= 1;
        }
    }

    /// Settles every pending process of `expected` (the tick's) whose
    /// doorbell slot says it finished.
    fn read(&mut self, bell: &shoal_runtime::Doorbell, expected: &[usize]) {
        if self.remaining == 0 {
            return;
        }
        for &i in expected {
            if self.pending[i] && bell.is_done(i) {
                self.settle(i);
            }
        }
    }
}

impl Ports {
    /// What a realtime loop does between its waits, at time `t_s` of the
    /// run: truths kept for a restart, deaths handled by the supervision
    /// policy, restarted processes' ready reports taken (they run on their
    /// own clock).
    pub(crate) fn keep_realtime(
        &mut self,
        procs: &[ProcessSpec],
        sup: &mut Supervisor,
        t_s: f64,
    ) -> anyhow::Result<()> {
        self.recovery.track_truths();
        for d in sup.reap() {
            self.handle_death(d, procs, sup, t_s)?;
        }
        let n = procs.len();
        let mut ready = Vec::new();
        let _ = self.done.try_wait(|ev| {
            if let Some(i) = ev.id.as_value().checked_sub(n).filter(|i| *i < n) {
                ready.push(i);
            }
        });
        for i in ready {
            self.recovery.ready(i, procs, &mut self.journal, t_s);
        }
        Ok(())
    }

    /// A process died at simulated time `t_s`: the supervision policy
    /// restarts it, or the run stops with the cause.
    pub(crate) fn handle_death(
        &mut self,
        d: Death,
        procs: &[ProcessSpec],
        sup: &mut Supervisor,
        t_s: f64,
    ) -> Result<(), RunError> {
        self.recovery
            .on_death(d, procs, sup, &self.node, &mut self.journal, t_s)
            .map_err(|death| RunError::ChildDied {
                death,
                sim_time_s: t_s,
            })
    }
}

/// Waits until every process in `expected` has reported ready (its ports
/// exist), for at most `timeout`.
pub(crate) fn wait_ready(
    ports: &mut Ports,
    sup: &mut Supervisor,
    procs: &[ProcessSpec],
    expected: &[usize],
    timeout: Duration,
) -> anyhow::Result<()> {
    for &i in expected {
        ports.recovery.await_ready(i, timeout);
    }
    wait_done(ports, sup, procs, &[], timeout, 0.0, Duration::ZERO)
}

/// Waits until every process in `expected` has finished its step of the tick
/// at `sim_time_s`, and every restarted process has reported ready.
///
/// A process that dies meanwhile is handled by the run's policy: with
/// `restart` it is started again, and when it reports ready it is woken to
/// take the step it owes (never before: a wake-up sent to a process whose
/// ports do not exist yet would be lost, one sent to a process that is
/// still starting would make it step twice).
pub(crate) fn wait_done(
    ports: &mut Ports,
    sup: &mut Supervisor,
    procs: &[ProcessSpec],
    expected: &[usize],
    timeout: Duration,
    sim_time_s: f64,
    spin: Duration,
) -> anyhow::Result<()> {
    let n = procs.len();
    let mut t = Tally {
        n,
        pending: vec![false; n],
        remaining: 0,
        ready: Vec::new(),
    };
    for &i in expected {
        if !t.pending[i] {
            t.pending[i] = true;
            t.remaining += 1;
        }
    }
    // Read once per tick here: a tick's end wakes this wait only once, when
    // every process has finished, and the loop below may end before its own
    // reading of the flag.
    if let Some(sig) = termination_requested() {
        return Err(RunError::Interrupted(sig).into());
    }
    let mut start = Instant::now();
    let slice = Duration::from_millis(50);
    // Adaptive wait: poll first, for at most the spin budget.
    while t.remaining > 0 && start.elapsed() < spin {
        t.read(&ports.bell, expected);
        std::hint::spin_loop();
    }
    loop {
        // A restarted process that is ready takes the step it owes.
        for i in std::mem::take(&mut t.ready) {
            // (A detached one owes it even when this wait is not for it.)
            if ports
                .recovery
                .ready(i, procs, &mut ports.journal, sim_time_s)
                && (t.pending[i] || ports.owes(i))
            {
                // Its slot gets the tick in progress with the wake-up.
                ports.wake(i, procs)?;
            }
        }
        if t.remaining == 0 && !ports.recovery.any_awaiting() {
            break;
        }
        let woken = if ports.recovery.any_awaiting() {
            // A restarted process says it is ready on `done`: poll(2) on the
            // listener's socket, then a non-blocking take (three system
            // calls where iceoryx2's timed_wait makes seven: it toggles the
            // socket's blocking mode and its timeout on every call).
            let readable = sys::wait_readable(ports.done_fd, slice).context("waiting for ready")?;
            ports
                .done
                .try_wait(|ev| t.on(ev.id.as_value()))
                .context("taking ready")?;
            readable
        } else {
            // Finished steps: done's counter is read before the slots, so a
            // notification after the reading ends the futex wait at once.
            let seen = ports.bell.done_seq();
            t.read(&ports.bell, expected);
            t.remaining == 0 || ports.bell.wait_done(seen, slice)
        };
        t.read(&ports.bell, expected);
        if t.remaining == 0 && t.ready.is_empty() && !ports.recovery.any_awaiting() {
            break;
        }
        if let Some(sig) = termination_requested() {
            return Err(RunError::Interrupted(sig).into());
        }
        // A process that died sends no done: the wait runs out (or a
        // signal cuts it short) before a death matters, so reap only then,
        // not after every done.
        let deaths = if woken {
            sup.send_due_signals();
            Vec::new()
        } else {
            sup.reap()
        };
        for d in deaths {
            ports.handle_death(d, procs, sup, sim_time_s)?;
            // The tick starts over for the restarted process.
            start = Instant::now();
        }
        let overdue = ports.recovery.overdue(procs);
        if !overdue.is_empty() || start.elapsed() > timeout {
            let waiting: Vec<String> = if overdue.is_empty() {
                procs
                    .iter()
                    .filter(|p| t.pending[p.index])
                    .map(|p| p.label())
                    .collect()
            } else {
                overdue
            };
            let mut h = Happening::new(EventKind::RunAborted, sim_time_s, None);
            h.detail = format!("no progress: still waiting for {waiting:?}");
            ports.journal.emit(h, serde_json::json!({}));
            return Err(RunError::Hung {
                timeout_s: timeout.as_secs_f64(),
                sim_time_s,
                waiting,
            }
            .into());
        }
    }
    Ok(())
}

/// SIGINT/SIGTERM received by the orchestrator (iceoryx2 installs the
/// handler when the orchestrator's node is created).
pub(crate) fn termination_requested() -> Option<&'static str> {
    use iceoryx2_bb_posix::signal::{NonFatalFetchableSignal, SignalHandler};
    match SignalHandler::last_signal() {
        Some(NonFatalFetchableSignal::Interrupt) => Some("SIGINT"),
        Some(NonFatalFetchableSignal::Terminate) => Some("SIGTERM"),
        _ => None,
    }
}

/// The default output directory: `runs/<scenario>-<local time>`.
pub fn default_out(scenario: &Scenario) -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    Path::new("runs").join(format!("{}-{secs}", scenario.name))
}
