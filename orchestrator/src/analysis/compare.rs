//! `shoal compare`: the two comparisons the paper argues but does not
//! measure, run side by side with the method on the same scenario and seed.
//!
//! - **method**: the scenario as given (camera + PnP, vertical shift on).
//! - **acoustic**: followers get the parent's pose over a simulated acoustic
//!   modem instead of the camera (`[acoustic]`: delay range/1500 m/s,
//!   80 bit/s → one update every 3.2 s, 10% loss). The followers' staleness
//!   limit is raised to two packet periods so they do not give up between
//!   packets — the baseline gets a fair chance.
//! - **no_vertical_shift**: the ablation D_b = 0.
//!
//! Fix fractions count the follower's `leader_pose` samples that carry a
//! fix; the modem publishes only when a packet arrives (so its fraction is
//! the share of packets that decoded), hence the fix rate column.
//!
//! Writes `compare.md`, `compare.json` and `compare.png`/`.svg` (slot error,
//! minimum distance and parent fixes over time, one curve per variant).

use std::path::PathBuf;

use anyhow::Context;
use serde_json::{json, Value};
use shoal_runtime::Mode;
use shoal_scenario::{Perception, Scenario};

use crate::{load_scenario, run_and_summarize, CompareCmd, RunSettings};

/// The variants, in table order.
pub fn variants(base: &Scenario) -> anyhow::Result<Vec<(&'static str, Scenario)>> {
    let method = base.clone();
    let mut acoustic = base.clone();
    acoustic.method.perception = Perception::Acoustic;
    let modem: camera_pose::acoustic::AcousticConfig = base.section("acoustic")?;
    if !acoustic.follower.contains_key("stale_after_s") {
        acoustic.follower.insert(
            "stale_after_s".into(),
            toml::Value::Float(2.0 * modem.period_s() + 0.5),
        );
    }
    let mut ablation = base.clone();
    ablation.method.vertical_shift = false;
    Ok(vec![
        ("method", method),
        ("acoustic", acoustic),
        ("no_vertical_shift", ablation),
    ])
}

fn f(v: &Value, p: &str) -> f64 {
    v.pointer(p).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

/// The smallest of a map of per-follower numbers.
fn min_of(v: &Value, p: &str) -> f64 {
    v.pointer(p)
        .and_then(Value::as_object)
        .map(|m| {
            m.values()
                .filter_map(Value::as_f64)
                .fold(f64::INFINITY, f64::min)
        })
        .unwrap_or(f64::NAN)
}

/// One row of the comparison table.
pub fn row(name: &str, s: &Value) -> Value {
    json!({
        "variant": name,
        "slot_error_rms_before_m": f(s, "/formation/slot_error_rms_m/before"),
        "slot_error_rms_during_m": f(s, "/formation/slot_error_rms_m/during"),
        "slot_error_rms_after_m": f(s, "/formation/slot_error_rms_m/after"),
        "min_pair_distance_m": f(s, "/safety/min_pair_distance_m"),
        "min_pair": s.pointer("/safety/min_pair").cloned().unwrap_or(Value::Null),
        "collisions": f(s, "/safety/collisions"),
        "min_obstacle_clearance_m": f(s, "/safety/min_obstacle_clearance_m"),
        "min_visible_fraction": min_of(s, "/perception/leader_visible_fraction"),
        "min_visible_fraction_in_passage": min_of(s, "/perception/parent_visible_fraction_in_passage"),
        "min_fix_rate_hz": min_of(s, "/perception/parent_fix_rate_hz"),
        "pose_error_p95_m": f(s, "/perception/pose_error_m/p95"),
    })
}

/// A markdown table of the rows.
pub fn table(rows: &[Value], safe: f64) -> String {
    let mut t = String::from(
        "| variant | slot rms before m | slot rms during m | slot rms after m | min pair m | collisions | min clearance m | min fix fraction | min fix fraction in passage | min fix rate Hz | pose err p95 m |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let g = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
        t.push_str(&format!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2}{} | {:.0} | {:.2} | {:.3} | {:.3} | {:.2} | {:.2} |\n",
            r["variant"].as_str().unwrap_or(""),
            g("slot_error_rms_before_m"),
            g("slot_error_rms_during_m"),
            g("slot_error_rms_after_m"),
            g("min_pair_distance_m"),
            if g("min_pair_distance_m") < safe {
                " (below safe)"
            } else {
                ""
            },
            g("collisions"),
            g("min_obstacle_clearance_m"),
            g("min_visible_fraction"),
            g("min_visible_fraction_in_passage"),
            g("min_fix_rate_hz"),
            g("pose_error_p95_m"),
        ));
    }
    t
}

pub fn cmd_compare(cmd: CompareCmd) -> anyhow::Result<()> {
    let mut base = load_scenario(&cmd.scenario)?;
    if let Some(s) = cmd.seed {
        base.seed = s;
    }
    let out = cmd.out.unwrap_or_else(|| {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        PathBuf::from("runs").join(format!("compare-{}-{secs}", base.name))
    });
    let settings = RunSettings::new(Mode::Lockstep, cmd.bin_dir, cmd.quiet, 30.0)?;
    let mut rows = Vec::new();
    let mut runs = Vec::new();
    for (name, scenario) in variants(&base)? {
        eprintln!("== {name}");
        let done = run_and_summarize(scenario, &out.join(name), &settings)
            .with_context(|| format!("variant {name}"))?;
        rows.push(row(name, &done.summary));
        runs.push((name, done));
    }
    let refs: Vec<_> = runs
        .iter()
        .map(|(n, d)| (*n, &d.scenario, &d.recording))
        .collect();
    crate::plots::write_compare_plot(&refs, &out).context("writing the comparison plot")?;
    let md = format!(
        "# {} (seed {}): method vs acoustic baseline vs no vertical shift\n\nsafe distance {} m\n\n{}",
        base.name,
        base.seed,
        base.safety.safe_distance_m,
        table(&rows, base.safety.safe_distance_m)
    );
    std::fs::write(out.join("compare.md"), &md)?;
    std::fs::write(
        out.join("compare.json"),
        serde_json::to_string_pretty(&rows)?,
    )?;
    print!("{md}");
    println!("{}", out.display());
    Ok(())
}
