//! The lockstep doorbell: how the orchestrator wakes the processes due at a
//! tick.
//!
//! One shared-memory segment per run, `/dev/shm/shoal_<run-id>_doorbell`
//! (the domain's prefix, so the run's cleanup and the stale-domain sweep
//! remove it with the rest), holds one slot per process, each on a cache
//! line of its own: the counter of its wake-ups and the last one it
//! finished. The orchestrator wakes process `i` by incrementing counter `i`
//! and calling `FUTEX_WAKE` on it; the process sleeps in `FUTEX_WAIT` until
//! the counter differs from the value it last stepped on.
//!
//! A further slot counts the processes of the tick still stepping: the
//! orchestrator sets it before it rings them, each process decrements it
//! when it has finished, and only the one that brings it to zero notifies
//! done. Which processes have finished is read from their slots, so a count
//! that a death left too high costs a wait's slice, never a wrong answer.
//!
//! The last slot is done's own counter, the other way round: a process
//! that notifies done increments it and calls `FUTEX_WAKE`, and the
//! orchestrator, having read it before it read the processes' slots, sleeps
//! in `FUTEX_WAIT` until it differs. It replaced the iceoryx2 event `done`
//! for finished steps (a `sendto` for the process, a `ppoll` and a
//! `recvfrom` for the orchestrator); that event still carries what is rare,
//! a restarted process's "ready".
//!
//! A ring also carries the tick it is for ([`Rung`]: the tick, its
//! simulated time, whether it is the run's last), which is all a process
//! needs of the run's clock, and whether the tick's count includes the
//! step. A step it does not include is one the orchestrator does not wait
//! for at the tick's end (the recorder's, which only has to be over before
//! it is rung again): that process notifies done itself, and its slot still
//! holds its tick when the run has moved on by the time it runs.
//!
//! It replaced an iceoryx2 event per process, whose Unix datagram socket
//! cost the orchestrator a `sendto` and the process a `ppoll` and one or two
//! `recvfrom` per step. A futex wake carries no data and needs neither: on
//! this machine a round trip between two processes cost 12 to 13 µs of CPU
//! by futex and 20 to 25 µs by datagram socket with `poll` (the same
//! wake-ups, counted in a C ping-pong of 100 000 round trips).
//!
//! Processes rung at the same ticks (the same rate and phase: every
//! vehicle's sonar, say) form a group: each sleeps on its group's gate, a
//! further counter in the group's first slot, instead of its own counter.
//! The orchestrator moves every due counter, then each group's gate once,
//! and one `FUTEX_WAKE` wakes the whole group: a system call per group of
//! a tick instead of one per process. A member woken without its counter
//! moving (a restarted process rung alone wakes its group) sleeps again.
//!
//! A counter changed before a process read it for the first time is not a
//! wake-up for it: a process reads its counter before it reports ready, so
//! a restarted process steps only when the orchestrator rings it anew.

use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::Duration;

use iceoryx2::prelude::{FileName, SemanticString};
use iceoryx2_bb_posix::access_mode::AccessMode;
use iceoryx2_bb_posix::creation_mode::CreationMode;
use iceoryx2_bb_posix::shared_memory::{SharedMemory, SharedMemoryBuilder};

use crate::domain::domain_prefix;

/// Slots past the processes': the tick's count of processes stepping and
/// done's counter.
const EXTRA_SLOTS: usize = 2;

/// One process's slot, alone on its cache line (the orchestrator writes
/// one while another process reads its own).
#[repr(C, align(64))]
struct Slot {
    /// Wake-ups rung so far.
    seq: AtomicU32,
    /// The wake-up whose step the process finished last.
    done: AtomicU32,
    /// Nonzero when the tick's count of processes stepping includes the
    /// step of the latest wake-up.
    counted: AtomicU32,
    /// Nonzero when the latest wake-up is for the run's last tick.
    last: AtomicU32,
    /// The gate of the group whose leader this slot is: wake-ups rung to
    /// the group so far ([`Doorbell::join`]).
    gate: AtomicU32,
    /// 1 + the slot whose gate this process sleeps on; 0 when it sleeps on
    /// its own counter.
    group: AtomicU32,
    /// The tick of the latest wake-up.
    tick: AtomicU64,
    /// Its simulated time, ns.
    sim_time_ns: AtomicU64,
}

