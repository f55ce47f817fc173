//! The recorder task.

use std::collections::BTreeMap;
use std::path::Path;

use ipc_types::{Channel, RunChannel, Sample};
use recordings::{Compression, RecordingWriter, WriterOptions};
use shoal_runtime::{
    ChannelLimits, Runtime, RuntimeError, StepContext, Subscriber, Task, TaskError,
};
use shoal_scenario::Scenario;

/// A sample waiting to be written.
struct Pending {
    sim_time_ns: u64,
    order: usize,
    seq: u64,
    start: usize,
    len: usize,
}

/// One recorded channel, type-erased.
trait Tap {
    fn drain(
        &mut self,
        ctx: Option<&StepContext>,
        order: usize,
        arena: &mut Vec<u8>,
        out: &mut Vec<Pending>,
    ) -> Result<(), RuntimeError>;
    fn channel(&self) -> u16;
    fn lost(&self) -> u64;
    fn rejected(&self) -> u64;
}

struct TypedTap<T: Sample> {
    sub: Subscriber<T>,
    channel: u16,
}

impl<T: Sample> Tap for TypedTap<T> {
    fn drain(
        &mut self,
        ctx: Option<&StepContext>,
        order: usize,
        arena: &mut Vec<u8>,
        out: &mut Vec<Pending>,
    ) -> Result<(), RuntimeError> {
        let push = |v: T| {
            let start = arena.len();
            arena.extend_from_slice(bytemuck::bytes_of(&v));
            out.push(Pending {
                sim_time_ns: v.header().sim_time_ns,
                order,
                seq: v.header().seq,
                start,
                len: std::mem::size_of::<T>(),
            });
        };
        match ctx {
            Some(ctx) => self.sub.take_ready(ctx, push),
            // Final drain: everything, regardless of stamp.
            None => self.sub.take_all(push),
        }
    }
    fn channel(&self) -> u16 {
        self.channel
    }
    fn lost(&self) -> u64 {
        self.sub.lost()
    }
    fn rejected(&self) -> u64 {
        self.sub.rejected()
    }
}

/// A follower's camera frames: read in place, every `every`-th frame
/// written as a `sensor_msgs/msg/Image` (the rest are skipped by design,
/// not lost).
struct ImageTap {
    sub: Subscriber<ipc_types::Image>,
    channel: u16,
    every: u32,
    frame_id: String,
}

impl Tap for ImageTap {
    fn drain(
        &mut self,
        ctx: Option<&StepContext>,
        order: usize,
        arena: &mut Vec<u8>,
        out: &mut Vec<Pending>,
    ) -> Result<(), RuntimeError> {
        let any_time = StepContext::any_time();
        let (every, frame_id) = (self.every, &self.frame_id);
        self.sub
            .take_ready_in_place(ctx.unwrap_or(&any_time), |img| {
                if img.frame % every != 0 {
                    return;
                }
                let start = arena.len();
                recordings::image::encode(img, frame_id, arena);
                out.push(Pending {
                    sim_time_ns: img.header.sim_time_ns,
                    order,
                    seq: img.header.seq,
                    start,
                    len: arena.len() - start,
                });
            })
    }
    fn channel(&self) -> u16 {
        self.channel
    }
    fn lost(&self) -> u64 {
        self.sub.lost()
    }
    fn rejected(&self) -> u64 {
        self.sub.rejected()
    }
}

/// Simulated time between chunk flushes, ns.
pub const FLUSH_PERIOD_SIM_NS: u64 = 1_000_000_000;

pub struct RecorderTask {
    writer: Option<RecordingWriter>,
    /// The live view (`--live`), serving what is recorded as it is.
    live: Option<crate::live::Live>,
    taps: Vec<Box<dyn Tap>>,
    arena: Vec<u8>,
    batch: Vec<Pending>,
    /// Simulation time of the last chunk flushed, ns.
    last_flush_sim_ns: u64,
}

fn open_tap<T: Sample>(
    rt: &Runtime,
    writer: &mut RecordingWriter,
    service: &str,
    topic: &str,
    limits: &ChannelLimits,
    buffer: usize,
) -> anyhow::Result<Box<dyn Tap>> {
    let sub = rt.subscriber::<T>(service, limits, buffer)?;
    tap_of(sub, writer, topic, limits, buffer)
}

/// The tap of a subscriber already open on `topic`.
fn tap_of<T: Sample>(
    sub: Subscriber<T>,
    writer: &mut RecordingWriter,
    topic: &str,
    limits: &ChannelLimits,
    buffer: usize,
) -> anyhow::Result<Box<dyn Tap>> {
    // The depth the bag states is the buffer this subscriber really has.
    let channel = writer.add_channel_with_depth::<T>(topic, buffer.clamp(1, limits.max_buffer))?;
    Ok(Box::new(TypedTap { sub, channel }))
}

