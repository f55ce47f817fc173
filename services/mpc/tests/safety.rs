//! The safety layer closed around the plant: whatever the target, the vehicle keeps its
//! clearance from the returns and the parent it is handed, and holds where no safe motion
//! toward the target exists.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use mpc::{closed_loop, Keepout, Mpc, MpcConfig, MpcInput, MpcStatus, MpcTarget};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use sim_plant::nav::{NavConfig, NavSensor};
use sim_plant::{Plant, PlantConfig, PlantState};

/// The parent's position and velocity (NED) at a time.
type ParentPath<'a> = &'a dyn Fn(f64) -> (Vector3<f64>, Vector3<f64>);

/// What one run of [`drive`] saw.
struct Outcome {
    /// Least distance from the vehicle to any of the points (at its time), m.
    min_distance_m: f64,
    /// Where the vehicle ended, NED.
    end: Vector3<f64>,
    /// Speed at the end, m/s.
    end_speed_mps: f64,
    /// Steps solved with the safety layer's constraints in the QP.
    guarded: usize,
}

/// Drives the vehicle from rest at the origin (10 m deep) toward a target moving north at
/// 1 m/s from 3 m ahead, for `seconds`, handing the controller the world-fixed `returns`
/// and, if any, a parent at `parent(t)` (position, velocity, NED), as the planner would:
/// in the level frame of the vehicle's own (noisy) heading.
fn drive(
    cfg: &MpcConfig,
    seconds: f64,
    returns: &[Vector3<f64>],
    parent: Option<ParentPath<'_>>,
) -> Outcome {
    drive_in(cfg, seconds, [0.0; 3], &|_| returns.to_vec(), parent)
}

/// [`drive`] in a current (NED, m/s), with the returns handed over at each step given by
/// `returns_near` from the vehicle's true position (as the planner picks the nearest).
fn drive_in(
    cfg: &MpcConfig,
    seconds: f64,
    current_ned_mps: [f64; 3],
    returns_near: &dyn Fn(Vector3<f64>) -> Vec<Vector3<f64>>,
    parent: Option<ParentPath<'_>>,
) -> Outcome {
    let mut plant = Plant::new(
        &PlantConfig {
            current_ned_mps,
            ..PlantConfig::default()
        },
        PlantState::at_rest(Vector3::new(0.0, 0.0, 10.0), UnitQuaternion::identity()),
    )
    .unwrap();
    let mut nav = NavSensor::new(&NavConfig::default(), 3).unwrap();
    let mut mpc = Mpc::new(cfg, plant.vehicle()).unwrap();
    let dt = cfg.step_s;
    let mut min_distance_m = f64::INFINITY;
    let mut guarded = 0;
    let steps = (seconds / dt).round() as usize;
    for k in 0..steps {
        let t = k as f64 * dt;
        let truth = *plant.state();
        let here = truth.position_ned_m;
        let m = nav.measure(&truth, false);
        let (_, _, psi) = m.attitude.euler_angles();
        let to_level = Rotation3::from_axis_angle(&Vector3::z_axis(), -psi);
        let goal = Vector3::new(3.0 + t, 0.0, 10.0);
        let mut keepout = Keepout::default();
        for r in &returns_near(here) {
            min_distance_m = min_distance_m.min((r - here).norm());
            let p = to_level * (r - here);
            keepout.push([p.x, p.y, p.z]);
        }
        if let Some(parent) = parent {
            let (p, v) = parent(t);
            min_distance_m = min_distance_m.min((p - here).norm());
            let (p, v) = (to_level * (p - here), to_level * v);
            keepout.parent = Some(([p.x, p.y, p.z], [v.x, v.y, v.z]));
        }
        let input = MpcInput {
            attitude: m.attitude,
            nu: closed_loop::nu_of(&m),
            target: MpcTarget {
                position_m: to_level * (goal - here),
                velocity_mps: to_level * Vector3::new(1.0, 0.0, 0.0),
                yaw_rel_rad: -psi,
            },
            keepout,
        };
        let tau = match mpc.step(&input) {
            Ok(out) => {
                if out.status == MpcStatus::Guarded {
                    guarded += 1;
                }
                out.tau
            }
            Err(e) => panic!("step {k}: {e}"),
        };
        plant.advance(&tau, dt).unwrap();
    }
    let end = plant.state().position_ned_m;
    Outcome {
        min_distance_m,
        end,
        end_speed_mps: plant.state().nu.fixed_rows::<3>(0).norm(),
        guarded,
    }
}

