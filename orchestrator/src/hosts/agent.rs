//! `shoal host`: the one shoal process of a host in a run spread over
//! hosts. It listens on Zenoh for a coordinator, starts and reaps its
//! host's share of the run (its vehicles' processes, the world if placed
//! here, a recorder of its own), bridges the crossing services, follows the
//! coordinator's lockstep clock, and sends back its outcome and files.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use anyhow::Context;
use shoal_scenario::{ProcessKind, ProcessSpec, Scenario};
use zenoh::Wait;

use super::bridge::{Bridge, Inbound};
use super::wire::{self, FileChunk, HostOutcome, StartOrder, StartReply};
use crate::launch::restart::{HostScope, Launch, Recovery};
use crate::launch::supervisor::Supervisor;
use crate::launch::{self, os as sys, Ports};

/// How an agent is started.
#[derive(Debug, Clone)]
pub struct AgentOptions {
    /// Zenoh locators to listen on.
    pub listen: Vec<String>,
    /// The host's name (the hosts file names it so).
    pub name: String,
    /// Where runs keep their files until the coordinator takes them.
    pub work: PathBuf,
    /// Where the service binaries are.
    pub bin_dir: PathBuf,
    /// Serve one run, then exit.
    pub once: bool,
    /// TLS as this host's identity, or plain TCP.
    pub security: super::tls::Security,
    /// The certificate names this agent takes orders from (over TLS).
    pub coordinators: Vec<String>,
}

/// A run this host finished, waiting for the coordinator to collect it.
struct Finished {
    run_id: String,
    outcome: HostOutcome,
    out: PathBuf,
}

/// Serves runs until SIGINT/SIGTERM (or, with `once`, until one run has
/// been collected).
pub fn serve(opts: &AgentOptions) -> anyhow::Result<()> {
    for (dead, files) in shoal_runtime::sweep_stale_domains() {
        tracing::warn!(run = %dead, files, "removed the shared memory of a dead run");
    }
    // Installs the SIGINT/SIGTERM handler before anything else runs.
    let _ = launch::termination_requested();
    let mut finished: Option<Finished> = None;
    let mut first = true;
    loop {
        match serve_session(opts, &mut finished, first)? {
            Served::Stop => return Ok(()),
            Served::Collected if opts.once => return Ok(()),
            Served::Collected => first = false,
        }
    }
}

/// How a session of [`serve`] ended.
enum Served {
    /// On a signal.
    Stop,
    /// A run was collected.
    Collected,
}

/// Opens a Zenoh session on the agent's endpoints, retrying for a while if
/// the last one's listener is not gone yet.
fn open_session(opts: &AgentOptions) -> anyhow::Result<zenoh::Session> {
    let start = Instant::now();
    loop {
        match zenoh::open(wire::agent_config(
            &opts.listen,
            &opts.security,
            &opts.coordinators,
        )?)
        .wait()
        {
            Ok(s) => return Ok(s),
            Err(e) if start.elapsed() < Duration::from_secs(5) => {
                tracing::debug!("Zenoh session on {:?}: {e}; again", opts.listen);
                std::thread::sleep(Duration::from_millis(100));
            }
            Err(e) => anyhow::bail!("cannot open a Zenoh session on {:?}: {e}", opts.listen),
        }
    }
}

