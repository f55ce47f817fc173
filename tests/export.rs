//! `shoal export --foxglove`, end to end: a short real run of the small
//! scenario with one obstacle of each kind is exported, and the exported
//! MCAP is judged by third-party checks with no shoal code: PyPI `mcap` +
//! Foxglove's own compiled protobuf definitions
//! (`tests/python/check_foxglove.py`), and Rerun's MCAP importer
//! (`tests/python/check_rerun.py`), which must make transforms of `/tf`,
//! poses of `/<V>/pose` and decode every scene update. The output is refused
//! when it exists, unless --force.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::BTreeSet;
use std::path::Path;

use recordings::Recording;
use shoal_tests::*;

/// The small scenario plus a box, a vertical cylinder, a sphere and a mesh.
/// The sphere stands ahead of the leader, within sonar range from the start,
/// so some beams echo.
fn scenario_with_obstacles(duration_s: f64) -> String {
    let mut s = small_scenario("export", duration_s);
    s.push_str(
        r#"
[[obstacles]]
kind = "box"
center_ned_m = [30.0, -25.0, 10.0]
half_extents_m = [5.0, 2.0, 8.0]
yaw_deg = 30.0

[[obstacles]]
kind = "cylinder"
center_ned_m = [40.0, 25.0, 10.0]
radius_m = 2.0
half_height_m = 10.0

[[obstacles]]
kind = "sphere"
center_ned_m = [16.0, 6.0, 10.0]
radius_m = 3.0

[[obstacles]]
kind = "mesh"
vertices_ned_m = [[60.0, -30.0, 25.0], [60.0, 30.0, 25.0], [90.0, 0.0, 25.0]]
triangles = [[0, 1, 2]]
"#,
    );
    s
}

fn export(rec: &Path, out: &Path, force: bool) -> std::process::Output {
    let mut args = vec![
        "export",
        rec.to_str().unwrap(),
        "--foxglove",
        out.to_str().unwrap(),
    ];
    if force {
        args.push("--force");
    }
    run_shoal(&args)
}

