//! The figures of one run (figs. 6-11 of the paper and the slot error).

use super::*;

/// Draws one figure on a backend.
pub(crate) fn draw<DB: DrawingBackend>(
    fig: Fig,
    d: &Data,
    root: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let body = titled(root, fig.title(), TITLE_H as u32, caption_style())?;
    match fig {
        Fig::TrajectoriesXy => draw_xy(d, &body),
        Fig::TrajectoriesXz => draw_xz(d, &body),
        Fig::ObstacleDistance => draw_obstacle_distance(d, &body),
        Fig::ParentDistances => draw_pairs(d, &body, true),
        Fig::PairDistances => draw_pairs(d, &body, false),
        Fig::MinDistance => draw_min_distance(d, &body),
        Fig::SlotError => draw_slot_error(d, &body),
    }
}

/// Draws one curve per vehicle, in the vehicle's colour, named in the legend.
pub(crate) fn vehicle_curves<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    leg: &mut Legend,
    d: &Data,
    series: &[(usize, Vec<(f64, f64)>)],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    for (k, s) in series {
        curve(c, leg, s.iter().copied(), d.colour(*k), 3, d.label(*k))?;
    }
    d.file_legend(leg);
    Ok(())
}

pub(crate) fn safe_line<'a, DB: DrawingBackend + 'a>(
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

/// The vertical range of a plot from zero: up to the largest of `values`
/// and `floor`, with `headroom` (1.05 = 5 % above).
pub(crate) fn y_from_zero(
    values: impl IntoIterator<Item = f64>,
    floor: f64,
    headroom: f64,
) -> Range<f64> {
    let mut y = Bounds::default();
    y.add(0.0);
    y.add(floor);
    values.into_iter().for_each(|v| y.add(v));
    0.0..y.hi.unwrap_or(1.0) * headroom
}

/// A plot of the run against time on `plot`: its mesh with `y_desc` up,
/// the passage shaded; returns the chart and its legend so far.
pub(crate) fn time_axes<'a, DB: DrawingBackend + 'a>(
    plot: &'a DrawingArea<DB, Shift>,
    d: &Data,
    y: &Range<f64>,
    y_desc: &str,
) -> anyhow::Result<(Chart<'a, DB>, Legend)>
where
    DB::ErrorType: 'static,
{
    let x = time_range(d);
    let mut leg = Legend::new();
    let mut c = chart(plot).build_cartesian_2d(x.clone(), y.clone())?;
    mesh(&mut c, "time (s)", y_desc, false)?;
    shade_passage(&mut c, &mut leg, d, &x, y)?;
    Ok((c, leg))
}

/// Shades the obstacle passage (any follower avoiding) over the full height.
pub(crate) fn shade_passage<'a, DB: DrawingBackend + 'a>(
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
pub(crate) fn annotate<'a, DB: DrawingBackend + 'a>(
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

pub(crate) fn time_range(d: &Data) -> Range<f64> {
    0.0..d.t_end_s.max(1.0)
}

pub(crate) fn draw_xy<DB: DrawingBackend>(
    d: &Data,
    area: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
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

pub(crate) fn draw_xz<DB: DrawingBackend>(
    d: &Data,
    area: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
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
    // Seen from the side, an obstacle the group passes beside (no track
    // point inside its footprint) would look like a wall swum through:
    // it is drawn as a pale band with its own key.
    let (on_track, beside): (Vec<_>, Vec<_>) = d.obstacles.iter().partition(|o| {
        let f = footprint(o);
        d.tracks
            .iter()
            .any(|t| t.p.iter().any(|p| inside(&f, (p.x, p.y))))
    });
    draw_obstacles(
        &mut c,
        &mut leg,
        on_track.iter().map(|o| side_profile(o)),
        |(pn, pz)| (pn, -pz),
    )?;
    let mut any_beside = false;
    for o in &beside {
        let pts: Vec<(f64, f64)> = side_profile(o)
            .into_iter()
            .map(|(pn, pz)| (pn, -pz))
            .collect();
        c.draw_series(std::iter::once(Polygon::new(pts, PALE_OBSTACLE.filled())))?;
        any_beside = true;
    }
    if any_beside {
        leg.push((
            "obstacle, passed beside".to_string(),
            Key::Fill(PALE_OBSTACLE),
        ));
    }
    draw_tracks(&mut c, &mut leg, d, |p| (p.x, -p.z))?;
    // What the vertical shift asks for: D_b/2 × the progress toward the
    // parent's track (eq. 5), filtered (eq. 9); a shift that stops part-way
    // asks for part of D_b/2.
    let mut any_asked = false;
    for (k, pts) in &d.depth_commands {
        if pts.is_empty() {
            continue;
        }
        let col = d.colour(*k);
        c.draw_series(DashedLineSeries::new(
            pts.iter().map(|&(n, z)| (n, -z)),
            10,
            6,
            col.stroke_width(2),
        ))?;
        match d.label(*k) {
            Some(name) => leg.push((
                format!("{name} depth asked (eq. 5)"),
                Key::Dashed(col, 2, 7, 4),
            )),
            None => any_asked = true,
        }
    }
    if any_asked {
        leg.push((
            "depth asked (eq. 5)".to_string(),
            Key::Dashed(GREY_500, 2, 7, 4),
        ));
    }
    draw_legend(&legend_area, &leg)
}

/// The fill of an obstacle the group passes beside, in a side view.
const PALE_OBSTACLE: RGBColor = RGBColor(236, 238, 241);

/// True when `p` lies inside the polygon `poly` (even-odd rule).
fn inside(poly: &[(f64, f64)], p: (f64, f64)) -> bool {
    let mut odd = false;
    for (i, a) in poly.iter().enumerate() {
        let b = poly[(i + 1) % poly.len()];
        if (a.1 > p.1) != (b.1 > p.1) && p.0 < a.0 + (p.1 - a.1) * (b.0 - a.0) / (b.1 - a.1) {
            odd = !odd;
        }
    }
    odd
}

/// Obstacles as filled outlines.
pub(crate) fn draw_obstacles<'a, DB: DrawingBackend + 'a>(
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
pub(crate) fn draw_tracks<'a, DB: DrawingBackend + 'a>(
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
        curve(c, leg, t.p.iter().map(&map), col, 3, d.label(k))?;
        if let (Some(a), Some(b)) = (t.p.first(), t.p.last()) {
            c.draw_series(std::iter::once(
                EmptyElement::at(map(a)) + Circle::new((0, 0), 7, col.filled()),
            ))?;
            c.draw_series(std::iter::once(
                EmptyElement::at(map(b)) + Rectangle::new([(-7, -7), (7, 7)], col.filled()),
            ))?;
        }
    }
    d.file_legend(leg);
    leg.push(("start".to_string(), Key::Dot(GREY_500)));
    leg.push(("end".to_string(), Key::Square(GREY_500)));
    Ok(())
}

pub(crate) fn draw_obstacle_distance<DB: DrawingBackend>(
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
pub(crate) fn runs_below(pts: &[(f64, f64)], top: f64) -> Vec<Vec<(f64, f64)>> {
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

/// Colour of pair `k` of `n`: distinct for up to 9, hues that keep clear
/// of red beyond.
pub(crate) fn pair_colour(k: usize, n: usize) -> RGBColor {
    // The vehicles' palette from its second colour, without the red of the
    // safe-distance line; the leader's black last.
    let palette: Vec<RGBColor> = VEHICLE_COLOURS[1..]
        .iter()
        .copied()
        .filter(|c| *c != VEHICLE_COLOURS[2])
        .chain(std::iter::once(VEHICLE_COLOURS[0]))
        .collect();
    if n <= palette.len() {
        palette[k % palette.len()]
    } else {
        let c = HSLColor(0.08 + 0.84 * k as f64 / n as f64, 0.75, 0.42).to_rgba();
        RGBColor(c.0, c.1, c.2)
    }
}

/// Fig. 9 (`parents`: each follower and its parent) or fig. 10 (every
/// other pair).
pub(crate) fn draw_pairs<DB: DrawingBackend>(
    d: &Data,
    area: &DrawingArea<DB, Shift>,
    parents: bool,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let pairs = d.pair_series_where(|i, j| d.linked(i, j) == parents);
    let y = y_from_zero(
        pairs.iter().flat_map(|(_, s)| s).map(|p| p.1),
        d.safe_m,
        1.05,
    );
    let (plot, legend_area) = split_legend(area);
    let x = time_range(d);
    let (mut c, mut leg) = time_axes(&plot, d, &y, "distance between the two vehicles (m)")?;
    let n = pairs.len();
    // a pair per legend row up to a dozen; beyond, one row says how many
    let named = n <= colours::MAX_NAMED_VEHICLES;
    for (k, (label, s)) in pairs.iter().enumerate() {
        curve(
            &mut c,
            &mut leg,
            s.iter().copied(),
            pair_colour(k, n),
            2,
            named.then_some(label.as_str()),
        )?;
    }
    if !named {
        leg.push((format!("{n} pairs, one line each"), Key::Line(GREY_500, 2)));
    }
    safe_line(&mut c, &mut leg, d, &x, true)?;
    draw_legend(&legend_area, &leg)
}

pub(crate) fn draw_min_distance<DB: DrawingBackend>(
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
    let y = y_from_zero(min.iter().map(|p| p.1), d.safe_m * 1.5, 1.1);
    let (plot, legend_area) = split_legend(area);
    let x = time_range(d);
    let (mut c, mut leg) = time_axes(&plot, d, &y, "minimum distance over all pairs (m)")?;
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

pub(crate) fn draw_slot_error<DB: DrawingBackend>(
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
    let y = y_from_zero(series.iter().flat_map(|(_, s)| s).map(|p| p.1), 1.0, 1.05);
    let (plot, legend_area) = split_legend(area);
    let (mut c, mut leg) = time_axes(&plot, d, &y, "distance from the nominal slot (m)")?;
    vehicle_curves(&mut c, &mut leg, d, &series)?;
    draw_legend(&legend_area, &leg)
}
