//! `shoal export`: converts a shoal recording into channels other tools show
//! without a plug-in (Foxglove).
//!
//! `shoal export REC.mcap --foxglove OUT.mcap` writes an MCAP whose channels
//! use the well-known Foxglove schemas in JSON (`json` message encoding,
//! `jsonschema` schema encoding, the official schema text embedded; see
//! [`foxglove`]), so Foxglove's 3D panel shows the run with no extension:
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

mod foxglove;
mod frames;
mod scene;

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, IsTerminal};
use std::path::{Path, PathBuf};

use anyhow::Context;
use ipc_types::{Beacons, Channel, LeaderPose, PlannerState, Sonar, Truth};
use nalgebra::Vector3;
use shoal_scenario::Scenario;

use foxglove::{FoxgloveMessage, FrameTransforms, Pose, PoseInFrame, SceneUpdate, Time};
use frames::{
    body_frame, level_frame, level_rotation, to_foxglove, transform, unit_wxyz, NED_FRAME,
};
use scene::{ScanView, SlotView, TruePose, VehicleLook};

/// Arguments of `shoal export`.
#[derive(Debug, clap::Args)]
pub struct ExportCmd {
    /// The shoal recording (MCAP), e.g. runs/paper-<time>/recording.mcap.
    pub recording: PathBuf,
    /// Write a Foxglove-ready MCAP here: obstacles, vehicles, slots, sonar
    /// beams and the camera's line of sight as foxglove.SceneUpdate,
    /// frames as foxglove.FrameTransforms, poses as foxglove.PoseInFrame
    /// (JSON). Open it in Foxglove and pick the `world` frame (ENU, z up).
    #[arg(long)]
    pub foxglove: PathBuf,
    /// Replace OUT if it exists (it is refused otherwise).
    #[arg(long)]
    pub force: bool,
    /// No progress bar and no closing table.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `shoal export`.
pub fn run(cmd: ExportCmd) -> anyhow::Result<()> {
    let out = &cmd.foxglove;
    if out.exists() {
        if !cmd.force {
            anyhow::bail!("{} exists: pass --force to replace it", out.display());
        }
        if same_file(out, &cmd.recording) {
            anyhow::bail!(
                "{} is the input recording: choose another output",
                out.display()
            );
        }
    }
    let rec = recordings::Recording::open(&cmd.recording)?;
    if rec.truncated() {
        tracing::warn!(
            "{} is truncated: exporting up to its last complete chunk",
            cmd.recording.display()
        );
    }
    let partial = partial_path(out);
    let result = File::create(&partial)
        .with_context(|| format!("cannot create {}", partial.display()))
        .and_then(|f| export_foxglove(&rec, BufWriter::with_capacity(1 << 20, f), !cmd.quiet));
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
    if !cmd.quiet {
        report.print(out);
    }
    Ok(())
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
    pub channels: Vec<(String, &'static str, u64)>,
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

    fn print(&self, out: &Path) {
        println!(
            "{}: {} messages on {} channels, {:.1} s .. {:.1} s (sim time)",
            out.display(),
            self.messages(),
            self.channels.len(),
            self.span_ns.0 as f64 * 1e-9,
            self.span_ns.1 as f64 * 1e-9
        );
        println!("{:<26} {:<26} {:>8}", "topic", "schema", "messages");
        for (topic, schema, n) in &self.channels {
            println!("{topic:<26} {schema:<26} {n:>8}");
        }
        for n in &self.notes {
            println!("note: {n}");
        }
    }
}

/// Writes Foxglove messages to one MCAP, a channel per topic, created on first use.
struct FoxgloveWriter<W: std::io::Write + std::io::Seek> {
    writer: mcap::Writer<W>,
    schemas: HashMap<&'static str, u16>,
    topics: HashMap<String, usize>,
    /// Channel id, topic, schema name, messages.
    channels: Vec<(u16, String, &'static str, u64)>,
    span_ns: (u64, u64),
    buf: Vec<u8>,
}

impl<W: std::io::Write + std::io::Seek> FoxgloveWriter<W> {
    fn new(w: W) -> anyhow::Result<Self> {
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
            buf: Vec::with_capacity(16 * 1024),
        })
    }

    fn write<T: FoxgloveMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> anyhow::Result<()> {
        let idx = match self.topics.get(topic) {
            Some(i) => *i,
            None => {
                let schema = match self.schemas.get(T::SCHEMA_NAME) {
                    Some(id) => *id,
                    None => {
                        let id = self.writer.add_schema(
                            T::SCHEMA_NAME,
                            "jsonschema",
                            T::SCHEMA_JSON.as_bytes(),
                        )?;
                        self.schemas.insert(T::SCHEMA_NAME, id);
                        id
                    }
                };
                let id = self
                    .writer
                    .add_channel(schema, topic, "json", &BTreeMap::new())?;
                self.channels
                    .push((id, topic.to_string(), T::SCHEMA_NAME, 0));
                self.topics
                    .insert(topic.to_string(), self.channels.len() - 1);
                self.channels.len() - 1
            }
        };
        let (id, _, schema, count) = &mut self.channels[idx];
        anyhow::ensure!(
            *schema == T::SCHEMA_NAME,
            "topic {topic} carries {schema}, not {}",
            T::SCHEMA_NAME
        );
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg)?;
        let header = mcap::records::MessageHeader {
            channel_id: *id,
            sequence: *count as u32,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer.write_to_known_channel(&header, &self.buf)?;
        *count += 1;
        self.span_ns = (
            self.span_ns.0.min(log_time_ns),
            self.span_ns.1.max(log_time_ns),
        );
        Ok(())
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

/// The scenario facts the view draws, with the defaults of each service
/// where the recording has no scenario.
struct ViewConfig {
    /// Vehicle names in scenario (or topic) order.
    vehicles: Vec<String>,
    /// Follower → parent.
    parents: HashMap<String, String>,
    obstacles: Vec<sonar::Obstacle>,
    camera: camera_pose::CameraConfig,
    beacons: camera_pose::BeaconLayout,
    hull: camera_pose::HullConfig,
    sonar: sonar::SonarConfig,
}

impl ViewConfig {
    fn from_recording(rec: &recordings::Recording, notes: &mut Vec<String>) -> Self {
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
        let text = rec
            .metadata()
            .get("shoal.run")
            .and_then(|m| m.get("scenario_toml"));
        let scenario = match text.map(|t| Scenario::from_toml(t)) {
            Some(Ok(s)) => Some(s),
            Some(Err(e)) => {
                notes.push(format!("the recorded scenario does not parse ({e}): no obstacles, slots or lines of sight"));
                None
            }
            None => {
                notes.push("the recording has no scenario (shoal.run/scenario_toml): no obstacles, slots or lines of sight".into());
                None
            }
        };
        let Some(s) = scenario else {
            return Self {
                vehicles: topic_vehicles(),
                parents: HashMap::new(),
                obstacles: Vec::new(),
                camera: Default::default(),
                beacons: Default::default(),
                hull: Default::default(),
                sonar: Default::default(),
            };
        };
        fn section<T: serde::de::DeserializeOwned + Default>(
            s: &Scenario,
            key: &str,
            notes: &mut Vec<String>,
        ) -> T {
            s.section(key).unwrap_or_else(|e| {
                notes.push(format!(
                    "[{key}] of the recorded scenario: {e}; drawn with defaults"
                ));
                T::default()
            })
        }
        let obstacles = s.obstacles_as::<sonar::Obstacle>().unwrap_or_else(|e| {
            notes.push(format!(
                "obstacles of the recorded scenario: {e}; not drawn"
            ));
            Vec::new()
        });
        Self {
            vehicles: s.vehicles.iter().map(|v| v.name.clone()).collect(),
            parents: s
                .vehicles
                .iter()
                .filter_map(|v| v.parent.clone().map(|p| (v.name.clone(), p)))
                .collect(),
            obstacles,
            camera: section(&s, "camera", notes),
            beacons: section(&s, "beacons", notes),
            hull: section(&s, "hull", notes),
            sonar: section(&s, "sonar", notes),
        }
    }

    fn look(&self, name: &str) -> VehicleLook {
        let is_parent = self.parents.values().any(|p| p == name);
        VehicleLook {
            name: name.to_string(),
            leader: !self.parents.contains_key(name),
            beacons_body_m: if is_parent {
                self.beacons.positions_body_m.clone()
            } else {
                Vec::new()
            },
            hull_length_m: self.hull.length_m,
            hull_radius_m: self.hull.radius_m,
        }
    }
}

/// `/<vehicle>/<channel>` → (vehicle, channel).
fn parse_topic(topic: &str) -> Option<(&str, Channel)> {
    let rest = topic.strip_prefix('/')?;
    let (vehicle, name) = rest.split_once('/')?;
    Channel::ALL
        .into_iter()
        .find(|c| c.name() == name)
        .map(|c| (vehicle, c))
}

/// One vehicle's true poses so far, in time order.
#[derive(Default)]
struct Track {
    times: Vec<u64>,
    poses: Vec<TruePose>,
}

impl Track {
    /// The latest pose at or before `t`.
    fn at(&self, t: u64) -> Option<&TruePose> {
        let n = self.times.partition_point(|x| *x <= t);
        n.checked_sub(1).map(|i| &self.poses[i])
    }
}

fn true_pose(s: &Truth) -> Option<TruePose> {
    let position = Vector3::from(s.position_ned_m);
    let attitude = unit_wxyz(s.q_body_to_ned_wxyz)?;
    position
        .iter()
        .all(|x| x.is_finite())
        .then_some(TruePose { position, attitude })
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Converts a loaded recording; writes the MCAP to `w`.
fn export_foxglove<W: std::io::Write + std::io::Seek>(
    rec: &recordings::Recording,
    w: W,
    progress: bool,
) -> anyhow::Result<ExportReport> {
    let mut notes = Vec::new();
    let cfg = ViewConfig::from_recording(rec, &mut notes);
    let mut out = FoxgloveWriter::new(w)?;

    // Per input channel: (vehicle, channel) for the ones the view uses.
    let routes: HashMap<u16, (String, Channel)> = rec
        .channels()
        .iter()
        .filter_map(|c| parse_topic(&c.topic).map(|(v, ch)| (c.id, (v.to_string(), ch))))
        .collect();
    // Time order; at equal times truth first, so everything at t sees truth at t.
    let msgs = rec.messages();
    let mut order: Vec<usize> = (0..msgs.len())
        .filter(|i| routes.contains_key(&msgs[*i].channel))
        .collect();
    order.sort_by_key(|i| {
        let m = &msgs[*i];
        let truth = routes.get(&m.channel).map(|r| r.1) == Some(Channel::Truth);
        (m.log_time, !truth)
    });

    // The static scene, at the first message's time.
    let t0 = order.first().map(|i| msgs[*i].log_time).unwrap_or(0);
    let ts0 = Time::from_ns(t0);
    if !cfg.obstacles.is_empty() {
        let update = SceneUpdate {
            deletions: Vec::new(),
            entities: cfg
                .obstacles
                .iter()
                .enumerate()
                .map(|(i, o)| scene::obstacle_entity(ts0, i, o))
                .collect(),
        };
        out.write("/scene/obstacles", t0, &update)?;
    }
    if !cfg.vehicles.is_empty() {
        let update = SceneUpdate {
            deletions: Vec::new(),
            entities: cfg
                .vehicles
                .iter()
                .map(|v| scene::vehicle_entity(ts0, &cfg.look(v)))
                .collect(),
        };
        out.write("/scene/vehicles", t0, &update)?;
    }

    let bar = progress_bar(progress, order.len() as u64);
    let mut tracks: HashMap<String, Track> = HashMap::new();
    // Truth of the current time step, flushed as one /tf message.
    let mut tf_time: Option<u64> = None;
    let mut tf = FrameTransforms {
        transforms: Vec::new(),
    };
    let mut skipped = 0u64;
    for (n, i) in order.iter().enumerate() {
        if n % 4096 == 0 {
            bar.set_position(n as u64);
        }
        let m = &msgs[*i];
        let Some((vehicle, channel)) = routes.get(&m.channel) else {
            continue;
        };
        if tf_time.is_some_and(|t| t != m.log_time || *channel != Channel::Truth) {
            flush_tf(&mut out, &mut tf, &mut tf_time)?;
        }
        match channel {
            Channel::Truth => {
                let Some(s) = recordings::decode::<Truth>(&m.data) else {
                    skipped += 1;
                    continue;
                };
                let Some(pose) = true_pose(&s) else {
                    skipped += 1;
                    continue;
                };
                let t = s.header.sim_time_ns;
                let ts = Time::from_ns(t);
                if tf_time.is_none() {
                    tf_time = Some(m.log_time);
                    tf.transforms.push(frames::world_to_ned_transform(ts));
                }
                let p = [pose.position.x, pose.position.y, pose.position.z];
                tf.transforms.push(transform(
                    ts,
                    NED_FRAME,
                    body_frame(vehicle),
                    p,
                    &pose.attitude,
                ));
                let level = level_rotation(frames::yaw_of(&pose.attitude));
                tf.transforms
                    .push(transform(ts, NED_FRAME, level_frame(vehicle), p, &level));
                out.write(
                    &format!("/{vehicle}/pose"),
                    m.log_time,
                    &PoseInFrame {
                        timestamp: ts,
                        frame_id: NED_FRAME.to_string(),
                        pose: Pose {
                            position: foxglove::Vector3::from_array(p),
                            orientation: to_foxglove(&pose.attitude),
                        },
                    },
                )?;
                let track = tracks.entry(vehicle.clone()).or_default();
                track.times.push(t);
                track.poses.push(pose);
            }
            Channel::Sonar => {
                let Some(s) = recordings::decode::<Sonar>(&m.data) else {
                    skipped += 1;
                    continue;
                };
                let count = (s.count as usize).min(ipc_types::MAX_BEAMS);
                let beams: Vec<(f64, f64, Option<f64>)> = (0..count)
                    .filter(|b| s.azimuth_rad[*b].is_finite() && s.elevation_rad[*b].is_finite())
                    .map(|b| {
                        let r = s.ranges_m[b];
                        let echo = (s.valid[b] == 1 && r.is_finite() && r >= 0.0).then_some(r);
                        (s.azimuth_rad[b], s.elevation_rad[b], echo)
                    })
                    .collect();
                let scan = ScanView {
                    beams,
                    mount_body_m: cfg.sonar.mount_position_body_m,
                    range_max_m: cfg.sonar.range_max_m,
                };
                let t = Time::from_ns(s.header.origin_sim_time_ns);
                let update = SceneUpdate {
                    deletions: Vec::new(),
                    entities: vec![scene::sonar_entity(t, vehicle, &scan)],
                };
                out.write("/scene/sonar", m.log_time, &update)?;
            }
            Channel::Beacons => {
                let Some(parent) = cfg.parents.get(vehicle) else {
                    continue;
                };
                let Some(s) = recordings::decode::<Beacons>(&m.data) else {
                    skipped += 1;
                    continue;
                };
                let t = s.header.origin_sim_time_ns;
                let (Some(me), Some(them)) = (
                    tracks.get(vehicle).and_then(|k| k.at(t)),
                    tracks.get(parent).and_then(|k| k.at(t)),
                ) else {
                    continue;
                };
                let camera = me.body_to_ned(cfg.camera.mount_position_body_m);
                let count = (s.count as usize)
                    .min(cfg.beacons.positions_body_m.len())
                    .min(ipc_types::MAX_BEACONS);
                let beacons: Vec<(Vector3<f64>, bool)> = cfg.beacons.positions_body_m[..count]
                    .iter()
                    .zip(s.visible.iter())
                    .map(|(b, v)| (them.body_to_ned(*b), *v == 1))
                    .collect();
                let update = SceneUpdate {
                    deletions: Vec::new(),
                    entities: vec![scene::line_of_sight_entity(
                        Time::from_ns(t),
                        vehicle,
                        parent,
                        &camera,
                        &beacons,
                    )],
                };
                out.write("/scene/line_of_sight", m.log_time, &update)?;
            }
            Channel::PlannerState => {
                let Some(parent) = cfg.parents.get(vehicle) else {
                    continue;
                };
                let Some(s) = recordings::decode::<PlannerState>(&m.data) else {
                    skipped += 1;
                    continue;
                };
                if !(finite(&s.slot_filtered_m) && finite(&s.slot_nominal_m)) {
                    skipped += 1;
                    continue;
                }
                let t = s.header.sim_time_ns;
                let (Some(me), Some(them)) = (
                    tracks.get(vehicle).and_then(|k| k.at(t)),
                    tracks.get(parent).and_then(|k| k.at(t)),
                ) else {
                    continue;
                };
                let slot = SlotView {
                    filtered_m: s.slot_filtered_m,
                    nominal_m: s.slot_nominal_m,
                    avoiding: s.avoiding == 1,
                    parent_valid: s.parent_valid == 1,
                    mode: s.mode,
                };
                let update = SceneUpdate {
                    deletions: Vec::new(),
                    entities: vec![scene::slot_entity(
                        Time::from_ns(t),
                        vehicle,
                        parent,
                        &slot,
                        me,
                        them,
                    )],
                };
                out.write("/scene/slots", m.log_time, &update)?;
            }
            Channel::LeaderPose => {
                let Some(s) = recordings::decode::<LeaderPose>(&m.data) else {
                    skipped += 1;
                    continue;
                };
                if s.valid != 1 || !finite(&s.parent_position_body_m) {
                    continue;
                }
                let Some(q) = unit_wxyz(s.q_parent_to_body_wxyz) else {
                    continue;
                };
                out.write(
                    &format!("/{vehicle}/parent_estimate"),
                    m.log_time,
                    &PoseInFrame {
                        timestamp: Time::from_ns(s.header.origin_sim_time_ns),
                        frame_id: body_frame(vehicle),
                        pose: Pose {
                            position: foxglove::Vector3::from_array(s.parent_position_body_m),
                            orientation: to_foxglove(&q),
                        },
                    },
                )?;
            }
            _ => {}
        }
    }
    flush_tf(&mut out, &mut tf, &mut tf_time)?;
    bar.finish_and_clear();
    if skipped > 0 {
        notes.push(format!(
            "{skipped} samples skipped (wrong size or non-finite values)"
        ));
    }
    out.finish(notes)
}

fn flush_tf<W: std::io::Write + std::io::Seek>(
    out: &mut FoxgloveWriter<W>,
    tf: &mut FrameTransforms,
    tf_time: &mut Option<u64>,
) -> anyhow::Result<()> {
    if let Some(t) = tf_time.take() {
        out.write("/tf", t, tf)?;
        tf.transforms.clear();
    }
    Ok(())
}

fn progress_bar(progress: bool, len: u64) -> indicatif::ProgressBar {
    if !progress || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {bar:40.cyan/blue} {pos:>8}/{len} messages ({per_sec}, eta {eta})",
    ) {
        bar.set_style(style);
    }
    bar
}
