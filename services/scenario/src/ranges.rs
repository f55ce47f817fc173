//! The range of every number a scenario sets, in one table.
//!
//! Each service's own `validate` refuses what its maths cannot take (a
//! negative mass, a zero rate, a NaN). This table adds the physical bounds
//! beyond which a value is a typo rather than a design: a speed of 2000 m/s,
//! a camera mounted 50 m off the hull, a noise larger than the signal, a
//! coordinate beyond what double precision resolves. It is checked on the
//! effective scenario (every section with its defaults), so a key is
//! checked whether the file sets it or not.
//!
//! A pattern is a dotted key with `[]` for any element of an array of
//! tables (`vehicles[].start_yaw_deg`); an array of numbers (or of arrays
//! of numbers) is checked element by element.

use crate::{invalid, short, ScenarioError, MAX_COORD_M};

/// `(key pattern, least, greatest, what the bound stands for)`, inclusive.
pub const RANGES: &[(&str, f64, f64, &str)] = &[
    // Where things are: what double precision resolves.
    (
        "vehicles[].start_ned_m",
        -MAX_COORD_M,
        MAX_COORD_M,
        "a coordinate",
    ),
    (
        "mission.waypoints_ned_m",
        -MAX_COORD_M,
        MAX_COORD_M,
        "a coordinate",
    ),
    (
        "obstacles[].center_ned_m",
        -MAX_COORD_M,
        MAX_COORD_M,
        "a coordinate",
    ),
    (
        "obstacles[].vertices_ned_m",
        -MAX_COORD_M,
        MAX_COORD_M,
        "a coordinate",
    ),
    // Angles: beyond a turn, sin and cos lose precision for nothing.
    ("vehicles[].start_yaw_deg", -720.0, 720.0, "an angle"),
    ("obstacles[].yaw_deg", -360.0, 360.0, "an angle"),
    ("camera.mount_rpy_deg", -360.0, 360.0, "an angle"),
    // On the hull.
    (
        "plant.vehicle.cg_body_m",
        -10.0,
        10.0,
        "a point on the hull",
    ),
    (
        "plant.vehicle.cb_body_m",
        -10.0,
        10.0,
        "a point on the hull",
    ),
    (
        "sonar.mount_position_body_m",
        -10.0,
        10.0,
        "a point on the hull",
    ),
    (
        "camera.mount_position_body_m",
        -10.0,
        10.0,
        "a point on the hull",
    ),
    (
        "beacons.positions_body_m",
        -10.0,
        10.0,
        "a point on the hull",
    ),
    (
        "mission.sonar_mount_body_m",
        -10.0,
        10.0,
        "a point on the hull",
    ),
    (
        "follower.sonar_mount_body_m",
        -10.0,
        10.0,
        "a point on the hull",
    ),
    ("beacons.facing_body", -1e6, 1e6, "a direction"),
    // Sizes.
    ("obstacles[].half_extents_m", 0.0, 1e4, "an obstacle's size"),
    ("obstacles[].radius_m", 0.0, 1e4, "an obstacle's size"),
    ("obstacles[].half_height_m", 0.0, 1e4, "an obstacle's size"),
    ("hull.radius_m", 0.0, 5.0, "a hull's size"),
    ("hull.length_m", 0.0, 100.0, "a hull's size"),
    ("sonar.hull_radius_m", 0.0, 5.0, "a hull's size"),
    ("sonar.hull_length_m", 0.0, 100.0, "a hull's size"),
    ("sonar.range_max_m", 0.0, 1000.0, "a sonar's reach"),
    ("camera.visibility_range_m", 0.0, 1000.0, "a range in water"),
    (
        "safety.safe_distance_m",
        0.0,
        1000.0,
        "a distance between vehicles",
    ),
    // Speeds, accelerations, the sea.
    ("mission.speed_mps", 0.0, 20.0, "an AUV's speed"),
    ("mission.offset_rate_mps", 0.0, 20.0, "an AUV's speed"),
    ("mission.accel_mps2", 0.0, 10.0, "an AUV's acceleration"),
    ("mission.decel_mps2", 0.0, 10.0, "an AUV's acceleration"),
    ("plant.current_ned_mps", -5.0, 5.0, "a sea current"),
    // Rates and times.
    ("rates.tick_s", 1e-4, 1.0, "a lockstep tick"),
    ("rates.plant_hz", 0.1, 1000.0, "a process rate"),
    ("rates.world_hz", 0.1, 1000.0, "a process rate"),
    ("rates.camera_hz", 0.1, 1000.0, "a process rate"),
    ("rates.sonar_hz", 0.1, 1000.0, "a process rate"),
    ("rates.planner_hz", 0.1, 1000.0, "a process rate"),
    ("rates.mpc_hz", 0.1, 1000.0, "a process rate"),
    ("rates.recorder_hz", 0.1, 1000.0, "a process rate"),
    ("supervision.restart_timeout_s", 0.0, 3600.0, "a wait"),
    ("supervision.max_restarts", 0.0, 1000.0, "a count"),
    ("faults[].duration_s", 0.0, 3600.0, "a stall"),
    ("follower.stale_after_s", 0.0, 3600.0, "a time"),
    ("follower.predict_s", 0.0, 3600.0, "a time"),
    ("follower.coast_s", 0.0, 3600.0, "a time"),
    ("follower.search_s", 0.0, 3600.0, "a time"),
    ("follower.headway_avg_s", 0.0, 3600.0, "a time"),
    ("follower.headway_s", 0.0, 100.0, "a time headway"),
    ("follower.yaw_headway_s", 0.0, 100.0, "a time headway"),
    (
        "follower.memory_max_age_s",
        0.0,
        crate::MAX_DURATION_S,
        "a time",
    ),
    (
        "mission.memory_max_age_s",
        0.0,
        crate::MAX_DURATION_S,
        "a time",
    ),
    // Guidance distances.
    (
        "mission.acceptance_radius_m",
        0.0,
        1000.0,
        "a guidance distance",
    ),
    ("mission.avoid_margin_m", 0.0, 100.0, "a guidance distance"),
    ("mission.lookahead_m", 0.0, 1000.0, "a guidance distance"),
    (
        "mission.los_lookahead_m",
        0.0,
        1000.0,
        "a guidance distance",
    ),
    ("mission.max_lead_m", 0.0, 1000.0, "a guidance distance"),
    ("mission.max_offset_m", 0.0, 1000.0, "a guidance distance"),
    ("mission.shadow_m", 0.0, 1000.0, "a guidance distance"),
    ("mission.side_margin_m", 0.0, 1000.0, "a guidance distance"),
    ("mission.turn_radius_m", 0.0, 1e4, "a turn radius"),
    ("mission.memory_behind_m", 0.0, 1e4, "a memory length"),
    ("mission.memory_cell_m", 0.0, 100.0, "a memory cell"),
    ("follower.memory_behind_m", 0.0, 1e4, "a memory length"),
    ("follower.memory_cell_m", 0.0, 100.0, "a memory cell"),
    (
        "follower.parent_echo_radius_m",
        0.0,
        100.0,
        "a guidance distance",
    ),
    (
        "follower.keep_clear_margin_m",
        0.0,
        100.0,
        "a guidance distance",
    ),
    (
        "follower.view_margin_deg",
        0.0,
        89.0,
        "a margin inside the view",
    ),
    // Noise: below the signal it blurs.
    ("nav.attitude_noise_rad", 0.0, 0.5, "a sensor's noise"),
    ("nav.rate_noise_radps", 0.0, 1.0, "a sensor's noise"),
    ("nav.velocity_noise_mps", 0.0, 5.0, "a sensor's noise"),
    ("nav.depth_noise_m", 0.0, 10.0, "a sensor's noise"),
    ("nav.position_noise_m", 0.0, 100.0, "a sensor's noise"),
    ("sonar.noise_m", 0.0, 10.0, "a sensor's noise"),
    ("camera.noise_px", 0.0, 100.0, "a sensor's noise"),
    ("acoustic.position_noise_m", 0.0, 100.0, "a sensor's noise"),
    ("acoustic.heading_noise_deg", 0.0, 180.0, "a sensor's noise"),
    (
        "mission.position_fix_noise_m",
        0.0,
        100.0,
        "a filter's noise",
    ),
    (
        "mission.dead_reckoning_noise_mps",
        0.0,
        10.0,
        "a filter's noise",
    ),
    ("follower.accel_noise_mps2", 0.0, 100.0, "a filter's noise"),
    (
        "follower.yaw_accel_noise_radps2",
        0.0,
        10.0,
        "a filter's noise",
    ),
    ("follower.pose_noise_min_m", 0.0, 100.0, "a filter's noise"),
    (
        "follower.pose_noise_default_m",
        0.0,
        100.0,
        "a filter's noise",
    ),
    (
        "follower.yaw_noise_min_rad",
        0.0,
        std::f64::consts::PI,
        "a filter's noise",
    ),
    ("follower.gate_chi2", 0.0, 1e4, "a chi-square gate"),
    ("pose.ambiguity_chi2", 0.0, 1e4, "a chi-square gate"),
    ("pose.pixel_sigma_floor_px", 0.0, 100.0, "a pixel noise"),
    ("pose.max_reprojection_rms_px", 0.0, 1000.0, "a pixel error"),
    // Counts.
    ("follower.reacquire_count", 1.0, 1000.0, "a count"),
    ("follower.max_rejections", 1.0, 1000.0, "a count"),
    ("mpc.max_iter", 1.0, 10_000.0, "an iteration limit"),
    // The vehicle and its controller.
    ("plant.vehicle.mass_kg", 0.0, 1e5, "a vehicle's mass"),
    (
        "plant.vehicle.inertia_kgm2",
        0.0,
        1e7,
        "a vehicle's inertia",
    ),
    ("plant.vehicle.added_mass", 0.0, 1e7, "an added mass"),
    ("plant.vehicle.damping_linear", 0.0, 1e6, "a damping"),
    ("plant.vehicle.damping_quadratic", 0.0, 1e6, "a damping"),
    ("plant.vehicle.weight_n", 0.0, 1e6, "a weight"),
    ("plant.vehicle.buoyancy_n", 0.0, 1e6, "a buoyancy"),
    ("plant.thrust_max", 0.0, 1e5, "a thrust"),
    ("mpc.rho1", 0.0, 1e8, "a cost weight"),
    ("mpc.rho2", 0.0, 1e8, "a cost weight"),
    ("mpc.terminal_weight", 1.0, 1e4, "a cost weight"),
    // The acoustic baseline.
    ("acoustic.bit_rate_bps", 0.0, 1e6, "a modem's bit rate"),
    ("acoustic.packet_bits", 1.0, 1e6, "a packet's size"),
    (
        "acoustic.sound_speed_mps",
        1300.0,
        1700.0,
        "the speed of sound in water",
    ),
];

