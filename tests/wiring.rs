//! A follower's planner and mpc wired as their binaries wire them (the same
//! `PlannerTask` and `MpcTask`, their ports opened through a `Runtime`), but
//! in one process over iceoryx2's `local::Service`: scripted `nav`,
//! `leader_pose` and `sonar` go in, and the test reads what comes out on
//! `setpoint`, `planner_state`, `thrust` and `mpc_stats`. No process is
//! spawned and no shared memory is used.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ipc_types::{
    Channel, LeaderPose, MpcStats, Nav, PlannerState, Sample, Setpoint, Sonar, Thrust,
};
use shoal_runtime::ports::Origin;
use shoal_runtime::{
    local, ChannelLimits, Mode, Publisher, RunArgs, Runtime, StepContext, Subscriber, Task,
};
use shoal_scenario::Scenario;

const FOLLOWER: &str = "F1";
const TICK_NS: u64 = 100_000_000;

fn args(run_id: &str, process: &str, index: usize) -> RunArgs {
    RunArgs {
        run_id: run_id.into(),
        vehicle: FOLLOWER.into(),
        process: process.into(),
        index,
        processes: 3,
        mode: Mode::Lockstep,
        period_s: 0.1,
        epoch_mono_ns: 0,
        phase_s: 0.0,
        spin_us: 0,
        restart: 0,
        resume: None,
        no_work: false,
    }
}

fn ctx(sim_time_ns: u64) -> StepContext {
    StepContext {
        sim_time_ns,
        tick: sim_time_ns / 10_000_000,
        wake_mono_ns: shoal_runtime::mono_ns(),
        since_last_ns: TICK_NS,
        last: false,
        mode: Mode::Lockstep,
        woken_by: shoal_runtime::Wake::Tick,
    }
}

/// The paper scenario with F1's displacements given (as `shoal check`
/// would assign them).
fn scenario() -> Scenario {
    let mut s = Scenario::paper().unwrap();
    for v in s.vehicles.iter_mut().filter(|v| v.parent.is_some()) {
        v.d_a_m = Some(2.5);
        v.d_b_m = Some(1.0);
    }
    s
}

/// What the script publishes and reads, on F1's channels.
struct Script {
    nav: Publisher<Nav, local::Service>,
    pose: Publisher<LeaderPose, local::Service>,
    sonar: Publisher<Sonar, local::Service>,
    setpoint: Subscriber<Setpoint, local::Service>,
    state: Subscriber<PlannerState, local::Service>,
    thrust: Subscriber<Thrust, local::Service>,
    stats: Subscriber<MpcStats, local::Service>,
}

impl Script {
    fn open(rt: &Runtime<local::Service>) -> Self {
        let run = &rt.args().run_id;
        let lim = ChannelLimits::vehicle();
        let name = |c| ipc_types::service_name(run, FOLLOWER, c);
        Self {
            nav: rt.publisher(&name(Channel::Nav), &lim).unwrap(),
            pose: rt.publisher(&name(Channel::LeaderPose), &lim).unwrap(),
            sonar: rt.publisher(&name(Channel::Sonar), &lim).unwrap(),
            setpoint: rt.subscriber(&name(Channel::Setpoint), &lim, 4).unwrap(),
            state: rt
                .subscriber(&name(Channel::PlannerState), &lim, 4)
                .unwrap(),
            thrust: rt.subscriber(&name(Channel::Thrust), &lim, 4).unwrap(),
            stats: rt.subscriber(&name(Channel::MpcStats), &lim, 4).unwrap(),
        }
    }

    /// F1 at rest at 10 m depth heading north; its parent seen at
    /// `parent_body_m` (body frame), parallel to it; the sonar sees nothing.
    fn publish(&mut self, t_ns: u64, parent_body_m: [f64; 3]) {
        let c = ctx(t_ns);
        let origin = Origin::here(&c);
        let mut nav = Nav::zeroed();
        nav.q_body_to_ned_wxyz = [1.0, 0.0, 0.0, 0.0];
        nav.depth_m = 10.0;
        self.nav.publish(nav, &c, origin).unwrap();
        let mut pose = LeaderPose::zeroed();
        pose.parent_position_body_m = parent_body_m;
        pose.q_parent_to_body_wxyz = [1.0, 0.0, 0.0, 0.0];
        for i in 0..6 {
            pose.covariance[7 * i] = 0.01;
        }
        pose.valid = 1;
        pose.beacons_used = 4;
        self.pose.publish(pose, &c, origin).unwrap();
        let mut sonar = Sonar::zeroed();
        sonar.count = 4;
        self.sonar.publish(sonar, &c, origin).unwrap();
    }
}

