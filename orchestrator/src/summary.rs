//! `summary.json`: the run's metrics, computed from ground truth in the
//! recording (not from what the vehicles believe).

use std::collections::BTreeMap;

use nalgebra::{Point3, UnitQuaternion, Vector3};
use recordings::Recording;
use serde_json::{json, Map, Value};
use shoal_scenario::Scenario;

use crate::run::RunOutcome;

/// Percentile of a sorted slice (nearest rank).
fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// One vehicle's true trajectory, indexed by simulation time (ns).
struct Track {
    t: Vec<u64>,
    p: Vec<Vector3<f64>>,
    q: Vec<UnitQuaternion<f64>>,
}

/// Largest gap across which a position is interpolated, ns.
const MAX_GAP_NS: u64 = 250_000_000;

impl Track {
    /// Position and attitude at `t`: the sample stamped `t` (lockstep: every
    /// plant steps on the same ticks), else interpolated between the samples
    /// around it when they are at most [`MAX_GAP_NS`] apart (realtime: each
    /// plant stamps its own wake-up time). The attitude is the nearer one's.
    fn at(&self, t: u64) -> Option<(Vector3<f64>, UnitQuaternion<f64>)> {
        match self.t.binary_search(&t) {
            Ok(i) => Some((self.p[i], self.q[i])),
            Err(0) => None,
            Err(i) if i == self.t.len() => None,
            Err(i) => {
                let (t0, t1) = (self.t[i - 1], self.t[i]);
                if t1 - t0 > MAX_GAP_NS {
                    return None;
                }
                let a = (t - t0) as f64 / (t1 - t0) as f64;
                let q = if a < 0.5 { self.q[i - 1] } else { self.q[i] };
                Some((self.p[i - 1] + (self.p[i] - self.p[i - 1]) * a, q))
            }
        }
    }
    /// The last sample at or before `t`.
    fn before(&self, t: u64) -> Option<usize> {
        match self.t.binary_search(&t) {
            Ok(i) => Some(i),
            Err(0) => None,
            Err(i) => Some(i - 1),
        }
    }
}