/// The doorbell's layout, for a program that maps it without this crate
/// (the `shoal_node` Python package, whose copy [`crate::python`]
/// generates): the bytes of a slot, the slots past the processes', and
/// each field's byte offset within a slot.
pub struct Layout {
    /// Bytes per slot.
    pub slot_bytes: usize,
    /// Slots after the processes' own: the tick's count of processes
    /// stepping, then done's counter.
    pub extra_slots: usize,
    /// `(field, byte offset)`, every field of a slot.
    pub fields: [(&'static str, usize); 8],
}

/// The layout of [`Slot`].
pub const LAYOUT: Layout = Layout {
    slot_bytes: std::mem::size_of::<Slot>(),
    extra_slots: EXTRA_SLOTS,
    fields: [
        ("seq", std::mem::offset_of!(Slot, seq)),
        ("done", std::mem::offset_of!(Slot, done)),
        ("counted", std::mem::offset_of!(Slot, counted)),
        ("last", std::mem::offset_of!(Slot, last)),
        ("gate", std::mem::offset_of!(Slot, gate)),
        ("group", std::mem::offset_of!(Slot, group)),
        ("tick", std::mem::offset_of!(Slot, tick)),
        ("sim_time_ns", std::mem::offset_of!(Slot, sim_time_ns)),
    ],
};

/// The tick a wake-up is for, as the process steps on it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rung {
    /// The tick, from 0.
    pub tick: u64,
    /// Its simulated time, ns since the run started.
    pub sim_time_ns: u64,
    /// True for the run's last tick.
    pub last: bool,
}

/// Why the doorbell could not be made or opened.
#[derive(Debug, thiserror::Error)]
pub enum DoorbellError {
    /// The run id gives no valid shared-memory name.
    #[error("`{0}` is not a valid shared-memory name")]
    Name(String),
    /// The segment could not be created or opened.
    #[error("cannot map the lockstep doorbell `{name}`")]
    Map {
        /// Its name in `/dev/shm`.
        name: String,
        /// iceoryx2's error.
        #[source]
        source: iceoryx2_bb_posix::shared_memory::SharedMemoryCreationError,
    },
    /// The segment holds fewer counters than the run has processes.
    #[error(
        "the lockstep doorbell `{name}` holds {found} counters, the run has {wanted} processes"
    )]
    Size {
        /// Its name in `/dev/shm`.
        name: String,
        /// Counters it holds.
        found: usize,
        /// Processes of the run.
        wanted: usize,
    },
}

/// The doorbell of a run, mapped (see the module documentation).
pub struct Doorbell {
    shm: SharedMemory,
    slots: usize,
}

impl std::fmt::Debug for Doorbell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Doorbell")
            .field("name", &self.shm.name().to_string())
            .field("slots", &self.slots)
            .finish()
    }
}

/// The doorbell's name in `/dev/shm`.
pub fn doorbell_name(run_id: &str) -> String {
    format!("{}doorbell", domain_prefix(run_id))
}

/// The doorbell's name, and as the file name shared memory is opened by.
fn file_name(run_id: &str) -> Result<(String, FileName), DoorbellError> {
    let name = doorbell_name(run_id);
    match FileName::new(name.as_bytes()) {
        Ok(file) => Ok((name, file)),
        Err(_) => Err(DoorbellError::Name(name)),
    }
}

impl Doorbell {
    /// Creates the doorbell of a run of `processes` processes, every counter
    /// zero (the orchestrator, before it starts any process); one that
    /// exists already is an error, never taken over. It is removed when this
    /// value drops.
    pub fn create(run_id: &str, processes: usize) -> Result<Self, DoorbellError> {
        let (name, file) = file_name(run_id)?;
        let shm = SharedMemoryBuilder::new(&file)
            .creation_mode(CreationMode::CreateExclusive)
            .size((processes + EXTRA_SLOTS) * std::mem::size_of::<Slot>())
            .create()
            .map_err(|source| DoorbellError::Map { name, source })?;
        Ok(Self {
            shm,
            slots: processes,
        })
    }

    /// Opens the doorbell of a run of `processes` processes (a process of
    /// the run; it never removes it).
    pub fn open(run_id: &str, processes: usize) -> Result<Self, DoorbellError> {
        let (name, file) = file_name(run_id)?;
        let shm = SharedMemoryBuilder::new(&file)
            .open_existing(AccessMode::ReadWrite)
            .map_err(|source| DoorbellError::Map {
                name: name.clone(),
                source,
            })?;
        let found = (shm.size() / std::mem::size_of::<Slot>()).saturating_sub(EXTRA_SLOTS);
        if found < processes {
            return Err(DoorbellError::Size {
                name,
                found,
                wanted: processes,
            });
        }
        Ok(Self {
            shm,
            slots: processes,
        })
    }

