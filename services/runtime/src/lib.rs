//! The one service loop every shoal process runs: an iceoryx2 node in the
//! run's own domain, typed ports with explicit service limits, the lockstep
//! clock and the realtime timer, header stamping, and a clean exit on
//! SIGINT/SIGTERM.
//!
//! A service is a [`Task`]: it opens its ports in its constructor through the
//! [`Runtime`], then [`Runtime::run`] calls [`Task::step`] once per wake-up:
//!
//! - **lockstep**: the orchestrator rings the process's counter of the
//!   run's [`Doorbell`] (a futex in shared memory) on the ticks where it is
//!   due, its slot holding the tick ([`Rung`]); the
//!   process steps on the samples stamped *before* this tick (later ones are
//!   held back for the next step, so the result does not depend on who ran
//!   first), then marks its step finished in its doorbell slot; the last
//!   process of the tick to finish wakes the orchestrator through the
//!   doorbell's done counter (the `done` event says only that a process is
//!   ready).
//! - **realtime**: the process wakes on its own interval on the wall clock;
//!   a wake-up later than one period is a deadline miss.
//!
//! Processes never busy-poll: in lockstep they block in futex(2) on their
//! doorbell counter, otherwise in ppoll(2) on their iceoryx2 event
//! listeners' sockets.
//!
//! ```no_run
//! use shoal_runtime::{Runtime, RunArgs, Task, StepContext, TaskError};
//! struct Idle;
//! impl Task for Idle {
//!     fn step(&mut self, _ctx: &StepContext) -> Result<(), TaskError> { Ok(()) }
//! }
//! # fn main() -> anyhow::Result<()> {
//! let args = RunArgs { run_id: "test".into(), vehicle: "L".into(), process: "idle".into(),
//!     index: 0, mode: shoal_runtime::Mode::Lockstep, period_s: 0.1, epoch_mono_ns: 0,
//!     processes: 1, phase_s: 0.0, spin_us: 0, restart: 0, resume: None,
//!     no_work: false };
//! let rt = Runtime::new(&args)?;
//! rt.run(Idle)?;
//! # Ok(()) }
//! ```

pub mod convert;
pub mod domain;
pub mod doorbell;
pub mod latency;
pub mod ports;
pub mod python;
pub mod stamp;
pub mod stats;
pub mod world;

use std::time::Duration;

use iceoryx2::prelude::*;
pub use iceoryx2::service::{ipc, local, Service};
use iceoryx2_bb_posix::signal::SignalHandler;
use ipc_types::RunChannel;

pub use domain::{
    alive_nodes, cleanup_domain, iceoryx_config, list_domain_files, release_domain, stale_domains,
    sweep_stale_domains, ChannelLimits, Release, EVENTS_HISTORY,
};
pub use doorbell::{Doorbell, Rung};
pub use latency::LatencyRecorder;
pub use ports::{Publisher, Subscriber};
pub use stamp::stamp_ns;
pub use world::WorldView;

/// How time advances in a run.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// The orchestrator ticks a clock and waits for every due process.
    Lockstep,
    /// Each process runs at its own rate on the wall clock, on phased timers.
    Realtime,
    /// On the wall clock, driven by data: the plant and the run-level
    /// processes keep their timers; every other stage steps when a new
    /// sample has arrived on each of its trigger inputs
    /// ([`Runtime::wake_on`]), and its phased timer becomes its deadline.
    Dataflow,
}

impl Mode {
    /// Lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Lockstep => "lockstep",
            Mode::Realtime => "realtime",
            Mode::Dataflow => "dataflow",
        }
    }

    /// True when time is the wall clock's (realtime and dataflow).
    pub fn wall_clock(self) -> bool {
        self != Mode::Lockstep
    }
}

/// The arguments every service process is started with (the orchestrator
/// passes them; see `shoal run`).
#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    /// Run identifier: names the iceoryx2 domain and every service.
    #[arg(long)]
    pub run_id: String,
    /// Vehicle this process belongs to (`run` for run-level processes).
    #[arg(long)]
    pub vehicle: String,
    /// Process kind (sim-plant, camera-pose, ...).
    #[arg(long)]
    pub process: String,
    /// This process's index in the run (its doorbell slot and `done` event id).
    #[arg(long)]
    pub index: usize,
    /// Number of processes in the run (sizes the `done` event service).
    #[arg(long)]
    pub processes: usize,
    /// Lockstep or realtime.
    #[arg(long, value_enum, default_value = "lockstep")]
    pub mode: Mode,
    /// Step period in seconds (realtime wake-up interval).
    #[arg(long, default_value_t = 0.1)]
    pub period_s: f64,
    /// Monotonic time (ns) at which simulated time 0 starts, realtime only.
    #[arg(long, default_value_t = 0)]
    pub epoch_mono_ns: u64,
    /// Offset of this process's activations within its period, s (realtime:
    /// the pipeline plant → world → sensors → planner → mpc is phased like
    /// a lockstep frame, so a chain does not wait a whole period per hop).
    #[arg(long, default_value_t = 0.0)]
    pub phase_s: f64,
    /// Adaptive wait: after a step, poll for the next wake-up this long
    /// before blocking, µs (0 = always block). Only worth it with spare cores.
    #[arg(long, default_value_t = 0)]
    pub spin_us: u64,
    /// How many times the orchestrator has restarted this process (0 at the
    /// start of the run). A restarted process joins a run in progress: in
    /// realtime it starts at its next activation instead of counting the
    /// ones before it as missed.
    #[arg(long, default_value_t = 0)]
    pub restart: u32,
    /// State handed over by the orchestrator to a restarted process (a file
    /// whose meaning is the service's: sim-plant takes its vehicle's last
    /// `truth` sample).
    #[arg(long)]
    pub resume: Option<std::path::PathBuf>,
    /// Take part in the run's schedule without doing the service's work:
    /// no task and no port of its own, every step returns at once
    /// ([`Runtime::serve`]). What is left is the runtime's own cost per
    /// step (wake, done, statistics); `shoal bench scale --floor` runs a
    /// group so.
    #[arg(long)]
    pub no_work: bool,
}

