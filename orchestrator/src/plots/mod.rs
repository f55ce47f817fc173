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

use crate::analysis::formation::{slot_errors, Passage};
use crate::analysis::track::{Track, Tracks};
use shoal_scenario::Scenario;

/// Figure names (file stems), in the order they are written.
const FIGURES: [Fig; 6] = [
    Fig::TrajectoriesXy,
    Fig::TrajectoriesXz,
    Fig::ObstacleDistance,
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

/// Vehicle colours: the leader black, then the tab10 palette.
const VEHICLE_COLOURS: [RGBColor; 10] = [
    RGBColor(0, 0, 0),
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
];

#[derive(Debug, Clone, Copy)]
enum Fig {
    TrajectoriesXy,
    TrajectoriesXz,
    ObstacleDistance,
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
            Fig::PairDistances => "Distance between every pair of vehicles (figs. 9-10)",
            Fig::MinDistance => "Minimum distance between any two vehicles (fig. 11)",
            Fig::SlotError => "Slot error of each follower (ground truth)",
        }
    }
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
        Ok(Self {
            tracks,
            followers,
            obstacles,
            field,
            safe_m: scenario.safety.safe_distance_m,
            collision_m: scenario.safety.collision_distance_m,
            avoiding_s,
            t_end_s,
        })
    }

    fn colour(&self, track: usize) -> RGBColor {
        VEHICLE_COLOURS[track % VEHICLE_COLOURS.len()]
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

    /// Pairwise distance series over the first vehicle's sample times:
    /// `(pair label, [(t s, distance m)])`.
    fn pair_series(&self) -> Vec<(String, Vec<(f64, f64)>)> {
        let mut out = Vec::new();
        let Some(master) = self.tracks.first() else {
            return out;
        };
        for i in 0..self.tracks.len() {
            for j in i + 1..self.tracks.len() {
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

    /// Slot error of a follower over time: `|p − (p_parent + R_parent·slot)|`.
    fn slot_error(&self, f: &Follower) -> Vec<(f64, f64)> {
        slot_errors(&self.tracks[f.track], &self.tracks[f.parent], f.slot)
            .into_iter()
            .map(|(t, e)| (secs(t), e))
            .collect()
    }
}

/// Height reserved for the title, px.
pub(crate) const TITLE_H: f64 = 56.0;

#[derive(Default)]
struct Bounds {
    lo: Option<f64>,
    hi: Option<f64>,
}

impl Bounds {
    fn add(&mut self, v: f64) {
        if v.is_finite() {
            self.lo = Some(self.lo.map_or(v, |l| l.min(v)));
            self.hi = Some(self.hi.map_or(v, |h| h.max(v)));
        }
    }
    /// The range padded by `frac` of its length (at least `min_len` long).
    fn padded(&self, frac: f64, min_len: f64) -> Range<f64> {
        let (lo, hi) = match (self.lo, self.hi) {
            (Some(l), Some(h)) => (l, h),
            _ => (0.0, 1.0),
        };
        let mid = 0.5 * (lo + hi);
        let half = (0.5 * (hi - lo)).max(0.5 * min_len) * (1.0 + 2.0 * frac);
        mid - half..mid + half
    }
}

/// The obstacle's outline seen from above, as (north, east) points, m.
fn footprint(o: &sonar::Obstacle) -> Vec<(f64, f64)> {
    match o {
        sonar::Obstacle::Box {
            center_ned_m: c,
            half_extents_m: h,
            yaw_deg,
        } => {
            let (s, co) = yaw_deg.to_radians().sin_cos();
            [(1.0, 1.0), (1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0)]
                .iter()
                .map(|&(a, b)| {
                    let (x, y) = (a * h[0], b * h[1]);
                    (c[0] + co * x - s * y, c[1] + s * x + co * y)
                })
                .collect()
        }
        sonar::Obstacle::Cylinder {
            center_ned_m: c,
            radius_m: r,
            ..
        }
        | sonar::Obstacle::Sphere {
            center_ned_m: c,
            radius_m: r,
        } => circle(c[0], c[1], *r),
        sonar::Obstacle::Mesh { vertices_ned_m, .. } => {
            hull(vertices_ned_m.iter().map(|v| (v[0], v[1])).collect())
        }
    }
}

/// The obstacle's outline seen from the side (east axis), as (north, depth) points, m.
fn side_profile(o: &sonar::Obstacle) -> Vec<(f64, f64)> {
    let rect = |n0: f64, n1: f64, d0: f64, d1: f64| vec![(n0, d0), (n1, d0), (n1, d1), (n0, d1)];
    match o {
        sonar::Obstacle::Box {
            center_ned_m: c,
            half_extents_m: h,
            yaw_deg,
        } => {
            let (s, co) = yaw_deg.to_radians().sin_cos();
            let hn = h[0] * co.abs() + h[1] * s.abs();
            rect(c[0] - hn, c[0] + hn, c[2] - h[2], c[2] + h[2])
        }
        sonar::Obstacle::Cylinder {
            center_ned_m: c,
            radius_m: r,
            half_height_m: hh,
        } => rect(c[0] - r, c[0] + r, c[2] - hh, c[2] + hh),
        sonar::Obstacle::Sphere {
            center_ned_m: c,
            radius_m: r,
        } => circle(c[0], c[2], *r),
        sonar::Obstacle::Mesh { vertices_ned_m, .. } => {
            hull(vertices_ned_m.iter().map(|v| (v[0], v[2])).collect())
        }
    }
}

fn circle(a: f64, b: f64, r: f64) -> Vec<(f64, f64)> {
    (0..64)
        .map(|k| {
            let t = f64::from(k) * std::f64::consts::TAU / 64.0;
            (a + r * t.cos(), b + r * t.sin())
        })
        .collect()
}

/// Convex hull (Andrew's monotone chain), counter-clockwise.
fn hull(mut pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    pts.retain(|p| p.0.is_finite() && p.1.is_finite());
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut h: Vec<(f64, f64)> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = h.len();
        let iter: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], p) <= 0.0 {
                h.pop();
            }
            h.push(p);
        }
        h.pop();
    }
    h
}

