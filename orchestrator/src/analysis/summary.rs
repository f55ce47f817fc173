//! `summary.json`: the run's metrics as one typed [`Summary`], computed from
//! ground truth in the recording (not from what the vehicles believe) and
//! from the processes' own statistics. Every consumer (the closing table,
//! `shoal compare`, the benches, the tests) reads its fields; a new metric is
//! one field here.

use std::collections::BTreeMap;
use std::path::Path;

use ipc_types::{Channel, LeaderPose, MpcStats, Truth};
use nalgebra::{Point3, Vector3};
use recordings::Recording;
use serde::{Deserialize, Serialize};
use shoal_runtime::latency::LatencySummary;
use shoal_runtime::LatencyRecorder;
use shoal_scenario::Scenario;

use super::formation::{slot_errors, Passage, Phase};
use super::track::Tracks;
use crate::launch::RunOutcome;

/// Version of `summary.json`'s layout; raised when a field changes meaning
/// or goes away (not when one is added).
pub const SCHEMA_VERSION: u32 = 1;

/// What `summary.json` holds.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// [`SCHEMA_VERSION`] of the writer.
    pub schema_version: u32,
    /// Scenario name.
    pub scenario: String,
    /// `lockstep` or `realtime`.
    pub mode: String,
    /// Seed of every random generator.
    pub seed: u64,
    /// Simulated time, s.
    pub sim_time_s: f64,
    /// Wall time of the run proper (first tick to last), s.
    pub wall_time_s: f64,
    /// Simulated s per wall s (0 if no wall time passed).
    pub real_time_factor: f64,
    /// Vehicles in the group.
    pub vehicles: usize,
    /// Processes spawned.
    pub processes: usize,
    /// Run id (names the iceoryx2 domain).
    pub run_id: String,
    /// Lockstep ticks driven.
    pub ticks: u64,
    /// CPU time by process kind (the orchestrator's own included), s.
    pub cpu_time_s: BTreeMap<String, f64>,
    /// Peak RSS by process kind (largest single process), KiB.
    pub max_rss_kib: BTreeMap<String, i64>,
    /// Distances between vehicles and to obstacles.
    pub safety: Safety,
    /// Slot errors.
    pub formation: Formation,
    /// What the followers saw of their parents.
    pub perception: Perception,
    /// The leader's mission.
    pub mission: Mission,
    /// Publish → take per channel kind and sensor → thrust, µs.
    pub latency_us: Latency,
    /// Realtime deadline misses per process kind.
    pub deadline_misses: BTreeMap<String, u64>,
    /// Step duration per process kind, µs.
    pub step_us: BTreeMap<String, LatencySummary>,
    /// Realtime wake-up lateness per process kind, µs.
    pub wake_late_us: BTreeMap<String, LatencySummary>,
    /// Injected faults, deaths, restarts and ends of gaps, in order.
    pub events: Vec<serde_json::Value>,
    /// Samples lost per input channel kind.
    pub samples_lost: BTreeMap<String, u64>,
    /// Samples rejected (non-finite) per input channel kind.
    pub samples_rejected: BTreeMap<String, u64>,
    /// The predictive controllers.
    pub mpc: MpcFigures,
    /// The recording.
    pub recording: RecordingFigures,
}

/// Distances between vehicles and to obstacles, from truth.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Safety {
    /// Smallest centre-to-centre distance of any pair, m (none with < 2 vehicles).
    pub min_pair_distance_m: Option<f64>,
    /// The pair it was, `A-B`.
    pub min_pair: String,
    /// The scenario's safe distance, m.
    pub safe_distance_m: f64,
    /// Pairs that came closer than the collision distance.
    pub collisions: usize,
    /// Smallest centre-to-obstacle distance of any vehicle, m.
    pub min_obstacle_clearance_m: Option<f64>,
    /// Each vehicle's smallest distance to an obstacle, m (empty without
    /// obstacles).
    pub obstacle_clearance_m: BTreeMap<String, f64>,
}

