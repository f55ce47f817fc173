//! Scan time of the default four 7° cones, the same four as 25° cones and as rays, and a
//! 16-beam multibeam, against 2 and 200 obstacles.
//!
//! `cargo bench -p sonar --bench scan -- --quick`
#![allow(clippy::unwrap_used)] // a benchmark fixture, not library code

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sonar::{Multibeam, Obstacle, ObstacleField, Sonar, SonarConfig};

/// `n` obstacles of mixed kinds scattered over a 200 m × 200 m area, two of them in front
/// of the vehicle (so every scan has returns), deterministic.
fn field(n: usize) -> ObstacleField {
    let mut obs = vec![
        Obstacle::Cylinder {
            center_ned_m: [12.0, -4.0, 0.0],
            radius_m: 2.0,
            half_height_m: 20.0,
        },
        Obstacle::Box {
            center_ned_m: [12.0, 6.0, 0.0],
            half_extents_m: [2.0, 2.0, 20.0],
            yaw_deg: 15.0,
        },
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    use rand::Rng;
    while obs.len() < n {
        let c: [f64; 3] = [
            rng.random_range(-100.0..100.0),
            rng.random_range(-100.0..100.0),
            rng.random_range(-5.0..30.0),
        ];
        // keep the area around the vehicle clear so the two near obstacles answer
        if c[0].abs() < 25.0 && c[1].abs() < 25.0 {
            continue;
        }
        obs.push(match obs.len() % 3 {
            0 => Obstacle::Sphere {
                center_ned_m: c,
                radius_m: rng.random_range(0.5..3.0),
            },
            1 => Obstacle::Cylinder {
                center_ned_m: c,
                radius_m: rng.random_range(0.5..3.0),
                half_height_m: rng.random_range(1.0..10.0),
            },
            _ => Obstacle::Box {
                center_ned_m: c,
                half_extents_m: [
                    rng.random_range(0.5..3.0),
                    rng.random_range(0.5..3.0),
                    rng.random_range(0.5..3.0),
                ],
                yaw_deg: rng.random_range(0.0..90.0),
            },
        });
    }
    ObstacleField::new(&obs).unwrap()
}

fn bench_scan(c: &mut Criterion) {
    let pose = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05),
    );
    // the default (four 7° split beams), the same four as 25° single beams (the Ping2's)
    // and as rays (the earlier model), and a forward-looking multibeam of 16 beams over 120°
    let layouts = [
        ("sonar_scan_4_cones_7deg", SonarConfig::default()),
        (
            "sonar_scan_4_cones_25deg",
            SonarConfig {
                beam_width_deg: 25.0,
                split_beam: false,
                ..SonarConfig::default()
            },
        ),
        (
            "sonar_scan_4_rays",
            SonarConfig {
                beam_width_deg: 0.0,
                ..SonarConfig::default()
            },
        ),
        (
            "sonar_scan_multibeam_16x120deg",
            SonarConfig {
                multibeam: Some(Multibeam {
                    beams: 16,
                    sector_deg: 120.0,
                    elevation_deg: 0.0,
                }),
                ..SonarConfig::default()
            },
        ),
    ];
    for (name, cfg) in layouts {
        let sonar = Sonar::new(&cfg).unwrap();
        let mut group = c.benchmark_group(name);
        for n in [2usize, 200] {
            let f = field(n);
            let mut rng = ChaCha8Rng::seed_from_u64(1);
            let s = sonar.scan(&f, &pose, &[], &mut rng);
            assert!(s.valid[..s.count].iter().any(|v| *v));
            group.bench_with_input(BenchmarkId::new("obstacles", n), &f, |b, f| {
                b.iter(|| sonar.scan(f, &pose, &[], &mut rng))
            });
        }
        group.finish();
    }

    let mut group = c.benchmark_group("obstacle_distance");
    for n in [2usize, 200] {
        let f = field(n);
        let p = nalgebra::Point3::new(1.0, 2.0, 0.0);
        group.bench_with_input(BenchmarkId::new("obstacles", n), &f, |b, f| {
            b.iter(|| f.distance(&p))
        });
    }
    group.finish();
}

fn bench_single_ray(c: &mut Criterion) {
    let mut group = c.benchmark_group("single_ray");
    let kinds = [
        (
            "sphere",
            Obstacle::Sphere {
                center_ned_m: [10.0, 0.5, 0.0],
                radius_m: 2.0,
            },
        ),
        (
            "box",
            Obstacle::Box {
                center_ned_m: [10.0, 0.5, 0.0],
                half_extents_m: [2.0, 2.0, 2.0],
                yaw_deg: 20.0,
            },
        ),
        (
            "cylinder",
            Obstacle::Cylinder {
                center_ned_m: [10.0, 0.5, 0.0],
                radius_m: 2.0,
                half_height_m: 5.0,
            },
        ),
    ];
    let origin = nalgebra::Point3::origin();
    let dir = nalgebra::Unit::new_normalize(nalgebra::Vector3::new(1.0, 0.05, 0.01));
    for (name, o) in kinds {
        let f = ObstacleField::new(&[o]).unwrap();
        assert!(f.cast_ray(&origin, &dir, 20.0).is_some());
        group.bench_function(name, |b| b.iter(|| f.cast_ray(&origin, &dir, 20.0)));
    }
    group.finish();
}

criterion_group!(benches, bench_scan, bench_single_ray);
criterion_main!(benches);
