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
fn spawn_over_hosts(
    net: &TestNet,
    scenario: &Path,
    hosts: &Path,
    out: &Path,
    extra: &[&str],
) -> Child {
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
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Runs `scenario` on one host into `dir/one`, then over the `k` hosts of a
/// fresh [`TestNet`] into `dir/hosts`, calling `during` once the run over
/// hosts is under way (started with `extra` arguments); checks both
/// recordings hold the same messages, the summaries agree, and every host
/// is left clean.
fn one_host_and_k_hosts(
    dir: &Path,
    scenario: &Path,
    k: usize,
    extra: &[&str],
    during: impl FnOnce(&TestNet),
) {
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
    let mut child = spawn_over_hosts(&net, scenario, &hosts_toml, &spread, extra);
    wait_child_run_json(&mut child, &spread, Duration::from_secs(30));
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
    one_host_and_k_hosts(tmp.path(), &paper, 2, &[], |_| {});
}

/// `tests/python/outside_client.py` (PyPI `eclipse-zenoh`) run from host
/// `from`'s namespace against `endpoint` with `args`; its JSON report.
fn outside_client(net: &TestNet, from: usize, endpoint: &str, args: &[&str]) -> serde_json::Value {
    let py = std::env::var("SHOAL_PYTHON").unwrap_or_else(|_| "python3".into());
    let mut c = net.in_host(from, &py);
    c.arg(repo_root().join("tests/python/outside_client.py"))
        .args(["--connect", endpoint])
        .args(args);
    report_of(c, "outside_client.py")
}

#[test]
fn an_outside_client_can_neither_join_nor_drive_a_host_and_the_run_keeps_its_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_path_buf();
    let paper = repo_root().join("scenarios/paper.toml");
    // Certificates an intruder might hold: another deployment's, and one
    // of this deployment's that has expired.
    let foreign = dir.join("foreign");
    run_shoal_ok(&["certs", "--out", foreign.to_str().unwrap(), "--host", "h2"]);
    let expired = dir.join("expired");
    let made = |net: &TestNet| {
        std::fs::create_dir_all(&expired).unwrap();
        for f in ["ca.pem", "ca.key"] {
            std::fs::copy(net.certs_dir().join(f), expired.join(f)).unwrap();
        }
        run_shoal_ok(&[
            "certs",
            "--out",
            expired.to_str().unwrap(),
            "--host",
            "h2",
            "--valid-from",
            "-40",
            "--days",
            "30",
        ]);
    };
    let spread = dir.join("hosts");
    let log_dir = dir.clone();
    // Paced (200 s simulated in about 10 s) so that every attempt falls
    // within the run.
    one_host_and_k_hosts(&dir, &paper, 2, &["--pace", "20"], |net| {
        made(net);
        let run_id = wait_run_json(&spread, Duration::from_secs(5))["run_id"]
            .as_str()
            .unwrap()
            .to_string();
        let certs = net.certs().unwrap().to_path_buf();
        let path = |d: &Path, f: &str| d.join(f).display().to_string();
        let ca = path(&certs, "ca.pem");
        let h1 = net.endpoint(0);
        // A certificate of this deployment, another host's: the session
        // opens (TLS accepts it), but access control refuses it everything:
        // it reads nothing of the run, and its aborts, clock ticks and
        // world samples go nowhere (the run's messages stay the one-host
        // run's, checked after).
        let (cert, key) = (path(&certs, "h2.pem"), path(&certs, "h2.key"));
        let r = outside_client(
            net,
            1,
            &h1,
            &[
                "--ca",
                &ca,
                "--cert",
                &cert,
                "--key",
                &key,
                "--run",
                &run_id,
                "--seconds",
                "3",
            ],
        );
        assert_eq!(r["opened"], true, "{r}");
        assert_eq!(r["published"].as_array().unwrap().len(), 3, "{r}");
        assert_eq!(
            r["received"], 0,
            "another host's certificate read the run: {r}"
        );
        assert!(
            !spread.join("summary.json").exists(),
            "the run ended before the attempt did"
        );
        // No certificate, another deployment's, an expired one, plain TCP:
        // no session at all, and the agent names why.
        let (fc, fk) = (path(&foreign, "h2.pem"), path(&foreign, "h2.key"));
        let (ec, ek) = (path(&expired, "h2.pem"), path(&expired, "h2.key"));
        let cases = [
            (vec!["--ca", &ca], "peer sent no certificates"),
            (
                vec!["--ca", &ca, "--cert", &fc, "--key", &fk],
                "UnknownIssuer",
            ),
            (
                vec!["--ca", &ca, "--cert", &ec, "--key", &ek],
                "certificate expired",
            ),
        ];
        for (args, named) in cases {
            let mut args = args.clone();
            args.extend(["--run", &run_id, "--seconds", "1"]);
            let r = outside_client(net, 1, &h1, &args);
            assert_eq!(r["opened"], false, "{named}: {r}");
            let log = std::fs::read_to_string(log_dir.join("h1.agent.log")).unwrap();
            assert!(
                log.contains(named),
                "the agent does not name `{named}`:\n{log}"
            );
        }
        let tcp = net.endpoint_with(0, "tcp");
        let r = outside_client(net, 1, &tcp, &["--seconds", "1"]);
        assert_eq!(r["opened"], false, "plain TCP: {r}");
    });
    // The agents announced TLS and whom they answer.
    let log = std::fs::read_to_string(dir.join("h1.agent.log")).unwrap();
    assert!(
        log.contains("(TLS, mutual authentication") && log.contains("answers only coordinator"),
        "{log}"
    );
    assert!(!log.contains("aborted"), "{log}");
}

