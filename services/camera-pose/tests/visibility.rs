//! What the camera sees: field of view, range, behind the camera, occlusion
//! by other vehicles' hulls, pixel noise.
#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)] // test code

mod common;

use approx::assert_relative_eq;
use camera_pose::*;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The parent `ahead_m` in front of the camera (north, follower at the
/// origin heading north), same heading.
fn parent_ahead(ahead_m: f64) -> Isometry3<f64> {
    // Camera at x = 1.4 m; the beacons are at x ∈ [-1.5, -1.0] of the parent.
    Isometry3::translation(1.4 + ahead_m + 1.25, 0.0, 0.0)
}

fn rng() -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(99)
}

#[test]
fn all_beacons_visible_in_clear_water() {
    let camera = Camera::new(&CameraConfig::default()).unwrap();
    let layout = BeaconLayout::default();
    let obs = camera.observe(
        &Isometry3::identity(),
        &parent_ahead(6.0),
        &layout,
        &[],
        &mut rng(),
    );
    assert_eq!(obs.count, 4);
    assert_eq!(obs.visible_count(), 4);
}

#[test]
fn a_vehicle_between_camera_and_beacons_hides_them() {
    let camera = Camera::new(&CameraConfig::default()).unwrap();
    let layout = BeaconLayout::default();
    let hull = HullConfig::default();
    let parent = parent_ahead(8.0);
    // A third vehicle crossing 4 m ahead of the camera, broadside (heading east).
    let crossing = Isometry3::from_parts(
        Translation3::new(1.4 + 4.0, 0.0, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
    );
    let occ = [hull.capsule(&crossing)];
    let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &occ, &mut rng());
    assert_eq!(obs.visible_count(), 0, "{obs:?}");
    assert!(obs.visible.iter().all(|v| !v));

    let cam_world = camera.camera_in_world(&Isometry3::identity());
    assert_eq!(
        camera
            .beacon_status(&cam_world, &parent, &layout, 0, &occ)
            .0,
        BeaconStatus::Occluded
    );

    // The same vehicle 3 m to the side no longer hides anything.
    let aside = Isometry3::from_parts(Translation3::new(1.4 + 4.0, 3.0, 0.0), crossing.rotation);
    let occ = [hull.capsule(&aside)];
    let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &occ, &mut rng());
    assert_eq!(obs.visible_count(), 4);

    // Nor does it behind the parent, or behind the camera.
    for x in [1.4 + 8.0 + 3.5, -3.0] {
        let occ = [hull.capsule(&Isometry3::from_parts(
            Translation3::new(x, 0.0, 0.0),
            crossing.rotation,
        ))];
        let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &occ, &mut rng());
        assert_eq!(obs.visible_count(), 4, "occluder at x = {x}");
    }
}

#[test]
fn a_thin_occluder_hides_only_the_beacon_behind_it() {
    let camera = Camera::new(&CameraConfig::default()).unwrap();
    let layout = BeaconLayout::default();
    let parent = parent_ahead(8.0);
    let cam = Point3::new(1.4, 0.0, 0.0);
    let b2 = parent * Point3::from(layout.positions_body_m[2]);
    let mid = cam + (b2 - cam) * 0.5;
    // A vertical pole of radius 0.1 m on the ray to beacon 2, at mid-range.
    let pole = Capsule {
        a: mid + Vector3::new(0.0, 0.0, -2.0),
        b: mid + Vector3::new(0.0, 0.0, 2.0),
        radius_m: 0.1,
    };
    let obs = camera.observe(
        &Isometry3::identity(),
        &parent,
        &layout,
        &[pole],
        &mut rng(),
    );
    assert_eq!(
        obs.visible,
        [true, true, false, true, false, false, false, false]
    );
    assert_eq!(obs.pixels[2], [0.0, 0.0]);
}

