//! The foundation, end to end with real processes: a run records every
//! channel so the official readers (and Rerun's importer) decode it; lockstep is deterministic;
//! SIGINT leaves nothing behind; two runs never cross; bad scenarios are
//! refused before anything starts; the perception rule holds on the live
//! service graph; the recorder's drop count is honest.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::{BTreeMap, BTreeSet};
use std::process::Stdio;
use std::time::{Duration, Instant};

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use recordings::Recording;
use shoal_tests::*;

#[test]
fn paper_run_records_every_channel_and_the_official_readers_decode_it() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("paper");
    let o = run_shoal(&["run", "--quiet", "--out", out.to_str().unwrap()]);
    assert!(
        o.status.success(),
        "shoal run failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    let report = rec.inspect();
    assert!(!report.truncated);
    let counts: BTreeMap<String, u64> = report
        .channels
        .iter()
        .map(|c| (c.topic.clone(), c.messages))
        .collect();
    for v in ["L", "F1", "F2", "F3", "F4"] {
        for ch in ipc_types::Channel::ALL {
            if v == "L" && ch.follower_only() {
                assert!(!counts.contains_key(&ipc_types::topic(v, ch)));
                continue;
            }
            let t = ipc_types::topic(v, ch);
            assert!(
                counts.get(&t).copied().unwrap_or(0) > 0,
                "{t} has no messages: {counts:?}"
            );
        }
    }
    assert!(counts["/world"] > 0);

    // `shoal inspect` lists them too.
    let o = run_shoal(&["inspect", out.join("recording.mcap").to_str().unwrap()]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("/F4/leader_pose") && text.contains("shoal_msgs/msg/LeaderPose"),
        "{text}"
    );

    // Official readers, no shoal code: every message decodes, and the values
    // agree with what shoal itself decodes.
    let report = python_report("read_mcap.py", &[out.join("recording.mcap")]);
    assert_eq!(
        report["messages"].as_u64().unwrap(),
        rec.messages().len() as u64
    );
    // A second, independent ROS 2 bag reader (PyPI `rosbags`, its own CDR
    // decoder): `pkg/msg/Type` names, offered QoS on every channel, and the
    // `rosbag2` metadata record agreeing with the file.
    let bag = python_report("read_rosbag2.py", &[out.join("recording.mcap")]);
    assert_eq!(
        bag["messages"].as_u64().unwrap(),
        rec.messages().len() as u64,
        "{bag}"
    );
    assert!(bag["types"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t == "shoal_msgs/msg/Truth"));
    // A third importer, Rerun's (PyPI `rerun-sdk`: `rerun mcap convert`): it resolves
    // nested types only by the `MSG: pkg/Type` sections rosbag2 writes, and keeps a
    // channel it cannot resolve as raw bytes. Every channel is decoded into a struct
    // with every field of its schema.
    let rr = python_report("check_rerun.py", &[out.join("recording.mcap")]);
    let with_messages = counts.values().filter(|n| **n > 0).count();
    assert_eq!(rr["channels"].as_u64(), Some(with_messages as u64), "{rr}");
    let truth = rec.samples::<ipc_types::Truth>("/F2/truth");
    let s5 = truth.iter().find(|t| t.header.seq == 5).unwrap();
    let py_pos: Vec<f64> = report["samples"]["/F2/truth"]["position_ned_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(py_pos, s5.position_ned_m.to_vec());
    let sonar = rec.samples::<ipc_types::Sonar>("/L/sonar");
    let s5 = sonar.iter().find(|t| t.header.seq == 5).unwrap();
    let py_valid: Vec<u64> = u64s(&report["samples"]["/L/sonar"]["valid"]);
    assert_eq!(
        py_valid,
        s5.valid.iter().map(|&v| u64::from(v)).collect::<Vec<_>>()
    );

    // The summary reports CPU time per process kind (no process busy-polls:
    // the whole run's CPU is a small multiple of its wall time on 2 cores).
    let s = summary(&out);
    for kind in PROCESS_KINDS {
        assert!(
            s["cpu_time_s"][kind].as_f64().is_some(),
            "cpu_time_s.{kind} missing: {s}"
        );
    }
    assert_eq!(s["recording"]["dropped"].as_u64(), Some(0));
    assert_eq!(
        s["recording"]["messages"].as_u64(),
        Some(rec.messages().len() as u64)
    );
    let run = wait_run_json(&out, Duration::from_secs(1));
    assert_domain_clean(run["run_id"].as_str().unwrap());
}

#[test]
fn two_lockstep_runs_with_the_same_seed_give_the_same_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let sc = write_scenario(tmp.path(), "s.toml", &small_scenario("det", 12.0));
    let mut hashes = Vec::new();
    for (i, seed) in ["7", "7", "8"].iter().enumerate() {
        let out = tmp.path().join(format!("r{i}"));
        run_shoal_ok(&[
            "run",
            "--quiet",
            sc.to_str().unwrap(),
            "--seed",
            seed,
            "--out",
            out.to_str().unwrap(),
        ]);
        hashes.push(
            Recording::open(&out.join("recording.mcap"))
                .unwrap()
                .message_hashes(),
        );
    }
    assert!(!hashes[0].is_empty());
    assert_eq!(hashes[0].len(), hashes[1].len());
    let first_diff = hashes[0].iter().zip(&hashes[1]).position(|(a, b)| a != b);
    assert_eq!(
        first_diff, None,
        "same seed, different message at index {first_diff:?}"
    );
    assert_ne!(
        hashes[0], hashes[2],
        "a different seed must change the noisy sensors"
    );

    // The recording keeps the effective scenario (every section with its
    // defaults) and the run's wall-clock start; the effective text is what
    // `shoal check --resolved` prints, and run again it gives the same
    // messages.
    let rec = Recording::open(&tmp.path().join("r0/recording.mcap")).unwrap();
    let meta = &rec.metadata()["shoal.run"];
    let effective = &meta["effective_toml"];
    let parsed: toml::Table = toml::from_str(effective).unwrap();
    assert_eq!(parsed["camera"]["width_px"].as_integer(), Some(512));
    assert!(parsed["camera"].get("mount_position_body_m").is_some());
    assert!(parsed["beacons"].get("positions_body_m").is_some());
    assert!(parsed["pose"].as_table().is_some_and(|t| !t.is_empty()));
    assert_eq!(parsed["seed"].as_integer(), Some(7));
    let start: u64 = meta["start_unix_ns"].parse().unwrap();
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    assert!(
        start < now && now - start < 3_600_000_000_000,
        "start_unix_ns {start}"
    );
    let eff = write_scenario(tmp.path(), "effective.toml", effective);
    let o = run_shoal_ok(&["check", "--resolved", eff.to_str().unwrap()]);
    assert_eq!(String::from_utf8_lossy(&o.stdout), *effective);
    let out = tmp.path().join("again");
    run_shoal_ok(&[
        "run",
        "--quiet",
        eff.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let again = Recording::open(&out.join("recording.mcap"))
        .unwrap()
        .message_hashes();
    assert!(
        again == hashes[0],
        "the effective scenario runs differently from the one it came from"
    );
}

#[test]
fn sigint_to_shoal_stops_every_child_and_leaves_no_shared_memory() {
    let tmp = tempfile::tempdir().unwrap();
    let sc = write_scenario(tmp.path(), "s.toml", &small_scenario("long", 3000.0));
    let out = tmp.path().join("r");
    // Half-way: the children are up and the recording grows.
    let (mut child, run_id) = start_run(&sc, &out, &[], 2 + 3 * 4 + 2);
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        !shoal_runtime::list_domain_files(&run_id).is_empty(),
        "a live run has a domain"
    );
    signal(child.id(), libc::SIGINT);
    let status = child.wait().unwrap();
    let mut err = String::new();
    use std::io::Read;
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(
        !status.success(),
        "an interrupted run must not report success"
    );
    // the shell's convention: 128 + SIGINT
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted by SIGINT"), "{err}");
    assert_domain_clean(&run_id);
    // The recording made so far is complete and readable.
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    assert!(!rec.truncated());
    assert!(!rec.messages().is_empty());
    // The summary and plots of the part that ran, and where they are.
    assert!(
        err.contains("the summary and plots of the part that ran"),
        "{err}"
    );
    let s = summary(&out);
    let t = s["sim_time_s"].as_f64().unwrap();
    let last = rec.messages().iter().map(|m| m.log_time).max().unwrap() as f64 * 1e-9;
    assert!(
        t > 0.0 && t < 3000.0 && (t - last).abs() < 0.1,
        "{t} vs {last}"
    );
    assert!(out.join("plots").read_dir().unwrap().next().is_some());
}

#[test]
fn a_summary_from_the_recording_alone_matches_the_runs_own() {
    let tmp = tempfile::tempdir().unwrap();
    let out = run_small(tmp.path(), "alone", 20.0);
    let rec = out.join("recording.mcap");
    let again = tmp.path().join("again");
    run_shoal_ok(&[
        "summarize",
        rec.to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
    ]);
    assert!(again.join("plots").read_dir().unwrap().next().is_some());
    let (a, b) = (summary(&out), summary(&again));
    // What the recording holds is the same figure to the bit.
    for key in [
        "/scenario",
        "/seed",
        "/vehicles",
        "/mode",
        "/run_id",
        "/sim_time_s",
        "/ticks",
        "/safety",
        "/formation",
        "/perception",
        "/mission",
        "/latency_us/end_to_end",
        "/mpc",
        "/events",
        "/verdict",
        "/recording/messages",
    ] {
        assert_eq!(a.pointer(key), b.pointer(key), "{key}");
    }
    let (wa, wb) = (
        a["wall_time_s"].as_f64().unwrap(),
        b["wall_time_s"].as_f64().unwrap(),
    );
    assert!((wa - wb).abs() < 0.05 * wa + 0.05, "wall {wa} vs {wb}");
    // A second summary into the same place is refused without --force.
    let o = run_shoal(&[
        "summarize",
        rec.to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--force"));
}

#[test]
fn two_runs_at_once_never_see_each_other() {
    let tmp = tempfile::tempdir().unwrap();
    let a = write_scenario(tmp.path(), "a.toml", &small_scenario("a", 30.0));
    // Same vehicle names, different formation: only service names keep them apart.
    let b_text = small_scenario("b", 30.0).replace("[-8.0, 4.0, 0.0]", "[-9.0, 4.0, 0.0]");
    let b = write_scenario(tmp.path(), "b.toml", &b_text);
    let outs = [tmp.path().join("ra"), tmp.path().join("rb")];
    let children: Vec<_> = [&a, &b]
        .iter()
        .zip(&outs)
        .map(|(s, o)| {
            shoal()
                .args([
                    "run",
                    "--quiet",
                    s.to_str().unwrap(),
                    "--out",
                    o.to_str().unwrap(),
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for c in children {
        let o = c.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let ra = Recording::open(&outs[0].join("recording.mcap")).unwrap();
    let rb = Recording::open(&outs[1].join("recording.mcap")).unwrap();
    for (rec, name) in [(&ra, "a"), (&rb, "b")] {
        let report = rec.inspect();
        // Every channel exactly once per frame, no gaps: nobody else's samples got in.
        for c in &report.channels {
            assert_eq!(c.gaps, 0, "{name}: {} has gaps", c.topic);
            // Statistics come once a second; events only when something happens.
            if c.topic == "/stats" {
                continue;
            }
            if c.topic == "/events" {
                assert_eq!(c.messages, 0, "{name}: events in a run without faults");
                continue;
            }
            assert_eq!(
                c.messages, 300,
                "{name}: {} has {} messages",
                c.topic, c.messages
            );
        }
        // The stats channel: once a second from each of the run's 16 processes, no one else.
        let stats = rec.samples::<ipc_types::ProcessStats>("/stats");
        assert_eq!(stats.len(), 16 * 29, "{name}: /stats");
        for p in &stats {
            let v = ipc_types::str_of(&p.vehicle);
            assert!(
                ["L", "F1", "F2", "run"].contains(&v),
                "{name}: stats from {v}"
            );
        }
        assert_eq!(rec.metadata()["shoal.run"]["scenario"], name);
    }
    // The different slot shows in each run's own truth.
    let fa = ra.samples::<ipc_types::Truth>("/F2/truth")[0].position_ned_m;
    let fb = rb.samples::<ipc_types::Truth>("/F2/truth")[0].position_ned_m;
    assert!(
        (fa[0] + 8.0).abs() < 1e-6 && (fb[0] + 9.0).abs() < 1e-6,
        "{fa:?} {fb:?}"
    );
}

#[test]
fn bad_scenarios_are_refused_naming_the_key_and_nothing_starts() {
    let tmp = tempfile::tempdir().unwrap();
    let base = small_scenario("bad", 5.0);
    let cases = [
        (
            "unknown key",
            base.replace("seed = 3", "seed = 3\nspeed = 4"),
            "speed",
        ),
        (
            "missing parent",
            base.replace(
                "parent = \"L\"\nslot_m = [-8.0, 4.0",
                "parent = \"X9\"\nslot_m = [-8.0, 4.0",
            ),
            "vehicles[2].parent",
        ),
        (
            "cycle",
            base.replace(
                "name = \"F1\"\nparent = \"L\"",
                "name = \"F1\"\nparent = \"F2\"",
            )
            .replace(
                "name = \"F2\"\nparent = \"L\"",
                "name = \"F2\"\nparent = \"F1\"",
            ),
            "cycle",
        ),
        (
            "negative size",
            format!("{base}\n[safety]\nsafe_distance_m = -2.0\n"),
            "safety.safe_distance_m",
        ),
        (
            "negative duration",
            base.replace("duration_s = 5.0", "duration_s = -5.0"),
            "duration_s",
        ),
        (
            "bad section key",
            format!("{base}\n[sonar]\nrange_max = 3.0\n"),
            "range_max",
        ),
    ];
    for (what, text, key) in cases {
        let sc = write_scenario(tmp.path(), "s.toml", &text);
        let check = run_shoal(&["check", sc.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&check.stderr);
        assert!(!check.status.success(), "{what}: check accepted it");
        assert!(
            err.contains(key),
            "{what}: message does not name `{key}`: {err}"
        );
        let out = tmp.path().join(format!("out-{}", what.replace(' ', "-")));
        let run = run_shoal(&[
            "run",
            "--quiet",
            sc.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{what}: run accepted it");
        assert!(
            err.contains(key),
            "{what}: run message does not name `{key}`: {err}"
        );
        assert!(
            !out.exists(),
            "{what}: a refused run must start nothing and write nothing"
        );
    }
}

/// Services each node of a live run has opened, by node name.
fn live_graph(run_id: &str) -> BTreeMap<String, BTreeSet<String>> {
    let config = shoal_runtime::iceoryx_config(run_id);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    ipc::Service::list(&config, |svc| {
        let name = svc.static_details.name().to_string();
        if let Some(dynamic) = &svc.dynamic_details {
            for n in &dynamic.nodes {
                if let NodeState::Alive(view) = n {
                    if let Some(d) = view.details() {
                        graph
                            .entry(d.name().to_string())
                            .or_default()
                            .insert(name.clone());
                    }
                }
            }
        }
        CallbackProgression::Continue
    })
    .unwrap();
    graph
}

/// Runs `scenario` until the named nodes have opened their services, stops
/// it, and returns the live service graph with the run's service prefix.
fn graph_of(
    scenario: &str,
    nodes: &[&str],
    extra: &[&str],
) -> (BTreeMap<String, BTreeSet<String>>, String, String) {
    let tmp = tempfile::tempdir().unwrap();
    let sc = write_scenario(tmp.path(), "s.toml", scenario);
    let out = tmp.path().join("r");
    let mut child = shoal()
        .args([
            "run",
            "--quiet",
            sc.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let run = wait_run_json(&out, Duration::from_secs(20));
    let run_id = run["run_id"].as_str().unwrap().to_string();
    let start = Instant::now();
    // A process opens its services one after another: take the graph once
    // every node has some and two reads 250 ms apart agree (a read between
    // two opens would miss the later one).
    let mut last = BTreeMap::new();
    let graph = loop {
        let g = live_graph(&run_id);
        let ready = nodes
            .iter()
            .all(|n| g.get(*n).is_some_and(|s| s.len() >= 4));
        if ready && g == last {
            break g;
        }
        last = g;
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "nodes never appeared: {last:?}"
        );
        std::thread::sleep(Duration::from_millis(if ready { 250 } else { 50 }));
    };
    signal(child.id(), libc::SIGINT);
    child.wait().unwrap();
    let prefix = format!("shoal/{run_id}/");
    (graph, prefix, run_id)
}

/// True if `service` (under `prefix`) is `vehicle`'s own channel or one of
/// the run's clock, done and stats services.
fn own_or_clock(prefix: &str, service: &str, vehicle: &str) -> bool {
    let rest = service.strip_prefix(prefix).unwrap_or(service);
    rest.starts_with(&format!("{vehicle}/")) || rest == "clock" || rest == "done" || rest == "stats"
}

#[test]
fn followers_planner_and_mpc_open_only_their_own_channels() {
    followers_open_only_their_own_channels(&[]);
}

/// The perception rule holds for a user's program too: the followers'
/// planner replaced by the Python example (`--replace`, the shoal_node
/// package) opens its own vehicle's channels and the run's, nothing else.
#[test]
fn a_python_planner_in_place_of_the_followers_opens_only_their_own_channels() {
    let flag = format!(
        "planner@followers=python3 {}",
        repo_root()
            .join("examples/python/paper_follower.py")
            .display()
    );
    followers_open_only_their_own_channels(&["--replace", &flag]);
}

fn followers_open_only_their_own_channels(extra: &[&str]) {
    let nodes = [
        "F1/planner",
        "F1/mpc",
        "F2/planner",
        "F2/mpc",
        "L/planner",
        "F1/camera-pose",
    ];
    let (graph, prefix, run_id) = graph_of(&small_scenario("graph", 3000.0), &nodes, extra);
    for follower in ["F1", "F2"] {
        for proc in ["planner", "mpc"] {
            let node = format!("{follower}/{proc}");
            let services = &graph[&node];
            for s in services {
                let rest = s
                    .strip_prefix(&prefix)
                    .unwrap_or_else(|| panic!("{node} opened a foreign service {s}"));
                let own = rest.starts_with(&format!("{follower}/"));
                // The run's clock and done events, and the stats channel
                // every process publishes its own runtime statistics on.
                let clock = rest == "clock" || rest == "done" || rest == "stats";
                assert!(
                    own || clock,
                    "{node} opened {s}: not its own vehicle's channel"
                );
                assert!(
                    !rest.ends_with("/truth") && rest != "world",
                    "{node} opened ground truth {s}"
                );
            }
        }
        assert!(graph[&format!("{follower}/planner")]
            .contains(&format!("{prefix}{follower}/leader_pose")));
    }
    // The checker itself is live: sensors do read the world.
    assert!(graph["F1/camera-pose"].contains(&format!("{prefix}world")));
    assert_domain_clean(&run_id);
}

#[test]
fn with_images_camera_pose_reads_only_its_own_frame_and_the_renderer_reads_the_world() {
    let nodes = [
        "F1/camera-pose",
        "F1/camera-sim",
        "F2/camera-pose",
        "F2/camera-sim",
    ];
    let (graph, prefix, run_id) = graph_of(&small_image_scenario("graph-img", 3000.0), &nodes, &[]);
    for follower in ["F1", "F2"] {
        let node = format!("{follower}/camera-pose");
        for s in &graph[&node] {
            assert!(
                s.starts_with(&prefix) && own_or_clock(&prefix, s, follower),
                "{node} opened {s}: not its own vehicle's channel"
            );
            assert!(
                !s.ends_with("/truth") && !s.ends_with("/world"),
                "{node} opened ground truth {s}"
            );
        }
        assert!(graph[&node].contains(&format!("{prefix}{follower}/image")));
        // The renderer is the sensor simulator: it reads the world.
        let sim = format!("{follower}/camera-sim");
        assert!(graph[&sim].contains(&format!("{prefix}world")));
        assert!(graph[&sim].contains(&format!("{prefix}{follower}/image")));
    }
    assert_domain_clean(&run_id);
}

#[test]
fn the_recorder_counts_what_it_could_not_record() {
    let tmp = tempfile::tempdir().unwrap();
    // A recorder that drains once a second with room for one sample per
    // channel, in realtime, must lose samples published at 10 Hz — and say so.
    let text = format!(
        "{}\n[rates]\nrecorder_hz = 1.0\n[recording]\nbuffer = 1\n",
        small_scenario("drops", 4.0)
    );
    let sc = write_scenario(tmp.path(), "s.toml", &text);
    let out = tmp.path().join("r");
    run_shoal_ok(&[
        "run",
        "--quiet",
        "--mode",
        "realtime",
        sc.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let s = summary(&out);
    let dropped = s["recording"]["dropped"].as_u64().unwrap();
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    let gaps: u64 = rec.inspect().channels.iter().map(|c| c.gaps).sum();
    assert!(dropped > 0, "nothing dropped: {s}");
    // The count agrees with the sequence gaps a reader sees in the file.
    assert_eq!(dropped, gaps);
}

#[test]
fn a_second_run_into_the_same_directory_is_refused_unless_forced() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = write_scenario(tmp.path(), "again.toml", &small_scenario("again", 2.0));
    let out = tmp.path().join("again");
    let mine = out.join("notes.txt");
    let run = |force: bool| {
        let mut args = vec!["run", "--quiet", scenario.to_str().unwrap(), "--out"];
        args.push(out.to_str().unwrap());
        if force {
            args.push("--force");
        }
        run_shoal(&args)
    };
    assert!(run(false).status.success());
    std::fs::write(&mine, "kept").unwrap();
    let first = std::fs::read(out.join("summary.json")).unwrap();
    let refused = run(false);
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("--force"), "{err}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), first);
    let forced = run(true);
    assert!(
        forced.status.success(),
        "{}",
        String::from_utf8_lossy(&forced.stderr)
    );
    // a fresh run: its own id, the recording reads, the user's file is untouched
    let summary = summary(&out);
    let before: serde_json::Value = serde_json::from_slice(&first).unwrap();
    assert_ne!(summary["run_id"], before["run_id"]);
    assert!(Recording::open(&out.join("recording.mcap")).is_ok());
    assert_eq!(std::fs::read_to_string(&mine).unwrap(), "kept");
}

/// The PM QoS CPU latency target in force now (µs; 2,000,000,000 when no
/// one asks for less).
fn cpu_latency_target_us() -> i32 {
    let mut b = [0u8; 4];
    use std::io::Read;
    std::fs::File::open("/dev/cpu_dma_latency")
        .and_then(|mut f| f.read_exact(&mut b))
        .expect("read /dev/cpu_dma_latency");
    i32::from_ne_bytes(b)
}

#[test]
fn idle_poll_holds_the_cpu_latency_at_zero_while_the_run_goes_and_lets_go_after() {
    let before = cpu_latency_target_us();
    let tmp = tempfile::tempdir().unwrap();
    let sc = write_scenario(tmp.path(), "s.toml", &small_scenario("poll", 3000.0));
    let out = tmp.path().join("r");
    let (mut child, _) = start_run(&sc, &out, &["--idle-poll"], 2 + 3 * 4 + 2);
    assert_eq!(cpu_latency_target_us(), 0, "held while the run goes");
    std::thread::sleep(Duration::from_millis(500));
    signal(child.id(), libc::SIGINT);
    assert_eq!(child.wait().unwrap().code(), Some(130));
    assert_eq!(cpu_latency_target_us(), before, "let go when the run ends");
}
