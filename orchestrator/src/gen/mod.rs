//! `shoal gen`: generates a large-group scenario — a formation tree whose
//! followers lead other followers, D_a/D_b assigned so that `shoal check`
//! accepts it, and obstacles the group must squeeze through — as TOML on
//! stdout.
//!
//! ```text
//! shoal gen --vehicles 25 --shape grid > gen25.toml
//! shoal check gen25.toml && shoal run gen25.toml --out /tmp/gen25
//! ```
//!
//! [`generate`] is a pure function of [`GenOptions`]: same options, same
//! text, byte for byte. What it builds:
//!
//! * **Formation** ([`layout`]): files `spacing` apart behind the leader;
//!   a file's head follows the head of the next file inward diagonally (a
//!   lateral link that shifts toward its parent's track near obstacles), the
//!   others the vehicle straight ahead in their file (a rigid link);
//!   neighbouring files are staggered by half a link. Every parent is in its
//!   followers' camera view at the start with 5° and 1 m to spare, and the
//!   tree deepens with N (a level per file outward or per vehicle back).
//! * **D_a/D_b** from [`planner::formation::assign_displacements`] (the
//!   function `shoal check` uses) with the safe distance plus the first of
//!   [`ASSIGN_MARGINS_M`] that has an assignment (falling back to the bare
//!   safe distance), written
//!   into every follower, so that the displacement trajectories keep the
//!   vehicles apart with room for tracking error.
//! * **Obstacles**: gates of two walls across the route. The gap is narrower
//!   than the group (its walls' faces lie on the outermost files' track,
//!   which must shift inward) but leaves the other files `D_min + 2 m` of
//!   clearance, so the shifted formation passes with the safe distance; the walls reach past the
//!   outermost file so no one passes outside. Gates are spaced so the whole
//!   group has passed one and closed up before the next.
//! * **Timing**: the followers remember obstacle points (and keep their
//!   shift) until the followers behind them have passed too
//!   (`follower.memory_behind_m`); the mission ends far enough past the
//!   last gate for the group to re-form, and the duration covers the leader's
//!   arrival plus a settled stretch.
//!
//! * **Controller**: the followers' MPC heading weight is raised
//!   [`YAW_WEIGHT_FACTOR`]-fold (`[mpc] rho1`), as deep trees copy each
//!   parent's heading into their slot.
//!
//! The seed sets the scenario's `seed` (sensor noise) and jitters where the
//! gates stand and how long their walls are.

pub mod compose;
pub mod course;
mod layout;
mod render;
#[cfg(test)]
mod tests;

use camera_pose::CameraConfig;
use planner::formation::{FollowerSlot, FormationParams};

pub use compose::Feature;
pub use course::{Course, Family};
pub use layout::{Lattice, Member};
use render::render;

