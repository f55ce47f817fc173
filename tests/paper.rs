//! The paper's result, reproduced: the narrow-passage run is safe and the
//! formation comes back, for the default seed and seeds 1..10 (issue 6).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use shoal_tests::*;

#[test]
fn paper_scenario_is_safe_and_the_formation_returns_for_seeds_0_to_10() {
    let tmp = tempfile::tempdir().unwrap();
    let mut worst = Vec::new();
    for seed in 0..=10u64 {
        let out = tmp.path().join(format!("s{seed}"));
        let o = run_shoal(&[
            "run",
            "--quiet",
            "--seed",
            &seed.to_string(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(
            o.status.success(),
            "seed {seed}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let s = summary(&out);
        let f = |p: &str| {
            s.pointer(p)
                .and_then(|v| v.as_f64())
                .unwrap_or_else(|| panic!("seed {seed}: {p} missing"))
        };
        assert_eq!(f("/safety/collisions"), 0.0, "seed {seed}");
        // Every vehicle's MPC solved every step (10 Hz over 200 s), and the
        // unconstrained shortcut took some of them, not all.
        assert_eq!(f("/mpc/solves"), 5.0 * 10.0 * 200.0, "seed {seed}");
        assert_eq!(f("/mpc/failures"), 0.0, "seed {seed}");
        let shortcut = f("/mpc/unconstrained");
        assert!(
            shortcut > 0.0 && shortcut < f("/mpc/solves"),
            "seed {seed}: {shortcut} of the solves without clarabel"
        );
        assert!(
            f("/safety/min_pair_distance_m") >= f("/safety/safe_distance_m"),
            "seed {seed}: {s}"
        );
        for (v, c) in s["safety"]["obstacle_clearance_m"].as_object().unwrap() {
            assert!(c.as_f64().unwrap() > 1.0, "seed {seed}: {v} clearance {c}");
        }
        assert!(
            f("/formation/slot_error_rms_m/during") > f("/formation/slot_error_rms_m/before"),
            "seed {seed}: the followers must leave their slots in the passage"
        );
        assert!(
            f("/formation/slot_error_rms_m/before") < 0.5,
            "seed {seed}: {s}"
        );
        assert!(
            f("/formation/slot_error_rms_m/after") < 0.5,
            "seed {seed}: {s}"
        );
        for (v, frac) in s["perception"]["leader_visible_fraction"]
            .as_object()
            .unwrap()
        {
            assert!(
                frac.as_f64().unwrap() >= 0.95,
                "seed {seed}: {v} saw its parent in {frac}"
            );
        }
        assert!(
            std::fs::read_dir(out.join("plots")).unwrap().count() >= 12,
            "seed {seed}: plots missing"
        );
        worst.push((
            seed,
            f("/formation/slot_error_rms_m/after"),
            f("/safety/min_obstacle_clearance_m"),
        ));
    }
    println!("seed, after rms, min clearance: {worst:?}");
}
