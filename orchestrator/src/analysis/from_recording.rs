//! A run's outcome read back from its recording alone, for `shoal
//! summarize` and for a run stopped by Ctrl-C: what [`summarize`] needs
//! besides the recording.
//!
//! Exact from the recording: the simulated time, the scenario (as run), the
//! mode, the events (`/events`), and the wall time of the run proper (the
//! span of the samples' publish stamps). From the processes' last recorded
//! statistics (`/stats`, about once a simulated second): steps, deadline
//! misses, samples lost and rejected (all inputs together, under
//! [`ALL_INPUTS`]), and the step, wake-up and hop latencies, re-made from
//! each process's recorded percentiles (p50, p99, p99.9, max) rather than
//! its whole histogram. Not in a recording: CPU time and peak memory (left
//! empty).
//!
//! [`summarize`]: super::summary::summarize

use std::collections::BTreeMap;

use bytemuck::Zeroable as _;
use ipc_types::{str_of, Event, EventKind, Header, ProcessStats};
use recordings::Recording;
use shoal_runtime::stats::{HopFile, StatsFile};
use shoal_scenario::Scenario;

use super::summary::{summarize, Summary};
use crate::launch::RunOutcome;

/// The key of `samples_lost` / `samples_rejected` when the channel kind is
/// not known (a recording counts them per process, not per input).
pub const ALL_INPUTS: &str = "all inputs";

/// The scenario the recording was made with (`shoal.run` / `scenario_toml`,
/// resolved).
pub fn recorded_scenario(rec: &Recording) -> anyhow::Result<Scenario> {
    use anyhow::Context as _;
    let text = rec
        .run_meta("scenario_toml")
        .context("the recording has no shoal.run/scenario_toml metadata")?;
    Scenario::from_toml(text).context("the recorded scenario does not parse")
}

/// The run's mode as recorded (`lockstep` when the recording does not say).
pub fn recorded_mode(rec: &Recording) -> String {
    rec.run_meta("mode").unwrap_or("lockstep").to_string()
}

/// Percentile buckets standing in for a histogram: half the samples at the
/// median, 49 % at p99, 0.9 % at p99.9, the rest at the maximum.
fn buckets(count: u64, p50: u64, p99: u64, p999: u64, max: u64) -> Vec<(u64, u64)> {
    if count == 0 {
        return Vec::new();
    }
    let at_max = (count / 1000).max(1).min(count);
    let at_p999 = (count * 9 / 1000).min(count - at_max);
    let at_p99 = (count * 49 / 100).min(count - at_max - at_p999);
    let at_p50 = count - at_max - at_p999 - at_p99;
    [(p50, at_p50), (p99, at_p99), (p999, at_p999), (max, at_max)]
        .into_iter()
        .filter(|&(_, n)| n > 0)
        .collect()
}

/// A process's statistics file as its last recorded sample has it.
fn stats_file(s: &ProcessStats) -> StatsFile {
    let hops = s
        .hops
        .iter()
        .take(s.hop_count as usize)
        .map(|h| HopFile {
            kind: str_of(&h.channel).to_string(),
            lost: 0,
            rejected: 0,
            latency_ns: buckets(h.count, h.p50_ns, h.p99_ns, h.p999_ns, h.max_ns),
        })
        .collect();
    StatsFile {
        vehicle: str_of(&s.vehicle).to_string(),
        process: str_of(&s.process).to_string(),
        steps: s.steps,
        deadline_misses: s.deadline_misses,
        // No p99.9 is recorded: the maximum stands in (an upper bound).
        step_ns: buckets(
            s.steps,
            s.step_p50_ns,
            s.step_p99_ns,
            s.step_max_ns,
            s.step_max_ns,
        ),
        // Only its p99 is recorded: no distribution to re-make.
        wake_late_ns: Vec::new(),
        hops,
        peak_rss_kib: None,
    }
}

