//! The figure of `shoal campaign`: pass rate per family, and every run's
//! closest approach to another vehicle and to an obstacle against their
//! limits.

use super::*;
use crate::campaign::{Report, Status};

const PASS: RGBColor = RGBColor(44, 160, 44);
const FAIL: RGBColor = RGBColor(214, 39, 40);
const PAIR: RGBColor = RGBColor(31, 119, 180);
const CLEAR: RGBColor = RGBColor(255, 127, 14);

/// Writes `campaign.png` and `campaign.svg` into `dir`.
pub fn write_campaign_plot(r: &Report, dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    register_font()?;
    let size = (WIDTH, 1300);
    let png = dir.join("campaign.png");
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        draw_campaign(r, &root).with_context(|| format!("drawing {}", png.display()))?;
        root.present()
            .with_context(|| format!("writing {}", png.display()))?;
    }
    let svg = dir.join("campaign.svg");
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        draw_campaign(r, &root).with_context(|| format!("drawing {}", svg.display()))?;
        root.present()
            .with_context(|| format!("writing {}", svg.display()))?;
    }
    Ok(vec![png, svg])
}

fn draw_campaign<DB: DrawingBackend>(
    r: &Report,
    root: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let overall = r
        .overall
        .pass_rate
        .map_or("n/a".into(), |p| format!("{:.1} %", 100.0 * p));
    let body = titled(
        root,
        &format!(
            "Campaign: {} of {}, {} courses x {} seeds, {} of {} runs pass ({overall})",
            r.shape, r.vehicles, r.courses, r.seeds, r.overall.passed, r.overall.runs
        ),
        TITLE_H as u32,
        caption_style(),
    )?;
    let (top, bottom) = body.split_vertically(body.dim_in_pixel().1 * 2 / 5);
    let n = r.by_family.len().max(1) as f64;
    let x = -0.5..n - 0.5;
    // pass rate per family
    let (plot, legend_area) = split_legend(&top);
    let mut c = chart(&plot).build_cartesian_2d(x.clone(), 0.0..105.0)?;
    family_mesh(&mut c, r, "family", "runs that pass (%)")?;
    for (i, f) in r.by_family.iter().enumerate() {
        let Some(p) = f.pass_rate else { continue };
        let i = i as f64;
        let colour = if f.passed == f.runs { PASS } else { FAIL };
        c.draw_series(std::iter::once(Rectangle::new(
            [(i - 0.3, 0.0), (i + 0.3, 100.0 * p)],
            colour.filled(),
        )))?;
    }
    let mut leg: Legend = vec![
        ("every run passes".into(), Key::Fill(PASS)),
        ("some run fails".into(), Key::Fill(FAIL)),
    ];
    hline(
        &mut c,
        &mut leg,
        &x,
        98.0,
        BLACK,
        2,
        (10, 6),
        Some("98 %".into()),
    )?;
    draw_legend(&legend_area, &leg)?;

    // closest approaches per run
    let (plot, legend_area) = split_legend(&bottom);
    let mut b = Bounds::default();
    b.add(0.0);
    for run in &r.runs {
        b.add(run.min_pair_m.unwrap_or(f64::NAN));
        b.add(run.clearance_m.unwrap_or(f64::NAN));
    }
    let y = 0.0..b.hi.unwrap_or(5.0) * 1.05;
    let mut c = chart(&plot).build_cartesian_2d(x.clone(), y)?;
    family_mesh(&mut c, r, "family (each dot a run)", "closest approach (m)")?;
    let mut leg: Legend = Vec::new();
    for (fi, f) in r.by_family.iter().enumerate() {
        let runs: Vec<_> = r
            .runs
            .iter()
            .filter(|run| run.family == f.family && run.status != Status::Interrupted)
            .collect();
        let k = runs.len().max(1) as f64;
        for (j, run) in runs.iter().enumerate() {
            let xx = fi as f64 - 0.35 + 0.7 * (j as f64 + 0.5) / k;
            if let Some(v) = run.min_pair_m {
                c.draw_series(std::iter::once(Circle::new((xx, v), 4, PAIR.filled())))?;
            }
            if let Some(v) = run.clearance_m {
                c.draw_series(std::iter::once(Circle::new((xx, v), 4, CLEAR.filled())))?;
            }
        }
    }
    leg.push(("min pair distance".into(), Key::Dot(PAIR)));
    leg.push(("obstacle clearance".into(), Key::Dot(CLEAR)));
    let safe = crate::gen::SAFE_DISTANCE_M;
    hline(
        &mut c,
        &mut leg,
        &x,
        safe,
        PAIR,
        2,
        (10, 6),
        Some("safe distance".into()),
    )?;
    hline(
        &mut c,
        &mut leg,
        &x,
        safe / 2.0,
        CLEAR,
        2,
        (10, 6),
        Some("half of it".into()),
    )?;
    draw_legend(&legend_area, &leg)?;
    Ok(())
}

/// Grid, ticks and axis names of a chart whose x axis is the families (one
/// per integer, named).
fn family_mesh<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    r: &Report,
    x_desc: &str,
    y_desc: &str,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let names: Vec<String> = r.by_family.iter().map(|f| f.family.clone()).collect();
    let label = move |v: &f64| {
        let i = v.round();
        if (v - i).abs() < 1e-6 && i >= 0.0 {
            names.get(i as usize).cloned().unwrap_or_default()
        } else {
            String::new()
        }
    };
    mesh_with(
        c,
        x_desc,
        y_desc,
        false,
        (r.by_family.len() * 2 + 1, &label),
    )
}
