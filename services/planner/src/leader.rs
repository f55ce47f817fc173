//! The leader: waypoints at a speed, and reactive obstacle avoidance with its own sonar.
//!
//! # Guidance
//! The path is the polyline from the leader's position at its first step through
//! `waypoints_ned_m`. A virtual target ("rabbit") moves along it at the commanded speed,
//! never more than `max_lead_m` ahead of the leader's projection on the path and never
//! behind it; the target velocity is the commanded speed along the path (feed-forward), so in
//! steady state the leader sits on the rabbit. The speed tapers as `√(2·decel·remaining)` to
//! stop on the last waypoint; within `acceptance_radius_m` of it the mission is done and the
//! leader holds there. An intermediate waypoint is passed when the leader comes within
//! `acceptance_radius_m` of it or its projection passes the leg's end. The wanted heading is
//! line-of-sight: the leg's course plus `atan(−e/los_lookahead_m)` for a cross-track error `e`.
//!
//! The speed command also ramps up at most `accel_mps2` (from rest at the start, and after a
//! stop), so the followers, who see the leader only through their cameras, are not left
//! behind by a step in speed.
//!
//! # Navigation
//! The leader steers on its own filtered position ([`crate::nav_filter`]): dead reckoning
//! from the DVL and AHRS, corrected by the noisy absolute fixes (`position_fix_noise_m`),
//! depth from the pressure sensor. The path's first vertex is the start as now best estimated
//! (filtered position minus the dead-reckoned travel), refined while on the first leg, so a
//! noisy first fix does not tilt the first leg.
//!
//! # Avoidance (our choice; the paper defers to its ref. [11])
//! A **lateral offset of the track**. Sonar returns are remembered in NED (the leader has
//! absolute navigation) until they are `memory_behind_m` behind it. Every step, the returns
//! between `memory_behind_m` behind and `lookahead_m` ahead along the current leg, at
//! cross-track positions `e_p`, constrain the offset `o` of the track:
//! `|e_p − o| ≥ c` with `c = d_min_m + avoid_margin_m`. The wanted offset is the feasible
//! one with the smallest `|o|` (so 0, the nominal track, whenever it is clear), among the
//! candidates `0` and `e_p ± c`; ties go to the one nearest the current offset, then to
//! starboard. The actual offset moves toward it at most `offset_rate_mps`. Once the
//! obstacle is behind, its points are forgotten and the offset returns to 0 at the same rate:
//! the leader returns to its track. If no offset within `max_offset_m` is clear, the leader
//! stops (mode `Blocked`) until one is. A passage at least `2c` wide on the track is taken
//! straight through. Deterministic: no randomness, ties broken by fixed rules.
//!
//! Followers that converge on the leader's track (eq. 8) then keep at least `D_min` from what
//! the leader passed, since the leader keeps `c ≥ D_min`.

