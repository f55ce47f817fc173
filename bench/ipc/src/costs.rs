//! Where a shoal hop's time goes: each per-sample step of shoal's ports
//! timed alone, and one publish → take hop through raw iceoryx2 and through
//! shoal's ports in one process (no scheduler, no wake-up in the figure).
//!
//! Every figure is the fastest of [`REPEATS`] batches, in ns per call, so a
//! preempted batch does not count.

use std::hint::black_box;
use std::time::Instant;

use iceoryx2::prelude::*;
use ipc_types::bench::{bench_service_name, BenchDirection, BenchPing256, BenchPing4K};
use ipc_types::Sample;
use shoal_runtime::ports::Origin;
use shoal_runtime::{ChannelLimits, LatencyRecorder, Mode, StepContext};

use crate::payload::{Payload, Raw256, Raw4K};
use crate::{cause, raw_config, BenchError, Cause, PeerConfig};

/// Batches per figure; the fastest counts.
const REPEATS: usize = 25;

/// How long the stamp clock is checked against the exact clock, ns: past
/// its calibration span, with pauses longer than its window.
pub const STAMP_CHECK_NS: u64 = 60_000_000;

/// Per-call costs of shoal's per-sample steps for one sample size, ns.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CostReport {
    /// Sample size, bytes.
    pub size: usize,
    /// `Sample::is_finite`, the check the `sample!` macro generates per
    /// type (run once on publish and once on take).
    pub is_finite_ns: f64,
    /// The same check as a plain early-exit loop over the payload's floats
    /// (the bench's own, for comparison with the generated one).
    pub finite_direct_ns: f64,
    /// Building the field description (`Described::fields`) that the
    /// schema-walking reference check reads; no longer paid per sample.
    pub fields_ns: f64,
    /// `shoal_runtime::mono_ns` (header stamp on publish, latency on take).
    pub mono_ns_ns: f64,
    /// `shoal_runtime::stamp_ns`, the clock of the hop stamps (on publish
    /// and on take): `CLOCK_MONOTONIC` through the time-stamp counter.
    pub stamp_ns_ns: f64,
    /// Stamps taken, each between two exact reads, for [`STAMP_CHECK_NS`].
    pub stamp_checked: u64,
    /// The farthest any of them lay outside its two exact reads, ns (0 if
    /// all inside).
    pub stamp_off_ns: f64,
    /// `LatencyRecorder::record_ns` (on take).
    pub record_ns: f64,
    /// One copy of the sample by value.
    pub copy_ns: f64,
    /// Raw iceoryx2 loan + write + send, then receive + copy out until
    /// empty, one process, iceoryx2's default service settings.
    pub hop_raw_ns: f64,
    /// The same with the service settings shoal's ports use (limits of a
    /// per-vehicle channel: history 1, 9 subscribers, buffer 16, ...).
    pub hop_raw_shoal_limits_ns: f64,
    /// shoal `Publisher::publish`, then `Subscriber::take_ready`, one process.
    pub hop_shoal_ns: f64,
    /// shoal's port steps replicated here on raw ports with the same
    /// settings (stamp, check, send by copy; receive, copy out, latency,
    /// sequence, check, hold queue), every sample by copy, the finite check
    /// the plain loop: the floor for shoal's bookkeeping over raw ports.
    pub hop_shoal_fixed_ns: f64,
}

fn best_of(batch: usize, mut f: impl FnMut()) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..REPEATS {
        let t0 = Instant::now();
        for _ in 0..batch {
            f();
        }
        best = best.min(t0.elapsed().as_nanos() as f64 / batch as f64);
    }
    best
}

/// Measures the costs for `cfg.size` in the domain `cfg.run_id`.
pub fn measure(cfg: &PeerConfig) -> Result<CostReport, BenchError> {
    match cfg.size {
        256 => measure_typed::<BenchPing256, Raw256>(cfg),
        4096 => measure_typed::<BenchPing4K, Raw4K>(cfg),
        s => Err(BenchError::UnsupportedSize(s)),
    }
}