pub(crate) fn caption_style() -> TextStyle<'static> {
    (FONT, 30).into_font().color(&BLACK)
}
pub(crate) fn subtitle_style() -> TextStyle<'static> {
    (FONT, 24).into_font().color(&BLACK)
}
fn desc_style() -> TextStyle<'static> {
    (FONT, 22).into_font().color(&BLACK)
}
fn tick_style() -> TextStyle<'static> {
    (FONT, 18).into_font().color(&BLACK)
}
pub(crate) fn legend_style() -> TextStyle<'static> {
    (FONT, 20).into_font().color(&BLACK)
}

/// A tick label: no trailing `.0`, no `-0`.
pub(crate) fn num(v: f64) -> String {
    let r = (v * 1000.0).round() / 1000.0 + 0.0;
    if r == r.trunc() {
        format!("{r:.0}")
    } else {
        format!("{r}")
    }
}

/// Draws one figure on a backend.
fn draw<DB: DrawingBackend>(fig: Fig, d: &Data, root: &DrawingArea<DB, Shift>) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let body = titled(root, fig.title(), TITLE_H as u32, caption_style())?;
    match fig {
        Fig::TrajectoriesXy => draw_xy(d, &body),
        Fig::TrajectoriesXz => draw_xz(d, &body),
        Fig::ObstacleDistance => draw_obstacle_distance(d, &body),
        Fig::PairDistances => draw_pairs(d, &body),
        Fig::MinDistance => draw_min_distance(d, &body),
        Fig::SlotError => draw_slot_error(d, &body),
    }
}

/// Draws `text` centred in a band of `h` px at the top; returns the area below.
pub(crate) fn titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    h: u32,
    style: TextStyle<'static>,
) -> anyhow::Result<DrawingArea<DB, Shift>>
where
    DB::ErrorType: 'static,
{
    let (top, body) = area.split_vertically(h);
    let (w, h) = top.dim_in_pixel();
    top.draw(&Text::new(
        text.to_string(),
        (w as i32 / 2, h as i32 / 2),
        style.pos(Pos::new(HPos::Center, VPos::Center)),
    ))?;
    Ok(body)
}

/// Width reserved right of the plot for the legend, px.
const LEGEND_W: u32 = 330;

/// Plotting-area size of a chart built by [`chart`] on the left of an area
/// of `(w, h)` px split by [`split_legend`].
fn plot_px((w, h): (u32, u32)) -> (f64, f64) {
    (
        f64::from(
            w.saturating_sub(2 * MARGIN + LEGEND_W + Y_LABEL_AREA)
                .max(1),
        ),
        f64::from(h.saturating_sub(2 * MARGIN + X_LABEL_AREA).max(1)),
    )
}

pub(crate) fn chart<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
) -> ChartBuilder<'a, 'b, DB> {
    let mut b = ChartBuilder::on(area);
    b.margin_top(MARGIN)
        .margin_bottom(MARGIN)
        .margin_left(MARGIN)
        .margin_right(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA);
    b
}