/// Slot errors, from truth: `|p − (p_parent + R_parent·slot)|`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Formation {
    /// RMS over every follower, before, during and after the passage, m.
    pub slot_error_rms_m: PhaseRms,
    /// Largest after the passage, m.
    pub slot_error_max_after_m: f64,
    /// RMS per follower over the run, m.
    pub slot_error_rms_m_by_follower: BTreeMap<String, Rms>,
    /// RMS per level of the formation tree (1 = the leader's followers), m.
    pub slot_error_rms_m_by_level: BTreeMap<String, f64>,
    /// First and last avoiding sample of any follower, s.
    pub passage_s: Option<[f64; 2]>,
}

/// An RMS before, during and after the passage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseRms {
    /// Before the first follower avoided (the whole run without a passage).
    pub before: f64,
    /// From then until 20 s after the last avoided.
    pub during: f64,
    /// After that.
    pub after: f64,
}

/// One RMS.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Rms {
    /// Root mean square, m.
    pub rms: f64,
}

/// What the followers saw of their parents.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Perception {
    /// Share of each follower's `leader_pose` samples that carry a fix.
    pub leader_visible_fraction: BTreeMap<String, f64>,
    /// The same within the passage window.
    pub parent_visible_fraction_in_passage: BTreeMap<String, f64>,
    /// Fixes per simulated second.
    pub parent_fix_rate_hz: BTreeMap<String, f64>,
    /// The camera's visibility range, m.
    pub visibility_range_m: f64,
    /// Farthest each follower's camera got from its parent, m.
    pub parent_range_max_m: BTreeMap<String, f64>,
    /// Followers whose camera got beyond the visibility range.
    pub beyond_visibility: Vec<String>,
    /// Error of the fixes against truth (parent in the follower's body frame), m.
    pub pose_error_m: Percentiles95,
}

/// Median and 95th percentile.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Percentiles95 {
    /// Median.
    pub p50: f64,
    /// 95th percentile.
    pub p95: f64,
}

/// The leader's mission.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Mission {
    /// The leader's distance to its last waypoint at the end, m.
    pub leader_goal_error_m: Option<f64>,
}

/// Latencies, µs.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Latency {
    /// Sensor event → thrust applied by sim-plant (truth stamps).
    pub end_to_end: LatencySummary,
    /// Publish → take per input channel kind, every taker merged.
    pub hops: BTreeMap<String, LatencySummary>,
}

/// The predictive controllers.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MpcFigures {
    /// Solve time over every vehicle, µs.
    pub solve_us: SolveTimes,
    /// Failed solves, summed over vehicles.
    pub failures: u64,
}

/// Solve-time percentiles, µs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SolveTimes {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

/// The recording as the recorder reported it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RecordingFigures {
    /// Path of `recording.mcap`.
    pub path: String,
    /// Messages written.
    pub messages: u64,
    /// Messages dropped (the recorder fell behind).
    pub dropped: u64,
    /// Samples rejected (non-finite).
    pub rejected: u64,
    /// The file was cut short.
    pub truncated: bool,
}

/// Why a summary could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum SummaryError {
    /// The file could not be read or written.
    #[error("cannot {op} {path}")]
    Io {
        /// `read` or `write`.
        op: &'static str,
        /// The file.
        path: String,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a summary of this layout.
    #[error("{path} is not a shoal summary.json (schema {SCHEMA_VERSION})")]
    Parse {
        /// The file.
        path: String,
        /// The cause.
        #[source]
        source: serde_json::Error,
    },
}