/// What one recorder records: everything, or (a run spread over hosts)
/// what the processes of its own host publish.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Scope {
    /// Record only these vehicles' channels (comma-separated; given with no
    /// value: none), the vehicles of this recorder's host.
    #[arg(long, value_delimiter = ',', num_args = 0..)]
    pub vehicles: Option<Vec<String>>,
    /// Do not record the world snapshot (another host runs the world).
    #[arg(long)]
    pub no_world: bool,
    /// The host this recorder runs on, kept in the recording's metadata.
    #[arg(long)]
    pub host: Option<String>,
}

impl Scope {
    fn records(&self, vehicle: &str) -> bool {
        self.vehicles
            .as_ref()
            .is_none_or(|v| v.iter().any(|n| n == vehicle))
    }
}

/// The scenario texts the recording keeps in its `shoal.run` metadata.
pub struct ScenarioTexts<'a> {
    /// The scenario as the run was given it, resolved (`scenario_toml`).
    pub as_run: &'a str,
    /// Every section with its defaults (`effective_toml`).
    pub effective: Option<&'a str>,
}

impl RecorderTask {
    pub fn new(
        rt: &Runtime,
        scenario: &Scenario,
        texts: &ScenarioTexts<'_>,
        scope: &Scope,
        out: &Path,
        live: Option<&str>,
    ) -> anyhow::Result<Self> {
        let opts = WriterOptions {
            compression: match scenario.recording.compression {
                shoal_scenario::Compression::Zstd => Compression::Zstd,
                shoal_scenario::Compression::Lz4 => Compression::Lz4,
                shoal_scenario::Compression::None => Compression::None,
            },
            zstd_level: scenario.recording.zstd_level,
            chunk_bytes: scenario.recording.chunk_kib * 1024,
            ..WriterOptions::default()
        };
        let mut writer = RecordingWriter::create(out, &opts)?;
        let mut meta = BTreeMap::new();
        meta.insert("scenario".to_string(), scenario.name.clone());
        meta.insert("scenario_toml".to_string(), texts.as_run.to_string());
        if let Some(e) = texts.effective {
            meta.insert("effective_toml".to_string(), e.to_string());
        }
        // The wall-clock start of the run (log times are simulated time from
        // 0): `shoal export --epoch` adds it so that viewers show the date.
        // Metadata, not messages: two lockstep runs still give the same
        // messages.
        let start_unix_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        meta.insert("start_unix_ns".to_string(), start_unix_ns.to_string());
        meta.insert("seed".to_string(), scenario.seed.to_string());
        meta.insert("mode".to_string(), rt.args().mode.as_str().to_string());
        meta.insert(
            "shoal_version".to_string(),
            env!("CARGO_PKG_VERSION").to_string(),
        );
        meta.insert("vehicles".to_string(), scenario.vehicles.len().to_string());
        meta.insert("run_id".to_string(), rt.args().run_id.clone());
        if let Some(h) = &scope.host {
            meta.insert("host".to_string(), h.clone());
        }
        writer.metadata("shoal.run", meta)?;

        let run = rt.args().run_id.clone();
        let buffer = scenario.recording.buffer;
        let vlimits = ChannelLimits::vehicle();
        let mut taps: Vec<Box<dyn Tap>> = Vec::new();
        if !scope.no_world {
            taps.push(open_tap::<ipc_types::World>(
                rt,
                &mut writer,
                &ipc_types::run_service_name(&run, RunChannel::World),
                "/world",
                &ChannelLimits::world(scenario.vehicles.len()),
                buffer.min(4),
            )?);
        }
        // Every process publishes stats and they stop together: this one
        // subscriber keeps the connection of each until it is read.
        let stats_limits = shoal_runtime::stats::stats_limits(rt.args().processes);
        let stats = rt.subscriber_of_many::<ipc_types::ProcessStats>(
            &ipc_types::run_service_name(&run, RunChannel::Stats),
            &stats_limits,
            4,
        )?;
        taps.push(tap_of(stats, &mut writer, "/stats", &stats_limits, 4)?);
        taps.push(open_tap::<ipc_types::Event>(
            rt,
            &mut writer,
            &ipc_types::run_service_name(&run, RunChannel::Events),
            "/events",
            &ChannelLimits::events(),
            shoal_runtime::EVENTS_HISTORY,
        )?);
        let recorded = || scenario.vehicles.iter().filter(|v| scope.records(&v.name));
        for v in recorded() {
            for ch in Channel::ALL {
                if ch.follower_only() && v.parent.is_none() {
                    continue;
                }
                let service = ipc_types::service_name(&run, &v.name, ch);
                let topic = ipc_types::topic(&v.name, ch);
                let b = buffer.min(vlimits.max_buffer);
                let tap = ipc_types::with_channel_type!(ch, T => open_tap::<T>(
                    rt,
                    &mut writer,
                    &service,
                    &topic,
                    &vlimits,
                    b,
                )?);
                taps.push(tap);
            }
        }
        if scenario.camera_model() == shoal_scenario::CameraModel::Image {
            let camera: camera_pose::CameraConfig = scenario.section("camera")?;
            let every = (scenario.rates.camera_hz / camera.record_hz)
                .round()
                .max(1.0) as u32;
            for v in recorded().filter(|v| v.parent.is_some()) {
                let limits = ChannelLimits::image();
                let sub = rt.subscriber::<ipc_types::Image>(
                    &ipc_types::image_service_name(&run, &v.name),
                    &limits,
                    limits.max_buffer,
                )?;
                let channel = writer
                    .add_image_channel(&ipc_types::image_topic(&v.name), limits.max_buffer)?;
                taps.push(Box::new(ImageTap {
                    sub,
                    channel,
                    every,
                    frame_id: recordings::image::frame_id(&v.name),
                }));
            }
        }
        let live = match live {
            Some(addr) => {
                let mut l = crate::live::Live::start(addr, &run, scenario)?;
                for tap in &taps {
                    if let Some(schema) = writer.channel_schema(tap.channel()) {
                        l.add(tap.channel(), schema)?;
                    }
                }
                Some(l)
            }
            None => None,
        };
        Ok(Self {
            writer: Some(writer),
            live,
            taps,
            arena: Vec::with_capacity(1 << 20),
            batch: Vec::with_capacity(4096),
            last_flush_sim_ns: 0,
        })
    }

