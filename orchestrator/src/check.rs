//! `shoal check`: every section of a scenario parsed into its service's
//! typed config and validated, before anything starts.

use anyhow::Context;
use shoal_scenario::Scenario;

/// Validates the whole scenario; the error names the key.
pub fn check(s: &Scenario) -> anyhow::Result<()> {
    s.validate()?;
    let plant: sim_plant::PlantConfig = s.section("plant")?;
    plant.validate().context("plant")?;
    let nav: sim_plant::nav::NavConfig = s.section("nav")?;
    nav.validate().context("nav")?;
    let sonar_cfg: sonar::SonarConfig = s.section("sonar")?;
    sonar_cfg.validate().context("sonar")?;
    let obstacles: Vec<sonar::Obstacle> = s.obstacles_as()?;
    for (i, o) in obstacles.iter().enumerate() {
        o.validate().with_context(|| format!("obstacles[{i}]"))?;
    }
    let camera: camera_pose::CameraConfig = s.section("camera")?;
    camera.validate().context("camera")?;
    let beacons: camera_pose::BeaconLayout = s.section("beacons")?;
    beacons.validate().context("beacons")?;
    let hull: camera_pose::HullConfig = s.section("hull")?;
    hull.validate().context("hull")?;
    let pose: camera_pose::PoseConfig = s.section("pose")?;
    pose.validate().context("pose")?;
    Ok(())
}
