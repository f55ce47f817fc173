//! What the Foxglove view draws: pure functions from shoal's samples and
//! scenario to Foxglove scene entities. No I/O.

use nalgebra::{UnitQuaternion, Vector3};

use crate::foxglove::{
    entity, line, meta, point, pose, pose_at, rgba, sphere, vector, ArrowPrimitive, Color,
    CubePrimitive, CylinderPrimitive, LineType, SceneEntity, TextPrimitive, Time,
    TriangleListPrimitive,
};
use crate::frames::{body_frame, level_frame, level_rotation, to_foxglove, NED_FRAME};

/// Obstacles: sandy, half transparent.
const OBSTACLE: Color = rgba(0.76, 0.62, 0.42, 0.55);
/// The leader's hull.
const LEADER: Color = rgba(0.95, 0.55, 0.10, 1.0);
/// A follower's hull.
const FOLLOWER: Color = rgba(0.20, 0.50, 0.95, 1.0);
/// Beacon lights on a parent's hull.
const BEACON: Color = rgba(1.0, 0.95, 0.3, 1.0);
/// A slot the follower is steering to.
const SLOT: Color = rgba(0.2, 0.9, 0.4, 0.85);
/// A slot shifted for an obstacle (the follower is avoiding).
const SLOT_AVOIDING: Color = rgba(1.0, 0.6, 0.1, 0.9);
/// The nominal slot (scenario's), ghosted.
const SLOT_NOMINAL: Color = rgba(0.8, 0.8, 0.8, 0.3);
/// The follower-to-slot error line.
const SLOT_ERROR: Color = rgba(1.0, 1.0, 1.0, 0.8);
/// A sonar beam with an echo.
const ECHO: Color = rgba(1.0, 0.25, 0.2, 1.0);
/// A sonar beam with no echo (drawn to the maximum range).
const NO_ECHO: Color = rgba(0.6, 0.6, 0.6, 0.25);
/// A beacon the camera saw in this frame.
const SEEN: Color = rgba(0.2, 0.95, 0.35, 0.9);
/// A beacon the camera did not see (occluded, out of view or too far).
const UNSEEN: Color = rgba(0.95, 0.2, 0.2, 0.6);

/// A true pose: position NED and attitude body → NED.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruePose {
    /// Position, NED, m.
    pub position: Vector3<f64>,
    /// Attitude, body → NED.
    pub attitude: UnitQuaternion<f64>,
}

impl TruePose {
    /// A body-frame point in NED.
    pub fn body_to_ned(&self, p_body: [f64; 3]) -> Vector3<f64> {
        self.attitude * Vector3::from(p_body) + self.position
    }
}

/// One obstacle of the scenario (shoal's sonar type), as an entity in `ned`.
pub fn obstacle_entity(t: Time, index: usize, obstacle: &sonar::Obstacle) -> SceneEntity {
    let mut e = entity(t, NED_FRAME, format!("obstacle/{index}"), false);
    meta(&mut e, "kind", obstacle.kind());
    match obstacle {
        sonar::Obstacle::Box {
            center_ned_m,
            half_extents_m,
            yaw_deg,
        } => e.cubes.push(CubePrimitive {
            pose: pose(
                *center_ned_m,
                to_foxglove(&level_rotation(yaw_deg.to_radians())),
            ),
            size: Some(vector(half_extents_m.map(|h| 2.0 * h))),
            color: Some(OBSTACLE),
        }),
        sonar::Obstacle::Cylinder {
            center_ned_m,
            radius_m,
            half_height_m,
        } => e.cylinders.push(CylinderPrimitive {
            // Foxglove's cylinder axis is its z: NED z, vertical, as shoal's.
            pose: pose_at(*center_ned_m),
            size: Some(vector([
                2.0 * radius_m,
                2.0 * radius_m,
                2.0 * half_height_m,
            ])),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color: Some(OBSTACLE),
        }),
        sonar::Obstacle::Sphere {
            center_ned_m,
            radius_m,
        } => e
            .spheres
            .push(sphere(*center_ned_m, [2.0 * radius_m; 3], OBSTACLE)),
        sonar::Obstacle::Mesh {
            vertices_ned_m,
            triangles,
        } => e.triangles.push(TriangleListPrimitive {
            pose: pose_at([0.0; 3]),
            points: vertices_ned_m.iter().map(|v| point(*v)).collect(),
            color: Some(OBSTACLE),
            colors: Vec::new(),
            indices: triangles.iter().flatten().copied().collect(),
        }),
    }
    e
}