pub(crate) type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Grid, ticks and axis names; `negate_y` labels the vertical axis with −y
/// (axes that grow downwards are plotted negated).
pub(crate) fn mesh<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    x_desc: &str,
    y_desc: &str,
    negate_y: bool,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let fy = move |v: &f64| num(if negate_y { -*v } else { *v });
    c.configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v| num(*v))
        .y_label_formatter(&fy)
        .x_labels(12)
        .y_labels(10)
        .axis_desc_style(desc_style())
        .label_style(tick_style())
        .light_line_style(WHITE.mix(0.0))
        .bold_line_style(GREY_300.stroke_width(1))
        .draw()?;
    Ok(())
}

/// How a legend entry is keyed.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Key {
    Line(RGBColor, u32),
    Dashed(RGBColor, u32, i32, i32),
    Fill(RGBColor),
    Dot(RGBColor),
    Square(RGBColor),
}

/// Legend entries, in drawing order.
pub(crate) type Legend = Vec<(String, Key)>;

/// Splits an area into the plot (left) and the legend column (right).
pub(crate) fn split_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
) -> (DrawingArea<DB, Shift>, DrawingArea<DB, Shift>) {
    let (w, _) = area.dim_in_pixel();
    area.split_horizontally(w.saturating_sub(LEGEND_W))
}

/// Draws the legend in its column, top-aligned with the plot.
pub(crate) fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &Legend,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    if entries.is_empty() {
        return Ok(());
    }
    const ROW: i32 = 30;
    let (w, _) = area.dim_in_pixel();
    let (x0, y0) = (4, MARGIN as i32);
    let mut text_w = 0;
    for (label, _) in entries {
        text_w = text_w.max(area.estimate_text_size(label, &legend_style())?.0 as i32);
    }
    let x1 = (x0 + 12 + 42 + text_w + 14).min(w as i32 - 2);
    let y1 = y0 + 12 + ROW * entries.len() as i32;
    area.draw(&Rectangle::new([(x0, y0), (x1, y1)], WHITE.filled()))?;
    area.draw(&Rectangle::new([(x0, y0), (x1, y1)], BLACK.stroke_width(1)))?;
    for (i, (label, key)) in entries.iter().enumerate() {
        let y = y0 + 6 + ROW * i as i32 + ROW / 2;
        let kx = x0 + 12;
        match *key {
            Key::Line(c, w) => area.draw(&PathElement::new(
                vec![(kx, y), (kx + 30, y)],
                c.stroke_width(w.max(3)),
            ))?,
            Key::Dashed(c, w, d, g) => {
                let mut x = kx;
                while x < kx + 30 {
                    area.draw(&PathElement::new(
                        vec![(x, y), ((x + d).min(kx + 30), y)],
                        c.stroke_width(w),
                    ))?;
                    x += d + g;
                }
            }
            Key::Fill(c) => {
                area.draw(&Rectangle::new([(kx, y - 9), (kx + 30, y + 9)], c.filled()))?
            }
            Key::Dot(c) => area.draw(&Circle::new((kx + 15, y), 7, c.filled()))?,
            Key::Square(c) => area.draw(&Rectangle::new(
                [(kx + 8, y - 7), (kx + 22, y + 7)],
                c.filled(),
            ))?,
        }
        area.draw(&Text::new(
            label.clone(),
            (kx + 42, y),
            legend_style().pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    Ok(())
}

/// Keeps the points that are at least 3 px apart on the chart (and the last
/// one): thick polylines through sub-pixel segments render jagged.
fn thin<'a, DB: DrawingBackend + 'a>(
    c: &Chart<'a, DB>,
    pts: impl IntoIterator<Item = (f64, f64)>,
) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut last: Option<(i32, i32)> = None;
    let mut pending = None;
    for p in pts {
        let b = c.backend_coord(&p);
        match last {
            Some(l) if (b.0 - l.0).pow(2) + (b.1 - l.1).pow(2) < 9 => pending = Some(p),
            _ => {
                out.push(p);
                last = Some(b);
                pending = None;
            }
        }
    }
    out.extend(pending);
    out
}

/// Draws a polyline (thinned), adding a legend entry if labelled.
pub(crate) fn curve<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    pts: impl IntoIterator<Item = (f64, f64)>,
    colour: RGBColor,
    width: u32,
    label: Option<&str>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let pts = thin(c, pts);
    c.draw_series(LineSeries::new(pts, colour.stroke_width(width)))?;
    if let Some(label) = label {
        leg.push((label.to_string(), Key::Line(colour, width)));
    }
    Ok(())
}

/// Draws one curve per vehicle, in the vehicle's colour, named in the legend.
fn vehicle_curves<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    d: &Data,
    series: &[(usize, Vec<(f64, f64)>)],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    for (k, s) in series {
        let name = d.tracks[*k].name.as_str();
        curve(c, leg, s.iter().copied(), d.colour(*k), 3, Some(name))?;
    }
    Ok(())
}

