//! Sample types of `shoal bench ipc`: ping-pong samples of 256 B, 4 KiB,
//! 256 KiB and 1 MiB (common [`Header`] included) that travel through
//! shoal's real ports, and the names of the benchmark's services.
//!
//! The payload is `f64`s, like every real shoal sample, so the publisher's
//! and subscriber's finite-value checks do the work they do on real channels.
//!
//! ```
//! use ipc_types::bench::{BenchPing256, BenchPing4K};
//! assert_eq!(std::mem::size_of::<BenchPing256>(), 256);
//! assert_eq!(std::mem::size_of::<BenchPing4K>(), 4096);
//! ```

use iceoryx2::prelude::ZeroCopySend;

use crate::{schema, Described, FieldDesc, FieldType, Header, Sample, TypeDesc};

sample! {
    /// A 256-byte ping-pong sample of `shoal bench ipc`.
    pub struct BenchPing256("shoal_msgs/msg/BenchPing256", "shoal.BenchPing256.v1", size = 256) {
        /// Common header.
        pub header: Header,
        /// Round trip this sample belongs to (the pong echoes the ping's).
        pub round: u64,
        /// Payload filled by the pinger and echoed unchanged by the ponger.
        pub payload: [f64; 26],
    }
}

sample! {
    /// A 4096-byte ping-pong sample of `shoal bench ipc`.
    pub struct BenchPing4K("shoal_msgs/msg/BenchPing4K", "shoal.BenchPing4K.v1", size = 4096) {
        /// Common header.
        pub header: Header,
        /// Round trip this sample belongs to (the pong echoes the ping's).
        pub round: u64,
        /// Payload filled by the pinger and echoed unchanged by the ponger.
        pub payload: [f64; 506],
    }
}

sample! {
    /// A 256 KiB ping-pong sample of `shoal bench ipc` (a camera frame's
    /// size), sent and read in place. Its payload is integers: the finite
    /// check costs nothing, as on an image.
    pub struct BenchPing256K("shoal_msgs/msg/BenchPing256K", "shoal.BenchPing256K.v1", size = 256 * 1024) {
        /// Common header.
        pub header: Header,
        /// Round trip this sample belongs to (the pong echoes the ping's).
        pub round: u64,
        /// Payload: eight words spread over it are written and checked.
        pub payload: [u64; (256 * 1024 - 48) / 8],
    }
}

sample! {
    /// A 1 MiB ping-pong sample of `shoal bench ipc`, sent and read in place.
    pub struct BenchPing1M("shoal_msgs/msg/BenchPing1M", "shoal.BenchPing1M.v1", size = 1024 * 1024) {
        /// Common header.
        pub header: Header,
        /// Round trip this sample belongs to (the pong echoes the ping's).
        pub round: u64,
        /// Payload: eight words spread over it are written and checked.
        pub payload: [u64; (1024 * 1024 - 48) / 8],
    }
}

/// Direction of a benchmark channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchDirection {
    /// Pinger → ponger.
    Ping,
    /// Ponger → pinger.
    Pong,
}

impl BenchDirection {
    /// `ping` or `pong`.
    pub const fn name(self) -> &'static str {
        match self {
            BenchDirection::Ping => "ping",
            BenchDirection::Pong => "pong",
        }
    }
}

/// `shoal/<run-id>/bench/<case>/<size>/<ping|pong>`: the sample channel of
/// one benchmark case in one direction.
pub fn bench_service_name(run_id: &str, case: &str, size: usize, dir: BenchDirection) -> String {
    format!("shoal/{run_id}/bench/{case}/{size}/{}", dir.name())
}

/// `shoal/<run-id>/bench/<case>/<size>/<ping|pong>/event`: the event service
/// that wakes the receiver of one direction (raw iceoryx2 cases).
pub fn bench_event_name(run_id: &str, case: &str, size: usize, dir: BenchDirection) -> String {
    format!("{}/event", bench_service_name(run_id, case, size, dir))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bench_samples_have_schemas_and_are_finite_when_zeroed() {
        let s = schema::ros2msg_schema::<BenchPing4K>().unwrap();
        assert!(s.starts_with("shoal_msgs/Header header\n"));
        assert!(s.contains("float64[506] payload"));
        assert!(BenchPing256::zeroed().is_finite());
        let mut p = BenchPing4K::zeroed();
        p.payload[505] = f64::NAN;
        assert!(!p.is_finite());
    }

    #[test]
    fn bench_service_names_separate_directions() {
        assert_eq!(
            bench_service_name("r", "shoal-poll", 256, BenchDirection::Ping),
            "shoal/r/bench/shoal-poll/256/ping"
        );
        assert_ne!(
            bench_event_name("r", "iox2-event", 256, BenchDirection::Ping),
            bench_event_name("r", "iox2-event", 256, BenchDirection::Pong)
        );
    }
}