fn strings(v: &serde_json::Value) -> BTreeSet<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn foxglove_export_passes_the_official_schemas_and_shows_every_part() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = write_scenario(tmp.path(), "export.toml", &scenario_with_obstacles(15.0));
    let run_dir = tmp.path().join("run");
    let o = run_shoal(&[
        "run",
        scenario.to_str().unwrap(),
        "--quiet",
        "--out",
        run_dir.to_str().unwrap(),
    ]);
    assert!(
        o.status.success(),
        "shoal run failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let rec_path = run_dir.join("recording.mcap");
    let rec = Recording::open(&rec_path).unwrap();
    let truth_steps: BTreeSet<u64> = rec.topic_messages("/L/truth").map(|m| m.log_time).collect();
    let n = |topics: &[&str]| -> u64 {
        topics
            .iter()
            .map(|t| rec.topic_messages(t).count() as u64)
            .sum()
    };
    let scans = n(&["/L/sonar", "/F1/sonar", "/F2/sonar"]);
    let frames = n(&["/F1/beacons", "/F2/beacons"]);
    let plans = n(&["/F1/planner_state", "/F2/planner_state"]);
    assert!(truth_steps.len() > 100 && scans > 300 && frames > 200 && plans > 200);

    let out = tmp.path().join("view.mcap");
    let o = export(&rec_path, &out, false);
    assert!(
        o.status.success(),
        "shoal export failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let summary = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        summary.contains("/scene/line_of_sight") && summary.contains("foxglove.SceneUpdate"),
        "{summary}"
    );
    assert!(!tmp.path().join("view.mcap.partial").exists());

    let report = python_report("check_foxglove.py", &[Path::new("--self-test"), &out]);
    let ch = &report["channels"];
    let count = |topic: &str| ch[topic]["count"].as_u64().unwrap_or(0);
    let schema = |topic: &str| ch[topic]["schema"].as_str().unwrap_or("").to_string();
    let prims = |topic: &str, kind: &str| ch[topic]["primitives"][kind].as_u64().unwrap_or(0);

    // Frames: one /tf per plant step, connecting every body and level frame to world.
    assert_eq!(schema("/tf"), "foxglove.FrameTransforms");
    assert_eq!(count("/tf"), truth_steps.len() as u64);
    let want: BTreeSet<String> = ["world", "ned"]
        .into_iter()
        .map(String::from)
        .chain(
            ["L", "F1", "F2"]
                .iter()
                .flat_map(|v| [format!("{v}/body"), format!("{v}/level")]),
        )
        .collect();
    assert_eq!(strings(&report["frames"]), want);

    // Obstacles: one of each kind, once.
    assert_eq!(count("/scene/obstacles"), 1);
    assert_eq!(
        strings(&ch["/scene/obstacles"]["entities"]).len(),
        4,
        "{}",
        ch["/scene/obstacles"]
    );
    for kind in ["cubes", "cylinders", "spheres", "triangles"] {
        assert_eq!(prims("/scene/obstacles", kind), 1, "{kind}");
    }

    // Vehicles: every one, with beacons on the parent only (L has 2 followers).
    let vehicles: BTreeSet<String> = ["vehicle/L", "vehicle/F1", "vehicle/F2"]
        .into_iter()
        .map(String::from)
        .collect();
    assert_eq!(strings(&ch["/scene/vehicles"]["entities"]), vehicles);
    assert_eq!(prims("/scene/vehicles", "arrows"), 3);
    assert!(prims("/scene/vehicles", "spheres") >= 3);

    // Slots and lines of sight per follower and recorded sample; sonar per scan.
    assert_eq!(
        strings(&ch["/scene/slots"]["entities"]),
        BTreeSet::from(["slot/F1".to_string(), "slot/F2".to_string()])
    );
    assert_eq!(count("/scene/slots"), plans);
    assert_eq!(
        strings(&ch["/scene/line_of_sight"]["entities"]),
        BTreeSet::from(["los/F1".to_string(), "los/F2".to_string()])
    );
    assert_eq!(count("/scene/line_of_sight"), frames);
    assert_eq!(count("/scene/sonar"), scans);
    assert!(
        prims("/scene/sonar", "spheres") > 0,
        "no sonar echo drawn though a sphere stands ahead: {}",
        ch["/scene/sonar"]
    );

    // Poses: every truth sample; parent estimates only from valid fixes.
    for v in ["L", "F1", "F2"] {
        assert_eq!(schema(&format!("/{v}/pose")), "foxglove.PoseInFrame");
        assert_eq!(
            count(&format!("/{v}/pose")),
            rec.topic_messages(&format!("/{v}/truth")).count() as u64
        );
    }
    let valid = rec
        .samples::<ipc_types::LeaderPose>("/F1/leader_pose")
        .iter()
        .filter(|s| s.valid == 1)
        .count() as u64;
    assert!(valid > 0);
    assert_eq!(count("/F1/parent_estimate"), valid);

    // The checker has teeth: broken copies of each channel's first message are refused.
    let n_channels = ch.as_object().unwrap().len() as u64;
    assert!(report["self_test_refused"].as_u64().unwrap() >= 5 * n_channels);

    // Rerun's importer understands every channel: transforms, poses, and
    // scene updates decoded field by field.
    let rr = python_report(
        "check_rerun.py",
        &[
            Path::new("--expect"),
            Path::new("/tf=Transform3D"),
            Path::new("--expect"),
            Path::new("/L/pose=InstancePoses3D"),
            Path::new("--expect"),
            Path::new("/F1/parent_estimate=InstancePoses3D"),
            &out,
        ],
    );
    assert_eq!(rr["channels"].as_u64(), Some(n_channels), "{rr}");
    for topic in [
        "/scene/obstacles",
        "/scene/vehicles",
        "/scene/slots",
        "/scene/sonar",
    ] {
        assert_eq!(rr["decoded"][topic]["fields"], 2, "{topic}: {rr}");
    }

    // An existing output is refused and left alone; --force replaces it.
    let before = std::fs::read(&out).unwrap();
    std::fs::write(&out, b"keep me").unwrap();
    let o = export(&rec_path, &out, false);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--force"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(std::fs::read(&out).unwrap(), b"keep me");
    let o = export(&rec_path, &out, true);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The same recording exports to the same bytes.
    assert_eq!(std::fs::read(&out).unwrap(), before);
}

