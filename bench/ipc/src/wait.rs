//! Waiting, shared by the iceoryx2 cases (raw and shoal): the polling wait
//! every `*-poll` case uses — spin, then yield, and give up after a timeout;
//! the clock is read only every [`CHECK_EVERY`] misses, so a reply that
//! arrives within the spin phase costs no clock read — and the notify and
//! WaitSet error handling of the blocking cases.

use std::time::{Duration, Instant};

use crate::{cause, BenchError};

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

/// Notifies an event, as a bench error on failure.
pub(crate) fn notify(
    n: &iceoryx2::port::notifier::Notifier<iceoryx2::prelude::ipc::Service>,
) -> Result<(), BenchError> {
    n.notify().map(|_| ()).map_err(|e| BenchError::Io {
        what: "notify",
        source: cause(e),
    })
}

/// A failed wait, as a bench error.
pub(crate) fn wait_error(e: impl std::error::Error + Send + Sync + 'static) -> BenchError {
    BenchError::Io {
        what: "waiting",
        source: cause(e),
    }
}

/// A wait that a signal ended is an interruption of the bench.
pub(crate) fn check_run(r: iceoryx2::waitset::WaitSetRunResult) -> Result<(), BenchError> {
    use iceoryx2::waitset::WaitSetRunResult;
    match r {
        WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt => {
            Err(BenchError::Interrupted)
        }
        _ => Ok(()),
    }
}
