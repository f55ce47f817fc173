//! The shoal cases: the same ping-pong through shoal's runtime, paying
//! what a service pays per sample: the run domain's node, the typed ports
//! with a per-vehicle channel's limits ([`ChannelLimits::vehicle`]), header
//! stamping and the finite check on publish, the finite check, sequence
//! accounting and latency histogram on take, and (blocking case) the
//! runtime's event service (`open_wake`) and a `WaitSet`, as a dataflow
//! stage waits on its inputs.

use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use ipc_types::bench::{bench_service_name, BenchDirection};
use ipc_types::Sample;
use shoal_runtime::ports::Origin;
use shoal_runtime::{ChannelLimits, Mode, Publisher, StepContext, Subscriber};

use crate::driver::{run_pinger, run_ponger, Served};
use crate::payload::Payload;
use crate::wait::{check_run, notify, wait_error, Backoff};
use crate::{cause, BenchError, Case, PeerConfig, PeerReport, PongReport};

/// Subscriber buffer of the bench channels (a service's usual depth).
const BUFFER: usize = 2;

/// The ports of one shoal peer.
struct Ports<S: Sample> {
    // The node must outlive its ports; kept here for that.
    _node: Node<ipc::Service>,
    tx: Publisher<S>,
    rx: Subscriber<S>,
    /// Wake events of the blocking case: the peer's / this process's own.
    events: Option<(Notifier<ipc::Service>, Listener<ipc::Service>)>,
}

fn open<S: Sample + Payload>(cfg: &PeerConfig, ping: bool) -> Result<Ports<S>, BenchError> {
    let (me, peer, out_dir, in_dir) = if ping {
        (
            "pinger",
            "ponger",
            BenchDirection::Ping,
            BenchDirection::Pong,
        )
    } else {
        (
            "ponger",
            "pinger",
            BenchDirection::Pong,
            BenchDirection::Ping,
        )
    };
    let vehicle = format!("bench-{}-{}", cfg.case.name(), cfg.size);
    let node = shoal_runtime::domain_node(&cfg.run_id, &format!("{vehicle}/{me}"))?;
    // A per-vehicle channel's limits; a camera frame's for the large sizes.
    let limits = if S::SIZE > 4096 {
        ChannelLimits::image()
    } else {
        ChannelLimits::vehicle()
    };
    let case = cfg.case.name();
    let tx = shoal_runtime::node_publisher::<S, _>(
        &node,
        &bench_service_name(&cfg.run_id, case, cfg.size, out_dir),
        &limits,
    )?;
    let rx = shoal_runtime::node_subscriber::<S, _>(
        &node,
        &bench_service_name(&cfg.run_id, case, cfg.size, in_dir),
        &limits,
        BUFFER,
    )?;
    let events = if cfg.case == Case::ShoalEvent {
        let notifier = shoal_runtime::open_wake(&node, &cfg.run_id, &vehicle, peer)?
            .notifier_builder()
            .create()
            .map_err(|e| BenchError::setup("the peer's wake notifier")(cause(e)))?;
        let listener = shoal_runtime::open_wake(&node, &cfg.run_id, &vehicle, me)?
            .listener_builder()
            .create()
            .map_err(|e| BenchError::setup("the wake listener")(cause(e)))?;
        Some((notifier, listener))
    } else {
        None
    };
    Ok(Ports {
        _node: node,
        tx,
        rx,
        events,
    })
}

/// A step context as the realtime loop builds one on each wake-up.
fn context(tick: u64) -> StepContext {
    let now = shoal_runtime::mono_ns();
    StepContext {
        sim_time_ns: now,
        tick,
        wake_mono_ns: now,
        since_last_ns: 0,
        last: false,
        mode: Mode::Realtime,
        woken_by: shoal_runtime::Wake::Tick,
    }
}

/// True for the sizes a service moves in place: from 4 KiB (the world
/// snapshot, 20 KB, and camera frames are the services' only samples that
/// large); smaller ones go by value, copied once each way, as every
/// per-vehicle sample (448 B at most) does.
fn in_place<S: Payload>() -> bool {
    S::SIZE >= 4096
}

/// Publishes the message of `round` with `origin`.
fn publish<S: Sample + Payload>(
    tx: &mut Publisher<S>,
    ctx: &StepContext,
    origin: Origin,
    round: u64,
) -> Result<(), BenchError> {
    if in_place::<S>() {
        tx.publish_in_place(ctx, origin, |s| s.fill(round))?;
    } else {
        tx.publish(S::make(round), ctx, origin)?;
    }
    Ok(())
}

/// Calls `f` on every ready sample: in place for the large sizes, on a
/// copy for the small ones.
fn take<S: Sample + Payload>(
    rx: &mut Subscriber<S>,
    ctx: &StepContext,
    mut f: impl FnMut(&S),
) -> Result<(), BenchError> {
    if in_place::<S>() {
        rx.take_ready_in_place(ctx, f)?;
    } else {
        rx.take_ready(ctx, |s| f(&s))?;
    }
    Ok(())
}

/// Takes every ready sample; returns whether the one of `round`, if any,
/// is intact.
fn take_round<S: Sample + Payload>(
    rx: &mut Subscriber<S>,
    ctx: &StepContext,
    round: u64,
) -> Result<Option<bool>, BenchError> {
    let mut found = None;
    take(rx, ctx, |s| {
        if s.round() == round {
            found = Some(s.check(round));
        }
    })?;
    Ok(found)
}

