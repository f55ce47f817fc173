//! What the follower's camera physically sees of its parent's beacons.

use nalgebra::{Isometry3, Point3, Vector3};
use rand_distr::{Distribution, StandardNormal};

use crate::{BeaconLayout, CameraConfig, CameraError, MAX_BEACONS};

/// Another vehicle's hull in world NED, used as an occluder: all points
/// within `radius_m` of the segment `a`–`b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    /// One end of the axis, NED, m.
    pub a: Point3<f64>,
    /// The other end of the axis, NED, m.
    pub b: Point3<f64>,
    /// Radius, m.
    pub radius_m: f64,
}

impl Capsule {
    /// True if the segment `p`–`q` passes through the capsule (comes closer
    /// to its axis than `radius_m`).
    pub fn blocks_segment(&self, p: &Point3<f64>, q: &Point3<f64>) -> bool {
        segment_distance_sq(p, q, &self.a, &self.b) < self.radius_m * self.radius_m
    }
}

/// Where a hull can hide one of the parent's beacons from the camera: within
/// `beacon reach + hull reach` of the segment from the camera centre to the
/// parent's body origin. Every sight line from the camera to a beacon lies
/// within the beacons' reach of that segment, so a hull whose body origin is
/// farther from it than the sum cannot block one; a camera tests only the
/// hulls inside ([`OcclusionZone::may_hide`]), which keeps its step
/// independent of the group's size without changing what it sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OcclusionZone {
    camera: Point3<f64>,
    parent: Point3<f64>,
    reach_sq: f64,
}

/// Added to the zone's reach so that rounding never drops a hull that
/// touches a sight line, m.
const ZONE_SLACK_M: f64 = 1e-6;

impl OcclusionZone {
    /// The zone of a camera centred at `camera` (world) looking at beacons
    /// within `beacon_reach_m` of `parent` (the parent's body origin, world),
    /// for hulls within `hull_reach_m` of their own body origin
    /// ([`crate::BeaconLayout::reach_m`], [`crate::HullConfig::reach_m`]).
    pub fn new(
        camera: Point3<f64>,
        parent: Point3<f64>,
        beacon_reach_m: f64,
        hull_reach_m: f64,
    ) -> Self {
        let reach = beacon_reach_m + hull_reach_m + ZONE_SLACK_M;
        Self {
            camera,
            parent,
            reach_sq: reach * reach,
        }
    }

    /// False only if a hull whose body origin is at `origin` (world) cannot
    /// block any sight line from the camera to a beacon.
    pub fn may_hide(&self, origin: &Point3<f64>) -> bool {
        segment_distance_sq(origin, origin, &self.camera, &self.parent) <= self.reach_sq
    }
}

/// Squared distance between segments `p1`–`q1` and `p2`–`q2` (Ericson,
/// *Real-Time Collision Detection*, §5.1.9), degenerate segments included.
pub fn segment_distance_sq(
    p1: &Point3<f64>,
    q1: &Point3<f64>,
    p2: &Point3<f64>,
    q2: &Point3<f64>,
) -> f64 {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.norm_squared();
    let e = d2.norm_squared();
    let f = d2.dot(&r);
    let eps = 1e-18;
    let (s, t) = if a <= eps && e <= eps {
        (0.0, 0.0)
    } else if a <= eps {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(&r);
        if e <= eps {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s = if denom > eps * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    let c1 = p1 + d1 * s;
    let c2 = p2 + d2 * t;
    (c1 - c2).norm_squared()
}

/// One camera frame of the parent's beacons. Index `i` is beacon `i` of the
/// [`BeaconLayout`]; entries at `count` and beyond are unused.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BeaconObservation {
    /// Measured pixel `(u, v)` of each beacon, px (origin top-left, `u`
    /// right, `v` down), noise included. `[0, 0]` where not visible.
    pub pixels: [[f64; 2]; MAX_BEACONS],
    /// True where the beacon was seen this frame.
    pub visible: [bool; MAX_BEACONS],
    /// Beacons in the layout (visible or not).
    pub count: usize,
}

impl BeaconObservation {
    /// Number of visible beacons.
    pub fn visible_count(&self) -> usize {
        self.visible[..self.count.min(MAX_BEACONS)]
            .iter()
            .filter(|v| **v)
            .count()
    }
}

/// Why a beacon is not seen (see [`Camera::beacon_status`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BeaconStatus {
    /// Seen.
    Visible,
    /// Behind the camera (or on its image plane).
    BehindCamera,
    /// Projects outside the image.
    OutsideImage,
    /// Farther than the water's visibility range.
    BeyondRange,
    /// The camera is outside the light's emission cone (seen from the wrong
    /// side, see [`BeaconLayout`]).
    FacingAway,
    /// Hidden behind an occluder.
    Occluded,
}

