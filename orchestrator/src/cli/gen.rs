//! `shoal gen`: a generated large-group scenario on stdout.

use crate::gen::{generate, GenOptions, ObstacleCount, Shape};

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
    /// Number of vehicles, leader included (2 to 256).
    #[arg(long, default_value_t = 25)]
    pub vehicles: usize,
    /// Formation shape: triangle (filled wedge, shallowest tree), v (two
    /// arms), column (three files), grid (wedge front, then 2k+1 files).
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
    #[arg(long, default_value = "auto")]
    pub obstacles: ObstacleCount,
    /// Scenario name (default `gen-<shape>-<N>-s<seed>`).
    #[arg(long)]
    pub name: Option<String>,
}

impl From<&GenCmd> for GenOptions {
    fn from(c: &GenCmd) -> Self {
        Self {
            vehicles: c.vehicles,
            shape: c.shape,
            spacing_m: c.spacing,
            seed: c.seed,
            obstacles: c.obstacles,
            name: c.name.clone(),
        }
    }
}

/// Runs `shoal gen`: prints the scenario on stdout.
pub fn run(cmd: GenCmd) -> anyhow::Result<()> {
    let text = generate(&GenOptions::from(&cmd))?;
    print!("{text}");
    Ok(())
}
