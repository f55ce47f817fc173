//! Soft real time, measured: realtime runs report deadline misses, step
//! times and per-hop latency (in summary.json and on the recorded `stats`
//! channel), and a third-party client (the official `iceoryx2` Python
//! package) reads a live run's channel.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Stdio;
use std::time::Duration;

use recordings::Recording;
use shoal_tests::*;

fn python_with_iceoryx2() -> std::process::Command {
    let mut py = std::process::Command::new(python_having(
        "iceoryx2",
        "pip install -r tests/requirements.txt",
    ));
    py.arg(repo_root().join("tests/python/live_truth.py"));
    py
}

#[test]
fn a_python_iceoryx2_client_reads_truth_from_a_live_run() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = write_scenario(tmp.path(), "live.toml", &small_scenario("live", 12.0));
    let out = tmp.path().join("live");
    let mut run = shoal()
        .args(["run", "--quiet", "--mode", "realtime", "--out"])
        .arg(&out)
        .arg(&scenario)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let client = python_with_iceoryx2()
        .arg(&out)
        .args(["F1", "--samples", "20", "--timeout", "11"])
        .output()
        .unwrap();
    let status = run.wait().unwrap();
    assert!(status.success(), "shoal run failed");
    assert!(
        client.status.success(),
        "python client: {}\n{}",
        String::from_utf8_lossy(&client.stdout),
        String::from_utf8_lossy(&client.stderr)
    );
    let got: serde_json::Value = serde_json::from_slice(&client.stdout).unwrap();
    let samples = got["samples"].as_array().unwrap();
    assert!(samples.len() >= 20);
    let run_id = wait_run_json(&out, Duration::from_secs(1))["run_id"]
        .as_str()
        .unwrap()
        .to_string();
    assert_eq!(got["service"], format!("shoal/{run_id}/F1/truth"));
    let mut last: Option<(u64, u64)> = None;
    for s in samples {
        let seq = s["seq"].as_u64().unwrap();
        let t = s["sim_time_ns"].as_u64().unwrap();
        if let Some((ls, lt)) = last {
            assert!(seq > ls && t > lt, "samples out of order: {s}");
        }
        last = Some((seq, t));
        let q = s["q_norm"].as_f64().unwrap();
        assert!(
            (q - 1.0).abs() < 1e-9,
            "attitude not a unit quaternion: {q}"
        );
        // F1 starts in its slot, 8 m behind and 4 m to port of L at 10 m depth,
        // and moves at most ~1.5 m/s.
        let p: Vec<f64> = s["position_ned_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let reach = 2.0 + 1.5 * t as f64 * 1e-9;
        assert!(
            (p[0] + 8.0).abs() < reach && (p[1] + 4.0).abs() < reach && (p[2] - 10.0).abs() < 2.0,
            "F1 is not where it should be: {p:?} at {t} ns"
        );
    }
    assert!(shoal_runtime::list_domain_files(&run_id).is_empty());
}

#[test]
fn an_outside_subscriber_still_attached_when_the_run_ends_sees_a_clean_end() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = write_scenario(tmp.path(), "end.toml", &small_scenario("end", 4.0));
    let out = tmp.path().join("end");
    let mut run = shoal()
        .args(["run", "--mode", "realtime", "--out"])
        .arg(&out)
        .arg(&scenario)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The client holds its subscriber past the run's end, as a viewer
    // left open would.
    let client = python_with_iceoryx2()
        .arg(&out)
        .args(["F1", "--samples", "5", "--timeout", "15", "--hold"])
        .output()
        .unwrap();
    let status = run.wait().unwrap();
    let mut err = String::new();
    use std::io::Read;
    run.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert!(status.success(), "shoal run failed: {err}");
    let client_err = String::from_utf8_lossy(&client.stderr);
    assert!(
        client.status.success(),
        "python client: {}\n{client_err}",
        String::from_utf8_lossy(&client.stdout)
    );
    for bad in ["corrupt", "already removed", "static storage"] {
        assert!(
            !client_err.to_lowercase().contains(bad),
            "the client saw an unclean end ({bad}):\n{client_err}"
        );
    }
    assert!(err.contains("outside node(s) still use"), "{err}");
    // The client was the last user: what remains of the run's domain is
    // stale now, and the next run's sweep (run here as it runs there)
    // removes all of it.
    let run_id = wait_run_json(&out, Duration::from_secs(1))["run_id"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(shoal_runtime::alive_nodes(&run_id).is_empty());
    assert!(shoal_runtime::stale_domains().contains(&run_id));
    shoal_runtime::sweep_stale_domains();
    assert_domain_clean(&run_id);
}