/// Most vehicles a scenario can hold (the world snapshot's size).
pub const MAX_VEHICLES: usize = ipc_types::MAX_VEHICLES;
/// Most obstacles `--obstacles` accepts (each pair is a gate along the route).
pub const MAX_OBSTACLES: usize = 16;
/// The safe distance written into `[safety]` (the paper's 2 m), m.
pub const SAFE_DISTANCE_M: f64 = 2.0;
/// Extra separation the generator asks of the displacement trajectories
/// beyond the safe distance, for tracking error, m, tried in this order. A
/// formation assigned at the bare safe distance keeps it only if every
/// vehicle tracks its slot exactly: triangles of 13-38 and grids of 21
/// assigned at 2 m came within 1.92-1.98 m on the tuning courses, and most
/// of those that have no 2.5 m assignment have one at 2.25 or 2.1 m.
pub const ASSIGN_MARGINS_M: [f64; 3] = [0.5, 0.25, 0.1];
/// Groups up to this size (the campaign's largest) are first assigned with
/// [`ASSIGN_MARGINS_M`], with [`MARGIN_SEARCH_BUDGET`] candidates; larger
/// ones go straight to the safe distance (a failing search costs seconds).
pub const MARGIN_MAX_VEHICLES: usize = 50;
/// Candidates the assignment with the margin may try (the check's default
/// 4000 finds one only for V shapes beyond five vehicles; measured with
/// 100 000: every column to 50, V to 40, grid to 14, triangle to 9, in
/// 0.5-1.7 s; a failing search 2-3.5 s).
pub const MARGIN_SEARCH_BUDGET: usize = 100_000;
/// Largest clearance of the innermost unshifted file from a gate's wall
/// beyond the safe distance, m (so that its sonar's `min δ` stays clear of
/// `D_min`). The margin is `min(this, spacing − D_min)`: with the default
/// 4 m spacing the wall's face lies on the next file's track, which must
/// shift inward by half the spacing (λ = 0.5) to keep `D_min` from it.
pub const GATE_CLEAR_MARGIN_M: f64 = 2.0;
/// The followers' MPC heading weight, as a multiple of the mpc default.
pub const YAW_WEIGHT_FACTOR: f64 = 5.0;
/// `follower.headway_s` of a generated scenario, s: the headway that keeps
/// a deep tree string-stable (see the planner's `FollowerConfig::headway_s`).
///
/// 2 s, twice the lag of a follower's loop (vision, observer and MPC: about
/// 1 s), as a constant time headway needs to damp every level. With 1 s the
/// along-track swing still grew slightly per level: on the 100-vehicle V
/// through a gate (13 levels) a follower 13 levels down swung 8-14 m behind
/// its parent (slot 9 m) and lost it for 6 s; with 2 s every camera stayed
/// within 11.5 m.
pub const HEADWAY_S: f64 = 2.0;
/// `follower.yaw_headway_s` of a generated scenario, s.
pub const YAW_HEADWAY_S: f64 = 3.0;
/// `follower.headway_avg_s` of a generated scenario, s: longer than the
/// planner's default, so that the start-up acceleration (20 s) is not where
/// the headway's slow average lets the gain per level exceed 1.
///
/// Measured on 100 vehicles against `yaw_headway_s = 1`, `headway_avg_s =
/// 20`: the V (14 levels) lost no parent instead of six in the start-up, the
/// grid's closest approach to a wall went from 0.34 m to 1.54 m, the
/// triangle kept 0 collisions with every camera within 10.8 m of its parent.
pub const HEADWAY_AVG_S: f64 = 60.0;
/// How far the walls reach past the outermost file, m.
pub const WALL_OVERHANG_M: f64 = 6.0;
/// The lateral links of the paper's formation (`--shape paper`), m.
pub const PAPER_LINK_M: f64 = 8.0;
/// Mission speed, m/s (the paper's).
pub const SPEED_MPS: f64 = 1.0;
/// Leader's speed ramp, m/s² (as the paper scenario).
pub const ACCEL_MPS2: f64 = 0.05;

/// The formation's shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Shape {
    /// A filled wedge: tree level d holds 2d + 1 vehicles (file c's head at
    /// level |c|). The shallowest tree for N; the default.
    Triangle,
    /// Two arms of files: each file's head and `round(√(N/8))` − 1 vehicles
    /// behind it (the paper's "triangle" of five is a V of heads only).
    V,
    /// Three files (port, centre, starboard) behind the leader, as long as
    /// N needs.
    Column,
    /// A wedge front, then `2k + 1` files with `k = round(√N / 2.5)`.
    Grid,
    /// The paper's five: L, F1/F2 8 m behind and 4 m either side of it,
    /// F3/F4 likewise behind F1/F2 (a V of heads with 8 m links).
    Paper,
}

impl Shape {
    /// Lower-case name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Shape::Triangle => "triangle",
            Shape::V => "v",
            Shape::Column => "column",
            Shape::Grid => "grid",
            Shape::Paper => "paper",
        }
    }
}

/// How many obstacles to place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObstacleCount {
    /// One gate of two walls (the paper's narrow passage).
    Auto,
    /// K walls: K/2 gates, and a single port-side wall if K is odd.
    Count(usize),
}

impl std::str::FromStr for ObstacleCount {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(ObstacleCount::Auto);
        }
        s.parse::<usize>()
            .map(ObstacleCount::Count)
            .map_err(|_| format!("`{s}` is neither `auto` nor a count of obstacles"))
    }
}

impl std::fmt::Display for ObstacleCount {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ObstacleCount::Auto => write!(f, "auto"),
            ObstacleCount::Count(k) => write!(f, "{k}"),
        }
    }
}

