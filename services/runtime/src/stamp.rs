//! The latency stamps' clock: `CLOCK_MONOTONIC`, read through the CPU's
//! time-stamp counter between exact reads.
//!
//! Every sample is stamped when published and when taken, and the two stamps
//! come from different processes. [`crate::mono_ns`] costs a vDSO call that
//! orders the counter read behind every outstanding load (about 21 ns on the
//! reference machine, two per hop); the counter alone costs about 9. So
//! [`stamp_ns`] extrapolates from the last exact read with the counter, and
//! reads the exact clock again once the last one is older than its window.
//!
//! How far that is off: each exact read's counter value is known to within
//! half the counter ticks that bracket it, and a read bracketed by more than
//! [`MAX_BRACKET_TICKS`] (interrupted, or slowed by a cache miss) does not
//! anchor the counter: an anchor is off by at most half that, 25 ns at the
//! reference machine's 2.6 GHz, and by under 15 typically. The counter's
//! rate is measured against the exact clock over the thread's life so far
//! (the span from its first exact read to its last); the window is
//! 1/[`WINDOW_SHARE`] of that span, at most [`WINDOW_NS`], so the rate error
//! moves a stamp by at most 2/[`WINDOW_SHARE`] of a bracket over one window,
//! plus what NTP slewing changed in the clock's rate since the thread began
//! (at most 500 ppm of [`WINDOW_NS`], 50 ns). The stamps of different
//! processes therefore agree with `CLOCK_MONOTONIC`, and with each other, to
//! that. Until the span reaches [`WINDOW_SHARE`] µs every stamp is an exact
//! read.
//!
//! The counter is used only where the kernel itself keeps time with it
//! (current clocksource `tsc`, which it picks only for an invariant,
//! synchronised counter) on x86-64; elsewhere every stamp is an exact read.

use std::cell::Cell;
use std::sync::OnceLock;

use crate::mono_ns;

/// Longest a stamp extrapolates from an exact read, ns.
pub const WINDOW_NS: u64 = 100_000;

/// A stamp extrapolates at most this fraction of the span the counter's rate
/// was measured over (1/64: the rate error then moves a stamp by at most
/// 1/32 of an exact read's bracket).
pub const WINDOW_SHARE: u64 = 64;

/// Widest bracket of counter reads around an exact read that may anchor the
/// counter, ticks: 49 ns at 2.6 GHz, 32 ns at 4 GHz. An undisturbed read
/// takes about 21 ns (55 ticks at 2.6 GHz); a wider bracket (an interrupt, a
/// cache miss in between) would leave the anchor off by up to half of it.
pub const MAX_BRACKET_TICKS: u64 = 128;

/// One exact read and the counter around it, with the counter's rate.
#[derive(Debug, Clone, Copy)]
struct Anchor {
    /// The last exact read, ns, and the counter at it.
    ns: u64,
    tsc: u64,
    /// The thread's first exact read, ns, and the counter at it.
    first_ns: u64,
    first_tsc: u64,
    /// ns per counter tick, 32.32 fixed point; 0 until calibrated.
    scale: u64,
    /// Counter ticks in [`WINDOW_NS`]; 0 until calibrated.
    window_ticks: u64,
}

thread_local! {
    static ANCHOR: Cell<Option<Anchor>> = const { Cell::new(None) };
}

/// True if the time-stamp counter can stand in for the exact clock here.
fn counter_usable() -> bool {
    static USABLE: OnceLock<bool> = OnceLock::new();
    *USABLE.get_or_init(|| {
        cfg!(target_arch = "x86_64")
            && std::fs::read_to_string(
                "/sys/devices/system/clocksource/clocksource0/current_clocksource",
            )
            .is_ok_and(|s| s.trim() == "tsc")
    })
}