    /// Slot `i`; slot `slots` is the tick's count of processes stepping,
    /// slot `slots + 1` done's counter.
    fn slot(&self, i: usize) -> &Slot {
        assert!(i < self.slots + EXTRA_SLOTS, "slot {i} of {}", self.slots);
        // SAFETY: the mapping is page aligned and holds `slots + EXTRA_SLOTS` `Slot`s
        // (checked at open); a `Slot` is atomic integers padded to 64 bytes,
        // valid for any bit pattern, and every access to it, here and in
        // other processes, is atomic. The reference lives no longer than
        // `self`, which keeps the mapping.
        #[allow(unsafe_code)]
        unsafe {
            &*self.shm.base_address().as_ptr().cast::<Slot>().add(i)
        }
    }

    fn counter(&self, i: usize) -> &AtomicU32 {
        assert!(i < self.slots, "process {i} of {}", self.slots);
        &self.slot(i).seq
    }

    /// The count of processes of the tick still stepping.
    fn stepping(&self) -> &AtomicU32 {
        &self.slot(self.slots).seq
    }

    /// Done's counter: finished steps notified so far.
    fn done_counter(&self) -> &AtomicU32 {
        &self.slot(self.slots + 1).seq
    }

    /// Done's counter now: read it before reading which processes have
    /// finished, and [`Doorbell::wait_done`] on it, so that no notification
    /// in between is lost.
    pub fn done_seq(&self) -> u32 {
        self.done_counter().load(Ordering::Acquire)
    }

    /// Notifies done (a process whose [`Doorbell::finished`] said so): wakes
    /// the one waiter, the orchestrator.
    pub fn notify_done(&self) {
        let c = self.done_counter();
        c.fetch_add(1, Ordering::Release);
        futex(c, libc::FUTEX_WAKE, 1, None);
    }

    /// Sleeps until done's counter differs from `seen`, at most `timeout`;
    /// true when it does (false when the wait ran out or a signal cut it
    /// short).
    pub fn wait_done(&self, seen: u32, timeout: Duration) -> bool {
        let done = self.done_counter();
        wait_on(done, done, seen, timeout).is_some()
    }

    /// Sets the count of processes due at the tick about to be rung (the
    /// orchestrator, before it rings them).
    pub fn arm(&self, due: usize) {
        self.stepping()
            .store(u32::try_from(due).unwrap_or(u32::MAX), Ordering::Release);
    }

