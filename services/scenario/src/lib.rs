//! The scenario file: what a run is made of, parsed from TOML with serde,
//! unknown keys refused, and validated before anything starts.
//!
//! The scenario owns the run's shape — vehicles and their formation tree,
//! rates, safety distance, recording — and carries each service library's
//! own section (`[plant]`, `[camera]`, `[sonar]`, `[mpc]`, ...) as a TOML
//! table that the service parses into its own typed config with
//! [`Scenario::section`]. `shoal check` parses every section, so a bad key
//! anywhere is refused before a process is spawned.
//!
//! **Frames.** Slots are `[x forward, y starboard, z down]` in the parent's
//! body frame (Fossen's FRD). The paper draws its formation with y to the
//! left: its `(x̃, ỹ)` is our `(x, −y)`. Positions are NED, m.
//!
//! ```
//! let text = r#"
//! name = "two"
//! duration_s = 10.0
//! [[vehicles]]
//! name = "L"
//! [[vehicles]]
//! name = "F1"
//! parent = "L"
//! slot_m = [-8.0, -4.0, 0.0]
//! "#;
//! let s = shoal_scenario::Scenario::from_toml(text).unwrap();
//! assert_eq!(s.leader().name, "L");
//! assert_eq!(s.processes().len(), 4 + 5 + 2);
//! ```

pub mod faults;
pub mod ranges;
pub mod replace;

use std::collections::{BTreeMap, HashMap};

use serde::{Deserialize, Serialize};

/// The paper scenario, embedded so `shoal run` works with no file.
pub const PAPER_TOML: &str = include_str!("../../../scenarios/paper.toml");

/// Why a scenario is refused. Each message names the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    /// An error that names nothing in a file (serialising, a missing
    /// embedded scenario).
    #[error("{0}")]
    Parse(String),
    /// The scenario file could not be read.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The file.
        path: String,
        /// The system's reason.
        reason: String,
    },
    /// A value out of range or inconsistent; `key` names it.
    #[error("{key}: {reason}")]
    Invalid {
        /// The offending key, e.g. `vehicles[2].parent`.
        key: String,
        /// What is wrong with it.
        reason: String,
    },
    /// An error placed in the file, as a compiler places one:
    /// `scenario.toml:12: follower.memory_behnd_m: unknown key; did you
    /// mean `memory_behind_m`?`.
    #[error("{}", place(file, *line, key.as_deref(), reason))]
    At {
        /// The file (empty for text that came from no file).
        file: String,
        /// 1-based line, when one can be named.
        line: Option<usize>,
        /// The dotted key, when one can be named.
        key: Option<String>,
        /// What is wrong.
        reason: String,
    },
}

fn place(file: &str, line: Option<usize>, key: Option<&str>, reason: &str) -> String {
    let mut out = match (file.is_empty(), line) {
        (false, Some(l)) => format!("{file}:{l}: "),
        (false, None) => format!("{file}: "),
        (true, Some(l)) => format!("line {l}: "),
        (true, None) => String::new(),
    };
    if let Some(k) = key {
        out.push_str(k);
        out.push_str(": ");
    }
    out.push_str(reason);
    out
}

impl ScenarioError {
    /// The error placed in `file`, whose text is `text`: the line of the key
    /// it names is found, and the file is named.
    #[must_use]
    pub fn located(self, file: &str, text: &str) -> Self {
        match self {
            Self::Invalid { key, reason } => Self::At {
                file: file.to_string(),
                line: line_of(text, &key),
                key: Some(key),
                reason,
            },
            Self::At {
                line, key, reason, ..
            } => Self::At {
                file: file.to_string(),
                line: line.or_else(|| key.as_deref().and_then(|k| line_of(text, k))),
                key,
                reason,
            },
            other => other,
        }
    }
}

/// The reason of serde's "unknown field `x`, expected one of `a`, `b`" as
/// a person wants it: the nearest known key (Jaro-Winkler similarity of at
/// least 0.8, from `strsim`) as "did you mean", else the known keys, a few
/// per line. Other messages pass through.
pub fn explain_unknown_key(msg: &str) -> String {
    let Some(rest) = msg
        .strip_prefix("unknown field `")
        .or_else(|| msg.strip_prefix("unknown variant `"))
    else {
        return msg.to_string();
    };
    let what = if msg.starts_with("unknown variant") {
        "value"
    } else {
        "key"
    };
    let Some((name, tail)) = rest.split_once('`') else {
        return msg.to_string();
    };
    let known: Vec<&str> = tail
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|k| !k.is_empty())
        .collect();
    let best = known
        .iter()
        .map(|k| (strsim::jaro_winkler(name, k), *k))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    match best {
        Some((score, k)) if score >= 0.8 => {
            format!("unknown {what} `{name}`; did you mean `{k}`?")
        }
        Some(_) => {
            let mut text = format!("unknown {what} `{name}`; the known ones are:");
            for group in known.chunks(6) {
                text.push_str("\n    ");
                text.push_str(&group.join(", "));
            }
            text
        }
        None => format!("unknown {what} `{name}`; none is allowed here"),
    }
}

/// The 1-based line of the key at dotted path `key` (`vehicles[1].slot_m`,
/// `follower.memory_m`, or a table such as `obstacles[2]`), as
/// [`key_at`] names keys; for a key that is not written in the file (a
/// missing one), the line of its table.
pub fn line_of(text: &str, key: &str) -> Option<usize> {
    lines_of(text, key).map(|(exact, table)| exact.unwrap_or(table))
}

/// The 1-based line where the key at dotted path `key` is written; `None`
/// when it is not (no fallback to its table).
pub fn line_of_exact(text: &str, key: &str) -> Option<usize> {
    lines_of(text, key).and_then(|(exact, _)| exact)
}

/// (the key's own line, the line of the nearest table above it).
fn lines_of(text: &str, key: &str) -> Option<(Option<usize>, usize)> {
    // One pass (a key looked up from the top at every line took minutes on
    // a file of 10,000 vehicles).
    let mut walk = PathWalk::default();
    let mut table_line = None;
    for (n, line) in text.split_inclusive('\n').enumerate() {
        let t = line.trim();
        let at = walk.line(line, true);
        if !t.is_empty() && !t.starts_with('#') {
            if let Some(k) = at {
                if k == key {
                    return Some((Some(n + 1), table_line.unwrap_or(n + 1)));
                }
                let is_header = t.starts_with('[');
                if is_header && key.starts_with(&format!("{k}.")) {
                    table_line = Some(n + 1);
                }
            }
        }
    }
    table_line.map(|t| (None, t))
}

