//! `shoal-sim-plant`: integrates one vehicle's Fossen model, applies its
//! `thrust`, publishes `truth` (ground truth) and `nav` (its own sensors).
use clap::Parser;

mod node;

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = shoal_scenario::Scenario::from_file(&cli.scenario)?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    rt.serve(|rt| node::PlantTask::new(rt, &scenario))?;
    Ok(())
}
