//! The conversion proper: every sample the view uses, in time order, into
//! Foxglove's scene, transforms and poses (one method per channel), written
//! to an [`Out`]: an MCAP file (`shoal export`) or a live server (`shoal
//! run --live`).

use std::collections::HashMap;

use ipc_types::{Beacons, Channel, LeaderPose, PlannerState, Sonar, Truth};
use nalgebra::Vector3;
use shoal_scenario::Scenario;

use crate::foxglove::{self, FoxgloveMessage, FrameTransforms, PoseInFrame, SceneUpdate, Time};
use crate::frames::{
    self, body_frame, level_frame, level_rotation, to_foxglove, transform, NED_FRAME,
};
use crate::scene::{self, ScanView, SlotView, TruePose, VehicleLook};
use crate::track::{unit_wxyz, Track};

/// Where the view's messages go.
pub trait Out {
    /// Writes `msg` on `topic` at simulated time `log_time_ns`.
    fn write<T: FoxgloveMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> anyhow::Result<()>;
    /// Added to every message's own timestamps (the run's wall-clock
    /// start with `--epoch`, else 0).
    fn epoch_ns(&self) -> u64;
}

/// The scenario facts the view draws, with the defaults of each service
/// where the recording has no scenario.
pub struct ViewConfig {
    /// Vehicle names in scenario (or topic) order.
    pub vehicles: Vec<String>,
    /// Follower → parent.
    pub parents: HashMap<String, String>,
    pub obstacles: Vec<sonar::Obstacle>,
    pub camera: camera_pose::CameraConfig,
    pub beacons: camera_pose::BeaconLayout,
    pub hull: camera_pose::HullConfig,
    pub sonar: sonar::SonarConfig,
}