/// A number as a person reads it: `7`, `0.5`, `5e-324` (not 324 zeros).
fn short(x: f64) -> String {
    if x != 0.0 && (x.abs() < 1e-4 || x.abs() >= 1e9) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

fn invalid(key: impl Into<String>, reason: impl Into<String>) -> ScenarioError {
    ScenarioError::Invalid {
        key: key.into(),
        reason: reason.into(),
    }
}

/// Keys of the service configs that the processes derive from other
/// settings, with where from: a scenario that sets one is refused, so that
/// nothing a user writes is silently replaced. (The service libraries keep
/// them as parameters, for programs that build a config directly.)
pub const DERIVED_KEYS: [(&str, &str, &str); 15] = [
    ("follower", "view_half_angle_deg", "[camera] fov_deg / 2"),
    (
        "follower",
        "camera_mount_body_m",
        "[camera] mount_position_body_m",
    ),
    (
        "follower",
        "parent_beacons_body_m",
        "[beacons] positions_body_m",
    ),
    ("mpc", "step_s", "the mpc rate, 1 / [rates] mpc_hz"),
    (
        "mpc",
        "thrust_max",
        "the plant's saturation, [plant] thrust_max",
    ),
    ("follower", "slot_in_parent_m", "each follower's own slot_m"),
    ("follower", "d_min_m", "[safety] safe_distance_m"),
    (
        "follower",
        "d_a_m",
        "each follower's own d_a_m (assigned from the formation when absent)",
    ),
    (
        "follower",
        "d_b_m",
        "each follower's own d_b_m (assigned from the formation when absent)",
    ),
    ("mission", "d_min_m", "[safety] safe_distance_m"),
    (
        "camera",
        "rate_hz",
        "the camera-pose rate, [rates] camera_hz",
    ),
    ("sonar", "rate_hz", "the sonar rate, [rates] sonar_hz"),
    ("mpc", "d_min_m", "[safety] safe_distance_m"),
    (
        "mission",
        "sonar_return_spread_deg",
        "[sonar] split_beam and beam_width_deg",
    ),
    (
        "mission",
        "sonar_wedge_deg",
        "[sonar] beams (or multibeam) and beam_width_deg",
    ),
];

/// Rates of every process kind, and the lockstep tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Rates {
    /// Lockstep tick, s. Every rate below must be a whole number of ticks.
    pub tick_s: f64,
    /// sim-plant: how often it applies thrust, integrates and publishes truth and nav, Hz.
    pub plant_hz: f64,
    /// world snapshot, Hz.
    pub world_hz: f64,
    /// camera frames, Hz.
    pub camera_hz: f64,
    /// sonar pings, Hz.
    pub sonar_hz: f64,
    /// planner, Hz.
    pub planner_hz: f64,
    /// predictive controller, Hz (its prediction step is 1 / mpc_hz).
    pub mpc_hz: f64,
    /// recorder drains (realtime mode), Hz.
    pub recorder_hz: f64,
}

impl Default for Rates {
    fn default() -> Self {
        Self {
            tick_s: 0.02,
            plant_hz: 10.0,
            world_hz: 10.0,
            camera_hz: 10.0,
            sonar_hz: 10.0,
            planner_hz: 10.0,
            mpc_hz: 10.0,
            recorder_hz: 10.0,
        }
    }
}

/// Safety limits the run is judged against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Safety {
    /// Safe distance between any two vehicles and D_min of the formation shift, m.
    pub safe_distance_m: f64,
    /// Two hulls closer than this (centre to centre) count as a collision, m.
    pub collision_distance_m: f64,
}

impl Default for Safety {
    fn default() -> Self {
        Self {
            safe_distance_m: 2.0,
            collision_distance_m: 0.8,
        }
    }
}

/// MCAP chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    /// zstd (default).
    Zstd,
    /// lz4.
    Lz4,
    /// none.
    None,
}

/// How the run is recorded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Recording {
    /// Chunk compression.
    pub compression: Compression,
    /// The zstd level when `compression = "zstd"`, 1 (fastest) to 19.
    /// Level 1 compresses a paper run's recording ~1.8x faster than zstd's
    /// default level 3 to within 1 % of its size, and the recorder shares
    /// the run's cores.
    pub zstd_level: u32,
    /// Target chunk size, KiB.
    pub chunk_kib: u64,
    /// The recorder's subscriber buffer per channel (samples).
    pub buffer: usize,
}

impl Default for Recording {
    fn default() -> Self {
        Self {
            compression: Compression::Zstd,
            zstd_level: 1,
            chunk_kib: 1024,
            buffer: 16,
        }
    }
}

/// How followers learn where their parent is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Perception {
    /// The paper's method: the follower's camera sees the parent's beacons.
    Camera,
    /// The baseline the paper argues against: the parent's pose arrives over
    /// a simulated acoustic modem (propagation delay, low bit rate, loss);
    /// see the `[acoustic]` section.
    Acoustic,
}

/// Variants of the method, for comparisons (`shoal compare`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Method {
    /// Where a follower's knowledge of its parent comes from (default camera).
    pub perception: Perception,
    /// Shift followers vertically along eq. (5) while they avoid (default
    /// true). `false` is the ablation D_b = 0: followers in line hide beacons
    /// from the ones behind.
    pub vertical_shift: bool,
    /// The method as generalised beyond the paper (default true): the
    /// leader's shadows, sides, formation window and turn arcs, the
    /// followers' view keeping, keep-clear and search, both planners'
    /// memory cells (`services/planner/README.md`). `false` is the paper's
    /// method as published, for `shoal compare`.
    pub generalised: bool,
}

impl Default for Method {
    fn default() -> Self {
        Self {
            perception: Perception::Camera,
            vertical_shift: true,
            generalised: true,
        }
    }
}

/// One vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSpec {
    /// Unique name, `[A-Za-z0-9_]+`.
    pub name: String,
    /// The vehicle whose beacons this one follows; none for the leader.
    #[serde(default)]
    pub parent: Option<String>,
    /// The slot in the parent's frame, FRD, m (followers only).
    #[serde(default)]
    pub slot_m: Option<[f64; 3]>,
    /// Start position NED, m. Default: the leader at `[0, 0, 10]`, a
    /// follower at its slot behind its parent's start.
    #[serde(default)]
    pub start_ned_m: Option<[f64; 3]>,
    /// Start heading, deg (default: the parent's).
    #[serde(default)]
    pub start_yaw_deg: Option<f64>,
    /// Displacement D_a of eq. (4), m (default: computed from the formation).
    /// The paper's side sign is applied by the planner (a port slot shifts
    /// forward, a starboard one back); a negative value reverses that.
    #[serde(default)]
    pub d_a_m: Option<f64>,
    /// Vertical displacement D_b of eq. (5), m, signed (+ = down) (default: computed).
    #[serde(default)]
    pub d_b_m: Option<f64>,
}

/// The service sections by name (`&` or `&mut` borrow), one list for the
/// shared and the mutable lookup.
macro_rules! section_match {
    ($s:ident, $key:ident, $($borrow:tt)+) => {
        Ok(match $key {
            "mission" => $($borrow)+ $s.mission,
            "plant" => $($borrow)+ $s.plant,
            "nav" => $($borrow)+ $s.nav,
            "camera" => $($borrow)+ $s.camera,
            "beacons" => $($borrow)+ $s.beacons,
            "hull" => $($borrow)+ $s.hull,
            "pose" => $($borrow)+ $s.pose,
            "sonar" => $($borrow)+ $s.sonar,
            "follower" => $($borrow)+ $s.follower,
            "mpc" => $($borrow)+ $s.mpc,
            "acoustic" => $($borrow)+ $s.acoustic,
            "optics" => $($borrow)+ $s.optics,
            "detect" => $($borrow)+ $s.detect,
            other => return Err(invalid(other, "no such section")),
        })
    };
}

