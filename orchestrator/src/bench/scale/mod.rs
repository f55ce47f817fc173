//! `shoal bench scale`: what a group costs as it grows (issue 8).
//!
//! For each group size N of `--vehicles` (default 5, 25, 50, 100) it
//! generates a scenario with the generator of `shoal gen` (`--shape`,
//! `--seed`), cuts it to `--duration` simulated seconds, checks that the
//! machine can hold the run ([`preflight::needs`] / [`preflight::fits`]: processes,
//! `/dev/shm`, open files) and runs it in lockstep through the same code as
//! `shoal run`, into `OUT/nNNN/` (recording, summary.json, logs). A size the
//! machine cannot hold is skipped with its reason in the table; a run that
//! fails is reported and the next size still runs.
//!
//! Per N it reports:
//!
//! * **processes**: service processes spawned (the orchestrator not counted);
//! * **real-time factor**: simulated s / wall s, first tick to last;
//! * **start+stop**: wall time of the run outside the ticks (spawning every
//!   process, waiting for all to be ready, stopping and reaping them), s;
//! * **CPU per vehicle-second**: user + system CPU time of every process of
//!   the run, the orchestrator's share included (start-up and shutdown
//!   too), divided by N × simulated s, in ms;
//! * **peak memory**: the sum over every process (orchestrator included) of
//!   its peak resident set (`VmHWM`), MiB. Shared pages (libraries, iceoryx2
//!   segments) count once per process that touched them, so this is an
//!   upper bound of what the run occupies; next to it the sum of the peak
//!   private (anonymous) memory, which is counted once. A thread reads
//!   `/proc/PID/status` of every child every 0.2 s while the run goes (the
//!   `ru_maxrss` of `wait4` would also count the orchestrator's pages that a
//!   child holds between fork and exec); its CPU is left out of the
//!   orchestrator's;
//! * **recorder messages/s and drops**: messages in the recording (its
//!   `shoal.recorder` metadata) per wall second, and the messages it lost;
//! * **collisions, min pair distance, min parent visible, max parent
//!   range**: from the summary, so a fast run that went wrong shows (the
//!   range is from a follower's camera to its parent, against the camera's
//!   visibility range).
//!
//! Then the cost ratio (CPU per vehicle-second at the largest N that ran
//! against N = 25; issue 8 asks for ≤ 1.5). It writes `OUT/scale.md` (the
//! table), `OUT/scale.json` (every figure) and `OUT/scale.png` /
//! `OUT/scale.svg` (cost and real-time factor against N). Nothing fails on
//! a figure.
//!
//! With `--floor` every vehicle process is started with `--no-work`: rung
//! at each tick it is due, it reports done and publishes its statistics,
//! but builds no task and opens no port. The world and the recorder work.
//! The table is then what the runtime itself costs for N vehicles; the
//! difference to a normal run is the vehicles' work and its traffic.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde_json::{json, Value};
use shoal_runtime::Mode;
use shoal_scenario::Scenario;

mod figures;
mod memory;
mod plot;
mod table;

pub use figures::{MemorySampled, ScaleSummary};

use figures::*;
use memory::*;
use plot::*;
use table::*;

use super::run::fmt_num;
use crate::gen::{self, GenOptions, Shape};
use crate::launch::os as sys;
use crate::launch::os::{own_memory, reset_own_peak_rss};
use crate::launch::{self, RunSettings};
use serde::{Deserialize, Serialize};

use crate::analysis::summary::{self, Summary};
use crate::{plots, preflight};

/// Issue 8: cost per vehicle-second at N = 100 at most this multiple of
/// the cost at N = 25.
const COST_RATIO_BOUND: f64 = 1.5;
/// The size the cost ratio is taken against.
const REFERENCE_N: usize = 25;

