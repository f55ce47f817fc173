//! Runs spread over hosts that share nothing: each host a network namespace
//! with its own mount namespace (private /dev/shm and /tmp), joined by veth
//! links; only Zenoh crosses. Each run is compared with its one-host run.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::Duration;

use recordings::Recording;
use shoal::hosts::netns::TestNet;
use shoal_tests::*;

/// Every message's hash (topic, log time, payload without wall-clock
/// fields), sorted: the same set means the same messages on the same topics
/// at the same times. (The joined file interleaves the hosts' parts by time,
/// so its order among messages of one instant differs from one recorder's.)
/// Left out: the recorders' own `/stats`, since every host runs a recorder
/// of its own, which records (and counts) only its host's share.
fn message_set(out: &Path) -> (Vec<[u8; 32]>, usize) {
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    let stats = rec.channel("/stats").map(|c| c.id);
    let mut recorder_stats = 0;
    let mut h: Vec<[u8; 32]> = rec
        .message_hashes()
        .into_iter()
        .zip(rec.messages())
        .filter(|(_, m)| {
            let mine = Some(m.channel) == stats
                && recordings::decode::<ipc_types::ProcessStats>(&m.data)
                    .is_some_and(|s| s.process.starts_with(b"recorder\0"));
            recorder_stats += usize::from(mine);
            !mine
        })
        .map(|(h, _)| h)
        .collect();
    h.sort_unstable();
    (h, recorder_stats)
}

/// K hosts with their agents up, and the hosts file naming them.
fn net_with_agents(dir: &Path, k: usize) -> (TestNet, PathBuf) {
    let mut net = TestNet::create(k).unwrap();
    net.start_agents(&bin_dir(), dir).unwrap();
    let hosts_toml = dir.join("hosts.toml");
    std::fs::write(&hosts_toml, toml::to_string(&net.hosts_file()).unwrap()).unwrap();
    (net, hosts_toml)
}

/// `shoal run --quiet SCENARIO --hosts HOSTS --out OUT` in the
/// coordinator's namespace, started (output piped).
fn spawn_over_hosts(net: &TestNet, scenario: &Path, hosts: &Path, out: &Path) -> Child {
    net.in_ctl(&bin_dir().join("shoal"))
        .args([
            "run",
            "--quiet",
            scenario.to_str().unwrap(),
            "--hosts",
            hosts.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Runs `scenario` on one host into `dir/one`, then over the `k` hosts of a
/// fresh [`TestNet`] into `dir/hosts`, calling `during` once the run over
/// hosts is under way; checks both recordings hold the same messages, the
/// summaries agree, and every host is left clean.
fn one_host_and_k_hosts(dir: &Path, scenario: &Path, k: usize, during: impl FnOnce(&TestNet)) {
    let one = dir.join("one");
    run_shoal_ok(&[
        "run",
        "--quiet",
        scenario.to_str().unwrap(),
        "--out",
        one.to_str().unwrap(),
    ]);
    let (net, hosts_toml) = net_with_agents(dir, k);
    let spread = dir.join("hosts");
    let child = spawn_over_hosts(&net, scenario, &hosts_toml, &spread);
    wait_run_json(&spread, Duration::from_secs(30));
    during(&net);
    let o = child.wait_with_output().unwrap();
    let agent_logs: String = (1..=k)
        .map(|h| std::fs::read_to_string(dir.join(format!("h{h}.agent.log"))).unwrap_or_default())
        .collect();
    assert!(
        o.status.success(),
        "shoal run --hosts: {}\nagents:\n{agent_logs}",
        String::from_utf8_lossy(&o.stderr)
    );
    let ((a, ra), (b, rb)) = (message_set(&one), message_set(&spread));
    assert!(a.len() > 1000, "{} messages", a.len());
    assert!(
        ra > 0 && rb >= k * ra - k,
        "recorder stats: {ra} on one host, {rb} on {k}"
    );
    assert_eq!(a.len(), b.len(), "message counts differ");
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(
        differing, 0,
        "{differing} messages differ between one host and {k}"
    );
    let (sa, sb) = (summary(&one), summary(&spread));
    for key in ["safety", "formation"] {
        assert_eq!(sa[key], sb[key], "{key}");
    }
    assert_eq!(sb["recording"]["dropped"].as_u64(), Some(0));
    assert_eq!(
        sb["recording"]["messages"].as_u64(),
        Some((b.len() + rb) as u64),
        "the joined recording's count adds up the hosts'"
    );
    // Every host's part is in: its recorder log came back.
    for h in 1..=k {
        assert!(
            spread.join(format!("logs/run.recorder.h{h}.log")).is_file(),
            "no recorder log of h{h}"
        );
    }
    // Clean on every host: no process but the agent, no shared memory.
    for h in 0..k {
        assert_eq!(net.others_on(h), Vec::<i32>::new(), "orphans on h{}", h + 1);
        assert_eq!(
            net.shm_files(h).unwrap(),
            Vec::<std::path::PathBuf>::new(),
            "shared memory left on h{}",
            h + 1
        );
    }
}

#[test]
fn the_paper_scenario_over_two_hosts_gives_the_one_host_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let paper = repo_root().join("scenarios/paper.toml");
    one_host_and_k_hosts(tmp.path(), &paper, 2, |_| {});
}

#[test]
fn twenty_five_vehicles_over_four_hosts_give_the_one_host_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let o = run_shoal_ok(&["gen", "--vehicles", "25", "--seed", "4"]);
    let mut text = String::from_utf8(o.stdout).unwrap();
    text = text.replacen("duration_s = ", "duration_s = 40.0\n# was: ", 1);
    let sc = write_scenario(tmp.path(), "g25.toml", &text);
    one_host_and_k_hosts(tmp.path(), &sc, 4, |_| {});
}

#[test]
fn a_killed_agent_stops_the_run_on_every_host_with_the_cause_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (mut net, hosts_toml) = net_with_agents(dir, 2);
    let sc = write_scenario(dir, "long.toml", &small_scenario("long", 600.0));
    let out = dir.join("run");
    let child = spawn_over_hosts(&net, &sc, &hosts_toml, &out);
    // Once the run is under way (its id is written, the hosts started).
    wait_run_json(&out, Duration::from_secs(30));
    std::thread::sleep(Duration::from_secs(3));
    net.stop_agent(1, libc::SIGKILL, Duration::from_secs(5));
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("host h2 was lost"), "{err}");
    // The killed agent's processes went with it; the other host is clean.
    let start = std::time::Instant::now();
    while !net.others_on(1).is_empty() && start.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(net.others_on(1), Vec::<i32>::new(), "orphans on h2");
    assert_eq!(net.others_on(0), Vec::<i32>::new(), "orphans on h1");
    assert_eq!(net.shm_files(0).unwrap(), Vec::<std::path::PathBuf>::new());
}

