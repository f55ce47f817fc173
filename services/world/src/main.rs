//! `shoal-world`: reads every vehicle's `truth` and publishes one `world`
//! snapshot, so sensors read one sample instead of subscribing to N vehicles.
use clap::Parser;

mod node;

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = shoal_scenario::Scenario::from_file(&cli.scenario)?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    let task = node::WorldTask::new(&rt, &scenario)?;
    rt.run(task)?;
    Ok(())
}