/// Arguments of `shoal bench scale`.
#[derive(Debug, clap::Args)]
#[command(
    long_about = "What a group costs as it grows. For each N of --vehicles, generate a scenario \
                  as `shoal gen --vehicles N --shape SHAPE --seed SEED` does, run it in lockstep \
                  for --duration simulated seconds and report: processes, real-time factor, \
                  wall time spent starting and stopping the processes, \
                  total CPU time per vehicle-second (every process, the orchestrator included), \
                  peak memory (sum of every process's peak RSS, and of its private memory, \
                  sampled from /proc every 0.2 s), recorder messages/s and drops, \
                  collisions, minimum pair distance and the least time a follower saw its parent. \
                  A size the machine cannot hold (processes, /dev/shm, open files; see `shoal \
                  check`) is skipped with the reason. Writes OUT/scale.md, OUT/scale.json and \
                  OUT/scale.png/.svg (cost and real-time factor against N); each run stays in \
                  OUT/nNNN/. With --floor the vehicle processes take part in every tick without \
                  working: the runtime's own cost, to set beside a normal run's.\n\nExamples: \
                  shoal bench scale --vehicles 5,25 --duration 20\n          \
                  shoal bench scale --vehicles 25,100 --floor"
)]
pub struct ScaleCmd {
    /// Group sizes to run, vehicles with the leader, comma-separated (each
    /// 2 to 256; run in increasing order, duplicates once).
    #[arg(long, value_delimiter = ',', default_value = "5,25,50,100", value_parser = parse_vehicles)]
    pub vehicles: Vec<usize>,
    /// Formation shape of the generated scenarios (as `shoal gen --shape`).
    #[arg(long, value_enum, default_value_t = Shape::Triangle)]
    pub shape: Shape,
    /// Simulated seconds of each run (the generated scenario's own duration
    /// is replaced; 30 s covers the start, not the gates).
    #[arg(long = "duration", default_value_t = 30.0, allow_negative_numbers = true,
          value_parser = crate::cli::parse_duration)]
    pub duration_s: f64,
    /// Seed of the generator and of the scenario's noise (as `shoal gen --seed`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory (default: runs/bench-scale-<unix time>); each run
    /// goes into OUT/nNNN/.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also draw every run's figures into OUT/nNNN/plots/ (slow for large
    /// groups: the pair-distance figure has N(N−1)/2 curves).
    #[arg(long)]
    pub plots: bool,
    /// The runtime's floor: start every vehicle process with `--no-work`.
    /// Each is still rung at every tick it is due, reports done and
    /// publishes its statistics, but builds no task and opens no port; the
    /// world and the recorder work as usual. Set beside a normal run, it
    /// splits a group's cost into the runtime's and the vehicles' work.
    #[arg(long)]
    pub floor: bool,
    #[command(flatten)]
    pub processes: crate::cli::ProcessArgs,
}

fn parse_vehicles(s: &str) -> Result<usize, String> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number of vehicles"))?;
    if !(2..=gen::MAX_VEHICLES).contains(&n) {
        return Err(format!(
            "{n}: a group has 2 to {} vehicles (a leader and at least one follower)",
            gen::MAX_VEHICLES
        ));
    }
    Ok(n)
}

/// Generates the scenario of `n` vehicles, cut to `duration_s`, resolved.
fn scenario_for(cmd: &ScaleCmd, n: usize) -> anyhow::Result<Scenario> {
    let opts = GenOptions {
        vehicles: n,
        shape: cmd.shape,
        seed: cmd.seed,
        ..GenOptions::default()
    };
    let text = gen::generate(&opts).with_context(|| format!("generating N = {n}"))?;
    let mut s = Scenario::from_toml(&text)
        .with_context(|| format!("the generated scenario of N = {n} does not parse"))?;
    s.duration_s = cmd.duration_s;
    preflight::resolve(&mut s).with_context(|| format!("the generated scenario of N = {n}"))?;
    Ok(s)
}