/// Serves on one Zenoh session until a run has been collected (every run
/// after it gets a fresh session: a Zenoh router keeps a link-state graph
/// of the routers it met, and after one coordinator left and another came,
/// an agent's declarations sometimes no longer reached the new one, as
/// seen with Zenoh 1.10 in `shoal bench hosts`), or a signal.
fn serve_session(
    opts: &AgentOptions,
    finished: &mut Option<Finished>,
    first: bool,
) -> anyhow::Result<Served> {
    let session = open_session(opts)?;
    // The queryable first: a coordinator that sees the token may ask at once.
    let queries = session
        .declare_queryable(wire::agent_queries(&opts.name))
        .wait()
        .map_err(|e| anyhow::anyhow!("queryable: {e}"))?;
    let alive = session
        .liveliness()
        .declare_token(wire::alive(&opts.name))
        .wait()
        .map_err(|e| anyhow::anyhow!("liveliness token: {e}"))?;
    if first {
        tracing::info!(name = %opts.name, listen = ?opts.listen, "host agent ready");
        match &opts.security {
            super::tls::Security::Tls(id) => eprintln!(
                "shoal host {} listening on {} (TLS, mutual authentication: certificate {}, CA {}); answers only {}",
                opts.name,
                opts.listen.join(", "),
                id.cert.display(),
                id.ca.display(),
                opts.coordinators.join(", ")
            ),
            super::tls::Security::Insecure => {
                tracing::warn!("INSECURE: plain TCP, no authentication, no access control");
                eprintln!(
                    "shoal host {} listening on {}: INSECURE (--insecure): plain TCP, no authentication, no access control; anyone who reaches it can start, read and abort runs",
                    opts.name,
                    opts.listen.join(", ")
                );
            }
        }
    }
    // When this session sent a finished run's files.
    let mut sent_at: Option<Instant> = None;
    let served = loop {
        if launch::termination_requested().is_some() {
            tracing::info!("host agent stopping on a signal");
            break Served::Stop;
        }
        // Files sent but never released: the coordinator is gone; they
        // stay on this host and the next coordinator gets a fresh session.
        if sent_at.is_some_and(|t| t.elapsed() > RELEASE_WAIT) {
            if let Some(f) = finished.take() {
                tracing::warn!(
                    run = %f.run_id,
                    "the coordinator never confirmed the run's files; they stay in {}",
                    f.out.display()
                );
            }
            break Served::Collected;
        }
        let query = match queries.recv_timeout(Duration::from_millis(200)) {
            Ok(Some(q)) => q,
            Ok(None) => continue,
            Err(e) => anyhow::bail!("the queryable closed: {e}"),
        };
        let key = query.key_expr().as_str().to_string();
        if key == wire::time(&opts.name) {
            let now = shoal_runtime::mono_ns().to_le_bytes().to_vec();
            let _ = query.reply(query.key_expr().clone(), now).wait();
        } else if key == wire::start(&opts.name) {
            let order = query
                .payload()
                .map(|p| p.to_bytes().into_owned())
                .context("a start order without payload")
                .and_then(|b| serde_json::from_slice::<StartOrder>(&b).context("start order"));
            match order {
                Ok(order) => {
                    tracing::info!(run = %order.run_id, coordinator = %order.coordinator, "a run starts");
                    if let Some(old) = finished.take() {
                        tracing::warn!(run = %old.run_id, "a run was never collected; its files stay in {}", old.out.display());
                    }
                    *finished = Some(run_share(&session, opts, order, query));
                }
                Err(e) => {
                    let _ = query.reply_err(format!("{e:#}")).wait();
                }
            }
        } else if let Some(run) = key.strip_prefix(&format!("shoal-host/{}/finish/", opts.name)) {
            match finished.as_ref() {
                Some(f) if f.run_id == run => {
                    if let Err(e) = send_back(&query, f) {
                        tracing::warn!("cannot send the run's files: {e:#}");
                    }
                    sent_at = Some(Instant::now());
                }
                _ => {
                    let _ = query
                        .reply_err(format!("host {} has no finished run {run}", opts.name))
                        .wait();
                }
            }
        } else if let Some(run) = key.strip_prefix(&format!("shoal-host/{}/release/", opts.name)) {
            match finished.take() {
                Some(f) if f.run_id == run => {
                    let _ = query
                        .reply(query.key_expr().clone(), Vec::<u8>::new())
                        .wait();
                    let _ = std::fs::remove_dir_all(&f.out);
                    break Served::Collected;
                }
                other => {
                    *finished = other;
                    let _ = query
                        .reply_err(format!("host {} has no finished run {run}", opts.name))
                        .wait();
                }
            }
        } else {
            let _ = query.reply_err(format!("unknown query {key}")).wait();
        }
    };
    drop((alive, queries));
    session
        .close()
        .wait()
        .map_err(|e| anyhow::anyhow!("closing the Zenoh session: {e}"))?;
    Ok(served)
}