#[test]
fn twenty_five_vehicles_over_four_hosts_give_the_one_host_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let o = run_shoal_ok(&["gen", "--vehicles", "25", "--seed", "4"]);
    let mut text = String::from_utf8(o.stdout).unwrap();
    text = text.replacen("duration_s = ", "duration_s = 40.0\n# was: ", 1);
    let sc = write_scenario(tmp.path(), "g25.toml", &text);
    one_host_and_k_hosts(tmp.path(), &sc, 4, &[], |_| {});
}

#[test]
fn a_killed_agent_stops_the_run_on_every_host_with_the_cause_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (mut net, hosts_toml) = net_with_agents(dir, 2);
    let sc = write_scenario(dir, "long.toml", &small_scenario("long", 600.0));
    let out = dir.join("run");
    let mut child = spawn_over_hosts(&net, &sc, &hosts_toml, &out, &[]);
    // Once the run is under way (its id is written, the hosts started).
    wait_child_run_json(&mut child, &out, Duration::from_secs(30));
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
    one_host_and_k_hosts(tmp.path(), &paper, 2, &[], |net| {
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
    let mut child = spawn_over_hosts(&net, &sc, &hosts_toml, &out, &[]);
    wait_child_run_json(&mut child, &out, Duration::from_secs(30));
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

/// `shoal run --quiet --mode MODE SCENARIO --hosts DIR/HOSTS --out OUT` in
/// the coordinator's namespace, to its end; panics with the agents' logs if
/// it fails.
fn run_over_hosts(net: &TestNet, dir: &Path, hosts: &str, mode: &str, scenario: &Path, out: &Path) {
    let o = net
        .in_ctl(&bin_dir().join("shoal"))
        .args(["run", "--quiet", "--mode", mode])
        .arg(scenario)
        .arg("--hosts")
        .arg(dir.join(hosts))
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    let agent_logs: String = (1..=net.hosts.len())
        .map(|h| std::fs::read_to_string(dir.join(format!("h{h}.agent.log"))).unwrap_or_default())
        .collect();
    assert!(
        o.status.success(),
        "shoal run --mode {mode} --hosts: {}\nagents:\n{agent_logs}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn a_realtime_run_over_two_hosts_starts_every_host_at_one_epoch_and_the_agents_serve_on() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Three hosts up; the first runs use two of them.
    let (net, _) = net_with_agents(dir, 3);
    let mut two = net.hosts_file();
    two.hosts.truncate(2);
    std::fs::write(dir.join("two.toml"), toml::to_string(&two).unwrap()).unwrap();
    let text = std::fs::read_to_string(repo_root().join("scenarios/paper.toml")).unwrap();
    let text = text.replacen("duration_s = ", "duration_s = 8.0\n# was: ", 1);
    let sc = write_scenario(dir, "paper8.toml", &text);
    let out = dir.join("rt");
    run_over_hosts(&net, dir, "two.toml", "realtime", &sc, &out);
    let s = summary(&out);
    assert_eq!(s["mode"], "realtime");
    // Every process of both hosts ran on the one clock: each stepped at
    // its rate through the run.
    for kind in PROCESS_KINDS {
        let steps = s["step_us"][kind]["count"].as_u64().unwrap_or(0);
        assert!(steps >= 60, "{kind} stepped {steps} times in 8 s at 10 Hz");
    }
    // The bridged channels' hop latencies are on the receiving host's
    // clock (stamps moved by the measured offsets), so they are positive.
    for kind in ["truth", "world"] {
        let h = &s["latency_us"]["hops"][kind];
        let (p50, p99, max) = (
            h["p50"].as_f64().unwrap(),
            h["p99"].as_f64().unwrap(),
            h["max"].as_f64().unwrap(),
        );
        assert!(0.0 < p50 && p50 <= p99 && p99 <= max, "{kind}: {h}");
    }
    // The clocks: both hosts share this kernel's monotonic clock, so the
    // true offset is 0, and it lies within the stated error at the start
    // and at the end.
    let hosts: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("hosts.json")).unwrap()).unwrap();
    for h in hosts["clock"]["hosts"].as_array().unwrap() {
        for at in ["start", "end"] {
            let (offset, error) = (
                h[at]["offset_us"].as_f64().unwrap(),
                h[at]["error_us"].as_f64().unwrap(),
            );
            assert!(offset.abs() <= error, "{}: {at}: {h}", h["host"]);
        }
    }
    // The world, on one host, saw the vehicles of the other live: its
    // last snapshot puts each vehicle near its last recorded truth.
    let rec = Recording::open(&out.join("recording.mcap")).unwrap();
    let world = rec.samples::<ipc_types::World>("/world");
    let Some(last) = world.last() else {
        // What the run left, to tell a lost host part from a lost channel.
        let counts: Vec<(String, usize)> = rec
            .channels()
            .iter()
            .map(|c| (c.topic.clone(), rec.topic_messages(&c.topic).count()))
            .collect();
        panic!(
            "no world snapshot; recording {counts:?}\nhosts.json {}\nsummary recording {} lost {}",
            std::fs::read_to_string(out.join("hosts.json")).unwrap_or_default(),
            s["recording"],
            s["samples_lost"]
        );
    };
    let names: Vec<String> = shoal_scenario::Scenario::from_toml(&text)
        .unwrap()
        .vehicles
        .iter()
        .map(|v| v.name.clone())
        .collect();
    assert_eq!(last.count as usize, names.len(), "{names:?}");
    for (i, name) in names.iter().enumerate() {
        let truth = rec.samples::<ipc_types::Truth>(&format!("/{name}/truth"));
        let t = truth.last().unwrap().position_ned_m;
        let w = last.vehicles[i].position_ned_m;
        let d = ((t[0] - w[0]).powi(2) + (t[1] - w[1]).powi(2) + (t[2] - w[2]).powi(2)).sqrt();
        assert!(d < 3.0, "{name}: the world has it {d:.2} m from its truth");
    }
    for h in 0..3 {
        assert_eq!(net.others_on(h), Vec::<i32>::new(), "orphans on h{}", h + 1);
        assert_eq!(net.shm_files(h).unwrap(), Vec::<PathBuf>::new());
    }
    // The same agents serve the next runs, lockstep then realtime again,
    // the last over all three hosts: a host that served runs before meets
    // a new coordinator beside one that never did.
    let short = write_scenario(dir, "short.toml", &small_scenario("short", 4.0));
    run_over_hosts(&net, dir, "two.toml", "lockstep", &short, &dir.join("ls"));
    run_over_hosts(
        &net,
        dir,
        "hosts.toml",
        "realtime",
        &short,
        &dir.join("rt3"),
    );
    let rt3: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("rt3/hosts.json")).unwrap())
            .unwrap();
    assert_eq!(rt3["hosts"].as_array().map(Vec::len), Some(3), "{rt3}");
}

