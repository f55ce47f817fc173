//! Small frame helpers: heading from an attitude, the level frame, angle wrapping.

use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// Heading (yaw, rad) of a body→NED attitude, ZYX Euler convention (Fossen).
pub fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    q.euler_angles().2
}

/// Wraps an angle to (−π, π].
pub fn wrap(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut x = a.rem_euclid(two_pi);
    if x > std::f64::consts::PI {
        x -= two_pi;
    }
    x
}

/// Rotation about the down axis by `yaw`: level-frame → NED-aligned axes.
pub fn rot_z(yaw: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
}

/// A NED-aligned vector expressed in the level frame of heading `yaw`.
pub fn to_level(yaw: f64, v: &Vector3<f64>) -> Vector3<f64> {
    rot_z(yaw).inverse() * v
}

/// A level-frame vector of heading `yaw` expressed in NED-aligned axes.
pub fn from_level(yaw: f64, v: &Vector3<f64>) -> Vector3<f64> {
    rot_z(yaw) * v
}