/// How long files sent stay waiting for the coordinator's release.
const RELEASE_WAIT: Duration = Duration::from_secs(60);

/// Replies to `finish`: the outcome, then every file in pieces.
fn send_back(query: &zenoh::query::Query, f: &Finished) -> anyhow::Result<()> {
    let key = query.key_expr().clone();
    query
        .reply(key.clone(), serde_json::to_vec(&f.outcome)?)
        .wait()
        .map_err(|e| anyhow::anyhow!("reply: {e}"))?;
    for rel in &f.outcome.files {
        let bytes = std::fs::read(f.out.join(rel))
            .with_context(|| format!("cannot read {}", f.out.join(rel).display()))?;
        let total = bytes.len() as u64;
        let mut offset = 0usize;
        loop {
            let end = (offset + wire::CHUNK_BYTES).min(bytes.len());
            let chunk = FileChunk {
                path: rel.clone(),
                offset: offset as u64,
                total,
            };
            query
                .reply(key.clone(), bytes[offset..end].to_vec())
                .attachment(serde_json::to_vec(&chunk)?)
                .wait()
                .map_err(|e| anyhow::anyhow!("reply: {e}"))?;
            offset = end;
            if offset >= bytes.len() {
                break;
            }
        }
    }
    Ok(())
}

/// The live state of this host's share of a run.
struct Share {
    mode: shoal_runtime::Mode,
    /// Realtime: the run's epoch on this host's monotonic clock, ns.
    epoch_mono_ns: u64,
    scenario: Scenario,
    procs: Vec<ProcessSpec>,
    local: Vec<bool>,
    ports: Ports,
    bridge: Bridge,
    rx: Receiver<Inbound>,
    fence: zenoh::pubsub::Publisher<'static>,
    failed: zenoh::pubsub::Publisher<'static>,
    tick_timeout: Duration,
    spin: Duration,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    _coordinator: zenoh::pubsub::Subscriber<()>,
}

/// Why this host's share ended early, as the coordinator is told.
#[derive(Debug, thiserror::Error)]
enum Stopped {
    #[error("the coordinator `{}` aborted the run: {}", .0.from, .0.reason)]
    Aborted(wire::AbortMsg),
    #[error("the coordinator is gone (it ended, or the link to it is cut)")]
    CoordinatorGone,
}

/// Runs this host's share of `order`, replying to `start` once its
/// processes are ready (or with the reason they are not).
fn run_share(
    session: &zenoh::Session,
    opts: &AgentOptions,
    order: StartOrder,
    start: zenoh::query::Query,
) -> Finished {
    let out = opts.work.join(&order.run_id);
    // The agent serves many runs: this one's CPU is what it adds.
    let cpu_before = sys::self_cpu_s();
    let mut sup = Supervisor::default();
    let mut outcome = HostOutcome {
        host: opts.name.clone(),
        ..HostOutcome::default()
    };
    let mut share = None;
    let result = match prepare(session, opts, &order, &out, &mut sup) {
        Err(e) => {
            let _ = start.reply_err(format!("{e:#}")).wait();
            Err(e)
        }
        Ok(s) => {
            let reply = StartReply {
                pid: std::process::id(),
                processes: s.local.iter().filter(|l| **l).count(),
                exports: s.bridge.exports(),
                imports: s.bridge.imports(),
            };
            let sent = serde_json::to_vec(&reply)
                .map_err(anyhow::Error::from)
                .and_then(|b| {
                    start
                        .reply(start.key_expr().clone(), b)
                        .wait()
                        .map_err(|e| anyhow::anyhow!("reply: {e}"))
                });
            // The query ends when it is dropped.
            drop(start);
            let share = share.insert(s);
            sent.and_then(|()| share.drive(&mut sup))
        }
    };
    if let (Err(e), Some(s)) = (&result, &share) {
        if e.downcast_ref::<Stopped>().is_none() {
            let _ = s.failed.put(format!("{e:#}")).wait();
        }
    }
    if let Err(e) = &result {
        tracing::error!("{e:#}");
        outcome.error = Some(format!("{e:#}"));
    }
    // Stop: the recorder first (it finishes the file), then everyone.
    sup.stop_all(
        |c| c.spec.kind == ProcessKind::Recorder,
        Duration::from_secs(5),
    );
    if let Some(mut s) = share {
        outcome.events = std::mem::take(&mut s.ports.journal.list);
        outcome.bridged_out = s.bridge.out;
        outcome.bridged_in = s.bridge.r#in;
        outcome.bridge_lost = s.bridge.lost();
        let parts = std::mem::take(&mut s.ports.recovery.recording_parts);
        drop(s);
        if !parts.is_empty() {
            if let Err(e) = launch::join_recordings(&out.join("recording.mcap"), &parts) {
                tracing::error!("{e:#}");
            }
        }
    }
    outcome.stats = shoal_runtime::stats::read_stats_files(&order.run_id);
    let _ = shoal_runtime::release_domain(&order.run_id);
    outcome.leftover_shm = shoal_runtime::list_domain_files(&order.run_id).len();
    outcome.usage = launch::child_usage(&sup);
    outcome.agent_cpu_s = sys::self_cpu_s() - cpu_before;
    outcome.files = files_below(&out);
    Finished {
        run_id: order.run_id,
        outcome,
        out,
    }
}

