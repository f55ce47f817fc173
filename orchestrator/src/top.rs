//! `shoal top`: what a running run's processes are doing, from the run's
//! `stats` and `events` channels and from `/proc`. This module is the
//! model (pure: samples in, a [`Snapshot`] out) and its text rendering;
//! `cli::top` reads the channels, samples `/proc` and draws it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ipc_types::{str_of, Event, EventKind, ProcessStats};
use serde::Serialize;

/// One process of the run as `/proc` shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcSample {
    /// Process id.
    pub pid: u32,
    /// `--vehicle`.
    pub vehicle: String,
    /// `--process`.
    pub process: String,
    /// User + system CPU time so far, s.
    pub cpu_s: f64,
    /// Resident memory, KiB.
    pub rss_kib: u64,
    /// `--processes`: how many processes the run has.
    pub processes: Option<usize>,
    /// `--out` (the recorder's recording).
    pub out: Option<PathBuf>,
}

/// The value of `--flag` in a NUL-separated command line.
fn arg_of<'a>(args: &'a [&'a str], flag: &str) -> Option<&'a str> {
    args.iter()
        .position(|a| *a == flag)
        .and_then(|i| args.get(i + 1))
        .copied()
}

/// Parses one `/proc/PID` of a process of run `run_id`; `None` for any
/// other process (or one that has gone).
pub fn parse_proc(
    pid: u32,
    cmdline: &[u8],
    stat: &str,
    statm: &str,
    run_id: &str,
    ticks_per_s: f64,
    page_kib: u64,
) -> Option<ProcSample> {
    let text = std::str::from_utf8(cmdline).ok()?;
    let args: Vec<&str> = text.split('\0').collect();
    if arg_of(&args, "--run-id") != Some(run_id) {
        return None;
    }
    // `pid (comm) state ppid ... utime stime`: fields 14 and 15, counted
    // after the command name, which may hold spaces.
    let after = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    let rss_pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(ProcSample {
        pid,
        vehicle: arg_of(&args, "--vehicle")?.to_string(),
        process: arg_of(&args, "--process")?.to_string(),
        cpu_s: (utime + stime) / ticks_per_s,
        rss_kib: rss_pages * page_kib,
        processes: arg_of(&args, "--processes").and_then(|n| n.parse().ok()),
        out: arg_of(&args, "--out").map(PathBuf::from),
    })
}

/// Every live process of run `run_id` on this machine.
pub fn scan_procs(run_id: &str) -> Vec<ProcSample> {
    let ticks_per_s = crate::launch::os::clock_ticks_per_s();
    let page_kib = crate::launch::os::page_size() / 1024;
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in dir.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        let base = e.path();
        let (Ok(cmdline), Ok(stat), Ok(statm)) = (
            std::fs::read(base.join("cmdline")),
            std::fs::read_to_string(base.join("stat")),
            std::fs::read_to_string(base.join("statm")),
        ) else {
            continue;
        };
        if let Some(p) = parse_proc(pid, &cmdline, &stat, &statm, run_id, ticks_per_s, page_kib) {
            out.push(p);
        }
    }
    out.sort_by(|a, b| (&a.vehicle, &a.process).cmp(&(&b.vehicle, &b.process)));
    out
}

/// The ids of the runs whose processes are alive on this machine.
pub fn running_runs() -> Vec<String> {
    let mut ids = std::collections::BTreeSet::new();
    if let Ok(dir) = std::fs::read_dir("/proc") {
        for e in dir.flatten() {
            if let Ok(cmdline) = std::fs::read(e.path().join("cmdline")) {
                let text = String::from_utf8_lossy(&cmdline);
                let args: Vec<&str> = text.split('\0').collect();
                if let (Some(id), Some(_)) = (arg_of(&args, "--run-id"), arg_of(&args, "--process"))
                {
                    ids.insert(id.to_string());
                }
            }
        }
    }
    ids.into_iter().collect()
}

