//! Conversions between sample fields (plain arrays) and nalgebra types,
//! done once at the process boundary, and seeds for per-process generators.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// `[w, x, y, z]` → unit quaternion (renormalised).
pub fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// Unit quaternion → `[w, x, y, z]`.
pub fn wxyz(q: &UnitQuaternion<f64>) -> [f64; 4] {
    let c = q.quaternion().coords; // [x, y, z, w]
    [c[3], c[0], c[1], c[2]]
}

/// Vector → array.
pub fn arr(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// A pose from a position and a `[w, x, y, z]` attitude.
pub fn pose(position: [f64; 3], q: [f64; 4]) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(Vector3::from(position)), quat(q))
}

/// A pose from the world snapshot.
pub fn world_pose(v: &ipc_types::VehiclePose) -> Isometry3<f64> {
    pose(v.position_ned_m, v.q_body_to_ned_wxyz)
}

/// A seed for one random stream of one process: deterministic in the
/// scenario seed, the vehicle index and the stream id (splitmix64).
pub fn seed_for(scenario_seed: u64, vehicle_index: usize, stream: u64) -> u64 {
    let mut z = scenario_seed
        .wrapping_add((vehicle_index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(stream.wrapping_mul(0xD1B5_4A32_D192_ED03));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_round_trip() {
        let q = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3);
        let back = quat(wxyz(&q));
        assert!((back.angle_to(&q)).abs() < 1e-12);
    }

    #[test]
    fn seeds_differ_by_vehicle_and_stream() {
        assert_ne!(seed_for(1, 0, 0), seed_for(1, 1, 0));
        assert_ne!(seed_for(1, 0, 0), seed_for(1, 0, 1));
        assert_eq!(seed_for(7, 3, 2), seed_for(7, 3, 2));
    }
}