/// A whole scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name.
    pub name: String,
    /// What the scenario shows.
    #[serde(default)]
    pub description: String,
    /// Seed of every random generator in the run.
    #[serde(default)]
    pub seed: u64,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Process rates and the lockstep tick.
    #[serde(default)]
    pub rates: Rates,
    /// Safety limits.
    #[serde(default)]
    pub safety: Safety,
    /// Recording options.
    #[serde(default)]
    pub recording: Recording,
    /// Method variant (camera or acoustic baseline, vertical shift on/off).
    #[serde(default)]
    pub method: Method,
    /// The vehicles; exactly one has no parent (the leader).
    pub vehicles: Vec<VehicleSpec>,
    /// Obstacles (`sonar::Obstacle` tables).
    #[serde(default)]
    pub obstacles: Vec<toml::Table>,
    /// The leader's mission (`planner::LeaderConfig`).
    #[serde(default)]
    pub mission: toml::Table,
    /// Vehicle dynamics (`sim_plant::PlantConfig`).
    #[serde(default)]
    pub plant: toml::Table,
    /// Navigation sensors (`sim_plant::nav::NavConfig`).
    #[serde(default)]
    pub nav: toml::Table,
    /// Camera (`camera_pose::CameraConfig`).
    #[serde(default)]
    pub camera: toml::Table,
    /// Beacon layout on every parent (`camera_pose::BeaconLayout`).
    #[serde(default)]
    pub beacons: toml::Table,
    /// Hull shape (`camera_pose::HullConfig`).
    #[serde(default)]
    pub hull: toml::Table,
    /// Pose solver (`camera_pose::PoseConfig`).
    #[serde(default)]
    pub pose: toml::Table,
    /// Rangefinders (`sonar::SonarConfig`).
    #[serde(default)]
    pub sonar: toml::Table,
    /// Follower planner, shared by every follower (`planner::FollowerConfig`).
    #[serde(default)]
    pub follower: toml::Table,
    /// Predictive controller (`mpc::MpcConfig`).
    #[serde(default)]
    pub mpc: toml::Table,
    /// Acoustic modem of the baseline (`camera-pose`'s `AcousticConfig`).
    #[serde(default)]
    pub acoustic: toml::Table,
    /// Water and sensor optics of the rendered camera image (`camera_sim::OpticsConfig`).
    #[serde(default)]
    pub optics: toml::Table,
    /// Beacon detection and identification in the image (`camera_pose::DetectConfig`).
    #[serde(default)]
    pub detect: toml::Table,
    /// What happens when a process dies (`[supervision]`).
    #[serde(default)]
    pub supervision: faults::Supervision,
    /// Faults injected on purpose (`[[faults]]`).
    #[serde(default)]
    pub faults: Vec<faults::Fault>,
    /// Processes run by the user's own command (`[[replace]]`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub replace: Vec<replace::Replace>,
}

/// A process kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProcessKind {
    /// Vehicle dynamics and own navigation sensors.
    SimPlant,
    /// One world snapshot of all vehicles.
    World,
    /// Follower camera: beacon pixels and the parent's pose.
    CameraPose,
    /// Follower camera's image, rendered from the world (`[camera] model = "image"`).
    CameraSim,
    /// Rangefinders.
    Sonar,
    /// Leader guidance or follower formation shift.
    Planner,
    /// Predictive controller.
    Mpc,
    /// MCAP recorder.
    Recorder,
}

impl ProcessKind {
    /// Every kind.
    pub const ALL: [ProcessKind; 8] = [
        ProcessKind::SimPlant,
        ProcessKind::World,
        ProcessKind::CameraPose,
        ProcessKind::CameraSim,
        ProcessKind::Sonar,
        ProcessKind::Planner,
        ProcessKind::Mpc,
        ProcessKind::Recorder,
    ];

    /// Kebab-case name, as in the process table.
    pub const fn name(self) -> &'static str {
        match self {
            ProcessKind::SimPlant => "sim-plant",
            ProcessKind::World => "world",
            ProcessKind::CameraPose => "camera-pose",
            ProcessKind::CameraSim => "camera-sim",
            ProcessKind::Sonar => "sonar",
            ProcessKind::Planner => "planner",
            ProcessKind::Mpc => "mpc",
            ProcessKind::Recorder => "recorder",
        }
    }

    /// The binary that runs this kind.
    pub const fn binary(self) -> &'static str {
        match self {
            ProcessKind::SimPlant => "shoal-sim-plant",
            ProcessKind::World => "shoal-world",
            ProcessKind::CameraPose => "shoal-camera-pose",
            ProcessKind::CameraSim => "shoal-camera-sim",
            ProcessKind::Sonar => "shoal-sonar",
            ProcessKind::Planner => "shoal-planner",
            ProcessKind::Mpc => "shoal-mpc",
            ProcessKind::Recorder => "shoal-recorder",
        }
    }

    /// Parses a kebab-case name.
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }

    /// Pipeline stage within one lockstep frame: plant → world → sensors →
    /// planner → mpc → (plant). The recorder is rung with the plant, and no
    /// tick's end waits for it ([`ProcessKind::detached`]). With
    /// camera images, the camera's renderer takes the sensors' stage and
    /// camera-pose, planner and mpc each move one stage later (six stages).
    pub const fn stage(self, model: CameraModel) -> u64 {
        let late = match model {
            CameraModel::Point => 0,
            CameraModel::Image => 1,
        };
        match self {
            ProcessKind::SimPlant | ProcessKind::Recorder => 0,
            ProcessKind::World => 1,
            ProcessKind::Sonar | ProcessKind::CameraSim => 2,
            ProcessKind::CameraPose => 2 + late,
            ProcessKind::Planner => 3 + late,
            ProcessKind::Mpc => 4 + late,
        }
    }
}

impl ProcessKind {
    /// True for a kind whose lockstep step no other process waits for: the
    /// recorder only drains what was published before its tick and nothing
    /// reads what it writes, so its step need only be over before it is
    /// rung again, and it runs alongside the frame's later stages instead
    /// of holding its own stage open.
    pub const fn detached(self) -> bool {
        matches!(self, ProcessKind::Recorder)
    }
}

/// What the follower's camera gives camera-pose (`[camera] model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CameraModel {
    /// The beacons' pixels projected from ground truth with Gaussian noise
    /// and a visibility cut-off, identities attached (camera-pose simulates
    /// them itself from the world).
    #[default]
    Point,
    /// A rendered 8-bit image of turbid water (the camera-sim process);
    /// camera-pose finds and identifies the beacons in it.
    Image,
}

impl CameraModel {
    /// Stages of one lockstep frame (see [`ProcessKind::stage`]).
    pub const fn stages(self) -> u64 {
        match self {
            CameraModel::Point => 5,
            CameraModel::Image => 6,
        }
    }
}

/// One process of the run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProcessSpec {
    /// Index in the run (its `done` event id).
    pub index: usize,
    /// Kind.
    pub kind: ProcessKind,
    /// Vehicle name, or `run` for run-level processes.
    pub vehicle: String,
    /// Wakes every `divisor` ticks...
    pub divisor: u64,
    /// ...on ticks where `tick % divisor == phase`.
    pub phase: u64,
}

impl ProcessSpec {
    /// True if the process steps on this tick.
    pub fn due(&self, tick: u64) -> bool {
        tick % self.divisor == self.phase
    }
    /// `vehicle/kind`, for messages.
    pub fn label(&self) -> String {
        format!("{}/{}", self.vehicle, self.kind.name())
    }
}

/// The vehicle name of run-level processes.
pub const RUN_VEHICLE: &str = "run";

impl Scenario {
    /// The embedded paper scenario.
    pub fn paper() -> Result<Self, ScenarioError> {
        Self::from_toml(PAPER_TOML)
    }

    /// Parses and validates TOML text. A syntax error, an unknown key or a
    /// value of the wrong type is reported with the key's full path
    /// (`vehicles[1].slot_m`) and its line.
    pub fn from_toml(text: &str) -> Result<Self, ScenarioError> {
        if text.len() > MAX_SCENARIO_BYTES {
            return Err(ScenarioError::Parse(format!(
                "the scenario is {}, more than a scenario may be ({})",
                mib(text.len() as u64),
                mib(MAX_SCENARIO_BYTES as u64)
            )));
        }
        let s: Scenario = toml::from_str(text).map_err(|e| parse_error("", text, &e))?;
        s.validate()?;
        Ok(s)
    }

    /// Serialises back to TOML (the resolved scenario a run writes down).
    pub fn to_toml(&self) -> Result<String, ScenarioError> {
        toml::to_string(self).map_err(|e| ScenarioError::Parse(e.to_string()))
    }

