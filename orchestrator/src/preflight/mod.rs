//! `shoal check`: every section of a scenario parsed into its service's
//! typed config and validated, the start checked (no vehicle inside an
//! obstacle or too close to another, every camera sees its parent), the
//! formation's displacement trajectories (D_a, D_b) assigned and checked,
//! and what the run needs from the machine ([`needs`]) compared with what
//! it has ([`fits`]), before anything starts.

use std::collections::BTreeMap;

use anyhow::Context;
use camera_pose::{BeaconStatus, Camera, Capsule};
use nalgebra::{Isometry3, Vector3};
use planner::formation::{FollowerSlot, FormationParams};
use shoal_runtime::domain::ChannelLimits;
use shoal_scenario::{Perception, ProcessKind, Scenario};

// The scenario crate cannot see ipc-types; the two limits must agree.
const _: () = assert!(shoal_scenario::MAX_VEHICLES == ipc_types::MAX_VEHICLES);

/// Validates the whole scenario and fills in every follower's D_a and D_b
/// (those the file leaves out are assigned from the formation); the error
/// names the key, or the pair of vehicles that cannot be kept apart.
pub fn resolve(s: &mut Scenario) -> anyhow::Result<()> {
    s.validate()?;
    let plant: sim_plant::PlantConfig = s.section("plant")?;
    plant.validate().context("plant")?;
    let nav: sim_plant::nav::NavConfig = s.section("nav")?;
    nav.validate().context("nav")?;
    let sonar_cfg: sonar::SonarConfig = s.section("sonar")?;
    sonar_cfg.validate().context("sonar")?;
    let obstacles: Vec<sonar::Obstacle> = s.obstacles_as()?;
    for (i, o) in obstacles.iter().enumerate() {
        o.validate().with_context(|| format!("obstacles[{i}]"))?;
    }
    let camera: camera_pose::CameraConfig = s.section("camera")?;
    camera.validate().context("camera")?;
    let beacons: camera_pose::BeaconLayout = s.section("beacons")?;
    beacons.validate().context("beacons")?;
    let hull: camera_pose::HullConfig = s.section("hull")?;
    hull.validate().context("hull")?;
    let pose: camera_pose::PoseConfig = s.section("pose")?;
    pose.validate().context("pose")?;
    camera_pose::PoseEstimator::new(&pose, &camera, &beacons).context("pose")?;
    let mission: planner::LeaderConfig = s.section("mission")?;
    mission.validate().context("mission")?;
    let follower: planner::FollowerConfig = s.section("follower")?;
    follower.validate().context("follower")?;
    let mpc_cfg: mpc::MpcConfig = s.section("mpc")?;
    mpc_cfg.validate().context("mpc")?;
    // Parsed whatever the perception mode, so a bad key is never silent.
    let acoustic: camera_pose::acoustic::AcousticConfig = s.section("acoustic")?;
    acoustic.validate().map_err(anyhow::Error::msg)?;
    let field = sonar::ObstacleField::new(&obstacles).context("obstacles")?;
    check_start(s, &field, &camera, &beacons, &hull, &pose)?;

    let slots: Vec<FollowerSlot> = s
        .vehicles
        .iter()
        .filter_map(|v| {
            Some(FollowerSlot {
                name: v.name.clone(),
                parent: v.parent.clone()?,
                slot_in_parent_m: v.slot_m?,
            })
        })
        .collect();
    let params = FormationParams {
        visibility_range_m: camera.visibility_range_m,
        ..Default::default()
    };
    let d_min = s.safety.safe_distance_m;
    let leader = s.leader().name.clone();
    let assigned = planner::formation::assign_displacements(&leader, &slots, d_min, &params)
        .context(
        "formation: no displacement trajectories keep every pair apart and every parent in sight",
    )?;
    let s_method_vertical = s.method.vertical_shift;
    let mut chosen = Vec::with_capacity(slots.len());
    for (slot, (d_a, d_b)) in slots.iter().zip(assigned) {
        let v = s
            .vehicles
            .iter_mut()
            .find(|v| v.name == slot.name)
            .context("follower vanished")?;
        let mut d = (v.d_a_m.unwrap_or(d_a), v.d_b_m.unwrap_or(d_b));
        if !s_method_vertical {
            // The ablation: no vertical displacement (eq. 5 with D_b = 0).
            d.1 = 0.0;
        }
        v.d_a_m = Some(d.0);
        v.d_b_m = Some(d.1);
        chosen.push(d);
    }
    // The ablation (no vertical shift) is by design a formation the check
    // refuses: it is run to measure what that costs.
    if s_method_vertical {
        planner::formation::check(&leader, &slots, &chosen, d_min, &params).context(
            "formation: the given D_a/D_b do not keep every pair apart and every parent in sight",
        )?;
    }
    fits(&needs(s))?;
    Ok(())
}

