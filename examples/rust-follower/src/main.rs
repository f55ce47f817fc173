//! `my-follower`: a follower planner brought by its user, in Rust, from
//! outside shoal. It takes the place of shoal's planner for the followers:
//!
//! ```text
//! cargo build --release -p my-follower
//! shoal run --replace 'planner@followers=target/release/my-follower'
//! ```
//!
//! The orchestrator starts it with the run's arguments (`ServiceCli`), and
//! `shoal_runtime::Runtime` gives it everything a shoal process has: its
//! vehicle's channels, the step loop in every mode, statistics, clean
//! shutdown. The method here is the paper's follower as published (eqs.
//! 4-9, shoal's `planner` library with none of shoal's extras): the place
//! where a researcher puts their own.
use anyhow::Context;
use clap::Parser;
use ipc_types::{Channel, LeaderPose, Nav, PlannerState, Setpoint, Sonar};
use nalgebra::Vector6;
use planner::{FollowerInput, FollowerPlanner, SonarScan};
use shoal_runtime::convert::quat;
use shoal_runtime::ports::Origin;
use shoal_runtime::{ChannelLimits, Publisher, Runtime, StepContext, Subscriber, Task, TaskError};
use shoal_scenario::Scenario;

/// One follower: its three inputs, its setpoint, its planner.
struct MyFollower {
    planner: FollowerPlanner,
    nav_in: Subscriber<Nav>,
    pose_in: Subscriber<LeaderPose>,
    sonar_in: Subscriber<Sonar>,
    setpoint_out: Publisher<Setpoint>,
    /// What the planner is doing: the summary finds the passage by it.
    state_out: Publisher<PlannerState>,
    nav: Option<Nav>,
}

impl MyFollower {
    fn new(rt: &Runtime, scenario: &Scenario) -> anyhow::Result<Self> {
        let (run, me) = (&rt.args().run_id, &rt.args().vehicle);
        let mut cfg = planner::node::follower_config(scenario, me)?;
        // The paper's method as published.
        cfg.view_margin_deg = 0.0;
        cfg.keep_clear = false;
        cfg.headway_cap = false;
        cfg.search_s = 0.0;
        cfg.memory_cell_m = 0.0;
        cfg.coordinated_turn = false;
        cfg.trail = false;
        let lim = ChannelLimits::vehicle();
        let name = |ch| ipc_types::service_name(run, me, ch);
        Ok(Self {
            planner: FollowerPlanner::new(&cfg).context("follower planner")?,
            nav_in: rt.subscriber(&name(Channel::Nav), &lim, 4)?,
            pose_in: rt.subscriber(&name(Channel::LeaderPose), &lim, 4)?,
            sonar_in: rt.subscriber(&name(Channel::Sonar), &lim, 4)?,
            setpoint_out: rt.publisher(&name(Channel::Setpoint), &lim)?,
            state_out: rt.publisher(&name(Channel::PlannerState), &lim)?,
            nav: None,
        })
    }
}

impl Task for MyFollower {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(n) = self.nav_in.latest(ctx)? {
            self.nav = Some(n);
        }
        let Some(nav) = self.nav else {
            return Ok(()); // nothing known about ourselves yet
        };
        let sonar = self.sonar_in.latest(ctx)?;
        let mut origin = Origin::of(&nav.header);
        let pose = self.pose_in.latest(ctx)?.map(|p| {
            origin = origin.earliest(Origin::of(&p.header));
            planner::node::pose_measurement(&p)
        });
        let v = nav.velocity_body_mps;
        let w = nav.rates_body_radps;
        let out = self
            .planner
            .step(&FollowerInput {
                t_s: nav.header.sim_time_ns as f64 * 1e-9,
                attitude: quat(nav.q_body_to_ned_wxyz),
                nu: Vector6::new(v[0], v[1], v[2], w[0], w[1], w[2]),
                depth_m: nav.depth_m,
                pose,
                sonar: sonar.as_ref().map(SonarScan::from_sample),
            })
            .map_err(TaskError::failed("my follower step"))?;
        // What the controller flies, and what the summary reads the passage from.
        self.setpoint_out
            .publish(planner::node::setpoint_of(&out), ctx, origin)?;
        self.state_out
            .publish(planner::node::state_of(&out), ctx, origin)?;
        Ok(())
    }
}

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = Scenario::from_file(&cli.scenario)?;
    let rt = Runtime::new(&cli.run)?;
    rt.serve(|rt| MyFollower::new(rt, &scenario))?;
    Ok(())
}
