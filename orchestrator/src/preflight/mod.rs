//! Pre-flight (`shoal check`, and every run before it starts): every section of a scenario parsed into its service's
//! typed config and validated, the start checked (no vehicle inside an
//! obstacle or too close to another, every camera sees its parent), the
//! formation's displacement trajectories (D_a, D_b) assigned and checked,
//! and what the run needs from the machine ([`resources::needs`]) compared
//! with what it has ([`resources::fits`]), before anything starts.

pub mod resources;

pub use resources::{fits, needs};

use std::collections::BTreeMap;

use anyhow::Context;
use camera_pose::{BeaconStatus, Camera, Capsule};
use nalgebra::{Isometry3, Vector3};
use planner::formation::{FollowerSlot, FormationParams};
use shoal_scenario::{Perception, Scenario};

// The scenario crate cannot see ipc-types; the two limits must agree.
const _: () = assert!(shoal_scenario::MAX_VEHICLES == ipc_types::MAX_VEHICLES);

/// The scenario at `path`, or the embedded paper scenario. A file is
/// checked whole here ([`resolve`], on a copy), so that every error, in a
/// service's section as much as at the top, is placed in the file:
/// `FILE:LINE: KEY: reason`.
pub fn load_scenario(path: &Option<std::path::PathBuf>) -> anyhow::Result<Scenario> {
    load_scenario_with(path, |_| {})
}

/// [`load_scenario`] with `adjust` (the command line's `--seed`,
/// `--duration`) applied before the whole check, so that the check sees
/// the scenario that will run.
pub fn load_scenario_with(
    path: &Option<std::path::PathBuf>,
    adjust: impl Fn(&mut Scenario),
) -> anyhow::Result<Scenario> {
    let Some(p) = path else {
        let mut s = Scenario::paper().context("the embedded paper scenario is invalid")?;
        adjust(&mut s);
        return Ok(s);
    };
    // Read once: the lines an error names are those of the text checked.
    let (mut s, text) = Scenario::read_file(p)?;
    let file = p.display().to_string();
    adjust(&mut s);
    let mut probe = s.clone();
    match resolve(&mut probe) {
        Ok(()) => Ok(s),
        Err(e) => Err(place_error(e, &file, &text)),
    }
}

/// An error of [`resolve`] placed in the scenario file: a
/// [`shoal_scenario::ScenarioError`] by its key; any other by the first
/// dotted key its message starts with (`plant: vehicle.mass_kg: …` is
/// `plant.vehicle.mass_kg`), when that key is written in the file.
fn place_error(e: anyhow::Error, file: &str, text: &str) -> anyhow::Error {
    if let Some(se) = e.downcast_ref::<shoal_scenario::ScenarioError>() {
        return se.clone().located(file, text).into();
    }
    let msg = format!("{e:#}");
    let is_key = |t: &str| {
        !t.is_empty()
            && t.chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || "_.[]".contains(c))
    };
    // `section: key reason` or `section: key: reason`: the first word of
    // each of the first two parts, tried as a key alone and joined.
    let mut rest = msg.as_str();
    let mut words = Vec::new();
    for _ in 0..2 {
        let word = rest.split([' ', ':']).next().unwrap_or("");
        if !is_key(word) {
            break;
        }
        rest = rest[word.len()..].trim_start_matches(':').trim_start();
        words.push((word, rest));
    }
    // (key, the reason after it, whether its table's line will do).
    let mut candidates = Vec::new();
    if let [(w0, _), (w1, after)] = words[..] {
        if w1.contains('.') {
            candidates.push((w1.to_string(), after, false));
        }
        candidates.push((format!("{w0}.{w1}"), after, false));
    }
    if let Some(&(w0, after)) = words.first() {
        candidates.push((w0.to_string(), after, true));
    }
    for (key, reason, table_will_do) in candidates {
        let line = if table_will_do {
            shoal_scenario::line_of(text, &key)
        } else {
            shoal_scenario::line_of_exact(text, &key)
        };
        if let Some(line) = line {
            return shoal_scenario::ScenarioError::At {
                file: file.to_string(),
                line: Some(line),
                key: Some(key),
                reason: reason.to_string(),
            }
            .into();
        }
    }
    e.context(format!("{file}: scenario refused"))
}