/// What the view needs to draw a vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleLook {
    /// Name.
    pub name: String,
    /// True for the leader (no parent).
    pub leader: bool,
    /// Beacon positions in its body frame if some follower watches it.
    pub beacons_body_m: Vec<[f64; 3]>,
    /// Hull length tip to tip, m.
    pub hull_length_m: f64,
    /// Hull radius, m.
    pub hull_radius_m: f64,
}

/// A vehicle model in its body frame (frame-locked, so it moves with `/tf`):
/// the hull as a cylinder along body x, an arrow out of the nose, its name,
/// and its beacons.
pub fn vehicle_entity(t: Time, v: &VehicleLook) -> SceneEntity {
    let mut e = entity(t, &body_frame(&v.name), format!("vehicle/{}", v.name), true);
    meta(&mut e, "role", if v.leader { "leader" } else { "follower" });
    let color = if v.leader { LEADER } else { FOLLOWER };
    // The cylinder's axis is its z: a quarter turn about y brings z onto x.
    let along_x = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    e.cylinders.push(CylinderPrimitive {
        pose: pose([0.0; 3], to_foxglove(&along_x)),
        size: Some(vector([
            2.0 * v.hull_radius_m,
            2.0 * v.hull_radius_m,
            v.hull_length_m,
        ])),
        bottom_scale: 1.0,
        top_scale: 0.6,
        color: Some(color),
    });
    e.arrows.push(ArrowPrimitive {
        pose: pose_at([v.hull_length_m / 2.0, 0.0, 0.0]),
        shaft_length: 0.8,
        shaft_diameter: 0.08,
        head_length: 0.35,
        head_diameter: 0.25,
        color: Some(color),
    });
    e.texts.push(TextPrimitive {
        // Above the hull: body z is down.
        pose: pose_at([0.0, 0.0, -(v.hull_radius_m + 0.6)]),
        billboard: true,
        font_size: 14.0,
        scale_invariant: true,
        color: Some(rgba(1.0, 1.0, 1.0, 1.0)),
        text: v.name.clone(),
    });
    for b in &v.beacons_body_m {
        e.spheres.push(sphere(*b, [0.15; 3], BEACON));
    }
    e
}

/// The slots of one follower, from a `planner_state` sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlotView {
    /// The slot the planner steers to (eq. 9, filtered), parent level frame, m.
    pub filtered_m: [f64; 3],
    /// The nominal slot, parent level frame, m.
    pub nominal_m: [f64; 3],
    /// Shifting to avoid an obstacle.
    pub avoiding: bool,
    /// The planner's parent estimate is valid.
    pub parent_valid: bool,
    /// Planner mode number.
    pub mode: u32,
}

/// A follower's slot in its parent's level frame (the planner's frame; it
/// follows the parent): the slot it steers to, the nominal one ghosted, and
/// a line from the slot to where the follower truly is (the slot error).
pub fn slot_entity(
    t: Time,
    follower: &str,
    parent: &str,
    slot: &SlotView,
    follower_pose: &TruePose,
    parent_pose: &TruePose,
) -> SceneEntity {
    let mut e = entity(t, &level_frame(parent), format!("slot/{follower}"), true);
    let yaw = crate::frames::yaw_of(&parent_pose.attitude);
    let here = level_rotation(yaw).inverse() * (follower_pose.position - parent_pose.position);
    let err = (here - Vector3::from(slot.filtered_m)).norm();
    meta(&mut e, "follower", follower);
    meta(&mut e, "parent", parent);
    meta(&mut e, "mode", slot.mode);
    meta(&mut e, "avoiding", slot.avoiding);
    meta(&mut e, "parent_estimate_valid", slot.parent_valid);
    meta(&mut e, "slot_error_m", format!("{err:.3}"));
    let slot_colour = if slot.avoiding { SLOT_AVOIDING } else { SLOT };
    e.spheres
        .push(sphere(slot.filtered_m, [0.5; 3], slot_colour));
    e.spheres
        .push(sphere(slot.nominal_m, [0.5; 3], SLOT_NOMINAL));
    e.lines.push(line(
        LineType::LineStrip,
        0.04,
        vec![point(slot.filtered_m), point([here.x, here.y, here.z])],
        SLOT_ERROR,
        Vec::new(),
    ));
    e
}

