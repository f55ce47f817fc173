//! Supervision against processes that misbehave on purpose (the
//! `shoal-fixture` binary standing in for F1's sonar): one that crashes at
//! start, one that hangs in a step, one that ignores SIGTERM. Each run ends
//! the way it should, with the cause named, every child reaped and the
//! run's shared memory gone.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

use shoal_tests::*;

/// A bin dir of the real services, except that `shoal-sonar` is the fixture.
fn fixture_bin_dir(dir: &Path) -> PathBuf {
    let bins = dir.join("bin");
    std::fs::create_dir_all(&bins).unwrap();
    for e in std::fs::read_dir(bin_dir()).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        if name.starts_with("shoal-") && e.path().is_file() && !name.ends_with(".d") {
            std::os::unix::fs::symlink(e.path(), bins.join(&name)).unwrap();
        }
    }
    let sonar = bins.join("shoal-sonar");
    std::fs::remove_file(&sonar).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_shoal-fixture"), &sonar).unwrap();
    bins
}

/// Runs the paper scenario (`extra` appended) for `duration` s with F1's
/// sonar misbehaving as `what`; returns the output and F1's sonar log.
fn run_with_fixture(what: &str, extra: &str, duration: &str, more: &[&str]) -> (Output, String) {
    let tmp = tempfile::tempdir().unwrap();
    let bins = fixture_bin_dir(tmp.path());
    let paper = std::fs::read_to_string(repo_root().join("scenarios/paper.toml")).unwrap();
    let scenario = write_scenario(tmp.path(), "s.toml", &format!("{paper}\n{extra}\n"));
    let out = tmp.path().join("run");
    let mut args = vec![
        "run",
        "--quiet",
        "--duration",
        duration,
        "--bin-dir",
        bins.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(more);
    args.push(scenario.to_str().unwrap());
    let o = shoal()
        .args(&args)
        .env("SHOAL_FIXTURE", what)
        .env("SHOAL_FIXTURE_VEHICLE", "F1")
        .env("SHOAL_FIXTURE_REAL", bin_dir().join("shoal-sonar"))
        .output()
        .unwrap();
    // Nothing left behind, however the run ended.
    assert_domain_clean(
        wait_run_json(&out, Duration::ZERO)["run_id"]
            .as_str()
            .unwrap(),
    );
    let log = std::fs::read_to_string(out.join("logs/F1.sonar.log")).unwrap_or_default();
    (o, log)
}

#[test]
fn a_process_that_crashes_at_start_stops_the_run_with_its_exit_and_log() {
    let (o, _) = run_with_fixture("crash", "", "5", &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("F1/sonar")
            && err.contains("exit code 3")
            && err.contains("crashing at start"),
        "{err}"
    );
}

#[test]
fn a_process_that_keeps_crashing_is_restarted_max_restarts_times_then_the_run_stops() {
    let (o, _) = run_with_fixture(
        "crash",
        "[supervision]\npolicy = \"restart\"\nmax_restarts = 2\n",
        "5",
        &[],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("F1/sonar") && err.contains("exit code 3"),
        "{err}"
    );
    // Three lives: the first and two restarts, each one in the log.
    assert_eq!(err.matches("process died; restarted").count(), 2, "{err}");
}

#[test]
fn a_process_that_hangs_in_a_step_is_reported_by_name_and_killed() {
    let (o, _) = run_with_fixture("hang", "", "5", &["--tick-timeout", "3"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        // Stuck in its first step at or after 1 s (the sonar's phase is 40 ms).
        err.contains("no progress for 3 s at t = 1.04 s") && err.contains("F1/sonar"),
        "{err}"
    );
}

#[test]
fn a_process_that_ignores_sigterm_is_killed_at_the_end_and_the_run_succeeds() {
    let (o, log) = run_with_fixture("ignore-term", "", "3", &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(log.contains("ignoring SIGTERM"), "{log}");
}
