//! `shoal bench ipc`: raw iceoryx2, shoal's runtime and Unix-domain sockets,
//! ping-pong side by side in separate processes.
//!
//! Every case runs as two `shoal-ipc-peer` processes (from the
//! `shoal-bench-ipc` crate, found next to `shoal`): a ponger that echoes and
//! a pinger that times each round trip on the monotonic clock and checks
//! the echoed payload. The timed round trips of a case are split over
//! `--passes` passes, each in fresh processes and in alternating case order,
//! so a slow change of the machine's load hits every case alike; the
//! percentiles are computed over all of them. Afterwards one process per
//! size times shoal's per-sample steps alone (`--role costs`), which says
//! where the difference between shoal and raw iceoryx2 goes.
//!
//! Everything runs in a throwaway iceoryx2 domain (`bench-<hex>`), removed
//! at the end, on error and on Ctrl-C; every child is reaped.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use serde_json::{json, Value};

use crate::launch::os as sys;

/// The name of the peer binary (package `shoal-bench-ipc`).
const PEER_BIN: &str = "shoal-ipc-peer";

/// Every case of the peer binary, in table order.
const CASES: [&str; 6] = [
    "iox2-poll",
    "shoal-poll",
    "iox2-event",
    "iox2-waitset",
    "shoal-event",
    "uds",
];

/// The comparisons the closing table gives: (shoal case, baseline, checked
/// against the goal of < 10 % added at p50 and p99).
const RATIOS: [(&str, &str, bool); 5] = [
    ("shoal-poll", "iox2-poll", true),
    ("shoal-event", "iox2-waitset", true),
    ("shoal-event", "iox2-event", true),
    ("shoal-event", "uds", false),
    ("shoal-poll", "uds", false),
];

/// The goal of issue 7: shoal adds under 10 % to raw iceoryx2 at p50 and p99.
const GOAL_RATIO: f64 = 1.10;

/// Arguments of `shoal bench ipc`.
#[derive(Debug, clap::Args)]
pub struct IpcCmd {
    /// Timed round trips per case and size (split over the passes). The
    /// default takes ~15 s on an idle 2-core machine, under a minute on a busy one.
    #[arg(long, default_value_t = 20_000)]
    pub iterations: u64,
    /// Untimed round trips before the timed ones, in every pass.
    #[arg(long, default_value_t = 1_000)]
    pub warmup: u64,
    /// Sample sizes in bytes, comma-separated: 256 (sent by value, as a
    /// service's small samples are), 4096 (written and read in place, as the
    /// services move every sample that large), 262144 and 1048576 (a camera
    /// frame's sizes, in place).
    #[arg(long, value_delimiter = ',', default_values_t = shoal_bench_ipc::SIZES)]
    pub sizes: Vec<usize>,
    /// Cases to run, comma-separated (default: all). iox2-poll / iox2-event /
    /// iox2-waitset: raw iceoryx2 polling / blocking on a Listener / blocking
    /// in a WaitSet; shoal-poll / shoal-event: shoal's runtime ports polling /
    /// blocking in a WaitSet on the runtime's wake event; uds: Unix socket.
    #[arg(long, value_delimiter = ',', value_parser = clap::builder::PossibleValuesParser::new(CASES))]
    pub cases: Vec<String>,
    /// Passes over all cases; each runs its share of the round trips in
    /// fresh processes.
    #[arg(long, default_value_t = 2)]
    pub passes: u64,
    /// CPUs the pinger and the ponger are pinned to, e.g. `0,1`.
    #[arg(long, value_delimiter = ',', default_values_t = [0usize, 1])]
    pub cpus: Vec<usize>,
    /// Let the scheduler place the peers (no pinning).
    #[arg(long)]
    pub no_pin: bool,
    /// Also write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Directory holding `shoal-ipc-peer` (default: next to `shoal`).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// Longest one pinger/ponger pair may run, s.
    #[arg(long, default_value_t = 120.0)]
    pub case_timeout: f64,
    /// Skip the per-sample cost breakdown.
    #[arg(long)]
    pub no_costs: bool,
}

