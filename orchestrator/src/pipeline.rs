//! One scenario from resolution to summary and plots: what `shoal run`,
//! `shoal compare` and the benches share.

use std::path::Path;

use anyhow::Context;
use shoal_scenario::Scenario;

use crate::analysis::summary::{summarize, Summary};
use crate::launch::{self, RunSettings};
use crate::{plots, preflight};

/// What a run writes into its output directory (and `--force` removes).
pub const RUN_OUTPUTS: [&str; 11] = [
    "recording.mcap",
    "hosts.json",
    "hosts.toml",
    "agents",
    "parts",
    "summary.json",
    "plots",
    "report.html",
    "logs",
    "run.json",
    "scenario.toml",
];

/// What a summary writes into its directory (`shoal summarize --force`
/// removes them, never the recording beside them).
pub const SUMMARY_OUTPUTS: [&str; 3] = ["summary.json", "plots", "report.html"];

/// Removes what an earlier run left in `out` ([`RUN_OUTPUTS`]), nothing else.
pub fn clear_outputs(out: &Path) -> anyhow::Result<()> {
    remove_all(out, &RUN_OUTPUTS)
}

/// Removes the files and directories `names` of `out` that exist.
pub fn remove_all(out: &Path, names: &[&str]) -> anyhow::Result<()> {
    for name in names {
        let p = out.join(name);
        let removed = if p.is_dir() {
            std::fs::remove_dir_all(&p)
        } else {
            std::fs::remove_file(&p)
        };
        match removed {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("cannot remove {}", p.display()));
            }
            _ => {}
        }
    }
    Ok(())
}

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
            "{} already holds a recording; choose another --out, or --force to replace it (nothing was overwritten)",
            out.display()
        );
    }
    let outcome = match launch::run(&settings.options(&scenario, out)) {
        Ok(o) => o,
        Err(e) => {
            let interrupted = e
                .chain()
                .any(|c| matches!(c.downcast_ref(), Some(launch::RunError::Interrupted(_))));
            if interrupted && out.join("recording.mcap").exists() {
                // A second Ctrl-C while the part that ran is summarised ends it.
                launch::os::default_termination_signals();
                match summarize_into(&out.join("recording.mcap"), out) {
                    Ok(s) => eprintln!(
                        "stopped at t = {:.1} s: the summary and plots of the part that ran are in {}",
                        s.sim_time_s,
                        out.display()
                    ),
                    Err(err) => tracing::warn!("no summary of the part that ran: {err:#}"),
                }
            }
            return Err(match disk_full(out) {
                Some(why) => e.context(why),
                None => e,
            });
        }
    };
    let rec = recordings::Recording::open(&outcome.recording)?;
    let summary = summarize(&scenario, &rec, &outcome, settings.mode.as_str());
    summary.write(&out.join("summary.json"))?;
    plots::write_plots(&scenario, &rec, &out.join("plots")).context("writing the plots")?;
    crate::report::write_report(out, &summary, &scenario, &rec).context("writing the report")?;
    Ok(Finished {
        summary,
        scenario,
        recording: rec,
    })
}

/// Free space below which a run that failed is taken to have filled its
/// output disk, bytes (less than the recorder's smallest chunk).
const DISK_FULL_BYTES: u64 = 256 * 1024;

/// Why a failed run failed, when its output disk is full: the disk named,
/// and what can still be read.
fn disk_full(out: &Path) -> Option<String> {
    let (free, _) = crate::launch::os::statvfs_free(out.to_str()?);
    let free = free?;
    (free < DISK_FULL_BYTES).then(|| {
        let rec = out.join("recording.mcap");
        format!(
            "the output disk is full ({} has {free} bytes free): the recording stops at its last complete chunk; `shoal recover {}` writes a whole copy elsewhere and `shoal summarize {}` reads it",
            out.display(),
            rec.display(),
            rec.display()
        )
    })
}

/// Summarises the recording at `recording` alone into `out`
/// (summary.json, plots/ and report.html), as `shoal summarize` does and as a run
/// stopped by Ctrl-C does for the part it ran. A truncated recording is
/// read up to its last complete chunk.
pub fn summarize_into(recording: &Path, out: &Path) -> anyhow::Result<Summary> {
    let rec = recordings::Recording::open(recording)?;
    crate::export::ensure_shoal_recording(&rec, recording)?;
    if rec.truncated() {
        tracing::warn!(
            "{} is truncated: summarising up to its last complete chunk (`shoal recover` writes a whole copy)",
            recording.display()
        );
    }
    let (scenario, summary) = crate::analysis::from_recording::summarize_recording(&rec)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    summary.write(&out.join("summary.json"))?;
    plots::write_plots(&scenario, &rec, &out.join("plots")).context("writing the plots")?;
    crate::report::write_report(out, &summary, &scenario, &rec).context("writing the report")?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn clearing_removes_a_runs_outputs_and_nothing_else() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path();
        for name in RUN_OUTPUTS {
            if name.contains('.') {
                std::fs::write(out.join(name), "x").unwrap();
            } else {
                std::fs::create_dir_all(out.join(name).join("inner")).unwrap();
            }
        }
        std::fs::write(out.join("notes.txt"), "mine").unwrap();
        clear_outputs(out).unwrap();
        for name in RUN_OUTPUTS {
            assert!(!out.join(name).exists(), "{name}");
        }
        assert!(out.join("notes.txt").exists());
        // nothing there: fine
        clear_outputs(out).unwrap();
        clear_outputs(&out.join("missing")).unwrap();
    }
}
