//! Simulated forward rangefinders ("sonar") for shoal's AUVs.
//!
//! The paper (sec. 2) equips every vehicle with `n` rangefinders that measure the distance
//! `d_j` to an obstacle along a fixed beam `α_j`; the vector `D = (d_1 … d_n)` feeds the
//! planner's eqs. (6)-(8). This crate simulates them: each beam is a ray cast with
//! [`parry3d_f64`] against the scenario's static obstacles ([`ObstacleField`], behind a
//! bounding-volume hierarchy) and, optionally, against the other vehicles' hulls
//! (capsules), plus Gaussian range noise. It is one of the two crates allowed to read ground
//! truth (the vehicle poses), and only to simulate what the sensor physically measures.
//!
//! Pure library: state in, values out; no clock, no I/O. parry speaks glam; the nalgebra ↔
//! glam conversion happens here, at the sensor boundary, and nowhere else.
//!
//! Conventions: world NED; body x forward, y starboard, z down; a beam's azimuth is
//! positive to starboard and its elevation positive **down** (towards body +z), as in the
//! `shoal.Sonar.v1` sample.
//!
//! # Example
//! ```
//! use nalgebra::{Isometry3, Translation3, UnitQuaternion};
//! use rand::SeedableRng;
//! use sonar::{Obstacle, ObstacleField, Sonar, SonarConfig};
//!
//! // A wall 10 m north of the vehicle.
//! let field = ObstacleField::new(&[Obstacle::Box {
//!     center_ned_m: [10.5, 0.0, 0.0],
//!     half_extents_m: [0.5, 50.0, 50.0],
//!     yaw_deg: 0.0,
//! }])
//! .unwrap();
//! let sonar = Sonar::new(&SonarConfig::default()).unwrap();
//! let pose = Isometry3::from_parts(Translation3::identity(), UnitQuaternion::identity());
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
//! let scan = sonar.scan(&field, &pose, &[], &mut rng);
//! assert_eq!(scan.count, 4);
//! // beam 1 looks 10° to port; the transducer sits 0.8 m forward on the nose
//! let expected = (10.0 - 0.8) / 10f64.to_radians().cos();
//! assert!(scan.valid[1] && (scan.ranges_m[1] - expected).abs() < 0.3);
//! ```
#![forbid(unsafe_code)]

mod obstacle;

use nalgebra::{Isometry3, Point3, Unit, Vector3};
use parry3d_f64::math::{Pose, Rot3};
use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::Capsule;
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

pub use obstacle::{Obstacle, ObstacleField};

pub use ipc_types::{SonarScan, MAX_BEAMS};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SonarError {
    /// A configuration key is out of range; `key` is the full key (`sonar.range_max_m`).
    #[error("{key} {reason}")]
    InvalidConfig {
        /// The offending key.
        key: String,
        /// What is wrong with it, including the value.
        reason: String,
    },
    /// An obstacle is malformed (`index` into the scenario's obstacle list, when known).
    #[error("obstacle{}: {reason}", index.map(|i| format!("s[{i}]")).unwrap_or_default())]
    InvalidObstacle {
        /// Position in the obstacle list.
        index: Option<usize>,
        /// What is wrong, naming the key.
        reason: String,
    },
}

/// One rangefinder beam, in body axes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Beam {
    /// Angle from body x towards body y (starboard), deg, in (-180, 180].
    pub azimuth_deg: f64,
    /// Angle below the body x-y plane (positive down), deg, in [-90, 90].
    pub elevation_deg: f64,
}