/// Draws a horizontal dashed line at `y` across `x`, adding a legend entry
/// if labelled.
#[allow(clippy::too_many_arguments)]
pub(crate) fn hline<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    x: &Range<f64>,
    y: f64,
    colour: RGBColor,
    width: u32,
    (dash, gap): (u32, u32),
    label: Option<String>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    c.draw_series(DashedLineSeries::new(
        [(x.start, y), (x.end, y)],
        dash,
        gap,
        colour.stroke_width(width),
    ))?;
    if let Some(label) = label {
        // Shorter dashes in the key, so that three fit.
        let (d, g) = (dash.min(7) as i32, if dash > 7 { 4 } else { gap as i32 });
        leg.push((label, Key::Dashed(colour, width, d, g)));
    }
    Ok(())
}

fn safe_line<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    d: &Data,
    x: &Range<f64>,
    labelled: bool,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    hline(
        c,
        leg,
        x,
        d.safe_m,
        RED,
        3,
        (14, 8),
        labelled.then(|| format!("safe distance {} m", num(d.safe_m))),
    )
}

/// Shades the obstacle passage (any follower avoiding) over the full height.
fn shade_passage<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    d: &Data,
    x: &Range<f64>,
    y: &Range<f64>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    for &(a, b) in &d.avoiding_s {
        let (a, b) = (a.max(x.start), b.min(x.end));
        if a < b {
            c.draw_series(std::iter::once(Rectangle::new(
                [(a, y.start), (b, y.end)],
                ORANGE_100.filled(),
            )))?;
        }
    }
    if !d.avoiding_s.is_empty() {
        leg.push((
            "passage (a follower avoiding)".to_string(),
            Key::Fill(ORANGE_100),
        ));
    }
    Ok(())
}

/// Marks a point with a circle and a label beside it.
fn annotate<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    x: &Range<f64>,
    p: (f64, f64),
    colour: RGBColor,
    label: String,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let right_half = p.0 > 0.5 * (x.start + x.end);
    let (anchor, dx) = if right_half {
        (HPos::Right, -14)
    } else {
        (HPos::Left, 14)
    };
    c.draw_series(std::iter::once(
        EmptyElement::at(p)
            + Circle::new((0, 0), 9, colour.stroke_width(3))
            + Text::new(
                label,
                (dx, 16),
                legend_style().pos(Pos::new(anchor, VPos::Top)),
            ),
    ))?;
    Ok(())
}

fn time_range(d: &Data) -> Range<f64> {
    0.0..d.t_end_s.max(1.0)
}

fn draw_xy<DB: DrawingBackend>(d: &Data, area: &DrawingArea<DB, Shift>) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    // Horizontal axis north, vertical axis east pointing down (a view from
    // above, not mirrored): plotted as −east with the labels negated back.
    let (n, e) = d.xy_ranges();
    let (pw, ph) = plot_px(area.dim_in_pixel());
    // Equal scale: widen whichever range is too short for its pixels.
    let m_per_px = ((n.end - n.start) / pw).max((e.end - e.start) / ph);
    let (nc, ec) = (0.5 * (n.start + n.end), 0.5 * (e.start + e.end));
    let n = nc - 0.5 * m_per_px * pw..nc + 0.5 * m_per_px * pw;
    let y = -(ec + 0.5 * m_per_px * ph)..-(ec - 0.5 * m_per_px * ph);
    let (plot, legend_area) = split_legend(area);
    let mut leg = Legend::new();
    let mut c = chart(&plot).build_cartesian_2d(n, y)?;
    mesh(
        &mut c,
        "north x (m)",
        "east y (m), increasing downwards",
        true,
    )?;
    draw_obstacles(
        &mut c,
        &mut leg,
        d.obstacles.iter().map(footprint),
        |(pn, pe)| (pn, -pe),
    )?;
    draw_tracks(&mut c, &mut leg, d, |p| (p.x, -p.y))?;
    draw_legend(&legend_area, &leg)
}

fn draw_xz<DB: DrawingBackend>(d: &Data, area: &DrawingArea<DB, Shift>) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let mut n = Bounds::default();
    let mut z = Bounds::default();
    for t in &d.tracks {
        for p in &t.p {
            n.add(p.x);
            z.add(p.z);
        }
    }
    let n = n.padded(0.04, 5.0);
    let z = z.padded(0.15, 4.0);
    let (plot, legend_area) = split_legend(area);
    let mut leg = Legend::new();
    let mut c = chart(&plot).build_cartesian_2d(n, -z.end..-z.start)?;
    mesh(&mut c, "north x (m)", "depth z (m), down positive", true)?;
    draw_obstacles(
        &mut c,
        &mut leg,
        d.obstacles.iter().map(side_profile),
        |(pn, pz)| (pn, -pz),
    )?;
    draw_tracks(&mut c, &mut leg, d, |p| (p.x, -p.z))?;
    draw_legend(&legend_area, &leg)
}