    /// Process `i` has finished the step of wake-up `seq`; true when it
    /// must notify done ([`Doorbell::notify_done`]): it was the last of its
    /// tick to finish, or its step was not counted in the tick.
    pub fn finished(&self, i: usize, seq: u32) -> bool {
        assert!(i < self.slots, "process {i} of {}", self.slots);
        let slot = self.slot(i);
        slot.done.store(seq, Ordering::Release);
        if slot.counted.load(Ordering::Acquire) == 0 {
            return true;
        }
        // Never below zero: a counted step the count no longer holds (it
        // cannot happen in lockstep) would otherwise hide every later
        // tick's end.
        self.stepping()
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| n.checked_sub(1))
            .is_ok_and(|n| n == 1)
    }

    /// True when process `i` has finished the step of its latest wake-up.
    pub fn is_done(&self, i: usize) -> bool {
        let s = self.slot(i);
        s.done.load(Ordering::Acquire) == s.seq.load(Ordering::Acquire)
    }

    /// Process `i`'s counter now.
    pub fn seq(&self, i: usize) -> u32 {
        self.counter(i).load(Ordering::Acquire)
    }

    /// The tick of process `i`'s latest wake-up (read after the wake-up
    /// itself, it is the tick rung with it).
    pub fn tick(&self, i: usize) -> u64 {
        self.slot(i).tick.load(Ordering::Acquire)
    }

    /// The tick of process `i`'s latest wake-up, with its simulated time
    /// and whether it is the run's last (read after the wake-up itself, it
    /// is the one rung with it).
    pub fn rung(&self, i: usize) -> Rung {
        let slot = self.slot(i);
        Rung {
            tick: slot.tick.load(Ordering::Acquire),
            sim_time_ns: slot.sim_time_ns.load(Ordering::Acquire),
            last: slot.last.load(Ordering::Acquire) != 0,
        }
    }

    /// Makes process `i` sleep on the gate of `leader`'s group instead of
    /// its own counter (the orchestrator, before it rings `i`; `leader` is
    /// a process of the run, `i` itself for the group's first). Processes
    /// always rung at the same ticks share a group, so that
    /// [`Doorbell::ring_all`] wakes them in one system call.
    pub fn join(&self, i: usize, leader: usize) {
        assert!(leader < self.slots, "leader {leader} of {}", self.slots);
        let leader = u32::try_from(leader + 1).unwrap_or(0);
        self.slot(i).group.store(leader, Ordering::Release);
    }

    /// The word process `i` sleeps on: its group's gate, or its counter.
    fn gate(&self, i: usize) -> &AtomicU32 {
        match self.slot(i).group.load(Ordering::Acquire) {
            0 => self.counter(i),
            g => &self.slot((g as usize - 1).min(self.slots - 1)).gate,
        }
    }

    /// Stores the wake-up of process `i` in its slot and counts it; it is
    /// seen once its gate moves (or right away by a process awake).
    fn stage(&self, i: usize, rung: Rung, counted: bool) {
        let c = self.counter(i);
        let slot = self.slot(i);
        slot.tick.store(rung.tick, Ordering::Relaxed);
        slot.sim_time_ns.store(rung.sim_time_ns, Ordering::Relaxed);
        slot.last.store(u32::from(rung.last), Ordering::Relaxed);
        slot.counted.store(u32::from(counted), Ordering::Relaxed);
        // Release: a process that sees the new counter sees all above.
        c.fetch_add(1, Ordering::Release);
    }

    /// Moves `gate`, process `i`'s ([`Doorbell::gate`]), on and wakes who
    /// sleeps on it: `i` alone, or its whole group (a member not rung goes
    /// back to sleep).
    fn open_gate(&self, i: usize, gate: &AtomicU32) {
        if std::ptr::eq(gate, self.counter(i)) {
            futex(gate, libc::FUTEX_WAKE, 1, None);
        } else {
            // Release, after the counters: a process that sees the gate
            // move sees its counter moved.
            gate.fetch_add(1, Ordering::Release);
            futex(gate, libc::FUTEX_WAKE, u32::MAX >> 1, None);
        }
    }

    /// Wakes process `i` for one step at `rung`; `counted` when the count
    /// [`Doorbell::arm`] set includes that step.
    pub fn ring(&self, i: usize, rung: Rung, counted: bool) {
        self.stage(i, rung, counted);
        self.open_gate(i, self.gate(i));
    }

    /// Wakes the processes `due` for one step at `rung` (`counted(i)` as
    /// in [`Doorbell::ring`]), with one system call per group of them.
    pub fn ring_all(&self, due: &[usize], rung: Rung, counted: impl Fn(usize) -> bool) {
        for &i in due {
            self.stage(i, rung, counted(i));
        }
        // The groups woken so far; a tick has a handful. Past that many a
        // group is woken again, which costs a system call and nothing else.
        let mut opened = [std::ptr::null::<AtomicU32>(); 16];
        let mut n = 0;
        for &i in due {
            let gate = self.gate(i);
            let at: *const AtomicU32 = gate;
            if opened[..n].contains(&at) {
                continue;
            }
            self.open_gate(i, gate);
            if n < opened.len() {
                opened[n] = at;
                n += 1;
            }
        }
    }

    /// Sleeps until process `i`'s counter differs from `seen`, at most
    /// `timeout`; returns the counter, or `None` when the wait ran out, a
    /// signal cut it short or its group was woken without it.
    pub fn wait(&self, i: usize, seen: u32, timeout: Duration) -> Option<u32> {
        wait_on(self.gate(i), self.counter(i), seen, timeout)
    }
}

/// Waits at most `timeout` for `word` to move on from `seen`, asleep on
/// `gate` (`word` itself, or a gate that moves after it); its new value,
/// or `None` if it has not moved (timeout or spurious wake-up).
fn wait_on(gate: &AtomicU32, word: &AtomicU32, seen: u32, timeout: Duration) -> Option<u32> {
    // The gate first: if the word has not moved when read after it, a
    // later move of the word moves the gate too, after the value read here.
    let g = gate.load(Ordering::Acquire);
    let now = word.load(Ordering::Acquire);
    if now != seen {
        return Some(now);
    }
    // The kernel compares the gate with `g` before it sleeps, so a change
    // between the loads above and the wait is never lost.
    futex(gate, libc::FUTEX_WAIT, g, Some(timeout));
    let now = word.load(Ordering::Acquire);
    (now != seen).then_some(now)
}

