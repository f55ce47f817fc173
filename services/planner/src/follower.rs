//! The follower: slot in its parent's frame from vision, shifted for obstacles (eqs. 4-9),
//! smoothed by an observer, with a defined behaviour when the parent is lost.

use nalgebra::{Isometry3, Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::frames::{from_level, to_level, wrap, yaw_of};
use crate::keepout;
use crate::observer::{FixOutcome, ObserverParams, ParentObserver};
use crate::shift::{beam_vector, Displacement, Shift, SlotFilter};
use crate::trail::Trail;
use crate::types::{
    cfg_err, check_finite, check_nonneg, check_pos, Mode, PlannerError, PlannerOutput,
    PlannerState, SonarScan, Target,
};

/// Remembered obstacle points (odometry frame).
pub const MEMORY_CAPACITY: usize = 128;
/// Own-pose history kept to place late vision fixes.
const HISTORY_CAPACITY: usize = 64;
/// ParentLost: the follower turns toward the parent's last known position only if that is
/// farther than this horizontally, m.
const LOOK_MIN_RANGE_M: f64 = 1.0;
/// On a trail, the line of sight to the parent sets the heading only when it is longer
/// than this horizontally, m (shorter, its noise would swing the heading).
const TRAIL_SIGHT_MIN_M: f64 = 2.0;

/// Follower planner configuration (`[follower]` in a scenario; the slot and `d_a_m`/`d_b_m`
/// are per vehicle).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FollowerConfig {
    /// Nominal slot in the parent's level frame (FRD: forward, starboard, down), m.
    /// Default `[-8, -4, 0]`: 8 m behind, 4 m to port.
    pub slot_in_parent_m: [f64; 3],
    /// Safe distance `D_min` of eqs. (7)-(8), m (default 2).
    pub d_min_m: f64,
    /// `D_a` of eq. (4), m (default 2.5, > `D_min` as the paper requires). The paper's side
    /// sign is applied: the slot's end point is `D_a/2` ahead for a port slot, behind for a
    /// starboard one; a negative value reverses that.
    pub d_a_m: f64,
    /// `D_b` of eq. (5), m, signed, + = down (default 0): the slot ends `D_b/2` lower.
    pub d_b_m: f64,
    /// Smoothing coefficient β of eq. (9), per planner step, in (0, 1] (default 0.1: a time
    /// constant of ~1 s at 10 Hz).
    pub beta: f64,
    /// Transducer position in the body frame, m (default `[0.8, 0, 0]`, as `sonar`).
    pub sonar_mount_body_m: [f64; 3],
    /// Returns closer than this to the parent estimate are taken as the parent's hull and
    /// ignored, m (default 1.5).
    pub parent_echo_radius_m: f64,
    /// A remembered obstacle point is dropped once it is this far behind the follower, m
    /// (default 3: forward beams no longer see an obstacle the follower is passing).
    pub memory_behind_m: f64,
    /// ... or this old, s (default 60).
    pub memory_max_age_s: f64,
    /// The parent estimate is stale after this long without a fused fix, s (default 0.5).
    pub stale_after_s: f64,
    /// Predicting: once stale, keep tracking the observer's prediction of the parent (its
    /// last velocity and turn rate, eqs. 6-9 included) at full speed for this long before
    /// coasting, s (default 0: start slowing down at once).
    ///
    /// Why: a parent does not know that its follower lost sight of it and swims on. A
    /// follower that slows to a stop falls back by the parent's speed times the outage;
    /// with the paper's 1 m/s, a 12 m visibility and a slot 8.9 m behind, a follower that
    /// stopped was out of range ~6 s after losing its parent and never saw it again (a
    /// camera blinded for 10 s: range 16.3 m when sight returned). Following the prediction
    /// keeps it in range for as long as the prediction holds, and the first fix after the
    /// outage is fused at once (the observer is not restarted while coasting).
    pub predict_s: f64,
    /// Coasting: after going stale (and `predict_s`), follow the last predicted target while
    /// slowing to a stop over this time, then hold, s (default 4).
    pub coast_s: f64,
    /// Consecutive fused fixes needed to resume tracking after the parent was lost (default 3).
    pub reacquire_count: u32,
    /// Time headway `h` of the slot, s (default 0: the paper's rigid slot). The target
    /// is moved back by `h·(v − v̄)`, where `v` is the follower's own velocity (DVL) and `v̄`
    /// the target's velocity averaged over `headway_avg_s` in the parent's level frame: a
    /// follower that moves faster than the formation has been moving aims a little behind
    /// its slot, one that moves slower a little ahead. At steady speed, and in a steady turn,
    /// `v = v̄` and the slot is exact.
    ///
    /// Why: a follower tracking a noisy, slightly late estimate of its parent's position
    /// and velocity passes its parent's motion on amplified near the loop's bandwidth
    /// (period ~8 s here); a chain of followers of followers multiplies it level by level.
    /// Measured on the generated 100-vehicle triangle (9 levels) without it: the along-track
    /// slot error grew ~1.8× per level, from 0.10 m RMS one level below the leader to 1 m at
    /// five and to collisions below. The `h·v` term is damping on the follower's own
    /// velocity, which keeps that gain below 1 except at periods longer than
    /// `headway_avg_s` (string stability, as the time-headway spacing policy of vehicle
    /// platoons). With `headway_s = yaw_headway_s = 1` the same 100-vehicle run keeps the
    /// along-track error at 0.26-0.39 m RMS on every level.
    ///
    /// The price: while the formation speeds up, each follower trails its slot by
    /// `h·(v − v̄)` (at the paper's 0.05 m/s² start, up to ~1 m). The paper's scenario,
    /// two levels deep, does not need it and keeps the default; `shoal gen` sets 1 s (with
    /// `yaw_headway_s = 3`, `headway_avg_s = 60`), and `shoal check` warns about a deeper
    /// tree without it.
    pub headway_s: f64,
    /// Averaging time constant of `v̄` in `headway_s` and of `r̄` in `yaw_headway_s`, s
    /// (default 20).
    pub headway_avg_s: f64,
    /// The headway of the heading, s (default 0: the parent's heading as estimated):
    /// the target heading is moved back by `h_ψ·(r − r̄)`, `r` the own turn rate (gyro) and
    /// `r̄` the parent's estimated turn rate averaged over `headway_avg_s`. A follower's
    /// heading is its followers' slot frame, so a heading chain that amplifies swings the
    /// slots of the levels below sideways (`arm · Δψ`); this is the same damping as
    /// `headway_s`, on the heading.
    pub yaw_headway_s: f64,
    /// Observer: parent acceleration noise density, m/s² (default 0.1).
    pub accel_noise_mps2: f64,
    /// Observer: parent heading acceleration noise density, rad/s² (default 0.02).
    pub yaw_accel_noise_radps2: f64,
    /// Floor on the fix position noise, 1σ, m (default 0.05).
    pub pose_noise_min_m: f64,
    /// Floor on the fix heading noise, 1σ, rad (default 0.02).
    pub yaw_noise_min_rad: f64,
    /// Fix position noise used when the fix's covariance is unusable, 1σ, m (default 0.3).
    pub pose_noise_default_m: f64,
    /// Chi-square gate on fixes (3 dof; default 16.3 ≈ 99.9 %).
    pub gate_chi2: f64,
    /// Rejected fixes in a row after which the observer restarts (default 3).
    pub max_rejections: u32,
    /// Keep the parent in view: the target heading is turned toward the parent whenever
    /// one of its beacons would lie within this margin of the image edge, deg (default 3;
    /// 0 switches it off). Our addition: the paper's follower holds its parent's heading,
    /// and in a turn that heading lags until the parent leaves the image.
    pub view_margin_deg: f64,
    /// Half the camera's horizontal field of view, deg (`shoal run` sets it from
    /// `[camera] fov_deg`; default 45).
    pub view_half_angle_deg: f64,
    /// The camera's position in the body frame, m (`shoal run` sets it from
    /// `[camera] mount_position_body_m`; default `[1.4, 0, 0]`).
    pub camera_mount_body_m: [f64; 3],
    /// The parent's beacons in its body frame, m (`shoal run` sets them from
    /// `[beacons] positions_body_m`; default the default layout).
    pub parent_beacons_body_m: Vec<[f64; 3]>,
    /// Keep the target `d_min_m` clear of remembered returns on the follower's side
    /// (default true; see `FollowerPlanner::keep_clear`).
    pub keep_clear: bool,
    /// The headway's averages never exceed what the parent does now (default true;
    /// `false`: the plain averages, as before issue 16).
    pub headway_cap: bool,
    /// Room for tracking error `keep_clear` leaves beyond `d_min_m`, m (default 0.25).
    pub keep_clear_margin_m: f64,
    /// After losing its parent, a follower heads for the slot behind where the parent is
    /// predicted to be (its last velocity carried on) for this long before it holds, s
    /// (default 10; 0: hold at once, facing the parent's last known position).
    pub search_s: f64,
    /// Returns closer than this to a remembered one refresh it instead of adding a point,
    /// m (default 0.5; 0: every return is a point, oldest dropped when full).
    pub memory_cell_m: f64,
    /// The observer predicts the parent along its estimated turn (default true; false:
    /// straight on, as the paper's constant-velocity observer; see
    /// [`ObserverParams::coordinated_turn`]).
    pub coordinated_turn: bool,
    /// The slot's along-track part is a distance along the parent's path, not along its
    /// heading now (default true; false: the paper's rigid slot). In a turn a rigid slot
    /// swings across the track by its length times the turn, more at every level, and files
    /// fold onto each other; with a trail each follower swims its parent's path offset
    /// sideways ([`crate::trail`]), heading so that it sees its parent where the rigid slot
    /// shows it.
    pub trail: bool,
}