/// Followers of followers this many levels below the leader need the
/// headway ([`planner::FollowerConfig::headway_s`]) to stay string-stable.
pub const HEADWAY_DEPTH: usize = 3;

/// What the scenario allows but will probably regret, one line each
/// (`shoal check` prints them, `shoal run` logs them).
pub fn advice(s: &Scenario) -> Vec<String> {
    let mut out = Vec::new();
    let follower: planner::FollowerConfig = s.section("follower").unwrap_or_default();
    let depth = tree_depth(s);
    if depth >= HEADWAY_DEPTH && follower.headway_s == 0.0 {
        let (h, h_yaw) = (crate::gen::HEADWAY_S, crate::gen::YAW_HEADWAY_S);
        out.push(format!(
            "the formation is {depth} levels deep and follower.headway_s = 0: each level \
             passes its parent's tracking error on amplified (string instability); \
             set `headway_s` and `yaw_headway_s` (`shoal gen` writes {h} and {h_yaw} s)"
        ));
    }
    out
}

/// Levels below the leader of the deepest follower (0 with no followers).
pub fn tree_depth(s: &Scenario) -> usize {
    s.levels().into_values().max().unwrap_or(0)
}

/// The start of the run: no vehicle inside an obstacle, none closer than the
/// safe distance to another, and every follower's camera sees enough of its
/// parent's beacons (camera perception only). Errors name the vehicle's key.
fn check_start(
    s: &Scenario,
    field: &sonar::ObstacleField,
    camera: &camera_pose::CameraConfig,
    beacons: &camera_pose::BeaconLayout,
    hull: &camera_pose::HullConfig,
    pose: &camera_pose::PoseConfig,
) -> anyhow::Result<()> {
    let starts = s.start_poses();
    let mut poses: BTreeMap<&str, Isometry3<f64>> = BTreeMap::new();
    for v in &s.vehicles {
        let (p, yaw) = starts
            .get(&v.name)
            .copied()
            .with_context(|| format!("no start pose for {}", v.name))?;
        poses.insert(
            &v.name,
            Isometry3::new(Vector3::from(p), Vector3::new(0.0, 0.0, yaw)),
        );
    }
    // Which key put the vehicle where it starts.
    let start_key = |i: usize| {
        let v = &s.vehicles[i];
        if v.start_ned_m.is_some() || v.parent.is_none() {
            format!("vehicles[{i}].start_ned_m")
        } else {
            format!("vehicles[{i}].slot_m")
        }
    };
    let capsules: Vec<Capsule> = s
        .vehicles
        .iter()
        .map(|v| hull.capsule(&poses[v.name.as_str()]))
        .collect();
    for (i, v) in s.vehicles.iter().enumerate() {
        // Obstacles: sample the hull's axis; closer than the radius is an overlap.
        let c = &capsules[i];
        let closest = (0..=8)
            .filter_map(|k| field.nearest(&(c.a + (c.b - c.a) * (f64::from(k) / 8.0))))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((j, d)) = closest {
            if d < c.radius_m {
                anyhow::bail!(
                    "{}: {} starts inside obstacles[{j}] (its hull axis is {d:.2} m from the \
                     obstacle, closer than hull.radius_m = {:.2})",
                    start_key(i),
                    v.name,
                    c.radius_m
                );
            }
        }
        // Other vehicles.
        for (j, w) in s.vehicles.iter().enumerate().take(i) {
            let d = (poses[v.name.as_str()].translation.vector
                - poses[w.name.as_str()].translation.vector)
                .norm();
            if d < s.safety.safe_distance_m {
                anyhow::bail!(
                    "{}: {} starts {d:.2} m from {} (vehicles[{j}]), closer than \
                     safety.safe_distance_m = {}",
                    start_key(i),
                    v.name,
                    w.name,
                    s.safety.safe_distance_m
                );
            }
        }
    }
    if s.method.perception != Perception::Camera {
        return Ok(());
    }
    let cam = Camera::new(camera).context("camera")?;
    for (i, v) in s.vehicles.iter().enumerate() {
        let Some(parent) = &v.parent else { continue };
        let Some(pi) = s.vehicle_index(parent) else {
            continue;
        };
        let follower_pose = poses[v.name.as_str()];
        let parent_pose = poses[parent.as_str()];
        let cam_world = cam.camera_in_world(&follower_pose);
        // Every other hull may hide a beacon; the parent's own and the
        // follower's own do not (as in the camera model).
        let occluders: Vec<Capsule> = capsules
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != i && *k != pi)
            .map(|(_, c)| *c)
            .collect();
        let mut seen = 0usize;
        let mut why: Vec<String> = Vec::new();
        for b in 0..beacons.positions_body_m.len() {
            let (status, _) = cam.beacon_status(&cam_world, &parent_pose, beacons, b, &occluders);
            match status {
                BeaconStatus::Visible => seen += 1,
                other => why.push(format!("beacon {b}: {}", describe(other, camera))),
            }
        }
        if seen < pose.min_beacons {
            let key = if v.start_yaw_deg.is_some() {
                format!("vehicles[{i}].start_yaw_deg")
            } else {
                start_key(i)
            };
            anyhow::bail!(
                "{key}: the camera of {} cannot see its parent {} at the start: {seen} of {} \
                 beacons visible, pose.min_beacons = {} needed ({})",
                v.name,
                parent,
                beacons.positions_body_m.len(),
                pose.min_beacons,
                why.join("; ")
            );
        }
    }
    Ok(())
}

