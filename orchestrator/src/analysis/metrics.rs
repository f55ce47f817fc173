//! The metrics of `summary.json`, each from the recording's ground truth or
//! the processes' statistics: safety, formation, perception, mission,
//! latency, the controllers.

use std::collections::{BTreeMap, HashMap};

use ipc_types::{Channel, LeaderPose, MpcStats, Truth};
use nalgebra::{Point3, Vector3};
use recordings::Recording;
use shoal_runtime::latency::LatencySummary;
use shoal_runtime::LatencyRecorder;
use shoal_scenario::Scenario;

use super::formation::{slot_errors, Passage, Phase};
use super::summary::*;
use super::track::Tracks;

/// Percentile of a sorted slice (nearest rank); 0 for none.
pub(crate) fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Root mean square; `None` for none.
pub(crate) fn rms_of(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| rms(v))
}

/// Root mean square; 0 for none.
pub(crate) fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

pub(crate) fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
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
    let mut contacts = Vec::new();
    let contact_m = scenario.safety.collision_distance_m / 2.0;
    if let Some(field) = &field {
        for t in ts {
            let d: Vec<(u64, f64)> = t
                .t_ns
                .iter()
                .zip(&t.p)
                .map(|(&ti, p)| (ti, field.distance(&Point3::from(*p))))
                .collect();
            let m = d.iter().map(|x| x.1).fold(f64::INFINITY, f64::min);
            if !obstacles.is_empty() {
                clearance.insert(t.name.clone(), m);
            }
            min_clear = min_clear.min(m);
            contacts.extend(stretches(&t.name, &d, |x| x < contact_m));
        }
    }
    Safety {
        min_pair_distance_m: finite(min_pair),
        min_pair: min_pair_names,
        safe_distance_m: scenario.safety.safe_distance_m,
        collision_distance_m: scenario.safety.collision_distance_m,
        collisions: collided.len(),
        obstacle_contacts: contacts,
        clearance_below_d_min: min_clear < scenario.safety.safe_distance_m,
        min_obstacle_clearance_m: finite(min_clear),
        obstacle_clearance_m: clearance,
        without_truth: ts
            .iter()
            .filter(|t| t.t_ns.is_empty())
            .map(|t| t.name.clone())
            .collect(),
    }
}

/// The stretches of a `(t ns, value)` series in which `hit` holds, with the
/// smallest value in each.
pub(crate) fn stretches(
    vehicle: &str,
    series: &[(u64, f64)],
    hit: impl Fn(f64) -> bool,
) -> Vec<Stretch> {
    let mut out: Vec<Stretch> = Vec::new();
    let mut open = false;
    for &(t, v) in series {
        let s = t as f64 * 1e-9;
        match (hit(v), open) {
            (true, false) => {
                out.push(Stretch {
                    vehicle: vehicle.to_string(),
                    from_s: s,
                    to_s: s,
                    extreme_m: Some(v),
                });
                open = true;
            }
            (true, true) => {
                if let Some(last) = out.last_mut() {
                    last.to_s = s;
                    last.extreme_m = Some(last.extreme_m.map_or(v, |m| m.min(v)));
                }
            }
            (false, _) => open = false,
        }
    }
    out
}

/// Longest time between two valid fixes (or from the first frame to the first fix, or
/// from the last fix to the last frame), s: `(t ns, valid)` in time order.
pub(crate) fn longest_gap_s(frames: &[(u64, bool)]) -> f64 {
    let Some(&(first, _)) = frames.first() else {
        return 0.0;
    };
    let end = frames.last().map_or(first, |f| f.0);
    let (mut since, mut longest) = (first, 0u64);
    for &(t, valid) in frames {
        if valid {
            longest = longest.max(t - since);
            since = t;
        }
    }
    longest.max(end - since) as f64 * 1e-9
}

/// Stretches longer than `limit_s` without a fix of the parent, from a
/// follower's first camera frame to its last: `(t ns, valid)` in time order.
pub(crate) fn lost_stretches(vehicle: &str, frames: &[(u64, bool)], limit_s: f64) -> Vec<Stretch> {
    let mut out = Vec::new();
    let Some(&(first, _)) = frames.first() else {
        return out;
    };
    let end = frames.last().map_or(first, |f| f.0);
    let mut check = |from: u64, to: u64| {
        if to.saturating_sub(from) as f64 * 1e-9 > limit_s {
            out.push(Stretch {
                vehicle: vehicle.to_string(),
                from_s: from as f64 * 1e-9,
                to_s: to as f64 * 1e-9,
                extreme_m: None,
            });
        }
    };
    let mut since = first;
    for &(t, valid) in frames {
        if valid {
            check(since, t);
            since = t;
        }
    }
    check(since, end);
    out
}

