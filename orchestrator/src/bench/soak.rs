//! `shoal bench soak`: a long realtime run, watched from outside for what
//! grows.
//!
//! Generates a group (25 vehicles by default), starts `shoal run --mode
//! realtime` on it as a child for the whole duration (an hour by default),
//! and every `--every` seconds reads `/proc` and `/dev/shm`: the run's
//! processes (the orchestrator and every descendant), their resident and
//! private memory, their open file descriptors, and the shared-memory
//! entries of the run. The samples go to OUT/soak.csv as they come; at the
//! end a table gives them at the first minute and at every sixth of the
//! run, with each figure's growth after the first minute (a leak shows as
//! growth that goes on; start-up shows as growth before it). Nothing fails
//! on a figure: a run that fails is reported as such.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use serde::Serialize;
use serde_json::json;

use crate::gen::{self, GenOptions};
use crate::launch::os as sys;

/// Arguments of `shoal bench soak`.
#[derive(Debug, clap::Args)]
pub struct SoakCmd {
    /// Vehicles of the generated group (leader included).
    #[arg(long, default_value_t = 25)]
    pub vehicles: usize,
    /// Wall-clock (= simulated) seconds of the run.
    #[arg(long, default_value_t = 3600.0, value_parser = crate::cli::parse_duration)]
    pub duration: f64,
    /// Seconds between two samples.
    #[arg(long, default_value_t = 10.0)]
    pub every: f64,
    /// Seed of the generated course and of the run.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory: scenario.toml, soak.csv, soak.json and the run
    /// itself in run/ (default: /tmp/shoal-soak-<unix time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(short, long)]
    pub quiet: bool,
}

/// One reading of the run from outside.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct SoakSample {
    /// Seconds since the run was started.
    pub t_s: f64,
    /// Processes: the orchestrator and its descendants.
    pub processes: usize,
    /// Their resident memory, KiB (shared pages counted in every process
    /// that maps them).
    pub rss_kib: u64,
    /// Their private anonymous memory (`RssAnon`), KiB: where a leak grows.
    pub anon_kib: u64,
    /// Their open file descriptors.
    pub fds: usize,
    /// Shared-memory files of the run (`/dev/shm` and its domain directory).
    pub shm_run: usize,
    /// Every entry below `/dev/shm`, any run's.
    pub shm_all: usize,
}

/// How one figure moved after the first minute.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Growth {
    /// Its value at the first sample at or after 60 s.
    pub at_1min: f64,
    /// Its largest value after that.
    pub max_after: f64,
    /// Its value at the last sample.
    pub last: f64,
    /// `max_after / at_1min - 1` (0 when both are 0).
    pub growth: f64,
}

impl Growth {
    /// The growth of `f` after the first minute while the whole run is up
    /// (every process it had at 1 min; the summary after the run is
    /// another phase, see [`after_run`]); `None` if no sample lies at or
    /// after 60 s.
    pub fn of(samples: &[SoakSample], f: impl Fn(&SoakSample) -> f64) -> Option<Self> {
        let live = live(samples)?;
        let at_1min = f(&live[0]);
        let max_after = live.iter().map(&f).fold(at_1min, f64::max);
        let last = f(live.last()?);
        let growth = if at_1min > 0.0 {
            max_after / at_1min - 1.0
        } else if max_after > 0.0 {
            f64::INFINITY
        } else {
            0.0
        };
        Some(Self {
            at_1min,
            max_after,
            last,
            growth,
        })
    }
}

/// The samples from the first minute on while the run has every process
/// it had then.
fn live(samples: &[SoakSample]) -> Option<&[SoakSample]> {
    let i = samples.iter().position(|s| s.t_s >= 60.0)?;
    let full = samples[i].processes;
    let n = samples[i..]
        .iter()
        .take_while(|s| s.processes >= full)
        .count();
    Some(&samples[i..i + n])
}

