//! What travels in a ping-pong: a round number and a payload that the
//! pinger fills from the round number and checks in the reply.
//!
//! The raw iceoryx2 and socket cases use [`Raw256`] / [`Raw4K`] (plain
//! `#[repr(C)]` words, no shoal header); the shoal cases use
//! [`BenchPing256`] / [`BenchPing4K`] from `ipc-types`, which start with
//! shoal's common header and go through the real `Sample` trait. Each pair
//! has the same total size.

use iceoryx2::prelude::ZeroCopySend;
use ipc_types::bench::{BenchPing256, BenchPing4K};

/// A ping-pong message.
pub trait Payload: Copy + Send + std::fmt::Debug + 'static {
    /// Total size in bytes.
    const SIZE: usize;
    /// The message of `round`: the round number and a payload derived from it.
    fn make(round: u64) -> Self;
    /// The round number it carries.
    fn round(&self) -> u64;
    /// True when every float of the message is finite, checked field by
    /// field in code (no schema walk); raw messages hold no floats.
    fn payload_is_finite(&self) -> bool {
        true
    }
    /// True when `other` carries the same round number and payload
    /// (shoal's header, which each publisher restamps, is not compared).
    fn same_payload(&self, other: &Self) -> bool;
}

/// Word `i` of the raw payload of `round`.
fn raw_word(round: u64, i: usize) -> u64 {
    round ^ (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// Element `i` of the shoal payload of `round` (always finite).
fn shoal_value(round: u64, i: usize) -> f64 {
    (round % (1 << 40)) as f64 + i as f64 * 0.25
}

macro_rules! raw_payload {
    ($(#[$meta:meta])* $name:ident, $tn:literal, $words:expr, $size:expr) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable, ZeroCopySend)]
        #[type_name($tn)]
        pub struct $name {
            /// Round number.
            pub round: u64,
            /// Payload words.
            pub words: [u64; $words],
        }
        const _: () = assert!(std::mem::size_of::<$name>() == $size);

        impl Payload for $name {
            const SIZE: usize = $size;
            fn make(round: u64) -> Self {
                let mut words = [0u64; $words];
                for (i, w) in words.iter_mut().enumerate() {
                    *w = raw_word(round, i);
                }
                Self { round, words }
            }
            fn round(&self) -> u64 {
                self.round
            }
            fn same_payload(&self, other: &Self) -> bool {
                self == other
            }
        }
    };
}

raw_payload!(
    /// 256 bytes of plain words for the raw iceoryx2 and socket cases.
    Raw256,
    "shoal.bench.Raw256.v1",
    31,
    256
);
raw_payload!(
    /// 4096 bytes of plain words for the raw iceoryx2 and socket cases.
    Raw4K,
    "shoal.bench.Raw4K.v1",
    511,
    4096
);

macro_rules! shoal_payload {
    ($name:ident, $size:expr) => {
        impl Payload for $name {
            const SIZE: usize = $size;
            fn make(round: u64) -> Self {
                let mut s: Self = bytemuck::Zeroable::zeroed();
                s.round = round;
                for (i, v) in s.payload.iter_mut().enumerate() {
                    *v = shoal_value(round, i);
                }
                s
            }
            fn round(&self) -> u64 {
                self.round
            }
            fn same_payload(&self, other: &Self) -> bool {
                self.round == other.round && self.payload == other.payload
            }
            fn payload_is_finite(&self) -> bool {
                // The header holds integers only; `round` too.
                self.payload.iter().all(|v| v.is_finite())
            }
        }
    };
}

shoal_payload!(BenchPing256, 256);
shoal_payload!(BenchPing4K, 4096);

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::Sample;

    #[test]
    fn payloads_differ_between_rounds_and_compare_equal_to_themselves() {
        fn check<P: Payload>() {
            let a = P::make(7);
            assert_eq!(a.round(), 7);
            assert!(a.same_payload(&P::make(7)));
            assert!(!a.same_payload(&P::make(8)));
            assert_eq!(std::mem::size_of::<P>(), P::SIZE);
        }
        check::<Raw256>();
        check::<Raw4K>();
        check::<BenchPing256>();
        check::<BenchPing4K>();
    }

    #[test]
    fn shoal_payloads_pass_the_finite_check_and_ignore_the_header() {
        let mut a = BenchPing4K::make(u64::MAX);
        assert!(a.is_finite());
        let b = a;
        a.header.seq = 99;
        assert!(a.same_payload(&b));
        a.payload[3] += 1.0;
        assert!(!a.same_payload(&b));
    }
}