    /// Parses one service section into that service's typed config.
    pub fn section<T: serde::de::DeserializeOwned>(&self, key: &str) -> Result<T, ScenarioError> {
        from_table(key, self.section_table(key)?)
    }

    /// The raw table of one service section.
    fn section_table(&self, key: &str) -> Result<&toml::Table, ScenarioError> {
        section_match!(self, key, &)
    }

    /// The raw table of one service section, to change.
    pub fn section_table_mut(&mut self, key: &str) -> Result<&mut toml::Table, ScenarioError> {
        section_match!(self, key, &mut)
    }

    /// Parses the obstacle list into the sonar's obstacle type.
    pub fn obstacles_as<T: serde::de::DeserializeOwned>(&self) -> Result<Vec<T>, ScenarioError> {
        self.obstacles
            .iter()
            .enumerate()
            .map(|(i, t)| from_table(&format!("obstacles[{i}]"), t))
            .collect()
    }

    /// Checks the scenario's own keys: names, the formation tree, sizes,
    /// rates, and that no section sets a key the orchestrator derives
    /// ([`DERIVED_KEYS`]).
    pub fn validate(&self) -> Result<(), ScenarioError> {
        // The counts first: nothing that grows with them runs before.
        self.validate_sizes()?;
        faults::validate(self)?;
        replace::validate(self)?;
        for (section, key, from) in DERIVED_KEYS {
            if self.section_table(section)?.contains_key(key) {
                return Err(invalid(
                    format!("{section}.{key}"),
                    format!(
                        "is not a setting: each process derives it from {from}; set that instead"
                    ),
                ));
            }
        }
        // The leader's position filter takes the nav sensor's noise when
        // the scenario gives one: of two values for one thing, one would go unused.
        if self.mission.contains_key("position_fix_noise_m")
            && self.nav.contains_key("position_noise_m")
        {
            return Err(invalid(
                "mission.position_fix_noise_m",
                "the leader's filter takes [nav] position_noise_m when that is set; set one of the two",
            ));
        }
        // The name becomes a directory name (`runs/<name>-<time>`): no paths.
        if self.name.is_empty()
            || self.name.len() > MAX_NAME_LEN
            || self.name.starts_with('.')
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
        {
            return Err(invalid(
                "name",
                format!(
                    "`{}` must be 1 to {MAX_NAME_LEN} of [A-Za-z0-9_.-], not starting with `.`",
                    self.name
                ),
            ));
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Err(invalid(
                "duration_s",
                format!("must be > 0, got {}", self.duration_s),
            ));
        }
        if self.duration_s > MAX_DURATION_S {
            return Err(invalid(
                "duration_s",
                format!(
                    "must be at most {MAX_DURATION_S} s (a year), got {}",
                    self.duration_s
                ),
            ));
        }
        let r = &self.rates;
        if !(r.tick_s.is_finite() && r.tick_s > 0.0 && r.tick_s <= 1.0) {
            return Err(invalid(
                "rates.tick_s",
                format!("must be in (0, 1] s, got {}", r.tick_s),
            ));
        }
        for (key, hz) in [
            ("rates.plant_hz", r.plant_hz),
            ("rates.world_hz", r.world_hz),
            ("rates.camera_hz", r.camera_hz),
            ("rates.sonar_hz", r.sonar_hz),
            ("rates.planner_hz", r.planner_hz),
            ("rates.mpc_hz", r.mpc_hz),
            ("rates.recorder_hz", r.recorder_hz),
        ] {
            if !(hz.is_finite() && hz > 0.0) {
                return Err(invalid(key, format!("must be > 0 Hz, got {hz}")));
            }
            let ticks = 1.0 / (hz * r.tick_s);
            if !ticks.is_finite() || ticks < 0.999 || (ticks - ticks.round()).abs() > 1e-6 {
                return Err(invalid(
                    key,
                    format!(
                        "{} Hz is not a whole number of {} s ticks (period/tick = {ticks:.4})",
                        short(hz),
                        r.tick_s
                    ),
                ));
            }
        }
        let model = self.camera_model();
        if let Some(m) = self.camera.get("model") {
            if !matches!(m.as_str(), Some("point" | "image")) {
                return Err(invalid(
                    "camera.model",
                    format!("must be \"point\" or \"image\", got {m}"),
                ));
            }
        }
        for (key, hz) in [
            ("rates.camera_hz", r.camera_hz),
            ("rates.planner_hz", r.planner_hz),
            ("rates.mpc_hz", r.mpc_hz),
        ] {
            let ticks = self.divisor(hz);
            if ticks < model.stages() && ticks > 1 {
                return Err(invalid(
                    key,
                    format!(
                        "{} Hz is {ticks} ticks of {} s, but a frame needs {} stages with camera {} \
                         (one tick each): make [rates] tick_s at most {}",
                        short(hz),
                        r.tick_s,
                        model.stages(),
                        if model == CameraModel::Image { "images" } else { "points" },
                        short(1.0 / (hz * model.stages() as f64)),
                    ),
                ));
            }
        }
        let s = &self.safety;
        if !(s.safe_distance_m.is_finite() && s.safe_distance_m > 0.0) {
            return Err(invalid(
                "safety.safe_distance_m",
                format!("must be > 0, got {}", s.safe_distance_m),
            ));
        }
        if !(s.collision_distance_m.is_finite()
            && s.collision_distance_m > 0.0
            && s.collision_distance_m < s.safe_distance_m)
        {
            return Err(invalid(
                "safety.collision_distance_m",
                format!(
                    "must be > 0 and below safety.safe_distance_m, got {}",
                    s.collision_distance_m
                ),
            ));
        }
        if self.recording.buffer == 0 || self.recording.buffer > 1024 {
            return Err(invalid(
                "recording.buffer",
                format!("must be in 1..=1024, got {}", self.recording.buffer),
            ));
        }
        if !(1..=19).contains(&self.recording.zstd_level) {
            return Err(invalid(
                "recording.zstd_level",
                format!("must be in 1..=19, got {}", self.recording.zstd_level),
            ));
        }
        if self.recording.chunk_kib == 0 || self.recording.chunk_kib > 1 << 20 {
            return Err(invalid(
                "recording.chunk_kib",
                format!(
                    "must be in 1..=1048576 KiB, got {}",
                    self.recording.chunk_kib
                ),
            ));
        }
        self.validate_vehicles()
    }