/// An error of iceoryx2 (each operation has its own type), kept whole as
/// the source of a [`RuntimeError`].
pub type IoxError = Box<dyn std::error::Error + Send + Sync>;

/// Errors of the runtime: one variant per operation, naming what it was
/// done on, with iceoryx2's error as the source.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// The iceoryx2 node could not be created.
    #[error("cannot create the iceoryx2 node `{name}`")]
    Node {
        /// Node name.
        name: String,
        /// Cause.
        #[source]
        source: IoxError,
    },
    /// A service could not be opened or created.
    #[error("cannot open service `{service}`")]
    Service {
        /// Service name.
        service: String,
        /// Cause.
        #[source]
        source: IoxError,
    },
    /// A port could not be created.
    #[error("cannot create a port on `{service}`")]
    Port {
        /// Service name.
        service: String,
        /// Cause.
        #[source]
        source: IoxError,
    },
    /// Sending or receiving failed.
    #[error("i/o on `{service}` failed")]
    Io {
        /// Service name.
        service: String,
        /// Cause.
        #[source]
        source: IoxError,
    },
    /// A sample with a NaN or infinite value (or, for a type that checks
    /// its ranges, a value out of range) was not published.
    #[error("refused to publish a sample with a non-finite or out-of-range value on `{service}`")]
    NonFinite {
        /// Service name.
        service: String,
    },
    /// The wait set could not be built or waiting failed.
    #[error("waiting for the next wake-up failed")]
    Wait(#[source] IoxError),
    /// The task's step failed.
    #[error("step at t = {sim_time_s:.3} s failed")]
    Task {
        /// Simulation time of the failing step.
        sim_time_s: f64,
        /// The task's error.
        #[source]
        source: TaskError,
    },
}

/// Why a task's step (or its finish) failed; the process exits with it.
#[derive(Debug, thiserror::Error)]
pub enum TaskError {
    /// One of its ports failed.
    #[error("a port failed")]
    Port(#[source] Box<RuntimeError>),
    /// Its library refused the inputs or could not compute: `what` names
    /// the operation (`planner step`, `recording write`).
    #[error("{what} failed")]
    Failed {
        /// The operation.
        what: &'static str,
        /// The library's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// An input it cannot work with.
    #[error("{input}: {reason}")]
    BadInput {
        /// The input (channel or field).
        input: &'static str,
        /// What is wrong with it.
        reason: String,
    },
}

impl TaskError {
    /// `map_err(TaskError::failed("planner step"))`: wraps a library error
    /// as the failure of operation `what`.
    pub fn failed<E: std::error::Error + Send + Sync + 'static>(
        what: &'static str,
    ) -> impl FnOnce(E) -> TaskError {
        move |e| TaskError::Failed {
            what,
            source: Box::new(e),
        }
    }
}

impl From<RuntimeError> for TaskError {
    fn from(e: RuntimeError) -> Self {
        TaskError::Port(Box::new(e))
    }
}

/// What a step knows about time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepContext {
    /// Simulation time at the start of this step, ns.
    pub sim_time_ns: u64,
    /// Lockstep tick number (realtime: the wake-up count).
    pub tick: u64,
    /// Monotonic wall time of the wake-up, ns.
    pub wake_mono_ns: u64,
    /// Time since this process's previous step, ns (0 on the first).
    pub since_last_ns: u64,
    /// True on the last lockstep tick.
    pub last: bool,
    /// The run's mode.
    pub mode: Mode,
    /// What woke the process for this step.
    pub woken_by: Wake,
}

/// What woke a process for a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// A lockstep tick, or an activation of the process's timer.
    Tick,
    /// Dataflow: a new sample on every trigger input.
    Input,
    /// Dataflow: the stage's deadline passed without its inputs.
    Deadline,
}

impl StepContext {
    /// A context at which every sample is ready, whatever its stamp (a
    /// final drain, replay, outside readers).
    pub fn any_time() -> Self {
        Self {
            sim_time_ns: u64::MAX,
            tick: 0,
            wake_mono_ns: 0,
            since_last_ns: 0,
            last: false,
            mode: Mode::Realtime,
            woken_by: Wake::Tick,
        }
    }

