//! Wiring of the predictive controller to its channels.

use crate::{Keepout, Mpc, MpcConfig, MpcInput, MpcTarget};
use ipc_types::{Channel, MpcStats, Nav, Sample, Setpoint, Thrust};
use nalgebra::{Vector3, Vector6};
use shoal_runtime::convert::quat;
use shoal_runtime::ports::Origin;
use shoal_runtime::{
    ChannelLimits, Publisher, Runtime, Service, StepContext, Subscriber, Task, TaskError,
};
use shoal_scenario::{ProcessKind, Scenario};
use sim_plant::model::Vehicle;
use sim_plant::PlantConfig;

/// The mpc process's task: its vehicle's `nav` and `setpoint` in; `thrust`
/// and `mpc_stats` out; over iceoryx2 service kind `S` (shared memory in the
/// binary).
pub struct MpcTask<S: Service = shoal_runtime::ipc::Service> {
    mpc: Mpc,
    thrust_max: [f64; 6],
    nav_in: Subscriber<Nav, S>,
    setpoint_in: Subscriber<Setpoint, S>,
    thrust_out: Publisher<Thrust, S>,
    stats_out: Publisher<MpcStats, S>,
    nav: Option<Nav>,
    setpoint: Option<Setpoint>,
    failures: u64,
}

impl<S: Service> MpcTask<S> {
    /// Opens the vehicle's ports on `rt` and builds its controller from the
    /// scenario (step from the mpc rate, bounds from the plant).
    pub fn new(rt: &Runtime<S>, scenario: &Scenario) -> anyhow::Result<Self> {
        let me = &rt.args().vehicle;
        let plant: PlantConfig = scenario.section("plant")?;
        let mut cfg: MpcConfig = scenario.section("mpc")?;
        // One source of truth: the control period is the process's rate and
        // the bounds are the plant's saturation.
        cfg.step_s = 1.0 / scenario.rates.mpc_hz;
        cfg.thrust_max = plant.thrust_max;
        // The safety layer keeps the run's safe distance; it is beyond the paper, so the
        // method as published flies without it.
        cfg.d_min_m = scenario.safety.safe_distance_m;
        if !scenario.method.generalised {
            cfg.safety = false;
        }
        let vehicle = Vehicle::new(&plant.vehicle)?;
        let run = &rt.args().run_id;
        let lim = ChannelLimits::vehicle();
        let setpoint = ipc_types::service_name(run, me, Channel::Setpoint);
        // Dataflow: a control step per new setpoint; nav is read as it stands.
        if scenario.same_rate(ProcessKind::Mpc, ProcessKind::Planner) {
            rt.wake_on(&setpoint, &lim)?;
        }
        Ok(Self {
            mpc: Mpc::new(&cfg, &vehicle)?,
            thrust_max: plant.thrust_max,
            nav_in: rt.subscriber(&ipc_types::service_name(run, me, Channel::Nav), &lim, 4)?,
            setpoint_in: rt.subscriber(&setpoint, &lim, 4)?,
            thrust_out: rt.publisher(&ipc_types::service_name(run, me, Channel::Thrust), &lim)?,
            stats_out: rt.publisher(&ipc_types::service_name(run, me, Channel::MpcStats), &lim)?,
            nav: None,
            setpoint: None,
            failures: 0,
        })
    }
}

impl<S: Service> Task for MpcTask<S> {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(n) = self.nav_in.latest(ctx)? {
            self.nav = Some(n);
        }
        if let Some(s) = self.setpoint_in.latest(ctx)? {
            self.setpoint = Some(s);
        }
        let (Some(nav), Some(sp)) = (self.nav, self.setpoint) else {
            return Ok(());
        };
        let v = nav.velocity_body_mps;
        let w = nav.rates_body_radps;
        let input = MpcInput {
            attitude: quat(nav.q_body_to_ned_wxyz),
            nu: Vector6::new(v[0], v[1], v[2], w[0], w[1], w[2]),
            target: MpcTarget {
                position_m: Vector3::from(sp.position_m),
                velocity_mps: Vector3::from(sp.velocity_mps),
                yaw_rel_rad: sp.yaw_rel_rad,
            },
            keepout: Keepout::from_setpoint(&sp),
        };
        let t0 = shoal_runtime::mono_ns();
        let result = self.mpc.step(&input);
        let solve_ns = shoal_runtime::mono_ns().saturating_sub(t0);
        let mut stats = MpcStats::zeroed();
        stats.solve_ns = solve_ns;
        let (tau, fallback) = match result {
            Ok(out) => {
                stats.iterations = out.iterations;
                stats.status = u32::from(out.status.code());
                stats.cost = if out.cost.is_finite() { out.cost } else { 0.0 };
                (out.tau, false)
            }
            Err(e) => {
                self.failures += 1;
                stats.status = 100;
                tracing::warn!(error = %e, "mpc solve failed; holding the previous input, decaying");
                (self.mpc.fallback(), true)
            }
        };
        stats.failures = self.failures;
        let mut thrust = Thrust::zeroed();
        let mut mask = 0u8;
        for i in 0..6 {
            let lim = self.thrust_max[i];
            let t = if tau[i].is_finite() {
                tau[i].clamp(-lim, lim)
            } else {
                0.0
            };
            if t.abs() >= lim * (1.0 - 1e-9) {
                mask |= 1 << i;
            }
            thrust.tau[i] = t;
        }
        thrust.saturated_mask = mask;
        thrust.fallback = u8::from(fallback);
        let origin = Origin::of(&sp.header).earliest(Origin::of(&nav.header));
        self.thrust_out.publish(thrust, ctx, origin)?;
        self.stats_out.publish(stats, ctx, origin)?;
        Ok(())
    }
}
