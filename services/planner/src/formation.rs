//! Choosing and checking `D_a` / `D_b` for every follower of a formation tree (paper sec. 3:
//! "`D_a` is chosen so that when different AUVs move along these given trajectories inside
//! the formation, the distances between them would always be no less than `D_min`"; "`D_b`
//! is chosen for each follower in such a way that any displacement along the given
//! trajectories within the formation does not cover the beacon's visibility area for other
//! members of the group").
//!
//! # Model
//! The check is geometric, in the leader's frame with every vehicle on the formation's
//! heading (the steady formation). Follower `k`'s slot moves along its displacement segment
//! `S_k + λ_k w_k`, `λ_k ∈ [0, 1]` ([`crate::shift::Displacement`]: `w_k` ends on its
//! parent's track, `±D_a/2` along and `D_b/2` down). A vehicle's position is the sum of the
//! segments along its chain of parents. Every follower reacts to its own sonar, so the `λ`
//! are **independent**: the check covers every combination.
//!
//! * **Separation**: for each pair, the minimum over all `λ` of their distance is `≥ D_min`.
//!   Shared ancestors cancel; what remains is the distance from the origin to a zonotope,
//!   a small convex box-constrained least-squares problem solved exactly by coordinate
//!   descent.
//! * **Line of sight**: for each follower `j`, its parent `P` and any third vehicle `k`, the
//!   distance from `k` to the segment `j → P` stays `≥ occlusion_radius_m` (hull radius plus
//!   the beacons' spread). With `P` the parent this is `min over μ, λ` of
//!   `|(k − P) − μ (j − P)|`: for each fixed `μ` a convex problem of the same kind, solved
//!   exactly; over `μ` the minimum is bounded interval by interval with its Lipschitz
//!   constant (a sound lower bound, to 1 cm), after a bounding-box test that discards
//!   far-apart triples.
//! * **Visibility range**: `|j − P| ≤ visibility_range_m` at both ends of `j`'s segment.
//!
//! # Assignment
//! [`assign_displacements`] visits followers by tree depth (then input order) and gives each
//! the first candidate that keeps every constraint with the vehicles already placed,
//! backtracking when one has none. Candidates, in order of preference: `D_b = 0`, then
//! `±step, ±2·step, …` up to `2·max_depth_shift_m` (`+` = down first), and for each,
//! `D_a = 1.25, 1.5, 2 × D_min` with the paper's side sign, then reversed. When no
//! assignment exists the error names the follower, and the pair (or triple) and distance of
//! its least-violating candidate.

use std::collections::HashMap;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::shift::Displacement;

/// One follower of the formation tree.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FollowerSlot {
    /// Vehicle name.
    pub name: String,
    /// Its parent (the leader or another follower).
    pub parent: String,
    /// Slot in the parent's frame, FRD, m.
    pub slot_in_parent_m: [f64; 3],
}

/// Camera and geometry parameters of the check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FormationParams {
    /// Water visibility: a follower must stay within this of its parent, m (default 12).
    pub visibility_range_m: f64,
    /// A vehicle closer than this to a line of sight hides the beacons, m (default 0.6:
    /// hull radius 0.25 plus beacon spread).
    pub occlusion_radius_m: f64,
    /// Largest vertical shift of one follower, `|D_b|/2`, m (default 3).
    pub max_depth_shift_m: f64,
    /// Step of the `D_b` candidates, m (default 1).
    pub d_b_step_m: f64,
    /// Candidates [`assign_displacements`] tries before it gives up (default 4000:
    /// a few milliseconds for the paper's five; a failing search costs about as many
    /// pair checks times the group's size).
    pub search_budget: usize,
}

impl Default for FormationParams {
    fn default() -> Self {
        Self {
            visibility_range_m: 12.0,
            occlusion_radius_m: 0.6,
            max_depth_shift_m: 3.0,
            d_b_step_m: 1.0,
            search_budget: 4_000,
        }
    }
}

