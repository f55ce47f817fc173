//! The paper's figures (figs. 6-11) and the slot error over time, drawn from
//! ground truth in a run's recording, as PNG and SVG.
//!
//! Text in the PNGs is rasterised by plotters' pure-Rust `ab_glyph` path with
//! DejaVu Sans embedded in the binary (crate `dejavu`), so no system font,
//! fontconfig or other C library is needed. The SVGs carry text as `<text>`
//! elements in `sans-serif`.
//!
//! Frames: world NED. The horizontal-plane figure is a view from above with
//! north to the right and east downwards (so it is not mirrored); the
//! vertical-plane figure draws depth (down positive) downwards.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::Context;
use nalgebra::{Point3, Vector3};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::full_palette::{GREY_300, GREY_500, GREY_700, ORANGE_100};
use plotters::style::text_anchor::{HPos, Pos, VPos};
use recordings::Recording;

mod campaign;
pub mod colours;
mod compare;
mod figures;
pub(crate) mod geometry;
mod style;

pub use campaign::write_campaign_plot;
pub use compare::write_compare_plot;
#[cfg(test)]
use compare::COMPARE_TITLE;
pub(crate) use style::*;

use colours::{Colouring, VEHICLE_COLOURS};

use figures::*;
use geometry::*;

use crate::analysis::formation::{slot_errors, Passage};
use crate::analysis::track::{Track, Tracks};
use shoal_scenario::Scenario;

/// Figure names (file stems), in the order they are written.
const FIGURES: [Fig; 7] = [
    Fig::TrajectoriesXy,
    Fig::TrajectoriesXz,
    Fig::ObstacleDistance,
    Fig::ParentDistances,
    Fig::PairDistances,
    Fig::MinDistance,
    Fig::SlotError,
];

/// Font family name the figures use; DejaVu Sans is registered under it.
pub(crate) const FONT: &str = "sans-serif";
/// Width of every figure, px.
pub(crate) const WIDTH: u32 = 1600;
/// Height of the time plots, px.
const HEIGHT: u32 = 900;
const MARGIN: u32 = 20;
const X_LABEL_AREA: u32 = 70;
const Y_LABEL_AREA: u32 = 90;

#[derive(Debug, Clone, Copy)]
enum Fig {
    TrajectoriesXy,
    TrajectoriesXz,
    ObstacleDistance,
    ParentDistances,
    PairDistances,
    MinDistance,
    SlotError,
}

impl Fig {
    fn stem(self) -> &'static str {
        match self {
            Fig::TrajectoriesXy => "trajectories_xy",
            Fig::TrajectoriesXz => "trajectories_xz",
            Fig::ObstacleDistance => "obstacle_distance",
            Fig::ParentDistances => "parent_distances",
            Fig::PairDistances => "pair_distances",
            Fig::MinDistance => "min_distance",
            Fig::SlotError => "slot_error",
        }
    }

    fn title(self) -> &'static str {
        match self {
            Fig::TrajectoriesXy => "Trajectories in the horizontal plane (top view, fig. 6)",
            Fig::TrajectoriesXz => {
                "Trajectories in the vertical plane: depth against north (fig. 7)"
            }
            Fig::ObstacleDistance => "Distance of each follower to the nearest obstacle (fig. 8)",
            Fig::ParentDistances => "Distance from each follower to its parent (fig. 9)",
            Fig::PairDistances => "Distance between the other pairs of vehicles (fig. 10)",
            Fig::MinDistance => "Minimum distance between any two vehicles (fig. 11)",
            Fig::SlotError => "Slot error of each follower (ground truth)",
        }
    }
}

/// The figures [`write_plots`] writes: (file stem, title), in order.
pub fn figure_list() -> Vec<(&'static str, &'static str)> {
    FIGURES.iter().map(|f| (f.stem(), f.title())).collect()
}

