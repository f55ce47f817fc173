//! The polling wait every `*-poll` case shares: spin, then yield, and give
//! up after a timeout. The clock is read only every [`CHECK_EVERY`] misses,
//! so a reply that arrives within the spin phase costs no clock read.

use std::time::{Duration, Instant};

use crate::BenchError;

/// Misses spent in `spin_loop` before each further miss yields the CPU.
const SPIN_MISSES: u32 = 20_000;
/// Misses between two looks at the clock.
const CHECK_EVERY: u32 = 1024;

/// One polling wait.
pub(crate) struct Backoff {
    misses: u32,
    timeout: Duration,
    started: Option<Instant>,
    what: &'static str,
}

impl Backoff {
    /// A wait that fails with a timeout naming `what`.
    pub(crate) fn new(timeout: Duration, what: &'static str) -> Self {
        Self {
            misses: 0,
            timeout,
            started: None,
            what,
        }
    }

    /// Called after each empty try: spins or yields; fails once the timeout
    /// has passed since the first clock check.
    pub(crate) fn snooze(&mut self) -> Result<(), BenchError> {
        self.misses = self.misses.saturating_add(1);
        if self.misses < SPIN_MISSES {
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
        if self.misses.is_multiple_of(CHECK_EVERY) {
            let now = Instant::now();
            let started = *self.started.get_or_insert(now);
            if now.duration_since(started) > self.timeout {
                return Err(BenchError::Timeout {
                    what: self.what,
                    secs: self.timeout.as_secs_f64(),
                });
            }
            if iceoryx2_bb_posix::signal::SignalHandler::termination_requested() {
                return Err(BenchError::Interrupted);
            }
        }
        Ok(())
    }
}
