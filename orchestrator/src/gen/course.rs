//! Obstacle courses of named families (`shoal gen --course FAMILY`): what a
//! formation meets on an ordinary route that nobody tuned the method for.
//!
//! A course is a route (the leader's waypoints from its start) and solids
//! placed along it in *route coordinates*: `s` metres along the route, `e`
//! metres to starboard of it. Every family is sized from the formation
//! ([`Geom`]): a gap is as wide as the generator's gate (`2 · half_gap_m`:
//! the inner files pass, the outer files must shift inward), walls reach
//! [`super::WALL_OVERHANG_M`] past the outermost file, and the seed draws
//! where, how long, how far off the track and which way.
//!
//! Gaps never sit on a turn: the leader flies a corner as an arc of the
//! radius its formation's view margin allows ([`planner::view`]); a gate
//! starts at least [`TURN_CLEAR_M`] past the arc's end, and the arc starts
//! at least the group's length plus [`TURN_AFTER_GATE_M`] after a gate, so
//! the formation turns in open water (but its followers may still be
//! shifted when the leader turns).

use std::f64::consts::PI;

use sonar::Obstacle as Solid;

use super::{mm, SplitMix, WALL_OVERHANG_M};

/// How far past the end of a turn's arc the next gate starts at the least, m.
pub const TURN_CLEAR_M: f64 = 25.0;
/// How far past a gate's end (beyond the group's length) a turn comes at
/// the least, m.
pub const TURN_AFTER_GATE_M: f64 = 15.0;
/// Where the first feature starts at the least, m along the route (the
/// formation needs its speed-up first).
pub const FIRST_FEATURE_M: f64 = 55.0;
/// Least room between two gaps of a slalom beyond the group's length, m:
/// closer, gaps offset opposite ways cannot be passed by a formation that
/// keeps its shape (measured: with 15-30 m between them, the paper's five
/// came within 1.4 m of each other and 0.9 m of a wall on 2 of 4 courses).
pub const SLALOM_ROOM_M: f64 = 10.0;
/// Smallest half-thickness of a wall, m.
pub const MIN_WALL_HALF_WIDTH_M: f64 = 3.0;

/// A family of courses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, clap::ValueEnum)]
pub enum Family {
    /// One gap centred on the track (the paper's narrow passage).
    Gate,
    /// One gap offset 2-6 m to port or starboard of the track.
    Offset,
    /// One gap slightly off the track whose two sides differ: walls of
    /// unequal length, or a wall and a large cylinder.
    Asymmetric,
    /// Two or three gaps in a row, offset alternately, each starting 10-25 m
    /// more than the group's length after the last ends.
    Slalom,
    /// A turn of 30-90° before, between or after gaps.
    Turn,
    /// Two opposite turns of 30-60° (the route ends parallel to its
    /// start, displaced), then a gap.
    SBend,
    /// A field of 4-7 cylinders across the route, each pair at least a gap
    /// apart.
    Cylinders,
    /// Walls at 10-25° to the track: a funnel, or a skewed channel.
    Angled,
    /// A change of depth of 3-8 m before a gap.
    Depth,
    /// A cross current of 0.1-0.3 m/s from port or starboard through a gap.
    Current,
    /// Not a preset: two to five features drawn from the whole space (gaps of
    /// any width the formation can pass, turns up to 180°, S-bends, fields of
    /// cylinders and spheres, walls at any angle, depth changes) with currents
    /// over any part.
    Composed,
}

impl Family {
    /// Every preset family, in order ([`Family::Composed`] is not one).
    pub const ALL: [Family; 10] = [
        Family::Gate,
        Family::Offset,
        Family::Asymmetric,
        Family::Slalom,
        Family::Turn,
        Family::SBend,
        Family::Cylinders,
        Family::Angled,
        Family::Depth,
        Family::Current,
    ];

    /// Name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Family::Gate => "gate",
            Family::Offset => "offset",
            Family::Asymmetric => "asymmetric",
            Family::Slalom => "slalom",
            Family::Turn => "turn",
            Family::SBend => "s-bend",
            Family::Cylinders => "cylinders",
            Family::Angled => "angled",
            Family::Depth => "depth",
            Family::Current => "current",
            Family::Composed => "composed",
        }
    }
}

