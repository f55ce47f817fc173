//! Wiring of the plant library to its channels.

use anyhow::Context;
use ipc_types::{Channel, Nav, Sample, Thrust, Truth};
use nalgebra::{UnitQuaternion, Vector3, Vector6};
use shoal_runtime::convert::{arr, seed_for, wxyz};
use shoal_runtime::ports::Origin;
use shoal_runtime::{
    ChannelLimits, Mode, Publisher, Runtime, StepContext, Subscriber, Task, TaskError, Wake,
};
use shoal_scenario::Scenario;
use sim_plant::nav::{NavConfig, NavSensor};
use sim_plant::{Plant, PlantConfig, PlantState};

pub struct PlantTask {
    plant: Plant,
    nav: NavSensor,
    is_leader: bool,
    thrust_in: Subscriber<Thrust>,
    truth_out: Publisher<Truth>,
    nav_out: Publisher<Nav>,
    tau: Vector6<f64>,
    thrust_origin_mono_ns: u64,
    thrust_applied_mono_ns: u64,
    period_s: f64,
    /// A restarted plant: simulated time of the `truth` it resumed from.
    resumed_from_ns: Option<u64>,
    /// Dataflow: simulated time of the plant's state, ns (it integrates up
    /// to each step's time, whatever woke it).
    state_ns: Option<u64>,
}

/// Most plant periods a restarted plant catches up on (realtime: the
/// vehicle coasts on its last thrust while its simulator was gone).
const MAX_CATCH_UP_STEPS: u64 = 600;

/// Reads the `truth` sample the orchestrator handed over to a restarted plant.
fn read_resume(path: &std::path::Path) -> anyhow::Result<Truth> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    if bytes.len() != std::mem::size_of::<Truth>() {
        anyhow::bail!(
            "{}: {} bytes, a truth sample has {}",
            path.display(),
            bytes.len(),
            std::mem::size_of::<Truth>()
        );
    }
    let t: Truth = bytemuck::pod_read_unaligned(&bytes);
    if !t.is_finite() {
        anyhow::bail!("{}: the handed-over truth is not finite", path.display());
    }
    Ok(t)
}

impl PlantTask {
    pub fn new(rt: &Runtime, scenario: &Scenario) -> anyhow::Result<Self> {
        let me = &rt.args().vehicle;
        let index = scenario
            .vehicle_index(me)
            .context("vehicle not in scenario")?;
        let spec = &scenario.vehicles[index];
        let cfg: PlantConfig = scenario.section("plant")?;
        let nav_cfg: NavConfig = scenario.section("nav")?;
        let (p, yaw) = scenario.start_poses()[me];
        let mut initial = PlantState::at_rest(
            Vector3::from(p),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        );
        // A restarted plant carries on from its vehicle's last truth.
        let resumed = rt.args().resume.as_deref().map(read_resume).transpose()?;
        let mut tau = Vector6::zeros();
        if let Some(t) = &resumed {
            initial = PlantState {
                position_ned_m: Vector3::from(t.position_ned_m),
                attitude: shoal_runtime::convert::quat(t.q_body_to_ned_wxyz),
                nu: Vector6::new(
                    t.velocity_body_mps[0],
                    t.velocity_body_mps[1],
                    t.velocity_body_mps[2],
                    t.rates_body_radps[0],
                    t.rates_body_radps[1],
                    t.rates_body_radps[2],
                ),
            };
            tau = Vector6::from(t.tau_applied);
            tracing::info!(
                t_s = t.header.sim_time_ns as f64 * 1e-9,
                "resuming from the handed-over truth"
            );
        }
        let run = &rt.args().run_id;
        let lim = ChannelLimits::vehicle();
        // Dataflow: thrust is applied when it arrives; truth and nav go out
        // on the plant's own clock.
        let thrust = ipc_types::service_name(run, me, Channel::Thrust);
        rt.wake_on(&thrust, &lim)?;
        rt.keep_timer();
        Ok(Self {
            plant: Plant::new(&cfg, initial)?,
            nav: NavSensor::new(&nav_cfg, seed_for(scenario.seed, index, 1))?,
            is_leader: spec.parent.is_none(),
            thrust_in: rt.subscriber(&thrust, &lim, 4)?,
            truth_out: rt.publisher(&ipc_types::service_name(run, me, Channel::Truth), &lim)?,
            nav_out: rt.publisher(&ipc_types::service_name(run, me, Channel::Nav), &lim)?,
            tau,
            thrust_origin_mono_ns: 0,
            thrust_applied_mono_ns: 0,
            period_s: 1.0 / scenario.rates.plant_hz,
            resumed_from_ns: resumed.map(|t| t.header.sim_time_ns),
            state_ns: None,
        })
    }
}

