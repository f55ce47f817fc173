//! `shoal bench step`: what the runtime costs per lockstep step of each
//! process kind, and the orchestrator per tick, apart from what a process
//! costs once (exec, opening its services, writing its exit files).
//!
//! A process's CPU time covers its whole life, so CPU ÷ steps overstates a
//! step. The bench runs the scenario at two lengths (`--short`, `--long`),
//! alternately (`--repeat` pairs), and takes the *marginal* cost: the extra
//! CPU of the long run over the extra steps. With `--syscalls` it runs one
//! more pair under `strace -f` and counts the system calls each kind makes
//! per step the same way (long minus short), by name.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::Context;
use shoal_runtime::Mode;
use shoal_scenario::{ProcessKind, Scenario};

use super::run::{fmt_num, Scratch};
use crate::analysis::summary::Summary;
use crate::cli::ProcessArgs;
use crate::launch::{self, os as sys};
use crate::pipeline::run_and_summarize;
use crate::preflight::load_scenario_with;

/// `shoal bench step`.
#[derive(Debug, clap::Args)]
pub struct StepCmd {
    /// Scenario TOML (default: the embedded paper scenario).
    pub scenario: Option<PathBuf>,
    /// Simulated seconds of the short run.
    #[arg(long, default_value_t = 10.0, value_parser = crate::cli::parse_duration)]
    pub short: f64,
    /// Simulated seconds of the long run.
    #[arg(long, default_value_t = 50.0, value_parser = crate::cli::parse_duration)]
    pub long: f64,
    /// Pairs of runs (short, long), alternated; the median is printed.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
    /// Also count system calls per step by kind and name (one more pair of
    /// runs, under `strace -f`, which must be installed).
    #[arg(long)]
    pub syscalls: bool,
    /// Keep the runs' directories (under /tmp) and print where.
    #[arg(long)]
    pub keep: bool,
    #[command(flatten)]
    pub processes: ProcessArgs,
}

/// CPU seconds and steps of each kind (and the orchestrator's, per busy
/// tick) in one run.
#[derive(Debug, Clone, Default)]
struct Costs {
    cpu_s: BTreeMap<String, f64>,
    steps: BTreeMap<String, f64>,
}

const ORCHESTRATOR: &str = "orchestrator";

/// System calls by kind, then by name.
type Calls = BTreeMap<String, BTreeMap<String, f64>>;

impl Costs {
    fn of(summary: &Summary, cpu_before: f64, scenario: &Scenario) -> Self {
        let mut c = Self::default();
        for (kind, s) in &summary.step_us {
            c.steps.insert(kind.clone(), s.count as f64);
            if let Some(cpu) = summary.cpu_time_s.get(kind) {
                c.cpu_s.insert(kind.clone(), *cpu);
            }
        }
        let orchestrator = summary
            .cpu_time_s
            .get(ORCHESTRATOR)
            .copied()
            .unwrap_or(f64::NAN);
        c.cpu_s
            .insert(ORCHESTRATOR.into(), orchestrator - cpu_before);
        c.steps.insert(
            ORCHESTRATOR.into(),
            crate::hosts::placement::lockstep_ticks_per_sim_s(scenario) * summary.sim_time_s,
        );
        c
    }
}

/// The marginal cost per step of `kind`, µs: long over short.
fn marginal_us(short: &Costs, long: &Costs, kind: &str) -> Option<f64> {
    let d_cpu = long.cpu_s.get(kind)? - short.cpu_s.get(kind)?;
    let d_steps = long.steps.get(kind)? - short.steps.get(kind)?;
    (d_steps > 0.0).then(|| d_cpu * 1e6 / d_steps)
}

