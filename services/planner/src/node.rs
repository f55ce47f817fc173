//! Wiring of the planner library to its channels.

use crate::{
    FollowerConfig, FollowerInput, FollowerPlanner, LeaderConfig, LeaderInput, LeaderPlanner,
    PlannerOutput, PoseMeasurement, SonarScan,
};
use anyhow::Context;
use ipc_types::{Channel, LeaderPose, Nav, PlannerState, Sample, Setpoint, Sonar};
use nalgebra::{Isometry3, Matrix6, Translation3, Vector3, Vector6};
use shoal_runtime::convert::{arr, quat};
use shoal_runtime::ports::Origin;
use shoal_runtime::{
    ChannelLimits, Publisher, Runtime, Service, StepContext, Subscriber, Task, TaskError,
};
use shoal_scenario::{ProcessKind, Scenario};

/// The follower configuration of one vehicle: the scenario's shared
/// `[follower]` section, its slot, D_min from the safety distance, and the
/// D_a, D_b that `shoal run` resolved for it (given or assigned from the
/// whole formation, see `shoal check`).
pub fn follower_config(scenario: &Scenario, name: &str) -> anyhow::Result<FollowerConfig> {
    let mut cfg: FollowerConfig = scenario.section("follower")?;
    let spec = scenario.vehicle(name).context("vehicle not in scenario")?;
    cfg.slot_in_parent_m = spec.slot_m.context("a follower needs slot_m")?;
    cfg.d_min_m = scenario.safety.safe_distance_m;
    let camera: camera_pose::CameraConfig = scenario.section("camera")?;
    let beacons: camera_pose::BeaconLayout = scenario.section("beacons")?;
    cfg.view_half_angle_deg = camera.fov_deg / 2.0;
    cfg.camera_mount_body_m = camera.mount_position_body_m;
    cfg.parent_beacons_body_m = beacons.positions_body_m;
    if scenario.method.generalised {
        if !scenario.follower.contains_key("memory_behind_m") {
            cfg.memory_behind_m = memory_behind_m(scenario, name, cfg.memory_behind_m);
        }
    } else {
        // the paper's method as published
        cfg.view_margin_deg = 0.0;
        cfg.keep_clear = false;
        cfg.headway_cap = false;
        cfg.search_s = 0.0;
        cfg.memory_cell_m = 0.0;
        cfg.coordinated_turn = false;
        cfg.trail = false;
    }
    cfg.d_a_m = spec
        .d_a_m
        .context("d_a_m not resolved: start the planner through `shoal run`")?;
    cfg.d_b_m = spec
        .d_b_m
        .context("d_b_m not resolved: start the planner through `shoal run`")?;
    Ok(cfg)
}

/// Room behind the rearmost follower of an arm for its hull and its displacement, m.
pub const MEMORY_BEHIND_MARGIN_M: f64 = 5.0;

/// How long a vehicle remembers an obstacle (and keeps its avoidance) when the
/// scenario does not say: until the farthest vehicle of the formation behind it
/// ([`Scenario::reach_behind_m`]) is [`MEMORY_BEHIND_MARGIN_M`] past it, and at least
/// the planner's `default`. A vehicle that returned to its track as soon as it was past
/// would pull the followers still alongside the obstacle into it.
pub fn memory_behind_m(scenario: &Scenario, name: &str, default: f64) -> f64 {
    let reach = scenario.reach_behind_m(name);
    if reach > 0.0 {
        default.max(reach + MEMORY_BEHIND_MARGIN_M)
    } else {
        default
    }
}

/// The leader's turn radius that keeps every follower's parent in view
/// ([`crate::view`]): from the slots, the camera's field of view and mount, the
/// beacon layout and the followers' keep-in-view margin; 0 (sharp corners) without
/// followers.
pub fn turn_radius_m(scenario: &Scenario, speed_mps: f64) -> anyhow::Result<f64> {
    let follower: FollowerConfig = scenario.section("follower")?;
    let reserve = follower.view_margin_deg.to_radians();
    let camera: camera_pose::CameraConfig = scenario.section("camera")?;
    let beacons: camera_pose::BeaconLayout = scenario.section("beacons")?;
    Ok(crate::view::formation_turn_radius_m(
        scenario.vehicles.iter().filter_map(|v| v.slot_m),
        &camera,
        &beacons,
        reserve,
        speed_mps,
    ))
}

/// The one key of sim-plant's `[nav]` section the leader's position filter needs; absent →
/// the mission's `position_fix_noise_m` (whose default is sim-plant's).
#[derive(serde::Deserialize)]
struct NavNoise {
    position_noise_m: Option<f64>,
}

