//! Wiring of the sonar library to its channels.

use anyhow::Context;
use ipc_types::{Channel, Sample};
use nalgebra::Isometry3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shoal_runtime::convert::seed_for;
use shoal_runtime::{ChannelLimits, Publisher, Runtime, StepContext, Task, TaskError, WorldView};
use shoal_scenario::{ProcessKind, Scenario};
use sonar::{Obstacle, ObstacleField, Sonar, SonarConfig};

pub struct SonarTask {
    sonar: Sonar,
    field: ObstacleField,
    index: usize,
    rng: ChaCha8Rng,
    world: WorldView,
    out: Publisher<ipc_types::Sonar>,
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
            world: WorldView::open(
                rt,
                scenario.vehicles.len(),
                scenario.same_rate(ProcessKind::Sonar, ProcessKind::World),
            )?,
            out: rt.publisher(
                &ipc_types::service_name(run, me, Channel::Sonar),
                &ChannelLimits::vehicle(),
            )?,
            others: Vec::with_capacity(scenario.vehicles.len()),
        })
    }
}

impl Task for SonarTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let origin = self.world.refresh(ctx)?;
        let (Some(origin), Some(pose)) = (origin, self.world.pose(self.index)) else {
            return Ok(());
        };
        // The other hulls matter only if they echo.
        self.others.clear();
        if self.sonar.config().hulls_echo {
            for (i, v) in self.world.poses().iter().enumerate() {
                if i != self.index {
                    self.others.push(*v);
                }
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