impl Summary {
    /// Reads `summary.json`.
    pub fn read(path: &Path) -> Result<Self, SummaryError> {
        let text = std::fs::read_to_string(path).map_err(|source| SummaryError::Io {
            op: "read",
            path: path.display().to_string(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| SummaryError::Parse {
            path: path.display().to_string(),
            source,
        })
    }

    /// Writes it as pretty JSON.
    pub fn write(&self, path: &Path) -> Result<(), SummaryError> {
        let text = serde_json::to_string_pretty(self).map_err(|source| SummaryError::Parse {
            path: path.display().to_string(),
            source,
        })?;
        std::fs::write(path, text).map_err(|source| SummaryError::Io {
            op: "write",
            path: path.display().to_string(),
            source,
        })
    }

    /// The smallest fraction of frames with a fix of any follower.
    pub fn min_parent_visible(&self) -> Option<f64> {
        min_value(&self.perception.leader_visible_fraction)
    }

    /// The farthest any follower's camera got from its parent, m.
    pub fn max_parent_range_m(&self) -> Option<f64> {
        self.perception
            .parent_range_max_m
            .values()
            .copied()
            .max_by(f64::total_cmp)
    }
}

/// The smallest value of a per-vehicle map.
pub fn min_value(m: &BTreeMap<String, f64>) -> Option<f64> {
    m.values().copied().min_by(f64::total_cmp)
}

/// Percentile of a sorted slice (nearest rank); 0 for none.
fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Root mean square; 0 for none.
fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// Builds the summary of a finished run.
pub fn summarize(
    scenario: &Scenario,
    rec: &Recording,
    outcome: &RunOutcome,
    mode: &str,
) -> Summary {
    let tracks = Tracks::load(scenario, rec);
    let passage = Passage::load(scenario, rec);
    let runtime = runtime_stats(&outcome.stats);
    let meta = rec.metadata().get("shoal.recorder");
    let get = |k: &str| -> u64 {
        meta.and_then(|m| m.get(k))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    Summary {
        schema_version: SCHEMA_VERSION,
        scenario: scenario.name.clone(),
        mode: mode.to_string(),
        seed: scenario.seed,
        sim_time_s: outcome.sim_time_s,
        wall_time_s: outcome.wall_time_s,
        real_time_factor: if outcome.wall_time_s > 0.0 {
            outcome.sim_time_s / outcome.wall_time_s
        } else {
            0.0
        },
        vehicles: scenario.vehicles.len(),
        processes: outcome.processes,
        run_id: outcome.run_id.clone(),
        ticks: outcome.ticks,
        cpu_time_s: outcome.cpu_time_s.clone(),
        max_rss_kib: outcome.max_rss_kib.clone(),
        safety: safety(scenario, &tracks),
        formation: formation(scenario, &tracks, &passage),
        perception: perception(scenario, rec, &tracks, &passage, outcome.sim_time_s),
        mission: mission(scenario, &tracks),
        latency_us: Latency {
            end_to_end: end_to_end(scenario, rec),
            hops: runtime.hops,
        },
        deadline_misses: runtime.deadline_misses,
        step_us: runtime.step_us,
        wake_late_us: runtime.wake_late_us,
        events: outcome.events.clone(),
        samples_lost: runtime.lost,
        samples_rejected: runtime.rejected,
        mpc: mpc(scenario, rec),
        recording: RecordingFigures {
            path: outcome.recording.display().to_string(),
            messages: get("messages"),
            dropped: get("dropped"),
            rejected: get("rejected"),
            truncated: rec.truncated(),
        },
    }
}

/// Pairwise distances over the first vehicle's sample times, and each
/// vehicle's distance to the obstacles.
pub fn safety(scenario: &Scenario, tracks: &Tracks) -> Safety {
    let ts = &tracks.tracks;
    let mut min_pair = f64::INFINITY;
    let mut min_pair_names = String::new();
    let mut collided = std::collections::BTreeSet::new();
    if let Some(first) = ts.first() {
        for &t in &first.t_ns {
            for i in 0..ts.len() {
                for j in i + 1..ts.len() {
                    let (Some((pa, _)), Some((pb, _))) = (ts[i].at(t), ts[j].at(t)) else {
                        continue;
                    };
                    let d = (pa - pb).norm();
                    if d < min_pair {
                        min_pair = d;
                        min_pair_names = format!("{}-{}", ts[i].name, ts[j].name);
                    }
                    if d < scenario.safety.collision_distance_m {
                        collided.insert((i, j));
                    }
                }
            }
        }
    }
    let obstacles: Vec<sonar::Obstacle> = scenario.obstacles_as().unwrap_or_default();
    let field = sonar::ObstacleField::new(&obstacles).ok();
    let mut min_clear = f64::INFINITY;
    let mut clearance = BTreeMap::new();
    if let Some(field) = &field {
        for t in ts {
            let m =
                t.p.iter()
                    .map(|p| field.distance(&Point3::from(*p)))
                    .fold(f64::INFINITY, f64::min);
            if !obstacles.is_empty() {
                clearance.insert(t.name.clone(), m);
            }
            min_clear = min_clear.min(m);
        }
    }
    Safety {
        min_pair_distance_m: finite(min_pair),
        min_pair: min_pair_names,
        safe_distance_m: scenario.safety.safe_distance_m,
        collisions: collided.len(),
        min_obstacle_clearance_m: finite(min_clear),
        obstacle_clearance_m: clearance,
    }
}

/// Slot errors split by the passage, per follower and per tree level.
pub fn formation(scenario: &Scenario, tracks: &Tracks, passage: &Passage) -> Formation {
    let (mut before, mut during, mut after) = (Vec::new(), Vec::new(), Vec::new());
    let mut per_follower = BTreeMap::new();
    let levels = scenario.levels();
    let mut by_level: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
    for v in &scenario.vehicles {
        let (Some(parent), Some(slot)) = (&v.parent, v.slot_m) else {
            continue;
        };
        let (Some(tf), Some(tp)) = (tracks.get(&v.name), tracks.get(parent)) else {
            continue;
        };
        let errs = slot_errors(tf, tp, slot);
        for &(t, e) in &errs {
            match passage.phase(t) {
                Phase::Before => before.push(e),
                Phase::During => during.push(e),
                Phase::After => after.push(e),
            }
        }
        let errs: Vec<f64> = errs.into_iter().map(|(_, e)| e).collect();
        per_follower.insert(v.name.clone(), Rms { rms: rms(&errs) });
        by_level
            .entry(levels.get(&v.name).copied().unwrap_or(0))
            .or_default()
            .extend(errs);
    }
    Formation {
        slot_error_rms_m: PhaseRms {
            before: rms(&before),
            during: rms(&during),
            after: rms(&after),
        },
        slot_error_max_after_m: after.iter().copied().fold(0.0, f64::max),
        slot_error_rms_m_by_follower: per_follower,
        slot_error_rms_m_by_level: by_level
            .iter()
            .map(|(l, e)| (l.to_string(), rms(e)))
            .collect(),
        passage_s: passage
            .window_ns()
            .map(|(a, b)| [a as f64 * 1e-9, b as f64 * 1e-9]),
    }
}

/// Fraction of camera frames with a valid pose; pose error against the
/// truth at the frame's time; how far each follower's camera got from its
/// parent (the visibility limit of the perception rule).
pub fn perception(
    scenario: &Scenario,
    rec: &Recording,
    tracks: &Tracks,
    passage: &Passage,
    sim_time_s: f64,
) -> Perception {
    let camera: camera_pose::CameraConfig = scenario.section("camera").unwrap_or_default();
    let mount = Vector3::from(camera.mount_position_body_m);
    let mut out = Perception {
        leader_visible_fraction: BTreeMap::new(),
        parent_visible_fraction_in_passage: BTreeMap::new(),
        parent_fix_rate_hz: BTreeMap::new(),
        visibility_range_m: camera.visibility_range_m,
        parent_range_max_m: BTreeMap::new(),
        beyond_visibility: Vec::new(),
        pose_error_m: Percentiles95 { p50: 0.0, p95: 0.0 },
    };
    let mut pose_err = Vec::new();
    for v in &scenario.vehicles {
        let Some(parent) = &v.parent else { continue };
        let (Some(tf), Some(tp)) = (tracks.get(&v.name), tracks.get(parent)) else {
            continue;
        };
        let poses = rec.samples::<LeaderPose>(&ipc_types::topic(&v.name, Channel::LeaderPose));
        let valid = poses.iter().filter(|p| p.valid != 0).count();
        let frac = if poses.is_empty() {
            0.0
        } else {
            valid as f64 / poses.len() as f64
        };
        out.leader_visible_fraction.insert(v.name.clone(), frac);
        if sim_time_s > 0.0 {
            out.parent_fix_rate_hz
                .insert(v.name.clone(), valid as f64 / sim_time_s);
        }
        if let Some((first, last)) = passage.window_ns() {
            let inside: Vec<_> = poses
                .iter()
                .filter(|p| (first..=last).contains(&p.header.sim_time_ns))
                .collect();
            let seen = inside.iter().filter(|p| p.valid != 0).count();
            if !inside.is_empty() {
                out.parent_visible_fraction_in_passage
                    .insert(v.name.clone(), seen as f64 / inside.len() as f64);
            }
        }
        let mut far = 0.0f64;
        for (i, &t) in tf.t_ns.iter().enumerate() {
            if let Some((pp, _)) = tp.at(t) {
                far = far.max((pp - (tf.p[i] + tf.q[i] * mount)).norm());
            }
        }
        out.parent_range_max_m.insert(v.name.clone(), far);
        if far > camera.visibility_range_m {
            out.beyond_visibility.push(v.name.clone());
        }
        for p in poses.iter().filter(|p| p.valid != 0) {
            let t = p.header.origin_sim_time_ns;
            if let (Some(i), Some(j)) = (tf.latest(t), tp.latest(t)) {
                let truth_body = tf.q[i].inverse() * (tp.p[j] - tf.p[i]);
                pose_err.push((truth_body - Vector3::from(p.parent_position_body_m)).norm());
            }
        }
    }
    pose_err.sort_by(f64::total_cmp);
    out.pose_error_m = Percentiles95 {
        p50: pct(&pose_err, 0.5),
        p95: pct(&pose_err, 0.95),
    };
    out
}

/// The leader's distance to its last waypoint at the end.
pub fn mission(scenario: &Scenario, tracks: &Tracks) -> Mission {
    let goal = scenario
        .mission
        .get("waypoints_ned_m")
        .and_then(|w| w.as_array())
        .and_then(|w| w.last())
        .and_then(|w| w.as_array())
        .and_then(|w| {
            let v: Vec<f64> = w
                .iter()
                .filter_map(|x| x.as_float().or(x.as_integer().map(|i| i as f64)))
                .collect();
            (v.len() == 3).then(|| Vector3::new(v[0], v[1], v[2]))
        });
    let last = tracks
        .get(&scenario.leader().name)
        .and_then(|t| t.p.last().copied());
    Mission {
        leader_goal_error_m: match (goal, last) {
            (Some(g), Some(p)) => finite((g - p).norm()),
            _ => None,
        },
    }
}

/// Sensor event → thrust applied by sim-plant, from the truth stamps.
fn end_to_end(scenario: &Scenario, rec: &Recording) -> LatencySummary {
    let mut e2e = LatencyRecorder::new();
    for v in &scenario.vehicles {
        let mut last_origin = 0;
        for s in rec.samples::<Truth>(&ipc_types::topic(&v.name, Channel::Truth)) {
            if s.thrust_origin_mono_ns != 0 && s.thrust_origin_mono_ns != last_origin {
                e2e.record_ns(
                    s.thrust_applied_mono_ns
                        .saturating_sub(s.thrust_origin_mono_ns),
                );
                last_origin = s.thrust_origin_mono_ns;
            }
        }
    }
    e2e.summary()
}

/// Solve times and failures of every vehicle's MPC.
fn mpc(scenario: &Scenario, rec: &Recording) -> MpcFigures {
    let mut solve = Vec::new();
    let mut failures = 0u64;
    for v in &scenario.vehicles {
        let stats = rec.samples::<MpcStats>(&ipc_types::topic(&v.name, Channel::MpcStats));
        solve.extend(stats.iter().map(|s| s.solve_ns as f64 / 1e3));
        failures += stats.last().map_or(0, |s| s.failures);
    }
    solve.sort_by(f64::total_cmp);
    MpcFigures {
        solve_us: SolveTimes {
            p50: pct(&solve, 0.5),
            p99: pct(&solve, 0.99),
            max: solve.last().copied().unwrap_or(0.0),
        },
        failures,
    }
}

/// The processes' runtime statistics, merged.
struct RuntimeStats {
    hops: BTreeMap<String, LatencySummary>,
    deadline_misses: BTreeMap<String, u64>,
    step_us: BTreeMap<String, LatencySummary>,
    wake_late_us: BTreeMap<String, LatencySummary>,
    lost: BTreeMap<String, u64>,
    rejected: BTreeMap<String, u64>,
}

/// Merges the exit files' histograms: per input channel kind for the hops,
/// per process kind for steps, wake-ups and deadline misses.
fn runtime_stats(files: &[shoal_runtime::stats::StatsFile]) -> RuntimeStats {
    let mut hops: BTreeMap<String, LatencyRecorder> = BTreeMap::new();
    let mut lost: BTreeMap<String, u64> = BTreeMap::new();
    let mut rejected: BTreeMap<String, u64> = BTreeMap::new();
    let mut steps: BTreeMap<String, LatencyRecorder> = BTreeMap::new();
    let mut late: BTreeMap<String, LatencyRecorder> = BTreeMap::new();
    let mut misses: BTreeMap<String, u64> = BTreeMap::new();
    for f in files {
        for h in &f.hops {
            hops.entry(h.kind.clone())
                .or_default()
                .add_buckets(&h.latency_ns);
            *lost.entry(h.kind.clone()).or_default() += h.lost;
            *rejected.entry(h.kind.clone()).or_default() += h.rejected;
        }
        steps
            .entry(f.process.clone())
            .or_default()
            .add_buckets(&f.step_ns);
        if !f.wake_late_ns.is_empty() {
            late.entry(f.process.clone())
                .or_default()
                .add_buckets(&f.wake_late_ns);
        }
        *misses.entry(f.process.clone()).or_default() += f.deadline_misses;
    }
    let table = |m: BTreeMap<String, LatencyRecorder>| -> BTreeMap<String, LatencySummary> {
        m.into_iter().map(|(k, r)| (k, r.summary())).collect()
    };
    RuntimeStats {
        hops: table(hops),
        deadline_misses: misses,
        step_us: table(steps),
        wake_late_us: table(late),
        lost,
        rejected,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::track::{Track, MAX_GAP_NS};
    use ipc_types::Sample;

    /// A leader, F1 8 m astern and 4 m to port of it, F2 10 m astern and
    /// 4 m to starboard of F1; a wall 20 m ahead of the leader's start.
    const SCENARIO: &str = r#"
name = "summary-test"
duration_s = 10.0

[safety]
safe_distance_m = 2.0
collision_distance_m = 1.0

[[vehicles]]
name = "L"
start_ned_m = [0.0, 0.0, 10.0]

[[vehicles]]
name = "F1"
parent = "L"
slot_m = [-8.0, -4.0, 0.0]
start_ned_m = [-8.0, -4.0, 10.0]

[[vehicles]]
name = "F2"
parent = "F1"
slot_m = [-10.0, 4.0, 0.0]
start_ned_m = [-18.0, 0.0, 10.0]

[[obstacles]]
kind = "box"
center_ned_m = [25.0, 0.0, 10.0]
half_extents_m = [5.0, 20.0, 5.0]
yaw_deg = 0.0
"#;

    fn scenario() -> Scenario {
        Scenario::from_toml(SCENARIO).expect("the test scenario is valid")
    }

    const S: u64 = 1_000_000_000;

    /// A track through `(t s, [n, e, d])` points, facing north.
    fn track(name: &str, pts: &[(f64, [f64; 3])]) -> Track {
        let truths: Vec<Truth> = pts
            .iter()
            .map(|&(t, p)| {
                let mut s = <Truth as Sample>::zeroed();
                s.header.sim_time_ns = (t * 1e9).round() as u64;
                s.position_ned_m = p;
                s.q_body_to_ned_wxyz = [1.0, 0.0, 0.0, 0.0];
                s
            })
            .collect();
        Track::from_truths(name, &truths)
    }

    /// Every vehicle on its slot, moving north at 1 m/s for 10 s, sampled
    /// every 0.1 s.
    fn on_slots() -> Vec<Track> {
        let times: Vec<f64> = (0..=100).map(|k| k as f64 * 0.1).collect();
        let at = |off: [f64; 3]| -> Vec<(f64, [f64; 3])> {
            times
                .iter()
                .map(|&t| (t, [t + off[0], off[1], 10.0 + off[2]]))
                .collect()
        };
        vec![
            track("L", &at([0.0; 3])),
            track("F1", &at([-8.0, -4.0, 0.0])),
            track("F2", &at([-18.0, 0.0, 0.0])),
        ]
    }

    #[test]
    fn a_pair_crossing_at_a_known_distance() {
        let sc = scenario();
        let mut ts = on_slots();
        // F2 crosses the leader's path 0.5 m below it: north at 2 m/s from
        // 10 m behind, so it passes the leader at t = 10 s.
        ts[2] = track(
            "F2",
            &(0..=100)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    (t, [-10.0 + 2.0 * t, 0.0, 10.5])
                })
                .collect::<Vec<_>>(),
        );
        let s = safety(&sc, &Tracks::new(ts));
        approx::assert_relative_eq!(s.min_pair_distance_m.unwrap_or(0.0), 0.5, epsilon = 1e-9);
        assert_eq!(s.min_pair, "L-F2");
        assert_eq!(s.collisions, 1, "closer than the 1 m collision distance");
        assert_eq!(s.safe_distance_m, 2.0);
    }

    #[test]
    fn clearance_is_the_distance_to_the_nearest_face() {
        let s = safety(&scenario(), &Tracks::new(on_slots()));
        // The leader ends at 10 m north, the wall's face is at 20 m.
        approx::assert_relative_eq!(s.obstacle_clearance_m["L"], 10.0, epsilon = 1e-9);
        approx::assert_relative_eq!(
            s.min_obstacle_clearance_m.unwrap_or(0.0),
            10.0,
            epsilon = 1e-9
        );
        assert_eq!(s.collisions, 0);
        assert_eq!(s.min_pair, "L-F1");
        approx::assert_relative_eq!(
            s.min_pair_distance_m.unwrap_or(0.0),
            80f64.sqrt(),
            epsilon = 1e-9
        );
    }

    #[test]
    fn a_follower_off_its_slot_by_a_known_amount_and_its_level() {
        let sc = scenario();
        let mut ts = on_slots();
        // F2's slot is 10 m astern and 4 m to starboard of F1: (−18, 0); put
        // it 3 m east and 4 m deep of it.
        ts[2] = track(
            "F2",
            &(0..=100)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    (t, [t - 18.0, 3.0, 14.0])
                })
                .collect::<Vec<_>>(),
        );
        let f = formation(&sc, &Tracks::new(ts), &Passage::default());
        approx::assert_relative_eq!(
            f.slot_error_rms_m_by_follower["F1"].rms,
            0.0,
            epsilon = 1e-9
        );
        approx::assert_relative_eq!(
            f.slot_error_rms_m_by_follower["F2"].rms,
            5.0,
            epsilon = 1e-9
        );
        approx::assert_relative_eq!(f.slot_error_rms_m_by_level["1"], 0.0, epsilon = 1e-9);
        approx::assert_relative_eq!(f.slot_error_rms_m_by_level["2"], 5.0, epsilon = 1e-9);
        // Without a passage everything is "before".
        approx::assert_relative_eq!(
            f.slot_error_rms_m.before,
            (25.0f64 / 2.0).sqrt(),
            epsilon = 1e-9
        );
        assert_eq!(f.slot_error_rms_m.during, 0.0);
        assert_eq!(f.passage_s, None);
    }

