//! `shoal compare`'s variants and table: the two comparisons the paper argues but does not
//! measure, run side by side with the method on the same scenario and seed.
//!
//! - **method**: the scenario as given (camera + PnP, vertical shift on, the
//!   method as generalised beyond the paper for any course).
//! - **published**: the paper's method as published (`[method] generalised =
//!   false`: none of the generalisations of `services/planner/README.md`).
//! - **acoustic**: followers get the parent's pose over a simulated acoustic
//!   modem instead of the camera (`[acoustic]`: delay range/1500 m/s,
//!   80 bit/s → one update every 3.2 s, 10% loss). The followers' staleness
//!   limit is raised to two packet periods so they do not give up between
//!   packets — the baseline gets a fair chance.
//! - **no_vertical_shift**: the ablation D_b = 0.
//! - **yours** (with `--replace`): the scenario as given with the user's own
//!   program in place of the processes it names: their method beside the
//!   paper's and shoal's.
//!
//! Fix fractions count the follower's `leader_pose` samples that carry a
//! fix; the modem publishes only when a packet arrives (so its fraction is
//! the share of packets that decoded), hence the fix rate column.
//!
//! Writes `compare.md`, `compare.json` and `compare.png`/`.svg` (slot error,
//! minimum distance and parent fixes over time, one curve per variant).

use shoal_scenario::{Perception, Scenario};

use super::summary::{fmt_or_na, min_value, Summary};

/// The variants, in table order; with `yours` (the user's `--replace`
/// entries), a last one, `yours`: the scenario with those processes
/// replaced.
pub fn variants(
    base: &Scenario,
    yours: &[shoal_scenario::replace::Replace],
) -> anyhow::Result<Vec<(&'static str, Scenario)>> {
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
    let mut published = base.clone();
    published.method.generalised = false;
    let mut out = vec![
        ("method", method),
        ("published", published),
        ("acoustic", acoustic),
        ("no_vertical_shift", ablation),
    ];
    if !yours.is_empty() {
        let mut mine = base.clone();
        mine.replace.extend(yours.iter().cloned());
        mine.validate()?;
        out.push(("yours", mine));
    }
    Ok(out)
}

/// One row of the comparison table.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Row {
    /// `method`, `published`, `acoustic`, `no_vertical_shift` or `yours`.
    pub variant: String,
    /// RMS slot error before the passage, m.
    pub slot_error_rms_before_m: Option<f64>,
    /// RMS slot error during the passage, m.
    pub slot_error_rms_during_m: Option<f64>,
    /// RMS slot error after the passage, m.
    pub slot_error_rms_after_m: Option<f64>,
    /// Smallest distance between two vehicles, m.
    pub min_pair_distance_m: Option<f64>,
    /// The pair it was.
    pub min_pair: String,
    /// Pairs closer than the collision distance.
    pub collisions: usize,
    /// Vehicles' contacts with an obstacle.
    pub obstacle_contacts: usize,
    /// Every safety figure passed.
    pub pass: bool,
    /// What failed.
    pub failed: Vec<String>,
    /// Smallest distance to an obstacle, m.
    pub min_obstacle_clearance_m: Option<f64>,
    /// Least share of a follower's frames with a fix of its parent.
    pub min_visible_fraction: Option<f64>,
    /// The same within the passage.
    pub min_visible_fraction_in_passage: Option<f64>,
    /// Least rate of fixes of any follower, Hz.
    pub min_fix_rate_hz: Option<f64>,
    /// 95th percentile of the pose error, m.
    pub pose_error_p95_m: Option<f64>,
}

/// The row of variant `name` from its summary.
pub fn row(name: &str, s: &Summary) -> Row {
    let p = &s.perception;
    Row {
        variant: name.to_string(),
        slot_error_rms_before_m: s.formation.slot_error_rms_m.before,
        slot_error_rms_during_m: s.formation.slot_error_rms_m.during,
        slot_error_rms_after_m: s.formation.slot_error_rms_m.after,
        min_pair_distance_m: s.safety.min_pair_distance_m,
        min_pair: s.safety.min_pair.clone(),
        collisions: s.safety.collisions,
        obstacle_contacts: s.safety.obstacle_contacts.len(),
        pass: s.verdict.pass,
        failed: s.verdict.failed.clone(),
        min_obstacle_clearance_m: s.safety.min_obstacle_clearance_m,
        min_visible_fraction: min_value(&p.leader_visible_fraction),
        min_visible_fraction_in_passage: min_value(&p.parent_visible_fraction_in_passage),
        min_fix_rate_hz: min_value(&p.parent_fix_rate_hz),
        pose_error_p95_m: p.pose_error_m.p95,
    }
}

/// A markdown table of the rows, a figure per line and a variant per column
/// (so it fits a terminal: about 30 + 13 columns per variant), `n/a` for a
/// figure that does not exist, with what failed below it.
pub fn table(rows: &[Row], safe: f64) -> String {
    type Cell = fn(&Row, f64) -> String;
    let figures: [(&str, Cell); 13] = [
        ("verdict", |r, _| {
            (if r.pass { "pass" } else { "FAIL" }).into()
        }),
        ("slot rms before (m)", |r, _| {
            fmt_or_na(r.slot_error_rms_before_m, 2)
        }),
        ("slot rms during (m)", |r, _| {
            fmt_or_na(r.slot_error_rms_during_m, 2)
        }),
        ("slot rms after (m)", |r, _| {
            fmt_or_na(r.slot_error_rms_after_m, 2)
        }),
        ("min pair (m)", |r, safe| {
            let below = r.min_pair_distance_m.is_some_and(|m| m < safe);
            format!(
                "{}{}",
                fmt_or_na(r.min_pair_distance_m, 2),
                if below { " < safe" } else { "" }
            )
        }),
        ("collisions", |r, _| r.collisions.to_string()),
        ("obstacle contacts", |r, _| r.obstacle_contacts.to_string()),
        ("min clearance (m)", |r, _| {
            fmt_or_na(r.min_obstacle_clearance_m, 2)
        }),
        ("min fix fraction", |r, _| {
            fmt_or_na(r.min_visible_fraction, 3)
        }),
        ("  in the passage", |r, _| {
            fmt_or_na(r.min_visible_fraction_in_passage, 3)
        }),
        ("min fix rate (Hz)", |r, _| fmt_or_na(r.min_fix_rate_hz, 2)),
        ("pose error p95 (m)", |r, _| {
            fmt_or_na(r.pose_error_p95_m, 2)
        }),
        ("min pair between", |r, _| r.min_pair.clone()),
    ];
    let mut t = String::from("| figure |");
    for r in rows {
        t.push_str(&format!(" {} |", r.variant));
    }
    t.push_str("\n|---|");
    for _ in rows {
        t.push_str("---|");
    }
    t.push('\n');
    for (name, cell) in figures {
        t.push_str(&format!("| {name} |"));
        for r in rows {
            t.push_str(&format!(" {} |", cell(r, safe)));
        }
        t.push('\n');
    }
    for r in rows.iter().filter(|r| !r.pass) {
        t.push_str(&format!("\n{} failed:\n", r.variant));
        for f in &r.failed {
            t.push_str(&format!("- {f}\n"));
        }
    }
    t
}
