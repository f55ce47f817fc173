//! Every case of `shoal bench ipc` as two real processes: the ponger echoes,
//! the pinger checks that each round trip came back with the round number
//! and payload it sent. No timing is asserted.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use shoal_bench_ipc::{Case, PeerReport, SIZES};

const PEER: &str = env!("CARGO_BIN_EXE_shoal-ipc-peer");
const ITERATIONS: u64 = 300;
const WARMUP: u64 = 25;

/// Kills and reaps a child that is still running when the test fails.
struct Reaped(Option<Child>);

impl Reaped {
    fn wait(&mut self, label: &str, deadline: Instant) -> std::process::Output {
        let mut child = self.0.take().expect("child already waited for");
        loop {
            if child.try_wait().expect("try_wait").is_some() {
                return child.wait_with_output().expect("collect output");
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let out = child.wait_with_output().expect("collect output");
                panic!(
                    "{label} hung; stderr:\n{}",
                    String::from_utf8_lossy(&out.stderr)
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Removes a case's iceoryx2 domain when the case ends, failed or not.
struct Domain(String);

impl Drop for Domain {
    fn drop(&mut self) {
        shoal_runtime::cleanup_domain(&self.0);
    }
}

fn spawn(role: &str, case: Case, size: usize, run_id: &str, samples: Option<&Path>) -> Reaped {
    let mut cmd = Command::new(PEER);
    cmd.args(["--role", role, "--case", case.name()])
        .args(["--size", &size.to_string()])
        .args(["--iterations", &ITERATIONS.to_string()])
        .args(["--warmup", &WARMUP.to_string()])
        .args(["--run-id", run_id, "--timeout-s", "20"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Some(p) = samples {
        cmd.arg("--samples").arg(p);
    }
    Reaped(Some(cmd.spawn().expect("start shoal-ipc-peer")))
}

#[test]
fn every_case_echoes_every_round_trip_intact_between_two_processes() {
    let dir = std::env::temp_dir().join(format!("shoal-bench-ipc-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (ci, case) in Case::ALL.into_iter().enumerate() {
        for size in SIZES {
            // Short: iceoryx2's event sockets live under the domain's directory
            // (`/dev/shm/shoal/<id>/shoal_<id>_<hash>.event`) and a Unix socket path
            // holds at most 107 bytes.
            let run_id = format!("bt{}-{ci}-{size}", std::process::id());
            let _domain = Domain(run_id.clone());
            let samples = dir.join(format!("{}-{size}.rtt", case.name()));
            let deadline = Instant::now() + Duration::from_secs(60);
            // The ponger starts second for half the cases: the handshake must
            // not depend on who comes first.
            let pong_first = size == 256;
            let (mut pong, mut ping) = if pong_first {
                let pong = spawn("pong", case, size, &run_id, None);
                (pong, spawn("ping", case, size, &run_id, Some(&samples)))
            } else {
                let ping = spawn("ping", case, size, &run_id, Some(&samples));
                (spawn("pong", case, size, &run_id, None), ping)
            };
            let ping_out = ping.wait(&format!("{} {size} pinger", case.name()), deadline);
            let pong_out = pong.wait(&format!("{} {size} ponger", case.name()), deadline);

            assert!(
                ping_out.status.success(),
                "{} {size} pinger failed: {}",
                case.name(),
                String::from_utf8_lossy(&ping_out.stderr)
            );
            assert!(
                pong_out.status.success(),
                "{} {size} ponger failed: {}",
                case.name(),
                String::from_utf8_lossy(&pong_out.stderr)
            );
            let report: PeerReport =
                serde_json::from_str(String::from_utf8_lossy(&ping_out.stdout).trim())
                    .expect("the pinger prints one JSON report");
            assert_eq!(report.case, case.name());
            assert_eq!(report.size, size);
            // Every round trip, warm-up included, came back with the round
            // number and the payload that was sent.
            assert_eq!(
                report.verified,
                WARMUP + ITERATIONS,
                "{} {size}",
                case.name()
            );
            let rtts: Vec<u64> = std::fs::read_to_string(&samples)
                .unwrap()
                .lines()
                .map(|l| l.parse().unwrap())
                .collect();
            assert_eq!(rtts.len() as u64, ITERATIONS, "{} {size}", case.name());
            assert!(rtts.iter().all(|&r| r > 0));
            assert!(report.min_ns <= report.p50_ns && report.p50_ns <= report.max_ns);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
