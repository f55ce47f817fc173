//! The first failure, a course written by hand outside the generator's families:
//! five AUVs through nine thin cylinders (radius 0.6-1.4 m) in a 0.2 m/s cross current
//! (`scenarios/thin-cylinders.toml`). With the paper's four rays the sector between ±10°
//! (the leader's own track) went unseen and, with nothing between the planner's target
//! and the thrusters, the leader touched a cylinder on every seed 0-3 (f040fa2). With the
//! sonar's cones and the controller's safety layer every vehicle keeps its clearance.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use shoal_tests::*;

#[test]
fn thin_cylinders_in_a_cross_current_are_passed_clear_on_seeds_0_to_2() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = repo_root().join("scenarios/thin-cylinders.toml");
    for seed in 0..=2u64 {
        let out = tmp.path().join(format!("s{seed}"));
        run_shoal_ok(&[
            "run",
            scenario.to_str().unwrap(),
            "--quiet",
            "--seed",
            &seed.to_string(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let s = summary(&out);
        assert_eq!(s["safety"]["collisions"], 0, "seed {seed}");
        assert_eq!(
            s["safety"]["obstacle_contacts"].as_array().map(Vec::len),
            Some(0),
            "seed {seed}: {}",
            s["safety"]["obstacle_contacts"]
        );
        let half = s["safety"]["safe_distance_m"].as_f64().unwrap() / 2.0;
        for (v, c) in s["safety"]["obstacle_clearance_m"].as_object().unwrap() {
            assert!(
                c.as_f64().unwrap() >= half,
                "seed {seed}: {v} came within {c} m of a cylinder"
            );
        }
        assert_eq!(s["verdict"]["pass"], true, "seed {seed}: {}", s["verdict"]);
        let goal = s["mission"]["leader_goal_error_m"].as_f64().unwrap();
        assert!(goal <= 1.0, "seed {seed}: leader {goal} m from its goal");
    }
}
