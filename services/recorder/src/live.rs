//! `shoal run --live`: a Foxglove WebSocket server inside the recorder,
//! serving the channels it records while the run goes.
//!
//! Every channel the recording has is advertised under the same topic with
//! the same `ros2msg` schema, and each message sent is the very CDR body the
//! recording stores (no second encoding): whatever opens the recording
//! decodes the live stream too. The server is the `foxglove` crate's (the
//! Foxglove WebSocket protocol, served under the subprotocol name
//! `foxglove.sdk.v1`), on its own threads: the recorder's step only hands a message to the server's
//! per-client queues and never waits for a socket.
//!
//! Beside the recorded channels, the view of `shoal export --foxglove`
//! (the `shoal-view` crate, the same code): `/tf`, `/scene/obstacles`,
//! `/scene/vehicles`, `/scene/slots`, `/scene/sonar`,
//! `/scene/line_of_sight`, `/<V>/pose` and `/<F>/parent_estimate` in
//! Foxglove's own protobuf schemas, built only while a client is
//! connected; the static scene (obstacles, hulls) is sent again every
//! simulated second for clients that join late.
//!
//! Cost: a channel no client subscribes to costs one atomic load per
//! message, and with no client connected no scene is built. A slow client
//! never stalls the run: when its queue (the backlog, [`BACKLOG`] messages)
//! is full, the server drops the oldest message for it; the client sees the
//! gap in each sample's `header.seq`.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;

use anyhow::Context as _;
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer};
use ipc_types::Channel;
use recordings::ChannelSchema;
use shoal_scenario::Scenario;
use shoal_view::foxglove::FoxgloveMessage;
use shoal_view::{Converter, Out, ViewConfig};

/// Simulated time between two sendings of the static scene, and the poses
/// the view keeps, ns.
const STATIC_EVERY_NS: u64 = 1_000_000_000;

/// Messages queued per client before the oldest is dropped: about two
/// simulated seconds of a 25-vehicle run's channels.
pub const BACKLOG: usize = 4096;

/// The live server and its channels.
pub struct Live {
    server: Option<foxglove::WebSocketServerHandle>,
    ctx: Arc<Context>,
    /// Recording channel id → live channel.
    channels: HashMap<u16, Arc<RawChannel>>,
    /// Messages handed to at least one subscribed client.
    sent: u64,
    /// The scene, built from the recorded samples while a client is connected.
    scene: Converter<SceneOut>,
    /// Recording channel id → (vehicle, channel) for the samples the scene uses.
    routes: HashMap<u16, (String, Channel)>,
    /// Simulated time the static scene is due again, ns.
    static_due_ns: u64,
    /// A client was connected when the current batch began.
    watched: bool,
}

/// The scene's messages, each on a live channel of its Foxglove schema
/// (made when first written).
struct SceneOut {
    ctx: Arc<Context>,
    channels: HashMap<String, Arc<RawChannel>>,
    buf: Vec<u8>,
    sent: u64,
}

impl Out for SceneOut {
    fn write<T: FoxgloveMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> anyhow::Result<()> {
        let channel = match self.channels.get(topic) {
            Some(c) => c,
            None => {
                let c = ChannelBuilder::new(topic)
                    .context(&self.ctx)
                    .message_encoding(T::get_message_encoding())
                    .schema(T::get_schema())
                    .build_raw()
                    .with_context(|| format!("cannot advertise {topic} live"))?;
                self.channels.entry(topic.to_string()).or_insert(c)
            }
        };
        if channel.has_sinks() {
            self.buf.clear();
            msg.encode(&mut self.buf)
                .map_err(|e| anyhow::anyhow!("cannot encode {topic}: {e}"))?;
            channel.log_with_meta(
                &self.buf,
                PartialMetadata {
                    log_time: Some(log_time_ns),
                },
            );
            self.sent += 1;
        }
        Ok(())
    }

    fn epoch_ns(&self) -> u64 {
        0
    }
}

