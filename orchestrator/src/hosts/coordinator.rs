//! `shoal run --hosts FILE`: one run spread over the agents of a hosts
//! file. The coordinator runs no service process itself: it places the
//! group, hands each agent its share, drives the lockstep clock over Zenoh,
//! and gathers every host's recording, logs and statistics into the one
//! output directory a one-host run leaves.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use anyhow::Context;
use zenoh::Wait;

use super::placement::{HostsFile, Placement};
use super::wire::{self, FileChunk, HostOutcome, StartOrder, StartReply};
use crate::launch::{self, os as sys, RunError, RunOptions, RunOutcome};

/// Longest an agent may take to start its processes, s.
const START_TIMEOUT: Duration = Duration::from_secs(120);
/// Longest the agents of a hosts file may take to answer at all.
const AGENTS_TIMEOUT: Duration = Duration::from_secs(20);

/// What the coordinator's Zenoh callbacks hand its loop.
#[derive(Debug)]
enum Heard {
    Fence(usize, u64),
    Failed(usize, String),
    HostGone(String),
}

/// Why a run over hosts stopped.
#[derive(Debug, thiserror::Error)]
pub enum HostsError {
    /// An agent is not there.
    #[error("no agent answers as host(s) {missing:?} (expected at {endpoints:?}); agents that answer: {present:?}. Start `shoal host --listen <endpoint> --name <host>` on each{tls}")]
    AgentsMissing {
        /// Hosts that did not answer.
        missing: Vec<String>,
        /// Their endpoints.
        endpoints: Vec<String>,
        /// Hosts that did.
        present: Vec<String>,
        /// Over TLS: what a handshake with each missing host says.
        tls: String,
    },
    /// A host's agent went away during the run.
    #[error(
        "host {host} was lost at t = {sim_time_s:.2} s: its agent ended or the link to it is cut"
    )]
    HostLost {
        /// The host.
        host: String,
        /// Simulated time, s.
        sim_time_s: f64,
    },
    /// A host's share failed.
    #[error("host {host} failed at t = {sim_time_s:.2} s: {message}")]
    HostFailed {
        /// The host.
        host: String,
        /// Simulated time, s.
        sim_time_s: f64,
        /// What it said.
        message: String,
    },
    /// Hosts did not fence a tick in time.
    #[error("no progress for {timeout_s:.0} s at t = {sim_time_s:.2} s: still waiting for host(s) {waiting:?}")]
    Hung {
        /// Timeout, s.
        timeout_s: f64,
        /// Simulated time, s.
        sim_time_s: f64,
        /// Hosts that did not fence.
        waiting: Vec<String>,
    },
}

fn zerr(what: &'static str) -> impl Fn(zenoh::Error) -> anyhow::Error {
    move |e| anyhow::anyhow!("zenoh {what}: {e}")
}