#[test]
fn beacons_beyond_the_visibility_range_are_not_seen() {
    let cfg = CameraConfig {
        visibility_range_m: 12.0,
        ..CameraConfig::default()
    };
    let camera = Camera::new(&cfg).unwrap();
    let layout = BeaconLayout::default();
    // Beacon 0 (tail tip) is 11.75 m from the camera; beacon 1 (x = -1.0)
    // is 12.26 m; beacons 2, 3 at about 12.01 m.
    let parent = Isometry3::translation(1.4 + 11.75 + 1.5, 0.0, 0.0);
    let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &[], &mut rng());
    assert_eq!(obs.visible[..4], [true, false, false, false]);
    let cam_world = camera.camera_in_world(&Isometry3::identity());
    assert_eq!(
        camera.beacon_status(&cam_world, &parent, &layout, 1, &[]).0,
        BeaconStatus::BeyondRange
    );
    // Closer, all are seen.
    let obs = camera.observe(
        &Isometry3::identity(),
        &parent_ahead(10.0),
        &layout,
        &[],
        &mut rng(),
    );
    assert_eq!(obs.visible_count(), 4);
}

#[test]
fn beacons_outside_the_field_of_view_are_not_seen() {
    let camera = Camera::new(&CameraConfig::default()).unwrap();
    let layout = BeaconLayout::default();
    // 90° horizontal FOV: a parent 5 m ahead and 6 m to starboard is at
    // about 50° off axis.
    let parent = Isometry3::translation(1.4 + 5.0 + 1.25, 6.0, 0.0);
    let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &[], &mut rng());
    assert_eq!(obs.visible_count(), 0);
    let cam_world = camera.camera_in_world(&Isometry3::identity());
    assert_eq!(
        camera.beacon_status(&cam_world, &parent, &layout, 0, &[]).0,
        BeaconStatus::OutsideImage
    );
    // With the beacons about 38° off axis they are seen.
    let parent = Isometry3::translation(1.4 + 6.0 + 1.25, 6.0 * 38f64.to_radians().tan(), 0.0);
    let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &[], &mut rng());
    assert_eq!(obs.visible_count(), 4);
    // Turning the camera 40° to starboard centres it in the image.
    let cfg = CameraConfig {
        mount_rpy_deg: [0.0, 0.0, 40.0],
        noise_px: 0.0,
        ..CameraConfig::default()
    };
    let turned = Camera::new(&cfg).unwrap();
    let far_right = Isometry3::translation(
        1.4 + 5.0 * 40f64.to_radians().cos(),
        5.0 * 40f64.to_radians().sin(),
        0.0,
    );
    let cam_world = turned.camera_in_world(&Isometry3::identity());
    let (status, px) =
        turned.point_status(&cam_world, &Point3::from(far_right.translation.vector), &[]);
    assert_eq!(status, BeaconStatus::Visible);
    assert_relative_eq!(px[0], 256.0, epsilon = 1e-9);
    assert_relative_eq!(px[1], 256.0, epsilon = 1e-9);
}

#[test]
fn beacons_behind_the_camera_are_not_seen() {
    let camera = Camera::new(&CameraConfig::default()).unwrap();
    let layout = BeaconLayout::default();
    let parent = Isometry3::translation(-6.0, 0.0, 0.0);
    let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &[], &mut rng());
    assert_eq!(obs.visible_count(), 0);
    let cam_world = camera.camera_in_world(&Isometry3::identity());
    assert_eq!(
        camera.beacon_status(&cam_world, &parent, &layout, 0, &[]).0,
        BeaconStatus::BehindCamera
    );
}

#[test]
fn projection_follows_the_documented_pixel_convention() {
    let cfg = CameraConfig {
        noise_px: 0.0,
        ..CameraConfig::default()
    };
    let camera = Camera::new(&cfg).unwrap();
    // f = 256 / tan(45°) = 256 px.
    assert_relative_eq!(camera.focal_px(), 256.0, epsilon = 1e-9);
    let cam_world = camera.camera_in_world(&Isometry3::identity());
    // 10 m ahead, 1 m to starboard, 2 m below: right and down in the image.
    let p = Point3::new(1.4 + 10.0, 1.0, 2.0);
    let (status, px) = camera.point_status(&cam_world, &p, &[]);
    assert_eq!(status, BeaconStatus::Visible);
    assert_relative_eq!(px[0], 256.0 + 25.6, epsilon = 1e-9);
    assert_relative_eq!(px[1], 256.0 + 51.2, epsilon = 1e-9);
}

