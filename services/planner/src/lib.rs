//! Guidance for shoal's AUVs: the leader's mission and obstacle avoidance, and the paper's
//! follower formation shift (eqs. (4)-(9)) with a vision observer (fig. 4).
//!
//! * [`FollowerPlanner`]: a follower knows only its own sensors (AHRS, DVL, depth, sonar)
//!   and its parent's pose from vision. Its slot is given in the parent's frame; an observer
//!   filters the parent's relative pose and velocity; sonar returns closer than `D_min` to
//!   its predicted track shift the slot along its displacement segment toward the parent's
//!   track ([`shift`], eqs. (4)-(9), with the derivation of the corrected eq. (8)); a lost
//!   parent gives a defined coast-then-hold behaviour.
//! * [`LeaderPlanner`]: waypoints at a speed, with a reactive lateral offset of the track
//!   around obstacles seen by its own sonar, returning to the track afterwards.
//! * [`formation`]: chooses `D_a`, `D_b` per follower so displacement trajectories keep
//!   `D_min` and nobody hides a parent's beacons from a follower; verifies a given choice.
//!
//! Both planners output a [`Target`] in the vehicle's **level frame** (origin at the vehicle
//! now, x along its heading projected on the horizontal, y to starboard, z down): the
//! position to be at, that point's velocity over ground (feed-forward), and the heading
//! change wanted. Pure library: time arrives in the inputs; no I/O, no clock.
//!
//! # Example
//! ```
//! use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
//! use planner::{FollowerConfig, FollowerInput, FollowerPlanner, Mode, PoseMeasurement};
//!
//! let cfg = FollowerConfig { reacquire_count: 1, ..FollowerConfig::default() };
//! let mut f = FollowerPlanner::new(&cfg).unwrap();
//! // the parent seen 8 m ahead and 4 m to starboard, same heading: the follower is in its
//! // default slot (8 m behind, 4 m to port of the parent)
//! let fix = PoseMeasurement {
//!     t_s: 0.0,
//!     parent_in_body: Isometry3::from_parts(
//!         Translation3::new(8.0, 4.0, 0.0),
//!         UnitQuaternion::identity(),
//!     ),
//!     covariance: Matrix6::identity() * 0.01,
//!     valid: true,
//! };
//! let out = f
//!     .step(&FollowerInput {
//!         t_s: 0.0,
//!         attitude: UnitQuaternion::identity(),
//!         nu: Vector6::zeros(),
//!         depth_m: 10.0,
//!         pose: Some(fix),
//!         sonar: None,
//!     })
//!     .unwrap();
//! assert_eq!(out.state.mode, Mode::Tracking);
//! assert!(out.target.position_m.norm() < 1e-9); // already in the slot
//! ```
#![forbid(unsafe_code)]

pub mod follower;
pub mod formation;
pub mod frames;
pub mod keepout;
pub mod leader;
pub mod nav_filter;
pub mod node;
pub mod observer;
pub mod shift;
pub mod trail;
mod types;
pub mod view;

pub use follower::{
    FollowerConfig, FollowerInput, FollowerPlanner, ParentEstimate, PoseMeasurement,
};
pub use leader::{LeaderConfig, LeaderInput, LeaderPlanner};
pub use types::{Mode, PlannerError, PlannerOutput, PlannerState, SonarScan, Target, MAX_BEAMS};