/// Obstacles as filled outlines.
fn draw_obstacles<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    shapes: impl Iterator<Item = Vec<(f64, f64)>>,
    map: impl Fn((f64, f64)) -> (f64, f64),
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let mut any = false;
    for shape in shapes {
        let pts: Vec<(f64, f64)> = shape.into_iter().map(&map).collect();
        let Some(&p0) = pts.first() else { continue };
        c.draw_series(std::iter::once(Polygon::new(
            pts.clone(),
            GREY_300.filled(),
        )))?;
        let mut outline = pts;
        outline.push(p0);
        c.draw_series(std::iter::once(PathElement::new(
            outline,
            GREY_700.stroke_width(2),
        )))?;
        any = true;
    }
    if any {
        leg.push(("obstacle".to_string(), Key::Fill(GREY_300)));
    }
    Ok(())
}

/// Every vehicle's track with start (circle) and end (square) markers.
fn draw_tracks<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    d: &Data,
    map: impl Fn(&Vector3<f64>) -> (f64, f64),
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    for (k, t) in d.tracks.iter().enumerate() {
        let col = d.colour(k);
        curve(c, leg, t.p.iter().map(&map), col, 3, Some(&t.name))?;
        if let (Some(a), Some(b)) = (t.p.first(), t.p.last()) {
            c.draw_series(std::iter::once(
                EmptyElement::at(map(a)) + Circle::new((0, 0), 7, col.filled()),
            ))?;
            c.draw_series(std::iter::once(
                EmptyElement::at(map(b)) + Rectangle::new([(-7, -7), (7, 7)], col.filled()),
            ))?;
        }
    }
    leg.push(("start".to_string(), Key::Dot(GREY_500)));
    leg.push(("end".to_string(), Key::Square(GREY_500)));
    Ok(())
}

fn draw_obstacle_distance<DB: DrawingBackend>(
    d: &Data,
    area: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let series: Vec<(usize, Vec<(f64, f64)>)> = match &d.field {
        Some(field) => d
            .followers
            .iter()
            .map(|f| {
                let t = &d.tracks[f.track];
                let pts = t
                    .t_ns
                    .iter()
                    .zip(&t.p)
                    .map(|(&ts, p)| (secs(ts), field.distance(&Point3::from(*p))))
                    .collect();
                (f.track, pts)
            })
            .collect(),
        None => Vec::new(),
    };
    // The closest approach of any follower.
    let closest = series
        .iter()
        .flat_map(|(k, s)| s.iter().map(move |p| (*k, *p)))
        .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1));

    let (plots, legend_area) = split_legend(area);
    let mut leg = Legend::new();
    let (_, h) = plots.dim_in_pixel();
    let (top, bottom) = plots.split_vertically(h * 52 / 100);
    let top = titled(&top, "whole run", 34, subtitle_style())?;

    // Whole run.
    let mut y = Bounds::default();
    y.add(0.0);
    y.add(d.safe_m);
    series.iter().flat_map(|(_, s)| s).for_each(|p| y.add(p.1));
    let y_full = 0.0..y.hi.unwrap_or(1.0) * 1.05;
    let x = time_range(d);
    let mut c = chart(&top).build_cartesian_2d(x.clone(), y_full.clone())?;
    mesh(&mut c, "time (s)", "clearance (m)", false)?;
    shade_passage(&mut c, &mut leg, d, &x, &y_full)?;
    vehicle_curves(&mut c, &mut leg, d, &series)?;
    if d.field.is_none() {
        c.draw_series(std::iter::once(Text::new(
            "no obstacles in this scenario",
            (x.end * 0.4, y_full.end * 0.5),
            desc_style(),
        )))?;
    }
    safe_line(&mut c, &mut leg, d, &x, true)?;

    // Zoom on the times any follower is near an obstacle.
    let y_zoom = 0.0..(4.0 * d.safe_m)
        .max(closest.map_or(0.0, |c| 2.0 * c.1 .1))
        .max(1.0);
    let mut tw = Bounds::default();
    for (_, s) in &series {
        s.iter()
            .filter(|p| p.1 < y_zoom.end)
            .for_each(|p| tw.add(p.0));
    }
    let x_zoom = match (tw.lo, tw.hi) {
        (Some(a), Some(b)) => (a - 5.0).max(x.start)..(b + 5.0).min(x.end).max(a + 1.0),
        _ => x.clone(),
    };
    let bottom = titled(
        &bottom,
        &format!("closest approach: clearance below {} m", num(y_zoom.end)),
        34,
        subtitle_style(),
    )?;
    let mut c = chart(&bottom).build_cartesian_2d(x_zoom.clone(), y_zoom.clone())?;
    mesh(&mut c, "time (s)", "clearance (m)", false)?;
    let mut unused = Legend::new();
    shade_passage(&mut c, &mut unused, d, &x_zoom, &y_zoom)?;
    for (k, s) in &series {
        let inside: Vec<(f64, f64)> = s
            .iter()
            .copied()
            .filter(|p| x_zoom.contains(&p.0))
            .collect();
        for run in runs_below(&inside, y_zoom.end) {
            curve(&mut c, &mut unused, run, d.colour(*k), 3, None)?;
        }
    }
    safe_line(&mut c, &mut unused, d, &x_zoom, false)?;
    if let Some((k, p)) = closest {
        let label = format!(
            "closest {} m ({}) at t = {} s",
            num((p.1 * 100.0).round() / 100.0),
            d.tracks[k].name,
            num((p.0 * 10.0).round() / 10.0)
        );
        annotate(&mut c, &x_zoom, p, d.colour(k), label)?;
    }
    draw_legend(&legend_area, &leg)
}

