//! The leader planner closed around a kinematic vehicle and the real sonar simulator.
#![allow(clippy::unwrap_used, clippy::panic)] // test fixtures

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3, Vector6};
use planner::{LeaderConfig, LeaderInput, LeaderPlanner, Mode, PlannerOutput, SonarScan};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::Distribution;
use sonar::{Obstacle, ObstacleField, Sonar, SonarConfig};

const DT: f64 = 0.1;

struct Leader {
    planner: LeaderPlanner,
    pos: Vector3<f64>,
    yaw: f64,
    vel: Vector3<f64>,
    t: f64,
    sonar: Sonar,
    field: ObstacleField,
    rng: ChaCha8Rng,
    /// 1σ noise added to the absolute fix, m.
    fix_noise_m: f64,
}

impl Leader {
    fn new(cfg: &LeaderConfig, obstacles: &[Obstacle]) -> Self {
        Self {
            planner: LeaderPlanner::new(cfg).unwrap(),
            pos: Vector3::new(0.0, 0.0, 10.0),
            yaw: 0.0,
            vel: Vector3::zeros(),
            t: 0.0,
            sonar: Sonar::new(&SonarConfig::default()).unwrap(),
            field: ObstacleField::new(obstacles).unwrap(),
            rng: ChaCha8Rng::seed_from_u64(3),
            fix_noise_m: 0.0,
        }
    }

    /// One step: scan, plan, then move like a well-tuned controller would (velocity
    /// feed-forward plus a proportional pull to the target, heading straight to the wanted).
    fn step(&mut self) -> PlannerOutput {
        let att = UnitQuaternion::from_euler_angles(0.0, 0.0, self.yaw);
        let iso = Isometry3::from_parts(Translation3::from(self.pos), att);
        let s = self.sonar.scan(&self.field, &iso, &[], &mut self.rng);
        let sonar = SonarScan {
            ranges_m: s.ranges_m,
            azimuth_rad: s.azimuth_rad,
            elevation_rad: s.elevation_rad,
            valid: s.valid,
            count: s.count,
        };
        let nu_lin = att.inverse() * self.vel;
        let noise = rand_distr::Normal::new(0.0, self.fix_noise_m.max(1e-12)).unwrap();
        let fix = self.pos
            + Vector3::new(
                noise.sample(&mut self.rng),
                noise.sample(&mut self.rng),
                noise.sample(&mut self.rng),
            );
        let out = self
            .planner
            .step(&LeaderInput {
                t_s: self.t,
                attitude: att,
                nu: Vector6::new(nu_lin.x, nu_lin.y, nu_lin.z, 0.0, 0.0, 0.0),
                position_ned_m: fix,
                depth_m: self.pos.z,
                sonar: Some(sonar),
            })
            .unwrap();
        let v = att * (out.target.velocity_mps + out.target.position_m * 1.0);
        self.vel = v;
        self.pos += v * DT;
        self.yaw += out.target.yaw_rel_rad.clamp(-0.1, 0.1);
        self.t += DT;
        out
    }

    fn clearance(&self) -> f64 {
        self.field.distance(&Point3::from(self.pos))
    }
}

#[test]
fn leader_reaches_its_waypoints() {
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[30.0, 0.0, 10.0], [30.0, 30.0, 12.0], [0.0, 30.0, 10.0]],
        ..LeaderConfig::default()
    };
    let mut l = Leader::new(&cfg, &[]);
    let mut seen = [false; 3];
    let mut done_at = None;
    let mut prev_cmd = f64::INFINITY;
    for _ in 0..2000 {
        let out = l.step();
        seen[out.state.waypoint_index] = true;
        // feed-forward plus a 1/s pull toward a target at most max_lead_m ahead
        let bound = cfg.speed_mps + cfg.max_lead_m * 1.0 + 1e-6;
        assert!(l.vel.norm() <= bound, "speed {}", l.vel.norm());
        if out.state.mode == Mode::MissionDone {
            if done_at.is_none() {
                // the speed had tapered to (nearly) zero before the hold: no step in speed
                assert!(
                    prev_cmd < 0.05,
                    "speed command {prev_cmd} m/s just before the hold"
                );
            }
            done_at.get_or_insert(l.t);
            assert_eq!(out.target.velocity_mps, Vector3::zeros());
        }
        prev_cmd = out.target.velocity_mps.norm();
    }
    assert_eq!(seen, [true; 3]);
    let done_at = done_at.expect("mission not done");
    // 90 m of path at 1 m/s, plus the slow-down into the last waypoint and the corners
    assert!(done_at > 85.0 && done_at < 140.0, "done at {done_at} s");
    let last = Vector3::from(cfg.waypoints_ned_m[2]);
    assert!((l.pos - last).norm() <= cfg.acceptance_radius_m);
}