/// Builds summary.json.
pub fn summarize(scenario: &Scenario, rec: &Recording, outcome: &RunOutcome, mode: &str) -> Value {
    let names: Vec<String> = scenario.vehicles.iter().map(|v| v.name.clone()).collect();
    let mut tracks: BTreeMap<String, Track> = BTreeMap::new();
    for n in &names {
        let truths = rec.samples::<ipc_types::Truth>(&format!("/{n}/truth"));
        tracks.insert(
            n.clone(),
            Track {
                t: truths.iter().map(|s| s.header.sim_time_ns).collect(),
                p: truths
                    .iter()
                    .map(|s| Vector3::from(s.position_ned_m))
                    .collect(),
                q: truths.iter().map(|s| quat(s.q_body_to_ned_wxyz)).collect(),
            },
        );
    }

    // Safety: pairwise distances over every common sample time.
    let mut min_pair = f64::INFINITY;
    let mut min_pair_names = String::new();
    let mut collided: BTreeMap<String, bool> = BTreeMap::new();
    if let Some(first) = names.first().and_then(|n| tracks.get(n)) {
        for &t in &first.t {
            for i in 0..names.len() {
                for j in i + 1..names.len() {
                    let (a, b) = (&tracks[&names[i]], &tracks[&names[j]]);
                    if let (Some((pa, _)), Some((pb, _))) = (a.at(t), b.at(t)) {
                        let d = (pa - pb).norm();
                        if d < min_pair {
                            min_pair = d;
                            min_pair_names = format!("{}-{}", names[i], names[j]);
                        }
                        if d < scenario.safety.collision_distance_m {
                            collided.insert(format!("{}-{}", names[i], names[j]), true);
                        }
                    }
                }
            }
        }
    }
    let obstacles: Vec<sonar::Obstacle> = scenario.obstacles_as().unwrap_or_default();
    let field = sonar::ObstacleField::new(&obstacles).ok();
    let mut min_clear = f64::INFINITY;
    let mut clearance: Map<String, Value> = Map::new();
    if let Some(field) = &field {
        for n in &names {
            let mut m = f64::INFINITY;
            for p in &tracks[n].p {
                m = m.min(field.distance(&Point3::from(*p)));
            }
            if !obstacles.is_empty() {
                clearance.insert(n.clone(), json!(m));
            }
            min_clear = min_clear.min(m);
        }
    }

    // Formation: slot error of each follower from truth, split by the time
    // any follower was shifting for an obstacle (planner_state.avoiding).
    let mut avoid_first = u64::MAX;
    let mut avoid_last = 0u64;
    for v in scenario.vehicles.iter().filter(|v| v.parent.is_some()) {
        for s in rec.samples::<ipc_types::PlannerState>(&format!("/{}/planner_state", v.name)) {
            if s.avoiding != 0 {
                avoid_first = avoid_first.min(s.header.sim_time_ns);
                avoid_last = avoid_last.max(s.header.sim_time_ns);
            }
        }
    }
    let settle_ns = 20_000_000_000u64;
    let mut before = Vec::new();
    let mut during = Vec::new();
    let mut after = Vec::new();
    let mut per_follower: Map<String, Value> = Map::new();
    // by level in the tree: how a tracking error grows from parent to child
    let levels = scenario.levels();
    let mut by_level: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
    for v in scenario.vehicles.iter() {
        let (Some(parent), Some(slot)) = (&v.parent, v.slot_m) else {
            continue;
        };
        let (tf, tp) = (&tracks[&v.name], &tracks[parent]);
        let mut errs = Vec::new();
        for (i, &t) in tf.t.iter().enumerate() {
            let Some((pp, qp)) = tp.at(t) else { continue };
            let target = pp + qp * Vector3::from(slot);
            let e = (tf.p[i] - target).norm();
            errs.push(e);
            if t < avoid_first {
                before.push(e);
            } else if t <= avoid_last.saturating_add(settle_ns) {
                during.push(e);
            } else {
                after.push(e);
            }
        }
        per_follower.insert(v.name.clone(), json!({ "rms": rms(&errs) }));
        by_level
            .entry(levels.get(&v.name).copied().unwrap_or(0))
            .or_default()
            .extend(errs);
    }
    let by_level: Map<String, Value> = by_level
        .iter()
        .map(|(level, errs)| (level.to_string(), json!(rms(errs))))
        .collect();
    let after_max = after.iter().copied().fold(0.0, f64::max);

    // Perception: fraction of camera frames with a valid pose; pose error
    // against the truth at the frame's time; how far each follower's camera
    // got from its parent (the visibility limit of the perception rule).
    let camera: camera_pose::CameraConfig = scenario.section("camera").unwrap_or_default();
    let mount = Vector3::from(camera.mount_position_body_m);
    let mut range_max: Map<String, Value> = Map::new();
    let mut beyond: Vec<String> = Vec::new();
    let mut visible: Map<String, Value> = Map::new();
    let mut visible_passage: Map<String, Value> = Map::new();
    let mut fix_rate: Map<String, Value> = Map::new();
    let mut pose_err = Vec::new();
    for v in scenario.vehicles.iter() {
        let Some(parent) = &v.parent else { continue };
        let poses = rec.samples::<ipc_types::LeaderPose>(&format!("/{}/leader_pose", v.name));
        let valid = poses.iter().filter(|p| p.valid != 0).count();
        let frac = if poses.is_empty() {
            0.0
        } else {
            valid as f64 / poses.len() as f64
        };
        visible.insert(v.name.clone(), json!(frac));
        if outcome.sim_time_s > 0.0 {
            fix_rate.insert(v.name.clone(), json!(valid as f64 / outcome.sim_time_s));
        }
        if avoid_first != u64::MAX {
            let inside: Vec<_> = poses
                .iter()
                .filter(|p| (avoid_first..=avoid_last).contains(&p.header.sim_time_ns))
                .collect();
            let seen = inside.iter().filter(|p| p.valid != 0).count();
            if !inside.is_empty() {
                visible_passage.insert(v.name.clone(), json!(seen as f64 / inside.len() as f64));
            }
        }
        let (tf, tp) = (&tracks[&v.name], &tracks[parent]);
        let mut far = 0.0f64;
        for (i, &t) in tf.t.iter().enumerate() {
            if let Some((pp, _)) = tp.at(t) {
                far = far.max((pp - (tf.p[i] + tf.q[i] * mount)).norm());
            }
        }
        range_max.insert(v.name.clone(), json!(far));
        if far > camera.visibility_range_m {
            beyond.push(v.name.clone());
        }
        for p in poses.iter().filter(|p| p.valid != 0) {
            let t = p.header.origin_sim_time_ns;
            if let (Some(i), Some(j)) = (tf.before(t), tp.before(t)) {
                let truth_body = tf.q[i].inverse() * (tp.p[j] - tf.p[i]);
                pose_err.push((truth_body - Vector3::from(p.parent_position_body_m)).norm());
            }
        }
    }
    pose_err.sort_by(f64::total_cmp);

    // Mission: the leader's distance to its last waypoint at the end.
    let leader = scenario.leader().name.clone();
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
    let goal_err = match (goal, tracks[&leader].p.last()) {
        (Some(g), Some(p)) => (g - p).norm(),
        _ => f64::NAN,
    };

    // Latency: sensor event → thrust applied by sim-plant, from truth stamps.
    let mut e2e = shoal_runtime::LatencyRecorder::new();
    for n in &names {
        let truths = rec.samples::<ipc_types::Truth>(&format!("/{n}/truth"));
        let mut last_origin = 0;
        for s in truths {
            if s.thrust_origin_mono_ns != 0 && s.thrust_origin_mono_ns != last_origin {
                e2e.record_ns(
                    s.thrust_applied_mono_ns
                        .saturating_sub(s.thrust_origin_mono_ns),
                );
                last_origin = s.thrust_origin_mono_ns;
            }
        }
    }
    let e2e = e2e.summary();
    let runtime = runtime_stats(&outcome.stats);

    // MPC.
    let mut solve = Vec::new();
    let mut failures = 0u64;
    for n in &names {
        let stats = rec.samples::<ipc_types::MpcStats>(&format!("/{n}/mpc_stats"));
        solve.extend(stats.iter().map(|s| s.solve_ns as f64 / 1e3));
        failures += stats.last().map_or(0, |s| s.failures);
    }
    solve.sort_by(f64::total_cmp);

    let meta = rec.metadata().get("shoal.recorder");
    let get = |k: &str| -> u64 {
        meta.and_then(|m| m.get(k))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    let finite = |x: f64| if x.is_finite() { json!(x) } else { Value::Null };

    json!({
        "scenario": scenario.name,
        "mode": mode,
        "seed": scenario.seed,
        "sim_time_s": outcome.sim_time_s,
        "wall_time_s": outcome.wall_time_s,
        "real_time_factor": if outcome.wall_time_s > 0.0 { outcome.sim_time_s / outcome.wall_time_s } else { 0.0 },
        "vehicles": names.len(),
        "processes": outcome.processes,
        "run_id": outcome.run_id,
        "ticks": outcome.ticks,
        "cpu_time_s": outcome.cpu_time_s,
        "max_rss_kib": outcome.max_rss_kib,
        "safety": {
            "min_pair_distance_m": finite(min_pair),
            "min_pair": min_pair_names,
            "safe_distance_m": scenario.safety.safe_distance_m,
            "collisions": collided.len(),
            "min_obstacle_clearance_m": finite(min_clear),
            "obstacle_clearance_m": clearance,
        },
        "formation": {
            "slot_error_rms_m": { "before": rms(&before), "during": rms(&during), "after": rms(&after) },
            "slot_error_max_after_m": after_max,
            "slot_error_rms_m_by_follower": per_follower,
            "slot_error_rms_m_by_level": by_level,
            "passage_s": if avoid_first == u64::MAX { Value::Null } else { json!([avoid_first as f64 * 1e-9, avoid_last as f64 * 1e-9]) },
        },
        "perception": {
            "leader_visible_fraction": visible,
            "parent_visible_fraction_in_passage": visible_passage,
            "parent_fix_rate_hz": fix_rate,
            "visibility_range_m": camera.visibility_range_m,
            "parent_range_max_m": range_max,
            "beyond_visibility": beyond,
            "pose_error_m": { "p50": pct(&pose_err, 0.5), "p95": pct(&pose_err, 0.95) },
        },
        "mission": { "leader_goal_error_m": finite(goal_err) },
        "latency_us": {
            "end_to_end": e2e,
            "hops": runtime.hops,
        },
        "deadline_misses": runtime.deadline_misses,
        "step_us": runtime.step_us,
        "wake_late_us": runtime.wake_late_us,
        "events": outcome.events,
        "samples_lost": runtime.lost,
        "samples_rejected": runtime.rejected,
        "mpc": {
            "solve_us": { "p50": pct(&solve, 0.5), "p99": pct(&solve, 0.99), "max": solve.last().copied().unwrap_or(0.0) },
            "failures": failures,
        },
        "recording": {
            "path": outcome.recording.display().to_string(),
            "messages": get("messages"),
            "dropped": get("dropped"),
            "rejected": get("rejected"),
            "truncated": rec.truncated(),
        },
    })
}

/// The processes' runtime statistics, merged.
struct RuntimeStats {
    /// Publish → take latency per input channel kind, every taker merged.
    hops: Value,
    /// Realtime deadline misses per process kind.
    deadline_misses: Value,
    /// Step duration per process kind.
    step_us: Value,
    /// Realtime wake-up lateness per process kind.
    wake_late_us: Value,
    /// Lost samples per input channel kind.
    lost: Value,
    /// Rejected (non-finite) samples per input channel kind.
    rejected: Value,
}

/// Merges the exit files' histograms: per input channel kind for the hops,
/// per process kind for steps, wake-ups and deadline misses.
fn runtime_stats(files: &[shoal_runtime::stats::StatsFile]) -> RuntimeStats {
    use shoal_runtime::LatencyRecorder;
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
    let table = |m: &BTreeMap<String, LatencyRecorder>| -> Value {
        Value::Object(
            m.iter()
                .map(|(k, r)| (k.clone(), json!(r.summary())))
                .collect(),
        )
    };
    let counts = |m: &BTreeMap<String, u64>| -> Value {
        Value::Object(m.iter().map(|(k, n)| (k.clone(), json!(n))).collect())
    };
    RuntimeStats {
        hops: table(&hops),
        deadline_misses: counts(&misses),
        step_us: table(&steps),
        wake_late_us: table(&late),
        lost: counts(&lost),
        rejected: counts(&rejected),
    }
}
