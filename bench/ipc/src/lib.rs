//! The peer processes of `shoal bench ipc`: ping-pong round trips between two
//! OS processes over
//!
//! - **raw iceoryx2** (no shoal code on the path): a publisher and a
//!   subscriber each way, waiting by polling (`iox2-poll`), by blocking on a
//!   [`Listener`](iceoryx2::port::listener::Listener) of an event service
//!   (`iox2-event`), or by blocking in a [`WaitSet`](iceoryx2::waitset::WaitSet)
//!   that the listener is attached to (`iox2-waitset`, the primitive shoal's
//!   runtime uses);
//! - **shoal's runtime ports** ([`shoal_runtime::Publisher`] /
//!   [`shoal_runtime::Subscriber`]: header stamping, finite check, sequence and
//!   latency accounting), polling (`shoal-poll`) or blocking in a WaitSet on the
//!   runtime's per-process wake event, as a service's loop does (`shoal-event`);
//! - a **Unix-domain stream socket** with blocking reads and writes (`uds`).
//!
//! The pinger times each round trip on the monotonic clock ([`Instant`]) from
//! just before it sends to just after it holds the reply, checks that the
//! reply carries the round number and payload it sent, and reports the
//! percentiles ([`PeerReport`], one JSON line on stdout). The ponger echoes
//! every sample until the pinger's stop sample, which it echoes too.
//! Before the first timed round the pinger resends round 0 until the ponger
//! answers, so neither process has to start first.
//!
//! `shoal bench ipc` starts both peers of every case as separate processes
//! of the `shoal-ipc-peer` binary and prints the side-by-side table.
//!
//! ```no_run
//! use clap::Parser;
//! use shoal_bench_ipc::{run_peer, PeerConfig, PeerOutput};
//! // The ponger runs in another process with `--role pong` and the same other arguments.
//! let cfg = PeerConfig::parse_from([
//!     "shoal-ipc-peer", "--role", "ping", "--case", "shoal-poll", "--size", "256",
//!     "--iterations", "1000", "--run-id", "bench-doc",
//! ]);
//! if let Ok(PeerOutput::Ping(report)) = run_peer(&cfg) {
//!     println!("p50 {} ns", report.p50_ns);
//! }
//! ```
//!
//! [`Instant`]: std::time::Instant

pub mod costs;
mod driver;
pub mod payload;
mod raw;
mod shoal;
mod uds;
mod wait;

use std::path::PathBuf;
use std::time::Duration;

pub use costs::CostReport;
pub use payload::{Payload, Raw1M, Raw256, Raw256K, Raw4K};

/// The sample sizes the benchmark knows, bytes (the shoal samples include
/// the common header): two a service sends by value, and a camera frame's
/// 256 KiB and 1 MiB, which travel in place.
pub const SIZES: [usize; 4] = [256, 4096, 256 * 1024, 1024 * 1024];

/// One benchmark case: a transport and a way of waiting.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
pub enum Case {
    /// Raw iceoryx2, busy try-receive loop.
    #[value(name = "iox2-poll")]
    #[serde(rename = "iox2-poll")]
    IoxPoll,
    /// Raw iceoryx2, publish + notify; the receiver blocks on its `Listener`.
    #[value(name = "iox2-event")]
    #[serde(rename = "iox2-event")]
    IoxEvent,
    /// Raw iceoryx2, publish + notify; the receiver blocks in a `WaitSet`.
    #[value(name = "iox2-waitset")]
    #[serde(rename = "iox2-waitset")]
    IoxWaitset,
    /// shoal's runtime ports, busy `take_ready` loop.
    #[value(name = "shoal-poll")]
    #[serde(rename = "shoal-poll")]
    ShoalPoll,
    /// shoal's runtime ports; the receiver blocks in a `WaitSet` on its
    /// runtime wake event, as a service's run loop does.
    #[value(name = "shoal-event")]
    #[serde(rename = "shoal-event")]
    ShoalEvent,
    /// Unix-domain stream socket, blocking `read`/`write`.
    #[value(name = "uds")]
    #[serde(rename = "uds")]
    Uds,
}