use nalgebra::{UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::frames::{to_level, wrap, yaw_of};
use crate::keepout;
use crate::nav_filter::PositionFilter;
use crate::shift::beam_vector;
use crate::types::{
    cfg_err, check_finite, check_nonneg, check_pos, Mode, PlannerError, PlannerOutput,
    PlannerState, SonarScan, Target,
};

/// Remembered obstacle points of the leader.
pub const LEADER_MEMORY_CAPACITY: usize = 256;
/// How far behind the leader remembered returns still constrain its offset when the
/// whole window (`memory_behind_m`) leaves no offset clear, m.
pub const OWN_BEHIND_M: f64 = 3.0;

/// The leader's mission and avoidance (`[mission]` in a scenario).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LeaderConfig {
    /// Waypoints, NED, m (default one, 100 m north at 10 m depth).
    pub waypoints_ned_m: Vec<[f64; 3]>,
    /// Cruise speed, m/s (default 1).
    pub speed_mps: f64,
    /// A waypoint is reached within this distance, m (default 2).
    pub acceptance_radius_m: f64,
    /// Safe distance to obstacles, m (default 2).
    pub d_min_m: f64,
    /// Extra clearance the leader keeps beyond `d_min_m`, m (default 0.5).
    pub avoid_margin_m: f64,
    /// Returns up to this far ahead constrain the track offset, m (default 20, the sonar
    /// range).
    pub lookahead_m: f64,
    /// Returns are remembered until this far behind the leader, m (default 3).
    pub memory_behind_m: f64,
    /// ... or this old, s (default 120).
    pub memory_max_age_s: f64,
    /// Largest track offset, m (default 15).
    pub max_offset_m: f64,
    /// Largest rate of change of the offset, m/s (default 0.4).
    pub offset_rate_mps: f64,
    /// Radius of the arcs the leader flies its route's corners on, m (default 0: sharp
    /// corners). `shoal run` sets it, unless the scenario does, from the formation's view
    /// margin ([`crate::view::turn_radius_m`]) so that every follower keeps its parent in
    /// view through a turn.
    pub turn_radius_m: f64,
    /// An obstacle is taken to continue this far beyond each return along the beam that
    /// saw it, m (default 5): the water before a return is clear, what lies behind it is
    /// not known, and a wall seen from inside a gap must not be passed on its far side.
    pub shadow_m: f64,
    /// Returns closer than this to a remembered one refresh it instead of adding a point,
    /// m (default 0.5; 0: every return is a point, oldest dropped when full).
    pub memory_cell_m: f64,
    /// An offset on the other side of the track than the current one must be shorter by
    /// this much to be chosen, m (default 1).
    pub side_margin_m: f64,
    /// A return that came abeam keeps the side the track passed it on (default true;
    /// `false`: every return may be passed on either side, as the paper's ref. [11]).
    pub keep_abeam_side: bool,
    /// An offset is feasible only if the way to it is (default true): moving toward it at
    /// `offset_rate_mps` while going on at the speed command, the track keeps the
    /// clearance from every return ahead when it comes up to it. A far gap is not aimed
    /// for across a near wall; a leader that cannot move over in time slows (`false`: only
    /// the offset itself is checked).
    pub check_reach: bool,
    /// Line-of-sight lookahead for the heading, m (default 5).
    pub los_lookahead_m: f64,
    /// The virtual target is at most this far ahead of the leader's projection, m (default 2).
    pub max_lead_m: f64,
    /// Deceleration into the last waypoint, m/s² (default 0.05).
    pub decel_mps2: f64,
    /// Transducer position in the body frame, m (default `[0.8, 0, 0]`).
    pub sonar_mount_body_m: [f64; 3],
    /// Largest increase of the speed command, m/s² (default 0.1: 10 s from rest to 1 m/s).
    pub accel_mps2: f64,
    /// 1σ noise of the absolute position fix per axis, m (default 0.5, the `nav` default;
    /// `shoal run` sets it from the scenario's `[nav] position_noise_m`).
    pub position_fix_noise_m: f64,
    /// Dead-reckoning velocity error assumed by the position filter, 1σ per step, m/s
    /// (default 0.02: twice the DVL's noise).
    pub dead_reckoning_noise_mps: f64,
    /// How far from its reported direction a sonar return may lie, deg (`shoal run` sets
    /// it from `[sonar]`: 0 for rays and split beams, which report the echo's own
    /// direction; a single-beam cone's full width). Default 0.
    pub sonar_return_spread_deg: f64,
    /// Half angle of the blind wedge the sonar's cones leave around the heading, deg
    /// (`shoal run` sets it from `[sonar]`; default 6.5, the default four 7° beams at
    /// ±10°; 0 when a cone holds the heading).
    pub sonar_wedge_deg: f64,
    /// Deceleration the leader plans to stop with short of what may lie in its path, m/s²
    /// (default 0.5, about a third of what full thrust gives; 0: off). The speed command
    /// is never above `√(2·a·(s − d_min/2 − avoid_margin))`, `s` the distance ahead the
    /// sonar has shown clear ([`clear_ahead_m`]): the leader never goes where its sonar has
    /// not shown clear water within its stopping distance, and slows where it cannot see
    /// far enough.
    pub brake_mps2: f64,
    /// The smallest obstacle radius the leader must see in time, m (default 0.3, the
    /// smallest `shoal gen` makes): an obstacle that size is seen through the blind wedge
    /// around the heading only within `r / sin(sonar_wedge_deg)`.
    pub min_obstacle_radius_m: f64,
}

impl Default for LeaderConfig {
    fn default() -> Self {
        Self {
            waypoints_ned_m: vec![[100.0, 0.0, 10.0]],
            speed_mps: 1.0,
            acceptance_radius_m: 2.0,
            d_min_m: 2.0,
            avoid_margin_m: 0.5,
            lookahead_m: 20.0,
            memory_behind_m: 3.0,
            memory_max_age_s: 120.0,
            max_offset_m: 15.0,
            offset_rate_mps: 0.4,
            turn_radius_m: 0.0,
            shadow_m: 5.0,
            memory_cell_m: 0.5,
            side_margin_m: 1.0,
            keep_abeam_side: true,
            check_reach: true,
            los_lookahead_m: 5.0,
            max_lead_m: 2.0,
            decel_mps2: 0.05,
            sonar_mount_body_m: [0.8, 0.0, 0.0],
            accel_mps2: 0.1,
            position_fix_noise_m: 0.5,
            dead_reckoning_noise_mps: 0.02,
            sonar_return_spread_deg: 0.0,
            sonar_wedge_deg: 6.5,
            brake_mps2: 0.5,
            min_obstacle_radius_m: 0.3,
        }
    }
}