    /// The group's size and every count, against the limits.
    fn validate_sizes(&self) -> Result<(), ScenarioError> {
        if self.vehicles.len() > ipc_types_max_vehicles() {
            return Err(invalid(
                "vehicles",
                format!(
                    "{} vehicles, at most {} fit in the world snapshot",
                    self.vehicles.len(),
                    ipc_types_max_vehicles()
                ),
            ));
        }
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(invalid(
                "obstacles",
                format!(
                    "{} obstacles, at most {MAX_OBSTACLES}",
                    self.obstacles.len()
                ),
            ));
        }
        let count = |key: &str| -> usize {
            self.obstacles
                .iter()
                .filter_map(|o| o.get(key).and_then(toml::Value::as_array))
                .map(Vec::len)
                .sum()
        };
        for (key, n) in [
            ("triangles", count("triangles")),
            ("vertices_ned_m", count("vertices_ned_m")),
        ] {
            if n > MAX_MESH_ELEMENTS {
                return Err(invalid(
                    "obstacles",
                    format!("{n} mesh {key} in all, at most {MAX_MESH_ELEMENTS}"),
                ));
            }
        }
        if self.faults.len() > MAX_FAULTS {
            return Err(invalid(
                "faults",
                format!("{} faults, at most {MAX_FAULTS}", self.faults.len()),
            ));
        }
        Ok(())
    }

    fn validate_vehicles(&self) -> Result<(), ScenarioError> {
        if self.vehicles.is_empty() {
            return Err(invalid("vehicles", "at least one vehicle is needed"));
        }
        // Their number is checked first, in `validate_sizes`.
        let mut index: HashMap<&str, usize> = HashMap::new();
        for (i, v) in self.vehicles.iter().enumerate() {
            let key = format!("vehicles[{i}].name");
            if v.name.is_empty()
                || v.name.len() > MAX_NAME_LEN
                || v.name == RUN_VEHICLE
                || !v
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_')
            {
                return Err(invalid(
                    key,
                    format!(
                        "`{}` must be [A-Za-z0-9_]{{1,{MAX_NAME_LEN}}} and not `{RUN_VEHICLE}`",
                        v.name
                    ),
                ));
            }
            if index.insert(&v.name, i).is_some() {
                return Err(invalid(key, format!("`{}` is used twice", v.name)));
            }
        }
        let leaders: Vec<usize> = (0..self.vehicles.len())
            .filter(|&i| self.vehicles[i].parent.is_none())
            .collect();
        if leaders.len() != 1 {
            let names: Vec<&str> = leaders
                .iter()
                .map(|&i| self.vehicles[i].name.as_str())
                .collect();
            return Err(invalid(
                "vehicles",
                format!(
                    "exactly one vehicle must have no parent (the leader), found {}: {names:?}",
                    leaders.len()
                ),
            ));
        }
        for (i, v) in self.vehicles.iter().enumerate() {
            let check3 = |key: String, a: &[f64; 3]| -> Result<(), ScenarioError> {
                if !a.iter().all(|x| x.is_finite()) {
                    Err(invalid(key, "values must be finite"))
                } else if a.iter().any(|x| x.abs() > MAX_COORD_M) {
                    Err(invalid(
                        key,
                        format!("values must be within ±{MAX_COORD_M} m, got {a:?}"),
                    ))
                } else {
                    Ok(())
                }
            };
            if let Some(p) = &v.parent {
                if !index.contains_key(p.as_str()) {
                    return Err(invalid(
                        format!("vehicles[{i}].parent"),
                        format!("`{p}` is not a vehicle of this scenario"),
                    ));
                }
                if p == &v.name {
                    return Err(invalid(
                        format!("vehicles[{i}].parent"),
                        format!("`{}` cannot follow itself", v.name),
                    ));
                }
                let Some(slot) = &v.slot_m else {
                    return Err(invalid(
                        format!("vehicles[{i}].slot_m"),
                        format!("follower `{}` needs a slot in its parent's frame", v.name),
                    ));
                };
                check3(format!("vehicles[{i}].slot_m"), slot)?;
                let horizontal = (slot[0] * slot[0] + slot[1] * slot[1]).sqrt();
                if horizontal < self.safety.safe_distance_m {
                    return Err(invalid(
                        format!("vehicles[{i}].slot_m"),
                        format!(
                            "slot is {horizontal:.2} m from the parent, closer than safety.safe_distance_m = {}",
                            self.safety.safe_distance_m
                        ),
                    ));
                }
                if slot[0] >= 0.0 {
                    return Err(invalid(
                        format!("vehicles[{i}].slot_m"),
                        "x must be negative: a follower's camera looks forward at its parent",
                    ));
                }
            } else if v.slot_m.is_some() {
                return Err(invalid(
                    format!("vehicles[{i}].slot_m"),
                    "the leader has no slot",
                ));
            }
            if let Some(s) = &v.start_ned_m {
                check3(format!("vehicles[{i}].start_ned_m"), s)?;
            }
            if let Some(y) = v.start_yaw_deg {
                if !(y.is_finite() && y.abs() <= 720.0) {
                    return Err(invalid(
                        format!("vehicles[{i}].start_yaw_deg"),
                        format!("must be finite and within ±720°, got {y}"),
                    ));
                }
            }
            for (key, d) in [("d_a_m", v.d_a_m), ("d_b_m", v.d_b_m)] {
                if let Some(d) = d {
                    if !(d.is_finite() && d.abs() <= MAX_COORD_M) {
                        return Err(invalid(
                            format!("vehicles[{i}].{key}"),
                            format!("must be finite and within ±{MAX_COORD_M} m, got {d}"),
                        ));
                    }
                }
            }
        }
        // Cycles: walk up from every vehicle; a tree reaches the leader in < n steps.
        for (i, v) in self.vehicles.iter().enumerate() {
            let mut seen = vec![v.name.as_str()];
            let mut cur = v;
            while let Some(p) = &cur.parent {
                if seen.contains(&p.as_str()) {
                    seen.push(p);
                    return Err(invalid(
                        format!("vehicles[{i}].parent"),
                        format!("the formation tree has a cycle: {}", seen.join(" -> ")),
                    ));
                }
                seen.push(p);
                cur = &self.vehicles[index[p.as_str()]];
            }
        }
        Ok(())
    }

    /// The leader (the one vehicle with no parent).
    pub fn leader(&self) -> &VehicleSpec {
        // validate() guarantees exactly one.
        self.vehicles
            .iter()
            .find(|v| v.parent.is_none())
            .unwrap_or(&self.vehicles[0])
    }

    /// A vehicle by name.
    pub fn vehicle(&self, name: &str) -> Option<&VehicleSpec> {
        self.vehicles.iter().find(|v| v.name == name)
    }

    /// Index of a vehicle in scenario order (its slot in the world snapshot).
    pub fn vehicle_index(&self, name: &str) -> Option<usize> {
        self.vehicles.iter().position(|v| v.name == name)
    }

    /// Index of the parent of vehicle `index`: `None` for the leader (or a
    /// parent the scenario does not hold, which `validate` refuses).
    pub fn parent_index(&self, index: usize) -> Option<usize> {
        let parent = self.vehicles.get(index)?.parent.as_deref()?;
        self.vehicle_index(parent)
    }

    /// Start position (NED, m) and heading (rad) of every vehicle, resolved:
    /// a follower without an explicit start sits in its slot behind its
    /// parent's start, with the parent's heading.
    pub fn start_poses(&self) -> BTreeMap<String, ([f64; 3], f64)> {
        let mut out: BTreeMap<String, ([f64; 3], f64)> = BTreeMap::new();
        // Resolve in tree order: parents first (validate() rules out cycles).
        let mut pending: Vec<&VehicleSpec> = self.vehicles.iter().collect();
        let mut guard = 0;
        while !pending.is_empty() && guard <= self.vehicles.len() {
            guard += 1;
            pending.retain(|v| {
                let resolved = match &v.parent {
                    None => Some((
                        v.start_ned_m.unwrap_or([0.0, 0.0, 10.0]),
                        v.start_yaw_deg.unwrap_or(0.0).to_radians(),
                    )),
                    Some(p) => out.get(p).map(|&(pp, pyaw)| {
                        let yaw = v.start_yaw_deg.map_or(pyaw, f64::to_radians);
                        let pos = v.start_ned_m.unwrap_or_else(|| {
                            let s = v.slot_m.unwrap_or([0.0; 3]);
                            let (sn, cs) = pyaw.sin_cos();
                            [
                                pp[0] + cs * s[0] - sn * s[1],
                                pp[1] + sn * s[0] + cs * s[1],
                                pp[2] + s[2],
                            ]
                        });
                        (pos, yaw)
                    }),
                };
                match resolved {
                    Some(r) => {
                        out.insert(v.name.clone(), r);
                        false
                    }
                    None => true,
                }
            });
        }
        out
    }

    /// How many lockstep ticks one period of `hz` lasts.
    pub fn divisor(&self, hz: f64) -> u64 {
        (1.0 / (hz * self.rates.tick_s)).round().max(1.0) as u64
    }

    /// True when `stage` runs at the rate of `input`, the kind that feeds
    /// it: in a dataflow run it then steps on `input`'s samples (one per
    /// frame) rather than on its own timer.
    pub fn same_rate(&self, stage: ProcessKind, input: ProcessKind) -> bool {
        self.rate_hz(stage) == self.rate_hz(input)
    }

    /// Rate of a process kind, Hz.
    pub fn rate_hz(&self, kind: ProcessKind) -> f64 {
        let r = &self.rates;
        match kind {
            ProcessKind::SimPlant => r.plant_hz,
            ProcessKind::World => r.world_hz,
            ProcessKind::CameraPose | ProcessKind::CameraSim => r.camera_hz,
            ProcessKind::Sonar => r.sonar_hz,
            ProcessKind::Planner => r.planner_hz,
            ProcessKind::Mpc => r.mpc_hz,
            ProcessKind::Recorder => r.recorder_hz,
        }
    }

    /// Each vehicle's level in the formation tree: 0 for the leader, one
    /// more than its parent's for a follower (a parent that is missing, or a
    /// cycle, which `validate` refuses, stops the count).
    pub fn levels(&self) -> BTreeMap<String, usize> {
        let parent: HashMap<&str, Option<&str>> = self
            .vehicles
            .iter()
            .map(|v| (v.name.as_str(), v.parent.as_deref()))
            .collect();
        self.vehicles
            .iter()
            .map(|v| {
                let mut level = 0;
                let mut cur = v.parent.as_deref();
                while let Some(p) = cur.filter(|_| level < self.vehicles.len()) {
                    level += 1;
                    cur = parent.get(p).copied().flatten();
                }
                (v.name.clone(), level)
            })
            .collect()
    }

    /// How far behind `name` its farthest descendant in the formation tree
    /// starts, along `name`'s heading, m (0 for a vehicle nobody follows): the
    /// length of the arm of the formation that passes an obstacle after it.
    pub fn reach_behind_m(&self, name: &str) -> f64 {
        let starts = self.start_poses();
        let Some(&(me, yaw)) = starts.get(name) else {
            return 0.0;
        };
        let parent: HashMap<&str, Option<&str>> = self
            .vehicles
            .iter()
            .map(|v| (v.name.as_str(), v.parent.as_deref()))
            .collect();
        let (sn, cs) = yaw.sin_cos();
        let mut reach = 0.0f64;
        for v in &self.vehicles {
            let mut cur = v.parent.as_deref();
            let mut hops = 0;
            while let Some(p) = cur.filter(|_| hops < self.vehicles.len()) {
                if p == name {
                    if let Some(&(pv, _)) = starts.get(&v.name) {
                        reach = reach.max(cs * (me[0] - pv[0]) + sn * (me[1] - pv[1]));
                    }
                    break;
                }
                hops += 1;
                cur = parent.get(p).copied().flatten();
            }
        }
        reach
    }

    /// The camera model, `[camera] model` (the point model when absent or
    /// not a known name; `validate` refuses the latter).
    pub fn camera_model(&self) -> CameraModel {
        match self.camera.get("model").and_then(|v| v.as_str()) {
            Some("image") => CameraModel::Image,
            _ => CameraModel::Point,
        }
    }

    /// Every process of the run in a fixed order: world, recorder, then per
    /// vehicle sim-plant, camera-sim (followers, with camera images),
    /// camera-pose (followers only), sonar, planner, mpc.
    pub fn processes(&self) -> Vec<ProcessSpec> {
        let model = self.camera_model();
        let mut out = Vec::new();
        let push = |kind: ProcessKind, vehicle: &str, out: &mut Vec<ProcessSpec>| {
            let divisor = if kind == ProcessKind::Recorder {
                // The recorder drains every frame of the slowest pipeline:
                // with the plant's divisor it sees each frame's samples once.
                self.divisor(self.rates.plant_hz)
            } else {
                self.divisor(self.rate_hz(kind))
            };
            out.push(ProcessSpec {
                index: out.len(),
                kind,
                vehicle: vehicle.to_string(),
                divisor,
                phase: kind.stage(model) % divisor,
            });
        };
        push(ProcessKind::World, RUN_VEHICLE, &mut out);
        push(ProcessKind::Recorder, RUN_VEHICLE, &mut out);
        for v in &self.vehicles {
            push(ProcessKind::SimPlant, &v.name, &mut out);
            if v.parent.is_some() {
                if model == CameraModel::Image {
                    push(ProcessKind::CameraSim, &v.name, &mut out);
                }
                push(ProcessKind::CameraPose, &v.name, &mut out);
            }
            push(ProcessKind::Sonar, &v.name, &mut out);
            push(ProcessKind::Planner, &v.name, &mut out);
            push(ProcessKind::Mpc, &v.name, &mut out);
        }
        out
    }

    /// Number of lockstep ticks in the run.
    pub fn ticks(&self) -> u64 {
        (self.duration_s / self.rates.tick_s).round() as u64
    }
}