/// Every file below `dir`, relative to it, sorted.
fn files_below(dir: &Path) -> Vec<String> {
    super::files_under(dir)
        .iter()
        .filter_map(|p| p.strip_prefix(dir).ok())
        .map(|p| p.display().to_string())
        .collect()
}

/// Opens this host's ports and bridges and starts its processes.
fn prepare(
    session: &zenoh::Session,
    opts: &AgentOptions,
    order: &StartOrder,
    out: &Path,
    sup: &mut Supervisor,
) -> anyhow::Result<Share> {
    let scenario = Scenario::from_toml(&order.scenario_toml).context("the run's scenario")?;
    let me = order.host;
    let placement = &order.placement;
    anyhow::ensure!(
        placement.hosts.get(me) == Some(&opts.name),
        "the run places host {me} as {:?}, but this agent is {}",
        placement.hosts.get(me),
        opts.name
    );
    launch::check_programs(&opts.bin_dir, &scenario, Some(&opts.name))?;
    std::fs::create_dir_all(out.join("logs"))
        .with_context(|| format!("cannot create {}", out.display()))?;
    let scenario_path = out.join("scenario.toml");
    std::fs::write(&scenario_path, &order.scenario_toml)?;
    let run_id = &order.run_id;
    shoal_runtime::domain::claim_domain(run_id, std::process::id())
        .context("cannot create the run's domain directory")?;
    let procs = scenario.processes();
    let local: Vec<bool> = procs
        .iter()
        .map(|p| placement.runs(&scenario, me, p))
        .collect();
    let mut ports = Ports::open_local(run_id, &procs, |p| local[p.index])?;
    let launch = Launch {
        bin_dir: opts.bin_dir.clone(),
        out: out.to_path_buf(),
        run_id: run_id.clone(),
        processes: procs.len(),
        mode: order.mode,
        epoch_mono_ns: order.epoch_mono_ns,
        spin_us: order.spin_us,
        no_work: false,
        live: None,
        scenario_path,
        scenario: scenario.clone(),
        scope: Some(HostScope {
            host: opts.name.clone(),
            local: local.clone(),
            vehicles: placement
                .vehicles_on(&scenario, me)
                .into_iter()
                .map(String::from)
                .collect(),
            world: placement.world_host == me,
        }),
    };
    std::fs::write(launch.effective_scenario(), &order.effective_toml)?;
    ports.recovery = Recovery::for_run(&ports.node, &procs, launch.clone())?;
    let (tx, rx) = mpsc::channel();
    let crossings = placement.crossings(&scenario, run_id);
    let bridge = Bridge::open(
        session,
        &ports.node,
        &crossings,
        me,
        scenario.vehicles.len(),
        &order.stamp_shift_ns,
        &tx,
    )?;
    let zerr = |what: &str| {
        let what = what.to_string();
        move |e: zenoh::Error| anyhow::anyhow!("zenoh {what}: {e}")
    };
    let mut subscribers = Vec::new();
    let clock_tx = tx.clone();
    subscribers.push(
        session
            .declare_subscriber(wire::clock(run_id))
            .callback(move |s| {
                let bytes = s.payload().to_bytes();
                let msg = match wire::decode_tick(&bytes) {
                    Some(t) => Inbound::Clock(t),
                    None => Inbound::End,
                };
                let _ = clock_tx.send(msg);
            })
            .wait()
            .map_err(zerr("clock subscriber"))?,
    );
    let abort_tx = tx.clone();
    subscribers.push(
        session
            .declare_subscriber(wire::abort(run_id))
            .callback(move |s| {
                let msg = wire::AbortMsg::decode(&s.payload().to_bytes());
                let _ = abort_tx.send(Inbound::Abort(msg));
            })
            .wait()
            .map_err(zerr("abort subscriber"))?,
    );
    let gone_tx = tx;
    let coordinator = session
        .liveliness()
        .declare_subscriber(wire::coordinator(run_id))
        .callback(move |s| {
            if s.kind() == zenoh::sample::SampleKind::Delete {
                let _ = gone_tx.send(Inbound::CoordinatorGone);
            }
        })
        .wait()
        .map_err(zerr("liveliness subscriber"))?;
    let block = zenoh::qos::CongestionControl::Block;
    let fence = session
        .declare_publisher(wire::fence(run_id, &opts.name))
        .congestion_control(block)
        .wait()
        .map_err(zerr("fence publisher"))?;
    let failed = session
        .declare_publisher(wire::failed(run_id, &opts.name))
        .congestion_control(block)
        .wait()
        .map_err(zerr("failure publisher"))?;
    for p in procs.iter().filter(|p| local[p.index]) {
        sup.spawn(
            p,
            &launch.binary(p),
            &launch.args(p, 0, None),
            &launch.log(p),
            0,
        )
        .with_context(|| format!("cannot start {} on host {}", p.label(), opts.name))?;
    }
    let tick_timeout = Duration::from_secs_f64(order.tick_timeout_s.max(0.1));
    let mine: Vec<usize> = procs
        .iter()
        .filter(|p| local[p.index])
        .map(|p| p.index)
        .collect();
    launch::wait_ready(
        &mut ports,
        sup,
        &procs,
        &mine,
        Duration::from_secs(60).max(tick_timeout),
    )?;
    Ok(Share {
        mode: order.mode,
        epoch_mono_ns: order.epoch_mono_ns,
        scenario,
        procs,
        local,
        ports,
        bridge,
        rx,
        fence,
        failed,
        tick_timeout,
        spin: Duration::from_micros(order.spin_us),
        _subscribers: subscribers,
        _coordinator: coordinator,
    })
}