/// What failed of the safety figures (see [`Verdict`]).
pub fn verdict(s: &Summary) -> Verdict {
    let f = &s.safety;
    let mut failed = Vec::new();
    for v in &f.without_truth {
        failed.push(format!(
            "{v} has no truth in the recording: its safety cannot be judged"
        ));
    }
    if f.collisions > 0 {
        failed.push(format!(
            "{} pair(s) of vehicles closer than the collision distance {} m",
            f.collisions, f.collision_distance_m
        ));
    }
    for c in &f.obstacle_contacts {
        failed.push(format!(
            "{} in contact with an obstacle from {:.1} s to {:.1} s (centre {:.2} m from it)",
            c.vehicle,
            c.from_s,
            c.to_s,
            c.extreme_m.unwrap_or(f64::NAN)
        ));
    }
    if let Some(m) = f.min_pair_distance_m.filter(|m| *m < f.safe_distance_m) {
        failed.push(format!(
            "min pair distance {m:.2} m ({}) below the safe distance {} m",
            f.min_pair, f.safe_distance_m
        ));
    }
    let half = f.safe_distance_m / 2.0;
    if let Some(m) = f.min_obstacle_clearance_m.filter(|m| *m < half) {
        failed.push(format!(
            "obstacle clearance {m:.2} m below half the safe distance ({half} m)"
        ));
    }
    // A process wrote garbage (a user's program, or a bug): its readers
    // refused it, so the vehicle flew without it.
    for (kind, n) in s.samples_rejected.iter().filter(|(_, n)| **n > 0) {
        failed.push(format!(
            "{n} sample(s) on {kind} rejected by their readers (a non-finite or out-of-range value): the process writing {kind} sent garbage"
        ));
    }
    for l in &s.perception.parent_lost {
        failed.push(format!(
            "{} without its parent from {:.1} s to {:.1} s (limit {PARENT_LOST_LIMIT_S} s)",
            l.vehicle, l.from_s, l.to_s
        ));
    }
    Verdict {
        pass: failed.is_empty(),
        failed,
    }
}

