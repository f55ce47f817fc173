//! `shoal run`: spawn the group, drive the clock, stop, reap, clean up.

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use ipc_types::{Clock, Header, RunChannel};
use shoal_runtime::{ChannelLimits, Mode, Publisher};
use shoal_scenario::{ProcessKind, ProcessSpec, Scenario};

use crate::supervisor::{Death, Supervisor};
use crate::sys;

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
    /// for `done`), µs; 0 = block at once.
    pub spin_us: u64,
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
    #[error("process {} ended unexpectedly ({}); last lines of its log:\n{}", .0.label, .0.exit.describe(), .0.log_tail)]
    ChildDied(Death),
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

/// The orchestrator's ports in the run's domain.
/// The orchestrator's ports of a run: the clock, every process's wake event, `done`.
pub(crate) struct Ports {
    pub(crate) node: Node<ipc::Service>,
    pub(crate) clock: Publisher<Clock>,
    pub(crate) done: Listener<ipc::Service>,
    pub(crate) wakes: Vec<Notifier<ipc::Service>>,
    /// Sequence number of the next clock sample.
    clock_seq: u64,
}

impl Ports {
    /// Opens the ports of a run whose processes are `procs`.
    pub(crate) fn open(run_id: &str, procs: &[ProcessSpec]) -> anyhow::Result<Self> {
        let node = shoal_runtime::domain_node(run_id, "run/orchestrator")?;
        let clock = shoal_runtime::node_publisher::<Clock>(
            &node,
            &ipc_types::run_service_name(run_id, RunChannel::Clock),
            &ChannelLimits::clock(procs.len()),
        )?;
        let done = shoal_runtime::open_done(&node, run_id, procs.len())?
            .listener_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("done listener: {e:?}"))?;
        let mut wakes = Vec::with_capacity(procs.len());
        for p in procs {
            let n = shoal_runtime::open_wake(&node, run_id, &p.vehicle, p.kind.name())?
                .notifier_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("wake notifier of {}: {e:?}", p.label()))?;
            wakes.push(n);
        }
        Ok(Self {
            node,
            clock,
            done,
            wakes,
            clock_seq: 0,
        })
    }

    /// Starts lockstep tick `tick` of `ticks` (each `tick_ns` long): publishes
    /// the clock, then wakes the processes in `due` (indices into `procs`).
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
        for &i in due {
            self.wakes[i]
                .notify()
                .map_err(|e| anyhow::anyhow!("wake {}: {e:?}", procs[i].label()))?;
        }
        Ok(())
    }
}

