//! What one run of `shoal bench scale` measured: its summary.json (the
//! run's summary and the memory sampled around it) and the figures read
//! from it.

use super::*;

/// `summary.json` of one run of this benchmark: the run's summary and
/// what the benchmark measured around it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ScaleSummary {
    /// The run's summary.
    #[serde(flatten)]
    pub run: Summary,
    /// Wall time of the whole run call (spawn to reap), s.
    pub run_call_s: Option<f64>,
    /// Memory sampled from `/proc` while the run went.
    pub memory_sampled: MemorySampled,
}

/// Peak memory per process kind, sampled from `/proc` while a run went.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MemorySampled {
    /// Peak RSS (`VmHWM`) summed over the processes of each kind, KiB.
    pub peak_rss_kib: BTreeMap<String, i64>,
    /// Peak private memory (`RssAnon`) summed per kind, KiB.
    pub peak_private_kib: BTreeMap<String, i64>,
    /// Processes seen.
    pub processes_sampled: usize,
    /// Sweeps over the processes.
    pub sweeps: u64,
    /// Time between sweeps, s.
    pub period_s: f64,
    /// CPU time of the sampling thread, s.
    pub sampler_cpu_s: f64,
    /// Whether the orchestrator's own peak could be reset before the run.
    pub orchestrator_peak_reset: bool,
}

/// The figures of one run, read from its summary.json.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Figures {
    /// Simulated time, s.
    pub(crate) sim_s: f64,
    /// Wall time, first tick to last, s.
    pub(crate) wall_s: f64,
    /// Wall time of the whole run: spawning, start-up, the ticks, stopping
    /// and reaping every process, s (`None` if the summary lacks it).
    pub(crate) run_call_s: Option<f64>,
    /// CPU time per process kind, the orchestrator's of this run only, s.
    pub(crate) cpu_s: BTreeMap<String, f64>,
    /// Peak RSS (`VmHWM`) summed over the processes of each kind, KiB.
    pub(crate) rss_kib: BTreeMap<String, i64>,
    /// Peak private memory (`RssAnon`) summed over the processes of each
    /// kind, KiB.
    pub(crate) private_kib: BTreeMap<String, i64>,
    /// Messages in the recording.
    pub(crate) recorder_messages: u64,
    /// Messages the recorder lost.
    pub(crate) recorder_dropped: u64,
    /// Pairs that came within the collision distance.
    pub(crate) collisions: u64,
    /// Least distance between two vehicles, m.
    pub(crate) min_pair_m: Option<f64>,
    /// The scenario's safe distance, m.
    pub(crate) safe_distance_m: Option<f64>,
    /// Least share of the run a follower saw its parent.
    pub(crate) min_parent_visible: Option<f64>,
    /// Farthest any follower's camera got from its parent, m.
    pub(crate) max_parent_range_m: Option<f64>,
    /// The camera's visibility range, m.
    pub(crate) visibility_range_m: Option<f64>,
}

impl Figures {
    /// Reads the figures from a run's summary (with the `memory_sampled`
    /// section this benchmark adds). `orchestrator_cpu_before` is this
    /// process's CPU time when the run started: the summary has the
    /// orchestrator's cumulative CPU, which here spans earlier runs; the
    /// memory sampler's own CPU is taken out of it too.
    pub(crate) fn from_summary(s: &ScaleSummary, orchestrator_cpu_before: f64) -> Self {
        let run = &s.run;
        let cpu_s = crate::bench::run::summary_cpu_s(
            run,
            orchestrator_cpu_before + s.memory_sampled.sampler_cpu_s,
        );
        Self {
            sim_s: run.sim_time_s,
            wall_s: run.wall_time_s,
            run_call_s: s.run_call_s,
            cpu_s,
            rss_kib: s.memory_sampled.peak_rss_kib.clone(),
            private_kib: s.memory_sampled.peak_private_kib.clone(),
            recorder_messages: run.recording.messages,
            recorder_dropped: run.recording.dropped,
            collisions: run.safety.collisions as u64,
            min_pair_m: run.safety.min_pair_distance_m,
            safe_distance_m: Some(run.safety.safe_distance_m),
            min_parent_visible: run.min_parent_visible(),
            max_parent_range_m: run.max_parent_range_m(),
            visibility_range_m: Some(run.perception.visibility_range_m),
        }
    }

    /// Simulated s per wall s.
    pub(crate) fn rtf(&self) -> f64 {
        ratio(self.sim_s, self.wall_s)
    }

    /// CPU time of every process, s.
    pub(crate) fn cpu_total_s(&self) -> f64 {
        self.cpu_s.values().sum()
    }

    /// CPU time per vehicle and simulated second, ms.
    pub(crate) fn cpu_ms_per_vehicle_s(&self, vehicles: usize) -> f64 {
        1e3 * ratio(self.cpu_total_s(), vehicles as f64 * self.sim_s)
    }

    /// Sum of every process's peak RSS, MiB.
    pub(crate) fn rss_total_mib(&self) -> f64 {
        self.rss_kib.values().sum::<i64>() as f64 / 1024.0
    }

    /// Sum of every process's peak private (anonymous) memory, MiB.
    pub(crate) fn private_total_mib(&self) -> f64 {
        self.private_kib.values().sum::<i64>() as f64 / 1024.0
    }

    /// Wall time outside the ticks (start-up and shutdown), s.
    pub(crate) fn start_stop_s(&self) -> Option<f64> {
        self.run_call_s.map(|t| (t - self.wall_s).max(0.0))
    }

    /// Recorded messages per wall second.
    pub(crate) fn recorder_msgs_per_s(&self) -> f64 {
        ratio(self.recorder_messages as f64, self.wall_s)
    }

    pub(crate) fn to_json(&self, vehicles: usize) -> Value {
        json!({
            "sim_s": self.sim_s,
            "wall_s": self.wall_s,
            "run_call_s": self.run_call_s,
            "start_stop_s": self.start_stop_s(),
            "real_time_factor": finite(self.rtf()),
            "cpu_s": self.cpu_s,
            "cpu_total_s": self.cpu_total_s(),
            "cpu_ms_per_vehicle_s": finite(self.cpu_ms_per_vehicle_s(vehicles)),
            "rss_sum_kib": self.rss_kib,
            "rss_total_mib": self.rss_total_mib(),
            "private_sum_kib": self.private_kib,
            "private_total_mib": self.private_total_mib(),
            "recorder_messages": self.recorder_messages,
            "recorder_dropped": self.recorder_dropped,
            "recorder_msgs_per_s": finite(self.recorder_msgs_per_s()),
            "collisions": self.collisions,
            "min_pair_distance_m": self.min_pair_m,
            "safe_distance_m": self.safe_distance_m,
            "min_parent_visible_fraction": self.min_parent_visible,
            "max_parent_range_m": self.max_parent_range_m,
            "visibility_range_m": self.visibility_range_m,
        })
    }
}

/// `a / b`, NaN when `b` is not positive.
pub(crate) fn ratio(a: f64, b: f64) -> f64 {
    if b > 0.0 {
        a / b
    } else {
        f64::NAN
    }
}

pub(crate) fn finite(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}