/// Validates the whole scenario and fills in every follower's D_a and D_b
/// (those the file leaves out are assigned from the formation); the error
/// names the key, or the pair of vehicles that cannot be kept apart.
pub fn resolve(s: &mut Scenario) -> anyhow::Result<()> {
    s.validate()?;
    // Parsed whatever the perception mode (the acoustic section too), so a
    // bad key is never silent.
    let sec = Sections::parse(s)?;
    sec.plant.validate().context("plant")?;
    sec.nav.validate().context("nav")?;
    sec.sonar.validate().context("sonar")?;
    let obstacles: Vec<sonar::Obstacle> = s.obstacles_as()?;
    for (i, o) in obstacles.iter().enumerate() {
        o.validate().with_context(|| format!("obstacles[{i}]"))?;
    }
    let (camera, beacons, hull, pose) = (&sec.camera, &sec.beacons, &sec.hull, &sec.pose);
    camera.validate().context("camera")?;
    beacons.validate().context("beacons")?;
    hull.validate().context("hull")?;
    pose.validate().context("pose")?;
    camera_pose::PoseEstimator::new(pose, camera, beacons).context("pose")?;
    sec.mission.validate().context("mission")?;
    sec.follower.validate().context("follower")?;
    sec.mpc.validate().context("mpc")?;
    sec.acoustic.validate().map_err(anyhow::Error::msg)?;
    sec.detect.validate().context("detect")?;
    sec.optics.validate().context("optics")?;
    if s.camera_model() == shoal_scenario::CameraModel::Image {
        // The visibility the optics must produce (the renderer derives the
        // water's attenuation from it) and the image's size.
        camera_sim::Renderer::new(camera, beacons, hull, &sec.optics).context("optics")?;
    }
    // Every number within its physical range, defaults included (the seed,
    // any u64, is no measure; a TOML table holds only i64).
    let mut measured = sec.fill(s)?;
    measured.seed = 0;
    shoal_scenario::ranges::check(&toml::Table::try_from(&measured)?)?;
    let field = sonar::ObstacleField::new(&obstacles).context("obstacles")?;
    check_start(s, &field, camera, beacons, hull, pose)?;

    let slots: Vec<FollowerSlot> = s
        .vehicles
        .iter()
        .filter_map(|v| {
            Some(FollowerSlot {
                name: v.name.clone(),
                parent: v.parent.clone()?,
                slot_in_parent_m: v.slot_m?,
            })
        })
        .collect();
    let params = FormationParams {
        visibility_range_m: camera.visibility_range_m,
        ..Default::default()
    };
    let d_min = s.safety.safe_distance_m;
    let leader = s.leader().name.clone();
    // a search only where the scenario leaves some D_a/D_b out: given ones
    // are verified below as they are (a search may fail where a file's own
    // assignment, from a longer search or by hand, is safe)
    let given = s
        .vehicles
        .iter()
        .filter(|v| v.parent.is_some())
        .all(|v| v.d_a_m.is_some() && v.d_b_m.is_some());
    let assigned = if given {
        vec![(0.0, 0.0); slots.len()]
    } else {
        planner::formation::assign_displacements(&leader, &slots, d_min, &params).context(
            "formation: no displacement trajectories keep every pair apart and every parent in sight",
        )?
    };
    let s_method_vertical = s.method.vertical_shift;
    let mut chosen = Vec::with_capacity(slots.len());
    for (slot, (d_a, d_b)) in slots.iter().zip(assigned) {
        let v = s
            .vehicles
            .iter_mut()
            .find(|v| v.name == slot.name)
            .context("follower vanished")?;
        let mut d = (v.d_a_m.unwrap_or(d_a), v.d_b_m.unwrap_or(d_b));
        if !s_method_vertical {
            // The ablation: no vertical displacement (eq. 5 with D_b = 0).
            d.1 = 0.0;
        }
        v.d_a_m = Some(d.0);
        v.d_b_m = Some(d.1);
        chosen.push(d);
    }
    // The ablation (no vertical shift) is by design a formation the check
    // refuses: it is run to measure what that costs.
    if s_method_vertical {
        planner::formation::check(&leader, &slots, &chosen, d_min, &params).context(
            "formation: the given D_a/D_b do not keep every pair apart and every parent in sight",
        )?;
    }
    fits(&needs(s))?;
    Ok(())
}

