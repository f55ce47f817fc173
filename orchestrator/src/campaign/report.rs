//! The campaign's report: pass rate per family and overall, the worst
//! figures, the failing runs with what failed; as Markdown
//! (`campaign.md`), JSON (`campaign.json`) and a plot (`campaign.png`,
//! `campaign.svg`).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::{CampaignOptions, RunRow, Status, FINAL_RMS_LIMIT_M, GOAL_LIMIT_M};
use crate::analysis::summary::{fmt_or_na, PARENT_LOST_LIMIT_S};

/// Pass rate and worst figures of a set of runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tally {
    /// Family name, or `all`.
    pub family: String,
    /// Runs finished (interrupted ones not counted).
    pub runs: usize,
    /// Runs that passed.
    pub passed: usize,
    /// `passed / runs` (`null` with no runs).
    pub pass_rate: Option<f64>,
    /// Smallest min pair distance, m.
    pub worst_min_pair_m: Option<f64>,
    /// Smallest obstacle clearance, m.
    pub worst_clearance_m: Option<f64>,
    /// Longest time a follower was without its parent, s.
    pub worst_parent_gap_s: Option<f64>,
    /// Largest slot error RMS over the last 30 s, m.
    pub worst_final_rms_m: Option<f64>,
    /// Largest distance of the leader from its goal, m.
    pub worst_goal_error_m: Option<f64>,
}

fn min_of(it: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    it.flatten().reduce(f64::min)
}
fn max_of(it: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    it.flatten().reduce(f64::max)
}

impl Tally {
    /// The tally of `rows` (those of status pass, fail or error).
    pub fn of<'a>(family: &str, rows: impl Iterator<Item = &'a RunRow> + Clone) -> Self {
        let done = rows.filter(|r| r.status != Status::Interrupted);
        let runs = done.clone().count();
        let passed = done.clone().filter(|r| r.status == Status::Pass).count();
        Self {
            family: family.to_string(),
            runs,
            passed,
            pass_rate: (runs > 0).then(|| passed as f64 / runs as f64),
            worst_min_pair_m: min_of(done.clone().map(|r| r.min_pair_m)),
            worst_clearance_m: min_of(done.clone().map(|r| r.clearance_m)),
            worst_parent_gap_s: max_of(done.clone().map(|r| r.parent_gap_s)),
            worst_final_rms_m: max_of(done.clone().map(|r| r.final_rms_m)),
            worst_goal_error_m: max_of(done.map(|r| r.goal_error_m)),
        }
    }
}

/// Group sizes of the report's table per size: name, least, most vehicles.
const SIZES: [(&str, usize, usize); 5] = [
    ("2-4 vehicles", 2, 4),
    ("5-9 vehicles", 5, 9),
    ("10-14 vehicles", 10, 14),
    ("15-29 vehicles", 15, 29),
    ("30-50+ vehicles", 30, usize::MAX),
];

/// Everything the campaign found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Formation shape.
    pub shape: String,
    /// Vehicles.
    pub vehicles: usize,
    /// Courses.
    pub courses: usize,
    /// Seeds per course.
    pub seeds: u64,
    /// Per family, in the order given.
    pub by_family: Vec<Tally>,
    /// Over every run.
    pub overall: Tally,
    /// Per kind of feature (composed courses): the runs whose course holds one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub by_feature: Vec<Tally>,
    /// Per group size (`5-9`, `10-14`, `15-29`, `30-50` vehicles, when more
    /// than one size ran).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub by_size: Vec<Tally>,
    /// Per camera model (when both ran).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub by_camera: Vec<Tally>,
    /// Runs stopped by Ctrl-C.
    pub interrupted: usize,
    /// The method the runs flew: `shoal`, `published` (the paper's as
    /// published) or the user's `--replace` flags.
    #[serde(default)]
    pub method: String,
    /// Earlier campaigns' tallies shown beside this one's (`--beside`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub beside: Vec<Beside>,
    /// Every run, in order.
    pub runs: Vec<RunRow>,
}

