//! `shoal-planner`: the leader follows its mission and avoids obstacles with
//! its own sonar; a follower keeps its slot from `leader_pose` and shifts it
//! along the displacement trajectories (eqs. 4-9) when its sonar sees an
//! obstacle. Publishes `setpoint` and `planner_state`. A follower reads only
//! its own vehicle's channels.
use clap::Parser;

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = shoal_scenario::Scenario::from_file(&cli.scenario)?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    rt.serve(|rt| planner::node::PlannerTask::new(rt, &scenario))?;
    Ok(())
}