fn measure_typed<S: Sample + Payload, R: Payload + ZeroCopySend>(
    cfg: &PeerConfig,
) -> Result<CostReport, BenchError> {
    let sample = S::make(3);
    let small = 5_000;
    let finite_batch = if S::SIZE > 1024 { 200 } else { 2_000 };
    let is_finite_ns = best_of(finite_batch, || {
        black_box(black_box(&sample).is_finite());
    });
    let finite_direct_ns = best_of(finite_batch, || {
        black_box(black_box(&sample).payload_is_finite());
    });
    let fields_ns = best_of(finite_batch, || {
        black_box(S::fields());
    });
    let mono_ns_ns = best_of(small, || {
        black_box(shoal_runtime::mono_ns());
    });
    // Warm the stamp clock up past its calibration span before timing it.
    let (stamp_checked, stamp_off_ns) = stamp_agreement();
    let stamp_ns_ns = best_of(small, || {
        black_box(shoal_runtime::stamp_ns());
    });
    let mut rec = LatencyRecorder::new();
    let mut v = 1_000u64;
    let record_ns = best_of(small, || {
        v = v.wrapping_mul(6364136223846793005).wrapping_add(1) % 100_000 + 1;
        rec.record_ns(black_box(v));
    });
    let copy_ns = best_of(small, || {
        let c: S = *black_box(&sample);
        black_box(c);
    });
    let hops = 1_000;

    // Raw iceoryx2, one process: iceoryx2's default service settings, then
    // the settings shoal's ports ask for (a per-vehicle channel's limits).
    let node = NodeBuilder::new()
        .config(&raw_config(&cfg.run_id))
        .create::<ipc::Service>()
        .map_err(|e| BenchError::setup("the costs node")(cause(e)))?;
    let raw = R::make(3);
    let hop_raw_ns = raw_hop::<R>(&node, cfg, "costs-raw", None, &raw, hops)?;
    let hop_raw_shoal_limits_ns = raw_hop::<R>(
        &node,
        cfg,
        "costs-raw-limits",
        Some(ChannelLimits::vehicle()),
        &raw,
        hops,
    )?;

    // shoal's ports, one process.
    let snode = shoal_runtime::domain_node(&cfg.run_id, "bench/costs")?;
    let sname = bench_service_name(&cfg.run_id, "costs-shoal", cfg.size, BenchDirection::Ping);
    let limits = ChannelLimits::vehicle();
    let mut stx = shoal_runtime::node_publisher::<S, _>(&snode, &sname, &limits)?;
    let mut srx = shoal_runtime::node_subscriber::<S, _>(&snode, &sname, &limits, 2)?;
    let ctx = StepContext {
        sim_time_ns: 0,
        tick: 0,
        wake_mono_ns: 0,
        since_last_ns: 0,
        last: false,
        mode: Mode::Realtime,
        woken_by: shoal_runtime::Wake::Tick,
    };
    let mut sfailure: Option<BenchError> = None;
    let hop_shoal_ns = best_of(hops, || {
        let mut step = || -> Result<(), shoal_runtime::RuntimeError> {
            stx.publish(*black_box(&sample), &ctx, Origin::of(sample.header()))?;
            srx.take_ready(&ctx, |v| {
                black_box(v);
            })
        };
        if let Err(e) = step() {
            sfailure = Some(e.into());
        }
    });
    if let Some(e) = sfailure {
        return Err(e);
    }
    let hop_shoal_fixed_ns = replica_hop::<S>(&node, cfg, &sample, hops)?;
    Ok(CostReport {
        size: S::SIZE,
        is_finite_ns,
        finite_direct_ns,
        fields_ns,
        mono_ns_ns,
        stamp_ns_ns,
        stamp_checked,
        stamp_off_ns,
        record_ns,
        copy_ns,
        hop_raw_ns,
        hop_raw_shoal_limits_ns,
        hop_shoal_ns,
        hop_shoal_fixed_ns,
    })
}

/// Stamps between exact reads for [`STAMP_CHECK_NS`], pausing now and
/// then for longer than the stamp clock's window: how many, and the farthest
/// one lay outside its bracket, ns.
fn stamp_agreement() -> (u64, f64) {
    let start = shoal_runtime::mono_ns();
    let (mut n, mut off) = (0u64, 0u64);
    while shoal_runtime::mono_ns() - start < STAMP_CHECK_NS {
        n += 1;
        if n.is_multiple_of(101) {
            std::thread::sleep(std::time::Duration::from_micros(150));
        }
        let before = shoal_runtime::mono_ns();
        let s = shoal_runtime::stamp_ns();
        let after = shoal_runtime::mono_ns();
        off = off
            .max(before.saturating_sub(s))
            .max(s.saturating_sub(after));
    }
    (n, off as f64)
}