impl Live {
    /// Starts serving on `addr` (`host:port`; port 0 picks a free one).
    pub fn start(addr: &str, run_id: &str, scenario: &Scenario) -> anyhow::Result<Self> {
        let sock: SocketAddr = addr
            .parse()
            .with_context(|| format!("--live {addr}: not an address such as 127.0.0.1:8765"))?;
        let ctx = Context::new();
        let server = WebSocketServer::new()
            .name(format!("shoal run {run_id}"))
            .bind(sock.ip().to_string(), sock.port())
            .context(&ctx)
            .message_backlog_size(BACKLOG)
            .start_blocking()
            .with_context(|| format!("cannot serve the live view on {addr}"))?;
        tracing::info!(
            "live view on ws://{}:{} (Foxglove WebSocket protocol)",
            sock.ip(),
            server.port()
        );
        let mut notes = Vec::new();
        let view = ViewConfig::from_scenario(Some(scenario), Vec::new, &mut notes);
        for n in notes {
            tracing::warn!("live scene: {n}");
        }
        let scene = Converter::new(
            view,
            SceneOut {
                ctx: ctx.clone(),
                channels: HashMap::new(),
                buf: Vec::with_capacity(16 * 1024),
                sent: 0,
            },
        );
        Ok(Self {
            server: Some(server),
            ctx,
            channels: HashMap::new(),
            sent: 0,
            scene,
            routes: HashMap::new(),
            static_due_ns: 0,
            watched: false,
        })
    }

    /// Advertises recording channel `id` as the recording declares it.
    pub fn add(&mut self, id: u16, schema: &ChannelSchema) -> anyhow::Result<()> {
        let channel = ChannelBuilder::new(&schema.topic)
            .context(&self.ctx)
            .message_encoding("cdr")
            .schema(Schema::new(
                schema.schema_name.clone(),
                "ros2msg",
                schema.schema_text.clone().into_bytes(),
            ))
            .build_raw()
            .with_context(|| format!("cannot advertise {} live", schema.topic))?;
        self.channels.insert(id, channel);
        if let Some((vehicle, ch)) = shoal_view::parse_topic(&schema.topic) {
            self.routes.insert(id, (vehicle.to_string(), ch));
        }
        Ok(())
    }

    /// Before a batch: whether a client is connected, asked once for the
    /// whole batch (the scene is built only then).
    pub fn batch_start(&mut self) {
        self.watched = self.server.as_ref().is_some_and(|s| s.client_count() > 0);
    }

    /// Sends one recorded message (its CDR body) of channel `id` to the
    /// clients subscribed to it, stamped with its simulated time.
    pub fn log(&mut self, id: u16, sim_time_ns: u64, body: &[u8]) {
        if let Some((vehicle, ch)) = self.routes.get(&id) {
            if self.watched {
                if let Err(e) = self.scene.message(vehicle, *ch, sim_time_ns, body) {
                    tracing::warn!("live scene: {e:#}");
                }
            }
        }
        if let Some(channel) = self.channels.get(&id) {
            if channel.has_sinks() {
                channel.log_with_meta(
                    body,
                    PartialMetadata {
                        log_time: Some(sim_time_ns),
                    },
                );
                self.sent += 1;
            }
        }
    }

    /// After a batch up to `sim_time_ns`: the batch's transforms out, the
    /// static scene again when due, old poses forgotten.
    pub fn batch_done(&mut self, sim_time_ns: u64) {
        if !self.watched {
            return;
        }
        let result = self.scene.flush_tf().and_then(|()| {
            if sim_time_ns >= self.static_due_ns {
                self.static_due_ns = sim_time_ns.saturating_add(STATIC_EVERY_NS);
                self.scene
                    .forget_before(sim_time_ns.saturating_sub(2 * STATIC_EVERY_NS));
                self.scene.static_scene(sim_time_ns)
            } else {
                Ok(())
            }
        });
        if let Err(e) = result {
            tracing::warn!("live scene: {e:#}");
        }
    }

    /// Messages sent so far (to at least one client), recorded channels
    /// and scene.
    pub fn sent(&self) -> u64 {
        self.sent + self.scene.out.sent
    }

    /// Stops the server: clients are told and disconnected.
    pub fn stop(&mut self) {
        if let Some(server) = self.server.take() {
            server.stop().wait_blocking();
            tracing::info!(sent = self.sent, "live view stopped");
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        self.stop();
    }
}