/// Why a formation or an assignment is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FormationError {
    /// A parameter is out of range.
    #[error("formation: {0}")]
    InvalidParam(String),
    /// Two vehicles share a name.
    #[error("formation: duplicate vehicle name {0}")]
    DuplicateName(String),
    /// A follower's parent is not in the formation.
    #[error("formation: {follower} follows unknown vehicle {parent}")]
    UnknownParent {
        /// The follower.
        follower: String,
        /// Its missing parent.
        parent: String,
    },
    /// The parent links do not reach the leader.
    #[error("formation: the parent chain of {0} never reaches the leader (cycle)")]
    Cycle(String),
    /// The assignment has the wrong length.
    #[error("formation: {got} displacements for {expected} followers")]
    WrongLength {
        /// Followers.
        expected: usize,
        /// Displacements given.
        got: usize,
    },
    /// Two vehicles come closer than the safe distance.
    #[error("{a} and {b} come within {distance_m:.2} m of each other along their displacement trajectories (safe distance {d_min_m} m)")]
    TooClose {
        /// One vehicle.
        a: String,
        /// The other.
        b: String,
        /// Their smallest distance, m.
        distance_m: f64,
        /// The safe distance, m.
        d_min_m: f64,
    },
    /// A vehicle can hide a parent's beacons from its follower.
    #[error("{occluder} comes within {clearance_m:.2} m of the line of sight from {observer} to its parent {parent} (needs {needed_m} m)")]
    Occludes {
        /// The follower whose view is blocked.
        observer: String,
        /// Its parent.
        parent: String,
        /// The vehicle in the way.
        occluder: String,
        /// Smallest distance to the line of sight, m.
        clearance_m: f64,
        /// Required, m.
        needed_m: f64,
    },
    /// A follower's slot is beyond the water's visibility from its parent.
    #[error("{follower} is up to {distance_m:.2} m from its parent {parent}, beyond the visibility range {visibility_m} m")]
    OutOfSight {
        /// The follower.
        follower: String,
        /// Its parent.
        parent: String,
        /// Largest distance along its displacement, m.
        distance_m: f64,
        /// Visibility, m.
        visibility_m: f64,
    },
    /// A vertical shift exceeds `max_depth_shift_m`.
    #[error(
        "{follower}: vertical shift |d_b|/2 = {shift_m} m exceeds max_depth_shift_m {max_m} m"
    )]
    DepthShift {
        /// The follower.
        follower: String,
        /// Its shift, m.
        shift_m: f64,
        /// Allowed, m.
        max_m: f64,
    },
    /// No displacement works for a follower.
    #[error("no D_a/D_b for {follower} keeps the formation safe; closest candidate: {cause}")]
    Impossible {
        /// The follower that could not be placed.
        follower: String,
        /// The violation of its least-bad candidate (names the pair and distance).
        cause: Box<FormationError>,
    },
}

/// The tree, indexed: vehicle 0 is the leader, vehicle `i + 1` is follower `i`.
struct Tree {
    names: Vec<String>,
    /// parent vehicle index for each vehicle (leader: itself).
    parent: Vec<usize>,
    /// For each vehicle, follower indices (vehicle − 1) from the leader's child down to it.
    chain: Vec<Vec<usize>>,
    slots: Vec<Vector3<f64>>,
    order: Vec<usize>,
}

fn build_tree(leader: &str, followers: &[FollowerSlot]) -> Result<Tree, FormationError> {
    let mut index: HashMap<&str, usize> = HashMap::new();
    index.insert(leader, 0);
    for (i, f) in followers.iter().enumerate() {
        if index.insert(f.name.as_str(), i + 1).is_some() {
            return Err(FormationError::DuplicateName(f.name.clone()));
        }
        if !f.slot_in_parent_m.iter().all(|x| x.is_finite()) {
            return Err(FormationError::InvalidParam(format!(
                "{}: slot_in_parent_m must be finite, got {:?}",
                f.name, f.slot_in_parent_m
            )));
        }
    }
    let n = followers.len() + 1;
    let mut parent = vec![0; n];
    for (i, f) in followers.iter().enumerate() {
        parent[i + 1] =
            *index
                .get(f.parent.as_str())
                .ok_or_else(|| FormationError::UnknownParent {
                    follower: f.name.clone(),
                    parent: f.parent.clone(),
                })?;
    }
    let mut chain = vec![Vec::new(); n];
    for v in 1..n {
        let mut c = Vec::new();
        let mut cur = v;
        while cur != 0 {
            if c.len() > n {
                return Err(FormationError::Cycle(followers[v - 1].name.clone()));
            }
            c.push(cur - 1);
            cur = parent[cur];
        }
        c.reverse();
        chain[v] = c;
    }
    let mut order: Vec<usize> = (0..followers.len()).collect();
    order.sort_by_key(|&i| chain[i + 1].len());
    let mut names = vec![leader.to_string()];
    names.extend(followers.iter().map(|f| f.name.clone()));
    let mut slots = vec![Vector3::zeros()];
    slots.extend(followers.iter().map(|f| Vector3::from(f.slot_in_parent_m)));
    Ok(Tree {
        names,
        parent,
        chain,
        slots,
        order,
    })
}

