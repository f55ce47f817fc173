//! A run's iceoryx2 domain: its own file prefix and root directory, the
//! limits of each of its services, and the removal of everything it left.
//!
//! Two runs on one machine never see each other: each has its own prefix
//! (`shoal_<run-id>_`) for the shared-memory files in `/dev/shm` and its own
//! root directory `/dev/shm/shoal/<run-id>/` for node and service files, and
//! every service name contains the run id.

use std::path::{Path, PathBuf};

use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, SemanticString};
use iceoryx2_bb_system_types::path::Path as IoxPath;

/// The directory that holds every run's root directory.
///
/// It is on the tmpfs that holds iceoryx2's shared memory, not below
/// `/tmp`: a run of the paper scenario creates and removes some 800 node,
/// port and service files there, and where `/tmp` is ext4 each creation
/// scans the inode table for recently deleted inodes (`recently_deleted`),
/// which grows with every run made before. Measured with `shoal run` of the
/// paper scenario cut to 0.1 s (start and stop alone): 0.51 to 1.07 s of
/// CPU with the roots on ext4, 0.29 to 0.35 s on tmpfs.
pub const DOMAINS_DIR: &str = "/dev/shm/shoal";

/// Where a run's iceoryx2 files live besides its shared memory (node,
/// port and service files, event sockets): `/dev/shm/shoal/<run-id>/`.
pub fn domain_root(run_id: &str) -> PathBuf {
    PathBuf::from(format!("{DOMAINS_DIR}/{run_id}/"))
}

/// The shared-memory file prefix of a run.
pub fn domain_prefix(run_id: &str) -> String {
    format!("shoal_{run_id}_")
}

/// Expired connections each subscriber keeps (iceoryx2's
/// `subscriber_expired_connection_buffer`): connections of publishers that
/// left while the subscriber still had samples of theirs queued or
/// borrowed, kept until those are read or returned.
///
/// iceoryx2 keeps 128 by default, and every subscriber builds the slot map
/// for them (and for its live connections) when it is created, written
/// whole: about 3.6 KB a slot, 464 KiB a subscriber. That was two thirds
/// of a run's private memory (`shoal bench scale`: 389 MiB at N = 25,
/// 1,583 MiB at N = 100) and most of the start-up's page zeroing. A shoal
/// subscriber reads its queue at every step, and every service has at most
/// two publishers (a process and its restarted successor) except `stats`,
/// whose reader asks for more ([`iceoryx_config_keeping`]); four is that
/// with room to spare.
pub const EXPIRED_CONNECTIONS: usize = 4;

/// The iceoryx2 configuration of a run's domain: [`iceoryx_config_keeping`]
/// with [`EXPIRED_CONNECTIONS`].
pub fn iceoryx_config(run_id: &str) -> Config {
    iceoryx_config_keeping(run_id, EXPIRED_CONNECTIONS)
}

/// The iceoryx2 configuration of a run's domain, whose subscribers keep up
/// to `expired_connections` connections of publishers that left (see
/// [`EXPIRED_CONNECTIONS`]).
///
/// iceoryx2 by default looks for dead nodes whenever a node is created or
/// dropped and whenever a service is opened. Each look lists every node of
/// the domain and reads each one's files, so starting N processes that each
/// open O(1) services costs O(N²): at 100 vehicles (500 processes) that scan
/// was half the start-up CPU. A shoal run does not need it. The orchestrator
/// owns every process, reaps each one with `wait4`, and calls
/// `try_cleanup_dead_nodes` itself when one dies (the restart policy), and
/// whatever a crashed run leaves is removed by the stale-domain sweep.
pub fn iceoryx_config_keeping(run_id: &str, expired_connections: usize) -> Config {
    let mut config = Config::default();
    config
        .defaults
        .publish_subscribe
        .subscriber_expired_connection_buffer = expired_connections;
    config.global.node.cleanup_dead_nodes_on_creation = false;
    config.global.node.cleanup_dead_nodes_on_destruction = false;
    config.global.service.cleanup_dead_nodes_on_open = false;
    if let Ok(prefix) = FileName::new(domain_prefix(run_id).as_bytes()) {
        config.global.prefix = prefix;
    }
    if let Ok(root) = IoxPath::new(domain_root(run_id).to_string_lossy().as_bytes()) {
        config.global.set_root_path(&root);
    }
    config
}