/// The scenario as every process runs it, as TOML: a resolved scenario
/// (D_a/D_b assigned) whose service sections hold every key of their typed
/// config, defaults filled in (`[camera]`'s intrinsics, `[beacons]`'
/// layout, `[pose]`, …), so that a reader of the recording gets them back.
/// Keys each process derives from other sections ([`DERIVED_KEYS`]) are
/// left out (the sections they come from are there); so is whichever of
/// `[nav] position_noise_m` and `[mission] position_fix_noise_m` the
/// scenario left out, since the leader's filter takes the first when it is
/// set. The text loads as a scenario that runs the same.
///
/// [`DERIVED_KEYS`]: shoal_scenario::DERIVED_KEYS
pub fn effective_toml(s: &Scenario) -> anyhow::Result<String> {
    Ok(effective(s)?.to_toml()?)
}

/// [`effective_toml`]'s scenario.
pub fn effective(s: &Scenario) -> anyhow::Result<Scenario> {
    Sections::parse(s)?.fill(s)
}

/// Every service section of a scenario, parsed into its service's typed
/// config (defaults filled in).
struct Sections {
    plant: sim_plant::PlantConfig,
    nav: sim_plant::nav::NavConfig,
    sonar: sonar::SonarConfig,
    camera: camera_pose::CameraConfig,
    beacons: camera_pose::BeaconLayout,
    hull: camera_pose::HullConfig,
    pose: camera_pose::PoseConfig,
    mission: planner::LeaderConfig,
    follower: planner::FollowerConfig,
    mpc: mpc::MpcConfig,
    acoustic: camera_pose::acoustic::AcousticConfig,
    optics: camera_sim::OpticsConfig,
    detect: camera_pose::DetectConfig,
}

impl Sections {
    fn parse(s: &Scenario) -> Result<Self, shoal_scenario::ScenarioError> {
        Ok(Self {
            plant: s.section("plant")?,
            nav: s.section("nav")?,
            sonar: s.section("sonar")?,
            camera: s.section("camera")?,
            beacons: s.section("beacons")?,
            hull: s.section("hull")?,
            pose: s.section("pose")?,
            mission: s.section("mission")?,
            follower: s.section("follower")?,
            mpc: s.section("mpc")?,
            acoustic: s.section("acoustic")?,
            optics: s.section("optics")?,
            detect: s.section("detect")?,
        })
    }

    /// `s` with each service section replaced by its config written out
    /// whole, less what [`effective_toml`] leaves out.
    fn fill(&self, s: &Scenario) -> anyhow::Result<Scenario> {
        fn table<T: serde::Serialize>(cfg: &T) -> anyhow::Result<toml::Table> {
            Ok(toml::Table::try_from(cfg)?)
        }
        let mut e = s.clone();
        e.plant = table(&self.plant)?;
        e.nav = table(&self.nav)?;
        e.sonar = table(&self.sonar)?;
        e.camera = table(&self.camera)?;
        e.beacons = table(&self.beacons)?;
        e.hull = table(&self.hull)?;
        e.pose = table(&self.pose)?;
        e.mission = table(&self.mission)?;
        if s.nav.contains_key("position_noise_m") {
            e.mission.remove("position_fix_noise_m");
        } else {
            e.nav.remove("position_noise_m");
        }
        e.follower = table(&self.follower)?;
        e.mpc = table(&self.mpc)?;
        e.acoustic = table(&self.acoustic)?;
        e.optics = table(&self.optics)?;
        e.detect = table(&self.detect)?;
        for (section, key, _) in shoal_scenario::DERIVED_KEYS {
            e.section_table_mut(section)?.remove(key);
        }
        Ok(e)
    }
}

/// Followers of followers this many levels below the leader need the
/// headway ([`planner::FollowerConfig::headway_s`]) to stay string-stable.
pub const HEADWAY_DEPTH: usize = 3;

/// What the scenario allows but will probably regret, one line each
/// (`shoal check` prints them, `shoal run` logs them).
pub fn advice(s: &Scenario) -> Vec<String> {
    let mut out = Vec::new();
    let follower: planner::FollowerConfig = s.section("follower").unwrap_or_default();
    let depth = tree_depth(s);
    if depth >= HEADWAY_DEPTH && follower.headway_s == 0.0 {
        let (h, h_yaw) = (crate::gen::HEADWAY_S, crate::gen::YAW_HEADWAY_S);
        out.push(format!(
            "the formation is {depth} levels deep and follower.headway_s = 0: each level \
             passes its parent's tracking error on amplified (string instability); \
             set `headway_s` and `yaw_headway_s` (`shoal gen` writes {h} and {h_yaw} s)"
        ));
    }
    out
}

