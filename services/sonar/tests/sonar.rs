//! Behaviour of the simulated rangefinders and the obstacle field.

use approx::assert_relative_eq;
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sonar::{Beam, Obstacle, ObstacleField, Sonar, SonarConfig, SonarError, MAX_BEAMS};

fn at(x: f64, y: f64, z: f64, yaw_deg: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()),
    )
}

fn dir(x: f64, y: f64, z: f64) -> Unit<Vector3<f64>> {
    Unit::new_normalize(Vector3::new(x, y, z))
}

/// A wall whose near face is the plane x = `x_face` (north of the origin).
fn wall_north(x_face: f64) -> Obstacle {
    Obstacle::Box {
        center_ned_m: [x_face + 0.5, 0.0, 0.0],
        half_extents_m: [0.5, 100.0, 100.0],
        yaw_deg: 0.0,
    }
}

fn one_beam(az: f64, el: f64) -> SonarConfig {
    SonarConfig {
        beams: vec![Beam {
            azimuth_deg: az,
            elevation_deg: el,
        }],
        mount_position_body_m: [0.0, 0.0, 0.0],
        // a ray: these tests check the geometry of one direction exactly
        beam_width_deg: 0.0,
        ..SonarConfig::default()
    }
}

/// A closed, outward-wound axis-aligned cube mesh of half size `h` centred at `c`.
fn cube_mesh(c: [f64; 3], h: f64) -> Obstacle {
    let mut v = Vec::new();
    for i in 0..8 {
        v.push([
            c[0] + if i & 1 == 0 { -h } else { h },
            c[1] + if i & 2 == 0 { -h } else { h },
            c[2] + if i & 4 == 0 { -h } else { h },
        ]);
    }
    // faces as quads (outward by the right-hand rule), split into triangles
    let quads = [
        [0, 2, 3, 1], // z-
        [4, 5, 7, 6], // z+
        [0, 1, 5, 4], // y-
        [2, 6, 7, 3], // y+
        [0, 4, 6, 2], // x-
        [1, 3, 7, 5], // x+
    ];
    let mut t = Vec::new();
    for q in quads {
        t.push([q[0], q[1], q[2]]);
        t.push([q[0], q[2], q[3]]);
    }
    Obstacle::Mesh {
        vertices_ned_m: v,
        triangles: t,
    }
}