impl LeaderConfig {
    /// Checks every key; the error names the first bad one (`mission.<key>`).
    pub fn validate(&self) -> Result<(), PlannerError> {
        if self.waypoints_ned_m.is_empty() {
            return Err(cfg_err(
                "mission.waypoints_ned_m",
                "must have at least one waypoint".to_string(),
            ));
        }
        for (i, w) in self.waypoints_ned_m.iter().enumerate() {
            if !w.iter().all(|x| x.is_finite()) {
                return Err(cfg_err(
                    &format!("mission.waypoints_ned_m[{i}]"),
                    format!("must be finite, got {w:?}"),
                ));
            }
        }
        check_pos("mission.speed_mps", self.speed_mps)?;
        check_pos("mission.acceptance_radius_m", self.acceptance_radius_m)?;
        check_pos("mission.d_min_m", self.d_min_m)?;
        check_nonneg("mission.avoid_margin_m", self.avoid_margin_m)?;
        check_pos("mission.lookahead_m", self.lookahead_m)?;
        check_nonneg("mission.memory_behind_m", self.memory_behind_m)?;
        check_pos("mission.memory_max_age_s", self.memory_max_age_s)?;
        check_nonneg("mission.max_offset_m", self.max_offset_m)?;
        check_pos("mission.offset_rate_mps", self.offset_rate_mps)?;
        check_nonneg("mission.shadow_m", self.shadow_m)?;
        check_nonneg("mission.turn_radius_m", self.turn_radius_m)?;
        check_nonneg("mission.memory_cell_m", self.memory_cell_m)?;
        check_nonneg("mission.side_margin_m", self.side_margin_m)?;
        check_pos("mission.los_lookahead_m", self.los_lookahead_m)?;
        check_pos("mission.max_lead_m", self.max_lead_m)?;
        check_pos("mission.decel_mps2", self.decel_mps2)?;
        check_pos("mission.accel_mps2", self.accel_mps2)?;
        check_pos("mission.position_fix_noise_m", self.position_fix_noise_m)?;
        check_pos(
            "mission.dead_reckoning_noise_mps",
            self.dead_reckoning_noise_mps,
        )?;
        for (i, v) in self.sonar_mount_body_m.iter().enumerate() {
            check_finite(&format!("mission.sonar_mount_body_m[{i}]"), *v)?;
        }
        check_nonneg(
            "mission.sonar_return_spread_deg",
            self.sonar_return_spread_deg,
        )?;
        check_nonneg("mission.sonar_wedge_deg", self.sonar_wedge_deg)?;
        check_nonneg("mission.brake_mps2", self.brake_mps2)?;
        check_pos("mission.min_obstacle_radius_m", self.min_obstacle_radius_m)?;
        Ok(())
    }
}

/// One leader planner step's inputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeaderInput {
    /// Simulation time the own navigation below was measured at, s. Everything the step
    /// returns refers to this instant (the process passes the nav sample's stamp, not its own
    /// tick time, so that dead reckoning and the vision fixes' stamps agree).
    pub t_s: f64,
    /// Attitude, body→NED.
    pub attitude: UnitQuaternion<f64>,
    /// Body velocity `[u, v, w, p, q, r]`.
    pub nu: Vector6<f64>,
    /// Absolute position fix, NED, m (the leader has absolute navigation; noisy, filtered
    /// here with the DVL).
    pub position_ned_m: Vector3<f64>,
    /// Depth from the pressure sensor, m.
    pub depth_m: f64,
    /// A new scan this step, if any.
    pub sonar: Option<SonarScan>,
}

#[derive(Debug, Clone, Copy)]
struct MemPoint {
    t: f64,
    pos: Vector3<f64>,
    /// Horizontal unit direction of the beam that saw it, NED: the water
    /// between the transducer and the point is clear, the obstacle lies
    /// beyond it.
    ray: Vector3<f64>,
    /// The side of it the leader's track passed (+1: to starboard), fixed when the point
    /// first came abeam; 0 while it is ahead.
    side: f64,
}

/// The leader planner. See the [module docs](self) for the method.
#[derive(Debug, Clone)]
pub struct LeaderPlanner {
    cfg: LeaderConfig,
    mount: Vector3<f64>,
    /// Path vertices: start, then the waypoints (zero-length legs dropped).
    path: Vec<Vector3<f64>>,
    /// For each path vertex, the index of the waypoint it is.
    wp_of: Vec<usize>,
    /// For each path vertex, whether it is a point of a corner's arc (passed on the
    /// projection only: the acceptance radius would skip several short arc legs at once).
    on_arc: Vec<bool>,
    /// Cumulative length at each vertex.
    cum: Vec<f64>,
    started: bool,
    t_prev: f64,
    leg: usize,
    rabbit: f64,
    offset: f64,
    offset_goal: f64,
    done: Option<(Vector3<f64>, f64)>,
    /// Speed command of the last step, m/s (ramped by `accel_mps2`).
    v_cmd: f64,
    nav: PositionFilter,
    memory: Vec<MemPoint>,
    /// Scratch: cross-track extents `(lo, hi)` of the returns in the window.
    window: Vec<(f64, f64, f64)>,
    /// Joins a mission in progress (a restarted planner): see [`Self::resume`].
    resuming: bool,
    /// How far ahead the latest scan has shown the leader's path clear, m.
    clear_ahead_m: f64,
}

