//! Simulated forward rangefinders ("sonar") for shoal's AUVs.
//!
//! The paper (sec. 2) equips every vehicle with `n` rangefinders that measure the distance
//! `d_j` to an obstacle along a fixed beam `α_j`; the vector `D = (d_1 … d_n)` feeds the
//! planner's eqs. (6)-(8). This crate simulates them as real echosounders: each beam is a
//! cone (default 7° wide, the Kongsberg Simrad ES200-7C's) that returns the nearest echo
//! inside it, found with [`parry3d_f64`] against the scenario's static obstacles
//! ([`ObstacleField`], behind a bounding-volume hierarchy) and, optionally, the other
//! vehicles' hulls (capsules), plus Gaussian range noise, and dropouts (likelier toward
//! the cone's edge, where the echo is weaker) and false echoes where configured. It is one
//! of the two crates allowed to read ground truth (the vehicle poses), and only to simulate
//! what the sensor physically measures.
//!
//! Pure library: state in, values out; no clock, no I/O. parry speaks glam; the nalgebra ↔
//! glam conversion happens here, at the sensor boundary, and nowhere else.
//!
//! Conventions: world NED; body x forward, y starboard, z down; a beam's azimuth is
//! positive to starboard and its elevation positive **down** (towards body +z), as in the
//! `shoal.Sonar.v2` sample.
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
//! // beam 1 looks 10° to port; the nearest point of the wall inside its 7° cone is on
//! // the cone's edge 6.5° to port; the transducer sits 0.8 m forward on the nose
//! let expected = (10.0 - 0.8) / 6.5f64.to_radians().cos();
//! assert!(scan.valid[1] && (scan.ranges_m[1] - expected).abs() < 0.3);
//! ```
#![forbid(unsafe_code)]

mod obstacle;

use nalgebra::{Isometry3, Point3, Unit, Vector3};
use parry3d_f64::math::{Pose, Rot3};
use parry3d_f64::query::{PointQuery, Ray, RayCast};
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
    /// Full width of every beam's cone, deg (default 7, the Kongsberg Simrad ES200-7C
    /// split-beam transducer's, 200 kHz): the beam returns the nearest echo inside it. Its
    /// edge is the one-way −3 dB angle, where the two-way echo is 6 dB below one on the
    /// axis. 0 makes every beam a ray (the paper's rangefinders).
    pub beam_width_deg: f64,
    /// Probability that an echo on a beam's axis is missed (default 0). An echo off the
    /// axis is weaker and missed more often: with `g` its two-way gain (1 on the axis, 1/4
    /// at the cone's edge), `min(1, dropout / g)`.
    pub dropout: f64,
    /// Probability per beam and scan of a false echo (default 0): a return at a range
    /// drawn uniformly in (0, `range_max_m`], reported when it is nearer than the true one.
    pub false_echo: f64,
    /// A forward-looking multibeam in place of `beams` (default none).
    pub multibeam: Option<Multibeam>,
    /// Every beam measures where in its cone the echo came from (default true): a
    /// split-beam transducer like the ES200-7C compares the phase of the echo on its four
    /// quadrants and reports the echo's angles within the beam. The scan then gives each
    /// return's own azimuth and elevation, with `angle_noise_deg` of noise. `false`: a
    /// single-beam echosounder, whose return is known only to lie somewhere in its cone;
    /// the scan gives the beam's axis.
    pub split_beam: bool,
    /// Noise of a split-beam angle, 1σ per axis, deg (default 0.2).
    pub angle_noise_deg: f64,
}

/// A forward-looking multibeam: `beams` cones side by side over a horizontal sector.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Multibeam {
    /// Number of beams, 1 to [`MAX_BEAMS`].
    pub beams: usize,
    /// Horizontal sector they cover, centred ahead, deg, in (0, 180].
    pub sector_deg: f64,
    /// Elevation of every beam, deg, positive down (default 0).
    #[serde(default)]
    pub elevation_deg: f64,
}

impl Multibeam {
    /// The beams: azimuths at the centres of `beams` equal parts of the sector.
    pub fn layout(&self) -> Vec<Beam> {
        let w = self.sector_deg / self.beams as f64;
        (0..self.beams)
            .map(|i| Beam {
                azimuth_deg: -self.sector_deg / 2.0 + w * (i as f64 + 0.5),
                elevation_deg: self.elevation_deg,
            })
            .collect()
    }