    /// Simulation time in seconds.
    pub fn sim_time_s(&self) -> f64 {
        self.sim_time_ns as f64 * 1e-9
    }
}

/// A service's work: one call per wake-up.
pub trait Task {
    /// Do one step: read inputs (samples stamped before `ctx.sim_time_ns`),
    /// publish outputs stamped with `ctx.sim_time_ns`.
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError>;
    /// Called once when the run ends (SIGTERM/SIGINT): flush, finish files.
    fn finish(&mut self) -> Result<(), TaskError> {
        Ok(())
    }
}

/// The task of a process started with `--no-work`: every step returns at
/// once.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoWork;

impl Task for NoWork {
    fn step(&mut self, _ctx: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
}

/// What a finished run loop reports.
#[derive(Debug, Clone, Default)]
pub struct RunReport {
    /// Steps taken.
    pub steps: u64,
    /// Realtime wake-ups later than one period.
    pub deadline_misses: u64,
}

/// Monotonic clock, ns (`CLOCK_MONOTONIC`, shared by every process).
pub fn mono_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own; CLOCK_MONOTONIC always exists on Linux.
    #[allow(unsafe_code)]
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sets up `tracing` for a process: compact lines on stderr, `RUST_LOG` filter
/// (default `info`, Zenoh's crates `warn`: their `info` is per session and
/// link, except access control's, which names a peer that matched no
/// subject and is refused), one span field set per process. Colour only when stderr
/// is a terminal and `NO_COLOR` is unset: a log file or a pipe gets plain
/// text.
pub fn init_tracing() {
    use std::io::IsTerminal as _;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new(
            "info,zenoh=warn,zenoh::net::routing::interceptor::access_control=info",
        )
    });
    let colour = std::io::stderr().is_terminal()
        && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(colour)
        .with_writer(std::io::stderr)
        .with_target(false)
        .compact()
        .try_init();
}

/// One process's connection to its run: the node and the clock ports, over
/// iceoryx2 service kind `S`: shared memory between processes
/// (`ipc::Service`, what every service binary uses), or `local::Service`,
/// inside one process, so that a test can wire several tasks together.
pub struct Runtime<S: Service = ipc::Service> {
    node: Node<S>,
    args: RunArgs,
    /// Dataflow: the arrival listeners of the trigger inputs.
    triggers: std::cell::RefCell<Vec<iceoryx2::port::listener::Listener<S>>>,
    /// Dataflow: the timer keeps stepping besides the triggers (the plant).
    keep_timer: std::cell::Cell<bool>,
}

impl Runtime {
    /// Creates the node `<vehicle>/<process>` in the run's domain, over
    /// shared memory (what every service binary does).
    pub fn new(args: &RunArgs) -> Result<Self, RuntimeError> {
        Self::open(args)
    }
}

impl<S: Service> Runtime<S> {
    /// [`Runtime::new`] over any iceoryx2 service kind:
    /// `Runtime::<local::Service>::open(args)` in a test.
    pub fn open(args: &RunArgs) -> Result<Self, RuntimeError> {
        let node =
            domain_node_of::<S>(&args.run_id, &format!("{}/{}", args.vehicle, args.process))?;
        Ok(Self {
            node,
            args: args.clone(),
            triggers: std::cell::RefCell::new(Vec::new()),
            keep_timer: std::cell::Cell::new(false),
        })
    }

    /// The iceoryx2 node (for opening extra services).
    pub fn node(&self) -> &Node<S> {
        &self.node
    }

    /// The arguments this process was started with.
    pub fn args(&self) -> &RunArgs {
        &self.args
    }

    /// Opens (or creates) a publisher on `service` with the given limits.
    pub fn publisher<T: ipc_types::Sample>(
        &self,
        service: &str,
        limits: &ChannelLimits,
    ) -> Result<Publisher<T, S>, RuntimeError> {
        let p = Publisher::open(&self.node, service, limits)?;
        if self.args.mode == Mode::Dataflow {
            return p.announcing(&self.node, limits);
        }
        Ok(p)
    }

    /// Dataflow: makes `service` (opened with `limits`) one of this
    /// process's trigger inputs. The process then steps once a new sample
    /// has arrived on every trigger input since its last step; its phased
    /// timer turns into a deadline, at which it steps with what it has and
    /// counts a miss. Nothing in the other modes.
    pub fn wake_on(&self, service: &str, limits: &ChannelLimits) -> Result<(), RuntimeError> {
        if self.args.mode != Mode::Dataflow {
            return Ok(());
        }
        let listener = open_arrival(&self.node, service, limits)?
            .listener_builder()
            .create()
            .map_err(|e| RuntimeError::Port {
                service: arrival_service_name(service),
                source: Box::new(e),
            })?;
        self.triggers.borrow_mut().push(listener);
        Ok(())
    }

    /// Dataflow: keeps the timer stepping besides the trigger inputs, for a
    /// process whose own clock is physical (the plant integrates on its
    /// timer and applies thrust when it comes).
    pub fn keep_timer(&self) {
        self.keep_timer.set(true);
    }

    /// Opens (or creates) a subscriber on `service` with the given limits.
    pub fn subscriber<T: ipc_types::Sample>(
        &self,
        service: &str,
        limits: &ChannelLimits,
        buffer: usize,
    ) -> Result<Subscriber<T, S>, RuntimeError> {
        Subscriber::open(&self.node, service, limits, buffer, self.args.mode)
    }

