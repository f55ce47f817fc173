//! Types shared by the leader and follower planners.

use nalgebra::Vector3;

pub use ipc_types::{SonarScan, MAX_BEAMS};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlannerError {
    /// A configuration key is out of range; `key` is the full key (`follower.beta`).
    #[error("{key} {reason}")]
    InvalidConfig {
        /// The offending key.
        key: String,
        /// What is wrong, including the value.
        reason: String,
    },
    /// An input value is NaN or infinite; the step was refused and the state is unchanged.
    #[error("non-finite input: {what}")]
    NonFiniteInput {
        /// Which input.
        what: &'static str,
    },
    /// `t_s` decreased between two steps; the state is unchanged.
    #[error("time went backwards: {previous_s} s then {now_s} s")]
    TimeWentBackwards {
        /// Previous step time, s.
        previous_s: f64,
        /// This step's time, s.
        now_s: f64,
    },
}

pub(crate) fn cfg_err(key: &str, reason: String) -> PlannerError {
    PlannerError::InvalidConfig {
        key: key.to_string(),
        reason,
    }
}

pub(crate) fn check_pos(key: &str, v: f64) -> Result<(), PlannerError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(cfg_err(key, format!("must be finite and > 0, got {v}")))
    }
}

pub(crate) fn check_nonneg(key: &str, v: f64) -> Result<(), PlannerError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(cfg_err(key, format!("must be finite and >= 0, got {v}")))
    }
}

pub(crate) fn check_finite(key: &str, v: f64) -> Result<(), PlannerError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(cfg_err(key, format!("must be finite, got {v}")))
    }
}

/// What the planner is doing. Sent as `u32` on `setpoint` and `planner_state`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum Mode {
    /// Follower in its nominal slot behind a fresh parent estimate; leader on its track.
    Tracking = 0,
    /// Follower: slot shifted or still returning (eqs. 7-9); leader: track offset.
    Avoiding = 1,
    /// Follower: parent estimate stale; following its prediction while slowing to a stop.
    Coasting = 2,
    /// Follower: no usable parent estimate; holding position and depth, facing the parent's
    /// last known position.
    ParentLost = 3,
    /// Leader: last waypoint reached; holding there.
    MissionDone = 4,
    /// Leader: every track offset within reach is blocked; stopped until one frees.
    Blocked = 5,
}

impl From<Mode> for u32 {
    fn from(m: Mode) -> u32 {
        m as u32
    }
}

impl TryFrom<u32> for Mode {
    type Error = u32;
    fn try_from(v: u32) -> Result<Self, u32> {
        Ok(match v {
            0 => Mode::Tracking,
            1 => Mode::Avoiding,
            2 => Mode::Coasting,
            3 => Mode::ParentLost,
            4 => Mode::MissionDone,
            5 => Mode::Blocked,
            other => return Err(other),
        })
    }
}

/// The setpoint for mpc, in the vehicle's **level frame**: origin at the vehicle now, x along
/// its current heading projected on the horizontal, y to starboard (horizontal), z down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Where the vehicle should be, level frame, m.
    pub position_m: Vector3<f64>,
    /// How that target point moves over ground (its velocity in the world, expressed in the
    /// level frame's axes), m/s: the velocity the vehicle should have when on target.
    pub velocity_mps: Vector3<f64>,
    /// Desired heading minus current heading, rad, in (−π, π].
    pub yaw_rel_rad: f64,
}

/// The planner's internal state (the `planner_state` channel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerState {
    /// Current mode.
    pub mode: Mode,
    /// Nominal slot, parent frame, m (zero for the leader).
    pub slot_nominal_m: Vector3<f64>,
    /// Slot shifted for obstacles (eq. 8), parent frame, m.
    pub slot_shifted_m: Vector3<f64>,
    /// Filtered slot (eq. 9), parent frame, m.
    pub slot_filtered_m: Vector3<f64>,
    /// `min δ_j` over the remembered returns (eq. 7), m; `f64::INFINITY` with none.
    /// Leader: the smallest lateral clearance of a remembered return to its shifted track.
    pub delta_min_m: f64,
    /// Age of the parent estimate (time since the last fused fix; since start if none), s.
    pub parent_age_s: f64,
    /// True while the parent estimate is fresh enough to steer on (follower only).
    pub parent_estimate_valid: bool,
    /// True while an obstacle return is within the safe distance (slot shift / track offset
    /// active).
    pub avoiding: bool,
    /// Leader: index of the waypoint being approached (0 for followers).
    pub waypoint_index: usize,
    /// Leader: distance to that waypoint, m (0 for followers).
    pub waypoint_distance_m: f64,
    /// Leader: lateral offset of its track, m, + = starboard (0 for followers).
    pub track_offset_m: f64,
}

/// One planner step's output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerOutput {
    /// The setpoint for mpc.
    pub target: Target,
    /// What the controller's safety layer keeps clear of (level frame, like `target`).
    pub keepout: ipc_types::Keepout,
    /// Internal state, for recording and plots.
    pub state: PlannerState,
}
