//! The world task: one subscriber per vehicle's truth, one snapshot out.

use ipc_types::{Channel, RunChannel, Sample, Truth, World};
use shoal_runtime::ports::Origin;
use shoal_runtime::{
    ChannelLimits, Publisher, Runtime, RuntimeError, StepContext, Subscriber, Task, TaskError,
};
use shoal_scenario::{ProcessKind, Scenario};

pub struct WorldTask {
    truths: Vec<Subscriber<Truth>>,
    out: Publisher<World>,
    snapshot: World,
    seen: Vec<bool>,
}

impl WorldTask {
    pub fn new(rt: &Runtime, scenario: &Scenario) -> Result<Self, RuntimeError> {
        let run = &rt.args().run_id;
        let mut truths = Vec::with_capacity(scenario.vehicles.len());
        for v in &scenario.vehicles {
            let name = ipc_types::service_name(run, &v.name, Channel::Truth);
            truths.push(rt.subscriber::<Truth>(&name, &ChannelLimits::vehicle(), 4)?);
            // Dataflow: the snapshot goes out once every vehicle's truth of
            // the frame is in (a dead plant's is waited for until the deadline).
            if scenario.same_rate(ProcessKind::World, ProcessKind::SimPlant) {
                rt.wake_on(&name, &ChannelLimits::vehicle())?;
            }
        }
        let out = rt.publisher::<World>(
            &ipc_types::run_service_name(run, RunChannel::World),
            &ChannelLimits::world(scenario.vehicles.len()),
        )?;
        let mut snapshot = World::zeroed();
        snapshot.count = scenario.vehicles.len() as u32;
        // Until a vehicle's first truth arrives, its pose is its start pose.
        for (i, v) in scenario.vehicles.iter().enumerate() {
            let (p, yaw) = scenario.start_poses()[&v.name];
            let s = &mut snapshot.vehicles[i];
            s.position_ned_m = p;
            s.q_body_to_ned_wxyz = [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()];
        }
        Ok(Self {
            seen: vec![false; truths.len()],
            truths,
            out,
            snapshot,
        })
    }
}

impl Task for WorldTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let mut origin = Origin::default();
        let mut stale = 0;
        for (i, sub) in self.truths.iter_mut().enumerate() {
            match sub.latest(ctx)? {
                Some(t) => {
                    let s = &mut self.snapshot.vehicles[i];
                    s.position_ned_m = t.position_ned_m;
                    s.q_body_to_ned_wxyz = t.q_body_to_ned_wxyz;
                    let q = t.q_body_to_ned_wxyz;
                    s.velocity_ned_mps = rotate(q, t.velocity_body_mps);
                    origin = origin.earliest(Origin::of(&t.header));
                    self.seen[i] = true;
                }
                None => stale += 1,
            }
        }
        self.snapshot.stale = stale;
        if origin.mono_ns == 0 {
            origin = Origin::here(ctx);
        }
        // Written where the sensors will read it: only what a run of n
        // vehicles uses (the rest of every chunk of this service stays
        // zero), not the whole 20 KB snapshot.
        let n = self.seen.len();
        let snapshot = &self.snapshot;
        self.out.publish_in_place(ctx, origin, |w| {
            w.count = snapshot.count;
            w.stale = snapshot.stale;
            w.vehicles[..n].copy_from_slice(&snapshot.vehicles[..n]);
        })?;
        Ok(())
    }
}

/// Rotates a body vector into NED with a `[w, x, y, z]` quaternion.
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [w, x, y, z] = q;
    // v' = v + 2w(u×v) + 2u×(u×v), u = (x, y, z)
    let u = [x, y, z];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let uv = cross(u, v);
    let uuv = cross(u, uv);
    [
        v[0] + 2.0 * (w * uv[0] + uuv[0]),
        v[1] + 2.0 * (w * uv[1] + uuv[1]),
        v[2] + 2.0 * (w * uv[2] + uuv[2]),
    ]
}

#[cfg(test)]
mod tests {
    use super::rotate;

    #[test]
    fn yaw_90_turns_forward_into_east() {
        let h = std::f64::consts::FRAC_PI_4;
        let v = rotate([h.cos(), 0.0, 0.0, h.sin()], [1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-12 && (v[1] - 1.0).abs() < 1e-12);
    }
}
