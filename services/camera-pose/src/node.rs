//! Wiring of the camera and PnP library to its channels.
//!
//! The split is the perception rule: `observe` (simulation of the sensor)
//! is the only part that touches ground truth; `estimate` sees nothing but
//! the observation, exactly what goes out on `beacons`.

use anyhow::Context;
use nalgebra::Matrix6;

use camera_pose::acoustic::{AcousticConfig, Modem};
use camera_pose::{
    BeaconLayout, BeaconObservation, Camera, CameraConfig, Capsule, HullConfig, PoseConfig,
    PoseEstimator,
};
use ipc_types::{Beacons, Channel, LeaderPose, RunChannel, Sample, World};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shoal_runtime::convert::{arr, seed_for, world_pose, wxyz};
use shoal_runtime::ports::Origin;
use shoal_runtime::{ChannelLimits, Publisher, Runtime, StepContext, Subscriber, Task, TaskError};
use shoal_scenario::Scenario;

/// Where this follower's parent estimate comes from.
enum Source {
    /// The camera and PnP (the paper's method).
    Camera,
    /// The acoustic-modem baseline.
    Acoustic(Modem),
}

pub struct CameraTask {
    source: Source,
    camera: Camera,
    estimator: PoseEstimator,
    layout: BeaconLayout,
    hull: HullConfig,
    index: usize,
    parent: usize,
    rng: ChaCha8Rng,
    world_in: Subscriber<World>,
    beacons_out: Publisher<Beacons>,
    pose_out: Publisher<LeaderPose>,
    world: Option<World>,
    occluders: Vec<Capsule>,
}

impl CameraTask {
    pub fn new(rt: &Runtime, scenario: &Scenario) -> anyhow::Result<Self> {
        let me = &rt.args().vehicle;
        let index = scenario
            .vehicle_index(me)
            .context("vehicle not in scenario")?;
        let parent_name = scenario.vehicles[index]
            .parent
            .as_ref()
            .context("camera-pose runs on followers only")?;
        let parent = scenario
            .vehicle_index(parent_name)
            .context("parent not in scenario")?;
        let cam_cfg: CameraConfig = scenario.section("camera")?;
        let layout: BeaconLayout = scenario.section("beacons")?;
        let pose_cfg: PoseConfig = scenario.section("pose")?;
        let hull: HullConfig = scenario.section("hull")?;
        let run = &rt.args().run_id;
        let lim = ChannelLimits::vehicle();
        let source = match scenario.method.perception {
            shoal_scenario::Perception::Camera => Source::Camera,
            shoal_scenario::Perception::Acoustic => {
                let cfg: AcousticConfig = scenario.section("acoustic")?;
                // Stagger the parents' broadcasts so they do not all send at once.
                let first = (parent as f64 * 0.37) % cfg.period_s();
                Source::Acoustic(Modem::new(&cfg, first).map_err(anyhow::Error::msg)?)
            }
        };
        Ok(Self {
            source,
            camera: Camera::new(&cam_cfg)?,
            estimator: PoseEstimator::new(&pose_cfg, &cam_cfg, &layout)?,
            layout,
            hull,
            index,
            parent,
            rng: ChaCha8Rng::seed_from_u64(seed_for(scenario.seed, index, 3)),
            world_in: rt.subscriber(
                &ipc_types::run_service_name(run, RunChannel::World),
                &ChannelLimits::world(scenario.vehicles.len()),
                2,
            )?,
            beacons_out: rt.publisher(&ipc_types::service_name(run, me, Channel::Beacons), &lim)?,
            pose_out: rt.publisher(&ipc_types::service_name(run, me, Channel::LeaderPose), &lim)?,
            world: None,
            occluders: Vec::with_capacity(scenario.vehicles.len()),
        })
    }

    /// The sensor: what the camera sees of the parent's beacons.
    fn observe(&mut self, w: &World) -> BeaconObservation {
        let me = world_pose(&w.vehicles[self.index]);
        let parent = world_pose(&w.vehicles[self.parent]);
        self.occluders.clear();
        for (i, v) in w.vehicles[..w.count as usize].iter().enumerate() {
            if i != self.index && i != self.parent {
                self.occluders.push(self.hull.capsule(&world_pose(v)));
            }
        }
        self.camera
            .observe(&me, &parent, &self.layout, &self.occluders, &mut self.rng)
    }
}

impl Task for CameraTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(w) = self.world_in.latest(ctx)? {
            self.world = Some(w);
        }
        let Some(w) = self.world else {
            return Ok(());
        };
        if let Source::Acoustic(modem) = &mut self.source {
            let me = world_pose(&w.vehicles[self.index]);
            let parent = world_pose(&w.vehicles[self.parent]);
            let truth = me.inverse() * parent;
            let now = shoal_runtime::mono_ns();
            let packet = modem.step(ctx.sim_time_s(), now, &truth, &mut self.rng);
            let cov = modem.covariance();
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
        let obs = self.observe(&w);
        let origin = Origin::of(&w.header);
        let mut b = Beacons::zeroed();
        for i in 0..obs.count.min(ipc_types::MAX_BEACONS) {
            b.pixels_uv[2 * i] = obs.pixels[i][0];
            b.pixels_uv[2 * i + 1] = obs.pixels[i][1];
            b.visible[i] = u8::from(obs.visible[i]);
        }
        b.count = obs.count as u32;
        b.visible_count = obs.visible_count() as u32;
        self.beacons_out.publish(b, ctx, origin)?;

        // From here on only the observation is used.
        let est = self.estimator.estimate(&obs);
        let p = if est.valid {
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
        // Never publish a wild guess: a non-finite fit is an invalid one.
        let p = if p.is_finite() {
            p
        } else {
            invalid_pose(est.beacons_used)
        };
        self.pose_out.publish(p, ctx, origin)?;
        Ok(())
    }
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
