//! Wiring of the camera and PnP library to its channels.
//!
//! The split is the perception rule: `observe` (simulation of the sensor)
//! is the only part that touches ground truth; `estimate` sees nothing but
//! the observation, exactly what goes out on `beacons`.
//!
//! The scenario's camera faults for this vehicle (`[[faults]]` with action
//! `blind` or `drop`, see `shoal_scenario::faults`) act here, by the step's
//! simulated time, in lockstep and in realtime alike:
//! - **blind**: the frame sees no beacon. `beacons` goes out with nothing
//!   visible and `leader_pose` invalid, exactly as a frame in which the
//!   parent is out of sight (the follower's planner counts it as a failed
//!   observation).
//! - **drop**: each frame is lost with probability `fraction`, drawn from
//!   the process's seeded RNG (so a lockstep run is reproduced exactly).
//!   A lost frame publishes nothing at all: no `beacons`, no `leader_pose`.
//!
//! With the acoustic-modem baseline the same faults hit the modem's packets:
//! blind loses every packet, drop each with probability `fraction`.

use anyhow::Context;
use nalgebra::Matrix6;

use camera_pose::acoustic::{AcousticConfig, Modem};
use camera_pose::{
    BeaconLayout, BeaconObservation, Camera, CameraConfig, Capsule, HullConfig, OcclusionZone,
    PoseConfig, PoseEstimator,
};
use camera_pose::{DetectConfig, Detector, Identifier, NoMatch, Prior};
use ipc_types::{Beacons, Channel, Image, LeaderPose, Sample};
use nalgebra::{Isometry3, Point3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shoal_runtime::convert::{arr, seed_for, wxyz};
use shoal_runtime::ports::Origin;
use shoal_runtime::{
    ChannelLimits, Publisher, Runtime, StepContext, Subscriber, Task, TaskError, WorldView,
};
use shoal_scenario::faults::{Fault, FaultAction};
use shoal_scenario::{ProcessKind, Scenario};

/// Where this follower's parent estimate comes from.
enum Source {
    /// The camera's point model and PnP: beacon pixels projected from the
    /// world snapshot, identities attached.
    Camera,
    /// The camera's image (`[camera] model = "image"`): blobs found and
    /// identified in this follower's own frame, then PnP. Reads nothing but
    /// the `image` channel.
    Image(Box<ImageSource>),
    /// The acoustic-modem baseline.
    Acoustic(Modem),
}

/// The image side of camera-pose: its frame, and what it keeps between frames.
struct ImageSource {
    image_in: Subscriber<Image>,
    detector: Detector,
    identifier: Identifier,
    /// The parent where the formation puts it (the nominal slot): the
    /// prediction when no recent fix is held.
    nominal: Isometry3<f64>,
    /// The last valid fix: simulated time, s, and the parent in the body frame.
    last_fix: Option<(f64, Isometry3<f64>)>,
    /// A fix this young is the previous frame's: tracking, s.
    track_for_s: f64,
}

/// A fix this young is the previous frame's (tracking), s: one and a half
/// frames at the default 10 Hz.
const TRACK_FOR_S: f64 = 0.15;

pub struct CameraTask {
    source: Source,
    camera: Camera,
    estimator: PoseEstimator,
    layout: BeaconLayout,
    hull: HullConfig,
    index: usize,
    parent: usize,
    rng: ChaCha8Rng,
    /// The world snapshot: read by the point model and the acoustic
    /// baseline only (their sensor simulation); never with images.
    world: Option<WorldView>,
    beacons_out: Publisher<Beacons>,
    pose_out: Publisher<LeaderPose>,
    occluders: Vec<Capsule>,
    /// The beacons' reach from the parent's body origin, m (for the
    /// occlusion zone; constant, so computed once).
    beacon_reach_m: f64,
    faults: CameraFaults,
}

impl CameraTask {
    pub fn new(rt: &Runtime, scenario: &Scenario) -> anyhow::Result<Self> {
        let me = &rt.args().vehicle;
        let index = scenario
            .vehicle_index(me)
            .context("vehicle not in scenario")?;
        let parent = scenario
            .parent_index(index)
            .context("camera-pose runs on followers only, whose parent is in the scenario")?;
        let cam_cfg: CameraConfig = scenario.section("camera")?;
        let layout: BeaconLayout = scenario.section("beacons")?;
        let pose_cfg: PoseConfig = scenario.section("pose")?;
        let hull: HullConfig = scenario.section("hull")?;
        let run = &rt.args().run_id;
        let lim = ChannelLimits::vehicle();
        let model = scenario.camera_model();
        let images = model == shoal_scenario::CameraModel::Image
            && scenario.method.perception == shoal_scenario::Perception::Camera;
        let source = match scenario.method.perception {
            shoal_scenario::Perception::Camera if model == shoal_scenario::CameraModel::Image => {
                let detect: DetectConfig = scenario.section("detect")?;
                let camera = Camera::new(&cam_cfg)?;
                let slot = scenario.vehicles[index].slot_m.unwrap_or([0.0; 3]);
                Source::Image(Box::new(ImageSource {
                    image_in: {
                        let name = ipc_types::image_service_name(run, me);
                        if scenario.same_rate(ProcessKind::CameraPose, ProcessKind::CameraSim) {
                            rt.wake_on(&name, &ChannelLimits::image())?;
                        }
                        rt.subscriber(&name, &ChannelLimits::image(), 2)?
                    },
                    detector: Detector::new(&detect)?,
                    identifier: Identifier::new(&detect, &layout, &camera, pose_cfg.min_beacons),
                    // The follower in its slot, heading as its parent: the
                    // parent is at −slot in the follower's body frame.
                    nominal: Isometry3::translation(-slot[0], -slot[1], -slot[2]),
                    last_fix: None,
                    track_for_s: TRACK_FOR_S,
                }))
            }
            shoal_scenario::Perception::Camera => Source::Camera,
            shoal_scenario::Perception::Acoustic => {
                let cfg: AcousticConfig = scenario.section("acoustic")?;
                // Stagger the parents' broadcasts so they do not all send at once.
                let first = (parent as f64 * 0.37) % cfg.period_s();
                Source::Acoustic(Modem::new(&cfg, first).map_err(anyhow::Error::msg)?)
            }
        };
        let beacon_reach_m = layout.reach_m();
        Ok(Self {
            source,
            camera: Camera::new(&cam_cfg)?,
            estimator: PoseEstimator::new(&pose_cfg, &cam_cfg, &layout)?,
            layout,
            hull,
            index,
            parent,
            rng: ChaCha8Rng::seed_from_u64(seed_for(scenario.seed, index, 3)),
            world: if images {
                None
            } else {
                // Acoustic fixes come from the modem's own clock, not from a frame.
                let framed = scenario.method.perception == shoal_scenario::Perception::Camera;
                Some(WorldView::open(
                    rt,
                    scenario.vehicles.len(),
                    framed && scenario.same_rate(ProcessKind::CameraPose, ProcessKind::World),
                )?)
            },
            beacons_out: rt.publisher(&ipc_types::service_name(run, me, Channel::Beacons), &lim)?,
            pose_out: rt.publisher(&ipc_types::service_name(run, me, Channel::LeaderPose), &lim)?,
            occluders: Vec::with_capacity(scenario.vehicles.len()),
            beacon_reach_m,
            faults: CameraFaults::new(&scenario.faults, me),
        })
    }

    /// The sensor: what the camera at `me` sees of the beacons of `parent`
    /// (its pose); the other vehicles of `world` may hide them.
    fn observe(
        &mut self,
        world: &WorldView,
        me: &Isometry3<f64>,
        parent: &Isometry3<f64>,
    ) -> BeaconObservation {
        // Only the hulls that can come between the camera and a beacon:
        // the zone needs positions, a hull in it its whole pose.
        let zone = OcclusionZone::new(
            Point3::from(self.camera.camera_in_world(me).translation.vector),
            Point3::from(parent.translation.vector),
            self.beacon_reach_m,
            self.hull.reach_m(),
        );
        self.occluders.clear();
        for (i, p) in world.positions().enumerate() {
            if i != self.index && i != self.parent && zone.may_hide(&p) {
                if let Some(v) = world.pose(i) {
                    self.occluders.push(self.hull.capsule(&v));
                }
            }
        }
        self.camera
            .observe(me, parent, &self.layout, &self.occluders, &mut self.rng)
    }
}

impl Task for CameraTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if matches!(self.source, Source::Image(_)) {
            return self.step_image(ctx);
        }
        let Some(mut world) = self.world.take() else {
            return Ok(());
        };
        let stepped = self.step_on(&mut world, ctx);
        self.world = Some(world);
        stepped
    }
}