/// Most vehicles a scenario may hold: the world snapshot's fixed size
/// (`ipc_types::MAX_VEHICLES`; the orchestrator asserts the two agree).
pub const MAX_VEHICLES: usize = 256;

const fn ipc_types_max_vehicles() -> usize {
    MAX_VEHICLES
}

/// Largest scenario, bytes: far above any course (a generated group of 100
/// with its course is about 50 KiB), small enough that reading and parsing
/// it stays well under a second.
pub const MAX_SCENARIO_BYTES: usize = 4 << 20;

/// Most obstacles a scenario may hold: every sonar beam and camera ray
/// tests each one it cannot rule out.
pub const MAX_OBSTACLES: usize = 4096;

/// Most triangles, and most vertices, over all mesh obstacles.
pub const MAX_MESH_ELEMENTS: usize = 200_000;

/// Most `[[faults]]` entries.
pub const MAX_FAULTS: usize = 1024;

fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / f64::from(1u32 << 20))
}

/// Longest simulated duration, s (a year).
pub const MAX_DURATION_S: f64 = 365.0 * 86400.0;

/// Largest coordinate of a start position, slot or displacement, m (1000 km:
/// beyond it double precision no longer resolves a vehicle's motion, and
/// sums of coordinates could overflow).
pub const MAX_COORD_M: f64 = 1e6;

/// Longest vehicle name (it becomes part of iceoryx2 service names).
pub const MAX_NAME_LEN: usize = 64;

/// Deserialises one section table into `T`, naming the offending key
/// (`camera.fov_deg`) on error. The table is written back to TOML text and
/// parsed from there, so the error carries a span to find the key by.
fn from_table<T: serde::de::DeserializeOwned>(
    section: &str,
    table: &toml::Table,
) -> Result<T, ScenarioError> {
    let text = match toml::to_string(table) {
        Ok(t) => t,
        Err(e) => return Err(invalid(section, e.to_string())),
    };
    let found = |e: &toml::de::Error| {
        let at = e.span().map(|r| r.start);
        if e.message().starts_with("missing field") {
            table_at(&text, at)
        } else {
            key_at(&text, at)
        }
    };
    toml::from_str(&text).map_err(|e| {
        let reason = explain_unknown_key(e.message().trim());
        match found(&e) {
            Some(k) => invalid(format!("{section}.{k}"), reason),
            None => invalid(section, reason),
        }
    })
}