impl LeaderPlanner {
    /// Validates the configuration and pre-allocates.
    pub fn new(cfg: &LeaderConfig) -> Result<Self, PlannerError> {
        cfg.validate()?;
        let n = cfg.waypoints_ned_m.len() + 1;
        Ok(Self {
            mount: Vector3::from(cfg.sonar_mount_body_m),
            path: Vec::with_capacity(n),
            wp_of: Vec::with_capacity(n),
            on_arc: Vec::with_capacity(n),
            cum: Vec::with_capacity(n),
            started: false,
            t_prev: 0.0,
            leg: 0,
            rabbit: 0.0,
            offset: 0.0,
            offset_goal: 0.0,
            done: None,
            v_cmd: 0.0,
            nav: PositionFilter::new(cfg.position_fix_noise_m, cfg.dead_reckoning_noise_mps),
            memory: Vec::with_capacity(LEADER_MEMORY_CAPACITY),
            window: Vec::with_capacity(LEADER_MEMORY_CAPACITY),
            resuming: false,
            clear_ahead_m: 0.0,
            cfg: cfg.clone(),
        })
    }

    /// Makes this planner join a mission already under way (the orchestrator
    /// restarted it): at its first step it skips the waypoints the vehicle
    /// has passed (those it is more than the acceptance radius beyond, along
    /// the next leg) and starts its
    /// speed command from the vehicle's speed along the track instead of
    /// from rest, so the group behind it sees no sudden stop.
    pub fn resume(&mut self) {
        self.resuming = true;
    }

    /// The wanted track offset given the remembered returns from `behind` back to `ahead`
    /// ahead along the leg (`a` its start, `tg`/`nrm` its tangent and starboard normal) for
    /// a clearance `c`; `es` is scratch (left holding the extents).
    #[allow(clippy::too_many_arguments)]
    fn wanted_offset(
        &self,
        es: &mut Vec<(f64, f64, f64)>,
        pos: &Vector3<f64>,
        a: &Vector3<f64>,
        tg: &Vector3<f64>,
        nrm: &Vector3<f64>,
        (behind, ahead): (f64, f64),
        c: f64,
    ) -> Option<f64> {
        es.clear();
        let shadow = self.cfg.shadow_m;
        es.extend(self.memory.iter().filter_map(|m| {
            let along = (m.pos - pos).dot(tg);
            (along >= -behind && along <= ahead).then(|| {
                let e = (m.pos - a).dot(nrm);
                let f = e + shadow * m.ray.dot(nrm);
                let (lo, hi) = (e.min(f), e.max(f));
                // what is abeam or behind can no longer be passed on its other side: it
                // extends away from the side the track passed it on without end
                if along > 0.0 || m.side == 0.0 || !self.cfg.keep_abeam_side {
                    (lo, hi, along)
                } else if m.side > 0.0 {
                    (f64::NEG_INFINITY, hi, along)
                } else {
                    (lo, f64::INFINITY, along)
                }
            })
        }));
        es.sort_unstable_by(|x, y| x.0.total_cmp(&y.0)); // in place, no allocation
        let max_offset = self.cfg.max_offset_m;
        // where the offset will be when the leader reaches `along`, moving toward `o` at
        // `offset_rate_mps` while it goes on at its speed command
        let (now, rate, v) = (self.offset, self.cfg.offset_rate_mps, self.v_cmd);
        let at = |o: f64, along: f64| {
            if !self.cfg.check_reach || along <= 0.0 || v <= 1e-6 {
                return o;
            }
            let reach = rate * along / v;
            now + (o - now).clamp(-reach, reach)
        };
        let feasible = |o: f64| {
            if o.abs() > max_offset + 1e-9 {
                return false;
            }
            // no extent reaches within c of o, nor of where the offset will be when the
            // leader comes up to it: an offset that would cut across a return ahead on
            // the way is not one
            let clear = |y: f64, lo: f64, hi: f64| lo >= y + c - 1e-9 || hi <= y - c + 1e-9;
            es.iter()
                .take_while(|(lo, _, _)| *lo < o + c - 1e-9)
                .all(|&(lo, hi, _)| clear(o, lo, hi))
                && es
                    .iter()
                    .all(|&(lo, hi, along)| clear(at(o, along), lo, hi))
        };
        let mut best: Option<f64> = None;
        // crossing to the other side of the track costs `side_margin_m`: a side is
        // changed for a clearly shorter way round, never by a tie that noise decides
        let side_margin = self.cfg.side_margin_m;
        let cur = self.offset_goal;
        let cost = |x: f64| {
            x.abs()
                + if x * cur < 0.0 && cur.abs() > 1e-9 {
                    side_margin
                } else {
                    0.0
                }
        };
        let better = |o: f64, b: f64| {
            let (ko, kb) = (cost(o), cost(b));
            if (ko - kb).abs() > 1e-9 {
                return ko < kb;
            }
            let (co, cb) = ((o - cur).abs(), (b - cur).abs());
            if (co - cb).abs() > 1e-9 {
                return co < cb;
            }
            o > b
        };
        let mut consider = |o: f64| {
            if feasible(o) && best.is_none_or(|b| better(o, b)) {
                best = Some(o);
            }
        };
        consider(0.0);
        consider(cur);
        for (lo, hi, _) in es.iter() {
            consider(hi + c);
            consider(lo - c);
        }
        best
    }

