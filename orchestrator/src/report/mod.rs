//! `report.html`: one self-contained page a person opens in a browser after
//! a run (or `shoal summarize`): the verdict, the summary's key figures,
//! every figure, and a top-view animation of the run drawn from the
//! recording. Nothing is fetched: the figures are inlined as data URLs, the
//! animation's data as JSON and its player as a short script.
//!
//! The page checks itself as it runs, for a headless browser to read back
//! from the DOM: `body[data-ready]` once the player has started,
//! `data-frames` the frames drawn so far, `data-images` the figures that
//! decoded, and `#errors` every script error or figure that failed.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use base64::Engine as _;
use recordings::Recording;
use serde::Serialize;
use shoal_scenario::Scenario;

use crate::analysis::summary::{fmt_or_na, min_value, Summary};
use crate::analysis::track::Tracks;
use crate::plots;

/// The file name.
pub const FILE: &str = "report.html";

/// Animation frames per simulated second.
pub const FRAME_HZ: f64 = 4.0;

/// The animation's data: every vehicle's track in the horizontal plane at
/// [`FRAME_HZ`], and every obstacle's outline seen from above.
#[derive(Debug, Serialize)]
struct Animation {
    /// Simulated time of each frame, s.
    t: Vec<f64>,
    vehicles: Vec<AnimVehicle>,
    /// Outlines, (north, east) points, m.
    obstacles: Vec<Vec<[f64; 2]>>,
    /// The safe distance, m (the circle drawn around each vehicle).
    safe_distance_m: f64,
    /// The legend of a group coloured by file: (label, `#rrggbb`), the leader
    /// first; empty when every vehicle is named beside its dot.
    files: Vec<(String, String)>,
}

#[derive(Debug, Serialize)]
struct AnimVehicle {
    name: String,
    parent: Option<String>,
    /// `#rrggbb`, as in the figures ([`plots::colours`]).
    colour: String,
    /// (north, east) per frame, m; null before the vehicle's first sample.
    ne: Vec<Option<[f64; 2]>>,
}