/// One recorded event as summary.json lists it.
fn event_json(e: &Event) -> serde_json::Value {
    let mut map = serde_json::Map::new();
    map.insert("t_s".into(), (e.header.sim_time_ns as f64 * 1e-9).into());
    map.insert(
        "event".into(),
        EventKind::from_code(e.kind)
            .map_or("unknown", EventKind::name)
            .into(),
    );
    let process = str_of(&e.process);
    if !process.is_empty() {
        map.insert("process".into(), process.into());
    }
    if e.signal != 0 {
        map.insert(
            "exit".into(),
            format!("killed by signal {}", e.signal).into(),
        );
    } else if e.exit_code >= 0 {
        map.insert("exit".into(), format!("exit code {}", e.exit_code).into());
    }
    let detail = str_of(&e.detail);
    if !detail.is_empty() {
        map.insert("detail".into(), detail.into());
    }
    if e.duration_s > 0.0 {
        map.insert("duration_s".into(), e.duration_s.into());
    }
    serde_json::Value::Object(map)
}

/// Each process's last recorded statistics.
fn last_stats(rec: &Recording) -> BTreeMap<(String, String), ProcessStats> {
    let mut last = BTreeMap::new();
    for s in rec.samples::<ProcessStats>("/stats") {
        let key = (
            str_of(&s.vehicle).to_string(),
            str_of(&s.process).to_string(),
        );
        last.insert(key, s);
    }
    last
}

/// The summary of the run a recording holds, from the recording alone
/// (see the module's documentation for what is exact), with the scenario
/// it was made with.
pub fn summarize_recording(rec: &Recording) -> anyhow::Result<(Scenario, Summary)> {
    let scenario = recorded_scenario(rec)?;
    let outcome = outcome_of(rec, &scenario);
    let mut summary = summarize(&scenario, rec, &outcome, &recorded_mode(rec));
    let last = last_stats(rec);
    let total = |f: fn(&ProcessStats) -> u64| -> BTreeMap<String, u64> {
        let n: u64 = last.values().map(f).sum();
        if n > 0 {
            BTreeMap::from([(ALL_INPUTS.to_string(), n)])
        } else {
            BTreeMap::new()
        }
    };
    summary.samples_lost = total(|s| s.lost);
    summary.samples_rejected = total(|s| s.rejected);
    if summary.sim_time_s < scenario.duration_s {
        summary.partial = true;
        summary.verdict.pass = false;
        summary.verdict.failed.push(format!(
            "the run stopped at t = {:.1} s of {} s: the figures cover the part that ran",
            summary.sim_time_s, scenario.duration_s
        ));
    }
    Ok((scenario, summary))
}