/// What to generate (what `shoal gen`'s arguments say).
#[derive(Debug, Clone, PartialEq)]
pub struct GenOptions {
    /// Vehicles, leader included.
    pub vehicles: usize,
    /// Shape.
    pub shape: Shape,
    /// File spacing, m.
    pub spacing_m: f64,
    /// Seed.
    pub seed: u64,
    /// Obstacles.
    pub obstacles: ObstacleCount,
    /// Scenario name (`None`: `gen-<shape>-<N>-s<seed>`, or
    /// `<course>-<shape>-<N>-s<seed>`).
    pub name: Option<String>,
    /// A course of this family instead of `obstacles`' gates.
    pub course: Option<Family>,
    /// The course's own seed (where and how its obstacles stand; `None`:
    /// `seed`), so one course can be run with several noise seeds.
    pub course_seed: Option<u64>,
    /// The camera model (`[camera] model`); with images the tick is the
    /// 0.01 s that a six-stage frame needs.
    pub camera: shoal_scenario::CameraModel,
    /// Features a composed course must have (with [`Family::Composed`]
    /// only; the others are drawn as usual).
    pub with: Vec<Feature>,
}

impl Default for GenOptions {
    fn default() -> Self {
        Self {
            vehicles: 25,
            shape: Shape::Triangle,
            spacing_m: 4.0,
            seed: 0,
            obstacles: ObstacleCount::Auto,
            name: None,
            course: None,
            course_seed: None,
            camera: shoal_scenario::CameraModel::Point,
            with: Vec::new(),
        }
    }
}

/// Why a scenario cannot be generated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GenError {
    /// More vehicles than the world snapshot holds.
    #[error("--vehicles {requested}: at most {max} vehicles fit in a run (ipc_types::MAX_VEHICLES, the world snapshot's size)")]
    TooManyVehicles {
        /// Asked for.
        requested: usize,
        /// The limit.
        max: usize,
    },
    /// Fewer than a leader and one follower.
    #[error("--vehicles {0}: a formation needs at least 2 vehicles (a leader and a follower)")]
    TooFewVehicles(usize),
    /// The spacing does not fit the camera or the safe distance.
    #[error("--spacing {spacing_m}: {reason}")]
    Spacing {
        /// Asked for, m.
        spacing_m: f64,
        /// Why not.
        reason: String,
    },
    /// Too many obstacles.
    #[error("--obstacles {requested}: at most {max}")]
    TooManyObstacles {
        /// Asked for.
        requested: usize,
        /// The limit.
        max: usize,
    },
    /// `--with` on anything but a composed course.
    #[error("--with needs --course composed (the presets have fixed features)")]
    WithNeedsComposed,
    /// A name a scenario cannot have.
    #[error("--name `{0}`: must be 1 to 64 of [A-Za-z0-9_.-], not starting with `.`")]
    Name(String),
    /// No D_a/D_b keeps the formation safe.
    #[error("no displacement trajectories keep this formation safe: {0}")]
    Formation(String),
    /// The paper's formation has five vehicles.
    #[error("--shape paper: the paper's formation has 5 vehicles, not {0}")]
    PaperSize(usize),
    /// A bug in the generator.
    #[error("internal: {0}")]
    Internal(String),
}

/// One gate across the route: walls on one or both sides of a gap.
#[derive(Debug, Clone, PartialEq)]
pub struct Gate {
    /// Distance of the walls' front faces ahead of the leader's start, m.
    pub start_m: f64,
    /// Wall length along the route, m.
    pub length_m: f64,
    /// Half the gap: the walls' inner faces are this far either side of the
    /// leader's track, m.
    pub half_gap_m: f64,
    /// Each wall's half-thickness across the route, m.
    pub wall_half_width_m: f64,
    /// A starboard wall as well as the port one.
    pub starboard: bool,
}

