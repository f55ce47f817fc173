//! `summary.json`: the run's metrics as one typed [`Summary`], computed from
//! ground truth in the recording (not from what the vehicles believe) and
//! from the processes' own statistics. Every consumer (the closing table,
//! `shoal compare`, the benches, the tests) reads its fields; a new metric is
//! one field here.

use std::collections::BTreeMap;
use std::path::Path;

use recordings::Recording;
use serde::{Deserialize, Serialize};
use shoal_runtime::latency::LatencySummary;
use shoal_scenario::Scenario;

use super::formation::Passage;
use super::metrics::{
    chain, end_to_end, formation, mission, mpc, perception, runtime_stats, safety, verdict,
};
use super::track::Tracks;
use crate::launch::RunOutcome;

/// Version of `summary.json`'s layout; raised when a field changes meaning
/// or goes away (not when one is added).
pub const SCHEMA_VERSION: u32 = 3;
/// The window at the end of a run that `formation.slot_error_rms_final_m`
/// covers, s.
pub const FINAL_WINDOW_S: f64 = 30.0;

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
    /// Whether every safety figure passed, and which did not.
    pub verdict: Verdict,
    /// The run stopped before its scenario's end (Ctrl-C, a kill): the
    /// figures cover the part that ran, and the verdict is a fail.
    #[serde(default)]
    pub partial: bool,
}

/// Pass or fail, from the safety figures: no collision of either kind, no
/// pair closer than the safe distance, no vehicle's centre closer to an
/// obstacle than half the safe distance, no follower without its parent
/// for longer than [`PARENT_LOST_LIMIT_S`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// Every safety figure passed.
    pub pass: bool,
    /// What failed, one line each (empty on a pass).
    pub failed: Vec<String>,
}

/// Longest a follower may go without a fix of its parent, s.
pub const PARENT_LOST_LIMIT_S: f64 = 5.0;

/// A stretch of time in which something held for one vehicle.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Stretch {
    /// The vehicle.
    pub vehicle: String,
    /// Start, s.
    pub from_s: f64,
    /// End, s.
    pub to_s: f64,
    /// The extreme value over it (closest approach for a contact), m.
    pub extreme_m: Option<f64>,
}

/// Distances between vehicles and to obstacles, from truth.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Safety {
    /// Smallest centre-to-centre distance of any pair, m (none with < 2 vehicles).
    pub min_pair_distance_m: Option<f64>,
    /// The pair it was, `A-B`.
    pub min_pair: String,
    /// The scenario's safe distance, m (also the planners' D_min).
    pub safe_distance_m: f64,
    /// The scenario's collision distance between two vehicles' centres, m.
    pub collision_distance_m: f64,
    /// Pairs that came closer than the collision distance.
    pub collisions: usize,
    /// Vehicles whose hull touched an obstacle (centre closer to it than
    /// half the collision distance), with when and how close.
    pub obstacle_contacts: Vec<Stretch>,
    /// The smallest obstacle clearance is below the planners' D_min (the
    /// safe distance): a warning; the verdict needs half of it.
    pub clearance_below_d_min: bool,
    /// Smallest centre-to-obstacle distance of any vehicle, m.
    pub min_obstacle_clearance_m: Option<f64>,
    /// Each vehicle's smallest distance to an obstacle, m (empty without
    /// obstacles).
    pub obstacle_clearance_m: BTreeMap<String, f64>,
    /// Vehicles of the scenario without a single truth sample in the
    /// recording: nothing of their safety can be judged, so the verdict
    /// fails (a run whose vehicles never moved is not a pass).
    #[serde(default)]
    pub without_truth: Vec<String>,
}

/// Slot errors, from truth: `|p − (p_parent + R_parent·slot)|`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Formation {
    /// RMS over every follower, before, during and after the passage, m.
    pub slot_error_rms_m: PhaseRms,
    /// Largest after the passage, m.
    pub slot_error_max_after_m: Option<f64>,
    /// RMS over every follower in the last [`FINAL_WINDOW_S`] of the run, m:
    /// generated courses end well past their last obstacle and the run
    /// well after the leader stops, so this is the formation re-formed
    /// after the course (and any creep after the stop).
    pub slot_error_rms_final_m: Option<f64>,
    /// RMS per follower over the run, m.
    pub slot_error_rms_m_by_follower: BTreeMap<String, Rms>,
    /// RMS per level of the formation tree (1 = the leader's followers), m.
    pub slot_error_rms_m_by_level: BTreeMap<String, f64>,
    /// First and last avoiding sample of any follower, s.
    pub passage_s: Option<[f64; 2]>,
}

/// An RMS before, during and after the passage; `null` for a part of the
/// run that did not happen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseRms {
    /// Before the first follower avoided (the whole run without a passage).
    pub before: Option<f64>,
    /// From then until 20 s after the last avoided.
    pub during: Option<f64>,
    /// After that.
    pub after: Option<f64>,
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
    /// Followers without a fix of their parent for longer than
    /// [`PARENT_LOST_LIMIT_S`], with when.
    pub parent_lost: Vec<Stretch>,
    /// Longest time between two valid fixes of its parent, per follower
    /// (from its first camera frame to its last), s.
    pub longest_parent_gap_s: BTreeMap<String, f64>,
    /// Farthest each follower's camera got from its parent, m.
    pub parent_range_max_m: BTreeMap<String, f64>,
    /// Followers whose camera got beyond the visibility range.
    pub beyond_visibility: Vec<String>,
    /// Error of the fixes against truth (parent in the follower's body frame), m.
    pub pose_error_m: Percentiles95,
}