    /// A subscriber of a service that many processes publish on (the run's
    /// `stats`: every process). It is opened on a node of its own whose
    /// subscribers keep an expired connection for every publisher the
    /// service may have (see [`domain::EXPIRED_CONNECTIONS`]), so that when
    /// the processes stop together none of their last samples is dropped
    /// unread. That node lives as long as the subscriber.
    pub fn subscriber_of_many<T: ipc_types::Sample>(
        &self,
        service: &str,
        limits: &ChannelLimits,
        buffer: usize,
    ) -> Result<Subscriber<T, S>, RuntimeError> {
        let config = domain::iceoryx_config_keeping(&self.args.run_id, limits.max_publishers);
        let node = node_with_config::<S>(
            &config,
            &format!("{}/{}", self.args.vehicle, self.args.process),
        )?;
        Subscriber::open(&node, service, limits, buffer, self.args.mode)
    }

    /// Runs the task `build` makes (see [`Runtime::run`]); with
    /// `--no-work`, runs a task that does nothing instead and never calls
    /// `build`, so the process opens no port of its own.
    pub fn serve<T: Task, E: From<RuntimeError>>(
        self,
        build: impl FnOnce(&Self) -> Result<T, E>,
    ) -> Result<RunReport, E>
    where
        iceoryx2::port::listener::Listener<S>: SynchronousMultiplexing,
    {
        if self.args.no_work {
            return Ok(self.run(NoWork)?);
        }
        let task = build(&self)?;
        Ok(self.run(task)?)
    }

    /// Runs `task` until SIGINT/SIGTERM, in the mode of the run.
    ///
    /// Either way the process's statistics are published on the run's
    /// `stats` channel once a second and written to its stats file at exit.
    pub fn run<T: Task>(self, task: T) -> Result<RunReport, RuntimeError>
    where
        iceoryx2::port::listener::Listener<S>: SynchronousMultiplexing,
    {
        let mut stats = stats::StatsReporter::new(&self.node, &self.args);
        let mut report = RunReport::default();
        let result = match self.args.mode {
            Mode::Lockstep => self.run_lockstep(task, &mut stats, &mut report),
            Mode::Realtime => self.run_realtime(task, &mut stats, &mut report),
            Mode::Dataflow if self.triggers.borrow().is_empty() => {
                self.run_realtime(task, &mut stats, &mut report)
            }
            Mode::Dataflow => self.run_dataflow(task, &mut stats, &mut report),
        };
        if let Err(e) = stats.write_file(&report) {
            tracing::warn!(%e, "cannot write the stats file");
        }
        result.map(|()| report)
    }

    fn done_notifier(&self) -> Result<iceoryx2::port::notifier::Notifier<S>, RuntimeError> {
        let name = ipc_types::run_service_name(&self.args.run_id, RunChannel::Done);
        open_done(&self.node, &self.args.run_id, self.args.processes)?
            .notifier_builder()
            .default_event_id(EventId::new(self.args.index))
            .create()
            .map_err(|e| RuntimeError::Port {
                service: name,
                source: Box::new(e),
            })
    }

    /// Tells the orchestrator that every port of this process exists: the
    /// `done` event with id [`ready_event_id`].
    fn notify_ready(
        &self,
        done: &iceoryx2::port::notifier::Notifier<S>,
    ) -> Result<(), RuntimeError> {
        done.notify_with_custom_event_id(EventId::new(ready_event_id(
            self.args.index,
            self.args.processes,
        )))
        .map(|_| ())
        .map_err(|e| RuntimeError::Io {
            service: "done".into(),
            source: Box::new(e),
        })
    }