/// `futex(2)` on a word of a shared mapping (not `FUTEX_PRIVATE_FLAG`: the
/// waiter and the waker are different processes). Its result is not
/// needed: callers read the word again.
fn futex(word: &AtomicU32, op: libc::c_int, val: u32, timeout: Option<Duration>) {
    let ts = timeout.map(|t| libc::timespec {
        tv_sec: libc::time_t::try_from(t.as_secs()).unwrap_or(libc::time_t::MAX),
        tv_nsec: libc::c_long::from(t.subsec_nanos()),
    });
    let ts_ptr = ts
        .as_ref()
        .map_or(std::ptr::null(), |t| t as *const libc::timespec);
    // SAFETY: `word` is a valid, aligned 32-bit word for the whole call;
    // `ts_ptr` is null or points at a timespec that outlives the call; the
    // remaining arguments are unused by FUTEX_WAIT and FUTEX_WAKE.
    #[allow(unsafe_code)]
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            op,
            val,
            ts_ptr,
            std::ptr::null::<u32>(),
            0u32,
        );
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn run_id(tag: &str) -> String {
        format!("db{tag}{}", std::process::id())
    }

    /// Tick `tick` of a run of 10 ms ticks, not its last.
    fn at(tick: u64) -> Rung {
        Rung {
            tick,
            sim_time_ns: tick * 10_000_000,
            last: false,
        }
    }

    #[test]
    fn a_ring_wakes_the_waiter_of_that_slot_only() {
        let id = run_id("a");
        let owner = Doorbell::create(&id, 3).unwrap();
        let seen = owner.seq(1);
        let (opened, is_open) = std::sync::mpsc::channel();
        let waiter = std::thread::spawn(move || {
            // A mapping of its own, as another process has.
            let other = Doorbell::open(&id, 3).unwrap();
            opened.send(()).unwrap();
            let got = other.wait(1, seen, Duration::from_secs(10));
            (got, other.seq(0), other.seq(2))
        });
        is_open.recv().unwrap();
        std::thread::sleep(Duration::from_millis(20));
        owner.ring(1, at(0), true);
        let (got, s0, s2) = waiter.join().unwrap();
        assert_eq!(got, Some(seen.wrapping_add(1)));
        assert_eq!((s0, s2), (0, 0), "the other slots did not move");
    }

    #[test]
    fn a_group_is_woken_at_once_and_a_member_not_rung_sleeps_on() {
        let id = run_id("g");
        let owner = Doorbell::create(&id, 4).unwrap();
        // 0, 1 and 3 share 0's gate; 2 sleeps on its own counter.
        for i in [0, 1, 3] {
            owner.join(i, 0);
        }
        let (opened, is_open) = std::sync::mpsc::channel();
        let waiters: Vec<_> = (0..4)
            .map(|i| {
                let id = id.clone();
                let opened = opened.clone();
                std::thread::spawn(move || {
                    let other = Doorbell::open(&id, 4).unwrap();
                    opened.send(()).unwrap();
                    // Waits as a process does: again after a wake-up that
                    // was not its own, until its slot moves or 300 ms pass.
                    let start = std::time::Instant::now();
                    while start.elapsed() < Duration::from_millis(300) {
                        if let Some(s) = other.wait(i, 0, Duration::from_millis(300)) {
                            return (Some(s), other.rung(i));
                        }
                    }
                    (None, other.rung(i))
                })
            })
            .collect();
        for _ in 0..4 {
            is_open.recv().unwrap();
        }
        std::thread::sleep(Duration::from_millis(20));
        owner.arm(3);
        owner.ring_all(&[0, 2, 3], at(7), |i| i != 2);
        let got: Vec<_> = waiters.into_iter().map(|w| w.join().unwrap()).collect();
        assert_eq!(got[0], (Some(1), at(7)));
        assert_eq!(got[2], (Some(1), at(7)), "the one alone, on its counter");
        assert_eq!(got[3], (Some(1), at(7)));
        assert_eq!(got[1], (None, Rung::default()), "not rung: it slept on");
        assert_eq!(owner.slot(2).counted.load(Ordering::Relaxed), 0);
        // A member rung alone (a restarted process) is woken through the gate.
        let member = {
            let id = id.clone();
            std::thread::spawn(move || {
                let other = Doorbell::open(&id, 4).unwrap();
                other.wait(3, 1, Duration::from_secs(10))
            })
        };
        std::thread::sleep(Duration::from_millis(20));
        owner.ring(3, at(8), true);
        assert_eq!(member.join().unwrap(), Some(2));
    }

    #[test]
    fn a_wait_on_a_quiet_slot_runs_out_and_a_past_ring_is_seen_at_once() {
        let id = run_id("b");
        let bell = Doorbell::create(&id, 2).unwrap();
        assert_eq!(bell.wait(0, 0, Duration::from_millis(10)), None);
        bell.ring(0, at(0), true);
        bell.ring(0, at(1), true);
        assert_eq!(bell.wait(0, 0, Duration::from_secs(10)), Some(2));
    }

    #[test]
    fn only_the_last_process_of_a_tick_to_finish_is_told_to_notify() {
        let id = run_id("d");
        let bell = Doorbell::create(&id, 3).unwrap();
        assert!((0..3).all(|i| bell.is_done(i)), "nothing rung yet");
        bell.arm(2);
        bell.ring(0, at(0), true);
        bell.ring(2, at(0), true);
        assert!(!bell.is_done(0) && bell.is_done(1) && !bell.is_done(2));
        assert!(!bell.finished(2, bell.seq(2)), "one still stepping");
        assert!(bell.is_done(2) && !bell.is_done(0));
        assert!(bell.finished(0, bell.seq(0)), "the last one notifies");
        assert!((0..3).all(|i| bell.is_done(i)));
        // Rung as counted, but past the count (it cannot happen in lockstep).
        bell.ring(1, at(1), true);
        assert!(
            !bell.finished(1, bell.seq(1)),
            "a step the count no longer holds is no tick's end"
        );
    }

    #[test]
    fn a_step_the_tick_does_not_count_notifies_itself_and_keeps_its_tick() {
        let id = run_id("e");
        let bell = Doorbell::create(&id, 3).unwrap();
        bell.arm(2);
        bell.ring(0, at(40), false);
        bell.ring(1, at(40), true);
        bell.ring(2, at(40), true);
        assert!(bell.finished(0, bell.seq(0)), "uncounted: it notifies");
        assert!(
            !bell.finished(1, bell.seq(1)),
            "the uncounted step left the count at two"
        );
        assert!(bell.finished(2, bell.seq(2)), "the last counted one");
        // The next tick rings process 1 alone: process 0's slot keeps 40.
        bell.arm(1);
        bell.ring(1, at(41), true);
        assert_eq!((bell.tick(0), bell.tick(1), bell.tick(2)), (40, 41, 40));
        assert_eq!((bell.rung(0), bell.rung(1)), (at(40), at(41)));
        assert!(bell.is_done(0) && !bell.is_done(1) && bell.is_done(2));
        let end = Rung {
            tick: 42,
            sim_time_ns: 420_000_000,
            last: true,
        };
        bell.ring(2, end, true);
        assert_eq!(bell.rung(2), end);
    }

    #[test]
    fn done_wakes_the_orchestrator_and_a_notification_before_its_wait_is_not_lost() {
        let id = run_id("f");
        let owner = Doorbell::create(&id, 2).unwrap();
        assert!(!owner.wait_done(owner.done_seq(), Duration::from_millis(10)));
        // Read, then notified before the wait: the wait returns at once.
        let seen = owner.done_seq();
        owner.notify_done();
        assert!(owner.wait_done(seen, Duration::from_secs(3600)));
        // Notified from another mapping while the orchestrator sleeps.
        let seen = owner.done_seq();
        let (opened, is_open) = std::sync::mpsc::channel();
        let process = std::thread::spawn(move || {
            let other = Doorbell::open(&id, 2).unwrap();
            opened.send(()).unwrap();
            std::thread::sleep(Duration::from_millis(20));
            other.notify_done();
            (other.seq(0), other.seq(1))
        });
        is_open.recv().unwrap();
        assert!(owner.wait_done(seen, Duration::from_secs(10)));
        assert_eq!(process.join().unwrap(), (0, 0), "no process was rung");
        assert_eq!(owner.done_seq(), seen.wrapping_add(1));
    }

    #[test]
    fn a_doorbell_is_removed_with_its_creator_and_a_short_one_is_refused() {
        let id = run_id("c");
        let bell = Doorbell::create(&id, 2).unwrap();
        assert!(matches!(
            Doorbell::open(&id, 5000),
            Err(DoorbellError::Size {
                found: 2,
                wanted: 5000,
                ..
            })
        ));
        drop(bell);
        assert!(matches!(
            Doorbell::open(&id, 2),
            Err(DoorbellError::Map { .. })
        ));
        assert!(crate::domain::list_domain_files(&id).is_empty());
    }
}
