//! The memory sampler: a thread that reads every child's `/proc` status
//! while a run goes.

use super::*;
use crate::launch::os::{child_pids, kind_from_cmdline, parse_status, thread_cpu_s, MemReading};

/// How often the memory sampler reads a run of `processes` processes: 2 ms
/// a process, from 20 ms to 1 s. `VmHWM` is a peak the kernel keeps, so
/// only `RssAnon` needs the sweeps, and it settles once a process has
/// started; but a process must be swept at least once while it lives. At
/// N = 100 a sweep every 200 ms (2,500 `/proc` reads a second) took 4 % of
/// the run's CPU under perf, taken from the run it measures; 1 s for every
/// size saw 5 of N = 25's 126 processes, whose run lasts about a second. At
/// 2 ms a process the sampler reads 500 files a second at any size.
pub(crate) fn sample_period(processes: usize) -> Duration {
    let per_process = Duration::from_millis(2);
    (per_process * u32::try_from(processes).unwrap_or(u32::MAX))
        .clamp(Duration::from_millis(20), Duration::from_secs(1))
}

/// The highest readings of every service process seen, by pid.
#[derive(Debug, Default)]
pub(crate) struct MemPeaks {
    /// pid → (kind, highest `VmHWM`, highest `RssAnon`).
    pub(crate) procs: HashMap<i32, (String, MemReading)>,
    /// Sweeps over the children taken.
    pub(crate) sweeps: u64,
    /// CPU time of the sampler thread, s.
    pub(crate) sampler_cpu_s: f64,
}

impl MemPeaks {
    /// Reads every child of this process once.
    pub(crate) fn sweep(&mut self) {
        self.sweeps += 1;
        for pid in child_pids() {
            let Ok(text) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
                continue;
            };
            let Some(r) = parse_status(&text) else {
                continue;
            };
            let entry = match self.procs.entry(pid) {
                std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
                std::collections::hash_map::Entry::Vacant(v) => {
                    let Some(kind) = std::fs::read(format!("/proc/{pid}/cmdline"))
                        .ok()
                        .and_then(|c| kind_from_cmdline(&c))
                    else {
                        continue;
                    };
                    v.insert((kind, MemReading::default()))
                }
            };
            entry.1.hwm_kib = entry.1.hwm_kib.max(r.hwm_kib);
            entry.1.anon_kib = entry.1.anon_kib.max(r.anon_kib);
        }
    }

    /// `(peak RSS, peak private)` summed per kind, KiB.
    pub(crate) fn by_kind(&self) -> (BTreeMap<String, i64>, BTreeMap<String, i64>) {
        let mut rss: BTreeMap<String, i64> = BTreeMap::new();
        let mut private: BTreeMap<String, i64> = BTreeMap::new();
        for (kind, r) in self.procs.values() {
            *rss.entry(kind.clone()).or_default() += r.hwm_kib;
            *private.entry(kind.clone()).or_default() += r.anon_kib;
        }
        (rss, private)
    }
}

/// A thread that sweeps the run's processes every [`sample_period`]:
/// `VmHWM` is the peak of the process's own address space since its exec
/// (the `ru_maxrss` that `wait4` reports also counts the orchestrator's
/// memory that the child held between fork and exec).
pub(crate) struct MemSampler {
    pub(crate) stop: Arc<AtomicBool>,
    pub(crate) handle: std::thread::JoinHandle<MemPeaks>,
}

impl MemSampler {
    pub(crate) fn start(period: Duration) -> anyhow::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let handle = std::thread::Builder::new()
            .name("mem-sampler".into())
            .spawn(move || {
                let mut peaks = MemPeaks::default();
                while !flag.load(Ordering::Relaxed) {
                    peaks.sweep();
                    std::thread::park_timeout(period);
                }
                peaks.sampler_cpu_s = thread_cpu_s();
                peaks
            })
            .context("cannot start the memory sampler thread")?;
        Ok(Self { stop, handle })
    }

    pub(crate) fn finish(self) -> MemPeaks {
        self.stop.store(true, Ordering::Relaxed);
        self.handle.thread().unpark();
        self.handle.join().unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sweep_period_grows_with_the_processes_within_its_bounds() {
        assert_eq!(sample_period(0), Duration::from_millis(20));
        assert_eq!(sample_period(5), Duration::from_millis(20));
        // N = 25: 126 processes, a run of about a second, swept 4 times.
        assert_eq!(sample_period(126), Duration::from_millis(252));
        assert_eq!(sample_period(501), Duration::from_secs(1));
        assert_eq!(sample_period(usize::MAX), Duration::from_secs(1));
    }
}