    /// Each beam's full width, deg: the sector divided among the beams, so they tile it.
    pub fn beam_width_deg(&self) -> f64 {
        self.sector_deg / self.beams as f64
    }
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
            beam_width_deg: 7.0,
            dropout: 0.0,
            false_echo: 0.0,
            multibeam: None,
            split_beam: true,
            angle_noise_deg: 0.2,
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
        if !(self.beam_width_deg.is_finite() && (0.0..=60.0).contains(&self.beam_width_deg)) {
            return Err(cfg_err(
                "beam_width_deg",
                format!("must be in [0, 60], got {}", self.beam_width_deg),
            ));
        }
        if !(self.angle_noise_deg.is_finite() && (0.0..=10.0).contains(&self.angle_noise_deg)) {
            return Err(cfg_err(
                "angle_noise_deg",
                format!("must be in [0, 10], got {}", self.angle_noise_deg),
            ));
        }
        for (key, p) in [("dropout", self.dropout), ("false_echo", self.false_echo)] {
            if !(p.is_finite() && (0.0..=1.0).contains(&p)) {
                return Err(cfg_err(key, format!("must be in [0, 1], got {p}")));
            }
        }
        if let Some(m) = &self.multibeam {
            if m.beams == 0 || m.beams > MAX_BEAMS {
                return Err(cfg_err(
                    "multibeam.beams",
                    format!("must be 1 to {MAX_BEAMS}, got {}", m.beams),
                ));
            }
            if !(m.sector_deg.is_finite() && m.sector_deg > 0.0 && m.sector_deg <= 180.0) {
                return Err(cfg_err(
                    "multibeam.sector_deg",
                    format!("must be in (0, 180], got {}", m.sector_deg),
                ));
            }
            if !(m.elevation_deg.is_finite() && m.elevation_deg.abs() <= 90.0) {
                return Err(cfg_err(
                    "multibeam.elevation_deg",
                    format!("must be in [-90, 90], got {}", m.elevation_deg),
                ));
            }
            if self.beams != Self::default().beams {
                return Err(cfg_err(
                    "multibeam",
                    "replaces `beams`: set one of the two, not both".into(),
                ));
            }
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

/// The nearest echo of one beam: its range, its angle off the beam's axis and its
/// direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Echo {
    /// Distance from the transducer, m.
    pub range_m: f64,
    /// Angle between the echo's direction and the beam's axis, rad.
    pub off_axis_rad: f64,
    /// Unit direction from the transducer to the echo, body axes.
    pub dir_body: Vector3<f64>,
}

/// Two-way gain of an echo `off_axis` from the axis of a beam of full width `width` (both
/// rad): a Gaussian pattern, one-way −3 dB at the cone's edge (`width / 2`), so the echo
/// there is 6 dB (a quarter) below one on the axis. 1 for a ray.
#[must_use]
pub fn two_way_gain(off_axis: f64, width: f64) -> f64 {
    if width <= 0.0 {
        return 1.0;
    }
    let x = off_axis / width;
    10f64.powf(-2.4 * x * x)
}

/// Angular spacing of the sampled rays' rings inside a cone, rad (6.25°): a beam up to
/// 12.5° wide is sampled by its axis and one ring at its edge (7 rays), a 25° beam by two
/// rings (19 rays).
const RING_STEP_RAD: f64 = 6.25 * std::f64::consts::PI / 180.0;

/// The rangefinder set of one vehicle.
#[derive(Debug, Clone)]
pub struct Sonar {
    cfg: SonarConfig,
    /// Beam axes in body axes.
    dirs_body: [Vector3<f64>; MAX_BEAMS],
    /// Full width of every beam, rad (0 = a ray).
    width: [f64; MAX_BEAMS],
    /// Rays sampling the cones, body axes, with their angle off their beam's axis; beam
    /// `i` owns `rays[ray_start[i]..ray_start[i + 1]]`, its axis first.
    rays: Vec<(Vector3<f64>, f64)>,
    ray_start: [usize; MAX_BEAMS + 1],
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

/// The axis and rings of rays that sample a cone of half angle `half` about `axis` (unit):
/// ring `k` of `K = ceil(half / 6.25°)` at `half·k/K` off the axis with `6k` rays, so the
/// cone's surface (ring `K`) is always among them.
fn cone_rays(axis: &Vector3<f64>, half: f64, out: &mut Vec<(Vector3<f64>, f64)>) {
    out.push((*axis, 0.0));
    if half <= 0.0 {
        return;
    }
    // two unit vectors across the axis
    let helper = if axis.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let u = axis.cross(&helper).normalize();
    let v = axis.cross(&u);
    let rings = (half / RING_STEP_RAD).ceil().max(1.0) as usize;
    for k in 1..=rings {
        let theta = half * k as f64 / rings as f64;
        let n = 6 * k;
        for j in 0..n {
            let phi = std::f64::consts::TAU * j as f64 / n as f64;
            let d = axis * theta.cos() + (u * phi.cos() + v * phi.sin()) * theta.sin();
            out.push((d.normalize(), theta));
        }
    }
}

impl Sonar {
    /// Validates the configuration and precomputes the beams and their sampling rays.
    pub fn new(cfg: &SonarConfig) -> Result<Self, SonarError> {
        cfg.validate()?;
        let (beams, width_deg) = match &cfg.multibeam {
            Some(m) => (m.layout(), m.beam_width_deg()),
            None => (cfg.beams.clone(), cfg.beam_width_deg),
        };
        let mut dirs_body = [Vector3::zeros(); MAX_BEAMS];
        let mut width = [0.0; MAX_BEAMS];
        let mut rays = Vec::new();
        let mut ray_start = [0; MAX_BEAMS + 1];
        let mut template = SonarScan {
            count: beams.len(),
            ..SonarScan::default()
        };
        for (i, b) in beams.iter().enumerate() {
            let (az, el) = (b.azimuth_deg.to_radians(), b.elevation_deg.to_radians());
            dirs_body[i] = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            width[i] = width_deg.to_radians();
            template.azimuth_rad[i] = az;
            template.elevation_rad[i] = el;
            ray_start[i] = rays.len();
            cone_rays(&dirs_body[i], width[i] / 2.0, &mut rays);
        }
        for slot in ray_start.iter_mut().skip(beams.len()) {
            *slot = rays.len();
        }
        let half = (cfg.hull_length_m / 2.0 - cfg.hull_radius_m).max(0.0);
        Ok(Self {
            cfg: cfg.clone(),
            dirs_body,
            width,
            rays,
            ray_start,
            template,
            hull: Capsule::new_x(half, cfg.hull_radius_m),
        })
    }

