//! Configuration: camera, beacon layout, hull, pose solver. Every field has a
//! documented default and unit; `validate()` names the bad key.

use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::MAX_BEACONS;

/// Errors of this crate: configuration that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// A configuration value is out of range; `key` names it (e.g. `camera.fov_deg`).
    #[error("{key} {reason}")]
    InvalidConfig {
        /// The offending key, with its table prefix.
        key: &'static str,
        /// What is wrong, with the value that was given.
        reason: String,
    },
}

fn invalid(key: &'static str, reason: String) -> CameraError {
    CameraError::InvalidConfig { key, reason }
}

fn finite3(key: &'static str, v: &[f64; 3]) -> Result<(), CameraError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(invalid(key, format!("must be finite, got {v:?}")))
    }
}

/// The follower's camera: a distortion-free pinhole.
///
/// The camera frame is the usual optical frame: origin at the centre of
/// projection, `z` forward along the optical axis, `x` right and `y` down in
/// the image. With `mount_rpy_deg = [0, 0, 0]` the optical axis is the body
/// `x` axis (forward), image right is body `y` (starboard) and image down is
/// body `z` (down). `mount_rpy_deg` then rotates that camera (roll, pitch, yaw
/// in the Fossen ZYX convention, about the camera's own forward/right/down
/// axes), so `[0, 20, 0]` tilts it 20° up and `[0, 0, -30]` turns it 30° to
/// port.
///
/// Pixels `(u, v)` are measured from the top-left corner of the image, `u`
/// right and `v` down; the principal point is the image centre
/// `(width_px / 2, height_px / 2)`; pixels are square and the focal length is
/// `f = (width_px / 2) / tan(fov_deg / 2)` px (so the vertical field of view
/// follows from the aspect ratio).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Image width, px. Default 512 (the paper's camera).
    pub width_px: u32,
    /// Image height, px. Default 512.
    pub height_px: u32,
    /// Horizontal field of view, degrees, in (0, 180). Default 90.
    pub fov_deg: f64,
    /// Camera centre in the follower body frame, m. Default `[1.4, 0, 0]`
    /// (in the nose of a 3 m hull).
    pub mount_position_body_m: [f64; 3],
    /// Mount rotation (roll, pitch, yaw), degrees, see the type's docs.
    /// Default `[0, 0, 0]`: looking along body +x.
    pub mount_rpy_deg: [f64; 3],
    /// Frame rate, Hz. Default 10. A program that builds the config sets it;
    /// in a scenario the rate is `[rates] camera_hz` and this key is refused.
    pub rate_hz: f64,
    /// Standard deviation of the Gaussian pixel noise on each coordinate, px.
    /// Default 1.0.
    pub noise_px: f64,
    /// The water's visibility, m. Default 12. With the point model, beacons
    /// farther than this from the camera are not seen; with the image model
    /// it sets the water's attenuation (see `camera_sim::OpticsConfig`), so
    /// that a beacon at this range is just at the detector's threshold.
    pub visibility_range_m: f64,
    /// What the camera gives camera-pose: `"point"` (the default; beacon
    /// pixels projected from truth with `noise_px` and identities attached)
    /// or `"image"` (a rendered 8-bit frame in which camera-pose finds and
    /// identifies the beacons itself; a `camera-sim` process per follower).
    pub model: shoal_scenario::CameraModel,
    /// With the image model: frames recorded per second of simulated time,
    /// at most `[rates] camera_hz` (every frame). Default 1 (about 0.1 MB/s
    /// of compressed 512×512 frames per follower).
    pub record_hz: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            width_px: 512,
            height_px: 512,
            fov_deg: 90.0,
            mount_position_body_m: [1.4, 0.0, 0.0],
            mount_rpy_deg: [0.0, 0.0, 0.0],
            rate_hz: 10.0,
            noise_px: 1.0,
            visibility_range_m: 12.0,
            model: shoal_scenario::CameraModel::Point,
            record_hz: 1.0,
        }
    }
}