/// Runs `ticks` lockstep frames (script, then planner, then mpc, each on
/// what was stamped before its own time) with the parent at
/// `parent_body_m`; returns the last setpoint, state, thrust and stats.
#[allow(clippy::type_complexity)]
fn frames(
    script: &mut Script,
    planner: &mut impl Task,
    mpc: &mut impl Task,
    from_tick: u64,
    ticks: u64,
    parent_body_m: [f64; 3],
) -> (Setpoint, PlannerState, Thrust, MpcStats, u64) {
    let mut last = None;
    let mut thrusts = 0;
    for k in from_tick..from_tick + ticks {
        let t = k * TICK_NS;
        script.publish(t, parent_body_m);
        planner.step(&ctx(t + 30_000_000)).unwrap();
        mpc.step(&ctx(t + 60_000_000)).unwrap();
        let after = ctx(t + TICK_NS - 1);
        let sp = script.setpoint.latest(&after).unwrap();
        let st = script.state.latest(&after).unwrap();
        let th = script.thrust.latest(&after).unwrap();
        let ms = script.stats.latest(&after).unwrap();
        thrusts += u64::from(th.is_some());
        if let (Some(sp), Some(st), Some(th), Some(ms)) = (sp, st, th, ms) {
            assert_eq!(
                sp.header.sim_time_ns,
                t + 30_000_000,
                "the planner stamps its tick"
            );
            assert_eq!(
                th.header.sim_time_ns,
                t + 60_000_000,
                "the mpc stamps its tick"
            );
            last = Some((sp, st, th, ms));
        }
    }
    let (sp, st, th, ms) = last.expect("the planner and the mpc published every frame");
    (sp, st, th, ms, thrusts)
}

#[test]
fn a_follower_planner_and_mpc_steer_toward_the_slot_from_scripted_inputs() {
    let run_id = format!("wire{}", std::process::id());
    let scenario = scenario();
    let script_rt = Runtime::<local::Service>::open(&args(&run_id, "script", 2)).unwrap();
    let planner_rt = Runtime::<local::Service>::open(&args(&run_id, "planner", 0)).unwrap();
    let mpc_rt = Runtime::<local::Service>::open(&args(&run_id, "mpc", 1)).unwrap();
    let mut script = Script::open(&script_rt);
    let mut planner = planner::node::PlannerTask::new(&planner_rt, &scenario).unwrap();
    let mut mpc = mpc::node::MpcTask::new(&mpc_rt, &scenario).unwrap();

    let slot = scenario.vehicle(FOLLOWER).unwrap().slot_m.unwrap();
    let plant: sim_plant::PlantConfig = scenario.section("plant").unwrap();

    // The parent 2 m farther ahead than the slot puts it: the target is
    // 2 m ahead of F1, and the mpc pushes forward.
    let ahead = [2.0 - slot[0], -slot[1], -slot[2]];
    let (sp, st, th, ms, n) = frames(&mut script, &mut planner, &mut mpc, 1, 40, ahead);
    assert_eq!(n, 40, "a thrust every frame");
    assert_eq!(st.parent_valid, 1);
    assert_eq!(st.mode, 0, "tracking");
    assert_eq!(st.avoiding, 0, "the sonar saw nothing");
    assert!(
        (sp.position_m[0] - 2.0).abs() < 0.3 && sp.position_m[1].abs() < 0.3,
        "target {:?} is 2 m ahead",
        sp.position_m
    );
    assert!(th.tau[0] > 0.0, "surge {:?} pushes forward", th.tau);
    for (i, t) in th.tau.iter().enumerate() {
        assert!(
            t.abs() <= plant.thrust_max[i] + 1e-9,
            "{:?} within the bounds",
            th.tau
        );
    }
    assert_eq!(ms.failures, 0);
    assert_eq!(th.fallback, 0);

    // The parent 2 m nearer than the slot: the target is behind, the mpc
    // pulls back.
    let behind = [-2.0 - slot[0], -slot[1], -slot[2]];
    let (sp, _, th, ms, _) = frames(&mut script, &mut planner, &mut mpc, 41, 40, behind);
    assert!(
        (sp.position_m[0] + 2.0).abs() < 0.3,
        "target {:?} is 2 m behind",
        sp.position_m
    );
    assert!(th.tau[0] < 0.0, "surge {:?} pulls back", th.tau);
    assert_eq!(ms.failures, 0);

    drop((planner, mpc, script));
    assert!(
        shoal_runtime::domain::list_domain_files(&run_id).is_empty(),
        "local services leave nothing in the run's domain"
    );
}