/// Runs `opts.scenario` over the hosts of `hosts`.
pub fn run(opts: &RunOptions, hosts: &HostsFile) -> anyhow::Result<RunOutcome> {
    let scenario = &opts.scenario;
    let placement = Placement::new(hosts, scenario)?;
    std::fs::create_dir_all(opts.out.join("logs"))
        .with_context(|| format!("cannot create {}", opts.out.display()))?;
    let scenario_toml = scenario.to_toml()?;
    std::fs::write(opts.out.join("scenario.toml"), &scenario_toml)?;
    let effective_toml = crate::preflight::effective_toml(scenario)?;
    std::fs::write(
        opts.out.join("logs").join("effective-scenario.toml"),
        &effective_toml,
    )?;
    let _ = launch::termination_requested();
    let run_id = sys::random_id();
    let security = hosts.security()?;
    let me = match &security {
        super::tls::Security::Tls(id) => {
            let until = id
                .check()
                .context("the coordinator's certificate ([tls] of the hosts file)")?;
            tracing::info!(cert = %id.cert.display(), valid_until = %until, "certificate checked");
            id.name.clone()
        }
        super::tls::Security::Insecure => {
            tracing::warn!(
                "INSECURE: plain TCP to the hosts, no authentication, no access control"
            );
            format!("insecure coordinator (pid {})", std::process::id())
        }
    };
    let acl =
        super::tls::coordinator_acl(&run_id, &placement, &placement.crossings(scenario, &run_id));
    let session = zenoh::open(wire::coordinator_config(
        &placement.endpoints,
        &security,
        Some(&acl),
    )?)
    .wait()
    .map_err(zerr("session"))?;
    await_agents(&session, &placement, &security)?;
    // Each host's monotonic clock against this one's: realtime puts the
    // epoch on every host's clock with it, and samples' stamps move with it
    // from host to host.
    let offsets = measure_offsets(&session, &placement)?;
    for (h, o) in placement.hosts.iter().zip(&offsets) {
        tracing::info!(host = %h, offset_us = o.offset_ns as f64 / 1e3, error_us = o.error_ns as f64 / 1e3, "clock offset");
    }
    let epoch = opts
        .mode
        .wall_clock()
        .then(|| shoal_runtime::mono_ns() + launch::epoch_margin_ns(scenario.processes().len()));

    let (tx, rx) = mpsc::channel();
    let index_of: BTreeMap<String, usize> = placement
        .hosts
        .iter()
        .enumerate()
        .map(|(i, h)| (h.clone(), i))
        .collect();
    let fences = {
        let tx = tx.clone();
        let index_of = index_of.clone();
        session
            .declare_subscriber(wire::fence(&run_id, "*"))
            .callback(move |s| {
                let host = wire::last_chunk(s.key_expr().as_str());
                if let (Some(&h), Some(t)) = (
                    index_of.get(host),
                    wire::decode_tick(&s.payload().to_bytes()),
                ) {
                    let _ = tx.send(Heard::Fence(h, t));
                }
            })
            .wait()
            .map_err(zerr("fence subscriber"))?
    };
    let failures = {
        let tx = tx.clone();
        let index_of = index_of.clone();
        session
            .declare_subscriber(wire::failed(&run_id, "*"))
            .callback(move |s| {
                let host = wire::last_chunk(s.key_expr().as_str());
                if let Some(&h) = index_of.get(host) {
                    let text = String::from_utf8_lossy(&s.payload().to_bytes()).into_owned();
                    let _ = tx.send(Heard::Failed(h, text));
                }
            })
            .wait()
            .map_err(zerr("failure subscriber"))?
    };
    let lost = session
        .liveliness()
        .declare_subscriber(wire::ALL_ALIVE)
        .callback(move |s| {
            if s.kind() == zenoh::sample::SampleKind::Delete {
                if let Some(h) = wire::host_of_alive(s.key_expr().as_str()) {
                    let _ = tx.send(Heard::HostGone(h.to_string()));
                }
            }
        })
        .wait()
        .map_err(zerr("liveliness subscriber"))?;
    let _token = session
        .liveliness()
        .declare_token(wire::coordinator(&run_id))
        .wait()
        .map_err(zerr("liveliness token"))?;
    let block = zenoh::qos::CongestionControl::Block;
    let clock = session
        .declare_publisher(wire::clock(&run_id))
        .congestion_control(block)
        .wait()
        .map_err(zerr("clock publisher"))?;
    let abort = session
        .declare_publisher(wire::abort(&run_id))
        .congestion_control(block)
        .wait()
        .map_err(zerr("abort publisher"))?;
    let run_json = serde_json::json!({
        "run_id": run_id,
        "pid": std::process::id(),
        "mode": opts.mode.as_str(),
        "hosts": placement.hosts,
        "endpoints": placement.endpoints,
        "vehicle_host": placement.vehicle_host,
        "world_host": placement.world_host,
    });
    std::fs::write(
        opts.out.join("run.json"),
        serde_json::to_string_pretty(&run_json)?,
    )?;

    let order = |h: usize| StartOrder {
        run_id: run_id.clone(),
        host: h,
        placement: placement.clone(),
        scenario_toml: scenario_toml.clone(),
        effective_toml: effective_toml.clone(),
        mode: opts.mode,
        tick_timeout_s: opts.tick_timeout.as_secs_f64(),
        spin_us: opts.spin_us,
        epoch_mono_ns: epoch.map_or(0, |e| offsets[h].to_agent(e)),
        stamp_shift_ns: offsets
            .iter()
            .map(|from| offsets[h].offset_ns - from.offset_ns)
            .collect(),
        coordinator: me.clone(),
    };
    let (started, start_error) = start_all(&session, &placement, order);
    let mut driven = Driven::default();
    let result = match (start_error, epoch) {
        (Some(e), _) => Err(e),
        (None, None) => drive(opts, &placement, &clock, &rx, &mut driven),
        (None, Some(epoch)) => drive_realtime(opts, &placement, &rx, &mut driven, epoch),
    };
    if let Err(e) = &result {
        let msg = wire::AbortMsg {
            from: me.clone(),
            reason: format!("{e:#}"),
        };
        let _ = abort.put(serde_json::to_vec(&msg)?).wait();
    } else {
        clock.put(Vec::<u8>::new()).wait().map_err(zerr("clock"))?;
    }
    // Every started host's outcome and files, also after a failure (its
    // logs say why); a lost host has none to give.
    let gone = driven.gone.clone();
    // Read again at the end: how far the clocks drifted over the run.
    let offsets_after = if gone.is_empty() {
        measure_offsets(&session, &placement).ok()
    } else {
        None
    };
    let mut outcomes = Vec::new();
    // A host that ran to the end but whose files did not all come back:
    // the run fails (its recording would lack that host) once the rest is
    // filed.
    let mut uncollected: Vec<String> = Vec::new();
    for h in started.iter().copied().filter(|h| !gone.contains(h)) {
        let host = &placement.hosts[h];
        let mut tries = 0;
        let got = loop {
            tries += 1;
            match collect(&session, host, &run_id, &opts.out) {
                Err(e) if tries < COLLECT_TRIES => {
                    tracing::warn!("collecting host {host}: {e:#}; asking again")
                }
                got => break got,
            }
        };
        match got {
            Ok(o) => {
                release(&session, host, &run_id);
                outcomes.push(o);
            }
            Err(e) => {
                let e = format!("cannot collect host {host}: {e:#}");
                tracing::warn!("{e}");
                uncollected.push(e);
            }
        }
    }
    drop((fences, failures, lost));
    let recording = opts.out.join("recording.mcap");
    let parts: Vec<std::path::PathBuf> = placement
        .hosts
        .iter()
        .map(|h| opts.out.join("parts").join(format!("{h}.mcap")))
        .filter(|p| p.is_file())
        .collect();
    // What joining costs (the choice of one recorder per host joined at the
    // end, against one recorder taking every channel over Zenoh).
    let parts_bytes: Vec<u64> = parts
        .iter()
        .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
        .collect();
    let join_start = Instant::now();
    let joined = if parts.is_empty() {
        Err(anyhow::anyhow!("no host sent a recording"))
    } else {
        let inputs: Vec<&Path> = parts.iter().map(|p| p.as_path()).collect();
        recordings::join_hosts(&inputs, &recording)
            .with_context(|| format!("cannot join the hosts' recordings {parts:?}"))
            .map(|r| {
                tracing::info!(
                    parts = parts.len(),
                    messages = r.messages,
                    "joined the hosts' recordings"
                );
                let _ = std::fs::remove_dir_all(opts.out.join("parts"));
            })
    };
    let join_s = join_start.elapsed().as_secs_f64();
    // What each host did, for users and `shoal bench hosts`.
    let per_host: Vec<serde_json::Value> = outcomes
        .iter()
        .map(|o| {
            serde_json::json!({
                "host": o.host,
                "processes": o.usage.len(),
                "cpu_s": o.usage.iter().map(|u| u.cpu_s).sum::<f64>(),
                "agent_cpu_s": o.agent_cpu_s,
                "bridged_out": o.bridged_out,
                "bridged_in": o.bridged_in,
                "bridge_lost": o.bridge_lost,
                "leftover_shm": o.leftover_shm,
                "error": o.error,
            })
        })
        .collect();
    let clock: Vec<serde_json::Value> = placement
        .hosts
        .iter()
        .enumerate()
        .map(|(h, name)| {
            let us = |o: Option<&wire::ClockOffset>| {
                o.map(|o| {
                    serde_json::json!({
                        "offset_us": o.offset_ns as f64 / 1e3,
                        "error_us": o.error_ns as f64 / 1e3,
                    })
                })
            };
            serde_json::json!({
                "host": name,
                "start": us(offsets.get(h)),
                "end": us(offsets_after.as_ref().and_then(|a| a.get(h))),
            })
        })
        .collect();
    let _ = std::fs::write(
        opts.out.join("hosts.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "run_id": run_id,
            "mode": opts.mode.as_str(),
            "hosts": per_host,
            "recording": {
                "parts_bytes": parts_bytes,
                "joined_bytes": std::fs::metadata(&recording).map_or(0, |m| m.len()),
                "join_s": join_s,
            },
            "clock": {
                "method": CLOCK_METHOD,
                "readings_per_host": CLOCK_READINGS,
                "hosts": clock,
            },
        }))
        .unwrap_or_default(),
    );
    let wall_time_s = result?;
    joined?;
    if let Some(e) = uncollected.first() {
        anyhow::bail!("{e}");
    }
    for o in &outcomes {
        if let Some(e) = &o.error {
            anyhow::bail!("host {} failed: {e}", o.host);
        }
        if o.leftover_shm > 0 {
            tracing::warn!(host = %o.host, files = o.leftover_shm, "shared memory left on the host");
        }
        if o.bridge_lost > 0 {
            tracing::warn!(host = %o.host, lost = o.bridge_lost, "the bridge lost samples");
        }
    }
    let usage: Vec<_> = outcomes.iter().flat_map(|o| o.usage.clone()).collect();
    let stats: Vec<_> = outcomes.iter().flat_map(|o| o.stats.clone()).collect();
    let (mut cpu_time_s, max_rss_kib) = launch::usage_by_kind(&usage, &stats);
    cpu_time_s.insert("orchestrator".into(), sys::self_cpu_s());
    cpu_time_s.insert(
        "host-agent".into(),
        outcomes.iter().map(|o| o.agent_cpu_s).sum(),
    );
    let mut events: Vec<serde_json::Value> =
        outcomes.iter().flat_map(|o| o.events.clone()).collect();
    events.sort_by(|a, b| {
        let t = |v: &serde_json::Value| v.get("t_s").and_then(|t| t.as_f64()).unwrap_or(0.0);
        t(a).total_cmp(&t(b))
    });
    Ok(RunOutcome {
        run_id,
        recording,
        wall_time_s,
        sim_time_s: driven.ticks as f64 * scenario.rates.tick_s,
        cpu_time_s,
        max_rss_kib,
        processes: outcomes.iter().map(|o| o.usage.len()).sum(),
        ticks: driven.ticks,
        stats,
        events,
    })
}