/// Segment start `S_k` and direction `w_k` of follower `k`.
fn segment(slot: &Vector3<f64>, d: (f64, f64)) -> Vector3<f64> {
    let disp = Displacement {
        slot: *slot,
        d_a: d.0,
        d_b: d.1,
    };
    disp.end() - slot
}

/// min over λ ∈ [0,1]ⁿ of |c + Σ λ_k w_k| (convex; cyclic coordinate descent).
///
/// Stops early with a lower bound once that bound reaches `enough` (the caller only needs
/// to know the minimum is at least that): for any unit `u`,
/// `|c + Wλ| ≥ u·c + Σ min(0, u·w_k)` on the whole box.
fn min_norm_box(c: &Vector3<f64>, cols: &[Vector3<f64>], enough: f64) -> f64 {
    let lower_bound =
        |u: &Vector3<f64>| u.dot(c) + cols.iter().map(|w| u.dot(w).min(0.0)).sum::<f64>();
    if c.norm() > 0.0 && lower_bound(&c.normalize()) >= enough {
        return enough;
    }
    let mut lambda = vec![0.0; cols.len()];
    let mut r = *c;
    for sweep in 0..200 {
        let mut moved = 0.0f64;
        for (k, w) in cols.iter().enumerate() {
            let ww = w.norm_squared();
            if ww < 1e-18 {
                continue;
            }
            let new = (lambda[k] - r.dot(w) / ww).clamp(0.0, 1.0);
            let delta = new - lambda[k];
            if delta != 0.0 {
                r += w * delta;
                lambda[k] = new;
                moved = moved.max(delta.abs());
            }
        }
        if moved < 1e-12 {
            break;
        }
        if sweep % 4 == 3 && r.norm() > 0.0 && lower_bound(&r.normalize()) >= enough {
            return enough;
        }
    }
    r.norm()
}

struct Geometry<'a> {
    tree: &'a Tree,
    /// Per follower: `Some(w_k)` once assigned.
    w: Vec<Option<Vector3<f64>>>,
}