    /// The configuration.
    pub fn config(&self) -> &LeaderConfig {
        &self.cfg
    }

    /// Current lateral offset of the track, m (+ starboard).
    pub fn track_offset(&self) -> f64 {
        self.offset
    }

    fn total(&self) -> f64 {
        self.cum.last().copied().unwrap_or(0.0)
    }

    /// Leg index containing arc length `s`.
    fn leg_at(&self, s: f64) -> usize {
        let legs = self.path.len().saturating_sub(1);
        (0..legs)
            .find(|&i| s <= self.cum[i + 1])
            .unwrap_or(legs.saturating_sub(1))
    }

    /// Unit tangent and starboard normal (horizontal) of leg `i`.
    fn frame(&self, i: usize) -> (Vector3<f64>, Vector3<f64>) {
        let d = self.path[i + 1] - self.path[i];
        let t = d / d.norm().max(1e-12);
        let h = (t.x * t.x + t.y * t.y).sqrt();
        let n = if h > 1e-9 {
            Vector3::new(-t.y / h, t.x / h, 0.0)
        } else {
            Vector3::new(0.0, 1.0, 0.0)
        };
        (t, n)
    }

    fn point_at(&self, s: f64) -> (Vector3<f64>, usize) {
        let i = self.leg_at(s);
        let (t, _) = self.frame(i);
        (self.path[i] + t * (s - self.cum[i]).max(0.0), i)
    }

    fn start(&mut self, pos: &Vector3<f64>) {
        self.path.push(*pos);
        self.wp_of.push(0);
        self.cum.push(0.0);
        let wps = &self.cfg.waypoints_ned_m;
        // Resuming: waypoint j is behind when the vehicle is more than the
        // acceptance radius beyond it along leg j → j+1.
        let passed = |j: usize| {
            let (w, next) = (Vector3::from(wps[j]), Vector3::from(wps[j + 1]));
            let t = (next - w) / (next - w).norm().max(1e-9);
            (pos - w).dot(&t) > self.cfg.acceptance_radius_m
        };
        let first = if self.resuming {
            (0..wps.len().saturating_sub(1))
                .take_while(|&j| passed(j))
                .count()
        } else {
            0
        };
        for (j, w) in self.cfg.waypoints_ned_m.iter().enumerate().skip(first) {
            let w = Vector3::from(*w);
            if let Some(last) = self.path.last().copied() {
                let l = (w - last).norm();
                if l > 1e-6 {
                    let c = self.cum.last().copied().unwrap_or(0.0) + l;
                    self.path.push(w);
                    self.wp_of.push(j);
                    self.cum.push(c);
                }
            }
        }
        self.round_corners();
        self.started = true;
    }