enum Role<S: Service> {
    Leader(LeaderPlanner),
    Follower {
        planner: FollowerPlanner,
        pose_in: Subscriber<LeaderPose, S>,
    },
}

/// The planner process's task: its vehicle's `nav`, `sonar` (and, for a
/// follower, `leader_pose`) in; `setpoint` and `planner_state` out; over
/// iceoryx2 service kind `S` (shared memory in the binary).
pub struct PlannerTask<S: Service = shoal_runtime::ipc::Service> {
    role: Role<S>,
    nav_in: Subscriber<Nav, S>,
    sonar_in: Subscriber<Sonar, S>,
    setpoint_out: Publisher<Setpoint, S>,
    state_out: Publisher<PlannerState, S>,
    nav: Option<Nav>,
}

impl<S: Service> PlannerTask<S> {
    /// Opens the vehicle's ports on `rt` and builds its leader or follower
    /// planner from the (resolved) scenario.
    pub fn new(rt: &Runtime<S>, scenario: &Scenario) -> anyhow::Result<Self> {
        let me = &rt.args().vehicle;
        let spec = scenario.vehicle(me).context("vehicle not in scenario")?;
        let run = &rt.args().run_id;
        let lim = ChannelLimits::vehicle();
        // Dataflow: a planner step per frame, once the frame's sonar scan
        // and (a follower with a camera) parent fix are in; nav is read as
        // it stands (the plant sends it before either).
        let sonar = ipc_types::service_name(run, me, Channel::Sonar);
        if scenario.same_rate(ProcessKind::Planner, ProcessKind::Sonar) {
            rt.wake_on(&sonar, &lim)?;
        }
        let pose = ipc_types::service_name(run, me, Channel::LeaderPose);
        if spec.parent.is_some()
            && scenario.method.perception == shoal_scenario::Perception::Camera
            && scenario.same_rate(ProcessKind::Planner, ProcessKind::CameraPose)
        {
            rt.wake_on(&pose, &lim)?;
        }
        let role = if spec.parent.is_none() {
            let mut cfg: LeaderConfig = scenario.section("mission")?;
            cfg.d_min_m = scenario.safety.safe_distance_m;
            let sonar: sonar::SonarConfig = scenario.section("sonar")?;
            let layout = sonar::Sonar::new(&sonar)?;
            cfg.sonar_return_spread_deg = layout.return_spread_rad().to_degrees();
            cfg.sonar_wedge_deg = layout.blind_wedge_rad().to_degrees();
            if scenario.method.generalised {
                if !scenario.mission.contains_key("memory_behind_m") {
                    cfg.memory_behind_m = memory_behind_m(scenario, me, cfg.memory_behind_m);
                }
                if !scenario.mission.contains_key("turn_radius_m") {
                    cfg.turn_radius_m = turn_radius_m(scenario, cfg.speed_mps)?;
                }
            } else {
                // the paper's method as published (its ref. [11] for the leader)
                cfg.shadow_m = 0.0;
                cfg.side_margin_m = 0.0;
                cfg.keep_abeam_side = false;
                cfg.memory_cell_m = 0.0;
                cfg.turn_radius_m = 0.0;
                cfg.brake_mps2 = 0.0;
                cfg.check_reach = false;
            }
            // The position filter's fix noise is the nav sensor's (sim-plant's `[nav]`).
            let nav: NavNoise = scenario.section("nav")?;
            if let Some(n) = nav.position_noise_m.filter(|n| *n > 0.0) {
                cfg.position_fix_noise_m = n;
            }
            let mut planner = LeaderPlanner::new(&cfg)?;
            if rt.args().restart > 0 {
                planner.resume();
            }
            Role::Leader(planner)
        } else {
            Role::Follower {
                planner: FollowerPlanner::new(&follower_config(scenario, me)?)?,
                pose_in: rt.subscriber(&pose, &lim, 4)?,
            }
        };
        Ok(Self {
            role,
            nav_in: rt.subscriber(&ipc_types::service_name(run, me, Channel::Nav), &lim, 4)?,
            sonar_in: rt.subscriber(&sonar, &lim, 4)?,
            setpoint_out: rt
                .publisher(&ipc_types::service_name(run, me, Channel::Setpoint), &lim)?,
            state_out: rt.publisher(
                &ipc_types::service_name(run, me, Channel::PlannerState),
                &lim,
            )?,
            nav: None,
        })
    }
}

