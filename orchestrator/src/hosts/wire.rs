//! What crosses hosts on Zenoh: key expressions, the run order, the
//! lockstep clock and fences, a host's outcome and its files.
//!
//! The coordinator (`shoal run --hosts`) is a Zenoh router that connects to
//! every agent (`shoal host`, also a router, listening); agents never link
//! to each other, so every message between hosts passes the coordinator's
//! router. That star is what makes lockstep across hosts exact: a router
//! forwards the messages of one link in the order they came, so a sample
//! that host A bridged during tick k reaches host B before the clock of
//! tick k + 1, which the coordinator sends only after A's fence for tick k
//! (sent after the sample, on the same link) has reached it. All messages
//! use one priority, reliable, blocking on congestion (none is dropped).
//!
//! | key | from → to | payload |
//! |---|---|---|
//! | `shoal-host/<host>/alive` | agent (liveliness) | |
//! | `shoal-host/<host>/start` | coordinator → agent (query) | [`StartOrder`] JSON; reply [`StartReply`] |
//! | `shoal-host/<host>/finish/<run>` | coordinator → agent (query) | replies: [`HostOutcome`], then [`FileChunk`]s |
//! | `shoal-host/<host>/time` | coordinator → agent (query) | reply: the agent's monotonic clock, ns (u64 LE) |
//! | `shoal-ctl/<run>/coordinator` | coordinator (liveliness) | |
//! | `shoal-ctl/<run>/clock` | coordinator → agents | tick (u64 LE); empty: the run ends |
//! | `shoal-ctl/<run>/abort` | coordinator → agents | the reason (UTF-8) |
//! | `shoal-ctl/<run>/fence/<host>` | agent → coordinator | the tick it closed (u64 LE) |
//! | `shoal-ctl/<run>/failed/<host>` | agent → coordinator | what failed (UTF-8) |
//! | `shoal/<run>/…` (the iceoryx2 service name) | publishing host → subscribing hosts | the sample without its zero tail |

use serde::{Deserialize, Serialize};
use shoal_runtime::Mode;

use super::placement::Placement;
use super::tls::{self, Security};
use crate::launch::ProcessUsage;

/// The liveliness token of an agent.
pub fn alive(host: &str) -> String {
    format!("shoal-host/{host}/alive")
}

/// Every agent's liveliness token.
pub const ALL_ALIVE: &str = "shoal-host/*/alive";

/// The host named in an agent's liveliness key.
pub fn host_of_alive(key: &str) -> Option<&str> {
    key.strip_prefix("shoal-host/")?.strip_suffix("/alive")
}

/// Everything an agent answers.
pub fn agent_queries(host: &str) -> String {
    format!("shoal-host/{host}/**")
}

/// The start of a run on `host`.
pub fn start(host: &str) -> String {
    format!("shoal-host/{host}/start")
}

/// The end of run `run` on `host`: its outcome and files.
pub fn finish(host: &str, run: &str) -> String {
    format!("shoal-host/{host}/finish/{run}")
}

/// The coordinator has all of run `run`'s files from `host`: the agent may
/// drop them and close its session. Until then it keeps them and answers
/// `finish` again (closing a Zenoh session cuts off the replies still on
/// their way, and the coordinator's query then ends short).
pub fn release(host: &str, run: &str) -> String {
    format!("shoal-host/{host}/release/{run}")
}

/// An agent's monotonic clock, read by a query (see [`ClockOffset`]).
pub fn time(host: &str) -> String {
    format!("shoal-host/{host}/time")
}

/// The coordinator's liveliness token for run `run`.
pub fn coordinator(run: &str) -> String {
    format!("shoal-ctl/{run}/coordinator")
}

/// The lockstep clock of run `run`.
pub fn clock(run: &str) -> String {
    format!("shoal-ctl/{run}/clock")
}

/// The abort of run `run`.
pub fn abort(run: &str) -> String {
    format!("shoal-ctl/{run}/abort")
}

/// The fences of `host` in run `run` (`*`: every host's).
pub fn fence(run: &str, host: &str) -> String {
    format!("shoal-ctl/{run}/fence/{host}")
}