    fn run_lockstep<T: Task>(
        &self,
        mut task: T,
        stats: &mut stats::StatsReporter<S>,
        report: &mut RunReport,
    ) -> Result<(), RuntimeError> {
        let me = self.args.index;
        let bell = Doorbell::open(&self.args.run_id, self.args.processes).map_err(|e| {
            RuntimeError::Port {
                service: doorbell::doorbell_name(&self.args.run_id),
                source: Box::new(e),
            }
        })?;
        // Read before "ready": a ring older than that is not a wake-up for
        // this process (it steps when the orchestrator rings it anew).
        let mut seen = bell.seq(me);
        let done = self.done_notifier()?;
        // The first read installs iceoryx2's SIGINT/SIGTERM handlers (no
        // request can have been caught before them): from here on a
        // termination request ends the loop and `finish` still runs.
        let _ = SignalHandler::termination_requested();
        // Ready: every port of this process exists, so the first tick's samples reach it.
        self.notify_ready(&done)?;

        let mut last_sim: Option<u64> = None;
        let mut failure: Option<RuntimeError> = None;
        let spin_ns = self.args.spin_us * 1_000;
        // Steps on a wake-up (the doorbell counter now `now`, last stepped
        // on `seen`); false once the run must end.
        let mut on_wake = |now: u32, seen: &mut u32| -> bool {
            // Step on every wake-up; with a spin budget, poll for the next
            // one before going back to block.
            let mut spin_until = 0u64;
            let mut now = Some(now);
            loop {
                let Some(n) = now.take() else {
                    if mono_ns() < spin_until {
                        std::hint::spin_loop();
                        let n = bell.seq(me);
                        if n != *seen {
                            now = Some(n);
                        }
                        continue;
                    }
                    return true;
                };
                *seen = n;
                // The tick rung, from the slot (the run may be at a later
                // tick when this step is one the orchestrator does not wait
                // for).
                let rung = bell.rung(me);
                let sim = rung.sim_time_ns;
                let wake_mono_ns = mono_ns();
                let ctx = StepContext {
                    sim_time_ns: sim,
                    tick: rung.tick,
                    wake_mono_ns,
                    since_last_ns: last_sim.map_or(0, |l| sim.saturating_sub(l)),
                    last: rung.last,
                    mode: Mode::Lockstep,
                    woken_by: Wake::Tick,
                };
                last_sim = Some(sim);
                if let Err(source) = task.step(&ctx) {
                    failure = Some(RuntimeError::Task {
                        sim_time_s: ctx.sim_time_s(),
                        source,
                    });
                    return false;
                }
                report.steps += 1;
                stats.after_step(&ctx, mono_ns().saturating_sub(wake_mono_ns), report);
                // Only the last process of the tick to finish wakes the
                // orchestrator (it reads the others' slots), and one whose
                // step the tick did not count.
                if bell.finished(me, *seen) {
                    bell.notify_done();
                }
                if spin_ns == 0 {
                    // Blocking: the next wake-up comes after the orchestrator
                    // has heard `done`; the futex wait sees it.
                    return true;
                }
                spin_until = mono_ns() + spin_ns;
            }
        };
        // The termination flag is read before each wait (a lock and an
        // atomic, no system call); a request that comes just after it
        // interrupts the futex wait, or is seen within its second. Another
        // signal (SIGCONT after a stall, SIGCHLD, ...) just waits again.
        loop {
            if SignalHandler::termination_requested() {
                break;
            }
            let Some(now) = bell.wait(me, seen, Duration::from_secs(1)) else {
                continue;
            };
            if !on_wake(now, &mut seen) {
                break;
            }
        }
        let finish = task.finish();
        if let Some(e) = failure {
            return Err(e);
        }
        finish.map_err(|source| RuntimeError::Task {
            sim_time_s: last_sim.unwrap_or(0) as f64 * 1e-9,
            source,
        })?;
        Ok(())
    }

    /// The phased timer of this process: activation `k` is due at
    /// `epoch + phase + k·period` on the monotonic clock. A restarted
    /// process joins at its next activation.
    fn schedule(&self) -> Schedule {
        let period_ns = (self.args.period_s.max(1e-4) * 1e9).round() as u64;
        let phase_ns = (self.args.phase_s.max(0.0) * 1e9).round() as u64;
        let epoch = if self.args.epoch_mono_ns == 0 {
            mono_ns()
        } else {
            self.args.epoch_mono_ns
        };
        let next = if self.args.restart > 0 {
            mono_ns()
                .saturating_sub(epoch + phase_ns)
                .div_ceil(period_ns)
        } else {
            0
        };
        Schedule {
            period_ns,
            phase_ns,
            epoch,
            next,
        }
    }

    /// Realtime: the process sleeps until its next activation
    /// ([`Runtime::schedule`]; `Node::wait`, which returns early on
    /// SIGINT/SIGTERM), steps with the activation's nominal time as its
    /// simulation time, and counts a deadline miss for every activation it
    /// could not start before the next one was due (those are skipped, not
    /// run late in a burst).
    fn run_realtime<T: Task>(
        &self,
        task: T,
        stats: &mut stats::StatsReporter<S>,
        report: &mut RunReport,
    ) -> Result<(), RuntimeError> {
        let done = self.done_notifier()?;
        self.notify_ready(&done)?;
        let mut sched = self.schedule();
        let mut stepper = self.stepper(task, stats, report);
        loop {
            let due = sched.due();
            let now = mono_ns();
            if now < due {
                match self.node.wait(Duration::from_nanos(due - now)) {
                    Ok(()) => {}
                    Err(iceoryx2::node::NodeWaitFailure::TerminationRequest) => break,
                    // Another signal cut the sleep short: sleep again.
                    Err(_) => {}
                }
                continue;
            }
            let (k, sim, skipped) = sched.activate(now);
            stepper.report.deadline_misses += skipped;
            stepper.stats.wake_late(now - (sched.epoch + sim));
            stepper.step(now, sim, k, Wake::Tick)?;
        }
        stepper.finish()
    }