#[test]
fn a_realtime_run_reports_deadlines_steps_and_every_hop() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = write_scenario(tmp.path(), "rt.toml", &small_scenario("rt", 6.0));
    let out = tmp.path().join("rt");
    let o = run_shoal(&[
        "run",
        "--quiet",
        "--mode",
        "realtime",
        "--out",
        out.to_str().unwrap(),
        scenario.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    assert_eq!(s["mode"], "realtime");
    for kind in PROCESS_KINDS {
        assert!(
            s["deadline_misses"][kind].is_u64(),
            "no deadline misses for {kind}: {}",
            s["deadline_misses"]
        );
        let steps = s["step_us"][kind]["count"].as_u64().unwrap_or(0);
        assert!(steps >= 50, "{kind} stepped {steps} times in 6 s at 10 Hz");
        assert!(s["wake_late_us"][kind]["count"].as_u64().unwrap_or(0) >= 50);
    }
    // Every channel kind a process takes has its hop latency; the chain
    // sensor → thrust applied has its end-to-end latency.
    for kind in [
        "truth",
        "world",
        "nav",
        "sonar",
        "beacons",
        "leader_pose",
        "setpoint",
        "thrust",
        "stats",
    ] {
        let h = &s["latency_us"]["hops"][kind];
        assert!(
            h["count"].as_u64().unwrap_or(0) > 0,
            "no hop latency for {kind}: {h}"
        );
        let (p50, p99, max) = (
            h["p50"].as_f64().unwrap(),
            h["p99"].as_f64().unwrap(),
            h["max"].as_f64().unwrap(),
        );
        assert!(0.0 < p50 && p50 <= p99 && p99 <= max, "{kind}: {h}");
    }
    assert!(s["latency_us"]["end_to_end"]["count"].as_u64().unwrap() > 0);
    assert_chain_stages(&s);
    // The same statistics are in the recording, on the stats channel.
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    let stats = rec.samples::<ipc_types::ProcessStats>("/stats");
    let processes = s["processes"].as_u64().unwrap() as usize;
    let reporters: std::collections::BTreeSet<(String, String)> = stats
        .iter()
        .map(|p| {
            (
                ipc_types::str_of(&p.vehicle).to_string(),
                ipc_types::str_of(&p.process).to_string(),
            )
        })
        .collect();
    assert_eq!(
        reporters.len(),
        processes,
        "every process reports: {reporters:?}"
    );
    let plant = stats
        .iter()
        .filter(|p| ipc_types::str_of(&p.process) == "sim-plant")
        .max_by_key(|p| p.steps)
        .unwrap();
    let hops: Vec<&str> = plant.hops[..plant.hop_count as usize]
        .iter()
        .map(|h| ipc_types::str_of(&h.channel))
        .collect();
    assert!(hops.contains(&"thrust"), "sim-plant takes thrust: {hops:?}");
}

/// The stages of the sensor → thrust chain in `summary.json`, each with
/// figures (`latency_us.chain`).
fn assert_chain_stages(s: &serde_json::Value) {
    let chain = s["latency_us"]["chain"].as_array().unwrap();
    let stages: Vec<&str> = chain.iter().map(|c| c["stage"].as_str().unwrap()).collect();
    assert_eq!(
        stages,
        ["world", "perception", "planner", "mpc", "sim-plant"],
        "{chain:?}"
    );
    for c in chain {
        assert!(c["count"].as_u64().unwrap() > 0, "no chain through {c}");
        let (p50, p99, max) = (
            c["p50"].as_f64().unwrap(),
            c["p99"].as_f64().unwrap(),
            c["max"].as_f64().unwrap(),
        );
        assert!(0.0 < p50 && p50 <= p99 && p99 <= max, "{c}");
    }
    assert!(
        s["latency_us"]["frame_to_thrust"]["count"]
            .as_u64()
            .unwrap()
            > 0
    );
}

#[test]
fn a_dataflow_run_steps_each_stage_on_its_inputs_and_counts_the_deadlines_it_misses() {
    let tmp = tempfile::tempdir().unwrap();
    // F1's camera loses every frame from 2 to 6 s: its planner gets no
    // parent fix for 40 frames, and steps at its deadlines instead. F2's
    // plant is killed at 4 s and restarted, on the wall clock.
    let text = format!(
        "{}\n[supervision]\npolicy = \"restart\"\n\n[[faults]]\naction = \"drop\"\nvehicle = \"F1\"\nfrom_s = 2.0\nto_s = 6.0\nfraction = 1.0\n\n[[faults]]\naction = \"kill\"\nvehicle = \"F2\"\nprocess = \"sim-plant\"\nat_s = 4.0\n",
        small_scenario("df", 8.0)
    );
    let scenario = write_scenario(tmp.path(), "df.toml", &text);
    let out = tmp.path().join("df");
    let o = run_shoal(&[
        "run",
        "--quiet",
        "--mode",
        "dataflow",
        "--out",
        out.to_str().unwrap(),
        scenario.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    assert_eq!(s["mode"], "dataflow");
    assert_chain_stages(&s);
    // Every process ended on the run's SIGTERM as it should, its statistics
    // written: also the stages woken only by their inputs (once killed by
    // it on the spot, before iceoryx2's handler was installed).
    for kind in PROCESS_KINDS {
        let n = s["step_us"][kind]["count"].as_u64().unwrap_or(0);
        assert!(n > 0, "no statistics of {kind}: {}", s["step_us"]);
    }
    // The plant steps on its 10 Hz clock and again on each thrust, which it
    // applies when it comes: about twice its clock's 3 × 80 activations.
    let plant_steps = s["step_us"]["sim-plant"]["count"].as_u64().unwrap();
    assert!(plant_steps > 360, "sim-plant stepped {plant_steps} times");
    // Driven by data, thrust follows its frame within that frame; on phased
    // timers it takes a whole period (100 ms; see the realtime test).
    let e2e = s["latency_us"]["end_to_end"]["p50"].as_f64().unwrap();
    assert!(e2e < 50_000.0, "sensor -> thrust p50 {e2e} µs");
    // F1's planner missed its deadline on the frames without a fix...
    let missed = s["deadline_misses"]["planner"].as_u64().unwrap();
    assert!(missed >= 30, "planner deadline misses: {missed}");
    // ...and still stepped on each of them: F1's setpoints kept coming.
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    let during = rec
        .samples::<ipc_types::Setpoint>("/F1/setpoint")
        .iter()
        .filter(|p| (2_500_000_000..5_500_000_000).contains(&p.header.sim_time_ns))
        .count();
    assert!(
        during >= 25,
        "F1's planner published {during} setpoints in 3 s without a fix"
    );
    // The kill struck, and the plant came back.
    let events: Vec<(&str, &str)> = s["events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["event"].as_str().unwrap(),
                e["process"].as_str().unwrap_or(""),
            )
        })
        .collect();
    for want in [
        "fault_injected",
        "process_died",
        "process_restarted",
        "process_ready",
    ] {
        assert!(
            events.contains(&(want, "F2/sim-plant")),
            "no {want} for F2/sim-plant: {events:?}"
        );
    }
    assert_domain_clean(s["run_id"].as_str().unwrap());
}

/// A tmux server of its own (`-L`), killed when dropped, also on failure.
struct Tmux(String);

impl Tmux {
    fn cmd(&self) -> std::process::Command {
        let mut c = std::process::Command::new("tmux");
        c.args(["-L", &self.0]);
        c
    }

    fn screen(&self) -> String {
        let o = self
            .cmd()
            .args(["capture-pane", "-p", "-t", "top"])
            .output()
            .unwrap();
        String::from_utf8_lossy(&o.stdout).to_string()
    }

    fn alive(&self) -> bool {
        self.cmd()
            .args(["has-session", "-t", "top"])
            .stderr(Stdio::null())
            .status()
            .map(|s| s.success())
            .unwrap_or(false)
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.cmd().arg("kill-server").stderr(Stdio::null()).status();
    }
}

/// Polls `f` every 100 ms until it holds or `timeout` passes.
fn eventually(timeout: Duration, mut f: impl FnMut() -> bool) -> bool {
    let start = std::time::Instant::now();
    while start.elapsed() < timeout {
        if f() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    false
}

#[test]
fn shoal_top_shows_every_process_of_a_realtime_run_and_updates_under_a_terminal() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = write_scenario(tmp.path(), "top.toml", &small_scenario("top", 40.0));
    let out = tmp.path().join("top");
    let (mut run, run_id) = start_run(&scenario, &out, &["--mode", "realtime"], 10);

    // One snapshot as JSON: every process of the run, each stepping (once
    // each has published its first statistics, a second into the run).
    let once = || -> serde_json::Value {
        let o = shoal()
            .args(["top", "--once", "--json"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let stepping = |snap: &serde_json::Value| {
        let rows = snap["processes"].as_array().unwrap();
        Some(rows.len() as u64) == snap["processes_expected"].as_u64()
            && rows.iter().all(|r| r["steps"].as_u64() > Some(0))
            && snap["hops"]
                .as_array()
                .unwrap()
                .iter()
                .any(|h| h["channel"] == "truth")
    };
    let mut snap = once();
    let start = std::time::Instant::now();
    while !stepping(&snap) && start.elapsed() < Duration::from_secs(20) {
        snap = once();
    }
    assert!(stepping(&snap), "{snap}");
    assert_eq!(snap["run_id"], run_id.as_str());
    let expected = snap["processes_expected"].as_u64().unwrap();
    let rows = snap["processes"].as_array().unwrap();
    assert_eq!(snap["processes_running"].as_u64(), Some(expected));
    for r in rows {
        assert_eq!(r["state"], "running", "{r}");
        assert!(r["pid"].as_u64().is_some(), "{r}");
        assert!(r["rss_mib"].as_f64().unwrap() > 0.0, "{r}");
    }
    for kind in ["sim-plant", "planner", "mpc", "recorder", "world"] {
        assert!(
            rows.iter().any(|r| r["process"] == kind),
            "no {kind}: {snap}"
        );
    }

    // The live table under a pseudo-terminal: it shows the processes and
    // its simulated time moves on; q quits.
    let tmux = Tmux(format!("shoal-top-{}", std::process::id()));
    let top = format!(
        "{} top {}",
        bin_dir().join("shoal").display(),
        out.display()
    );
    let started = tmux
        .cmd()
        .args([
            "new-session",
            "-d",
            "-s",
            "top",
            "-x",
            "160",
            "-y",
            "60",
            &top,
        ])
        .status()
        .unwrap();
    assert!(started.success());
    assert!(
        eventually(Duration::from_secs(20), || {
            let s = tmux.screen();
            s.contains("processes") && s.contains("recorder") && s.contains("planner")
        }),
        "the table never showed: {}",
        tmux.screen()
    );
    let sim = |s: &str| -> Option<String> {
        s.split("sim ")
            .nth(1)
            .map(|r| r.split(' ').next().unwrap_or("").to_string())
    };
    let first = sim(&tmux.screen());
    assert!(first.is_some(), "{}", tmux.screen());
    assert!(
        eventually(Duration::from_secs(20), || sim(&tmux.screen()) != first),
        "the table never updated from sim {first:?}: {}",
        tmux.screen()
    );
    let quit = tmux
        .cmd()
        .args(["send-keys", "-t", "top", "q"])
        .status()
        .unwrap();
    assert!(quit.success());
    assert!(
        eventually(Duration::from_secs(10), || !tmux.alive()),
        "q did not quit"
    );

    signal(run.id(), libc::SIGINT);
    let _ = run.wait();
    assert_domain_clean(&run_id);
}
