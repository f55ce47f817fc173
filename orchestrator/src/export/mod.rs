//! `shoal export`: converts a shoal recording into channels other tools show
//! without a plug-in (Foxglove).
//!
//! `shoal export REC.mcap --foxglove OUT.mcap` writes an MCAP whose channels
//! use the well-known Foxglove schemas in protobuf (`protobuf` message and
//! schema encoding, each schema the `FileDescriptorSet` Foxglove publishes;
//! see [`foxglove`]), so Foxglove's 3D panel shows the run with no extension
//! and Rerun's MCAP importer reads it as transforms and scene entities:
//!
//! | topic | schema | what, and how it is derived |
//! |---|---|---|
//! | `/tf` | `foxglove.FrameTransforms` | at every `truth` time: `world → ned` (fixed), and per vehicle `ned → <V>/body` (true position, attitude body → NED) and `ned → <V>/level` (position, heading only) |
//! | `/scene/obstacles` | `foxglove.SceneUpdate` | once: each scenario obstacle (box, cylinder, sphere, mesh) in `ned` |
//! | `/scene/vehicles` | `foxglove.SceneUpdate` | once: each vehicle's hull, heading arrow, name and beacons in `<V>/body`, frame-locked |
//! | `/scene/slots` | `foxglove.SceneUpdate` | per follower `planner_state`: the filtered slot (eq. 9; orange while avoiding), the nominal slot (ghost) in the parent's `level` frame, and a line to where the follower truly is |
//! | `/scene/sonar` | `foxglove.SceneUpdate` | per `sonar` scan: each beam from the transducer in `<V>/body`, red to the echo, grey to the maximum range when none |
//! | `/scene/line_of_sight` | `foxglove.SceneUpdate` | per follower `beacons` frame: a line from its camera to each beacon of its parent (true poses), green if seen in that frame, red if not |
//! | `/<V>/pose` | `foxglove.PoseInFrame` | per `truth`: the true pose in `ned` (turn on history for a track) |
//! | `/<F>/parent_estimate` | `foxglove.PoseInFrame` | per valid `leader_pose`: the parent's pose as the follower's camera estimated it, in `<F>/body` |
//!
//! **Frames.** shoal's world is NED. The root frame `world` is ENU (z up) and
//! `/tf` carries the fixed `world → ned` rotation; everything else is in
//! shoal's own axes (see [`frames`]). Choose `world` as the display frame.
//!
//! **Time.** Log and publish times are the source sample's simulation time
//! (ns from the start of the run, so the view starts at 1970-01-01 00:00:00).
//! A message's own timestamp is the sim time its geometry holds for: the
//! sample's sim time, or for sensor-derived entities (sonar, line of sight,
//! parent estimate) the sim time of the world snapshot the sensor saw
//! (`origin_sim_time_ns`). Entities that need another vehicle's pose use its
//! latest `truth` at or before that time.
//!
//! The scenario (vehicles, formation tree, obstacles, beacon layout, camera
//! and sonar mounts) comes from the recording's `shoal.run` metadata. Without
//! it, only `/tf`, `/scene/vehicles`, `/scene/sonar` and the poses are written.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::Context;
use ipc_types::Channel;
use shoal_scenario::Scenario;
use shoal_view::foxglove::FoxgloveMessage;
use shoal_view::{parse_topic, Converter, Out, ViewConfig};

/// How an export is written.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExportOptions {
    /// Replace an existing output.
    pub force: bool,
    /// Show a progress bar (on a terminal).
    pub progress: bool,
    /// Shift every time by the run's wall-clock start (`shoal.run`
    /// `start_unix_ns`), so that viewers show the real date.
    pub epoch: bool,
}

/// The run's wall-clock start, ns since the Unix epoch, as the recorder
/// kept it (`shoal.run` / `start_unix_ns`).
pub fn start_unix_ns(rec: &recordings::Recording) -> Option<u64> {
    rec.run_meta("start_unix_ns").and_then(|v| v.parse().ok())
}