impl CameraConfig {
    /// Checks every field; the error names the key.
    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width_px == 0 || self.width_px > 65_536 {
            return Err(invalid(
                "camera.width_px",
                format!("must be in [1, 65536], got {}", self.width_px),
            ));
        }
        if self.height_px == 0 || self.height_px > 65_536 {
            return Err(invalid(
                "camera.height_px",
                format!("must be in [1, 65536], got {}", self.height_px),
            ));
        }
        if !(self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            return Err(invalid(
                "camera.fov_deg",
                format!("must be in (0, 180), got {}", self.fov_deg),
            ));
        }
        finite3("camera.mount_position_body_m", &self.mount_position_body_m)?;
        finite3("camera.mount_rpy_deg", &self.mount_rpy_deg)?;
        if !(self.rate_hz > 0.0 && self.rate_hz.is_finite()) {
            return Err(invalid(
                "camera.rate_hz",
                format!("must be positive and finite, got {}", self.rate_hz),
            ));
        }
        if !(self.noise_px >= 0.0 && self.noise_px.is_finite()) {
            return Err(invalid(
                "camera.noise_px",
                format!("must be >= 0 and finite, got {}", self.noise_px),
            ));
        }
        if !(self.record_hz > 0.0 && self.record_hz.is_finite()) {
            return Err(invalid(
                "camera.record_hz",
                format!("must be positive and finite, got {}", self.record_hz),
            ));
        }
        if self.model == shoal_scenario::CameraModel::Image
            && (self.width_px as usize) * (self.height_px as usize) > ipc_types::MAX_IMAGE_BYTES
        {
            return Err(invalid(
                "camera.width_px",
                format!(
                    "{}×{} px is more than an image sample holds ({} px)",
                    self.width_px,
                    self.height_px,
                    ipc_types::MAX_IMAGE_BYTES
                ),
            ));
        }
        if self.visibility_range_m.is_nan() || self.visibility_range_m <= 0.0 {
            return Err(invalid(
                "camera.visibility_range_m",
                format!("must be positive, got {}", self.visibility_range_m),
            ));
        }
        Ok(())
    }

    /// Focal length, px: `(width_px / 2) / tan(fov_deg / 2)`.
    pub fn focal_px(&self) -> f64 {
        0.5 * f64::from(self.width_px) / (0.5 * self.fov_deg.to_radians()).tan()
    }

    /// Principal point `(c_u, c_v)`, px: the image centre.
    pub fn principal_point_px(&self) -> [f64; 2] {
        [
            0.5 * f64::from(self.width_px),
            0.5 * f64::from(self.height_px),
        ]
    }

    /// The camera's pose in the follower body frame, `T_C^F` (camera optical
    /// frame → body): rotation `R_C^F` and translation `X_C^F` of eq. (3).
    pub fn camera_in_body(&self) -> Isometry3<f64> {
        let [r, p, y] = self.mount_rpy_deg;
        let mount = nalgebra::UnitQuaternion::from_euler_angles(
            r.to_radians(),
            p.to_radians(),
            y.to_radians(),
        );
        // Optical (x right, y down, z forward) → camera-body (x forward,
        // y right, z down): columns are the optical axes in camera-body axes.
        let base = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, //
            1.0, 0.0, 0.0, //
            0.0, 1.0, 0.0,
        ));
        let rot = mount * nalgebra::UnitQuaternion::from_rotation_matrix(&base);
        Isometry3::from_parts(Vector3::from(self.mount_position_body_m).into(), rot)
    }
}

/// Light beacons on the PARENT vehicle, in the parent's body frame (x
/// forward, y starboard, z down), m. Beacon `i` keeps its index everywhere:
/// identities are known (each beacon is recognisable in the image).
///
/// The default is four beacons at the stern of a 3 m long, 0.3 m radius hull
/// (the paper uses four at the stern), placed on the tail cone and the tips
/// of the cruciform tail fins (0.4 m from the axis):
///
/// | beacon | where | position (m) |
/// |---|---|---|
/// | 0 | tail-cone tip | `[-1.50, 0.00, 0.00]` |
/// | 1 | top fin tip, forward edge | `[-1.00, 0.00, -0.40]` |
/// | 2 | starboard fin tip | `[-1.25, 0.40, 0.00]` |
/// | 3 | port fin tip | `[-1.25, -0.40, 0.00]` |
///
/// The lights shine aft: each is seen only from within
/// `emission_half_angle_deg` (default 100°, a little more than a hemisphere,
/// as for a light standing proud of the tail cone or a fin tip) of
/// `facing_body` (default `[-1, 0, 0]`, aft). Set the half-angle to 180 for
/// omnidirectional lights. The camera model hides a beacon seen from outside
/// its cone, and the pose solver uses the same fact to reject a mirrored
/// solution that would put the camera where the lights cannot be seen (for
/// instance in front of the parent); see [`crate::PoseConfig::emission_margin_deg`].
///
/// Why: (1) they are **not coplanar** (beacon 1 stands 0.4 m off the plane of
/// the other three), and four non-coplanar points with known identities have
/// one PnP solution, whereas four coplanar points admit the two-fold
/// "flipped" solution that makes heading unreliable; (2) the **spread** is as
/// wide as the hull allows (0.8 m across, 0.5 m along the axis, 0.4 m up),
/// since the position error of PnP grows as range² / baseline; (3) the 0.5 m
/// **depth** spread along the hull axis gives parallax, which is what makes
/// heading observable when the follower looks at the parent from behind.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BeaconLayout {
    /// Beacon positions in the parent's body frame, m. 3 to [`MAX_BEACONS`].
    pub positions_body_m: Vec<[f64; 3]>,
    /// Direction the lights shine towards, parent body frame (need not be
    /// unit length). Default `[-1, 0, 0]`: aft.
    pub facing_body: [f64; 3],
    /// Half-angle of each light's emission cone about `facing_body`,
    /// degrees, in (0, 180]; 180 = seen from everywhere. Default 100.
    pub emission_half_angle_deg: f64,
}