fn describe(status: BeaconStatus, camera: &camera_pose::CameraConfig) -> String {
    match status {
        BeaconStatus::Visible => "visible".into(),
        BeaconStatus::BehindCamera => "behind the camera".into(),
        BeaconStatus::OutsideImage => {
            format!("outside the image (camera.fov_deg = {})", camera.fov_deg)
        }
        BeaconStatus::BeyondRange => format!(
            "beyond camera.visibility_range_m = {}",
            camera.visibility_range_m
        ),
        BeaconStatus::FacingAway => "seen from outside its emission cone".into(),
        BeaconStatus::Occluded => "hidden by another hull".into(),
    }
}

/// What a run of a scenario needs from the machine, estimated from its
/// topology before anything starts (`shoal check` prints it).
///
/// The shared-memory and file-descriptor models were fitted to a measured
/// run of the paper scenario (iceoryx2 0.10, 5 vehicles, 26 processes: 72
/// services, 258 files in `/dev/shm` holding 4.0 MB, at most 307 open files
/// in one process, the recorder) and err on the high side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Needs {
    /// Processes: the service processes plus the orchestrator.
    pub processes: u64,
    /// iceoryx2 services: every vehicle channel, world, clock, done, and one
    /// wake event per process.
    pub services: u64,
    /// Bytes of `/dev/shm`: each publisher's data segment (sample size ×
    /// slots), each service's dynamic segment, each connection.
    pub shm_bytes: u64,
    /// Files in `/dev/shm`.
    pub shm_files: u64,
    /// Most file descriptors one process holds (the recorder, which opens
    /// every channel, or the orchestrator, which opens every wake event).
    pub open_files: u64,
}

/// Bytes of one publisher's data segment in iceoryx2 0.10: a slot per
/// sample that can be in flight (every subscriber's buffer plus two
/// borrowed each, the history, two loans, one spare), each the sample plus
/// 52 bytes of management, plus ~150 bytes (fitted to measured segments:
/// 448 B × 165 slots → 82 650 B; 20 528 B × 93 slots → 1 914 090 B).
fn data_segment_bytes(sample: usize, limits: &ChannelLimits) -> u64 {
    let slots = limits.max_subscribers * (limits.max_buffer + 2) + limits.history + 3;
    150 + (slots as u64) * (sample as u64 + 52)
}