/// One row of the process table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// Vehicle (`run` for the world and the recorder).
    pub vehicle: String,
    /// Process kind.
    pub process: String,
    /// `running`, or `gone` (seen before, no process now).
    pub state: &'static str,
    /// Process id, while running.
    pub pid: Option<u32>,
    /// Steps so far.
    pub steps: u64,
    /// Steps per wall-clock second over the last interval.
    pub steps_per_s: Option<f64>,
    /// Step time median over the process's last publishing period, µs.
    pub step_p50_us: Option<f64>,
    /// Step time 99th percentile over the same period, µs.
    pub step_p99_us: Option<f64>,
    /// Realtime deadline misses so far.
    pub deadline_misses: u64,
    /// CPU over the last interval, % of one core.
    pub cpu_pct: Option<f64>,
    /// Resident memory, MiB.
    pub rss_mib: Option<f64>,
    /// Restarts so far (the run's events).
    pub restarts: u32,
    /// Input samples lost so far.
    pub lost: u64,
    /// Input samples rejected (non-finite) so far.
    pub rejected: u64,
}

/// One input channel kind over every process that reads it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HopRow {
    /// Channel kind (`truth`, `world`, ...).
    pub channel: String,
    /// Processes reading it.
    pub readers: usize,
    /// Samples taken, all readers.
    pub count: u64,
    /// Publish → take latency, the median of the readers' medians, µs.
    pub p50_us: f64,
    /// The worst reader's 99th percentile, µs.
    pub p99_us: f64,
    /// The largest, µs.
    pub max_us: f64,
}

/// The recorder's part.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecorderRow {
    /// Bytes of recording written so far.
    pub bytes: Option<u64>,
    /// Bytes per wall-clock second over the last interval.
    pub bytes_per_s: Option<f64>,
    /// Samples the recorder lost (its inputs' gaps).
    pub dropped: u64,
    /// Samples it refused (non-finite).
    pub rejected: u64,
}

/// What `shoal top` shows at one moment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Snapshot {
    /// The run.
    pub run_id: String,
    /// Simulated time of the newest statistics, s.
    pub sim_time_s: f64,
    /// Processes the run has (`--processes`), if known.
    pub processes_expected: Option<usize>,
    /// Processes running now.
    pub processes_running: usize,
    /// One row per process, by vehicle then kind.
    pub processes: Vec<Row>,
    /// Per input channel kind.
    pub hops: Vec<HopRow>,
    /// The recorder.
    pub recorder: RecorderRow,
    /// The latest events, newest last.
    pub events: Vec<String>,
}

type Key = (String, String);

/// The state `shoal top` keeps between two snapshots.
#[derive(Debug, Default)]
pub struct Top {
    run_id: String,
    stats: BTreeMap<Key, ProcessStats>,
    /// Steps and the wall time (s) at the previous snapshot.
    prev_steps: BTreeMap<Key, (u64, f64)>,
    /// CPU seconds and wall time (s) at the previous snapshot, per pid.
    prev_cpu: BTreeMap<u32, (f64, f64)>,
    prev_bytes: Option<(u64, f64)>,
    restarts: BTreeMap<Key, u32>,
    seen: std::collections::BTreeSet<Key>,
    events: Vec<String>,
}

impl Top {
    /// Nothing seen yet of run `run_id`.
    pub fn new(run_id: &str) -> Self {
        Self {
            run_id: run_id.to_string(),
            ..Self::default()
        }
    }

    /// A statistics sample arrived.
    pub fn stats(&mut self, s: &ProcessStats) {
        let key = (
            str_of(&s.vehicle).to_string(),
            str_of(&s.process).to_string(),
        );
        self.seen.insert(key.clone());
        self.stats.insert(key, *s);
    }

    /// An event arrived.
    pub fn event(&mut self, e: &Event) {
        let kind = EventKind::ALL.into_iter().find(|k| *k as u32 == e.kind);
        let who = str_of(&e.process).to_string();
        if kind == Some(EventKind::ProcessRestarted) {
            if let Some((v, p)) = who.split_once('/') {
                self.restarts
                    .insert((v.to_string(), p.to_string()), e.restarts);
            }
        }
        let name = kind.map_or("event", EventKind::name);
        let detail = str_of(&e.detail);
        self.events.push(format!(
            "{:.1} s {name} {who}{}{detail}",
            e.header.sim_time_ns as f64 * 1e-9,
            if detail.is_empty() { "" } else { ": " }
        ));
        let len = self.events.len();
        if len > 8 {
            self.events.drain(..len - 8);
        }
    }