/// Runs one resolved scenario into `dir`: summary.json (with a
/// `memory_sampled` section: peak RSS and private memory per kind, the
/// orchestrator's included) and, if asked, the figures.
fn run_one(
    scenario: &Scenario,
    dir: &Path,
    settings: &RunSettings,
    plots: bool,
) -> anyhow::Result<Figures> {
    let opts = settings.options(scenario, dir);
    let peak_reset = reset_own_peak_rss();
    let cpu_before = sys::self_cpu_s();
    let period = sample_period(scenario.processes().len());
    let sampler = MemSampler::start(period)?;
    let t0 = Instant::now();
    let outcome = launch::run(&opts);
    let run_call_s = t0.elapsed().as_secs_f64();
    let peaks = sampler.finish();
    let outcome = outcome?;
    let processes = scenario.processes().len();
    if peaks.procs.len() < processes {
        eprintln!(
            "memory: only {} of {processes} processes were swept (every {} ms); \
             the memory figures undercount",
            peaks.procs.len(),
            period.as_millis()
        );
    }
    let (mut rss, mut private) = peaks.by_kind();
    if let Some(own) = own_memory() {
        rss.insert("orchestrator".into(), own.hwm_kib);
        private.insert("orchestrator".into(), own.anon_kib);
    }
    let rec = recordings::Recording::open(&outcome.recording)?;
    let s = ScaleSummary {
        run: summary::summarize(scenario, &rec, &outcome, settings.mode.as_str()),
        run_call_s: Some(run_call_s),
        memory_sampled: MemorySampled {
            peak_rss_kib: rss,
            peak_private_kib: private,
            processes_sampled: peaks.procs.len(),
            sweeps: peaks.sweeps,
            period_s: period.as_secs_f64(),
            sampler_cpu_s: peaks.sampler_cpu_s,
            orchestrator_peak_reset: peak_reset,
        },
    };
    let path = dir.join("summary.json");
    std::fs::write(&path, serde_json::to_string_pretty(&s)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    if plots {
        plots::write_plots(scenario, &rec, &dir.join("plots")).context("writing the plots")?;
    }
    Ok(Figures::from_summary(&s, cpu_before))
}

/// True if the error is SIGINT/SIGTERM: the benchmark stops there.
fn interrupted(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        matches!(
            c.downcast_ref::<launch::RunError>(),
            Some(launch::RunError::Interrupted(_))
        )
    })
}

/// Generates, checks and runs the scenario of `n` vehicles into `dir`; its
/// row, and the error if a termination request stopped it (the benchmark
/// stops there).
fn one_size(
    cmd: &ScaleCmd,
    n: usize,
    tag: &str,
    dir: PathBuf,
    settings: &RunSettings,
) -> (Row, Option<anyhow::Error>) {
    let row = |processes: Option<usize>, status: Status| Row {
        vehicles: n,
        processes,
        dir: dir.clone(),
        status,
    };
    let scenario = match scenario_for(cmd, n) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{tag}: FAILED: {e:#}");
            let status = Status::Failed(format!("{e:#}"));
            return (row(None, status), None);
        }
    };
    let processes = scenario.processes().len();
    let needs = preflight::needs(&scenario);
    if let Err(e) = preflight::fits(&needs) {
        eprintln!("{tag}: skipped, the machine cannot hold it: {e:#}");
        let status = Status::Skipped(format!("{e:#}"));
        return (row(Some(processes), status), None);
    }
    eprintln!(
        "{tag}: {processes} processes, {} s simulated, into {} ...",
        fmt_num(cmd.duration_s),
        dir.display()
    );
    let t0 = Instant::now();
    let status = match run_one(&scenario, &dir, settings, cmd.plots) {
        Ok(f) => {
            eprintln!(
                "{tag}: {}x real time, {} ms CPU per vehicle-s, {} MiB peak RSS sum, \
                 {} recorder msg/s, {} dropped, {} collisions ({:.0} s)",
                fmt_num(f.rtf()),
                fmt_num(f.cpu_ms_per_vehicle_s(n)),
                fmt_num(f.rss_total_mib()),
                fmt_num(f.recorder_msgs_per_s()),
                f.recorder_dropped,
                f.collisions,
                t0.elapsed().as_secs_f64()
            );
            Status::Ran(Box::new(f))
        }
        Err(e) if interrupted(&e) => {
            eprintln!("{tag}: interrupted");
            let status = Status::Failed(format!("{e:#}"));
            return (row(Some(processes), status), Some(e));
        }
        Err(e) => {
            eprintln!("{tag}: FAILED: {e:#}");
            Status::Failed(format!("{e:#}"))
        }
    };
    (row(Some(processes), status), None)
}

