//! `shoal compare`: the method, the acoustic-modem baseline and the
//! no-vertical-shift ablation on one scenario and seed.

use std::path::PathBuf;

use anyhow::Context;
use shoal_runtime::Mode;

use crate::analysis::compare::{row, table, variants};
use crate::launch::RunSettings;
use crate::{pipeline, plots, preflight};

#[derive(Debug, clap::Args)]
pub struct CompareCmd {
    /// Scenario TOML (default: the embedded paper scenario).
    scenario: Option<PathBuf>,
    /// Output directory (default: runs/compare-<scenario>-<unix time>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Seed (overrides the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
    /// No progress bars.
    #[arg(long, short)]
    quiet: bool,
    /// Add a variant `yours`: the scenario with your own program in place of
    /// a process, PROCESS[@VEHICLES]=COMMAND as `shoal run --replace` takes
    /// it (repeatable).
    #[arg(long, value_name = "PROCESS[@VEHICLES]=COMMAND", value_parser = super::run::parse_replace)]
    replace: Vec<shoal_scenario::replace::Replace>,
}

/// Runs every variant into OUT/<variant>/ and writes compare.md, .json, .png.
pub fn run(cmd: CompareCmd) -> anyhow::Result<()> {
    let base = preflight::load_scenario_with(&cmd.scenario, |s| {
        if let Some(seed) = cmd.seed {
            s.seed = seed;
        }
    })?;
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
    for (name, scenario) in variants(&base, &cmd.replace)? {
        eprintln!("== {name}");
        let done = pipeline::run_and_summarize(scenario, &out.join(name), &settings)
            .with_context(|| format!("variant {name}"))?;
        rows.push(row(name, &done.summary));
        runs.push((name, done));
    }
    let refs: Vec<_> = runs
        .iter()
        .map(|(n, d)| (*n, &d.scenario, &d.recording))
        .collect();
    plots::write_compare_plot(&refs, &out).context("writing the comparison plot")?;
    let yours = if cmd.replace.is_empty() {
        String::new()
    } else {
        let list: Vec<String> = cmd
            .replace
            .iter()
            .map(|r| format!("{} → `{}`", r.process.name(), r.command.join(" ")))
            .collect();
        format!(" vs yours ({})", list.join(", "))
    };
    let md = format!(
        "# {} (seed {}): method vs as published vs acoustic baseline vs no vertical shift{yours}\n\nsafe distance {} m\n\n{}",
        base.name,
        base.seed,
        base.safety.safe_distance_m,
        table(&rows, base.safety.safe_distance_m)
    );
    std::fs::write(out.join("compare.md"), &md)?;
    std::fs::write(
        out.join("compare.json"),
        crate::analysis::summary::tidy_json_text(&rows)?,
    )?;
    print!("{md}");
    println!("{}", out.display());
    Ok(())
}