    fn stepper<'a, T: Task>(
        &self,
        task: T,
        stats: &'a mut stats::StatsReporter<S>,
        report: &'a mut RunReport,
    ) -> WallStepper<'a, T, S> {
        WallStepper {
            task,
            stats,
            report,
            mode: self.args.mode,
            last_sim: None,
        }
    }

    /// Dataflow: the process steps once a new sample has arrived on every
    /// trigger input since its last step (their arrival events, polled
    /// together), with the wall time of the step as its simulation time.
    /// Activation `k` of its phased timer ([`Runtime::schedule`]) is its
    /// deadline for frame `k`: a step on input before it stands for the
    /// frame (the timer then skips to the next activation, so a stage that
    /// keeps up wakes once per frame); a deadline reached without one is a
    /// miss, and the process steps with what it has. With
    /// [`Runtime::keep_timer`] every activation is a step, as in realtime,
    /// and the triggers add steps of their own.
    fn run_dataflow<T: Task>(
        &self,
        task: T,
        stats: &mut stats::StatsReporter<S>,
        report: &mut RunReport,
    ) -> Result<(), RuntimeError>
    where
        iceoryx2::port::listener::Listener<S>: SynchronousMultiplexing,
    {
        let done = self.done_notifier()?;
        // The first read installs iceoryx2's SIGINT/SIGTERM handlers, as in
        // lockstep: a process woken only by its inputs may never reach a
        // timed-out wait, and without them SIGTERM would end it on the spot,
        // its task unfinished and its statistics unwritten.
        let _ = SignalHandler::termination_requested();
        self.notify_ready(&done)?;
        let mut sched = self.schedule();
        let triggers = self.triggers.borrow();
        // ppoll(2) on the listeners' sockets, not a WaitSet: its timeout is
        // in nanoseconds, where epoll's whole milliseconds would wake the
        // plants up to 1 ms late, each by a different amount.
        let mut fds: Vec<libc::pollfd> = triggers
            .iter()
            .map(|l| libc::pollfd {
                fd: listener_fd(l),
                events: libc::POLLIN,
                revents: 0,
            })
            .collect();
        set_timer_slack_ns(1_000);
        let keep_timer = self.keep_timer.get();
        let mut pending = vec![false; triggers.len()];
        // No miss is counted before the first input arrived.
        let mut started = false;
        let mut stepper = self.stepper(task, stats, report);
        loop {
            if SignalHandler::termination_requested() {
                break;
            }
            let due = sched.due();
            let now = mono_ns();
            if now >= due {
                let (k, sim, skipped) = sched.activate(now);
                let wake = if keep_timer {
                    stepper.report.deadline_misses += skipped;
                    Wake::Tick
                } else {
                    if started {
                        stepper.report.deadline_misses += skipped + 1;
                    }
                    Wake::Deadline
                };
                stepper.stats.wake_late(now - (sched.epoch + sim));
                stepper.step(now, sim, k, wake)?;
                continue;
            }
            match poll_until(&mut fds, due - now) {
                Ok(true) => {
                    for (i, (f, l)) in fds.iter().zip(triggers.iter()).enumerate() {
                        if f.revents != 0 {
                            let _ = l.try_wait(|_| {});
                            pending[i] = true;
                        }
                    }
                }
                Ok(false) => {
                    // The timeout, or a signal: a termination request ends the run.
                    if let Err(iceoryx2::node::NodeWaitFailure::TerminationRequest) =
                        self.node.wait(Duration::ZERO)
                    {
                        break;
                    }
                }
                Err(e) => {
                    let _ = stepper.finish();
                    return Err(RuntimeError::Wait(Box::new(e)));
                }
            }
            if pending.iter().all(|p| *p) {
                pending.fill(false);
                started = true;
                let now = mono_ns();
                if !keep_timer {
                    sched.stand_for_frame(now);
                }
                let sim = now.saturating_sub(sched.epoch);
                stepper.step(now, sim, sched.next, Wake::Input)?;
            }
        }
        stepper.finish()
    }
}

/// The socket an iceoryx2 event listener wakes up on (to poll it).
pub fn listener_fd<S: Service>(l: &iceoryx2::port::listener::Listener<S>) -> i32
where
    iceoryx2::port::listener::Listener<S>: SynchronousMultiplexing,
{
    #[allow(unsafe_code)]
    // SAFETY: the descriptor stays owned by the listener, which outlives
    // every poll of it; it is only polled.
    unsafe {
        l.file_descriptor().native_handle()
    }
}

/// Waits until one of `fds` is readable (`Ok(true)`, with `revents` set) or
/// `timeout_ns` has passed or a signal came (`Ok(false)`): ppoll(2), whose
/// timeout is in nanoseconds.
pub fn poll_until(fds: &mut [libc::pollfd], timeout_ns: u64) -> std::io::Result<bool> {
    let ts = libc::timespec {
        tv_sec: (timeout_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (timeout_ns % 1_000_000_000) as libc::c_long,
    };
    #[allow(unsafe_code)]
    // SAFETY: `fds` and `ts` live across the call; no signal mask is passed.
    let n = unsafe {
        libc::ppoll(
            fds.as_mut_ptr(),
            fds.len() as libc::nfds_t,
            &ts,
            std::ptr::null(),
        )
    };
    match n {
        -1 => {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::Interrupted {
                Ok(false)
            } else {
                Err(e)
            }
        }
        0 => Ok(false),
        _ => Ok(true),
    }
}

/// Lets this thread's timed waits end at most `ns` after they are due
/// (Linux's default slack is 50 µs; a realtime stage wants its deadline).
fn set_timer_slack_ns(ns: u64) {
    #[allow(unsafe_code)]
    // SAFETY: PR_SET_TIMERSLACK takes one integer argument and touches no memory.
    let r = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, ns as libc::c_ulong, 0, 0, 0) };
    if r != 0 {
        tracing::debug!(error = %std::io::Error::last_os_error(), "cannot set the timer slack");
    }
}