/// A wall of returns across the path 15 m ahead, one every 0.5 m from 4 m to port to 4 m to
/// starboard (eight of them, as the planner hands over at most eight, spread out).
fn wall() -> Vec<Vector3<f64>> {
    (0..8)
        .map(|i| Vector3::new(15.0, -3.5 + f64::from(i), 10.0))
        .collect()
}

#[test]
fn a_target_beyond_a_wall_is_not_flown_into_it() {
    let cfg = MpcConfig::default();
    let clearance = cfg.d_min_m / 2.0 + cfg.safety_margin_m;
    let held = drive(&cfg, 40.0, &wall(), None);
    // the target went on through the wall; the vehicle held short of it and stopped
    assert!(
        held.min_distance_m >= clearance - 0.1,
        "came within {} m of a return (clearance {clearance} m)",
        held.min_distance_m
    );
    assert!(
        held.end.x < 15.0 - clearance + 0.1,
        "ended at {:?}",
        held.end
    );
    assert!(held.end.x > 10.0, "held far short, at {:?}", held.end);
    assert!(
        held.end_speed_mps < 0.1,
        "still moving at {}",
        held.end_speed_mps
    );
    // without the layer the same target is flown straight through the wall
    let off = MpcConfig {
        safety: false,
        ..MpcConfig::default()
    };
    let through = drive(&off, 40.0, &wall(), None);
    assert!(through.end.x > 30.0, "ended at {:?}", through.end);
    assert!(through.min_distance_m < 0.6, "{}", through.min_distance_m);
    assert_eq!(through.guarded, 0);
}

#[test]
fn a_parent_that_stops_ahead_is_kept_at_the_safe_distance() {
    // the parent runs ahead at 1 m/s from 6 m ahead, then stops at 20 m; the target
    // (which, wrongly, goes on) would run the follower into it
    let parent = |t: f64| {
        let x = (6.0 + t).min(20.0);
        let v = if 6.0 + t < 20.0 { 1.0 } else { 0.0 };
        (Vector3::new(x, 0.3, 10.0), Vector3::new(v, 0.0, 0.0))
    };
    let cfg = MpcConfig::default();
    let out = drive(&cfg, 40.0, &[], Some(&parent));
    let keep = cfg.d_min_m + cfg.safety_margin_m;
    assert!(
        out.min_distance_m >= keep - 0.15,
        "came within {} m of the parent (keeps {keep} m)",
        out.min_distance_m
    );
    assert!(out.end.x < 20.0 - keep + 0.3, "ended at {:?}", out.end);
    assert!(out.guarded > 0);
}

#[test]
fn with_nothing_to_keep_clear_of_the_controller_is_the_same_bit_for_bit() {
    let on = MpcConfig::default();
    let off = MpcConfig {
        safety: false,
        ..MpcConfig::default()
    };
    let taus = |cfg: &MpcConfig| {
        let mut v = Vec::new();
        closed_loop::run(cfg, 60.0, 0.05, |s| v.push(s.tau)).unwrap();
        v
    };
    assert_eq!(taus(&on), taus(&off));
}

#[test]
fn a_current_that_sets_the_vehicle_onto_a_wall_is_held_off() {
    // A wall 1.4 m to starboard of the track, returns every 1.5 m along it near the
    // vehicle; a 0.7 m/s current from port sets the vehicle toward it. The target runs
    // along the track, clear of the wall (so it is not held short): only the QP's
    // clearances keep the vehicle off.
    let wall_y = 1.4;
    let near = |here: Vector3<f64>| {
        let x0 = (here.x / 1.5).floor() * 1.5;
        (-2..6)
            .map(|i| Vector3::new(x0 + 1.5 * f64::from(i), wall_y, 10.0))
            .collect::<Vec<_>>()
    };
    let current = [0.0, 0.7, 0.0];
    let cfg = MpcConfig::default();
    let clearance = cfg.d_min_m / 2.0 + cfg.safety_margin_m;
    let off = drive_in(
        &MpcConfig {
            safety: false,
            ..MpcConfig::default()
        },
        40.0,
        current,
        &near,
        None,
    );
    let on = drive_in(&cfg, 40.0, current, &near, None);
    // the current alone sets it well inside the clearance ...
    assert!(
        off.min_distance_m < clearance - 0.1,
        "without the layer: {}",
        off.min_distance_m
    );
    // ... which the layer keeps, solving its own QP to do so
    assert!(
        on.min_distance_m >= clearance - 0.05,
        "with the layer: {}",
        on.min_distance_m
    );
    assert!(on.guarded > 0);
    assert!(on.end.x > 30.0, "it went on along the wall: {:?}", on.end);
}