    /// Replaces every corner of the path (a turn of more than 1°) by an arc of
    /// `turn_radius_m` (less where the legs are too short for it), as vertices 5° apart.
    fn round_corners(&mut self) {
        let r = self.cfg.turn_radius_m;
        if r <= 0.0 || self.path.len() < 3 {
            return;
        }
        let horiz = |v: Vector3<f64>| Vector3::new(v.x, v.y, 0.0);
        let (path, wp) = (
            std::mem::take(&mut self.path),
            std::mem::take(&mut self.wp_of),
        );
        self.on_arc.clear();
        self.path.push(path[0]);
        self.wp_of.push(wp[0]);
        self.on_arc.push(false);
        for i in 1..path.len() - 1 {
            let (p0, p1, p2) = (path[i - 1], path[i], path[i + 1]);
            let (d_in, d_out) = (horiz(p1 - p0), horiz(p2 - p1));
            let (l_in, l_out) = (d_in.norm(), d_out.norm());
            let (t_in, t_out) = (d_in / l_in.max(1e-9), d_out / l_out.max(1e-9));
            let theta = (t_in.x * t_out.y - t_in.y * t_out.x).atan2(t_in.dot(&t_out));
            if theta.abs() < 1f64.to_radians() || l_in < 1e-6 || l_out < 1e-6 {
                self.path.push(p1);
                self.wp_of.push(wp[i]);
                self.on_arc.push(false);
                continue;
            }
            let half = (theta.abs() / 2.0).tan();
            let t = (r * half).min(0.45 * l_in).min(0.45 * l_out);
            let r_eff = t / half;
            let a = p1 - (p1 - p0) * (t / l_in);
            let b = p1 + (p2 - p1) * (t / l_out);
            // the centre is to starboard of the way in for a turn to starboard
            let n = Vector3::new(-t_in.y, t_in.x, 0.0) * theta.signum();
            let centre = a + n * r_eff;
            let k = (theta.abs() / 5f64.to_radians()).ceil().max(1.0) as usize;
            for j in 0..=k {
                let f = j as f64 / k as f64;
                let (sn, cs) = (theta * f).sin_cos();
                let v = a - centre;
                let p = Vector3::new(
                    centre.x + v.x * cs - v.y * sn,
                    centre.y + v.x * sn + v.y * cs,
                    a.z + (b.z - a.z) * f,
                );
                self.path.push(p);
                self.wp_of.push(wp[i]);
            }
            let arc_from = self.on_arc.len();
            self.on_arc.resize(self.path.len(), true);
            // the arc's last point leads onto the straight leg
            if let Some(last) = self
                .on_arc
                .last_mut()
                .filter(|_| arc_from < self.path.len())
            {
                *last = false;
            }
        }
        self.path.push(path[path.len() - 1]);
        self.wp_of.push(wp[path.len() - 1]);
        self.on_arc.push(false);
        self.cum.clear();
        self.cum.push(0.0);
        for i in 1..self.path.len() {
            let c = self.cum[i - 1] + (self.path[i] - self.path[i - 1]).norm();
            self.cum.push(c);
        }
    }

    /// Moves the first vertex to the start as now best estimated (horizontal only) and
    /// recomputes the cumulative lengths.
    fn reanchor_start(&mut self) {
        let s = self.nav.start_estimate();
        if let Some(p0) = self.path.first_mut() {
            p0.x = s.x;
            p0.y = s.y;
        }
        for i in 1..self.path.len() {
            self.cum[i] = self.cum[i - 1] + (self.path[i] - self.path[i - 1]).norm();
        }
    }

    fn check_input(input: &LeaderInput) -> Result<(), PlannerError> {
        let ok = |what, b: bool| {
            if b {
                Ok(())
            } else {
                Err(PlannerError::NonFiniteInput { what })
            }
        };
        ok("t_s", input.t_s.is_finite())?;
        ok(
            "attitude",
            input
                .attitude
                .quaternion()
                .coords
                .iter()
                .all(|x| x.is_finite()),
        )?;
        ok("nu", input.nu.iter().all(|x| x.is_finite()))?;
        ok(
            "position_ned_m",
            input.position_ned_m.iter().all(|x| x.is_finite()),
        )?;
        ok("depth_m", input.depth_m.is_finite())?;
        Ok(())
    }