/// A process's phased timer on the wall clock (realtime and dataflow).
struct Schedule {
    period_ns: u64,
    phase_ns: u64,
    epoch: u64,
    /// The next activation.
    next: u64,
}

impl Schedule {
    /// When the next activation is due, monotonic ns.
    fn due(&self) -> u64 {
        self.epoch + self.phase_ns + self.next * self.period_ns
    }

    /// A step on input at `now` stands for the frame whose activation is
    /// the first due after `now`: the next one due is the frame after it.
    fn stand_for_frame(&mut self, now: u64) {
        let first_after = (now + 1)
            .saturating_sub(self.epoch + self.phase_ns)
            .div_ceil(self.period_ns);
        self.next = self.next.max(first_after + 1);
    }

    /// Takes the latest activation due at `now`: its number, its nominal
    /// simulation time, and how many activations before it were skipped.
    fn activate(&mut self, now: u64) -> (u64, u64, u64) {
        let skipped = now.saturating_sub(self.due()) / self.period_ns;
        self.next += skipped;
        let k = self.next;
        self.next += 1;
        (k, k * self.period_ns + self.phase_ns, skipped)
    }
}

/// Steps a task on the wall clock (realtime and dataflow), keeping its
/// simulation time monotonic and its statistics.
struct WallStepper<'a, T: Task, S: Service> {
    task: T,
    stats: &'a mut stats::StatsReporter<S>,
    report: &'a mut RunReport,
    mode: Mode,
    last_sim: Option<u64>,
}

impl<T: Task, S: Service> WallStepper<'_, T, S> {
    /// One step woken at `now` for simulation time `sim` (held monotonic)
    /// on activation `tick`; a failed step finishes the task.
    fn step(&mut self, now: u64, sim: u64, tick: u64, woken_by: Wake) -> Result<(), RuntimeError> {
        let sim = self.last_sim.map_or(sim, |l| sim.max(l));
        let ctx = StepContext {
            sim_time_ns: sim,
            tick,
            wake_mono_ns: now,
            since_last_ns: self.last_sim.map_or(0, |l| sim - l),
            last: false,
            mode: self.mode,
            woken_by,
        };
        self.last_sim = Some(sim);
        if let Err(source) = self.task.step(&ctx) {
            let _ = self.task.finish();
            return Err(RuntimeError::Task {
                sim_time_s: ctx.sim_time_s(),
                source,
            });
        }
        self.report.steps += 1;
        self.stats
            .after_step(&ctx, mono_ns().saturating_sub(now), self.report);
        Ok(())
    }

    /// The run ended: the task's finish.
    fn finish(mut self) -> Result<(), RuntimeError> {
        let sim = self.last_sim.unwrap_or(0);
        self.task.finish().map_err(|source| RuntimeError::Task {
            sim_time_s: sim as f64 * 1e-9,
            source,
        })
    }
}

pub(crate) fn service_name(name: &str) -> Result<ServiceName, RuntimeError> {
    ServiceName::new(name).map_err(|e| RuntimeError::Service {
        service: name.to_string(),
        source: Box::new(e),
    })
}

/// The command line of every service binary: the run arguments and the
/// resolved scenario file the orchestrator wrote.
#[derive(Debug, Clone, clap::Parser)]
#[command(about = "A shoal service process; started by `shoal run`, not by hand.")]
pub struct ServiceCli {
    /// Run arguments.
    #[command(flatten)]
    pub run: RunArgs,
    /// The run's resolved scenario (TOML).
    #[arg(long)]
    pub scenario: std::path::PathBuf,
}

/// Event id of process `index`'s "ready" on the `done` service (finished
/// lockstep steps are told through the [`Doorbell`], not on it).
pub const fn ready_event_id(index: usize, processes: usize) -> usize {
    processes + index
}