/// Levels below the leader of the deepest follower (0 with no followers).
pub fn tree_depth(s: &Scenario) -> usize {
    s.levels().into_values().max().unwrap_or(0)
}

/// The start of the run: no vehicle inside an obstacle, none closer than the
/// safe distance to another, and every follower's camera sees enough of its
/// parent's beacons (camera perception only). Errors name the vehicle's key.
fn check_start(
    s: &Scenario,
    field: &sonar::ObstacleField,
    camera: &camera_pose::CameraConfig,
    beacons: &camera_pose::BeaconLayout,
    hull: &camera_pose::HullConfig,
    pose: &camera_pose::PoseConfig,
) -> anyhow::Result<()> {
    let starts = s.start_poses();
    let mut poses: BTreeMap<&str, Isometry3<f64>> = BTreeMap::new();
    for v in &s.vehicles {
        let (p, yaw) = starts
            .get(&v.name)
            .copied()
            .with_context(|| format!("no start pose for {}", v.name))?;
        poses.insert(
            &v.name,
            Isometry3::new(Vector3::from(p), Vector3::new(0.0, 0.0, yaw)),
        );
    }
    // Which key put the vehicle where it starts.
    let start_key = |i: usize| {
        let v = &s.vehicles[i];
        if v.start_ned_m.is_some() || v.parent.is_none() {
            format!("vehicles[{i}].start_ned_m")
        } else {
            format!("vehicles[{i}].slot_m")
        }
    };
    let capsules: Vec<Capsule> = s
        .vehicles
        .iter()
        .map(|v| hull.capsule(&poses[v.name.as_str()]))
        .collect();
    for (i, v) in s.vehicles.iter().enumerate() {
        // Obstacles: sample the hull's axis; closer than the radius is an overlap.
        let c = &capsules[i];
        let closest = (0..=8)
            .filter_map(|k| field.nearest(&(c.a + (c.b - c.a) * (f64::from(k) / 8.0))))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((j, d)) = closest {
            if d < c.radius_m {
                anyhow::bail!(
                    "{}: {} starts inside obstacles[{j}] (its hull axis is {d:.2} m from the \
                     obstacle, closer than hull.radius_m = {:.2})",
                    start_key(i),
                    v.name,
                    c.radius_m
                );
            }
        }
        // Other vehicles.
        for (j, w) in s.vehicles.iter().enumerate().take(i) {
            let d = (poses[v.name.as_str()].translation.vector
                - poses[w.name.as_str()].translation.vector)
                .norm();
            if d < s.safety.safe_distance_m {
                anyhow::bail!(
                    "{}: {} starts {d:.2} m from {} (vehicles[{j}]), closer than \
                     safety.safe_distance_m = {}",
                    start_key(i),
                    v.name,
                    w.name,
                    s.safety.safe_distance_m
                );
            }
        }
    }
    if s.method.perception != Perception::Camera {
        return Ok(());
    }
    let cam = Camera::new(camera).context("camera")?;
    for (i, v) in s.vehicles.iter().enumerate() {
        let Some(parent) = &v.parent else { continue };
        let Some(pi) = s.vehicle_index(parent) else {
            continue;
        };
        let follower_pose = poses[v.name.as_str()];
        let parent_pose = poses[parent.as_str()];
        let cam_world = cam.camera_in_world(&follower_pose);
        // Every other hull may hide a beacon; the parent's own and the
        // follower's own do not (as in the camera model).
        let occluders: Vec<Capsule> = capsules
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != i && *k != pi)
            .map(|(_, c)| *c)
            .collect();
        let mut seen = 0usize;
        let mut why: Vec<String> = Vec::new();
        for b in 0..beacons.positions_body_m.len() {
            let (status, _) = cam.beacon_status(&cam_world, &parent_pose, beacons, b, &occluders);
            match status {
                BeaconStatus::Visible => seen += 1,
                other => why.push(format!("beacon {b}: {}", describe(other, camera))),
            }
        }
        if seen < pose.min_beacons {
            let key = if v.start_yaw_deg.is_some() {
                format!("vehicles[{i}].start_yaw_deg")
            } else {
                start_key(i)
            };
            anyhow::bail!(
                "{key}: the camera of {} cannot see its parent {} at the start: {seen} of {} \
                 beacons visible, pose.min_beacons = {} needed ({})",
                v.name,
                parent,
                beacons.positions_body_m.len(),
                pose.min_beacons,
                why.join("; ")
            );
        }
    }
    Ok(())
}