fn nu_of(n: &Nav) -> Vector6<f64> {
    let v = n.velocity_body_mps;
    let w = n.rates_body_radps;
    Vector6::new(v[0], v[1], v[2], w[0], w[1], w[2])
}

impl<S: Service> Task for PlannerTask<S> {
    fn step(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(n) = self.nav_in.latest(ctx)? {
            self.nav = Some(n);
        }
        let Some(nav) = self.nav else {
            return Ok(()); // nothing known about ourselves yet
        };
        let sonar = self.sonar_in.latest(ctx)?;
        let mut origin = Origin::of(&nav.header);
        if let Some(s) = &sonar {
            origin = origin.earliest(Origin::of(&s.header));
        }
        // The planner's time base is the time of the nav sample, not this process's tick:
        // the plant measured the state at the start of the frame and the planner runs three
        // ticks later. Dead reckoning, the placing of vision fixes (stamped with their image
        // time) and the target must all refer to the instant the state was measured, or the
        // slot lags by speed × the difference (0.08 m at 1 m/s measured in the paper run).
        let t_s = nav.header.sim_time_ns as f64 * 1e-9;
        let attitude = quat(nav.q_body_to_ned_wxyz);
        let out: PlannerOutput = match &mut self.role {
            Role::Leader(p) => {
                if nav.position_valid == 0 {
                    return Err(TaskError::BadInput {
                        input: "nav.position_valid",
                        reason: "the leader's nav has no absolute position".into(),
                    });
                }
                p.step(&LeaderInput {
                    t_s,
                    attitude,
                    nu: nu_of(&nav),
                    position_ned_m: Vector3::from(nav.position_ned_m),
                    depth_m: nav.depth_m,
                    sonar: sonar.as_ref().map(SonarScan::from_sample),
                })
                .map_err(TaskError::failed("leader planner step"))?
            }
            Role::Follower { planner, pose_in } => {
                let pose = pose_in.latest(ctx)?.map(|p| {
                    origin = origin.earliest(Origin::of(&p.header));
                    pose_measurement(&p)
                });
                planner
                    .step(&FollowerInput {
                        t_s,
                        attitude,
                        nu: nu_of(&nav),
                        depth_m: nav.depth_m,
                        pose,
                        sonar: sonar.as_ref().map(SonarScan::from_sample),
                    })
                    .map_err(TaskError::failed("follower planner step"))?
            }
        };
        self.setpoint_out.publish(setpoint_of(&out), ctx, origin)?;
        self.state_out.publish(state_of(&out), ctx, origin)?;
        Ok(())
    }
}

/// A parent fix as the planner takes it, from camera-pose's sample: the
/// parent's pose in the follower's body frame at the image's time.
pub fn pose_measurement(p: &LeaderPose) -> PoseMeasurement {
    let mut cov = Matrix6::zeros();
    for r in 0..6 {
        for c in 0..6 {
            cov[(r, c)] = p.covariance[6 * r + c];
        }
    }
    PoseMeasurement {
        t_s: p.header.origin_sim_time_ns as f64 * 1e-9,
        parent_in_body: Isometry3::from_parts(
            Translation3::from(Vector3::from(p.parent_position_body_m)),
            quat(p.q_parent_to_body_wxyz),
        ),
        covariance: cov,
        valid: p.valid != 0,
    }
}

/// The setpoint a planner's output hands the controller (target, mode,
/// and what the safety layer keeps clear of).
pub fn setpoint_of(out: &PlannerOutput) -> Setpoint {
    let mut sp = Setpoint::zeroed();
    sp.position_m = arr(&out.target.position_m);
    sp.velocity_mps = arr(&out.target.velocity_mps);
    sp.yaw_rel_rad = out.target.yaw_rel_rad;
    sp.mode = out.state.mode.into();
    out.keepout.write_to(&mut sp);
    sp
}

/// The `planner_state` sample of a planner's output (an unknown figure -1).
pub fn state_of(out: &PlannerOutput) -> PlannerState {
    let s = &out.state;
    let known = |x: f64| if x.is_finite() { x } else { -1.0 };
    let mut st = PlannerState::zeroed();
    st.slot_nominal_m = arr(&s.slot_nominal_m);
    st.slot_shifted_m = arr(&s.slot_shifted_m);
    st.slot_filtered_m = arr(&s.slot_filtered_m);
    st.delta_min_m = known(s.delta_min_m);
    st.parent_age_s = known(s.parent_age_s);
    st.waypoint_distance_m = known(s.waypoint_distance_m);
    st.mode = s.mode.into();
    st.parent_valid = u8::from(s.parent_estimate_valid);
    st.avoiding = u8::from(s.avoiding);
    st
}
