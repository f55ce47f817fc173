//! `shoal check`: validate and resolve a scenario, print the formation.

use std::path::PathBuf;

use crate::preflight;

/// Resolves the scenario at `path` (default: the paper's) and prints each
/// follower's slot and D_a/D_b, with any advice; with `resolved`, the
/// effective scenario as TOML instead.
pub fn run(path: Option<PathBuf>, resolved: bool) -> anyhow::Result<()> {
    let mut s = preflight::load_scenario(&path)?;
    preflight::resolve(&mut s)?;
    if resolved {
        print!("{}", preflight::effective_toml(&s)?);
        return Ok(());
    }
    println!(
        "{}: ok ({} vehicles, {} processes)",
        s.name,
        s.vehicles.len(),
        s.processes().len()
    );
    for line in preflight::advice(&s) {
        println!("warning: {line}");
    }
    for v in s.vehicles.iter().filter(|v| v.parent.is_some()) {
        println!(
            "  {:<8} follows {:<8} slot {:?} m  D_a {:.2} m  D_b {:+.2} m",
            v.name,
            v.parent.as_deref().unwrap_or(""),
            v.slot_m.unwrap_or_default(),
            v.d_a_m.unwrap_or(0.0),
            v.d_b_m.unwrap_or(0.0)
        );
    }
    Ok(())
}