/// The follower's pinhole camera (see [`CameraConfig`] for the frames).
#[derive(Debug, Clone)]
pub struct Camera {
    focal_px: f64,
    principal_px: [f64; 2],
    width_px: f64,
    height_px: f64,
    camera_in_body: Isometry3<f64>,
    noise_px: f64,
    range_m: f64,
}

impl Camera {
    /// Builds the camera after validating `cfg`.
    pub fn new(cfg: &CameraConfig) -> Result<Self, CameraError> {
        cfg.validate()?;
        Ok(Self {
            focal_px: cfg.focal_px(),
            principal_px: cfg.principal_point_px(),
            width_px: f64::from(cfg.width_px),
            height_px: f64::from(cfg.height_px),
            camera_in_body: cfg.camera_in_body(),
            noise_px: cfg.noise_px,
            range_m: cfg.visibility_range_m,
        })
    }

    /// Focal length, px.
    pub fn focal_px(&self) -> f64 {
        self.focal_px
    }

    /// Principal point, px.
    pub fn principal_point_px(&self) -> [f64; 2] {
        self.principal_px
    }

    /// `T_C^F`: camera optical frame → follower body.
    pub fn camera_in_body(&self) -> &Isometry3<f64> {
        &self.camera_in_body
    }

    /// The camera's pose in the world (camera → NED) for a follower at
    /// `follower_pose` (body → NED).
    pub fn camera_in_world(&self, follower_pose: &Isometry3<f64>) -> Isometry3<f64> {
        follower_pose * self.camera_in_body
    }

    /// Noise-free pinhole projection of a point in the camera frame, px;
    /// `None` if it is not in front of the camera.
    pub fn project(&self, p_cam: &Point3<f64>) -> Option<[f64; 2]> {
        if p_cam.z <= 1e-9 {
            return None;
        }
        let iz = 1.0 / p_cam.z;
        Some([
            self.principal_px[0] + self.focal_px * p_cam.x * iz,
            self.principal_px[1] + self.focal_px * p_cam.y * iz,
        ])
    }

    /// Whether a point `p_world` (NED) is seen by a camera at `cam_world`
    /// (camera → NED), and where (noise-free pixel) if so.
    ///
    /// The checks, in order: in front of the camera; inside the image
    /// (`0 ≤ u ≤ width`, `0 ≤ v ≤ height`); within the visibility range
    /// (straight-line distance from the camera centre); the segment from the
    /// camera centre to the point crosses no occluder capsule. (A beacon's
    /// emission cone is checked by [`Self::beacon_status`].)
    pub fn point_status(
        &self,
        cam_world: &Isometry3<f64>,
        p_world: &Point3<f64>,
        occluders: &[Capsule],
    ) -> (BeaconStatus, [f64; 2]) {
        self.status(cam_world, p_world, occluders, || true)
    }

    /// Whether beacon `index` of `layout`, on a parent at `parent_pose`
    /// (body → NED), is seen by a camera at `cam_world`: as
    /// [`Self::point_status`], plus the emission cone (checked after the
    /// range, before occlusion).
    pub fn beacon_status(
        &self,
        cam_world: &Isometry3<f64>,
        parent_pose: &Isometry3<f64>,
        layout: &BeaconLayout,
        index: usize,
        occluders: &[Capsule],
    ) -> (BeaconStatus, [f64; 2]) {
        let Some(b) = layout.positions_body_m.get(index) else {
            return (BeaconStatus::OutsideImage, [0.0; 2]);
        };
        let b = Point3::from(*b);
        let viewer =
            parent_pose.inverse_transform_point(&Point3::from(cam_world.translation.vector));
        self.status(cam_world, &(parent_pose * b), occluders, || {
            layout.shines_towards(&b, &viewer)
        })
    }