/// One sonar scan, from a `sonar` sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanView {
    /// Per beam: azimuth (+ starboard), elevation (+ down), rad; range, m, if it echoed.
    pub beams: Vec<(f64, f64, Option<f64>)>,
    /// Where the beams start, body frame, m.
    pub mount_body_m: [f64; 3],
    /// How far a beam with no echo is drawn, m.
    pub range_max_m: f64,
}

/// A beam direction in the body frame (azimuth + starboard, elevation + down).
pub fn beam_direction(azimuth_rad: f64, elevation_rad: f64) -> Vector3<f64> {
    Vector3::new(
        elevation_rad.cos() * azimuth_rad.cos(),
        elevation_rad.cos() * azimuth_rad.sin(),
        elevation_rad.sin(),
    )
}

/// The beams of one scan in the vehicle's body frame, placed where the body
/// was at `t` (not frame-locked): echoes red to the return, with a dot at it;
/// beams with no echo faint grey to the maximum range.
pub fn sonar_entity(t: Time, vehicle: &str, scan: &ScanView) -> SceneEntity {
    let mut e = entity(t, &body_frame(vehicle), format!("sonar/{vehicle}"), false);
    let mount = Vector3::from(scan.mount_body_m);
    let mut points = Vec::with_capacity(2 * scan.beams.len());
    let mut colors = Vec::with_capacity(2 * scan.beams.len());
    let mut echoes = Vec::new();
    for (i, (az, el, range)) in scan.beams.iter().enumerate() {
        let dir = beam_direction(*az, *el);
        let (len, color) = match range {
            Some(r) => (*r, ECHO),
            None => (scan.range_max_m, NO_ECHO),
        };
        let end = mount + dir * len;
        points.push(point([mount.x, mount.y, mount.z]));
        points.push(point([end.x, end.y, end.z]));
        colors.extend([color, color]);
        if let Some(r) = range {
            echoes.push(format!("{i}:{r:.2}"));
            e.spheres
                .push(sphere([end.x, end.y, end.z], [0.3; 3], ECHO));
        }
    }
    meta(
        &mut e,
        "echoes_m",
        if echoes.is_empty() {
            "none".to_string()
        } else {
            echoes.join(" ")
        },
    );
    e.lines
        .push(line(LineType::LineList, 0.05, points, ECHO, colors));
    e
}