/// Writes the figures of a run into `dir` (created if missing) as PNG and SVG; returns the files written.
// Called by main.rs after a run; the allow keeps the module warning-free until then.
pub fn write_plots(
    scenario: &Scenario,
    rec: &Recording,
    dir: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    register_font()?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let data = Data::load(scenario, rec)?;
    let mut written = Vec::with_capacity(2 * FIGURES.len());
    for fig in FIGURES {
        let size = data.size(fig);
        let png = dir.join(format!("{}.png", fig.stem()));
        {
            let root = BitMapBackend::new(&png, size).into_drawing_area();
            draw(fig, &data, &root).with_context(|| format!("drawing {}", png.display()))?;
            root.present()
                .with_context(|| format!("writing {}", png.display()))?;
        }
        written.push(png);
        let svg = dir.join(format!("{}.svg", fig.stem()));
        {
            let root = SVGBackend::new(&svg, size).into_drawing_area();
            draw(fig, &data, &root).with_context(|| format!("drawing {}", svg.display()))?;
            root.present()
                .with_context(|| format!("writing {}", svg.display()))?;
        }
        written.push(svg);
    }
    Ok(written)
}

/// Registers the embedded DejaVu Sans as [`FONT`] (once per process).
pub(crate) fn register_font() -> anyhow::Result<()> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular())
            .map_err(|_| "the embedded DejaVu Sans font could not be parsed".to_string())
    })
    .clone()
    .map_err(anyhow::Error::msg)
}

/// A follower with its parent and slot (parent body frame, FRD, m).
struct Follower {
    track: usize,
    parent: usize,
    slot: [f64; 3],
}

/// Everything the figures need, loaded once.
struct Data {
    tracks: Vec<Track>,
    followers: Vec<Follower>,
    obstacles: Vec<sonar::Obstacle>,
    field: Option<sonar::ObstacleField>,
    safe_m: f64,
    collision_m: f64,
    /// Times when any follower was shifting for an obstacle, s.
    avoiding_s: Vec<(f64, f64)>,
    t_end_s: f64,
    /// Per follower whose shift moves it in depth (D_b ≠ 0): the depth its
    /// planner asks for (the parent's depth plus the filtered slot's z,
    /// eqs. (5), (9)) against its own north, m.
    depth_commands: Vec<(usize, Vec<(f64, f64)>)>,
    /// Vehicle by vehicle, or by file for a large group ([`colours`]).
    colouring: Colouring,
}

fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

impl Data {
    fn load(scenario: &Scenario, rec: &Recording) -> anyhow::Result<Self> {
        let tracks = Tracks::load(scenario, rec).tracks;
        let followers = scenario
            .vehicles
            .iter()
            .enumerate()
            .filter_map(|(i, v)| {
                let parent = scenario.vehicle_index(v.parent.as_deref()?)?;
                Some(Follower {
                    track: i,
                    parent,
                    slot: v.slot_m?,
                })
            })
            .collect::<Vec<_>>();
        let obstacles: Vec<sonar::Obstacle> = scenario
            .obstacles_as()
            .context("obstacles of the scenario")?;
        let field = if obstacles.is_empty() {
            None
        } else {
            Some(sonar::ObstacleField::new(&obstacles).context("obstacle field")?)
        };

        // Avoidance intervals: when any follower was shifting for an obstacle.
        let avoiding_s = Passage::load(scenario, rec)
            .spans
            .iter()
            .map(|s| (secs(s.start_ns), secs(s.end_ns)))
            .collect();

        let t_end_s = tracks
            .iter()
            .filter_map(|t| t.t_ns.last())
            .map(|&t| secs(t))
            .fold(0.0, f64::max);
        let depth_commands = followers
            .iter()
            .filter(|f| scenario.vehicles[f.track].d_b_m.is_some_and(|d| d != 0.0))
            .map(|f| {
                let name = &scenario.vehicles[f.track].name;
                let states =
                    rec.samples::<ipc_types::PlannerState>(&format!("/{name}/planner_state"));
                let pts = states
                    .iter()
                    .filter_map(|s| {
                        let t = s.header.sim_time_ns;
                        let (me, _) = tracks.get(f.track)?.at(t)?;
                        let (parent, _) = tracks.get(f.parent)?.at(t)?;
                        Some((me.x, parent.z + s.slot_filtered_m[2]))
                    })
                    .collect();
                (f.track, pts)
            })
            .collect();
        Ok(Self {
            tracks,
            followers,
            obstacles,
            field,
            safe_m: scenario.safety.safe_distance_m,
            collision_m: scenario.safety.collision_distance_m,
            avoiding_s,
            t_end_s,
            depth_commands,
            colouring: Colouring::of(scenario),
        })
    }

