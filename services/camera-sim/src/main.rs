//! `shoal-camera-sim`: renders a follower's camera frame from the `world`
//! snapshot and publishes it on `image`, written in place in shared memory.
use clap::Parser;

mod node;

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = shoal_scenario::Scenario::from_file(&cli.scenario)?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    rt.serve(|rt| node::CameraSimTask::new(rt, &scenario))?;
    Ok(())
}
