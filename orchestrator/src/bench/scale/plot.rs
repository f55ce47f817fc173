//! The figure of `shoal bench scale`: cost and real-time factor against N.

use super::*;

/// Points `(N, value)` of the rows that ran.
pub(crate) fn series(rows: &[Row], value: impl Fn(&Row, &Figures) -> f64) -> Vec<(f64, f64)> {
    rows.iter()
        .filter_map(|r| {
            let f = r.figures()?;
            let v = value(r, f);
            v.is_finite().then_some((r.vehicles as f64, v))
        })
        .collect()
}

/// Writes `scale.png` and `scale.svg` into `dir`; nothing when no run
/// finished.
pub(crate) fn write_plot(rows: &[Row], title: &str, dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    if rows.iter().all(|r| r.figures().is_none()) {
        return Ok(Vec::new());
    }
    plots::register_font()?;
    let size = (plots::WIDTH, 1300);
    let png = dir.join("scale.png");
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        draw_scale(rows, title, &root).with_context(|| format!("drawing {}", png.display()))?;
        root.present()
            .with_context(|| format!("writing {}", png.display()))?;
    }
    let svg = dir.join("scale.svg");
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        draw_scale(rows, title, &root).with_context(|| format!("drawing {}", svg.display()))?;
        root.present()
            .with_context(|| format!("writing {}", svg.display()))?;
    }
    Ok(vec![png, svg])
}

/// Two panels against N: (a) CPU per vehicle-second with issue 8's bound
/// (1.5 × the cost at N = 25), (b) real-time factor with the 1× line.
pub(crate) fn draw_scale<DB: DrawingBackend>(
    rows: &[Row],
    title: &str,
    root: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let body = plots::titled(root, title, plots::TITLE_H as u32, plots::caption_style())?;
    let panels = body.split_evenly((2, 1));
    let max_n = rows.iter().map(|r| r.vehicles).max().unwrap_or(1) as f64;
    let x = 0.0..(max_n * 1.08).max(2.0);
    let blue = RGBColor(31, 119, 180);
    let red = RGBColor(214, 39, 40);
    let reference = rows
        .iter()
        .find(|r| r.vehicles == REFERENCE_N)
        .and_then(Row::cost);
    let cost = series(rows, |r, f| f.cpu_ms_per_vehicle_s(r.vehicles));
    let rtf = series(rows, |_, f| f.rtf());
    // The bound needs the cost at N = 25: the subtitle promises the dashed
    // line only when that size was run.
    let cost_sub = if reference.is_some() {
        format!(
            "(a) cost per vehicle-second (every process, orchestrator included; \
             dashed: issue 8's bound, {COST_RATIO_BOUND} x the cost at N = {REFERENCE_N})"
        )
    } else {
        format!(
            "(a) cost per vehicle-second (every process, orchestrator included; \
             no bound: N = {REFERENCE_N} was not run)"
        )
    };
    type Panel<'p> = (&'p [(f64, f64)], &'p str, &'p str, Option<(f64, String)>);
    let panel_specs: [Panel; 2] = [
        (
            &cost,
            "total CPU time per vehicle-second (ms)",
            &cost_sub,
            reference.map(|c| {
                (
                    COST_RATIO_BOUND * c,
                    format!("{COST_RATIO_BOUND} x cost at N = {REFERENCE_N}"),
                )
            }),
        ),
        (
            &rtf,
            "real-time factor (simulated s / wall s)",
            "(b) real-time factor (issue 8's goal: >= 1x at N = 100)",
            Some((1.0, "real time (1x)".to_string())),
        ),
    ];
    for (i, (pts, y_desc, sub, line)) in panel_specs.iter().enumerate() {
        let area = plots::titled(&panels[i], sub, 34, plots::subtitle_style())?;
        let top = pts
            .iter()
            .map(|p| p.1)
            .chain(line.as_ref().map(|l| l.0))
            .fold(0.0, f64::max);
        let y = 0.0..(top * 1.2).max(1e-3);
        let (plot, legend_area) = plots::split_legend(&area);
        let mut leg = plots::Legend::new();
        let mut c = plots::chart(&plot).build_cartesian_2d(x.clone(), y.clone())?;
        plots::mesh(&mut c, "vehicles N", y_desc, false)?;
        if let Some((v, label)) = line {
            plots::hline(
                &mut c,
                &mut leg,
                &x,
                *v,
                red,
                3,
                (14, 8),
                Some(label.clone()),
            )?;
        }
        let name = if i == 0 {
            "measured cost"
        } else {
            "measured real-time factor"
        };
        plots::curve(&mut c, &mut leg, pts.iter().copied(), blue, 3, None)?;
        c.draw_series(pts.iter().map(|&p| {
            EmptyElement::at(p)
                + Circle::new((0, 0), 8, blue.filled())
                + Text::new(
                    plots::num((p.1 * 100.0).round() / 100.0),
                    (10, -12),
                    plots::legend_style().pos(Pos::new(HPos::Left, VPos::Bottom)),
                )
        }))?;
        leg.insert(0, (name.to_string(), plots::Key::Dot(blue)));
        plots::draw_legend(&legend_area, &leg)?;
    }
    Ok(())
}