/// Answers every ready sample after checking it; the reply keeps the
/// ping's origin, as a downstream service keeps its input's.
fn echo_all<S: Sample + Payload>(
    rx: &mut Subscriber<S>,
    tx: &mut Publisher<S>,
    ctx: &StepContext,
) -> Result<Served, BenchError> {
    let mut served = Served::default();
    let mut failure = None;
    take(rx, ctx, |s| {
        if failure.is_some() {
            return;
        }
        let round = s.round();
        if !s.check(round) {
            failure = Some(BenchError::Corrupt { round });
            return;
        }
        match publish(tx, ctx, Origin::of(s.header()), round) {
            Ok(()) => served.add(round),
            Err(e) => failure = Some(e),
        }
    })?;
    match failure {
        Some(e) => Err(e),
        None => Ok(served),
    }
}

fn waitset() -> Result<WaitSet<ipc::Service>, BenchError> {
    WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| BenchError::setup("a wait set")(cause(e)))
}

/// The pinger of a shoal case. It is the "sensor": each ping starts a new
/// causal chain ([`Origin::here`]).
pub(crate) fn ping<S: Sample + Payload>(cfg: &PeerConfig) -> Result<PeerReport, BenchError> {
    let mut ports = open::<S>(cfg, true)?;
    let Ports { tx, rx, events, .. } = &mut ports;
    let timeout = cfg.timeout();
    let ctx = context(0);
    let mut send = |round: u64| publish(tx, &ctx, Origin::here(&ctx), round);
    match events {
        Some((notifier, listener)) => {
            let waitset = waitset()?;
            let guard = waitset
                .attach_notification(&*listener)
                .map_err(|e| BenchError::setup("a wait set attachment")(cause(e)))?;
            let mut tick = 0u64;
            run_pinger(
                cfg,
                S::SIZE,
                |round| {
                    send(round)?;
                    notify(notifier)
                },
                |round, limit| loop {
                    let mut found = None;
                    let mut failure = None;
                    let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
                        if !id.has_event_from(&guard) {
                            return CallbackProgression::Continue;
                        }
                        let mut woken = false;
                        let _ = listener.try_wait(|_| woken = true);
                        if !woken {
                            return CallbackProgression::Continue;
                        }
                        tick += 1;
                        let ctx = context(tick);
                        match take_round(rx, &ctx, round) {
                            Ok(m) => found = found.or(m),
                            Err(e) => failure = Some(e),
                        }
                        CallbackProgression::Continue
                    };
                    let r = waitset
                        .wait_and_process_once_with_timeout(
                            on_event,
                            limit.unwrap_or(Duration::MAX),
                        )
                        .map_err(wait_error)?;
                    check_run(r)?;
                    if let Some(e) = failure {
                        return Err(e);
                    }
                    if found.is_some() || limit.is_some() {
                        return Ok(found);
                    }
                },
            )
        }
        None => run_pinger(cfg, S::SIZE, send, |round, limit| {
            let mut backoff = Backoff::new(limit.unwrap_or(timeout), "a polled reply");
            loop {
                if let Some(m) = take_round(rx, &ctx, round)? {
                    return Ok(Some(m));
                }
                if let Err(e) = backoff.snooze() {
                    return match (e, limit) {
                        (BenchError::Timeout { .. }, Some(_)) => Ok(None),
                        (e, _) => Err(e),
                    };
                }
            }
        }),
    }
}

/// The ponger of a shoal case.
pub(crate) fn pong<S: Sample + Payload>(cfg: &PeerConfig) -> Result<PongReport, BenchError> {
    let mut ports = open::<S>(cfg, false)?;
    let Ports { tx, rx, events, .. } = &mut ports;
    match events {
        Some((notifier, listener)) => {
            let waitset = waitset()?;
            let guard = waitset
                .attach_notification(&*listener)
                .map_err(|e| BenchError::setup("a wait set attachment")(cause(e)))?;
            let mut tick = 0u64;
            run_ponger(cfg.warmup, || {
                let mut served = Served::default();
                let mut failure = None;
                // The body of the runtime's run loop: drain the wake event, build
                // the step context, step (take + publish), then notify.
                let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
                    if !id.has_event_from(&guard) {
                        return CallbackProgression::Continue;
                    }
                    let mut woken = false;
                    let _ = listener.try_wait(|_| woken = true);
                    if !woken {
                        return CallbackProgression::Continue;
                    }
                    tick += 1;
                    let ctx = context(tick);
                    let step = echo_all(rx, tx, &ctx).and_then(|s| {
                        if s.echoed > 0 {
                            notify(notifier)?;
                        }
                        Ok(s)
                    });
                    match step {
                        Ok(s) => {
                            served.merge(s);
                            CallbackProgression::Continue
                        }
                        Err(e) => {
                            failure = Some(e);
                            CallbackProgression::Stop
                        }
                    }
                };
                let r = waitset
                    .wait_and_process_once(on_event)
                    .map_err(wait_error)?;
                check_run(r)?;
                match failure {
                    Some(e) => Err(e),
                    None => Ok(served),
                }
            })
        }
        None => {
            let timeout = cfg.timeout();
            let ctx = context(0);
            run_ponger(cfg.warmup, || {
                let mut backoff = Backoff::new(timeout, "the next ping");
                loop {
                    let served = echo_all(rx, tx, &ctx)?;
                    if served.echoed > 0 {
                        return Ok(served);
                    }
                    backoff.snooze()?;
                }
            })
        }
    }
}