/// Bytes of one service's dynamic segment (port and node tables); an upper
/// bound of the measured 2.1-5.8 KB.
fn dynamic_segment_bytes(limits: &ChannelLimits) -> u64 {
    1024 + 96 * (limits.max_publishers + limits.max_subscribers + limits.max_nodes) as u64
}

/// Bytes of one publisher→subscriber connection (measured 0.4-1 KB).
const CONNECTION_BYTES: u64 = 1024;

/// Open files of one process: a base (node, logs, libraries) plus a few per
/// service it opens (static config, port tag, dynamic segment, data
/// segment, connection). Fitted to the measured run: 8 services → 112
/// files, 47 services → 307.
fn open_files_of(services: u64) -> u64 {
    80 + 6 * services
}

/// Estimates what a run of `s` needs (see [`Needs`]).
pub fn needs(s: &Scenario) -> Needs {
    let procs = s.processes();
    let n_procs = procs.len() as u64;
    let vehicles = s.vehicles.len();
    let followers = s.vehicles.iter().filter(|v| v.parent.is_some()).count();
    let sizes = |c: ipc_types::Channel| -> usize {
        use ipc_types::Channel as C;
        match c {
            C::Truth => std::mem::size_of::<ipc_types::Truth>(),
            C::Nav => std::mem::size_of::<ipc_types::Nav>(),
            C::Thrust => std::mem::size_of::<ipc_types::Thrust>(),
            C::Sonar => std::mem::size_of::<ipc_types::Sonar>(),
            C::Beacons => std::mem::size_of::<ipc_types::Beacons>(),
            C::LeaderPose => std::mem::size_of::<ipc_types::LeaderPose>(),
            C::Setpoint => std::mem::size_of::<ipc_types::Setpoint>(),
            C::PlannerState => std::mem::size_of::<ipc_types::PlannerState>(),
            C::MpcStats => std::mem::size_of::<ipc_types::MpcStats>(),
        }
    };
    let vlim = ChannelLimits::vehicle();
    let wlim = ChannelLimits::world(vehicles);
    let clim = ChannelLimits::clock(procs.len());
    let dlim = ChannelLimits::done(procs.len());
    let wake = ChannelLimits {
        max_publishers: 2,
        max_subscribers: 2,
        max_nodes: 4,
        max_buffer: 1,
        history: 0,
    };
    let mut shm: u64 = 0;
    let mut files: u64 = 1; // the domain's global management segment
    let mut vehicle_channels: u64 = 0;
    for v in &s.vehicles {
        for c in ipc_types::Channel::ALL {
            if c.follower_only() && v.parent.is_none() {
                continue;
            }
            vehicle_channels += 1;
            shm += data_segment_bytes(sizes(c), &vlim) + dynamic_segment_bytes(&vlim);
            files += 2;
        }
    }
    // world and clock: pub-sub with a data segment each; done: an event.
    shm += data_segment_bytes(std::mem::size_of::<ipc_types::World>(), &wlim)
        + dynamic_segment_bytes(&wlim);
    shm += data_segment_bytes(std::mem::size_of::<ipc_types::Clock>(), &clim)
        + dynamic_segment_bytes(&clim);
    shm += dynamic_segment_bytes(&dlim) + 1024;
    files += 2 + 2 + 2;
    // one wake event per process: dynamic + event management segments.
    shm += n_procs * (dynamic_segment_bytes(&wake) + 1024);
    files += 2 * n_procs;
    // Connections: the recorder reads every vehicle channel; the consumers
    // of each vehicle (world ← truth; planner and mpc ← nav; plant ← thrust;
    // planner ← sonar, leader_pose; mpc ← setpoint) about seven more; every
    // camera, sonar and the recorder read the world; every process the clock.
    let sensors = (vehicles + followers) as u64;
    let connections = vehicle_channels + 7 * vehicles as u64 + sensors + 1 + n_procs;
    shm += connections * CONNECTION_BYTES;
    files += connections;
    let services = vehicle_channels + 3 + n_procs;
    let recorder_services = vehicle_channels + 4;
    let orchestrator_services = n_procs + 2;
    let world_services = vehicles as u64 + 4;
    let busiest = recorder_services
        .max(orchestrator_services)
        .max(world_services);
    debug_assert!(procs.iter().any(|p| p.kind == ProcessKind::Recorder));
    Needs {
        processes: n_procs + 1,
        services,
        shm_bytes: shm,
        shm_files: files,
        open_files: open_files_of(busiest),
    }
}