    /// One planner step. On error the state is unchanged.
    pub fn step(&mut self, input: &LeaderInput) -> Result<PlannerOutput, PlannerError> {
        Self::check_input(input)?;
        let t = input.t_s;
        if self.started && t < self.t_prev {
            return Err(PlannerError::TimeWentBackwards {
                previous_s: self.t_prev,
                now_s: t,
            });
        }
        let first = !self.started;
        let dt = if first {
            0.0
        } else {
            (t - self.t_prev).min(1.0)
        };
        let att = input.attitude;
        let v_body = input.nu.fixed_rows::<3>(0).into_owned();
        let pos = self
            .nav
            .step(dt, &att, &v_body, &input.position_ned_m, input.depth_m);
        if first {
            self.start(&pos);
            if self.resuming && self.path.len() >= 2 {
                let (tg, _) = self.frame(0);
                self.v_cmd = (att * v_body).dot(&tg).clamp(0.0, self.cfg.speed_mps);
            }
        } else if self.leg == 0 && self.done.is_none() {
            self.reanchor_start();
        }
        self.t_prev = t;
        let yaw = yaw_of(&att);
        let c = self.cfg.d_min_m + self.cfg.avoid_margin_m;
        let last_wp = self
            .cfg
            .waypoints_ned_m
            .last()
            .map(|w| Vector3::from(*w))
            .unwrap_or(pos);

        // memory of returns, NED
        if let Some(scan) = &input.sonar {
            self.clear_ahead_m = clear_ahead_m(
                scan,
                self.cfg.sonar_return_spread_deg,
                self.cfg.d_min_m / 2.0 + self.cfg.avoid_margin_m,
            );
            if self.cfg.sonar_wedge_deg > 0.0 {
                let wedge = self.cfg.sonar_wedge_deg.to_radians().sin();
                self.clear_ahead_m = self
                    .clear_ahead_m
                    .min(self.cfg.min_obstacle_radius_m / wedge);
            }
            for (d, az, el) in scan.returns() {
                let p = pos + att * (self.mount + beam_vector(d, az, el));
                let dir = att * beam_vector(1.0, az, el);
                let ray = Vector3::new(dir.x, dir.y, 0.0);
                let ray = ray / ray.norm().max(1e-9);
                // one point per cell: a wall seen for a minute stays a wall, not the
                // last few seconds of echoes
                let cell = self.cfg.memory_cell_m;
                if let Some(m) = self
                    .memory
                    .iter_mut()
                    .find(|m| (m.pos.xy() - p.xy()).norm() < cell)
                {
                    *m = MemPoint {
                        t,
                        pos: p,
                        ray,
                        side: m.side,
                    };
                    continue;
                }
                if self.memory.len() == LEADER_MEMORY_CAPACITY {
                    self.memory.remove(0);
                }
                self.memory.push(MemPoint {
                    t,
                    pos: p,
                    ray,
                    side: 0.0,
                });
            }
        }
        let (behind, max_age) = (self.cfg.memory_behind_m, self.cfg.memory_max_age_s);
        self.memory
            .retain(|m| to_level(yaw, &(m.pos - pos)).x >= -behind && t - m.t <= max_age);

        // mission done (sticky): near the last waypoint, and the virtual target has reached
        // it, so the speed command has tapered to zero — switching to the hold earlier cut
        // the feed-forward from ~0.45 m/s to 0 in one step and the followers overshot
        let rabbit_at_end = self.rabbit >= self.total() - 1e-9;
        if self.done.is_none()
            && (pos - last_wp).norm() <= self.cfg.acceptance_radius_m
            && (self.path.len() < 2 || (self.leg + 2 >= self.path.len() && rabbit_at_end))
        {
            self.done = Some((last_wp, yaw));
        }
        if self.path.len() < 2 && self.done.is_none() {
            self.done = Some((last_wp, yaw));
        }
        let keepout = keepout::select(|| self.memory.iter().map(|m| to_level(yaw, &(m.pos - pos))));
        if let Some((hold, hold_yaw)) = self.done {
            return Ok(PlannerOutput {
                target: Target {
                    position_m: to_level(yaw, &(hold - pos)),
                    velocity_mps: Vector3::zeros(),
                    yaw_rel_rad: wrap(hold_yaw - yaw),
                },
                keepout,
                state: self.state(Mode::MissionDone, f64::INFINITY, (hold - pos).norm(), false),
            });
        }

        // projection on the current leg; advance past reached waypoints
        let legs = self.path.len() - 1;
        loop {
            let (tg, _) = self.frame(self.leg);
            let a = self.path[self.leg];
            let len = self.cum[self.leg + 1] - self.cum[self.leg];
            let along = (pos - a).dot(&tg);
            let end = self.path[self.leg + 1];
            let on_arc = self.on_arc.get(self.leg + 1).copied().unwrap_or(false);
            let reached =
                (!on_arc && (pos - end).norm() <= self.cfg.acceptance_radius_m) || along >= len;
            if reached && self.leg + 1 < legs {
                self.leg += 1;
            } else {
                break;
            }
        }
        let (tg, nrm) = self.frame(self.leg);
        let a = self.path[self.leg];
        let len = self.cum[self.leg + 1] - self.cum[self.leg];
        let s_proj = self.cum[self.leg] + (pos - a).dot(&tg).clamp(0.0, len);

        // avoidance: the wanted offset, from the cross-track extents in the window (each
        // return and its shadow: the obstacle continues `shadow_m` beyond it along the beam).
        // The window reaches `memory_behind_m` back, so the offset is kept until the
        // formation behind has passed; if nothing is clear of that whole window (a second
        // gap, offset the other way, close behind the first) only the leader's own
        // `OWN_BEHIND_M` counts; then, still with that, only the nearer half and quarter of
        // the lookahead (the near wall is passed before the far gap is aimed for: a wall
        // abeam is never dropped to reach a gap that is still 20 m away); and last only what
        // is ahead, rather than stopping with the way ahead open.
        for m in &mut self.memory {
            if m.side == 0.0 && (m.pos - pos).dot(&tg) <= 0.0 {
                let e = (m.pos - a).dot(&nrm);
                m.side = if self.offset >= e { 1.0 } else { -1.0 };
            }
        }
        let mut es = std::mem::take(&mut self.window);
        let mut best: Option<f64> = None;
        let (own, ahead) = (behind.min(OWN_BEHIND_M), self.cfg.lookahead_m);
        for window in [
            (behind, ahead),
            (own, ahead),
            (own, ahead / 2.0),
            (own, ahead / 4.0),
            (0.0, ahead),
        ] {
            best = self.wanted_offset(&mut es, &pos, &a, &tg, &nrm, window, c);
            if best.is_some() {
                break;
            }
        }
        let blocked = best.is_none();
        if let Some(o) = best {
            self.offset_goal = o;
        }
        let step = self.cfg.offset_rate_mps * dt;
        let prev_offset = self.offset;
        self.offset += (self.offset_goal - self.offset).clamp(-step, step);
        let offset_rate = if dt > 0.0 {
            (self.offset - prev_offset) / dt
        } else {
            0.0
        };
        let delta_min = es
            .iter()
            .map(|(lo, hi, _)| (lo - self.offset).max(self.offset - hi).max(0.0))
            .fold(f64::INFINITY, f64::min);
        self.window = es;

        // rabbit
        let total = self.total();
        // never faster than it can stop short of what may lie in its path
        let seen = if self.cfg.brake_mps2 > 0.0 {
            let room = self.clear_ahead_m - (self.cfg.d_min_m / 2.0 + self.cfg.avoid_margin_m);
            (2.0 * self.cfg.brake_mps2 * room.max(0.0)).sqrt()
        } else {
            f64::INFINITY
        };
        let v_cmd = if blocked {
            0.0
        } else {
            self.cfg
                .speed_mps
                .min((2.0 * self.cfg.decel_mps2 * (total - self.rabbit).max(0.0)).sqrt())
                .min(self.v_cmd + self.cfg.accel_mps2 * dt)
                .min(seen)
        };
        self.v_cmd = v_cmd;
        self.rabbit = (self.rabbit + v_cmd * dt)
            .min(s_proj + self.cfg.max_lead_m)
            .max(s_proj)
            .min(total);
        let (p_r, leg_r) = self.point_at(self.rabbit);
        let (t_r, n_r) = self.frame(leg_r);
        let target_ned = p_r + n_r * self.offset;
        let vel_ned = t_r * v_cmd + n_r * offset_rate;

        // line-of-sight heading toward the shifted track
        let e_v = (pos - a).dot(&nrm) - self.offset;
        let course = tg.y.atan2(tg.x);
        let chi = course + (-e_v).atan2(self.cfg.los_lookahead_m);

        let avoiding = self.offset_goal != 0.0 || self.offset != 0.0;
        let mode = if blocked {
            Mode::Blocked
        } else if avoiding {
            Mode::Avoiding
        } else {
            Mode::Tracking
        };
        let wp_dist = (pos - self.path[self.leg + 1]).norm();
        Ok(PlannerOutput {
            target: Target {
                position_m: to_level(yaw, &(target_ned - pos)),
                velocity_mps: to_level(yaw, &vel_ned),
                yaw_rel_rad: wrap(chi - yaw),
            },
            keepout,
            state: self.state(mode, delta_min, wp_dist, delta_min < c),
        })
    }