impl Share {
    /// Runs this host's share to the end of the run.
    fn drive(&mut self, sup: &mut Supervisor) -> anyhow::Result<()> {
        match self.mode {
            shoal_runtime::Mode::Lockstep => self.lockstep(sup),
            shoal_runtime::Mode::Realtime | shoal_runtime::Mode::Dataflow => self.realtime(sup),
        }
    }

    /// Realtime: the processes run on their own clocks from the epoch; the
    /// agent bridges samples in as they come and out every millisecond,
    /// supervises, and ends when the coordinator says so.
    fn realtime(&mut self, sup: &mut Supervisor) -> anyhow::Result<()> {
        const FORWARD: Duration = Duration::from_millis(1);
        const KEEP: Duration = Duration::from_millis(100);
        let epoch = self.epoch_mono_ns;
        let end = epoch + (self.scenario.duration_s * 1e9) as u64;
        let late = end + self.tick_timeout.as_nanos() as u64 + 5_000_000_000;
        let mut next_keep = Instant::now();
        loop {
            match self.rx.recv_timeout(FORWARD) {
                Ok(Inbound::Sample { index, bytes }) => self.bridge.receive(index, &bytes)?,
                Ok(Inbound::Clock(_)) | Err(RecvTimeoutError::Timeout) => {}
                Ok(Inbound::End) => return Ok(()),
                Ok(Inbound::Abort(reason)) => return Err(Stopped::Aborted(reason).into()),
                Ok(Inbound::CoordinatorGone) => return Err(Stopped::CoordinatorGone.into()),
                Err(RecvTimeoutError::Disconnected) => anyhow::bail!("the Zenoh callbacks ended"),
            }
            self.bridge.forward()?;
            if Instant::now() >= next_keep {
                next_keep = Instant::now() + KEEP;
                if let Some(sig) = launch::termination_requested() {
                    return Err(launch::RunError::Interrupted(sig).into());
                }
                let now = shoal_runtime::mono_ns();
                let t_s = now.saturating_sub(epoch) as f64 * 1e-9;
                self.ports.keep_realtime(&self.procs, sup, t_s)?;
                anyhow::ensure!(
                    now <= late,
                    "the coordinator did not end the run {:.0} s after its end",
                    (now - end) as f64 * 1e-9
                );
            }
        }
    }