/// A TOML error of the top-level file as a [`ScenarioError::Parse`] naming
/// the key and the line.
fn parse_error(prefix: &str, text: &str, e: &toml::de::Error) -> ScenarioError {
    let start = e.span().map(|r| r.start);
    let line = start.map(|o| text.get(..o).map_or(0, |t| t.matches('\n').count()) + 1);
    let msg = e.message().trim();
    // A missing key is reported on its table, not on whatever key the span starts at.
    let missing = msg.starts_with("missing field");
    let found = if missing {
        table_at(text, start)
    } else {
        key_at(text, start)
    };
    // A missing top-level key has no line worth naming.
    let line = if missing && found.is_none() {
        None
    } else {
        line
    };
    let key = found.map(|k| {
        if prefix.is_empty() {
            k
        } else {
            format!("{prefix}.{k}")
        }
    });
    ScenarioError::At {
        file: String::new(),
        line,
        key,
        reason: explain_unknown_key(msg),
    }
}

/// The dotted path of the key at byte `offset` of a TOML document, found
/// from the table headers above it: `vehicles[1].slot_m` for a key under
/// the second `[[vehicles]]`, `rates` for the `[rates]` header itself.
/// Best effort (multi-line strings that hold `[` at a line start confuse
/// it); `None` when nothing can be named.
pub fn key_at(text: &str, offset: Option<usize>) -> Option<String> {
    path_at(text, offset, true)
}

/// The table (`vehicles[1]`, `camera`) that byte `offset` lies in; `None`
/// at the top level.
pub fn table_at(text: &str, offset: Option<usize>) -> Option<String> {
    path_at(text, offset, false)
}

fn path_at(text: &str, offset: Option<usize>, with_key: bool) -> Option<String> {
    let offset = offset?.min(text.len());
    let mut walk = PathWalk::default();
    let mut pos = 0usize;
    for line in text.split_inclusive('\n') {
        let end = pos + line.len();
        let answer = walk.line(line, with_key);
        if offset >= pos && (offset < end || end == text.len()) {
            return answer;
        }
        pos = end;
    }
    walk.table()
}

/// The table headers read so far, line by line, in one pass: what
/// [`key_at`] and [`table_at`] name at each line's start.
#[derive(Debug, Default)]
struct PathWalk {
    /// The current table (`vehicles[1]`, `camera`), or empty at the top level.
    header: String,
    /// Elements of each array of tables so far.
    counts: HashMap<String, usize>,
    /// Brackets a value left open (an array over several lines), and its key.
    depth: i32,
    open_key: Option<String>,
}

impl PathWalk {
    /// The current table, if any.
    fn table(&self) -> Option<String> {
        (!self.header.is_empty()).then(|| self.header.clone())
    }

    fn under(&self, k: String) -> String {
        if self.header.is_empty() {
            k
        } else {
            format!("{}.{k}", self.header)
        }
    }

    /// Reads the next line; returns the path at its start (the key with
    /// `with_key`, else its table).
    fn line(&mut self, line: &str, with_key: bool) -> Option<String> {
        let t = line.trim();
        if self.depth > 0 {
            // A continuation of the open value: its key's line, not a header.
            let answer = if with_key {
                self.open_key.clone()
            } else {
                self.table()
            };
            self.depth += bracket_delta(t);
            return answer;
        }
        if let Some(inner) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
            let name = clean_key(inner);
            let n = self.counts.entry(name.clone()).or_insert(0);
            self.header = format!("{name}[{n}]");
            *n += 1;
            return Some(self.header.clone());
        }
        if let Some(inner) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
            self.header = clean_key(inner);
            // `[vehicles.x]` under an array of tables belongs to its last element.
            if let Some((first, rest)) = self.header.split_once('.') {
                if let Some(n) = self.counts.get(first) {
                    self.header = format!("{first}[{}].{rest}", n.saturating_sub(1));
                }
            }
            return Some(self.header.clone());
        }
        let kv = (!t.starts_with('#'))
            .then(|| t.split_once('='))
            .flatten()
            .map(|(k, v)| (clean_key(k), v));
        let answer = match (&kv, with_key) {
            (Some((k, _)), true) if !k.is_empty() => Some(self.under(k.clone())),
            _ => self.table(),
        };
        if let Some((k, v)) = kv {
            let d = bracket_delta(v);
            if d > 0 {
                self.depth = d;
                self.open_key = Some(self.under(k));
            }
        }
        answer
    }
}

/// Opening minus closing brackets of a TOML value's text, outside strings
/// and before a comment.
fn bracket_delta(v: &str) -> i32 {
    let mut d = 0;
    let mut quote: Option<char> = None;
    let mut escaped = false;
    for c in v.chars() {
        match quote {
            Some(q) => {
                if escaped {
                    escaped = false;
                } else if c == '\\' && q == '"' {
                    escaped = true;
                } else if c == q {
                    quote = None;
                }
            }
            None => match c {
                '"' | '\'' => quote = Some(c),
                '#' => break,
                '[' => d += 1,
                ']' => d -= 1,
                _ => {}
            },
        }
    }
    d
}

fn clean_key(k: &str) -> String {
    k.split('.')
        .map(|p| {
            p.trim()
                .trim_matches(|c| c == '[' || c == ']')
                .trim_matches('"')
                .trim_matches('\'')
        })
        .collect::<Vec<_>>()
        .join(".")
}

impl Scenario {
    /// Reads and validates a scenario file.
    /// Every error is placed in the file ([`ScenarioError::located`]).
    pub fn from_file(path: &std::path::Path) -> Result<Self, ScenarioError> {
        Self::read_file(path).map(|(s, _)| s)
    }