/// The median of `v` (sorted in place).
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Runs the benchmark.
pub fn run(cmd: StepCmd) -> anyhow::Result<()> {
    anyhow::ensure!(
        cmd.long > cmd.short,
        "--long ({} s) must be longer than --short ({} s)",
        cmd.long,
        cmd.short
    );
    let base = load_scenario_with(&cmd.scenario, |_| {})?;
    let with = |d: f64| {
        let mut s = base.clone();
        s.duration_s = d;
        s
    };
    let (short_sc, long_sc) = (with(cmd.short), with(cmd.long));
    let scratch = Scratch {
        path: std::env::temp_dir().join(format!("shoal-bench-step-{}", std::process::id())),
        keep: cmd.keep,
    };
    std::fs::create_dir_all(&scratch.path)?;
    let settings = cmd.processes.settings(Mode::Lockstep, true)?;
    // Held for the wake-up reference too; each run holds it again.
    let qos = launch::idle_poll_guard(settings.idle_poll)?;
    // The floor a step can reach: one blocking wake-up, measured here now.
    let wake_us = sys::wake_up_cpu_us(20_000).context("the wake-up reference")?;
    // The same through the doorbell that wakes a lockstep process.
    let futex_us = sys::futex_wake_up_cpu_us(20_000).context("the doorbell wake-up reference")?;
    let mut pairs = Vec::new();
    for i in 0..cmd.repeat {
        let mut pair = Vec::new();
        for (label, sc) in [("short", &short_sc), ("long", &long_sc)] {
            let out = scratch.path.join(format!("{label}-{}", i + 1));
            let cpu_before = sys::self_cpu_s();
            let summary = run_and_summarize(sc.clone(), &out, &settings)
                .with_context(|| format!("the run into {} failed", out.display()))?
                .summary;
            eprintln!(
                "  pair {}/{}, {label} ({} s): {:.1}x real time",
                i + 1,
                cmd.repeat,
                fmt_num(sc.duration_s),
                summary.real_time_factor
            );
            pair.push(Costs::of(&summary, cpu_before, sc));
        }
        pairs.push(pair);
    }
    let mut kinds: Vec<String> = pairs[0][1].steps.keys().cloned().collect();
    kinds.sort_by_key(|k| (k == ORCHESTRATOR, k.clone()));
    println!(
        "CPU per step, {} pairs of {} s and {} s in lockstep (load {}):",
        cmd.repeat,
        fmt_num(cmd.short),
        fmt_num(cmd.long),
        fmt_num(launch::os::load_average().unwrap_or(f64::NAN))
    );
    println!(
        "  one blocking wake-up (two threads, Unix datagram ping-pong): {} us of CPU; \
         by the lockstep doorbell (futex): {} us{}",
        fmt_num(wake_us),
        fmt_num(futex_us),
        if qos.is_some() {
            "; idle CPUs poll (/dev/cpu_dma_latency held at 0)"
        } else {
            ""
        }
    );
    println!(
        "  {:<28} {:>12} {:>14} {:>12} {:>10}",
        "kind", "marginal us", "whole-life us", "steps (long)", "/ wake-up"
    );
    let mut figures = BTreeMap::new();
    for kind in &kinds {
        let mut m: Vec<f64> = pairs
            .iter()
            .filter_map(|p| marginal_us(&p[0], &p[1], kind))
            .collect();
        let mut whole: Vec<f64> = pairs
            .iter()
            .filter_map(|p| {
                let (cpu, steps) = (p[1].cpu_s.get(kind)?, p[1].steps.get(kind)?);
                (*steps > 0.0).then(|| cpu * 1e6 / steps)
            })
            .collect();
        let steps = pairs[0][1].steps.get(kind).copied().unwrap_or(0.0);
        let (m, w) = (median(&mut m), median(&mut whole));
        let label = if kind == ORCHESTRATOR {
            "orchestrator (per busy tick)".to_string()
        } else {
            kind.clone()
        };
        println!(
            "  {label:<28} {:>12} {:>14} {:>12} {:>10}",
            fmt_num(m),
            fmt_num(w),
            fmt_num(steps),
            fmt_num(m / wake_us)
        );
        figures.insert(
            kind.clone(),
            serde_json::json!({ "marginal_us": m, "whole_life_us": w, "per_wake_up": m / wake_us }),
        );
    }
    if cmd.syscalls {
        let bin = launch::bin_dir_or_default(cmd.processes.bin_dir.clone())?;
        let counts: Vec<(Costs, Calls)> = [("short", &short_sc), ("long", &long_sc)]
            .iter()
            .map(|(label, sc)| traced_run(&bin, sc, &scratch.path.join(format!("strace-{label}"))))
            .collect::<anyhow::Result<_>>()?;
        let ((cs, short_calls), (cl, long_calls)) = (&counts[0], &counts[1]);
        println!("\nsystem calls per step (strace -f, long minus short):");
        for kind in &kinds {
            let d_steps = cl.steps.get(kind).copied().unwrap_or(0.0)
                - cs.steps.get(kind).copied().unwrap_or(0.0);
            if d_steps <= 0.0 {
                continue;
            }
            let empty = BTreeMap::new();
            let (a, b) = (
                short_calls.get(kind).unwrap_or(&empty),
                long_calls.get(kind).unwrap_or(&empty),
            );
            let mut per: Vec<(String, f64)> = b
                .iter()
                .map(|(name, n)| (name.clone(), (n - a.get(name).unwrap_or(&0.0)) / d_steps))
                .filter(|(_, n)| *n >= 0.05)
                .collect();
            per.sort_by(|x, y| y.1.total_cmp(&x.1));
            let total: f64 = per.iter().map(|(_, n)| n).sum();
            let names: Vec<String> = per
                .iter()
                .take(6)
                .map(|(name, n)| format!("{name} {}", fmt_num(*n)))
                .collect();
            println!("  {kind:<28} {:>6}  {}", fmt_num(total), names.join(", "));
            if let Some(f) = figures.get_mut(kind) {
                f["syscalls_per_step"] = serde_json::json!(total);
                f["syscalls"] = serde_json::json!(per.into_iter().collect::<BTreeMap<_, _>>());
            }
        }
    }
    let json = scratch.path.with_extension("json");
    let report = serde_json::json!({
        "wake_up_us": wake_us,
        "wake_up_futex_us": futex_us,
        "idle_poll": qos.is_some(),
        "kinds": figures,
    });
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    drop(qos);
    println!("\n{}", json.display());
    Ok(())
}