/// Rangefinder configuration (`[sonar]` in a scenario).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SonarConfig {
    /// Beams; default 4 forward at azimuth −30, −10, 10, 30 deg, elevation 0 (the paper's
    /// "4 rangefinders located in front"). At most [`MAX_BEAMS`].
    pub beams: Vec<Beam>,
    /// Maximum range, m (default 20). Nothing farther echoes.
    pub range_max_m: f64,
    /// Range noise, 1σ, m (default 0.05).
    pub noise_m: f64,
    /// Scan rate, Hz (default 10), not used by [`Sonar::scan`]. In a scenario
    /// the rate is `[rates] sonar_hz` and this key is refused.
    pub rate_hz: f64,
    /// Transducer position in the body frame, m (default `[0.8, 0, 0]`, the nose).
    pub mount_position_body_m: [f64; 3],
    /// Whether other vehicles' hulls return echoes (default false).
    pub hulls_echo: bool,
    /// Hull radius of the other vehicles when `hulls_echo`, m (default 0.25).
    pub hull_radius_m: f64,
    /// Overall hull length (capsule tip to tip) when `hulls_echo`, m (default 1.6).
    pub hull_length_m: f64,
}

impl Default for SonarConfig {
    fn default() -> Self {
        Self {
            beams: [-30.0, -10.0, 10.0, 30.0]
                .iter()
                .map(|&a| Beam {
                    azimuth_deg: a,
                    elevation_deg: 0.0,
                })
                .collect(),
            range_max_m: 20.0,
            noise_m: 0.05,
            rate_hz: 10.0,
            mount_position_body_m: [0.8, 0.0, 0.0],
            hulls_echo: false,
            hull_radius_m: 0.25,
            hull_length_m: 1.6,
        }
    }
}

fn cfg_err(key: &str, reason: String) -> SonarError {
    SonarError::InvalidConfig {
        key: format!("sonar.{key}"),
        reason,
    }
}

impl SonarConfig {
    /// Checks every key; the error names the first bad one.
    pub fn validate(&self) -> Result<(), SonarError> {
        if self.beams.is_empty() || self.beams.len() > MAX_BEAMS {
            return Err(cfg_err(
                "beams",
                format!(
                    "must have 1 to {MAX_BEAMS} entries, got {}",
                    self.beams.len()
                ),
            ));
        }
        for (i, b) in self.beams.iter().enumerate() {
            if !(b.azimuth_deg.is_finite() && b.azimuth_deg > -180.0 && b.azimuth_deg <= 180.0) {
                return Err(cfg_err(
                    &format!("beams[{i}].azimuth_deg"),
                    format!("must be in (-180, 180], got {}", b.azimuth_deg),
                ));
            }
            if !(b.elevation_deg.is_finite() && b.elevation_deg.abs() <= 90.0) {
                return Err(cfg_err(
                    &format!("beams[{i}].elevation_deg"),
                    format!("must be in [-90, 90], got {}", b.elevation_deg),
                ));
            }
        }
        if !(self.range_max_m.is_finite() && self.range_max_m > 0.0) {
            return Err(cfg_err(
                "range_max_m",
                format!("must be finite and > 0, got {}", self.range_max_m),
            ));
        }
        if !(self.noise_m.is_finite() && self.noise_m >= 0.0) {
            return Err(cfg_err(
                "noise_m",
                format!("must be finite and >= 0, got {}", self.noise_m),
            ));
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return Err(cfg_err(
                "rate_hz",
                format!("must be finite and > 0, got {}", self.rate_hz),
            ));
        }
        if !self.mount_position_body_m.iter().all(|x| x.is_finite()) {
            return Err(cfg_err(
                "mount_position_body_m",
                format!("must be finite, got {:?}", self.mount_position_body_m),
            ));
        }
        if !(self.hull_radius_m.is_finite() && self.hull_radius_m > 0.0) {
            return Err(cfg_err(
                "hull_radius_m",
                format!("must be finite and > 0, got {}", self.hull_radius_m),
            ));
        }
        if !(self.hull_length_m.is_finite() && self.hull_length_m >= 2.0 * self.hull_radius_m) {
            return Err(cfg_err(
                "hull_length_m",
                format!(
                    "must be finite and >= 2 * hull_radius_m ({}), got {}",
                    2.0 * self.hull_radius_m,
                    self.hull_length_m
                ),
            ));
        }
        Ok(())
    }
}

