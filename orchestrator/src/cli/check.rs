//! `shoal check`: validate and resolve a scenario, print the formation,
//! and with `--hosts` its placement and what crosses hosts.

use std::path::PathBuf;

use crate::hosts::{HostsFile, Placement};
use crate::preflight;

/// Framing a Zenoh message adds on a link, bytes (a frame header with the
/// key as a declared id; TCP/IP headers are shared by a batch).
const ZENOH_OVERHEAD: usize = 16;

/// Resolves the scenario at `path` (default: the paper's) and prints each
/// follower's slot and D_a/D_b, with any advice; with `resolved`, the
/// effective scenario as TOML instead; with `hosts`, the placement.
pub fn run(
    path: Option<PathBuf>,
    resolved: bool,
    hosts: Option<PathBuf>,
    out: Option<PathBuf>,
) -> anyhow::Result<()> {
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
    let slots: Vec<planner::formation::FollowerSlot> = s
        .vehicles
        .iter()
        .filter_map(|v| {
            Some(planner::formation::FollowerSlot {
                name: v.name.clone(),
                parent: v.parent.clone()?,
                slot_in_parent_m: v.slot_m?,
            })
        })
        .collect();
    if let (Some(leader), false) = (
        s.vehicles.iter().find(|v| v.parent.is_none()),
        slots.is_empty(),
    ) {
        let d_min = s.safety.safe_distance_m;
        if let Ok((narrowest, full)) =
            planner::formation::narrowest_gap_m(&leader.name, &slots, d_min)
        {
            println!(
                "  formation {full:.1} m wide; narrowest gap it passes at the safe distance ({d_min} m): {narrowest:.1} m"
            );
            if let Some(o) = preflight::narrowest_opening(&s)? {
                println!(
                    "  route: narrowest opening {:.1} m wide, {:.0} m along",
                    o.width_m, o.along_m
                );
                if o.width_m < narrowest {
                    println!(
                        "warning: the route passes an opening {:.1} m wide {:.0} m along, narrower than the {narrowest:.1} m this formation passes at the safe distance: a gap in a wall that narrow will bring files within the safe distance (between separate obstacles, files may pass on either side)",
                        o.width_m, o.along_m
                    );
                }
            }
        }
    }
    for line in preflight::advice(&s) {
        println!("warning: {line}");
    }
    let out = out.unwrap_or_else(|| PathBuf::from("runs"));
    let expected = preflight::resources::expected_recording_bytes(&s);
    let free = preflight::resources::free_bytes_at(&out);
    println!(
        "  recording: about {:.0} MB expected; {}",
        expected as f64 / 1e6,
        free.map_or("the output disk's free space is unknown".to_string(), |f| {
            format!("{} has {:.0} MB free", out.display(), f as f64 / 1e6)
        })
    );
    if let Some(free) = free.filter(|&f| f < expected) {
        println!(
            "warning: the output disk cannot hold the expected recording (about {:.0} MB; {} has {:.0} MB free): the run would stop when the disk fills, its recording readable up to there. Free space, shorten the run (--duration), or write elsewhere (--out)",
            expected as f64 / 1e6,
            out.display(),
            free as f64 / 1e6
        );
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
    print_replacements(&s);
    if let Some(path) = hosts {
        print_placement(&s, &HostsFile::load(&path)?)?;
    }
    Ok(())
}

/// Which processes a user's command runs (`[[replace]]`, `--replace`), one
/// line per command, and a warning for a program that cannot be found here.
fn print_replacements(s: &shoal_scenario::Scenario) {
    let mut by_command: Vec<(&[String], Vec<String>)> = Vec::new();
    for p in s.processes() {
        if let Some(command) = s.replacement(p.kind, &p.vehicle) {
            match by_command.iter_mut().find(|(c, _)| *c == command) {
                Some((_, list)) => list.push(p.label()),
                None => by_command.push((command, vec![p.label()])),
            }
        }
    }
    for (command, list) in by_command {
        println!("  replaced {} by `{}`", list.join(", "), command.join(" "));
        if crate::launch::os::find_program(&command[0]).is_none() {
            println!(
                "warning: `{}` cannot be found from here (a name is looked up on PATH, a path from the directory shoal runs in)",
                command[0]
            );
        }
    }
}

/// The placement of `s` on `file`'s hosts, the crossings and the links.
fn print_placement(s: &shoal_scenario::Scenario, file: &HostsFile) -> anyhow::Result<()> {
    let p = Placement::new(file, s)?;
    let procs = s.processes();
    println!("placement on {} host(s):", p.len());
    for h in 0..p.len() {
        let n = procs.iter().filter(|x| p.runs(s, h, x)).count();
        let vehicles = p.vehicles_on(s, h);
        println!(
            "  {:<10} {:<28} {:>4} processes{}  vehicles: {}",
            p.hosts[h],
            p.endpoints[h],
            n,
            if p.world_host == h { " (world)" } else { "" },
            if vehicles.is_empty() {
                "-".to_string()
            } else {
                vehicles.join(" ")
            }
        );
    }
    let crossings = p.crossings(s, "RUN");
    let sample_rate: f64 = crossings
        .iter()
        .map(|c| c.rate_hz * c.to.len() as f64)
        .sum();
    println!(
        "crossing hosts: {} service(s), {:.0} samples per simulated second delivered",
        crossings.len(),
        sample_rate
    );
    for c in &crossings {
        let to: Vec<&str> = c.to.iter().map(|&t| p.hosts[t].as_str()).collect();
        println!(
            "  {:<6} {:<8} {} -> {}  {} B at {:.0} Hz",
            c.what,
            c.vehicle,
            p.hosts[c.from],
            to.join(","),
            c.sample_bytes,
            c.rate_hz
        );
    }
    println!(
        "links to the coordinator, per simulated second ({ZENOH_OVERHEAD} B framing per message; {:.0} lockstep ticks/s):",
        crate::hosts::placement::lockstep_ticks_per_sim_s(s)
    );
    for (h, (up, down)) in p.link_load(s, "RUN", ZENOH_OVERHEAD).iter().enumerate() {
        println!(
            "  {:<10} up {:>9.1} kB/s ({:>6.0} msg/s)   down {:>9.1} kB/s ({:>6.0} msg/s)",
            p.hosts[h],
            up.bytes_per_s / 1e3,
            up.messages_per_s,
            down.bytes_per_s / 1e3,
            down.messages_per_s
        );
    }
    Ok(())
}