impl std::fmt::Display for Family {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What the course is fitted to: the formation's size and the gate's gap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geom {
    /// Half the gap of a gate, m: the narrowest the formation passes (its
    /// outermost files shifted inward, see [`super::narrowest_gap_m`]).
    pub half_gap_m: f64,
    /// The outermost vehicle's distance from the leader's track, m.
    pub outer_m: f64,
    /// Length of the group (leader to the rearmost vehicle), m.
    pub group_len_m: f64,
    /// Route past the last feature before the goal, m.
    pub settle_m: f64,
    /// The leader's start depth, m.
    pub depth_m: f64,
    /// Shallowest depth any leader route may take, m.
    pub min_depth_m: f64,
    /// Centre depth of the walls at the start depth, m (the tree's vertical
    /// shifts make it differ from `depth_m`).
    pub z_offset_m: f64,
    /// Half height of a wall, m.
    pub half_height_m: f64,
    /// Radius of the leader's turns, m (as the planner derives it).
    pub turn_radius_m: f64,
}

/// A generated course.
#[derive(Debug, Clone, PartialEq)]
pub struct Course {
    /// The family.
    pub family: Family,
    /// One line on what this one is (the seed's draw).
    pub what: String,
    /// The solids (boxes and cylinders), NED.
    pub solids: Vec<Solid>,
    /// The leader's waypoints (NED, m), the goal last.
    pub waypoints: Vec<[f64; 3]>,
    /// Ocean current (NED, m/s), if any.
    pub current_ned_mps: Option<[f64; 3]>,
    /// Route length from the start to the goal, m.
    pub length_m: f64,
    /// Where the last feature (gap, turn, change of depth) ends, m along
    /// the route.
    pub end_m: f64,
    /// Turns, deg (signed, starboard positive).
    pub turns_deg: Vec<f64>,
    /// Gates (gaps between walls) on the route.
    pub gates: usize,
    /// What a composed course holds, in order (empty for a preset).
    pub features: Vec<super::compose::Feature>,
    /// Zones of current (a composed course's currents over parts of it).
    pub current_zones: Vec<sim_plant::current::CurrentZone>,
}

/// The route as a polyline being built: vertices in NE, their depths.
#[derive(Debug, Clone)]
pub(super) struct Route {
    /// (north, east, depth) of each vertex, the start first.
    pts: Vec<[f64; 3]>,
}

impl Route {
    fn new(depth_m: f64) -> Self {
        Self {
            pts: vec![[0.0, 0.0, depth_m]],
        }
    }
    /// The last vertex (the start until the route is extended).
    fn end(&self) -> [f64; 3] {
        self.pts.last().copied().unwrap_or_default()
    }
    pub(super) fn len(&self) -> f64 {
        self.pts
            .windows(2)
            .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
            .sum()
    }
    fn heading(&self) -> f64 {
        let n = self.pts.len();
        if n < 2 {
            return 0.0;
        }
        let (a, b) = (self.pts[n - 2], self.pts[n - 1]);
        (b[1] - a[1]).atan2(b[0] - a[0])
    }
    /// Extends the route straight on by `d` metres at the heading of the
    /// last leg turned by `turn` rad, ending at `depth`.
    pub(super) fn extend(&mut self, turn: f64, d: f64, depth: f64) {
        let psi = self.heading() + turn;
        let last = self.end();
        self.pts
            .push([last[0] + d * psi.cos(), last[1] + d * psi.sin(), depth]);
    }
    /// Point (north, east, depth) and heading at arc length `s` (straight
    /// on past the end).
    pub(super) fn at(&self, s: f64) -> ([f64; 3], f64) {
        let mut left = s;
        for w in self.pts.windows(2) {
            let (a, b) = (w[0], w[1]);
            let l = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            let psi = (b[1] - a[1]).atan2(b[0] - a[0]);
            if left <= l {
                let f = left / l;
                return (
                    [
                        a[0] + left * psi.cos(),
                        a[1] + left * psi.sin(),
                        a[2] + f * (b[2] - a[2]),
                    ],
                    psi,
                );
            }
            left -= l;
        }
        let psi = self.heading();
        let e = self.end();
        (
            [e[0] + left * psi.cos(), e[1] + left * psi.sin(), e[2]],
            psi,
        )
    }
}

/// Builds a course along a route as it is laid out.
pub(super) struct Builder<'a> {
    pub(super) g: Geom,
    rng: &'a mut SplitMix,
    pub(super) route: Route,
    pub(super) solids: Vec<Solid>,
    pub(super) end_m: f64,
    pub(super) turns_deg: Vec<f64>,
    pub(super) gates: usize,
}