impl ViewConfig {
    /// The view of `scenario` (defaults for what it cannot give, each
    /// named in `notes`); without one, the vehicles `without` lists and
    /// nothing else.
    pub fn from_scenario(
        scenario: Option<&Scenario>,
        without: impl FnOnce() -> Vec<String>,
        notes: &mut Vec<String>,
    ) -> Self {
        let Some(s) = scenario else {
            return Self {
                vehicles: without(),
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
            camera: section(s, "camera", notes),
            beacons: section(s, "beacons", notes),
            hull: section(s, "hull", notes),
            sonar: section(s, "sonar", notes),
        }
    }

    /// How vehicle `name` is drawn.
    pub fn look(&self, name: &str) -> VehicleLook {
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
pub fn parse_topic(topic: &str) -> Option<(&str, Channel)> {
    let rest = topic.strip_prefix('/')?;
    let (vehicle, name) = rest.split_once('/')?;
    Channel::ALL
        .into_iter()
        .find(|c| c.name() == name)
        .map(|c| (vehicle, c))
}

/// The true pose of `track` at its last sample at or before `t`.
fn pose_at(track: &Track, t: u64) -> Option<TruePose> {
    track.latest(t).map(|i| TruePose {
        position: track.p[i],
        attitude: track.q[i],
    })
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The state of a conversion: the view, the output, every vehicle's true
/// poses so far, the transforms of the current time step.
pub struct Converter<O: Out> {
    cfg: ViewConfig,
    /// Where the messages go.
    pub out: O,
    tracks: HashMap<String, Track>,
    /// Truth of the current time step, flushed as one /tf message.
    tf_time: Option<u64>,
    tf: FrameTransforms,
    /// Samples that could not be decoded or held non-finite values.
    skipped: u64,
}

/// What became of one message.
enum Done {
    /// Converted, or not shown (nothing to show it with yet).
    Used,
    /// Undecodable or non-finite.
    Skipped,
}

impl<O: Out> Converter<O> {
    /// A conversion of the view `cfg` into `out`, nothing seen yet.
    pub fn new(cfg: ViewConfig, out: O) -> Self {
        Self {
            cfg,
            out,
            tracks: HashMap::new(),
            tf_time: None,
            tf: FrameTransforms {
                transforms: Vec::new(),
            },
            skipped: 0,
        }
    }

    /// Samples that could not be decoded or held non-finite values.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Forgets every vehicle's poses older than `t_ns` (a live view keeps
    /// memory bounded; what needs a pose looks back at most a second).
    pub fn forget_before(&mut self, t_ns: u64) {
        for track in self.tracks.values_mut() {
            track.forget_before(t_ns);
        }
    }

    /// A message's own timestamp for simulated time `ns`: shifted as the
    /// log times are.
    fn time(&self, ns: u64) -> Time {
        foxglove::time_from_ns(ns.saturating_add(self.out.epoch_ns()))
    }

    /// The static scene (obstacles, vehicle models), at time `t0`.
    pub fn static_scene(&mut self, t0: u64) -> anyhow::Result<()> {
        let ts0 = self.time(t0);
        if !self.cfg.obstacles.is_empty() {
            let update = SceneUpdate {
                deletions: Vec::new(),
                entities: self
                    .cfg
                    .obstacles
                    .iter()
                    .enumerate()
                    .map(|(i, o)| scene::obstacle_entity(ts0, i, o))
                    .collect(),
            };
            self.out.write("/scene/obstacles", t0, &update)?;
        }
        if !self.cfg.vehicles.is_empty() {
            let update = SceneUpdate {
                deletions: Vec::new(),
                entities: self
                    .cfg
                    .vehicles
                    .iter()
                    .map(|v| scene::vehicle_entity(ts0, &self.cfg.look(v)))
                    .collect(),
            };
            self.out.write("/scene/vehicles", t0, &update)?;
        }
        Ok(())
    }

    /// Converts one message of `vehicle`'s `channel`.
    pub fn message(
        &mut self,
        vehicle: &str,
        channel: Channel,
        log_time: u64,
        data: &[u8],
    ) -> anyhow::Result<()> {
        if self
            .tf_time
            .is_some_and(|t| t != log_time || channel != Channel::Truth)
        {
            self.flush_tf()?;
        }
        let done = match channel {
            Channel::Truth => self.truth(vehicle, log_time, data)?,
            Channel::Sonar => self.sonar(vehicle, log_time, data)?,
            Channel::Beacons => self.beacons(vehicle, log_time, data)?,
            Channel::PlannerState => self.planner_state(vehicle, log_time, data)?,
            Channel::LeaderPose => self.leader_pose(vehicle, log_time, data)?,
            _ => Done::Used,
        };
        if let Done::Skipped = done {
            self.skipped += 1;
        }
        Ok(())
    }

    /// Writes the transforms of the current time step as one `/tf` message.
    pub fn flush_tf(&mut self) -> anyhow::Result<()> {
        if let Some(t) = self.tf_time.take() {
            self.out.write("/tf", t, &self.tf)?;
            self.tf.transforms.clear();
        }
        Ok(())
    }

    /// The true poses of `vehicle` and of `parent` at `t`.
    fn poses(&self, vehicle: &str, parent: &str, t: u64) -> Option<(TruePose, TruePose)> {
        Some((
            pose_at(self.tracks.get(vehicle)?, t)?,
            pose_at(self.tracks.get(parent)?, t)?,
        ))
    }

    /// A true pose: the vehicle's body and level frames on `/tf`, its pose.
    fn truth(&mut self, vehicle: &str, log_time: u64, data: &[u8]) -> anyhow::Result<Done> {
        let Some(s) = recordings::decode::<Truth>(data) else {
            return Ok(Done::Skipped);
        };
        let track = self
            .tracks
            .entry(vehicle.to_string())
            .or_insert_with(|| Track::new(vehicle));
        if !track.push(&s) {
            return Ok(Done::Skipped);
        }
        let Some(pose) = pose_at(track, s.header.sim_time_ns) else {
            return Ok(Done::Used);
        };
        let t = s.header.sim_time_ns;
        let ts = self.time(t);
        if self.tf_time.is_none() {
            self.tf_time = Some(log_time);
            self.tf.transforms.push(frames::world_to_ned_transform(ts));
        }
        let p = [pose.position.x, pose.position.y, pose.position.z];
        self.tf.transforms.push(transform(
            ts,
            NED_FRAME,
            body_frame(vehicle),
            p,
            &pose.attitude,
        ));
        let level = level_rotation(frames::yaw_of(&pose.attitude));
        self.tf
            .transforms
            .push(transform(ts, NED_FRAME, level_frame(vehicle), p, &level));
        self.out.write(
            &format!("/{vehicle}/pose"),
            log_time,
            &PoseInFrame {
                timestamp: Some(ts),
                frame_id: NED_FRAME.to_string(),
                pose: foxglove::pose(p, to_foxglove(&pose.attitude)),
            },
        )?;
        Ok(Done::Used)
    }

    /// A sonar scan: its beams and echoes.
    fn sonar(&mut self, vehicle: &str, log_time: u64, data: &[u8]) -> anyhow::Result<Done> {
        let Some(s) = recordings::decode::<Sonar>(data) else {
            return Ok(Done::Skipped);
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
            mount_body_m: self.cfg.sonar.mount_position_body_m,
            range_max_m: self.cfg.sonar.range_max_m,
        };
        let t = self.time(s.header.origin_sim_time_ns);
        let update = SceneUpdate {
            deletions: Vec::new(),
            entities: vec![scene::sonar_entity(t, vehicle, &scan)],
        };
        self.out.write("/scene/sonar", log_time, &update)?;
        Ok(Done::Used)
    }

    /// A camera frame's beacons: the lines of sight to the parent's lights.
    fn beacons(&mut self, vehicle: &str, log_time: u64, data: &[u8]) -> anyhow::Result<Done> {
        let Some(parent) = self.cfg.parents.get(vehicle).cloned() else {
            return Ok(Done::Used);
        };
        let Some(s) = recordings::decode::<Beacons>(data) else {
            return Ok(Done::Skipped);
        };
        let t = s.header.origin_sim_time_ns;
        let Some((me, them)) = self.poses(vehicle, &parent, t) else {
            return Ok(Done::Used);
        };
        let camera = me.body_to_ned(self.cfg.camera.mount_position_body_m);
        let count = (s.count as usize)
            .min(self.cfg.beacons.positions_body_m.len())
            .min(ipc_types::MAX_BEACONS);
        let beacons: Vec<(Vector3<f64>, bool)> = self.cfg.beacons.positions_body_m[..count]
            .iter()
            .zip(s.visible.iter())
            .map(|(b, v)| (them.body_to_ned(*b), *v == 1))
            .collect();
        let update = SceneUpdate {
            deletions: Vec::new(),
            entities: vec![scene::line_of_sight_entity(
                self.time(t),
                vehicle,
                &parent,
                &camera,
                &beacons,
            )],
        };
        self.out.write("/scene/line_of_sight", log_time, &update)?;
        Ok(Done::Used)
    }

    /// A planner state: the slot, filtered and nominal, and the follower.
    fn planner_state(&mut self, vehicle: &str, log_time: u64, data: &[u8]) -> anyhow::Result<Done> {
        let Some(parent) = self.cfg.parents.get(vehicle).cloned() else {
            return Ok(Done::Used);
        };
        let Some(s) = recordings::decode::<PlannerState>(data) else {
            return Ok(Done::Skipped);
        };
        if !(finite(&s.slot_filtered_m) && finite(&s.slot_nominal_m)) {
            return Ok(Done::Skipped);
        }
        let t = s.header.sim_time_ns;
        let Some((me, them)) = self.poses(vehicle, &parent, t) else {
            return Ok(Done::Used);
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
                self.time(t),
                vehicle,
                &parent,
                &slot,
                &me,
                &them,
            )],
        };
        self.out.write("/scene/slots", log_time, &update)?;
        Ok(Done::Used)
    }

    /// A parent estimate, in the follower's body frame.
    fn leader_pose(&mut self, vehicle: &str, log_time: u64, data: &[u8]) -> anyhow::Result<Done> {
        let Some(s) = recordings::decode::<LeaderPose>(data) else {
            return Ok(Done::Skipped);
        };
        if s.valid != 1 || !finite(&s.parent_position_body_m) {
            return Ok(Done::Used);
        }
        let Some(q) = unit_wxyz(s.q_parent_to_body_wxyz) else {
            return Ok(Done::Used);
        };
        self.out.write(
            &format!("/{vehicle}/parent_estimate"),
            log_time,
            &PoseInFrame {
                timestamp: Some(self.time(s.header.origin_sim_time_ns)),
                frame_id: body_frame(vehicle),
                pose: foxglove::pose(s.parent_position_body_m, to_foxglove(&q)),
            },
        )?;
        Ok(Done::Used)
    }
}
