//! The frames of the Foxglove view and the one conversion between shoal's
//! NED world and the frame Foxglove displays.
//!
//! Foxglove's 3D panel takes +z as up. shoal's world is NED (x north, y east,
//! z down; right-handed, but z down), so the export publishes a fixed root
//! frame [`WORLD_FRAME`] that is **ENU** (x east, y north, z up, as ROS
//! REP-103), and one fixed transform `world → ned` ([`world_from_ned`]).
//! Every other frame and entity is written in shoal's own axes, under
//! `ned`: a vehicle's body frame `<V>/body` (FRD: x forward, y starboard,
//! z down) with its true pose, its level frame `<V>/level` (the planner's:
//! origin at the vehicle, x along its heading on the horizontal, z down),
//! and obstacles in `ned`. So the only conversion is this fixed rotation,
//! which Foxglove applies; [`ned_to_world`] is the same map written out.

use nalgebra::{Quaternion as NQuat, UnitQuaternion, Vector3};

use crate::foxglove::{vector, FrameTransform, Quaternion, Time};

/// The display root: ENU, z up. Pick it as Foxglove's display frame.
pub const WORLD_FRAME: &str = "world";
/// shoal's world frame: NED.
pub const NED_FRAME: &str = "ned";

/// A vehicle's body frame (FRD), `<V>/body`.
pub fn body_frame(vehicle: &str) -> String {
    format!("{vehicle}/body")
}

/// A vehicle's level frame (heading only, z down), `<V>/level`.
pub fn level_frame(vehicle: &str) -> String {
    format!("{vehicle}/level")
}

/// The orientation of the NED axes in the ENU world: the rotation `R` with
/// `p_world = R · p_ned`, i.e. north → +y, east → +x, down → −z. It is a
/// half turn about the axis `(1, 1, 0)/√2`: `w = 0, x = y = √½, z = 0`.
pub fn world_from_ned() -> UnitQuaternion<f64> {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    UnitQuaternion::new_unchecked(NQuat::new(0.0, h, h, 0.0))
}

/// A NED point or vector in the ENU world: `(n, e, d) → (e, n, −d)`: what
/// the published `world → ned` transform does, written out (the tests hold
/// the two equal).
#[cfg(test)]
pub fn ned_to_world(p: [f64; 3]) -> [f64; 3] {
    [p[1], p[0], -p[2]]
}

/// A nalgebra quaternion in Foxglove's `{x, y, z, w}` layout.
pub fn to_foxglove(q: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

/// The heading (ZYX yaw) of a body → NED attitude, rad, as the planner
/// computes it.
pub fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    q.euler_angles().2
}

/// The rotation about NED z (down) by `yaw`: level → NED axes.
pub fn level_rotation(yaw: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
}

/// The fixed `world → ned` transform at `t`.
pub fn world_to_ned_transform(t: Time) -> FrameTransform {
    FrameTransform {
        timestamp: Some(t),
        parent_frame_id: WORLD_FRAME.to_string(),
        child_frame_id: NED_FRAME.to_string(),
        translation: Some(vector([0.0; 3])),
        rotation: Some(to_foxglove(&world_from_ned())),
    }
}

