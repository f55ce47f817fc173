//! `shoal bench run`: what a whole scenario costs on this machine.
//!
//! Runs the scenario (default: the paper's) through the same in-process
//! path as `shoal run`, into a throwaway directory, in three ways:
//!
//! 1. lockstep with blocking waits (the default of `shoal run`), `--repeat`
//!    times: real-time factor, wall time, CPU time per process kind and in
//!    total, CPU per simulated second;
//! 2. lockstep with the adaptive wait (every process polls `--spin-us` for
//!    its next wake-up before blocking), `--repeat` times, the same figures;
//! 3. realtime mode, shortened to `--realtime-duration`: end-to-end latency
//!    (sensor event → thrust applied by sim-plant), deadline misses and
//!    wake-up lateness per process kind, and every hop's publish → take
//!    latency, from the run's summary.json.
//!
//! The goal of issue 7 (the paper scenario in lockstep at ≥ 50× real time)
//! is printed next to the figure; nothing here fails on a figure.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use serde_json::{json, Value};
use shoal_runtime::Mode;

use shoal_runtime::latency::LatencySummary;

use crate::analysis::summary::Summary;
use crate::cli::ProcessArgs;
use crate::launch::os as sys;
use crate::launch::RunSettings;
use crate::pipeline::run_and_summarize;
use crate::preflight::load_scenario_with;

/// Issue 7: the paper scenario in lockstep at ≥ 50× real time.
const GOAL_RTF: f64 = 50.0;

/// Arguments of `shoal bench run`.
#[derive(Debug, clap::Args)]
pub struct RunBenchCmd {
    /// Scenario TOML (default: the embedded paper scenario).
    pub scenario: Option<PathBuf>,
    /// Runs of each lockstep variant; the table gives the median and the
    /// minimum of each figure. The default (3) keeps the paper scenario's
    /// whole benchmark under about two minutes.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
    /// Spin budget of the adaptive-wait lockstep variant, µs (every process
    /// polls this long for its next wake-up before blocking).
    #[arg(long, default_value_t = 50)]
    pub spin_us: u64,
    /// Simulated (= wall) seconds of each wall-clock run (one on phased
    /// timers, `realtime`, one driven by data, `dataflow`); the scenario's
    /// duration if shorter. 0 skips them.
    #[arg(long, default_value_t = 60.0)]
    pub realtime_duration: f64,
    /// Simulated seconds of each lockstep run (default: the scenario's).
    #[arg(long, allow_negative_numbers = true, value_parser = crate::cli::parse_duration)]
    pub duration: Option<f64>,
    /// Seed of every random generator (overrides the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Keep the runs' output directories (recordings, summaries, plots)
    /// under /tmp and print where; by default they are removed.
    #[arg(long)]
    pub keep: bool,
    /// Also write every figure (each run's, the medians and minima, the
    /// realtime sections of summary.json) as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub processes: ProcessArgs,
}

/// The figures of one lockstep run.
#[derive(Debug, Clone, PartialEq)]
struct LockstepRun {
    /// Simulated seconds per wall second (first tick to last).
    rtf: f64,
    /// Wall time of the run proper, s.
    wall_s: f64,
    /// Simulated time, s.
    sim_s: f64,
    /// CPU time per process kind (`orchestrator` included), s.
    cpu_s: BTreeMap<String, f64>,
}

/// CPU seconds by process kind from a run's summary, with
/// `not_this_run_s` taken off the orchestrator's: its figure is this
/// process's cumulative CPU, which in a benchmark spans earlier runs.
pub(crate) fn summary_cpu_s(s: &Summary, not_this_run_s: f64) -> BTreeMap<String, f64> {
    let mut cpu_s = s.cpu_time_s.clone();
    if let Some(o) = cpu_s.get_mut("orchestrator") {
        *o = (*o - not_this_run_s).max(0.0);
    }
    cpu_s
}