    fn colour(&self, track: usize) -> RGBColor {
        self.colouring.colour(track)
    }

    /// A vehicle's name for a legend; none when the group is coloured by file.
    fn label(&self, track: usize) -> Option<&str> {
        (!self.colouring.by_file()).then(|| self.tracks[track].name.as_str())
    }

    /// The files' legend entries when the group is coloured by file.
    fn file_legend(&self, leg: &mut Legend) {
        for (label, colour) in self.colouring.files() {
            leg.push((label.clone(), Key::Line(*colour, 3)));
        }
    }

    /// Pixel size of a figure.
    fn size(&self, fig: Fig) -> (u32, u32) {
        match fig {
            Fig::TrajectoriesXy => {
                let (n, e) = self.xy_ranges();
                let (pw, _) = plot_px((WIDTH, HEIGHT));
                let ph = pw * (e.end - e.start) / (n.end - n.start);
                let h = ph + f64::from(2 * MARGIN + X_LABEL_AREA) + TITLE_H;
                (WIDTH, (h.round() as u32).clamp(700, 1600))
            }
            Fig::TrajectoriesXz => (WIDTH, 800),
            Fig::ObstacleDistance => (WIDTH, 1200),
            _ => (WIDTH, HEIGHT),
        }
    }

    /// North and east ranges of tracks and obstacle footprints, padded, m.
    fn xy_ranges(&self) -> (Range<f64>, Range<f64>) {
        let mut n = Bounds::default();
        let mut e = Bounds::default();
        for t in &self.tracks {
            for p in &t.p {
                n.add(p.x);
                e.add(p.y);
            }
        }
        for o in &self.obstacles {
            for (pn, pe) in footprint(o) {
                n.add(pn);
                e.add(pe);
            }
        }
        (n.padded(0.04, 5.0), e.padded(0.08, 5.0))
    }

    /// True when track `j` is track `i`'s parent or the other way round.
    fn linked(&self, i: usize, j: usize) -> bool {
        self.followers
            .iter()
            .any(|f| (f.track, f.parent) == (i, j) || (f.track, f.parent) == (j, i))
    }

    /// Pairwise distance series over the first vehicle's sample times:
    /// `(pair label, [(t s, distance m)])`, of the pairs `keep` takes.
    fn pair_series_where(
        &self,
        keep: impl Fn(usize, usize) -> bool,
    ) -> Vec<(String, Vec<(f64, f64)>)> {
        let mut out = Vec::new();
        let Some(master) = self.tracks.first() else {
            return out;
        };
        for i in 0..self.tracks.len() {
            for j in i + 1..self.tracks.len() {
                if !keep(i, j) {
                    continue;
                }
                let (a, b) = (&self.tracks[i], &self.tracks[j]);
                let pts = master
                    .t_ns
                    .iter()
                    .filter_map(|&t| {
                        let (ia, ib) = (a.recent(t)?, b.recent(t)?);
                        Some((secs(t), (a.p[ia] - b.p[ib]).norm()))
                    })
                    .collect();
                out.push((format!("{}–{}", a.name, b.name), pts));
            }
        }
        out
    }

    /// Every pair's distance series ([`Data::pair_series_where`]).
    fn pair_series(&self) -> Vec<(String, Vec<(f64, f64)>)> {
        self.pair_series_where(|_, _| true)
    }

