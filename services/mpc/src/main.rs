//! `shoal-mpc`: the predictive controller (eqs. 14-18). Reads its own `nav`
//! and `setpoint`, publishes `thrust` (saturated, never NaN) and `mpc_stats`.
use clap::Parser;

fn main() -> anyhow::Result<()> {
    let cli = shoal_runtime::ServiceCli::parse();
    shoal_runtime::init_tracing();
    let scenario = shoal_scenario::Scenario::from_file(&cli.scenario)?;
    let rt = shoal_runtime::Runtime::new(&cli.run)?;
    rt.serve(|rt| mpc::node::MpcTask::new(rt, &scenario))?;
    Ok(())
}