impl<'a> Builder<'a> {
    pub(super) fn new(g: Geom, rng: &'a mut SplitMix) -> Self {
        Self {
            g,
            rng,
            route: Route::new(g.depth_m),
            solids: Vec::new(),
            end_m: 0.0,
            turns_deg: Vec::new(),
            gates: 0,
        }
    }
    pub(super) fn u(&mut self) -> f64 {
        self.rng.unit()
    }
    /// +1 or −1.
    pub(super) fn sign(&mut self) -> f64 {
        if self.u() < 0.5 {
            -1.0
        } else {
            1.0
        }
    }
    /// Depth at the route's current end.
    pub(super) fn depth(&self) -> f64 {
        self.route.pts.last().map_or(self.g.depth_m, |p| p[2])
    }
    /// Straight on until the route is `s` long.
    pub(super) fn straight_to(&mut self, s: f64) {
        let l = self.route.len();
        if s > l {
            let d = self.depth();
            self.route.extend(0.0, s - l, d);
        }
    }
    /// How far before and after its vertex the leader's arc of a turn of
    /// `deg` reaches, m.
    pub(super) fn tangent(&self, deg: f64) -> f64 {
        self.g.turn_radius_m * (deg.to_radians().abs() / 2.0).tan()
    }
    /// A turn of `deg` at arc length `s`.
    pub(super) fn turn_at(&mut self, s: f64, deg: f64) {
        self.straight_to(s);
        let d = self.depth();
        // a short leg carries the new heading
        self.route.extend(deg.to_radians(), 1.0, d);
        self.turns_deg.push(deg);
        self.end_m = self.end_m.max(s + self.tangent(deg));
    }
    /// A box whose centre is `s` along and `e` across, with half extents
    /// (along, across) and its yaw relative to the route.
    pub(super) fn wall(
        &mut self,
        s: f64,
        e: f64,
        half_along: f64,
        half_across: f64,
        rel_yaw_deg: f64,
    ) {
        let (p, psi) = self.route.at(s);
        let right = psi + PI / 2.0;
        self.solids.push(Solid::Box {
            center_ned_m: [
                mm(p[0] + e * right.cos()),
                mm(p[1] + e * right.sin()),
                mm(p[2] + self.g.z_offset_m),
            ],
            half_extents_m: [mm(half_along), mm(half_across), mm(self.g.half_height_m)],
            yaw_deg: mm((psi.to_degrees() + rel_yaw_deg + 540.0).rem_euclid(360.0) - 180.0),
        });
        self.end_m = self.end_m.max(s + half_along);
    }
    /// A sphere of radius `r`, `s` along, `e` across and `dz` below the route.
    pub(super) fn sphere(&mut self, s: f64, e: f64, dz: f64, r: f64) {
        let (p, psi) = self.route.at(s);
        let right = psi + PI / 2.0;
        self.solids.push(Solid::Sphere {
            center_ned_m: [
                mm(p[0] + e * right.cos()),
                mm(p[1] + e * right.sin()),
                mm(p[2] + dz),
            ],
            radius_m: mm(r),
        });
        self.end_m = self.end_m.max(s + r);
    }
    pub(super) fn cylinder(&mut self, s: f64, e: f64, r: f64) {
        let (p, psi) = self.route.at(s);
        let right = psi + PI / 2.0;
        self.solids.push(Solid::Cylinder {
            center_ned_m: [
                mm(p[0] + e * right.cos()),
                mm(p[1] + e * right.sin()),
                mm(p[2] + self.g.z_offset_m),
            ],
            radius_m: mm(r),
            half_height_m: mm(self.g.half_height_m),
        });
        self.end_m = self.end_m.max(s + r);
    }
    /// Half-thickness of the walls of a gap centred `e` off the track, so
    /// they reach past the outermost file on either side.
    fn wall_half_width(&self, e: f64) -> f64 {
        self.wall_half_width_for(e, self.g.half_gap_m)
    }
    /// [`Self::wall_half_width`] for a gap of half width `hg`.
    /// Two walls of half length `half` and half width `w` at `a`° to the track, centred
    /// `mid` along it, whose inner faces come no nearer the track than `hg`: a funnel
    /// (port wall turned out at its front, −a, starboard +a) or a channel skewed to a side
    /// drawn here.
    pub(super) fn angled_pair(
        &mut self,
        mid: f64,
        half: f64,
        hg: f64,
        w: f64,
        a: f64,
        funnel: bool,
    ) {
        let (sn, cs) = (a.to_radians().sin(), a.to_radians().cos());
        let off = hg + half * sn + w * cs;
        if funnel {
            self.wall(mid, -off, half, w, -a);
            self.wall(mid, off, half, w, a);
        } else {
            let rot = self.sign() * a;
            self.wall(mid, -off, half, w, rot);
            self.wall(mid, off, half, w, rot);
        }
        self.gates += 1;
    }

