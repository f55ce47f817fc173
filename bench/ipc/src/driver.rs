//! The ping-pong protocol, the same for every transport: the handshake,
//! the timed loop with its checks, the stop, and the report.

use std::io::Write as _;
use std::time::{Duration, Instant};

use crate::{involuntary_switches, BenchError, PeerConfig, PeerReport, PongReport};

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
    /// The highest round number among them (the stop's excluded).
    pub last_round: u64,
}

impl Served {
    /// Adds what another call served.
    pub(crate) fn merge(&mut self, other: Served) {
        self.echoed += other.echoed;
        self.stop |= other.stop;
        self.last_round = self.last_round.max(other.last_round);
    }

    /// Accounts one echoed sample of `round`.
    pub(crate) fn add(&mut self, round: u64) {
        self.echoed += 1;
        if round == STOP {
            self.stop = true;
        } else {
            self.last_round = self.last_round.max(round);
        }
    }
}

/// Runs the pinger side for messages of `size` bytes.
///
/// `send(round)` writes the message of `round` (in place where the
/// transport allows) and sends it. `wait(round, limit)` returns whether the
/// reply of `round` carried the right payload, dropping replies of other
/// rounds (late handshake echoes); with `Some(limit)` it may give up after
/// about that long and return `None`, with `None` it waits as its case
/// waits (polls give up after the peer timeout, blocking waits block).
pub(crate) fn run_pinger(
    cfg: &PeerConfig,
    size: usize,
    mut send: impl FnMut(u64) -> Result<(), BenchError>,
    mut wait: impl FnMut(u64, Option<Duration>) -> Result<Option<bool>, BenchError>,
) -> Result<PeerReport, BenchError> {
    let timeout = cfg.timeout();
    let start = Instant::now();
    // Handshake: resend round 0 until the ponger, whenever it starts, echoes it.
    loop {
        send(0)?;
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
    let mut switches_before = None;
    for round in 1..=total {
        if round == cfg.warmup + 1 {
            switches_before = involuntary_switches();
        }
        let t0 = Instant::now();
        send(round)?;
        let reply = wait(round, None)?;
        let rtt = t0.elapsed();
        let Some(intact) = reply else {
            return Err(BenchError::Timeout {
                what: "a reply",
                secs: timeout.as_secs_f64(),
            });
        };
        if !intact {
            return Err(BenchError::Corrupt { round });
        }
        verified += 1;
        if round > cfg.warmup {
            rtts.push(u64::try_from(rtt.as_nanos()).unwrap_or(u64::MAX));
        }
    }
    let preempted = switches_before
        .zip(involuntary_switches())
        .map(|(a, b)| b.saturating_sub(a));
    send(STOP)?;
    if wait(STOP, Some(timeout))?.is_none() {
        return Err(BenchError::Timeout {
            what: "the ponger acknowledging the stop",
            secs: timeout.as_secs_f64(),
        });
    }
    if let Some(path) = &cfg.samples {
        write_samples(path, &rtts)?;
    }
    Ok(report(cfg, size, verified, &rtts, preempted))
}

/// Runs the ponger side: `serve` waits (as its case waits) and echoes what
/// arrived, until the stop sample. `warmup` is the pinger's, so that
/// preemptions are counted from the first timed round on.
pub(crate) fn run_ponger(
    warmup: u64,
    mut serve: impl FnMut() -> Result<Served, BenchError>,
) -> Result<PongReport, BenchError> {
    let mut echoed = 0u64;
    let mut switches_before = None;
    loop {
        let s = serve()?;
        if switches_before.is_none() && s.last_round > warmup {
            switches_before = involuntary_switches();
        }
        if s.stop {
            let preempted = switches_before
                .zip(involuntary_switches())
                .map(|(a, b)| b.saturating_sub(a));
            return Ok(PongReport {
                echoed: echoed + s.echoed - 1,
                preempted,
            });
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

fn report(
    cfg: &PeerConfig,
    size: usize,
    verified: u64,
    rtts: &[u64],
    preempted: Option<u64>,
) -> PeerReport {
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
        preempted,
    }
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;

    use clap::Parser;

    use super::*;
    use crate::payload::{Payload, Raw256};

    fn cfg() -> PeerConfig {
        PeerConfig::parse_from([
            "peer",
            "--role",
            "ping",
            "--run-id",
            "unit",
            "--iterations",
            "5",
            "--warmup",
            "2",
        ])
    }

    /// A loopback "transport" that answers every message, corrupting the
    /// payload of round `bad` (if any).
    fn loopback(bad: Option<u64>) -> Result<PeerReport, BenchError> {
        let queue = std::cell::RefCell::new(VecDeque::new());
        run_pinger(
            &cfg(),
            Raw256::SIZE,
            |round| {
                let mut echo = Raw256::make(round);
                if Some(round) == bad {
                    echo.words[30] ^= 1;
                }
                queue.borrow_mut().push_back(echo);
                Ok(())
            },
            |round, _| {
                while let Some(m) = queue.borrow_mut().pop_front() {
                    if m.round == round {
                        return Ok(Some(m.check(round)));
                    }
                }
                Ok(None)
            },
        )
    }

    #[test]
    fn pinger_counts_every_intact_round_trip() {
        let r = loopback(None).unwrap();
        assert_eq!(r.verified, 7);
        assert_eq!(r.iterations, 5);
        assert!(r.min_ns <= r.p50_ns && r.p50_ns <= r.max_ns);
    }

    #[test]
    fn pinger_refuses_a_reply_with_a_changed_payload() {
        assert!(matches!(
            loopback(Some(4)),
            Err(BenchError::Corrupt { round: 4 })
        ));
    }

    #[test]
    fn ponger_stops_at_the_stop_sample_and_counts_the_rest() {
        let mut rounds = vec![0, 1, 2, STOP].into_iter();
        let report = run_ponger(1, || {
            let mut s = Served::default();
            s.add(rounds.next().unwrap());
            Ok(s)
        })
        .unwrap();
        assert_eq!(report.echoed, 3);
    }
}
