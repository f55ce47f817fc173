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