    pub(super) fn wall_half_width_for(&self, e: f64, hg: f64) -> f64 {
        ((self.g.outer_m + WALL_OVERHANG_M + e.abs() - hg) / 2.0).max(MIN_WALL_HALF_WIDTH_M)
    }
    /// A gate: walls `len` long from `s0`, the gap centred `e` across,
    /// each side `len_port`/`len_stbd` long (centred on the gate's middle).
    pub(super) fn gate(&mut self, s0: f64, len_port: f64, len_stbd: f64, e: f64) {
        self.gate_of(s0, len_port, len_stbd, e, self.g.half_gap_m);
    }
    /// [`Self::gate`] with a gap of half width `hg`.
    pub(super) fn gate_of(&mut self, s0: f64, len_port: f64, len_stbd: f64, e: f64, hg: f64) {
        let len = len_port.max(len_stbd);
        self.straight_to(s0 + len + 1.0);
        let w = self.wall_half_width_for(e, hg);
        let mid = s0 + len / 2.0;
        self.wall(mid, e - hg - w, len_port / 2.0, w, 0.0);
        self.wall(mid, e + hg + w, len_stbd / 2.0, w, 0.0);
        self.gates += 1;
    }
    pub(super) fn wall_len(&mut self) -> f64 {
        16.0 + 8.0 * self.u()
    }
    /// Where a gate may start after everything so far (a turn's vertex
    /// needs [`TURN_CLEAR_M`]).
    pub(super) fn next_gate_start(&mut self, gap_m: f64) -> f64 {
        let after_turn = if self.turns_deg.is_empty() {
            0.0
        } else {
            self.end_m + TURN_CLEAR_M
        };
        (self.end_m + gap_m).max(after_turn).max(FIRST_FEATURE_M)
    }
    /// Where the vertex of a turn of `deg` may come after everything so far.
    pub(super) fn next_turn_at(&mut self, deg: f64) -> f64 {
        let t = self.tangent(deg);
        let after_gate = if self.gates > 0 {
            self.end_m + self.g.group_len_m + TURN_AFTER_GATE_M + 10.0 * self.u() + t
        } else {
            0.0
        };
        after_gate.max(FIRST_FEATURE_M - 5.0 + 10.0 * self.u() + t)
    }

    pub(super) fn finish(mut self, family: Family, what: String) -> Course {
        let goal_s = self.end_m + self.g.settle_m;
        self.straight_to(goal_s);
        let (goal, _) = self.route.at(goal_s);
        // the vertices where the route turns or changes slope, then the goal
        let mut pts: Vec<[f64; 3]> = self.route.pts[1..]
            .iter()
            .copied()
            .filter(|p| ((p[0] - goal[0]).powi(2) + (p[1] - goal[1]).powi(2)).sqrt() > 1.0)
            .collect();
        pts.push(goal);
        let waypoints = simplify(&self.route.pts[0], &pts);
        Course {
            family,
            what,
            solids: self.solids,
            waypoints,
            current_ned_mps: None,
            length_m: goal_s,
            end_m: self.end_m,
            turns_deg: self.turns_deg,
            gates: self.gates,
            features: Vec::new(),
            current_zones: Vec::new(),
        }
    }
}

/// Drops vertices where the route goes straight on (same heading and
/// slope in and out).
fn simplify(start: &[f64; 3], pts: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut out: Vec<[f64; 3]> = Vec::new();
    let mut prev = *start;
    for (i, p) in pts.iter().enumerate() {
        let Some(next) = pts.get(i + 1) else {
            out.push(*p);
            break;
        };
        let dir = |a: &[f64; 3], b: &[f64; 3]| {
            let l = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2))
                .sqrt()
                .max(1e-9);
            [(b[0] - a[0]) / l, (b[1] - a[1]) / l, (b[2] - a[2]) / l]
        };
        let (a, b) = (dir(&prev, p), dir(p, next));
        let straight =
            (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9 && (a[2] - b[2]).abs() < 1e-9;
        if !straight {
            out.push(*p);
            prev = *p;
        }
    }
    out
}