impl Geometry<'_> {
    fn assigned(&self, v: usize) -> bool {
        v == 0 || self.w[v - 1].is_some()
    }

    fn wk(&self, k: usize) -> Vector3<f64> {
        self.w[k].unwrap_or_else(Vector3::zeros)
    }

    /// Reachable axis-aligned box of vehicle `v`.
    fn bbox(&self, v: usize) -> (Vector3<f64>, Vector3<f64>) {
        let mut lo = Vector3::zeros();
        let mut hi = Vector3::zeros();
        for &k in &self.tree.chain[v] {
            let s = self.tree.slots[k + 1];
            let e = s + self.wk(k);
            lo += s.inf(&e);
            hi += s.sup(&e);
        }
        (lo, hi)
    }

    /// Smallest distance between vehicles `i` and `j` over all displacements (or a value
    /// `≥ enough` once it is known to be at least that).
    fn pair_distance(&self, i: usize, j: usize, enough: f64) -> f64 {
        let (ci, cj) = (&self.tree.chain[i], &self.tree.chain[j]);
        let common = ci.iter().zip(cj.iter()).take_while(|(a, b)| a == b).count();
        let mut c = Vector3::zeros();
        let mut cols = Vec::with_capacity(ci.len() + cj.len());
        for &k in &ci[common..] {
            c += self.tree.slots[k + 1];
            cols.push(self.wk(k));
        }
        for &k in &cj[common..] {
            c -= self.tree.slots[k + 1];
            cols.push(-self.wk(k));
        }
        min_norm_box(&c, &cols, enough)
    }

    /// Smallest distance from `k` to the line of sight `j → parent(j)` over all
    /// displacements (or a value `≥ radius` once it is known to be at least that).
    ///
    /// With `P` the parent, the distance is `min over μ ∈ [0, 1]` of
    /// `|(k − P) − μ (j − P)|`; for a fixed `μ` that is affine in every `λ`, so the minimum
    /// over `λ` is the convex problem of [`min_norm_box`]. Over `μ` the minimum is bounded
    /// below interval by interval with its Lipschitz constant (certified to 1 cm).
    fn sight_clearance(&self, j: usize, k: usize, radius: f64) -> f64 {
        let p = self.tree.parent[j];
        // bounding-box rejection
        let (jl, jh) = self.bbox(j);
        let (pl, ph) = self.bbox(p);
        let (kl, kh) = self.bbox(k);
        let (sl, sh) = (jl.inf(&pl), jh.sup(&ph));
        let gap = (sl - kh).sup(&(kl - sh)).sup(&Vector3::zeros()).norm();
        if gap >= radius {
            return gap;
        }
        let (cp, ck) = (&self.tree.chain[p], &self.tree.chain[k]);
        let common = cp.iter().zip(ck.iter()).take_while(|(a, b)| a == b).count();
        let jf = j - 1; // j's own follower index (j is never the leader here)
                        // k − P = c0 + Σ λ a_f ;  j − P = S_j + λ_j w_j
        let mut vars: Vec<(usize, Vector3<f64>)> = Vec::new();
        let mut c0 = Vector3::zeros();
        let mut add = |f: usize, sign: f64, vars: &mut Vec<(usize, Vector3<f64>)>| {
            c0 += self.tree.slots[f + 1] * sign;
            let w = self.wk(f) * sign;
            match vars.iter_mut().find(|(g, _)| *g == f) {
                Some((_, acc)) => *acc += w,
                None => vars.push((f, w)),
            }
        };
        for &f in &ck[common..] {
            add(f, 1.0, &mut vars);
        }
        for &f in &cp[common..] {
            add(f, -1.0, &mut vars);
        }
        if !vars.iter().any(|(g, _)| *g == jf) {
            vars.push((jf, Vector3::zeros()));
        }
        let s_j = self.tree.slots[j];
        let w_j = self.wk(jf);
        let mut cols = vec![Vector3::zeros(); vars.len()];
        // g(μ) = min over λ is Lipschitz in μ with constant max|j − P| ≤ `lip`, so an interval
        // [a, b] is certified clear when min(g(a), g(b)) − lip·(b − a)/2 ≥ radius; otherwise
        // it is split, down to 1 cm along the line of sight.
        let lip = s_j.norm().max((s_j + w_j).norm()).max(1e-9);
        let grid = 8usize;
        let h0 = 1.0 / grid as f64;
        let enough = radius + lip * h0 / 2.0 + 1e-9;
        let mut at = |mu: f64| {
            for (col, (f, a)) in cols.iter_mut().zip(&vars) {
                *col = if *f == jf { a - w_j * mu } else { *a };
            }
            min_norm_box(&(c0 - s_j * mu), &cols, enough)
        };
        let mut g_min = f64::INFINITY;
        let mut stack: Vec<(f64, f64, f64, f64)> = Vec::with_capacity(64);
        let mut prev = (0.0, at(0.0));
        g_min = g_min.min(prev.1);
        for i in 1..=grid {
            let mu = i as f64 * h0;
            let g = at(mu);
            g_min = g_min.min(g);
            stack.push((prev.0, prev.1, mu, g));
            prev = (mu, g);
        }
        let mut bound = f64::INFINITY;
        while let Some((a, ga, b, gb)) = stack.pop() {
            let lb = ga.min(gb) - lip * (b - a) / 2.0;
            if lb >= radius {
                continue;
            }
            if lip * (b - a) < 0.01 {
                bound = bound.min(lb.max(0.0));
                continue;
            }
            let m = 0.5 * (a + b);
            let gm = at(m);
            g_min = g_min.min(gm);
            stack.push((a, ga, m, gm));
            stack.push((m, gm, b, gb));
        }
        g_min.min(bound)
    }

    /// Every constraint between follower vehicle `v` and the vehicles already assigned;
    /// the worst violation as an error.
    fn violations_of(
        &self,
        v: usize,
        d_min: f64,
        params: &FormationParams,
    ) -> Option<(f64, FormationError)> {
        let n = self.tree.names.len();
        let name = |i: usize| self.tree.names[i].clone();
        let mut worst: Option<(f64, FormationError)> = None;
        let mut note = |deficit: f64, e: FormationError| {
            if worst.as_ref().is_none_or(|(d, _)| deficit > *d) {
                worst = Some((deficit, e));
            }
        };
        // visibility range to its parent
        let p = self.tree.parent[v];
        let s = self.tree.slots[v];
        let far = s.norm().max((s + self.wk(v - 1)).norm());
        if far > params.visibility_range_m {
            note(
                far - params.visibility_range_m,
                FormationError::OutOfSight {
                    follower: name(v),
                    parent: name(p),
                    distance_m: far,
                    visibility_m: params.visibility_range_m,
                },
            );
        }
        for u in 0..n {
            if u == v || !self.assigned(u) {
                continue;
            }
            let (al, ah) = self.bbox(v);
            let (bl, bh) = self.bbox(u);
            let gap = (al - bh).sup(&(bl - ah)).sup(&Vector3::zeros()).norm();
            if gap < d_min {
                let d = self.pair_distance(v, u, d_min);
                if d < d_min {
                    note(
                        d_min - d,
                        FormationError::TooClose {
                            a: name(v),
                            b: name(u),
                            distance_m: d,
                            d_min_m: d_min,
                        },
                    );
                }
            }
            // u hides v's parent
            if u != p {
                let c = self.sight_clearance(v, u, params.occlusion_radius_m);
                if c < params.occlusion_radius_m {
                    note(
                        params.occlusion_radius_m - c,
                        FormationError::Occludes {
                            observer: name(v),
                            parent: name(p),
                            occluder: name(u),
                            clearance_m: c,
                            needed_m: params.occlusion_radius_m,
                        },
                    );
                }
            }
            // v hides u's parent
            if u != 0 && self.tree.parent[u] != v {
                let c = self.sight_clearance(u, v, params.occlusion_radius_m);
                if c < params.occlusion_radius_m {
                    note(
                        params.occlusion_radius_m - c,
                        FormationError::Occludes {
                            observer: name(u),
                            parent: name(self.tree.parent[u]),
                            occluder: name(v),
                            clearance_m: c,
                            needed_m: params.occlusion_radius_m,
                        },
                    );
                }
            }
        }
        worst
    }
}

