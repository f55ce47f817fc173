//! The raw iceoryx2 cases: only iceoryx2's own API on the path, with its
//! default service settings, the way its examples and benchmarks use it.

use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use ipc_types::bench::{bench_event_name, bench_service_name, BenchDirection};

use crate::driver::{run_pinger, run_ponger, Served};
use crate::payload::Payload;
use crate::wait::{check_run, notify, wait_error, Backoff};
use crate::{cause, raw_config, BenchError, Case, PeerConfig, PeerReport, PongReport};

/// The ports of one raw peer.
struct Ports<M: Payload + ZeroCopySend> {
    // The node must outlive its ports; kept here for that.
    _node: Node<ipc::Service>,
    tx: Publisher<ipc::Service, M, ()>,
    rx: Subscriber<ipc::Service, M, ()>,
    /// Event ports of the blocking cases: wakes the peer / is woken.
    events: Option<(Notifier<ipc::Service>, Listener<ipc::Service>)>,
}

fn open<M: Payload + ZeroCopySend>(cfg: &PeerConfig, ping: bool) -> Result<Ports<M>, BenchError> {
    let config = raw_config(&cfg.run_id);
    let node = NodeBuilder::new()
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| BenchError::setup("the raw iceoryx2 node")(cause(e)))?;
    let (out_dir, in_dir) = if ping {
        (BenchDirection::Ping, BenchDirection::Pong)
    } else {
        (BenchDirection::Pong, BenchDirection::Ping)
    };
    let case = cfg.case.name();
    let pubsub = |dir| {
        let name = bench_service_name(&cfg.run_id, case, cfg.size, dir);
        let service_name =
            ServiceName::new(&name).map_err(|e| BenchError::setup(name.clone())(cause(e)))?;
        node.service_builder(&service_name)
            .publish_subscribe::<M>()
            .open_or_create()
            .map_err(|e| BenchError::setup(name)(cause(e)))
    };
    let tx = pubsub(out_dir)?
        .publisher_builder()
        .create()
        .map_err(|e| BenchError::setup("a raw publisher")(cause(e)))?;
    let rx = pubsub(in_dir)?
        .subscriber_builder()
        .create()
        .map_err(|e| BenchError::setup("a raw subscriber")(cause(e)))?;
    let events = if cfg.case == Case::IoxPoll {
        None
    } else {
        let event = |dir| {
            let name = bench_event_name(&cfg.run_id, case, cfg.size, dir);
            let service_name =
                ServiceName::new(&name).map_err(|e| BenchError::setup(name.clone())(cause(e)))?;
            node.service_builder(&service_name)
                .event()
                .open_or_create()
                .map_err(|e| BenchError::setup(name)(cause(e)))
        };
        let notifier = event(out_dir)?
            .notifier_builder()
            .create()
            .map_err(|e| BenchError::setup("a raw notifier")(cause(e)))?;
        let listener = event(in_dir)?
            .listener_builder()
            .create()
            .map_err(|e| BenchError::setup("a raw listener")(cause(e)))?;
        Some((notifier, listener))
    };
    Ok(Ports {
        _node: node,
        tx,
        rx,
        events,
    })
}

/// Loans a sample, writes the message of `round` in place and sends it.
fn send<M: Payload + ZeroCopySend>(
    tx: &Publisher<ipc::Service, M, ()>,
    round: u64,
) -> Result<(), BenchError> {
    let sample = tx.loan_uninit().map_err(|e| BenchError::Io {
        what: "loan",
        source: cause(e),
    })?;
    #[allow(unsafe_code)]
    // SAFETY: `M: Pod`, so any bytes are a valid `M`, and the chunk is
    // initialised shared memory (zero-filled by the OS at creation, then
    // only ever written with whole samples).
    let mut sample = unsafe { sample.assume_init() };
    sample.payload_mut().fill(round);
    sample.send().map(|_| ()).map_err(|e| BenchError::Io {
        what: "send",
        source: cause(e),
    })
}

/// Takes every waiting sample; returns whether the one of `round`, if any,
/// is intact (checked in place).
fn take_round<M: Payload + ZeroCopySend>(
    rx: &Subscriber<ipc::Service, M, ()>,
    round: u64,
) -> Result<Option<bool>, BenchError> {
    let mut found = None;
    while let Some(s) = rx.receive().map_err(|e| BenchError::Io {
        what: "receive",
        source: cause(e),
    })? {
        if s.round() == round {
            found = Some(s.check(round));
        }
    }
    Ok(found)
}