    /// The snapshot at wall time `now_s` (any monotonic clock, s) with the
    /// processes `/proc` shows and the recording's size.
    pub fn snapshot(
        &mut self,
        now_s: f64,
        procs: &[ProcSample],
        recording_bytes: Option<u64>,
    ) -> Snapshot {
        let mut keys: std::collections::BTreeSet<Key> = self.seen.clone();
        for p in procs {
            keys.insert((p.vehicle.clone(), p.process.clone()));
        }
        let mut rows = Vec::new();
        for key in keys {
            let proc_ = procs
                .iter()
                .find(|p| p.vehicle == key.0 && p.process == key.1);
            let s = self.stats.get(&key);
            let steps = s.map_or(0, |s| s.steps);
            // A rate needs statistics at both ends of the interval.
            let steps_per_s = match (s, self.prev_steps.get(&key)) {
                (Some(_), Some((n, t))) if now_s > *t => {
                    Some(steps.saturating_sub(*n) as f64 / (now_s - t))
                }
                _ => None,
            };
            if s.is_some() {
                self.prev_steps.insert(key.clone(), (steps, now_s));
            }
            let cpu_pct = proc_.and_then(|p| {
                let prev = self.prev_cpu.insert(p.pid, (p.cpu_s, now_s));
                prev.and_then(|(c, t)| {
                    (now_s > t).then(|| 100.0 * (p.cpu_s - c).max(0.0) / (now_s - t))
                })
            });
            let us = |ns: u64| (ns > 0).then(|| ns as f64 / 1e3);
            rows.push(Row {
                state: if proc_.is_some() { "running" } else { "gone" },
                pid: proc_.map(|p| p.pid),
                steps,
                steps_per_s,
                step_p50_us: s.and_then(|s| us(s.recent_step_p50_ns)),
                step_p99_us: s.and_then(|s| us(s.recent_step_p99_ns)),
                deadline_misses: s.map_or(0, |s| s.deadline_misses),
                cpu_pct,
                rss_mib: proc_.map(|p| p.rss_kib as f64 / 1024.0),
                restarts: self.restarts.get(&key).copied().unwrap_or(0),
                lost: s.map_or(0, |s| s.lost),
                rejected: s.map_or(0, |s| s.rejected),
                vehicle: key.0,
                process: key.1,
            });
        }
        let recorder = self
            .stats
            .iter()
            .find(|((_, p), _)| p == "recorder")
            .map(|(_, s)| *s);
        let bytes_per_s = match (recording_bytes, self.prev_bytes) {
            (Some(b), Some((pb, pt))) if now_s > pt => {
                Some(b.saturating_sub(pb) as f64 / (now_s - pt))
            }
            _ => None,
        };
        self.prev_bytes = recording_bytes.map(|b| (b, now_s));
        Snapshot {
            run_id: self.run_id.clone(),
            sim_time_s: self
                .stats
                .values()
                .map(|s| s.header.sim_time_ns)
                .max()
                .unwrap_or(0) as f64
                * 1e-9,
            processes_expected: procs.iter().find_map(|p| p.processes),
            processes_running: procs.len(),
            processes: rows,
            hops: hops(self.stats.values()),
            recorder: RecorderRow {
                bytes: recording_bytes,
                bytes_per_s,
                dropped: recorder.map_or(0, |s| s.lost),
                rejected: recorder.map_or(0, |s| s.rejected),
            },
            events: self.events.clone(),
        }
    }
}

/// Per input channel kind, over the processes' latest statistics.
fn hops<'a>(stats: impl Iterator<Item = &'a ProcessStats>) -> Vec<HopRow> {
    let mut by: BTreeMap<String, Vec<ipc_types::HopStats>> = BTreeMap::new();
    for s in stats {
        for h in s.hops.iter().take(s.hop_count as usize) {
            by.entry(str_of(&h.channel).to_string())
                .or_default()
                .push(*h);
        }
    }
    by.into_iter()
        .map(|(channel, hs)| {
            let mut p50: Vec<u64> = hs.iter().map(|h| h.p50_ns).collect();
            p50.sort_unstable();
            HopRow {
                channel,
                readers: hs.len(),
                count: hs.iter().map(|h| h.count).sum(),
                p50_us: p50[p50.len() / 2] as f64 / 1e3,
                p99_us: hs.iter().map(|h| h.p99_ns).max().unwrap_or(0) as f64 / 1e3,
                max_us: hs.iter().map(|h| h.max_ns).max().unwrap_or(0) as f64 / 1e3,
            }
        })
        .collect()
}

