//! Runtime statistics of one process: step durations, realtime wake-up
//! lateness and deadline misses, and the publish → take latency of every
//! input channel kind. Published about once a second on the run's `stats`
//! channel (so the recording holds them) and written to a file at exit (so
//! the orchestrator can merge the full histograms into `summary.json`).

use std::path::{Path, PathBuf};

use iceoryx2::prelude::*;
use iceoryx2::service::Service;
use ipc_types::{fixed_str, HopStats, ProcessStats, RunChannel, Sample};
use serde::{Deserialize, Serialize};

use crate::latency::LatencyRecorder;
use crate::ports::{for_each_hop, hop_snapshot, Origin};
use crate::{domain, ChannelLimits, Publisher, RunArgs, RunReport, StepContext};

/// Interval between two published statistics samples, ns (simulated time in
/// lockstep, wall time in realtime).
pub(crate) const PUBLISH_EVERY_NS: u64 = 1_000_000_000;

/// One input channel kind in the exit file.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct HopFile {
    /// Channel kind (`truth`, `world`, `clock`, ...).
    pub kind: String,
    /// Samples lost.
    pub lost: u64,
    /// Samples rejected (non-finite).
    pub rejected: u64,
    /// Publish → take latency histogram, `(ns, count)` buckets.
    pub latency_ns: Vec<(u64, u64)>,
}

/// What a process leaves in `<domain root>/stats/<vehicle>.<process>.json` at exit.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct StatsFile {
    /// Vehicle.
    pub vehicle: String,
    /// Process kind.
    pub process: String,
    /// Steps taken.
    pub steps: u64,
    /// Realtime deadline misses.
    pub deadline_misses: u64,
    /// Step duration histogram, `(ns, count)` buckets.
    pub step_ns: Vec<(u64, u64)>,
    /// Realtime wake-up lateness histogram, `(ns, count)` buckets.
    pub wake_late_ns: Vec<(u64, u64)>,
    /// Every input channel kind.
    pub hops: Vec<HopFile>,
    /// The process's own peak resident memory (`VmHWM`), KiB, read at exit.
    /// Unlike `wait4`'s `ru_maxrss`, it does not count the parent's pages the
    /// child held between fork and exec.
    #[serde(default)]
    pub peak_rss_kib: Option<u64>,
}

/// A memory field (`VmHWM:`, `RssAnon:`, …) of a `/proc/PID/status` text, KiB.
pub fn proc_status_kib(text: &str, field: &str) -> Option<u64> {
    text.lines()
        .find_map(|l| l.strip_prefix(field))?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// This process's peak resident memory, KiB (`VmHWM` of `/proc/self/status`).
pub fn own_peak_rss_kib() -> Option<u64> {
    proc_status_kib(
        &std::fs::read_to_string("/proc/self/status").ok()?,
        "VmHWM:",
    )
}

/// Where a run's processes leave their statistics files.
pub fn stats_dir(run_id: &str) -> PathBuf {
    domain::domain_root(run_id).join("stats")
}

/// Reads every statistics file of a run (unreadable ones are skipped with a warning).
pub fn read_stats_files(run_id: &str) -> Vec<StatsFile> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(stats_dir(run_id)) else {
        return out;
    };
    for e in entries.flatten() {
        let path = e.path();
        match std::fs::read(&path)
            .map_err(|e| e.to_string())
            .and_then(|b| serde_json::from_slice(&b).map_err(|e| e.to_string()))
        {
            Ok(f) => out.push(f),
            Err(err) => tracing::warn!(path = %path.display(), %err, "unreadable stats file"),
        }
    }
    out.sort_by(|a: &StatsFile, b| (&a.vehicle, &a.process).cmp(&(&b.vehicle, &b.process)));
    out
}

/// Limits of the run's `stats` channel: every process publishes, the
/// recorder (and outside clients) read. The recorder opens it on two nodes:
/// its own, to publish, and the one it reads on
/// ([`crate::Runtime::subscriber_of_many`]).
pub fn stats_limits(processes: usize) -> ChannelLimits {
    ChannelLimits {
        max_publishers: processes + 2,
        max_subscribers: 1 + domain::SPARE_SUBSCRIBERS,
        max_nodes: processes + 3 + domain::SPARE_SUBSCRIBERS,
        max_buffer: 4,
        history: 0,
    }
}

/// Collects and reports one process's statistics.
pub(crate) struct StatsReporter<S: Service> {
    publisher: Option<Publisher<ProcessStats, S>>,
    vehicle: String,
    process: String,
    run_id: String,
    step: LatencyRecorder,
    /// Steps since the last publication (`recent_step_*`).
    recent: LatencyRecorder,
    wake_late: LatencyRecorder,
    next_ns: u64,
}