impl CameraTask {
    /// A step of the point and acoustic models on `world`, the view that
    /// this task keeps (taken out of it while the step borrows the rest).
    fn step_on(&mut self, world: &mut WorldView, ctx: &StepContext) -> Result<(), TaskError> {
        let Some(origin) = world.refresh(ctx)? else {
            return Ok(());
        };
        let (Some(me), Some(parent)) = (world.pose(self.index), world.pose(self.parent)) else {
            return Ok(());
        };
        if let Source::Acoustic(modem) = &mut self.source {
            let truth = me.inverse() * parent;
            let now = shoal_runtime::mono_ns();
            let packet = modem.step(ctx.sim_time_s(), now, &truth, &mut self.rng);
            let cov = modem.covariance();
            // Decided only when a packet arrives: a fault loses packets, not silence.
            let packet = packet
                .filter(|_| self.faults.frame(ctx.sim_time_s(), &mut self.rng) == FrameFault::None);
            // A modem delivers packets, not frames: between packets there is
            // nothing to publish (an invalid sample would read as a failed
            // observation and break the follower's reacquisition streak).
            if let Some(p) = packet {
                let pose = pose_sample(true, 0, 0.0, 0, &p.parent_in_body, &cov);
                let origin = Origin {
                    mono_ns: p.sent_mono_ns,
                    sim_time_ns: (p.sent_s * 1e9).round() as u64,
                };
                self.pose_out.publish(pose, ctx, origin)?;
            }
            return Ok(());
        }
        let fault = self.faults.frame(ctx.sim_time_s(), &mut self.rng);
        if fault == FrameFault::Lost {
            // A lost frame: nothing was captured, so nothing is published.
            return Ok(());
        }
        let mut obs = self.observe(world, &me, &parent);
        if fault == FrameFault::Blind {
            // The beacons are there but the camera sees none of them.
            obs = BeaconObservation {
                count: obs.count,
                ..BeaconObservation::default()
            };
        }
        self.beacons_out
            .publish(beacons_sample(&obs), ctx, origin)?;

        // From here on only the observation is used.
        let est = self.estimator.estimate(&obs);
        self.publish_estimate(&est, true, ctx, origin)?;
        Ok(())
    }