/// The camera's line of sight from a follower to each beacon of its parent,
/// in `ned` at the camera frame's time: green where the frame saw the beacon,
/// red where it did not.
pub fn line_of_sight_entity(
    t: Time,
    follower: &str,
    parent: &str,
    camera_ned: &Vector3<f64>,
    beacons: &[(Vector3<f64>, bool)],
) -> SceneEntity {
    let mut e = entity(t, NED_FRAME, format!("los/{follower}"), false);
    let seen = beacons.iter().filter(|(_, v)| *v).count();
    meta(&mut e, "follower", follower);
    meta(&mut e, "parent", parent);
    meta(&mut e, "visible", format!("{seen}/{}", beacons.len()));
    let cam = point([camera_ned.x, camera_ned.y, camera_ned.z]);
    let mut points = Vec::with_capacity(2 * beacons.len());
    let mut colors = Vec::with_capacity(2 * beacons.len());
    for (b, visible) in beacons {
        let c = if *visible { SEEN } else { UNSEEN };
        points.push(cam);
        points.push(point([b.x, b.y, b.z]));
        colors.extend([c, c]);
    }
    e.lines
        .push(line(LineType::LineList, 0.03, points, SEEN, colors));
    e
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn pose(p: [f64; 3], yaw_deg: f64) -> TruePose {
        TruePose {
            position: Vector3::from(p),
            attitude: level_rotation(yaw_deg.to_radians()),
        }
    }

    #[test]
    fn beam_directions_follow_the_sonar_convention() {
        // +30° azimuth is forward-starboard; +90° elevation is straight down.
        let d = beam_direction(30f64.to_radians(), 0.0);
        assert_relative_eq!(
            d,
            Vector3::new(30f64.to_radians().cos(), 0.5, 0.0),
            epsilon = 1e-12
        );
        let d = beam_direction(0.0, std::f64::consts::FRAC_PI_2);
        assert_relative_eq!(d, Vector3::new(0.0, 0.0, 1.0), epsilon = 1e-12);
    }

    #[test]
    fn sonar_lines_end_at_the_echo_or_the_maximum_range() {
        let scan = ScanView {
            beams: vec![
                (0.0, 0.0, Some(5.0)),
                (std::f64::consts::FRAC_PI_2, 0.0, None),
            ],
            mount_body_m: [0.8, 0.0, 0.0],
            range_max_m: 20.0,
        };
        let e = sonar_entity(crate::foxglove::time_from_ns(0), "L", &scan);
        assert_eq!(e.frame_id, "L/body");
        let p = &e.lines[0].points;
        assert_eq!(p.len(), 4);
        assert_relative_eq!(p[1].x, 5.8);
        assert_relative_eq!(p[3].y, 20.0, epsilon = 1e-12);
        assert_relative_eq!(p[3].x, 0.8, epsilon = 1e-12);
        assert_eq!(e.lines[0].colors[1], ECHO);
        assert_eq!(e.lines[0].colors[3], NO_ECHO);
        assert_eq!(e.spheres.len(), 1);
    }

    #[test]
    fn slot_error_line_ends_at_the_follower_in_the_parent_level_frame() {
        // Parent at the origin heading east; follower 8 m west and 4 m north of it:
        // in the parent's level frame that is 8 m behind and 4 m to port.
        let parent = pose([0.0, 0.0, 10.0], 90.0);
        let follower = pose([4.0, -8.0, 10.0], 90.0);
        let slot = SlotView {
            filtered_m: [-8.0, -4.0, 0.0],
            nominal_m: [-8.0, -4.0, 0.0],
            avoiding: false,
            parent_valid: true,
            mode: 1,
        };
        let e = slot_entity(
            crate::foxglove::time_from_ns(0),
            "F1",
            "L",
            &slot,
            &follower,
            &parent,
        );
        assert_eq!(e.frame_id, "L/level");
        let end = e.lines[0].points[1];
        assert_relative_eq!(end.x, -8.0, epsilon = 1e-9);
        assert_relative_eq!(end.y, -4.0, epsilon = 1e-9);
        assert_relative_eq!(end.z, 0.0, epsilon = 1e-9);
        let err = e.metadata.iter().find(|k| k.key == "slot_error_m").unwrap();
        assert_eq!(err.value, "0.000");
    }

    #[test]
    fn a_yawed_box_keeps_its_yaw_about_down() {
        let o = sonar::Obstacle::Box {
            center_ned_m: [70.0, -9.0, 10.0],
            half_extents_m: [10.0, 5.0, 15.0],
            yaw_deg: 90.0,
        };
        let e = obstacle_entity(crate::foxglove::time_from_ns(0), 0, &o);
        let c = &e.cubes[0];
        let size = c.size.unwrap();
        assert_eq!((size.x, size.y, size.z), (20.0, 10.0, 30.0));
        // A quarter turn about z: w = z = √½.
        assert_relative_eq!(
            c.pose.unwrap().orientation.unwrap().w,
            std::f64::consts::FRAC_1_SQRT_2
        );
        assert_relative_eq!(
            c.pose.unwrap().orientation.unwrap().z,
            std::f64::consts::FRAC_1_SQRT_2
        );
    }

    #[test]
    fn line_of_sight_colours_by_visibility() {
        let cam = Vector3::new(0.0, 0.0, 0.0);
        let b = [
            (Vector3::new(5.0, 0.0, 0.0), true),
            (Vector3::new(5.0, 1.0, 0.0), false),
        ];
        let e = line_of_sight_entity(crate::foxglove::time_from_ns(0), "F1", "L", &cam, &b);
        assert_eq!(e.lines[0].points.len(), 4);
        assert_eq!(e.lines[0].colors[0], SEEN);
        assert_eq!(e.lines[0].colors[2], UNSEEN);
        assert_eq!(e.metadata[2].value, "1/2");
    }

    #[test]
    fn body_points_go_to_ned_through_the_true_pose() {
        let p = pose([1.0, 2.0, 3.0], 90.0);
        // 1 m forward of a vehicle heading east is 1 m east of it.
        let q = p.body_to_ned([1.0, 0.0, 0.0]);
        assert_relative_eq!(q, Vector3::new(1.0, 3.0, 3.0), epsilon = 1e-12);
    }
}