    /// The configuration this sonar was built with.
    pub fn config(&self) -> &SonarConfig {
        &self.cfg
    }

    /// Full width of beam `i`'s cone, rad (0 for a ray or a beam past `count`).
    #[must_use]
    pub fn beam_width_rad(&self, i: usize) -> f64 {
        self.width.get(i).copied().unwrap_or(0.0)
    }

    /// How far from its reported direction a return may lie, rad: 0 for rays and split
    /// beams (which report the echo's own direction), the full width of the widest cone
    /// for single beams (whose return may lie anywhere in it).
    #[must_use]
    pub fn return_spread_rad(&self) -> f64 {
        if self.cfg.split_beam {
            return 0.0;
        }
        self.width[..self.template.count]
            .iter()
            .copied()
            .fold(0.0, f64::max)
    }

    /// Half angle of the blind wedge the cones leave around the body's x axis, rad: the
    /// least angle between the heading and any cone (0 when a cone holds the heading).
    #[must_use]
    pub fn blind_wedge_rad(&self) -> f64 {
        (0..self.template.count)
            .map(|i| {
                let off = self.dirs_body[i].x.clamp(-1.0, 1.0).acos();
                (off - self.width[i] / 2.0).max(0.0)
            })
            .fold(std::f64::consts::PI, f64::min)
    }

    /// The beams' axes and widths as every scan reports them (`count` beams).
    #[must_use]
    pub fn layout(&self) -> &SonarScan {
        &self.template
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
        self.true_echoes(field, pose, others)
            .map(|e| e.map(|e| e.range_m))
    }