fn round2(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

fn animation(scenario: &Scenario, rec: &Recording) -> Animation {
    let tracks = Tracks::load(scenario, rec);
    let end_ns = tracks.end_ns();
    let step_ns = (1e9 / FRAME_HZ) as u64;
    let times: Vec<u64> = (0..=end_ns / step_ns).map(|i| i * step_ns).collect();
    let colouring = plots::colours::Colouring::of(scenario);
    let vehicles = scenario
        .vehicles
        .iter()
        .enumerate()
        .map(|(k, v)| AnimVehicle {
            name: v.name.clone(),
            parent: v.parent.clone(),
            colour: plots::colours::hex(colouring.colour(k)),
            ne: times
                .iter()
                .map(|&t| {
                    tracks
                        .get(&v.name)
                        .and_then(|tr| tr.at(t))
                        .map(|(p, _)| [round2(p.x), round2(p.y)])
                })
                .collect(),
        })
        .collect();
    let obstacles = scenario
        .obstacles_as::<sonar::Obstacle>()
        .unwrap_or_default()
        .iter()
        .map(|o| {
            plots::geometry::footprint(o)
                .into_iter()
                .map(|(n, e)| [round2(n), round2(e)])
                .collect()
        })
        .collect();
    Animation {
        t: times.iter().map(|&t| t as f64 * 1e-9).collect(),
        vehicles,
        obstacles,
        safe_distance_m: scenario.safety.safe_distance_m,
        files: colouring
            .files()
            .iter()
            .map(|(label, c)| (label.clone(), plots::colours::hex(*c)))
            .collect(),
    }
}

/// Text made safe to put between HTML tags.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The key figures as (group, label, value, passed?) rows.
fn key_figures(s: &Summary) -> Vec<(&'static str, &'static str, String, Option<bool>)> {
    let f = &s.safety;
    let m = |x: Option<f64>| fmt_or_na(x, 2);
    let lost = s.perception.parent_lost.len();
    vec![
        (
            "run",
            "simulated",
            format!(
                "{:.1} s in {:.1} s ({:.1}x real time), {}",
                s.sim_time_s,
                s.wall_time_s,
                s.real_time_factor,
                esc(&s.mode)
            ),
            None,
        ),
        (
            "run",
            "group",
            format!(
                "{} vehicles, {} processes, seed {}",
                s.vehicles, s.processes, s.seed
            ),
            None,
        ),
        (
            "safety",
            "collisions",
            format!(
                "{} between vehicles, {} with obstacles",
                f.collisions,
                f.obstacle_contacts.len()
            ),
            Some(f.collisions == 0 && f.obstacle_contacts.is_empty()),
        ),
        (
            "safety",
            "closest pair",
            format!(
                "{} m ({}) against the safe {} m",
                m(f.min_pair_distance_m),
                esc(&f.min_pair),
                f.safe_distance_m
            ),
            f.min_pair_distance_m.map(|d| d >= f.safe_distance_m),
        ),
        (
            "safety",
            "closest obstacle",
            format!(
                "{} m against {} m (half the safe distance)",
                m(f.min_obstacle_clearance_m),
                f.safe_distance_m / 2.0
            ),
            f.min_obstacle_clearance_m
                .map(|d| d >= f.safe_distance_m / 2.0),
        ),
        (
            "perception",
            "parent lost > 5 s",
            format!("{lost} follower(s)"),
            Some(lost == 0),
        ),
        (
            "perception",
            "least share of frames with a fix",
            fmt_or_na(s.min_parent_visible(), 3),
            None,
        ),
        (
            "perception",
            "pose error p50 / p95",
            format!(
                "{} / {} m",
                m(s.perception.pose_error_m.p50),
                m(s.perception.pose_error_m.p95)
            ),
            None,
        ),
        (
            "formation",
            "slot error rms before / during / after the passage",
            format!(
                "{} / {} / {} m",
                m(s.formation.slot_error_rms_m.before),
                m(s.formation.slot_error_rms_m.during),
                m(s.formation.slot_error_rms_m.after)
            ),
            None,
        ),
        (
            "formation",
            "slot error rms, last 30 s",
            format!("{} m", m(s.formation.slot_error_rms_final_m)),
            None,
        ),
        (
            "mission",
            "leader's goal error",
            format!("{} m", m(s.mission.leader_goal_error_m)),
            None,
        ),
        (
            "software",
            "sensor to thrust p50 / p99",
            format!(
                "{:.0} / {:.0} µs",
                s.latency_us.end_to_end.p50, s.latency_us.end_to_end.p99
            ),
            None,
        ),
        (
            "software",
            "camera frame to thrust p50 / p99 (stages, p50)",
            format!(
                "{:.0} / {:.0} µs ({})",
                s.latency_us.frame_to_thrust.p50,
                s.latency_us.frame_to_thrust.p99,
                s.latency_us
                    .chain
                    .iter()
                    .map(|c| format!("{} {:.0}", c.stage, c.us.p50))
                    .collect::<Vec<_>>()
                    .join(" · ")
            ),
            None,
        ),
        (
            "software",
            "MPC solve p50 / p99",
            if s.mpc.solves > 0 {
                format!(
                    "{:.0} / {:.0} µs ({:.0} % without clarabel)",
                    s.mpc.solve_us.p50,
                    s.mpc.solve_us.p99,
                    100.0 * s.mpc.unconstrained as f64 / s.mpc.solves as f64
                )
            } else {
                format!("{:.0} / {:.0} µs", s.mpc.solve_us.p50, s.mpc.solve_us.p99)
            },
            None,
        ),
        (
            "software",
            "recording",
            format!(
                "{} messages, {} dropped{}",
                s.recording.messages,
                s.recording.dropped,
                if s.recording.truncated {
                    ", truncated"
                } else {
                    ""
                }
            ),
            Some(s.recording.dropped == 0),
        ),
    ]
}

const STYLE: &str = r#"
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; padding: 0 1em; }
h1 { margin-bottom: 0.2em; }
.verdict { display: inline-block; padding: 0.2em 0.8em; border-radius: 4px; color: #fff; font-weight: bold; }
.pass { background: #2a8a3e; } .fail { background: #c0392b; }
table { border-collapse: collapse; margin: 1em 0; }
td, th { border-bottom: 1px solid #ddd; padding: 0.3em 0.8em; text-align: left; vertical-align: top; }
td.ok { color: #2a8a3e; } td.bad { color: #c0392b; font-weight: bold; }
figure { margin: 1.5em 0; } figure img { width: 100%; border: 1px solid #ddd; }
figcaption { color: #555; font-size: 0.95em; }
#player canvas { border: 1px solid #ccc; background: #fbfbfd; width: 100%; max-width: 1000px; }
#player .controls { margin: 0.5em 0; display: flex; gap: 1em; align-items: center; }
#player input[type=range] { flex: 1; }
#errors { color: #c0392b; }
"#;

/// The player: draws frame `i` of `DATA` on the canvas, top view with north
/// up and east to the right; play/pause, a time slider and a speed choice.
const PLAYER: &str = r#"
(function () {
  const errors = document.getElementById('errors');
  function fail(msg) { errors.textContent += msg + '\n'; }
  window.addEventListener('error', e => fail('script error: ' + e.message));
  const body = document.body;
  let images = 0;
  for (const img of document.querySelectorAll('figure img')) {
    const done = () => {
      if (img.naturalWidth > 0) { images += 1; body.dataset.images = images; }
      else fail('figure did not load: ' + img.alt);
    };
    if (img.complete) done(); else { img.addEventListener('load', done); img.addEventListener('error', done); }
  }
  const D = JSON.parse(document.getElementById('data').textContent);
  const canvas = document.getElementById('view');
  const ctx = canvas.getContext('2d');
  const slider = document.getElementById('time');
  const button = document.getElementById('play');
  const speed = document.getElementById('speed');
  const label = document.getElementById('clock');
  const view = document.getElementById('mode');
  slider.max = D.t.length - 1;
  let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
  const grow = p => { if (!p) return; for (let k = 0; k < 2; k++) { lo[k] = Math.min(lo[k], p[k]); hi[k] = Math.max(hi[k], p[k]); } };
  D.vehicles.forEach(v => v.ne.forEach(grow));
  D.obstacles.forEach(o => o.forEach(grow));
  if (!isFinite(lo[0])) { lo = [-10, -10]; hi = [10, 10]; }
  const pad = 5;
  // North to the right and east down, as in fig. 6; equal scales.
  let scale = 1, cx = 0, cy = 0;
  const X = n => (n - cx) * scale + canvas.width / 2;
  const Y = e => (e - cy) * scale + canvas.height / 2;
  function frameView(i) {
    if (view.value === 'follow') {
      let s = [0, 0], k = 0, glo = [Infinity, Infinity], ghi = [-Infinity, -Infinity];
      for (const v of D.vehicles) {
        const p = v.ne[i]; if (!p) continue;
        s[0] += p[0]; s[1] += p[1]; k += 1;
        for (let j = 0; j < 2; j++) { glo[j] = Math.min(glo[j], p[j]); ghi[j] = Math.max(ghi[j], p[j]); }
      }
      if (k > 0) {
        cx = s[0] / k; cy = s[1] / k;
        const w = Math.max(60, ghi[0] - glo[0] + 30), h = Math.max(36, ghi[1] - glo[1] + 20);
        scale = Math.min(canvas.width / w, canvas.height / h);
        return;
      }
    }
    cx = (lo[0] + hi[0]) / 2; cy = (lo[1] + hi[1]) / 2;
    scale = Math.min(canvas.width / (hi[0] - lo[0] + 2 * pad), canvas.height / (hi[1] - lo[1] + 2 * pad));
  }
  // A large group is coloured by file (D.files: its legend) and its
  // vehicles go unnamed; a small one names every vehicle beside its dot.
  const named = D.files.length === 0;
  function legend() {
    if (named) return;
    ctx.font = '12px sans-serif';
    const w = 12 + Math.max(...D.files.map(f => ctx.measureText(f[0]).width)) + 36, h = 8 + 18 * D.files.length;
    ctx.fillStyle = 'rgba(255,255,255,0.85)'; ctx.fillRect(8, 8, w, h);
    ctx.strokeStyle = '#888'; ctx.strokeRect(8, 8, w, h);
    D.files.forEach((f, k) => {
      const y = 8 + 13 + 18 * k;
      ctx.fillStyle = f[1]; ctx.fillRect(16, y - 5, 22, 6);
      ctx.fillStyle = '#222'; ctx.fillText(f[0], 44, y + 1);
    });
  }
  const index = {}; D.vehicles.forEach((v, i) => index[v.name] = i);
  let frame = 0, playing = true, last = null, drawn = 0;
  function draw(i) {
    frameView(i);
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    ctx.fillStyle = '#9aa5b1';
    for (const o of D.obstacles) {
      ctx.beginPath(); o.forEach((p, k) => k ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))); ctx.closePath(); ctx.fill();
    }
    D.vehicles.forEach((v, vi) => {
      const c = v.colour;
      ctx.strokeStyle = c; ctx.globalAlpha = 0.35; ctx.beginPath();
      let started = false;
      for (let k = 0; k <= i; k++) { const p = v.ne[k]; if (!p) continue; if (started) ctx.lineTo(X(p[0]), Y(p[1])); else { ctx.moveTo(X(p[0]), Y(p[1])); started = true; } }
      ctx.stroke(); ctx.globalAlpha = 1;
    });
    D.vehicles.forEach((v, vi) => {
      const p = v.ne[i]; if (!p) return;
      const q = v.parent !== null && index[v.parent] !== undefined ? D.vehicles[index[v.parent]].ne[i] : null;
      if (q) { ctx.strokeStyle = '#bbb'; ctx.setLineDash([4, 4]); ctx.beginPath(); ctx.moveTo(X(p[0]), Y(p[1])); ctx.lineTo(X(q[0]), Y(q[1])); ctx.stroke(); ctx.setLineDash([]); }
    });
    D.vehicles.forEach((v, vi) => {
      const p = v.ne[i]; if (!p) return;
      const c = v.colour;
      ctx.strokeStyle = c; ctx.globalAlpha = 0.25; ctx.beginPath(); ctx.arc(X(p[0]), Y(p[1]), D.safe_distance_m / 2 * scale, 0, 2 * Math.PI); ctx.stroke(); ctx.globalAlpha = 1;
      ctx.fillStyle = c; ctx.beginPath(); ctx.arc(X(p[0]), Y(p[1]), 4, 0, 2 * Math.PI); ctx.fill();
      if (named) { ctx.font = '12px sans-serif'; ctx.fillText(v.name, X(p[0]) + 6, Y(p[1]) - 6); }
    });
    legend();
    label.textContent = 't = ' + D.t[i].toFixed(1) + ' s';
    slider.value = i;
    drawn += 1; body.dataset.frames = drawn;
  }
  // Timers, not requestAnimationFrame, drive the animation: a page that is
  // hidden or headless (a browser under a virtual clock) may never be given
  // an animation frame, while timers run everywhere at a steady rate.
  function tick() {
    const now = performance.now();
    if (playing && last !== null) {
      const dt = (now - last) / 1000 * Number(speed.value);
      frame = Math.min(D.t.length - 1, frame + dt * (D.t.length > 1 ? 1 / (D.t[1] - D.t[0]) : 0));
      if (frame >= D.t.length - 1) playing = false, button.textContent = 'play';
      draw(Math.floor(frame));
    }
    last = now;
    setTimeout(tick, 1000 / 30);
  }
  button.addEventListener('click', () => { playing = !playing; if (playing && frame >= D.t.length - 1) frame = 0; button.textContent = playing ? 'pause' : 'play'; });
  slider.addEventListener('input', () => { frame = Number(slider.value); draw(frame); });
  view.addEventListener('change', () => draw(Math.floor(frame)));
  draw(0);
  body.dataset.ready = '1';
  setTimeout(tick, 1000 / 30);
})();
"#;

/// How to look at the run in Foxglove and Rerun: the files beside the
/// report, linked relatively.
const VIEWERS: &str = "<h2 id=\"viewers\">In Foxglove and Rerun</h2>\n<p>The run's recording, <a href=\"recording.mcap\">recording.mcap</a>, opens as it is in Foxglove (Open local file: every channel in its <code>shoal_msgs</code> schema, the camera frames in the Image panel) and in Rerun (<code>rerun recording.mcap</code>).</p>\n<p>For the 3D scene (obstacles, hulls, slots, sonar beams, lines of sight, poses), <code>shoal export recording.mcap --foxglove foxglove.mcap</code> writes <a href=\"foxglove.mcap\">foxglove.mcap</a> beside this page in Foxglove's own schemas: in Foxglove, Open local file, then a 3D panel with display frame <code>world</code>; in Rerun, <code>rerun foxglove.mcap</code> (transforms, poses and scene updates).</p>\n<p>While a run goes, <code>shoal run --live</code> serves it to Foxglove (Open connection, Foxglove WebSocket, <code>ws://127.0.0.1:8765</code>) and <code>shoal top</code> shows its processes.</p>\n";

/// Writes `report.html` into `out`: `summary` and `scenario` of the run,
/// its figures from `out/plots/`, its animation from `rec`. Returns the
/// file.
pub fn write_report(
    out: &Path,
    summary: &Summary,
    scenario: &Scenario,
    rec: &Recording,
) -> anyhow::Result<PathBuf> {
    let mut h = String::with_capacity(1 << 20);
    let title = format!("shoal: {}", esc(&summary.scenario));
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n"
    );
    let (class, word) = if summary.verdict.pass {
        ("pass", "PASS")
    } else {
        ("fail", "FAIL")
    };
    let _ = writeln!(
        h,
        "<h1>{}</h1>\n<p><span class=\"verdict {class}\" id=\"verdict\">{word}</span> {}</p>",
        esc(&summary.scenario),
        esc(&scenario.description)
    );
    if !summary.verdict.failed.is_empty() {
        h.push_str("<ul id=\"failed\">\n");
        for f in &summary.verdict.failed {
            let _ = writeln!(h, "<li>{}</li>", esc(f));
        }
        h.push_str("</ul>\n");
    }
    h.push_str("<pre id=\"errors\"></pre>\n<h2>Key figures</h2>\n<table id=\"figures\">\n");
    for (group, label, value, ok) in key_figures(summary) {
        let class = match ok {
            Some(true) => " class=\"ok\"",
            Some(false) => " class=\"bad\"",
            None => "",
        };
        let _ = writeln!(
            h,
            "<tr><th>{group}</th><td>{label}</td><td{class}>{value}</td></tr>"
        );
    }
    h.push_str("</table>\n");
    if let Some(min_vis) = min_value(&summary.perception.leader_visible_fraction) {
        let _ = writeln!(
            h,
            "<p>Every follower had its parent in view in at least {:.1} % of its camera frames.</p>",
            100.0 * min_vis
        );
    }
    h.push_str("<h2>The run from above</h2>\n<div id=\"player\">\n<div class=\"controls\"><button id=\"play\">pause</button><input type=\"range\" id=\"time\" min=\"0\" value=\"0\"><span id=\"clock\"></span><label>speed <select id=\"speed\"><option value=\"1\">1x</option><option value=\"5\">5x</option><option value=\"10\" selected>10x</option><option value=\"30\">30x</option></select></label><label>view <select id=\"mode\"><option value=\"follow\" selected>follow the group</option><option value=\"course\">whole course</option></select></label></div>\n<canvas id=\"view\" width=\"1000\" height=\"600\"></canvas>\n<p>Top view, north to the right and east down (as in fig. 6); faint circles are half the safe distance around each vehicle, dashed lines join each follower to its parent.</p>\n</div>\n");
    h.push_str("<h2>Figures</h2>\n");
    let plots_dir = out.join("plots");
    for (stem, caption) in plots::figure_list() {
        let png = plots_dir.join(format!("{stem}.png"));
        let bytes =
            std::fs::read(&png).with_context(|| format!("cannot read {}", png.display()))?;
        let b64 = base64::engine::general_purpose::STANDARD.encode(&bytes);
        let _ = writeln!(
            h,
            "<figure><img alt=\"{stem}\" src=\"data:image/png;base64,{b64}\"><figcaption>{}</figcaption></figure>",
            esc(caption)
        );
    }
    h.push_str(VIEWERS);
    let data = serde_json::to_string(&animation(scenario, rec))?;
    // `</` cannot end the script element early inside JSON.
    let data = data.replace("</", "<\\/");
    let _ = write!(
        h,
        "<script type=\"application/json\" id=\"data\">{data}</script>\n<script>{PLAYER}</script>\n</body>\n</html>\n"
    );
    let path = out.join(FILE);
    std::fs::write(&path, h).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}