#[test]
fn pixel_noise_has_the_configured_sigma_and_is_deterministic() {
    let cfg = CameraConfig {
        noise_px: 1.5,
        ..CameraConfig::default()
    };
    let camera = Camera::new(&cfg).unwrap();
    let exact = Camera::new(&CameraConfig {
        noise_px: 0.0,
        ..cfg.clone()
    })
    .unwrap();
    let layout = BeaconLayout::default();
    let parent = parent_ahead(6.0);
    let truth = exact.observe(&Isometry3::identity(), &parent, &layout, &[], &mut rng());
    let mut r = rng();
    let (mut sum, mut sum_sq, mut n) = (0.0, 0.0, 0.0);
    for _ in 0..5000 {
        let obs = camera.observe(&Isometry3::identity(), &parent, &layout, &[], &mut r);
        for i in 0..4 {
            for k in 0..2 {
                let d = obs.pixels[i][k] - truth.pixels[i][k];
                sum += d;
                sum_sq += d * d;
                n += 1.0;
            }
        }
    }
    let mean = sum / n;
    let sigma = (sum_sq / n - mean * mean).sqrt();
    assert!(mean.abs() < 0.03, "mean {mean}");
    assert!((sigma / 1.5 - 1.0).abs() < 0.03, "sigma {sigma}");

    let a = camera.observe(&Isometry3::identity(), &parent, &layout, &[], &mut rng());
    let b = camera.observe(&Isometry3::identity(), &parent, &layout, &[], &mut rng());
    assert_eq!(a, b);

    // Hiding beacon 2 leaves the others' noise unchanged.
    let b2 = parent * Point3::from(layout.positions_body_m[2]);
    let cam = Point3::new(1.4, 0.0, 0.0);
    let mid = cam + (b2 - cam) * 0.5;
    let pole = Capsule {
        a: mid + Vector3::new(0.0, 0.0, -2.0),
        b: mid + Vector3::new(0.0, 0.0, 2.0),
        radius_m: 0.1,
    };
    let c = camera.observe(
        &Isometry3::identity(),
        &parent,
        &layout,
        &[pole],
        &mut rng(),
    );
    assert!(!c.visible[2]);
    for i in [0, 1, 3] {
        assert_eq!(a.pixels[i], c.pixels[i]);
    }
}