impl Default for FollowerConfig {
    fn default() -> Self {
        Self {
            slot_in_parent_m: [-8.0, -4.0, 0.0],
            d_min_m: 2.0,
            d_a_m: 2.5,
            d_b_m: 0.0,
            beta: 0.1,
            sonar_mount_body_m: [0.8, 0.0, 0.0],
            parent_echo_radius_m: 1.5,
            memory_behind_m: 3.0,
            memory_max_age_s: 60.0,
            stale_after_s: 0.5,
            predict_s: 0.0,
            coast_s: 4.0,
            reacquire_count: 3,
            headway_s: 0.0,
            headway_avg_s: 20.0,
            yaw_headway_s: 0.0,
            accel_noise_mps2: 0.1,
            yaw_accel_noise_radps2: 0.02,
            pose_noise_min_m: 0.05,
            yaw_noise_min_rad: 0.02,
            pose_noise_default_m: 0.3,
            gate_chi2: 16.27,
            max_rejections: 3,
            view_margin_deg: 3.0,
            keep_clear: true,
            headway_cap: true,
            keep_clear_margin_m: 0.25,
            search_s: 10.0,
            memory_cell_m: 0.5,
            coordinated_turn: true,
            trail: true,
            view_half_angle_deg: 45.0,
            camera_mount_body_m: [1.4, 0.0, 0.0],
            parent_beacons_body_m: vec![
                [-1.50, 0.00, 0.00],
                [-1.00, 0.00, -0.40],
                [-1.25, 0.40, 0.00],
                [-1.25, -0.40, 0.00],
            ],
        }
    }
}