/// Another campaign's pass rates, shown beside a campaign's own (the same
/// courses flown by another method).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Beside {
    /// Its method, as its report names it.
    pub method: String,
    /// Where its report is.
    pub path: String,
    /// Its tallies per family, then over every run.
    pub tallies: Vec<Tally>,
}

impl Beside {
    /// Reads an earlier campaign's `campaign.json`.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let r: Report = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a campaign report", path.display()))?;
        let mut tallies = r.by_family;
        tallies.push(r.overall);
        Ok(Self {
            method: if r.method.is_empty() {
                "shoal".into()
            } else {
                r.method
            },
            path: path.display().to_string(),
            tallies,
        })
    }
}

/// A pass count and rate as the tables show it.
fn pass_cell(t: Option<&Tally>) -> String {
    t.map_or("–".to_string(), |t| {
        format!(
            "{}/{} ({})",
            t.passed,
            t.runs,
            t.pass_rate
                .map_or("n/a".to_string(), |r| format!("{:.1} %", 100.0 * r))
        )
    })
}

/// The method a campaign's runs fly, in words.
fn method_of(o: &CampaignOptions) -> String {
    let base = if o.published { "published" } else { "shoal" };
    if o.replace.is_empty() {
        return base.to_string();
    }
    let flags: Vec<String> = o
        .replace
        .iter()
        .map(|r| format!("--replace '{r}'"))
        .collect();
    format!("{base}, with {}", flags.join(" "))
}

impl Report {
    /// The report of `rows`.
    pub fn new(o: &CampaignOptions, rows: Vec<RunRow>) -> Self {
        // over the space every course is composed: one row, not ten empty ones
        let families = if o.space {
            vec![crate::gen::Family::Composed]
        } else {
            o.families.clone()
        };
        let by_family = families
            .iter()
            .map(|f| Tally::of(f.name(), rows.iter().filter(|r| r.family == f.name())))
            .collect();
        let by_feature = crate::gen::Feature::ALL
            .iter()
            .filter(|k| rows.iter().any(|r| r.features.contains(k)))
            .map(|k| Tally::of(k.name(), rows.iter().filter(|r| r.features.contains(k))))
            .collect();
        let mut by_size: Vec<Tally> = SIZES
            .iter()
            .filter(|(_, lo, hi)| rows.iter().any(|r| (*lo..=*hi).contains(&r.vehicles)))
            .map(|(name, lo, hi)| {
                Tally::of(
                    name,
                    rows.iter().filter(|r| (*lo..=*hi).contains(&r.vehicles)),
                )
            })
            .collect();
        if by_size.len() < 2 {
            by_size.clear();
        }
        let mut by_camera: Vec<Tally> = ["point", "image"]
            .iter()
            .filter(|c| rows.iter().any(|r| r.camera == **c))
            .map(|c| Tally::of(c, rows.iter().filter(|r| r.camera == *c)))
            .collect();
        if by_camera.len() < 2 {
            by_camera.clear();
        }
        Self {
            shape: if o.space {
                "any".to_string()
            } else {
                o.shape.name().to_string()
            },
            vehicles: o.vehicles,
            courses: o.courses,
            seeds: o.seeds,
            by_family,
            overall: Tally::of("all", rows.iter()),
            by_feature,
            by_size,
            by_camera,
            interrupted: rows
                .iter()
                .filter(|r| r.status == Status::Interrupted)
                .count(),
            method: method_of(o),
            beside: o.beside.clone(),
            runs: rows,
        }
    }

    /// The runs that did not pass (interrupted ones aside).
    pub fn failures(&self) -> impl Iterator<Item = &RunRow> {
        self.runs
            .iter()
            .filter(|r| matches!(r.status, Status::Fail | Status::Error))
    }