    /// Slot error of a follower over time: `|p − (p_parent + R_parent·slot)|`.
    fn slot_error(&self, f: &Follower) -> Vec<(f64, f64)> {
        slot_errors(&self.tracks[f.track], &self.tracks[f.parent], f.slot)
            .into_iter()
            .map(|(t, e)| (secs(t), e))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::{PlannerState, Sample, Truth};
    use recordings::{RecordingWriter, WriterOptions};

    const SCENARIO: &str = r#"
name = "plots-test"
duration_s = 10.0

[[vehicles]]
name = "L"
start_ned_m = [0.0, 0.0, 10.0]

[[vehicles]]
name = "F1"
parent = "L"
slot_m = [-8.0, -4.0, 0.0]

[[vehicles]]
name = "F2"
parent = "L"
slot_m = [-8.0, 4.0, 0.0]

[[obstacles]]
kind = "box"
center_ned_m = [5.0, -9.0, 10.0]
half_extents_m = [2.0, 2.0, 5.0]
yaw_deg = 30.0

[[obstacles]]
kind = "cylinder"
center_ned_m = [5.0, 9.0, 10.0]
radius_m = 2.0
half_height_m = 5.0
"#;

    /// Writes 10 s of three vehicles moving north at 1 m/s, F1 avoiding
    /// between 3 s and 6 s.
    fn synthetic(path: &Path, scenario: &Scenario) {
        let mut w = RecordingWriter::create(path, &WriterOptions::default()).unwrap();
        for v in &scenario.vehicles {
            let truth = w
                .add_channel::<Truth>(&format!("/{}/truth", v.name))
                .unwrap();
            let state = w
                .add_channel::<PlannerState>(&format!("/{}/planner_state", v.name))
                .unwrap();
            let slot = v.slot_m.unwrap_or([0.0; 3]);
            for k in 0..100u64 {
                let t = k as f64 * 0.1;
                let mut s = Truth::zeroed();
                s.header.seq = k;
                s.header.sim_time_ns = k * 100_000_000;
                let wobble = if v.parent.is_some() {
                    0.5 * (t).sin()
                } else {
                    0.0
                };
                s.position_ned_m = [t + slot[0], slot[1] + wobble, 10.0 + 0.1 * t];
                s.q_body_to_ned_wxyz = [1.0, 0.0, 0.0, 0.0];
                w.write(truth, &s).unwrap();
                let mut p = PlannerState::zeroed();
                p.header = s.header;
                p.avoiding = u8::from(v.name == "F1" && (3.0..6.0).contains(&t));
                w.write(state, &p).unwrap();
            }
        }
        w.finish().unwrap();
    }

    #[test]
    fn every_figure_is_written_as_png_and_svg() {
        let scenario = Scenario::from_toml(SCENARIO).unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("recording.mcap");
        synthetic(&path, &scenario);
        let rec = Recording::open(&path).unwrap();
        let dir = tmp.path().join("plots");
        let files = write_plots(&scenario, &rec, &dir).unwrap();
        assert_eq!(files.len(), 2 * FIGURES.len());
        for fig in FIGURES {
            let png = dir.join(format!("{}.png", fig.stem()));
            let svg = dir.join(format!("{}.svg", fig.stem()));
            assert!(files.contains(&png) && files.contains(&svg));
            let bytes = std::fs::read(&png).unwrap();
            assert!(
                bytes.len() > 1000,
                "{} is {} bytes",
                png.display(),
                bytes.len()
            );
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
            let text = std::fs::read_to_string(&svg).unwrap();
            assert!(
                text.contains(fig.title()),
                "{} lacks its title",
                svg.display()
            );
            let key = match fig {
                Fig::ParentDistances => "L–F2",
                Fig::PairDistances => "F1–F2",
                Fig::MinDistance => "minimum pairwise distance",
                _ => "F2",
            };
            assert!(
                text.contains(&format!("\n{key}\n")),
                "{} lacks the legend entry {key}",
                svg.display()
            );
        }
        let xy = std::fs::read_to_string(dir.join("trajectories_xy.svg")).unwrap();
        assert!(xy.contains("north x (m)") && xy.contains("\nobstacle\n"));
    }

    #[test]
    fn the_comparison_figure_names_every_variant_and_clips_a_divergent_one() {
        let scenario = Scenario::from_toml(SCENARIO).unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("recording.mcap");
        synthetic(&path, &scenario);
        let rec = Recording::open(&path).unwrap();
        // The second variant: the followers 50 m off their slots.
        let far = tmp.path().join("far.mcap");
        let mut shifted = scenario.clone();
        for v in shifted.vehicles.iter_mut().filter(|v| v.parent.is_some()) {
            v.slot_m = v.slot_m.map(|s| [s[0] - 50.0, s[1], s[2]]);
        }
        synthetic(&far, &shifted);
        let far_rec = Recording::open(&far).unwrap();
        let files = write_compare_plot(
            &[
                ("method", &scenario, &rec),
                ("baseline", &scenario, &far_rec),
            ],
            tmp.path(),
        )
        .unwrap();
        assert_eq!(files.len(), 2);
        let svg = std::fs::read_to_string(tmp.path().join("compare.svg")).unwrap();
        assert!(svg.contains(COMPARE_TITLE));
        assert!(svg.contains("\nmethod\n"));
        assert!(
            svg.contains("baseline (clipped; max 50)"),
            "the divergent variant is marked clipped"
        );
        let png = std::fs::read(tmp.path().join("compare.png")).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    }

    #[test]
    fn slot_error_is_zero_on_the_slot_and_the_distance_of_the_offset_off_it() {
        let scenario = Scenario::from_toml(SCENARIO).unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("recording.mcap");
        synthetic(&path, &scenario);
        let rec = Recording::open(&path).unwrap();
        let d = Data::load(&scenario, &rec).unwrap();
        assert_eq!(d.followers.len(), 2);
        for f in &d.followers {
            for (t, e) in d.slot_error(f) {
                // Leader at (t, 0, 10+0.1t) facing north; follower at slot + east wobble.
                approx::assert_relative_eq!(e, (0.5 * t.sin()).abs(), epsilon = 1e-9);
            }
        }
        assert_eq!(d.avoiding_s.len(), 1);
        approx::assert_relative_eq!(d.avoiding_s[0].0, 3.0, epsilon = 1e-9);
        approx::assert_relative_eq!(d.avoiding_s[0].1, 6.0, epsilon = 1e-9);
    }

    #[test]
    fn runs_below_split_at_the_top_and_interpolate_the_crossings() {
        let pts = [(0.0, 1.0), (1.0, 3.0), (2.0, 5.0), (3.0, 1.0), (4.0, 2.0)];
        let runs = runs_below(&pts, 3.0);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0], vec![(0.0, 1.0), (1.0, 3.0), (1.0, 3.0)]);
        assert_eq!(runs[1], vec![(2.5, 3.0), (3.0, 1.0), (4.0, 2.0)]);
    }

    #[test]
    fn footprints_follow_yaw_and_hull_is_convex() {
        let o = sonar::Obstacle::Box {
            center_ned_m: [0.0, 0.0, 0.0],
            half_extents_m: [2.0, 1.0, 1.0],
            yaw_deg: 90.0,
        };
        let f = footprint(&o);
        // Rotated 90° towards east: the long side lies along east.
        let max_e = f.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        let max_n = f.iter().map(|p| p.0).fold(f64::MIN, f64::max);
        approx::assert_relative_eq!(max_e, 2.0, epsilon = 1e-12);
        approx::assert_relative_eq!(max_n, 1.0, epsilon = 1e-12);
        let h = hull(vec![
            (0.0, 0.0),
            (1.0, 0.0),
            (0.5, 0.2),
            (1.0, 1.0),
            (0.0, 1.0),
        ]);
        assert_eq!(h.len(), 4);
    }
}