/// One raw publish → receive hop, ns per hop; `limits` as shoal's ports set
/// them, or iceoryx2's defaults.
fn raw_hop<R: Payload + ZeroCopySend>(
    node: &Node<ipc::Service>,
    cfg: &PeerConfig,
    case: &str,
    limits: Option<ChannelLimits>,
    raw: &R,
    hops: usize,
) -> Result<f64, BenchError> {
    let name = bench_service_name(&cfg.run_id, case, cfg.size, BenchDirection::Ping);
    let service_name =
        ServiceName::new(&name).map_err(|e| BenchError::setup(name.clone())(cause(e)))?;
    let builder = node.service_builder(&service_name).publish_subscribe::<R>();
    let service = match limits {
        None => builder.open_or_create(),
        Some(l) => builder
            .max_publishers(l.max_publishers)
            .max_subscribers(l.max_subscribers)
            .max_nodes(l.max_nodes)
            .subscriber_max_buffer_size(l.max_buffer)
            .history_size(l.history)
            .subscriber_max_borrowed_samples(2)
            .enable_safe_overflow(true)
            .open_or_create(),
    }
    .map_err(|e| BenchError::setup(name.clone())(cause(e)))?;
    let tx = match limits {
        None => service.publisher_builder().create(),
        Some(_) => service.publisher_builder().max_loaned_samples(2).create(),
    }
    .map_err(|e| BenchError::setup("a raw publisher")(cause(e)))?;
    let rx = match limits {
        None => service.subscriber_builder().create(),
        Some(_) => service.subscriber_builder().buffer_size(2).create(),
    }
    .map_err(|e| BenchError::setup("a raw subscriber")(cause(e)))?;
    let mut failure: Option<BenchError> = None;
    let ns = best_of(hops, || {
        let step = || -> Result<(), Cause> {
            tx.loan_uninit()
                .map_err(cause)?
                .write_payload(*black_box(raw))
                .send()
                .map_err(cause)?;
            while let Some(s) = rx.receive().map_err(cause)? {
                let v: R = *s;
                black_box(v);
            }
            Ok(())
        };
        if let Err(source) = step() {
            failure = Some(BenchError::Io {
                what: "raw hop",
                source,
            });
        }
    });
    match failure {
        Some(e) => Err(e),
        None => Ok(ns),
    }
}

/// shoal's publish → take steps on raw ports (see
/// [`CostReport::hop_shoal_fixed_ns`]), ns per hop.
fn replica_hop<S: Sample + Payload>(
    node: &Node<ipc::Service>,
    cfg: &PeerConfig,
    sample: &S,
    hops: usize,
) -> Result<f64, BenchError> {
    let l = ChannelLimits::vehicle();
    let name = bench_service_name(&cfg.run_id, "costs-replica", cfg.size, BenchDirection::Ping);
    let service_name =
        ServiceName::new(&name).map_err(|e| BenchError::setup(name.clone())(cause(e)))?;
    let service = node
        .service_builder(&service_name)
        .publish_subscribe::<S>()
        .max_publishers(l.max_publishers)
        .max_subscribers(l.max_subscribers)
        .max_nodes(l.max_nodes)
        .subscriber_max_buffer_size(l.max_buffer)
        .history_size(l.history)
        .subscriber_max_borrowed_samples(2)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| BenchError::setup(name.clone())(cause(e)))?;
    let tx = service
        .publisher_builder()
        .max_loaned_samples(2)
        .create()
        .map_err(|e| BenchError::setup("a replica publisher")(cause(e)))?;
    let rx = service
        .subscriber_builder()
        .buffer_size(2)
        .create()
        .map_err(|e| BenchError::setup("a replica subscriber")(cause(e)))?;
    let mut held: std::collections::VecDeque<S> = std::collections::VecDeque::with_capacity(32);
    let mut latency = LatencyRecorder::new();
    let mut seq = 0u64;
    let mut next_seq: Option<u64> = None;
    let mut lost = 0u64;
    let mut failure: Option<BenchError> = None;
    let ns = best_of(hops, || {
        let mut step = || -> Result<(), Cause> {
            // Publisher::publish
            let mut out = *black_box(sample);
            if !out.payload_is_finite() {
                return Err("non-finite".into());
            }
            let origin = Origin::of(out.header());
            let h = out.header_mut();
            h.seq = seq;
            h.sim_time_ns = 0;
            h.origin_mono_ns = origin.mono_ns;
            h.origin_sim_time_ns = origin.sim_time_ns;
            h.publish_mono_ns = shoal_runtime::stamp_ns();
            tx.send_copy(out).map_err(cause)?;
            seq += 1;
            // Subscriber::take_ready
            while let Some(r) = rx.receive().map_err(cause)? {
                let v: S = *r;
                drop(r);
                let h = *v.header();
                latency.record_ns(shoal_runtime::stamp_ns().saturating_sub(h.publish_mono_ns));
                if let Some(n) = next_seq {
                    if h.seq > n {
                        lost += h.seq - n;
                    }
                }
                next_seq = Some(h.seq + 1);
                if !v.payload_is_finite() {
                    continue;
                }
                held.push_back(v);
            }
            while let Some(v) = held.pop_front() {
                black_box(v);
            }
            Ok(())
        };
        if let Err(source) = step() {
            failure = Some(BenchError::Io {
                what: "replica hop",
                source,
            });
        }
    });
    black_box(lost);
    match failure {
        Some(e) => Err(e),
        None => Ok(ns),
    }
}
