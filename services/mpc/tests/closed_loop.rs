//! Closed loop at library level: `sim_plant::Plant` as the plant, its nav sensors as the
//! measurement, `Mpc` as the controller, a moving target given in the level frame exactly as
//! the planner will give it.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use mpc::{Mpc, MpcConfig, MpcError, MpcInput, MpcTarget};
use nalgebra::{Rotation3, UnitQuaternion, Vector3, Vector6};
use sim_plant::nav::{NavConfig, NavSensor};
use sim_plant::{Plant, PlantConfig, PlantState};

/// The target in NED: position, velocity, heading at time t.
fn target_at(t: f64) -> (Vector3<f64>, Vector3<f64>, f64) {
    let speed = 1.0;
    let start = Vector3::new(6.0, 2.0, 11.0);
    let t_turn = 30.0;
    if t < t_turn {
        (
            start + Vector3::new(speed * t, 0.0, 0.0),
            Vector3::new(speed, 0.0, 0.0),
            0.0,
        )
    } else {
        // Then a starboard turn on a 40 m circle, descending at 0.1 m/s.
        let radius = 40.0;
        let w = speed / radius;
        let a = w * (t - t_turn);
        let centre = start + Vector3::new(speed * t_turn, radius, 0.0);
        let p = centre + Vector3::new(radius * a.sin(), -radius * a.cos(), 0.1 * (t - t_turn));
        let v = Vector3::new(speed * a.cos(), speed * a.sin(), 0.1);
        (p, v, a)
    }
}

struct Run {
    /// Position error after the initial transient, m (per control step).
    errors_after_transient: Vec<f64>,
    heading_errors_after_transient: Vec<f64>,
    /// Applied thrust after the initial transient.
    taus: Vec<Vector6<f64>>,
    failures: usize,
    max_iterations: u32,
}

