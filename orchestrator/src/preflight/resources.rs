//! What a run needs from the machine (processes, shared memory, files)
//! against what the machine allows right now.

use shoal_runtime::domain::ChannelLimits;
use shoal_scenario::{ProcessKind, Scenario};

use crate::launch::os;

/// What a run of a scenario needs from the machine, estimated from its
/// topology before anything starts (`shoal check` prints it).
///
/// The shared-memory and file-descriptor models were fitted to measured
/// runs of the paper scenario (iceoryx2 0.10, 5 vehicles, 26 processes: 48
/// services, 4.8 MB of shared memory, at most 316 open files in one
/// process, the recorder; 237 shared-memory files and 569 entries below the
/// domain's root, both in `/dev/shm`) and err on the high side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Needs {
    /// Processes: the service processes plus the orchestrator.
    pub processes: u64,
    /// iceoryx2 services: every vehicle channel, world, clock, done, events
    /// and stats.
    pub services: u64,
    /// Bytes of `/dev/shm`: each publisher's data segment (sample size ×
    /// slots), each service's dynamic segment, each connection.
    pub shm_bytes: u64,
    /// Files in `/dev/shm`: shared-memory segments, and the node, port and
    /// service files and directories of the domain's root below
    /// `/dev/shm/shoal`.
    pub shm_files: u64,
    /// Most file descriptors one process holds (the recorder, which opens
    /// every channel).
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
    let vlim = ChannelLimits::vehicle();
    let wlim = ChannelLimits::world(vehicles);
    let clim = ChannelLimits::clock(procs.len());
    let dlim = ChannelLimits::done(procs.len());
    let mut shm: u64 = 0;
    let mut files: u64 = 1; // the domain's global management segment
    let mut vehicle_channels: u64 = 0;
    for v in &s.vehicles {
        for c in ipc_types::Channel::ALL {
            if c.follower_only() && v.parent.is_none() {
                continue;
            }
            vehicle_channels += 1;
            shm += data_segment_bytes(c.sample_size(), &vlim) + dynamic_segment_bytes(&vlim);
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
    // events (one publisher) and stats (one publisher per process): a data
    // segment each, a dynamic segment per service; the lockstep doorbell.
    let elim = ChannelLimits::events();
    let slim = shoal_runtime::stats::stats_limits(procs.len());
    shm += data_segment_bytes(std::mem::size_of::<ipc_types::Event>(), &elim)
        + dynamic_segment_bytes(&elim);
    shm += n_procs * data_segment_bytes(std::mem::size_of::<ipc_types::ProcessStats>(), &slim)
        + dynamic_segment_bytes(&slim);
    files += 1 + n_procs + 2 + 1;
    // Connections: the recorder reads every vehicle channel; the consumers
    // of each vehicle (world ← truth; planner and mpc ← nav; plant ← thrust;
    // planner ← sonar, leader_pose; mpc ← setpoint) about seven more; every
    // camera, sonar and the recorder read the world. The clock has no
    // reader in the run (a process takes its tick from the doorbell).
    let sensors = (vehicles + followers) as u64;
    let connections = vehicle_channels + 12 * vehicles as u64 + sensors + 2;
    shm += connections * CONNECTION_BYTES;
    files += connections;
    let services = vehicle_channels + 5;
    // The domain's root: a static file per service; per process a node
    // directory with its details and monitoring entries (the recorder has
    // a second node, for reading stats); the socket of `done`; a service
    // tag and a port tag per port (every publisher, subscriber, notifier
    // and listener; 214 of each measured).
    let ports = connections + vehicle_channels + 2 * n_procs + 4;
    files += 4 + services + 1 + 5 * (n_procs + 2) + 2 * ports;
    let recorder_services = vehicle_channels + 4;
    let orchestrator_services = 4;
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
    if let Some((max, current, path)) = os::pids_cgroup() {
        consider(
            max.saturating_sub(current),
            format!("the pids cgroup {path}: pids.max = {max}, {current} in use"),
        );
    }
    let (nproc, uid) = os::nproc_limit();
    if let (Some(max), true) = (nproc, uid != 0) {
        let mine = os::user_processes(uid);
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

/// Recording bytes per vehicle per simulated second, measured: the paper
/// scenario (five vehicles, point camera model) records 1.07 MB in 20 s.
const RECORDING_BYTES_PER_VEHICLE_S: f64 = 10_700.0;
/// With the image camera model, per follower per simulated second, on top
/// (its frames): the paper's image run records 10.57 MB in 20 s.
const RECORDING_IMAGE_BYTES_PER_FOLLOWER_S: f64 = 119_000.0;
/// Room left over the measured rates (other courses, more events).
const RECORDING_MARGIN: f64 = 1.25;

/// The recording a run of `s` is expected to write, bytes.
pub fn expected_recording_bytes(s: &shoal_scenario::Scenario) -> u64 {
    let vehicles = s.vehicles.len() as f64;
    let followers = s.vehicles.iter().filter(|v| v.parent.is_some()).count() as f64;
    let images = if s.camera_model() == shoal_scenario::CameraModel::Image {
        followers * RECORDING_IMAGE_BYTES_PER_FOLLOWER_S
    } else {
        0.0
    };
    ((vehicles * RECORDING_BYTES_PER_VEHICLE_S + images) * s.duration_s * RECORDING_MARGIN) as u64
}

/// Free bytes on the disk that holds `dir`, or would hold it (its nearest
/// existing ancestor).
pub fn free_bytes_at(dir: &std::path::Path) -> Option<u64> {
    let abs = if dir.is_absolute() {
        dir.to_path_buf()
    } else {
        std::env::current_dir().ok()?.join(dir)
    };
    let existing = abs.ancestors().find(|a| a.exists())?;
    os::statvfs_free(existing.to_str()?).0
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    /// Measured on a live run of the paper scenario (iceoryx2 0.10, this
    /// repository's limits; lockstep, no process reading the clock): 48
    /// services in the domain, 4 788 530 bytes of shared memory (806 KB of
    /// it the 26 stats publishers' segments), 316 open files in the
    /// recorder; 237 shared-memory files and 569 entries below the domain's
    /// root in /dev/shm.
    const PAPER_SERVICES: u64 = 48;
    const PAPER_SHM_FILES: u64 = 237 + 569;
    const PAPER_SHM_BYTES: u64 = 4_788_530;
    const PAPER_RECORDER_FILES: u64 = 316;

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
}