impl Default for BeaconLayout {
    fn default() -> Self {
        Self {
            positions_body_m: vec![
                [-1.50, 0.00, 0.00],
                [-1.00, 0.00, -0.40],
                [-1.25, 0.40, 0.00],
                [-1.25, -0.40, 0.00],
            ],
            facing_body: [-1.0, 0.0, 0.0],
            emission_half_angle_deg: 100.0,
        }
    }
}

impl BeaconLayout {
    /// Checks the count (3 to [`MAX_BEACONS`]), finiteness, that no two
    /// beacons are within 1 cm of each other and that they are not all on
    /// one line. Coplanar layouts are allowed (see [`Self::is_coplanar`]).
    pub fn validate(&self) -> Result<(), CameraError> {
        let n = self.positions_body_m.len();
        if !(3..=MAX_BEACONS).contains(&n) {
            return Err(invalid(
                "beacons.positions_body_m",
                format!("must hold 3 to {MAX_BEACONS} beacons, got {n}"),
            ));
        }
        for p in &self.positions_body_m {
            finite3("beacons.positions_body_m", p)?;
        }
        finite3("beacons.facing_body", &self.facing_body)?;
        if Vector3::from(self.facing_body).norm() < 1e-9 {
            return Err(invalid(
                "beacons.facing_body",
                format!("must not be zero, got {:?}", self.facing_body),
            ));
        }
        if !(self.emission_half_angle_deg > 0.0 && self.emission_half_angle_deg <= 180.0) {
            return Err(invalid(
                "beacons.emission_half_angle_deg",
                format!("must be in (0, 180], got {}", self.emission_half_angle_deg),
            ));
        }
        let pts = self.points_vec();
        for i in 0..n {
            for j in i + 1..n {
                if (pts[i] - pts[j]).norm() < 0.01 {
                    return Err(invalid(
                        "beacons.positions_body_m",
                        format!("beacons {i} and {j} are closer than 1 cm"),
                    ));
                }
            }
        }
        let mut max_area: f64 = 0.0;
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    let a = (pts[j] - pts[i]).cross(&(pts[k] - pts[i])).norm();
                    max_area = max_area.max(a);
                }
            }
        }
        if max_area < 1e-4 {
            return Err(invalid(
                "beacons.positions_body_m",
                "must not all lie on one line".to_string(),
            ));
        }
        Ok(())
    }

    /// The beacons as points (at most [`MAX_BEACONS`]).
    pub fn points(&self) -> impl Iterator<Item = Point3<f64>> + '_ {
        self.positions_body_m
            .iter()
            .take(MAX_BEACONS)
            .map(|p| Point3::from(*p))
    }

    /// Farthest any beacon lies from the parent's body origin, m.
    pub fn reach_m(&self) -> f64 {
        self.points().map(|p| p.coords.norm()).fold(0.0, f64::max)
    }

    fn points_vec(&self) -> Vec<Point3<f64>> {
        self.points().collect()
    }

    /// Unit facing direction (parent body frame).
    pub fn facing_unit(&self) -> Vector3<f64> {
        Vector3::from(self.facing_body)
            .try_normalize(1e-12)
            .unwrap_or_else(|| Vector3::new(-1.0, 0.0, 0.0))
    }

    /// True if a light at `beacon` (parent body frame) can be seen from
    /// `viewer` (parent body frame): within the emission cone.
    pub fn shines_towards(&self, beacon: &Point3<f64>, viewer: &Point3<f64>) -> bool {
        cone_contains(
            &self.facing_unit(),
            self.emission_half_angle_deg.to_radians().cos(),
            &(viewer - beacon),
        )
    }

    /// True if every beacon lies within `tol_m` of one plane (then PnP may
    /// have two solutions; the previous estimate picks one).
    pub fn is_coplanar(&self, tol_m: f64) -> bool {
        let pts = self.points_vec();
        let n = pts.len();
        if n < 4 {
            return true;
        }
        let c = pts.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n as f64;
        let mut m = nalgebra::Matrix3::zeros();
        for p in &pts {
            let d = p.coords - c;
            m += d * d.transpose();
        }
        let eig = m.symmetric_eigen();
        let min = eig.eigenvalues.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        // Smallest eigenvalue = sum of squared distances to the best plane.
        (min.max(0.0) / n as f64).sqrt() <= tol_m
    }
}