/// Builds the course of `family` for the formation `g` from `seed`: the
/// same arguments, the same course. `with`: the features a composed course
/// must have (ignored by the presets).
pub fn build(family: Family, g: Geom, seed: u64, with: &[super::Feature]) -> Course {
    let mut rng = SplitMix(seed ^ 0x434F_5552_5345);
    let mut b = Builder::new(g, &mut rng);
    let what = match family {
        Family::Gate => {
            let s0 = FIRST_FEATURE_M + 10.0 * b.u();
            let len = b.wall_len();
            b.gate(s0, len, len, 0.0);
            format!("a gap {:.1} m wide on the track", 2.0 * g.half_gap_m)
        }
        Family::Offset => {
            let e = b.sign() * (2.0 + 4.0 * b.u());
            let s0 = FIRST_FEATURE_M + 10.0 * b.u();
            let len = b.wall_len();
            b.gate(s0, len, len, e);
            format!("a gap {:.1} m to {}", e.abs(), side(e))
        }
        Family::Asymmetric => {
            let e = b.sign() * (0.5 + 1.5 * b.u());
            let s0 = FIRST_FEATURE_M + 10.0 * b.u();
            if b.u() < 0.5 {
                let short = 8.0 + 4.0 * b.u();
                let long = 24.0 + 8.0 * b.u();
                let (lp, ls) = if b.u() < 0.5 {
                    (short, long)
                } else {
                    (long, short)
                };
                b.gate(s0, lp, ls, e);
                format!(
                    "a gap {:.1} m to {} between a {:.0} m and a {:.0} m wall",
                    e.abs(),
                    side(e),
                    lp,
                    ls
                )
            } else {
                // a wall on one side, a large cylinder on the other
                let len = b.wall_len();
                b.straight_to(s0 + len + 1.0);
                let w = b.wall_half_width(e);
                let hg = g.half_gap_m;
                let r = 2.0 + 1.5 * b.u();
                let wall_side = b.sign();
                let mid = s0 + len / 2.0;
                b.wall(mid, e + wall_side * (hg + w), len / 2.0, w, 0.0);
                b.cylinder(mid, e - wall_side * (hg + r), r);
                b.gates += 1;
                format!(
                    "a gap {:.1} m to {} between a wall ({}) and a cylinder of radius {:.1} m",
                    e.abs(),
                    side(e),
                    side(wall_side),
                    r
                )
            }
        }
        Family::Slalom => {
            let k = if b.u() < 0.5 { 2 } else { 3 };
            let first = b.sign();
            let mut offs = Vec::new();
            for i in 0..k {
                let e = first * if i % 2 == 0 { 1.0 } else { -1.0 } * (1.5 + 2.5 * b.u());
                // the next gap starts 10-25 m past the group's length after the last: the
                // leader turns for it (20 m ahead, its sonar's range) while the rear is
                // still in the last one, but the group can pass both in shape
                let gap = if i == 0 {
                    0.0
                } else {
                    g.group_len_m + SLALOM_ROOM_M + 15.0 * b.u()
                };
                let s0 = b.next_gate_start(gap) + if i == 0 { 10.0 * b.u() } else { 0.0 };
                let len = b.wall_len();
                b.gate(s0, len, len, e);
                offs.push(format!("{:.1} m {}", e.abs(), side(e)));
            }
            format!("{k} gaps in a row ({})", offs.join(", "))
        }
        Family::Turn => {
            let deg = b.sign() * (30.0 + 60.0 * b.u());
            let v = b.u();
            let variant = if v < 1.0 / 3.0 {
                let at = b.next_turn_at(deg);
                b.turn_at(at, deg);
                let s0 = b.next_gate_start(0.0) + 10.0 * b.u();
                let len = b.wall_len();
                b.gate(s0, len, len, 0.0);
                "before a gap"
            } else if v < 2.0 / 3.0 {
                let s0 = FIRST_FEATURE_M + 10.0 * b.u();
                let len = b.wall_len();
                b.gate(s0, len, len, 0.0);
                let at = b.next_turn_at(deg);
                b.turn_at(at, deg);
                let s1 = b.next_gate_start(0.0) + 10.0 * b.u();
                let len = b.wall_len();
                b.gate(s1, len, len, 0.0);
                "between two gaps"
            } else {
                let s0 = FIRST_FEATURE_M + 10.0 * b.u();
                let len = b.wall_len();
                b.gate(s0, len, len, 0.0);
                let at = b.next_turn_at(deg);
                b.turn_at(at, deg);
                "after a gap"
            };
            format!("a turn of {:.0}° to {} {variant}", deg.abs(), side(deg))
        }
        Family::SBend => {
            let deg = b.sign() * (30.0 + 30.0 * b.u());
            let at = b.next_turn_at(deg);
            b.turn_at(at, deg);
            let leg = 2.0 * b.tangent(deg) + 10.0 + 20.0 * b.u();
            b.turn_at(at + leg, -deg);
            let s0 = b.next_gate_start(0.0) + 10.0 * b.u();
            let len = b.wall_len();
            b.gate(s0, len, len, 0.0);
            format!(
                "turns of {:.0}° to {} and back, {:.0} m apart, then a gap",
                deg.abs(),
                side(deg),
                leg
            )
        }
        Family::Cylinders => {
            let n = 4 + (4.0 * b.u()) as usize;
            let depth = 30.0 + 20.0 * b.u();
            let across = g.outer_m + 4.0;
            let s0 = FIRST_FEATURE_M;
            b.straight_to(s0 + depth + 5.0);
            let mut placed: Vec<(f64, f64, f64)> = Vec::new();
            for _ in 0..400 {
                if placed.len() == n {
                    break;
                }
                let r = 0.6 + 0.9 * b.u();
                let s = s0 + depth * b.u();
                let e = across * (2.0 * b.u() - 1.0);
                let room = placed.iter().all(|&(s2, e2, r2)| {
                    ((s - s2).powi(2) + (e - e2).powi(2)).sqrt() - r - r2 >= 2.0 * g.half_gap_m
                });
                if room {
                    placed.push((s, e, r));
                }
            }
            for &(s, e, r) in &placed {
                b.cylinder(s, e, r);
            }
            b.gates += 1;
            format!(
                "{} cylinders over {:.0} m, at least {:.1} m apart",
                placed.len(),
                depth,
                2.0 * g.half_gap_m
            )
        }
        Family::Angled => {
            let a = 10.0 + 15.0 * b.u();
            let funnel = b.u() < 0.5;
            let s0 = FIRST_FEATURE_M + 10.0 * b.u();
            let len = b.wall_len();
            b.straight_to(s0 + len + 5.0);
            let half = len / 2.0;
            let w = b.wall_half_width(0.0);
            b.angled_pair(s0 + half, half, g.half_gap_m, w, a, funnel);
            if funnel {
                format!("a funnel of walls at {a:.0}° to the track")
            } else {
                format!("a channel skewed {a:.0}° across the track")
            }
        }
        Family::Depth => {
            let room_up = g.depth_m - g.min_depth_m;
            let down = room_up < 3.0 || b.u() < 0.5;
            let dz = if down {
                3.0 + 5.0 * b.u()
            } else {
                -(3.0 + (room_up - 3.0).min(5.0) * b.u())
            };
            let at = FIRST_FEATURE_M - 15.0 + 10.0 * b.u();
            b.straight_to(at);
            let d = b.depth() + dz;
            b.route.extend(0.0, 40.0, d);
            b.end_m = b.end_m.max(at + 40.0);
            let s0 = b.next_gate_start(15.0) + 10.0 * b.u();
            let len = b.wall_len();
            b.gate(s0, len, len, 0.0);
            format!(
                "{} {:.1} m over 40 m, then a gap",
                if dz > 0.0 { "down" } else { "up" },
                dz.abs()
            )
        }
        Family::Current => {
            let m = 0.1 + 0.2 * b.u();
            let from = b.sign();
            let s0 = FIRST_FEATURE_M + 10.0 * b.u();
            let len = b.wall_len();
            b.gate(s0, len, len, 0.0);
            let mut c = b.finish(
                family,
                format!(
                    "a cross current of {m:.2} m/s from {} through a gap",
                    if from > 0.0 { "starboard" } else { "port" }
                ),
            );
            // the route heads north: a current from starboard flows west
            c.current_ned_mps = Some([0.0, -from * m, 0.0]);
            return c;
        }
        Family::Composed => {
            drop(b);
            return super::compose::build(g, &mut rng, with);
        }
    };
    b.finish(family, what)
}

pub(super) fn side(x: f64) -> &'static str {
    if x < 0.0 {
        "port"
    } else {
        "starboard"
    }
}