/// Answers every waiting sample: checks it in place, then writes the reply
/// of its round into a loaned sample.
fn echo_all<M: Payload + ZeroCopySend>(
    rx: &Subscriber<ipc::Service, M, ()>,
    tx: &Publisher<ipc::Service, M, ()>,
) -> Result<Served, BenchError> {
    let mut served = Served::default();
    while let Some(s) = rx.receive().map_err(|e| BenchError::Io {
        what: "receive",
        source: cause(e),
    })? {
        let round = s.round();
        if !s.check(round) {
            return Err(BenchError::Corrupt { round });
        }
        drop(s);
        send(tx, round)?;
        served.add(round);
    }
    Ok(served)
}

/// The pinger of a raw case.
pub(crate) fn ping<M: Payload + ZeroCopySend>(cfg: &PeerConfig) -> Result<PeerReport, BenchError> {
    let ports = open::<M>(cfg, true)?;
    let Ports { tx, rx, events, .. } = &ports;
    let timeout = cfg.timeout();
    match (cfg.case, events) {
        (Case::IoxEvent, Some((notifier, listener))) => run_pinger(
            cfg,
            M::SIZE,
            |round| {
                send(tx, round)?;
                notify(notifier)
            },
            |round, limit| loop {
                match limit {
                    None => listener.blocking_wait(|_| {}),
                    Some(t) => listener.timed_wait(|_| {}, t),
                }
                .map_err(wait_error)?;
                if let Some(m) = take_round(rx, round)? {
                    return Ok(Some(m));
                }
                if limit.is_some() {
                    return Ok(None);
                }
            },
        ),
        (Case::IoxWaitset, Some((notifier, listener))) => {
            let waitset = WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
                .create::<ipc::Service>()
                .map_err(|e| BenchError::setup("a wait set")(cause(e)))?;
            let guard = waitset
                .attach_notification(listener)
                .map_err(|e| BenchError::setup("a wait set attachment")(cause(e)))?;
            run_pinger(
                cfg,
                M::SIZE,
                |round| {
                    send(tx, round)?;
                    notify(notifier)
                },
                |round, limit| loop {
                    let mut found = None;
                    let mut failure = None;
                    let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
                        if id.has_event_from(&guard) {
                            let _ = listener.try_wait(|_| {});
                            match take_round(rx, round) {
                                Ok(m) => found = found.or(m),
                                Err(e) => failure = Some(e),
                            }
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
        _ => run_pinger(
            cfg,
            M::SIZE,
            |round| send(tx, round),
            |round, limit| {
                let mut backoff = Backoff::new(limit.unwrap_or(timeout), "a polled reply");
                loop {
                    if let Some(m) = take_round(rx, round)? {
                        return Ok(Some(m));
                    }
                    if let Err(e) = backoff.snooze() {
                        return match (e, limit) {
                            (BenchError::Timeout { .. }, Some(_)) => Ok(None),
                            (e, _) => Err(e),
                        };
                    }
                }
            },
        ),
    }
}

/// The ponger of a raw case.
pub(crate) fn pong<M: Payload + ZeroCopySend>(cfg: &PeerConfig) -> Result<PongReport, BenchError> {
    let ports = open::<M>(cfg, false)?;
    let Ports { tx, rx, events, .. } = &ports;
    match (cfg.case, events) {
        (Case::IoxEvent, Some((notifier, listener))) => run_ponger(cfg.warmup, || {
            listener.blocking_wait(|_| {}).map_err(wait_error)?;
            let served = echo_all(rx, tx)?;
            if served.echoed > 0 {
                notify(notifier)?;
            }
            Ok(served)
        }),
        (Case::IoxWaitset, Some((notifier, listener))) => {
            let waitset = WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
                .create::<ipc::Service>()
                .map_err(|e| BenchError::setup("a wait set")(cause(e)))?;
            let guard = waitset
                .attach_notification(listener)
                .map_err(|e| BenchError::setup("a wait set attachment")(cause(e)))?;
            run_ponger(cfg.warmup, || {
                let mut served = Served::default();
                let mut failure = None;
                let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
                    if id.has_event_from(&guard) {
                        let _ = listener.try_wait(|_| {});
                        match echo_all(rx, tx).and_then(|s| {
                            if s.echoed > 0 {
                                notify(notifier)?;
                            }
                            Ok(s)
                        }) {
                            Ok(s) => {
                                served.merge(s);
                            }
                            Err(e) => {
                                failure = Some(e);
                                return CallbackProgression::Stop;
                            }
                        }
                    }
                    CallbackProgression::Continue
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
        _ => {
            let timeout = cfg.timeout();
            run_ponger(cfg.warmup, || {
                let mut backoff = Backoff::new(timeout, "the next ping");
                loop {
                    let served = echo_all(rx, tx)?;
                    if served.echoed > 0 {
                        return Ok(served);
                    }
                    backoff.snooze()?;
                }
            })
        }
    }
}
