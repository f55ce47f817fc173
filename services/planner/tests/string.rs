//! String stability: a file of followers each following the one ahead, in a
//! small world where every vehicle is a double integrator steered toward its
//! planner's target (as the MPC does, with a proportional-derivative law), the
//! fixes are noisy and one step late. The leader swims north at 1 m/s and
//! makes a sideways manoeuvre; how much of it arrives at each level is what a
//! deep formation lives or dies by.
#![allow(clippy::unwrap_used)]

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
use planner::{FollowerConfig, FollowerInput, FollowerPlanner, PoseMeasurement};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::StandardNormal;

const DT: f64 = 0.1;
const LEVELS: usize = 8;
const SLOT: [f64; 3] = [-6.0, 0.0, 0.0];
/// The tracking law: acceleration = KP · position error + KD · velocity error.
const KP: f64 = 1.0;
const KD: f64 = 1.4;
/// 1σ of a fix's position, m.
const FIX_SIGMA_M: f64 = 0.05;

/// The leader: north at 1 m/s, with one sideways swerve of 1 m (a smooth
/// bump between 20 s and 30 s).
fn leader_at(t: f64) -> Vector3<f64> {
    let s = ((t - 20.0) / 10.0).clamp(0.0, 1.0);
    let bump = (std::f64::consts::PI * s).sin().powi(2);
    Vector3::new(t, bump, 10.0)
}

struct Vehicle {
    p: Vector3<f64>,
    v: Vector3<f64>,
    planner: FollowerPlanner,
}

/// Runs the file for 80 s; returns each level's largest sideways deviation
/// from the leader's straight track (its lateral excursion), after 15 s.
fn run(cfg: &FollowerConfig, seed: u64) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut file: Vec<Vehicle> = (1..=LEVELS)
        .map(|k| Vehicle {
            p: leader_at(0.0) + Vector3::from(SLOT) * k as f64,
            v: Vector3::new(1.0, 0.0, 0.0),
            planner: FollowerPlanner::new(cfg).unwrap(),
        })
        .collect();
    let mut worst = vec![0.0f64; LEVELS];
    // positions one step ago: the fixes are one frame late
    let mut late: Vec<Vector3<f64>> = std::iter::once(leader_at(0.0))
        .chain(file.iter().map(|f| f.p))
        .collect();
    let mut t = 0.0;
    while t < 80.0 {
        let now: Vec<Vector3<f64>> = std::iter::once(leader_at(t))
            .chain(file.iter().map(|f| f.p))
            .collect();
        for (k, f) in file.iter_mut().enumerate() {
            let noise = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal) * FIX_SIGMA_M);
            let seen = late[k] - late[k + 1] + noise;
            let out = f
                .planner
                .step(&FollowerInput {
                    t_s: t,
                    attitude: UnitQuaternion::identity(),
                    nu: Vector6::new(f.v.x, f.v.y, f.v.z, 0.0, 0.0, 0.0),
                    depth_m: f.p.z,
                    pose: Some(PoseMeasurement {
                        t_s: t - DT,
                        parent_in_body: Isometry3::from_parts(
                            Translation3::from(seen),
                            UnitQuaternion::identity(),
                        ),
                        covariance: Matrix6::identity() * FIX_SIGMA_M.powi(2),
                        valid: true,
                    }),
                    sonar: None,
                })
                .unwrap();
            let a = out.target.position_m * KP + (out.target.velocity_mps - f.v) * KD;
            f.v += a * DT;
            f.p += f.v * DT;
            if t > 15.0 {
                worst[k] = worst[k].max(f.p.y.abs());
            }
        }
        late = now;
        t += DT;
    }
    worst
}

fn config(headway_s: f64) -> FollowerConfig {
    FollowerConfig {
        slot_in_parent_m: SLOT,
        headway_s,
        ..FollowerConfig::default()
    }
}

