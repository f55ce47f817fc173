//! The restart policy with real processes: each kind of process of the paper
//! scenario is killed (SIGKILL) at a pseudo-random time, 20 trials in all.
//! Every run finishes with zero collisions, the gap is in the events channel
//! of the recording and in summary.json, and nothing is left behind: no
//! process of the run, no shared memory of its domain.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ipc_types::{EventKind, Sample};
use std::time::Duration;

use recordings::Recording;
use shoal_tests::*;

const VEHICLES: [&str; 5] = ["L", "F1", "F2", "F3", "F4"];
/// Simulated seconds per trial: the whole passage (the leader is through it
/// at about 90 s) and the formation closing up behind it.
const DURATION_S: f64 = 120.0;

/// splitmix64: the trials' pseudo-random choices, from the trial number.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Trial `i`: which process dies and when.
fn trial_fault(i: u64) -> (String, &'static str, f64) {
    let kind = PROCESS_KINDS[(i % PROCESS_KINDS.len() as u64) as usize];
    // The world and the recorder are the run's; the leader has no camera.
    let vehicles: &[&str] = match kind {
        "world" | "recorder" => &["run"],
        "camera-pose" => &VEHICLES[1..],
        _ => &VEHICLES,
    };
    let vehicle = vehicles[(mix(i) % vehicles.len() as u64) as usize].to_string();
    // Anywhere from just after the start to near the end, on a tick.
    let at_s = 2.0 + ((mix(i ^ 0xABCD) % 5_000) as f64 / 5_000.0) * (DURATION_S - 10.0);
    (vehicle, kind, (at_s * 50.0).round() / 50.0)
}

fn trial(i: u64) {
    let (vehicle, kind, at_s) = trial_fault(i);
    let label = format!("{vehicle}/{kind}");
    let tmp = tempfile::tempdir().unwrap();
    let paper = std::fs::read_to_string(repo_root().join("scenarios/paper.toml")).unwrap();
    let text = format!(
        "{paper}\n[supervision]\npolicy = \"restart\"\n\n[[faults]]\naction = \"kill\"\nvehicle = \"{vehicle}\"\nprocess = \"{kind}\"\nat_s = {at_s}\n"
    );
    let scenario = write_scenario(tmp.path(), "restart.toml", &text);
    let out = tmp.path().join("run");
    let o = run_shoal(&[
        "run",
        "--quiet",
        "--duration",
        &DURATION_S.to_string(),
        "--out",
        out.to_str().unwrap(),
        scenario.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "trial {i} ({label} at {at_s} s): {err}");

    // Nothing left behind.
    assert_domain_clean(
        wait_run_json(&out, Duration::ZERO)["run_id"]
            .as_str()
            .unwrap(),
    );

    // The run went on safely, to the end.
    let summary = summary(&out);
    assert_eq!(
        summary["safety"]["collisions"], 0,
        "trial {i} ({label} at {at_s} s): {}",
        summary["safety"]
    );
    assert!((summary["sim_time_s"].as_f64().unwrap() - DURATION_S).abs() < 1e-6);

    // The gap, in summary.json: fault, death, restart, ready — in that order.
    assert_eq!(
        events_of(&summary, &label),
        KILLED_AND_RESTARTED,
        "trial {i} ({label})"
    );

    // ...and in the recording's events channel, even when the recorder was
    // the one killed (the events channel keeps a history for it).
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    assert!(!rec.truncated(), "trial {i}: the recording is not whole");
    let events = rec.samples::<ipc_types::Event>("/events");
    let kinds: Vec<EventKind> = events
        .iter()
        .filter(|e| ipc_types::str_of(&e.process) == label)
        .filter_map(|e| EventKind::from_code(e.kind))
        .collect();
    assert_eq!(
        kinds,
        [
            EventKind::FaultInjected,
            EventKind::ProcessDied,
            EventKind::ProcessRestarted,
            EventKind::ProcessReady
        ],
        "trial {i} ({label}): /events"
    );
    let died = events
        .iter()
        .find(|e| e.kind == EventKind::ProcessDied as u32)
        .unwrap();
    assert_eq!(died.signal, libc::SIGKILL);
    let stamp = died.header().sim_time_ns as f64 / 1e9;
    assert!(
        (stamp - at_s).abs() < 0.2,
        "trial {i}: died at {stamp} s, killed at {at_s} s"
    );
    // The recording goes on after the gap, to the end.
    let truth = rec.samples::<ipc_types::Truth>("/L/truth");
    assert!(truth.last().unwrap().header.sim_time_ns as f64 / 1e9 > DURATION_S - 0.5);
    eprintln!("trial {i}: {label} killed at {at_s} s: finished, 0 collisions");
}

#[test]
fn every_kind_of_process_killed_and_restarted_trials_0_to_9() {
    for i in 0..10 {
        trial(i);
    }
}

#[test]
fn every_kind_of_process_killed_and_restarted_trials_10_to_19() {
    for i in 10..20 {
        trial(i);
    }
}