/// Every file the run's domain holds right now: shared memory in `/dev/shm`
/// with the run's prefix, and everything below its root directory.
pub fn list_domain_files(run_id: &str) -> Vec<PathBuf> {
    let prefix = domain_prefix(run_id);
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir("/dev/shm") {
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().starts_with(&prefix) {
                out.push(e.path());
            }
        }
    }
    walk(&domain_root(run_id), &mut out);
    out
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else {
                out.push(p);
            }
        }
    }
}

/// Removes every file of the run's domain. Call it only when no process of
/// the run is alive. Returns how many files were removed.
pub fn cleanup_domain(run_id: &str) -> usize {
    let files = list_domain_files(run_id);
    let mut removed = 0;
    for f in &files {
        if std::fs::remove_file(f).is_ok() {
            removed += 1;
        }
    }
    let _ = std::fs::remove_dir_all(domain_root(run_id));
    removed
}

/// The file in a run's root that names the process owning the run.
const OWNER_FILE: &str = "owner.pid";

/// The file in a run's root that says its orchestrator has ended and left
/// the domain to outside nodes ([`release_domain`]).
const RELEASED_FILE: &str = "released";

/// Marks `pid` (the orchestrator) as the owner of the run's domain, so a
/// later run can tell a dead run's leftovers from a live run's files.
pub fn claim_domain(run_id: &str, pid: u32) -> std::io::Result<()> {
    let root = domain_root(run_id);
    std::fs::create_dir_all(&root)?;
    std::fs::write(root.join(OWNER_FILE), pid.to_string())
}

/// True when a process with this pid exists.
fn alive(pid: i32) -> bool {
    // SAFETY: kill with signal 0 only checks that the pid exists and may be signalled.
    #[allow(unsafe_code)]
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
}

/// The nodes in a run's domain that are not known dead, by name: after the
/// run's own processes have ended, outside clients (a Python reader, a
/// replay). A node still starting, one of another user, or a domain that
/// cannot be listed counts as in use: nothing is removed from under it.
pub fn alive_nodes(run_id: &str) -> Vec<String> {
    use iceoryx2::node::{NodeState, NodeView as _};
    use iceoryx2::prelude::{ipc, CallbackProgression, Node};
    let mut out = Vec::new();
    let listed = Node::<ipc::Service>::list(&iceoryx_config(run_id), |state| {
        match state {
            NodeState::Alive(view) => out.push(
                view.details()
                    .as_ref()
                    .map_or_else(|| "?".to_string(), |d| d.name().to_string()),
            ),
            NodeState::Dead(_) => {}
            NodeState::Inaccessible(_) => out.push("(another user's node)".to_string()),
            NodeState::Undefined(_) => out.push("(a node starting)".to_string()),
        }
        CallbackProgression::Continue
    });
    if listed.is_err() && domain_root(run_id).exists() {
        out.push("(the domain could not be listed)".to_string());
    }
    out.sort();
    out
}

/// What ending a run did to its domain.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Release {
    /// Every file removed (how many).
    Removed(usize),
    /// Outside nodes still use it (their names): the run's own files are
    /// removed; iceoryx2 removes each service with its last user, and the
    /// next run's stale sweep removes what remains once they have left
    /// (or crashed).
    LeftTo(Vec<String>),
}

/// Ends a run's hold on its domain, once its own processes are gone: all of
/// it when no node is alive; otherwise only the run's bookkeeping (the
/// owner file, the statistics files), so that a client still attached
/// sees its services end cleanly instead of vanish under it.
pub fn release_domain(run_id: &str) -> Release {
    let alive = alive_nodes(run_id);
    if alive.is_empty() {
        return Release::Removed(cleanup_domain(run_id));
    }
    let root = domain_root(run_id);
    let _ = std::fs::write(root.join(RELEASED_FILE), "");
    let _ = std::fs::remove_file(root.join(OWNER_FILE));
    let _ = std::fs::remove_dir_all(root.join("stats"));
    Release::LeftTo(alive)
}