/// How a receiver waits for the next sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitMode {
    /// Busy try-receive loop (spins, then yields).
    Poll,
    /// Blocks in the kernel until woken.
    Block,
}

impl Case {
    /// Every case, in table order.
    pub const ALL: [Case; 6] = [
        Case::IoxPoll,
        Case::ShoalPoll,
        Case::IoxEvent,
        Case::IoxWaitset,
        Case::ShoalEvent,
        Case::Uds,
    ];

    /// The case's name on the command line and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Case::IoxPoll => "iox2-poll",
            Case::IoxEvent => "iox2-event",
            Case::IoxWaitset => "iox2-waitset",
            Case::ShoalPoll => "shoal-poll",
            Case::ShoalEvent => "shoal-event",
            Case::Uds => "uds",
        }
    }

    /// Polling or blocking.
    pub const fn wait_mode(self) -> WaitMode {
        match self {
            Case::IoxPoll | Case::ShoalPoll => WaitMode::Poll,
            _ => WaitMode::Block,
        }
    }

    /// Looks a case up by its name.
    pub fn from_name(name: &str) -> Option<Case> {
        Case::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// What a peer process does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Role {
    /// Sends pings, times round trips, prints its report as one JSON line.
    Ping,
    /// Echoes every ping until the stop sample.
    Pong,
    /// Times shoal's per-sample steps in one process; prints them as one JSON line.
    Costs,
}

/// The command line of `shoal-ipc-peer`.
#[derive(Debug, Clone, clap::Parser)]
#[command(
    name = "shoal-ipc-peer",
    about = "One peer of a `shoal bench ipc` ping-pong case; started by `shoal bench ipc` (or a test), \
             which starts a `pong` and a `ping` with the same --case, --size, --iterations, --warmup and --run-id."
)]
pub struct PeerConfig {
    /// ping: time round trips; pong: echo; costs: time shoal's per-sample steps in one process.
    #[arg(long, value_enum)]
    pub role: Role,
    /// Transport and wait mode (ignored by `costs`).
    #[arg(long, value_enum, default_value = "iox2-poll")]
    pub case: Case,
    /// Sample size in bytes: 256, 4096, 262144 or 1048576.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Timed round trips.
    #[arg(long, default_value_t = 10_000)]
    pub iterations: u64,
    /// Untimed round trips before the timed ones (their payloads are checked too).
    #[arg(long, default_value_t = 1_000)]
    pub warmup: u64,
    /// The iceoryx2 domain (`shoal_<run-id>_` in /dev/shm, /dev/shm/shoal/<run-id>/);
    /// the Unix socket lives in that directory too. At most 23 bytes.
    #[arg(long)]
    pub run_id: String,
    /// Pin this process to one CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Longest wait for the peer to show up, for a polled reply, or for the
    /// stop to be acknowledged, s.
    #[arg(long, default_value_t = 20.0)]
    pub timeout_s: f64,
    /// ping: also write every timed round trip (ns, one per line) to this file.
    #[arg(long)]
    pub samples: Option<PathBuf>,
}

impl PeerConfig {
    /// The timeout as a duration.
    pub fn timeout(&self) -> Duration {
        Duration::from_secs_f64(self.timeout_s.clamp(0.01, 3600.0))
    }
}

/// What the pinger measured (all times round trip, ns).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PeerReport {
    /// The case's name.
    pub case: String,
    /// Sample size, bytes.
    pub size: usize,
    /// Timed round trips.
    pub iterations: u64,
    /// Untimed round trips before them.
    pub warmup: u64,
    /// Round trips whose reply carried the round number and payload sent
    /// (warm-up included; equals `warmup + iterations` on success).
    pub verified: u64,
    /// Fastest, ns.
    pub min_ns: u64,
    /// Mean, ns.
    pub mean_ns: f64,
    /// Median, ns.
    pub p50_ns: u64,
    /// 99th percentile, ns.
    pub p99_ns: u64,
    /// 99.9th percentile, ns.
    pub p999_ns: u64,
    /// Slowest, ns.
    pub max_ns: u64,
    /// Times the kernel took the CPU from the pinger during the timed round
    /// trips (involuntary context switches; `None` without `/proc`).
    pub preempted: Option<u64>,
}

