//! Closed loop at library level: `sim_plant::Plant` as the plant, its nav sensors as the
//! measurement, `Mpc` as the controller, a moving target given in the level frame exactly as
//! the planner will give it.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use mpc::closed_loop::{self, target_at, wrap};
use mpc::{Keepout, Mpc, MpcConfig, MpcError, MpcInput, MpcStatus, MpcTarget};
use nalgebra::{UnitQuaternion, Vector3, Vector6};

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

/// Runs the loop; `target_noise_m` adds white noise to the target position, as an observer
/// of the parent's pose from vision would leave.
fn run(cfg: &MpcConfig, duration_s: f64, transient_s: f64, target_noise_m: f64) -> Run {
    let mut out = Run {
        errors_after_transient: Vec::new(),
        heading_errors_after_transient: Vec::new(),
        taus: Vec::new(),
        failures: 0,
        max_iterations: 0,
    };
    let dt = cfg.step_s;
    closed_loop::run(cfg, duration_s, target_noise_m, |s| {
        match s.result {
            Ok(o) => {
                out.max_iterations = out.max_iterations.max(o.iterations);
                assert!(o.cost.is_finite() && o.cost >= -1e-6, "cost {}", o.cost);
            }
            Err(_) => out.failures += 1,
        }
        let tau = s.tau;
        for i in 0..6 {
            assert!(
                tau[i].is_finite() && tau[i].abs() <= cfg.thrust_max[i] + 1e-9,
                "step {}: tau[{i}] = {} beyond ±{}",
                s.k,
                tau[i],
                cfg.thrust_max[i]
            );
        }
        // The plant never had to saturate what the MPC asked for.
        assert_eq!(*s.plant.applied_tau(), tau);
        if s.t >= transient_s {
            out.taus.push(tau);
            let st = s.plant.state();
            let (p_t, _, psi_t) = target_at(s.t + dt);
            out.errors_after_transient
                .push((st.position_ned_m - p_t).norm());
            let (_, _, psi) = st.euler_rpy();
            out.heading_errors_after_transient
                .push(wrap(psi_t - psi).abs());
        }
    })
    .unwrap();
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

/// The unconstrained-first path changes nothing but the time: the same loop with clarabel
/// on every step applies the same inputs (to the solver's tolerance) and tracks the same.
#[test]
fn unconstrained_first_tracks_as_clarabel_alone() {
    let fast = MpcConfig::default();
    let slow = MpcConfig {
        unconstrained_first: false,
        ..fast.clone()
    };
    let (a, b) = (run(&fast, 70.0, 20.0, 0.05), run(&slow, 70.0, 20.0, 0.05));
    let mut shortcut = 0usize;
    closed_loop::run(&fast, 70.0, 0.05, |s| {
        if matches!(s.result, Ok(o) if o.status == MpcStatus::Unconstrained) {
            shortcut += 1;
        }
    })
    .unwrap();
    let max_dtau = a
        .taus
        .iter()
        .zip(&b.taus)
        .map(|(x, y)| (x - y).abs().max())
        .fold(0.0, f64::max);
    eprintln!(
        "unconstrained on {shortcut} of 700 steps; max err {:.4} / {:.4} m; max |Δτ| {max_dtau:.2e}",
        a.max_error(),
        b.max_error()
    );
    assert!(shortcut > 0, "the shortcut never applied");
    assert!(
        shortcut < 700,
        "no step had an active bound: the test shows nothing of clarabel"
    );
    assert!((a.max_error() - b.max_error()).abs() <= 0.05 * b.max_error());
    assert!(max_dtau < 1e-2, "inputs differ by {max_dtau} N");
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
        keepout: Keepout::default(),
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
        keepout: Keepout::default(),
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