/// The largest resident and private memory once the run's processes are
/// gone (the orchestrator writing the summary, plots and report), KiB.
pub fn after_run(samples: &[SoakSample]) -> Option<(u64, u64)> {
    let live = live(samples)?;
    let i = samples.iter().position(|s| s.t_s >= 60.0)? + live.len();
    let rest = &samples[i..];
    (!rest.is_empty()).then(|| {
        (
            rest.iter().map(|s| s.rss_kib).max().unwrap_or(0),
            rest.iter().map(|s| s.anon_kib).max().unwrap_or(0),
        )
    })
}

/// The process ids of `root` and all its descendants, from every
/// process's parent in `/proc/PID/stat`.
fn tree_of(root: i32) -> Vec<i32> {
    let mut parent = Vec::new();
    if let Ok(dir) = std::fs::read_dir("/proc") {
        for e in dir.flatten() {
            let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<i32>().ok()) else {
                continue;
            };
            let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
                continue;
            };
            // `pid (comm) state ppid ...`, the command name may hold spaces.
            let ppid = stat
                .rsplit_once(')')
                .and_then(|(_, rest)| rest.split_whitespace().nth(1)?.parse::<i32>().ok());
            if let Some(ppid) = ppid {
                parent.push((pid, ppid));
            }
        }
    }
    let mut tree = vec![root];
    let mut i = 0;
    while i < tree.len() {
        let p = tree[i];
        tree.extend(parent.iter().filter(|(_, pp)| *pp == p).map(|(c, _)| *c));
        i += 1;
    }
    tree
}

/// The run id a process of the tree carries (`--run-id`), if any yet.
fn run_id_of(pids: &[i32]) -> Option<String> {
    pids.iter().find_map(|pid| {
        let raw = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
        sys::arg_from_cmdline(&raw, "--run-id")
    })
}

/// Reads the run rooted at `root` now.
fn sample(root: i32, t_s: f64, run_id: &mut Option<String>) -> SoakSample {
    let pids = tree_of(root);
    if run_id.is_none() {
        *run_id = run_id_of(&pids);
    }
    let mut s = SoakSample {
        t_s,
        ..SoakSample::default()
    };
    let page_kib = sys::page_size() / 1024;
    for pid in &pids {
        let Ok(statm) = std::fs::read_to_string(format!("/proc/{pid}/statm")) else {
            continue;
        };
        s.processes += 1;
        s.rss_kib += statm
            .split_whitespace()
            .nth(1)
            .and_then(|p| p.parse::<u64>().ok())
            .unwrap_or(0)
            * page_kib;
        if let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) {
            s.anon_kib += shoal_runtime::stats::proc_status_kib(&status, "RssAnon:").unwrap_or(0);
        }
        s.fds += std::fs::read_dir(format!("/proc/{pid}/fd"))
            .map(|d| d.count())
            .unwrap_or(0);
    }
    s.shm_run = run_id
        .as_deref()
        .map_or(0, |id| shoal_runtime::list_domain_files(id).len());
    s.shm_all = crate::hosts::files_under(Path::new("/dev/shm")).len();
    s
}