/// What the ponger reports.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PongReport {
    /// Samples echoed (stop sample excluded).
    pub echoed: u64,
    /// Times the kernel took the CPU from the ponger from its first timed
    /// round on (involuntary context switches; `None` without `/proc`).
    pub preempted: Option<u64>,
}

/// What a peer process produced.
#[derive(Debug, Clone, PartialEq)]
pub enum PeerOutput {
    /// The pinger's measurement.
    Ping(PeerReport),
    /// The ponger's report.
    Pong(PongReport),
    /// The per-sample cost breakdown.
    Costs(CostReport),
}

/// Errors of a peer.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A node, service, port or socket could not be created.
    #[error("cannot set up {what}")]
    Setup {
        /// What was being created.
        what: String,
        /// Cause.
        #[source]
        source: Cause,
    },
    /// Sending, receiving or waiting failed.
    #[error("{what} failed")]
    Io {
        /// The operation.
        what: &'static str,
        /// Cause.
        #[source]
        source: Cause,
    },
    /// shoal's runtime refused.
    #[error(transparent)]
    Runtime(#[from] shoal_runtime::RuntimeError),
    /// The peer did not answer in time.
    #[error("timed out after {secs:.1} s: {what}")]
    Timeout {
        /// What was awaited.
        what: &'static str,
        /// The timeout, s.
        secs: f64,
    },
    /// A reply carried the right round number but another payload.
    #[error("round {round}: the reply's payload differs from the ping's")]
    Corrupt {
        /// The round.
        round: u64,
    },
    /// SIGINT or SIGTERM arrived.
    #[error("interrupted by a termination request")]
    Interrupted,
    /// No sample type of that size exists.
    #[error("unsupported sample size {0} B (256, 4096, 262144 or 1048576)")]
    UnsupportedSize(usize),
    /// The samples file could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
}

impl BenchError {
    pub(crate) fn setup(what: impl Into<String>) -> impl FnOnce(Cause) -> BenchError {
        let what = what.into();
        move |source| BenchError::Setup { what, source }
    }
}

/// The error that caused a [`BenchError`] (iceoryx2's, the OS's), kept whole.
pub type Cause = Box<dyn std::error::Error + Send + Sync>;

/// Boxes an error as a [`Cause`].
pub(crate) fn cause<E: std::error::Error + Send + Sync + 'static>(e: E) -> Cause {
    Box::new(e)
}

/// Longest run id whose iceoryx2 event sockets
/// (`/dev/shm/shoal/<id>/shoal_<id>_<hash of up to 31 digits>.event`) still
/// fit the 107 bytes of a Unix socket path.
pub const MAX_RUN_ID_LEN: usize = 23;