/// Clock readings per host and measurement.
const CLOCK_READINGS: usize = 16;

/// How the hosts' clocks agree, as `hosts.json` says.
const CLOCK_METHOD: &str = "each host's monotonic clock against the coordinator's, from the fastest of the query round trips (Cristian); the true offset lies within error_us of offset_us. Realtime runs start every host at the coordinator's epoch put on the host's own clock by its offset; bridged samples' stamps move by the difference of the two hosts' offsets";

/// Reads every agent's monotonic clock [`CLOCK_READINGS`] times.
fn measure_offsets(
    session: &zenoh::Session,
    placement: &Placement,
) -> anyhow::Result<Vec<wire::ClockOffset>> {
    placement
        .hosts
        .iter()
        .map(|host| {
            let mut readings = Vec::with_capacity(CLOCK_READINGS);
            for _ in 0..CLOCK_READINGS {
                let sent_ns = shoal_runtime::mono_ns();
                let replies = session
                    .get(wire::time(host))
                    .consolidation(zenoh::query::ConsolidationMode::None)
                    .timeout(Duration::from_secs(2))
                    .wait()
                    .map_err(zerr("clock query"))?;
                let Ok(reply) = replies.recv() else { continue };
                let received_ns = shoal_runtime::mono_ns();
                if let Some(agent_ns) = reply
                    .result()
                    .ok()
                    .and_then(|s| wire::decode_tick(&s.payload().to_bytes()))
                {
                    readings.push(wire::ClockReading {
                        sent_ns,
                        agent_ns,
                        received_ns,
                    });
                }
            }
            wire::ClockOffset::estimate(&readings)
                .with_context(|| format!("host {host} did not answer a clock reading"))
        })
        .collect()
}

