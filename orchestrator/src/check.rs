//! `shoal check`: every section of a scenario parsed into its service's
//! typed config and validated, and the formation's displacement
//! trajectories (D_a, D_b) assigned and checked, before anything starts.

use anyhow::Context;
use planner::formation::{FollowerSlot, FormationParams};
use shoal_scenario::Scenario;

/// Validates the whole scenario and fills in every follower's D_a and D_b
/// (those the file leaves out are assigned from the formation); the error
/// names the key, or the pair of vehicles that cannot be kept apart.
pub fn resolve(s: &mut Scenario) -> anyhow::Result<()> {
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
    sonar::ObstacleField::new(&obstacles).context("obstacles")?;
    let camera: camera_pose::CameraConfig = s.section("camera")?;
    camera.validate().context("camera")?;
    let beacons: camera_pose::BeaconLayout = s.section("beacons")?;
    beacons.validate().context("beacons")?;
    let hull: camera_pose::HullConfig = s.section("hull")?;
    hull.validate().context("hull")?;
    let pose: camera_pose::PoseConfig = s.section("pose")?;
    pose.validate().context("pose")?;
    camera_pose::PoseEstimator::new(&pose, &camera, &beacons).context("pose")?;
    let mission: planner::LeaderConfig = s.section("mission")?;
    mission.validate().context("mission")?;
    let follower: planner::FollowerConfig = s.section("follower")?;
    follower.validate().context("follower")?;
    let mpc_cfg: mpc::MpcConfig = s.section("mpc")?;
    mpc_cfg.validate().context("mpc")?;

    let slots: Vec<FollowerSlot> = s
        .vehicles
        .iter()
        .filter_map(|v| {
            Some(FollowerSlot {
                name: v.name.clone(),
                parent: v.parent.clone()?,
                slot_in_parent_m: v.slot_m?,
            })
        })
        .collect();
    let params = FormationParams {
        visibility_range_m: camera.visibility_range_m,
        ..Default::default()
    };
    let d_min = s.safety.safe_distance_m;
    let leader = s.leader().name.clone();
    let assigned = planner::formation::assign_displacements(&leader, &slots, d_min, &params)
        .context(
        "formation: no displacement trajectories keep every pair apart and every parent in sight",
    )?;
    let s_method_vertical = s.method.vertical_shift;
    let mut chosen = Vec::with_capacity(slots.len());
    for (slot, (d_a, d_b)) in slots.iter().zip(assigned) {
        let v = s
            .vehicles
            .iter_mut()
            .find(|v| v.name == slot.name)
            .context("follower vanished")?;
        let mut d = (v.d_a_m.unwrap_or(d_a), v.d_b_m.unwrap_or(d_b));
        if !s_method_vertical {
            // The ablation: no vertical displacement (eq. 5 with D_b = 0).
            d.1 = 0.0;
        }
        v.d_a_m = Some(d.0);
        v.d_b_m = Some(d.1);
        chosen.push(d);
    }
    // The ablation (no vertical shift) is by design a formation the check
    // refuses: it is run to measure what that costs.
    if s_method_vertical {
        planner::formation::check(&leader, &slots, &chosen, d_min, &params).context(
            "formation: the given D_a/D_b do not keep every pair apart and every parent in sight",
        )?;
    }
    if s.method.perception == shoal_scenario::Perception::Acoustic {
        let acoustic: camera_pose::acoustic::AcousticConfig = s.section("acoustic")?;
        acoustic.validate().map_err(anyhow::Error::msg)?;
    }
    Ok(())
}
