//! Wiring of the sonar library to its channels.

use anyhow::Context;
use ipc_types::{Channel, RunChannel, Sample, World};
use nalgebra::Isometry3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shoal_runtime::convert::{seed_for, world_poses};
use shoal_runtime::ports::Origin;
use shoal_runtime::{ChannelLimits, Publisher, Runtime, StepContext, Subscriber, Task, TaskError};
use shoal_scenario::Scenario;
use sonar::{Obstacle, ObstacleField, Sonar, SonarConfig};

pub struct SonarTask {
    sonar: Sonar,
    field: ObstacleField,
    index: usize,
    rng: ChaCha8Rng,
    world_in: Subscriber<World>,
    out: Publisher<ipc_types::Sonar>,
    /// Every vehicle's pose in the newest world snapshot, read in place.
    poses: Vec<Isometry3<f64>>,
    /// The snapshot's origin; `None` until the first one.
    world_origin: Option<Origin>,
    others: Vec<Isometry3<f64>>,
}

impl SonarTask {
    pub fn new(rt: &Runtime, scenario: &Scenario) -> anyhow::Result<Self> {
        let me = &rt.args().vehicle;
        let index = scenario
            .vehicle_index(me)
            .context("vehicle not in scenario")?;
        let cfg: SonarConfig = scenario.section("sonar")?;
        let obstacles: Vec<Obstacle> = scenario.obstacles_as()?;
        let run = &rt.args().run_id;
        Ok(Self {
            sonar: Sonar::new(&cfg)?,
            field: ObstacleField::new(&obstacles)?,
            index,
            rng: ChaCha8Rng::seed_from_u64(seed_for(scenario.seed, index, 2)),
            world_in: rt.subscriber(
                &ipc_types::run_service_name(run, RunChannel::World),
                &ChannelLimits::world(scenario.vehicles.len()),
                2,
            )?,
            out: rt.publisher(
                &ipc_types::service_name(run, me, Channel::Sonar),
                &ChannelLimits::vehicle(),
            )?,
            poses: Vec::with_capacity(scenario.vehicles.len()),
            world_origin: None,
            others: Vec::with_capacity(scenario.vehicles.len()),
        })
    }
}

impl Task for SonarTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let poses = &mut self.poses;
        let fresh = self.world_in.with_latest_in_place(ctx, |w| {
            world_poses(w, poses);
            Origin::of(&w.header)
        })?;
        if fresh.is_some() {
            self.world_origin = fresh;
        }
        let (Some(origin), Some(&pose)) = (self.world_origin, self.poses.get(self.index)) else {
            return Ok(());
        };
        self.others.clear();
        for (i, v) in self.poses.iter().enumerate() {
            if i != self.index {
                self.others.push(*v);
            }
        }
        let scan = self
            .sonar
            .scan(&self.field, &pose, &self.others, &mut self.rng);
        let mut s = ipc_types::Sonar::zeroed();
        scan.write_to(&mut s);
        self.out.publish(s, ctx, origin)?;
        Ok(())
    }
}