/// Percentiles of one case × size, µs.
#[derive(Debug, Clone)]
struct Stats {
    case: String,
    size: usize,
    count: usize,
    /// Involuntary context switches of both peers during the timed rounds.
    preempted: Option<u64>,
    p50: f64,
    p99: f64,
    p999: f64,
    max: f64,
    mean: f64,
}

impl Stats {
    /// Nearest-rank percentiles of round trips given in ns.
    fn of(case: &str, size: usize, mut ns: Vec<u64>, preempted: Option<u64>) -> Option<Self> {
        if ns.is_empty() {
            return None;
        }
        ns.sort_unstable();
        let n = ns.len();
        let q = |p: f64| {
            let rank = ((p * n as f64).ceil() as usize).clamp(1, n);
            ns[rank - 1] as f64 / 1e3
        };
        Some(Self {
            case: case.to_string(),
            size,
            count: n,
            preempted,
            p50: q(0.5),
            p99: q(0.99),
            p999: q(0.999),
            max: ns[n - 1] as f64 / 1e3,
            mean: ns.iter().map(|&v| v as f64).sum::<f64>() / n as f64 / 1e3,
        })
    }

    fn to_json(&self) -> Value {
        json!({
            "case": self.case, "size": self.size, "wait": wait_of(&self.case),
            "count": self.count, "preempted": self.preempted, "p50_us": self.p50, "p99_us": self.p99,
            "p999_us": self.p999, "max_us": self.max, "mean_us": self.mean,
        })
    }
}

fn wait_of(case: &str) -> &'static str {
    if case.ends_with("-poll") {
        "poll"
    } else {
        "block"
    }
}

/// Removes the bench domain and the work directory, whatever happens.
struct Cleanup {
    run_id: String,
    work: PathBuf,
}

impl Drop for Cleanup {
    fn drop(&mut self) {
        let removed = shoal_runtime::cleanup_domain(&self.run_id);
        tracing::debug!(removed, run_id = %self.run_id, "bench domain removed");
        let _ = std::fs::remove_dir_all(&self.work);
    }
}

/// A running peer: its process and where its stderr goes.
struct Peer {
    label: String,
    child: Child,
    log: PathBuf,
    exit: Option<std::process::ExitStatus>,
}

/// The peers of one case; whatever still runs when this is dropped is
/// terminated and reaped.
#[derive(Default)]
struct Peers(Vec<Peer>);

impl Peers {
    fn spawn(
        &mut self,
        label: &str,
        bin: &Path,
        args: &[String],
        stdout: Option<&Path>,
        log: &Path,
    ) -> anyhow::Result<()> {
        let err = File::create(log).with_context(|| format!("cannot create {}", log.display()))?;
        let out = match stdout {
            Some(p) => Stdio::from(
                File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
            ),
            None => Stdio::null(),
        };
        let mut cmd = Command::new(bin);
        cmd.args(args)
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(Stdio::from(err));
        sys::die_with_parent(&mut cmd);
        let child = cmd
            .spawn()
            .with_context(|| format!("cannot start {}", bin.display()))?;
        self.0.push(Peer {
            label: label.to_string(),
            child,
            log: log.to_path_buf(),
            exit: None,
        });
        Ok(())
    }

