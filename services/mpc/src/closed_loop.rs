//! A closed loop at library level, for tests and benchmarks: `sim_plant::Plant` as the
//! plant, its nav sensors as the measurement, [`Mpc`] as the controller, and a moving,
//! turning target given in the level frame exactly as the planner gives it.

use std::time::{Duration, Instant};

use nalgebra::{Rotation3, UnitQuaternion, Vector3, Vector6};
use sim_plant::nav::{NavConfig, NavMeasurement, NavSensor};
use sim_plant::{Plant, PlantConfig, PlantError, PlantState};

use crate::{Keepout, Mpc, MpcConfig, MpcError, MpcInput, MpcOutput, MpcTarget};

/// The target in NED at time `t`: position, velocity, heading. 1 m/s straight ahead for
/// 30 s, then a starboard turn on a 40 m circle, descending at 0.1 m/s.
#[must_use]
pub fn target_at(t: f64) -> (Vector3<f64>, Vector3<f64>, f64) {
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
        let radius = 40.0;
        let w = speed / radius;
        let a = w * (t - t_turn);
        let centre = start + Vector3::new(speed * t_turn, radius, 0.0);
        let p = centre + Vector3::new(radius * a.sin(), -radius * a.cos(), 0.1 * (t - t_turn));
        let v = Vector3::new(speed * a.cos(), speed * a.sin(), 0.1);
        (p, v, a)
    }
}

/// An angle wrapped to [−π, π).
#[must_use]
pub fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// Uniform pseudo-random numbers of a given standard deviation (deterministic).
#[derive(Debug, Clone)]
pub struct Noise(pub u64);

impl Noise {
    /// The next number, standard deviation `sigma`.
    pub fn next(&mut self, sigma: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        #[allow(clippy::cast_precision_loss)]
        let u = (self.0 >> 11) as f64 / (1u64 << 53) as f64;
        (u - 0.5) * 12f64.sqrt() * sigma
    }
}

/// The body velocity `[u v w p q r]` a nav measurement gives the controller.
#[must_use]
pub fn nu_of(m: &NavMeasurement) -> Vector6<f64> {
    let mut nu = Vector6::zeros();
    nu.fixed_rows_mut::<3>(0).copy_from(&m.velocity_body_mps);
    nu.fixed_rows_mut::<3>(3).copy_from(&m.rates_body_radps);
    nu
}

/// One control step of the loop, as the callback sees it.
#[derive(Debug)]
pub struct LoopStep<'a> {
    /// Control step index.
    pub k: usize,
    /// Time at the start of the step, s.
    pub t: f64,
    /// What the controller returned.
    pub result: &'a Result<MpcOutput, MpcError>,
    /// The input applied (the fallback's on an error).
    pub tau: Vector6<f64>,
    /// Wall time of [`Mpc::step`].
    pub solve: Duration,
    /// The plant after the step.
    pub plant: &'a Plant,
}

/// Runs the loop for `duration_s` from rest at 10 m depth in a 0.1 m/s current, with white
/// noise of `target_noise_m` on the target position (as the planner's observer of the
/// parent's pose from vision leaves); `each` sees every step after the plant advanced.
///
/// # Errors
/// [`MpcError`] if the controller cannot be built; the plant's error if it refuses a step.
pub fn run(
    cfg: &MpcConfig,
    duration_s: f64,
    target_noise_m: f64,
    mut each: impl FnMut(&LoopStep<'_>),
) -> Result<(), LoopError> {
    let mut noise = Noise(12345);
    let plant_cfg = PlantConfig {
        current_ned_mps: [0.1, -0.05, 0.0],
        ..PlantConfig::default()
    };
    let mut plant = Plant::new(
        &plant_cfg,
        PlantState::at_rest(Vector3::new(0.0, 0.0, 10.0), UnitQuaternion::identity()),
    )?;
    let mut nav = NavSensor::new(&NavConfig::default(), 11)?;
    let mut mpc = Mpc::new(cfg, plant.vehicle())?;
    let dt = cfg.step_s;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let steps = (duration_s / dt).round() as usize;
    for k in 0..steps {
        #[allow(clippy::cast_precision_loss)]
        let t = k as f64 * dt;
        let truth = *plant.state();
        let m = nav.measure(&truth, false);
        let (p_t, v_t, psi_t) = target_at(t);
        // The planner's job, done here from the true relative position and the vehicle's
        // own noisy heading: express the target in the level frame.
        let (_, _, psi) = m.attitude.euler_angles();
        let to_level = Rotation3::from_axis_angle(&Vector3::z_axis(), -psi);
        let target = MpcTarget {
            position_m: to_level * (p_t - truth.position_ned_m)
                + Vector3::from_fn(|_, _| noise.next(target_noise_m)),
            velocity_mps: to_level * v_t,
            yaw_rel_rad: wrap(psi_t - psi),
        };
        let input = MpcInput {
            attitude: m.attitude,
            nu: nu_of(&m),
            target,
            keepout: Keepout::default(),
        };
        let t0 = Instant::now();
        let result = mpc.step(&input);
        let solve = t0.elapsed();
        let tau = match &result {
            Ok(o) => o.tau,
            Err(_) => mpc.fallback(),
        };
        plant.advance(&tau, dt)?;
        each(&LoopStep {
            k,
            t,
            result: &result,
            tau,
            solve,
            plant: &plant,
        });
    }
    Ok(())
}

/// Why [`run`] could not run.
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// The controller could not be built.
    #[error(transparent)]
    Mpc(#[from] MpcError),
    /// The plant or its sensors refused their configuration or a step.
    #[error(transparent)]
    Plant(#[from] PlantError),
}
