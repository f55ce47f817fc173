//! Replay and re-run, with real processes: every process of every vehicle of
//! a lockstep paper recording, re-run alone on its recorded inputs, publishes
//! exactly what it published in the run; a changed flag shows up as the
//! first difference; a plain replay reaches a live subscriber in order.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Stdio;
use std::time::{Duration, Instant};

use recordings::Recording;
use shoal_runtime::ChannelLimits;
use shoal_tests::*;

fn record(duration: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("rec");
    let o = run_shoal(&[
        "run",
        "--quiet",
        "--duration",
        duration,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (tmp, out.join("recording.mcap"))
}

fn rerun(rec: &std::path::Path, args: &[&str]) -> (i32, serde_json::Value) {
    let o = shoal()
        .arg("replay")
        .arg(rec)
        .args(["--json", "--rerun"])
        .args(args)
        .output()
        .unwrap();
    let report = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "re-run {args:?} printed no report ({e}): {}",
            String::from_utf8_lossy(&o.stderr)
        )
    });
    (o.status.code().unwrap_or(-1), report)
}

#[test]
fn rerunning_every_process_of_a_lockstep_paper_recording_differs_nowhere_until_a_flag_changes() {
    // 80 s: through the start of the passage, so the planners shift.
    let (_tmp, rec) = record("80");
    for v in ["L", "F1", "F2", "F3", "F4"] {
        for kind in ["sim-plant", "camera-pose", "sonar", "planner", "mpc"] {
            if v == "L" && kind == "camera-pose" {
                continue;
            }
            let (code, report) = rerun(&rec, &[kind, "--vehicle", v]);
            assert_eq!(code, 0, "{v}/{kind}: {report}");
            assert!(report["difference"].is_null(), "{v}/{kind}: {report}");
            let compared: u64 = report["compared"]
                .as_object()
                .unwrap()
                .values()
                .map(|n| n.as_u64().unwrap())
                .sum();
            assert!(
                compared >= 800,
                "{v}/{kind} compared only {compared} samples"
            );
        }
    }
    let (code, report) = rerun(&rec, &["world"]);
    assert_eq!(code, 0, "world: {report}");

    // One planner flag changed: the observer's heading noise.
    let (code, report) = rerun(
        &rec,
        &[
            "planner",
            "--vehicle",
            "F3",
            "--set",
            "follower.yaw_accel_noise_radps2=0.02",
        ],
    );
    assert_eq!(code, 3, "{report}");
    let d = &report["difference"];
    assert!(d["topic"].as_str().unwrap().starts_with("/F3/"), "{d}");
    assert!(!d["field"].as_str().unwrap().is_empty());
    assert_ne!(d["recorded"], d["rerun"]);
    assert!(d["sim_time_s"].as_f64().unwrap() >= 0.0);

    // A key that does not exist is refused before anything starts.
    let o = shoal()
        .arg("replay")
        .arg(&rec)
        .args([
            "--rerun",
            "planner",
            "--vehicle",
            "F1",
            "--set",
            "follower.no_such_key=1",
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no_such_key"));
}

#[test]
fn a_replay_reaches_a_live_subscriber_in_the_original_order() {
    let (_tmp, rec) = record("10");
    let recording = Recording::open(&rec).unwrap();
    let expected = recording.samples::<ipc_types::Truth>("/F2/truth");
    assert!(expected.len() >= 90);
    let run_id = format!("replaytest{}", std::process::id());
    let mut replay = shoal()
        .arg("replay")
        .arg(&rec)
        .args([
            "--speed",
            "20",
            "--wait-subscribers",
            "1",
            "--run-id",
            &run_id,
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let node = shoal_runtime::domain_node(&run_id, "test/replay-reader").unwrap();
    let service = ipc_types::service_name(&run_id, "F2", ipc_types::Channel::Truth);
    let limits = ChannelLimits::vehicle();
    let start = Instant::now();
    let mut sub = loop {
        match shoal_runtime::node_subscriber::<ipc_types::Truth, _>(
            &node,
            &service,
            &limits,
            limits.max_buffer,
        ) {
            Ok(s) => break s,
            Err(_) if start.elapsed() < Duration::from_secs(20) => {
                std::thread::sleep(Duration::from_millis(20))
            }
            Err(e) => panic!("cannot subscribe to {service}: {e}"),
        }
    };
    let mut got = Vec::new();
    while got.len() < expected.len() && start.elapsed() < Duration::from_secs(30) {
        sub.take_all(|s| got.push(s)).unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(replay.wait().unwrap().success());
    assert_eq!(got.len(), expected.len(), "every recorded sample arrives");
    for (g, e) in got.iter().zip(&expected) {
        assert_eq!(
            bytemuck::bytes_of(g),
            bytemuck::bytes_of(e),
            "the original sample, header included"
        );
    }
    drop(sub);
    drop(node);
    shoal_runtime::cleanup_domain(&run_id);
}
