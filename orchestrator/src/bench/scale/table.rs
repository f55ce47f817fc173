//! The table of `shoal bench scale`: one row per group size and the cost ratio.

use super::*;

/// What became of one group size.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Status {
    /// Ran to the end.
    Ran(Box<Figures>),
    /// Not started: the machine cannot hold it (the reason).
    Skipped(String),
    /// Started (or generated) and failed (the error).
    Failed(String),
}

/// One row of the table.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Row {
    /// Vehicles, leader included.
    pub(crate) vehicles: usize,
    /// Service processes (the orchestrator not counted); `None` if the
    /// scenario could not be generated.
    pub(crate) processes: Option<usize>,
    /// The run's directory.
    pub(crate) dir: PathBuf,
    pub(crate) status: Status,
}

impl Row {
    pub(crate) fn figures(&self) -> Option<&Figures> {
        match &self.status {
            Status::Ran(f) => Some(f),
            _ => None,
        }
    }

    /// CPU ms per vehicle-second, if the run finished.
    pub(crate) fn cost(&self) -> Option<f64> {
        self.figures()
            .map(|f| f.cpu_ms_per_vehicle_s(self.vehicles))
            .filter(|c| c.is_finite())
    }

    pub(crate) fn to_json(&self) -> Value {
        let (status, reason, figures) = match &self.status {
            Status::Ran(f) => ("ran", Value::Null, f.to_json(self.vehicles)),
            Status::Skipped(r) => ("skipped", json!(r), Value::Null),
            Status::Failed(r) => ("failed", json!(r), Value::Null),
        };
        json!({
            "vehicles": self.vehicles,
            "processes": self.processes,
            "dir": self.dir.display().to_string(),
            "status": status,
            "reason": reason,
            "figures": figures,
        })
    }
}

/// The cost ratio of issue 8: `(largest N that ran, its cost / the cost at
/// N = 25)`, when both ran and the largest is not 25 itself.
pub(crate) fn cost_ratio(rows: &[Row]) -> Option<(usize, f64)> {
    let reference = rows
        .iter()
        .find(|r| r.vehicles == REFERENCE_N)
        .and_then(Row::cost)?;
    let (n, cost) = rows
        .iter()
        .filter_map(|r| r.cost().map(|c| (r.vehicles, c)))
        .max_by_key(|(n, _)| *n)?;
    (n != REFERENCE_N && reference > 0.0).then(|| (n, cost / reference))
}

/// First line of an error, for a table cell.
pub(crate) fn one_line(s: &str) -> String {
    let line = s.lines().next().unwrap_or("").replace('|', "/");
    if line.chars().count() > 160 {
        let mut cut: String = line.chars().take(157).collect();
        cut.push_str("...");
        cut
    } else {
        line
    }
}

/// Column headings of the table.
pub(crate) const HEADINGS: [&str; 14] = [
    "N",
    "processes",
    "real-time factor",
    "start+stop s",
    "CPU ms / vehicle-s",
    "peak RSS sum MiB",
    "private MiB",
    "recorder msg/s",
    "drops",
    "collisions",
    "min pair m",
    "min parent visible",
    "max parent range m",
    "note",
];

/// The cells of a row, in [`HEADINGS`] order.
pub(crate) fn cells(r: &Row) -> Vec<String> {
    let procs = r.processes.map_or("-".to_string(), |p| p.to_string());
    match &r.status {
        Status::Ran(f) => {
            let note = match (f.min_pair_m, f.safe_distance_m) {
                _ if f.collisions > 0 || f.recorder_dropped > 0 => "UNHEALTHY".to_string(),
                (Some(m), Some(safe)) if m < safe => "below safe distance".to_string(),
                _ => match (f.max_parent_range_m, f.visibility_range_m) {
                    (Some(r), Some(v)) if r > v => "a parent out of visibility range".to_string(),
                    _ => String::new(),
                },
            };
            vec![
                r.vehicles.to_string(),
                procs,
                format!("{}x", fmt_num(f.rtf())),
                f.start_stop_s().map_or("-".to_string(), fmt_num),
                fmt_num(f.cpu_ms_per_vehicle_s(r.vehicles)),
                fmt_num(f.rss_total_mib()),
                fmt_num(f.private_total_mib()),
                fmt_num(f.recorder_msgs_per_s()),
                f.recorder_dropped.to_string(),
                f.collisions.to_string(),
                f.min_pair_m.map_or("-".to_string(), fmt_num),
                f.min_parent_visible
                    .map_or("-".to_string(), |v| format!("{:.0}%", 100.0 * v)),
                f.max_parent_range_m.map_or("-".to_string(), fmt_num),
                note,
            ]
        }
        Status::Skipped(why) | Status::Failed(why) => {
            let what = if matches!(r.status, Status::Skipped(_)) {
                "skipped"
            } else {
                "FAILED"
            };
            let mut c = vec![r.vehicles.to_string(), procs];
            c.extend(std::iter::repeat_n("-".to_string(), HEADINGS.len() - 3));
            c.push(format!("{what}: {}", one_line(why)));
            c
        }
    }
}

/// The table as Markdown (also what is printed): a figure per line and a
/// group size per column, so that it fits a terminal; each size's note
/// below it, then the cost-ratio line.
pub(crate) fn render_table(rows: &[Row]) -> String {
    let all: Vec<Vec<String>> = rows.iter().map(cells).collect();
    let last = HEADINGS.len() - 1;
    let label_w = HEADINGS[..last]
        .iter()
        .map(|h| h.chars().count())
        .max()
        .unwrap_or(1);
    let col_w: Vec<usize> = all
        .iter()
        .map(|c| {
            c[..last]
                .iter()
                .map(|x| x.chars().count())
                .max()
                .unwrap_or(1)
                .max(3)
        })
        .collect();
    let mut out = String::new();
    for (i, h) in HEADINGS[..last].iter().enumerate() {
        let _ = write!(out, "| {h:<label_w$} |");
        for (c, w) in all.iter().zip(&col_w) {
            let _ = write!(out, " {:>w$} |", c[i], w = *w);
        }
        out.push('\n');
        if i == 0 {
            let _ = write!(out, "| {} |", "-".repeat(label_w));
            for w in &col_w {
                let _ = write!(out, " {}: |", "-".repeat(w - 1));
            }
            out.push('\n');
        }
    }
    out.push('\n');
    for c in all.iter().filter(|c| !c[last].is_empty()) {
        let _ = writeln!(out, "N = {}: {}", c[0], c[last]);
    }
    out.push_str(&ratio_line(rows));
    out.push('\n');
    out
}

/// The cost ratio against issue 8's bound, in words.
pub(crate) fn ratio_line(rows: &[Row]) -> String {
    match cost_ratio(rows) {
        Some((n, r)) => format!(
            "cost ratio (CPU per vehicle-second, N = {n} / N = {REFERENCE_N}): {r:.2} \
             (issue 8: <= {COST_RATIO_BOUND}) [{}]",
            if r <= COST_RATIO_BOUND {
                "met"
            } else {
                "MISSED"
            }
        ),
        None => {
            format!("cost ratio: needs N = {REFERENCE_N} and a larger N that both ran to the end")
        }
    }
}