impl LockstepRun {
    /// Reads a run's figures from its summary. `orchestrator_cpu_before` is
    /// this process's CPU time when the run started: the summary reports
    /// the orchestrator's cumulative CPU, which here spans earlier runs.
    fn from_summary(s: &Summary, orchestrator_cpu_before: f64) -> Self {
        Self {
            rtf: s.real_time_factor,
            wall_s: s.wall_time_s,
            sim_s: s.sim_time_s,
            cpu_s: summary_cpu_s(s, orchestrator_cpu_before),
        }
    }

    fn total_cpu(&self) -> f64 {
        self.cpu_s.values().sum()
    }

    fn cpu_per_sim_s(&self) -> f64 {
        if self.sim_s > 0.0 {
            self.total_cpu() / self.sim_s
        } else {
            f64::NAN
        }
    }

    fn to_json(&self) -> Value {
        json!({
            "real_time_factor": self.rtf, "wall_s": self.wall_s, "sim_s": self.sim_s,
            "cpu_s": self.cpu_s, "cpu_total_s": self.total_cpu(),
            "cpu_per_sim_s": self.cpu_per_sim_s(),
        })
    }
}

/// One lockstep way of waiting and its runs.
#[derive(Debug, Clone)]
struct Variant {
    /// Table heading.
    label: String,
    /// Spin budget, µs (0: blocking).
    spin_us: u64,
    runs: Vec<LockstepRun>,
}

/// Median (mean of the middle two for an even count) and minimum, ignoring
/// NaN; `None` when nothing is left.
fn median_min(values: &[f64]) -> Option<(f64, f64)> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    };
    Some((median, v[0]))
}

/// The rows of the lockstep table: (label, one value per run) for each
/// figure, CPU per process kind in name order.
fn lockstep_rows(variant: &Variant, kinds: &BTreeSet<String>) -> Vec<(String, Vec<f64>)> {
    let col = |f: &dyn Fn(&LockstepRun) -> f64| variant.runs.iter().map(f).collect::<Vec<_>>();
    let mut rows = vec![
        ("real-time factor (x)".to_string(), col(&|r| r.rtf)),
        ("wall (s)".to_string(), col(&|r| r.wall_s)),
    ];
    for k in kinds {
        rows.push((
            format!("CPU {k} (s)"),
            col(&|r| r.cpu_s.get(k).copied().unwrap_or(f64::NAN)),
        ));
    }
    rows.push(("CPU total (s)".to_string(), col(&|r| r.total_cpu())));
    rows.push((
        "CPU per simulated s (s)".to_string(),
        col(&|r| r.cpu_per_sim_s()),
    ));
    rows
}

/// A figure as printed: three significant digits, `-` for NaN or infinity.
pub(crate) fn fmt_num(x: f64) -> String {
    if !x.is_finite() {
        "-".to_string()
    } else if x.abs() >= 100.0 {
        format!("{x:.0}")
    } else if x.abs() >= 10.0 {
        format!("{x:.1}")
    } else if x.abs() >= 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.3}")
    }
}

/// Whether the figure meets the ≥ 50× goal (judged on the median).
fn goal_note(median_rtf: Option<f64>) -> &'static str {
    match median_rtf {
        Some(x) if x >= GOAL_RTF => "met",
        Some(_) => "MISSED",
        None => "-",
    }
}