/// Opens the `done` event service of a run (same limits for every opener):
/// ids `0..processes` are finished steps, `processes..2·processes` readies.
pub fn open_done<S: Service>(
    node: &Node<S>,
    run_id: &str,
    processes: usize,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<S>, RuntimeError> {
    let name = ipc_types::run_service_name(run_id, RunChannel::Done);
    let limits = ChannelLimits::done(processes);
    node.service_builder(&service_name(&name)?)
        .event()
        .max_notifiers(limits.max_publishers)
        .max_listeners(limits.max_subscribers)
        .max_nodes(limits.max_nodes)
        .event_id_max_value(2 * processes.max(1))
        .open_or_create()
        .map_err(|e| RuntimeError::Service {
            service: name,
            source: Box::new(e),
        })
}

/// The event service a dataflow publisher notifies after each send on `service`.
pub fn arrival_service_name(service: &str) -> String {
    format!("{service}/arrived")
}

/// Opens the arrival event service of pub-sub `service` (the publisher's
/// notifier and the triggered subscribers' listeners; one event id). A
/// publisher and a subscriber opening it at once may race: retried.
pub fn open_arrival<S: Service>(
    node: &Node<S>,
    service: &str,
    limits: &ChannelLimits,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<S>, RuntimeError> {
    use iceoryx2::service::builder::event::{
        EventCreateError as C, EventOpenError as O, EventOpenOrCreateError as E,
    };
    let name = arrival_service_name(service);
    let sname = service_name(&name)?;
    ports::open_retrying(
        || {
            node.service_builder(&sname)
                .event()
                .max_notifiers(limits.max_publishers)
                .max_listeners(limits.max_subscribers)
                .max_nodes(limits.max_nodes)
                .event_id_max_value(0)
                .open_or_create()
        },
        |e| {
            matches!(
                e,
                E::SystemInFlux
                    | E::EventOpenError(O::DoesNotExist)
                    | E::EventCreateError(C::AlreadyExists | C::IsBeingCreatedByAnotherInstance)
            )
        },
    )
    .map_err(|e| RuntimeError::Service {
        service: name,
        source: Box::new(e),
    })
}

/// Opens a process's wake-up event service (one event id, the runtime's
/// limits): the event `shoal bench ipc` measures in its `shoal-event` case.
/// A lockstep process is woken through the run's [`Doorbell`] instead.
pub fn open_wake<S: Service>(
    node: &Node<S>,
    run_id: &str,
    vehicle: &str,
    process: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<S>, RuntimeError> {
    let name = ipc_types::wake_service_name(run_id, vehicle, process);
    node.service_builder(&service_name(&name)?)
        .event()
        .max_notifiers(2)
        .max_listeners(2)
        .max_nodes(4)
        // One event id (0): a listener's every wait then resets one
        // counter, not iceoryx2's default of 256.
        .event_id_max_value(0)
        .open_or_create()
        .map_err(|e| RuntimeError::Service {
            service: name,
            source: Box::new(e),
        })
}

/// Creates a node in a run's domain (the orchestrator's, a test's, a replayer's).
pub fn domain_node(run_id: &str, name: &str) -> Result<Node<ipc::Service>, RuntimeError> {
    domain_node_of::<ipc::Service>(run_id, name)
}

/// [`domain_node`] over any iceoryx2 service kind.
pub fn domain_node_of<S: Service>(run_id: &str, name: &str) -> Result<Node<S>, RuntimeError> {
    node_with_config(&iceoryx_config(run_id), name)
}

/// A node named `name` with the iceoryx2 configuration `config`.
fn node_with_config<S: Service>(config: &Config, name: &str) -> Result<Node<S>, RuntimeError> {
    let node_name = NodeName::new(name).map_err(|e| RuntimeError::Node {
        name: name.to_string(),
        source: Box::new(e),
    })?;
    NodeBuilder::new()
        .name(&node_name)
        .config(config)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<S>()
        .map_err(|e| RuntimeError::Node {
            name: name.to_string(),
            source: Box::new(e),
        })
}

/// Opens a publisher on a node that is not a [`Runtime`] (the orchestrator's clock).
pub fn node_publisher<T: ipc_types::Sample, S: Service>(
    node: &Node<S>,
    service: &str,
    limits: &ChannelLimits,
) -> Result<Publisher<T, S>, RuntimeError> {
    Publisher::open(node, service, limits)
}

/// Opens a subscriber on a node that is not a [`Runtime`] (tests, tools).
pub fn node_subscriber<T: ipc_types::Sample, S: Service>(
    node: &Node<S>,
    service: &str,
    limits: &ChannelLimits,
    buffer: usize,
) -> Result<Subscriber<T, S>, RuntimeError> {
    Subscriber::open(node, service, limits, buffer, Mode::Realtime)
}

#[cfg(test)]
mod tests {
    use super::Schedule;

    fn schedule() -> Schedule {
        Schedule {
            period_ns: 100,
            phase_ns: 20,
            epoch: 1_000,
            next: 0,
        }
    }

    #[test]
    fn an_activation_taken_late_skips_the_ones_it_missed() {
        let mut s = schedule();
        assert_eq!(s.due(), 1_020);
        assert_eq!(s.activate(1_020), (0, 20, 0));
        assert_eq!(s.due(), 1_120);
        // 250 late: activations 1 and 2 were missed; 3 runs.
        assert_eq!(s.activate(1_370), (3, 320, 2));
        assert_eq!(s.due(), 1_420);
    }

    #[test]
    fn a_step_on_input_stands_for_the_next_frame_once() {
        let mut s = schedule();
        // Input at 1_005, before activation 0 (1_020): 0 is covered, 1 is next.
        s.stand_for_frame(1_005);
        assert_eq!(s.due(), 1_120);
        // A second input in the same period covers nothing more.
        s.stand_for_frame(1_019);
        assert_eq!(s.due(), 1_120);
        // Input exactly at an activation's time stands for the one after.
        s.stand_for_frame(1_020);
        assert_eq!(s.due(), 1_220);
        // The next period's input covers activation 2.
        s.stand_for_frame(1_150);
        assert_eq!(s.due(), 1_320);
        // Before the epoch: the first activation is covered.
        let mut early = schedule();
        early.stand_for_frame(10);
        assert_eq!(early.due(), 1_120);
    }
}