    /// Waits until every peer has exited successfully; fails as soon as one
    /// fails, on Ctrl-C / SIGTERM, or after `timeout`.
    fn wait_all(&mut self, timeout: Duration) -> anyhow::Result<()> {
        let start = Instant::now();
        loop {
            for p in &mut self.0 {
                if p.exit.is_none() {
                    p.exit = p
                        .child
                        .try_wait()
                        .with_context(|| format!("waiting for {}", p.label))?;
                }
                if let Some(status) = p.exit {
                    if !status.success() {
                        bail!(
                            "{} failed ({status}):\n{}",
                            p.label,
                            crate::launch::supervisor::tail(&p.log, 12)
                        );
                    }
                }
            }
            if self.0.iter().all(|p| p.exit.is_some()) {
                return Ok(());
            }
            if iceoryx2_bb_posix::signal::SignalHandler::termination_requested() {
                bail!("interrupted");
            }
            if start.elapsed() > timeout {
                let waiting: Vec<&str> = self
                    .0
                    .iter()
                    .filter(|p| p.exit.is_none())
                    .map(|p| p.label.as_str())
                    .collect();
                bail!(
                    "{} still running after {:.0} s (raise --case-timeout?)",
                    waiting.join(", "),
                    timeout.as_secs_f64()
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Peers {
    fn drop(&mut self) {
        for p in self.0.iter_mut().filter(|p| p.exit.is_none()) {
            sys::send_signal(p.child.id() as i32, libc::SIGTERM);
        }
        let start = Instant::now();
        for p in self.0.iter_mut().filter(|p| p.exit.is_none()) {
            while start.elapsed() < Duration::from_secs(1) {
                if let Ok(Some(s)) = p.child.try_wait() {
                    p.exit = Some(s);
                    break;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            if p.exit.is_none() {
                let _ = p.child.kill();
                p.exit = p.child.wait().ok();
            }
        }
    }
}

/// Everything the cases share.
struct Bench<'a> {
    cmd: &'a IpcCmd,
    bin: PathBuf,
    run_id: String,
    work: PathBuf,
}

impl Bench<'_> {
    fn common_args(&self, role: &str, case: &str, size: usize) -> Vec<String> {
        vec![
            "--role".into(),
            role.into(),
            "--case".into(),
            case.into(),
            "--size".into(),
            size.to_string(),
            "--run-id".into(),
            self.run_id.clone(),
        ]
    }

    /// Runs one pinger/ponger pair; returns the timed round trips (ns) and
    /// how often the kernel preempted either peer meanwhile.
    fn pair(
        &self,
        case: &str,
        size: usize,
        iterations: u64,
        pass: u64,
    ) -> anyhow::Result<(Vec<u64>, Option<u64>)> {
        let tag = format!("{case}-{size}-{pass}");
        let samples = self.work.join(format!("{tag}.rtt"));
        let report = self.work.join(format!("{tag}.json"));
        let pong_report = self.work.join(format!("{tag}.pong.json"));
        let mut peers = Peers::default();
        for (role, cpu) in [("pong", 1), ("ping", 0)] {
            let mut args = self.common_args(role, case, size);
            args.extend([
                "--iterations".into(),
                iterations.to_string(),
                "--warmup".into(),
                self.cmd.warmup.to_string(),
            ]);
            if !self.cmd.no_pin {
                args.extend(["--cpu".into(), self.cmd.cpus[cpu].to_string()]);
            }
            let stdout = if role == "ping" {
                args.extend(["--samples".into(), samples.display().to_string()]);
                report.as_path()
            } else {
                pong_report.as_path()
            };
            let log = self.work.join(format!("{tag}.{role}.log"));
            peers.spawn(
                &format!("{case} {size} B {role}er"),
                &self.bin,
                &args,
                Some(stdout),
                &log,
            )?;
        }
        peers.wait_all(Duration::from_secs_f64(self.cmd.case_timeout.max(1.0)))?;
        let text = std::fs::read_to_string(&report)
            .with_context(|| format!("the {case} pinger wrote no report"))?;
        let r: Value = serde_json::from_str(text.trim())
            .with_context(|| format!("the {case} pinger's report is not JSON: {text}"))?;
        let verified = r["verified"].as_u64().unwrap_or(0);
        if verified != iterations + self.cmd.warmup {
            bail!(
                "{case} {size} B: {verified} of {} round trips came back intact",
                iterations + self.cmd.warmup
            );
        }
        let rtts = std::fs::read_to_string(&samples)
            .with_context(|| format!("the {case} pinger wrote no samples"))?
            .lines()
            .map(|l| l.trim().parse::<u64>())
            .collect::<Result<Vec<_>, _>>()
            .with_context(|| format!("the {case} samples file is garbled"))?;
        if rtts.len() as u64 != iterations {
            bail!(
                "{case} {size} B: {} samples, expected {iterations}",
                rtts.len()
            );
        }
        let pong: Option<Value> = std::fs::read_to_string(&pong_report)
            .ok()
            .and_then(|t| serde_json::from_str(t.trim()).ok());
        let preempted = r["preempted"]
            .as_u64()
            .zip(pong.and_then(|p| p["preempted"].as_u64()))
            .map(|(a, b)| a + b);
        Ok((rtts, preempted))
    }

    /// Runs the cost probe for one size.
    fn costs(&self, size: usize) -> anyhow::Result<Value> {
        let out = self.work.join(format!("costs-{size}.json"));
        let log = self.work.join(format!("costs-{size}.log"));
        let mut args = self.common_args("costs", "shoal-poll", size);
        if !self.cmd.no_pin {
            args.extend(["--cpu".into(), self.cmd.cpus[0].to_string()]);
        }
        let mut peers = Peers::default();
        peers.spawn(
            &format!("cost probe {size} B"),
            &self.bin,
            &args,
            Some(&out),
            &log,
        )?;
        peers.wait_all(Duration::from_secs_f64(self.cmd.case_timeout.max(1.0)))?;
        let text = std::fs::read_to_string(&out).context("the cost probe wrote nothing")?;
        serde_json::from_str(text.trim()).with_context(|| format!("cost probe output: {text}"))
    }
}

/// Runs `shoal bench ipc`.
pub fn run(cmd: IpcCmd) -> anyhow::Result<()> {
    if cmd.iterations == 0 || cmd.passes == 0 {
        bail!("--iterations and --passes must be at least 1");
    }
    if cmd.cpus.len() != 2 {
        bail!("--cpus takes two CPUs: the pinger's and the ponger's, e.g. 0,1");
    }
    if let Some(s) = cmd
        .sizes
        .iter()
        .find(|s| !shoal_bench_ipc::SIZES.contains(*s))
    {
        bail!(
            "--sizes: {s} B is not a benchmark size ({})",
            shoal_bench_ipc::SIZES.map(|s| s.to_string()).join(", ")
        );
    }
    let cases: Vec<&str> = if cmd.cases.is_empty() {
        CASES.to_vec()
    } else {
        CASES
            .iter()
            .copied()
            .filter(|c| cmd.cases.iter().any(|x| x == c))
            .collect()
    };
    let bin_dir = crate::launch::bin_dir_or_default(cmd.bin_dir.clone())?;
    let bin = bin_dir.join(PEER_BIN);
    if !bin.is_file() {
        bail!(
            "{} not found; build it with `cargo build --release --workspace --bins` or pass --bin-dir",
            bin.display()
        );
    }
    // Ctrl-C / SIGTERM now set a flag that the waits below check, so the
    // peers are stopped and the domain removed instead of left behind.
    let _ = iceoryx2_bb_posix::signal::SignalHandler::termination_requested();

    let id = sys::random_id();
    let run_id = format!("bench-{id}");
    let work = std::env::temp_dir().join(format!("shoal-bench-ipc-{id}"));
    std::fs::create_dir_all(&work).with_context(|| format!("cannot create {}", work.display()))?;
    let _cleanup = Cleanup {
        run_id: run_id.clone(),
        work: work.clone(),
    };
    let bench = Bench {
        cmd: &cmd,
        bin,
        run_id,
        work,
    };

    let per_pass = cmd.iterations.div_ceil(cmd.passes);
    let load_before = crate::launch::os::load_average();
    let start = Instant::now();
    let mut rtts: Vec<Vec<Vec<u64>>> = vec![vec![Vec::new(); cases.len()]; cmd.sizes.len()];
    let mut preempted: Vec<Vec<Option<u64>>> = vec![vec![None; cases.len()]; cmd.sizes.len()];
    let total = cmd.passes as usize * cmd.sizes.len() * cases.len();
    let mut done = 0;
    let progress = std::io::IsTerminal::is_terminal(&std::io::stderr());
    for pass in 0..cmd.passes {
        for (si, &size) in cmd.sizes.iter().enumerate() {
            let mut order: Vec<usize> = (0..cases.len()).collect();
            if pass % 2 == 1 {
                order.reverse();
            }
            for ci in order {
                done += 1;
                if progress {
                    eprint!(
                        "\r  [{done}/{total}] {} {size} B (pass {})        ",
                        cases[ci],
                        pass + 1
                    );
                }
                let r = bench
                    .pair(cases[ci], size, per_pass, pass)
                    .with_context(|| format!("case {} {size} B", cases[ci]))?;
                rtts[si][ci].extend(r.0);
                preempted[si][ci] = match (preempted[si][ci], r.1) {
                    (Some(a), Some(b)) if pass > 0 => Some(a + b),
                    (_, b) if pass == 0 => b,
                    _ => None,
                };
            }
        }
    }
    if progress {
        eprint!("\r{:60}\r", "");
    }
    let costs: Vec<Value> = if cmd.no_costs {
        Vec::new()
    } else {
        // The breakdown is of the by-value path; the in-place sizes have no copy to break down.
        cmd.sizes
            .iter()
            .filter(|&&s| s <= 4096)
            .map(|&s| bench.costs(s))
            .collect::<anyhow::Result<_>>()?
    };
    let wall_s = start.elapsed().as_secs_f64();
    let load_after = crate::launch::os::load_average();

    let mut stats = Vec::new();
    for (si, &size) in cmd.sizes.iter().enumerate() {
        for (ci, case) in cases.iter().enumerate() {
            if let Some(s) = Stats::of(
                case,
                size,
                std::mem::take(&mut rtts[si][ci]),
                preempted[si][ci],
            ) {
                stats.push(s);
            }
        }
    }
    let ratios = ratios(&stats, &cmd.sizes);
    print_report(
        &cmd,
        &stats,
        &ratios,
        &costs,
        per_pass,
        load_before,
        load_after,
        wall_s,
    );

    if let Some(path) = &cmd.json {
        let doc = json!({
            "bench": "ipc",
            "settings": {
                "iterations_per_case": per_pass * cmd.passes,
                "passes": cmd.passes,
                "warmup_per_pass": cmd.warmup,
                "pinned_cpus": if cmd.no_pin { Value::Null } else { json!(cmd.cpus) },
                "cpus_online": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0),
            },
            "load_average": { "before": load_before, "after": load_after },
            "wall_time_s": wall_s,
            "results": stats.iter().map(Stats::to_json).collect::<Vec<_>>(),
            "ratios": ratios.iter().map(Ratio::to_json).collect::<Vec<_>>(),
            "costs_ns": costs,
        });
        std::fs::write(path, serde_json::to_string_pretty(&doc)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("{}", path.display());
    }
    Ok(())
}

/// One shoal case against one baseline at one size.
struct Ratio {
    size: usize,
    case: &'static str,
    baseline: &'static str,
    p50: f64,
    p99: f64,
    p999: f64,
    goal: bool,
}

impl Ratio {
    fn meets_goal(&self) -> bool {
        self.p50 < GOAL_RATIO && self.p99 < GOAL_RATIO
    }

    fn to_json(&self) -> Value {
        json!({
            "size": self.size, "case": self.case, "baseline": self.baseline,
            "p50": self.p50, "p99": self.p99, "p999": self.p999,
            "goal_applies": self.goal,
            "goal_met": if self.goal { json!(self.meets_goal()) } else { Value::Null },
        })
    }
}

fn ratios(stats: &[Stats], sizes: &[usize]) -> Vec<Ratio> {
    let find = |case: &str, size: usize| stats.iter().find(|s| s.case == case && s.size == size);
    let mut out = Vec::new();
    for &size in sizes {
        for (case, baseline, goal) in RATIOS {
            if let (Some(a), Some(b)) = (find(case, size), find(baseline, size)) {
                out.push(Ratio {
                    size,
                    case,
                    baseline,
                    p50: a.p50 / b.p50,
                    p99: a.p99 / b.p99,
                    p999: a.p999 / b.p999,
                    goal,
                });
            }
        }
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn print_report(
    cmd: &IpcCmd,
    stats: &[Stats],
    ratios: &[Ratio],
    costs: &[Value],
    per_pass: u64,
    load_before: Option<f64>,
    load_after: Option<f64>,
    wall_s: f64,
) {
    let load = |l: Option<f64>| l.map_or("?".to_string(), |v| format!("{v:.2}"));
    let pin = if cmd.no_pin {
        "not pinned".to_string()
    } else {
        format!(
            "pinger on CPU {}, ponger on CPU {}",
            cmd.cpus[0], cmd.cpus[1]
        )
    };
    println!(
        "shoal bench ipc: ping-pong round trip, µs ({} timed round trips per case in {} passes of {} + {} warm-up; {pin}; load average {} -> {}; {wall_s:.1} s)\n(preempted: times the kernel took the CPU from either peer during the timed round trips)",
        per_pass * cmd.passes,
        cmd.passes,
        per_pass,
        cmd.warmup,
        load(load_before),
        load(load_after),
    );
    println!();
    println!(
        "{:>8}  {:<13} {:<6} {:>9} {:>9} {:>9} {:>9} {:>9} {:>10}",
        "size", "case", "wait", "p50", "p99", "p99.9", "max", "mean", "preempted"
    );
    for s in stats {
        println!(
            "{:>8}  {:<13} {:<6} {:>9.2} {:>9.2} {:>9.2} {:>9.1} {:>9.2} {:>10}",
            size_label(s.size),
            s.case,
            wait_of(&s.case),
            s.p50,
            s.p99,
            s.p999,
            s.max,
            s.mean,
            s.preempted.map_or("?".to_string(), |p| p.to_string()),
        );
    }
    if !ratios.is_empty() {
        println!();
        println!(
            "{:>8}  {:<27} {:>6} {:>6} {:>6}  goal: shoal adds < 10 % at p50 and p99",
            "size", "ratio", "p50", "p99", "p99.9"
        );
        for r in ratios {
            let verdict = match (r.goal, r.meets_goal()) {
                (false, _) => "",
                (true, true) => "met",
                (true, false) => "MISSED",
            };
            println!(
                "{:>8}  {:<27} {:>6.2} {:>6.2} {:>6.2}  {verdict}",
                size_label(r.size),
                format!("{} / {}", r.case, r.baseline),
                r.p50,
                r.p99,
                r.p999
            );
        }
    }
    print_zero_copy(stats);
    if !costs.is_empty() {
        print_costs(costs);
    }
}

/// `256 B`, `4 KiB`, `256 KiB`, `1 MiB`.
fn size_label(size: usize) -> String {
    if size >= 1 << 20 && size.is_multiple_of(1 << 20) {
        format!("{} MiB", size >> 20)
    } else if size >= 1 << 10 && size.is_multiple_of(1 << 10) {
        format!("{} KiB", size >> 10)
    } else {
        format!("{size} B")
    }
}

/// The zero-copy goals (issue 18): shoal's blocking round trip against a
/// Unix socket's, at most this fraction, per size.
const ZERO_COPY_GOALS: [(usize, f64); 2] = [(256 * 1024, 0.5), (1024 * 1024, 0.25)];

/// The zero-copy lines of the report: shoal-event against uds at the large
/// sizes, and how flat polling stays from the smallest size to the largest.
fn print_zero_copy(stats: &[Stats]) {
    let find = |case: &str, size: usize| stats.iter().find(|s| s.case == case && s.size == size);
    let mut lines = Vec::new();
    for (size, goal) in ZERO_COPY_GOALS {
        if let (Some(a), Some(b)) = (find("shoal-event", size), find("uds", size)) {
            let r = a.p50 / b.p50;
            lines.push(format!(
                "{:>8}  shoal-event / uds p50 {r:.2} (goal ≤ {goal}: {})",
                size_label(size),
                if r <= goal { "met" } else { "MISSED" }
            ));
        }
    }
    let polls: Vec<&Stats> = stats.iter().filter(|s| s.case == "shoal-poll").collect();
    if let (Some(small), Some(large)) = (
        polls.iter().min_by_key(|s| s.size),
        polls.iter().max_by_key(|s| s.size),
    ) {
        if large.size > small.size {
            let r = large.p50 / small.p50;
            lines.push(format!(
                "{:>8}  shoal-poll p50 {} / {}: {r:.2} (goal ≤ 2, flat: {})",
                "",
                size_label(large.size),
                size_label(small.size),
                if r <= 2.0 { "met" } else { "MISSED" }
            ));
        }
    }
    if !lines.is_empty() {
        println!();
        println!("zero copy: the large sizes travel in place");
        for l in lines {
            println!("{l}");
        }
    }
}

/// The cost breakdown of `shoal-ipc-peer --role costs`.
fn print_costs(costs: &[Value]) {
    let f = |c: &Value, k: &str| c[k].as_f64().unwrap_or(f64::NAN);
    let size = |c: &Value| format!("{} B", f(c, "size"));
    println!();
    println!(
        "where a shoal hop's time goes: one publish -> take in one process, no wake-up, ns per hop"
    );
    println!(
        "{:>6}  {:>8} {:>13} {:>10} {:>10}  shoal with a per-type finite check (replica)",
        "size", "raw", "raw, limits", "shoal", "added"
    );
    for c in costs {
        println!(
            "{:>6}  {:>8.0} {:>13.0} {:>10.0} {:>10.0}  {:.0}",
            size(c),
            f(c, "hop_raw_ns"),
            f(c, "hop_raw_shoal_limits_ns"),
            f(c, "hop_shoal_ns"),
            f(c, "hop_shoal_ns") - f(c, "hop_raw_shoal_limits_ns"),
            f(c, "hop_shoal_fixed_ns"),
        );
    }
    println!(
        "{:>6}  {:>22} {:>12} {:>8} {:>8} {:>7} {:>7}   (ns per call)",
        "size", "is_finite (generated)", "plain loop", "mono_ns", "stamp_ns", "record", "copy"
    );
    for c in costs {
        println!(
            "{:>6}  {:>22.0} {:>12.0} {:>8.0} {:>8.0} {:>7.0} {:>7.0}",
            size(c),
            f(c, "is_finite_ns"),
            f(c, "finite_direct_ns"),
            f(c, "mono_ns_ns"),
            f(c, "stamp_ns_ns"),
            f(c, "record_ns"),
            f(c, "copy_ns"),
        );
    }
    for c in costs {
        println!(
            "{:>6}  hop stamps (stamp_ns, the counter between exact reads): {:.0} stamps each between two CLOCK_MONOTONIC reads, the farthest {:.0} ns outside them",
            size(c),
            f(c, "stamp_checked"),
            f(c, "stamp_off_ns"),
        );
    }
    for c in costs {
        let added = f(c, "hop_shoal_ns") - f(c, "hop_raw_shoal_limits_ns");
        println!(
            "{:>6}  shoal adds {added:.0} ns per hop; Sample::is_finite on publish and on take is {:.0} ns of it",
            size(c),
            2.0 * f(c, "is_finite_ns"),
        );
    }
}