#[test]
fn hull_capsule_runs_along_body_x() {
    let hull = HullConfig::default();
    let pose = Isometry3::from_parts(
        Translation3::new(10.0, 5.0, 2.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
    );
    let c = hull.capsule(&pose);
    // Heading east: the axis runs east-west, 1.2 m each side.
    assert_relative_eq!(c.a, Point3::new(10.0, 3.8, 2.0), epsilon = 1e-12);
    assert_relative_eq!(c.b, Point3::new(10.0, 6.2, 2.0), epsilon = 1e-12);
    assert_relative_eq!(c.radius_m, 0.3);
    // Tip to tip: 2 × 1.2 + 2 × 0.3 = 3 m.
    assert_relative_eq!(
        (c.b - c.a).norm() + 2.0 * c.radius_m,
        hull.length_m,
        epsilon = 1e-12
    );
    // A segment grazing the side is blocked, one passing 0.31 m off is not.
    let p = Point3::new(9.71, 0.0, 2.0);
    let q = Point3::new(9.71, 10.0, 2.0);
    assert!(c.blocks_segment(&p, &q));
    let p = Point3::new(9.69, 0.0, 2.0);
    let q = Point3::new(9.69, 10.0, 2.0);
    assert!(!c.blocks_segment(&p, &q));
}

#[test]
fn beacons_seen_from_outside_their_emission_cone_are_not_seen() {
    let camera = Camera::new(&CameraConfig::default()).unwrap();
    let layout = BeaconLayout::default();
    let cam_world = camera.camera_in_world(&Isometry3::identity());
    // The parent 8 m ahead, facing the follower: its stern lights shine away.
    let facing_us = Isometry3::from_parts(
        Translation3::new(1.4 + 8.0 - 1.25, 0.0, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::PI),
    );
    let obs = camera.observe(&Isometry3::identity(), &facing_us, &layout, &[], &mut rng());
    assert_eq!(obs.visible_count(), 0);
    assert_eq!(
        camera
            .beacon_status(&cam_world, &facing_us, &layout, 0, &[])
            .0,
        BeaconStatus::FacingAway
    );
    // Broadside (parent heading east, 8 m ahead): 90° from aft, inside the
    // default 100° cone, so seen.
    let broadside = Isometry3::from_parts(
        Translation3::new(1.4 + 8.0, 1.25, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
    );
    let obs = camera.observe(&Isometry3::identity(), &broadside, &layout, &[], &mut rng());
    assert_eq!(obs.visible_count(), 4);
    // With a 60° cone, broadside is outside.
    let narrow = BeaconLayout {
        emission_half_angle_deg: 60.0,
        ..BeaconLayout::default()
    };
    let obs = camera.observe(&Isometry3::identity(), &broadside, &narrow, &[], &mut rng());
    assert_eq!(obs.visible_count(), 0);
    // Omnidirectional lights are seen even from the front.
    let omni = BeaconLayout {
        emission_half_angle_deg: 180.0,
        ..BeaconLayout::default()
    };
    let obs = camera.observe(&Isometry3::identity(), &facing_us, &omni, &[], &mut rng());
    assert_eq!(obs.visible_count(), 4);
}

proptest::proptest! {
    /// A camera that tests only the hulls in its occlusion zone sees exactly
    /// what it sees when it tests every hull of the group.
    #[test]
    fn the_occlusion_zone_keeps_every_hull_that_hides_a_beacon(
        ahead in 2.0f64..14.0,
        side in -3.0f64..3.0,
        others in proptest::collection::vec((0.0f64..18.0, -5.0f64..5.0, -2.0f64..2.0, -3.2f64..3.2), 1..24),
    ) {
        let camera = Camera::new(&CameraConfig::default()).unwrap();
        let layout = BeaconLayout::default();
        let hull = HullConfig::default();
        let me = Isometry3::identity();
        let parent = Isometry3::translation(1.4 + ahead, side, 0.0);
        let poses: Vec<Isometry3<f64>> = others
            .iter()
            .map(|&(x, y, z, yaw)| {
                Isometry3::from_parts(
                    Translation3::new(x, y, z),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
                )
            })
            .collect();
        let zone = OcclusionZone::new(
            Point3::from(camera.camera_in_world(&me).translation.vector),
            Point3::from(parent.translation.vector),
            layout.reach_m(),
            hull.reach_m(),
        );
        let all: Vec<Capsule> = poses.iter().map(|p| hull.capsule(p)).collect();
        let kept: Vec<Capsule> = poses
            .iter()
            .filter(|p| zone.may_hide(&Point3::from(p.translation.vector)))
            .map(|p| hull.capsule(p))
            .collect();
        let full = camera.observe(&me, &parent, &layout, &all, &mut rng());
        let culled = camera.observe(&me, &parent, &layout, &kept, &mut rng());
        proptest::prop_assert_eq!(full.visible, culled.visible);
        proptest::prop_assert_eq!(full.pixels, culled.pixels);
        // Each dropped hull hides nothing on its own either.
        for p in poses.iter().filter(|p| !zone.may_hide(&Point3::from(p.translation.vector))) {
            let alone = camera.observe(&me, &parent, &layout, &[hull.capsule(p)], &mut rng());
            proptest::prop_assert_eq!(alone.visible_count(), camera.observe(&me, &parent, &layout, &[], &mut rng()).visible_count());
        }
    }
}
