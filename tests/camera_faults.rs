//! Camera faults with real processes (issue 9): the paper scenario with a
//! follower's camera blinded for 10 s, or losing 30 % of its frames for 10 s.
//! The run stays safe; the blinded follower reacquires its parent within 5 s
//! after sight returns and holds its slot again; the share of lost frames is
//! the scenario's fraction within binomial error.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;

use ipc_types::{Beacons, LeaderPose, PlannerState, Truth};
use recordings::Recording;
use shoal_tests::*;

/// `planner_state.mode` of a follower that tracks its parent (planner `Mode::Tracking`).
const MODE_TRACKING: u32 = 0;
/// ... tracking with its slot shifted by an obstacle (`Mode::Avoiding`).
const MODE_AVOIDING: u32 = 1;

/// The paper scenario, text as shipped.
fn paper() -> String {
    std::fs::read_to_string(repo_root().join("scenarios/paper.toml")).unwrap()
}

/// Runs `text` with `shoal run` (lockstep, the scenario's seed) and returns
/// the output directory's recording and summary.
fn run(
    dir: &Path,
    name: &str,
    text: &str,
    duration_s: Option<f64>,
) -> (Recording, serde_json::Value) {
    let scenario = write_scenario(dir, &format!("{name}.toml"), text);
    let out = dir.join(name);
    let mut args = vec![
        "run".to_string(),
        scenario.to_str().unwrap().to_string(),
        "--quiet".into(),
        "--out".into(),
        out.to_str().unwrap().to_string(),
    ];
    if let Some(d) = duration_s {
        args.extend(["--duration".into(), d.to_string()]);
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = run_shoal(&args);
    assert!(
        o.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    (
        Recording::open(&out.join("recording.mcap")).unwrap(),
        summary(&out),
    )
}

fn num(s: &serde_json::Value, pointer: &str) -> f64 {
    s.pointer(pointer)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or_else(|| panic!("{pointer} missing in {s}"))
}

/// Zero collisions and no pair ever closer than the safe distance.
fn assert_safe(s: &serde_json::Value) {
    assert_eq!(num(s, "/safety/collisions"), 0.0, "{s}");
    let (d, safe) = (
        num(s, "/safety/min_pair_distance_m"),
        num(s, "/safety/safe_distance_m"),
    );
    assert!(d >= safe, "min pair distance {d} m < safe {safe} m: {s}");
}

fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

fn in_window(ns: u64, from_s: f64, to_s: f64) -> bool {
    (from_s..to_s).contains(&secs(ns))
}

/// The follower's distance to the slot its planner holds at that moment:
/// `|p_F − (p_P + R_yaw(P)·slot_filtered)|`, from ground truth and the
/// planner's own filtered (eq. 9) slot in the parent's level frame, at each
/// truth sample in `[from_s, to_s)`.
///
/// Not the nominal slot: in the passage the slot is shifted on purpose
/// (eqs. 7-8; ~4 m off nominal for F4), so the nominal error says nothing
/// about whether the follower holds the formation.
fn slot_errors(rec: &Recording, f: &str, parent: &str, from_s: f64, to_s: f64) -> Vec<(f64, f64)> {
    let me = rec.samples::<Truth>(&format!("/{f}/truth"));
    let par = rec.samples::<Truth>(&format!("/{parent}/truth"));
    let states = rec.samples::<PlannerState>(&format!("/{f}/planner_state"));
    let mut out = Vec::new();
    for m in me
        .iter()
        .filter(|m| in_window(m.header.sim_time_ns, from_s, to_s))
    {
        let t = m.header.sim_time_ns;
        let Some(p) = par.iter().find(|p| p.header.sim_time_ns == t) else {
            continue;
        };
        let Some(s) = states.iter().rev().find(|s| s.header.sim_time_ns <= t) else {
            continue;
        };
        let yaw = p.euler_rpy_rad[2];
        let (c, sn) = (yaw.cos(), yaw.sin());
        let [sx, sy, sz] = s.slot_filtered_m;
        let target = [
            p.position_ned_m[0] + c * sx - sn * sy,
            p.position_ned_m[1] + sn * sx + c * sy,
            p.position_ned_m[2] + sz,
        ];
        let e = (0..3)
            .map(|i| (m.position_ned_m[i] - target[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        out.push((secs(t), e));
    }
    out
}

#[test]
fn follower_blinded_for_10_s_stays_safe_and_reacquires_within_5_s() {
    let (from_s, to_s) = (60.0, 70.0);
    let mut text = paper();
    // The follower keeps tracking its parent's prediction while it cannot see
    // it ([follower] predict_s, planner): a follower that stopped fell out of
    // the camera's 12 m range ~6 s into the outage and never saw its parent
    // again. Set here unless paper.toml already sets it.
    if !text
        .lines()
        .any(|l| l.trim_start().starts_with("predict_s"))
    {
        assert!(
            text.contains("\n[follower]\n"),
            "paper.toml has no [follower]"
        );
        text = text.replacen("\n[follower]\n", "\n[follower]\npredict_s = 10.0\n", 1);
    }
    text.push_str(&format!(
        "\n[[faults]]\naction = \"blind\"\nvehicle = \"F4\"\nfrom_s = {from_s:?}\nto_s = {to_s:?}\n"
    ));
    let tmp = tempfile::tempdir().unwrap();
    let (rec, s) = run(tmp.path(), "blind", &text, None);
    assert_safe(&s);
    for (v, c) in s["safety"]["obstacle_clearance_m"].as_object().unwrap() {
        assert!(c.as_f64().unwrap() > 1.0, "{v} clearance {c}");
    }

    // Blind: every frame is published, none sees a beacon, no fix.
    let poses = rec.samples::<LeaderPose>("/F4/leader_pose");
    let blind: Vec<_> = poses
        .iter()
        .filter(|p| in_window(p.header.sim_time_ns, from_s, to_s))
        .collect();
    assert_eq!(
        blind.len(),
        100,
        "a blind camera still delivers its 10 Hz frames"
    );
    assert!(blind.iter().all(|p| p.valid == 0), "a fix while blind");
    let beacons = rec.samples::<Beacons>("/F4/beacons");
    let seen: u32 = beacons
        .iter()
        .filter(|b| in_window(b.header.sim_time_ns, from_s, to_s))
        .map(|b| b.visible_count)
        .sum();
    assert_eq!(seen, 0, "beacons seen while blind");
    // The fault is F4's alone.
    let f3 = rec.samples::<LeaderPose>("/F3/leader_pose");
    assert!(f3
        .iter()
        .filter(|p| in_window(p.header.sim_time_ns, from_s, to_s))
        .all(|p| p.valid != 0));

    // Reacquired: a valid fix, and the planner tracking, within 5 s.
    let fix_s = poses
        .iter()
        .find(|p| p.valid != 0 && secs(p.header.sim_time_ns) >= to_s)
        .map(|p| secs(p.header.sim_time_ns))
        .expect("F4 never saw F2 again");
    let states = rec.samples::<PlannerState>("/F4/planner_state");
    let tracking = |m: u32| m == MODE_TRACKING || m == MODE_AVOIDING;
    assert!(
        states
            .iter()
            .filter(|st| in_window(st.header.sim_time_ns, from_s + 1.0, to_s))
            .all(|st| !tracking(st.mode)),
        "F4's planner claims to track while blind"
    );
    let track_s = states
        .iter()
        .find(|st| tracking(st.mode) && secs(st.header.sim_time_ns) >= to_s)
        .map(|st| secs(st.header.sim_time_ns))
        .expect("F4's planner never tracked again");
    println!(
        "F4 blind {from_s}-{to_s} s: first fix {:.2} s, tracking {:.2} s after sight returned",
        fix_s - to_s,
        track_s - to_s
    );
    assert!(fix_s - to_s <= 5.0, "first fix {fix_s} s");
    assert!(track_s - to_s <= 5.0, "tracking again at {track_s} s");
    // ... and it keeps tracking through the passage (F4 loses F2 briefly at
    // the passage's exit, ~120 s, in the run without a fault too).
    let dropped_out: Vec<f64> = states
        .iter()
        .map(|st| (secs(st.header.sim_time_ns), st.mode))
        .filter(|(t, m)| (track_s..110.0).contains(t) && !tracking(*m))
        .map(|(t, _)| t)
        .collect();
    assert!(dropped_out.is_empty(), "lost again at {dropped_out:?}");

    // Back in its slot: the distance to the slot its planner holds is below
    // 1 m from 10 s after the window to the passage's exit. Measured: < 0.55 m
    // there, the same as in the run without a fault (the passage's exit, where
    // the parent swings back to its own slot, moves it ~3 m in both).
    let errs = slot_errors(&rec, "F4", "F2", to_s, 110.0);
    let back_s = errs
        .iter()
        .rev()
        .find(|(_, e)| *e >= 1.0)
        .map_or(to_s, |(t, _)| *t);
    let worst = errs
        .iter()
        .filter(|(t, _)| *t >= to_s + 10.0)
        .map(|(_, e)| *e)
        .fold(0.0, f64::max);
    println!(
        "F4 slot error below 1 m for good {:.1} s after sight returned; max {worst:.2} m over [{}, 110) s",
        back_s - to_s,
        to_s + 10.0
    );
    assert!(errs.len() > 300, "{} truth samples", errs.len());
    assert!(worst < 1.0, "slot error {worst} m after the outage");

    // Not lost for good: the formation after the passage is the paper's.
    let after = num(&s, "/formation/slot_error_rms_m/after");
    assert!(after < 0.5, "slot error after the passage {after} m: {s}");
    let outside = poses
        .iter()
        .filter(|p| !in_window(p.header.sim_time_ns, from_s, to_s))
        .collect::<Vec<_>>();
    let valid = outside.iter().filter(|p| p.valid != 0).count() as f64 / outside.len() as f64;
    assert!(valid >= 0.95, "F4 saw F2 in {valid} of the other frames");
}

#[test]
fn dropping_30_percent_of_frames_loses_that_share_and_stays_safe() {
    let (from_s, to_s, p) = (50.0, 60.0, 0.3);
    let mut text = paper();
    text.push_str(&format!(
        "\n[[faults]]\naction = \"drop\"\nvehicle = \"F2\"\nfrom_s = {from_s:?}\nto_s = {to_s:?}\nfraction = {p:?}\n"
    ));
    let tmp = tempfile::tempdir().unwrap();
    // 100 s: past the window and into the passage.
    let (rec, s) = run(tmp.path(), "drop", &text, Some(100.0));
    assert_safe(&s);

    let count = |topic: &str, a: f64, b: f64| {
        rec.topic_messages(topic)
            .filter_map(|m| recordings::decode::<LeaderPose>(&m.data))
            .filter(|x| in_window(x.header.sim_time_ns, a, b))
            .count()
    };
    // Frames the camera takes in the window: F1's camera, at the same rate, is untouched.
    let frames = count("/F1/leader_pose", from_s, to_s);
    assert_eq!(frames, 100, "10 Hz over 10 s");
    let got = count("/F2/leader_pose", from_s, to_s);
    let beacons = rec
        .samples::<Beacons>("/F2/beacons")
        .iter()
        .filter(|b| in_window(b.header.sim_time_ns, from_s, to_s))
        .count();
    assert_eq!(
        beacons, got,
        "a lost frame publishes neither beacons nor a pose"
    );
    let share = (frames - got) as f64 / frames as f64;
    // Binomial(n = 100, p = 0.3): σ = sqrt(p(1 − p)/n) ≈ 0.046; 4σ ≈ 0.18
    // (the seed fixes the draw; 4σ leaves a changed RNG stream room).
    let sigma = (p * (1.0 - p) / frames as f64).sqrt();
    println!("F2 lost {share:.2} of its frames in [{from_s}, {to_s}) s (p = {p}, σ = {sigma:.3})");
    assert!(
        (share - p).abs() <= 4.0 * sigma,
        "lost {share}, want {p} ± {}",
        4.0 * sigma
    );
    // Nothing is lost outside the window.
    for (a, b) in [(40.0, from_s), (to_s, 70.0)] {
        assert_eq!(
            count("/F2/leader_pose", a, b),
            count("/F1/leader_pose", a, b)
        );
    }
}
