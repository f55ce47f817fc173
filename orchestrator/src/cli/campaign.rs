//! `shoal campaign`: generated courses × seeds, and their report.

use std::path::PathBuf;

use crate::campaign::{self, CampaignOptions};
use crate::gen::{Family, Shape};

/// Arguments of `shoal campaign`.
#[derive(Debug, clap::Args)]
#[command(
    long_about = "Run N generated obstacle courses x K noise seeds in lockstep (as many runs at \
                  once as --jobs) and write OUT/campaign.md, OUT/campaign.json and \
                  OUT/campaign.png/.svg: the pass rate per family and overall, the worst min \
                  pair, clearance, parent gap, settled slot error and goal error, and every \
                  failing run's directory with what failed. Course i is of family i mod F with \
                  course seed i div F. A run passes with no collision of either kind, min pair \
                  >= the safe distance, clearance >= half of it, no parent lost over 5 s, slot \
                  error RMS over the last 30 s < 0.5 m and the leader within 1 m of its goal.\n\n\
                  The same command again resumes (runs with a summary.json are kept). Ctrl-C \
                  stops the runs under way and writes the report of those finished. Exit \
                  status 0 if every run passed, 3 if one failed.\n\nExample: shoal campaign \
                  --shape paper --courses 10 --seeds 1 --out runs/campaign"
)]
pub struct CampaignCmd {
    /// Formation shape (as `shoal gen`): paper (the paper's five), v, triangle, column, grid.
    #[arg(long, value_enum, default_value_t = Shape::Paper)]
    shape: Shape,
    /// Number of vehicles (default 5 with `--shape paper`, else 9).
    #[arg(long)]
    vehicles: Option<usize>,
    /// Distance between neighbouring files, m.
    #[arg(long, default_value_t = 4.0)]
    spacing: f64,
    /// Families, comma-separated (default: every family).
    #[arg(long, value_enum, value_delimiter = ',')]
    families: Vec<Family>,
    /// Number of courses (spread over the families in turn).
    #[arg(long, default_value_t = 10)]
    courses: usize,
    /// Noise seeds per course (0..K).
    #[arg(long, default_value_t = 1)]
    seeds: u64,
    /// Runs at once (default: the number of cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Output directory (default: runs/campaign-<shape>-<N>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
    /// Keep the recordings of passing runs too (default: only the failing runs').
    #[arg(long)]
    keep_recordings: bool,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
    /// Run the paper's method as published (`[method] generalised = false`),
    /// to measure a change to the method against it.
    #[arg(long)]
    published: bool,
    /// Camera model of every course (as `shoal gen --camera`).
    #[arg(long, value_enum, default_value_t = crate::cli::gen::CameraArg::Point)]
    camera: crate::cli::gen::CameraArg,
    /// Sample the whole space: every course composed (2-5 features: gaps from the
    /// formation's narrowest to its full width, turns up to 180°, S-bends, cylinder and
    /// sphere fields, walls at any angle, depth changes, currents over any part), each
    /// with a formation drawn from its course seed (5-50 vehicles of any shape, a fifth
    /// with images). --shape, --vehicles, --camera and --families are then not used.
    #[arg(long, conflicts_with_all = ["shape", "vehicles", "camera", "families"])]
    space: bool,
    /// The first course seed: run courses K, K+1, ... (so a method tuned on one range
    /// can be judged on another).
    #[arg(long, default_value_t = 0)]
    first_course_seed: u64,
    /// Run your own method over the campaign: every run gets this
    /// `--replace PROCESS[@VEHICLES]=COMMAND` (see `shoal run --help`), and
    /// the report names it. Repeatable.
    #[arg(long, value_name = "PROCESS[@VEHICLES]=COMMAND", value_parser = check_replace)]
    replace: Vec<String>,
    /// Show the pass rates of earlier campaigns over the same courses (their
    /// campaign.json) beside this one's, a column per method: yours beside
    /// the paper's (--published) and shoal's. Repeatable.
    #[arg(long, value_name = "CAMPAIGN.JSON")]
    beside: Vec<PathBuf>,
}

/// A `--replace` flag as given, once `shoal run` would take it.
fn check_replace(flag: &str) -> Result<String, String> {
    super::run::parse_replace(flag).map(|_| flag.to_string())
}

/// Runs the campaign, prints its table; exit status 3 if a run failed.
pub fn run(cmd: CampaignCmd) -> anyhow::Result<()> {
    let vehicles = cmd
        .vehicles
        .unwrap_or(if cmd.shape == Shape::Paper { 5 } else { 9 });
    let families = if cmd.families.is_empty() {
        Family::ALL.to_vec()
    } else {
        cmd.families.clone()
    };
    let out = cmd.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(if cmd.space {
            format!("campaign-space-{}", cmd.first_course_seed)
        } else {
            format!("campaign-{}-{vehicles}", cmd.shape.name())
        })
    });
    let jobs = cmd.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    let o = CampaignOptions {
        shape: cmd.shape,
        vehicles,
        spacing_m: cmd.spacing,
        families,
        courses: cmd.courses,
        seeds: cmd.seeds,
        jobs,
        out: out.clone(),
        shoal: std::env::current_exe()?,
        bin_dir: cmd.bin_dir.clone(),
        keep_recordings: cmd.keep_recordings,
        quiet: cmd.quiet,
        published: cmd.published,
        camera: cmd.camera.into(),
        space: cmd.space,
        first_course_seed: cmd.first_course_seed,
        replace: cmd.replace.clone(),
        beside: cmd
            .beside
            .iter()
            .map(|p| crate::campaign::report::Beside::read(p))
            .collect::<anyhow::Result<_>>()?,
    };
    let report = campaign::run(&o)?;
    print!("{}", report.markdown());
    println!("\n{}", out.display());
    if report.failures().next().is_some() {
        std::process::exit(3);
    }
    Ok(())
}