impl Task for PlantTask {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        // Resumed: the handed-over truth is the state at the start of its
        // step; the steps from there to now ran with its applied thrust.
        if let Some(from) = self.resumed_from_ns.take() {
            let period_ns = (self.period_s * 1e9).round().max(1.0) as u64;
            let steps = (ctx.sim_time_ns.saturating_sub(from) + period_ns / 2) / period_ns;
            for _ in 0..steps.min(MAX_CATCH_UP_STEPS) {
                self.advance(self.period_s)?;
            }
        }
        if ctx.mode == Mode::Dataflow {
            return self.step_dataflow(ctx);
        }
        self.take_thrust(ctx)?;
        self.publish(ctx)?;
        let dt = match ctx.mode {
            Mode::Lockstep => self.period_s,
            Mode::Realtime | Mode::Dataflow => ctx.since_last_ns as f64 * 1e-9,
        };
        self.advance(dt)
    }
}

impl PlantTask {
    /// Takes the newest thrust, if one came, and applies it from now on.
    fn take_thrust(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(t) = self.thrust_in.latest(ctx)? {
            self.tau = Vector6::from(t.tau);
            self.thrust_origin_mono_ns = t.header.origin_mono_ns;
            self.thrust_applied_mono_ns = shoal_runtime::mono_ns();
        }
        Ok(())
    }

    fn advance(&mut self, dt: f64) -> Result<(), TaskError> {
        if dt > 0.0 {
            self.plant
                .advance(&self.tau, dt)
                .map_err(TaskError::failed("plant step"))?;
        }
        Ok(())
    }

    /// Dataflow: the state is carried to this step's time on the thrust
    /// applied so far; then a new thrust takes effect at once, and on the
    /// plant's own clock its truth and nav go out.
    fn step_dataflow(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let from = *self.state_ns.get_or_insert(ctx.sim_time_ns);
        self.advance(ctx.sim_time_ns.saturating_sub(from) as f64 * 1e-9)?;
        self.state_ns = Some(ctx.sim_time_ns.max(from));
        self.take_thrust(ctx)?;
        if ctx.woken_by == Wake::Input {
            return Ok(());
        }
        self.publish(ctx)
    }

    /// Publishes the state as truth and as the vehicle's own nav sensor.
    fn publish(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let applied = self.plant.saturate(&self.tau);
        let s = *self.plant.state();
        let (r, p, y) = s.euler_rpy();
        let mut truth = Truth::zeroed();
        truth.position_ned_m = arr(&s.position_ned_m);
        truth.q_body_to_ned_wxyz = wxyz(&s.attitude);
        truth.euler_rpy_rad = [r, p, y];
        truth.velocity_body_mps = [s.nu[0], s.nu[1], s.nu[2]];
        truth.rates_body_radps = [s.nu[3], s.nu[4], s.nu[5]];
        truth.tau_applied = applied.into();
        truth.thrust_origin_mono_ns = self.thrust_origin_mono_ns;
        truth.thrust_applied_mono_ns = self.thrust_applied_mono_ns;
        let here = Origin::here(ctx);
        self.truth_out.publish(truth, ctx, here)?;

        let m = self.nav.measure(&s, self.is_leader);
        let (r, p, y) = m.attitude.euler_angles();
        let mut nav = Nav::zeroed();
        nav.q_body_to_ned_wxyz = wxyz(&m.attitude);
        nav.euler_rpy_rad = [r, p, y];
        nav.rates_body_radps = arr(&m.rates_body_radps);
        nav.velocity_body_mps = arr(&m.velocity_body_mps);
        nav.depth_m = m.depth_m;
        if let Some(pos) = m.position_ned_m {
            nav.position_ned_m = arr(&pos);
            nav.position_valid = 1;
        }
        self.nav_out.publish(nav, ctx, here)?;
        Ok(())
    }
}