    /// The table as Markdown: one row per family and one for all, then the
    /// failing runs with their paths and what failed.
    pub fn markdown(&self) -> String {
        let mut t = String::new();
        if self.shape == "any" {
            let _ = writeln!(
                t,
                "# Campaign over the space: {} composed courses × {} seeds, each with its own formation\n",
                self.courses, self.seeds
            );
        } else {
            let _ = writeln!(
                t,
                "# Campaign: {} of {} vehicles, {} courses × {} seeds\n",
                self.shape, self.vehicles, self.courses, self.seeds
            );
        }
        if !self.method.is_empty() {
            let _ = writeln!(t, "Method: {}.\n", self.method);
        }
        let _ = writeln!(
            t,
            "A run passes with no collision of either kind, min pair ≥ the safe distance, \
             clearance ≥ half of it, no parent lost over {PARENT_LOST_LIMIT_S} s, slot error \
             RMS over the last 30 s < {FINAL_RMS_LIMIT_M} m and the leader within \
             {GOAL_LIMIT_M} m of its goal.\n"
        );
        table(
            &mut t,
            "family",
            self.by_family.iter().chain(std::iter::once(&self.overall)),
        );
        if !self.beside.is_empty() {
            let _ = writeln!(
                t,
                "\nBeside it, the same courses flown by other methods (passed/runs):\n"
            );
            let _ = write!(t, "| family | {} |", self.method);
            for b in &self.beside {
                let _ = write!(t, " {} |", b.method);
            }
            let _ = writeln!(t, "\n|---|---|{}", "---|".repeat(self.beside.len()));
            for own in self.by_family.iter().chain(std::iter::once(&self.overall)) {
                let _ = write!(t, "| {} | {} |", own.family, pass_cell(Some(own)));
                for b in &self.beside {
                    let theirs = b.tallies.iter().find(|x| x.family == own.family);
                    let _ = write!(t, " {} |", pass_cell(theirs));
                }
                let _ = writeln!(t);
            }
        }
        for (label, tallies) in [
            ("kind of feature", &self.by_feature),
            ("group size", &self.by_size),
            ("camera", &self.by_camera),
        ] {
            if !tallies.is_empty() {
                let _ = writeln!(t);
                table(&mut t, label, tallies.iter());
            }
        }
        if self.interrupted > 0 {
            let _ = writeln!(
                t,
                "\n{} run(s) interrupted (not counted).",
                self.interrupted
            );
        }
        let failures: Vec<&RunRow> = self.failures().collect();
        if failures.is_empty() {
            let _ = writeln!(t, "\nNo run failed.");
        } else {
            let _ = writeln!(t, "\n## Failing runs\n");
            for r in failures {
                let _ = writeln!(t, "- `{}`: {}", r.dir, r.failed.join("; "));
            }
        }
        t
    }
}

/// A Markdown table of `tallies`, the first column headed `label`.
fn table<'a>(t: &mut String, label: &str, tallies: impl Iterator<Item = &'a Tally>) {
    let na = fmt_or_na;
    let _ = writeln!(
        t,
        "| {label} | runs | pass | pass rate | worst min pair (m) | worst clearance (m) | \
         worst parent gap (s) | worst final RMS (m) | worst goal error (m) |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|---|---|");
    for f in tallies {
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            f.family,
            f.runs,
            f.passed,
            f.pass_rate
                .map_or("n/a".to_string(), |r| format!("{:.1} %", 100.0 * r)),
            na(f.worst_min_pair_m, 2),
            na(f.worst_clearance_m, 2),
            na(f.worst_parent_gap_s, 1),
            na(f.worst_final_rms_m, 2),
            na(f.worst_goal_error_m, 2),
        );
    }
}

/// Writes `campaign.md`, `campaign.json` and the plot into `dir`.
pub fn write_report(r: &Report, dir: &Path) -> anyhow::Result<()> {
    let md = dir.join("campaign.md");
    std::fs::write(&md, r.markdown()).with_context(|| format!("cannot write {}", md.display()))?;
    let json = dir.join("campaign.json");
    std::fs::write(&json, serde_json::to_string_pretty(r)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    crate::plots::write_campaign_plot(r, dir).context("drawing the campaign plot")?;
    Ok(())
}
