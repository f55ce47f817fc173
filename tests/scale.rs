//! Large groups (issue 8), with real processes: the generated 100-vehicle
//! obstacle scenario runs in lockstep to the end, safe, with every follower
//! in sight of its parent; `shoal bench scale` writes its table and plot.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use shoal_tests::*;

/// `shoal gen` with `args`, into `dir/file`.
fn generate(dir: &std::path::Path, file: &str, args: &[&str]) -> std::path::PathBuf {
    let mut all = vec!["gen"];
    all.extend_from_slice(args);
    let o = run_shoal(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let path = dir.join(file);
    std::fs::write(&path, &o.stdout).unwrap();
    path
}

#[test]
fn a_generated_group_of_100_runs_to_the_end_safe_and_every_parent_in_sight() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = generate(tmp.path(), "g100.toml", &["--vehicles", "100"]);

    // `shoal check` accepts it as generated, with nothing to warn about
    let o = run_shoal(&["check", scenario.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(said.contains("ok (100 vehicles, 501 processes)"), "{said}");
    assert!(!said.contains("warning"), "{said}");

    let out = tmp.path().join("run");
    let o = run_shoal(&[
        "run",
        scenario.to_str().unwrap(),
        "--mode",
        "lockstep",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    let num = |p: &str| {
        s.pointer(p)
            .and_then(serde_json::Value::as_f64)
            .unwrap_or_else(|| panic!("{p} missing"))
    };
    let text: toml::Table = std::fs::read_to_string(&scenario).unwrap().parse().unwrap();
    // to the end
    assert_eq!(num("/sim_time_s"), text["duration_s"].as_float().unwrap());

    // the group is deep: followers of followers, well past one camera's range
    let vehicles = text["vehicles"].as_array().unwrap();
    let parent = |name: &str| {
        vehicles
            .iter()
            .find(|v| v["name"].as_str() == Some(name))
            .and_then(|v| v.get("parent"))
            .and_then(|p| p.as_str())
            .map(str::to_string)
    };
    let depth = |name: &str| {
        let mut d = 0;
        let mut cur = parent(name);
        while let Some(p) = cur {
            d += 1;
            cur = parent(&p);
        }
        d
    };
    let deepest = vehicles
        .iter()
        .map(|v| depth(v["name"].as_str().unwrap()))
        .max()
        .unwrap();
    assert!(deepest >= 8, "the tree is only {deepest} deep");

    // zero collisions, the safe distance kept, nothing lost by the recorder
    assert_eq!(num("/safety/collisions"), 0.0, "{}", s["safety"]);
    assert!(
        num("/safety/min_pair_distance_m") >= num("/safety/safe_distance_m"),
        "{} {}",
        s["safety"]["min_pair"],
        s["safety"]["min_pair_distance_m"]
    );
    assert_eq!(num("/recording/dropped"), 0.0, "{}", s["recording"]);
    for (channel, n) in s["samples_lost"].as_object().unwrap() {
        assert_eq!(n.as_u64(), Some(0), "{channel}: {}", s["samples_lost"]);
    }

    // the group had to squeeze through: the outer files shifted for the walls
    assert!(s["formation"]["passage_s"].is_array(), "no one shifted");
    let clearance = num("/safety/min_obstacle_clearance_m");
    assert!(clearance > 1.0, "min clearance {clearance} m");

    // string stability: the slot error does not grow down the tree (without
    // the headway it grew ~1.8x per level, to metres at level 9)
    let by_level = s["formation"]["slot_error_rms_m_by_level"]
        .as_object()
        .unwrap();
    assert_eq!(by_level.len(), deepest, "{by_level:?}");
    let first = by_level["1"].as_f64().unwrap();
    for (level, rms) in by_level {
        let rms = rms.as_f64().unwrap();
        assert!(
            rms <= (2.0 * first).max(0.5) && rms < 1.5,
            "level {level}: slot error {rms} m RMS, level 1: {first} m ({by_level:?})"
        );
    }

    // every follower within its camera's visibility range of its parent,
    // all the way, and seeing it
    let range = num("/perception/visibility_range_m");
    let ranges = s["perception"]["parent_range_max_m"].as_object().unwrap();
    assert_eq!(ranges.len(), 99);
    for (v, r) in ranges {
        let r = r.as_f64().unwrap();
        assert!(r <= range, "{v}'s camera got {r} m from its parent");
    }
    assert_eq!(s["perception"]["beyond_visibility"], serde_json::json!([]));
    for (v, frac) in s["perception"]["leader_visible_fraction"]
        .as_object()
        .unwrap()
    {
        let frac = frac.as_f64().unwrap();
        assert!(frac >= 0.95, "{v} saw its parent in {frac} of the frames");
    }

    assert_domain_clean(
        wait_run_json(&out, std::time::Duration::ZERO)["run_id"]
            .as_str()
            .unwrap(),
    );
}

/// `shoal bench scale --duration 2 --out OUT` with `args`; it must succeed.
/// Returns what it printed.
fn bench_scale(out: &std::path::Path, args: &[&str]) -> String {
    let mut all = vec![
        "bench",
        "scale",
        "--duration",
        "2",
        "--out",
        out.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    let o = run_shoal(&all);
    let said = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    said
}

#[test]
fn bench_scale_writes_its_table_figures_and_plot() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("scale");
    bench_scale(&out, &["--vehicles", "3,6", "--plots"]);
    let table = std::fs::read_to_string(out.join("scale.md")).unwrap();
    for heading in [
        "processes",
        "real-time factor",
        "CPU ms / vehicle-s",
        "peak RSS sum MiB",
        "recorder msg/s",
        "drops",
        "max parent range m",
    ] {
        assert!(table.contains(heading), "{heading}: {table}");
    }
    let figures: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("scale.json")).unwrap()).unwrap();
    let rows = figures["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{figures}");
    for (row, n) in rows.iter().zip([3u64, 6]) {
        assert_eq!(row["vehicles"].as_u64(), Some(n), "{row}");
        assert_eq!(row["processes"].as_u64(), Some(5 * n + 1), "{row}");
        let f = &row["figures"];
        assert!(f["cpu_total_s"].as_f64().unwrap() > 0.0, "{row}");
        assert!(f["real_time_factor"].as_f64().unwrap() > 0.0, "{row}");
        assert!(f["rss_total_mib"].as_f64().unwrap() > 0.0, "{row}");
        assert_eq!(f["recorder_dropped"].as_u64(), Some(0), "{row}");
        assert_eq!(f["collisions"].as_u64(), Some(0), "{row}");
    }
    for plot in ["scale.png", "scale.svg"] {
        assert!(
            std::fs::metadata(out.join(plot)).unwrap().len() > 1000,
            "{plot}"
        );
    }
}

#[test]
fn bench_scale_floor_rings_every_vehicle_process_and_none_of_them_works() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("floor");
    let said = bench_scale(&out, &["--vehicles", "3", "--floor"]);
    assert!(said.contains("floor"), "{said}");
    let figures: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("scale.json")).unwrap()).unwrap();
    assert_eq!(figures["floor"], serde_json::json!(true), "{figures}");

    // every vehicle process stepped at each of its ticks: 10 Hz for 2 s,
    // the camera on the two followers only
    let s = summary(&out.join("n003"));
    let steps = |kind: &str| {
        s.pointer(&format!("/step_us/{kind}/count"))
            .and_then(serde_json::Value::as_u64)
            .unwrap_or_else(|| panic!("no steps of {kind}: {}", s["step_us"]))
    };
    for kind in ["sim-plant", "sonar", "planner", "mpc"] {
        assert_eq!(steps(kind), 3 * 20, "{kind}");
    }
    assert_eq!(steps("camera-pose"), 2 * 20);

    // and none published a sample of its own: only the run's channels
    // (the world's snapshots, the statistics) hold messages
    let recording = out.join("n003").join("recording.mcap");
    let o = run_shoal(&["inspect", recording.to_str().unwrap()]);
    let listing = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{listing}");
    let mut written = Vec::new();
    let topics = listing
        .lines()
        .filter(|l| l.starts_with('/') && l.contains("/msg/"));
    for line in topics {
        let cols: Vec<&str> = line.split_whitespace().collect();
        let count: u64 = cols[2].parse().unwrap_or_else(|_| panic!("{line}"));
        if count > 0 {
            written.push(cols[0]);
        }
    }
    written.sort_unstable();
    assert_eq!(written, ["/stats", "/world"], "{listing}");
}
