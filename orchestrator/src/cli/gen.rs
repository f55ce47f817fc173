//! `shoal gen`: a generated large-group scenario on stdout.

use crate::gen::{generate, Family, Feature, GenOptions, ObstacleCount, Shape};

/// Arguments of `shoal gen`.
#[derive(Debug, clap::Args)]
#[command(
    long_about = "Generate a large-group scenario on stdout: a formation tree whose every parent \
                  is in its followers' camera view at the start, followers leading followers \
                  (the tree deepens with N), D_a/D_b assigned so that \
                  `shoal check` accepts it, and gates of walls the group must squeeze through. \
                  Same options, same file.\n\nExample: shoal gen --vehicles 25 --shape grid > \
                  gen25.toml && shoal run gen25.toml"
)]
pub struct GenCmd {
    /// Number of vehicles, leader included (2 to 256; default 25, or 5 with
    /// `--shape paper`).
    #[arg(long)]
    pub vehicles: Option<usize>,
    /// Formation shape: triangle (filled wedge, shallowest tree), v (two
    /// arms; `--vehicles 9` is two branches four deep), column (three
    /// files), grid (wedge front, then 2k+1 files), paper (the paper's five).
    #[arg(long, value_enum, default_value_t = Shape::Triangle)]
    pub shape: Shape,
    /// Distance between neighbouring files, m. A file's head is 2 × that
    /// ahead-and-across from its parent (more if the camera needs it); the
    /// others two thirds of that behind theirs. 3 to 4.5 with the default
    /// camera.
    #[arg(long, default_value_t = 4.0)]
    pub spacing: f64,
    /// Seed: the scenario's noise seed, and the jitter of gate positions and
    /// wall lengths.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Obstacles: `auto` (one gate of two walls) or a count K (K/2 gates along
    /// the route, plus one port-side wall if K is odd; 0 = open water).
    #[arg(long, default_value = "auto", conflicts_with = "course")]
    pub obstacles: ObstacleCount,
    /// An obstacle course of this family instead of gates: gate, offset,
    /// asymmetric, slalom, turn, s-bend, cylinders, angled, depth, current
    /// (the route, its obstacles and any current drawn from the course seed),
    /// or composed: two to five features strung along one route, gap widths
    /// from the formation's full width down to the narrowest it passes.
    #[arg(long, value_enum)]
    pub course: Option<Family>,
    /// The course's seed (default: `--seed`): one course, several noise seeds.
    #[arg(long, requires = "course")]
    pub course_seed: Option<u64>,
    /// With `--course composed`: features the course must have, comma
    /// separated (gap, turn, u-turn, s-bend, cylinders, spheres, walls,
    /// depth, current); the rest are drawn from the course seed as usual.
    #[arg(long, value_enum, value_delimiter = ',', requires = "course")]
    pub with: Vec<Feature>,
    /// Scenario name (default `gen-<shape>-<N>-s<seed>`).
    #[arg(long)]
    pub name: Option<String>,
    /// Camera model: point (beacon pixels from the truth) or image (rendered
    /// frames, a camera-sim process per follower, a 0.01 s tick).
    #[arg(long, value_enum, default_value_t = CameraArg::Point)]
    pub camera: CameraArg,
}

/// `--camera` of `shoal gen` and `shoal campaign`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CameraArg {
    /// Beacon pixels projected from the truth.
    Point,
    /// Rendered frames in which camera-pose finds the beacons.
    Image,
}

impl From<CameraArg> for shoal_scenario::CameraModel {
    fn from(c: CameraArg) -> Self {
        match c {
            CameraArg::Point => Self::Point,
            CameraArg::Image => Self::Image,
        }
    }
}

impl From<&GenCmd> for GenOptions {
    fn from(c: &GenCmd) -> Self {
        Self {
            vehicles: c
                .vehicles
                .unwrap_or(if c.shape == Shape::Paper { 5 } else { 25 }),
            shape: c.shape,
            spacing_m: c.spacing,
            seed: c.seed,
            obstacles: c.obstacles,
            name: c.name.clone(),
            course: c.course,
            course_seed: c.course_seed,
            camera: c.camera.into(),
            with: c.with.clone(),
        }
    }
}

/// Runs `shoal gen`: prints the scenario on stdout.
pub fn run(cmd: GenCmd) -> anyhow::Result<()> {
    let text = generate(&GenOptions::from(&cmd))?;
    print!("{text}");
    Ok(())
}
