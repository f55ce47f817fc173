//! Acceptance tests of issue 3: energy, skew-symmetry, steady surge speed, RK4 order,
//! self-righting, pitch through ±90°, non-finite handling, current, config.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use approx::assert_relative_eq;
use nalgebra::{UnitQuaternion, Vector3, Vector6};
use proptest::prelude::*;
use sim_plant::model::Vehicle;
use sim_plant::{Plant, PlantConfig, PlantError, PlantState, VehicleParams};

fn nu_strategy() -> impl Strategy<Value = Vector6<f64>> {
    (
        -2.0..2.0f64,
        -1.0..1.0f64,
        -1.0..1.0f64,
        -1.0..1.0f64,
        -1.0..1.0f64,
        -1.0..1.0f64,
    )
        .prop_map(|(u, v, w, p, q, r)| Vector6::new(u, v, w, p, q, r))
}

fn attitude_strategy() -> impl Strategy<Value = UnitQuaternion<f64>> {
    (-3.1..3.1f64, -1.5..1.5f64, -3.1..3.1f64)
        .prop_map(|(r, p, y)| UnitQuaternion::from_euler_angles(r, p, y))
}

fn energy(plant: &Plant) -> (f64, f64) {
    let s = plant.state();
    let v = plant.vehicle();
    (
        v.kinetic_energy(&s.nu),
        v.potential_energy(&s.position_ned_m, &s.attitude),
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    /// τ = 0, neutral buoyancy and CG = CB (so g ≡ 0): kinetic energy never increases.
    #[test]
    fn kinetic_energy_never_increases_without_thrust(nu in nu_strategy(), att in attitude_strategy(), munk in any::<bool>()) {
        let config = PlantConfig {
            vehicle: VehicleParams { cb_body_m: [0.0; 3], munk_moment: munk, ..VehicleParams::default() },
            ..PlantConfig::default()
        };
        let mut plant = Plant::new(&config, PlantState { position_ned_m: Vector3::zeros(), attitude: att, nu }).unwrap();
        let mut prev = energy(&plant).0;
        for _ in 0..1500 {
            plant.advance(&Vector6::zeros(), 0.01).unwrap();
            let ke = energy(&plant).0;
            prop_assert!(ke <= prev * (1.0 + 1e-12) + 1e-15, "KE rose from {prev} to {ke}");
            prev = ke;
        }
    }

    /// τ = 0, neutral buoyancy, the paper's vehicle (CG below CB): kinetic + hydrostatic
    /// potential energy never increases (KE alone may, as a heeled vehicle rights itself).
    #[test]
    fn mechanical_energy_never_increases_without_thrust(nu in nu_strategy(), att in attitude_strategy()) {
        let config = PlantConfig::default();
        let mut plant = Plant::new(&config, PlantState { position_ned_m: Vector3::new(0.0, 0.0, 10.0), attitude: att, nu }).unwrap();
        let (k, p) = energy(&plant);
        let mut prev = k + p;
        for _ in 0..1500 {
            plant.advance(&Vector6::zeros(), 0.01).unwrap();
            let (k, p) = energy(&plant);
            // Potential energy is ~W·z ≈ 3e4 J in absolute terms: allow its round-off.
            prop_assert!(k + p <= prev + 1e-9, "E rose from {prev} to {}", k + p);
            prev = k + p;
        }
    }

    /// νᵀ C(ν) ν = 0 to machine precision (C skew-symmetric), with and without Munk terms,
    /// with the CG away from the origin.
    #[test]
    fn coriolis_does_no_work(nu in nu_strategy(), munk in any::<bool>(), gx in -0.1..0.1f64, gz in -0.1..0.1f64) {
        let v = Vehicle::new(&VehicleParams { munk_moment: munk, cg_body_m: [gx, 0.01, gz], ..VehicleParams::default() }).unwrap();
        let c = v.coriolis(&nu);
        let work = nu.dot(&(c * nu));
        let scale = nu.abs().dot(&(c.abs() * nu.abs()));
        prop_assert!(work.abs() <= 16.0 * f64::EPSILON * scale.max(1e-300), "work {work}, scale {scale}");
        prop_assert!(nu.dot(&v.coriolis_force(&nu)).abs() <= 16.0 * f64::EPSILON * scale.max(1e-300));
    }
}

#[test]
fn constant_surge_thrust_settles_at_drag_balance_speed() {
    let config = PlantConfig::default();
    let p = &config.vehicle;
    let (d1, d2) = (p.damping_linear[0], p.damping_quadratic[0]);
    for tau_x in [50.0, 200.0, 450.0, -150.0] {
        let mut plant = Plant::new(&config, PlantState::default()).unwrap();
        let tau = Vector6::new(tau_x, 0.0, 0.0, 0.0, 0.0, 0.0);
        plant.advance(&tau, 60.0).unwrap();
        // d1·u + d2·u|u| = τx  ⇒  |u| = (−d1 + √(d1² + 4 d2 |τx|)) / (2 d2)
        let u = f64::signum(tau_x) * (-d1 + (d1 * d1 + 4.0 * d2 * tau_x.abs()).sqrt()) / (2.0 * d2);
        let nu = plant.state().nu;
        assert!(
            (nu[0] - u).abs() < 1e-3,
            "τx = {tau_x}: u = {} vs {u}",
            nu[0]
        );
        assert!(nu.rows(1, 5).norm() < 1e-9);
    }
}

#[test]
fn thrust_is_saturated_per_axis() {
    let config = PlantConfig::default();
    let mut plant = Plant::new(&config, PlantState::default()).unwrap();
    plant
        .advance(&Vector6::new(1e4, -1e4, 10.0, -1e3, 0.0, 1e3), 0.01)
        .unwrap();
    let m = config.thrust_max;
    assert_eq!(
        *plant.applied_tau(),
        Vector6::new(m[0], -m[1], 10.0, -m[3], 0.0, m[5])
    );
}

fn run_with_step(step_s: f64, initial: PlantState, tau: &Vector6<f64>, t: f64) -> PlantState {
    let config = PlantConfig {
        step_s,
        ..PlantConfig::default()
    };
    let mut plant = Plant::new(&config, initial).unwrap();
    plant.advance(tau, t).unwrap();
    *plant.state()
}

fn state_error(a: &PlantState, b: &PlantState) -> f64 {
    let dq = if a.attitude.coords.dot(&b.attitude.coords) < 0.0 {
        (a.attitude.coords + b.attitude.coords).amax()
    } else {
        (a.attitude.coords - b.attitude.coords).amax()
    };
    (a.position_ned_m - b.position_ned_m)
        .amax()
        .max((a.nu - b.nu).amax())
        .max(dq)
}

/// Halving the RK4 step cuts the error against a fine-step reference by 16 ± 4 (4th order).
#[test]
fn rk4_error_falls_sixteen_fold_per_halving() {
    let initial = PlantState {
        position_ned_m: Vector3::new(0.0, 0.0, 5.0),
        attitude: UnitQuaternion::from_euler_angles(0.2, -0.3, 0.5),
        nu: Vector6::new(1.0, 0.4, -0.3, 0.4, -0.3, 0.5),
    };
    let tau = Vector6::new(300.0, 100.0, -80.0, 30.0, 60.0, -70.0);
    let t = 2.0;
    let reference = run_with_step(0.1 / 256.0, initial, &tau, t);
    let e1 = state_error(&run_with_step(0.1, initial, &tau, t), &reference);
    let e2 = state_error(&run_with_step(0.05, initial, &tau, t), &reference);
    let ratio = e1 / e2;
    assert!(
        (12.0..=20.0).contains(&ratio),
        "error ratio {ratio} (e(h) = {e1:e}, e(h/2) = {e2:e})"
    );
}

fn heel_test(cg_z: f64, cb_z: f64) -> (f64, f64) {
    let config = PlantConfig {
        vehicle: VehicleParams {
            cg_body_m: [0.0, 0.0, cg_z],
            cb_body_m: [0.0, 0.0, cb_z],
            ..VehicleParams::default()
        },
        ..PlantConfig::default()
    };
    let heel = 30f64.to_radians();
    let mut plant = Plant::new(
        &config,
        PlantState::at_rest(
            Vector3::new(0.0, 0.0, 10.0),
            UnitQuaternion::from_euler_angles(heel, 0.0, 0.0),
        ),
    )
    .unwrap();
    let mut min_roll = f64::INFINITY;
    for _ in 0..600 {
        plant.advance(&Vector6::zeros(), 0.1).unwrap();
        min_roll = min_roll.min(plant.state().euler_rpy().0.abs());
    }
    (plant.state().euler_rpy().0.abs(), min_roll)
}

#[test]
fn heeled_vehicle_rights_itself_when_cg_below_cb() {
    // Default: CG at origin, CB 0.05 m above (z up is negative in FRD).
    let (final_roll, _) = heel_test(0.0, -0.05);
    assert!(final_roll < 0.5f64.to_radians(), "final roll {final_roll}");
}

#[test]
fn heeled_vehicle_capsizes_when_cg_above_cb() {
    let (final_roll, min_roll) = heel_test(0.0, 0.05);
    // It never comes back toward upright and ends up inverted.
    assert!(min_roll >= 30f64.to_radians() - 1e-9, "min roll {min_roll}");
    assert!(final_roll > 170f64.to_radians(), "final roll {final_roll}");
}

#[test]
fn pitches_through_vertical_without_blowing_up() {
    let config = PlantConfig::default();
    let mut plant = Plant::new(
        &config,
        PlantState::at_rest(Vector3::new(0.0, 0.0, 20.0), UnitQuaternion::identity()),
    )
    .unwrap();
    // 200 N·m beats the 159 N·m maximum righting moment: the vehicle loops in pitch.
    let tau = Vector6::new(0.0, 0.0, 0.0, 0.0, 200.0, 0.0);
    let (mut nose_up, mut nose_down_after) = (false, false);
    for _ in 0..600 {
        plant.advance(&tau, 0.05).unwrap();
        let s = plant.state();
        assert!(s.is_finite());
        assert_relative_eq!(s.attitude.norm(), 1.0, epsilon = 1e-12);
        let (r, p, y) = s.euler_rpy();
        assert!(r.is_finite() && p.is_finite() && y.is_finite());
        let nose_z = s.attitude.transform_vector(&Vector3::x()).z;
        if nose_z < -0.999 {
            nose_up = true;
        }
        if nose_up && nose_z > 0.999 {
            nose_down_after = true;
        }
    }
    assert!(nose_up, "never pitched through +90°");
    assert!(nose_down_after, "never came over the top through −90°");
}

#[test]
fn non_finite_input_is_an_error_and_state_untouched() {
    let config = PlantConfig::default();
    let start = PlantState {
        nu: Vector6::new(1.0, 0.0, 0.0, 0.0, 0.1, 0.0),
        ..PlantState::default()
    };
    let mut plant = Plant::new(&config, start).unwrap();
    plant
        .advance(&Vector6::new(100.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0.1)
        .unwrap();
    let before = *plant.state();
    let tau_before = *plant.applied_tau();
    let mut nan_tau = Vector6::zeros();
    nan_tau[3] = f64::NAN;
    assert_eq!(
        plant.advance(&nan_tau, 0.1),
        Err(PlantError::NonFiniteInput("tau"))
    );
    let mut inf_tau = Vector6::zeros();
    inf_tau[0] = f64::INFINITY;
    assert!(plant.advance(&inf_tau, 0.1).is_err());
    assert_eq!(
        plant.advance(&Vector6::zeros(), f64::NAN),
        Err(PlantError::NonFiniteInput("duration_s"))
    );
    assert!(matches!(
        plant.advance(&Vector6::zeros(), -1.0),
        Err(PlantError::InvalidInput(_))
    ));
    assert_eq!(*plant.state(), before);
    assert_eq!(*plant.applied_tau(), tau_before);

    let mut bad = start;
    bad.position_ned_m.x = f64::NAN;
    assert!(Plant::new(&config, bad).is_err());
    assert!(plant.set_state(bad).is_err());
    assert_eq!(*plant.state(), before);
}

#[test]
fn blow_up_during_integration_is_an_error_and_state_untouched() {
    let config = PlantConfig::default();
    // Finite but absurd: the quadratic damping overflows to infinity in the first substep.
    let start = PlantState {
        nu: Vector6::new(1e200, 0.0, 0.0, 0.0, 0.0, 1e200),
        ..PlantState::default()
    };
    let mut plant = Plant::new(&config, start).unwrap();
    assert_eq!(
        plant.advance(&Vector6::zeros(), 0.1),
        Err(PlantError::NonFiniteState)
    );
    assert_eq!(*plant.state(), start);
}

#[test]
fn zero_duration_does_not_move_the_state() {
    let mut plant = Plant::new(&PlantConfig::default(), PlantState::default()).unwrap();
    plant.advance(&Vector6::repeat(10.0), 0.0).unwrap();
    assert_eq!(*plant.state(), PlantState::default());
}

#[test]
fn drifts_with_the_ocean_current() {
    let config = PlantConfig {
        current_ned_mps: [0.3, -0.2, 0.0],
        ..PlantConfig::default()
    };
    // Heading east: the north current is a sway to port in the body frame.
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    let mut plant = Plant::new(&config, PlantState::at_rest(Vector3::zeros(), q)).unwrap();
    plant.advance(&Vector6::zeros(), 200.0).unwrap();
    let s = plant.state();
    let v_ned = s
        .attitude
        .transform_vector(&s.nu.fixed_rows::<3>(0).into_owned());
    assert_relative_eq!(v_ned, Vector3::new(0.3, -0.2, 0.0), epsilon = 1e-3);
}

/// A cross-current zone across a northbound vehicle's path: inside, a drifting hull takes the
/// zone's current; past it, the sideways drift decays again (damping only, no current).
#[test]
fn a_current_zone_drifts_a_vehicle_only_while_it_is_inside() {
    use sim_plant::current::CurrentZone;
    let config = PlantConfig {
        current_zones: vec![CurrentZone {
            center_ne_m: [0.0, 0.0],
            half_length_m: 500.0,
            half_width_m: 500.0,
            yaw_deg: 0.0,
            current_ned_mps: [0.0, 0.25, 0.0],
            edge_m: 10.0,
        }],
        ..PlantConfig::default()
    };
    let mut plant = Plant::new(&config, PlantState::default()).unwrap();
    plant.advance(&Vector6::zeros(), 300.0).unwrap();
    let s = plant.state();
    let v = s
        .attitude
        .transform_vector(&s.nu.fixed_rows::<3>(0).into_owned());
    assert_relative_eq!(v, Vector3::new(0.0, 0.25, 0.0), epsilon = 2e-3);
    // far outside the zone (a hull placed there at rest) there is no drift
    let mut outside = Plant::new(
        &config,
        PlantState::at_rest(Vector3::new(0.0, 2000.0, 0.0), UnitQuaternion::identity()),
    )
    .unwrap();
    outside.advance(&Vector6::zeros(), 50.0).unwrap();
    assert!(outside.state().nu.fixed_rows::<3>(0).norm() < 1e-9);
    // a bad zone names its key
    let mut bad = config.clone();
    bad.current_zones[0].half_width_m = 0.0;
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("current_zones[0].half_width_m"), "{e}");
}

#[test]
fn config_defaults_round_trip_through_toml_and_unknown_keys_are_refused() {
    let config = PlantConfig::default();
    let text = toml::to_string(&config).unwrap();
    let back: PlantConfig = toml::from_str(&text).unwrap();
    assert_eq!(back, config);
    let partial: PlantConfig =
        toml::from_str("step_s = 0.005\n[vehicle]\nmass_kg = 300.0\n").unwrap();
    assert_eq!(partial.step_s, 0.005);
    assert_eq!(partial.vehicle.mass_kg, 300.0);
    assert_eq!(partial.vehicle.inertia_kgm2, [225.0, 175.0, 215.0]);
    assert!(toml::from_str::<PlantConfig>("step = 0.01").is_err());
}

#[test]
fn validate_names_the_bad_key() {
    let mut c = PlantConfig::default();
    c.vehicle.damping_quadratic[2] = -1.0;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("vehicle.damping_quadratic"), "{e}");
    let c = PlantConfig {
        step_s: 0.0,
        ..PlantConfig::default()
    };
    assert!(c.validate().unwrap_err().to_string().contains("step_s"));
    let c = PlantConfig {
        thrust_max: [1.0, 1.0, f64::NAN, 1.0, 1.0, 1.0],
        ..PlantConfig::default()
    };
    assert!(c.validate().unwrap_err().to_string().contains("thrust_max"));
    assert!(Plant::new(&c, PlantState::default()).is_err());
}