/// The parts of a curve at or below `top`, each ending where it crosses `top`
/// (linearly interpolated), so that a zoomed plot shows no clamped lines.
fn runs_below(pts: &[(f64, f64)], top: f64) -> Vec<Vec<(f64, f64)>> {
    let cross = |a: (f64, f64), b: (f64, f64)| {
        let f = (top - a.1) / (b.1 - a.1);
        (a.0 + f * (b.0 - a.0), top)
    };
    let mut runs = Vec::new();
    let mut run: Vec<(f64, f64)> = Vec::new();
    for (i, &p) in pts.iter().enumerate() {
        let prev = i.checked_sub(1).map(|j| pts[j]);
        if p.1 <= top {
            if let Some(q) = prev.filter(|q| q.1 > top) {
                run.push(cross(q, p));
            }
            run.push(p);
        } else if let Some(q) = prev.filter(|q| q.1 <= top) {
            run.push(cross(q, p));
            runs.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    runs
}

/// Colour of pair `k` of `n`.
fn pair_colour(k: usize, n: usize) -> RGBColor {
    if n <= VEHICLE_COLOURS.len() {
        VEHICLE_COLOURS[(k + 1) % VEHICLE_COLOURS.len()]
    } else {
        let c = HSLColor(k as f64 / n as f64, 0.75, 0.42).to_rgba();
        RGBColor(c.0, c.1, c.2)
    }
}

fn draw_pairs<DB: DrawingBackend>(d: &Data, area: &DrawingArea<DB, Shift>) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let pairs = d.pair_series();
    let mut y = Bounds::default();
    y.add(0.0);
    y.add(d.safe_m);
    pairs.iter().flat_map(|(_, s)| s).for_each(|p| y.add(p.1));
    let y = 0.0..y.hi.unwrap_or(1.0) * 1.05;
    let x = time_range(d);
    let (plot, legend_area) = split_legend(area);
    let mut leg = Legend::new();
    let mut c = chart(&plot).build_cartesian_2d(x.clone(), y.clone())?;
    mesh(
        &mut c,
        "time (s)",
        "distance between the two vehicles (m)",
        false,
    )?;
    shade_passage(&mut c, &mut leg, d, &x, &y)?;
    let n = pairs.len();
    for (k, (label, s)) in pairs.iter().enumerate() {
        curve(
            &mut c,
            &mut leg,
            s.iter().copied(),
            pair_colour(k, n),
            2,
            Some(label),
        )?;
    }
    safe_line(&mut c, &mut leg, d, &x, true)?;
    draw_legend(&legend_area, &leg)
}

fn draw_min_distance<DB: DrawingBackend>(
    d: &Data,
    area: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let pairs = d.pair_series();
    // Minimum over pairs at each time (the pair series share the first
    // vehicle's sample times).
    let mut min: Vec<(f64, f64, usize)> = Vec::new();
    for (k, (_, s)) in pairs.iter().enumerate() {
        for &(t, v) in s {
            match min.binary_search_by(|m| m.0.total_cmp(&t)) {
                Ok(i) => {
                    if v < min[i].1 {
                        min[i] = (t, v, k);
                    }
                }
                Err(i) => min.insert(i, (t, v, k)),
            }
        }
    }
    let mut y = Bounds::default();
    y.add(0.0);
    y.add(d.safe_m * 1.5);
    min.iter().for_each(|p| y.add(p.1));
    let y = 0.0..y.hi.unwrap_or(1.0) * 1.1;
    let x = time_range(d);
    let (plot, legend_area) = split_legend(area);
    let mut leg = Legend::new();
    let mut c = chart(&plot).build_cartesian_2d(x.clone(), y.clone())?;
    mesh(
        &mut c,
        "time (s)",
        "minimum distance over all pairs (m)",
        false,
    )?;
    shade_passage(&mut c, &mut leg, d, &x, &y)?;
    curve(
        &mut c,
        &mut leg,
        min.iter().map(|m| (m.0, m.1)),
        BLUE,
        3,
        Some("minimum pairwise distance"),
    )?;
    safe_line(&mut c, &mut leg, d, &x, true)?;
    hline(
        &mut c,
        &mut leg,
        &x,
        d.collision_m,
        BLACK,
        2,
        (4, 6),
        Some(format!("collision distance {} m", num(d.collision_m))),
    )?;
    if let Some(m) = min.iter().min_by(|a, b| a.1.total_cmp(&b.1)) {
        let label = format!(
            "min {} m ({}) at t = {} s",
            num((m.1 * 100.0).round() / 100.0),
            pairs.get(m.2).map_or("", |p| p.0.as_str()),
            num((m.0 * 10.0).round() / 10.0)
        );
        annotate(&mut c, &x, (m.0, m.1), BLUE, label)?;
    }
    draw_legend(&legend_area, &leg)
}

fn draw_slot_error<DB: DrawingBackend>(
    d: &Data,
    area: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let series: Vec<(usize, Vec<(f64, f64)>)> = d
        .followers
        .iter()
        .map(|f| (f.track, d.slot_error(f)))
        .collect();
    let mut y = Bounds::default();
    y.add(0.0);
    y.add(1.0);
    series.iter().flat_map(|(_, s)| s).for_each(|p| y.add(p.1));
    let y = 0.0..y.hi.unwrap_or(1.0) * 1.05;
    let x = time_range(d);
    let (plot, legend_area) = split_legend(area);
    let mut leg = Legend::new();
    let mut c = chart(&plot).build_cartesian_2d(x.clone(), y.clone())?;
    mesh(
        &mut c,
        "time (s)",
        "distance from the nominal slot (m)",
        false,
    )?;
    shade_passage(&mut c, &mut leg, d, &x, &y)?;
    vehicle_curves(&mut c, &mut leg, d, &series)?;
    draw_legend(&legend_area, &leg)
}

/// Colours of the variants in the comparison figure.
const VARIANT_COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
];