fn describe(status: BeaconStatus, camera: &camera_pose::CameraConfig) -> String {
    match status {
        BeaconStatus::Visible => "visible".into(),
        BeaconStatus::BehindCamera => "behind the camera".into(),
        BeaconStatus::OutsideImage => {
            format!("outside the image (camera.fov_deg = {})", camera.fov_deg)
        }
        BeaconStatus::BeyondRange => format!(
            "beyond camera.visibility_range_m = {}",
            camera.visibility_range_m
        ),
        BeaconStatus::FacingAway => "seen from outside its emission cone".into(),
        BeaconStatus::Occluded => "hidden by another hull".into(),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    /// The paper's passage is the 8 m between its two walls, 60 m along the
    /// route (the walls' near ends); walls 2 m nearer the track make it 4 m;
    /// a cylinder on the route closes it; no obstacles, no opening.
    #[test]
    fn narrowest_opening_is_the_papers_passage() {
        let paper = include_str!("../../../scenarios/paper.toml");
        let s = Scenario::from_toml(paper).unwrap();
        let o = narrowest_opening(&s).unwrap().unwrap();
        assert!((o.width_m - 8.0).abs() < 1e-6, "{o:?}");
        assert!((60.0..=80.0).contains(&o.along_m), "{o:?}");
        let narrow = paper
            .replace("[70.0, -9.0, 10.0]", "[70.0, -7.0, 10.0]")
            .replace("[70.0, 9.0, 10.0]", "[70.0, 7.0, 10.0]");
        let o = narrowest_opening(&Scenario::from_toml(&narrow).unwrap())
            .unwrap()
            .unwrap();
        assert!((o.width_m - 4.0).abs() < 1e-6, "{o:?}");
        let blocked = format!(
            "{paper}
[[obstacles]]
kind = \"cylinder\"
center_ned_m = [120.0, 0.0, 10.0]
radius_m = 0.5
half_height_m = 10.0
"
        );
        let o = narrowest_opening(&Scenario::from_toml(&blocked).unwrap())
            .unwrap()
            .unwrap();
        assert_eq!(o.width_m, 0.0, "{o:?}");
        assert!((o.along_m - 120.0).abs() <= 1.0, "{o:?}");
        let mut open = Scenario::from_toml(paper).unwrap();
        open.obstacles.clear();
        assert_eq!(narrowest_opening(&open).unwrap(), None);
    }

    #[test]
    fn every_range_checks_a_number_of_a_full_scenario() {
        let paper = include_str!("../../../scenarios/paper.toml");
        let text = format!(
            "{paper}
[[obstacles]]
kind = \"cylinder\"
center_ned_m = [400.0, 25.0, 10.0]
radius_m = 2.0
half_height_m = 10.0

[[obstacles]]
kind = \"sphere\"
center_ned_m = [416.0, 6.0, 10.0]
radius_m = 3.0

[[obstacles]]
kind = \"mesh\"
vertices_ned_m = [[600.0, -30.0, 25.0], [600.0, 30.0, 25.0], [900.0, 0.0, 25.0]]
triangles = [[0, 1, 2]]

[[faults]]
action = \"stall\"
vehicle = \"F1\"
process = \"mpc\"
at_s = 10.0
duration_s = 1.0
"
        );
        let unmatched = |text: &str| {
            let mut s = Scenario::from_toml(text).unwrap();
            resolve(&mut s).unwrap();
            let effective: toml::Table = toml::from_str(&effective_toml(&s).unwrap()).unwrap();
            shoal_scenario::ranges::unmatched(&effective)
        };
        // The effective scenario holds one of the two position noises
        // (the one the file sets, else the leader's filter's).
        let with_nav = format!("{text}\n[nav]\nposition_noise_m = 0.5\n");
        let (a, b) = (unmatched(&text), unmatched(&with_nav));
        let neither: Vec<_> = a.iter().filter(|p| b.contains(p)).collect();
        assert!(neither.is_empty(), "ranges that check nothing: {neither:?}");
        // And one beyond its range is refused, named.
        let fast = text.replace("speed_mps = 1.0", "speed_mps = 1000.0");
        assert_ne!(fast, text);
        let mut s = Scenario::from_toml(&fast).unwrap();
        let e = resolve(&mut s).unwrap_err().to_string();
        assert!(e.contains("mission.speed_mps: 1000 is out of range"), "{e}");
    }

    #[test]
    fn a_deep_tree_without_headway_is_warned_about_and_the_paper_is_not() {
        let paper = Scenario::paper().unwrap();
        assert_eq!(tree_depth(&paper), 2);
        assert!(advice(&paper).is_empty());
        // L <- F1 <- F2 <- F3: three levels
        let chain = |extra: &str| {
            let mut text = String::from("name = \"chain\"\nduration_s = 10.0\n");
            text.push_str(extra);
            text.push_str("[[vehicles]]\nname = \"L\"\n");
            for (i, parent) in ["L", "F1", "F2"].iter().enumerate() {
                text.push_str(&format!(
                    "[[vehicles]]\nname = \"F{}\"\nparent = \"{parent}\"\nslot_m = [-6.0, 0.0, 0.0]\n",
                    i + 1
                ));
            }
            Scenario::from_toml(&text).unwrap()
        };
        let bare = chain("");
        assert_eq!(tree_depth(&bare), 3);
        let said = advice(&bare);
        assert_eq!(said.len(), 1, "{said:?}");
        assert!(said[0].contains("3 levels deep"), "{said:?}");
        assert!(advice(&chain("[follower]\nheadway_s = 1.0\n")).is_empty());
    }

    /// Byte ranges of the numbers in `text` (not inside names).
    fn numbers(text: &str) -> Vec<(usize, usize)> {
        let b = text.as_bytes();
        let mut out = Vec::new();
        let mut i = 0;
        while i < b.len() {
            let starts = b[i].is_ascii_digit()
                || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit));
            let after_word = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
            if starts && !after_word {
                let mut j = i + 1;
                while j < b.len()
                    && (b[j].is_ascii_digit() || matches!(b[j], b'.' | b'e' | b'E' | b'-' | b'+'))
                {
                    j += 1;
                }
                out.push((i, j));
                i = j;
            } else {
                i += 1;
            }
        }
        out
    }

    /// The whole check (every section, the start, the formation, the
    /// machine) on the paper scenario with 1-3 of its numbers replaced by
    /// edge values, and with extra sections holding edge values: never a
    /// panic; whatever passes has finite displacements for every follower.
    #[test]
    fn resolve_never_panics_on_mutated_scenarios() {
        const EDGE: &[&str] = &[
            "nan", "inf", "-inf", "0", "-0.0", "1e308", "-1e308", "5e-324", "-1", "1", "0.5",
            "1e6", "-8.0", "30.0", "2.0", "100",
        ];
        const SECTIONS: &[&str] = &[
            "[camera]\nfov_deg = X\n",
            "[camera]\nvisibility_range_m = X\n",
            "[beacons]\nemission_half_angle_deg = X\n",
            "[hull]\nradius_m = X\n",
            "[pose]\nmin_beacons = 3\nmax_reprojection_rms_px = X\n",
            "[sonar]\nrange_max_m = X\n",
            "[mpc]\nhorizon = 5\n",
            "[plant]\nstep_s = X\n",
            "[plant.vehicle]\nmass_kg = X\n",
            "[mpc]\nstep_s = X\n",
            "[follower]\nmemory_behind_m = X\n",
            "[acoustic]\nbit_rate_bps = X\n",
            "[[obstacles]]\nkind = \"sphere\"\ncenter_ned_m = [X, 0.0, 10.0]\nradius_m = 3.0\n",
            "[[obstacles]]\nkind = \"mesh\"\nvertices_ned_m = [[0.0, 0.0, X], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\ntriangles = [[0, 1, 2]]\n",
        ];
        let paper = shoal_scenario::PAPER_TOML;
        let nums = numbers(paper);
        let mut seed: u64 = 0x5eed_1234_abcd_ef01;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let (mut cases, mut accepted) = (0, 0);
        for _ in 0..400 {
            let mut text = paper.to_string();
            let mut picks: Vec<(usize, usize, &str)> = (0..1 + rnd() % 3)
                .map(|_| {
                    let (a, b) = nums[(rnd() as usize) % nums.len()];
                    (a, b, EDGE[(rnd() as usize) % EDGE.len()])
                })
                .collect();
            picks.sort_by_key(|p| std::cmp::Reverse(p.0));
            picks.dedup_by_key(|p| p.0);
            for (a, b, e) in picks {
                text.replace_range(a..b, e);
            }
            if rnd() % 2 == 0 {
                let sec = SECTIONS[(rnd() as usize) % SECTIONS.len()];
                let val = EDGE[(rnd() as usize) % EDGE.len()];
                // Appended sections must not repeat a table the paper has.
                let head = sec.lines().next().unwrap_or("");
                if !text.contains(head) || head.starts_with("[[") {
                    text.push('\n');
                    text.push_str(&sec.replace('X', val));
                }
            }
            cases += 1;
            let Ok(mut s) = Scenario::from_toml(&text) else {
                continue;
            };
            if resolve(&mut s).is_ok() {
                accepted += 1;
                for v in s.vehicles.iter().filter(|v| v.parent.is_some()) {
                    let (a, b) = (v.d_a_m.unwrap(), v.d_b_m.unwrap());
                    assert!(
                        a.is_finite() && b.is_finite(),
                        "{}: {a} {b}\n{text}",
                        v.name
                    );
                }
            }
        }
        // The mutations reach the check, and some pass it.
        assert_eq!(cases, 400);
        assert!(accepted > 0);
        println!("resolve: {accepted} of {cases} mutated scenarios accepted");
    }

    #[test]
    fn resolve_accepts_the_paper_and_fills_every_displacement() {
        let mut s = Scenario::paper().unwrap();
        resolve(&mut s).unwrap();
        for v in s.vehicles.iter().filter(|v| v.parent.is_some()) {
            assert!(v.d_a_m.is_some() && v.d_b_m.is_some(), "{}", v.name);
        }
    }
}