/// The failures of `host` in run `run` (`*`: every host's).
pub fn failed(run: &str, host: &str) -> String {
    format!("shoal-ctl/{run}/failed/{host}")
}

/// The last chunk of a key expression.
pub fn last_chunk(key: &str) -> &str {
    key.rsplit('/').next().unwrap_or(key)
}

/// A tick on the wire.
pub fn encode_tick(tick: u64) -> [u8; 8] {
    tick.to_le_bytes()
}

/// A tick from the wire; `None` for anything but 8 bytes.
pub fn decode_tick(bytes: &[u8]) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.try_into().ok()?))
}

/// A sample without its zero tail (a world snapshot holds room for 256
/// vehicles; a run has fewer).
pub fn trim(bytes: &[u8]) -> &[u8] {
    // Whole blocks of zeros first (the OR of a fixed-size block compiles to
    // vector instructions; a world's tail is tens of KiB), then bytes.
    const BLOCK: usize = 64;
    let mut end = bytes.len();
    while end >= BLOCK && bytes[end - BLOCK..end].iter().fold(0u8, |a, &b| a | b) == 0 {
        end -= BLOCK;
    }
    let end = bytes[..end]
        .iter()
        .rposition(|&b| b != 0)
        .map_or(0, |i| i + 1);
    &bytes[..end]
}

/// Writes a trimmed sample back over `out`, zeros after it. `false` (and
/// nothing written) if it is longer than `out`.
pub fn untrim(wire: &[u8], out: &mut [u8]) -> bool {
    if wire.len() > out.len() {
        return false;
    }
    out[..wire.len()].copy_from_slice(wire);
    out[wire.len()..].fill(0);
    true
}

/// What the coordinator tells an agent to run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StartOrder {
    /// The run id (names every service and key).
    pub run_id: String,
    /// This host's index in the placement.
    pub host: usize,
    /// Where everything runs.
    pub placement: Placement,
    /// The resolved scenario, as `shoal run` writes it.
    pub scenario_toml: String,
    /// The effective scenario (defaults filled in), for the recording.
    pub effective_toml: String,
    /// Lockstep or realtime.
    pub mode: Mode,
    /// Longest a local step may take, s.
    pub tick_timeout_s: f64,
    /// Adaptive wait of every process, µs.
    pub spin_us: u64,
    /// Realtime: the run's epoch in this host's own monotonic clock, ns
    /// (the coordinator's epoch plus this host's measured offset); 0 in
    /// lockstep.
    #[serde(default)]
    pub epoch_mono_ns: u64,
    /// Per host of the placement: what to add to the monotonic stamps of a
    /// sample bridged in from it to put them on this host's clock, ns.
    #[serde(default)]
    pub stamp_shift_ns: Vec<i64>,
    /// Who sends the order: the coordinator's name (its certificate's,
    /// over TLS) and where it runs.
    #[serde(default)]
    pub coordinator: String,
}

/// An abort on the wire: who sends it and why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AbortMsg {
    /// The coordinator's name (its certificate's, over TLS).
    pub from: String,
    /// Why.
    pub reason: String,
}

impl AbortMsg {
    /// An abort from the wire; a payload that is not one is named as such.
    pub fn decode(bytes: &[u8]) -> Self {
        serde_json::from_slice(bytes).unwrap_or_else(|_| Self {
            from: "(unnamed sender)".into(),
            reason: String::from_utf8_lossy(bytes).into_owned(),
        })
    }
}

/// One reading of an agent's clock: the coordinator's monotonic clock when
/// it asked and when the answer came, and the agent's in between, ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockReading {
    /// Coordinator's clock when the query left.
    pub sent_ns: u64,
    /// The agent's clock in its answer.
    pub agent_ns: u64,
    /// Coordinator's clock when the answer came.
    pub received_ns: u64,
}

/// How far an agent's monotonic clock is from the coordinator's, estimated
/// as Cristian's algorithm does: from the reading with the shortest round
/// trip, taking the agent's stamp to lie at its middle. Whatever the
/// delays, the true offset lies within `error_ns` (half that round trip)
/// of `offset_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClockOffset {
    /// Agent's clock minus the coordinator's, ns.
    pub offset_ns: i64,
    /// Bound on the estimate's error, ns.
    pub error_ns: u64,
    /// Readings it was taken from.
    pub readings: usize,
}