fn check_params(d_min_m: f64, params: &FormationParams) -> Result<(), FormationError> {
    let pos = |k: &str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(FormationError::InvalidParam(format!(
                "{k} must be finite and > 0, got {v}"
            )))
        }
    };
    pos("d_min_m", d_min_m)?;
    pos("visibility_range_m", params.visibility_range_m)?;
    pos("occlusion_radius_m", params.occlusion_radius_m)?;
    pos("d_b_step_m", params.d_b_step_m)?;
    if !(params.max_depth_shift_m.is_finite() && params.max_depth_shift_m >= 0.0) {
        return Err(FormationError::InvalidParam(format!(
            "max_depth_shift_m must be finite and >= 0, got {}",
            params.max_depth_shift_m
        )));
    }
    Ok(())
}

/// Chooses `(D_a, D_b)` for every follower (same order as `followers`), in
/// [`crate::FollowerConfig`]'s convention (`D_a` with the paper's side sign applied by the
/// follower; `D_b` signed, + = down). See the [module docs](self).
pub fn assign_displacements(
    leader: &str,
    followers: &[FollowerSlot],
    d_min_m: f64,
    params: &FormationParams,
) -> Result<Vec<(f64, f64)>, FormationError> {
    check_params(d_min_m, params)?;
    let tree = build_tree(leader, followers)?;
    let mut cands: Vec<(f64, f64)> = Vec::new();
    let mut d_bs = vec![0.0];
    let mut k = 1.0;
    while k * params.d_b_step_m <= 2.0 * params.max_depth_shift_m + 1e-9 {
        d_bs.push(k * params.d_b_step_m);
        d_bs.push(-k * params.d_b_step_m);
        k += 1.0;
    }
    for &db in &d_bs {
        for sign in [1.0, -1.0] {
            for m in [1.25, 1.5, 2.0] {
                cands.push((sign * m * d_min_m, db));
            }
        }
    }
    // the nominal formation (no displacement) must already be safe: no D_a/D_b can fix it
    let nominal = Geometry {
        tree: &tree,
        w: vec![Some(Vector3::zeros()); followers.len()],
    };
    for &f in &tree.order {
        if let Some((_, cause)) = nominal.violations_of(f + 1, d_min_m, params) {
            return Err(FormationError::Impossible {
                follower: tree.names[f + 1].clone(),
                cause: Box::new(cause),
            });
        }
    }
    let mut geo = Geometry {
        tree: &tree,
        w: vec![None; followers.len()],
    };
    let mut choice = vec![0usize; followers.len()];
    let mut out = vec![(0.0, 0.0); followers.len()];
    let mut level = 0usize;
    let mut budget = params.search_budget;
    // the least-bad failure at the deepest level reached
    let mut deepest: Option<(usize, f64, FormationError)> = None;
    while level < tree.order.len() {
        let f = tree.order[level];
        let v = f + 1;
        let mut placed = false;
        while choice[f] < cands.len() {
            let cand = cands[choice[f]];
            choice[f] += 1;
            if budget == 0 {
                break;
            }
            budget -= 1;
            geo.w[f] = Some(segment(&tree.slots[v], cand));
            match geo.violations_of(v, d_min_m, params) {
                None => {
                    out[f] = cand;
                    placed = true;
                    break;
                }
                Some((deficit, e)) => {
                    let better = match &deepest {
                        None => true,
                        Some((lv, d, _)) => level > *lv || (level == *lv && deficit < *d),
                    };
                    if better {
                        deepest = Some((level, deficit, e));
                    }
                }
            }
        }
        if placed {
            level += 1;
            continue;
        }
        geo.w[f] = None;
        choice[f] = 0;
        if level == 0 || budget == 0 {
            let (lv, _, cause) = deepest.unwrap_or((
                level,
                0.0,
                FormationError::InvalidParam("no candidate".to_string()),
            ));
            let who = tree.order.get(lv).map_or(f, |x| *x);
            return Err(FormationError::Impossible {
                follower: tree.names[who + 1].clone(),
                cause: Box::new(cause),
            });
        }
        level -= 1;
        let prev = tree.order[level];
        geo.w[prev] = None;
    }
    Ok(out)
}