/// What the machine allows right now; `None` where there is no limit or it
/// cannot be read.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Limits {
    /// Processes that can still be started, and which limit says so.
    pub processes: Option<(u64, String)>,
    /// Free bytes in `/dev/shm` (statvfs, for an unprivileged user).
    pub shm_free_bytes: Option<u64>,
    /// Free inodes in `/dev/shm`.
    pub shm_free_files: Option<u64>,
    /// `RLIMIT_NOFILE` (soft) that the run's processes inherit.
    pub open_files: Option<u64>,
}

/// Reads the machine's limits: statvfs(`/dev/shm`), `RLIMIT_NOFILE`, and
/// for processes the least of `kernel.pid_max` / `kernel.threads-max` minus
/// the tasks alive, the pids cgroup (v1 or v2), and `RLIMIT_NPROC` minus
/// this user's processes (not for root, whom the kernel exempts).
pub fn machine_limits() -> Limits {
    let (shm_free_bytes, shm_free_files) = os::statvfs_free("/dev/shm");
    let mut procs: Option<(u64, String)> = None;
    let mut consider = |free: u64, what: String| {
        if procs.as_ref().is_none_or(|(f, _)| free < *f) {
            procs = Some((free, what));
        }
    };
    let read_u64 =
        |p: &str| -> Option<u64> { std::fs::read_to_string(p).ok()?.trim().parse().ok() };
    // Tasks alive: the 4th field of /proc/loadavg is running/total.
    let tasks = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|t| {
            t.split_whitespace()
                .nth(3)?
                .split('/')
                .nth(1)?
                .parse::<u64>()
                .ok()
        })
        .unwrap_or(0);
    for (path, what) in [
        ("/proc/sys/kernel/pid_max", "kernel.pid_max"),
        ("/proc/sys/kernel/threads-max", "kernel.threads-max"),
    ] {
        if let Some(max) = read_u64(path) {
            consider(
                max.saturating_sub(tasks),
                format!("{what} = {max} with {tasks} tasks alive"),
            );
        }
    }
    if let Some((max, current, path)) = pids_cgroup() {
        consider(
            max.saturating_sub(current),
            format!("the pids cgroup {path}: pids.max = {max}, {current} in use"),
        );
    }
    let (nproc, uid) = os::nproc_limit();
    if let (Some(max), true) = (nproc, uid != 0) {
        let mine = user_processes(uid);
        consider(
            max.saturating_sub(mine),
            format!("RLIMIT_NPROC = {max} with {mine} processes of uid {uid}"),
        );
    }
    Limits {
        processes: procs,
        shm_free_bytes,
        shm_free_files,
        open_files: os::nofile_limit(),
    }
}

/// `pids.max` and `pids.current` of this process's pids cgroup, if limited.
fn pids_cgroup() -> Option<(u64, u64, String)> {
    let text = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    for line in text.lines() {
        let mut parts = line.splitn(3, ':');
        let (_, ctrl, path) = (parts.next()?, parts.next()?, parts.next()?);
        let dir = if ctrl == "pids" {
            format!("/sys/fs/cgroup/pids{path}")
        } else if ctrl.is_empty() {
            format!("/sys/fs/cgroup{path}")
        } else {
            continue;
        };
        let max = std::fs::read_to_string(format!("{dir}/pids.max")).ok();
        let Some(max) = max.and_then(|m| m.trim().parse::<u64>().ok()) else {
            continue;
        };
        let current = std::fs::read_to_string(format!("{dir}/pids.current"))
            .ok()
            .and_then(|c| c.trim().parse::<u64>().ok())
            .unwrap_or(0);
        return Some((max, current, dir));
    }
    None
}

/// Processes owned by `uid` (entries of /proc owned by it).
fn user_processes(uid: u32) -> u64 {
    use std::os::unix::fs::MetadataExt;
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return 0;
    };
    entries
        .flatten()
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .bytes()
                .all(|b| b.is_ascii_digit())
        })
        .filter(|e| e.metadata().is_ok_and(|m| m.uid() == uid))
        .count() as u64
}