/// The numbers at `path` under `value`, each with the key that names it
/// (`vehicles[2].start_ned_m`) and its pattern (`vehicles[].start_ned_m`).
fn numbers(path: &str, pattern: &str, value: &toml::Value, out: &mut Vec<(String, String, f64)>) {
    match value {
        toml::Value::Float(x) => out.push((path.to_string(), pattern.to_string(), *x)),
        toml::Value::Integer(i) => out.push((path.to_string(), pattern.to_string(), *i as f64)),
        toml::Value::Table(t) => table_numbers(path, pattern, t, out),
        toml::Value::Array(a) => {
            for (i, v) in a.iter().enumerate() {
                if v.is_table() {
                    numbers(&format!("{path}[{i}]"), &format!("{pattern}[]"), v, out);
                } else {
                    // A number in a list is named by its list's key.
                    numbers(path, pattern, v, out);
                }
            }
        }
        _ => {}
    }
}

fn table_numbers(path: &str, pattern: &str, t: &toml::Table, out: &mut Vec<(String, String, f64)>) {
    for (k, v) in t {
        let (p, q) = if path.is_empty() {
            (k.clone(), k.clone())
        } else {
            (format!("{path}.{k}"), format!("{pattern}.{k}"))
        };
        numbers(&p, &q, v, out);
    }
}

