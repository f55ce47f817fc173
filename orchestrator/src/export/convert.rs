//! The conversion proper: every message the view uses, in time order, into
//! Foxglove's scene, transforms and poses (one method per channel).

use super::*;

/// Converts a loaded recording; writes the MCAP to `w`.
pub(super) fn export_foxglove<W: std::io::Write + std::io::Seek>(
    rec: &recordings::Recording,
    w: W,
    progress: bool,
    epoch_ns: u64,
) -> anyhow::Result<ExportReport> {
    let mut notes = Vec::new();
    let cfg = ViewConfig::from_recording(rec, &mut notes);
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

    let mut conv = Converter {
        cfg,
        out,
        tracks: HashMap::new(),
        tf_time: None,
        tf: FrameTransforms {
            transforms: Vec::new(),
        },
        skipped: 0,
    };
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
    if conv.skipped > 0 {
        notes.push(format!(
            "{} samples skipped (wrong size or non-finite values)",
            conv.skipped
        ));
    }
    conv.out.finish(notes)
}

/// The state of a conversion: the view, the output, every vehicle's true
/// poses so far, the transforms of the current time step.
struct Converter<W: std::io::Write + std::io::Seek> {
    cfg: ViewConfig,
    out: FoxgloveWriter<W>,
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

impl<W: std::io::Write + std::io::Seek> Converter<W> {
    /// A message's own timestamp for simulated time `ns`: shifted as the
    /// log times are.
    fn time(&self, ns: u64) -> Time {
        foxglove::time_from_ns(ns.saturating_add(self.out.epoch_ns))
    }

    /// The static scene (obstacles, vehicle models), at time `t0`.
    fn static_scene(&mut self, t0: u64) -> anyhow::Result<()> {
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
    fn message(
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
    fn flush_tf(&mut self) -> anyhow::Result<()> {
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