impl<S: Service> StatsReporter<S> {
    pub(crate) fn new(node: &Node<S>, args: &RunArgs) -> Self {
        let service = ipc_types::run_service_name(&args.run_id, RunChannel::Stats);
        let publisher = Publisher::open(node, &service, &stats_limits(args.processes))
            .map_err(
                |e| tracing::warn!(%e, "no stats channel; statistics go to the exit file only"),
            )
            .ok();
        Self {
            publisher,
            vehicle: args.vehicle.clone(),
            process: args.process.clone(),
            run_id: args.run_id.clone(),
            step: LatencyRecorder::new(),
            recent: LatencyRecorder::new(),
            wake_late: LatencyRecorder::new(),
            next_ns: PUBLISH_EVERY_NS,
        }
    }

    /// Records one step; publishes the statistics when a second has passed.
    pub(crate) fn after_step(&mut self, ctx: &StepContext, step_ns: u64, report: &RunReport) {
        self.step.record_ns(step_ns);
        self.recent.record_ns(step_ns);
        if ctx.sim_time_ns >= self.next_ns {
            self.next_ns = (ctx.sim_time_ns / PUBLISH_EVERY_NS + 1) * PUBLISH_EVERY_NS;
            let sample = self.sample(report);
            self.recent = LatencyRecorder::new();
            if let Some(p) = self.publisher.as_mut() {
                if let Err(e) = p.publish(sample, ctx, Origin::default()) {
                    tracing::debug!(%e, "stats not published");
                }
            }
        }
    }

    /// Records how late a realtime activation woke, ns.
    pub(crate) fn wake_late(&mut self, ns: u64) {
        self.wake_late.record_ns(ns);
    }

    fn sample(&self, report: &RunReport) -> ProcessStats {
        let mut s = ProcessStats::zeroed();
        s.vehicle = fixed_str(&self.vehicle);
        s.process = fixed_str(&self.process);
        s.steps = report.steps;
        s.deadline_misses = report.deadline_misses;
        let [p50, p99] = self.step.quantiles_ns([0.5, 0.99]);
        s.step_p50_ns = p50;
        s.step_p99_ns = p99;
        s.step_max_ns = self.step.max_ns();
        if self.recent.count() > 0 {
            let [p50, p99] = self.recent.quantiles_ns([0.5, 0.99]);
            s.recent_step_p50_ns = p50;
            s.recent_step_p99_ns = p99;
        }
        s.wake_late_p99_ns = self.wake_late.quantile_ns(0.99);
        let mut n = 0;
        let (mut lost, mut rejected) = (0, 0);
        for_each_hop(|h| {
            lost += h.lost;
            rejected += h.rejected;
            if let Some(slot) = s.hops.get_mut(n) {
                let [p50_ns, p99_ns, p999_ns] = h.latency.quantiles_ns([0.5, 0.99, 0.999]);
                *slot = HopStats {
                    channel: fixed_str(&h.kind),
                    count: h.latency.count(),
                    p50_ns,
                    p99_ns,
                    p999_ns,
                    max_ns: h.latency.max_ns(),
                };
                n += 1;
            }
        });
        s.hop_count = n as u64;
        s.lost = lost;
        s.rejected = rejected;
        s
    }

    /// Writes the exit file.
    pub(crate) fn write_file(&self, report: &RunReport) -> std::io::Result<PathBuf> {
        let file = StatsFile {
            vehicle: self.vehicle.clone(),
            process: self.process.clone(),
            steps: report.steps,
            deadline_misses: report.deadline_misses,
            step_ns: self.step.buckets(),
            wake_late_ns: self.wake_late.buckets(),
            hops: hop_snapshot()
                .into_iter()
                .map(|h| HopFile {
                    kind: h.kind,
                    lost: h.lost,
                    rejected: h.rejected,
                    latency_ns: h.latency.buckets(),
                })
                .collect(),
            peak_rss_kib: own_peak_rss_kib(),
        };
        let dir = stats_dir(&self.run_id);
        std::fs::create_dir_all(&dir)?;
        let path = dir.join(format!("{}.{}.json", self.vehicle, self.process));
        write_atomically(
            &path,
            &serde_json::to_vec(&file).map_err(std::io::Error::other)?,
        )?;
        Ok(path)
    }
}

/// Writes `bytes` to a temporary file beside `path`, then renames it.
fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn own_peak_rss_counts_memory_this_process_touched() {
        let before = own_peak_rss_kib().expect("VmHWM in /proc/self/status");
        assert!(before > 0);
        // touch 64 MiB more than the process ever held: the peak must rise by most of it
        let block = vec![1u8; 64 << 20];
        let after = own_peak_rss_kib().unwrap();
        assert!(
            after >= before + (48 << 10),
            "{before} KiB -> {after} KiB with {} MiB touched",
            block.iter().map(|&b| usize::from(b)).sum::<usize>() >> 20
        );
    }

    #[test]
    fn an_exit_file_without_the_peak_still_reads() {
        let old = r#"{"vehicle":"F1","process":"mpc","steps":3,"deadline_misses":0,
                      "step_ns":[[1000,3]],"wake_late_ns":[],"hops":[]}"#;
        let f: StatsFile = serde_json::from_str(old).unwrap();
        assert_eq!(f.peak_rss_kib, None);
        assert_eq!(f.steps, 3);
    }
}
