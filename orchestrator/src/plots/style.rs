//! The chart toolkit every figure is drawn with: text styles, the titled
//! area, a chart with its mesh, the legend column, thinned curves, lines.

use super::*;

/// Height reserved for the title, px.
pub(crate) const TITLE_H: f64 = 56.0;

#[derive(Default)]
pub(crate) struct Bounds {
    pub(crate) lo: Option<f64>,
    pub(crate) hi: Option<f64>,
}

impl Bounds {
    pub(crate) fn add(&mut self, v: f64) {
        if v.is_finite() {
            self.lo = Some(self.lo.map_or(v, |l| l.min(v)));
            self.hi = Some(self.hi.map_or(v, |h| h.max(v)));
        }
    }
    /// The range padded by `frac` of its length (at least `min_len` long).
    pub(crate) fn padded(&self, frac: f64, min_len: f64) -> Range<f64> {
        let (lo, hi) = match (self.lo, self.hi) {
            (Some(l), Some(h)) => (l, h),
            _ => (0.0, 1.0),
        };
        let mid = 0.5 * (lo + hi);
        let half = (0.5 * (hi - lo)).max(0.5 * min_len) * (1.0 + 2.0 * frac);
        mid - half..mid + half
    }
}

pub(crate) fn caption_style() -> TextStyle<'static> {
    (FONT, 30).into_font().color(&BLACK)
}

pub(crate) fn subtitle_style() -> TextStyle<'static> {
    (FONT, 24).into_font().color(&BLACK)
}

pub(crate) fn desc_style() -> TextStyle<'static> {
    (FONT, 22).into_font().color(&BLACK)
}

pub(crate) fn tick_style() -> TextStyle<'static> {
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
pub(crate) const LEGEND_W: u32 = 330;

/// Plotting-area size of a chart built by [`chart`] on the left of an area
/// of `(w, h)` px split by [`split_legend`].
pub(crate) fn plot_px((w, h): (u32, u32)) -> (f64, f64) {
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
    mesh_with(c, x_desc, y_desc, negate_y, (12, &|v| num(*v)))
}

/// [`mesh`] with `x_labels` ticks on the horizontal axis, named by `x_fmt`.
pub(crate) fn mesh_with<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    x_desc: &str,
    y_desc: &str,
    negate_y: bool,
    (x_labels, x_fmt): (usize, &dyn Fn(&f64) -> String),
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let fy = move |v: &f64| num(if negate_y { -*v } else { *v });
    c.configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(x_fmt)
        .y_label_formatter(&fy)
        .x_labels(x_labels)
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
pub(crate) fn thin<'a, DB: DrawingBackend + 'a>(
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