/// What the run's outcome was, as far as its recording tells.
pub fn outcome_of(rec: &Recording, scenario: &Scenario) -> RunOutcome {
    let last = last_stats(rec);
    let events = rec
        .samples::<Event>("/events")
        .iter()
        .map(event_json)
        .collect();
    // The run proper: the span of the publish stamps (CLOCK_MONOTONIC, one
    // clock for every process of the machine).
    let (mut first_mono, mut last_mono) = (u64::MAX, 0u64);
    let mut sim_end = 0u64;
    for m in rec.messages() {
        sim_end = sim_end.max(m.log_time);
        let body = m.data.get(4..4 + std::mem::size_of::<Header>());
        let h = body.map_or_else(Header::zeroed, bytemuck::pod_read_unaligned::<Header>);
        if h.publish_mono_ns > 0 {
            first_mono = first_mono.min(h.publish_mono_ns);
            last_mono = last_mono.max(h.publish_mono_ns);
        }
    }
    let wall_time_s = if last_mono > first_mono {
        (last_mono - first_mono) as f64 * 1e-9
    } else {
        0.0
    };
    // A process steps once per its own period, so the last sample of a
    // whole run may stand up to the slowest period before its end: within
    // that, the run went to its end; before it, it stopped there (the last
    // tick's samples are stamped at its start, and it ran that tick too).
    let last_s = sim_end as f64 * 1e-9;
    let slowest_s = scenario
        .processes()
        .iter()
        .map(|p| 1.0 / scenario.rate_hz(p.kind))
        .fold(scenario.rates.tick_s, f64::max);
    let sim_time_s = if last_s + slowest_s + 0.5 * scenario.rates.tick_s >= scenario.duration_s {
        scenario.duration_s
    } else {
        last_s + scenario.rates.tick_s
    };
    let stats: Vec<StatsFile> = last.values().map(stats_file).collect();
    RunOutcome {
        run_id: rec.run_meta("run_id").unwrap_or_default().to_string(),
        recording: rec.path().to_path_buf(),
        wall_time_s,
        sim_time_s,
        cpu_time_s: BTreeMap::new(),
        max_rss_kib: BTreeMap::new(),
        processes: scenario.processes().len(),
        ticks: (sim_time_s / scenario.rates.tick_s).round() as u64,
        stats,
        events,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A recording of the leader's truth every `period_s` up to `last_s`,
    /// made with the scenario `text`.
    fn truths(text: &str, period_s: f64, last_s: f64) -> (tempfile::TempDir, Recording) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.mcap");
        let mut w =
            recordings::RecordingWriter::create(&path, &recordings::WriterOptions::default())
                .unwrap();
        let meta = BTreeMap::from([("scenario_toml".to_string(), text.to_string())]);
        w.metadata("shoal.run", meta).unwrap();
        let ch = w.add_channel::<ipc_types::Truth>("/L/truth").unwrap();
        let n = (last_s / period_s).round() as u64;
        for i in 0..=n {
            let mut t = <ipc_types::Truth as bytemuck::Zeroable>::zeroed();
            t.header.seq = i;
            t.header.sim_time_ns = (i as f64 * period_s * 1e9).round() as u64;
            t.q_body_to_ned_wxyz = [1.0, 0.0, 0.0, 0.0];
            w.write(ch, &t).unwrap();
        }
        w.finish().unwrap();
        let rec = Recording::open(&path).unwrap();
        (dir, rec)
    }

    #[test]
    fn a_whole_run_at_slow_rates_is_whole_and_a_cut_one_is_partial() {
        // Every process at 5 Hz: the last samples stand 0.12-0.2 s before
        // the end of a whole run.
        let text = "name = \"slow\"\nduration_s = 20.0\n[rates]\nplant_hz = 5.0\nworld_hz = 5.0\ncamera_hz = 5.0\nsonar_hz = 5.0\nplanner_hz = 5.0\nmpc_hz = 5.0\nrecorder_hz = 5.0\n[[vehicles]]\nname = \"L\"\n";
        let scenario = Scenario::from_toml(text).unwrap();
        let (_d, whole) = truths(text, 0.2, 19.8);
        assert_eq!(outcome_of(&whole, &scenario).sim_time_s, 20.0);
        let (_d, cut) = truths(text, 0.2, 10.0);
        let t = outcome_of(&cut, &scenario).sim_time_s;
        assert!((t - 10.02).abs() < 1e-9, "{t}");
    }

    #[test]
    fn percentile_buckets_give_the_percentiles_back() {
        let b = buckets(10_000, 100, 900, 2_000, 5_000);
        assert_eq!(b.iter().map(|x| x.1).sum::<u64>(), 10_000);
        let mut r = shoal_runtime::latency::LatencyRecorder::new();
        r.add_buckets(&b);
        let s = r.summary();
        // The histogram keeps 3 significant digits.
        let near = |a: f64, b: f64| (a - b).abs() <= 0.01 * b;
        assert!(near(s.p50, 0.1), "{s:?}");
        assert!(near(s.p99, 0.9), "{s:?}");
        assert!(near(s.p999, 2.0), "{s:?}");
        assert!(near(s.max, 5.0), "{s:?}");
        assert!(buckets(0, 1, 2, 3, 4).is_empty());
        assert_eq!(buckets(1, 1, 2, 3, 4), vec![(4, 1)]);
    }
}