/// Refuses a run that this machine cannot hold (see [`needs`], [`machine_limits`]).
pub fn fits(n: &Needs) -> anyhow::Result<()> {
    fits_within(n, &machine_limits())
}

/// [`fits`] against given limits. The message names `vehicles` (the size
/// of the group is what drives every figure) and the limit.
pub fn fits_within(n: &Needs, l: &Limits) -> anyhow::Result<()> {
    if let Some((free, what)) = &l.processes {
        if n.processes > *free {
            anyhow::bail!(
                "vehicles: the run needs {} processes, but only {free} more can start here ({what})",
                n.processes
            );
        }
    }
    if let Some(free) = l.shm_free_bytes {
        if n.shm_bytes > free {
            anyhow::bail!(
                "vehicles: the run needs about {:.1} MiB of /dev/shm for {} iceoryx2 services, \
                 but only {:.1} MiB are free",
                n.shm_bytes as f64 / 1048576.0,
                n.services,
                free as f64 / 1048576.0
            );
        }
    }
    if let Some(free) = l.shm_free_files {
        if n.shm_files > free {
            anyhow::bail!(
                "vehicles: the run needs about {} files in /dev/shm, but only {free} inodes are free",
                n.shm_files
            );
        }
    }
    if let Some(max) = l.open_files {
        if n.open_files > max {
            anyhow::bail!(
                "vehicles: one process of the run (the recorder) needs about {} open files for \
                 {} iceoryx2 services, but RLIMIT_NOFILE is {max} (raise it with `ulimit -n`)",
                n.open_files,
                n.services
            );
        }
    }
    Ok(())
}

