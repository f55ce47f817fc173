//! Latency histograms (HDR), recorded on the hot path with one subtraction
//! and one counter increment per sample; percentiles are computed only when
//! reported (once a second, and at exit).

use hdrhistogram::Histogram;

/// A histogram of latencies in nanoseconds (1 ns to 60 s, 2 significant digits: a
/// value is kept to within 1 %).
///
/// Why 2 and not 3: every process reports its percentiles once per simulated
/// second, and a percentile is a walk over the buckets up to it. With 3
/// digits a bucket span holds 1024 counters, with 2 it holds 128; at 100
/// vehicles (500 processes) those walks were ~7 % of the run's CPU
/// (`perf`: `HistogramIterator::next`); 2 digits walk 8× fewer counters.
#[derive(Debug, Clone)]
pub struct LatencyRecorder {
    hist: Option<Histogram<u64>>,
}

/// Significant decimal digits the histogram keeps.
pub const SIGNIFICANT_DIGITS: u8 = 2;

impl Default for LatencyRecorder {
    fn default() -> Self {
        Self::new()
    }
}

/// Percentiles of a histogram, in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, Default)]
pub struct LatencySummary {
    /// Median, µs.
    pub p50: f64,
    /// 99th percentile, µs.
    pub p99: f64,
    /// 99.9th percentile, µs.
    pub p999: f64,
    /// Largest, µs.
    pub max: f64,
    /// Number of samples.
    pub count: u64,
}

impl LatencyRecorder {
    /// An empty recorder.
    pub fn new() -> Self {
        Self {
            hist: Histogram::new_with_bounds(1, 60_000_000_000, SIGNIFICANT_DIGITS).ok(),
        }
    }

    /// Records one latency, ns (clamped into range).
    pub fn record_ns(&mut self, ns: u64) {
        if let Some(h) = self.hist.as_mut() {
            h.saturating_record(ns.max(1));
        }
    }

    /// Adds another recorder's samples.
    pub fn merge(&mut self, other: &LatencyRecorder) {
        if let (Some(a), Some(b)) = (self.hist.as_mut(), other.hist.as_ref()) {
            let _ = a.add(b);
        }
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.hist.as_ref().map_or(0, |h| h.len())
    }

    /// The recorded buckets as `(value ns, count)` pairs (for files).
    pub fn buckets(&self) -> Vec<(u64, u64)> {
        self.hist.as_ref().map_or_else(Vec::new, |h| {
            h.iter_recorded()
                .map(|v| (v.value_iterated_to(), v.count_at_value()))
                .collect()
        })
    }

    /// Adds `(value ns, count)` pairs written by [`LatencyRecorder::buckets`].
    pub fn add_buckets(&mut self, buckets: &[(u64, u64)]) {
        if let Some(h) = self.hist.as_mut() {
            for &(v, n) in buckets {
                let _ = h.record_n(v.clamp(1, h.high()), n);
            }
        }
    }

    /// Value at quantile `q` in ns (0 when empty).
    pub fn quantile_ns(&self, q: f64) -> u64 {
        self.hist
            .as_ref()
            .filter(|h| !h.is_empty())
            .map_or(0, |h| h.value_at_quantile(q))
    }

    /// Values at several ascending quantiles in one pass over the buckets, ns
    /// (zeros when empty).
    pub fn quantiles_ns<const N: usize>(&self, qs: [f64; N]) -> [u64; N] {
        let mut out = [0u64; N];
        let Some(h) = self.hist.as_ref().filter(|h| !h.is_empty()) else {
            return out;
        };
        let total = h.len();
        let targets = qs.map(|q| ((q.clamp(0.0, 1.0) * total as f64).ceil() as u64).max(1));
        let mut k = 0;
        let mut seen = 0u64;
        for v in h.iter_recorded() {
            seen += v.count_at_value();
            while k < N && seen >= targets[k] {
                out[k] = h.highest_equivalent(v.value_iterated_to());
                k += 1;
            }
            if k == N {
                break;
            }
        }
        out
    }

    /// Largest value, ns (0 when empty).
    pub fn max_ns(&self) -> u64 {
        self.hist.as_ref().map_or(0, |h| h.max())
    }

    /// p50/p99/p99.9/max in µs.
    pub fn summary(&self) -> LatencySummary {
        match &self.hist {
            Some(h) if !h.is_empty() => LatencySummary {
                p50: h.value_at_quantile(0.5) as f64 / 1e3,
                p99: h.value_at_quantile(0.99) as f64 / 1e3,
                p999: h.value_at_quantile(0.999) as f64 / 1e3,
                max: h.max() as f64 / 1e3,
                count: h.len(),
            },
            _ => LatencySummary::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_round_trip_through_a_file_form() {
        let mut a = LatencyRecorder::new();
        for v in [1_000u64, 2_000, 2_000, 50_000, 1_000_000] {
            a.record_ns(v);
        }
        let mut b = LatencyRecorder::new();
        b.add_buckets(&a.buckets());
        assert_eq!(b.count(), 5);
        assert_eq!(a.summary(), b.summary());
        assert_eq!(a.max_ns(), b.max_ns());
        assert_eq!(b.quantile_ns(0.5), a.quantile_ns(0.5));
    }

    #[test]
    fn one_pass_quantiles_equal_the_histograms_own() {
        let mut a = LatencyRecorder::new();
        let mut x = 12345u64;
        for _ in 0..10_000 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            a.record_ns(1 + (x >> 40) % 5_000_000);
        }
        let qs = [0.5, 0.9, 0.99, 0.999];
        let got = a.quantiles_ns(qs);
        for (q, g) in qs.iter().zip(got) {
            assert_eq!(g, a.quantile_ns(*q), "q = {q}");
        }
        assert_eq!(LatencyRecorder::new().quantiles_ns([0.5]), [0]);
    }
}