    /// The nearest echo inside every beam's cone (`None` = nothing within `range_max_m`).
    ///
    /// A cone's nearest echo is the least of: the nearest point of each obstacle (and hull)
    /// when that lies inside the cone (exact for a convex obstacle whose nearest point is
    /// in it), and the hits of rays sampling the cone (its axis and rings out to its edge;
    /// the rest). Every echo found is a real surface point inside the cone.
    pub fn true_echoes(
        &self,
        field: &ObstacleField,
        pose: &Isometry3<f64>,
        others: &[Isometry3<f64>],
    ) -> [Option<Echo>; MAX_BEAMS] {
        let mut out = [None; MAX_BEAMS];
        let origin = pose * Point3::from(Vector3::from(self.cfg.mount_position_body_m));
        let max = self.cfg.range_max_m;
        let hull_reach = self.cfg.hull_length_m / 2.0;
        for (i, slot) in out.iter_mut().enumerate().take(self.template.count) {
            let mut best: Option<Echo> = None;
            let axis_body = self.dirs_body[i];
            let mut take = |range: f64, off_axis: f64, dir_body: Vector3<f64>| {
                if range <= max && best.is_none_or(|b| range < b.range_m) {
                    best = Some(Echo {
                        range_m: range,
                        off_axis_rad: off_axis,
                        dir_body: if range > 0.0 { dir_body } else { axis_body },
                    });
                }
            };
            let half = self.width[i] / 2.0;
            for (d, off) in &self.rays[self.ray_start[i]..self.ray_start[i + 1]] {
                let dir = Unit::new_normalize(pose.rotation * d);
                if let Some(t) = field.cast_ray(&origin, &dir, max) {
                    take(t, *off, *d);
                }
            }
            let axis = Unit::new_normalize(pose.rotation * self.dirs_body[i]);
            if half > 0.0 {
                if let Some((t, off, dir)) = field.cone_nearest(&origin, &axis, half, max) {
                    take(t, off, pose.rotation.inverse() * dir);
                }
            }
            if self.cfg.hulls_echo {
                let o = obstacle::pvec(&origin.coords);
                let a = obstacle::pvec(&axis);
                for other in others {
                    if (other.translation.vector - origin.coords).norm() > max + hull_reach {
                        continue;
                    }
                    let hull_pose = to_pose(other);
                    for (d, off) in &self.rays[self.ray_start[i]..self.ray_start[i + 1]] {
                        let dir = pose.rotation * d;
                        let ray = Ray::new(o, obstacle::pvec(&dir));
                        if let Some(t) = self.hull.cast_ray(&hull_pose, &ray, max, true) {
                            take(t, *off, *d);
                        }
                    }
                    if half > 0.0 {
                        let proj = self.hull.project_point(&hull_pose, o, true);
                        if proj.is_inside {
                            take(0.0, 0.0, axis_body);
                        } else if let Some(off) = obstacle::off_axis(proj.point - o, a, half.cos())
                        {
                            let v = proj.point - o;
                            let range = v.length();
                            let w = Vector3::new(v.x, v.y, v.z) / range.max(1e-12);
                            take(range, off, pose.rotation.inverse() * w);
                        }
                    }
                }
            }
            *slot = best;
        }
        out
    }

    /// One scan with range noise, the echo's angles (split beam), and dropouts and false
    /// echoes where configured.
    ///
    /// Each beam draws exactly one standard-normal sample, hit or not, then two more for
    /// the angles of a split beam (a cone, `angle_noise_deg > 0`), one uniform sample if
    /// `dropout > 0` and two if `false_echo > 0`, so the random stream (and hence a seeded
    /// run) does not depend on the geometry. A return is `max(0, d + σ·n)`; if that
    /// exceeds `range_max_m` the beam reports no return (the receiver's range gate), and
    /// its range is set to `range_max_m`. A split beam reports a return's own azimuth and
    /// elevation (a false echo, with no direction of its own, the beam's axis); a beam
    /// without a return, or a single beam, its axis.
    pub fn scan<R: Rng>(
        &self,
        field: &ObstacleField,
        pose: &Isometry3<f64>,
        others: &[Isometry3<f64>],
        rng: &mut R,
    ) -> SonarScan {
        let truth = self.true_echoes(field, pose, others);
        let mut scan = self.template;
        let max = self.cfg.range_max_m;
        for (i, hit) in truth.iter().enumerate().take(scan.count) {
            let n: f64 = rng.sample(StandardNormal);
            let mut range = hit.map(|e| (e.range_m + self.cfg.noise_m * n).max(0.0));
            let mut angles = None;
            if self.cfg.split_beam && self.width[i] > 0.0 {
                let sigma = self.cfg.angle_noise_deg.to_radians();
                let (na, ne): (f64, f64) = if sigma > 0.0 {
                    (rng.sample(StandardNormal), rng.sample(StandardNormal))
                } else {
                    (0.0, 0.0)
                };
                angles = hit.map(|e| {
                    let d = e.dir_body;
                    let az = d.y.atan2(d.x);
                    let el = d.z.clamp(-1.0, 1.0).asin();
                    (az + sigma * na, el + sigma * ne)
                });
            }
            if self.cfg.dropout > 0.0 {
                let u: f64 = rng.random();
                if let Some(e) = hit {
                    let p = self.cfg.dropout / two_way_gain(e.off_axis_rad, self.width[i]);
                    if u < p.min(1.0) {
                        range = None;
                    }
                }
            }
            if self.cfg.false_echo > 0.0 {
                let (u, v): (f64, f64) = (rng.random(), rng.random());
                if u < self.cfg.false_echo {
                    let r = max * (1.0 - v); // (0, max]
                    if range.is_none_or(|x| r < x) {
                        range = Some(r);
                        angles = None;
                    }
                }
            }
            match range {
                Some(r) if r <= max => {
                    scan.ranges_m[i] = r;
                    scan.valid[i] = true;
                    if let Some((az, el)) = angles {
                        scan.azimuth_rad[i] = az;
                        scan.elevation_rad[i] = el;
                    }
                }
                _ => scan.ranges_m[i] = max,
            }
        }
        scan
    }
}