    /// [`Scenario::from_file`], with the text it was read from (to place
    /// the errors of later checks in the same text).
    pub fn read_file(path: &std::path::Path) -> Result<(Self, String), ScenarioError> {
        let file = path.display().to_string();
        let read_error = |reason: String| ScenarioError::Read {
            path: file.clone(),
            reason,
        };
        // The size first, and never more than the limit read (a pipe or a
        // growing file has no size to ask).
        let f = std::fs::File::open(path).map_err(|e| read_error(e.to_string()))?;
        let too_big = |n: u64| {
            read_error(format!(
                "it is {}, more than a scenario may be ({})",
                mib(n),
                mib(MAX_SCENARIO_BYTES as u64)
            ))
        };
        if let Ok(m) = f.metadata() {
            if m.is_file() && m.len() > MAX_SCENARIO_BYTES as u64 {
                return Err(too_big(m.len()));
            }
        }
        let mut text = String::new();
        std::io::Read::read_to_string(
            &mut std::io::Read::take(f, MAX_SCENARIO_BYTES as u64 + 1),
            &mut text,
        )
        .map_err(|e| read_error(e.to_string()))?;
        if text.len() > MAX_SCENARIO_BYTES {
            return Err(too_big(text.len() as u64));
        }
        let s = Self::from_toml(&text).map_err(|e| e.located(&file, &text))?;
        Ok((s, text))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_fault_key_its_action_ignores_or_a_fault_after_the_end_is_refused() {
        let base = "name = \"t\"\nduration_s = 10.0\n[[vehicles]]\nname = \"L\"\n[[vehicles]]\nname = \"F1\"\nparent = \"L\"\nslot_m = [-8.0, -4.0, 0.0]\n";
        let with = |fault: &str| Scenario::from_toml(&format!("{base}[[faults]]\n{fault}"));
        let e = with(
            "action = \"kill\"\nvehicle = \"F1\"\nprocess = \"mpc\"\nat_s = 2.0\nfraction = 0.5\n",
        )
        .unwrap_err()
        .to_string();
        assert_eq!(e, "faults[0].fraction: is not used by a `kill` fault");
        let e = with("action = \"blind\"\nvehicle = \"F1\"\nfrom_s = 12.0\nto_s = 13.0\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("faults[0].from_s: 12 s is after the run's end"),
            "{e}"
        );
        assert!(with("action = \"blind\"\nvehicle = \"F1\"\nfrom_s = 2.0\nto_s = 3.0\n").is_ok());
    }

    #[test]
    fn an_unknown_key_gets_the_nearest_known_one_or_the_list() {
        let near = explain_unknown_key(
            "unknown field `memory_behnd_m`, expected one of `memory_behind_m`, `memory_max_age_s`",
        );
        assert_eq!(
            near,
            "unknown key `memory_behnd_m`; did you mean `memory_behind_m`?"
        );
        let far = explain_unknown_key(
            "unknown field `lidar_hz`, expected one of `tick_s`, `plant_hz`, `a`, `b`, `c`, `d`, `e`",
        );
        assert!(
            far.starts_with("unknown key `lidar_hz`; the known ones are:\n    tick_s, plant_hz")
        );
        assert_eq!(far.lines().count(), 3, "six per line: {far}");
        assert_eq!(
            explain_unknown_key("unknown variant `gzip`, expected one of `zstd`, `lz4`, `none`")
                .lines()
                .next(),
            Some("unknown value `gzip`; the known ones are:")
        );
        assert_eq!(explain_unknown_key("duplicate key"), "duplicate key");
    }

    #[test]
    fn a_key_is_found_on_its_line_and_a_missing_one_on_its_tables() {
        let text = "name = \"t\"\n\n[[vehicles]]\nname = \"L\"\n[[vehicles]]\n  parent = \"L\"\n[follower]\n# memory_m = 1\nmemory_m = 2\n";
        assert_eq!(line_of(text, "name"), Some(1));
        assert_eq!(line_of(text, "vehicles[1].parent"), Some(6));
        assert_eq!(line_of(text, "follower.memory_m"), Some(9));
        assert_eq!(line_of(text, "follower.other"), Some(7));
        assert_eq!(line_of_exact(text, "follower.other"), None);
        assert_eq!(line_of(text, "nowhere"), None);
        let e = invalid("vehicles[1].parent", "bad").located("s.toml", text);
        assert_eq!(e.to_string(), "s.toml:6: vehicles[1].parent: bad");
    }

    #[test]
    fn a_multi_line_array_is_one_key_not_a_header() {
        let text = "[mission]\nwaypoints_ned_m = [\n  [100.0, 0.0, 10.0],\n  [200.0, 0.0, 10.0], # \"]\"\n]\nspeed_mps = 30.0\n";
        assert_eq!(line_of(text, "mission.speed_mps"), Some(6));
        assert_eq!(line_of(text, "mission.waypoints_ned_m"), Some(2));
        assert_eq!(
            key_at(text, text.find("[200").map(|o| o + 1)),
            Some("mission.waypoints_ned_m".into())
        );
    }

    #[test]
    fn a_file_that_is_not_there_is_said_once() {
        let e = Scenario::from_file(std::path::Path::new("/nonexistent/x.toml")).unwrap_err();
        let text = e.to_string();
        assert_eq!(text.matches("cannot read").count(), 1, "{text}");
        assert!(
            text.starts_with("cannot read /nonexistent/x.toml: "),
            "{text}"
        );
    }

    const BASE: &str = r#"
name = "t"
duration_s = 10.0
[[vehicles]]
name = "L"
[[vehicles]]
name = "F1"
parent = "L"
slot_m = [-8.0, -4.0, 0.0]
[[vehicles]]
name = "F3"
parent = "F1"
slot_m = [-8.0, -4.0, 0.0]
"#;

    #[test]
    fn levels_count_the_parents_up_to_the_leader() {
        let s = Scenario::from_toml(BASE).unwrap();
        let levels = s.levels();
        assert_eq!(levels["L"], 0);
        assert_eq!(levels["F1"], 1);
        assert_eq!(levels["F3"], 2);
        assert_eq!(levels.len(), 3);
    }

    fn err_of(text: &str) -> String {
        Scenario::from_toml(text).unwrap_err().to_string()
    }

    #[test]
    fn paper_scenario_parses() {
        let s = Scenario::paper().unwrap();
        assert_eq!(s.vehicles.len(), 5);
        assert_eq!(s.leader().name, "L");
        // 2 run-level + 5 vehicles × 4 + 4 cameras
        assert_eq!(s.processes().len(), 2 + 5 * 4 + 4);
    }

    #[test]
    fn unknown_key_is_named() {
        let e = err_of(&format!("{BASE}\nspeed = 3\n"));
        assert!(e.contains("speed"), "{e}");
        let e = err_of(&BASE.replace(
            "slot_m = [-8.0, -4.0, 0.0]\n[[vehicles]]\nname = \"F3\"",
            "slot_m = [-8.0, -4.0, 0.0]\nslott = 1\n[[vehicles]]\nname = \"F3\"",
        ));
        assert!(e.contains("slott"), "{e}");
    }

    #[test]
    fn missing_parent_is_named() {
        let e = err_of(&BASE.replace("parent = \"F1\"", "parent = \"F9\""));
        assert!(e.contains("vehicles[2].parent") && e.contains("F9"), "{e}");
    }

    #[test]
    fn cycle_is_named() {
        let text = BASE.replace(
            "name = \"F1\"\nparent = \"L\"",
            "name = \"F1\"\nparent = \"F3\"",
        );
        // now F1 -> F3 -> F1 and L alone
        let e = err_of(&text);
        assert!(e.contains("cycle"), "{e}");
    }

    #[test]
    fn negative_size_is_named() {
        let e = err_of(&format!("{BASE}\n[safety]\nsafe_distance_m = -1.0\n"));
        assert!(e.contains("safety.safe_distance_m"), "{e}");
        let e = err_of(&BASE.replace("duration_s = 10.0", "duration_s = -5.0"));
        assert!(e.contains("duration_s"), "{e}");
    }

    #[test]
    fn a_zstd_level_out_of_range_is_named() {
        for bad in [0, 20] {
            let e = err_of(&format!("{BASE}\n[recording]\nzstd_level = {bad}\n"));
            assert!(e.contains("recording.zstd_level"), "{e}");
        }
        let ok = Scenario::from_toml(&format!("{BASE}\n[recording]\nzstd_level = 19\n"));
        assert_eq!(ok.unwrap().recording.zstd_level, 19);
    }

    #[test]
    fn rates_must_fit_the_tick() {
        let e = err_of(&format!("{BASE}\n[rates]\ncamera_hz = 7.0\n"));
        assert!(e.contains("rates.camera_hz"), "{e}");
    }

    #[test]
    fn followers_start_in_their_slots() {
        let s = Scenario::from_toml(BASE).unwrap();
        let p = s.start_poses();
        let f3 = p["F3"].0;
        assert!((f3[0] + 16.0).abs() < 1e-12 && (f3[1] + 8.0).abs() < 1e-12);
    }

    #[test]
    fn schedule_is_a_pipeline() {
        let s = Scenario::from_toml(BASE).unwrap();
        let procs = s.processes();
        let plant = procs
            .iter()
            .find(|p| p.kind == ProcessKind::SimPlant)
            .unwrap();
        let mpc = procs.iter().find(|p| p.kind == ProcessKind::Mpc).unwrap();
        assert_eq!(plant.divisor, 5);
        assert!(plant.due(0) && plant.due(5) && !plant.due(4));
        assert!(mpc.due(4));
    }

    proptest! {
        #[test]
        fn parser_never_panics(text in ".{0,400}") {
            let _ = Scenario::from_toml(&text);
        }

        #[test]
        fn mutated_scenarios_never_panic(cut in 0usize..400, insert in "[\\[\\]=\"a-z0-9 .\\-\n]{0,12}") {
            let mut t = BASE.to_string();
            let at = cut.min(t.len());
            if t.is_char_boundary(at) {
                t.insert_str(at, &insert);
            }
            let _ = Scenario::from_toml(&t);
        }
    }
}