    /// One frame of the image model: the newest frame of this follower's
    /// own camera, read in place; blobs; which are the parent's beacons;
    /// PnP. Nothing else is read.
    fn step_image(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let Source::Image(src) = &mut self.source else {
            return Ok(());
        };
        let now = ctx.sim_time_s();
        // The last fix predicts where the parent is, the better the younger
        // (the formation holds it about there); the nominal slot only
        // before the first fix.
        let prior = match src.last_fix {
            Some((t, p)) if now - t <= src.track_for_s => (p, Prior::Tracking),
            Some((t, p)) => (p, Prior::Aged { age_s: now - t }),
            None => (src.nominal, Prior::Nominal),
        };
        let (detector, identifier) = (&mut src.detector, &src.identifier);
        let found = src.image_in.with_latest_in_place(ctx, |img| {
            let (w, h) = (img.width_px as usize, img.height_px as usize);
            let blobs = detector.detect(img.pixels(), w, h);
            let id = identifier.identify(blobs, &prior.0, prior.1);
            (id, blobs.len(), Origin::of(&img.header))
        })?;
        let Some((id, blobs, origin)) = found else {
            return Ok(());
        };
        let fault = self.faults.frame(now, &mut self.rng);
        if fault == FrameFault::Lost {
            return Ok(());
        }
        let mut obs = id.observation;
        let mut status = match id.failure {
            None => 0,
            Some(NoMatch::NotInView) => 1,
            Some(NoMatch::TooFew) => 2,
            Some(NoMatch::Ambiguous) => 3,
        };
        if fault == FrameFault::Blind {
            obs = BeaconObservation {
                count: obs.count,
                ..BeaconObservation::default()
            };
            status = 2;
        }
        let mut b = beacons_sample(&obs);
        b.blobs = if fault == FrameFault::Blind {
            0
        } else {
            blobs as u32
        };
        b.identification = status;
        self.beacons_out.publish(b, ctx, origin)?;
        // A fix that jumps farther from the last one than the parent can
        // move is another vehicle's lamps: no fix this frame.
        let last = src_last_fix(&self.source);
        let plausible = |fix: &Isometry3<f64>| match (&self.source, last) {
            (Source::Image(src), Some((t, p))) => {
                src.identifier
                    .plausible(&p.translation.vector, &fix.translation.vector, now - t)
            }
            _ => true,
        };
        // The identifier's runners-up are judged by the pose solver (none
        // after a blinding fault).
        let others = if fault == FrameFault::Blind {
            &id.runners_up[..0]
        } else {
            &id.runners_up[..id.runners_up_count]
        };
        let est = self.estimator.estimate_among(&obs, others);
        let plausible = !est.valid || plausible(&est.parent_in_body);
        if !plausible {
            tracing::debug!(t_s = now, "fix refused: too far from the last one");
            self.estimator.reset();
        }
        if self.publish_estimate(&est, plausible, ctx, origin)? {
            if let Source::Image(src) = &mut self.source {
                src.last_fix = Some((now, est.parent_in_body));
            }
        }
        Ok(())
    }