/// Waits until an agent answers as every host of the placement.
fn await_agents(
    session: &zenoh::Session,
    placement: &Placement,
    security: &super::tls::Security,
) -> anyhow::Result<()> {
    let start = Instant::now();
    loop {
        let replies = session
            .liveliness()
            .get(wire::ALL_ALIVE)
            .timeout(Duration::from_secs(2))
            .wait()
            .map_err(zerr("liveliness query"))?;
        let mut present = Vec::new();
        while let Ok(r) = replies.recv() {
            if let Ok(s) = r.result() {
                if let Some(h) = wire::host_of_alive(s.key_expr().as_str()) {
                    present.push(h.to_string());
                }
            }
        }
        let missing: Vec<String> = placement
            .hosts
            .iter()
            .filter(|h| !present.contains(h))
            .cloned()
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        if start.elapsed() > AGENTS_TIMEOUT {
            let endpoints: Vec<String> = missing
                .iter()
                .filter_map(|m| placement.hosts.iter().position(|h| h == m))
                .map(|i| placement.endpoints[i].clone())
                .collect();
            present.sort();
            // Over TLS, a handshake of our own says what the link's did not.
            let tls: Vec<String> = match security {
                super::tls::Security::Tls(id) => endpoints
                    .iter()
                    .zip(&missing)
                    .map(|(e, h)| format!("\n  {h} at {e}: {}", super::tls::probe(e, id)))
                    .collect(),
                super::tls::Security::Insecure => Vec::new(),
            };
            return Err(HostsError::AgentsMissing {
                missing,
                endpoints,
                present,
                tls: tls.concat(),
            }
            .into());
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Hands every host its share; returns the hosts that started, and the
/// first failure.
fn start_all(
    session: &zenoh::Session,
    placement: &Placement,
    order: impl Fn(usize) -> StartOrder,
) -> (Vec<usize>, Option<anyhow::Error>) {
    let mut pending = Vec::new();
    let mut error = None;
    for (h, name) in placement.hosts.iter().enumerate() {
        let sent = serde_json::to_vec(&order(h))
            .map_err(anyhow::Error::from)
            .and_then(|payload| {
                session
                    .get(wire::start(name))
                    .payload(payload)
                    // Each reply as it comes (the default holds them to the end).
                    .consolidation(zenoh::query::ConsolidationMode::None)
                    .timeout(START_TIMEOUT)
                    .wait()
                    .map_err(zerr("start query"))
            });
        match sent {
            Ok(replies) => pending.push((h, replies)),
            Err(e) => {
                error.get_or_insert(e);
            }
        }
    }
    let mut started = Vec::new();
    for (h, replies) in pending {
        let name = &placement.hosts[h];
        match replies.recv() {
            Ok(r) => match r.result() {
                Ok(s) => {
                    started.push(h);
                    match serde_json::from_slice::<StartReply>(&s.payload().to_bytes()) {
                        Ok(reply) => tracing::info!(
                            host = %name,
                            processes = reply.processes,
                            exports = reply.exports,
                            imports = reply.imports,
                            "host started"
                        ),
                        Err(e) => {
                            error.get_or_insert(anyhow::anyhow!("host {name}: bad reply: {e}"));
                        }
                    }
                }
                Err(e) => {
                    // It failed before its processes ran, but may hold files.
                    started.push(h);
                    let text = String::from_utf8_lossy(&e.payload().to_bytes()).into_owned();
                    error.get_or_insert(anyhow::anyhow!("host {name} cannot start: {text}"));
                }
            },
            Err(_) => {
                error.get_or_insert(anyhow::anyhow!(
                    "host {name} did not answer the start within {} s",
                    START_TIMEOUT.as_secs()
                ));
            }
        }
    }
    (started, error)
}

/// What the lockstep loop saw.
#[derive(Debug, Default)]
struct Driven {
    ticks: u64,
    gone: Vec<usize>,
}

impl Driven {
    /// The error `heard` is, at simulated time `sim_s`, if it is one (a
    /// lost host is noted: it has nothing left to collect).
    fn stop_cause(
        &mut self,
        heard: Heard,
        placement: &Placement,
        sim_s: f64,
    ) -> Option<HostsError> {
        match heard {
            Heard::Fence(..) => None,
            Heard::Failed(h, message) => Some(HostsError::HostFailed {
                host: placement.hosts[h].clone(),
                sim_time_s: sim_s,
                message,
            }),
            Heard::HostGone(name) => {
                let h = placement.hosts.iter().position(|x| *x == name)?;
                self.gone.push(h);
                Some(HostsError::HostLost {
                    host: name,
                    sim_time_s: sim_s,
                })
            }
        }
    }
}

/// Realtime: waits out the run from `epoch` (the coordinator's clock; every
/// host runs on its own clock from the same instant), watching for a
/// failed or lost host; returns the run's length, s.
fn drive_realtime(
    opts: &RunOptions,
    placement: &Placement,
    rx: &Receiver<Heard>,
    driven: &mut Driven,
    epoch: u64,
) -> anyhow::Result<f64> {
    let scenario = &opts.scenario;
    let end = epoch + (scenario.duration_s * 1e9) as u64;
    let bar = crate::progress::bar(
        opts.progress,
        scenario.duration_s.ceil() as u64,
        "s simulated",
    );
    loop {
        let now = shoal_runtime::mono_ns();
        if now >= end {
            break;
        }
        let t_s = now.saturating_sub(epoch) as f64 * 1e-9;
        let wait = Duration::from_nanos(end - now).min(Duration::from_millis(100));
        match rx.recv_timeout(wait) {
            Ok(heard) => {
                if let Some(e) = driven.stop_cause(heard, placement, t_s) {
                    return Err(e.into());
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => anyhow::bail!("the Zenoh callbacks ended"),
        }
        if let Some(sig) = launch::termination_requested() {
            return Err(RunError::Interrupted(sig).into());
        }
        bar.set_position(t_s as u64);
    }
    bar.finish_and_clear();
    driven.ticks = (scenario.duration_s / scenario.rates.tick_s).round() as u64;
    Ok((end - epoch) as f64 * 1e-9)
}

/// Drives the clock to the end of the run; returns the wall time, s.
fn drive(
    opts: &RunOptions,
    placement: &Placement,
    clock: &zenoh::pubsub::Publisher<'_>,
    rx: &Receiver<Heard>,
    driven: &mut Driven,
) -> anyhow::Result<f64> {
    let scenario = &opts.scenario;
    let procs = scenario.processes();
    let ticks = scenario.ticks();
    let tick_ns = (scenario.rates.tick_s * 1e9).round() as u64;
    let k = placement.len();
    let bar = crate::progress::bar(
        opts.progress,
        scenario.duration_s.ceil() as u64,
        "s simulated",
    );
    let start = Instant::now();
    let mut fenced = vec![false; k];
    for tick in 0..ticks {
        if !procs.iter().any(|p| p.due(tick)) {
            continue;
        }
        let sim_s = (tick * tick_ns) as f64 / 1e9;
        if let Some(pace) = opts.pace {
            // Paced (`--pace`): no tick before its simulated time, scaled.
            let due_at = start + Duration::from_secs_f64(sim_s / pace);
            if let Some(wait) = due_at.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        clock
            .put(wire::encode_tick(tick).to_vec())
            .wait()
            .map_err(zerr("clock"))?;
        fenced.fill(false);
        let mut remaining = k;
        let since = Instant::now();
        while remaining > 0 {
            match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(Heard::Fence(h, t)) if t == tick => {
                    if !fenced[h] {
                        fenced[h] = true;
                        remaining -= 1;
                    }
                }
                Ok(heard) => {
                    if let Some(e) = driven.stop_cause(heard, placement, sim_s) {
                        return Err(e.into());
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => anyhow::bail!("the Zenoh callbacks ended"),
            }
            if let Some(sig) = launch::termination_requested() {
                return Err(RunError::Interrupted(sig).into());
            }
            if since.elapsed() > opts.tick_timeout {
                return Err(HostsError::Hung {
                    timeout_s: opts.tick_timeout.as_secs_f64(),
                    sim_time_s: sim_s,
                    waiting: (0..k)
                        .filter(|&h| !fenced[h])
                        .map(|h| placement.hosts[h].clone())
                        .collect(),
                }
                .into());
            }
        }
        driven.ticks = tick + 1;
        if tick % 50 == 0 {
            bar.set_position(sim_s as u64);
        }
    }
    bar.finish_and_clear();
    driven.ticks = ticks;
    Ok(start.elapsed().as_secs_f64())
}

/// Times a host is asked for its files before the run fails.
const COLLECT_TRIES: usize = 3;

/// Tells `host` that its files of run `run_id` are all here: it drops them
/// and closes its session (not before, or replies on their way are lost).
fn release(session: &zenoh::Session, host: &str, run_id: &str) {
    let replies = session
        .get(wire::release(host, run_id))
        .timeout(Duration::from_secs(10))
        .wait();
    match replies.map(|r| r.recv()) {
        Ok(Ok(r)) if r.result().is_ok() => {}
        _ => tracing::warn!("host {host} did not confirm the release of its files"),
    }
}

/// Takes host `host`'s outcome and files into `out`: its recording as
/// `parts/<host>.mcap`, its logs into `logs/`.
fn collect(
    session: &zenoh::Session,
    host: &str,
    run_id: &str,
    out: &Path,
) -> anyhow::Result<HostOutcome> {
    let replies = session
        .get(wire::finish(host, run_id))
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(Duration::from_secs(300))
        .wait()
        .map_err(zerr("finish query"))?;
    let mut outcome: Option<HostOutcome> = None;
    let mut files: BTreeMap<String, std::fs::File> = BTreeMap::new();
    // Per file sent: (bytes received, the whole file's size).
    let mut received: BTreeMap<String, (u64, u64)> = BTreeMap::new();
    while let Ok(r) = replies.recv() {
        let s = match r.result() {
            Ok(s) => s,
            Err(e) => anyhow::bail!(
                "host {host}: {}",
                String::from_utf8_lossy(&e.payload().to_bytes())
            ),
        };
        let bytes = s.payload().to_bytes();
        let Some(att) = s.attachment() else {
            outcome = Some(serde_json::from_slice(&bytes).context("a host's outcome")?);
            continue;
        };
        let chunk: FileChunk = serde_json::from_slice(&att.to_bytes()).context("a file chunk")?;
        let rel = Path::new(&chunk.path);
        anyhow::ensure!(
            rel.components()
                .all(|c| matches!(c, std::path::Component::Normal(_))),
            "host {host} sent a file outside the run: {}",
            chunk.path
        );
        let got = received
            .entry(chunk.path.clone())
            .or_insert((0, chunk.total));
        got.0 += bytes.len() as u64;
        let target = if chunk.path == "recording.mcap" {
            out.join("parts").join(format!("{host}.mcap"))
        } else if chunk.path.starts_with("logs/") && !chunk.path.ends_with(".toml") {
            out.join(rel)
        } else {
            continue;
        };
        use std::io::{Seek, SeekFrom, Write};
        if !files.contains_key(&chunk.path) {
            if let Some(d) = target.parent() {
                std::fs::create_dir_all(d)?;
            }
            let f = std::fs::File::create(&target)
                .with_context(|| format!("cannot create {}", target.display()))?;
            files.insert(chunk.path.clone(), f);
        }
        if let Some(f) = files.get_mut(&chunk.path) {
            f.seek(SeekFrom::Start(chunk.offset))?;
            f.write_all(&bytes)?;
        }
    }
    let outcome = outcome.with_context(|| format!("host {host} sent no outcome"))?;
    // Every file the host announced, whole: a piece lost on the way would
    // otherwise leave a recording that silently lacks what it held.
    for path in &outcome.files {
        match received.get(path) {
            Some(&(got, total)) if got == total => {}
            Some(&(got, total)) => {
                anyhow::bail!("host {host} sent {got} of the {total} bytes of {path}")
            }
            None => anyhow::bail!("host {host} announced {path} but never sent it"),
        }
    }
    Ok(outcome)
}
