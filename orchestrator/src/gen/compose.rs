//! Composed courses (`--course composed`): a route that strings together two
//! to five features drawn from the whole space the generator covers, instead
//! of one family's pattern.
//!
//! * **Gaps** of any width the formation can pass: from the narrowest (its
//!   outermost files shifted inward, [`super::narrowest_gap_m`]) up to its
//!   full width with the safe distance to either wall, centred on the track
//!   or up to 6 m off it, walls of equal or unequal length; several in a
//!   row, a group's length plus 10-25 m apart.
//! * **Turns** of 20-100°, and **U-turns** of 100-180° (two half turns a
//!   short leg apart, as a leader flies them); **S-bends** of 20-60° and back.
//! * **Fields** of 3-7 cylinders or spheres of radius 0.3-1.5 m across the
//!   formation's width, each pair at least a drawn gap apart; a sphere's
//!   centre within half its radius of the route's depth (a horizontal sonar
//!   sees only a sliver of one well above or below its plane).
//! * **Walls at any angle**: a funnel or a skewed channel at 5-45° to the
//!   track.
//! * **Depth changes** of 3-8 m over 40 m.
//! * **Currents** of 0.05-0.3 m/s from any direction over one feature's
//!   stretch or the whole course (a zone of the plant's current field,
//!   [`sim_plant::current`]).
//!
//! Features are laid out in order with the room the presets use (a gap
//! [`super::course::TURN_CLEAR_M`] past a turn's arc, a turn a group's length past a gap).
//! A draw whose solids come near the route away from their own feature (a
//! U-turn's return leg past an earlier wall) is drawn again. Every course
//! has at least one feature with solids; `--with` puts the features asked
//! for in slots drawn at random. The rendered file carries a forward-looking
//! multibeam (`[sonar] multibeam`, 16 cones over 120°): with obstacles down
//! to 0.3 m the paper's four 7° cones leave too much of the track unseen.

use serde::{Deserialize, Serialize};
use sim_plant::current::CurrentZone;

use super::course::{side, Builder, Course, Family, Geom, SLALOM_ROOM_M};
use super::{mm, SplitMix, SAFE_DISTANCE_M};

/// A kind of feature on a composed course (the campaign tallies runs per kind).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Serialize,
    Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Feature {
    /// A gap between two walls.
    Gap,
    /// A turn of 20-100°.
    Turn,
    /// A turn of 100-180°.
    UTurn,
    /// Two opposite turns of 20-60°.
    SBend,
    /// A field of cylinders.
    Cylinders,
    /// A field of spheres.
    Spheres,
    /// Walls at an angle to the track (a funnel or a skewed channel).
    Walls,
    /// A change of depth.
    Depth,
    /// A zone of current.
    Current,
}

impl Feature {
    /// Every kind, in order.
    pub const ALL: [Feature; 9] = [
        Feature::Gap,
        Feature::Turn,
        Feature::UTurn,
        Feature::SBend,
        Feature::Cylinders,
        Feature::Spheres,
        Feature::Walls,
        Feature::Depth,
        Feature::Current,
    ];

    /// Name, as in the tables.
    pub fn name(self) -> &'static str {
        match self {
            Feature::Gap => "gap",
            Feature::Turn => "turn",
            Feature::UTurn => "u-turn",
            Feature::SBend => "s-bend",
            Feature::Cylinders => "cylinders",
            Feature::Spheres => "spheres",
            Feature::Walls => "walls",
            Feature::Depth => "depth",
            Feature::Current => "current",
        }
    }

    /// Whether the feature puts obstacles in the water.
    pub fn is_solid(self) -> bool {
        matches!(
            self,
            Feature::Gap | Feature::Cylinders | Feature::Spheres | Feature::Walls
        )
    }
}