impl FollowerConfig {
    /// Checks every key; the error names the first bad one (`follower.<key>`).
    pub fn validate(&self) -> Result<(), PlannerError> {
        for (i, v) in self.slot_in_parent_m.iter().enumerate() {
            check_finite(&format!("follower.slot_in_parent_m[{i}]"), *v)?;
        }
        let s = self.slot_in_parent_m;
        if (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt() < self.d_min_m {
            return Err(cfg_err(
                "follower.slot_in_parent_m",
                format!(
                    "is closer to the parent than d_min_m ({}), got {s:?}",
                    self.d_min_m
                ),
            ));
        }
        check_pos("follower.d_min_m", self.d_min_m)?;
        check_finite("follower.d_a_m", self.d_a_m)?;
        check_finite("follower.d_b_m", self.d_b_m)?;
        if !(self.beta.is_finite() && self.beta > 0.0 && self.beta <= 1.0) {
            return Err(cfg_err(
                "follower.beta",
                format!("must be in (0, 1], got {}", self.beta),
            ));
        }
        for (i, v) in self.sonar_mount_body_m.iter().enumerate() {
            check_finite(&format!("follower.sonar_mount_body_m[{i}]"), *v)?;
        }
        check_nonneg("follower.parent_echo_radius_m", self.parent_echo_radius_m)?;
        check_nonneg("follower.memory_behind_m", self.memory_behind_m)?;
        check_pos("follower.memory_max_age_s", self.memory_max_age_s)?;
        check_pos("follower.stale_after_s", self.stale_after_s)?;
        check_nonneg("follower.predict_s", self.predict_s)?;
        check_nonneg("follower.coast_s", self.coast_s)?;
        check_nonneg("follower.headway_s", self.headway_s)?;
        check_pos("follower.headway_avg_s", self.headway_avg_s)?;
        check_nonneg("follower.yaw_headway_s", self.yaw_headway_s)?;
        check_nonneg("follower.view_margin_deg", self.view_margin_deg)?;
        check_nonneg("follower.keep_clear_margin_m", self.keep_clear_margin_m)?;
        check_nonneg("follower.search_s", self.search_s)?;
        check_nonneg("follower.memory_cell_m", self.memory_cell_m)?;
        check_pos("follower.view_half_angle_deg", self.view_half_angle_deg)?;
        if self.reacquire_count == 0 {
            return Err(cfg_err(
                "follower.reacquire_count",
                "must be >= 1, got 0".to_string(),
            ));
        }
        check_pos("follower.accel_noise_mps2", self.accel_noise_mps2)?;
        check_pos(
            "follower.yaw_accel_noise_radps2",
            self.yaw_accel_noise_radps2,
        )?;
        check_pos("follower.pose_noise_min_m", self.pose_noise_min_m)?;
        check_pos("follower.yaw_noise_min_rad", self.yaw_noise_min_rad)?;
        check_pos("follower.pose_noise_default_m", self.pose_noise_default_m)?;
        check_pos("follower.gate_chi2", self.gate_chi2)?;
        if self.max_rejections == 0 {
            return Err(cfg_err(
                "follower.max_rejections",
                "must be >= 1, got 0".to_string(),
            ));
        }
        Ok(())
    }
}

/// One vision fix of the parent (the `leader_pose` channel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseMeasurement {
    /// Time the image was taken, s (simulation time).
    pub t_s: f64,
    /// The parent's pose in the follower's body frame (eq. 3).
    pub parent_in_body: Isometry3<f64>,
    /// Covariance of `[position, rotation vector]`, body frame.
    pub covariance: Matrix6<f64>,
    /// False if camera-pose could not solve; such a fix is never used.
    pub valid: bool,
}

/// One follower planner step's inputs: the vehicle's own sensors, plus what is new.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowerInput {
    /// Simulation time the own navigation below was measured at, s. Everything the step
    /// returns refers to this instant (the process passes the nav sample's stamp, not its own
    /// tick time, so that dead reckoning and the vision fixes' stamps agree).
    pub t_s: f64,
    /// Own attitude from the AHRS, body→NED. Its heading is used only differentially.
    pub attitude: UnitQuaternion<f64>,
    /// Own body velocity `[u, v, w, p, q, r]` (DVL + gyros).
    pub nu: Vector6<f64>,
    /// Own depth, m.
    pub depth_m: f64,
    /// A new vision fix this step, if any.
    pub pose: Option<PoseMeasurement>,
    /// A new scan this step, if any.
    pub sonar: Option<SonarScan>,
}

/// The parent as the observer sees it, in the follower's level frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParentEstimate {
    /// Parent position, level frame, m.
    pub position_m: Vector3<f64>,
    /// Parent velocity over ground, level-frame axes, m/s.
    pub velocity_mps: Vector3<f64>,
    /// Parent heading minus own heading, rad.
    pub yaw_rel_rad: f64,
    /// Parent turn rate, rad/s.
    pub yaw_rate_radps: f64,
    /// 1σ position uncertainty, m.
    pub position_std_m: f64,
    /// Time since the last fused fix, s.
    pub age_s: f64,
}

/// The slot's geometry and filter state (boxed to keep the planner small).
#[derive(Debug, Clone)]
struct SlotState {
    disp: Displacement,
    filter: SlotFilter,
    last_shift: Shift,
    anchor: Option<Anchor>,
    /// The headway's averages: `v̄`, the target's velocity in the parent's level frame, and
    /// `r̄`, the parent's turn rate.
    headway_mean: Option<(Vector3<f64>, f64)>,
    /// Where the parent's estimate has been (`trail`).
    trail: Trail,
}

#[derive(Debug, Clone, Copy)]
struct OwnPose {
    t: f64,
    pos: Vector3<f64>,
    att: UnitQuaternion<f64>,
}

#[derive(Debug, Clone, Copy)]
struct MemPoint {
    t: f64,
    pos: Vector3<f64>,
}

/// A frozen target the follower moves to without a fresh parent estimate.
#[derive(Debug, Clone, Copy)]
struct Anchor {
    t0: f64,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    yaw: f64,
    /// ParentLost: where the parent was last estimated to be (odometry frame); the follower
    /// turns its nose (and camera) toward it.
    look: Option<Vector3<f64>>,
}

/// How far past the target, along the parent's heading, remembered returns still keep it
/// clear ([`FollowerConfig::keep_clear`]), m.
pub const KEEP_CLEAR_AHEAD_M: f64 = 3.0;

/// The follower planner (paper sec. 3 and fig. 4).
///
/// Each [`FollowerPlanner::step`]:
/// 1. dead-reckons the follower in its odometry frame (DVL + AHRS, depth sensor);
/// 2. places the new sonar returns in that frame and remembers them until they are
///    `memory_behind_m` behind (so the slot stays shifted while the follower passes an
///    obstacle its forward beams no longer see);
/// 3. runs the observer ([`crate::observer`]) on the new vision fix;
/// 4. in the parent's level frame (eq. 6, with the relative heading from vision): eq. (7)
///    over the remembered points, eq. (8) for the shifted slot, eq. (9) to smooth it;
/// 5. returns the slot in the follower's level frame, its velocity over ground
///    (feed-forward) and the parent's heading relative to its own.
///
/// Lost parent: the estimate is *stale* `stale_after_s` after the last fused fix. Then
/// **Coasting**: first, for `predict_s`, the follower keeps tracking its slot behind the
/// observer's prediction of the parent exactly as when it sees it; then the target continues
/// along the last predicted target at its depth and heading, decelerating linearly to a stop
/// over `coast_s` (it travels `v·coast_s/2`).
/// Then **ParentLost**: hold that point and depth, and turn toward the parent's last known
/// position (the observer's estimate, predicted to the moment the parent was declared lost)
/// so that the camera looks where the parent was; with no estimate at all (at start) the
/// heading is held. A vision fix during Coasting
/// resumes tracking at once; after ParentLost (and at start) the observer restarts and
/// tracking resumes after `reacquire_count` consecutive fused fixes. `parent_age_s` and
/// `parent_estimate_valid` always say how old the estimate is.
#[derive(Debug, Clone)]
pub struct FollowerPlanner {
    // boxed: keeps the planner small enough to move around by value
    cfg: Box<FollowerConfig>,
    slot: Box<SlotState>,
    mount: Vector3<f64>,
    observer: Box<ParentObserver>,
    t_start: Option<f64>,
    t_prev: f64,
    odo: Vector3<f64>,
    history: Vec<OwnPose>,
    memory: Vec<MemPoint>,
    t_last_fix: Option<f64>,
    t_last_seen_fix: Option<f64>,
    consecutive_fixes: u32,
    mode: Mode,
    last_target_odo: Option<(Vector3<f64>, Vector3<f64>, f64)>,
}