/// Slot errors split by the passage, per follower and per tree level.
pub fn formation(scenario: &Scenario, tracks: &Tracks, passage: &Passage) -> Formation {
    let (mut before, mut during, mut after) = (Vec::new(), Vec::new(), Vec::new());
    let mut per_follower = BTreeMap::new();
    let levels = scenario.levels();
    let mut by_level: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
    let mut all: Vec<(u64, f64)> = Vec::new();
    for v in &scenario.vehicles {
        let (Some(parent), Some(slot)) = (&v.parent, v.slot_m) else {
            continue;
        };
        let (Some(tf), Some(tp)) = (tracks.get(&v.name), tracks.get(parent)) else {
            continue;
        };
        let errs = slot_errors(tf, tp, slot);
        all.extend(errs.iter().copied());
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
    let t_end = all.iter().map(|(t, _)| *t).max().unwrap_or(0);
    let from = t_end.saturating_sub((FINAL_WINDOW_S * 1e9) as u64);
    let last: Vec<f64> = all
        .iter()
        .filter(|(t, _)| *t >= from)
        .map(|(_, e)| *e)
        .collect();
    Formation {
        slot_error_rms_final_m: rms_of(&last),
        slot_error_rms_m: PhaseRms {
            before: rms_of(&before),
            during: rms_of(&during),
            after: rms_of(&after),
        },
        slot_error_max_after_m: after.iter().copied().max_by(f64::total_cmp),
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
        parent_lost: Vec::new(),
        longest_parent_gap_s: BTreeMap::new(),
        pose_error_m: Percentiles95::default(),
    };
    let mut pose_err = Vec::new();
    for v in &scenario.vehicles {
        let Some(parent) = &v.parent else { continue };
        let (Some(tf), Some(tp)) = (tracks.get(&v.name), tracks.get(parent)) else {
            continue;
        };
        let poses = rec.samples::<LeaderPose>(&ipc_types::topic(&v.name, Channel::LeaderPose));
        let valid = poses.iter().filter(|p| p.valid != 0).count();
        let mut frames: Vec<(u64, bool)> = poses
            .iter()
            .map(|p| (p.header.sim_time_ns, p.valid != 0))
            .collect();
        frames.sort_by_key(|f| f.0);
        out.parent_lost
            .extend(lost_stretches(&v.name, &frames, PARENT_LOST_LIMIT_S));
        let longest = longest_gap_s(&frames);
        out.longest_parent_gap_s.insert(v.name.clone(), longest);
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
        p50: (!pose_err.is_empty()).then(|| pct(&pose_err, 0.5)),
        p95: (!pose_err.is_empty()).then(|| pct(&pose_err, 0.95)),
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
pub(crate) fn end_to_end(scenario: &Scenario, rec: &Recording) -> LatencySummary {
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

/// The stages of the sensor → thrust chain, in order: each one's figure is
/// the time from the previous stage's output to its own (waiting, transport
/// and work), so that a chain's stages add up to its end-to-end latency.
/// `perception` ends when both camera-pose's fix (a follower's) and the
/// sonar scan of the frame are out, as the planner needs both.
pub const CHAIN_STAGES: [&str; 5] = ["world", "perception", "planner", "mpc", "sim-plant"];

/// First publish time of each origin on `topic`: origin ns → publish ns.
fn publishes<T: ipc_types::Sample>(rec: &Recording, topic: &str) -> HashMap<u64, u64> {
    let mut out = HashMap::new();
    for s in rec.samples::<T>(topic) {
        let h = s.header();
        out.entry(h.origin_mono_ns).or_insert(h.publish_mono_ns);
    }
    out
}

/// Sensor event → thrust applied, split by stage ([`CHAIN_STAGES`]): for
/// every thrust that sim-plant applied, the samples of its chain (those
/// with its origin) on `world`, `leader_pose` and `sonar`, `setpoint` and
/// `thrust`. A chain missing a link (a lost frame) is left out. Also each
/// chain from its frame (the `world` snapshot the sensors saw) to thrust.
pub(crate) fn chain(scenario: &Scenario, rec: &Recording) -> (Vec<ChainStage>, LatencySummary) {
    let mut stages: Vec<LatencyRecorder> = CHAIN_STAGES
        .iter()
        .map(|_| LatencyRecorder::new())
        .collect();
    let mut from_frame = LatencyRecorder::new();
    let world = publishes::<ipc_types::World>(rec, "/world");
    for v in &scenario.vehicles {
        let at = |c: Channel| ipc_types::topic(&v.name, c);
        let pose = publishes::<LeaderPose>(rec, &at(Channel::LeaderPose));
        let sonar = publishes::<ipc_types::Sonar>(rec, &at(Channel::Sonar));
        let setpoint = publishes::<ipc_types::Setpoint>(rec, &at(Channel::Setpoint));
        let thrust = publishes::<ipc_types::Thrust>(rec, &at(Channel::Thrust));
        let mut last_origin = 0;
        for s in rec.samples::<Truth>(&at(Channel::Truth)) {
            let o = s.thrust_origin_mono_ns;
            if o == 0 || o == last_origin {
                continue;
            }
            last_origin = o;
            let perceived = pose.get(&o).max(sonar.get(&o));
            let (Some(&w), Some(&p), Some(&sp), Some(&th)) =
                (world.get(&o), perceived, setpoint.get(&o), thrust.get(&o))
            else {
                continue;
            };
            let marks = [o, w, p, sp, th, s.thrust_applied_mono_ns];
            for (rec, pair) in stages.iter_mut().zip(marks.windows(2)) {
                rec.record_ns(pair[1].saturating_sub(pair[0]));
            }
            from_frame.record_ns(s.thrust_applied_mono_ns.saturating_sub(w));
        }
    }
    let stages = CHAIN_STAGES
        .iter()
        .zip(stages)
        .map(|(stage, r)| ChainStage {
            stage: (*stage).to_string(),
            us: r.summary(),
        })
        .collect();
    (stages, from_frame.summary())
}

/// Solve times and failures of every vehicle's MPC.
pub(crate) fn mpc(scenario: &Scenario, rec: &Recording) -> MpcFigures {
    let (mut solve, mut guarded) = (Vec::new(), Vec::new());
    let (mut failures, mut unconstrained) = (0u64, 0u64);
    let guarded_code = u32::from(mpc::MpcStatus::Guarded.code());
    for v in &scenario.vehicles {
        let stats = rec.samples::<MpcStats>(&ipc_types::topic(&v.name, Channel::MpcStats));
        solve.extend(stats.iter().map(|s| s.solve_ns as f64 / 1e3));
        guarded.extend(
            stats
                .iter()
                .filter(|s| s.status == guarded_code)
                .map(|s| s.solve_ns as f64 / 1e3),
        );
        failures += stats.last().map_or(0, |s| s.failures);
        unconstrained += stats
            .iter()
            .filter(|s| s.status == u32::from(mpc::MpcStatus::Unconstrained.code()))
            .count() as u64;
    }
    solve.sort_by(f64::total_cmp);
    guarded.sort_by(f64::total_cmp);
    let times = |v: &[f64]| SolveTimes {
        p50: pct(v, 0.5),
        p99: pct(v, 0.99),
        max: v.last().copied().unwrap_or(0.0),
    };
    MpcFigures {
        solve_us: times(&solve),
        failures,
        solves: solve.len() as u64,
        unconstrained,
        guarded: guarded.len() as u64,
        guarded_solve_us: times(&guarded),
    }
}

/// The processes' runtime statistics, merged.
pub(crate) struct RuntimeStats {
    pub(crate) hops: BTreeMap<String, LatencySummary>,
    pub(crate) deadline_misses: BTreeMap<String, u64>,
    pub(crate) step_us: BTreeMap<String, LatencySummary>,
    pub(crate) wake_late_us: BTreeMap<String, LatencySummary>,
    pub(crate) lost: BTreeMap<String, u64>,
    pub(crate) rejected: BTreeMap<String, u64>,
}

/// Merges the exit files' histograms: per input channel kind for the hops,
/// per process kind for steps, wake-ups and deadline misses.
pub(crate) fn runtime_stats(files: &[shoal_runtime::stats::StatsFile]) -> RuntimeStats {
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
        let ns: Vec<(u64, [f64; 3])> = pts
            .iter()
            .map(|&(t, p)| ((t * 1e9).round() as u64, p))
            .collect();
        crate::analysis::track::track_through(name, &ns)
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
    fn a_hull_in_the_wall_is_a_contact_with_its_times_and_fails_the_run() {
        let sc = scenario();
        let mut ts = on_slots();
        // The leader runs into the wall's face at 20 m: north at 2.5 m/s
        // for 10 s ends 5 m inside it. Contact: centre within half the
        // collision distance (0.5 m) of the face, from t = 7.8 s on.
        ts[0] = track(
            "L",
            &(0..=100)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    (t, [2.5 * t, 0.0, 10.0])
                })
                .collect::<Vec<_>>(),
        );
        let safety = safety(&sc, &Tracks::new(ts));
        assert_eq!(safety.collisions, 0, "no pair collided");
        assert_eq!(safety.obstacle_contacts.len(), 1);
        let c = &safety.obstacle_contacts[0];
        assert_eq!(c.vehicle, "L");
        approx::assert_relative_eq!(c.from_s, 7.9, epsilon = 1e-9);
        approx::assert_relative_eq!(c.to_s, 10.0, epsilon = 1e-9);
        assert_eq!(c.extreme_m, Some(0.0), "inside the wall");
        assert!(safety.clearance_below_d_min);
        let s = Summary {
            safety,
            ..Summary::default()
        };
        let v = verdict(&s);
        assert!(!v.pass);
        assert!(
            v.failed
                .iter()
                .any(|f| f.starts_with("L in contact with an obstacle from 7.9 s")),
            "{v:?}"
        );
        assert!(
            v.failed
                .iter()
                .any(|f| f.contains("half the safe distance")),
            "{v:?}"
        );
    }

    #[test]
    fn a_parent_lost_longer_than_the_limit_is_reported_with_its_times() {
        let s = |t: f64| (t * 1e9).round() as u64;
        // Fixes at 10 Hz, none from 2.0 s (exclusive) to 8.5 s: 6.5 s lost.
        let frames: Vec<(u64, bool)> = (0..=100)
            .map(|k| {
                let t = k as f64 * 0.1;
                (s(t), !(t > 2.05 && t < 8.45))
            })
            .collect();
        let lost = lost_stretches("F1", &frames, PARENT_LOST_LIMIT_S);
        assert_eq!(lost.len(), 1);
        approx::assert_relative_eq!(lost[0].from_s, 2.0, epsilon = 1e-9);
        approx::assert_relative_eq!(lost[0].to_s, 8.5, epsilon = 1e-9);
        // 4.9 s without a fix is within the limit; a follower that never
        // saw its parent over 6 s is lost from its first frame to its last.
        let short: Vec<(u64, bool)> = (0..=100)
            .map(|k| (s(k as f64 * 0.1), !(11..60).contains(&k)))
            .collect();
        assert!(lost_stretches("F1", &short, PARENT_LOST_LIMIT_S).is_empty());
        let never: Vec<(u64, bool)> = (0..=60).map(|k| (s(k as f64 * 0.1), false)).collect();
        let lost = lost_stretches("F2", &never, PARENT_LOST_LIMIT_S);
        assert_eq!(lost.len(), 1);
        approx::assert_relative_eq!(lost[0].to_s - lost[0].from_s, 6.0, epsilon = 1e-9);
        // the longest gap agrees with the stretches
        approx::assert_relative_eq!(longest_gap_s(&frames), 6.5, epsilon = 1e-9);
        approx::assert_relative_eq!(longest_gap_s(&never), 6.0, epsilon = 1e-9);
        let mut sum = Summary::default();
        sum.perception.parent_lost = lost;
        let v = verdict(&sum);
        assert!(
            !v.pass && v.failed[0].starts_with("F2 without its parent"),
            "{v:?}"
        );
    }

    #[test]
    fn a_vehicle_without_truth_fails_the_verdict_by_name() {
        // F2's plant never published: the others' tracks are safe
        let mut tracks = on_slots();
        tracks[2] = track("F2", &[]);
        let s = Summary {
            safety: safety(&scenario(), &Tracks::new(tracks)),
            ..Summary::default()
        };
        assert_eq!(s.safety.without_truth, ["F2"]);
        let v = verdict(&s);
        assert!(!v.pass, "{v:?}");
        assert_eq!(
            v.failed,
            ["F2 has no truth in the recording: its safety cannot be judged"]
        );
        // with every track there, the same run passes
        let s = Summary {
            safety: safety(&scenario(), &Tracks::new(on_slots())),
            ..Summary::default()
        };
        assert!(s.safety.without_truth.is_empty());
    }

    #[test]
    fn a_safe_run_passes() {
        let s = Summary {
            safety: safety(&scenario(), &Tracks::new(on_slots())),
            ..Summary::default()
        };
        assert!(s.safety.obstacle_contacts.is_empty());
        let v = verdict(&s);
        assert!(v.pass && v.failed.is_empty(), "{v:?}");
    }

    #[test]
    fn garbage_a_reader_rejected_fails_the_verdict_naming_its_channel() {
        let mut s = Summary {
            safety: safety(&scenario(), &Tracks::new(on_slots())),
            ..Summary::default()
        };
        s.samples_rejected.insert("nav".into(), 0);
        s.samples_rejected.insert("setpoint".into(), 42);
        let v = verdict(&s);
        assert!(!v.pass);
        assert_eq!(v.failed.len(), 1, "{v:?}");
        assert!(
            v.failed[0].starts_with("42 sample(s) on setpoint rejected"),
            "{v:?}"
        );
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
            f.slot_error_rms_m.before.unwrap_or(f64::NAN),
            (25.0f64 / 2.0).sqrt(),
            epsilon = 1e-9
        );
        assert_eq!(f.slot_error_rms_m.during, None, "no passage: no 'during'");
        assert_eq!(f.slot_error_rms_m.after, None);
        assert_eq!(f.slot_error_max_after_m, None);
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
        assert_eq!(
            f.slot_error_rms_m.after, None,
            "the run ends inside the settling"
        );
        // F1 is 1 m off its slot during the passage, and so is F2: its slot
        // hangs on F1, which is where F2 is not.
        approx::assert_relative_eq!(
            f.slot_error_rms_m.during.unwrap_or(f64::NAN),
            1.0,
            epsilon = 1e-9
        );
        approx::assert_relative_eq!(
            f.slot_error_rms_m.before.unwrap_or(f64::NAN),
            0.0,
            epsilon = 1e-9
        );
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