/// Runs one peer as `cfg` says (pins it to `cfg.cpu` first).
pub fn run_peer(cfg: &PeerConfig) -> Result<PeerOutput, BenchError> {
    if cfg.run_id.len() > MAX_RUN_ID_LEN {
        return Err(BenchError::setup(format!("the domain `{}`", cfg.run_id))(format!(
            "a run id longer than {MAX_RUN_ID_LEN} bytes makes iceoryx2's event socket paths too long"
        ).into()));
    }
    if let Some(cpu) = cfg.cpu {
        pin_to(cpu)?;
    }
    match cfg.role {
        Role::Costs => costs::measure(cfg).map(PeerOutput::Costs),
        Role::Ping => {
            let report = match (cfg.case, cfg.size) {
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 256) => {
                    raw::ping::<Raw256>(cfg)
                }
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 4096) => {
                    raw::ping::<Raw4K>(cfg)
                }
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 262_144) => {
                    raw::ping::<Raw256K>(cfg)
                }
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 1_048_576) => {
                    raw::ping::<Raw1M>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 256) => {
                    shoal::ping::<ipc_types::bench::BenchPing256>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 4096) => {
                    shoal::ping::<ipc_types::bench::BenchPing4K>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 262_144) => {
                    shoal::ping::<ipc_types::bench::BenchPing256K>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 1_048_576) => {
                    shoal::ping::<ipc_types::bench::BenchPing1M>(cfg)
                }
                (Case::Uds, 256) => uds::ping::<Raw256>(cfg),
                (Case::Uds, 4096) => uds::ping::<Raw4K>(cfg),
                (Case::Uds, 262_144) => uds::ping::<Raw256K>(cfg),
                (Case::Uds, 1_048_576) => uds::ping::<Raw1M>(cfg),
                (_, s) => Err(BenchError::UnsupportedSize(s)),
            }?;
            Ok(PeerOutput::Ping(report))
        }
        Role::Pong => {
            let report = match (cfg.case, cfg.size) {
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 256) => {
                    raw::pong::<Raw256>(cfg)
                }
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 4096) => {
                    raw::pong::<Raw4K>(cfg)
                }
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 262_144) => {
                    raw::pong::<Raw256K>(cfg)
                }
                (Case::IoxPoll | Case::IoxEvent | Case::IoxWaitset, 1_048_576) => {
                    raw::pong::<Raw1M>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 256) => {
                    shoal::pong::<ipc_types::bench::BenchPing256>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 4096) => {
                    shoal::pong::<ipc_types::bench::BenchPing4K>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 262_144) => {
                    shoal::pong::<ipc_types::bench::BenchPing256K>(cfg)
                }
                (Case::ShoalPoll | Case::ShoalEvent, 1_048_576) => {
                    shoal::pong::<ipc_types::bench::BenchPing1M>(cfg)
                }
                (Case::Uds, 256) => uds::pong::<Raw256>(cfg),
                (Case::Uds, 4096) => uds::pong::<Raw4K>(cfg),
                (Case::Uds, 262_144) => uds::pong::<Raw256K>(cfg),
                (Case::Uds, 1_048_576) => uds::pong::<Raw1M>(cfg),
                (_, s) => Err(BenchError::UnsupportedSize(s)),
            }?;
            Ok(PeerOutput::Pong(report))
        }
    }
}

/// Involuntary context switches of this process so far (`/proc/self/status`).
pub fn involuntary_switches() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("nonvoluntary_ctxt_switches:"))?
        .trim()
        .parse()
        .ok()
}

fn pin_to(cpu: usize) -> Result<(), BenchError> {
    use iceoryx2_bb_posix::thread::{ThreadHandle, ThreadProperties};
    ThreadHandle::from_self()
        .set_affinity(&[cpu])
        .map_err(|e| BenchError::setup(format!("CPU affinity {cpu}"))(cause(e)))
}

/// The iceoryx2 configuration of a benchmark domain for the raw cases: the
/// same prefix and root directory as a shoal run of that id (so
/// [`shoal_runtime::cleanup_domain`] removes both), built here with
/// iceoryx2's own API so no shoal code touches the raw path.
pub fn raw_config(run_id: &str) -> iceoryx2::config::Config {
    use iceoryx2::prelude::{FileName, SemanticString};
    use shoal_runtime::domain::{domain_prefix, domain_root};
    let mut config = iceoryx2::config::Config::default();
    if let Ok(prefix) = FileName::new(domain_prefix(run_id).as_bytes()) {
        config.global.prefix = prefix;
    }
    if let Ok(root) =
        iceoryx2_bb_system_types::path::Path::new(domain_root(run_id).to_string_lossy().as_bytes())
    {
        config.global.set_root_path(&root);
    }
    config
}

/// Where the `uds` case's socket lives: inside the run's domain directory.
pub fn socket_path(run_id: &str, size: usize) -> PathBuf {
    shoal_runtime::domain::domain_root(run_id).join(format!("bench-uds-{size}.sock"))
}