#[test]
fn leader_offsets_around_an_obstacle_and_returns_to_its_track() {
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[120.0, 0.0, 10.0]],
        ..LeaderConfig::default()
    };
    let pillar = Obstacle::Cylinder {
        center_ned_m: [50.0, 0.5, 10.0],
        radius_m: 2.0,
        half_height_m: 10.0,
    };
    let mut l = Leader::new(&cfg, &[pillar]);
    let mut min_clear = f64::INFINITY;
    let mut max_dev: f64 = 0.0;
    let mut avoided = false;
    while l.pos.x < 110.0 && l.t < 300.0 {
        let out = l.step();
        min_clear = min_clear.min(l.clearance());
        if out.state.mode == Mode::Avoiding {
            avoided = true;
        }
        max_dev = max_dev.max(l.pos.y.abs());
        if l.pos.x > 85.0 {
            // back on the track
            assert!(l.pos.y.abs() < 0.3, "y {} at x {}", l.pos.y, l.pos.x);
            assert_eq!(out.state.track_offset_m, 0.0);
            assert_eq!(out.state.mode, Mode::Tracking);
        }
    }
    assert!(avoided);
    // the pillar blocks the track: the leader swerved by more than its radius ...
    assert!(max_dev > 2.0, "max deviation {max_dev}");
    // ... and kept the safe distance from its surface (centre to surface)
    assert!(min_clear >= cfg.d_min_m, "min clearance {min_clear}");
}

#[test]
fn leader_goes_straight_through_a_passage_wide_enough() {
    // the paper's passage: walls at |y| ≥ 4, 8 m apart; clearance needed 2 + 0.5
    let walls = [
        Obstacle::Box {
            center_ned_m: [70.0, -9.0, 10.0],
            half_extents_m: [10.0, 5.0, 15.0],
            yaw_deg: 0.0,
        },
        Obstacle::Box {
            center_ned_m: [70.0, 9.0, 10.0],
            half_extents_m: [10.0, 5.0, 15.0],
            yaw_deg: 0.0,
        },
    ];
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[170.0, 0.0, 10.0]],
        ..LeaderConfig::default()
    };
    let mut l = Leader::new(&cfg, &walls);
    while l.pos.x < 100.0 && l.t < 300.0 {
        let out = l.step();
        assert_eq!(out.state.track_offset_m, 0.0);
        assert!(l.pos.y.abs() < 0.05);
    }
    assert!(l.pos.x >= 100.0);
}

#[test]
fn leader_stops_when_no_offset_is_clear() {
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[100.0, 0.0, 10.0]],
        max_offset_m: 1.0,
        ..LeaderConfig::default()
    };
    let wall = Obstacle::Box {
        center_ned_m: [40.0, 0.0, 10.0],
        half_extents_m: [1.0, 30.0, 15.0],
        yaw_deg: 0.0,
    };
    let mut l = Leader::new(&cfg, &[wall]);
    let mut blocked = false;
    for _ in 0..1500 {
        // the target is in the level frame of the heading the step started with
        let (s, c) = l.yaw.sin_cos();
        let out = l.step();
        if out.state.mode == Mode::Blocked {
            blocked = true;
            // no speed along the track (north); the offset may still move across it
            let v = out.target.velocity_mps;
            assert!((c * v.x - s * v.y).abs() < 1e-9, "moving on at {v:?}");
        }
    }
    assert!(blocked);
    assert!(l.vel.norm() < 1e-3, "still moving at {}", l.vel.norm());
    assert!(
        l.clearance() > cfg.d_min_m,
        "stopped {} m from the wall",
        l.clearance()
    );
}

#[test]
fn leader_is_deterministic() {
    let cfg = LeaderConfig::default();
    let pillar = Obstacle::Sphere {
        center_ned_m: [30.0, -1.0, 10.0],
        radius_m: 2.0,
    };
    let run = || {
        let mut l = Leader::new(&cfg, std::slice::from_ref(&pillar));
        (0..600).map(|_| l.step()).collect::<Vec<_>>()
    };
    assert_eq!(run(), run());
}

#[test]
fn mission_config_reads_from_toml() {
    let cfg: LeaderConfig =
        toml::from_str("waypoints_ned_m = [[170.0, 0.0, 10.0]]\nspeed_mps = 1.0").unwrap();
    assert_eq!(cfg.waypoints_ned_m.len(), 1);
    assert_eq!(
        cfg.acceptance_radius_m,
        LeaderConfig::default().acceptance_radius_m
    );
    let bad = LeaderConfig {
        waypoints_ned_m: vec![],
        ..LeaderConfig::default()
    };
    assert!(LeaderPlanner::new(&bad)
        .unwrap_err()
        .to_string()
        .contains("mission.waypoints_ned_m"));
    let bad = LeaderConfig {
        speed_mps: 0.0,
        ..LeaderConfig::default()
    };
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("mission.speed_mps"));
    assert!(toml::from_str::<LeaderConfig>("speed = 1.0").is_err());
}