/// Runs the soak.
pub fn run(cmd: SoakCmd) -> anyhow::Result<()> {
    anyhow::ensure!(cmd.every > 0.0, "--every must be > 0 s");
    anyhow::ensure!(cmd.duration > 0.0, "--duration must be > 0 s");
    let out = cmd.out.clone().unwrap_or_else(|| {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        PathBuf::from(format!("/tmp/shoal-soak-{now}"))
    });
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let text = gen::generate(&GenOptions {
        vehicles: cmd.vehicles,
        seed: cmd.seed,
        ..GenOptions::default()
    })?;
    let scenario = out.join("scenario.toml");
    std::fs::write(&scenario, text)?;
    let shoal = std::env::current_exe().context("the path of shoal itself")?;
    let mut run = Command::new(&shoal);
    run.arg("run")
        .arg(&scenario)
        .args(["--mode", "realtime", "--quiet", "--force"])
        .arg("--duration")
        .arg(cmd.duration.to_string())
        .arg("--seed")
        .arg(cmd.seed.to_string())
        .arg("--out")
        .arg(out.join("run"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(out.join("run.stderr"))?);
    sys::die_with_parent(&mut run);
    let mut child = run.spawn().context("cannot start shoal run")?;
    let root = child.id() as i32;
    eprintln!(
        "soak: {} vehicles in realtime for {:.0} s; samples every {:.0} s into {}",
        cmd.vehicles,
        cmd.duration,
        cmd.every,
        out.join("soak.csv").display()
    );
    let mut csv = std::io::BufWriter::new(std::fs::File::create(out.join("soak.csv"))?);
    writeln!(csv, "t_s,processes,rss_kib,anon_kib,fds,shm_run,shm_all")?;
    let bar = crate::progress::bar(!cmd.quiet, cmd.duration.ceil() as u64, "s");
    let start = Instant::now();
    let mut run_id = None;
    let mut samples = Vec::new();
    let mut next = Duration::ZERO;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        let now = start.elapsed();
        if now >= next {
            let s = sample(root, now.as_secs_f64(), &mut run_id);
            writeln!(
                csv,
                "{:.1},{},{},{},{},{},{}",
                s.t_s, s.processes, s.rss_kib, s.anon_kib, s.fds, s.shm_run, s.shm_all
            )?;
            csv.flush()?;
            samples.push(s);
            next += Duration::from_secs_f64(cmd.every);
        }
        bar.set_position(now.as_secs());
        std::thread::sleep(Duration::from_millis(200).min(next.saturating_sub(now)));
    };
    bar.finish_and_clear();
    // After the run: what it left behind.
    let after = sample(root, start.elapsed().as_secs_f64(), &mut run_id);
    let growth = |f: fn(&SoakSample) -> f64| Growth::of(&samples, f);
    let report = json!({
        "vehicles": cmd.vehicles,
        "duration_s": cmd.duration,
        "run_ok": status.success(),
        "run_status": status.to_string(),
        "run_id": run_id,
        "samples": samples.len(),
        "growth_after_1min": {
            "rss_kib": growth(|s| s.rss_kib as f64),
            "anon_kib": growth(|s| s.anon_kib as f64),
            "fds": growth(|s| s.fds as f64),
            "shm_run": growth(|s| s.shm_run as f64),
            "processes": growth(|s| s.processes as f64),
        },
        "left_after_run": { "shm_run": after.shm_run, "processes": after.processes },
        "summary_phase_peak_kib": after_run(&samples).map(|(rss, anon)| json!({ "rss": rss, "anon": anon })),
    });
    std::fs::write(
        out.join("soak.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    print!("{}", table(&samples));
    println!(
        "after the run: {} shared-memory files of the run left, {} processes",
        after.shm_run, after.processes
    );
    if let Some((rss, anon)) = after_run(&samples) {
        println!(
            "the summary after the run (the orchestrator alone): at most {:.0} MiB resident, {:.0} MiB private",
            rss as f64 / 1024.0,
            anon as f64 / 1024.0
        );
    }
    println!("while the whole run is up, from the first minute:");
    for (name, g) in [
        ("resident memory", growth(|s| s.rss_kib as f64)),
        ("private memory", growth(|s| s.anon_kib as f64)),
        ("open descriptors", growth(|s| s.fds as f64)),
        ("shared-memory files", growth(|s| s.shm_run as f64)),
    ] {
        if let Some(g) = g {
            println!(
                "{name}: {:.0} at 1 min, at most {:.0} after it ({:+.1} %), {:.0} at the end",
                g.at_1min,
                g.max_after,
                g.growth * 100.0,
                g.last
            );
        }
    }
    println!("figures: {}", out.join("soak.json").display());
    anyhow::ensure!(
        status.success(),
        "the run failed ({status}); see {}",
        out.join("run.stderr").display()
    );
    Ok(())
}

/// The samples at the first minute and at every sixth of the run.
fn table(samples: &[SoakSample]) -> String {
    let Some(last) = samples.last() else {
        return "no sample\n".into();
    };
    let mut picks = Vec::new();
    let mut marks: Vec<f64> = std::iter::once(60.0)
        .chain((1..=6).map(|k| last.t_s * k as f64 / 6.0))
        .collect();
    marks.sort_by(f64::total_cmp);
    for mark in marks {
        if let Some(s) = samples.iter().find(|s| s.t_s >= mark) {
            if picks.last() != Some(&s) {
                picks.push(s);
            }
        }
    }
    let mut out = format!(
        "{:>8} {:>9} {:>11} {:>11} {:>7} {:>9}\n",
        "t s", "processes", "RSS MiB", "private MiB", "fds", "shm files"
    );
    for s in picks {
        out += &format!(
            "{:>8.0} {:>9} {:>11.1} {:>11.1} {:>7} {:>9}\n",
            s.t_s,
            s.processes,
            s.rss_kib as f64 / 1024.0,
            s.anon_kib as f64 / 1024.0,
            s.fds,
            s.shm_run
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(t_s: f64, rss: u64) -> SoakSample {
        SoakSample {
            t_s,
            rss_kib: rss,
            ..SoakSample::default()
        }
    }

    #[test]
    fn the_summary_phase_is_apart_from_the_run() {
        let mut s: Vec<SoakSample> = (0..10).map(|i| at(i as f64 * 30.0, 100)).collect();
        for x in &mut s {
            x.processes = 5;
        }
        s.push(SoakSample {
            t_s: 300.0,
            processes: 1,
            rss_kib: 4000,
            anon_kib: 3000,
            ..SoakSample::default()
        });
        let g = Growth::of(&s, |s| s.rss_kib as f64).unwrap();
        assert_eq!(g.max_after, 100.0);
        assert_eq!(after_run(&s), Some((4000, 3000)));
        assert_eq!(after_run(&s[..10]), None);
    }

    #[test]
    fn growth_counts_from_the_first_minute() {
        // Start-up growth before 60 s does not count; 10 % after it does.
        let s = [
            at(0.0, 10),
            at(30.0, 90),
            at(60.0, 100),
            at(90.0, 110),
            at(120.0, 105),
        ];
        let g = Growth::of(&s, |s| s.rss_kib as f64).unwrap();
        assert_eq!(g.at_1min, 100.0);
        assert_eq!(g.max_after, 110.0);
        assert_eq!(g.last, 105.0);
        assert!((g.growth - 0.1).abs() < 1e-12);
        assert!(Growth::of(&s[..2], |s| s.rss_kib as f64).is_none());
        let zero = [at(60.0, 0), at(70.0, 0)];
        assert_eq!(Growth::of(&zero, |s| s.rss_kib as f64).unwrap().growth, 0.0);
    }

    #[test]
    fn the_tree_of_this_process_holds_its_children() {
        let mut child = Command::new("sleep").arg("5").spawn().unwrap();
        let tree = tree_of(std::process::id() as i32);
        assert_eq!(tree[0], std::process::id() as i32);
        assert!(tree.contains(&(child.id() as i32)));
        child.kill().unwrap();
        child.wait().unwrap();
        let s = sample(std::process::id() as i32, 1.0, &mut None);
        assert!(s.processes >= 1 && s.fds >= 3 && s.rss_kib > 0);
    }

    #[test]
    fn the_table_picks_the_first_minute_and_sixths() {
        let s: Vec<SoakSample> = (0..=36).map(|i| at(i as f64 * 10.0, 1024)).collect();
        let t = table(&s);
        // Header, 60 s, then 60 (already there), 120, ..., 360 s.
        assert_eq!(t.lines().count(), 1 + 6);
        assert!(t.lines().nth(1).unwrap().trim_start().starts_with("60"));
        assert!(t.lines().last().unwrap().trim_start().starts_with("360"));
        // A run shorter than 6 minutes: its sixths come before the minute.
        let t = table(&s[..10]);
        let times: Vec<f64> = t
            .lines()
            .skip(1)
            .map(|l| l.split_whitespace().next().unwrap().parse().unwrap())
            .collect();
        assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
    }
}