/// One variant's curves for the comparison figure.
struct VariantSeries {
    name: String,
    /// RMS over followers of the slot error, `(t s, m)`.
    slot_rms: Vec<(f64, f64)>,
    /// Minimum pairwise distance, `(t s, m)`.
    min_pair: Vec<(f64, f64)>,
    /// Valid parent fixes per second per follower (camera frames or modem
    /// packets), in windows of [`FIX_WINDOW_S`], `(window centre s, Hz)`.
    fix_rate: Vec<(f64, f64)>,
}

/// Width of the windows over which the fix rate is pooled, s.
const FIX_WINDOW_S: f64 = 2.0;

impl VariantSeries {
    fn load(name: &str, scenario: &Scenario, rec: &Recording) -> anyhow::Result<(Self, Data)> {
        let d = Data::load(scenario, rec)?;
        // RMS slot error over followers at the first follower's sample times.
        let per: Vec<Vec<(f64, f64)>> = d.followers.iter().map(|f| d.slot_error(f)).collect();
        let mut slot_rms = Vec::new();
        if let Some(first) = per.first() {
            for (i, &(t, _)) in first.iter().enumerate() {
                let vals: Vec<f64> = per
                    .iter()
                    .filter_map(|s| s.get(i).filter(|p| (p.0 - t).abs() < 1e-6).map(|p| p.1))
                    .collect();
                if vals.len() == per.len() {
                    let ms = vals.iter().map(|v| v * v).sum::<f64>() / vals.len() as f64;
                    slot_rms.push((t, ms.sqrt()));
                }
            }
        }
        let mut min_pair: Vec<(f64, f64)> = Vec::new();
        for (_, s) in d.pair_series() {
            if min_pair.is_empty() {
                min_pair = s;
                continue;
            }
            for (m, p) in min_pair.iter_mut().zip(s) {
                m.1 = m.1.min(p.1);
            }
        }
        let windows = (d.t_end_s / FIX_WINDOW_S).ceil().max(1.0) as usize;
        let mut counts = vec![0u64; windows];
        for f in &d.followers {
            let topic = format!("/{}/leader_pose", d.tracks[f.track].name);
            for p in rec.samples::<ipc_types::LeaderPose>(&topic) {
                let k = ((secs(p.header.sim_time_ns) / FIX_WINDOW_S) as usize).min(windows - 1);
                counts[k] += u64::from(p.valid != 0);
            }
        }
        let per_window = FIX_WINDOW_S * d.followers.len().max(1) as f64;
        let fix_rate = counts
            .iter()
            .enumerate()
            .map(|(k, &c)| ((k as f64 + 0.5) * FIX_WINDOW_S, c as f64 / per_window))
            .collect();
        Ok((
            Self {
                name: name.to_string(),
                slot_rms,
                min_pair,
                fix_rate,
            },
            d,
        ))
    }
}