/// A figure or a dash.
pub fn fmt_opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.decimals$}"))
}

/// The column titles of the process table.
pub const COLUMNS: [&str; 12] = [
    "vehicle", "process", "state", "pid", "steps/s", "p50 µs", "p99 µs", "misses", "cpu %",
    "rss MiB", "restarts", "lost",
];

/// A row's cells, in [`COLUMNS`] order.
pub fn cells(r: &Row) -> [String; 12] {
    [
        r.vehicle.clone(),
        r.process.clone(),
        r.state.to_string(),
        r.pid.map_or_else(|| "-".to_string(), |p| p.to_string()),
        fmt_opt(r.steps_per_s, 1),
        fmt_opt(r.step_p50_us, 1),
        fmt_opt(r.step_p99_us, 1),
        r.deadline_misses.to_string(),
        fmt_opt(r.cpu_pct, 1),
        fmt_opt(r.rss_mib, 1),
        r.restarts.to_string(),
        (r.lost + r.rejected).to_string(),
    ]
}

/// The header line.
pub fn headline(s: &Snapshot) -> String {
    format!(
        "run {}  sim {:.1} s  processes {}/{}  recorder {} written, {}/s, {} dropped",
        s.run_id,
        s.sim_time_s,
        s.processes_running,
        s.processes_expected
            .map_or_else(|| "?".to_string(), |n| n.to_string()),
        s.recorder
            .bytes
            .map_or_else(|| "-".to_string(), human_bytes),
        s.recorder
            .bytes_per_s
            .map_or_else(|| "-".to_string(), |b| human_bytes(b as u64)),
        s.recorder.dropped
    )
}

fn human_bytes(b: u64) -> String {
    match b {
        b if b >= 1 << 30 => format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64),
        b if b >= 1 << 20 => format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64),
        b if b >= 1 << 10 => format!("{:.1} KiB", b as f64 / 1024.0),
        b => format!("{b} B"),
    }
}

/// The whole snapshot as plain text (`--once`).
pub fn text(s: &Snapshot) -> String {
    let mut rows: Vec<[String; 12]> = vec![COLUMNS.map(String::from)];
    rows.extend(s.processes.iter().map(cells));
    let widths: Vec<usize> = (0..12)
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut out = headline(s);
    out.push('\n');
    for r in &rows {
        let line: Vec<String> = r
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c:<w$}"))
            .collect();
        out.push_str(line.join("  ").trim_end());
        out.push('\n');
    }
    out.push_str("\nhop (input)        readers  samples    p50 µs    p99 µs    max µs\n");
    for h in &s.hops {
        out.push_str(&format!(
            "{:<18} {:>7}  {:>7}  {:>8.1}  {:>8.1}  {:>8.1}\n",
            h.channel, h.readers, h.count, h.p50_us, h.p99_us, h.max_us
        ));
    }
    for e in &s.events {
        out.push_str(e);
        out.push('\n');
    }
    out
}