#[test]
fn without_headway_a_swerve_grows_level_by_level_down_the_file() {
    // the paper's rigid slot (the trail, which bends the slot along the parent's
    // path, halves the swing a parent's heading gives it, but not the loop's gain)
    let rigid = FollowerConfig {
        trail: false,
        ..config(0.0)
    };
    let w = run(&rigid, 1);
    // the first follower repeats the leader's 1 m swerve, with some overshoot
    assert!(w[0] > 0.9, "{w:?}");
    // and every level passes it on larger (the rigid slot of the paper):
    // eight levels down it is many times the first one's (measured: 15×)
    assert!(w[LEVELS - 1] > 3.0 * w[0], "{w:?}");
}

/// On the trail the target's velocity is the parent's speed along its path at the
/// trail point, without the sideways part of the parent's velocity: the file does not
/// pass a swerve on amplified even without the headway (measured: at most 1.04× the
/// first level's, where the rigid slot's grows 15×).
#[test]
fn on_the_trail_a_swerve_stays_bounded_down_the_file_without_headway() {
    for seed in 1..4 {
        let w = run(&config(0.0), seed);
        assert!(w[0] > 0.8, "seed {seed}: {w:?}");
        let most = w.iter().copied().fold(0.0, f64::max);
        assert!(most <= 1.2 * w[0], "seed {seed}: {w:?}");
    }
}

#[test]
fn with_headway_a_swerve_stays_bounded_down_the_file() {
    for seed in 1..4 {
        let w = run(&config(1.0), seed);
        assert!(w[0] > 0.8, "seed {seed}: {w:?}");
        // no level swerves much more than the first (measured: at most 1.35×;
        // what remains is the slow average v̄ of the headway)
        let most = w.iter().copied().fold(0.0, f64::max);
        assert!(most <= 1.5 * w[0], "seed {seed}: {w:?}");
    }
}

/// A planner that has followed a parent swimming north at 1 m/s, on its
/// slot, for 60 s (fixes exact and one step late).
fn steady(cfg: &FollowerConfig) -> FollowerPlanner {
    let mut p = FollowerPlanner::new(cfg).unwrap();
    for i in 0..600 {
        let t = f64::from(i) * DT;
        let out = p.step(&steady_input(t, 1.0, 0.0, true)).unwrap();
        if i == 599 {
            // on its slot and moving with the parent: the target is here
            assert!(out.target.position_m.norm() < 0.02, "{out:?}");
            assert!(out.target.yaw_rel_rad.abs() < 1e-3, "{out:?}");
        }
    }
    p
}

/// The input at `t` of a follower on its slot, moving north at `u` and
/// turning at `r`, with the fix of the frame before if `seen`.
fn steady_input(t: f64, u: f64, r: f64, seen: bool) -> FollowerInput {
    FollowerInput {
        t_s: t,
        attitude: UnitQuaternion::identity(),
        nu: Vector6::new(u, 0.0, 0.0, 0.0, 0.0, r),
        depth_m: 10.0,
        pose: seen.then(|| PoseMeasurement {
            t_s: t - DT,
            parent_in_body: Isometry3::from_parts(
                Translation3::from(-Vector3::from(SLOT)),
                UnitQuaternion::identity(),
            ),
            covariance: Matrix6::identity() * 1e-4,
            valid: true,
        }),
        sonar: None,
    }
}

#[test]
fn headway_leaves_the_slot_exact_at_steady_speed_and_moves_it_back_by_h_times_the_excess() {
    let cfg = FollowerConfig {
        yaw_headway_s: 2.0,
        ..config(1.0)
    };
    let mut same = steady(&cfg);
    let mut fast = same.clone();
    let a = same
        .step(&steady_input(60.0, 1.0, 0.0, false))
        .unwrap()
        .target;
    // 0.5 m/s faster than the formation and turning at 0.1 rad/s while it
    // goes straight: the target moves back by 1 s × 0.5 m/s (plus the 0.05 m
    // the odometry moved farther in the step), the heading by 2 s × 0.1 rad/s
    let b = fast
        .step(&steady_input(60.0, 1.5, 0.1, false))
        .unwrap()
        .target;
    let moved_back = a.position_m.x - b.position_m.x;
    assert!((moved_back - 0.55).abs() < 1e-6, "{moved_back}");
    let turned = b.yaw_rel_rad - a.yaw_rel_rad;
    assert!((turned + 0.2).abs() < 1e-6, "{turned}");
}
