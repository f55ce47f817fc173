//! Shared helpers for the integration tests.
#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)] // test code
#![allow(dead_code)]

use camera_pose::{BeaconLayout, BeaconObservation, Camera, CameraConfig};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;

/// A parent pose (body → NED) for a follower at the identity, seen by the
/// default camera (looking along body/north +x): the parent's origin at
/// `range_m` from the camera centre, within ±`max_off_axis_deg` of the
/// optical axis, its attitude within ±`max_yaw_deg` of the follower's heading
/// (pitch and roll ±20°) so that the follower looks at it roughly from behind.
pub fn parent_pose_in_view<R: Rng>(
    camera: &Camera,
    range_m: f64,
    max_off_axis_deg: f64,
    max_yaw_deg: f64,
    rng: &mut R,
) -> Isometry3<f64> {
    let a = max_off_axis_deg.to_radians();
    let ax: f64 = rng.random_range(-a..a);
    let ay: f64 = rng.random_range(-a..a);
    let dir = Vector3::new(ax.tan(), ay.tan(), 1.0).normalize();
    let cam = camera.camera_in_world(&Isometry3::identity());
    let p = cam * Point3::from(dir * range_m);
    let y = max_yaw_deg.to_radians();
    let yaw: f64 = rng.random_range(-y..y);
    let pitch: f64 = rng.random_range(-0.35..0.35);
    let roll: f64 = rng.random_range(-0.35..0.35);
    Isometry3::from_parts(
        Translation3::from(p.coords),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// Noise-free observation of every beacon, or `None` if one is not visible.
pub fn observe_all<R: Rng>(
    camera: &Camera,
    parent: &Isometry3<f64>,
    layout: &BeaconLayout,
    rng: &mut R,
) -> Option<BeaconObservation> {
    let obs = camera.observe(&Isometry3::identity(), parent, layout, &[], rng);
    (obs.visible_count() == layout.positions_body_m.len()).then_some(obs)
}

/// A camera config with a given noise and a long visibility range.
pub fn camera_cfg(noise_px: f64) -> CameraConfig {
    CameraConfig {
        noise_px,
        visibility_range_m: 100.0,
        ..CameraConfig::default()
    }
}

/// Yaw of a rotation (ZYX Euler), rad.
pub fn yaw(q: &UnitQuaternion<f64>) -> f64 {
    q.euler_angles().2
}

/// Smallest absolute difference of two angles, rad.
pub fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}