/// The run named by `run` (an output directory with `run.json`, or a run
/// id), or the one run running here.
pub fn resolve_run(run: Option<&Path>) -> anyhow::Result<String> {
    if let Some(r) = run {
        let json = r.join("run.json");
        if json.is_file() {
            let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json)?)?;
            return v["run_id"]
                .as_str()
                .map(String::from)
                .ok_or_else(|| anyhow::anyhow!("{} names no run_id", json.display()));
        }
        let id = r.to_string_lossy().to_string();
        anyhow::ensure!(
            !id.contains('/') && !r.exists(),
            "{}: neither a run's output directory (no run.json) nor a run id",
            r.display()
        );
        return Ok(id);
    }
    match running_runs().as_slice() {
        [] => anyhow::bail!("no run is running on this machine (start one with `shoal run`)"),
        [one] => Ok(one.clone()),
        many => anyhow::bail!(
            "{} runs are running here ({}): name one (its run id or output directory)",
            many.len(),
            many.join(", ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable as _;
    use ipc_types::fixed_str;

    const STAT: &str = "4242 (shoal-mpc x) S 1 2 3 4 5 6 7 8 9 10 250 50 0 0 20 0 1 0 100 1000 300";

    fn cmdline(run: &str, v: &str, p: &str) -> Vec<u8> {
        format!("/bin/shoal-mpc\0--run-id\0{run}\0--vehicle\0{v}\0--process\0{p}\0--processes\0\x32\x34\0")
            .into_bytes()
    }

    #[test]
    fn a_process_of_the_run_is_read_from_its_command_line_and_stat() {
        let p = parse_proc(
            4242,
            &cmdline("ab12", "F1", "mpc"),
            STAT,
            "1000 256 0",
            "ab12",
            100.0,
            4,
        )
        .unwrap();
        assert_eq!((p.vehicle.as_str(), p.process.as_str()), ("F1", "mpc"));
        // utime 250 + stime 50 ticks at 100 per second.
        assert!((p.cpu_s - 3.0).abs() < 1e-12);
        assert_eq!(p.rss_kib, 1024);
        assert_eq!(p.processes, Some(24));
        assert!(parse_proc(
            1,
            &cmdline("other", "F1", "mpc"),
            STAT,
            "1 1",
            "ab12",
            100.0,
            4
        )
        .is_none());
    }

    fn stats(v: &str, p: &str, sim_s: u64, steps: u64) -> ProcessStats {
        let mut s = ProcessStats::zeroed();
        s.vehicle = fixed_str(v);
        s.process = fixed_str(p);
        s.header.sim_time_ns = sim_s * 1_000_000_000;
        s.steps = steps;
        s.recent_step_p50_ns = 20_000;
        s.recent_step_p99_ns = 90_000;
        s.hop_count = 1;
        s.hops[0].channel = fixed_str("truth");
        s.hops[0].count = steps;
        s.hops[0].p50_ns = 5_000 * sim_s;
        s.hops[0].p99_ns = 9_000 * sim_s;
        s
    }

    fn proc_(v: &str, p: &str, pid: u32, cpu_s: f64) -> ProcSample {
        ProcSample {
            pid,
            vehicle: v.into(),
            process: p.into(),
            cpu_s,
            rss_kib: 2048,
            processes: Some(3),
            out: None,
        }
    }

    #[test]
    fn rates_come_from_two_snapshots_and_a_vanished_process_is_gone() {
        let mut top = Top::new("ab12");
        top.stats(&stats("F1", "mpc", 1, 10));
        top.stats(&stats("F1", "planner", 2, 20));
        let first = top.snapshot(
            0.0,
            &[proc_("F1", "mpc", 7, 1.0), proc_("F1", "planner", 8, 1.0)],
            Some(1000),
        );
        assert_eq!(first.processes[0].steps_per_s, None);
        assert_eq!(first.processes[0].cpu_pct, None);
        top.stats(&stats("F1", "mpc", 3, 30));
        let second = top.snapshot(2.0, &[proc_("F1", "mpc", 7, 1.5)], Some(5000));
        let mpc = second
            .processes
            .iter()
            .find(|r| r.process == "mpc")
            .unwrap();
        assert_eq!(mpc.steps_per_s, Some(10.0));
        assert_eq!(mpc.cpu_pct, Some(25.0));
        assert_eq!(mpc.step_p99_us, Some(90.0));
        assert_eq!(mpc.rss_mib, Some(2.0));
        let planner = second
            .processes
            .iter()
            .find(|r| r.process == "planner")
            .unwrap();
        assert_eq!(planner.state, "gone");
        assert_eq!(second.recorder.bytes_per_s, Some(2000.0));
        assert!((second.sim_time_s - 3.0).abs() < 1e-9);
        // Hops: the median of the readers' medians, the worst p99.
        assert_eq!(second.hops[0].readers, 2);
        assert_eq!(second.hops[0].p99_us, 27.0);
        assert!(text(&second).contains("gone"));
    }

    #[test]
    fn restarts_are_counted_from_the_events() {
        let mut top = Top::new("ab12");
        let mut e = Event::zeroed();
        e.kind = EventKind::ProcessRestarted as u32;
        e.process = fixed_str("F2/camera-pose");
        e.restarts = 2;
        top.event(&e);
        let s = top.snapshot(0.0, &[proc_("F2", "camera-pose", 9, 0.1)], None);
        assert_eq!(s.processes[0].restarts, 2);
        assert!(s.events[0].contains("process_restarted F2/camera-pose"));
    }
}