#[cfg(target_arch = "x86_64")]
fn counter() -> u64 {
    // SAFETY: RDTSC has no preconditions on x86-64; it only reads the counter.
    #[allow(unsafe_code)]
    unsafe {
        core::arch::x86_64::_rdtsc()
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn counter() -> u64 {
    0
}

/// `CLOCK_MONOTONIC` now, ns, for a latency stamp (see the module doc).
pub fn stamp_ns() -> u64 {
    if !counter_usable() {
        return mono_ns();
    }
    let tsc = counter();
    if let Some(a) = ANCHOR.get() {
        let ticks = tsc.wrapping_sub(a.tsc);
        if ticks < a.window_ticks {
            return a.ns + ((u128::from(ticks) * u128::from(a.scale)) >> 32) as u64;
        }
    }
    exact(tsc)
}

/// An exact read, taken as the new anchor if the counter reads around it
/// are close; `before` is the counter just before it.
fn exact(before: u64) -> u64 {
    let ns = mono_ns();
    let after = counter();
    let bracket = after.wrapping_sub(before);
    if bracket > MAX_BRACKET_TICKS {
        return ns;
    }
    // The exact read happened between the two counter reads.
    let tsc = before.wrapping_add(bracket / 2);
    let mut a = ANCHOR.get().unwrap_or(Anchor {
        ns,
        tsc,
        first_ns: ns,
        first_tsc: tsc,
        scale: 0,
        window_ticks: 0,
    });
    a.ns = ns;
    a.tsc = tsc;
    let span_ns = ns.saturating_sub(a.first_ns);
    let span_ticks = tsc.wrapping_sub(a.first_tsc);
    let window_ns = (span_ns / WINDOW_SHARE).min(WINDOW_NS);
    if window_ns >= 1_000 && span_ticks > 0 && span_ticks < u64::MAX / 2 {
        let scale = (u128::from(span_ns) << 32) / u128::from(span_ticks);
        a.scale = u64::try_from(scale).unwrap_or(0);
        a.window_ticks = if a.scale == 0 {
            0
        } else {
            u64::try_from((u128::from(window_ns) << 32) / u128::from(a.scale)).unwrap_or(0)
        };
    }
    ANCHOR.set(Some(a));
    ns
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every stamp lies between the exact reads just before and just after
    /// it, to within `slack` ns; over 40 ms, so the counter is calibrated
    /// for most of it, with pauses longer and shorter than the window.
    fn bracketed(slack: u64) -> (u64, u64) {
        let start = mono_ns();
        let (mut stamps, mut outside) = (0u64, 0u64);
        let mut i = 0u64;
        while mono_ns() - start < 40_000_000 {
            i += 1;
            if i.is_multiple_of(97) {
                std::thread::sleep(std::time::Duration::from_micros(150));
            } else if i.is_multiple_of(7) {
                let t = mono_ns();
                while mono_ns() - t < 20_000 {}
            }
            let before = mono_ns();
            let s = stamp_ns();
            let after = mono_ns();
            stamps += 1;
            if s + slack < before || s > after + slack {
                outside += 1;
            }
        }
        (stamps, outside)
    }

    #[test]
    fn stamps_agree_with_the_exact_clock() {
        let (stamps, outside) = bracketed(1_000);
        assert!(stamps > 1_000, "only {stamps} stamps");
        assert_eq!(
            outside, 0,
            "{outside} of {stamps} stamps off by more than 1 µs"
        );
    }

    #[test]
    fn the_counter_is_calibrated_after_the_calibration_span_where_usable() {
        let _ = bracketed(1_000);
        let a = ANCHOR.get();
        if let Some(a) = a.filter(|_| counter_usable()) {
            assert!(a.scale > 0 && a.window_ticks > 0, "{a:?}");
            // The window holds WINDOW_NS of counter ticks.
            let window_ns = (u128::from(a.window_ticks) * u128::from(a.scale)) >> 32;
            assert!(
                window_ns.abs_diff(u128::from(WINDOW_NS)) < 100,
                "{window_ns}"
            );
        } else {
            // Every stamp was an exact read.
            assert!(a.is_none());
        }
    }
}
