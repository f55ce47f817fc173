//! The ping-pong protocol, the same for every transport: the handshake,
//! the timed loop with its checks, the stop, and the report.

use std::io::Write as _;
use std::time::{Duration, Instant};

use crate::payload::Payload;
use crate::{BenchError, PeerConfig, PeerReport};

/// Round number of the stop sample (echoed, then the ponger exits).
pub(crate) const STOP: u64 = u64::MAX;
/// How long one handshake attempt waits for the echo of round 0.
pub(crate) const HANDSHAKE_TRY: Duration = Duration::from_millis(20);

/// What one `serve` call of a ponger did.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Served {
    /// Samples echoed (the stop sample included).
    pub echoed: u64,
    /// The stop sample was among them.
    pub stop: bool,
}

impl Served {
    /// Accounts one echoed sample of `round`.
    pub(crate) fn add(&mut self, round: u64) {
        self.echoed += 1;
        self.stop |= round == STOP;
    }
}

/// Runs the pinger side.
///
/// `send` sends one message. `wait(round, limit)` returns the reply of
/// `round`, dropping replies of other rounds (late handshake echoes);
/// with `Some(limit)` it may give up after about that long and return
/// `None`, with `None` it waits as its case waits (polls give up after the
/// peer timeout, blocking waits block).
pub(crate) fn run_pinger<M: Payload>(
    cfg: &PeerConfig,
    mut send: impl FnMut(&M) -> Result<(), BenchError>,
    mut wait: impl FnMut(u64, Option<Duration>) -> Result<Option<M>, BenchError>,
) -> Result<PeerReport, BenchError> {
    let timeout = cfg.timeout();
    let start = Instant::now();
    // Handshake: resend round 0 until the ponger, whenever it starts, echoes it.
    loop {
        send(&M::make(0))?;
        if wait(0, Some(HANDSHAKE_TRY))?.is_some() {
            break;
        }
        if start.elapsed() > timeout {
            return Err(BenchError::Timeout {
                what: "the ponger never answered round 0",
                secs: timeout.as_secs_f64(),
            });
        }
    }
    let total = cfg.warmup + cfg.iterations;
    let mut rtts: Vec<u64> = Vec::with_capacity(cfg.iterations as usize);
    let mut verified = 0u64;
    for round in 1..=total {
        let msg = M::make(round);
        let t0 = Instant::now();
        send(&msg)?;
        let reply = wait(round, None)?;
        let rtt = t0.elapsed();
        let Some(reply) = reply else {
            return Err(BenchError::Timeout {
                what: "a reply",
                secs: timeout.as_secs_f64(),
            });
        };
        if !reply.same_payload(&msg) {
            return Err(BenchError::Corrupt { round });
        }
        verified += 1;
        if round > cfg.warmup {
            rtts.push(u64::try_from(rtt.as_nanos()).unwrap_or(u64::MAX));
        }
    }
    send(&M::make(STOP))?;
    if wait(STOP, Some(timeout))?.is_none() {
        return Err(BenchError::Timeout {
            what: "the ponger acknowledging the stop",
            secs: timeout.as_secs_f64(),
        });
    }
    if let Some(path) = &cfg.samples {
        write_samples(path, &rtts)?;
    }
    Ok(report(cfg, M::SIZE, verified, &rtts))
}

/// Runs the ponger side: `serve` waits (as its case waits) and echoes what
/// arrived, until the stop sample. Returns the samples echoed before it.
pub(crate) fn run_ponger(
    mut serve: impl FnMut() -> Result<Served, BenchError>,
) -> Result<u64, BenchError> {
    let mut echoed = 0u64;
    loop {
        let s = serve()?;
        if s.stop {
            return Ok(echoed + s.echoed - 1);
        }
        echoed += s.echoed;
    }
}

fn write_samples(path: &std::path::Path, rtts: &[u64]) -> Result<(), BenchError> {
    let io = |source| BenchError::Write {
        path: path.to_path_buf(),
        source,
    };
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).map_err(io)?);
    for r in rtts {
        writeln!(out, "{r}").map_err(io)?;
    }
    out.flush().map_err(io)
}

fn report(cfg: &PeerConfig, size: usize, verified: u64, rtts: &[u64]) -> PeerReport {
    let mut hist = hdrhistogram::Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3).ok();
    if let Some(h) = hist.as_mut() {
        for &r in rtts {
            h.saturating_record(r.max(1));
        }
    }
    let q = |p: f64| hist.as_ref().map_or(0, |h| h.value_at_quantile(p));
    let mean_ns = if rtts.is_empty() {
        0.0
    } else {
        rtts.iter().map(|&r| r as f64).sum::<f64>() / rtts.len() as f64
    };
    PeerReport {
        case: cfg.case.name().to_string(),
        size,
        iterations: cfg.iterations,
        warmup: cfg.warmup,
        verified,
        min_ns: rtts.iter().copied().min().unwrap_or(0),
        mean_ns,
        p50_ns: q(0.5),
        p99_ns: q(0.99),
        p999_ns: q(0.999),
        max_ns: rtts.iter().copied().max().unwrap_or(0),
    }
}
