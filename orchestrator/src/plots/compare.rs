//! The comparison figure of `shoal compare`: one curve per variant.

use super::*;

/// Colours of the variants in the comparison figure.
pub(crate) const VARIANT_COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
];

/// One variant's curves for the comparison figure.
pub(crate) struct VariantSeries {
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
pub(crate) const FIX_WINDOW_S: f64 = 2.0;

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
pub(crate) const COMPARE_TITLE: &str =
    "Method vs as published vs acoustic baseline vs no vertical shift: slot error, minimum distance, parent fix rate";

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

pub(crate) fn draw_compare<DB: DrawingBackend>(
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
        // The method (the first) is drawn last and widest, so that a
        // variant that runs with it never hides it; the key keeps the order.
        let width = |k: usize| if k == 0 { 4 } else { 2 };
        for (k, s) in series.iter().enumerate().rev() {
            let pts = pick(s).iter().map(|&(t, v)| (t, v.min(y.end)));
            curve(&mut c, &mut leg, pts, colour(k), width(k), None)?;
        }
        for (k, s) in series.iter().enumerate() {
            let max = pick(s).iter().map(|p| p.1).fold(0.0, f64::max);
            let label = if max > y.end {
                format!("{} (clipped; max {})", s.name, num(max.round()))
            } else {
                s.name.clone()
            };
            leg.push((label, Key::Line(colour(k), width(k))));
        }
        if i == 1 {
            safe_line(&mut c, &mut leg, d, &x, true)?;
        }
        draw_legend(&legend_area, &leg)?;
    }
    Ok(())
}