impl std::fmt::Display for Feature {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Least features on a composed course.
pub const MIN_FEATURES: usize = 2;
/// Most features on a composed course.
pub const MAX_FEATURES: usize = 5;
/// Smallest radius of a cylinder or sphere, m.
pub const MIN_RADIUS_M: f64 = 0.3;
/// Strongest current, m/s.
pub const MAX_CURRENT_MPS: f64 = 0.3;
/// How near the route a solid may come away from its own feature, beyond the
/// formation's half width, m.
const AWAY_CLEAR_M: f64 = 10.0;
/// Draws before a course without U-turns is accepted.
const DRAWS: usize = 24;

/// The structural features (a current is laid over them) and their weights.
const KINDS: [(Feature, f64); 8] = [
    (Feature::Gap, 3.0),
    (Feature::Turn, 1.2),
    (Feature::UTurn, 0.6),
    (Feature::SBend, 0.8),
    (Feature::Cylinders, 1.2),
    (Feature::Spheres, 0.8),
    (Feature::Walls, 1.0),
    (Feature::Depth, 0.8),
];

/// One feature as laid: its kind, its stretch of route, the solids it placed.
struct Laid {
    kind: Feature,
    from_m: f64,
    to_m: f64,
    solids: std::ops::Range<usize>,
}

/// Builds a composed course for the formation `g` (deterministic in `rng`).
pub(super) fn build(g: Geom, rng: &mut SplitMix, with: &[Feature]) -> Course {
    let forced_uturn = with.contains(&Feature::UTurn);
    for draw in 0..DRAWS {
        let uturns = forced_uturn || draw + 1 < DRAWS;
        if let Some(c) = draw_once(g, rng, uturns, with) {
            return c;
        }
    }
    // unreachable in practice (a course without U-turns never doubles back);
    // a plain course keeps the generator total
    let mut b = Builder::new(g, rng);
    let s0 = b.next_gate_start(0.0);
    let len = b.wall_len();
    b.gate(s0, len, len, 0.0);
    let mut c = b.finish(Family::Composed, "a gap on the track".into());
    c.features = vec![Feature::Gap];
    c
}

/// The half width of a drawn gap: between the narrowest the formation passes
/// and its full width with the safe distance to either wall.
fn half_gap(b: &mut Builder<'_>) -> f64 {
    let lo = b.g.half_gap_m;
    let hi = (b.g.outer_m + SAFE_DISTANCE_M).max(lo);
    mm(lo + (hi - lo) * b.u())
}

/// Draws one feature by weight; `solid_only` leaves out those without
/// obstacles (a course always has something to avoid).
fn pick(b: &mut Builder<'_>, uturns: bool, solid_only: bool) -> Feature {
    let kinds: Vec<(Feature, f64)> = KINDS
        .iter()
        .copied()
        .filter(|(k, _)| uturns || *k != Feature::UTurn)
        .filter(|(k, _)| !solid_only || k.is_solid())
        .collect();
    let total: f64 = kinds.iter().map(|k| k.1).sum();
    let mut x = b.u() * total;
    for (k, w) in &kinds {
        if x < *w {
            return *k;
        }
        x -= w;
    }
    Feature::Gap
}

/// Where a turn of `deg` may have its vertex: after everything so far
/// (gates need the group's length, turns their arcs) and past the route's end.
fn turn_vertex(b: &mut Builder<'_>, deg: f64) -> f64 {
    let t = b.tangent(deg);
    let after_turn = if b.turns_deg.is_empty() {
        0.0
    } else {
        b.end_m + 10.0 + t
    };
    b.next_turn_at(deg).max(after_turn).max(b.route.len() + 1.0)
}

/// Where an obstacle feature may start, `room` m after the last gate.
fn obstacle_start(b: &mut Builder<'_>, last: Option<Feature>, room_behind_gap: bool) -> f64 {
    let room = match last {
        Some(Feature::Gap | Feature::Cylinders | Feature::Spheres | Feature::Walls)
            if room_behind_gap =>
        {
            b.g.group_len_m + SLALOM_ROOM_M + 15.0 * b.u()
        }
        _ => 0.0,
    };
    let s = b.next_gate_start(room) + if last.is_none() { 10.0 * b.u() } else { 0.0 };
    s.max(b.route.len())
}

fn field(b: &mut Builder<'_>, s0: f64, spheres: bool) -> String {
    let n = 3 + (5.0 * b.u()) as usize;
    let depth = 25.0 + 20.0 * b.u();
    let across = b.g.outer_m + 4.0;
    let apart = 2.0 * half_gap(b);
    b.straight_to(s0 + depth + 5.0);
    let mut placed: Vec<(f64, f64, f64)> = Vec::new();
    for _ in 0..400 {
        if placed.len() == n {
            break;
        }
        let r = MIN_RADIUS_M + 1.2 * b.u();
        let s = s0 + depth * b.u();
        let e = across * (2.0 * b.u() - 1.0);
        let room = placed
            .iter()
            .all(|&(s2, e2, r2)| ((s - s2).powi(2) + (e - e2).powi(2)).sqrt() - r - r2 >= apart);
        if room {
            placed.push((s, e, r));
        }
    }
    for &(s, e, r) in &placed {
        if spheres {
            // the equator within half a radius of the route's depth: a
            // horizontal sonar sees only a sliver of a sphere well above or
            // below its plane (vertical sensing is the sensing issue's)
            let dz = 0.5 * r * (2.0 * b.u() - 1.0);
            b.sphere(s, e, dz, r);
        } else {
            b.cylinder(s, e, r);
        }
    }
    b.gates += 1;
    format!(
        "{} {} over {depth:.0} m, {apart:.1} m apart",
        placed.len(),
        match (spheres, placed.len()) {
            (true, 1) => "sphere",
            (true, _) => "spheres",
            (false, 1) => "cylinder",
            (false, _) => "cylinders",
        }
    )
}

fn walls(b: &mut Builder<'_>, s0: f64) -> String {
    let a = 5.0 + 40.0 * b.u();
    let funnel = b.u() < 0.5;
    let len = b.wall_len();
    b.straight_to(s0 + len + 5.0);
    let half = len / 2.0;
    let hg = half_gap(b);
    let w = b.wall_half_width_for(0.0, hg);
    b.angled_pair(s0 + half, half, hg, w, a, funnel);
    format!(
        "a {} at {a:.0}°, {:.1} m wide",
        if funnel { "funnel" } else { "skewed channel" },
        2.0 * hg
    )
}

fn draw_once(g: Geom, rng: &mut SplitMix, uturns: bool, with: &[Feature]) -> Option<Course> {
    let mut b = Builder::new(g, rng);
    let mut k = MIN_FEATURES + (((MAX_FEATURES - MIN_FEATURES + 1) as f64) * b.u()) as usize;
    // the features asked for take slots drawn at random, the rest as usual
    let mut asked: Vec<Feature> = Vec::new();
    for f in with {
        if *f != Feature::Current && !asked.contains(f) {
            asked.push(*f);
        }
    }
    k = k.max(asked.len());
    let mut slots: Vec<Option<Feature>> = vec![None; k];
    for f in asked {
        let free: Vec<usize> = (0..k).filter(|i| slots[*i].is_none()).collect();
        let i = free[((free.len() as f64 * b.u()) as usize).min(free.len() - 1)];
        slots[i] = Some(f);
    }
    let mut laid: Vec<Laid> = Vec::new();
    let mut what: Vec<String> = Vec::new();
    let mut last: Option<Feature> = None;
    for i in 0..k {
        // the last free slot is a solid one if nothing else puts one in the water
        let solid_only = !laid.iter().any(|l| l.kind.is_solid())
            && slots[i + 1..]
                .iter()
                .all(|f| f.is_some_and(|f| !f.is_solid()));
        let kind = match slots[i] {
            Some(f) => f,
            None => pick(&mut b, uturns, solid_only),
        };
        let from = b.end_m;
        let first_solid = b.solids.len();
        let text = match kind {
            Feature::Gap => {
                let s0 = obstacle_start(&mut b, last, true);
                let hg = half_gap(&mut b);
                let e = if b.u() < 0.5 {
                    0.0
                } else {
                    mm(b.sign() * (0.5 + 5.5 * b.u()))
                };
                let (lp, ls) = if b.u() < 0.3 {
                    (8.0 + 24.0 * b.u(), 8.0 + 24.0 * b.u())
                } else {
                    let l = b.wall_len();
                    (l, l)
                };
                b.gate_of(s0, lp, ls, e, hg);
                if e == 0.0 {
                    format!("a gap {:.1} m wide", 2.0 * hg)
                } else {
                    format!(
                        "a gap {:.1} m wide {:.1} m to {}",
                        2.0 * hg,
                        e.abs(),
                        side(e)
                    )
                }
            }
            Feature::Turn => {
                let deg = b.sign() * (20.0 + 80.0 * b.u());
                let at = turn_vertex(&mut b, deg);
                b.turn_at(at, deg);
                format!("a turn of {:.0}° to {}", deg.abs(), side(deg))
            }
            Feature::UTurn => {
                let deg = b.sign() * (100.0 + 80.0 * b.u());
                let half = deg / 2.0;
                let at = turn_vertex(&mut b, half);
                b.turn_at(at, half);
                let leg = 2.0 * b.tangent(half) + 10.0 + 10.0 * b.u();
                b.turn_at(at + leg, half);
                format!("a turn of {:.0}° to {}", deg.abs(), side(deg))
            }
            Feature::SBend => {
                let deg = b.sign() * (20.0 + 40.0 * b.u());
                let at = turn_vertex(&mut b, deg);
                b.turn_at(at, deg);
                let leg = 2.0 * b.tangent(deg) + 10.0 + 20.0 * b.u();
                b.turn_at(at + leg, -deg);
                format!("an S-bend of {:.0}° to {} and back", deg.abs(), side(deg))
            }
            Feature::Cylinders | Feature::Spheres => {
                let s0 = obstacle_start(&mut b, last, true);
                field(&mut b, s0, kind == Feature::Spheres)
            }
            Feature::Walls => {
                let s0 = obstacle_start(&mut b, last, true);
                walls(&mut b, s0)
            }
            Feature::Depth => {
                let room_up = b.depth() - b.g.min_depth_m;
                let down = room_up < 3.0 || b.u() < 0.5;
                let dz = if down {
                    3.0 + 5.0 * b.u()
                } else {
                    -(3.0 + (room_up - 3.0).min(5.0) * b.u())
                };
                let at = (b.end_m + 10.0 + 10.0 * b.u())
                    .max(super::course::FIRST_FEATURE_M - 15.0)
                    .max(b.route.len());
                b.straight_to(at);
                let d = b.depth() + dz;
                b.route.extend(0.0, 40.0, d);
                b.end_m = b.end_m.max(at + 40.0);
                format!("{} {:.1} m", if dz > 0.0 { "down" } else { "up" }, dz.abs())
            }
            Feature::Current => String::new(),
        };
        laid.push(Laid {
            kind,
            from_m: from,
            to_m: b.end_m,
            solids: first_solid..b.solids.len(),
        });
        what.push(text);
        last = Some(kind);
    }
    // currents over one feature's stretch, or the whole course
    let mut zones = Vec::new();
    let settle = b.g.settle_m;
    if b.u() < 0.45 || with.contains(&Feature::Current) {
        let count = 1 + usize::from(b.u() < 0.3);
        for _ in 0..count {
            let m = 0.05 + (MAX_CURRENT_MPS - 0.05) * b.u();
            let from_deg = 360.0 * b.u();
            let (sa, sb) = if b.u() < 0.3 {
                (0.0, b.end_m + settle)
            } else {
                let i = ((laid.len() as f64) * b.u()) as usize;
                let l = &laid[i.min(laid.len() - 1)];
                (
                    (l.from_m - 20.0).max(0.0),
                    (l.to_m + 20.0).min(b.end_m + settle),
                )
            };
            let (p, psi) = b.route.at((sa + sb) / 2.0);
            // a current "from" a bearing flows toward its opposite
            let to = (from_deg + 180.0).to_radians();
            zones.push(CurrentZone {
                center_ne_m: [mm(p[0]), mm(p[1])],
                half_length_m: mm(((sb - sa) / 2.0).max(10.0)),
                half_width_m: mm(b.g.outer_m + 200.0),
                yaw_deg: mm(psi.to_degrees()),
                current_ned_mps: [mm(m * to.cos()), mm(m * to.sin()), 0.0],
                edge_m: 10.0,
            });
            what.push(format!("a current of {m:.2} m/s from {from_deg:.0}°"));
        }
    }
    let end_m = b.end_m;
    let course_solids = b.solids.clone();
    let pts = b.route.clone();
    let mut c = b.finish(Family::Composed, what.join(", then "));
    c.features = laid.iter().map(|l| l.kind).collect();
    if !zones.is_empty() {
        c.features.push(Feature::Current);
    }
    c.current_zones = zones;
    // a solid near the route away from its own feature: draw again
    let own: Vec<(&Laid, sonar::ObstacleField)> = laid
        .iter()
        .filter(|l| !l.solids.is_empty())
        .filter_map(|l| {
            Some((
                l,
                sonar::ObstacleField::new(&course_solids[l.solids.clone()]).ok()?,
            ))
        })
        .collect();
    let reach = g.group_len_m + 40.0;
    let clear = g.outer_m + AWAY_CLEAR_M;
    let mut s = 0.0;
    while s <= end_m + g.settle_m {
        let (p, _) = pts.at(s);
        let q = nalgebra::Point3::new(p[0], p[1], p[2]);
        let near = own
            .iter()
            .any(|(l, f)| (s < l.from_m - reach || s > l.to_m + reach) && f.distance(&q) < clear);
        if near {
            return None;
        }
        s += 2.0;
    }
    Some(c)
}