/// With the nav's default absolute-fix noise (0.5 m per axis at 10 Hz) the leader steers on
/// its filtered position: heading commands stay smooth, it keeps its track and its speed
/// (raw fixes made it zig-zag by ±6° and ratchet its virtual target forward to ~1.4 m/s).
#[test]
fn leader_filters_noisy_fixes() {
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[300.0, 0.0, 10.0]],
        ..LeaderConfig::default()
    };
    let mut l = Leader::new(&cfg, &[]);
    l.fix_noise_m = 0.5;
    let mut x_at_20 = 0.0;
    for k in 0..1200 {
        let out = l.step();
        if k >= 200 {
            // after the ramp: heading command within ~1.5°, on the track within 0.3 m
            assert!(
                out.target.yaw_rel_rad.abs() < 0.025,
                "yaw command {} at {}",
                out.target.yaw_rel_rad,
                l.t
            );
            assert!(l.pos.y.abs() < 0.3, "y {} at {}", l.pos.y, l.t);
            assert!((l.pos.z - 10.0).abs() < 1e-9);
        }
        if k == 200 {
            x_at_20 = l.pos.x;
        }
    }
    let speed = (l.pos.x - x_at_20) / 100.0;
    assert!((speed - cfg.speed_mps).abs() < 0.03, "mean speed {speed}");
}

/// The speed command ramps up at `accel_mps2` from rest.
#[test]
fn leader_ramps_its_speed_up() {
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[300.0, 0.0, 10.0]],
        accel_mps2: 0.1,
        ..LeaderConfig::default()
    };
    let mut l = Leader::new(&cfg, &[]);
    let mut prev = 0.0;
    for k in 0..200 {
        let out = l.step();
        let v = out.target.velocity_mps.norm();
        assert!(
            v <= prev + cfg.accel_mps2 * DT + 1e-9,
            "step {k}: {prev} -> {v}"
        );
        assert!(v <= cfg.speed_mps + 1e-9);
        prev = v;
    }
    assert!(
        (prev - cfg.speed_mps).abs() < 1e-9,
        "cruise speed reached: {prev}"
    );
}

#[test]
fn restarted_leader_carries_on_where_the_old_one_was() {
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[30.0, 0.0, 10.0], [30.0, 30.0, 12.0], [0.0, 30.0, 10.0]],
        ..LeaderConfig::default()
    };
    // The first planner flies until it is well along the second leg.
    let mut l = Leader::new(&cfg, &[]);
    let mut before = None;
    for _ in 0..2000 {
        let out = l.step();
        if out.state.waypoint_index == 1 && l.pos.y > 10.0 {
            before = Some(out);
            break;
        }
    }
    let before = before.expect("never reached the second leg");
    let speed = before.target.velocity_mps.norm();
    assert!(speed > 0.5, "cruising at {speed} m/s");

    // (the resumed one goes first: the fixture moves the vehicle as told)
    // A cold planner would head back to the first waypoint from rest...
    let mut cold = LeaderPlanner::new(&cfg).unwrap();
    // ...a resumed one heads for the second, at the vehicle's speed.
    let mut resumed = LeaderPlanner::new(&cfg).unwrap();
    resumed.resume();
    l.t += DT;
    for (p, resume) in [(&mut resumed, true), (&mut cold, false)] {
        std::mem::swap(&mut l.planner, p);
        let out = l.step();
        std::mem::swap(&mut l.planner, p);
        if resume {
            assert_eq!(out.state.waypoint_index, 1);
            let v = out.target.velocity_mps.norm();
            assert!(
                (v - speed).abs() < 0.1,
                "resumed at {v} m/s, was {speed} m/s"
            );
        } else {
            assert_eq!(out.state.waypoint_index, 0);
            assert!(out.target.velocity_mps.norm() < 0.05);
        }
    }
}

/// Two gaps 16 m apart, the first 2.6 m to port of the track, the second 4 m to
/// starboard (a generated slalom course): the leader keeps its offset through the first
/// while the first's walls are within `memory_behind_m`, then crosses to the second as soon
/// as nothing ahead leaves the first offset clear; it never passes a wall it has come abeam
/// of on the wall's far side, and never stops.
#[test]
fn leader_threads_two_gaps_offset_opposite_ways() {
    let cfg = LeaderConfig {
        waypoints_ned_m: vec![[183.0, 0.0, 10.0]],
        memory_behind_m: 21.0,
        ..LeaderConfig::default()
    };
    let b = |c: [f64; 3], h: [f64; 3]| Obstacle::Box {
        center_ned_m: c,
        half_extents_m: h,
        yaw_deg: 0.0,
    };
    let obs = [
        b([68.943, -13.125, 10.5], [9.122, 6.375, 10.5]),
        b([68.943, 7.625, 10.5], [9.122, 6.375, 10.5]),
        b([104.246, -7.483, 10.5], [10.394, 6.517, 10.5]),
        b([104.246, 13.552, 10.5], [10.394, 6.517, 10.5]),
    ];
    let mut l = Leader::new(&cfg, &obs);
    let mut min_clear = f64::INFINITY;
    while l.pos.x < 130.0 && l.t < 300.0 {
        let out = l.step();
        min_clear = min_clear.min(l.clearance());
        assert_ne!(out.state.mode, Mode::Blocked, "blocked at x {}", l.pos.x);
    }
    assert!(l.pos.x >= 130.0, "stuck at x {}", l.pos.x);
    assert!(min_clear >= cfg.d_min_m, "min clearance {min_clear}");
}