/// Refuses a file shoal did not write: one with neither shoal's run
/// metadata nor a channel of a shoal sample type (converting it would give
/// an empty view and look like success).
pub fn ensure_shoal_recording(rec: &recordings::Recording, path: &Path) -> anyhow::Result<()> {
    anyhow::ensure!(
        rec.written_by_shoal(),
        "{} is not a shoal recording: it has no `shoal.run` metadata and no channel of a shoal_msgs type (nothing was written)",
        path.display()
    );
    Ok(())
}

/// Converts the recording at `recording` into a Foxglove MCAP at `out`:
/// written beside it first and moved into place only when complete, so a
/// failure leaves nothing; an existing `out` is replaced only with `force`
/// and never when it is the input; a file shoal did not write is refused.
pub fn export_to_file(
    recording: &Path,
    out: &Path,
    opts: ExportOptions,
) -> anyhow::Result<ExportReport> {
    let ExportOptions {
        force,
        progress,
        epoch,
    } = opts;
    if out.exists() {
        if !force {
            anyhow::bail!("{} exists: pass --force to replace it", out.display());
        }
        if same_file(out, recording) {
            anyhow::bail!(
                "{} is the input recording: choose another output",
                out.display()
            );
        }
    }
    let rec = recordings::Recording::open(recording)?;
    ensure_shoal_recording(&rec, recording)?;
    let epoch_ns = if epoch {
        start_unix_ns(&rec).with_context(|| {
            format!(
                "{} does not say when its run started (shoal.run/start_unix_ns): export it without --epoch",
                recording.display()
            )
        })?
    } else {
        0
    };
    if rec.truncated() {
        tracing::warn!(
            "{} is truncated: exporting up to its last complete chunk",
            recording.display()
        );
    }
    let partial = partial_path(out);
    let result = File::create(&partial)
        .with_context(|| format!("cannot create {}", partial.display()))
        .and_then(|f| {
            export_foxglove(
                &rec,
                BufWriter::with_capacity(1 << 20, f),
                progress,
                epoch_ns,
            )
        });
    let report = match result {
        Ok(r) => r,
        Err(e) => {
            // Leave no half-written file behind; the error is what matters.
            let _ = std::fs::remove_file(&partial);
            return Err(e);
        }
    };
    std::fs::rename(&partial, out)
        .with_context(|| format!("cannot move {} to {}", partial.display(), out.display()))?;
    Ok(report)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

fn partial_path(out: &Path) -> PathBuf {
    let mut name = out.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    out.with_file_name(name)
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportReport {
    /// Per channel, in order of creation: topic, schema name, messages.
    pub channels: Vec<(String, String, u64)>,
    /// First and last log time, ns.
    pub span_ns: (u64, u64),
    /// Why parts of the view are missing, if any.
    pub notes: Vec<String>,
}

impl ExportReport {
    /// Total messages.
    pub fn messages(&self) -> u64 {
        self.channels.iter().map(|c| c.2).sum()
    }
}

/// Writes Foxglove messages to one MCAP, a channel per topic, created on first use.
struct FoxgloveWriter<W: std::io::Write + std::io::Seek> {
    writer: mcap::Writer<W>,
    schemas: HashMap<String, u16>,
    topics: HashMap<String, usize>,
    /// Channel id, topic, schema name, messages.
    channels: Vec<(u16, String, String, u64)>,
    span_ns: (u64, u64),
    /// Added to every log and publish time (the run's start with
    /// `--epoch`, else 0).
    epoch_ns: u64,
    buf: Vec<u8>,
}

impl<W: std::io::Write + std::io::Seek> Out for FoxgloveWriter<W> {
    fn write<T: FoxgloveMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> anyhow::Result<()> {
        self.write_message(topic, log_time_ns, msg)
    }

    fn epoch_ns(&self) -> u64 {
        self.epoch_ns
    }
}

impl<W: std::io::Write + std::io::Seek> FoxgloveWriter<W> {
    fn new(w: W, epoch_ns: u64) -> anyhow::Result<Self> {
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(0)
            .chunk_size(Some(1 << 20))
            .library(format!("shoal {} export", env!("CARGO_PKG_VERSION")))
            .create(w)?;
        Ok(Self {
            writer,
            schemas: HashMap::new(),
            topics: HashMap::new(),
            channels: Vec::new(),
            span_ns: (u64::MAX, 0),
            epoch_ns,
            buf: Vec::with_capacity(16 * 1024),
        })
    }

    /// The index of `topic`'s channel, created with its schema on first use.
    fn channel(
        &mut self,
        topic: &str,
        schema: &::foxglove::Schema,
        message_encoding: &str,
    ) -> anyhow::Result<usize> {
        if let Some(i) = self.topics.get(topic) {
            let carried = &self.channels[*i].2;
            anyhow::ensure!(
                *carried == schema.name,
                "topic {topic} carries {carried}, not {}",
                schema.name
            );
            return Ok(*i);
        }
        let schema_id = match self.schemas.get(&schema.name) {
            Some(id) => *id,
            None => {
                let id = self
                    .writer
                    .add_schema(&schema.name, &schema.encoding, &schema.data)?;
                self.schemas.insert(schema.name.clone(), id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, message_encoding, &BTreeMap::new())?;
        self.channels
            .push((id, topic.to_string(), schema.name.clone(), 0));
        self.topics
            .insert(topic.to_string(), self.channels.len() - 1);
        Ok(self.channels.len() - 1)
    }

    /// Writes `data` on channel `idx` at `log_time_ns` (shifted by the epoch).
    fn write_bytes(&mut self, idx: usize, log_time_ns: u64, data: &[u8]) -> anyhow::Result<()> {
        let (id, _, _, count) = &mut self.channels[idx];
        let header = mcap::records::MessageHeader {
            channel_id: *id,
            sequence: *count as u32,
            log_time: log_time_ns.saturating_add(self.epoch_ns),
            publish_time: log_time_ns.saturating_add(self.epoch_ns),
        };
        self.writer.write_to_known_channel(&header, data)?;
        *count += 1;
        self.span_ns = (
            self.span_ns.0.min(log_time_ns),
            self.span_ns.1.max(log_time_ns),
        );
        Ok(())
    }

    /// Writes a Foxglove message (protobuf, its schema the type's own).
    fn write_message<T: FoxgloveMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> anyhow::Result<()> {
        let schema = T::get_schema()
            .with_context(|| format!("a Foxglove message type without a schema on {topic}"))?;
        let idx = self.channel(topic, &schema, &T::get_message_encoding())?;
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        let encoded = msg
            .encode(&mut buf)
            .map_err(|e| anyhow::anyhow!("cannot encode {} for {topic}: {e}", schema.name));
        let written = encoded.and_then(|()| self.write_bytes(idx, log_time_ns, &buf));
        self.buf = buf;
        written
    }

    /// Copies a recorded camera frame (`sensor_msgs/msg/Image`, CDR, as
    /// stored) onto `topic`: Foxglove's Image panel shows it as it is.
    fn write_image(&mut self, topic: &str, log_time_ns: u64, data: &[u8]) -> anyhow::Result<()> {
        let schema = ::foxglove::Schema::new(
            recordings::image::SCHEMA_NAME,
            "ros2msg",
            recordings::image::SCHEMA_TEXT.as_bytes(),
        );
        let idx = self.channel(topic, &schema, "cdr")?;
        self.write_bytes(idx, log_time_ns, data)
    }

    fn finish(mut self, notes: Vec<String>) -> anyhow::Result<ExportReport> {
        self.writer.finish()?;
        Ok(ExportReport {
            channels: self
                .channels
                .into_iter()
                .map(|(_, t, s, n)| (t, s, n))
                .collect(),
            span_ns: if self.span_ns.0 == u64::MAX {
                (0, 0)
            } else {
                self.span_ns
            },
            notes,
        })
    }
}

/// The view of a recording: its `shoal.run` scenario, else its topics.
fn view_of(rec: &recordings::Recording, notes: &mut Vec<String>) -> ViewConfig {
    let topic_vehicles = || -> Vec<String> {
        let mut v: Vec<String> = rec
            .channels()
            .iter()
            .filter_map(|c| parse_topic(&c.topic))
            .filter(|(_, ch)| *ch == Channel::Truth)
            .map(|(v, _)| v.to_string())
            .collect();
        v.dedup();
        v
    };
    let scenario = match rec.run_meta("scenario_toml").map(Scenario::from_toml) {
        Some(Ok(s)) => Some(s),
        Some(Err(e)) => {
            notes.push(format!(
                "the recorded scenario does not parse ({e}): no obstacles, slots or lines of sight"
            ));
            None
        }
        None => {
            notes.push("the recording has no scenario (shoal.run/scenario_toml): no obstacles, slots or lines of sight".into());
            None
        }
    };
    ViewConfig::from_scenario(scenario.as_ref(), topic_vehicles, notes)
}

/// Converts a loaded recording; writes the MCAP to `w`.
fn export_foxglove<W: std::io::Write + std::io::Seek>(
    rec: &recordings::Recording,
    w: W,
    progress: bool,
    epoch_ns: u64,
) -> anyhow::Result<ExportReport> {
    let mut notes = Vec::new();
    let cfg = view_of(rec, &mut notes);
    let out = FoxgloveWriter::new(w, epoch_ns)?;

    // Per input channel: (vehicle, channel) for the ones the view uses.
    let routes: HashMap<u16, (String, Channel)> = rec
        .channels()
        .iter()
        .filter_map(|c| parse_topic(&c.topic).map(|(v, ch)| (c.id, (v.to_string(), ch))))
        .collect();
    // Camera frames go across unchanged, on their own topic.
    let images: HashMap<u16, String> = rec
        .channels()
        .iter()
        .filter(|c| c.schema_name == recordings::image::SCHEMA_NAME)
        .map(|c| (c.id, c.topic.clone()))
        .collect();
    // Time order; at equal times truth first, so everything at t sees truth at t.
    let msgs = rec.messages();
    let mut order: Vec<usize> = (0..msgs.len())
        .filter(|i| {
            routes.contains_key(&msgs[*i].channel) || images.contains_key(&msgs[*i].channel)
        })
        .collect();
    order.sort_by_key(|i| {
        let m = &msgs[*i];
        let truth = routes.get(&m.channel).map(|r| r.1) == Some(Channel::Truth);
        (m.log_time, !truth)
    });

    let mut conv = Converter::new(cfg, out);
    conv.static_scene(order.first().map(|i| msgs[*i].log_time).unwrap_or(0))?;
    let bar = crate::progress::bar(progress, order.len() as u64, "messages");
    for (n, i) in order.iter().enumerate() {
        if n % 4096 == 0 {
            bar.set_position(n as u64);
        }
        let m = &msgs[*i];
        if let Some(topic) = images.get(&m.channel) {
            conv.out.write_image(topic, m.log_time, &m.data)?;
            continue;
        }
        let Some((vehicle, channel)) = routes.get(&m.channel) else {
            continue;
        };
        conv.message(vehicle, *channel, m.log_time, &m.data)?;
    }
    conv.flush_tf()?;
    bar.finish_and_clear();
    if conv.skipped() > 0 {
        notes.push(format!(
            "{} samples skipped (wrong size or non-finite values)",
            conv.skipped()
        ));
    }
    conv.out.finish(notes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use ipc_types::{Beacons, PlannerState, Sample, Sonar, Truth};
    use recordings::{RecordingWriter, WriterOptions};
    use serde_json::Value;
    use shoal_view::foxglove::{FrameTransforms, PoseInFrame, SceneUpdate};

    const SCENARIO: &str = r#"
name = "unit"
duration_s = 1.0
[[vehicles]]
name = "L"
[[vehicles]]
name = "F1"
parent = "L"
slot_m = [-8.0, -4.0, 0.0]
[[obstacles]]
kind = "sphere"
center_ned_m = [30.0, 0.0, 10.0]
radius_m = 2.0
"#;

    fn truth(t: u64, p: [f64; 3]) -> Truth {
        let mut s = Truth::zeroed();
        s.header.sim_time_ns = t;
        s.header.origin_sim_time_ns = t;
        s.position_ned_m = p;
        s.q_body_to_ned_wxyz = [1.0, 0.0, 0.0, 0.0];
        s
    }

    /// A two-vehicle recording: L at (10, 0, 10), F1 in its slot 8 m behind
    /// and 4 m to port, both heading north; one camera frame, one planner
    /// state, one sonar scan 40 ms later, as the lockstep pipeline stamps them.
    fn write_recording(path: &Path, with_scenario: bool) {
        let mut w = RecordingWriter::create(path, &WriterOptions::default()).unwrap();
        if with_scenario {
            let mut meta = BTreeMap::new();
            meta.insert("scenario_toml".to_string(), SCENARIO.to_string());
            w.metadata("shoal.run", meta).unwrap();
        }
        let lt = w.add_channel::<Truth>("/L/truth").unwrap();
        let ft = w.add_channel::<Truth>("/F1/truth").unwrap();
        let fb = w.add_channel::<Beacons>("/F1/beacons").unwrap();
        let fp = w.add_channel::<PlannerState>("/F1/planner_state").unwrap();
        let ls = w.add_channel::<Sonar>("/L/sonar").unwrap();
        for k in 0..3u64 {
            let t = k * 100_000_000;
            w.write(lt, &truth(t, [10.0 + k as f64, 0.0, 10.0]))
                .unwrap();
            w.write(ft, &truth(t, [2.0 + k as f64, -4.0, 10.0]))
                .unwrap();
        }
        let mut b = Beacons::zeroed();
        b.header.sim_time_ns = 40_000_000;
        b.count = 4;
        b.visible = [1, 0, 1, 1, 0, 0, 0, 0];
        w.write(fb, &b).unwrap();
        let mut p = PlannerState::zeroed();
        p.header.sim_time_ns = 60_000_000;
        p.slot_nominal_m = [-8.0, -4.0, 0.0];
        p.slot_filtered_m = [-8.0, -4.0, 0.0];
        w.write(fp, &p).unwrap();
        let mut s = Sonar::zeroed();
        s.header.sim_time_ns = 40_000_000;
        s.count = 1;
        s.ranges_m[0] = 5.0;
        s.valid[0] = 1;
        w.write(ls, &s).unwrap();
        w.finish().unwrap();
    }

    /// Exports and reads back: topic → messages as JSON, in log-time order.
    fn export_of(with_scenario: bool) -> (ExportReport, BTreeMap<String, Vec<(u64, Value)>>) {
        export_at(with_scenario, 0)
    }

    /// [`export_of`] with every time shifted by `epoch_ns`.
    fn export_at(
        with_scenario: bool,
        epoch_ns: u64,
    ) -> (ExportReport, BTreeMap<String, Vec<(u64, Value)>>) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rec.mcap");
        write_recording(&path, with_scenario);
        let rec = recordings::Recording::open(&path).unwrap();
        let mut buf = std::io::Cursor::new(Vec::new());
        let report = export_foxglove(&rec, &mut buf, false, epoch_ns).unwrap();
        let bytes = buf.into_inner();
        let mut out: BTreeMap<String, Vec<(u64, Value)>> = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            assert_eq!(m.channel.message_encoding, "protobuf");
            let schema = m.channel.schema.as_ref().unwrap();
            assert_eq!(schema.encoding, "protobuf");
            // Decoded with Foxglove's own types, looked at as JSON.
            fn json<T: ::foxglove::Decode + serde::Serialize>(data: &[u8]) -> Value
            where
                T::Error: std::fmt::Debug,
            {
                serde_json::to_value(T::decode(data).unwrap()).unwrap()
            }
            let value = match schema.name.as_str() {
                "foxglove.SceneUpdate" => json::<SceneUpdate>(&m.data),
                "foxglove.FrameTransforms" => json::<FrameTransforms>(&m.data),
                "foxglove.PoseInFrame" => json::<PoseInFrame>(&m.data),
                other => panic!("unexpected schema {other}"),
            };
            out.entry(m.channel.topic.clone())
                .or_default()
                .push((m.log_time, value));
        }
        (report, out)
    }

    fn xyz(v: &Value) -> [f64; 3] {
        [
            v["x"].as_f64().unwrap(),
            v["y"].as_f64().unwrap(),
            v["z"].as_f64().unwrap(),
        ]
    }

    #[test]
    fn line_of_sight_runs_from_the_camera_to_the_parents_beacons_at_the_frame_time() {
        let (report, out) = export_of(true);
        assert!(report.notes.is_empty(), "{:?}", report.notes);
        let (t, los) = &out["/scene/line_of_sight"][0];
        assert_eq!(*t, 40_000_000);
        let e = &los["entities"][0];
        // The frame saw the world of t = 0 (origin_sim_time_ns = 0).
        assert_eq!(e["timestamp"]["nsec"], 0);
        let line = &e["lines"][0];
        let pts: Vec<[f64; 3]> = line["points"].as_array().unwrap().iter().map(xyz).collect();
        assert_eq!(pts.len(), 8);
        // Camera 1.4 m ahead of F1 at (2, -4, 10); beacon 0 is 1.5 m behind L at (10, 0, 10).
        assert_eq!(pts[0], [3.4, -4.0, 10.0]);
        assert_eq!(pts[1], [8.5, 0.0, 10.0]);
        // Beacon 1 (1 m behind, 0.4 m up) was not seen: red; beacon 2 was: green.
        assert_eq!(pts[3], [9.0, 0.0, 9.6]);
        let colour = |i: usize| line["colors"][i]["g"].as_f64().unwrap() > 0.5;
        assert!(colour(1) && !colour(3) && colour(5) && colour(7));
    }

    #[test]
    fn slots_sonar_and_frames_come_from_the_recorded_samples() {
        let (report, out) = export_of(true);
        let topics: Vec<&str> = report.channels.iter().map(|c| c.0.as_str()).collect();
        for t in [
            "/scene/obstacles",
            "/scene/vehicles",
            "/tf",
            "/L/pose",
            "/F1/pose",
            "/scene/slots",
            "/scene/sonar",
            "/scene/line_of_sight",
        ] {
            assert!(topics.contains(&t), "{t} missing from {topics:?}");
        }
        assert_eq!(
            report.messages(),
            out.values().map(|v| v.len() as u64).sum::<u64>()
        );
        // One /tf per truth time, each with world→ned and both vehicles' body and level frames.
        let tf = &out["/tf"];
        assert_eq!(tf.len(), 3);
        assert_eq!(tf[2].0, 200_000_000);
        let children: Vec<&str> = tf[2].1["transforms"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t["child_frame_id"].as_str().unwrap())
            .collect();
        assert_eq!(
            children,
            ["ned", "L/body", "L/level", "F1/body", "F1/level"]
        );
        assert_eq!(
            xyz(&tf[2].1["transforms"][1]["translation"]),
            [12.0, 0.0, 10.0]
        );
        // The slot: F1 is exactly in it, seen from L's level frame at t = 60 ms (truth of t = 0).
        let slot = &out["/scene/slots"][0].1["entities"][0];
        assert_eq!(slot["frame_id"], "L/level");
        let err = slot["metadata"]
            .as_array()
            .unwrap()
            .iter()
            .find(|k| k["key"] == "slot_error_m")
            .unwrap();
        assert_eq!(err["value"], "0.000");
        let end = xyz(&slot["lines"][0]["points"][1]);
        assert_relative_eq!(end[0], -8.0);
        assert_relative_eq!(end[1], -4.0);
        // Sonar: one beam straight ahead from the 0.8 m mount to the 5 m echo.
        let sonar = &out["/scene/sonar"][0].1["entities"][0];
        assert_eq!(sonar["frame_id"], "L/body");
        assert_eq!(xyz(&sonar["lines"][0]["points"][1]), [5.8, 0.0, 0.0]);
        // The sphere obstacle, in ned.
        let ob = &out["/scene/obstacles"][0].1["entities"][0];
        assert_eq!(ob["frame_id"], "ned");
        assert_eq!(xyz(&ob["spheres"][0]["size"]), [4.0, 4.0, 4.0]);
    }

    #[test]
    fn without_a_scenario_the_frames_vehicles_and_poses_are_still_written() {
        let (report, out) = export_of(false);
        assert!(
            report.notes.iter().any(|n| n.contains("no scenario")),
            "{:?}",
            report.notes
        );
        assert!(
            out.contains_key("/tf")
                && out.contains_key("/scene/vehicles")
                && out.contains_key("/scene/sonar")
        );
        assert!(!out.contains_key("/scene/slots") && !out.contains_key("/scene/line_of_sight"));
        let ids: Vec<&str> = out["/scene/vehicles"][0].1["entities"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["id"].as_str().unwrap())
            .collect();
        // Recording (channel) order.
        assert_eq!(ids, ["vehicle/L", "vehicle/F1"]);
    }

    #[test]
    fn the_output_is_refused_when_it_exists_and_never_the_input() {
        let dir = tempfile::tempdir().unwrap();
        let rec = dir.path().join("rec.mcap");
        write_recording(&rec, true);
        let out = dir.path().join("view.mcap");
        std::fs::write(&out, b"old").unwrap();
        let forced = ExportOptions {
            force: true,
            ..Default::default()
        };
        let e = export_to_file(&rec, &out, ExportOptions::default()).unwrap_err();
        assert!(e.to_string().contains("--force"), "{e}");
        assert_eq!(std::fs::read(&out).unwrap(), b"old");
        export_to_file(&rec, &out, forced).unwrap();
        assert_ne!(std::fs::read(&out).unwrap(), b"old");
        assert!(!partial_path(&out).exists());
        let e = export_to_file(&rec, &rec, forced).unwrap_err();
        assert!(e.to_string().contains("input recording"), "{e}");
    }

    #[test]
    fn the_epoch_shifts_every_log_time_and_timestamp_by_the_same_amount() {
        let start = 1_796_000_000_123_456_789_u64;
        let (_, plain) = export_at(true, 0);
        let (_, dated) = export_at(true, start);
        assert_eq!(
            plain.keys().collect::<Vec<_>>(),
            dated.keys().collect::<Vec<_>>()
        );
        for (topic, msgs) in &plain {
            for ((t0, m0), (t1, m1)) in msgs.iter().zip(&dated[topic]) {
                assert_eq!(t1 - t0, start, "{topic}");
                if let (Some(a), Some(b)) = (m0.get("timestamp"), m1.get("timestamp")) {
                    let ns = |v: &Value| {
                        v["sec"].as_u64().unwrap() * 1_000_000_000 + v["nsec"].as_u64().unwrap()
                    };
                    assert_eq!(ns(b) - ns(a), start, "{topic}");
                }
            }
        }
    }

    #[test]
    fn a_file_shoal_did_not_write_is_refused_and_nothing_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let other = dir.path().join("other.mcap");
        {
            let f = std::io::BufWriter::new(std::fs::File::create(&other).unwrap());
            let mut w = mcap::Writer::new(f).unwrap();
            let schema = w.add_schema("foo.Bar", "jsonschema", b"{}").unwrap();
            let ch = w
                .add_channel(schema, "/x", "json", &BTreeMap::new())
                .unwrap();
            let header = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: 0,
                log_time: 1,
                publish_time: 1,
            };
            w.write_to_known_channel(&header, b"{}").unwrap();
            w.finish().unwrap();
        }
        let out = dir.path().join("view.mcap");
        let e = export_to_file(&other, &out, ExportOptions::default()).unwrap_err();
        assert!(e.to_string().contains("not a shoal recording"), "{e}");
        assert!(!out.exists() && !partial_path(&out).exists());
    }
}
