//! What a sensor simulator keeps of the run's `world` snapshot: every
//! vehicle's pose, read out of shared memory in place (the sample is
//! 20 KB; copying it out whole every step was the sonar's largest cost), of
//! which only the vehicles present are copied.

use ipc_types::{VehiclePose, World};
use nalgebra::{Isometry3, Point3};

use crate::convert::world_pose;
use crate::ports::Origin;
use crate::{ChannelLimits, Runtime, RuntimeError, StepContext, Subscriber};

/// The newest world snapshot's poses and origin.
///
/// A refresh copies the snapshot's poses as they are; each is turned into
/// an [`Isometry3`] only when asked for. A sensor mostly needs its own pose,
/// its parent's and the positions of the rest (the camera's occlusion zone),
/// so converting all N at every refresh was work that grew with the group
/// in every sensor process.
pub struct WorldView {
    sub: Subscriber<World>,
    raw: Vec<VehiclePose>,
    /// Every pose converted, once asked for ([`WorldView::poses`]).
    poses: Vec<Isometry3<f64>>,
    converted: bool,
    origin: Option<Origin>,
}

impl WorldView {
    /// A view fed by `sub` (the run's `world` channel).
    pub fn new(sub: Subscriber<World>) -> Self {
        Self {
            sub,
            raw: Vec::new(),
            poses: Vec::new(),
            converted: true,
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
        let raw = &mut self.raw;
        let fresh = self.sub.with_latest_in_place(ctx, |w| {
            raw.clear();
            raw.extend_from_slice(w.poses());
            Origin::of(&w.header)
        })?;
        if fresh.is_some() {
            self.origin = fresh;
            self.converted = false;
        }
        Ok(self.origin)
    }

    /// How many vehicles the snapshot holds.
    pub fn len(&self) -> usize {
        self.raw.len()
    }

    /// True before the first snapshot.
    pub fn is_empty(&self) -> bool {
        self.raw.is_empty()
    }

    /// Vehicle `i`'s pose (body → NED), in scenario order.
    pub fn pose(&self, i: usize) -> Option<Isometry3<f64>> {
        self.raw.get(i).map(world_pose)
    }

    /// Every vehicle's position, NED, in scenario order: the translation of
    /// its [`WorldView::pose`], without the attitude.
    pub fn positions(&self) -> impl ExactSizeIterator<Item = Point3<f64>> + '_ {
        self.raw.iter().map(|v| Point3::from(v.position_ned_m))
    }

    /// Every vehicle's pose (body → NED), in scenario order, converted once
    /// per snapshot.
    pub fn poses(&mut self) -> &[Isometry3<f64>] {
        if !self.converted {
            self.poses.clear();
            self.poses.extend(self.raw.iter().map(world_pose));
            self.converted = true;
        }
        &self.poses
    }
}
