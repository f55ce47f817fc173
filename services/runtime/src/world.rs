//! What a sensor simulator keeps of the run's `world` snapshot: every
//! vehicle's pose, read out of shared memory in place (the snapshot is
//! 20 KB; copying it out every step was the sonar's largest cost).

use ipc_types::World;
use nalgebra::Isometry3;

use crate::convert::world_pose;
use crate::ports::Origin;
use crate::{ChannelLimits, Runtime, RuntimeError, StepContext, Subscriber};

/// The newest world snapshot's poses and origin.
pub struct WorldView {
    sub: Subscriber<World>,
    poses: Vec<Isometry3<f64>>,
    origin: Option<Origin>,
}

impl WorldView {
    /// A view fed by `sub` (the run's `world` channel).
    pub fn new(sub: Subscriber<World>) -> Self {
        Self {
            sub,
            poses: Vec::new(),
            origin: None,
        }
    }

    /// Subscribes `rt` to the run's `world` channel (a run of `vehicles`);
    /// with `triggered`, a dataflow run steps the process on each snapshot
    /// ([`Runtime::wake_on`]).
    pub fn open(rt: &Runtime, vehicles: usize, triggered: bool) -> Result<Self, RuntimeError> {
        let name = ipc_types::run_service_name(&rt.args().run_id, ipc_types::RunChannel::World);
        let limits = ChannelLimits::world(vehicles);
        let sub = rt.subscriber(&name, &limits, 2)?;
        if triggered {
            rt.wake_on(&name, &limits)?;
        }
        Ok(Self::new(sub))
    }

    /// Reads the newest ready snapshot, if one arrived, where it lies;
    /// returns the origin of the newest snapshot seen so far (`None` before
    /// the first).
    pub fn refresh(&mut self, ctx: &StepContext) -> Result<Option<Origin>, RuntimeError> {
        let poses = &mut self.poses;
        let fresh = self.sub.with_latest_in_place(ctx, |w| {
            poses.clear();
            poses.extend(w.poses().iter().map(world_pose));
            Origin::of(&w.header)
        })?;
        if fresh.is_some() {
            self.origin = fresh;
        }
        Ok(self.origin)
    }

    /// Every vehicle's pose (body → NED), in scenario order.
    pub fn poses(&self) -> &[Isometry3<f64>] {
        &self.poses
    }
}