/// The three POSIX queries [`machine_limits`] needs, each wrapped once.
#[allow(unsafe_code)]
mod os {
    /// Free bytes and free inodes of a file system, for an unprivileged user.
    pub fn statvfs_free(path: &str) -> (Option<u64>, Option<u64>) {
        let Ok(c) = std::ffi::CString::new(path) else {
            return (None, None);
        };
        // SAFETY: an all-zero statvfs is a valid value; statvfs fills it.
        let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
        // SAFETY: a NUL-terminated path and a pointer to a local.
        if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
            return (None, None);
        }
        let bytes = (st.f_bavail as u64).saturating_mul(st.f_frsize as u64);
        // A file system without inode accounting (tmpfs with nr_inodes=0) reports 0 files.
        let files = (st.f_files != 0).then_some(st.f_favail as u64);
        (Some(bytes), files)
    }

    fn soft_limit(resource: libc::__rlimit_resource_t) -> Option<u64> {
        let mut r = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: a pointer to a local.
        if unsafe { libc::getrlimit(resource, &mut r) } != 0 || r.rlim_cur == libc::RLIM_INFINITY {
            return None;
        }
        Some(r.rlim_cur)
    }

    /// `RLIMIT_NOFILE` (soft), `None` if unlimited.
    pub fn nofile_limit() -> Option<u64> {
        soft_limit(libc::RLIMIT_NOFILE)
    }

    /// `RLIMIT_NPROC` (soft) and the effective uid.
    pub fn nproc_limit() -> (Option<u64>, u32) {
        // SAFETY: geteuid has no memory effects.
        let uid = unsafe { libc::geteuid() };
        (soft_limit(libc::RLIMIT_NPROC), uid)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    /// Measured on a live run of the paper scenario (iceoryx2 0.10, this
    /// repository's limits): 72 services in the domain, 258 files in
    /// /dev/shm holding 4 014 828 bytes, 307 open files in the recorder.
    const PAPER_SERVICES: u64 = 72;
    const PAPER_SHM_FILES: u64 = 258;
    const PAPER_SHM_BYTES: u64 = 4_014_828;
    const PAPER_RECORDER_FILES: u64 = 307;

    #[test]
    fn a_deep_tree_without_headway_is_warned_about_and_the_paper_is_not() {
        let paper = Scenario::paper().unwrap();
        assert_eq!(tree_depth(&paper), 2);
        assert!(advice(&paper).is_empty());
        // L <- F1 <- F2 <- F3: three levels
        let chain = |extra: &str| {
            let mut text = String::from("name = \"chain\"\nduration_s = 10.0\n");
            text.push_str(extra);
            text.push_str("[[vehicles]]\nname = \"L\"\n");
            for (i, parent) in ["L", "F1", "F2"].iter().enumerate() {
                text.push_str(&format!(
                    "[[vehicles]]\nname = \"F{}\"\nparent = \"{parent}\"\nslot_m = [-6.0, 0.0, 0.0]\n",
                    i + 1
                ));
            }
            Scenario::from_toml(&text).unwrap()
        };
        let bare = chain("");
        assert_eq!(tree_depth(&bare), 3);
        let said = advice(&bare);
        assert_eq!(said.len(), 1, "{said:?}");
        assert!(said[0].contains("3 levels deep"), "{said:?}");
        assert!(advice(&chain("[follower]\nheadway_s = 1.0\n")).is_empty());
    }

    #[test]
    fn paper_needs_match_a_measured_run_and_err_high() {
        let s = Scenario::paper().unwrap();
        let n = needs(&s);
        assert_eq!(n.processes, s.processes().len() as u64 + 1);
        assert_eq!(n.services, PAPER_SERVICES);
        assert!(
            (PAPER_SHM_BYTES..2 * PAPER_SHM_BYTES).contains(&n.shm_bytes),
            "{n:?}"
        );
        assert!(
            (PAPER_SHM_FILES..2 * PAPER_SHM_FILES).contains(&n.shm_files),
            "{n:?}"
        );
        assert!(
            (PAPER_RECORDER_FILES..2 * PAPER_RECORDER_FILES).contains(&n.open_files),
            "{n:?}"
        );
    }

    #[test]
    fn needs_grow_with_the_group() {
        let small = needs(&Scenario::paper().unwrap());
        let mut s = Scenario::paper().unwrap();
        let template = s.vehicles[1].clone();
        for i in 0..20 {
            let mut v = template.clone();
            v.name = format!("X{i}");
            s.vehicles.push(v);
        }
        let big = needs(&s);
        assert!(big.processes > small.processes && big.services > small.services);
        assert!(big.shm_bytes > small.shm_bytes && big.open_files > small.open_files);
    }

    #[test]
    fn each_machine_limit_refuses_and_is_named() {
        let n = needs(&Scenario::paper().unwrap());
        let roomy = Limits {
            processes: Some((n.processes, "test".into())),
            shm_free_bytes: Some(n.shm_bytes),
            shm_free_files: Some(n.shm_files),
            open_files: Some(n.open_files),
        };
        fits_within(&n, &roomy).unwrap();
        let unknown = Limits {
            processes: None,
            shm_free_bytes: None,
            shm_free_files: None,
            open_files: None,
        };
        fits_within(&n, &unknown).unwrap();
        let cases = [
            (
                Limits {
                    processes: Some((n.processes - 1, "the pids cgroup".into())),
                    ..roomy.clone()
                },
                "the pids cgroup",
            ),
            (
                Limits {
                    shm_free_bytes: Some(n.shm_bytes - 1),
                    ..roomy.clone()
                },
                "MiB of /dev/shm",
            ),
            (
                Limits {
                    shm_free_files: Some(n.shm_files - 1),
                    ..roomy.clone()
                },
                "inodes",
            ),
            (
                Limits {
                    open_files: Some(n.open_files - 1),
                    ..roomy.clone()
                },
                "RLIMIT_NOFILE",
            ),
        ];
        for (limits, word) in cases {
            let e = fits_within(&n, &limits).unwrap_err().to_string();
            assert!(e.starts_with("vehicles: ") && e.contains(word), "{e}");
        }
    }

    #[test]
    fn this_machine_reports_its_limits() {
        let l = machine_limits();
        // /dev/shm exists on every Linux machine this runs on.
        assert!(l.shm_free_bytes.is_some(), "{l:?}");
        assert!(l.processes.is_some(), "{l:?}");
    }

    /// Byte ranges of the numbers in `text` (not inside names).
    fn numbers(text: &str) -> Vec<(usize, usize)> {
        let b = text.as_bytes();
        let mut out = Vec::new();
        let mut i = 0;
        while i < b.len() {
            let starts = b[i].is_ascii_digit()
                || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit));
            let after_word = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
            if starts && !after_word {
                let mut j = i + 1;
                while j < b.len()
                    && (b[j].is_ascii_digit() || matches!(b[j], b'.' | b'e' | b'E' | b'-' | b'+'))
                {
                    j += 1;
                }
                out.push((i, j));
                i = j;
            } else {
                i += 1;
            }
        }
        out
    }

    /// The whole check (every section, the start, the formation, the
    /// machine) on the paper scenario with 1-3 of its numbers replaced by
    /// edge values, and with extra sections holding edge values: never a
    /// panic; whatever passes has finite displacements for every follower.
    #[test]
    fn resolve_never_panics_on_mutated_scenarios() {
        const EDGE: &[&str] = &[
            "nan", "inf", "-inf", "0", "-0.0", "1e308", "-1e308", "5e-324", "-1", "1", "0.5",
            "1e6", "-8.0", "30.0", "2.0", "100",
        ];
        const SECTIONS: &[&str] = &[
            "[camera]\nfov_deg = X\n",
            "[camera]\nvisibility_range_m = X\n",
            "[beacons]\nemission_half_angle_deg = X\n",
            "[hull]\nradius_m = X\n",
            "[pose]\nmin_beacons = 3\nmax_reprojection_rms_px = X\n",
            "[sonar]\nrange_max_m = X\n",
            "[mpc]\nhorizon = 5\n",
            "[plant]\nstep_s = X\n",
            "[plant.vehicle]\nmass_kg = X\n",
            "[mpc]\nstep_s = X\n",
            "[follower]\nmemory_behind_m = X\n",
            "[acoustic]\nbit_rate_bps = X\n",
            "[[obstacles]]\nkind = \"sphere\"\ncenter_ned_m = [X, 0.0, 10.0]\nradius_m = 3.0\n",
            "[[obstacles]]\nkind = \"mesh\"\nvertices_ned_m = [[0.0, 0.0, X], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\ntriangles = [[0, 1, 2]]\n",
        ];
        let paper = shoal_scenario::PAPER_TOML;
        let nums = numbers(paper);
        let mut seed: u64 = 0x5eed_1234_abcd_ef01;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let (mut cases, mut accepted) = (0, 0);
        for _ in 0..400 {
            let mut text = paper.to_string();
            let mut picks: Vec<(usize, usize, &str)> = (0..1 + rnd() % 3)
                .map(|_| {
                    let (a, b) = nums[(rnd() as usize) % nums.len()];
                    (a, b, EDGE[(rnd() as usize) % EDGE.len()])
                })
                .collect();
            picks.sort_by_key(|p| std::cmp::Reverse(p.0));
            picks.dedup_by_key(|p| p.0);
            for (a, b, e) in picks {
                text.replace_range(a..b, e);
            }
            if rnd() % 2 == 0 {
                let sec = SECTIONS[(rnd() as usize) % SECTIONS.len()];
                let val = EDGE[(rnd() as usize) % EDGE.len()];
                // Appended sections must not repeat a table the paper has.
                let head = sec.lines().next().unwrap_or("");
                if !text.contains(head) || head.starts_with("[[") {
                    text.push('\n');
                    text.push_str(&sec.replace('X', val));
                }
            }
            cases += 1;
            let Ok(mut s) = Scenario::from_toml(&text) else {
                continue;
            };
            if resolve(&mut s).is_ok() {
                accepted += 1;
                for v in s.vehicles.iter().filter(|v| v.parent.is_some()) {
                    let (a, b) = (v.d_a_m.unwrap(), v.d_b_m.unwrap());
                    assert!(
                        a.is_finite() && b.is_finite(),
                        "{}: {a} {b}\n{text}",
                        v.name
                    );
                }
            }
        }
        // The mutations reach the check, and some pass it.
        assert_eq!(cases, 400);
        assert!(accepted > 0);
        println!("resolve: {accepted} of {cases} mutated scenarios accepted");
    }

    #[test]
    fn resolve_accepts_the_paper_and_fills_every_displacement() {
        let mut s = Scenario::paper().unwrap();
        resolve(&mut s).unwrap();
        for v in s.vehicles.iter().filter(|v| v.parent.is_some()) {
            assert!(v.d_a_m.is_some() && v.d_b_m.is_some(), "{}", v.name);
        }
    }
}