impl FollowerPlanner {
    /// Validates the configuration and pre-allocates the buffers.
    pub fn new(cfg: &FollowerConfig) -> Result<Self, PlannerError> {
        cfg.validate()?;
        let slot = Vector3::from(cfg.slot_in_parent_m);
        let disp = Displacement {
            slot,
            d_a: cfg.d_a_m,
            d_b: cfg.d_b_m,
        };
        let mut filter = SlotFilter::new(cfg.beta);
        filter.reset(slot);
        Ok(Self {
            slot: Box::new(SlotState {
                disp,
                filter,
                last_shift: Shift {
                    slot,
                    lambda: 0.0,
                    delta_min: f64::INFINITY,
                    y_dc: None,
                    active: false,
                },
                anchor: None,
                headway_mean: None,
                trail: Trail::new(),
            }),
            mount: Vector3::from(cfg.sonar_mount_body_m),
            observer: Box::new(ParentObserver::new(ObserverParams {
                accel_noise_mps2: cfg.accel_noise_mps2,
                yaw_accel_noise_radps2: cfg.yaw_accel_noise_radps2,
                gate_chi2: cfg.gate_chi2,
                max_rejections: cfg.max_rejections,
                initial_speed_std_mps: 1.0,
                coordinated_turn: cfg.coordinated_turn,
            })),
            t_start: None,
            t_prev: 0.0,
            odo: Vector3::zeros(),
            history: Vec::with_capacity(HISTORY_CAPACITY),
            memory: Vec::with_capacity(MEMORY_CAPACITY),
            t_last_fix: None,
            t_last_seen_fix: None,
            consecutive_fixes: 0,
            mode: Mode::ParentLost,
            last_target_odo: None,
            cfg: Box::new(cfg.clone()),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &FollowerConfig {
        &self.cfg
    }

    /// The displacement segment of this follower (eqs. 4-5).
    pub fn displacement(&self) -> &Displacement {
        &self.slot.disp
    }

    /// Number of remembered obstacle points.
    pub fn remembered_points(&self) -> usize {
        self.memory.len()
    }

    /// The observer's parent estimate in the current level frame, if initialised.
    pub fn parent_estimate(&self) -> Option<ParentEstimate> {
        if !self.observer.initialized() {
            return None;
        }
        let own = self.history.last()?;
        let yaw = yaw_of(&own.att);
        Some(ParentEstimate {
            position_m: to_level(yaw, &(self.observer.position() - own.pos)),
            velocity_mps: to_level(yaw, &self.observer.velocity()),
            yaw_rel_rad: wrap(self.observer.yaw() - yaw),
            yaw_rate_radps: self.observer.yaw_rate(),
            position_std_m: self.observer.position_std(),
            age_s: self.t_last_fix.map_or(f64::INFINITY, |t| own.t - t),
        })
    }

    fn check_input(input: &FollowerInput) -> Result<(), PlannerError> {
        let q = input.attitude.quaternion();
        let finite = |what, ok: bool| {
            if ok {
                Ok(())
            } else {
                Err(PlannerError::NonFiniteInput { what })
            }
        };
        finite("t_s", input.t_s.is_finite())?;
        finite("attitude", q.coords.iter().all(|x| x.is_finite()))?;
        finite("nu", input.nu.iter().all(|x| x.is_finite()))?;
        finite("depth_m", input.depth_m.is_finite())?;
        if let Some(p) = &input.pose {
            if p.valid {
                let pq = p.parent_in_body.rotation.quaternion();
                finite(
                    "pose",
                    p.t_s.is_finite()
                        && p.parent_in_body
                            .translation
                            .vector
                            .iter()
                            .all(|x| x.is_finite())
                        && pq.coords.iter().all(|x| x.is_finite()),
                )?;
            }
        }
        Ok(())
    }

    /// The own pose at (or just before) `t`, from the history.
    fn own_at(&self, t: f64) -> Option<OwnPose> {
        self.history
            .iter()
            .rev()
            .find(|h| h.t <= t + 1e-9)
            .or_else(|| self.history.first())
            .copied()
    }

    fn fix_noise(&self, att: &UnitQuaternion<f64>, cov: &Matrix6<f64>) -> (Matrix3<f64>, f64) {
        let r = att.to_rotation_matrix();
        let usable = cov.iter().all(|x| x.is_finite()) && (0..6).all(|i| cov[(i, i)] >= 0.0);
        let floor = self.cfg.pose_noise_min_m.powi(2);
        let (pos, yaw_var) = if usable {
            let p: Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
            let o: Matrix3<f64> = cov.fixed_view::<3, 3>(3, 3).into_owned();
            let p_ned = r * p * r.transpose();
            let o_ned = r * o * r.transpose();
            (p_ned, o_ned[(2, 2)])
        } else {
            (
                Matrix3::identity() * self.cfg.pose_noise_default_m.powi(2),
                (5f64.to_radians()).powi(2),
            )
        };
        (
            pos + Matrix3::identity() * floor,
            yaw_var.max(0.0) + self.cfg.yaw_noise_min_rad.powi(2),
        )
    }

    /// One planner step. On error the state is unchanged.
    pub fn step(&mut self, input: &FollowerInput) -> Result<PlannerOutput, PlannerError> {
        Self::check_input(input)?;
        let t = input.t_s;
        let first = self.t_start.is_none();
        if !first && t < self.t_prev {
            return Err(PlannerError::TimeWentBackwards {
                previous_s: self.t_prev,
                now_s: t,
            });
        }
        let dt = if first {
            0.0
        } else {
            (t - self.t_prev).min(1.0)
        };
        let t_start = *self.t_start.get_or_insert(t);
        self.t_prev = t;

        // 1. own odometry
        let att = input.attitude;
        let yaw_own = yaw_of(&att);
        let v_own = att * input.nu.fixed_rows::<3>(0).into_owned();
        self.odo.x += v_own.x * dt;
        self.odo.y += v_own.y * dt;
        self.odo.z = input.depth_m;
        if self.history.len() == HISTORY_CAPACITY {
            self.history.remove(0);
        }
        self.history.push(OwnPose {
            t,
            pos: self.odo,
            att,
        });

        // 2. observer: predict, then the new fix
        self.observer.predict(t);
        let age_before = self.t_last_fix.map_or(f64::INFINITY, |tf| t - tf);
        // a fix no newer than the last fused one is a repeat (or out of order): ignored
        let repeat = |pm: &PoseMeasurement| self.t_last_seen_fix.is_some_and(|tf| pm.t_s <= tf);
        if let Some(pm) = input.pose.filter(|pm| !repeat(pm)) {
            self.t_last_seen_fix = Some(pm.t_s);
            if pm.valid {
                let t_meas = pm.t_s.min(t);
                let own = self.own_at(t_meas).unwrap_or(OwnPose {
                    t,
                    pos: self.odo,
                    att,
                });
                let p_fix = own.pos + own.att * pm.parent_in_body.translation.vector;
                let yaw_fix = yaw_of(&(own.att * pm.parent_in_body.rotation));
                let (r_pos, yaw_var) = self.fix_noise(&own.att, &pm.covariance);
                let lost = age_before > self.lost_after_s();
                let outcome = if !self.observer.initialized() || lost {
                    let here = p_fix + v_own * (t - t_meas);
                    self.observer
                        .restart(t, &here, &r_pos, yaw_fix, yaw_var, &v_own);
                    FixOutcome::Restarted
                } else {
                    self.observer
                        .fuse(t_meas, &p_fix, &r_pos, yaw_fix, yaw_var, &v_own)
                };
                match outcome {
                    FixOutcome::Accepted => {
                        self.t_last_fix = Some(t_meas);
                        self.consecutive_fixes += 1;
                    }
                    FixOutcome::Restarted => {
                        self.t_last_fix = Some(t_meas);
                        self.consecutive_fixes = 1;
                        self.slot.trail.clear();
                    }
                    FixOutcome::Rejected => self.consecutive_fixes = 0,
                }
            } else {
                self.consecutive_fixes = 0;
            }
        }
        let age = self.t_last_fix.map_or(t - t_start, |tf| t - tf);
        let fresh = self.observer.initialized()
            && self.t_last_fix.is_some()
            && age <= self.cfg.stale_after_s;
        // stale, but still followed on the observer's prediction (`predict_s`)
        let predicting = !fresh
            && self.observer.initialized()
            && self.t_last_fix.is_some()
            && matches!(self.mode, Mode::Tracking | Mode::Avoiding | Mode::Coasting)
            && age <= self.cfg.stale_after_s + self.cfg.predict_s;

        // 3. sonar returns into the odometry frame, then forget what is behind
        if let Some(scan) = &input.sonar {
            // the parent's own echo is ignored around its estimate, predicted or fresh
            let parent = (fresh || predicting).then(|| self.observer.position());
            for (d, az, el) in scan.returns() {
                let p = self.odo + att * (self.mount + beam_vector(d, az, el));
                if let Some(pp) = parent {
                    if (p - pp).norm() < self.cfg.parent_echo_radius_m {
                        continue;
                    }
                }
                // one point per cell: the wall abeam is still known when the beams have
                // been hitting the wall ahead for longer than the capacity lasts
                if let Some(m) = self
                    .memory
                    .iter_mut()
                    .find(|m| (m.pos.xy() - p.xy()).norm() < self.cfg.memory_cell_m)
                {
                    *m = MemPoint { t, pos: p };
                    continue;
                }
                if self.memory.len() == MEMORY_CAPACITY {
                    self.memory.remove(0);
                }
                self.memory.push(MemPoint { t, pos: p });
            }
        }
        let (odo, behind, max_age) = (
            self.odo,
            self.cfg.memory_behind_m,
            self.cfg.memory_max_age_s,
        );
        self.memory
            .retain(|m| to_level(yaw_own, &(m.pos - odo)).x >= -behind && t - m.t <= max_age);

        // 4. mode
        let next = if fresh {
            match self.mode {
                Mode::ParentLost if self.consecutive_fixes < self.cfg.reacquire_count => {
                    Mode::ParentLost
                }
                _ => Mode::Tracking,
            }
        } else if self.observer.initialized()
            && matches!(self.mode, Mode::Tracking | Mode::Avoiding | Mode::Coasting)
            && age <= self.lost_after_s()
        {
            Mode::Coasting
        } else {
            Mode::ParentLost
        };

        let (target_pos, target_vel, target_yaw, mode) = match next {
            Mode::Tracking | Mode::Avoiding => {
                if self.mode == Mode::ParentLost {
                    // re-entering: restart the slot filter from the current shift
                    self.slot.filter.reset(self.slot.last_shift.slot);
                    self.slot.headway_mean = None;
                }
                self.slot.anchor = None;
                self.track(dt, &v_own, input.nu[5], yaw_own)
            }
            Mode::Coasting if predicting => {
                // Predicting: the slot behind the observer's prediction (it was predicted to
                // `t` above). No anchor yet: the slowdown starts from the last predicted
                // target when this phase ends.
                self.slot.anchor = None;
                let (p, v, y, _) = self.track(dt, &v_own, input.nu[5], yaw_own);
                (p, v, y, Mode::Coasting)
            }
            Mode::Coasting => {
                let anchor = match self.slot.anchor {
                    Some(a) if self.mode == Mode::Coasting => a,
                    _ => {
                        let (p, v, y) =
                            self.last_target_odo
                                .unwrap_or((self.odo, Vector3::zeros(), yaw_own));
                        let a = Anchor {
                            t0: t,
                            pos: p,
                            vel: Vector3::new(v.x, v.y, 0.0),
                            yaw: y,
                            look: None,
                        };
                        self.slot.anchor = Some(a);
                        a
                    }
                };
                let big_t = self.cfg.coast_s;
                let tau = (t - anchor.t0).clamp(0.0, big_t);
                let (s, f) = if big_t > 0.0 {
                    (tau - tau * tau / (2.0 * big_t), 1.0 - tau / big_t)
                } else {
                    (0.0, 0.0)
                };
                // keep turning toward where the parent is predicted to be: a parent lost at
                // the image edge in a turn comes back into view
                let yaw = self.keep_in_view(
                    anchor.yaw,
                    yaw_own,
                    &self.observer.position(),
                    self.observer.yaw(),
                );
                (
                    anchor.pos + anchor.vel * s,
                    anchor.vel * f,
                    yaw,
                    Mode::Coasting,
                )
            }
            _ => {
                // the parent's last estimate, predicted to now: where to look for it
                let look = self
                    .observer
                    .initialized()
                    .then(|| self.observer.position());
                let anchor = match self.slot.anchor {
                    Some(a) if self.mode == Mode::ParentLost => a,
                    Some(a) if self.mode == Mode::Coasting => {
                        let a = Anchor {
                            t0: t,
                            pos: a.pos + a.vel * (0.5 * self.cfg.coast_s),
                            vel: Vector3::zeros(),
                            yaw: a.yaw,
                            look,
                        };
                        self.slot.anchor = Some(a);
                        a
                    }
                    _ => {
                        let (pos, yaw) = match self.last_target_odo {
                            Some((p, _, y)) => (p, y),
                            None => (self.odo, yaw_own),
                        };
                        let a = Anchor {
                            t0: t,
                            pos,
                            vel: Vector3::zeros(),
                            yaw,
                            look,
                        };
                        self.slot.anchor = Some(a);
                        a
                    }
                };
                // Face the parent's last known position so that it comes back into the
                // camera's view (a parent lost at the edge of the image, e.g. after a turn,
                // would otherwise stay just outside it for good); keep the held heading if
                // that position is too close to give a bearing.
                let yaw = anchor
                    .look
                    .map(|l| l - self.odo)
                    .filter(|d| d.xy().norm() > LOOK_MIN_RANGE_M)
                    .map_or(anchor.yaw, |d| d.y.atan2(d.x));
                if self.observer.initialized() && t - anchor.t0 < self.cfg.search_s {
                    // Search: for `search_s`, go to the slot behind where the parent is
                    // predicted to be (the observer carries it on at its last velocity),
                    // facing it, so that a parent that moved on out of sight is found
                    // again instead of left behind for good.
                    let p = self.observer.position();
                    let yaw_p = self.observer.yaw();
                    let v = self.observer.velocity();
                    let slot = from_level(yaw_p, &self.slot.disp.slot);
                    let (pos, vel) = self.keep_clear(p + slot, Vector3::new(v.x, v.y, 0.0), yaw_p);
                    let yaw = Some(p - self.odo)
                        .filter(|d| d.xy().norm() > LOOK_MIN_RANGE_M)
                        .map_or(yaw, |d| d.y.atan2(d.x));
                    (pos, vel, yaw, Mode::ParentLost)
                } else {
                    (anchor.pos, Vector3::zeros(), yaw, Mode::ParentLost)
                }
            }
        };
        self.mode = mode;

        let target = Target {
            position_m: to_level(yaw_own, &(target_pos - self.odo)),
            velocity_mps: to_level(yaw_own, &target_vel),
            yaw_rel_rad: wrap(target_yaw - yaw_own),
        };
        // the safety layer's points: remembered returns, and the parent while its estimate
        // is current (fresh, or followed on its prediction)
        let odo = self.odo;
        let mut keepout = keepout::select(|| {
            self.memory
                .iter()
                .map(|m| to_level(yaw_own, &(m.pos - odo)))
        });
        if fresh || predicting {
            let p = to_level(yaw_own, &(self.observer.position() - odo));
            let v = to_level(yaw_own, &self.observer.velocity());
            keepout.parent = Some(([p.x, p.y, p.z], [v.x, v.y, v.z]));
        }
        let state = PlannerState {
            mode,
            slot_nominal_m: self.slot.disp.slot,
            slot_shifted_m: self.slot.last_shift.slot,
            slot_filtered_m: self.slot.filter.value().unwrap_or(self.slot.disp.slot),
            delta_min_m: self.slot.last_shift.delta_min,
            parent_age_s: age,
            parent_estimate_valid: fresh,
            avoiding: self.slot.last_shift.active,
            waypoint_index: 0,
            waypoint_distance_m: 0.0,
            track_offset_m: 0.0,
        };
        Ok(PlannerOutput {
            target,
            keepout,
            state,
        })
    }

    /// The target heading `yaw`, turned toward the parent just enough that every beacon
    /// of the parent (estimated at `p_parent`, heading `yaw_parent`) lies at least
    /// `view_margin_deg` inside the image edge: seen from the target heading, and, when
    /// the camera's heading now (`yaw_own`, which lags the target in a turn) already has a
    /// beacon beyond that margin, at least as far toward it as brings it back. `yaw` itself
    /// when the beacons span more than the field of view allows.
    fn keep_in_view(
        &self,
        yaw: f64,
        yaw_own: f64,
        p_parent: &Vector3<f64>,
        yaw_parent: f64,
    ) -> f64 {
        if self.cfg.view_margin_deg <= 0.0 || self.cfg.parent_beacons_body_m.is_empty() {
            return yaw;
        }
        let lim = (self.cfg.view_half_angle_deg - self.cfg.view_margin_deg).to_radians();
        let m = self.cfg.camera_mount_body_m;
        let cam = self.odo + from_level(yaw_own, &Vector3::new(m[0], m[1], 0.0));
        // bearings of the beacons off a heading
        let span = |heading: f64| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for b in &self.cfg.parent_beacons_body_m {
                let p = p_parent + from_level(yaw_parent, &Vector3::new(b[0], b[1], 0.0));
                let d = p - cam;
                let beta = wrap(d.y.atan2(d.x) - heading);
                lo = lo.min(beta);
                hi = hi.max(beta);
            }
            (lo, hi)
        };
        let (lo, hi) = span(yaw);
        if hi - lo > 2.0 * lim {
            return yaw;
        }
        let mut y = if hi > lim {
            wrap(yaw + (hi - lim))
        } else if lo < -lim {
            wrap(yaw + (lo + lim))
        } else {
            yaw
        };
        let (lo, hi) = span(yaw_own);
        if hi > lim {
            let least = wrap(yaw_own + (hi - lim));
            if wrap(y - least) < 0.0 {
                y = least;
            }
        } else if lo < -lim {
            let most = wrap(yaw_own + (lo + lim));
            if wrap(y - most) > 0.0 {
                y = most;
            }
        }
        y
    }

    /// The target `pos` moved across the parent's heading (`yaw_parent`) until it keeps
    /// `d_min_m + keep_clear_margin_m` from every remembered return between the
    /// follower and a little past the
    /// target along that heading, on the follower's own side of each return: a wall the
    /// follower is alongside is never crossed, whichever way its parent moves (our
    /// addition: eq. 8 shifts a follower toward its parent's track, which is no help when
    /// the parent itself moves sideways, as between two gaps offset opposite ways). When
    /// returns on both sides leave less than `2 d_min` the target goes midway. A target held
    /// off a wall loses its velocity toward it.
    fn keep_clear(
        &self,
        pos: Vector3<f64>,
        vel: Vector3<f64>,
        yaw_parent: f64,
    ) -> (Vector3<f64>, Vector3<f64>) {
        if !self.cfg.keep_clear {
            return (pos, vel);
        }
        let d = self.cfg.d_min_m + self.cfg.keep_clear_margin_m;
        let own = to_level(yaw_parent, &(self.odo - pos));
        let (x_lo, x_hi) = (own.x.min(0.0) - 1.0, own.x.max(0.0) + KEEP_CLEAR_AHEAD_M);
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for m in &self.memory {
            let q = to_level(yaw_parent, &(m.pos - pos));
            if q.x < x_lo || q.x > x_hi {
                continue;
            }
            if own.y >= q.y {
                lo = lo.max(q.y + d);
            } else {
                hi = hi.min(q.y - d);
            }
        }
        let y = if lo <= hi {
            0.0f64.clamp(lo, hi)
        } else {
            0.5 * (lo + hi)
        };
        if y == 0.0 {
            return (pos, vel);
        }
        // held off a wall: no velocity toward it either (the parent's sideways motion
        // would otherwise still carry the follower in)
        let mut v = to_level(yaw_parent, &vel);
        if v.y * y < 0.0 {
            v.y = 0.0;
        }
        (
            pos + from_level(yaw_parent, &Vector3::new(0.0, y, 0.0)),
            from_level(yaw_parent, &v),
        )
    }

    /// Age of the last fused fix after which the parent is lost (stale, predicted, coasted), s.
    fn lost_after_s(&self) -> f64 {
        self.cfg.stale_after_s + self.cfg.predict_s + self.cfg.coast_s
    }

    /// Tracking: eqs. (6)-(9) in the parent's level frame, then the headway
    /// ([`FollowerConfig::headway_s`]) for the own velocity `v_own` (odometry frame); returns
    /// the target position, velocity and heading in the odometry frame, and the mode.
    fn track(
        &mut self,
        dt: f64,
        v_own: &Vector3<f64>,
        r_own: f64,
        yaw_own: f64,
    ) -> (Vector3<f64>, Vector3<f64>, f64, Mode) {
        let p_parent = self.observer.position();
        let v_parent = self.observer.velocity();
        let yaw_parent = self.observer.yaw();
        let r_parent = self.observer.yaw_rate();
        // eq. (6): remembered returns in the parent's frame (rotation from vision)
        let shift = self.slot.disp.shift(
            self.memory
                .iter()
                .map(|m| to_level(yaw_parent, &(m.pos - p_parent)).y),
            self.cfg.d_min_m,
        );
        let prev = self.slot.filter.value().unwrap_or(self.slot.disp.slot);
        let filtered = self.slot.filter.update(&shift.slot); // eq. (9)
        let slot_rate = if dt > 0.0 {
            (filtered - prev) / dt
        } else {
            Vector3::zeros()
        };
        self.slot.last_shift = shift;
        // the rigid slot (the paper's), or the slot bent along the parent's path (`trail`):
        // its along-track arm on the chord from where the parent was the arm's length back
        // (heading `ψ_q` there) to where it is now, its lateral and vertical parts square
        // to the path there (`crate::trail`)
        let (anchor, yaw_slot, arm, vel) = if self.cfg.trail && filtered.x < 0.0 {
            self.slot.trail.push(p_parent, yaw_parent);
            let (_, yaw_q) = self.slot.trail.behind(p_parent, yaw_parent, -filtered.x);
            let yaw_chord = wrap(yaw_parent - 0.5 * wrap(yaw_parent - yaw_q));
            let across = from_level(yaw_q, &Vector3::new(0.0, filtered.y, filtered.z));
            let arm = from_level(yaw_chord, &Vector3::new(filtered.x, 0.0, 0.0)) + across;
            let speed = v_parent.xy().norm();
            let along = Vector3::new(yaw_q.cos(), yaw_q.sin(), 0.0) * speed;
            let vel = along
                + Vector3::z() * v_parent.z
                + Vector3::z().cross(&across) * r_parent
                + from_level(yaw_q, &slot_rate);
            (p_parent, yaw_q, arm, vel)
        } else {
            let arm = from_level(yaw_parent, &filtered);
            let vel =
                v_parent + Vector3::z().cross(&arm) * r_parent + from_level(yaw_parent, &slot_rate);
            (p_parent, yaw_parent, arm, vel)
        };
        // headway: v̄ is kept in the parent's level frame, so that a steady turn is steady
        let v_level = to_level(yaw_parent, &vel);
        let gain = (dt / self.cfg.headway_avg_s).min(1.0);
        let (mut mean_v, mut mean_r) = match self.slot.headway_mean {
            Some((v, r)) => (v + (v_level - v) * gain, r + (r_parent - r) * gain),
            None => (v_level, r_parent),
        };
        // The formation is never taken to move faster, or turn faster, than the target
        // does now: when the parent slows to a stop (or ends a turn) the slow average
        // would otherwise keep `v̄` (`r̄`) up for a minute and put the target that far
        // ahead of the slot (turned into the finished turn) while everyone is at rest.
        if self.cfg.headway_cap {
            let cap = v_level.norm();
            if mean_v.norm() > cap {
                mean_v *= cap / mean_v.norm();
            }
            if mean_r * r_parent <= 0.0 {
                mean_r = 0.0;
            } else if mean_r.abs() > r_parent.abs() {
                mean_r = r_parent;
            }
        }
        self.slot.headway_mean = Some((mean_v, mean_r));
        let headway = (v_own - from_level(yaw_parent, &mean_v)) * self.cfg.headway_s;
        // On a trail the heading is the one that shows the parent where the rigid slot
        // shows it (the slot's own bearing, `atan2(−s_y, −s_x)`, off the line of sight):
        // heading along the past path instead turns the parent by about `L/R` in the image
        // in a turn of radius R, out of view at the formation's margins. On a straight leg
        // it is the parent's heading, as the rigid slot's.
        let yaw_view = if self.cfg.trail && filtered.x < 0.0 {
            let sight = p_parent - (anchor + arm);
            if sight.xy().norm() > TRAIL_SIGHT_MIN_M {
                wrap(sight.y.atan2(sight.x) - (-filtered.y).atan2(-filtered.x))
            } else {
                yaw_slot
            }
        } else {
            yaw_slot
        };
        let (pos, vel) = self.keep_clear(anchor + arm - headway, vel, yaw_slot);
        let yaw = wrap(yaw_view - self.cfg.yaw_headway_s * (r_own - mean_r));
        let yaw = self.keep_in_view(yaw, yaw_own, &p_parent, yaw_parent);
        self.last_target_odo = Some((pos, vel, yaw));
        let returning = (filtered - self.slot.disp.slot).norm() > 0.05;
        let mode = if shift.active || returning {
            Mode::Avoiding
        } else {
            Mode::Tracking
        };
        (pos, vel, yaw, mode)
    }
}

#[cfg(test)]
mod tests {
    //! The `predict_s` phase in a small kinematic world (the fixtures of `tests/follower.rs`
    //! in brief): the parent swims north at 1 m/s, the follower goes where it is told.
    #![allow(clippy::unwrap_used)]

    use super::*;
    use nalgebra::Translation3;

    const DT: f64 = 0.1;

    struct World {
        planner: FollowerPlanner,
        me: Vector3<f64>,
        vel: Vector3<f64>,
        t: f64,
        slot: Vector3<f64>,
    }

    fn parent_at(t: f64) -> Vector3<f64> {
        Vector3::new(t, 0.0, 10.0)
    }

    impl World {
        fn new(cfg: &FollowerConfig) -> Self {
            let slot = Vector3::from(cfg.slot_in_parent_m);
            Self {
                planner: FollowerPlanner::new(cfg).unwrap(),
                me: parent_at(0.0) + slot,
                vel: Vector3::new(1.0, 0.0, 0.0),
                t: 0.0,
                slot,
            }
        }

        /// One step, with a perfect fix if `seen`; the follower then moves to its target.
        fn step(&mut self, seen: bool) -> PlannerOutput {
            let fix = seen.then(|| PoseMeasurement {
                t_s: self.t,
                parent_in_body: Isometry3::from_parts(
                    Translation3::from(parent_at(self.t) - self.me),
                    UnitQuaternion::identity(),
                ),
                covariance: Matrix6::identity() * 0.01,
                valid: true,
            });
            let out = self
                .planner
                .step(&FollowerInput {
                    t_s: self.t,
                    attitude: UnitQuaternion::identity(),
                    nu: Vector6::new(self.vel.x, self.vel.y, self.vel.z, 0.0, 0.0, 0.0),
                    depth_m: self.me.z,
                    pose: fix,
                    sonar: None,
                })
                .unwrap();
            let next = self.me + out.target.position_m + out.target.velocity_mps * DT;
            self.vel = (next - self.me) / DT;
            self.me = next;
            self.t += DT;
            out
        }
    }

    #[test]
    fn predicting_keeps_the_slot_through_a_ten_second_outage_and_resumes_at_the_first_fix() {
        let cfg = FollowerConfig {
            predict_s: 10.0,
            ..FollowerConfig::default()
        };
        let mut w = World::new(&cfg);
        for _ in 0..100 {
            w.step(true);
        }
        let mut coasting = 0;
        for _ in 0..100 {
            let out = w.step(false);
            assert_ne!(out.state.mode, Mode::ParentLost, "t = {}", w.t);
            coasting += usize::from(out.state.mode == Mode::Coasting);
            // on the slot behind where the parent really is (it swims on at 1 m/s)
            let err = (w.me - (parent_at(w.t) + w.slot)).norm();
            assert!(err < 0.2, "t = {}: {err} m off the slot", w.t);
        }
        assert!(coasting >= 90, "{coasting} steps coasting");
        // the first fix resumes tracking: the observer was not restarted
        let out = w.step(true);
        assert_eq!(out.state.mode, Mode::Tracking);
        assert!(out.state.parent_estimate_valid);
    }

    #[test]
    fn after_predicting_the_follower_slows_to_a_stop_then_is_lost() {
        let cfg = FollowerConfig {
            predict_s: 2.0,
            search_s: 3.0,
            ..FollowerConfig::default()
        };
        let mut w = World::new(&cfg);
        for _ in 0..100 {
            w.step(true);
        }
        let t_last = w.t - DT;
        let mut speeds = Vec::new();
        for _ in 0..150 {
            let t = w.t;
            let out = w.step(false);
            let age = t - t_last;
            let want = if age <= cfg.stale_after_s + 1e-9 {
                Mode::Tracking
            } else if age <= cfg.stale_after_s + cfg.predict_s + cfg.coast_s + 1e-9 {
                Mode::Coasting
            } else {
                Mode::ParentLost
            };
            assert_eq!(out.state.mode, want, "age {age}");
            speeds.push((age, out.target.velocity_mps.norm()));
        }
        for (age, v) in speeds {
            let slow_from = cfg.stale_after_s + cfg.predict_s;
            if age <= slow_from + 1e-9 {
                assert!(
                    (v - 1.0).abs() < 0.05,
                    "age {age}: {v} m/s while predicting"
                );
            } else if age > slow_from + cfg.coast_s + 1e-9 {
                // lost: searching after the parent at its predicted speed, then held (the
                // steps at either end of the search aside)
                let since = age - slow_from - cfg.coast_s;
                if since > cfg.search_s + 2.0 * DT {
                    assert!(v.abs() < 1e-9, "age {age}: {v} m/s when lost");
                } else if since > 2.0 * DT && since < cfg.search_s - DT {
                    assert!((v - 1.0).abs() < 0.05, "age {age}: {v} m/s searching");
                }
            } else {
                // slowing linearly over coast_s
                let f = 1.0 - (age - slow_from - DT) / cfg.coast_s;
                assert!((v - f).abs() < 0.06, "age {age}: {v} m/s, want {f}");
            }
        }
    }

    /// On a straight leg the trail's slot is the rigid one: the same targets, step by
    /// step, once the trail is longer than the slot.
    #[test]
    fn on_a_straight_leg_the_trail_is_the_rigid_slot() {
        let rigid = FollowerConfig {
            trail: false,
            ..FollowerConfig::default()
        };
        let trail = FollowerConfig::default();
        let (mut a, mut b) = (World::new(&rigid), World::new(&trail));
        for i in 0..300 {
            let (oa, ob) = (a.step(true), b.step(true));
            if i > 150 {
                let d = (oa.target.position_m - ob.target.position_m).norm();
                assert!(d < 0.05, "step {i}: {d} m apart");
                assert!((a.me - (parent_at(a.t) + a.slot)).norm() < 0.1);
                assert!((b.me - (parent_at(b.t) + b.slot)).norm() < 0.1);
            }
        }
    }
}