/// Verifies a given assignment (`shoal check`): tree, depth shifts, visibility range,
/// separation and lines of sight. Returns the worst violation.
pub fn check(
    leader: &str,
    followers: &[FollowerSlot],
    displacements: &[(f64, f64)],
    d_min_m: f64,
    params: &FormationParams,
) -> Result<(), FormationError> {
    check_params(d_min_m, params)?;
    let tree = build_tree(leader, followers)?;
    if displacements.len() != followers.len() {
        return Err(FormationError::WrongLength {
            expected: followers.len(),
            got: displacements.len(),
        });
    }
    for (f, d) in followers.iter().zip(displacements) {
        if !(d.0.is_finite() && d.1.is_finite()) {
            return Err(FormationError::InvalidParam(format!(
                "{}: displacement must be finite, got {d:?}",
                f.name
            )));
        }
        if d.1.abs() / 2.0 > params.max_depth_shift_m + 1e-9 {
            return Err(FormationError::DepthShift {
                follower: f.name.clone(),
                shift_m: d.1.abs() / 2.0,
                max_m: params.max_depth_shift_m,
            });
        }
    }
    let geo = Geometry {
        tree: &tree,
        w: tree
            .slots
            .iter()
            .skip(1)
            .zip(displacements)
            .map(|(s, d)| Some(segment(s, *d)))
            .collect(),
    };
    let mut worst: Option<(f64, FormationError)> = None;
    for v in 1..tree.names.len() {
        if let Some((d, e)) = geo.violations_of(v, d_min_m, params) {
            if worst.as_ref().is_none_or(|(w, _)| d > *w) {
                worst = Some((d, e));
            }
        }
    }
    match worst {
        Some((_, e)) => Err(e),
        None => Ok(()),
    }
}

/// Room a gap leaves beyond the safe distance between a wall and the nearest file that does
/// not shift, at the most, m (`shoal gen`'s gates use it).
pub const GAP_CLEAR_MARGIN_M: f64 = 2.0;