/// The lockstep table: one row per figure, median and minimum per variant.
fn render_lockstep(variants: &[Variant]) -> String {
    let kinds: BTreeSet<String> = variants
        .iter()
        .flat_map(|v| v.runs.iter().flat_map(|r| r.cpu_s.keys().cloned()))
        .collect();
    let per_variant: Vec<Vec<(String, Vec<f64>)>> =
        variants.iter().map(|v| lockstep_rows(v, &kinds)).collect();
    let mut out = String::new();
    let _ = write!(out, "{:<26}", "lockstep");
    for v in variants {
        let _ = write!(out, "  {:>22}", v.label);
    }
    out.push('\n');
    let _ = write!(out, "{:<26}", "");
    for v in variants {
        let head = format!("median / min of {}", v.runs.len());
        let _ = write!(out, "  {head:>22}");
    }
    out.push('\n');
    let Some(first) = per_variant.first() else {
        return out;
    };
    for (i, (label, _)) in first.iter().enumerate() {
        let _ = write!(out, "{label:<26}");
        for rows in &per_variant {
            let cell = match rows.get(i).and_then(|(_, vals)| median_min(vals)) {
                Some((med, min)) => format!("{} / {}", fmt_num(med), fmt_num(min)),
                None => "-".to_string(),
            };
            let _ = write!(out, "  {cell:>22}");
        }
        out.push('\n');
        if i == 0 {
            let _ = write!(out, "{:<26}", "  goal (issue 7): >= 50x");
            for v in variants {
                let rtf: Vec<f64> = v.runs.iter().map(|r| r.rtf).collect();
                let note = goal_note(median_min(&rtf).map(|(m, _)| m));
                let _ = write!(out, "  {note:>22}");
            }
            out.push('\n');
        }
    }
    out
}

/// Percentile cells of a latency summary (`p50`, `p99`, `p999`, `max`,
/// `count`, µs) as printed.
fn latency_cells(v: &LatencySummary) -> String {
    format!(
        "{:>10} {:>10} {:>10} {:>10} {:>8}",
        fmt_num(v.p50),
        fmt_num(v.p99),
        fmt_num(v.p999),
        fmt_num(v.max),
        v.count
    )
}

/// The realtime tables, from a realtime run's summary.json.
fn render_realtime(s: &Summary) -> String {
    let mut out = String::new();
    let head = format!(
        "{:>10} {:>10} {:>10} {:>10} {:>8}",
        "p50", "p99", "p99.9", "max", "count"
    );
    let how = match s.mode.as_str() {
        "dataflow" => "each stage woken by its inputs",
        _ => "phased timers",
    };
    let _ = writeln!(
        out,
        "{}: {} s on the wall clock, {how} ({:.1} s wall)",
        s.mode,
        fmt_num(s.sim_time_s),
        s.wall_time_s
    );
    let _ = writeln!(out, "{:<26}{head}", "latency, µs");
    let _ = writeln!(
        out,
        "{:<26}{}",
        "end to end",
        latency_cells(&s.latency_us.end_to_end)
    );
    let _ = writeln!(
        out,
        "{:<26}(plant's truth -> thrust applied by sim-plant)",
        ""
    );
    let _ = writeln!(
        out,
        "{:<26}{}",
        "camera frame -> thrust",
        latency_cells(&s.latency_us.frame_to_thrust)
    );
    for c in &s.latency_us.chain {
        let _ = writeln!(
            out,
            "{:<26}{}",
            format!("  stage {}", c.stage),
            latency_cells(&c.us)
        );
    }
    let kinds: BTreeSet<&String> = s
        .deadline_misses
        .keys()
        .chain(s.wake_late_us.keys())
        .collect();
    let _ = writeln!(
        out,
        "\n{:<26}{:>16} {:>21}",
        "process kind", "deadline misses", "wake-up late p99, µs"
    );
    for k in kinds {
        let m = s
            .deadline_misses
            .get(k)
            .map_or("-".to_string(), |x| format!("{x}"));
        let l = s
            .wake_late_us
            .get(k)
            .map_or("-".to_string(), |v| fmt_num(v.p99));
        let _ = writeln!(out, "{k:<26}{m:>16} {l:>21}");
    }
    let _ = writeln!(out, "\n{:<26}{head}", "hop (publish -> take), µs");
    for (k, v) in &s.latency_us.hops {
        let _ = writeln!(out, "{k:<26}{}", latency_cells(v));
    }
    out
}

/// The output directory of every run; removed when dropped unless kept.
pub(super) struct Scratch {
    pub(super) path: PathBuf,
    pub(super) keep: bool,
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if self.keep {
            eprintln!("runs kept in {}", self.path.display());
        } else if let Err(e) = std::fs::remove_dir_all(&self.path) {
            tracing::warn!(path = %self.path.display(), error = %e, "cannot remove the bench runs");
        }
    }
}

