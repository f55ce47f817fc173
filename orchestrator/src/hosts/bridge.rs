//! The services of one host that cross to others: each bridged out is an
//! iceoryx2 subscriber drained after every local step onto a Zenoh
//! publisher; each bridged in is a Zenoh subscriber whose samples an
//! iceoryx2 publisher sends, header and all, as they came.
//!
//! Only the crossings of the placement are bridged (the world snapshot and
//! the truths of vehicles away from the world): a vehicle's own loop stays
//! in shared memory on its host.

use std::sync::mpsc::Sender;

use anyhow::Context;
use iceoryx2::prelude::*;
use ipc_types::{Sample, Truth, World};
use shoal_runtime::{ChannelLimits, Publisher, StepContext, Subscriber};
use zenoh::Wait;

use super::placement::Crossing;
use super::wire;

/// A service bridged out.
trait Export {
    /// Puts every sample that arrived since the last call; returns how many.
    fn forward(&mut self) -> anyhow::Result<u64>;
    /// Samples the subscriber lost to overflow.
    fn lost(&self) -> u64;
}

struct TypedExport<T: Sample> {
    sub: Subscriber<T>,
    publisher: zenoh::pubsub::Publisher<'static>,
}

impl<T: Sample> Export for TypedExport<T> {
    fn forward(&mut self) -> anyhow::Result<u64> {
        let Self { sub, publisher } = self;
        let mut n = 0;
        let mut failure = None;
        sub.take_ready_in_place(&StepContext::any_time(), |v| {
            let bytes = wire::trim(bytemuck::bytes_of(v));
            if let Err(e) = publisher.put(bytes.to_vec()).wait() {
                failure.get_or_insert(anyhow::anyhow!("zenoh put: {e}"));
            }
            n += 1;
        })?;
        match failure {
            Some(e) => Err(e.context(format!("bridging {} out", sub.service()))),
            None => Ok(n),
        }
    }

    fn lost(&self) -> u64 {
        self.sub.lost()
    }
}

/// A service bridged in.
trait Import {
    /// Sends a sample as it came off the wire.
    fn send(&mut self, wire: &[u8]) -> anyhow::Result<()>;
}

struct TypedImport<T: Sample> {
    publisher: Publisher<T>,
    /// Added to the sample's monotonic stamps: the sending host's clock to
    /// this one's.
    shift_ns: i64,
}

impl<T: Sample> Import for TypedImport<T> {
    fn send(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let service = self.publisher.service().to_string();
        let mut fits = true;
        let shift = self.shift_ns;
        self.publisher.publish_stamped_in_place(|t| {
            fits = wire::untrim(bytes, bytemuck::bytes_of_mut(t));
            if shift != 0 {
                let h = t.header_mut();
                h.publish_mono_ns = wire::shift_stamp(h.publish_mono_ns, shift);
                h.origin_mono_ns = wire::shift_stamp(h.origin_mono_ns, shift);
            }
        })?;
        anyhow::ensure!(
            fits,
            "{service}: {} bytes came, more than its {}-byte sample",
            bytes.len(),
            std::mem::size_of::<T>()
        );
        Ok(())
    }
}

/// What a host's Zenoh callbacks hand its main loop, in arrival order.
#[derive(Debug)]
pub enum Inbound {
    /// A sample of import `index`.
    Sample {
        /// Index into the bridge's imports.
        index: usize,
        /// The trimmed sample.
        bytes: Vec<u8>,
    },
    /// The clock of a tick.
    Clock(u64),
    /// The run's last tick is done.
    End,
    /// The coordinator aborted the run.
    Abort(super::wire::AbortMsg),
    /// The coordinator's liveliness token went away (it died, or the link).
    CoordinatorGone,
}

/// Every crossing of one host.
pub struct Bridge {
    exports: Vec<Box<dyn Export>>,
    imports: Vec<Box<dyn Import>>,
    // Kept alive: dropping one undeclares it.
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    /// Samples sent out so far.
    pub out: u64,
    /// Samples received so far.
    pub r#in: u64,
}

impl Bridge {
    /// Opens the crossings of host `me`: exports where it publishes,
    /// imports where it subscribes; imported samples go to `tx`, their
    /// monotonic stamps moved by `stamp_shift_ns[from]` (none if absent).
    pub fn open(
        session: &zenoh::Session,
        node: &Node<ipc::Service>,
        crossings: &[Crossing],
        me: usize,
        vehicles: usize,
        stamp_shift_ns: &[i64],
        tx: &Sender<Inbound>,
    ) -> anyhow::Result<Self> {
        let mut exports: Vec<Box<dyn Export>> = Vec::new();
        let mut imports: Vec<Box<dyn Import>> = Vec::new();
        let mut subscribers = Vec::new();
        for c in crossings {
            let limits = match c.what {
                "world" => ChannelLimits::world(vehicles),
                _ => ChannelLimits::vehicle(),
            };
            if c.from == me {
                let publisher = session
                    .declare_publisher(c.service.clone())
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .wait()
                    .map_err(|e| anyhow::anyhow!("zenoh publisher {}: {e}", c.service))?;
                let buffer = limits.max_buffer;
                exports.push(match c.what {
                    "world" => Box::new(TypedExport::<World> {
                        sub: shoal_runtime::node_subscriber(node, &c.service, &limits, buffer)?,
                        publisher,
                    }),
                    _ => Box::new(TypedExport::<Truth> {
                        sub: shoal_runtime::node_subscriber(node, &c.service, &limits, buffer)?,
                        publisher,
                    }),
                });
            } else if c.to.contains(&me) {
                let index = imports.len();
                let shift_ns = stamp_shift_ns.get(c.from).copied().unwrap_or(0);
                imports.push(match c.what {
                    "world" => Box::new(TypedImport::<World> {
                        publisher: shoal_runtime::node_publisher(node, &c.service, &limits)?,
                        shift_ns,
                    }),
                    _ => Box::new(TypedImport::<Truth> {
                        publisher: shoal_runtime::node_publisher(node, &c.service, &limits)?,
                        shift_ns,
                    }),
                });
                let tx = tx.clone();
                let sub = session
                    .declare_subscriber(c.service.clone())
                    .callback(move |s| {
                        let _ = tx.send(Inbound::Sample {
                            index,
                            bytes: s.payload().to_bytes().into_owned(),
                        });
                    })
                    .wait()
                    .map_err(|e| anyhow::anyhow!("zenoh subscriber {}: {e}", c.service))
                    .with_context(|| format!("bridging {} in", c.service))?;
                subscribers.push(sub);
            }
        }
        Ok(Self {
            exports,
            imports,
            _subscribers: subscribers,
            out: 0,
            r#in: 0,
        })
    }

    /// Services bridged out.
    pub fn exports(&self) -> usize {
        self.exports.len()
    }

    /// Services bridged in.
    pub fn imports(&self) -> usize {
        self.imports.len()
    }

    /// Puts everything the local publishers of bridged services sent.
    pub fn forward(&mut self) -> anyhow::Result<()> {
        for e in &mut self.exports {
            self.out += e.forward()?;
        }
        Ok(())
    }

    /// Sends an imported sample into shared memory.
    pub fn receive(&mut self, index: usize, bytes: &[u8]) -> anyhow::Result<()> {
        let import = self
            .imports
            .get_mut(index)
            .with_context(|| format!("no import {index}"))?;
        import.send(bytes)?;
        self.r#in += 1;
        Ok(())
    }

    /// Samples the exports' subscribers lost.
    pub fn lost(&self) -> u64 {
        self.exports.iter().map(|e| e.lost()).sum()
    }
}
