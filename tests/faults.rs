//! Faults, with real processes: shoal itself killed with SIGKILL mid-run
//! leaves a recording that reads (and, if cut short, recovers), no orphan
//! processes, and a domain the next run removes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Stdio;
use std::time::{Duration, Instant};

use recordings::Recording;
use shoal_tests::*;

#[test]
fn sigkill_of_shoal_leaves_a_readable_recording_and_the_next_run_starts_clean() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("killed");
    let mut child = shoal()
        .args(["run", "--quiet", "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let run = wait_run_json(&out, Duration::from_secs(20));
    let run_id = run["run_id"].as_str().unwrap().to_string();
    // Let it record for a while (the paper run takes a few seconds).
    let rec_path = out.join("recording.mcap");
    let start = Instant::now();
    while std::fs::metadata(&rec_path).map(|m| m.len()).unwrap_or(0) < 200_000 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "nothing recorded"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    signal(child.id(), libc::SIGKILL);
    assert!(child.wait().is_ok());

    // The children notice their parent's death and stop; none is left.
    let start = Instant::now();
    while !processes_mentioning(&run_id).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "orphans of the killed run: {:?}",
            processes_mentioning(&run_id)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // Its domain is left behind (nobody was there to clean it) and known dead.
    assert!(
        shoal_runtime::stale_domains().contains(&run_id),
        "the killed run's domain is not reported stale"
    );

    // The recording reads (up to its last complete chunk if it was cut).
    let rec = Recording::open(&rec_path).unwrap();
    assert!(
        rec.messages().len() > 100,
        "{} messages",
        rec.messages().len()
    );
    let inspect = run_shoal(&["inspect", rec_path.to_str().unwrap()]);
    assert!(inspect.status.success());
    if rec.truncated() {
        assert!(String::from_utf8_lossy(&inspect.stdout).contains("TRUNCATED"));
        let fixed = tmp.path().join("fixed.mcap");
        let o = run_shoal(&[
            "recover",
            rec_path.to_str().unwrap(),
            "--out",
            fixed.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let whole = Recording::open(&fixed).unwrap();
        assert!(!whole.truncated());
        assert_eq!(whole.messages().len(), rec.messages().len());
    }

    // The next run removes the dead run's shared memory before it starts.
    let scenario = write_scenario(tmp.path(), "next.toml", &small_scenario("next", 2.0));
    let next = tmp.path().join("next");
    let o = run_shoal(&[
        "run",
        "--quiet",
        "--out",
        next.to_str().unwrap(),
        scenario.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let left = shoal_runtime::list_domain_files(&run_id);
    assert!(
        left.is_empty(),
        "the dead run's files survived the next run: {left:?}"
    );
}

fn paper_with(faults: &str) -> String {
    let paper = std::fs::read_to_string(repo_root().join("scenarios/paper.toml")).unwrap();
    format!("{paper}\n{faults}\n")
}

/// Runs the paper scenario with `faults` added (and `args`) into
/// `dir/name`; returns the output directory and what shoal said.
fn run_paper_with(
    dir: &std::path::Path,
    name: &str,
    faults: &str,
    args: &[&str],
) -> (std::path::PathBuf, std::process::Output) {
    let scenario = write_scenario(dir, &format!("{name}.toml"), &paper_with(faults));
    let out = dir.join(name);
    let mut all = vec!["run", "--quiet", "--out", out.to_str().unwrap()];
    all.extend_from_slice(args);
    all.push(scenario.to_str().unwrap());
    let o = run_shoal(&all);
    (out, o)
}

#[test]
fn a_stalled_process_holds_the_lockstep_clock_and_the_run_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let text = paper_with(
        "[[faults]]\naction = \"stall\"\nvehicle = \"F1\"\nprocess = \"mpc\"\nat_s = 10.0\nduration_s = 1.5\n",
    );
    let scenario = write_scenario(tmp.path(), "stall.toml", &text);
    let out = tmp.path().join("stall");
    let start = Instant::now();
    let o = run_shoal(&[
        "run",
        "--quiet",
        "--duration",
        "30",
        "--out",
        out.to_str().unwrap(),
        scenario.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        start.elapsed() >= Duration::from_millis(1500),
        "the stall did not hold the clock"
    );
    let s = summary(&out);
    let events = s["events"].as_array().unwrap();
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0]["action"], "stall");
    assert_eq!(events[0]["process"], "F1/mpc");
    assert_eq!(s["safety"]["collisions"], 0);
    // Lockstep: the stall changes nothing the vehicles do.
    let plain = tmp.path().join("plain");
    let o = run_shoal(&[
        "run",
        "--quiet",
        "--duration",
        "30",
        "--out",
        plain.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    let a = Recording::open(&out.join("recording.mcap")).unwrap();
    let b = Recording::open(&plain.join("recording.mcap")).unwrap();
    assert_eq!(
        a.samples::<ipc_types::Truth>("/F1/truth")
            .last()
            .map(|t| t.position_ned_m),
        b.samples::<ipc_types::Truth>("/F1/truth")
            .last()
            .map(|t| t.position_ned_m),
    );
}

#[test]
fn a_killed_process_under_the_abort_policy_stops_the_run_cleanly_with_the_cause() {
    let tmp = tempfile::tempdir().unwrap();
    let (out, o) = run_paper_with(
        tmp.path(),
        "kill",
        "[supervision]\npolicy = \"abort\"\n\n[[faults]]\naction = \"kill\"\nvehicle = \"F3\"\nprocess = \"sonar\"\nat_s = 12.0\n",
        &[],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("F3/sonar") && err.contains("SIGKILL"), "{err}");
    let run_id = wait_run_json(&out, Duration::ZERO)["run_id"]
        .as_str()
        .unwrap()
        .to_string();
    assert_domain_clean(&run_id);
    // What was recorded up to the kill reads.
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    let truth = rec.samples::<ipc_types::Truth>("/F3/truth");
    assert!(truth.last().unwrap().header.sim_time_ns >= 11_000_000_000);
}

#[test]
fn a_killed_recorder_loses_about_one_simulated_second() {
    // The recorder closes a chunk every simulated second: at the paper
    // run's ~50x real time, a wall-clock period would lose ~50 s of it.
    let tmp = tempfile::tempdir().unwrap();
    let (out, o) = run_paper_with(
        tmp.path(),
        "kill-recorder",
        "[[faults]]\naction = \"kill\"\nvehicle = \"run\"\nprocess = \"recorder\"\nat_s = 40.0\n",
        &["--duration", "60"],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("run/recorder") && err.contains("at t = 40.00 s"),
        "{err}"
    );
    let rec_path = out.join("recording.mcap");
    let fixed = tmp.path().join("fixed.mcap");
    run_shoal_ok(&[
        "recover",
        rec_path.to_str().unwrap(),
        "--out",
        fixed.to_str().unwrap(),
    ]);
    let rec = Recording::open(&fixed).unwrap();
    let last_ns = rec.messages().iter().map(|m| m.log_time).max().unwrap();
    let lost_s = 40.0 - last_ns as f64 * 1e-9;
    assert!(
        lost_s <= 1.5,
        "the recording ends at {:.2} s: {lost_s:.2} s of the run before the kill is lost",
        last_ns as f64 * 1e-9
    );
    // The recovered recording summarises on its own.
    let sum = tmp.path().join("summary-of-fixed");
    run_shoal_ok(&[
        "summarize",
        "--quiet",
        fixed.to_str().unwrap(),
        "--out",
        sum.to_str().unwrap(),
    ]);
    let s = summary(&sum);
    let t = s["sim_time_s"].as_f64().unwrap();
    assert!((38.0..=40.0).contains(&t), "summarised up to {t} s");
    assert_eq!(s["safety"]["collisions"], 0);
}
