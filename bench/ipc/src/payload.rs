//! What travels in a ping-pong: a round number and a payload that the
//! pinger fills from the round number and checks in the reply.
//!
//! The raw iceoryx2 and socket cases use [`Raw256`] / [`Raw4K`] (plain
//! `#[repr(C)]` words, no shoal header); the shoal cases use
//! [`BenchPing256`] / [`BenchPing4K`] from `ipc-types`, which start with
//! shoal's common header and go through the real `Sample` trait. Each pair
//! has the same total size, and both are filled and checked by the same two
//! functions over their payload as 64-bit words (a shoal payload's floats
//! by their bits), so the pinger and ponger of a shoal case do the same
//! work on the payload as a raw case's, and the ratio of the two is the
//! ports' alone.

use iceoryx2::prelude::ZeroCopySend;
use ipc_types::bench::{BenchPing1M, BenchPing256, BenchPing256K, BenchPing4K};

/// A ping-pong message, written and read in place (a large one never
/// travels by value).
pub trait Payload: bytemuck::Pod + Send + std::fmt::Debug + 'static {
    /// Total size in bytes.
    const SIZE: usize;
    /// Writes the message of `round` in place: the round number and a
    /// payload derived from it (every word of the small sizes; eight words
    /// spread over the large ones, which a producer such as a camera writes
    /// whole anyway, whatever carries them: the benchmark measures the
    /// transport, and a socket still copies every byte).
    fn fill(&mut self, round: u64);
    /// The round number it carries.
    fn round(&self) -> u64;
    /// True when the payload is the one [`Payload::fill`] writes for `round`
    /// (shoal's header, which each publisher restamps, is not compared).
    fn check(&self, round: u64) -> bool;
    /// The message of `round`, by value (small sizes only).
    fn make(round: u64) -> Self {
        let mut m: Self = bytemuck::Zeroable::zeroed();
        m.fill(round);
        m
    }
    /// True when every float of the message is finite, checked field by
    /// field in code (no schema walk); raw messages hold no floats.
    fn payload_is_finite(&self) -> bool {
        true
    }
}

/// Words written and checked in a large payload, spread evenly over it.
pub const SPOT_WORDS: usize = 8;

/// The multiplier that spreads a word's index over its bits.
const SPREAD: u64 = 0x9E37_79B9_7F4A_7C15;

/// Word `i` of the payload of `round`, raw or shoal, from `spread`, which
/// is `(i + 1) * SPREAD` (kept by the loops as a running sum). Bit 62 is
/// clear, so read as a float its exponent is below the all-ones of
/// infinity and NaN: a shoal payload's floats are finite, as a service's
/// sample must be.
fn word(round: u64, spread: u64) -> u64 {
    (round ^ spread) & !(1 << 62)
}

/// Writes every `STRIDE`-th word of a payload for `round`. Raw and shoal
/// payloads are filled and checked by these same two functions, over their
/// words as `u64` (one copy of the machine code for both): a shoal case
/// differs from its raw peer by the ports alone.
#[inline(never)]
fn fill_words<const STRIDE: usize>(words: &mut [u64], round: u64) {
    let mut spread = SPREAD;
    for w in words.iter_mut().step_by(STRIDE) {
        *w = word(round, spread);
        spread = spread.wrapping_add(SPREAD.wrapping_mul(STRIDE as u64));
    }
}

/// True when every `STRIDE`-th word is the one [`fill_words`] writes for `round`.
#[inline(never)]
fn check_words<const STRIDE: usize>(words: &[u64], round: u64) -> bool {
    let mut spread = SPREAD;
    let mut diff = 0;
    for &w in words.iter().step_by(STRIDE) {
        diff |= w ^ word(round, spread);
        spread = spread.wrapping_add(SPREAD.wrapping_mul(STRIDE as u64));
    }
    diff == 0
}