/// Runs a scenario to the end and leaves the recording in `opts.out`.
pub fn run(opts: &RunOptions) -> anyhow::Result<RunOutcome> {
    let scenario = &opts.scenario;
    std::fs::create_dir_all(opts.out.join("logs"))
        .with_context(|| format!("cannot create {}", opts.out.display()))?;
    let scenario_path = opts.out.join("scenario.toml");
    std::fs::write(&scenario_path, scenario.to_toml()?)
        .with_context(|| format!("cannot write {}", scenario_path.display()))?;
    let recording = opts.out.join("recording.mcap");
    let procs = scenario.processes();
    for kind in ProcessKind::ALL {
        let bin = opts.bin_dir.join(kind.binary());
        if !bin.is_file() {
            bail!(
                "service binary {} not found (build with `cargo build --release`, or pass --bin-dir)",
                bin.display()
            );
        }
    }

    if scenario.supervision.policy == shoal_scenario::faults::Policy::Restart {
        bail!(
            "supervision.policy = \"restart\" is not supported yet: a dead process stops the run \
             (policy \"abort\"); nothing was started"
        );
    }
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
    let epoch_margin_ns = 1_000_000_000 + 20_000_000 * procs.len() as u64;
    let epoch = shoal_runtime::mono_ns() + epoch_margin_ns;

    let result = (|| -> anyhow::Result<(f64, u64)> {
        for p in &procs {
            let mut args = vec![
                "--run-id".to_string(),
                run_id.clone(),
                "--vehicle".into(),
                p.vehicle.clone(),
                "--process".into(),
                p.kind.name().into(),
                "--index".into(),
                p.index.to_string(),
                "--processes".into(),
                procs.len().to_string(),
                "--mode".into(),
                opts.mode.as_str().into(),
                "--period-s".into(),
                format!("{}", 1.0 / scenario.rate_hz(p.kind)),
                "--epoch-mono-ns".into(),
                epoch.to_string(),
                "--phase-s".into(),
                format!("{}", p.phase as f64 * scenario.rates.tick_s),
                "--spin-us".into(),
                opts.spin_us.to_string(),
                "--scenario".into(),
                scenario_path.display().to_string(),
            ];
            if p.kind == ProcessKind::Recorder {
                args.push("--out".into());
                args.push(recording.display().to_string());
            }
            let log = opts
                .out
                .join("logs")
                .join(format!("{}.{}.log", p.vehicle, p.kind.name()));
            sup.spawn(p, &opts.bin_dir.join(p.kind.binary()), &args, &log)
                .with_context(|| format!("cannot start {}", p.label()))?;
        }
        // Ready: every process reports once its ports exist.
        let all: Vec<usize> = (0..procs.len()).collect();
        wait_done(
            &mut ports,
            &mut sup,
            &procs,
            &all,
            Duration::from_secs(60).max(opts.tick_timeout),
            0.0,
            Duration::ZERO,
        )?;
        match opts.mode {
            Mode::Lockstep => lockstep(opts, &mut ports, &mut sup, &procs),
            Mode::Realtime => realtime(opts, &mut ports, &mut sup, epoch),
        }
    })();

    // Stop: the recorder first (it finishes the file), then everyone; reap all.
    sup.stop_all(
        |c| c.spec.kind == ProcessKind::Recorder,
        Duration::from_secs(5),
    );
    drop(ports);
    let stats = shoal_runtime::stats::read_stats_files(&run_id);
    shoal_runtime::cleanup_domain(&run_id);

    let (wall_time_s, ticks) = result?;
    let mut cpu_time_s: BTreeMap<String, f64> = BTreeMap::new();
    let mut max_rss_kib: BTreeMap<String, i64> = BTreeMap::new();
    for c in sup.children() {
        let name = c.spec.kind.name().to_string();
        if let Some(e) = c.exit {
            *cpu_time_s.entry(name.clone()).or_default() += e.cpu_s;
            let m = max_rss_kib.entry(name).or_default();
            *m = (*m).max(e.max_rss_kib);
        }
    }
    cpu_time_s.insert("orchestrator".into(), sys::self_cpu_s());
    let failed: Vec<String> = sup
        .children()
        .iter()
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
        events: std::mem::take(&mut sup.events),
    })
}

fn progress_bar(opts: &RunOptions, len: u64) -> indicatif::ProgressBar {
    if !opts.progress || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {bar:40.cyan/blue} {pos:>5}/{len} s simulated ({per_sec}, eta {eta})",
    ) {
        bar.set_style(style);
    }
    bar
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
    let bar = progress_bar(opts, scenario.duration_s.ceil() as u64);
    let start = Instant::now();
    let mut due: Vec<usize> = Vec::with_capacity(procs.len());
    // Kills and stalls, by the tick at which they strike.
    let mut injections: Vec<(u64, &shoal_scenario::faults::Fault)> = scenario
        .faults
        .iter()
        .filter_map(|f| {
            let at = f.at_s?;
            Some(((at / scenario.rates.tick_s).ceil() as u64, f))
        })
        .collect();
    injections.sort_by_key(|(t, _)| *t);
    let mut next_injection = 0;
    for tick in 0..ticks {
        let sim = tick * tick_ns;
        while next_injection < injections.len() && injections[next_injection].0 <= tick {
            inject(injections[next_injection].1, procs, sup, sim);
            next_injection += 1;
        }
        due.clear();
        due.extend(procs.iter().filter(|p| p.due(tick)).map(|p| p.index));
        if due.is_empty() {
            continue;
        }
        ports.start_tick(tick, ticks, tick_ns, &due, procs)?;
        wait_done(
            ports,
            sup,
            procs,
            &due,
            opts.tick_timeout,
            sim as f64 * 1e-9,
            Duration::from_micros(opts.spin_us),
        )?;
        if tick % 50 == 0 {
            bar.set_position((sim as f64 * 1e-9) as u64);
        }
    }
    bar.finish_and_clear();
    Ok((start.elapsed().as_secs_f64(), ticks))
}