/// A free UDP port on loopback (for an agent's QUIC listener).
fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn plain_tcp_only_when_asked_and_bad_certificates_named_before_anything_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let certs = dir.join("certs");
    let c = certs.to_str().unwrap();
    run_shoal_ok(&["certs", "--out", c, "--host", "h1=127.0.0.1"]);
    // An agent on plain TCP without --insecure: refused, and why.
    let o = run_shoal(&[
        "host",
        "--listen",
        "tcp/127.0.0.1:1",
        "--name",
        "h1",
        "--once",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("plain TCP") && err.contains("--insecure"),
        "{err}"
    );
    // Zenoh's tls/ link is refused with its reason.
    let o = run_shoal(&[
        "host",
        "--listen",
        "tls/127.0.0.1:1",
        "--name",
        "h1",
        "--certs",
        c,
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("2557"), "{err}");
    // An expired certificate: the agent does not start, and names it.
    let old = dir.join("old");
    std::fs::create_dir_all(&old).unwrap();
    for f in ["ca.pem", "ca.key"] {
        std::fs::copy(certs.join(f), old.join(f)).unwrap();
    }
    run_shoal_ok(&[
        "certs",
        "--out",
        old.to_str().unwrap(),
        "--host",
        "h1",
        "--valid-from",
        "-40",
        "--days",
        "30",
    ]);
    let o = run_shoal(&[
        "host",
        "--listen",
        "quic/127.0.0.1:1",
        "--name",
        "h1",
        "--certs",
        old.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("expired") && err.contains("h1.pem"),
        "{err}"
    );
    // A hosts file on plain TCP without --insecure: refused before any run.
    let sc = write_scenario(dir, "s.toml", &small_scenario("s", 5.0));
    let tcp = write_scenario(
        dir,
        "tcp.toml",
        "[[host]]\nname = \"h1\"\nendpoint = \"tcp/127.0.0.1:1\"\n",
    );
    let o = run_shoal(&[
        "run",
        sc.to_str().unwrap(),
        "--hosts",
        tcp.to_str().unwrap(),
        "--out",
        dir.join("refused").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("plain TCP") && err.contains("--insecure"),
        "{err}"
    );
    // QUIC without certificates for the coordinator: refused, and why.
    let port = free_udp_port();
    let endpoint = format!("quic/127.0.0.1:{port}");
    let bare = write_scenario(
        dir,
        "bare.toml",
        &format!("[[host]]\nname = \"h1\"\nendpoint = \"{endpoint}\"\n"),
    );
    let o = run_shoal(&[
        "run",
        sc.to_str().unwrap(),
        "--hosts",
        bare.to_str().unwrap(),
        "--out",
        dir.join("refused").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("[tls]"), "{err}");
    // A coordinator of another deployment: the agent refuses it (its log
    // names the certificate's fault), and the coordinator's error says
    // what its own handshake with the agent found.
    let mut agent = shoal()
        .args([
            "host", "--listen", &endpoint, "--name", "h1", "--certs", c, "--once",
        ])
        .args(["--work", dir.join("work").to_str().unwrap()])
        .stderr(std::fs::File::create(dir.join("agent.log")).unwrap())
        .spawn()
        .unwrap();
    let foreign = dir.join("foreign");
    run_shoal_ok(&[
        "certs",
        "--out",
        foreign.to_str().unwrap(),
        "--host",
        "h1=127.0.0.1",
    ]);
    let hosts = write_scenario(
        dir,
        "hosts.toml",
        &format!(
            "[[host]]\nname = \"h1\"\nendpoint = \"{endpoint}\"\n\n[tls]\ncerts = \"{}\"\n",
            foreign.display()
        ),
    );
    let o = run_shoal(&[
        "run",
        sc.to_str().unwrap(),
        "--hosts",
        hosts.to_str().unwrap(),
        "--out",
        dir.join("refused").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("not signed by our CA"),
        "{err}"
    );
    // The same agent serves a coordinator of its own deployment.
    let ours = write_scenario(
        dir,
        "ours.toml",
        &format!("[[host]]\nname = \"h1\"\nendpoint = \"{endpoint}\"\n\n[tls]\ncerts = \"{c}\"\n"),
    );
    let out = dir.join("run");
    run_shoal_ok(&[
        "run",
        sc.to_str().unwrap(),
        "--hosts",
        ours.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(agent.wait().unwrap().success());
    let log = std::fs::read_to_string(dir.join("agent.log")).unwrap();
    assert!(log.contains("UnknownIssuer"), "{log}");
    assert!(
        log.contains("a run starts") && log.contains("coordinator=coordinator"),
        "{log}"
    );
}
