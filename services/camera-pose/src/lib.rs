//! # camera-pose — the follower's camera and the parent's pose (paper eqs. 1-3)
//!
//! A follower AUV sees light beacons on its *parent* (its visual leader)
//! through an onboard camera and solves the parent's pose from the beacon
//! pixels alone. This crate is the pure library behind the `camera-pose`
//! process:
//!
//! - [`Camera::observe`] simulates what the camera physically sees from
//!   ground truth: pinhole projection, field of view, the water's visibility
//!   range, occlusion by other vehicles' hulls ([`Capsule`]), pixel noise.
//!   Its output, [`BeaconObservation`], is what goes on the `beacons` channel.
//! - [`PoseEstimator::estimate`] solves the parent's pose from that
//!   observation alone (PnP, eq. 2: POSIT and P3P starts, then
//!   Levenberg–Marquardt; see [`PoseEstimator`]), converts it into the follower body frame
//!   (eq. 3) and gives the follower's position in the parent's frame (eq. 1).
//!   Its output, [`PoseEstimate`], is what goes on `leader_pose`; it says
//!   `valid = false` rather than guess.
//!
//! No I/O, no clock, no threads; `observe` and `estimate` do not allocate.
//!
//! ## Frames
//! World NED; body x forward, y starboard, z down (Fossen); poses are
//! `Isometry3` body → NED. The camera frame is the optical frame (z along the
//! optical axis, x right, y down in the image), mounted on the follower body
//! by [`CameraConfig::camera_in_body`]; see [`CameraConfig`].
//!
//! ## Example
//! ```
//! use camera_pose::*;
//! use nalgebra::{Isometry3, Vector3};
//! use rand::SeedableRng;
//!
//! let cam_cfg = CameraConfig::default();
//! let layout = BeaconLayout::default();
//! let camera = Camera::new(&cam_cfg)?;
//! let mut estimator = PoseEstimator::new(&PoseConfig::default(), &cam_cfg, &layout)?;
//!
//! // Follower at the origin heading north; parent 6 m ahead, 0.5 m to starboard.
//! let follower = Isometry3::identity();
//! let parent = Isometry3::new(Vector3::new(6.0, 0.5, 0.0), Vector3::new(0.0, 0.0, 0.1));
//! let mut rng = rand::rngs::StdRng::seed_from_u64(7);
//! let obs = camera.observe(&follower, &parent, &layout, &[], &mut rng);
//! assert_eq!(obs.visible_count(), 4);
//!
//! let est = estimator.estimate(&obs);
//! assert!(est.valid);
//! // The parent in the follower body frame (eq. 3): about 6 m ahead.
//! assert!((est.parent_in_body.translation.vector - parent.translation.vector).norm() < 0.5);
//! # Ok::<(), CameraError>(())
//! ```
#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod camera;
mod config;
pub mod detect;
mod pnp;
mod poly;

pub mod acoustic;
pub use camera::{
    segment_distance_sq, BeaconObservation, BeaconStatus, Camera, Capsule, OcclusionZone,
};
pub use config::{BeaconLayout, CameraConfig, CameraError, HullConfig, PoseConfig};
pub use detect::{
    Blob, DetectConfig, Detector, Identification, Identifier, NoMatch, Prior, RUNNERS_UP,
};
pub use pnp::{follower_in_parent, parent_in_body, PoseEstimate, PoseEstimator, MAX_P3P_TRIPLES};

/// Most beacons on one parent (the IPC `beacons` sample has room for 8).
pub const MAX_BEACONS: usize = 8;