/// The narrowest opening the leader's route passes through: at a point of
/// the route, obstacles on both sides of it, measured across it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Opening {
    /// From the obstacle to port to the one to starboard, m.
    pub width_m: f64,
    /// How far along the route, m.
    pub along_m: f64,
}

/// Farthest an obstacle abeam counts as a side of an opening, m.
pub const OPENING_REACH_M: f64 = 150.0;

/// The narrowest opening on the leader's route (its start, then its
/// waypoints), sampled every metre: horizontal rays to port and starboard,
/// square to the route, at the route's depth. `None` without obstacles on
/// both sides anywhere. A point of the route inside an obstacle gives 0.
pub fn narrowest_opening(s: &Scenario) -> anyhow::Result<Option<Opening>> {
    let obstacles: Vec<sonar::Obstacle> = s.obstacles_as()?;
    if obstacles.is_empty() {
        return Ok(None);
    }
    let field = sonar::ObstacleField::new(&obstacles)?;
    let mission: planner::LeaderConfig = s.section("mission")?;
    let starts = s.start_poses();
    let Some((start, _)) = starts.get(&s.leader().name) else {
        return Ok(None);
    };
    let mut route = vec![nalgebra::Vector3::from(*start)];
    route.extend(
        mission
            .waypoints_ned_m
            .iter()
            .map(|w| nalgebra::Vector3::from(*w)),
    );
    let mut best: Option<Opening> = None;
    let mut along = 0.0;
    for leg in route.windows(2) {
        let d = leg[1] - leg[0];
        let len = d.xy().norm();
        if len < 1e-9 {
            continue;
        }
        // square to the leg, to starboard (NED: north → east)
        let across = nalgebra::Unit::new_normalize(nalgebra::Vector3::new(-d.y, d.x, 0.0));
        let mut k = 0.0;
        while k <= len {
            let p = nalgebra::Point3::from(leg[0] + d * (k / len));
            let starboard = field.cast_ray(&p, &across, OPENING_REACH_M);
            let port = field.cast_ray(&p, &-across, OPENING_REACH_M);
            if let (Some(a), Some(b)) = (port, starboard) {
                let width_m = if field.distance(&p) <= 0.0 {
                    0.0
                } else {
                    a + b
                };
                if best.is_none_or(|o| width_m < o.width_m) {
                    best = Some(Opening {
                        width_m,
                        along_m: along + k,
                    });
                }
            }
            k += 1.0;
        }
        along += len;
    }
    Ok(best)
}