    #[test]
    fn the_passage_splits_the_slot_error() {
        let sc = scenario();
        let mut ts = on_slots();
        // F1 1 m off its slot from t = 5 s on.
        ts[1] = track(
            "F1",
            &(0..=100)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    let off = if k >= 50 { 1.0 } else { 0.0 };
                    (t, [t - 8.0, -4.0 + off, 10.0])
                })
                .collect::<Vec<_>>(),
        );
        // F1 avoided from 5 s to 6 s: "during" runs to 26 s, past the end.
        let passage = Passage::from_followers([(0..=100)
            .map(|k| (k * S / 10, (50..=60).contains(&k)))
            .collect()]);
        let f = formation(&sc, &Tracks::new(ts), &passage);
        assert_eq!(f.passage_s, Some([5.0, 6.0]));
        assert_eq!(f.slot_error_rms_m.after, 0.0);
        // F1 is 1 m off its slot during the passage, and so is F2: its slot
        // hangs on F1, which is where F2 is not.
        approx::assert_relative_eq!(f.slot_error_rms_m.during, 1.0, epsilon = 1e-9);
        approx::assert_relative_eq!(f.slot_error_rms_m.before, 0.0, epsilon = 1e-9);
    }

    #[test]
    fn a_gap_in_the_data_is_not_bridged() {
        let sc = scenario();
        let mut ts = on_slots();
        // The leader's truth stops for 2 s in the middle, during which F1
        // is 10 m off: those samples have no parent pose and do not count.
        ts[0] = track(
            "L",
            &(0..=100)
                .filter(|k| !(40..60).contains(k))
                .map(|k| {
                    let t = k as f64 * 0.1;
                    (t, [t, 0.0, 10.0])
                })
                .collect::<Vec<_>>(),
        );
        ts[1] = track(
            "F1",
            &(0..=100)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    let off = if (43..57).contains(&k) { 10.0 } else { 0.0 };
                    (t, [t - 8.0, -4.0 + off, 10.0])
                })
                .collect::<Vec<_>>(),
        );
        const { assert!(2 * S > MAX_GAP_NS) };
        let tracks = Tracks::new(ts);
        let f = formation(&sc, &tracks, &Passage::default());
        approx::assert_relative_eq!(
            f.slot_error_rms_m_by_follower["F1"].rms,
            0.0,
            epsilon = 1e-9
        );
        let s = safety(&sc, &tracks);
        assert!(s.min_pair_distance_m.is_some());
    }

    #[test]
    fn the_goal_error_is_missing_without_waypoints_and_a_summary_reads_back() {
        let sc = scenario();
        let tracks = Tracks::new(on_slots());
        assert_eq!(mission(&sc, &tracks).leader_goal_error_m, None);
        let mut with_goal = sc.clone();
        with_goal.mission.insert(
            "waypoints_ned_m".into(),
            toml::Value::Array(vec![toml::Value::Array(vec![
                toml::Value::Float(13.0),
                toml::Value::Float(4.0),
                toml::Value::Float(10.0),
            ])]),
        );
        let goal = mission(&with_goal, &tracks).leader_goal_error_m;
        approx::assert_relative_eq!(goal.unwrap_or(0.0), 5.0, epsilon = 1e-9);
    }
}
