//! # camera-sim — the follower's camera image, rendered from the scene
//!
//! The simulation side of the vision chain. The `camera-sim` process reads
//! the `world` snapshot (ground truth: it is a sensor simulator, like the
//! sonar) and renders what the follower's camera sees into a fixed-size
//! 8-bit mono `image` sample; camera-pose then reads nothing but that image.
//!
//! - [`OpticsConfig`]: turbid water and the sensor — lamps with emission
//!   cones, inverse-square fall-off and attenuation `exp(−c·r)`, a
//!   forward-scatter glow that widens with optical depth, veiling
//!   backscatter, dark hulls, shot and read noise, 8-bit quantisation and
//!   saturation. Visibility is a result of the optics: see
//!   [`OpticsConfig::attenuation`].
//! - [`Renderer::render`]: one frame, in place, deterministic for a seed.
//!   Every vehicle carries the same lamps, so the other vehicles' lamps are
//!   in the image as distractors, and their hulls hide what is behind them.
//!
//! No I/O, no clock, no threads; rendering allocates nothing.
//!
//! ```
//! use camera_pose::{BeaconLayout, CameraConfig, HullConfig};
//! use camera_sim::{OpticsConfig, Renderer};
//! use nalgebra::{Isometry3, Vector3};
//!
//! let cam = CameraConfig::default();
//! let mut r = Renderer::new(&cam, &BeaconLayout::default(), &HullConfig::default(),
//!                           &OpticsConfig::default())?;
//! // Follower at the origin heading north, its parent 8 m ahead.
//! let poses = [Isometry3::identity(), Isometry3::translation(8.0, 0.0, 0.0)];
//! let mut img = vec![0u8; 512 * 512];
//! let stats = r.render(&poses, 0, Some(1), 7, &mut img);
//! assert_eq!(stats.target_lamps, 4);
//! assert!(img.iter().any(|&p| p == 255)); // saturated lamp cores at 8 m
//! # Ok::<(), camera_sim::OpticsError>(())
//! ```
#![warn(missing_docs)]

mod optics;
mod render;

pub use optics::{OpticsConfig, OpticsError};
pub use render::{inverse_normal_cdf, FrameStats, Renderer};

#[cfg(test)]
mod tests;