/// Runs `scenario` under `strace -f` into `out`; returns its costs and
/// the system calls of each kind by name.
fn traced_run(bin: &Path, scenario: &Scenario, out: &Path) -> anyhow::Result<(Costs, Calls)> {
    std::fs::create_dir_all(out)?;
    let sc_path = out.join("scenario.in.toml");
    std::fs::write(&sc_path, scenario.to_toml()?)?;
    let trace = out.join("strace.txt");
    let status = Command::new("strace")
        .arg("-f")
        .arg("-qq")
        .arg("-o")
        .arg(&trace)
        .arg(bin.join("shoal"))
        .args(["run", "--quiet", "--force", "--tick-timeout", "300"])
        .arg(&sc_path)
        .arg("--out")
        .arg(out.join("run"))
        .stdout(Stdio::null())
        .status()
        .context("cannot run strace (install it: apt-get install strace)")?;
    anyhow::ensure!(status.success(), "the traced run failed");
    let summary: Summary = serde_json::from_str(
        &std::fs::read_to_string(out.join("run/summary.json")).context("the traced summary")?,
    )?;
    let costs = Costs::of(&summary, 0.0, scenario);
    let text = std::fs::read_to_string(&trace)?;
    let _ = std::fs::remove_file(&trace);
    Ok((costs, count_syscalls(&text)))
}

/// The kind whose binary `path` is (`shoal` is the orchestrator).
fn kind_of_binary(path: &str) -> Option<String> {
    let name = Path::new(path).file_name()?.to_str()?;
    if name == "shoal" {
        return Some(ORCHESTRATOR.into());
    }
    ProcessKind::ALL
        .iter()
        .find(|k| k.binary() == name)
        .map(|k| k.name().to_string())
}