/// Everything the file says, before it is written out.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The options it was made from.
    pub opts: GenOptions,
    /// Scenario name.
    pub name: String,
    /// The lattice.
    pub lattice: Lattice,
    /// Vehicles, leader first.
    pub members: Vec<Member>,
    /// `(D_a, D_b)` of each follower (member 1 onward), m.
    pub displacements: Vec<(f64, f64)>,
    /// The separation the displacements were assigned for, m.
    pub assigned_for_m: f64,
    /// Leader's start depth, m.
    pub depth_m: f64,
    /// Largest upward / downward accumulated vertical shift of any vehicle
    /// when every follower is fully shifted, m.
    pub shift_up_m: f64,
    /// See `shift_up_m`.
    pub shift_down_m: f64,
    /// Gates along the route (north from the leader's start).
    pub gates: Vec<Gate>,
    /// Leader's goal, m north of its start.
    pub goal_m: f64,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// `follower.memory_behind_m`.
    pub memory_behind_m: f64,
    /// `follower.memory_max_age_s`.
    pub memory_max_age_s: f64,
    /// The course, when one was asked for (then `gates` is empty).
    pub course: Option<Course>,
    /// Half the gap of a gate (of the gates, or of the course's gaps), m.
    pub half_gap_m: f64,
    /// The outermost vehicle's distance from the leader's track, m.
    pub outer_m: f64,
}

/// SplitMix64: a small deterministic generator for the seed's jitter.
#[derive(Debug, Clone)]
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub(crate) fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && !s.starts_with('.')
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

/// The narrowest gap the formation of `members` passes at the safe distance
/// and its full width, m (what `shoal check` reports:
/// [`planner::formation::narrowest_gap_m`]).
pub fn narrowest_gap_m(members: &[Member]) -> Result<(f64, f64), GenError> {
    let slots = slots_of(members);
    planner::formation::narrowest_gap_m(&members[0].name, &slots, SAFE_DISTANCE_M)
        .map_err(|e| GenError::Internal(e.to_string()))
}

fn slots_of(members: &[Member]) -> Vec<FollowerSlot> {
    members
        .iter()
        .filter_map(|m| {
            Some(FollowerSlot {
                name: m.name.clone(),
                parent: members[m.parent?].name.clone(),
                slot_in_parent_m: m.slot_m?,
            })
        })
        .collect()
}