/// True if `d` lies within the cone of axis `axis` (unit) whose half-angle
/// has cosine `cos_half` (a half-angle of 180° contains everything).
pub(crate) fn cone_contains(axis: &Vector3<f64>, cos_half: f64, d: &Vector3<f64>) -> bool {
    if cos_half <= -1.0 + 1e-12 {
        return true;
    }
    let n = d.norm();
    n > 0.0 && axis.dot(d) >= cos_half * n
}

/// A vehicle's hull as a capsule (cylinder with hemispherical ends) whose
/// axis is the body x axis, centred on the body origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HullConfig {
    /// Overall length, tip to tip, m. Default 3.0.
    pub length_m: f64,
    /// Radius, m. Default 0.3.
    pub radius_m: f64,
}

impl Default for HullConfig {
    fn default() -> Self {
        Self {
            length_m: 3.0,
            radius_m: 0.3,
        }
    }
}

impl HullConfig {
    /// Checks `radius_m > 0` and `length_m >= 2 radius_m`.
    pub fn validate(&self) -> Result<(), CameraError> {
        if !(self.radius_m > 0.0 && self.radius_m.is_finite()) {
            return Err(invalid(
                "hull.radius_m",
                format!("must be positive and finite, got {}", self.radius_m),
            ));
        }
        if !(self.length_m >= 2.0 * self.radius_m && self.length_m.is_finite()) {
            return Err(invalid(
                "hull.length_m",
                format!(
                    "must be finite and at least twice radius_m ({}), got {}",
                    2.0 * self.radius_m,
                    self.length_m
                ),
            ));
        }
        Ok(())
    }

    /// Farthest any point of the hull lies from the body origin, m.
    pub fn reach_m(&self) -> f64 {
        (0.5 * self.length_m).max(self.radius_m)
    }

    /// The hull in world NED for a vehicle at `pose` (body → NED): the axis
    /// runs along body x from `-(length/2 - radius)` to `+(length/2 - radius)`.
    pub fn capsule(&self, pose: &Isometry3<f64>) -> crate::Capsule {
        let h = (0.5 * self.length_m - self.radius_m).max(0.0);
        crate::Capsule {
            a: pose * Point3::new(-h, 0.0, 0.0),
            b: pose * Point3::new(h, 0.0, 0.0),
            radius_m: self.radius_m,
        }
    }
}

