//! One scenario from resolution to summary and plots: what `shoal run`,
//! `shoal compare` and the benches share.

use std::path::Path;

use anyhow::Context;
use shoal_scenario::Scenario;

use crate::analysis::summary::{summarize, Summary};
use crate::launch::{self, RunSettings};
use crate::{plots, preflight};

/// A finished, summarised run.
pub struct Finished {
    /// What summary.json holds.
    pub summary: Summary,
    /// The scenario as resolved and run (D_a/D_b assigned).
    pub scenario: Scenario,
    /// The run's recording, read.
    pub recording: recordings::Recording,
}

/// Resolves, runs and summarises one scenario into `out` (summary.json and
/// plots written).
pub fn run_and_summarize(
    mut scenario: Scenario,
    out: &Path,
    settings: &RunSettings,
) -> anyhow::Result<Finished> {
    preflight::resolve(&mut scenario).context("scenario refused")?;
    for line in preflight::advice(&scenario) {
        tracing::warn!("{line}");
    }
    if out.join("recording.mcap").exists() {
        anyhow::bail!(
            "{} already holds a recording; choose another --out (nothing was overwritten)",
            out.display()
        );
    }
    let outcome = launch::run(&settings.options(&scenario, out))?;
    let rec = recordings::Recording::open(&outcome.recording)?;
    let summary = summarize(&scenario, &rec, &outcome, settings.mode.as_str());
    summary.write(&out.join("summary.json"))?;
    plots::write_plots(&scenario, &rec, &out.join("plots")).context("writing the plots")?;
    Ok(Finished {
        summary,
        scenario,
        recording: rec,
    })
}