/// Rounds to a millimetre (keeps the file short and stable).
fn mm(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// D_a/D_b for the formation from the check's own assignment
/// ([`planner::formation::assign_displacements`]), asked for the safe
/// distance plus each of [`ASSIGN_MARGINS_M`] in turn if `with_margin`, then
/// for the safe distance; returns them with the separation they keep.
fn assign(
    members: &[Member],
    with_margin: bool,
) -> Result<(Vec<(f64, f64)>, f64), planner::formation::FormationError> {
    let slots = slots_of(members);
    let params = FormationParams {
        visibility_range_m: CameraConfig::default().visibility_range_m,
        ..Default::default()
    };
    let leader = members[0].name.as_str();
    // the same formation is assigned once per process (a campaign plans one
    // per course, the tests hundreds), since the search with the margin
    // takes seconds
    type Assigned = Result<(Vec<(f64, f64)>, f64), planner::formation::FormationError>;
    static DONE: std::sync::OnceLock<
        std::sync::Mutex<std::collections::HashMap<String, Assigned>>,
    > = std::sync::OnceLock::new();
    let key = format!("{with_margin} {leader} {slots:?}");
    let done = DONE.get_or_init(Default::default);
    if let Some(r) = done.lock().ok().and_then(|m| m.get(&key).cloned()) {
        return r;
    }
    let r = (|| {
        if with_margin {
            let wide = FormationParams {
                search_budget: MARGIN_SEARCH_BUDGET,
                ..params.clone()
            };
            for margin in ASSIGN_MARGINS_M {
                let sep = SAFE_DISTANCE_M + margin;
                if let Ok(d) = planner::formation::assign_displacements(leader, &slots, sep, &wide)
                {
                    return Ok((d, sep));
                }
            }
        }
        planner::formation::assign_displacements(leader, &slots, SAFE_DISTANCE_M, &params)
            .map(|d| (d, SAFE_DISTANCE_M))
    })();
    if let Ok(mut m) = done.lock() {
        m.insert(key, r.clone());
    }
    r
}

/// The radius the leader will fly the course's corners on (what the planner
/// derives from the default camera and beacons, [`planner::view`]), m.
fn turn_radius_m(members: &[Member]) -> f64 {
    planner::view::formation_turn_radius_m(
        members.iter().filter_map(|m| m.slot_m),
        &CameraConfig::default(),
        &camera_pose::BeaconLayout::default(),
        planner::FollowerConfig::default()
            .view_margin_deg
            .to_radians(),
        SPEED_MPS,
    )
}

/// Plans the scenario (everything but the text).
pub fn plan(opts: &GenOptions) -> Result<Plan, GenError> {
    let n = opts.vehicles;
    if n > MAX_VEHICLES {
        return Err(GenError::TooManyVehicles {
            requested: n,
            max: MAX_VEHICLES,
        });
    }
    if n < 2 {
        return Err(GenError::TooFewVehicles(n));
    }
    if opts.shape == Shape::Paper && n != 5 {
        return Err(GenError::PaperSize(n));
    }
    let walls = match opts.obstacles {
        ObstacleCount::Auto => 2,
        ObstacleCount::Count(k) if k > MAX_OBSTACLES => {
            return Err(GenError::TooManyObstacles {
                requested: k,
                max: MAX_OBSTACLES,
            })
        }
        ObstacleCount::Count(k) => k,
    };
    if !opts.with.is_empty() && opts.course != Some(Family::Composed) {
        return Err(GenError::WithNeedsComposed);
    }
    let name = match &opts.name {
        Some(s) if valid_name(s) => s.clone(),
        Some(s) => return Err(GenError::Name(s.clone())),
        None => match (opts.course, opts.course_seed) {
            (Some(f), Some(c)) => format!("{f}{c}-{}-{n}-s{}", opts.shape.name(), opts.seed),
            (Some(f), None) => format!("{f}-{}-{n}-s{}", opts.shape.name(), opts.seed),
            (None, _) => format!("gen-{}-{n}-s{}", opts.shape.name(), opts.seed),
        },
    };
    // The tightest lattice the camera allows first; if no D_a/D_b keeps that
    // one safe (close files leave the displacements little room), longer
    // links, up to what the visibility range allows.
    let tightest = if opts.shape == Shape::Paper {
        Lattice {
            diag_m: PAPER_LINK_M,
            row_m: PAPER_LINK_M * 2.0 / 3.0,
            col_m: opts.spacing_m,
        }
    } else {
        layout::lattice(opts.spacing_m)?
    };
    let mut failure = String::new();
    let mut found = None;
    let mut diag_m = tightest.diag_m;
    while diag_m <= layout::max_row_m() + 1e-9 {
        let lattice = Lattice {
            diag_m,
            row_m: diag_m * 2.0 / 3.0,
            col_m: tightest.col_m,
        };
        let shape = match opts.shape {
            Shape::Paper => Shape::V,
            s => s,
        };
        let members = layout::members(shape, n, lattice)?;
        match assign(&members, n <= MARGIN_MAX_VEHICLES) {
            Ok((d, sep)) => {
                found = Some((lattice, members, d, sep));
                break;
            }
            Err(e) => failure = format!("with lateral links {diag_m} m long: {e}"),
        }
        diag_m += 1.5;
    }
    let Some((lattice, members, displacements, assigned_for_m)) = found else {
        return Err(GenError::Formation(failure));
    };
    let outer_m = members.iter().map(|m| m.pos_m[1].abs()).fold(0.0, f64::max);

    // Vertical shifts accumulate down the tree (each follower's slot is in
    // its parent's frame): start deep enough that no one surfaces.
    let mut up = vec![0.0f64; n];
    let mut down = vec![0.0f64; n];
    for i in 1..n {
        let p = members[i]
            .parent
            .ok_or_else(|| GenError::Internal("orphan".into()))?;
        let db = displacements[i - 1].1 / 2.0;
        up[i] = up[p] + (-db).max(0.0);
        down[i] = down[p] + db.max(0.0);
    }
    let shift_up_m = up.iter().copied().fold(0.0, f64::max);
    let shift_down_m = down.iter().copied().fold(0.0, f64::max);
    let depth_m = (6.0 + shift_up_m).max(10.0).ceil();

    let mut rng = SplitMix(opts.seed ^ 0x5348_4F41_4C47_454E);
    let group_len = members.iter().map(|m| -m.pos_m[0]).fold(0.0, f64::max);
    let c_max = members.iter().map(|m| m.col.abs()).max().unwrap_or(0);
    // The outermost file shifts; the others pass as they are. The paper's
    // passage is narrower: its walls stand on F1/F2's track (8 m wide), so
    // every follower shifts.
    let c_in = if opts.shape == Shape::Paper {
        0
    } else {
        (c_max - 1).max(0)
    };
    let margin = GATE_CLEAR_MARGIN_M.min(lattice.col_m - SAFE_DISTANCE_M);
    let half_gap_m = c_in as f64 * lattice.col_m + SAFE_DISTANCE_M + margin;
    let outer = c_max as f64 * lattice.col_m;
    let wall_half_width_m = mm(((outer + WALL_OVERHANG_M - half_gap_m) / 2.0).max(3.0));

    // The shifting heads keep an obstacle in mind (and their shift) until
    // the followers behind them have passed it too.
    let reach = layout::reach_behind(&members);
    let d_a_max = displacements.iter().map(|d| d.0.abs()).fold(0.0, f64::max);
    let shifting_reach = members
        .iter()
        .zip(&reach)
        .filter(|(m, _)| m.col.abs() > c_in && m.slot_m.is_some_and(|s| s[1] != 0.0))
        .map(|(_, r)| *r)
        .fold(0.0, f64::max);
    let memory_behind_m = mm((shifting_reach + d_a_max / 2.0 + 3.0).max(12.0));

    let between = group_len + memory_behind_m + 40.0;
    let mut gates = Vec::new();
    let mut at = 55.0 + 10.0 * rng.unit();
    let mut max_len = 0.0f64;
    for g in 0..walls.div_ceil(2) {
        let length_m = mm(16.0 + 8.0 * rng.unit());
        max_len = max_len.max(length_m);
        gates.push(Gate {
            start_m: mm(at),
            length_m,
            half_gap_m,
            wall_half_width_m,
            starboard: 2 * g + 1 < walls,
        });
        at += length_m + between + 10.0 * rng.unit();
    }
    let last_end = gates.last().map_or(40.0, |g: &Gate| g.start_m + g.length_m);
    let mut goal_m = mm(last_end + group_len + memory_behind_m + 40.0).ceil();
    let course = opts.course.map(|family| {
        let outer = members.iter().map(|m| m.pos_m[1].abs()).fold(0.0, f64::max);
        let geom = course::Geom {
            half_gap_m,
            outer_m: outer,
            group_len_m: group_len,
            settle_m: group_len + memory_behind_m + 40.0,
            depth_m,
            min_depth_m: (6.0 + shift_up_m).ceil(),
            z_offset_m: (shift_down_m - shift_up_m) / 2.0,
            half_height_m: (shift_up_m + shift_down_m) / 2.0 + 10.0,
            turn_radius_m: turn_radius_m(&members),
        };
        course::build(
            family,
            geom,
            opts.course_seed.unwrap_or(opts.seed),
            &opts.with,
        )
    });
    if let Some(c) = &course {
        gates.clear();
        goal_m = c.length_m.ceil();
        max_len = max_len.max(32.0);
    }
    // Leader: goal at SPEED after a ramp of SPEED/ACCEL (costs half of it),
    // a taper into the goal (about the same), then 40 s of settled formation
    // (and 10 s for each turn).
    let ramp_s = SPEED_MPS / ACCEL_MPS2;
    let turns = course.as_ref().map_or(0, |c| c.turns_deg.len());
    let duration_s =
        ((goal_m / SPEED_MPS + ramp_s + 40.0 + 10.0 * turns as f64) / 10.0).ceil() * 10.0;
    let memory_max_age_s =
        (((memory_behind_m + max_len + 20.0) / SPEED_MPS * 1.5).max(60.0)).ceil();

    Ok(Plan {
        opts: opts.clone(),
        name,
        lattice,
        members,
        displacements,
        assigned_for_m,
        depth_m,
        shift_up_m,
        shift_down_m,
        gates,
        goal_m,
        duration_s,
        memory_behind_m,
        memory_max_age_s,
        course,
        half_gap_m,
        outer_m,
    })
}

/// Generates the scenario TOML for `opts`: deterministic, and accepted by
/// `shoal check`.
pub fn generate(opts: &GenOptions) -> Result<String, GenError> {
    text(&plan(opts)?)
}

/// The scenario TOML of a plan.
pub fn text(p: &Plan) -> Result<String, GenError> {
    render(p).map_err(|e| GenError::Internal(format!("formatting: {e}")))
}