    fn state(&self, mode: Mode, delta_min: f64, wp_dist: f64, avoiding: bool) -> PlannerState {
        let wp = if self.done.is_some() {
            self.cfg.waypoints_ned_m.len().saturating_sub(1)
        } else {
            self.wp_of.get(self.leg + 1).copied().unwrap_or(0)
        };
        PlannerState {
            mode,
            slot_nominal_m: Vector3::zeros(),
            slot_shifted_m: Vector3::zeros(),
            slot_filtered_m: Vector3::zeros(),
            delta_min_m: delta_min,
            parent_age_s: 0.0,
            parent_estimate_valid: true,
            avoiding,
            waypoint_index: wp,
            waypoint_distance_m: wp_dist,
            track_offset_m: self.offset,
        }
    }
}

/// How far ahead `scan` shows the leader's path clear, m: the along-track distance of the
/// nearest return that may lie within `corridor` of the heading. A return reported at
/// range `r`, `θ` off the heading, may lie up to `spread_deg / 2` nearer the heading (a
/// single-beam cone's return lies anywhere in it); at `ε = max(0, θ − spread/2)` it lies
/// `r·sin ε` abeam and `r·cos ε` ahead. ∞ when no return may be in the path.
#[must_use]
pub fn clear_ahead_m(scan: &SonarScan, spread_deg: f64, corridor: f64) -> f64 {
    let half = (spread_deg / 2.0).to_radians();
    let mut clear = f64::INFINITY;
    for (r, az, el) in scan.returns() {
        // angle between the return's direction and the body's x axis
        let off = (el.cos() * az.cos()).clamp(-1.0, 1.0).acos();
        let eps = (off - half).max(0.0);
        if eps < std::f64::consts::FRAC_PI_2 && r * eps.sin() < corridor {
            clear = clear.min(r * eps.cos());
        }
    }
    clear
}