/// Median and 95th percentile (`null` without samples).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Percentiles95 {
    /// Median.
    pub p50: Option<f64>,
    /// 95th percentile.
    pub p95: Option<f64>,
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
    /// The end-to-end figure split by stage of the chain, in order
    /// (`analysis::metrics::CHAIN_STAGES`): every vehicle's chains merged.
    #[serde(default)]
    pub chain: Vec<ChainStage>,
    /// Camera frame (the `world` snapshot the sensors saw) → thrust applied:
    /// the chain without its first stage, per chain.
    #[serde(default)]
    pub frame_to_thrust: LatencySummary,
}

/// One stage of the sensor → thrust chain: from the previous stage's output
/// to its own, µs.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ChainStage {
    /// `world`, `perception`, `planner`, `mpc` or `sim-plant` (thrust applied).
    pub stage: String,
    /// Its latency over every chain.
    #[serde(flatten)]
    pub us: LatencySummary,
}

/// The predictive controllers.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MpcFigures {
    /// Solve time over every vehicle, µs.
    pub solve_us: SolveTimes,
    /// Failed solves, summed over vehicles.
    pub failures: u64,
    /// Control steps that published a solve (`mpc_stats` samples), summed over vehicles.
    #[serde(default)]
    pub solves: u64,
    /// Of those, the steps whose unconstrained minimiser was within every bound (the
    /// exact solution without clarabel, status 2); the rest went to clarabel.
    #[serde(default)]
    pub unconstrained: u64,
    /// Of those, the steps solved with the safety layer's clearances in the QP (status 3:
    /// something sensed would otherwise have been entered, or a bound was active near it).
    #[serde(default)]
    pub guarded: u64,
    /// Solve time of the guarded steps, µs.
    #[serde(default)]
    pub guarded_solve_us: SolveTimes,
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

    /// Writes it as pretty JSON, every number at most
    /// [`SIGNIFICANT_DIGITS`] significant digits ([`tidy_json`]).
    pub fn write(&self, path: &Path) -> Result<(), SummaryError> {
        let text = tidy_json_text(self).map_err(|source| SummaryError::Parse {
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

/// Significant digits a written figure keeps: beyond them a sum of
/// binary fractions only shows its rounding noise (`118.46000000000001`).
pub const SIGNIFICANT_DIGITS: usize = 12;

/// Rounds every float of `v` to [`SIGNIFICANT_DIGITS`] significant digits
/// (shortest form), in place.
pub fn tidy_json(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Number(n) if n.is_f64() => {
            if let Some(x) = n.as_f64() {
                let digits = SIGNIFICANT_DIGITS - 1;
                let rounded: f64 = format!("{x:.digits$e}").parse().unwrap_or(x);
                if let Some(r) = serde_json::Number::from_f64(rounded) {
                    *n = r;
                }
            }
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(tidy_json),
        serde_json::Value::Object(m) => m.values_mut().for_each(tidy_json),
        _ => {}
    }
}

/// `value` as pretty JSON with its floats tidied ([`tidy_json`]).
pub fn tidy_json_text<T: Serialize>(value: &T) -> Result<String, serde_json::Error> {
    let mut v = serde_json::to_value(value)?;
    tidy_json(&mut v);
    serde_json::to_string_pretty(&v)
}

/// A figure as a table shows it: `digits` decimals, or `n/a` where it does
/// not exist.
pub fn fmt_or_na(x: Option<f64>, digits: usize) -> String {
    x.filter(|v| v.is_finite())
        .map_or_else(|| "n/a".to_string(), |v| format!("{v:.digits$}"))
}

/// The smallest value of a per-vehicle map.
pub fn min_value(m: &BTreeMap<String, f64>) -> Option<f64> {
    m.values().copied().min_by(f64::total_cmp)
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
    let (chain_stages, frame_to_thrust) = chain(scenario, rec);
    let mut s = Summary {
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
            chain: chain_stages,
            frame_to_thrust,
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
        verdict: Verdict::default(),
        partial: false,
    };
    s.verdict = verdict(&s);
    s
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn written_figures_carry_no_float_noise() {
        let mut v = serde_json::json!({
            "a": 118.46000000000001,
            "b": [199.98000000000002, 1e-7, 3],
            "c": {"d": 0.1 + 0.2, "e": "x", "f": 2.0},
        });
        tidy_json(&mut v);
        let text = v.to_string();
        assert!(
            text.contains("118.46,") || text.contains("118.46}"),
            "{text}"
        );
        assert!(text.contains("199.98,"), "{text}");
        assert!(text.contains("0.3,") || text.contains("0.3}"), "{text}");
        assert_eq!(v["b"][2], 3);
        assert_eq!(v["b"][1].as_f64(), Some(1e-7));
        // A summary survives the round trip.
        let s = Summary {
            sim_time_s: 199.98000000000002,
            ..Default::default()
        };
        let back: Summary = serde_json::from_str(&tidy_json_text(&s).unwrap()).unwrap();
        assert_eq!(back.sim_time_s, 199.98);
    }
}