impl Run {
    fn max_error(&self) -> f64 {
        self.errors_after_transient
            .iter()
            .copied()
            .fold(0.0, f64::max)
    }
    fn rms_du(&self) -> Vector6<f64> {
        let mut s = Vector6::zeros();
        for w in self.taus.windows(2) {
            s += (w[1] - w[0]).component_mul(&(w[1] - w[0]));
        }
        (s / (self.taus.len() - 1) as f64).map(f64::sqrt)
    }
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// Uniform pseudo-random numbers with standard deviation `sigma` (deterministic).
struct Noise(u64);

impl Noise {
    fn next(&mut self, sigma: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 12f64.sqrt() * sigma
    }
}

/// Runs the loop; `target_noise_m` adds white noise to the target position, as an observer
/// of the parent's pose from vision would leave.
fn run(cfg: &MpcConfig, duration_s: f64, transient_s: f64, target_noise_m: f64) -> Run {
    let mut noise = Noise(12345);
    let plant_cfg = PlantConfig {
        current_ned_mps: [0.1, -0.05, 0.0],
        ..PlantConfig::default()
    };
    let mut plant = Plant::new(
        &plant_cfg,
        PlantState::at_rest(Vector3::new(0.0, 0.0, 10.0), UnitQuaternion::identity()),
    )
    .unwrap();
    let mut nav = NavSensor::new(&NavConfig::default(), 11).unwrap();
    let mut mpc = Mpc::new(cfg, plant.vehicle()).unwrap();
    let dt = cfg.step_s;
    let steps = (duration_s / dt).round() as usize;
    let mut out = Run {
        errors_after_transient: Vec::new(),
        heading_errors_after_transient: Vec::new(),
        taus: Vec::new(),
        failures: 0,
        max_iterations: 0,
    };
    for k in 0..steps {
        let t = k as f64 * dt;
        let truth = *plant.state();
        let m = nav.measure(&truth, false);
        let (p_t, v_t, psi_t) = target_at(t);
        // The planner's job, done here from the true relative position (the planner's
        // observer gives a smooth estimate) and the vehicle's own noisy heading: express
        // the target in the level frame.
        let (_, _, psi) = m.attitude.euler_angles();
        let to_level = Rotation3::from_axis_angle(&Vector3::z_axis(), -psi);
        let pos = truth.position_ned_m;
        let target = MpcTarget {
            position_m: to_level * (p_t - pos)
                + Vector3::from_fn(|_, _| noise.next(target_noise_m)),
            velocity_mps: to_level * v_t,
            yaw_rel_rad: wrap(psi_t - psi),
        };
        let mut nu = Vector6::zeros();
        nu.fixed_rows_mut::<3>(0).copy_from(&m.velocity_body_mps);
        nu.fixed_rows_mut::<3>(3).copy_from(&m.rates_body_radps);
        let input = MpcInput {
            attitude: m.attitude,
            nu,
            target,
        };
        let tau = match mpc.step(&input) {
            Ok(o) => {
                out.max_iterations = out.max_iterations.max(o.iterations);
                assert!(o.cost.is_finite() && o.cost >= -1e-6, "cost {}", o.cost);
                o.tau
            }
            Err(_) => {
                out.failures += 1;
                mpc.fallback()
            }
        };
        for i in 0..6 {
            assert!(
                tau[i].is_finite() && tau[i].abs() <= cfg.thrust_max[i] + 1e-9,
                "step {k}: tau[{i}] = {} beyond ±{}",
                tau[i],
                cfg.thrust_max[i]
            );
        }
        plant.advance(&tau, dt).unwrap();
        // The plant never had to saturate what the MPC asked for.
        assert_eq!(*plant.applied_tau(), tau);
        if t >= transient_s {
            out.taus.push(tau);
            let s = plant.state();
            let (p_t, _, psi_t) = target_at(t + dt);
            out.errors_after_transient
                .push((s.position_ned_m - p_t).norm());
            let (_, _, psi) = s.euler_rpy();
            out.heading_errors_after_transient
                .push(wrap(psi_t - psi).abs());
        }
    }
    out
}

#[test]
fn tracks_a_moving_turning_target_with_bounded_error_and_bounded_thrust() {
    let cfg = MpcConfig::default();
    let r = run(&cfg, 70.0, 20.0, 0.0);
    eprintln!(
        "max err {:.3} m, max heading err {:.4} rad, rms du {:?}, failures {}, max iter {}",
        r.max_error(),
        r.heading_errors_after_transient
            .iter()
            .copied()
            .fold(0.0, f64::max),
        r.rms_du(),
        r.failures,
        r.max_iterations
    );
    assert_eq!(r.failures, 0);
    assert!(
        r.max_error() < 0.5,
        "max error after transient {} m",
        r.max_error()
    );
    let max_heading = r
        .heading_errors_after_transient
        .iter()
        .copied()
        .fold(0.0, f64::max);
    assert!(max_heading < 0.1, "max heading error {max_heading} rad");
}

#[test]
fn larger_rho2_gives_smaller_input_moves() {
    let base = MpcConfig::default();
    let heavy = MpcConfig {
        rho2: base.rho2.map(|w| w * 10.0),
        ..base.clone()
    };
    // With a noisy target (5 cm), as the planner's observer will give it.
    let a = run(&base, 50.0, 20.0, 0.05);
    let b = run(&heavy, 50.0, 20.0, 0.05);
    let (da, db) = (a.rms_du(), b.rms_du());
    eprintln!(
        "rms du base {:.2?} heavy {:.2?}; max err {:.3} / {:.3} m",
        da.as_slice(),
        db.as_slice(),
        a.max_error(),
        b.max_error()
    );
    for i in 0..6 {
        assert!(
            db[i] < da[i],
            "axis {i}: rms Δu {} (heavy) vs {} (base)",
            db[i],
            da[i]
        );
    }
    // Both still track.
    assert!(a.max_error() < 0.5 && b.max_error() < 0.5);
}

#[test]
fn fallback_is_finite_and_decays() {
    let vehicle = sim_plant::model::Vehicle::new(&sim_plant::VehicleParams::default()).unwrap();
    let cfg = MpcConfig::default();
    let mut mpc = Mpc::new(&cfg, &vehicle).unwrap();
    let input = MpcInput {
        attitude: UnitQuaternion::identity(),
        nu: Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        target: MpcTarget {
            position_m: Vector3::new(10.0, -3.0, 2.0),
            velocity_mps: Vector3::new(1.0, 0.0, 0.0),
            yaw_rel_rad: 0.5,
        },
    };
    for _ in 0..5 {
        mpc.step(&input).unwrap();
    }
    let start = *mpc.last_tau();
    assert!(start.norm() > 1.0);
    let mut prev = start.norm();
    for k in 1..=60 {
        let u = mpc.fallback();
        assert!(u.iter().all(|x| x.is_finite()));
        assert!(u.norm() < prev);
        approx::assert_relative_eq!(u, start * cfg.fallback_decay.powi(k), max_relative = 1e-12);
        prev = u.norm();
    }
    assert!(prev < 1e-3 * start.norm());
    // The controller picks up from the decayed input.
    assert!(mpc.step(&input).is_ok());
}

#[test]
fn non_finite_input_is_an_error_and_changes_nothing() {
    let vehicle = sim_plant::model::Vehicle::new(&sim_plant::VehicleParams::default()).unwrap();
    let mut mpc = Mpc::new(&MpcConfig::default(), &vehicle).unwrap();
    let good = MpcInput {
        attitude: UnitQuaternion::identity(),
        nu: Vector6::zeros(),
        target: MpcTarget {
            position_m: Vector3::new(3.0, 0.0, 0.0),
            velocity_mps: Vector3::zeros(),
            yaw_rel_rad: 0.0,
        },
    };
    mpc.step(&good).unwrap();
    let before = *mpc.last_tau();
    let mut bad = good;
    bad.nu[4] = f64::NAN;
    assert_eq!(mpc.step(&bad), Err(MpcError::NonFiniteInput("nu")));
    let mut bad = good;
    bad.target.position_m.y = f64::INFINITY;
    assert_eq!(mpc.step(&bad), Err(MpcError::NonFiniteInput("target")));
    let mut bad = good;
    bad.target.yaw_rel_rad = f64::NAN;
    assert_eq!(mpc.step(&bad), Err(MpcError::NonFiniteInput("target")));
    assert_eq!(*mpc.last_tau(), before);
    let vertical = MpcInput {
        attitude: UnitQuaternion::from_euler_angles(0.0, 1.56, 0.0),
        ..good
    };
    assert!(matches!(
        mpc.step(&vertical),
        Err(MpcError::AttitudeSingular { .. })
    ));
    assert!(mpc.fallback().iter().all(|x| x.is_finite()));
}