#[test]
fn reads_a_wall_at_a_known_distance_within_three_sigma() {
    let cfg = SonarConfig::default();
    let sonar = Sonar::new(&cfg).unwrap();
    let field = ObstacleField::new(&[wall_north(10.0)]).unwrap();
    let pose = at(0.0, 0.0, 0.0, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let n = 2000;
    let mut sums = [0.0; 4];
    let mut sq = [0.0; 4];
    for _ in 0..n {
        let scan = sonar.scan(&field, &pose, &[], &mut rng);
        assert_eq!(scan.count, 4);
        for i in 0..4 {
            assert!(scan.valid[i]);
            // the transducer sits at x = 0.8 on the nose; the wall's nearest point inside
            // each cone is on its edge nearest to the wall's normal
            let truth = (10.0 - cfg.mount_position_body_m[0]) / off_normal(&cfg, i).cos();
            let err = scan.ranges_m[i] - truth;
            // a single reading: within 3σ except with probability 0.3 %, so check it on
            // the first beam of the first scans only via the mean/std below, and bound
            // every reading by 5σ (probability < 1e-6)
            assert!(err.abs() < 5.0 * cfg.noise_m, "beam {i}: err {err}");
            sums[i] += err;
            sq[i] += err * err;
        }
    }
    for i in 0..4 {
        let mean = sums[i] / n as f64;
        let std = (sq[i] / n as f64 - mean * mean).sqrt();
        // the mean error is within 3σ of its own standard error
        assert!(
            mean.abs() < 3.0 * cfg.noise_m / (n as f64).sqrt(),
            "beam {i} mean {mean}"
        );
        // and the spread is the configured σ
        assert!(
            (std - cfg.noise_m).abs() < 0.1 * cfg.noise_m,
            "beam {i} std {std}"
        );
    }
    // a single noisy reading is within 3σ
    let scan = sonar.scan(&field, &pose, &[], &mut ChaCha8Rng::seed_from_u64(3));
    let truth = (10.0 - 0.8) / off_normal(&cfg, 3).cos();
    assert!((scan.ranges_m[3] - truth).abs() < 3.0 * cfg.noise_m);
}

/// The least angle between beam `i`'s cone and straight ahead, rad.
fn off_normal(cfg: &SonarConfig, i: usize) -> f64 {
    (cfg.beams[i].azimuth_deg.abs() - cfg.beam_width_deg / 2.0)
        .max(0.0)
        .to_radians()
}

/// A vertical cylinder of radius `r` centred at (`x`, `y`), tall enough for any beam.
fn pillar(x: f64, y: f64, r: f64) -> Obstacle {
    Obstacle::Cylinder {
        center_ned_m: [x, y, 0.0],
        radius_m: r,
        half_height_m: 20.0,
    }
}

#[test]
fn cones_see_a_thin_pillar_dead_ahead_that_rays_miss() {
    // a 0.3 m pillar on the track, between the ±10° beams, seen by 25° cones
    let field = ObstacleField::new(&[pillar(12.0, 0.0, 0.3)]).unwrap();
    let pose = at(0.0, 0.0, 0.0, 0.0);
    let cones = Sonar::new(&SonarConfig {
        beam_width_deg: 25.0,
        ..SonarConfig::default()
    })
    .unwrap();
    let rays = Sonar::new(&SonarConfig {
        beam_width_deg: 0.0,
        ..SonarConfig::default()
    })
    .unwrap();
    let c = cones.true_ranges(&field, &pose, &[]);
    let r = rays.true_ranges(&field, &pose, &[]);
    assert!(r.iter().all(Option::is_none), "rays {r:?}");
    // both inner cones hold it; its nearest point is 12 − 0.3 − 0.8 m from the nose
    for i in [1, 2] {
        assert_relative_eq!(c[i].unwrap(), 12.0 - 0.3 - 0.8, epsilon = 1e-9);
    }
    assert!(c[0].is_none() && c[3].is_none(), "outer cones {c:?}");
    // the echo sits 10° off both inner axes
    let e = cones.true_echoes(&field, &pose, &[]);
    assert_relative_eq!(
        e[1].unwrap().off_axis_rad,
        10f64.to_radians(),
        epsilon = 1e-9
    );
    // the default 7° cones see the issue's 0.7 m pillar dead ahead once its side is within
    // their inner edges (6.5° off the heading): from 0.7 / sin 6.5° ≈ 6.2 m, where a ray
    // at 10° sees it from 0.7 / sin 10° ≈ 4.0 m
    let seen_from = |cfg: &SonarConfig| {
        let sonar = Sonar::new(cfg).unwrap();
        (0..400)
            .map(|k| 2.0 + 0.05 * f64::from(k))
            .filter(|d| {
                let f = ObstacleField::new(&[pillar(0.8 + d, 0.0, 0.7)]).unwrap();
                sonar
                    .true_ranges(&f, &pose, &[])
                    .iter()
                    .any(Option::is_some)
            })
            .fold(0.0f64, f64::max)
    };
    let cone = seen_from(&SonarConfig::default());
    let ray = seen_from(&SonarConfig {
        beam_width_deg: 0.0,
        ..SonarConfig::default()
    });
    assert!(
        (cone - 0.7 / 6.5f64.to_radians().sin()).abs() < 0.1,
        "cones from {cone}"
    );
    // that is the blind wedge the layout reports: 6.5° for 7° cones, none for 25°
    let wedge = |w: f64| {
        Sonar::new(&SonarConfig {
            beam_width_deg: w,
            ..SonarConfig::default()
        })
        .unwrap()
        .blind_wedge_rad()
        .to_degrees()
    };
    assert_relative_eq!(wedge(7.0), 6.5, epsilon = 1e-9);
    assert_relative_eq!(wedge(0.0), 10.0, epsilon = 1e-9);
    assert_relative_eq!(wedge(25.0), 0.0);
    // a split beam's return is where it says; a single beam's anywhere in its cone
    let single = SonarConfig {
        split_beam: false,
        ..SonarConfig::default()
    };
    assert_eq!(
        Sonar::new(&SonarConfig::default())
            .unwrap()
            .return_spread_rad(),
        0.0
    );
    assert_relative_eq!(
        Sonar::new(&single).unwrap().return_spread_rad(),
        7f64.to_radians()
    );
    assert!(
        (ray - 0.7 / 10f64.to_radians().sin()).abs() < 0.1,
        "rays from {ray}"
    );
}

#[test]
fn a_split_beam_says_where_in_its_cone_the_echo_came_from() {
    // the paper's passage: a wall at y = 4; the +10° beam's nearest echo is on its outer
    // edge, 13.5° to starboard, 4 / sin 13.5° away
    let field = ObstacleField::new(&[Obstacle::Box {
        center_ned_m: [20.0, 9.0, 0.0],
        half_extents_m: [40.0, 5.0, 20.0],
        yaw_deg: 0.0,
    }])
    .unwrap();
    let mut cfg = one_beam(10.0, 0.0);
    cfg.beam_width_deg = 7.0;
    cfg.noise_m = 0.0;
    cfg.angle_noise_deg = 0.0;
    let pose = at(0.0, 0.0, 0.0, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let split = Sonar::new(&cfg).unwrap().scan(&field, &pose, &[], &mut rng);
    assert_relative_eq!(
        split.ranges_m[0],
        4.0 / 13.5f64.to_radians().sin(),
        epsilon = 1e-3
    );
    assert_relative_eq!(split.azimuth_rad[0], 13.5f64.to_radians(), epsilon = 1e-3);
    // placed along what it reports, the echo is on the wall
    let y = split.ranges_m[0] * split.azimuth_rad[0].sin();
    assert_relative_eq!(y, 4.0, epsilon = 1e-2);
    // a single beam gives its axis: placed there the echo would be 1 m off the wall
    cfg.split_beam = false;
    let single = Sonar::new(&cfg).unwrap().scan(&field, &pose, &[], &mut rng);
    assert_relative_eq!(single.azimuth_rad[0], 10f64.to_radians(), epsilon = 1e-12);
    // the angles are noisy by `angle_noise_deg`
    cfg.split_beam = true;
    cfg.angle_noise_deg = 0.5;
    let sonar = Sonar::new(&cfg).unwrap();
    let n = 2000;
    let errs: Vec<f64> = (0..n)
        .map(|_| sonar.scan(&field, &pose, &[], &mut rng).azimuth_rad[0] - 13.5f64.to_radians())
        .collect();
    let sd = (errs.iter().map(|e| e * e).sum::<f64>() / f64::from(n)).sqrt();
    assert!(
        (sd.to_degrees() - 0.5).abs() < 0.05,
        "angle noise {}",
        sd.to_degrees()
    );
}

#[test]
fn a_cone_sees_nothing_outside_its_edge() {
    let mut cfg = one_beam(0.0, 0.0);
    cfg.beam_width_deg = 20.0;
    let sonar = Sonar::new(&cfg).unwrap();
    let pose = at(0.0, 0.0, 0.0, 0.0);
    // a 0.2 m pillar centred 9° off the axis (inside the 10° half width) and one 12° off
    // (its near side spans 12° ± 1.1°: wholly outside)
    for (deg, inside) in [(9.0f64, true), (12.0, false)] {
        let r = 0.2;
        let d = 10.0;
        let (s, c) = deg.to_radians().sin_cos();
        // its nearest point is `d` from the apex, on the given bearing
        let field = ObstacleField::new(&[pillar((d + r) * c, (d + r) * s, r)]).unwrap();
        let got = sonar.true_ranges(&field, &pose, &[])[0];
        assert_eq!(got.is_some(), inside, "{deg}°: {got:?}");
        if let Some(g) = got {
            assert_relative_eq!(g, d, epsilon = 1e-6);
        }
    }
}

#[test]
fn dropouts_are_likelier_toward_the_edge_and_false_echoes_come_at_their_rate() {
    let n = 4000;
    let count = |cfg: &SonarConfig, field: &ObstacleField| {
        let sonar = Sonar::new(cfg).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        (0..n)
            .filter(|_| {
                sonar
                    .scan(field, &at(0.0, 0.0, 0.0, 0.0), &[], &mut rng)
                    .valid[0]
            })
            .count() as f64
            / n as f64
    };
    let mut cfg = one_beam(0.0, 0.0);
    cfg.beam_width_deg = 20.0;
    cfg.dropout = 0.1;
    // on the axis: 10 % missed
    let ahead = ObstacleField::new(&[pillar(10.3, 0.0, 0.3)]).unwrap();
    let hit = count(&cfg, &ahead);
    assert!((hit - 0.9).abs() < 0.03, "on axis {hit}");
    // near the edge (9.5° of a 10° half width): gain 10^(−2.4·0.475²) ≈ 0.29, 34 % missed
    let (s, c) = 9.5f64.to_radians().sin_cos();
    let edge = ObstacleField::new(&[pillar(10.2 * c, 10.2 * s, 0.2)]).unwrap();
    let gain = sonar::two_way_gain(9.5f64.to_radians(), 20f64.to_radians());
    let hit = count(&cfg, &edge);
    assert!(
        (hit - (1.0 - 0.1 / gain)).abs() < 0.03,
        "edge {hit}, gain {gain}"
    );
    // false echoes in open water, at their rate and within the range
    cfg.dropout = 0.0;
    cfg.false_echo = 0.05;
    let empty = ObstacleField::new(&[]).unwrap();
    let rate = count(&cfg, &empty);
    assert!((rate - 0.05).abs() < 0.015, "false echoes {rate}");
    let sonar = Sonar::new(&cfg).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    for _ in 0..n {
        let s = sonar.scan(&empty, &at(0.0, 0.0, 0.0, 0.0), &[], &mut rng);
        assert!(s.ranges_m[0] > 0.0 && s.ranges_m[0] <= cfg.range_max_m);
    }
}

#[test]
fn the_edge_is_six_decibels_down_two_way() {
    let w = 25f64.to_radians();
    assert_relative_eq!(sonar::two_way_gain(0.0, w), 1.0);
    assert_relative_eq!(
        10.0 * sonar::two_way_gain(w / 2.0, w).log10(),
        -6.0,
        epsilon = 1e-9
    );
    assert_relative_eq!(sonar::two_way_gain(0.3, 0.0), 1.0);
}

#[test]
fn a_multibeam_tiles_its_sector() {
    let cfg = SonarConfig {
        multibeam: Some(sonar::Multibeam {
            beams: 12,
            sector_deg: 120.0,
            elevation_deg: 0.0,
        }),
        ..SonarConfig::default()
    };
    let sonar = Sonar::new(&cfg).unwrap();
    let l = sonar.layout();
    assert_eq!(l.count, 12);
    assert_relative_eq!(l.azimuth_rad[0], (-55f64).to_radians(), epsilon = 1e-12);
    assert_relative_eq!(l.azimuth_rad[11], 55f64.to_radians(), epsilon = 1e-12);
    assert_relative_eq!(sonar.beam_width_rad(0), 10f64.to_radians(), epsilon = 1e-12);
    // a pillar 40° to starboard is seen by the beam centred at 35° (30°-40°)... or its
    // neighbour, whichever cone its nearest point is in
    let (s, c) = 37f64.to_radians().sin_cos();
    let field = ObstacleField::new(&[pillar(10.3 * c, 10.3 * s, 0.3)]).unwrap();
    let r = sonar.true_ranges(&field, &at(0.0, 0.0, 0.0, 0.0), &[]);
    let seen: Vec<usize> = (0..12).filter(|&i| r[i].is_some()).collect();
    assert!(seen.contains(&9), "{seen:?}");
    // beams and multibeam together are refused, naming the key
    let mut both = cfg.clone();
    both.beams.pop();
    assert!(matches!(
        both.validate(),
        Err(SonarError::InvalidConfig { key, .. }) if key == "sonar.multibeam"
    ));
}

#[test]
fn no_return_when_nothing_is_in_range() {
    let cfg = SonarConfig::default();
    let sonar = Sonar::new(&cfg).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    // a wall 25 m away, beyond the 20 m range, and a sphere behind the vehicle
    let field = ObstacleField::new(&[
        wall_north(25.0),
        Obstacle::Sphere {
            center_ned_m: [-5.0, 0.0, 0.0],
            radius_m: 2.0,
        },
    ])
    .unwrap();
    let scan = sonar.scan(&field, &at(0.0, 0.0, 0.0, 0.0), &[], &mut rng);
    for i in 0..scan.count {
        assert!(!scan.valid[i]);
        assert_eq!(scan.ranges_m[i], cfg.range_max_m);
    }
    for i in scan.count..MAX_BEAMS {
        assert!(!scan.valid[i]);
        assert_eq!(scan.ranges_m[i], 0.0);
    }
    // an empty field never echoes
    let empty = ObstacleField::new(&[]).unwrap();
    let scan = sonar.scan(&empty, &at(0.0, 0.0, 0.0, 0.0), &[], &mut rng);
    assert!(scan.valid.iter().all(|v| !v));
    assert!(empty.is_empty());
    assert_eq!(empty.distance(&Point3::origin()), f64::INFINITY);
    assert_eq!(empty.nearest(&Point3::origin()), None);
}

#[test]
fn beams_turn_with_the_vehicle_and_azimuth_is_to_starboard() {
    // facing east (yaw 90°), a wall east at y = 10; a beam at +90° azimuth looks south
    let field = ObstacleField::new(&[
        Obstacle::Box {
            center_ned_m: [0.0, 10.5, 0.0],
            half_extents_m: [100.0, 0.5, 100.0],
            yaw_deg: 0.0,
        },
        Obstacle::Box {
            center_ned_m: [-6.5, 0.0, 0.0],
            half_extents_m: [0.5, 3.0, 100.0],
            yaw_deg: 0.0,
        },
    ])
    .unwrap();
    let mut cfg = one_beam(0.0, 0.0);
    cfg.noise_m = 0.0;
    cfg.beams.push(Beam {
        azimuth_deg: 90.0,
        elevation_deg: 0.0,
    });
    let sonar = Sonar::new(&cfg).unwrap();
    let scan = sonar.scan(
        &field,
        &at(0.0, 0.0, 0.0, 90.0),
        &[],
        &mut ChaCha8Rng::seed_from_u64(0),
    );
    assert_relative_eq!(scan.ranges_m[0], 10.0, epsilon = 1e-9);
    assert_relative_eq!(scan.ranges_m[1], 6.0, epsilon = 1e-9);
    assert_relative_eq!(scan.azimuth_rad[1], std::f64::consts::FRAC_PI_2);
}

#[test]
fn elevation_is_positive_down() {
    // the sea bed as a box whose top is at z = 30, vehicle at z = 25
    let field = ObstacleField::new(&[Obstacle::Box {
        center_ned_m: [0.0, 0.0, 31.0],
        half_extents_m: [100.0, 100.0, 1.0],
        yaw_deg: 0.0,
    }])
    .unwrap();
    let mut cfg = one_beam(0.0, 30.0);
    cfg.noise_m = 0.0;
    cfg.beams.push(Beam {
        azimuth_deg: 0.0,
        elevation_deg: -30.0,
    });
    let sonar = Sonar::new(&cfg).unwrap();
    let r = sonar.true_ranges(&field, &at(0.0, 0.0, 25.0, 0.0), &[]);
    assert_relative_eq!(
        r[0].unwrap(),
        5.0 / 30f64.to_radians().sin(),
        epsilon = 1e-9
    );
    assert_eq!(r[1], None);
}

#[test]
fn box_hits_where_expected_including_yaw() {
    let f = ObstacleField::new(&[Obstacle::Box {
        center_ned_m: [10.0, 0.0, 0.0],
        half_extents_m: [1.0, 1.0, 1.0],
        yaw_deg: 45.0,
    }])
    .unwrap();
    // the yawed box shows a vertical edge towards the origin at 10 − √2
    let d = f
        .cast_ray(&Point3::origin(), &dir(1.0, 0.0, 0.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 10.0 - 2f64.sqrt(), epsilon = 1e-9);
    // above the box (z = −1.5, NED up), nothing
    assert_eq!(
        f.cast_ray(&Point3::new(0.0, 0.0, -1.5), &dir(1.0, 0.0, 0.0), 20.0),
        None
    );
    // clearance from the origin is to the edge, the same 10 − √2
    assert_relative_eq!(
        f.distance(&Point3::origin()),
        10.0 - 2f64.sqrt(),
        epsilon = 1e-9
    );
}

#[test]
fn cylinder_is_vertical_and_hits_where_expected() {
    let f = ObstacleField::new(&[Obstacle::Cylinder {
        center_ned_m: [10.0, 0.0, 10.0],
        radius_m: 2.0,
        half_height_m: 1.0,
    }])
    .unwrap();
    // horizontal ray at the cylinder's depth: the side at x = 8
    let d = f
        .cast_ray(&Point3::new(0.0, 0.0, 10.0), &dir(1.0, 0.0, 0.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 8.0, epsilon = 1e-9);
    // a ray down from above its axis: its top cap at z = 9
    let d = f
        .cast_ray(&Point3::new(10.0, 1.5, 0.0), &dir(0.0, 0.0, 1.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 9.0, epsilon = 1e-9);
    // at depth 5 the horizontal ray passes above it
    assert_eq!(
        f.cast_ray(&Point3::new(0.0, 0.0, 5.0), &dir(1.0, 0.0, 0.0), 20.0),
        None
    );
    // an oblique ray: enters the circle x² + y² = 4 around (10, 0) from (0, 1)
    let d = f
        .cast_ray(&Point3::new(0.0, 1.0, 10.0), &dir(1.0, 0.0, 0.0), 20.0)
        .unwrap();
    // (parry's cylinder ray cast is iterative: good to ~1e-9 m)
    assert_relative_eq!(d, 10.0 - 3f64.sqrt(), epsilon = 1e-6);
}

#[test]
fn sphere_hits_where_expected() {
    let f = ObstacleField::new(&[Obstacle::Sphere {
        center_ned_m: [0.0, 10.0, 5.0],
        radius_m: 3.0,
    }])
    .unwrap();
    let d = f
        .cast_ray(&Point3::new(0.0, 0.0, 5.0), &dir(0.0, 1.0, 0.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 7.0, epsilon = 1e-9);
    // a ray offset by 2 m: chord at √(9 − 4) = √5 before the centre plane
    let d = f
        .cast_ray(&Point3::new(2.0, 0.0, 5.0), &dir(0.0, 1.0, 0.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 10.0 - 5f64.sqrt(), epsilon = 1e-9);
    // the max range cuts it off
    assert_eq!(
        f.cast_ray(&Point3::new(0.0, 0.0, 5.0), &dir(0.0, 1.0, 0.0), 6.9),
        None
    );
}

#[test]
fn mesh_hits_where_expected_closed_and_open() {
    // closed cube mesh (solid) at x = 10, half size 1
    let f = ObstacleField::new(&[cube_mesh([10.0, 0.0, 0.0], 1.0)]).unwrap();
    let d = f
        .cast_ray(&Point3::new(0.0, 0.2, 0.3), &dir(1.0, 0.0, 0.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 9.0, epsilon = 1e-9);
    // inside the closed mesh the clearance is 0; outside it is to the nearest face
    assert_eq!(f.distance(&Point3::new(10.2, 0.1, -0.3)), 0.0);
    assert_relative_eq!(
        f.distance(&Point3::new(10.0, 0.0, 4.0)),
        3.0,
        epsilon = 1e-9
    );

    // an open mesh: one vertical quad in the plane y = 6 spanning x ∈ [0, 10], z ∈ [−5, 5]
    let wall = Obstacle::Mesh {
        vertices_ned_m: vec![
            [0.0, 6.0, -5.0],
            [10.0, 6.0, -5.0],
            [10.0, 6.0, 5.0],
            [0.0, 6.0, 5.0],
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    };
    let f = ObstacleField::new(&[wall]).unwrap();
    let d = f
        .cast_ray(&Point3::new(5.0, 0.0, 0.0), &dir(0.0, 1.0, 0.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 6.0, epsilon = 1e-9);
    // from the far side too (a surface has two sides), and never "inside"
    let d = f
        .cast_ray(&Point3::new(5.0, 9.0, 0.0), &dir(0.0, -1.0, 0.0), 20.0)
        .unwrap();
    assert_relative_eq!(d, 3.0, epsilon = 1e-9);
    assert_relative_eq!(f.distance(&Point3::new(5.0, 9.0, 0.0)), 3.0, epsilon = 1e-9);
}

#[test]
fn nearest_names_the_obstacle_and_inside_is_zero() {
    let obs = [
        Obstacle::Sphere {
            center_ned_m: [20.0, 0.0, 0.0],
            radius_m: 1.0,
        },
        Obstacle::Sphere {
            center_ned_m: [0.0, 5.0, 0.0],
            radius_m: 1.0,
        },
        Obstacle::Cylinder {
            center_ned_m: [-9.0, 0.0, 0.0],
            radius_m: 2.0,
            half_height_m: 3.0,
        },
    ];
    let f = ObstacleField::new(&obs).unwrap();
    let (i, d) = f.nearest(&Point3::origin()).unwrap();
    assert_eq!(i, 1);
    assert_relative_eq!(d, 4.0, epsilon = 1e-9);
    let (i, d) = f.nearest(&Point3::new(-6.0, 0.0, 0.0)).unwrap();
    assert_eq!(i, 2);
    assert_relative_eq!(d, 1.0, epsilon = 1e-9);
    assert_eq!(f.nearest(&Point3::new(-9.5, 0.5, 1.0)), Some((2, 0.0)));
    assert_eq!(f.distance(&Point3::new(20.2, 0.0, 0.0)), 0.0);
}

#[test]
fn other_hulls_echo_only_when_enabled() {
    let field = ObstacleField::new(&[]).unwrap();
    let mut cfg = SonarConfig {
        noise_m: 0.0,
        ..SonarConfig::default()
    };
    cfg.beams = vec![Beam {
        azimuth_deg: 0.0,
        elevation_deg: 0.0,
    }];
    let me = at(0.0, 0.0, 0.0, 0.0);
    // another vehicle 6 m ahead, same heading: its stern tip at 6 − 0.8 = 5.2 m,
    // the transducer at 0.8 m on our nose: 4.4 m
    let other = at(6.0, 0.0, 0.0, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let s = Sonar::new(&cfg).unwrap();
    assert!(!s.scan(&field, &me, &[other], &mut rng).valid[0]);
    cfg.hulls_echo = true;
    let s = Sonar::new(&cfg).unwrap();
    let scan = s.scan(&field, &me, &[other], &mut rng);
    assert!(scan.valid[0]);
    assert_relative_eq!(scan.ranges_m[0], 4.4, epsilon = 1e-9);
    // crossing broadside 6 m ahead: its side at 6 − 0.25 − 0.8 = 4.95 m
    let scan = s.scan(&field, &me, &[at(6.0, 0.0, 0.0, 90.0)], &mut rng);
    assert_relative_eq!(scan.ranges_m[0], 4.95, epsilon = 1e-9);
    // an obstacle nearer than the hull wins
    let field = ObstacleField::new(&[wall_north(3.0)]).unwrap();
    let scan = s.scan(&field, &me, &[other], &mut rng);
    assert_relative_eq!(scan.ranges_m[0], 2.2, epsilon = 1e-9);
}

#[test]
fn same_seed_same_scan() {
    let field = ObstacleField::new(&[wall_north(8.0)]).unwrap();
    let s = Sonar::new(&SonarConfig::default()).unwrap();
    let pose = at(1.0, 2.0, 3.0, 10.0);
    let a = s.scan(&field, &pose, &[], &mut ChaCha8Rng::seed_from_u64(9));
    let b = s.scan(&field, &pose, &[], &mut ChaCha8Rng::seed_from_u64(9));
    assert_eq!(a, b);
}

#[test]
fn config_validation_names_the_key() {
    let bad = SonarConfig {
        range_max_m: -1.0,
        ..SonarConfig::default()
    };
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("sonar.range_max_m") && e.contains("-1"), "{e}");
    let bad = SonarConfig {
        beams: vec![
            Beam {
                azimuth_deg: 0.0,
                elevation_deg: 0.0
            };
            MAX_BEAMS + 1
        ],
        ..SonarConfig::default()
    };
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("sonar.beams"));
    let bad = one_beam(0.0, 95.0);
    let e = Sonar::new(&bad).unwrap_err().to_string();
    assert!(e.contains("sonar.beams[0].elevation_deg"), "{e}");
    let bad = SonarConfig {
        hull_length_m: 0.1,
        ..SonarConfig::default()
    };
    assert!(matches!(
        bad.validate(),
        Err(SonarError::InvalidConfig { key, .. }) if key == "sonar.hull_length_m"
    ));
    assert!(SonarConfig::default().validate().is_ok());
}

#[test]
fn obstacle_validation_names_the_index_and_key() {
    let obs = [
        wall_north(3.0),
        Obstacle::Sphere {
            center_ned_m: [0.0, 0.0, 0.0],
            radius_m: 0.0,
        },
    ];
    let e = ObstacleField::new(&obs).unwrap_err();
    assert_eq!(
        e.to_string(),
        "obstacles[1]: sphere.radius_m must be finite and > 0, got 0"
    );
    let m = Obstacle::Mesh {
        vertices_ned_m: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        triangles: vec![[0, 1, 3]],
    };
    assert!(m
        .validate()
        .unwrap_err()
        .to_string()
        .contains("mesh.triangles[0]"));
    let c = Obstacle::Cylinder {
        center_ned_m: [f64::NAN, 0.0, 0.0],
        radius_m: 1.0,
        half_height_m: 1.0,
    };
    assert!(c.validate().is_err());
}

#[test]
fn config_and_obstacles_read_from_toml() {
    #[derive(serde::Deserialize)]
    struct Scenario {
        sonar: SonarConfig,
        obstacles: Vec<Obstacle>,
    }
    let text = r#"
        [sonar]
        range_max_m = 15.0
        beams = [{ azimuth_deg = -20.0, elevation_deg = 0.0 }, { azimuth_deg = 20.0, elevation_deg = 5.0 }]

        [[obstacles]]
        kind = "cylinder"
        center_ned_m = [30.0, -6.0, 10.0]
        radius_m = 2.0
        half_height_m = 15.0

        [[obstacles]]
        kind = "box"
        center_ned_m = [30.0, 6.0, 10.0]
        half_extents_m = [2.0, 2.0, 15.0]
        yaw_deg = 0.0
    "#;
    let s: Scenario = toml::from_str(text).unwrap();
    assert_eq!(s.sonar.range_max_m, 15.0);
    assert_eq!(s.sonar.noise_m, SonarConfig::default().noise_m);
    assert_eq!(s.sonar.beams.len(), 2);
    assert_eq!(s.obstacles[0].kind(), "cylinder");
    assert!(ObstacleField::new(&s.obstacles).is_ok());
    // unknown keys are refused
    assert!(toml::from_str::<SonarConfig>("range_max = 3.0").is_err());
    assert!(toml::from_str::<Obstacle>(
        "kind = \"sphere\"\ncenter_ned_m = [0.0, 0.0, 0.0]\nradius_m = 1.0\ncolour = 1"
    )
    .is_err());
    // round trip
    let back: SonarConfig = toml::from_str(&toml::to_string(&s.sonar).unwrap()).unwrap();
    assert_eq!(back, s.sonar);
}

fn arb_obstacle() -> impl Strategy<Value = Obstacle> {
    let c = prop::array::uniform3(-40.0..40.0f64);
    prop_oneof![
        (
            c.clone(),
            prop::array::uniform3(0.2..4.0f64),
            -180.0..180.0f64
        )
            .prop_map(|(c, h, y)| Obstacle::Box {
                center_ned_m: c,
                half_extents_m: h,
                yaw_deg: y
            }),
        (c.clone(), 0.2..4.0f64, 0.2..6.0f64).prop_map(|(c, r, h)| Obstacle::Cylinder {
            center_ned_m: c,
            radius_m: r,
            half_height_m: h
        }),
        (c, 0.2..4.0f64).prop_map(|(c, r)| Obstacle::Sphere {
            center_ned_m: c,
            radius_m: r
        }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The hierarchy answers exactly what casting into every obstacle one by one does.
    #[test]
    fn hierarchy_matches_brute_force(
        obs in prop::collection::vec(arb_obstacle(), 1..40),
        o in prop::array::uniform3(-10.0..10.0f64),
        d in prop::array::uniform3(-1.0..1.0f64),
    ) {
        let dv = Vector3::from(d);
        prop_assume!(dv.norm() > 0.1);
        let dir = Unit::new_normalize(dv);
        let origin = Point3::from(Vector3::from(o));
        let field = ObstacleField::new(&obs).unwrap();
        let singles: Vec<ObstacleField> =
            obs.iter().map(|x| ObstacleField::new(std::slice::from_ref(x)).unwrap()).collect();
        let brute = singles.iter().filter_map(|f| f.cast_ray(&origin, &dir, 60.0))
            .fold(None, |a: Option<f64>, t| Some(a.map_or(t, |a| a.min(t))));
        match (field.cast_ray(&origin, &dir, 60.0), brute) {
            (None, None) => {}
            (Some(a), Some(b)) => prop_assert!((a - b).abs() < 1e-9),
            (a, b) => prop_assert!(false, "hierarchy {a:?} vs brute force {b:?}"),
        }
        let bd = singles.iter().map(|f| f.distance(&origin)).fold(f64::INFINITY, f64::min);
        prop_assert!((field.distance(&origin) - bd).abs() < 1e-9);
    }

    /// Ray against a sphere matches the closed-form intersection.
    #[test]
    fn sphere_matches_closed_form(
        c in prop::array::uniform3(-20.0..20.0f64),
        r in 0.1..5.0f64,
        d in prop::array::uniform3(-1.0..1.0f64),
    ) {
        let dv = Vector3::from(d);
        prop_assume!(dv.norm() > 0.1);
        let u = dv.normalize();
        let cv = Vector3::from(c);
        prop_assume!(cv.norm() > r + 1e-6);
        let field = ObstacleField::new(&[Obstacle::Sphere { center_ned_m: c, radius_m: r }]).unwrap();
        // |t u − c|² = r²  ⇒  t = u·c − √((u·c)² − |c|² + r²)
        let b = u.dot(&cv);
        let disc = b * b - cv.norm_squared() + r * r;
        let expect = (disc >= 0.0 && b - disc.sqrt() > 0.0).then(|| b - disc.sqrt());
        let got = field.cast_ray(&Point3::origin(), &Unit::new_unchecked(u), 100.0);
        match (got, expect) {
            (Some(g), Some(e)) => prop_assert!((g - e).abs() < 1e-7, "{g} vs {e}"),
            (None, None) => {}
            // grazing rays may fall either side of the tangent
            (g, e) => prop_assert!(disc.abs() < 1e-6, "{g:?} vs {e:?}, disc {disc}"),
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A cone's echo is never nearer than the nearest surface and no farther than its own
    /// axis; among spheres (for which the search is exact) never farther than any ray
    /// inside the cone (a dense fan of them).
    #[test]
    fn a_cone_returns_the_nearest_echo_inside_it(
        obs in prop::collection::vec(arb_obstacle(), 1..20),
        spheres_only in any::<bool>(),
        o in prop::array::uniform3(-10.0..10.0f64),
        yaw in -180.0..180.0f64,
        width in 2.0..40.0f64,
    ) {
        let obs: Vec<Obstacle> = if spheres_only {
            obs.into_iter().map(|x| match x {
                Obstacle::Box { center_ned_m, half_extents_m, .. } => Obstacle::Sphere {
                    center_ned_m, radius_m: half_extents_m[0],
                },
                Obstacle::Cylinder { center_ned_m, radius_m, .. } => Obstacle::Sphere {
                    center_ned_m, radius_m,
                },
                other => other,
            }).collect()
        } else {
            obs
        };
        let field = ObstacleField::new(&obs).unwrap();
        let origin = Point3::from(Vector3::from(o));
        let pose = Isometry3::from_parts(
            Translation3::from(origin.coords),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw.to_radians()),
        );
        let mut cfg = one_beam(0.0, 0.0);
        cfg.beam_width_deg = width;
        cfg.range_max_m = 60.0;
        let sonar = Sonar::new(&cfg).unwrap();
        let got = sonar.true_ranges(&field, &pose, &[])[0];
        let axis = pose.rotation * Vector3::x();
        let half = (width / 2.0).to_radians();
        // a fan of 41 × 41 rays over the cone's square
        let mut dense: Option<f64> = None;
        for a in -20..=20 {
            for b in -20..=20 {
                let (ta, tb) = (half * a as f64 / 20.0, half * b as f64 / 20.0);
                if ta * ta + tb * tb > half * half {
                    continue;
                }
                let d = pose.rotation * Vector3::new(1.0, ta.tan(), tb.tan()).normalize();
                if let Some(t) = field.cast_ray(&origin, &Unit::new_normalize(d), 60.0) {
                    dense = Some(dense.map_or(t, |x: f64| x.min(t)));
                }
            }
        }
        if let Some(g) = got {
            prop_assert!(g >= field.distance(&origin) - 1e-9);
            if let Some(ax) = field.cast_ray(&origin, &Unit::new_normalize(axis), 60.0) {
                prop_assert!(g <= ax + 1e-9);
            }
        }
        if let (Some(d), true) = (dense, spheres_only) {
            prop_assert!(got.is_some_and(|g| g <= d + 1e-9), "cone {got:?} vs dense {d}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// The closed-form vertical-cylinder cast agrees with parry's own (GJK) cast.
    #[test]
    fn cylinder_matches_parry(
        c in prop::array::uniform3(-10.0..10.0f64),
        r in 0.2..4.0f64,
        h in 0.2..6.0f64,
        o in prop::array::uniform3(-15.0..15.0f64),
        d in prop::array::uniform3(-1.0..1.0f64),
    ) {
        use parry3d_f64::math::{Pose, Rot3, Vector as V};
        use parry3d_f64::query::{Ray, RayCast};
        use parry3d_f64::shape::Cylinder;
        let dv = Vector3::from(d);
        prop_assume!(dv.norm() > 0.1);
        let u = dv.normalize();
        let field = ObstacleField::new(&[Obstacle::Cylinder {
            center_ned_m: c, radius_m: r, half_height_m: h,
        }]).unwrap();
        let got = field.cast_ray(&Point3::from(Vector3::from(o)), &Unit::new_unchecked(u), 40.0);
        let pose = Pose::from_parts(V::from_array(c), Rot3::from_rotation_x(std::f64::consts::FRAC_PI_2));
        let ray = Ray::new(V::from_array(o), V::new(u.x, u.y, u.z));
        let expect = Cylinder::new(h, r).cast_ray(&pose, &ray, 40.0, true);
        match (got, expect) {
            (Some(g), Some(e)) => prop_assert!((g - e).abs() < 1e-6, "{g} vs {e}"),
            (None, None) => {}
            // a ray that grazes an edge may fall either side in either method
            (g, e) => {
                let t = g.or(e).unwrap();
                let p = Vector3::from(o) + t * u - Vector3::from(c);
                let rim = ((p.x * p.x + p.y * p.y).sqrt() - r).abs() < 1e-6
                    || (p.z.abs() - h).abs() < 1e-6;
                prop_assert!(rim, "{g:?} vs {e:?}");
            }
        }
    }
}
