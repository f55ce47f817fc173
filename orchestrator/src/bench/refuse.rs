//! `shoal bench refuse`: how fast, and in how much memory, `shoal check`
//! refuses inputs far too large (issue 48's list: 10,000 vehicles, 100,000
//! obstacles, a 100 MB scenario, a mesh of a million triangles), each timed
//! as its own process. The tests assert the refusals and their messages;
//! the times and peak memory are printed here, never asserted.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::Context;

/// Arguments of `shoal bench refuse`.
#[derive(Debug, clap::Args)]
pub struct RefuseCmd {
    /// Where to write the inputs (default: a directory under the system's
    /// temporary directory, removed at the end).
    #[arg(long)]
    pub dir: Option<PathBuf>,
}

/// A scenario of `vehicles` in a binary tree, then `extra` as it is.
pub fn sized_scenario(vehicles: usize, extra: &str) -> String {
    let mut s = String::from("name = \"big\"\nduration_s = 10.0\n");
    for i in 0..vehicles {
        s.push_str(&format!("[[vehicles]]\nname = \"V{i}\"\n"));
        if i > 0 {
            let side = if i % 2 == 0 { 4.0 } else { -4.0 };
            s.push_str(&format!(
                "parent = \"V{}\"\nslot_m = [-8.0, {side}, 0.0]\n",
                (i - 1) / 2
            ));
        }
    }
    s.push_str(extra);
    s
}

/// `n` spheres along the track.
pub fn spheres(n: usize) -> String {
    (0..n)
        .map(|k| {
            format!(
                "[[obstacles]]\nkind = \"sphere\"\ncenter_ned_m = [{}.0, 0.0, 10.0]\nradius_m = 1.0\n",
                100 + k
            )
        })
        .collect()
}

/// One mesh of `triangles` triangles.
pub fn mesh(triangles: usize) -> String {
    let tri = vec!["[0,1,2]"; triangles].join(",");
    format!("[[obstacles]]\nkind = \"mesh\"\nvertices_ned_m = [[0.0,0.0,0.0],[1.0,0.0,0.0],[0.0,1.0,0.0]]\ntriangles = [{tri}]\n")
}

/// The oversized inputs: a name, the scenario's text, and what the refusal
/// must say.
pub fn oversized_inputs() -> Vec<(&'static str, String, &'static str)> {
    let big_text = format!(
        "name = \"x\"\nduration_s = 1.0\n{}",
        format!("# {}\n", "x".repeat(97)).repeat(1_000_000)
    );
    vec![
        (
            "10k-vehicles",
            sized_scenario(10_000, ""),
            "10000 vehicles, at most 256",
        ),
        (
            "5k-obstacles",
            sized_scenario(3, &spheres(5_000)),
            "5000 obstacles, at most 4096",
        ),
        (
            "100k-obstacles",
            sized_scenario(3, &spheres(100_000)),
            "more than a scenario may be (4.0 MiB)",
        ),
        ("100MB", big_text, "more than a scenario may be (4.0 MiB)"),
        (
            "300k-triangles",
            sized_scenario(1, &mesh(300_000)),
            "300000 mesh triangles in all, at most 200000",
        ),
        (
            "1M-triangles",
            sized_scenario(1, &mesh(1_000_000)),
            "more than a scenario may be (4.0 MiB)",
        ),
    ]
}

/// Runs `shoal check FILE` as its own process: exit success, stderr, wall
/// seconds, peak resident memory in KiB.
fn timed_check(shoal: &Path, file: &Path) -> anyhow::Result<(bool, String, f64, i64)> {
    let start = Instant::now();
    let mut cmd = Command::new(shoal);
    cmd.arg("check")
        .arg(file)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    // A pre-exec hook makes this a fork, not a vfork: a vfork'd child's
    // peak would be this process's (which wrote the inputs).
    crate::launch::os::die_with_parent(&mut cmd);
    let child = cmd.spawn().context("cannot start shoal check")?;
    let pid = child.id() as i32;
    let mut stderr = child.stderr.context("no stderr")?;
    let mut text = String::new();
    std::io::Read::read_to_string(&mut stderr, &mut text)?;
    let exit = crate::launch::os::wait_pid(pid).context("shoal check was not reaped")?;
    let wall = start.elapsed().as_secs_f64();
    Ok((exit.success(), text, wall, exit.max_rss_kib))
}

/// Runs the benchmark.
pub fn run(cmd: RefuseCmd) -> anyhow::Result<()> {
    let dir = cmd.dir.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("shoal-refuse-{}", crate::launch::os::random_id()))
    });
    std::fs::create_dir_all(&dir)?;
    let shoal = std::env::current_exe().context("the path of shoal itself")?;
    println!("shoal check on oversized inputs, each its own process:");
    println!(
        "  {:<16} {:>10} {:>9} {:>9} {:>12}  message",
        "input", "MB", "refused", "ms", "peak RSS MiB"
    );
    // Every input is written first and dropped: a process spawned while
    // this one holds them would count their pages in its peak.
    let mut inputs = Vec::new();
    for (name, text, expect) in oversized_inputs() {
        let path = dir.join(format!("{name}.toml"));
        std::fs::write(&path, &text)?;
        inputs.push((name, path, text.len(), expect));
    }
    crate::launch::os::trim_heap();
    let mut all_refused = true;
    for (name, path, bytes, expect) in inputs {
        let (ok, stderr, wall, rss) = timed_check(&shoal, &path)?;
        let said = stderr.contains(expect);
        all_refused &= !ok && said;
        let line = stderr
            .lines()
            .find(|l| l.contains(expect))
            .or_else(|| stderr.lines().last())
            .unwrap_or("")
            .trim();
        let line = line.rsplit_once(": ").map_or(line, |(_, m)| m);
        println!(
            "  {name:<16} {:>10.1} {:>9} {:>9.0} {:>12.1}  {}",
            bytes as f64 / 1e6,
            if ok { "no" } else { "yes" },
            wall * 1e3,
            rss as f64 / 1024.0,
            line.chars().take(90).collect::<String>()
        );
    }
    if cmd.dir.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    println!(
        "  goal: each refused within 1 s in bounded memory; {}",
        if all_refused {
            "every input refused with its message"
        } else {
            "NOT every input refused with its message"
        }
    );
    Ok(())
}
