//! The vehicle's own navigation sensors: AHRS (attitude, body rates), DVL (body velocity over
//! ground), pressure depth, and — for the leader only — an absolute position fix.
//!
//! Each reading is the truth plus zero-mean Gaussian noise from a seeded
//! [`rand_chacha::ChaCha8Rng`], so the same seed gives the same readings. Attitude noise is a
//! small rotation applied in the body frame (`q_meas = q_true ⊗ exp(δ/2)`, `δ ~ N(0, σ²I)`),
//! so the measured quaternion stays a unit quaternion and has no Euler singularity.

use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::{PlantError, PlantState};

/// Noise levels of the navigation sensors (1-σ, white, per axis). All must be finite and ≥ 0;
/// zero turns a sensor's noise off.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NavConfig {
    /// AHRS attitude noise per axis, rad. Default 0.003 (≈ 0.17°, a good fibre-optic AHRS).
    pub attitude_noise_rad: f64,
    /// AHRS body-rate noise per axis, rad/s. Default 0.001.
    pub rate_noise_radps: f64,
    /// DVL body-velocity noise per axis, m/s. Default 0.01.
    pub velocity_noise_mps: f64,
    /// Pressure-sensor depth noise, m. Default 0.02.
    pub depth_noise_m: f64,
    /// Absolute position-fix noise per NED axis (leader only), m. Default 0.5.
    pub position_noise_m: f64,
}

impl Default for NavConfig {
    fn default() -> Self {
        Self {
            attitude_noise_rad: 0.003,
            rate_noise_radps: 0.001,
            velocity_noise_mps: 0.01,
            depth_noise_m: 0.02,
            position_noise_m: 0.5,
        }
    }
}

impl NavConfig {
    /// Checks every noise level is finite and non-negative; the error names the key.
    ///
    /// # Errors
    /// [`PlantError::InvalidConfig`] naming the first bad key.
    pub fn validate(&self) -> Result<(), PlantError> {
        let keys = [
            ("nav.attitude_noise_rad", self.attitude_noise_rad),
            ("nav.rate_noise_radps", self.rate_noise_radps),
            ("nav.velocity_noise_mps", self.velocity_noise_mps),
            ("nav.depth_noise_m", self.depth_noise_m),
            ("nav.position_noise_m", self.position_noise_m),
        ];
        for (key, v) in keys {
            if !v.is_finite() || v < 0.0 {
                return Err(PlantError::InvalidConfig(format!(
                    "{key} must be finite and >= 0, got {v}"
                )));
            }
        }
        Ok(())
    }
}

/// One navigation reading: what the vehicle itself knows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NavMeasurement {
    /// AHRS attitude, body→NED.
    pub attitude: UnitQuaternion<f64>,
    /// AHRS body rates `[p q r]`, rad/s.
    pub rates_body_radps: Vector3<f64>,
    /// DVL velocity over ground in the body frame `[u v w]`, m/s.
    pub velocity_body_mps: Vector3<f64>,
    /// Depth (NED z of the body origin), m.
    pub depth_m: f64,
    /// Absolute NED position; `Some` only when asked for (the leader).
    pub position_ned_m: Option<Vector3<f64>>,
}

/// Seeded noisy sensor model. Deterministic: same seed and same truths ⇒ same readings.
#[derive(Debug, Clone)]
pub struct NavSensor {
    cfg: NavConfig,
    rng: ChaCha8Rng,
}

impl NavSensor {
    /// # Errors
    /// [`PlantError::InvalidConfig`] if `cfg` does not validate.
    pub fn new(cfg: &NavConfig, seed: u64) -> Result<Self, PlantError> {
        cfg.validate()?;
        Ok(Self {
            cfg: cfg.clone(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    fn gauss3(&mut self, sigma: f64) -> Vector3<f64> {
        let mut v = Vector3::zeros();
        for x in v.iter_mut() {
            let n: f64 = StandardNormal.sample(&mut self.rng);
            *x = n * sigma;
        }
        v
    }

    /// Reads the sensors at the true state `truth`. The generator is advanced by the same
    /// number of draws whatever `absolute_position` is, so switching it does not change the
    /// other readings.
    pub fn measure(&mut self, truth: &PlantState, absolute_position: bool) -> NavMeasurement {
        let d_att = self.gauss3(self.cfg.attitude_noise_rad);
        let d_rate = self.gauss3(self.cfg.rate_noise_radps);
        let d_vel = self.gauss3(self.cfg.velocity_noise_mps);
        let d_depth: f64 = {
            let n: f64 = StandardNormal.sample(&mut self.rng);
            n * self.cfg.depth_noise_m
        };
        let d_pos = self.gauss3(self.cfg.position_noise_m);
        let attitude = truth.attitude * UnitQuaternion::from_scaled_axis(d_att);
        let rates: Vector3<f64> = truth.nu.fixed_rows::<3>(3).into_owned();
        let vel: Vector3<f64> = truth.nu.fixed_rows::<3>(0).into_owned();
        NavMeasurement {
            attitude,
            rates_body_radps: rates + d_rate,
            velocity_body_mps: vel + d_vel,
            depth_m: truth.position_ned_m.z + d_depth,
            position_ned_m: absolute_position.then(|| truth.position_ned_m + d_pos),
        }
    }
}