impl ClockOffset {
    /// The estimate from `readings`; `None` if there is none.
    pub fn estimate(readings: &[ClockReading]) -> Option<Self> {
        let best = readings
            .iter()
            .filter(|r| r.received_ns >= r.sent_ns)
            .min_by_key(|r| r.received_ns - r.sent_ns)?;
        let rtt = best.received_ns - best.sent_ns;
        let middle = best.sent_ns as i128 + (rtt / 2) as i128;
        Some(Self {
            offset_ns: (best.agent_ns as i128 - middle) as i64,
            error_ns: rtt.div_ceil(2),
            readings: readings.len(),
        })
    }

    /// `t_ns` of the coordinator's clock on the agent's clock.
    pub fn to_agent(&self, t_ns: u64) -> u64 {
        t_ns.saturating_add_signed(self.offset_ns)
    }
}

/// A monotonic stamp moved by `shift_ns`; 0 (no stamp) stays 0.
pub fn shift_stamp(stamp_ns: u64, shift_ns: i64) -> u64 {
    if stamp_ns == 0 {
        0
    } else {
        stamp_ns.saturating_add_signed(shift_ns)
    }
}

/// An agent's answer once its processes are ready.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StartReply {
    /// The agent's process id.
    pub pid: u32,
    /// Processes it started.
    pub processes: usize,
    /// Services it bridges out and in.
    pub exports: usize,
    /// Services it bridges in.
    pub imports: usize,
}

/// What a host did in a run: the first reply to `finish`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct HostOutcome {
    /// The host.
    pub host: String,
    /// Every reaped process's usage.
    pub usage: Vec<ProcessUsage>,
    /// The processes' exit statistics.
    pub stats: Vec<shoal_runtime::stats::StatsFile>,
    /// The host's events (faults, deaths, restarts).
    pub events: Vec<serde_json::Value>,
    /// CPU time of the agent itself, s.
    pub agent_cpu_s: f64,
    /// Samples bridged out to Zenoh, and in from it.
    pub bridged_out: u64,
    /// Samples bridged in from Zenoh.
    pub bridged_in: u64,
    /// Samples the bridge could not take (iceoryx2 subscriber overflow).
    pub bridge_lost: u64,
    /// Why the host's share of the run failed, if it did.
    pub error: Option<String>,
    /// The files that follow, relative to the run's output directory.
    pub files: Vec<String>,
    /// Shared-memory files of the run left on the host after cleanup.
    pub leftover_shm: usize,
}

/// One piece of a file a host sends back (the reply's attachment; the
/// payload is the bytes).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FileChunk {
    /// Path relative to the run's output directory.
    pub path: String,
    /// Byte offset of this piece.
    pub offset: u64,
    /// Size of the whole file.
    pub total: u64,
}

/// Bytes per file chunk.
pub const CHUNK_BYTES: usize = 4 << 20;

/// The Zenoh configuration of an agent: a router listening on `listen`,
/// connecting to nobody, no scouting (agents link only to the coordinator);
/// over TLS, answering only the `coordinators` named.
pub fn agent_config(
    listen: &[String],
    security: &Security,
    coordinators: &[String],
) -> anyhow::Result<zenoh::Config> {
    let acl = matches!(security, Security::Tls(_)).then(|| tls::answer_only(coordinators));
    base_config(listen, &[], security, acl.as_ref())
}

/// The Zenoh configuration of a coordinator: a router connecting to every
/// agent, listening nowhere; over TLS with `acl` (see
/// [`tls::coordinator_acl`]).
pub fn coordinator_config(
    connect: &[String],
    security: &Security,
    acl: Option<&serde_json::Value>,
) -> anyhow::Result<zenoh::Config> {
    base_config(&[], connect, security, acl)
}