/// Runs the benchmark: a progress line per N on stderr, the table on
/// stdout, the files into OUT.
pub fn run(cmd: ScaleCmd) -> anyhow::Result<()> {
    let mut sizes = cmd.vehicles.clone();
    sizes.sort_unstable();
    sizes.dedup();
    let out = cmd.out.clone().unwrap_or_else(|| {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        Path::new("runs").join(format!("bench-scale-{secs}"))
    });
    let dir_of = |n: usize| out.join(format!("n{n:03}"));
    for &n in &sizes {
        if dir_of(n).join("recording.mcap").exists() {
            anyhow::bail!(
                "{} already holds a recording; choose another --out (nothing was overwritten)",
                dir_of(n).display()
            );
        }
    }
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut settings = cmd.processes.settings(Mode::Lockstep, false)?;
    settings.no_work = cmd.floor;
    let started = Instant::now();
    let load_before = crate::launch::os::load_average();
    let mut rows: Vec<Row> = Vec::with_capacity(sizes.len());
    let mut stopped: Option<anyhow::Error> = None;
    for (i, &n) in sizes.iter().enumerate() {
        let tag = format!("[{}/{}] N = {n}", i + 1, sizes.len());
        let (row, interruption) = one_size(&cmd, n, &tag, dir_of(n), &settings);
        rows.push(row);
        if interruption.is_some() {
            stopped = interruption;
            break;
        }
    }
    let load_after = crate::launch::os::load_average();
    let elapsed = started.elapsed().as_secs_f64();

    let load = |l: Option<f64>| l.map_or("?".to_string(), |x| format!("{x:.2}"));
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    let head = format!(
        "shoal bench scale: shape {}, seed {}, {} s simulated per run, lockstep; {cpus} CPUs, \
         load average {} -> {}; {:.0} s in all{}{}",
        cmd.shape.name(),
        cmd.seed,
        fmt_num(cmd.duration_s),
        load(load_before),
        load(load_after),
        elapsed,
        if cmd.processes.idle_poll {
            "; idle CPUs poll (/dev/cpu_dma_latency held at 0)"
        } else {
            ""
        },
        if cmd.floor {
            "; floor: the vehicle processes do no work (--no-work)"
        } else {
            ""
        }
    );
    let table = render_table(&rows);
    println!("{head}\n\n{table}");
    let md = format!(
        "# shoal bench scale\n\n{head}\n\n{table}\nCPU: every process of the run, the \
         orchestrator included, per vehicle and simulated second. Peak RSS sum: every \
         process's peak resident set added up (shared pages count once per process).\n"
    );
    let md_path = out.join("scale.md");
    std::fs::write(&md_path, md).with_context(|| format!("cannot write {}", md_path.display()))?;
    let doc = json!({
        "shape": cmd.shape.name(),
        "seed": cmd.seed,
        "duration_s": cmd.duration_s,
        "mode": "lockstep",
        "floor": cmd.floor,
        "cpus": cpus,
        "load_average": [load_before, load_after],
        "elapsed_s": elapsed,
        "rows": rows.iter().map(Row::to_json).collect::<Vec<_>>(),
        "cost_ratio": cost_ratio(&rows).map(|(n, r)| json!({
            "vehicles": n, "reference_vehicles": REFERENCE_N, "ratio": r,
            "bound": COST_RATIO_BOUND, "met": r <= COST_RATIO_BOUND,
        })),
    });
    let json_path = out.join("scale.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&doc)?)
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    let title = format!(
        "shoal bench scale: cost and speed against group size ({} formation, {} s simulated, lockstep)",
        cmd.shape.name(),
        fmt_num(cmd.duration_s)
    );
    match write_plot(&rows, &title, &out) {
        Ok(files) if files.is_empty() => eprintln!("no run finished: no plot"),
        Ok(_) => {}
        Err(e) => eprintln!("the plot could not be drawn: {e:#}"),
    }
    println!("{}", out.display());
    if let Some(e) = stopped {
        return Err(e);
    }
    let failed: Vec<usize> = rows
        .iter()
        .filter(|r| matches!(r.status, Status::Failed(_)))
        .map(|r| r.vehicles)
        .collect();
    if !failed.is_empty() {
        anyhow::bail!("the runs of N = {failed:?} failed (see the table and their logs)");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launch::os::{kind_from_cmdline, parse_status, MemReading};
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        cmd: ScaleCmd,
    }

    fn parse(args: &[&str]) -> Result<ScaleCmd, clap::Error> {
        Cli::try_parse_from(std::iter::once("scale").chain(args.iter().copied())).map(|c| c.cmd)
    }

    fn figures(sim_s: f64, wall_s: f64, cpu: &[(&str, f64)], rss: &[(&str, i64)]) -> Figures {
        let private = rss.iter().map(|(k, v)| (k.to_string(), *v / 2)).collect();
        Figures {
            sim_s,
            wall_s,
            run_call_s: Some(wall_s + 4.0),
            cpu_s: cpu.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            rss_kib: rss.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            private_kib: private,
            recorder_messages: 1000,
            recorder_dropped: 0,
            collisions: 0,
            min_pair_m: Some(3.5),
            safe_distance_m: Some(2.0),
            min_parent_visible: Some(0.97),
            max_parent_range_m: Some(10.5),
            visibility_range_m: Some(12.0),
        }
    }

    fn ran(n: usize, cpu_total: f64) -> Row {
        Row {
            vehicles: n,
            processes: Some(5 * n + 1),
            dir: PathBuf::from(format!("out/n{n:03}")),
            status: Status::Ran(Box::new(figures(
                20.0,
                10.0,
                &[("mpc", cpu_total)],
                &[("mpc", 1024)],
            ))),
        }
    }

    #[test]
    fn arguments_default_to_the_issue_sizes_and_refuse_bad_ones() {
        let c = parse(&[]).unwrap();
        assert_eq!(c.vehicles, vec![5, 25, 50, 100]);
        assert_eq!(c.shape, Shape::Triangle);
        assert_eq!(c.duration_s, 30.0);
        assert!(c.out.is_none() && !c.plots);
        let c = parse(&["--vehicles", "25,5", "--duration", "20", "--shape", "v"]).unwrap();
        assert_eq!(c.vehicles, vec![25, 5]);
        assert_eq!(c.duration_s, 20.0);
        assert_eq!(c.shape, Shape::V);
        assert!(parse(&["--vehicles", "1"]).is_err());
        assert!(parse(&["--vehicles", &(gen::MAX_VEHICLES + 1).to_string()]).is_err());
        assert!(parse(&["--vehicles", "5,x"]).is_err());
        assert!(parse(&["--duration", "0"]).is_err());
        let refused = parse(&["--duration", "-3"]).unwrap_err().to_string();
        assert!(
            refused.contains("not a positive number of seconds"),
            "{refused}"
        );
        assert!(parse(&["--duration", "nan"]).is_err());
    }

    #[test]
    fn figures_are_read_from_the_summary_with_this_runs_orchestrator_cpu() {
        let map = |kv: &[(&str, f64)]| -> BTreeMap<String, f64> {
            kv.iter().map(|(k, v)| (k.to_string(), *v)).collect()
        };
        let kib = |kv: &[(&str, i64)]| -> BTreeMap<String, i64> {
            kv.iter().map(|(k, v)| (k.to_string(), *v)).collect()
        };
        let mut run = Summary {
            sim_time_s: 20.0,
            wall_time_s: 8.0,
            cpu_time_s: map(&[("mpc", 6.0), ("orchestrator", 12.0), ("world", 1.0)]),
            ..Summary::default()
        };
        run.recording.messages = 4000;
        run.recording.dropped = 2;
        run.safety.min_pair_distance_m = Some(2.5);
        run.safety.safe_distance_m = 2.0;
        run.perception.leader_visible_fraction = map(&[("F1", 0.9), ("F2", 0.75)]);
        run.perception.parent_range_max_m = map(&[("F1", 9.5), ("F2", 11.25)]);
        run.perception.visibility_range_m = 12.0;
        let s = ScaleSummary {
            run,
            run_call_s: Some(11.5),
            memory_sampled: MemorySampled {
                peak_rss_kib: kib(&[("mpc", 20480), ("orchestrator", 10240)]),
                peak_private_kib: kib(&[("mpc", 2048), ("orchestrator", 1024)]),
                sampler_cpu_s: 0.25,
                ..MemorySampled::default()
            },
        };
        // The orchestrator: 12 s cumulative − 10.75 s before − 0.25 s sampler.
        let f = Figures::from_summary(&s, 10.75);
        assert_eq!(f.cpu_s["orchestrator"], 1.0);
        assert_eq!(f.cpu_total_s(), 8.0);
        assert_eq!(f.rtf(), 2.5);
        // 8 s of CPU over 5 vehicles × 20 s = 80 ms per vehicle-second.
        approx::assert_relative_eq!(f.cpu_ms_per_vehicle_s(5), 80.0, epsilon = 1e-12);
        assert_eq!(f.rss_total_mib(), 30.0);
        assert_eq!(f.private_total_mib(), 3.0);
        assert_eq!(f.start_stop_s(), Some(3.5));
        assert_eq!(f.recorder_msgs_per_s(), 500.0);
        assert_eq!(f.recorder_dropped, 2);
        assert_eq!(f.min_parent_visible, Some(0.75));
        assert_eq!(f.max_parent_range_m, Some(11.25));
        assert_eq!(f.visibility_range_m, Some(12.0));
        assert_eq!(f.min_pair_m, Some(2.5));
        // A summary.json that lacks a figure is refused when read, not read as 0.
        assert!(serde_json::from_value::<ScaleSummary>(json!({ "sim_time_s": 1.0 })).is_err());
        // What the benchmark writes reads back whole.
        let text = serde_json::to_string(&s).unwrap();
        assert_eq!(serde_json::from_str::<ScaleSummary>(&text).unwrap(), s);
    }

    #[test]
    fn memory_readings_come_from_status_and_the_kind_from_the_command_line() {
        let status = "Name:\tshoal-mpc\nVmPeak:\t  99999 kB\nVmHWM:\t   14000 kB\nVmRSS:\t   12000 kB\nRssAnon:\t    3000 kB\nRssFile:\t    9000 kB\n";
        assert_eq!(
            parse_status(status),
            Some(MemReading {
                hwm_kib: 14000,
                anon_kib: 3000
            })
        );
        assert_eq!(parse_status("Name:\tx\n"), None);
        let cmdline =
            b"/bin/shoal-mpc\0--run-id\0ab12\0--vehicle\0F1\0--process\0mpc\0--index\x003\0";
        assert_eq!(kind_from_cmdline(cmdline), Some("mpc".to_string()));
        // The orchestrator's own command line (a child before exec).
        assert_eq!(kind_from_cmdline(b"shoal\0bench\0scale\0"), None);
        let mut peaks = MemPeaks::default();
        let r = |h, a| MemReading {
            hwm_kib: h,
            anon_kib: a,
        };
        peaks.procs.insert(10, ("mpc".into(), r(100, 10)));
        peaks.procs.insert(11, ("mpc".into(), r(300, 30)));
        peaks.procs.insert(12, ("world".into(), r(50, 5)));
        let (rss, private) = peaks.by_kind();
        assert_eq!(rss["mpc"], 400);
        assert_eq!(rss["world"], 50);
        assert_eq!(private["mpc"], 40);
        assert_eq!(private["world"], 5);
    }

    #[test]
    fn the_cost_ratio_is_the_largest_n_that_ran_against_n25() {
        // Cost per vehicle-s: total / (N × 20 s).
        let rows = vec![
            ran(5, 1.0),
            ran(25, 5.0),
            ran(50, 12.0),
            Row {
                vehicles: 100,
                processes: Some(501),
                dir: PathBuf::from("out/n100"),
                status: Status::Skipped("vehicles: too many processes".into()),
            },
        ];
        let (n, r) = cost_ratio(&rows).unwrap();
        assert_eq!(n, 50);
        approx::assert_relative_eq!(r, (12.0 / 50.0) / (5.0 / 25.0), epsilon = 1e-12);
        // Without N = 25, or with nothing larger, there is no ratio.
        assert_eq!(cost_ratio(&[ran(5, 1.0), ran(50, 10.0)]), None);
        assert_eq!(cost_ratio(&[ran(5, 1.0), ran(25, 5.0)]), None);
    }

    #[test]
    fn the_table_has_a_row_per_size_and_says_why_one_was_skipped() {
        let mut unhealthy = ran(50, 20.0);
        if let Status::Ran(f) = &mut unhealthy.status {
            f.collisions = 1;
        }
        let rows = vec![
            ran(5, 1.0),
            ran(25, 5.0),
            unhealthy,
            Row {
                vehicles: 100,
                processes: Some(501),
                dir: PathBuf::from("out/n100"),
                status: Status::Skipped(
                    "vehicles: the run needs 502 processes, but only 300 more can start here"
                        .into(),
                ),
            },
        ];
        let t = render_table(&rows);
        // A figure per line, a size per column.
        let cols = |l: &str| -> Vec<String> {
            l.trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_string())
                .collect()
        };
        let line = |h: &str| {
            let l = t
                .lines()
                .find(|l| l.starts_with(&format!("| {h} ")))
                .unwrap_or_else(|| panic!("no line {h} in\n{t}"));
            cols(l)
        };
        assert_eq!(line("N"), ["N", "5", "25", "50", "100"]);
        assert!(
            t.lines().all(|l| l.chars().count() <= 100),
            "too wide:\n{t}"
        );
        // N = 25: 5 s CPU over 25 × 20 vehicle-s = 10 ms; 2x real time; 4 s
        // outside the ticks; 1 MiB RSS, 0.5 MiB private; 1000 messages over 10 s.
        let at25 = |h: &str| line(h)[2].clone();
        assert_eq!(at25(HEADINGS[1]), "126");
        assert_eq!(at25(HEADINGS[2]), "2.00x");
        assert_eq!(at25(HEADINGS[3]), "4.00");
        assert_eq!(at25(HEADINGS[4]), "10.0");
        assert_eq!(at25(HEADINGS[5]), "1.00");
        assert_eq!(at25(HEADINGS[6]), "0.500");
        assert_eq!(at25(HEADINGS[7]), "100");
        assert_eq!(at25(HEADINGS[11]), "97%");
        assert_eq!(at25(HEADINGS[12]), "10.5");
        assert!(!t.contains("N = 25:"), "{t}");
        assert!(t.contains("N = 50: UNHEALTHY"), "{t}");
        assert_eq!(line(HEADINGS[1])[4], "501");
        assert!(
            t.contains("N = 100: skipped: vehicles: the run needs 502"),
            "{t}"
        );
        // The ratio line: N = 50 (largest that ran) against N = 25.
        let expected = format!("{:.2}", (20.0 / 50.0) / (5.0 / 25.0));
        assert!(
            t.lines()
                .any(|l| l.contains("N = 50 / N = 25") && l.contains(&expected)),
            "{t}"
        );
    }

    #[test]
    fn the_plot_is_written_when_a_run_finished() {
        let tmp = tempfile::tempdir().unwrap();
        let rows = vec![ran(5, 1.0), ran(25, 5.0)];
        let files = write_plot(&rows, "test", tmp.path()).unwrap();
        assert_eq!(files.len(), 2);
        let png = std::fs::read(tmp.path().join("scale.png")).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        let svg = std::fs::read_to_string(tmp.path().join("scale.svg")).unwrap();
        assert!(svg.contains("vehicles N") && svg.contains("1.5 x cost at N = 25"));
        let skipped = vec![Row {
            vehicles: 5,
            processes: None,
            dir: PathBuf::from("x"),
            status: Status::Failed("no".into()),
        }];
        assert!(write_plot(&skipped, "test", tmp.path()).unwrap().is_empty());
    }
}