macro_rules! raw_payload {
    ($(#[$meta:meta])* $name:ident, $tn:literal, $words:expr, $size:expr, $stride:expr) => {
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
            fn fill(&mut self, round: u64) {
                self.round = round;
                fill_words::<{ $stride }>(&mut self.words, round);
            }
            fn round(&self) -> u64 {
                self.round
            }
            fn check(&self, round: u64) -> bool {
                self.round == round && check_words::<{ $stride }>(&self.words, round)
            }
        }
    };
}

raw_payload!(
    /// 256 bytes of plain words for the raw iceoryx2 and socket cases.
    Raw256,
    "shoal.bench.Raw256.v1",
    31,
    256,
    1
);
raw_payload!(
    /// 4096 bytes of plain words for the raw iceoryx2 and socket cases.
    Raw4K,
    "shoal.bench.Raw4K.v1",
    511,
    4096,
    1
);
raw_payload!(
    /// 256 KiB of plain words for the raw iceoryx2 and socket cases.
    Raw256K,
    "shoal.bench.Raw256K.v1",
    (256 * 1024 - 8) / 8,
    256 * 1024,
    (256 * 1024 - 8) / 8 / SPOT_WORDS
);
raw_payload!(
    /// 1 MiB of plain words for the raw iceoryx2 and socket cases.
    Raw1M,
    "shoal.bench.Raw1M.v1",
    (1024 * 1024 - 8) / 8,
    1024 * 1024,
    (1024 * 1024 - 8) / 8 / SPOT_WORDS
);

macro_rules! shoal_payload {
    ($name:ident, $size:expr, $stride:expr, $finite:expr) => {
        impl Payload for $name {
            const SIZE: usize = $size;
            fn fill(&mut self, round: u64) {
                self.round = round;
                fill_words::<{ $stride }>(bytemuck::cast_slice_mut(&mut self.payload), round);
            }
            fn round(&self) -> u64 {
                self.round
            }
            fn check(&self, round: u64) -> bool {
                self.round == round
                    && check_words::<{ $stride }>(bytemuck::cast_slice(&self.payload), round)
            }
            fn payload_is_finite(&self) -> bool {
                // The header holds integers only; `round` too.
                $finite(&self.payload)
            }
        }
    };
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn integers(_: &[u64]) -> bool {
    true
}

shoal_payload!(BenchPing256, 256, 1, all_finite);
shoal_payload!(BenchPing4K, 4096, 1, all_finite);
shoal_payload!(
    BenchPing256K,
    256 * 1024,
    (256 * 1024 - 48) / 8 / SPOT_WORDS,
    integers
);
shoal_payload!(
    BenchPing1M,
    1024 * 1024,
    (1024 * 1024 - 48) / 8 / SPOT_WORDS,
    integers
);

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::Sample;

    #[test]
    fn payloads_differ_between_rounds_and_check_against_their_own() {
        fn check<P: Payload>() {
            let mut a: Box<P> = bytemuck::zeroed_box();
            a.fill(7);
            assert_eq!(a.round(), 7);
            assert!(a.check(7));
            assert!(!a.check(8));
            assert_eq!(std::mem::size_of::<P>(), P::SIZE);
        }
        check::<Raw256>();
        check::<Raw4K>();
        check::<Raw256K>();
        check::<Raw1M>();
        check::<BenchPing256>();
        check::<BenchPing4K>();
        check::<BenchPing256K>();
        check::<BenchPing1M>();
        // A corrupted checked word of a large payload is refused.
        let mut big: Box<Raw1M> = bytemuck::zeroed_box();
        big.fill(3);
        big.words[(big.words.len() / SPOT_WORDS) * 7] ^= 1;
        assert!(!big.check(3));
    }

    #[test]
    fn shoal_payloads_pass_the_finite_check_and_ignore_the_header() {
        let mut a = BenchPing4K::make(u64::MAX);
        assert!(a.is_finite());
        a.header.seq = 99;
        assert!(a.check(u64::MAX));
        a.payload[3] += 1.0;
        assert!(!a.check(u64::MAX));
    }
}