/// Strikes a kill or stall fault (scenario `[[faults]]`) at simulation time `sim_ns`.
fn inject(
    fault: &shoal_scenario::faults::Fault,
    procs: &[ProcessSpec],
    sup: &mut Supervisor,
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
    tracing::warn!(process = %spec.label(), action, t_s = sim_ns as f64 * 1e-9, "fault injected");
    sup.events.push(serde_json::json!({
        "t_s": sim_ns as f64 * 1e-9,
        "event": "fault_injected",
        "action": action,
        "process": spec.label(),
        "duration_s": fault.duration_s,
    }));
}

fn realtime(
    opts: &RunOptions,
    ports: &mut Ports,
    sup: &mut Supervisor,
    epoch: u64,
) -> anyhow::Result<(f64, u64)> {
    let scenario = &opts.scenario;
    let end = epoch + (scenario.duration_s * 1e9) as u64;
    let bar = progress_bar(opts, scenario.duration_s.ceil() as u64);
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("waitset: {e:?}"))?;
    let _ = &ports.node;
    let _tick = waitset
        .attach_interval(Duration::from_millis(100))
        .map_err(|e| anyhow::anyhow!("waitset: {e:?}"))?;
    loop {
        let now = shoal_runtime::mono_ns();
        if now >= end {
            break;
        }
        let r = waitset
            .wait_and_process_once_with_timeout(
                |_| CallbackProgression::Continue,
                Duration::from_millis(100),
            )
            .map_err(|e| anyhow::anyhow!("waitset: {e:?}"))?;
        check_signal(r)?;
        if let Some(d) = sup.reap().into_iter().next() {
            sup.events.push(serde_json::json!({
                "t_s": now.saturating_sub(epoch) as f64 * 1e-9,
                "event": "process_died",
                "process": d.label,
                "exit": d.exit.describe(),
                "policy": "abort",
            }));
            return Err(RunError::ChildDied(d).into());
        }
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

/// Waits until every process in `expected` has notified `done`.
/// Waits until every process in `expected` has notified `done`.
pub(crate) fn wait_done(
    ports: &mut Ports,
    sup: &mut Supervisor,
    procs: &[ProcessSpec],
    expected: &[usize],
    timeout: Duration,
    sim_time_s: f64,
    spin: Duration,
) -> anyhow::Result<()> {
    let mut pending = vec![false; procs.len()];
    let mut remaining = 0usize;
    for &i in expected {
        if !pending[i] {
            pending[i] = true;
            remaining += 1;
        }
    }
    let start = Instant::now();
    let slice = Duration::from_millis(50);
    // Adaptive wait: poll first, for at most the spin budget.
    while remaining > 0 && start.elapsed() < spin {
        let _ = ports.done.try_wait(|ev| {
            let id = ev.id.as_value();
            if id < pending.len() && pending[id] {
                pending[id] = false;
                remaining -= 1;
            }
        });
        std::hint::spin_loop();
    }
    while remaining > 0 {
        ports
            .done
            .timed_wait(
                |ev| {
                    let id = ev.id.as_value();
                    if id < pending.len() && pending[id] {
                        pending[id] = false;
                        remaining -= 1;
                    }
                },
                slice,
            )
            .map_err(|e| match e {
                // A signal that lands inside the blocking wait ends it early.
                ListenerWaitError::InterruptSignal => anyhow::Error::from(RunError::Interrupted(
                    termination_requested().unwrap_or("SIGINT"),
                )),
                other => anyhow::anyhow!("waiting for done: {other:?}"),
            })?;
        if remaining == 0 {
            break;
        }
        if let Some(sig) = termination_requested() {
            return Err(RunError::Interrupted(sig).into());
        }
        if let Some(d) = sup.reap().into_iter().next() {
            sup.events.push(serde_json::json!({
                "t_s": sim_time_s,
                "event": "process_died",
                "process": d.label,
                "exit": d.exit.describe(),
                "policy": "abort",
            }));
            return Err(RunError::ChildDied(d).into());
        }
        if start.elapsed() > timeout {
            let waiting = procs
                .iter()
                .filter(|p| pending[p.index])
                .map(|p| p.label())
                .collect();
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
fn termination_requested() -> Option<&'static str> {
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