/// Runs `scenario` once into `out`; returns its summary and this process's
/// CPU time when it started.
fn one_run(
    scenario: &shoal_scenario::Scenario,
    out: &Path,
    settings: &RunSettings,
) -> anyhow::Result<(Summary, f64)> {
    let cpu_before = sys::self_cpu_s();
    let summary = run_and_summarize(scenario.clone(), out, settings)
        .with_context(|| format!("the run into {} failed", out.display()))?
        .summary;
    Ok((summary, cpu_before))
}

/// Runs the benchmark and prints its tables.
pub fn run(cmd: RunBenchCmd) -> anyhow::Result<()> {
    let scenario = load_scenario_with(&cmd.scenario, |s| {
        if let Some(seed) = cmd.seed {
            s.seed = seed;
        }
        if let Some(d) = cmd.duration {
            s.duration_s = d;
        }
    })?;
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis())
        .unwrap_or(0);
    let scratch = Scratch {
        path: std::env::temp_dir().join(format!("shoal-bench-run-{}-{stamp}", std::process::id())),
        keep: cmd.keep,
    };
    std::fs::create_dir_all(&scratch.path)
        .with_context(|| format!("cannot create {}", scratch.path.display()))?;
    let started = Instant::now();
    let load_before = crate::launch::os::load_average();

    let mut variants = vec![
        Variant {
            label: "blocking wait".into(),
            spin_us: 0,
            runs: Vec::new(),
        },
        Variant {
            label: format!("adaptive ({} µs spin)", cmd.spin_us),
            spin_us: cmd.spin_us,
            runs: Vec::new(),
        },
    ];
    let mut processes = None;
    // Alternate the variants so a drift in the machine's load hits both.
    for i in 0..cmd.repeat {
        for (vi, v) in variants.iter_mut().enumerate() {
            let mut settings = cmd.processes.settings(Mode::Lockstep, true)?;
            settings.spin_us = v.spin_us;
            let out = scratch.path.join(format!(
                "lockstep-{}-{}",
                ["block", "spin"][vi.min(1)],
                i + 1
            ));
            let (summary, cpu_before) = one_run(&scenario, &out, &settings)?;
            processes = processes.or(Some(summary.processes));
            let r = LockstepRun::from_summary(&summary, cpu_before);
            eprintln!(
                "  lockstep, {:<22} run {}/{}: {:.1}x real time, {:.2} s wall, {:.2} s CPU",
                v.label,
                i + 1,
                cmd.repeat,
                r.rtf,
                r.wall_s,
                r.total_cpu()
            );
            v.runs.push(r);
        }
    }

    let realtime = if cmd.realtime_duration > 0.0 {
        let mut rt = scenario.clone();
        rt.duration_s = rt.duration_s.min(cmd.realtime_duration);
        let mut runs = Vec::new();
        for mode in [Mode::Realtime, Mode::Dataflow] {
            eprintln!(
                "  {}: {} s on the wall clock ...",
                mode.as_str(),
                fmt_num(rt.duration_s)
            );
            let settings = cmd.processes.settings(mode, true)?;
            let (summary, _) = one_run(&rt, &scratch.path.join(mode.as_str()), &settings)?;
            runs.push(summary);
        }
        runs
    } else {
        Vec::new()
    };
    let load_after = crate::launch::os::load_average();
    let elapsed = started.elapsed().as_secs_f64();

    let load = |l: Option<f64>| l.map_or("?".to_string(), |x| format!("{x:.2}"));
    println!(
        "shoal bench run: {} ({} vehicles, {} processes), seed {}, {} s simulated per lockstep run, \
         {} runs per variant; load average {} -> {}; {:.0} s{}",
        scenario.name,
        scenario.vehicles.len(),
        processes.map_or("?".to_string(), |p| p.to_string()),
        scenario.seed,
        fmt_num(scenario.duration_s),
        cmd.repeat,
        load(load_before),
        load(load_after),
        elapsed,
        if cmd.processes.idle_poll {
            "; idle CPUs poll (/dev/cpu_dma_latency held at 0)"
        } else {
            ""
        }
    );
    println!();
    print!("{}", render_lockstep(&variants));
    for s in &realtime {
        println!();
        print!("{}", render_realtime(s));
    }

    if let Some(path) = &cmd.json {
        let variant_json = |v: &Variant| {
            let kinds: BTreeSet<String> = v
                .runs
                .iter()
                .flat_map(|r| r.cpu_s.keys().cloned())
                .collect();
            let stats: serde_json::Map<String, Value> = lockstep_rows(v, &kinds)
                .into_iter()
                .map(|(label, vals)| {
                    let cell = median_min(&vals)
                        .map_or(Value::Null, |(m, n)| json!({ "median": m, "min": n }));
                    (label, cell)
                })
                .collect();
            json!({
                "label": v.label, "spin_us": v.spin_us,
                "runs": v.runs.iter().map(LockstepRun::to_json).collect::<Vec<_>>(),
                "median_min": stats,
                "goal_rtf": GOAL_RTF,
                "goal": goal_note(median_min(&v.runs.iter().map(|r| r.rtf).collect::<Vec<_>>()).map(|(m, _)| m)),
            })
        };
        let doc = json!({
            "scenario": scenario.name,
            "seed": scenario.seed,
            "vehicles": scenario.vehicles.len(),
            "processes": processes,
            "lockstep_sim_s": scenario.duration_s,
            "repeat": cmd.repeat,
            "load_average": [load_before, load_after],
            "elapsed_s": elapsed,
            "lockstep": variants.iter().map(variant_json).collect::<Vec<_>>(),
            "realtime": realtime.iter().map(|s| json!({
                "mode": s.mode,
                "sim_time_s": s.sim_time_s, "wall_time_s": s.wall_time_s,
                "cpu_time_s": s.cpu_time_s,
                "latency_us": s.latency_us, "deadline_misses": s.deadline_misses,
                "wake_late_us": s.wake_late_us, "step_us": s.step_us,
                "samples_lost": s.samples_lost, "samples_rejected": s.samples_rejected,
            })).collect::<Vec<_>>(),
        });
        std::fs::write(path, serde_json::to_string_pretty(&doc)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("\n{}", path.display());
    }
    drop(scratch);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::summary::Latency;

    fn run_with(rtf: f64, wall: f64, cpu: &[(&str, f64)]) -> LockstepRun {
        LockstepRun {
            rtf,
            wall_s: wall,
            sim_s: rtf * wall,
            cpu_s: cpu.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        }
    }

    #[test]
    fn median_and_min_of_odd_even_and_nan() {
        assert_eq!(median_min(&[3.0, 1.0, 2.0]), Some((2.0, 1.0)));
        assert_eq!(median_min(&[4.0, 1.0, 3.0, 2.0]), Some((2.5, 1.0)));
        assert_eq!(median_min(&[f64::NAN, 5.0]), Some((5.0, 5.0)));
        assert_eq!(median_min(&[f64::NAN]), None);
        assert_eq!(median_min(&[]), None);
    }

    #[test]
    fn a_summary_gives_the_run_figures_and_the_orchestrator_cpu_of_this_run_only() {
        let s = Summary {
            real_time_factor: 40.0,
            wall_time_s: 5.0,
            sim_time_s: 200.0,
            cpu_time_s: [("mpc", 3.0), ("orchestrator", 10.5), ("world", 0.5)]
                .map(|(k, v)| (k.to_string(), v))
                .into(),
            ..Summary::default()
        };
        let r = LockstepRun::from_summary(&s, 10.0);
        assert_eq!(r.rtf, 40.0);
        assert_eq!(r.cpu_s["orchestrator"], 0.5);
        assert_eq!(r.total_cpu(), 4.0);
        assert_eq!(r.cpu_per_sim_s(), 4.0 / 200.0);
        // A summary.json that lacks a figure is refused when read, not read as 0.
        assert!(serde_json::from_value::<Summary>(json!({ "real_time_factor": 1.0 })).is_err());
    }

    #[test]
    fn lockstep_table_gives_median_and_min_per_variant_and_the_goal() {
        let variants = vec![
            Variant {
                label: "blocking wait".into(),
                spin_us: 0,
                runs: vec![
                    run_with(60.0, 3.0, &[("mpc", 2.0), ("world", 0.2)]),
                    run_with(40.0, 5.0, &[("mpc", 4.0), ("world", 0.4)]),
                    run_with(55.0, 4.0, &[("mpc", 3.0), ("world", 0.3)]),
                ],
            },
            Variant {
                label: "adaptive (50 µs spin)".into(),
                spin_us: 50,
                runs: vec![run_with(45.0, 4.0, &[("mpc", 6.0), ("sonar", 1.0)])],
            },
        ];
        let t = render_lockstep(&variants);
        let line = |start: &str| {
            t.lines()
                .find(|l| l.starts_with(start))
                .unwrap_or_else(|| panic!("no {start} row in\n{t}"))
                .to_string()
        };
        assert!(line("real-time factor").contains("55.0 / 40.0"), "{t}");
        assert!(line("real-time factor").contains("45.0 / 45.0"), "{t}");
        let goal = line("  goal");
        assert!(goal.contains("met") && goal.contains("MISSED"), "{t}");
        assert!(line("wall (s)").contains("4.00 / 3.00"), "{t}");
        assert!(line("CPU mpc (s)").contains("3.00 / 2.00"), "{t}");
        // A kind one variant never ran shows as missing there.
        let sonar = line("CPU sonar (s)");
        assert!(sonar.contains(" - ") || sonar.contains("  -"), "{t}");
        assert!(sonar.contains("1.00 / 1.00"), "{t}");
        assert!(line("CPU total (s)").contains("3.30 / 2.20"), "{t}");
        // CPU per simulated second: total / (rtf * wall).
        let per_sim = line("CPU per simulated s");
        assert!(per_sim.contains(&fmt_num(3.3 / 220.0)), "{t}");
    }

    #[test]
    fn realtime_table_reads_the_summary_sections() {
        let lat = |p50: f64| LatencySummary {
            p50,
            p99: 2.0 * p50,
            p999: 3.0 * p50,
            max: 4.0 * p50,
            count: 7,
        };
        let s = Summary {
            sim_time_s: 60.0,
            wall_time_s: 60.4,
            latency_us: Latency {
                end_to_end: lat(1500.0),
                hops: [
                    ("nav".to_string(), lat(12.0)),
                    ("truth".to_string(), lat(9.0)),
                ]
                .into(),
                ..Default::default()
            },
            deadline_misses: [("mpc".to_string(), 3), ("world".to_string(), 0)].into(),
            wake_late_us: [("mpc".to_string(), lat(50.0))].into(),
            ..Summary::default()
        };
        let t = render_realtime(&s);
        let e2e = t.lines().find(|l| l.starts_with("end to end")).unwrap();
        assert!(
            e2e.contains("1500")
                && e2e.contains("3000")
                && e2e.contains("4500")
                && e2e.contains("6000"),
            "{t}"
        );
        let mpc = t.lines().find(|l| l.starts_with("mpc")).unwrap();
        assert!(
            mpc.contains(" 3 ") && mpc.trim_end().ends_with("100"),
            "{t}"
        );
        let world = t.lines().find(|l| l.starts_with("world")).unwrap();
        assert!(world.trim_end().ends_with('-'), "{t}");
        assert!(
            t.lines()
                .any(|l| l.starts_with("nav") && l.contains("12.0")),
            "{t}"
        );
        assert!(
            t.lines()
                .any(|l| l.starts_with("truth") && l.contains("9.00")),
            "{t}"
        );
    }
}
