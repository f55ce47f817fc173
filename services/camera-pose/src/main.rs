//! `shoal-camera-pose`: a follower's camera. Projects the parent's beacons
//! from the `world` snapshot (the only ground truth it may read, to simulate
//! what the camera physically sees), publishes the pixels on `beacons`, and
//! solves the parent's pose from those pixels alone onto `leader_pose`.
use clap::Parser;

mod node;

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = shoal_scenario::Scenario::from_file(&cli.scenario)?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    rt.serve(|rt| node::CameraTask::new(rt, &scenario))?;
    Ok(())
}
