//! `shoal run --live`: a Foxglove WebSocket server inside the recorder,
//! serving the channels it records while the run goes.
//!
//! Every channel the recording has is advertised under the same topic with
//! the same `ros2msg` schema, and each message sent is the very CDR body the
//! recording stores (no second encoding): whatever opens the recording
//! decodes the live stream too. The server is the `foxglove` crate's (the
//! Foxglove WebSocket protocol, `foxglove.websocket.v1`), on its own
//! threads: the recorder's step only hands a message to the server's
//! per-client queues and never waits for a socket.
//!
//! Cost: a channel no client subscribes to costs one atomic load per
//! message. A slow client never stalls the run: when its queue (the
//! backlog, [`BACKLOG`] messages) is full, the server drops the oldest
//! message for it; the client sees the gap in each sample's `header.seq`.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;

use anyhow::Context as _;
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer};
use recordings::ChannelSchema;

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
}

impl Live {
    /// Starts serving on `addr` (`host:port`; port 0 picks a free one).
    pub fn start(addr: &str, run_id: &str) -> anyhow::Result<Self> {
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
        Ok(Self {
            server: Some(server),
            ctx,
            channels: HashMap::new(),
            sent: 0,
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
        Ok(())
    }

    /// Sends one recorded message (its CDR body) of channel `id` to the
    /// clients subscribed to it, stamped with its simulated time.
    pub fn log(&mut self, id: u16, sim_time_ns: u64, body: &[u8]) {
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

    /// Messages sent so far (to at least one client).
    pub fn sent(&self) -> u64 {
        self.sent
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
