//! Typed ports: publishers that stamp the common header and refuse
//! non-finite samples, subscribers that hold back samples of the current
//! lockstep tick, count losses and rejected samples, and time every hop.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

use iceoryx2::port::publisher::Publisher as IoxPublisher;
use iceoryx2::port::subscriber::Subscriber as IoxSubscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::Service;
use ipc_types::{Header, Sample};

use crate::domain::ChannelLimits;
use crate::latency::LatencyRecorder;
use crate::{service_name, stamp_ns, Mode, RuntimeError, StepContext};

/// What one process has taken on one input channel kind (every subscription
/// of that kind merged): publish → take latency, losses, rejections.
#[derive(Debug, Clone, Default)]
pub struct HopEntry {
    /// Channel kind: the last segment of the service name (`truth`, `world`, ...).
    pub kind: String,
    /// Publish → take latency, ns.
    pub latency: LatencyRecorder,
    /// Samples that never arrived.
    pub lost: u64,
    /// Samples refused for a non-finite value.
    pub rejected: u64,
}

thread_local! {
    /// This process's hop statistics, one entry per input channel kind. A
    /// shoal process runs its task on one thread, so the subscribers and the
    /// runtime loop that reports them share these without locking; recording
    /// costs one `RefCell` flag and one histogram increment.
    static HOPS: RefCell<Vec<Rc<RefCell<HopEntry>>>> = const { RefCell::new(Vec::new()) };
}

/// The hop statistics entry of a channel kind (created on first use).
fn hop_entry(kind: &str) -> Rc<RefCell<HopEntry>> {
    HOPS.with(|h| {
        let mut h = h.borrow_mut();
        if let Some(e) = h.iter().find(|e| e.borrow().kind == kind) {
            return Rc::clone(e);
        }
        let e = Rc::new(RefCell::new(HopEntry {
            kind: kind.to_string(),
            ..Default::default()
        }));
        h.push(Rc::clone(&e));
        e
    })
}

/// A copy of this thread's hop statistics, in the order the kinds were first subscribed.
pub fn hop_snapshot() -> Vec<HopEntry> {
    HOPS.with(|h| h.borrow().iter().map(|e| e.borrow().clone()).collect())
}

/// Calls `f` on each of this thread's hop statistics in place (no copy of
/// the histograms: the once-a-second report stays cheap).
pub fn for_each_hop(mut f: impl FnMut(&HopEntry)) {
    HOPS.with(|h| {
        for e in h.borrow().iter() {
            f(&e.borrow());
        }
    });
}

/// The channel kind of a service name: its last `/`-separated segment.
pub fn channel_kind(service: &str) -> &str {
    service.rsplit('/').next().unwrap_or(service)
}

/// Where a sample's causal chain started: the sensor event it descends from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Origin {
    /// Monotonic wall time of the sensor event, ns.
    pub mono_ns: u64,
    /// Simulation time of the sensor event, ns.
    pub sim_time_ns: u64,
}

impl Origin {
    /// A new sensor event: now, at this step's simulation time.
    pub fn here(ctx: &StepContext) -> Self {
        Self {
            mono_ns: stamp_ns(),
            sim_time_ns: ctx.sim_time_ns,
        }
    }
    /// The origin recorded in an input's header.
    pub fn of(header: &Header) -> Self {
        Self {
            mono_ns: header.origin_mono_ns,
            sim_time_ns: header.origin_sim_time_ns,
        }
    }
    /// The older of two origins (the chain's first sensor event); a zero origin is ignored.
    pub fn earliest(self, other: Origin) -> Origin {
        match (self.mono_ns, other.mono_ns) {
            (0, _) => other,
            (_, 0) => self,
            (a, b) if b < a => other,
            _ => self,
        }
    }
}

