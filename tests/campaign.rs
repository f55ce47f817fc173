//! `shoal campaign` (issue 16), with real processes: one generated course of
//! every family with the paper's formation, run to the end in lockstep, every
//! run passing; the table, JSON and plot written; the command resumes; and
//! Ctrl-C stops it with the runs under way marked, nothing left running.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::time::{Duration, Instant};

use shoal_tests::*;

const FAMILIES: [&str; 10] = [
    "gate",
    "offset",
    "asymmetric",
    "slalom",
    "turn",
    "s-bend",
    "cylinders",
    "angled",
    "depth",
    "current",
];

#[test]
fn one_course_of_every_family_passes_and_the_report_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("c");
    let args = [
        "campaign",
        "--courses",
        "10",
        "--seeds",
        "1",
        "--jobs",
        "2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ];
    let o = run_shoal(&args);
    let said = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("campaign.json")).unwrap()).unwrap();
    let runs = r["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 10);
    for f in FAMILIES {
        let tally = r["by_family"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["family"] == f)
            .unwrap_or_else(|| panic!("{f} missing"));
        assert_eq!(tally["runs"], 1, "{f}");
        assert_eq!(tally["passed"], 1, "{f}: {said}");
        // a run's own summary agrees with its row
        let run = runs.iter().find(|x| x["family"] == f).unwrap();
        let dir = std::path::Path::new(run["dir"].as_str().unwrap());
        let s = summary(dir);
        assert_eq!(s["verdict"]["pass"], true, "{f}");
        assert_eq!(
            run["min_pair_m"].as_f64(),
            s["safety"]["min_pair_distance_m"].as_f64()
        );
        assert!(run["min_pair_m"].as_f64().unwrap() >= 2.0);
        assert!(run["clearance_m"].as_f64().unwrap() >= 1.0);
        assert!(run["final_rms_m"].as_f64().unwrap() < 0.5);
        assert!(run["goal_error_m"].as_f64().unwrap() <= 1.0);
        // passing runs keep their summary and plots, not their recording
        assert!(!dir.join("recording.mcap").exists());
        assert!(dir.join("plots").join("trajectories_xy.png").is_file());
    }
    assert_eq!(r["overall"]["pass_rate"].as_f64(), Some(1.0));
    let md = std::fs::read_to_string(out.join("campaign.md")).unwrap();
    assert!(md.contains("| all | 10 | 10 | 100.0 % |"), "{md}");
    assert!(md.contains("No run failed."));
    assert_eq!(
        said.lines().next(),
        md.lines().next(),
        "the table is printed"
    );
    let png = std::fs::read(out.join("campaign.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    assert!(std::fs::read_to_string(out.join("campaign.svg"))
        .unwrap()
        .contains("<svg"));

    // the same command again resumes: every run is kept, none is run again
    let first = out
        .join("runs")
        .join(runs[0]["name"].as_str().unwrap())
        .join("summary.json");
    let written = || std::fs::metadata(&first).unwrap().modified().unwrap();
    let before = written();
    let o = run_shoal(&args);
    assert!(o.status.success());
    assert_eq!(before, written(), "resumed, not re-run");
}

#[test]
fn ctrl_c_stops_the_campaign_and_reports_what_finished() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("c");
    let child = shoal()
        .args([
            "campaign",
            "--families",
            "gate",
            "--courses",
            "3",
            "--jobs",
            "1",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // wait until the first run is under way (its recording exists)
    let first = out
        .join("runs")
        .join("gate0-paper-5-s0")
        .join("recording.mcap");
    let t0 = Instant::now();
    while !first.exists() {
        assert!(t0.elapsed() < Duration::from_secs(60), "no run started");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(500));
    signal(child.id(), libc::SIGINT);
    let o = child.wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&o.stdout).to_string();
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("campaign.json")).unwrap()).unwrap();
    assert_eq!(r["interrupted"], 1, "{said}");
    assert_eq!(r["overall"]["runs"], 0, "nothing else was started");
    assert!(said.contains("1 run(s) interrupted"), "{said}");
    assert!(o.status.success(), "nothing failed: {said}");
    // no process of the campaign is left
    let needle = out.to_str().unwrap();
    let t0 = Instant::now();
    while !processes_mentioning(needle).is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "left running: {:?}",
            processes_mentioning(needle)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}