/// Runs whose owner (the orchestrator that claimed them) is dead, or that
/// no owner holds any more (released to outside clients, or half made,
/// for over a minute), and in which no node is alive: their domain files
/// are leftovers of a crash.
pub fn stale_domains() -> Vec<String> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(DOMAINS_DIR) else {
        return out;
    };
    for e in entries.flatten() {
        let Some(run_id) = e.file_name().to_str().map(str::to_string) else {
            continue;
        };
        let owner = std::fs::read_to_string(e.path().join(OWNER_FILE))
            .ok()
            .and_then(|s| s.trim().parse::<i32>().ok());
        let released = e.path().join(RELEASED_FILE).exists();
        let unowned = match owner {
            Some(pid) => pid > 0 && !alive(pid),
            None if released => true,
            None => e
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > std::time::Duration::from_secs(60)),
        };
        if unowned && alive_nodes(&run_id).is_empty() {
            out.push(run_id);
        }
    }
    out.sort();
    out
}

/// Removes the domain files of every run whose owner is dead; returns
/// `(run id, files removed)` for each.
pub fn sweep_stale_domains() -> Vec<(String, usize)> {
    stale_domains()
        .into_iter()
        .map(|id| {
            let n = cleanup_domain(&id);
            (id, n)
        })
        .collect()
}

/// Limits of one iceoryx2 service. Every process that opens a service must
/// ask for the same limits, so they are computed here from the run's size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelLimits {
    /// Most publishers (notifiers for events).
    pub max_publishers: usize,
    /// Most subscribers (listeners for events).
    pub max_subscribers: usize,
    /// Most nodes that may open the service.
    pub max_nodes: usize,
    /// Largest subscriber buffer.
    pub max_buffer: usize,
    /// Samples kept for late joiners.
    pub history: usize,
}

/// Subscribers reserved on every service for outside clients (a Python
/// reader, `shoal replay`, tests).
pub const SPARE_SUBSCRIBERS: usize = 4;

/// Events kept on the `events` channel for late joiners.
pub const EVENTS_HISTORY: usize = 16;

/// Subscriber buffer of the recorder: it drains once per lockstep frame or
/// realtime wake-up, so it must hold everything a publisher sends meanwhile.
pub const RECORDER_BUFFER: usize = 16;

impl ChannelLimits {
    /// A per-vehicle channel: one publisher, a handful of readers, the recorder.
    pub fn vehicle() -> Self {
        let subs = 4 + 1 + SPARE_SUBSCRIBERS;
        Self {
            max_publishers: 2,
            max_subscribers: subs,
            max_nodes: subs + 2,
            max_buffer: RECORDER_BUFFER,
            history: 1,
        }
    }

    /// A follower's camera frames: camera-pose and the recorder read them;
    /// small buffers, since every chunk is a whole frame. No history: a
    /// reader that joins late (a restarted camera-pose) waits for the next
    /// frame, as a camera's reader does, and a send need not retain the
    /// last frame for late joiners (about 6 % of a polled in-place hop in
    /// `shoal bench ipc`).
    pub fn image() -> Self {
        let subs = 2 + SPARE_SUBSCRIBERS;
        Self {
            max_publishers: 2,
            max_subscribers: subs,
            max_nodes: subs + 2,
            max_buffer: 2,
            history: 0,
        }
    }

    /// The world snapshot: read by every camera and sonar, and the recorder.
    pub fn world(vehicles: usize) -> Self {
        let subs = 2 * vehicles + 1 + SPARE_SUBSCRIBERS;
        Self {
            max_publishers: 2,
            max_subscribers: subs,
            max_nodes: subs + 2,
            max_buffer: 4,
            history: 1,
        }
    }

    /// The lockstep clock: read by every process.
    pub fn clock(processes: usize) -> Self {
        let subs = processes + SPARE_SUBSCRIBERS;
        Self {
            max_publishers: 1,
            max_subscribers: subs,
            max_nodes: subs + 1,
            max_buffer: 2,
            history: 1,
        }
    }

    /// The run's `events`: the orchestrator publishes, the recorder (and
    /// outside clients) read; the last 16 are kept for a reader that joins
    /// late (a restarted recorder records the death that restarted it).
    pub fn events() -> Self {
        let subs = 1 + SPARE_SUBSCRIBERS;
        Self {
            max_publishers: 1,
            max_subscribers: subs,
            max_nodes: subs + 2,
            max_buffer: EVENTS_HISTORY,
            history: EVENTS_HISTORY,
        }
    }

    /// The `done` event: one notifier per process, the orchestrator listens.
    pub fn done(processes: usize) -> Self {
        Self {
            max_publishers: processes + 1,
            max_subscribers: 2,
            max_nodes: processes + 2,
            max_buffer: 1,
            history: 0,
        }
    }
}