fn open_pubsub<T: Sample, S: Service>(
    node: &Node<S>,
    service: &str,
    limits: &ChannelLimits,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<S, T, ()>, RuntimeError>
{
    let name = service_name(service)?;
    open_retrying(
        || {
            node.service_builder(&name)
                .publish_subscribe::<T>()
                .max_publishers(limits.max_publishers)
                .max_subscribers(limits.max_subscribers)
                .max_nodes(limits.max_nodes)
                .subscriber_max_buffer_size(limits.max_buffer)
                .history_size(limits.history)
                .subscriber_max_borrowed_samples(BORROWED_SAMPLES)
                .enable_safe_overflow(true)
                .open_or_create()
        },
        transient,
    )
    .map_err(|e| RuntimeError::Service {
        service: service.to_string(),
        source: Box::new(e),
    })
}

/// Runs `open` (a service's `open_or_create`) until it succeeds or fails
/// with an error that `transient` does not excuse. Two processes opening a
/// new service at once race inside `open_or_create` (one sees it
/// half-created: `DoesNotExist` or `IsBeingCreatedByAnotherInstance`); a
/// short retry settles it.
pub(crate) fn open_retrying<F, E>(
    mut open: impl FnMut() -> Result<F, E>,
    transient: impl Fn(&E) -> bool,
) -> Result<F, E> {
    let mut attempt = 0;
    loop {
        match open() {
            Err(e) if attempt < OPEN_RETRIES && transient(&e) => {
                attempt += 1;
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            r => return r,
        }
    }
}

/// Samples a subscriber may hold borrowed from shared memory at once.
const BORROWED_SAMPLES: usize = 2;

/// Attempts at opening a service that another process is creating.
const OPEN_RETRIES: u32 = 200;

/// True for the errors of a service caught half-created (or half-removed)
/// by another process: opening found no service yet, or creating found it
/// just created by someone else.
fn transient(e: &PublishSubscribeOpenOrCreateError) -> bool {
    use iceoryx2::service::builder::publish_subscribe::{
        PublishSubscribeCreateError as C, PublishSubscribeOpenError as O,
    };
    matches!(
        e,
        PublishSubscribeOpenOrCreateError::SystemInFlux
            | PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(O::DoesNotExist)
            | PublishSubscribeOpenOrCreateError::PublishSubscribeCreateError(
                C::AlreadyExists | C::IsBeingCreatedByAnotherInstance
            )
    )
}

/// A publisher of one sample type on one service, over iceoryx2 service
/// kind `S` (shared memory between processes by default; `local::Service`
/// inside one process, for tests).
pub struct Publisher<T: Sample, S: Service = ipc::Service> {
    inner: IoxPublisher<S, T, ()>,
    factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<S, T, ()>,
    service: String,
    seq: u64,
    /// Dataflow: notifies the service's arrival event after every send, so
    /// that the stages triggered by it wake ([`crate::Runtime::wake_on`]).
    /// Boxed: a notifier is large, and most publishers have none.
    arrival: Option<Box<iceoryx2::port::notifier::Notifier<S>>>,
}

impl<T: Sample, S: Service> Publisher<T, S> {
    pub(crate) fn open(
        node: &Node<S>,
        service: &str,
        limits: &ChannelLimits,
    ) -> Result<Self, RuntimeError> {
        let factory = open_pubsub::<T, S>(node, service, limits)?;
        let inner = factory
            .publisher_builder()
            .max_loaned_samples(2)
            .create()
            .map_err(|e| RuntimeError::Port {
                service: service.to_string(),
                source: Box::new(e),
            })?;
        Ok(Self {
            inner,
            factory,
            service: service.to_string(),
            seq: 0,
            arrival: None,
        })
    }

    /// Announces every send on the service's arrival event (dataflow mode).
    pub(crate) fn announcing(
        mut self,
        node: &Node<S>,
        limits: &ChannelLimits,
    ) -> Result<Self, RuntimeError> {
        let name = crate::arrival_service_name(&self.service);
        let notifier = crate::open_arrival(node, &self.service, limits)?
            .notifier_builder()
            .create()
            .map_err(|e| RuntimeError::Port {
                service: name,
                source: Box::new(e),
            })?;
        self.arrival = Some(Box::new(notifier));
        Ok(self)
    }

    /// Counts a sample sent and wakes the stages it triggers.
    fn sent(&mut self) -> Result<(), RuntimeError> {
        self.seq += 1;
        if let Some(n) = &self.arrival {
            n.notify().map_err(|e| RuntimeError::Io {
                service: crate::arrival_service_name(&self.service),
                source: Box::new(e),
            })?;
        }
        Ok(())
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Subscribers connected to the service right now.
    pub fn subscribers(&self) -> usize {
        self.factory.dynamic_config().number_of_subscribers()
    }

    /// Stamps the header (sequence, this step's simulation time, publish
    /// time, origin) and sends. A sample with a non-finite value is refused
    /// with an error and never sent.
    pub fn publish(
        &mut self,
        sample: T,
        ctx: &StepContext,
        origin: Origin,
    ) -> Result<(), RuntimeError> {
        if !sample.is_finite() {
            return Err(RuntimeError::NonFinite {
                service: self.service.clone(),
            });
        }
        // Read the clock before touching shared memory: an exact read (see
        // `stamp`) waits for outstanding loads, and the loan's may miss the
        // cache.
        let publish_mono_ns = stamp_ns();
        // Written once into the loaned shared-memory chunk and stamped in
        // place: no intermediate copies of the payload.
        let loan = self
            .inner
            .loan_uninit()
            .map_err(|e| self.send_error(iceoryx2::port::SendError::from(e)))?;
        let mut out = loan.write_payload(sample);
        self.stamp(out.payload_mut().header_mut(), ctx, origin, publish_mono_ns);
        out.send().map_err(|e| self.send_error(e))?;
        self.sent()
    }

    /// Writes this publisher's stamps into a header about to be sent.
    fn stamp(&self, h: &mut Header, ctx: &StepContext, origin: Origin, publish_mono_ns: u64) {
        h.seq = self.seq;
        h.sim_time_ns = ctx.sim_time_ns;
        h.origin_mono_ns = origin.mono_ns;
        h.origin_sim_time_ns = origin.sim_time_ns;
        h.publish_mono_ns = publish_mono_ns;
    }

    /// Publishes a sample written in place: `fill` gets the loaned
    /// shared-memory chunk itself, so a large sample (a camera frame) is
    /// written once, where the subscriber will read it, and never copied.
    /// The chunk holds the bytes of an earlier sample of this service (or
    /// zeros): `fill` must write every field it means to publish. The
    /// header is stamped after `fill` returns, so the publish time is when
    /// the sample is complete. A sample with a non-finite value is refused
    /// (the chunk goes back unsent).
    pub fn publish_in_place(
        &mut self,
        ctx: &StepContext,
        origin: Origin,
        fill: impl FnOnce(&mut T),
    ) -> Result<(), RuntimeError> {
        let mut out = self.loan_in_place()?;
        fill(out.payload_mut());
        if !out.payload().is_finite() {
            return Err(RuntimeError::NonFinite {
                service: self.service.clone(),
            });
        }
        self.stamp(out.payload_mut().header_mut(), ctx, origin, stamp_ns());
        out.send().map_err(|e| self.send_error(e))?;
        self.sent()
    }

    /// Sends a sample whose header `fill` writes itself (replay of a
    /// large sample), in place like [`Publisher::publish_in_place`].
    pub fn publish_stamped_in_place(
        &mut self,
        fill: impl FnOnce(&mut T),
    ) -> Result<(), RuntimeError> {
        let mut out = self.loan_in_place()?;
        fill(out.payload_mut());
        out.send().map_err(|e| self.send_error(e))?;
        self.sent()
    }

    /// A loaned chunk to write a sample into where it lies.
    fn loan_in_place(&self) -> Result<iceoryx2::sample_mut::SampleMut<S, T, ()>, RuntimeError> {
        let loan = self
            .inner
            .loan_uninit()
            .map_err(|e| self.send_error(iceoryx2::port::SendError::from(e)))?;
        #[allow(unsafe_code)]
        // SAFETY: `T: Pod`, so every byte pattern is a valid `T`; the chunk
        // lies in a shared-memory segment that the OS zero-filled when it was
        // created and that has only ever held whole `T` values of this
        // service since, so all of its bytes are initialised.
        Ok(unsafe { loan.assume_init() })
    }

    fn send_error(&self, e: iceoryx2::port::SendError) -> RuntimeError {
        RuntimeError::Io {
            service: self.service.clone(),
            source: Box::new(e),
        }
    }

    /// Connects the subscribers that appeared since the last send and hands
    /// them the history (otherwise a late joiner sees it only at the next
    /// send: a restarted process must read the current clock before the
    /// orchestrator sends another).
    pub fn update_connections(&self) -> Result<(), RuntimeError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        self.inner
            .update_connections()
            .map_err(|e| RuntimeError::Io {
                service: self.service.clone(),
                source: Box::new(e),
            })
    }

    /// Sends a sample whose header is already complete (replay, the clock).
    pub fn publish_stamped(&mut self, sample: T) -> Result<(), RuntimeError> {
        self.inner
            .send_copy(sample)
            .map_err(|e| self.send_error(e))?;
        self.sent()
    }
}

/// A subscriber of one sample type on one service, over iceoryx2 service
/// kind `S` (see [`Publisher`]).
pub struct Subscriber<T: Sample, S: Service = ipc::Service> {
    inner: IoxSubscriber<S, T, ()>,
    service: String,
    mode: Mode,
    held: VecDeque<T>,
    /// Samples borrowed from shared memory and not yet ready (the in-place
    /// path, [`Subscriber::with_latest_in_place`]).
    held_in_place: VecDeque<iceoryx2::sample::Sample<S, T, ()>>,
    /// Next expected sequence number of each publisher (a service may have
    /// several: the stats channel, a restarted process).
    next_seq: Vec<(u128, u64)>,
    lost: u64,
    rejected: u64,
    hops: Rc<RefCell<HopEntry>>,
}

impl<T: Sample, S: Service> Subscriber<T, S> {
    pub(crate) fn open(
        node: &Node<S>,
        service: &str,
        limits: &ChannelLimits,
        buffer: usize,
        mode: Mode,
    ) -> Result<Self, RuntimeError> {
        let factory = open_pubsub::<T, S>(node, service, limits)?;
        let inner = factory
            .subscriber_builder()
            .buffer_size(buffer.clamp(1, limits.max_buffer))
            .create()
            .map_err(|e| RuntimeError::Port {
                service: service.to_string(),
                source: Box::new(e),
            })?;
        Ok(Self {
            inner,
            service: service.to_string(),
            mode,
            held: VecDeque::with_capacity(2 * limits.max_buffer),
            held_in_place: VecDeque::with_capacity(BORROWED_SAMPLES),
            next_seq: Vec::new(),
            lost: 0,
            rejected: 0,
            hops: hop_entry(channel_kind(service)),
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Samples that never arrived (gaps in the publisher's sequence).
    pub fn lost(&self) -> u64 {
        self.lost
    }

    /// Samples refused because they held a non-finite value.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// Publish → take latency of every sample of this channel kind this
    /// process received so far (all its subscriptions of the kind merged).
    pub fn latency(&self) -> crate::latency::LatencySummary {
        self.hops.borrow().latency.summary()
    }

    /// Receives every waiting sample and accounts for it (latency, sequence,
    /// finite check). With `deliver`, a sample that is ready while nothing
    /// is held goes straight to the callback, copied once out of shared
    /// memory; every other sample is held, in arrival order.
    fn pull<F: FnMut(T)>(
        &mut self,
        mut deliver: Option<(&StepContext, &mut F)>,
    ) -> Result<(), RuntimeError> {
        loop {
            let received = self.inner.receive().map_err(|e| RuntimeError::Io {
                service: self.service.clone(),
                source: Box::new(e),
            })?;
            let Some(sample) = received else {
                return Ok(());
            };
            // The take time first: an exact read (see `stamp`) waits for
            // outstanding loads, so it goes before the payload's cache misses.
            let taken = stamp_ns();
            let publisher = sample.header().publisher_id().value();
            // One copy out of shared memory (a plain memcpy takes the cache
            // misses best); every check then reads the local copy.
            let value: T = *sample.payload();
            let h = *value.header();
            let finite = value.is_finite();
            self.account(publisher, &h, taken, finite);
            if !finite {
                drop(sample);
                tracing::warn!(service = %self.service, seq = h.seq, "rejected a sample with a non-finite or out-of-range value");
                continue;
            }
            match &mut deliver {
                Some((ctx, f)) if self.held.is_empty() && self.ready(ctx, &value) => {
                    // The chunk goes back to its publisher after the callback,
                    // so a reply published from it leaves first.
                    f(value);
                    drop(sample);
                }
                _ => {
                    drop(sample);
                    self.held.push_back(value);
                }
            }
        }
    }

    fn ready(&self, ctx: &StepContext, s: &T) -> bool {
        self.mode.wall_clock() || s.header().sim_time_ns < ctx.sim_time_ns
    }

    /// Hands the held samples that are ready to `f`, oldest first, up to the
    /// first one that is not.
    fn release_ready(&mut self, ctx: &StepContext, f: &mut impl FnMut(T)) {
        while let Some(front) = self.held.front() {
            if !self.ready(ctx, front) {
                break;
            }
            if let Some(v) = self.held.pop_front() {
                f(v);
            }
        }
    }

    /// Every sample that is ready at this step, oldest first. In lockstep, a
    /// sample is ready when it was stamped before this step's tick; later
    /// ones stay held for the next step.
    pub fn take_ready(
        &mut self,
        ctx: &StepContext,
        mut f: impl FnMut(T),
    ) -> Result<(), RuntimeError> {
        // Held samples are older than anything still in the queue; once one
        // of them is not ready, every newer sample is held behind it.
        self.release_ready(ctx, &mut f);
        self.pull(Some((ctx, &mut f)))
    }

    /// Every held and arrived sample regardless of its stamp, oldest first
    /// (a final drain, replay, outside readers).
    pub fn take_all(&mut self, f: impl FnMut(T)) -> Result<(), RuntimeError> {
        self.take_ready(&StepContext::any_time(), f)
    }

    /// The newest ready sample, if any arrived since the last call.
    pub fn latest(&mut self, ctx: &StepContext) -> Result<Option<T>, RuntimeError> {
        let mut last = None;
        self.take_ready(ctx, |v| last = Some(v))?;
        Ok(last)
    }

    /// Calls `f` on the newest ready sample in place, in shared memory (no
    /// copy: the way to read a camera frame), if one arrived since the last
    /// call; older ready samples are accounted for and released unread. A
    /// sample that is not ready yet (lockstep) stays borrowed until it is.
    /// Use this or the copying readers on one subscriber, not both.
    pub fn with_latest_in_place<R>(
        &mut self,
        ctx: &StepContext,
        f: impl FnOnce(&T) -> R,
    ) -> Result<Option<R>, RuntimeError> {
        while self.inner.has_samples().map_err(|e| RuntimeError::Io {
            service: self.service.clone(),
            source: Box::new(e),
        })? {
            if self.held_in_place.len() >= BORROWED_SAMPLES {
                // Full: the oldest is superseded by the one queued behind it.
                self.held_in_place.pop_front();
            }
            match self.receive_in_place()? {
                None => break,
                Some(Some(sample)) => self.held_in_place.push_back(sample),
                Some(None) => {}
            }
        }
        let ready = self
            .held_in_place
            .iter()
            .take_while(|s| self.ready(ctx, s.payload()))
            .count();
        if ready == 0 {
            return Ok(None);
        }
        // Release the older ready ones; read the newest where it lies.
        self.held_in_place.drain(..ready - 1);
        let newest = self.held_in_place.pop_front();
        Ok(newest.map(|s| f(s.payload())))
    }

    /// Calls `f` on every ready sample in place, oldest first (the
    /// recorder's path for camera frames: each is read once, where it lies,
    /// and released). A sample that is not ready stays borrowed; at most
    /// two are, and the rest wait in the subscriber's queue.
    pub fn take_ready_in_place(
        &mut self,
        ctx: &StepContext,
        mut f: impl FnMut(&T),
    ) -> Result<(), RuntimeError> {
        while self
            .held_in_place
            .front()
            .is_some_and(|s| self.ready(ctx, s.payload()))
        {
            if let Some(s) = self.held_in_place.pop_front() {
                f(s.payload());
            }
        }
        while self.held_in_place.len() < BORROWED_SAMPLES {
            let sample = match self.receive_in_place()? {
                None => break,
                Some(None) => continue,
                Some(Some(sample)) => sample,
            };
            if self.held_in_place.is_empty() && self.ready(ctx, sample.payload()) {
                f(sample.payload());
            } else {
                self.held_in_place.push_back(sample);
            }
        }
        Ok(())
    }

    /// Receives one sample without copying it and books it: `None` when
    /// nothing waits, `Some(None)` for a sample refused for a non-finite
    /// value (booked, logged, released).
    #[allow(clippy::type_complexity)]
    fn receive_in_place(
        &mut self,
    ) -> Result<Option<Option<iceoryx2::sample::Sample<S, T, ()>>>, RuntimeError> {
        let received = self.inner.receive().map_err(|e| RuntimeError::Io {
            service: self.service.clone(),
            source: Box::new(e),
        })?;
        let Some(sample) = received else {
            return Ok(None);
        };
        let taken = stamp_ns();
        let publisher = sample.header().publisher_id().value();
        let h = *sample.payload().header();
        let finite = sample.payload().is_finite();
        self.account(publisher, &h, taken, finite);
        if finite {
            Ok(Some(Some(sample)))
        } else {
            tracing::warn!(service = %self.service, seq = h.seq, "rejected a sample with a non-finite or out-of-range value");
            Ok(Some(None))
        }
    }

    /// Books one received sample: latency, sequence gaps, rejection.
    fn account(&mut self, publisher: u128, h: &Header, taken: u64, finite: bool) {
        let mut hops = self.hops.borrow_mut();
        hops.latency
            .record_ns(taken.saturating_sub(h.publish_mono_ns));
        match self.next_seq.iter_mut().find(|(p, _)| *p == publisher) {
            Some((_, n)) => {
                if h.seq > *n {
                    self.lost += h.seq - *n;
                    hops.lost += h.seq - *n;
                }
                *n = h.seq + 1;
            }
            None => self.next_seq.push((publisher, h.seq + 1)),
        }
        if !finite {
            self.rejected += 1;
            hops.rejected += 1;
        }
    }

    /// The newest sample regardless of its stamp (the clock).
    pub fn drain_latest(&mut self) -> Result<Option<T>, RuntimeError> {
        self.pull::<fn(T)>(None)?;
        let last = self.held.back().copied();
        self.held.clear();
        Ok(last)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ChannelLimits;
    use ipc_types::Nav;

    fn ctx(sim_time_ns: u64) -> StepContext {
        StepContext {
            sim_time_ns,
            tick: 0,
            wake_mono_ns: 0,
            since_last_ns: 0,
            last: false,
            mode: Mode::Lockstep,
            woken_by: crate::Wake::Tick,
        }
    }

    fn nav(marker: f64) -> Nav {
        let mut n = Nav::zeroed();
        n.depth_m = marker;
        n
    }

    fn take(sub: &mut Subscriber<Nav>, at: u64) -> Vec<(f64, u64)> {
        let mut got = Vec::new();
        sub.take_ready(&ctx(at), |v| got.push((v.depth_m, v.header.sim_time_ns)))
            .unwrap();
        got
    }

    /// Removes the test's iceoryx2 domain, also when an assertion fails.
    struct Domain(String);
    impl Drop for Domain {
        fn drop(&mut self) {
            crate::cleanup_domain(&self.0);
        }
    }

    #[test]
    fn ports_hold_stamp_order_count_and_refuse_like_the_design_says() {
        let run = format!("ports{}", std::process::id());
        let _domain = Domain(run.clone());
        let node = crate::domain_node(&run, "ports-test").unwrap();
        let service = format!("shoal/{run}/V/nav");
        let limits = ChannelLimits::vehicle();
        let mut a = crate::node_publisher::<Nav, _>(&node, &service, &limits).unwrap();
        let mut b = crate::node_publisher::<Nav, _>(&node, &service, &limits).unwrap();
        let mut sub =
            Subscriber::<Nav>::open(&node, &service, &limits, 16, Mode::Lockstep).unwrap();

        // Stamps: sequence from 0, this step's simulation time, the origin.
        let origin = Origin {
            mono_ns: 7,
            sim_time_ns: 3,
        };
        for (i, t) in [0u64, 10, 20, 30].iter().enumerate() {
            a.publish(nav(i as f64), &ctx(*t), origin).unwrap();
        }
        let mut first = None;
        sub.take_ready(&ctx(15), |v| {
            first.get_or_insert(v);
        })
        .unwrap();
        let first = first.unwrap();
        assert_eq!(first.header.seq, 0);
        assert_eq!(first.header.origin_mono_ns, 7);
        assert_eq!(first.header.origin_sim_time_ns, 3);
        assert!(first.header.publish_mono_ns > 0);
        // Only samples stamped before the tick; the rest held, in order.
        assert_eq!(take(&mut sub, 15), vec![]);
        a.publish(nav(4.0), &ctx(40), origin).unwrap();
        assert_eq!(take(&mut sub, 15), vec![]);
        assert_eq!(take(&mut sub, 35), vec![(2.0, 20), (3.0, 30)]);
        assert_eq!(take(&mut sub, 100), vec![(4.0, 40)]);

        // A held sample that is not ready blocks newer ones, even ready ones
        // of another publisher; both come out in arrival order later.
        a.publish(nav(5.0), &ctx(50), origin).unwrap();
        b.publish(nav(6.0), &ctx(10), origin).unwrap();
        assert_eq!(take(&mut sub, 20), vec![]);
        assert_eq!(take(&mut sub, 60), vec![(5.0, 50), (6.0, 10)]);

        // A non-finite sample is refused on publish and never sent.
        assert!(a.publish(nav(f64::NAN), &ctx(60), origin).is_err());
        assert_eq!(take(&mut sub, 1_000), vec![]);
        // One that bypasses the check (a pre-stamped send) is rejected on
        // take and counted; a gap in a publisher's sequence counts as lost.
        let mut bad = nav(f64::INFINITY);
        bad.header.seq = 6;
        bad.header.sim_time_ns = 60;
        a.publish_stamped(bad).unwrap();
        let mut gap = nav(8.0);
        gap.header.seq = 10;
        gap.header.sim_time_ns = 70;
        a.publish_stamped(gap).unwrap();
        assert_eq!(take(&mut sub, 1_000), vec![(8.0, 70)]);
        assert_eq!(sub.rejected(), 1);
        assert_eq!(sub.lost(), 3);
        assert_eq!(sub.latency().count, 9);

        // latest: the newest ready one; drain_latest: the newest regardless.
        a.publish(nav(9.0), &ctx(80), origin).unwrap();
        a.publish(nav(10.0), &ctx(90), origin).unwrap();
        a.publish(nav(11.0), &ctx(200), origin).unwrap();
        assert_eq!(
            sub.latest(&ctx(100)).unwrap().map(|v| v.depth_m),
            Some(10.0)
        );
        a.publish(nav(12.0), &ctx(300), origin).unwrap();
        assert_eq!(sub.drain_latest().unwrap().map(|v| v.depth_m), Some(12.0));
        assert_eq!(take(&mut sub, 1_000), vec![]);
    }

    #[test]
    fn in_place_samples_are_stamped_held_until_ready_and_read_where_they_lie() {
        let run = format!("inplace{}", std::process::id());
        let _domain = Domain(run.clone());
        let node = crate::domain_node(&run, "inplace-test").unwrap();
        let service = format!("shoal/{run}/V/nav");
        let limits = ChannelLimits::vehicle();
        let mut publ = crate::node_publisher::<Nav, _>(&node, &service, &limits).unwrap();
        let mut sub = Subscriber::<Nav>::open(&node, &service, &limits, 4, Mode::Lockstep).unwrap();
        let origin = Origin {
            mono_ns: 5,
            sim_time_ns: 1,
        };
        for t in [0u64, 10, 20] {
            publ.publish_in_place(&ctx(t), origin, |n| {
                // The chunk may hold an earlier sample: write what we publish.
                *n = nav(t as f64);
            })
            .unwrap();
        }
        let read = |sub: &mut Subscriber<Nav>, at: u64| {
            sub.with_latest_in_place(&ctx(at), |n| {
                (n.depth_m, n.header.seq, n.header.origin_mono_ns)
            })
            .unwrap()
        };
        // Ready at 15: samples 0 and 10; the newest is read, sample 20 stays borrowed.
        assert_eq!(read(&mut sub, 15), Some((10.0, 1, 5)));
        assert_eq!(read(&mut sub, 15), None);
        assert_eq!(read(&mut sub, 25), Some((20.0, 2, 5)));
        // A non-finite sample is refused on publish and never sent.
        assert!(publ
            .publish_in_place(&ctx(30), origin, |n| n.depth_m = f64::NAN)
            .is_err());
        assert_eq!(read(&mut sub, 1_000), None);
        publ.publish_in_place(&ctx(40), origin, |n| *n = nav(4.0))
            .unwrap();
        assert_eq!(read(&mut sub, 1_000), Some((4.0, 3, 5)));
        assert_eq!(sub.lost(), 0);
        assert_eq!(sub.latency().count, 4);
    }

    /// Connects the subscriber to the publishers that appeared, without
    /// reading anything.
    fn connect(sub: &Subscriber<Nav>) {
        use iceoryx2::port::update_connections::UpdateConnections;
        sub.inner.update_connections().unwrap();
    }

    #[test]
    fn the_last_samples_of_publishers_that_left_are_still_read() {
        let run = format!("expired{}", std::process::id());
        let _domain = Domain(run.clone());
        let read = |sub: &mut Subscriber<Nav>| {
            let mut got = Vec::new();
            sub.take_all(|v| got.push(v.depth_m)).unwrap();
            got
        };

        // A per-vehicle channel: a process, its restarted successor and
        // the next, each gone with a sample unread.
        let node = crate::domain_node(&run, "expired-test").unwrap();
        let service = format!("shoal/{run}/V/nav");
        let limits = ChannelLimits::vehicle();
        let mut sub =
            Subscriber::<Nav>::open(&node, &service, &limits, 16, Mode::Realtime).unwrap();
        for marker in [1.0, 2.0, 3.0] {
            let mut p = crate::node_publisher::<Nav, _>(&node, &service, &limits).unwrap();
            connect(&sub);
            p.publish(nav(marker), &ctx(0), Origin::default()).unwrap();
        }
        assert_eq!(read(&mut sub), vec![1.0, 2.0, 3.0]);

        // A channel every process publishes on (stats), read on a node
        // that keeps a connection for each: twice the default's worth of
        // publishers stop together, and none of their samples is lost.
        let many = 2 * crate::domain::EXPIRED_CONNECTIONS;
        let limits = crate::stats::stats_limits(many);
        let service = format!("shoal/{run}/stats");
        let wide = crate::node_with_config::<ipc::Service>(
            &crate::domain::iceoryx_config_keeping(&run, limits.max_publishers),
            "expired-test-wide",
        )
        .unwrap();
        let mut sub = Subscriber::<Nav>::open(&wide, &service, &limits, 4, Mode::Realtime).unwrap();
        let mut publishers: Vec<_> = (0..many)
            .map(|_| crate::node_publisher::<Nav, _>(&node, &service, &limits).unwrap())
            .collect();
        connect(&sub);
        for (i, p) in publishers.iter_mut().enumerate() {
            p.publish(nav(i as f64), &ctx(0), Origin::default())
                .unwrap();
        }
        drop(publishers);
        let got = read(&mut sub);
        assert_eq!(got.len(), many, "{got:?}");
    }
}
