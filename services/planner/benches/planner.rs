//! Step time of the follower and leader planners, and the formation assignment for the
//! paper's 5 vehicles and for 101.
//!
//! `cargo bench -p planner --bench planner -- --quick`
#![allow(clippy::unwrap_used)] // a benchmark fixture, not library code

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
use planner::formation::{assign_displacements, FollowerSlot, FormationParams};
use planner::{
    FollowerConfig, FollowerInput, FollowerPlanner, LeaderConfig, LeaderInput, LeaderPlanner,
    PoseMeasurement, SonarScan,
};

fn scan(hit: bool) -> SonarScan {
    let mut s = SonarScan {
        count: 4,
        ..SonarScan::default()
    };
    for (i, a) in [-30.0f64, -10.0, 10.0, 30.0].iter().enumerate() {
        s.azimuth_rad[i] = a.to_radians();
        s.ranges_m[i] = if hit { 6.0 + i as f64 } else { 20.0 };
        s.valid[i] = hit;
    }
    s
}

fn bench_steps(c: &mut Criterion) {
    let mut f = FollowerPlanner::new(&FollowerConfig::default()).unwrap();
    let mut t = 0.0;
    c.bench_function("follower_step_fix_and_scan", |b| {
        b.iter(|| {
            t += 0.1;
            let fix = PoseMeasurement {
                t_s: t,
                parent_in_body: Isometry3::from_parts(
                    Translation3::new(8.0, 4.0, 0.0),
                    UnitQuaternion::identity(),
                ),
                covariance: Matrix6::identity() * 0.01,
                valid: true,
            };
            f.step(&FollowerInput {
                t_s: t,
                attitude: UnitQuaternion::identity(),
                nu: Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                depth_m: 10.0,
                pose: Some(fix),
                sonar: Some(scan(true)),
            })
            .unwrap()
        })
    });
    let mut l = LeaderPlanner::new(&LeaderConfig {
        waypoints_ned_m: vec![[1.0e6, 0.0, 10.0]],
        ..LeaderConfig::default()
    })
    .unwrap();
    let mut t = 0.0;
    c.bench_function("leader_step_scan", |b| {
        b.iter(|| {
            t += 0.1;
            l.step(&LeaderInput {
                t_s: t,
                attitude: UnitQuaternion::identity(),
                nu: Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                position_ned_m: Vector3::new(t, 0.0, 10.0),
                depth_m: 10.0,
                sonar: Some(scan(true)),
            })
            .unwrap()
        })
    });
}

fn slot(name: String, parent: String, s: [f64; 3]) -> FollowerSlot {
    FollowerSlot {
        name,
        parent,
        slot_in_parent_m: s,
    }
}

/// The paper's triangle extended into a V: two arms of `n` followers, each 8 m behind and
/// 4 m outboard of the one ahead.
fn vee(n: usize) -> Vec<FollowerSlot> {
    let mut f = Vec::new();
    for (side, y) in [("P", -4.0), ("S", 4.0)] {
        for r in 0..n {
            let parent = if r == 0 {
                "L".to_string()
            } else {
                format!("{side}{}", r - 1)
            };
            f.push(slot(format!("{side}{r}"), parent, [-8.0, y, 0.0]));
        }
    }
    f
}

fn bench_formation(c: &mut Criterion) {
    let p = FormationParams::default();
    let paper = vec![
        slot("F1".into(), "L".into(), [-8.0, -4.0, 0.0]),
        slot("F2".into(), "L".into(), [-8.0, 4.0, 0.0]),
        slot("F3".into(), "F1".into(), [-8.0, -4.0, 0.0]),
        slot("F4".into(), "F2".into(), [-8.0, 4.0, 0.0]),
    ];
    c.bench_function("assign_paper_5", |b| {
        b.iter(|| assign_displacements("L", &paper, 2.0, &p).unwrap())
    });
    let big = vee(50);
    assert_eq!(big.len(), 100);
    let mut g = c.benchmark_group("assign_101");
    g.sample_size(10);
    g.bench_function("assign_101", |b| {
        b.iter(|| assign_displacements("L", &big, 2.0, &p).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench_steps, bench_formation);
criterion_main!(benches);