/// The narrowest gap the formation passes at the safe distance `d_min_m` with today's
/// method, and its full width (nominal lateral span), m: `(narrowest, full)`.
///
/// A V of heads at most two levels deep (the paper's five: no two vehicles on one track)
/// compresses fully: every follower may shift onto its parent's track, so the gap needs
/// only the safe distance plus [`GAP_CLEAR_MARGIN_M`] on either side of the leader's track
/// (the paper's 8 m passage). Any other tree passes with its outermost file on either side shifted inward onto the next
/// file's track: the walls stand the safe distance plus the margin (at most the room
/// between the two outermost files beyond `d_min_m`) outside the next file. Lateral offsets
/// are summed along each chain of slots, with the formation on one heading.
///
/// # Errors
/// [`FormationError`] when the followers do not form a tree under `leader`.
pub fn narrowest_gap_m(
    leader: &str,
    followers: &[FollowerSlot],
    d_min_m: f64,
) -> Result<(f64, f64), FormationError> {
    build_tree(leader, followers)?;
    let by_name: HashMap<&str, &FollowerSlot> =
        followers.iter().map(|f| (f.name.as_str(), f)).collect();
    // (lateral offset, depth in the tree) of each follower
    let chain = |f: &FollowerSlot| {
        let (mut y, mut depth, mut at) = (0.0, 0usize, f);
        loop {
            y += at.slot_in_parent_m[1];
            depth += 1;
            match by_name.get(at.parent.as_str()) {
                Some(p) if depth <= followers.len() => at = p,
                _ => return (y, depth),
            }
        }
    };
    let placed: Vec<(f64, usize)> = followers.iter().map(chain).collect();
    let outer = placed.iter().map(|p| p.0.abs()).fold(0.0, f64::max);
    let deepest = placed.iter().map(|p| p.1).max().unwrap_or(0);
    let full = 2.0 * outer;
    let mut tracks: Vec<f64> = placed.iter().map(|p| p.0).chain([0.0]).collect();
    tracks.sort_by(f64::total_cmp);
    let one_per_track = tracks.windows(2).all(|w| w[1] - w[0] > 0.05);
    if deepest <= 2 && one_per_track {
        return Ok((2.0 * (d_min_m + GAP_CLEAR_MARGIN_M), full));
    }
    // the second-outermost distinct lateral offset (the leader's track counts)
    let next = placed
        .iter()
        .map(|p| p.0.abs())
        .filter(|y| *y < outer - 0.05)
        .fold(0.0, f64::max);
    let margin = GAP_CLEAR_MARGIN_M.min(outer - next - d_min_m).max(0.0);
    Ok((2.0 * (next + d_min_m + margin), full))
}

#[cfg(test)]
mod gap_tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn slot(name: &str, parent: &str, y: f64) -> FollowerSlot {
        FollowerSlot {
            name: name.into(),
            parent: parent.into(),
            slot_in_parent_m: [-8.0, y, 0.0],
        }
    }

    #[test]
    fn the_papers_five_pass_its_8_m_passage_and_a_deep_v_only_shifts_its_outer_file() {
        let paper = [
            slot("F1", "L", -4.0),
            slot("F2", "L", 4.0),
            slot("F3", "F1", -4.0),
            slot("F4", "F2", 4.0),
        ];
        assert_eq!(narrowest_gap_m("L", &paper, 2.0).unwrap(), (8.0, 16.0));
        let mut v = paper.to_vec();
        v.push(slot("F5", "F3", -4.0));
        v.push(slot("F6", "F4", 4.0));
        // outer file at 12 m shifts onto the one at 8 m: walls 4 m outside it
        assert_eq!(narrowest_gap_m("L", &v, 2.0).unwrap(), (24.0, 24.0));
        // files 3 m apart leave 1 m beyond the safe distance
        let close: Vec<FollowerSlot> = v
            .iter()
            .map(|f| FollowerSlot {
                slot_in_parent_m: [-8.0, f.slot_in_parent_m[1] * 0.75, 0.0],
                ..f.clone()
            })
            .collect();
        assert_eq!(narrowest_gap_m("L", &close, 2.0).unwrap(), (18.0, 18.0));
        assert!(narrowest_gap_m("L", &[slot("F1", "X", 1.0)], 2.0).is_err());
        // two deep but a follower on the leader's track: only the outer files shift
        let mut wedge = paper.to_vec();
        wedge[2] = slot("F3", "F1", 4.0);
        assert_eq!(narrowest_gap_m("L", &wedge, 2.0).unwrap(), (16.0, 16.0));
        let mut tri = paper[..2].to_vec();
        tri.push(slot("F3", "L", 0.0));
        tri.push(slot("F4", "F1", -4.0));
        assert_eq!(narrowest_gap_m("L", &tri, 2.0).unwrap(), (16.0, 16.0));
    }
}