    fn drain(&mut self, ctx: Option<&StepContext>) -> Result<(), TaskError> {
        self.arena.clear();
        self.batch.clear();
        for (order, tap) in self.taps.iter_mut().enumerate() {
            tap.drain(ctx, order, &mut self.arena, &mut self.batch)?;
        }
        self.batch
            .sort_unstable_by_key(|p| (p.sim_time_ns, p.order, p.seq));
        let Some(writer) = self.writer.as_mut() else {
            return Ok(());
        };
        if let Some(live) = self.live.as_mut() {
            live.batch_start();
        }
        for p in &self.batch {
            let channel = self.taps[p.order].channel();
            writer
                .write_raw(
                    channel,
                    p.sim_time_ns,
                    p.seq,
                    &self.arena[p.start..p.start + p.len],
                )
                .map_err(TaskError::failed("recording write"))?;
            if let Some(live) = self.live.as_mut() {
                live.log(channel, p.sim_time_ns, writer.last_message());
            }
        }
        if let (Some(live), Some(last)) = (self.live.as_mut(), self.batch.last()) {
            live.batch_done(last.sim_time_ns);
        }
        // Close a chunk each simulated second, so a recorder that dies loses
        // about a second of the run at any speed (a wall-clock period would
        // lose a minute of a run at 60x real time).
        if let Some(last) = self.batch.last() {
            if last.sim_time_ns >= self.last_flush_sim_ns.saturating_add(FLUSH_PERIOD_SIM_NS) {
                writer
                    .flush()
                    .map_err(TaskError::failed("recording flush"))?;
                self.last_flush_sim_ns = last.sim_time_ns;
            }
        }
        Ok(())
    }
}

impl Task for RecorderTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let ctx = (ctx.mode == shoal_runtime::Mode::Lockstep).then_some(ctx);
        self.drain(ctx)
    }

    fn finish(&mut self) -> Result<(), TaskError> {
        self.drain(None)?;
        let live_sent = self.live.take().map(|mut live| {
            live.stop();
            live.sent()
        });
        let lost: u64 = self.taps.iter().map(|t| t.lost()).sum();
        let rejected: u64 = self.taps.iter().map(|t| t.rejected()).sum();
        if let Some(mut writer) = self.writer.take() {
            let mut meta = BTreeMap::new();
            meta.insert("messages".to_string(), writer.messages().to_string());
            meta.insert("dropped".to_string(), lost.to_string());
            meta.insert("rejected".to_string(), rejected.to_string());
            if let Some(n) = live_sent {
                // Messages the live view sent to at least one client.
                meta.insert("live_sent".to_string(), n.to_string());
            }
            writer
                .metadata("shoal.recorder", meta)
                .map_err(TaskError::failed("recording metadata"))?;
            let n = writer
                .finish()
                .map_err(TaskError::failed("recording finish"))?;
            tracing::info!(messages = n, dropped = lost, rejected, "recording finished");
        }
        Ok(())
    }
}