/// Settings of the PnP solver ([`crate::PoseEstimator`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PoseConfig {
    /// Fewest visible beacons for a valid estimate, 3 to [`MAX_BEACONS`].
    /// Default 4: three points have up to four exact solutions, so with
    /// three the answer rests on the previous estimate alone.
    pub min_beacons: usize,
    /// Most Levenberg–Marquardt iterations per start. Default 50.
    pub max_iterations: u32,
    /// Convergence: a step smaller than this, relative (translation relative
    /// to the range; rotation in rad), ends the refinement. Default 1e-10.
    pub convergence_tol: f64,
    /// Convergence: an accepted step that lowers the sum of squared
    /// reprojection errors by less than this fraction ends the refinement.
    /// Default 1e-9 (far below what pixel noise can resolve).
    pub relative_cost_tol: f64,
    /// A fit whose RMS reprojection error exceeds this is invalid, px.
    /// Default 4.0 (about 8σ at the default 1 px noise with 4 beacons).
    pub max_reprojection_rms_px: f64,
    /// Local minima whose sums of squared reprojection errors differ by less
    /// than this many σ² are indistinguishable by the pixels; the one nearest
    /// the previous estimate is taken (this rejects the mirrored / flipped
    /// solution). Default 9 (3σ).
    pub ambiguity_chi2: f64,
    /// P3P is run on this many visible triples (those with the largest image
    /// triangles), 1 to 4; each gives up to four starting poses. More triples
    /// find more of the local minima at long range, at some 5-10 µs each;
    /// on the default layout a second triple changed nothing measurable in
    /// the OpenCV comparison (`tests/opencv_compare.rs`). Default 1.
    pub p3p_triples: usize,
    /// A candidate pose that puts the camera more than this many degrees
    /// outside a used beacon's emission cone ([`BeaconLayout`]) is rejected:
    /// the lights could not have been seen from there. This is what rejects
    /// the mirrored solution when there is no previous estimate. The margin
    /// absorbs the pose error of a true fit near the cone's edge.
    /// Default 10.
    pub emission_margin_deg: f64,
    /// Smallest pixel σ used for the covariance, px: the covariance uses
    /// `σ = max(camera.noise_px, pixel_sigma_floor_px)`. Default 0.3.
    pub pixel_sigma_floor_px: f64,
}

impl Default for PoseConfig {
    fn default() -> Self {
        Self {
            min_beacons: 4,
            max_iterations: 50,
            convergence_tol: 1e-10,
            relative_cost_tol: 1e-9,
            max_reprojection_rms_px: 4.0,
            ambiguity_chi2: 9.0,
            p3p_triples: 1,
            emission_margin_deg: 10.0,
            pixel_sigma_floor_px: 0.3,
        }
    }
}

impl PoseConfig {
    /// Checks every field; the error names the key.
    pub fn validate(&self) -> Result<(), CameraError> {
        if !(3..=MAX_BEACONS).contains(&self.min_beacons) {
            return Err(invalid(
                "pose.min_beacons",
                format!("must be in [3, {MAX_BEACONS}], got {}", self.min_beacons),
            ));
        }
        if self.max_iterations == 0 || self.max_iterations > 10_000 {
            return Err(invalid(
                "pose.max_iterations",
                format!("must be in [1, 10000], got {}", self.max_iterations),
            ));
        }
        if !(self.convergence_tol > 0.0 && self.convergence_tol < 1e-2) {
            return Err(invalid(
                "pose.convergence_tol",
                format!("must be in (0, 0.01), got {}", self.convergence_tol),
            ));
        }
        if !(self.relative_cost_tol >= 0.0 && self.relative_cost_tol < 1e-2) {
            return Err(invalid(
                "pose.relative_cost_tol",
                format!("must be in [0, 0.01), got {}", self.relative_cost_tol),
            ));
        }
        if self.max_reprojection_rms_px.is_nan() || self.max_reprojection_rms_px <= 0.0 {
            return Err(invalid(
                "pose.max_reprojection_rms_px",
                format!("must be positive, got {}", self.max_reprojection_rms_px),
            ));
        }
        if !(self.ambiguity_chi2 >= 0.0 && self.ambiguity_chi2.is_finite()) {
            return Err(invalid(
                "pose.ambiguity_chi2",
                format!("must be >= 0 and finite, got {}", self.ambiguity_chi2),
            ));
        }
        if !(1..=crate::pnp::MAX_P3P_TRIPLES).contains(&self.p3p_triples) {
            return Err(invalid(
                "pose.p3p_triples",
                format!(
                    "must be in [1, {}], got {}",
                    crate::pnp::MAX_P3P_TRIPLES,
                    self.p3p_triples
                ),
            ));
        }
        if !(self.emission_margin_deg >= 0.0 && self.emission_margin_deg <= 180.0) {
            return Err(invalid(
                "pose.emission_margin_deg",
                format!("must be in [0, 180], got {}", self.emission_margin_deg),
            ));
        }
        if !(self.pixel_sigma_floor_px > 0.0 && self.pixel_sigma_floor_px.is_finite()) {
            return Err(invalid(
                "pose.pixel_sigma_floor_px",
                format!(
                    "must be positive and finite, got {}",
                    self.pixel_sigma_floor_px
                ),
            ));
        }
        Ok(())
    }
}