/// The rangefinder set of one vehicle.
#[derive(Debug, Clone)]
pub struct Sonar {
    cfg: SonarConfig,
    /// Beam unit vectors in body axes.
    dirs_body: [Vector3<f64>; MAX_BEAMS],
    template: SonarScan,
    hull: Capsule,
}

fn to_pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    Pose::from_parts(
        obstacle::pvec(&iso.translation.vector),
        Rot3::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

impl Sonar {
    /// Validates the configuration and precomputes the beam directions.
    pub fn new(cfg: &SonarConfig) -> Result<Self, SonarError> {
        cfg.validate()?;
        let mut dirs_body = [Vector3::zeros(); MAX_BEAMS];
        let mut template = SonarScan {
            count: cfg.beams.len(),
            ..SonarScan::default()
        };
        for (i, b) in cfg.beams.iter().enumerate() {
            let (az, el) = (b.azimuth_deg.to_radians(), b.elevation_deg.to_radians());
            dirs_body[i] = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            template.azimuth_rad[i] = az;
            template.elevation_rad[i] = el;
        }
        let half = (cfg.hull_length_m / 2.0 - cfg.hull_radius_m).max(0.0);
        Ok(Self {
            cfg: cfg.clone(),
            dirs_body,
            template,
            hull: Capsule::new_x(half, cfg.hull_radius_m),
        })
    }

    /// The configuration this sonar was built with.
    pub fn config(&self) -> &SonarConfig {
        &self.cfg
    }

    /// Noise-free range of every beam (m, `None` = nothing within `range_max_m`).
    ///
    /// `pose` is the vehicle's body→NED pose; `others` are the other vehicles' poses, used
    /// only if `hulls_echo` (each hull a capsule along its body x).
    pub fn true_ranges(
        &self,
        field: &ObstacleField,
        pose: &Isometry3<f64>,
        others: &[Isometry3<f64>],
    ) -> [Option<f64>; MAX_BEAMS] {
        let mut out = [None; MAX_BEAMS];
        let origin = pose * Point3::from(Vector3::from(self.cfg.mount_position_body_m));
        let max = self.cfg.range_max_m;
        let reach = max + self.cfg.hull_length_m / 2.0;
        for (i, slot) in out.iter_mut().enumerate().take(self.template.count) {
            let dir = Unit::new_normalize(pose.rotation * self.dirs_body[i]);
            let mut best = field.cast_ray(&origin, &dir, max);
            if self.cfg.hulls_echo {
                let ray = Ray::new(obstacle::pvec(&origin.coords), obstacle::pvec(&dir));
                for other in others {
                    if (other.translation.vector - origin.coords).norm() > reach {
                        continue;
                    }
                    let limit = best.unwrap_or(max);
                    if let Some(t) = self.hull.cast_ray(&to_pose(other), &ray, limit, true) {
                        if t < limit {
                            best = Some(t);
                        }
                    }
                }
            }
            *slot = best;
        }
        out
    }

    /// One scan with range noise.
    ///
    /// Each beam draws exactly one standard-normal sample, hit or not, so the random stream
    /// (and hence a seeded run) does not depend on the geometry. A return is
    /// `max(0, d + σ·n)`; if that exceeds `range_max_m` the beam reports no return (the
    /// receiver's range gate), and its range is set to `range_max_m`.
    pub fn scan<R: Rng>(
        &self,
        field: &ObstacleField,
        pose: &Isometry3<f64>,
        others: &[Isometry3<f64>],
        rng: &mut R,
    ) -> SonarScan {
        let truth = self.true_ranges(field, pose, others);
        let mut scan = self.template;
        let max = self.cfg.range_max_m;
        for (i, hit) in truth.iter().enumerate().take(scan.count) {
            let n: f64 = rng.sample(StandardNormal);
            match *hit {
                Some(d) => {
                    let r = (d + self.cfg.noise_m * n).max(0.0);
                    if r <= max {
                        scan.ranges_m[i] = r;
                        scan.valid[i] = true;
                    } else {
                        scan.ranges_m[i] = max;
                    }
                }
                None => scan.ranges_m[i] = max,
            }
        }
        scan
    }
}
