//! The metrics of `summary.json`, each from the recording's ground truth or
//! the processes' statistics: safety, formation, perception, mission,
//! latency, the controllers.

use std::collections::BTreeMap;

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

/// Solve times and failures of every vehicle's MPC.
pub(crate) fn mpc(scenario: &Scenario, rec: &Recording) -> MpcFigures {
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
