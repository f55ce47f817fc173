//! Latency histograms (HDR), recorded on the hot path with one subtraction
//! and one counter increment per sample; percentiles are computed only when
//! reported (once a second, and at exit).

use std::cell::RefCell;

use hdrhistogram::Histogram;

/// A histogram of latencies in nanoseconds (1 ns to 60 s, 2 significant digits: a
/// value is kept to within 1 %).
///
/// Why 2 and not 3: every process reports its percentiles once per simulated
/// second, and a percentile is a walk over the buckets up to it. With 3
/// digits a bucket span holds 1024 counters, with 2 it holds 128; at 100
/// vehicles (500 processes) those walks were ~7 % of the run's CPU
/// (`perf`: `HistogramIterator::next`); 2 digits walk 8× fewer counters.
///
/// Quantiles asked for more than once are followed, not recomputed: each
/// keeps a cursor (its bucket and the count below it) that every record
/// updates with one comparison, and a query moves it by the few buckets the
/// quantile moved since the last one, instead of walking from zero.
#[derive(Debug, Clone)]
pub struct LatencyRecorder {
    hist: Option<Histogram<u64>>,
    cursors: RefCell<Vec<Cursor>>,
}

/// Where a followed quantile stands: the bucket `at` (its lowest
/// equivalent value) and how many samples lie in lower buckets.
#[derive(Debug, Clone, Copy)]
struct Cursor {
    q: f64,
    at: u64,
    below: u64,
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
            cursors: RefCell::new(Vec::new()),
        }
    }

    /// Records one latency, ns (clamped into range).
    pub fn record_ns(&mut self, ns: u64) {
        if let Some(h) = self.hist.as_mut() {
            let v = ns.max(1).min(h.high());
            h.saturating_record(v);
            for c in self.cursors.get_mut().iter_mut() {
                if v < c.at {
                    c.below += 1;
                }
            }
        }
    }

    /// Adds another recorder's samples.
    pub fn merge(&mut self, other: &LatencyRecorder) {
        if let (Some(a), Some(b)) = (self.hist.as_mut(), other.hist.as_ref()) {
            let _ = a.add(b);
            self.cursors.get_mut().clear();
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
            self.cursors.get_mut().clear();
        }
    }

    /// Value at quantile `q` in ns (0 when empty).
    pub fn quantile_ns(&self, q: f64) -> u64 {
        self.quantiles_ns([q])[0]
    }

    /// Values at several quantiles, ns (zeros when empty). The first query
    /// of a quantile walks the buckets; later ones move its cursor.
    pub fn quantiles_ns<const N: usize>(&self, qs: [f64; N]) -> [u64; N] {
        let mut out = [0u64; N];
        let Some(h) = self.hist.as_ref().filter(|h| !h.is_empty()) else {
            return out;
        };
        let total = h.len();
        let mut cursors = self.cursors.borrow_mut();
        for (slot, q) in out.iter_mut().zip(qs) {
            let q = q.clamp(0.0, 1.0);
            let target = ((q * total as f64).ceil() as u64).max(1);
            let i = match cursors.iter().position(|c| c.q == q) {
                Some(i) => i,
                None => {
                    cursors.push(Self::walk_to(h, q, target));
                    cursors.len() - 1
                }
            };
            let c = &mut cursors[i];
            loop {
                let here = h.count_at(c.at);
                if c.below + here < target {
                    c.below += here;
                    c.at = h.next_non_equivalent(c.at);
                } else if c.below >= target && c.at > 1 {
                    let prev = h.lowest_equivalent(c.at - 1);
                    c.below -= h.count_at(prev);
                    c.at = prev;
                } else {
                    break;
                }
            }
            *slot = h.highest_equivalent(c.at);
        }
        out
    }

    /// A new cursor at the bucket of the `target`-th sample (one walk).
    fn walk_to(h: &Histogram<u64>, q: f64, target: u64) -> Cursor {
        let mut seen = 0u64;
        for v in h.iter_recorded() {
            let n = v.count_at_value();
            if seen + n >= target {
                return Cursor {
                    q,
                    at: h.lowest_equivalent(v.value_iterated_to()),
                    below: seen,
                };
            }
            seen += n;
        }
        Cursor { q, at: 1, below: 0 }
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
        let h = a.hist.as_ref().unwrap();
        for (q, g) in qs.iter().zip(got) {
            assert_eq!(g, h.value_at_quantile(*q), "q = {q}");
        }
        assert_eq!(LatencyRecorder::new().quantiles_ns([0.5]), [0]);
    }

    proptest::proptest! {
        /// Followed quantiles (cursors moved between queries, over records
        /// that shift the distribution up and down) equal a fresh walk.
        #[test]
        fn followed_quantiles_equal_a_fresh_walk(
            batches in proptest::collection::vec(
                (proptest::collection::vec(1u64..100_000_000_000, 1..200), 0u8..3), 1..12),
        ) {
            let mut a = LatencyRecorder::new();
            for (values, shift) in batches {
                for v in values {
                    a.record_ns(v >> (8 * u32::from(shift)));
                }
                let qs = [0.0, 0.5, 0.99, 0.999, 1.0];
                let followed = a.quantiles_ns(qs);
                for (q, f) in qs.iter().zip(followed) {
                    let fresh = LatencyRecorder::walk_to(a.hist.as_ref().unwrap(), *q,
                        ((q * a.count() as f64).ceil() as u64).max(1));
                    let h = a.hist.as_ref().unwrap();
                    proptest::prop_assert_eq!(f, h.highest_equivalent(fresh.at), "q = {}", q);
                    proptest::prop_assert_eq!(f, h.highest_equivalent(h.value_at_quantile(*q)), "q = {} vs value_at_quantile", q);
                }
            }
        }
    }
}