    /// Publishes `leader_pose` for an estimate: the fix when it is valid
    /// and `accept`ed, else "no fix" (never a wild guess: a non-finite fit
    /// is an invalid one). Returns whether a fix went out.
    fn publish_estimate(
        &mut self,
        est: &camera_pose::PoseEstimate,
        accept: bool,
        ctx: &StepContext,
        origin: Origin,
    ) -> Result<bool, TaskError> {
        let p = if est.valid && accept {
            pose_sample(
                true,
                est.beacons_used,
                est.reprojection_rms_px,
                est.iterations,
                &est.parent_in_body,
                &est.covariance,
            )
        } else {
            let mut p = invalid_pose(est.beacons_used);
            p.iterations = est.iterations;
            p.reprojection_rms_px = est.reprojection_rms_px;
            p
        };
        let p = if p.is_finite() {
            p
        } else {
            invalid_pose(est.beacons_used)
        };
        self.pose_out.publish(p, ctx, origin)?;
        Ok(p.valid == 1)
    }
}

/// The image source's last fix, if any.
fn src_last_fix(source: &Source) -> Option<(f64, Isometry3<f64>)> {
    match source {
        Source::Image(src) => src.last_fix,
        _ => None,
    }
}

/// The `beacons` sample of an observation: each beacon's pixel and
/// whether it was seen.
fn beacons_sample(obs: &BeaconObservation) -> Beacons {
    let mut b = Beacons::zeroed();
    for i in 0..obs.count.min(ipc_types::MAX_BEACONS) {
        b.pixels_uv[2 * i] = obs.pixels[i][0];
        b.pixels_uv[2 * i + 1] = obs.pixels[i][1];
        b.visible[i] = u8::from(obs.visible[i]);
    }
    b.count = obs.count as u32;
    b.visible_count = obs.visible_count() as u32;
    b
}

/// A `leader_pose` sample for a fix.
fn pose_sample(
    valid: bool,
    beacons_used: usize,
    reprojection_rms_px: f64,
    iterations: u32,
    parent_in_body: &nalgebra::Isometry3<f64>,
    covariance: &Matrix6<f64>,
) -> LeaderPose {
    let mut p = LeaderPose::zeroed();
    p.valid = u8::from(valid);
    p.beacons_used = beacons_used.min(255) as u8;
    p.iterations = iterations;
    p.reprojection_rms_px = reprojection_rms_px;
    p.parent_position_body_m = arr(&parent_in_body.translation.vector);
    p.q_parent_to_body_wxyz = wxyz(&parent_in_body.rotation);
    let follower = camera_pose::follower_in_parent(parent_in_body);
    p.follower_in_parent_m = arr(&follower);
    for r in 0..6 {
        for c in 0..6 {
            p.covariance[6 * r + c] = covariance[(r, c)];
        }
    }
    p
}