/// A router listening on `listen` and connecting to `connect` (the
/// benchmark's peers).
pub fn router_config(
    listen: &[String],
    connect: &[String],
    security: &Security,
    acl: Option<&serde_json::Value>,
) -> anyhow::Result<zenoh::Config> {
    base_config(listen, connect, security, acl)
}

fn base_config(
    listen: &[String],
    connect: &[String],
    security: &Security,
    acl: Option<&serde_json::Value>,
) -> anyhow::Result<zenoh::Config> {
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: String| {
        c.insert_json5(k, &v)
            .map_err(|e| anyhow::anyhow!("zenoh configuration {k} = {v}: {e}"))
    };
    set(&mut c, "mode", "\"router\"".into())?;
    set(&mut c, "listen/endpoints", serde_json::to_string(listen)?)?;
    set(&mut c, "connect/endpoints", serde_json::to_string(connect)?)?;
    set(&mut c, "scouting/multicast/enabled", "false".into())?;
    set(&mut c, "scouting/gossip/enabled", "false".into())?;
    // An agent that is not there yet is retried; a run waits for it.
    set(&mut c, "connect/timeout_ms", "-1".into())?;
    if let Security::Tls(id) = security {
        for (k, v) in id.zenoh_settings() {
            set(&mut c, k, v)?;
        }
        if let Some(acl) = acl {
            set(&mut c, "access_control", acl.to_string())?;
        }
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn keys_name_their_host_and_run() {
        assert_eq!(host_of_alive(&alive("h2")), Some("h2"));
        assert_eq!(last_chunk(&fence("r", "h3")), "h3");
        assert_eq!(decode_tick(&encode_tick(77)), Some(77));
        assert_eq!(decode_tick(b"x"), None);
    }

    #[test]
    fn the_offset_comes_from_the_fastest_round_trip() {
        // The agent runs 5 ms ahead; the second reading is the fastest.
        let r = |sent: u64, at: u64, back: u64| ClockReading {
            sent_ns: sent,
            agent_ns: at + 5_000_000,
            received_ns: back,
        };
        let o = ClockOffset::estimate(&[
            r(0, 900, 1_000),
            r(2_000, 2_050, 2_100),
            r(3_000, 3_010, 3_600),
        ])
        .unwrap();
        assert_eq!(o.error_ns, 50);
        assert_eq!(o.offset_ns, 5_000_000);
        assert_eq!(o.to_agent(1_000), 5_001_000);
        assert_eq!(ClockOffset::estimate(&[]), None);
        assert_eq!(shift_stamp(0, -7), 0);
        assert_eq!(shift_stamp(10, -7), 3);
    }

    proptest! {
        /// Whatever the delays each way, the true offset lies within the
        /// stated error of the estimate.
        #[test]
        fn the_true_offset_lies_within_the_stated_error(
            offset in -1_000_000_000i64..1_000_000_000,
            trips in proptest::collection::vec((0u64..5_000_000, 0u64..5_000_000, 0u64..1_000_000), 1..20),
        ) {
            let mut t = 10_000_000_000u64;
            let readings: Vec<ClockReading> = trips
                .iter()
                .map(|&(there, back, gap)| {
                    let r = ClockReading {
                        sent_ns: t,
                        agent_ns: (t + there).saturating_add_signed(offset),
                        received_ns: t + there + back,
                    };
                    t += there + back + gap;
                    r
                })
                .collect();
            let o = ClockOffset::estimate(&readings).unwrap();
            prop_assert!((o.offset_ns - offset).unsigned_abs() <= o.error_ns);
        }

        #[test]
        fn a_trimmed_sample_comes_back_whole(
            head in proptest::collection::vec(any::<u8>(), 0..300),
            zeros in 0usize..300,
        ) {
            let mut sample = head.clone();
            sample.extend(std::iter::repeat_n(0u8, zeros));
            let wire = trim(&sample);
            prop_assert!(wire.len() <= head.len());
            // Nothing but the zero tail goes: the wire ends in a non-zero byte.
            prop_assert_ne!(wire.last(), Some(&0));
            let mut back = vec![0xAAu8; sample.len()];
            prop_assert!(untrim(wire, &mut back));
            prop_assert_eq!(back, sample);
        }
    }
}