    /// Lockstep: follows the coordinator's clock to the end of the run.
    fn lockstep(&mut self, sup: &mut Supervisor) -> anyhow::Result<()> {
        let scenario = &self.scenario;
        let ticks = scenario.ticks();
        let tick_ns = (scenario.rates.tick_s * 1e9).round() as u64;
        let mut injections = launch::injections(scenario);
        injections.retain(|(_, f)| {
            self.procs.iter().any(|p| {
                self.local[p.index] && Some(p.kind) == f.process_kind() && p.vehicle == f.vehicle
            })
        });
        let mut next_injection = 0;
        let mut due = Vec::with_capacity(self.procs.len());
        let mut last_clock = Instant::now();
        let mut sim_s = 0.0;
        loop {
            let msg = match self.rx.recv_timeout(Duration::from_millis(50)) {
                Ok(m) => m,
                Err(RecvTimeoutError::Timeout) => {
                    if let Some(sig) = launch::termination_requested() {
                        return Err(launch::RunError::Interrupted(sig).into());
                    }
                    for d in sup.reap() {
                        self.ports.handle_death(d, &self.procs, sup, sim_s)?;
                    }
                    anyhow::ensure!(
                        last_clock.elapsed() <= self.tick_timeout,
                        "no clock from the coordinator for {:.0} s after t = {sim_s:.2} s",
                        self.tick_timeout.as_secs_f64()
                    );
                    continue;
                }
                Err(RecvTimeoutError::Disconnected) => anyhow::bail!("the Zenoh callbacks ended"),
            };
            match msg {
                Inbound::Sample { index, bytes } => self.bridge.receive(index, &bytes)?,
                Inbound::Clock(tick) => {
                    last_clock = Instant::now();
                    let sim = tick * tick_ns;
                    sim_s = sim as f64 / 1e9;
                    while next_injection < injections.len() && injections[next_injection].0 <= tick
                    {
                        launch::inject(
                            injections[next_injection].1,
                            &self.procs,
                            sup,
                            &mut self.ports.journal,
                            sim,
                        );
                        next_injection += 1;
                    }
                    due.clear();
                    due.extend(
                        self.procs
                            .iter()
                            .filter(|p| self.local[p.index] && p.due(tick))
                            .map(|p| p.index),
                    );
                    if !due.is_empty() {
                        self.ports
                            .start_tick(tick, ticks, tick_ns, &due, &self.procs)?;
                        launch::wait_done(
                            &mut self.ports,
                            sup,
                            &self.procs,
                            &due,
                            self.tick_timeout,
                            sim_s,
                            self.spin,
                        )?;
                    }
                    self.ports.recovery.track_truths();
                    self.bridge.forward()?;
                    self.fence
                        .put(wire::encode_tick(tick).to_vec())
                        .wait()
                        .map_err(|e| anyhow::anyhow!("zenoh fence: {e}"))?;
                }
                Inbound::End => return Ok(()),
                Inbound::Abort(reason) => return Err(Stopped::Aborted(reason).into()),
                Inbound::CoordinatorGone => return Err(Stopped::CoordinatorGone.into()),
            }
        }
    }
}