#[test]
fn a_link_cut_for_three_seconds_pauses_the_run_and_it_ends_with_the_same_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let paper = repo_root().join("scenarios/paper.toml");
    let spread = tmp.path().join("hosts");
    one_host_and_k_hosts(tmp.path(), &paper, 2, |net| {
        std::thread::sleep(Duration::from_millis(1500));
        net.set_link(1, false).unwrap();
        std::thread::sleep(Duration::from_secs(3));
        // The run was still going when the link came back.
        assert!(
            !spread.join("recording.mcap").exists(),
            "the run ended first"
        );
        net.set_link(1, true).unwrap();
    });
}

#[test]
fn a_link_cut_past_the_lease_stops_every_host_cleanly_with_the_cause_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (net, hosts_toml) = net_with_agents(dir, 2);
    let sc = write_scenario(dir, "long.toml", &small_scenario("long", 600.0));
    let out = dir.join("run");
    let child = spawn_over_hosts(&net, &sc, &hosts_toml, &out);
    wait_run_json(&out, Duration::from_secs(30));
    std::thread::sleep(Duration::from_secs(2));
    net.set_link(1, false).unwrap();
    let o = child.wait_with_output().unwrap();
    net.set_link(1, true).unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("host h2 was lost"), "{err}");
    // The cut-off host's agent found the coordinator gone, stopped its
    // processes and removed its shared memory; it serves on.
    let start = std::time::Instant::now();
    while !net.others_on(1).is_empty() && start.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(100));
    }
    for h in 0..2 {
        assert_eq!(net.others_on(h), Vec::<i32>::new(), "orphans on h{}", h + 1);
        assert_eq!(
            net.shm_files(h).unwrap(),
            Vec::<PathBuf>::new(),
            "shared memory left on h{}",
            h + 1
        );
    }
    let log = std::fs::read_to_string(dir.join("h2.agent.log")).unwrap();
    assert!(log.contains("the coordinator is gone"), "{log}");
}