    fn status(
        &self,
        cam_world: &Isometry3<f64>,
        p_world: &Point3<f64>,
        occluders: &[Capsule],
        shines: impl FnOnce() -> bool,
    ) -> (BeaconStatus, [f64; 2]) {
        let p_cam = cam_world.inverse_transform_point(p_world);
        let Some(px) = self.project(&p_cam) else {
            return (BeaconStatus::BehindCamera, [0.0; 2]);
        };
        if !(px[0] >= 0.0 && px[0] <= self.width_px && px[1] >= 0.0 && px[1] <= self.height_px) {
            return (BeaconStatus::OutsideImage, [0.0; 2]);
        }
        if p_cam.coords.norm() > self.range_m {
            return (BeaconStatus::BeyondRange, [0.0; 2]);
        }
        if !shines() {
            return (BeaconStatus::FacingAway, [0.0; 2]);
        }
        let centre = Point3::from(cam_world.translation.vector);
        if occluders.iter().any(|c| c.blocks_segment(&centre, p_world)) {
            return (BeaconStatus::Occluded, [0.0; 2]);
        }
        (BeaconStatus::Visible, px)
    }

    /// What the camera physically sees.
    ///
    /// A beacon counts only if it is in front of the camera, inside the
    /// image, within `visibility_range_m`, seen from inside its light's
    /// emission cone ([`BeaconLayout`]), and not hidden by any occluder
    /// capsule: the segment from the camera centre to the beacon is tested
    /// against every capsule in `occluders`. Pass every other vehicle's hull
    /// there, but **not** the parent's own hull (its beacons sit on its
    /// surface; self-occlusion by the parent is not modelled) and not the
    /// follower's own hull (the camera sits inside it).
    ///
    /// Pixel noise: each coordinate of each visible beacon gets
    /// `N(0, noise_px²)` from `rng`. Two normal draws are taken for every
    /// beacon of the layout, visible or not, so that one beacon going out of
    /// view does not change the noise of the others (determinism). Visibility
    /// is decided on the noise-free projection; a noisy pixel may lie up to a
    /// few σ outside the image. Beacons beyond [`MAX_BEACONS`] are ignored.
    pub fn observe<R: rand::Rng>(
        &self,
        follower_pose: &Isometry3<f64>,
        parent_pose: &Isometry3<f64>,
        layout: &BeaconLayout,
        occluders: &[Capsule],
        rng: &mut R,
    ) -> BeaconObservation {
        let cam_world = self.camera_in_world(follower_pose);
        let viewer =
            parent_pose.inverse_transform_point(&Point3::from(cam_world.translation.vector));
        let mut obs = BeaconObservation::default();
        for (i, b) in layout.points().enumerate() {
            let nu: f64 = StandardNormal.sample(rng);
            let nv: f64 = StandardNormal.sample(rng);
            let p_world = parent_pose * b;
            let (status, px) = self.status(&cam_world, &p_world, occluders, || {
                layout.shines_towards(&b, &viewer)
            });
            if status == BeaconStatus::Visible {
                obs.visible[i] = true;
                obs.pixels[i] = [px[0] + self.noise_px * nu, px[1] + self.noise_px * nv];
            }
            obs.count = i + 1;
        }
        obs
    }

    /// Direction of a pixel as a unit bearing in the camera frame.
    pub fn bearing(&self, px: [f64; 2]) -> Vector3<f64> {
        Vector3::new(
            (px[0] - self.principal_px[0]) / self.focal_px,
            (px[1] - self.principal_px[1]) / self.focal_px,
            1.0,
        )
        .normalize()
    }
}
