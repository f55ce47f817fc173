//! `shoal-sonar`: casts the vehicle's rangefinder beams against the
//! scenario's obstacles (and, if enabled, other hulls) from the `world`
//! snapshot, and publishes `sonar`.
use clap::Parser;

mod node;

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = shoal_scenario::Scenario::from_file(&cli.scenario)?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    rt.serve(|rt| node::SonarTask::new(rt, &scenario))?;
    Ok(())
}