/// The port the recorder's live view took (`--live 127.0.0.1:0`), from its log.
fn live_port(run_dir: &Path, child: &mut std::process::Child) -> u16 {
    let log = run_dir.join("logs/run.recorder.log");
    let start = std::time::Instant::now();
    loop {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        if let Some(rest) = text.split("live view on ws://127.0.0.1:").nth(1) {
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            return digits.parse().unwrap();
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the run ended ({status}) before its live view came up: {text}");
        }
        assert!(start.elapsed().as_secs() < 60, "no live view: {text}");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[test]
fn a_live_run_serves_what_it_records_to_a_foxglove_protocol_client_and_a_stalled_client_does_not_stall_it(
) {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = write_scenario(tmp.path(), "live.toml", &small_scenario("live", 16.0));
    let run_dir = tmp.path().join("run");
    let mut child = shoal()
        .args(["run", "--quiet", "--live", "127.0.0.1:0", "--pace", "2"])
        .arg(&scenario)
        .arg("--out")
        .arg(&run_dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let url = format!("ws://127.0.0.1:{}", live_port(&run_dir, &mut child));
    let client = repo_root().join("tests/python/live_client.py");
    // A client that subscribes to everything and then reads nothing for
    // longer than the run lasts.
    let stalled = python()
        .arg(&client)
        .args([url.as_str(), "--stall", "10"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let topics = [
        "/L/truth",
        "/F1/planner_state",
        "/F1/leader_pose",
        "/F2/sonar",
    ];
    let scene = ["/tf", "/scene/vehicles", "/scene/slots", "/L/pose"];
    let mut args = vec![url.as_str()];
    for t in topics.iter().chain(&scene) {
        args.extend(["--subscribe", t]);
    }
    args.extend(["--count", "20"]);
    let live = python_report("live_client.py", &args);

    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "the live run failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stalled = stalled.wait_with_output().unwrap();
    assert!(
        stalled.status.success(),
        "the stalled client failed: {}",
        String::from_utf8_lossy(&stalled.stderr)
    );
    assert_eq!(summary(&run_dir)["verdict"]["pass"], true);

    // Every channel of the recording was advertised, with its schema, and
    // beside them the view `shoal export --foxglove` writes, in Foxglove's
    // schemas.
    let rec = Recording::open(&run_dir.join("recording.mcap")).unwrap();
    let recorded: BTreeSet<(String, String)> = rec
        .channels()
        .iter()
        .map(|c| (c.topic.clone(), c.schema_name.clone()))
        .collect();
    let advertised: BTreeSet<(String, String)> = live["advertised"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(t, s)| (t.clone(), s.as_str().unwrap().to_string()))
        .collect();
    assert!(
        advertised.is_superset(&recorded),
        "{:?}",
        recorded.difference(&advertised)
    );
    for (topic, schema) in advertised.difference(&recorded) {
        assert!(schema.starts_with("foxglove."), "{topic}: {schema}");
    }
    for topic in scene {
        // The static scene goes out once a simulated second.
        let least = if topic == "/scene/vehicles" { 3 } else { 20 };
        assert!(
            live["subscribed"][topic]["count"].as_u64() >= Some(least),
            "{topic}: {live}"
        );
    }
    let entities =
        |topic: &str| -> BTreeSet<String> { strings(&live["subscribed"][topic]["entities"]) };
    assert!(entities("/scene/vehicles").is_superset(&BTreeSet::from([
        "vehicle/L".to_string(),
        "vehicle/F1".to_string(),
        "vehicle/F2".to_string()
    ])));
    assert_eq!(
        entities("/scene/slots"),
        BTreeSet::from(["slot/F1".to_string(), "slot/F2".to_string()])
    );
    assert!(live["server"].as_str().unwrap().starts_with("shoal run"));

    // What came live is what was recorded: the same bytes at the same time,
    // decoded by mcap-ros2-support from the advertised schema, in order.
    for topic in topics {
        let got = &live["subscribed"][topic];
        assert!(got["count"].as_u64().unwrap() >= 20, "{topic}: {got}");
        let log_times: Vec<u64> = u64s(&got["log_times"]);
        let sim_times: Vec<u64> = u64s(&got["sim_times"]);
        assert_eq!(
            log_times, sim_times,
            "{topic}: log time is the sample's sim time"
        );
        let seqs: Vec<u64> = u64s(&got["seqs"]);
        assert!(
            seqs.windows(2).all(|w| w[1] == w[0] + 1),
            "{topic}: a client that keeps up misses nothing: {seqs:?}"
        );
        let recorded: std::collections::BTreeMap<u64, String> = rec
            .topic_messages(topic)
            .map(|m| (m.log_time, hex(&m.data)))
            .collect();
        for (t, payload) in log_times.iter().zip(got["payload_hex"].as_array().unwrap()) {
            assert_eq!(
                recorded.get(t).map(String::as_str),
                payload.as_str(),
                "{topic} at {t} ns: the live message is not the recorded one"
            );
        }
    }
    // The recorder counted what it sent live.
    let sent: u64 = rec
        .metadata()
        .get("shoal.recorder")
        .and_then(|m| m.get("live_sent"))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    assert!(sent >= 80, "live_sent {sent}");
}