/// A `leader_pose` that says "no fix this frame".
fn invalid_pose(beacons_used: usize) -> LeaderPose {
    let mut p = LeaderPose::zeroed();
    p.q_parent_to_body_wxyz = [1.0, 0.0, 0.0, 0.0];
    p.beacons_used = beacons_used.min(255) as u8;
    p
}

/// What a camera fault does to one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FrameFault {
    /// No fault: the frame is taken as usual.
    None,
    /// The frame sees no beacon (a blind window).
    Blind,
    /// The frame is lost (a drop window): nothing is published.
    Lost,
}

/// One `blind` or `drop` window of this vehicle's camera.
#[derive(Debug, Clone)]
struct FaultWindow {
    /// The scenario's entry (action, `from_s`, `to_s`, `fraction`).
    fault: Fault,
    /// Its index in `[[faults]]`, for the log.
    index: usize,
    /// Whether the previous frame was inside the window (to log its edges).
    active: bool,
}

/// The scenario's camera faults of one vehicle, decided frame by frame.
///
/// Windows are `[from_s, to_s)` of simulated time. When a blind and a drop
/// window overlap, the drop is drawn first: a lost frame is lost whether or
/// not the camera would have seen anything. The RNG is drawn once per frame
/// inside a drop window and never outside one, so a run without faults
/// keeps its random sequence.
#[derive(Debug, Clone)]
struct CameraFaults {
    vehicle: String,
    windows: Vec<FaultWindow>,
}

impl CameraFaults {
    /// The `blind` and `drop` entries of `faults` that name `vehicle`.
    fn new(faults: &[Fault], vehicle: &str) -> Self {
        let windows: Vec<FaultWindow> = faults
            .iter()
            .enumerate()
            .filter(|(_, f)| {
                matches!(f.action, FaultAction::Blind | FaultAction::Drop) && f.vehicle == vehicle
            })
            .map(|(index, f)| FaultWindow {
                fault: f.clone(),
                index,
                active: false,
            })
            .collect();
        for w in &windows {
            tracing::info!(
                fault = w.index,
                action = ?w.fault.action,
                from_s = w.fault.from_s,
                to_s = w.fault.to_s,
                fraction = w.fault.fraction,
                "camera fault scheduled"
            );
        }
        Self {
            vehicle: vehicle.to_string(),
            windows,
        }
    }