/// Title of the comparison figure.
const COMPARE_TITLE: &str =
    "Method vs acoustic baseline vs no vertical shift: slot error, minimum distance, parent fix rate";

/// Writes `compare.png` and `compare.svg` into `dir`: three panels over time
/// (RMS slot error over followers, minimum pairwise distance against the safe
/// distance, valid fixes of the parent per second), one curve per variant, the
/// first variant's passage shaded. The vertical scale of the first two panels
/// is set by the first variant (the method); a curve that leaves it is clipped
/// at the top and its legend entry says so.
pub fn write_compare_plot(
    variants: &[(&str, &Scenario, &Recording)],
    dir: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    register_font()?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut series = Vec::with_capacity(variants.len());
    let mut first: Option<Data> = None;
    for (name, scenario, rec) in variants {
        let (s, d) =
            VariantSeries::load(name, scenario, rec).with_context(|| format!("variant {name}"))?;
        series.push(s);
        if first.is_none() {
            first = Some(d);
        }
    }
    let d = first.context("no variants to compare")?;
    let size = (WIDTH, 1500);
    let png = dir.join("compare.png");
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        draw_compare(&d, &series, &root).with_context(|| format!("drawing {}", png.display()))?;
        root.present()
            .with_context(|| format!("writing {}", png.display()))?;
    }
    let svg = dir.join("compare.svg");
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        draw_compare(&d, &series, &root).with_context(|| format!("drawing {}", svg.display()))?;
        root.present()
            .with_context(|| format!("writing {}", svg.display()))?;
    }
    Ok(vec![png, svg])
}

fn draw_compare<DB: DrawingBackend>(
    d: &Data,
    series: &[VariantSeries],
    root: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let body = titled(root, COMPARE_TITLE, TITLE_H as u32, caption_style())?;
    let panels = body.split_evenly((3, 1));
    let x = 0.0..series
        .iter()
        .flat_map(|s| s.slot_rms.last().map(|p| p.0))
        .fold(d.t_end_s, f64::max)
        .max(1.0);
    let colour = |k: usize| VARIANT_COLOURS[k % VARIANT_COLOURS.len()];
    type Pick = fn(&VariantSeries) -> &Vec<(f64, f64)>;
    let picks: [(Pick, &str, &str); 3] = [
        (
            |s| &s.slot_rms,
            "slot error, RMS over followers (m)",
            "(a) slot error",
        ),
        (
            |s| &s.min_pair,
            "minimum pairwise distance (m)",
            "(b) minimum distance",
        ),
        (
            |s| &s.fix_rate,
            "parent fixes per follower (Hz, 2 s windows)",
            "(c) parent fix rate",
        ),
    ];
    for (i, (pick, y_desc, sub)) in picks.iter().enumerate() {
        let area = titled(&panels[i], sub, 34, subtitle_style())?;
        let mut yb = Bounds::default();
        yb.add(0.0);
        if i == 1 {
            yb.add(d.safe_m * 1.5);
        }
        // A baseline that diverges must not flatten the others: the scale is
        // the method's (or every variant's, for the fix rate).
        let scaled = if i == 2 { series } else { &series[..1] };
        scaled.iter().flat_map(pick).for_each(|p| yb.add(p.1));
        let y = 0.0..yb.hi.unwrap_or(1.0).max(0.5) * 1.15;
        let (plot, legend_area) = split_legend(&area);
        let mut leg = Legend::new();
        let mut c = chart(&plot).build_cartesian_2d(x.clone(), y.clone())?;
        mesh(&mut c, "time (s)", y_desc, false)?;
        shade_passage(&mut c, &mut leg, d, &x, &y)?;
        for (k, s) in series.iter().enumerate() {
            let max = pick(s).iter().map(|p| p.1).fold(0.0, f64::max);
            let label = if max > y.end {
                format!("{} (clipped; max {})", s.name, num(max.round()))
            } else {
                s.name.clone()
            };
            let pts = pick(s).iter().map(|&(t, v)| (t, v.min(y.end)));
            curve(&mut c, &mut leg, pts, colour(k), 3, Some(&label))?;
        }
        if i == 1 {
            safe_line(&mut c, &mut leg, d, &x, true)?;
        }
        draw_legend(&legend_area, &leg)?;
    }
    Ok(())
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
                Fig::PairDistances => "L–F2",
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