/// `parent → child` with the child at `position` (parent axes) and orientation `q`.
pub fn transform(
    t: Time,
    parent: &str,
    child: String,
    position: [f64; 3],
    q: &UnitQuaternion<f64>,
) -> FrameTransform {
    FrameTransform {
        timestamp: Some(t),
        parent_frame_id: parent.to_string(),
        child_frame_id: child,
        translation: Some(vector(position)),
        rotation: Some(to_foxglove(q)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::unit_wxyz;
    use approx::assert_relative_eq;
    use nalgebra::Point3;

    fn world_of(p_ned: [f64; 3]) -> [f64; 3] {
        let v = world_from_ned() * Vector3::from(p_ned);
        [v.x, v.y, v.z]
    }

    #[test]
    fn ned_axes_land_on_enu_axes() {
        // north is ENU +y, east is ENU +x, down is ENU −z.
        assert_relative_eq!(
            Vector3::from(world_of([1.0, 0.0, 0.0])),
            Vector3::new(0.0, 1.0, 0.0),
            epsilon = 1e-12
        );
        assert_relative_eq!(
            Vector3::from(world_of([0.0, 1.0, 0.0])),
            Vector3::new(1.0, 0.0, 0.0),
            epsilon = 1e-12
        );
        assert_relative_eq!(
            Vector3::from(world_of([0.0, 0.0, 1.0])),
            Vector3::new(0.0, 0.0, -1.0),
            epsilon = 1e-12
        );
    }

    #[test]
    fn the_published_rotation_is_the_written_out_map() {
        // 3 m north, 4 m east, 5 m deep → x = 4 (east), y = 3 (north), z = −5 (up).
        assert_eq!(ned_to_world([3.0, 4.0, 5.0]), [4.0, 3.0, -5.0]);
        for p in [[3.0, 4.0, 5.0], [-1.5, 0.25, -7.0], [70.0, -9.0, 10.0]] {
            assert_relative_eq!(
                Vector3::from(world_of(p)),
                Vector3::from(ned_to_world(p)),
                epsilon = 1e-12
            );
        }
        // A proper rotation (det +1), so Foxglove can use it as a transform.
        let m = world_from_ned().to_rotation_matrix();
        assert_relative_eq!(m.matrix().determinant(), 1.0, epsilon = 1e-12);
        let f = world_to_ned_transform(crate::foxglove::time_from_ns(0))
            .rotation
            .unwrap();
        assert_eq!((f.w, f.z), (0.0, 0.0));
        assert_relative_eq!(f.x, f.y);
    }

    /// world ← ned ← body, the chain Foxglove composes from `/tf`.
    fn body_point_in_world(pos_ned: [f64; 3], q_wxyz: [f64; 4], p_body: [f64; 3]) -> [f64; 3] {
        let q = unit_wxyz(q_wxyz).unwrap();
        let p_ned = q * Point3::from(p_body) + Vector3::from(pos_ned);
        let v = world_from_ned() * p_ned.coords;
        [v.x, v.y, v.z]
    }

    #[test]
    fn a_vehicle_heading_east_points_along_world_x() {
        // Heading 90°: body → NED is a quarter turn about NED z (down).
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let q = [h, 0.0, 0.0, h];
        // Its origin at NED (10, 5, 3) is world (5, 10, −3).
        let o = body_point_in_world([10.0, 5.0, 3.0], q, [0.0; 3]);
        assert_relative_eq!(
            Vector3::from(o),
            Vector3::new(5.0, 10.0, -3.0),
            epsilon = 1e-12
        );
        // 1 m ahead of it is 1 m further east: NED (10, 6, 3) → world (6, 10, −3).
        let a = body_point_in_world([10.0, 5.0, 3.0], q, [1.0, 0.0, 0.0]);
        assert_relative_eq!(
            Vector3::from(a),
            Vector3::new(6.0, 10.0, -3.0),
            epsilon = 1e-12
        );
        // 1 m to its starboard is 1 m south: world y − 1.
        let s = body_point_in_world([10.0, 5.0, 3.0], q, [0.0, 1.0, 0.0]);
        assert_relative_eq!(
            Vector3::from(s),
            Vector3::new(5.0, 9.0, -3.0),
            epsilon = 1e-12
        );
        // 1 m below it (body z) is 1 m lower in the world.
        let d = body_point_in_world([10.0, 5.0, 3.0], q, [0.0, 0.0, 1.0]);
        assert_relative_eq!(
            Vector3::from(d),
            Vector3::new(5.0, 10.0, -4.0),
            epsilon = 1e-12
        );
        assert_relative_eq!(yaw_of(&unit_wxyz(q).unwrap()), std::f64::consts::FRAC_PI_2);
    }

    #[test]
    fn nose_up_pitch_points_up_in_the_world() {
        // Pitch +30° (Fossen: positive pitch raises the nose), heading north.
        let th = 30f64.to_radians();
        let q = [(th / 2.0).cos(), 0.0, (th / 2.0).sin(), 0.0];
        let a = body_point_in_world([0.0; 3], q, [1.0, 0.0, 0.0]);
        // NED (cos 30°, 0, −sin 30°) → world (0, cos 30°, +sin 30°): north and up.
        assert_relative_eq!(
            Vector3::from(a),
            Vector3::new(0.0, th.cos(), th.sin()),
            epsilon = 1e-12
        );
    }

    #[test]
    fn quaternion_order_and_level_frame() {
        // shoal's [w, x, y, z] becomes Foxglove's {x, y, z, w}.
        let q = unit_wxyz([2.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(to_foxglove(&q), crate::foxglove::IDENTITY);
        let c = 0.8f64;
        let s = 0.6f64;
        let f = to_foxglove(&unit_wxyz([c, s, 0.0, 0.0]).unwrap());
        assert_relative_eq!(f.w, c);
        assert_relative_eq!(f.x, s);
        assert!(unit_wxyz([0.0; 4]).is_none());
        assert!(unit_wxyz([f64::NAN, 0.0, 0.0, 1.0]).is_none());
        // The level frame of heading 90° maps level x (forward) to NED east.
        let v = level_rotation(std::f64::consts::FRAC_PI_2) * Vector3::new(1.0, 0.0, 0.0);
        assert_relative_eq!(v, Vector3::new(0.0, 1.0, 0.0), epsilon = 1e-12);
    }
}