    /// The fault of the frame taken at `t_s` (simulated time), logging each
    /// window as the first frame inside it and the first frame after it
    /// arrive.
    fn frame<R: rand::Rng>(&mut self, t_s: f64, rng: &mut R) -> FrameFault {
        let mut lost = false;
        let mut blind = false;
        for w in &mut self.windows {
            let active = w.fault.camera_active(&self.vehicle, t_s);
            if active != w.active {
                w.active = active;
                if active {
                    tracing::info!(fault = w.index, action = ?w.fault.action, t_s, "camera fault starts");
                } else {
                    tracing::info!(fault = w.index, action = ?w.fault.action, t_s, "camera fault ends");
                }
            }
            if !active {
                continue;
            }
            match w.fault.action {
                FaultAction::Drop => {
                    let p = w.fault.fraction.unwrap_or(0.0);
                    // One draw per drop window per frame, whatever the outcome.
                    if rng.random::<f64>() < p {
                        lost = true;
                    }
                }
                FaultAction::Blind => blind = true,
                FaultAction::Kill | FaultAction::Stall => {}
            }
        }
        if lost {
            FrameFault::Lost
        } else if blind {
            FrameFault::Blind
        } else {
            FrameFault::None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    fn fault(action: FaultAction, vehicle: &str, from_s: f64, to_s: f64, p: f64) -> Fault {
        Fault {
            action,
            vehicle: vehicle.into(),
            process: None,
            at_s: None,
            duration_s: None,
            from_s: Some(from_s),
            to_s: Some(to_s),
            fraction: (action == FaultAction::Drop).then_some(p),
        }
    }

    fn rng() -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(7)
    }

    #[test]
    fn blind_window_covers_from_inclusive_to_exclusive() {
        let mut f = CameraFaults::new(&[fault(FaultAction::Blind, "F4", 60.0, 70.0, 0.0)], "F4");
        let mut r = rng();
        assert_eq!(f.frame(59.9, &mut r), FrameFault::None);
        assert_eq!(f.frame(60.0, &mut r), FrameFault::Blind);
        assert_eq!(f.frame(65.0, &mut r), FrameFault::Blind);
        assert_eq!(f.frame(69.9, &mut r), FrameFault::Blind);
        assert_eq!(f.frame(70.0, &mut r), FrameFault::None);
        assert_eq!(f.frame(80.0, &mut r), FrameFault::None);
    }

    #[test]
    fn faults_of_other_vehicles_and_processes_are_ignored() {
        let kill = Fault {
            action: FaultAction::Kill,
            vehicle: "F4".into(),
            process: Some("camera-pose".into()),
            at_s: Some(1.0),
            duration_s: None,
            from_s: None,
            to_s: None,
            fraction: None,
        };
        let mut f = CameraFaults::new(
            &[
                fault(FaultAction::Blind, "F3", 0.0, 100.0, 0.0),
                fault(FaultAction::Drop, "F2", 0.0, 100.0, 1.0),
                kill,
            ],
            "F4",
        );
        assert!(f.windows.is_empty());
        let mut r = rng();
        for i in 0..100 {
            assert_eq!(f.frame(f64::from(i), &mut r), FrameFault::None);
        }
    }

    #[test]
    fn drop_loses_about_fraction_of_the_frames_and_nothing_outside() {
        let p = 0.3;
        let mut f = CameraFaults::new(&[fault(FaultAction::Drop, "F2", 50.0, 1050.0, p)], "F2");
        let mut r = rng();
        // 10 000 frames at 10 Hz inside the window.
        let n = 10_000;
        let lost = (0..n)
            .filter(|i| f.frame(50.0 + f64::from(*i) * 0.1, &mut r) == FrameFault::Lost)
            .count();
        let share = lost as f64 / f64::from(n);
        // Binomial: σ = sqrt(p(1−p)/n) ≈ 0.0046; 5σ.
        let sigma = (p * (1.0 - p) / f64::from(n)).sqrt();
        assert!((share - p).abs() < 5.0 * sigma, "lost {share}");
        // Outside the window nothing is lost, and the RNG is not drawn.
        let mut before = rng();
        let mut probe = rng();
        assert_eq!(f.frame(49.9, &mut before), FrameFault::None);
        assert_eq!(f.frame(1050.0, &mut before), FrameFault::None);
        assert_eq!(before.random::<u64>(), probe.random::<u64>());
    }

    #[test]
    fn drop_decisions_repeat_with_the_same_seed() {
        let run = || {
            let mut f = CameraFaults::new(&[fault(FaultAction::Drop, "F2", 0.0, 10.0, 0.5)], "F2");
            let mut r = rng();
            (0..100)
                .map(|i| f.frame(f64::from(i) * 0.1, &mut r))
                .collect::<Vec<_>>()
        };
        let a = run();
        assert_eq!(a, run());
        assert!(a.contains(&FrameFault::Lost) && a.contains(&FrameFault::None));
    }

    #[test]
    fn drop_fractions_zero_and_one_are_exact() {
        let mut r = rng();
        let mut never = CameraFaults::new(&[fault(FaultAction::Drop, "F1", 0.0, 10.0, 0.0)], "F1");
        let mut always = CameraFaults::new(&[fault(FaultAction::Drop, "F1", 0.0, 10.0, 1.0)], "F1");
        for i in 0..100 {
            let t = f64::from(i) * 0.1;
            assert_eq!(never.frame(t, &mut r), FrameFault::None);
            assert_eq!(always.frame(t, &mut r), FrameFault::Lost);
        }
    }

    #[test]
    fn a_lost_frame_wins_over_a_blind_one_where_windows_overlap() {
        let mut f = CameraFaults::new(
            &[
                fault(FaultAction::Blind, "F1", 0.0, 10.0, 0.0),
                fault(FaultAction::Drop, "F1", 5.0, 10.0, 1.0),
            ],
            "F1",
        );
        let mut r = rng();
        assert_eq!(f.frame(1.0, &mut r), FrameFault::Blind);
        assert_eq!(f.frame(5.0, &mut r), FrameFault::Lost);
        assert!(f.windows.iter().all(|w| w.active));
        assert_eq!(f.frame(10.0, &mut r), FrameFault::None);
        assert!(f.windows.iter().all(|w| !w.active));
    }
}