/// Every number of `doc`: (key, pattern, value).
fn all_numbers(doc: &toml::Table) -> Vec<(String, String, f64)> {
    let mut all = Vec::new();
    table_numbers("", "", doc, &mut all);
    all
}

/// Checks every number of an (effective) scenario document against
/// [`RANGES`]; the error names the key.
pub fn check(doc: &toml::Table) -> Result<(), ScenarioError> {
    for (key, pattern, x) in all_numbers(doc) {
        if let Some((_, lo, hi, what)) = RANGES.iter().find(|r| r.0 == pattern) {
            if !(x >= *lo && x <= *hi) {
                return Err(invalid(
                    key,
                    format!(
                        "{} is out of range for {what}: must be within [{}, {}]",
                        short(x),
                        short(*lo),
                        short(*hi)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The patterns of [`RANGES`] that no number of `doc` matches (a test
/// asks that a full scenario leaves none: a pattern that matches nothing
/// checks nothing).
pub fn unmatched(doc: &toml::Table) -> Vec<&'static str> {
    let all = all_numbers(doc);
    RANGES
        .iter()
        .map(|r| r.0)
        .filter(|p| !all.iter().any(|(_, q, _)| q == p))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_number_out_of_range_is_named_by_its_key() {
        let doc: toml::Table = toml::from_str(
            "[mission]\nspeed_mps = 2000.0\n[[vehicles]]\nname = \"L\"\n[[vehicles]]\nname = \"F\"\nstart_ned_m = [0.0, 0.0, 2e6]\n",
        )
        .unwrap_or_default();
        let e = check(&doc).unwrap_err().to_string();
        assert!(
            e.starts_with("mission.speed_mps: 2000 is out of range for an AUV's speed"),
            "{e}"
        );
        let mut ok = doc.clone();
        ok.insert("mission".into(), toml::Value::Table(toml::Table::new()));
        let e = check(&ok).unwrap_err().to_string();
        assert!(
            e.starts_with("vehicles[1].start_ned_m: 2000000 is out of range"),
            "{e}"
        );
    }

    #[test]
    fn every_pattern_is_unique() {
        for (i, r) in RANGES.iter().enumerate() {
            assert!(r.1 <= r.2, "{}", r.0);
            assert!(!RANGES[i + 1..].iter().any(|s| s.0 == r.0), "{} twice", r.0);
        }
    }
}
