//! Wiring of the renderer to its channels: the run's `world` in, this
//! follower's `image` out, rendered in place into the loaned sample.
//!
//! This is a sensor simulator: it reads ground truth (every vehicle's pose
//! in the world snapshot), as the sonar does. What it publishes is only the
//! frame; camera-pose reads nothing else.

use anyhow::Context;
use camera_pose::{BeaconLayout, CameraConfig, HullConfig};
use camera_sim::{OpticsConfig, Renderer};
use ipc_types::Image;
use shoal_runtime::convert::seed_for;
use shoal_runtime::{ChannelLimits, Publisher, Runtime, StepContext, Task, TaskError, WorldView};
use shoal_scenario::{ProcessKind, Scenario};

pub struct CameraSimTask {
    renderer: Renderer,
    index: usize,
    parent: usize,
    seed: u64,
    frame: u32,
    world: WorldView,
    image_out: Publisher<Image>,
}

impl CameraSimTask {
    pub fn new(rt: &Runtime, scenario: &Scenario) -> anyhow::Result<Self> {
        let me = &rt.args().vehicle;
        let index = scenario
            .vehicle_index(me)
            .context("vehicle not in scenario")?;
        let parent = scenario
            .parent_index(index)
            .context("camera-sim runs on followers only, whose parent is in the scenario")?;
        let camera: CameraConfig = scenario.section("camera")?;
        let layout: BeaconLayout = scenario.section("beacons")?;
        let hull: HullConfig = scenario.section("hull")?;
        let optics: OpticsConfig = scenario.section("optics")?;
        let renderer = Renderer::new(&camera, &layout, &hull, &optics)?;
        tracing::info!(
            attenuation_per_m = renderer.attenuation_per_m(),
            visibility_range_m = camera.visibility_range_m,
            "water optics"
        );
        let run = &rt.args().run_id;
        Ok(Self {
            renderer,
            index,
            parent,
            seed: seed_for(scenario.seed, index, 4),
            frame: 0,
            world: WorldView::open(
                rt,
                scenario.vehicles.len(),
                scenario.same_rate(ProcessKind::CameraSim, ProcessKind::World),
            )?,
            image_out: rt.publisher(
                &ipc_types::image_service_name(run, me),
                &ChannelLimits::image(),
            )?,
        })
    }
}

impl Task for CameraSimTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let Some(origin) = self.world.refresh(ctx)? else {
            return Ok(());
        };
        let (width, height) = (self.renderer.width(), self.renderer.height());
        let seed = seed_for(self.seed, self.frame as usize, 0);
        let frame = self.frame;
        let (renderer, poses, own, parent) = (
            &mut self.renderer,
            self.world.poses(),
            self.index,
            self.parent,
        );
        let mut stats = camera_sim::FrameStats::default();
        self.image_out.publish_in_place(ctx, origin, |img| {
            img.width_px = width as u32;
            img.height_px = height as u32;
            img.step_bytes = width as u32;
            img.frame = frame;
            stats = renderer.render(
                poses,
                own,
                Some(parent),
                seed,
                &mut img.data[..width * height],
            );
        })?;
        tracing::trace!(
            frame,
            lamps = stats.lamps,
            parent_lamps = stats.target_lamps,
            saturated = stats.saturated,
            "frame"
        );
        self.frame = self.frame.wrapping_add(1);
        Ok(())
    }
}
