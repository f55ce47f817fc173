//! Keeping parents in view: how far off its camera's axis a follower sees its
//! parent's beacons from its slot, and the turn rate that geometry allows the
//! leader (our addition; the paper's leader follows its waypoints' corners).
//!
//! A follower holds its parent's heading, so in a steady formation its parent's
//! beacons sit at a fixed bearing in its image. When the parent turns, the
//! follower's heading lags behind (its observer estimates the parent's heading
//! from vision, its controller then turns it), and the parent's beacons drift
//! toward the image edge by about `turn rate × lag`. The leader therefore turns
//! no faster than `(margin − reserve) / lag`, the margin being the smallest angle
//! between any follower's view of its parent's beacons and its image edge, the
//! reserve the followers' own keep-in-view margin (`[follower] view_margin_deg`):
//! in a steady turn no follower has to leave its slot's heading to keep its
//! parent in view, and the heading loop's lag behind a follower's keep-in-view
//! target has that reserve to spend. A corner of the route is flown as an arc of
//! radius `speed / rate`.

/// Lag of a follower's heading behind its parent's in a turn, s: the vision
/// observer's delay plus the heading loop's and the heading headway's.
/// Measured on the generated turn course `turn0` (paper formation, leader
/// turning at 2.8°/s): the outer follower's heading trailed the leader's by
/// 14-18°, i.e. 5-6 s.
pub const VIEW_LAG_S: f64 = 5.0;
/// Smallest margin used, rad (a formation with its parents at the image edge
/// still gets a finite radius).
pub const MIN_MARGIN_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// Largest horizontal bearing (rad, off the camera's axis) of any of the
/// parent's beacons (`beacons`, parent body frame) seen from a camera at
/// `camera_mount` (follower body frame) of a follower at `slot` (parent
/// frame), both on the same heading.
pub fn parent_bearing_rad(slot: [f64; 3], beacons: &[[f64; 3]], camera_mount: [f64; 3]) -> f64 {
    beacons
        .iter()
        .map(|b| {
            let dx = b[0] - (slot[0] + camera_mount[0]);
            let dy = b[1] - (slot[1] + camera_mount[1]);
            dy.abs().atan2(dx)
        })
        .fold(0.0, f64::max)
}

/// The smallest angle between any follower's view of its parent and its
/// image edge (`half_fov_rad` off axis), rad; `None` without followers.
pub fn view_margin_rad(
    slots: impl IntoIterator<Item = [f64; 3]>,
    beacons: &[[f64; 3]],
    camera_mount: [f64; 3],
    half_fov_rad: f64,
) -> Option<f64> {
    slots
        .into_iter()
        .map(|s| half_fov_rad - parent_bearing_rad(s, beacons, camera_mount))
        .reduce(f64::min)
}

/// The radius of the leader's turns at `speed_mps` for a view margin and the
/// followers' reserve, m: `speed / ((margin − reserve) / VIEW_LAG_S)`.
pub fn turn_radius_m(margin_rad: f64, reserve_rad: f64, speed_mps: f64) -> f64 {
    speed_mps * VIEW_LAG_S / (margin_rad - reserve_rad).max(MIN_MARGIN_RAD)
}

/// The leader's turn radius at `speed_mps` for followers at `slots` (each in its
/// parent's frame) seen by `camera` with the parent's `beacons`, keeping the
/// followers' `reserve_rad`, m; 0 (sharp corners) without followers. What
/// `shoal run` flies and `shoal gen` lays its courses out for.
pub fn formation_turn_radius_m(
    slots: impl IntoIterator<Item = [f64; 3]>,
    camera: &camera_pose::CameraConfig,
    beacons: &camera_pose::BeaconLayout,
    reserve_rad: f64,
    speed_mps: f64,
) -> f64 {
    view_margin_rad(
        slots,
        &beacons.positions_body_m,
        camera.mount_position_body_m,
        camera.fov_deg.to_radians() / 2.0,
    )
    .map_or(0.0, |m| turn_radius_m(m, reserve_rad, speed_mps))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    const BEACONS: [[f64; 3]; 4] = [
        [-1.50, 0.00, 0.00],
        [-1.00, 0.00, -0.40],
        [-1.25, 0.40, 0.00],
        [-1.25, -0.40, 0.00],
    ];

    #[test]
    fn the_papers_followers_see_their_parents_about_39_degrees_off_axis() {
        let b = parent_bearing_rad([-8.0, -4.0, 0.0], &BEACONS, [1.4, 0.0, 0.0]).to_degrees();
        assert!((b - 39.4).abs() < 0.2, "{b}");
        let m = view_margin_rad(
            [[-8.0, -4.0, 0.0], [-8.0, 4.0, 0.0]],
            &BEACONS,
            [1.4, 0.0, 0.0],
            45f64.to_radians(),
        )
        .unwrap();
        assert!((m.to_degrees() - 5.6).abs() < 0.2, "{}", m.to_degrees());
    }

    #[test]
    fn a_smaller_margin_means_wider_turns() {
        let wide = turn_radius_m(2f64.to_radians(), 0.0, 1.0);
        let tight = turn_radius_m(10f64.to_radians(), 0.0, 1.0);
        assert!(wide > tight && tight > 0.0);
        assert!(turn_radius_m(-1.0, 0.0, 1.0).is_finite());
        // the followers' reserve comes off the margin
        let reserved = turn_radius_m(10f64.to_radians(), 3f64.to_radians(), 1.0);
        assert_relative_eq!(reserved, turn_radius_m(7f64.to_radians(), 0.0, 1.0));
        assert!(turn_radius_m(3f64.to_radians(), 3f64.to_radians(), 1.0).is_finite());
        assert!(view_margin_rad([], &BEACONS, [1.4, 0.0, 0.0], 0.7).is_none());
    }
}