/// System calls by kind and name in an `strace -f -o` trace: each thread
/// belongs to the kind of the binary its process last executed.
fn count_syscalls(trace: &str) -> Calls {
    let mut kind_of: BTreeMap<u32, String> = BTreeMap::new();
    let mut out = Calls::new();
    for line in trace.lines() {
        let Some((pid, rest)) = line.trim_start().split_once(char::is_whitespace) else {
            continue;
        };
        let Ok(pid) = pid.parse::<u32>() else {
            continue;
        };
        let rest = rest.trim_start();
        let resumed = rest.starts_with("<...");
        let name = if resumed {
            rest.trim_start_matches("<... ")
                .split(' ')
                .next()
                .unwrap_or("")
        } else {
            rest.split('(').next().unwrap_or("")
        };
        if name.is_empty() || name.starts_with('+') || name.starts_with('-') {
            continue;
        }
        // A new thread or process starts as its parent's kind.
        if matches!(name, "clone" | "clone3" | "fork" | "vfork") {
            if let Some(child) = rest
                .rsplit_once(") = ")
                .and_then(|(_, r)| r.split_whitespace().next())
                .and_then(|r| r.parse::<u32>().ok())
            {
                // The child's own lines may come first (its execve too).
                if let Some(k) = kind_of.get(&pid).cloned() {
                    kind_of.entry(child).or_insert(k);
                }
            }
        }
        // (Its result often comes on a later line: a run's binaries exist.)
        if name == "execve" && !resumed {
            if let Some(k) = rest.split('"').nth(1).and_then(kind_of_binary) {
                kind_of.insert(pid, k);
            }
        }
        if resumed {
            continue;
        }
        let kind = kind_of
            .get(&pid)
            .cloned()
            .unwrap_or_else(|| ORCHESTRATOR.into());
        *out.entry(kind)
            .or_default()
            .entry(name.to_string())
            .or_default() += 1.0;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn syscalls_go_to_the_kind_of_the_binary_their_process_runs() {
        let trace = "\
100   execve(\"/x/shoal\", [\"shoal\"], 0x0 /* 1 vars */) = 0
100   clone3({flags=CLONE_VM, ...}, 88) = 101
101   futex(0x1, FUTEX_WAIT, 0, NULL <unfinished ...>
100   clone(child_stack=NULL, flags=SIGCHLD <unfinished ...>
200   execve(\"/x/shoal-sonar\", [\"shoal-sonar\"], 0x0 /* 1 vars */ <unfinished ...>
200   <... execve resumed>) = 0
100   <... clone resumed>) = 200
200   sendto(3, \"x\", 1, 0, NULL, 0) = 1
200   recvfrom(3, 0x1, 1, 0, NULL, NULL) = -1 EAGAIN (Resource temporarily unavailable)
200   recvfrom(3, 0x1, 1, 0, NULL, NULL) = -1 EAGAIN (Resource temporarily unavailable)
101   <... futex resumed>) = 0
200   +++ exited with 0 +++
";
        let c = count_syscalls(trace);
        assert_eq!(c["sonar"]["recvfrom"], 2.0);
        assert_eq!(c["sonar"]["sendto"], 1.0);
        assert_eq!(c["sonar"].get("execve"), Some(&1.0));
        assert_eq!(c["orchestrator"]["futex"], 1.0);
        assert_eq!(c["orchestrator"]["clone"], 1.0);
        assert_eq!(c["orchestrator"]["clone3"], 1.0);
    }

    #[test]
    fn the_marginal_cost_leaves_out_what_a_process_costs_once() {
        // 1 s to start, then 10 µs a step.
        let run = |steps: f64| Costs {
            cpu_s: [("sonar".to_string(), 1.0 + steps * 10e-6)].into(),
            steps: [("sonar".to_string(), steps)].into(),
        };
        let m = marginal_us(&run(1000.0), &run(5000.0), "sonar").unwrap();
        assert!((m - 10.0).abs() < 1e-9, "{m}");
        assert_eq!(marginal_us(&run(1000.0), &run(1000.0), "sonar"), None);
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
    }
}
