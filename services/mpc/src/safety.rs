//! The safety layer: half-space constraints that keep the predicted positions off what the
//! vehicle has sensed, whatever target the planner asks for.
//!
//! Each step the planner hands over up to [`MAX_KEEPOUT`] remembered sonar returns `o_k`
//! and, for a follower, its parent's estimated position and velocity (level frame, never
//! truth: [`Keepout`]). For every such point and every constrained step `j` of the horizon
//! (the ends of the input blocks: steps 1, 3, 7, 13, 20 at P = 20, M = 5) the predicted
//! position `p_j` must satisfy
//!
//! ```text
//!   n_kjᵀ (p_j − o_k(t_j)) ≥ r_k − s_kj,     s_kj ≥ 0,
//! ```
//!
//! with `o_k(t_j) = o_k + w_k·t_j` (`w_k` the parent's velocity, 0 for a return) and
//! `r_k = D_min/2 + margin` for a return, `D_min + margin` for the parent. Any point of that
//! half-space is at least `r_k` from `o_k(t_j)`, so the constraint is sufficient whatever
//! the unit `n_kj` is. For a return `n_kj` is horizontal: the obstacle behind a return is
//! taken to reach up and down (a wall, a pillar), so the vehicle may not dive under or
//! climb over the point; the parent's is 3D, as a follower may pass above or below its
//! parent (the paper's vertical shift, D_b). `p_j = G_j v̂ + f_j` is linear in the scaled
//! input moves `v̂` (the position rows of the condensed prediction), so each is one linear
//! inequality of the QP.
//!
//! `n_kj` is chosen from the unconstrained minimiser's path (the polyline through its
//! predicted positions from the vehicle now):
//! - the path passes the point clear: from the point toward the predicted position (the
//!   tangent plane there: a vehicle passing alongside is not held back);
//! - the path comes inside the clearance: away from the path's nearest approach (a wall
//!   beside the track a current sets the vehicle toward is kept beside it);
//! - ... unless another such point within twice the clearance is pushed the other way
//!   (the path runs between two returns of a wall across it): along the line of sight from
//!   the vehicle now, so that it stops short rather than being pushed sideways both ways.
//!
//! The slack `s_kj` (one per point and step, m) keeps the QP feasible when the vehicle is
//! already inside a clearance: it costs `slack_weight·(s + 10·s²)`, far above the tracking
//! errors a planner's target makes. And `Safety::hold_short` stops the reference short
//! of a clearance it would enter, so that the vehicle slows and holds where no safe motion
//! toward the target exists instead of being pulled into soft constraints (which, on a
//! linearised model, it would creep through).
//!
//! Cost: the unconstrained minimiser is checked against every point first (its whole
//! path); when it keeps every clearance and bound it is the exact solution, as without the
//! layer; when it keeps every clearance but not a bound, the bounds-only QP is solved and
//! stands if its answer keeps every clearance too. Only the rest solves this larger QP.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSolver, IPSolver};
use nalgebra::{SMatrix, Vector3};

pub use ipc_types::{Keepout, MAX_KEEPOUT};

use crate::prediction::NU;
use crate::{MpcConfig, MpcError, MpcStatus};

/// Position rows of one block's prediction sensitivity `S_j^b` (3 × 6).
pub(crate) type PosSens = SMatrix<f64, 3, NU>;

/// Points the layer can hold at once: the returns and the parent.
pub(crate) const N_POINTS: usize = MAX_KEEPOUT + 1;

/// One point to keep clear of this step.
#[derive(Debug, Clone, Copy, Default)]
struct Point {
    /// Position now, level frame, m.
    at: Vector3<f64>,
    /// Velocity, m/s (the parent's; 0 for a return).
    vel: Vector3<f64>,
    /// Clearance to keep, m.
    clearance: f64,
    /// Keep the clearance horizontally (a return: the obstacle behind it is taken to
    /// reach up and down, as a wall or a pillar does), or in 3D (the parent, which a
    /// follower may pass above or below: the paper's vertical shift).
    column: bool,
}

impl Point {
    /// The separation that counts: horizontal for a column, full otherwise.
    fn apart(&self, d: Vector3<f64>) -> Vector3<f64> {
        if self.column {
            Vector3::new(d.x, d.y, 0.0)
        } else {
            d
        }
    }
}

/// The controller's QP data as `assemble` fills it: the upper triangle of `P` (column by
/// column), `q`, and the bounds' right-hand side `b`.
#[derive(Clone, Copy)]
pub(crate) struct QpData<'a> {
    pub(crate) p: &'a [f64],
    pub(crate) q: &'a [f64],
    pub(crate) b: &'a [f64],
}

/// The layer's QP (the controller's QP plus slacks and half-spaces) and its scratch.
pub(crate) struct Safety {
    solver: DefaultSolver<f64>,
    /// Input variables `6M`.
    n_u: usize,
    /// Constrained steps (1-based step index of each block's end).
    pub(crate) steps: Vec<usize>,
    /// `G_j` per constrained step and block (unscaled: `S_j^b` rows 0..3), and `f_j`.
    pub(crate) sens: Vec<PosSens>,
    pub(crate) free_pos: Vec<Vector3<f64>>,
    points: [Point; N_POINTS],
    active: [bool; N_POINTS],
    p_vals: Vec<f64>,
    q_vals: Vec<f64>,
    a_vals: Vec<f64>,
    b_vals: Vec<f64>,
    /// Scratch: predicted positions of the linearisation point per constrained step.
    pred: Vec<Vector3<f64>>,
    obstacle_clearance: f64,
    parent_clearance: f64,
}

impl Safety {
    /// Rows of `A` per input column: two bounds and one per point and constrained step.
    fn col_len(&self) -> usize {
        2 + N_POINTS * self.steps.len()
    }

    /// Builds the layer's solver for the blocks ending at `block_end`, with the
    /// upper-triangle pattern of the controller's Hessian (`colptr`, `rowval` over its
    /// columns) and `nominal` data for clarabel's equilibration.
    pub(crate) fn new(
        cfg: &MpcConfig,
        block_end: &[usize],
        (colptr, rowval): (&[usize], &[usize]),
        nominal: QpData<'_>,
        build: impl Fn(
            &CscMatrix<f64>,
            &[f64],
            &CscMatrix<f64>,
            &[f64],
        ) -> Result<DefaultSolver<f64>, MpcError>,
    ) -> Result<Self, MpcError> {
        let (nominal_p, nominal_q, nominal_b) = (nominal.p, nominal.q, nominal.b);
        let n_u = nominal_q.len();
        let steps = block_end.to_vec();
        let n_j = steps.len();
        // one slack per half-space (point, constrained step): a violation that cannot be
        // helped at an early step (the vehicle inside a clearance, still moving in) does
        // not license the later steps to violate as much
        let n_s = N_POINTS * n_j;
        let n = n_u + n_s;
        // P: the controller's upper triangle, then the slacks' diagonal.
        let mut p_colptr = colptr.to_vec();
        let mut p_rowval = rowval.to_vec();
        for k in 0..n_s {
            p_rowval.push(n_u + k);
            p_colptr.push(p_rowval.len());
        }
        let mut p_vals = nominal_p.to_vec();
        p_vals.extend(std::iter::repeat_n(20.0 * cfg.slack_weight, n_s));
        let mut q_vals = nominal_q.to_vec();
        q_vals.extend(std::iter::repeat_n(cfg.slack_weight, n_s));
        // A: rows [bounds +, bounds −, half-spaces (point k, step jj at 2n_u + k·n_j + jj),
        // slacks ≥ 0 (2n_u + n_s + r)]; slack r belongs to half-space r.
        let hs0 = 2 * n_u;
        let nn0 = hs0 + n_s;
        let m = nn0 + n_s;
        let mut a_colptr = vec![0];
        let mut a_rowval = Vec::new();
        let mut a_vals = Vec::new();
        for c in 0..n_u {
            a_rowval.extend([c, n_u + c]);
            a_vals.extend([1.0, -1.0]);
            for r in 0..n_s {
                a_rowval.push(hs0 + r);
                // nominal: every point ahead, pushing back along x
                a_vals.push(if c % NU == 0 { 0.01 } else { 0.0 });
            }
            a_colptr.push(a_rowval.len());
        }
        for r in 0..n_s {
            a_rowval.extend([hs0 + r, nn0 + r]);
            a_vals.extend([-1.0, -1.0]);
            a_colptr.push(a_rowval.len());
        }
        let mut b_vals = nominal_b.to_vec();
        b_vals.extend(std::iter::repeat_n(1.0, n_s));
        b_vals.extend(std::iter::repeat_n(0.0, n_s));
        let p_mat = CscMatrix::new(n, n, p_colptr, p_rowval, p_vals.clone());
        let a_mat = CscMatrix::new(m, n, a_colptr, a_rowval, a_vals.clone());
        let solver = build(&p_mat, &q_vals, &a_mat, &b_vals)?;
        let nb = steps.len();
        Ok(Self {
            solver,
            n_u,
            sens: vec![PosSens::zeros(); n_j * nb],
            free_pos: vec![Vector3::zeros(); n_j],
            steps,
            points: [Point::default(); N_POINTS],
            active: [false; N_POINTS],
            p_vals,
            q_vals,
            a_vals,
            b_vals,
            pred: vec![Vector3::zeros(); n_j],
            obstacle_clearance: cfg.d_min_m / 2.0 + cfg.safety_margin_m,
            parent_clearance: cfg.d_min_m + cfg.safety_margin_m,
        })
    }

    /// The target with its reference (`position + velocity·t` over `horizon_s`, reached
    /// from the vehicle now along a straight line) stopped short of the first clearance it
    /// would enter (the straight way to the target counting only where it runs through a
    /// point, within [`THROUGH`] of its clearance): the vehicle is then asked to slow and
    /// hold where no safe motion toward the target exists, instead of being pulled into the
    /// constraints (which, soft and linearised, would let it creep in). The target itself
    /// when the reference stays clear.
    pub(crate) fn hold_short(&self, target: &crate::MpcTarget, horizon_s: f64) -> crate::MpcTarget {
        let p = target.position_m;
        let v = target.velocity_mps;
        // the first entry, as a fraction of each leg: vehicle → target, target → its end
        let mut first: Option<(usize, f64)> = None;
        for k in (0..N_POINTS).filter(|&k| self.active[k]) {
            let pt = self.points[k];
            let r = pt.clearance + HOLD_MARGIN_M;
            let legs = [
                (Vector3::zeros(), p, pt.at),
                (p, p + v * horizon_s, pt.at + pt.vel * horizon_s),
            ];
            for (leg, (a, b, o)) in legs.into_iter().enumerate() {
                let (a, b) = (pt.apart(a - o), pt.apart(b - o));
                // The way from the vehicle to the target counts only when it runs through
                // the point (within THROUGH of its clearance): one that passes it at the
                // edge of the clearance is the constraints' to keep (a vehicle set toward
                // a wall beside its track must not be frozen there).
                if leg == 0 && segment_closest(a, b).norm() >= THROUGH * pt.clearance {
                    continue;
                }
                if let Some(f) = entry(a, b, r) {
                    if first.is_none_or(|(l, g)| (leg, f) < (l, g)) {
                        first = Some((leg, f));
                    }
                    break;
                }
            }
        }
        match first {
            None => *target,
            Some((0, f)) => crate::MpcTarget {
                position_m: p * f,
                velocity_mps: Vector3::zeros(),
                yaw_rel_rad: target.yaw_rel_rad,
            },
            Some((_, f)) => crate::MpcTarget {
                position_m: p,
                velocity_mps: v * f,
                yaw_rel_rad: target.yaw_rel_rad,
            },
        }
    }

    /// Takes this step's points; false when there is nothing to keep clear of.
    pub(crate) fn load(&mut self, keepout: &Keepout) -> bool {
        self.active = [false; N_POINTS];
        for (k, p) in keepout.points().iter().enumerate() {
            let at = Vector3::from(*p);
            if at.iter().all(|x| x.is_finite()) {
                self.points[k] = Point {
                    at,
                    vel: Vector3::zeros(),
                    clearance: self.obstacle_clearance,
                    column: true,
                };
                self.active[k] = true;
            }
        }
        if let Some((p, v)) = keepout.parent {
            let (at, vel) = (Vector3::from(p), Vector3::from(v));
            if at.iter().chain(vel.iter()).all(|x| x.is_finite()) {
                self.points[MAX_KEEPOUT] = Point {
                    at,
                    vel,
                    clearance: self.parent_clearance,
                    column: false,
                };
                self.active[MAX_KEEPOUT] = true;
            }
        }
        self.active.iter().any(|a| *a)
    }

    /// Predicted positions at the constrained steps for scaled moves `x` (`None`: zero
    /// moves, the previous input held), into `pred`.
    fn predict(&mut self, x: Option<&[f64]>, umax: &nalgebra::Vector6<f64>) {
        let nb = self.steps.len();
        for jj in 0..self.steps.len() {
            let mut p = self.free_pos[jj];
            if let Some(x) = x {
                for b in 0..nb {
                    let g = &self.sens[jj * nb + b];
                    for c in 0..NU {
                        let v = x[b * NU + c] * umax[c];
                        p += g.column(c) * v;
                    }
                }
            }
            self.pred[jj] = p;
        }
    }

    /// True when the path the predicted positions (`pred`) trace from the vehicle now comes
    /// within point `k`'s clearance: the polyline through them, each segment against the
    /// point where it is at the segment's end.
    fn crosses(&self, k: usize, h: f64) -> bool {
        self.approach(k, h).0 < self.points[k].clearance
    }

    /// The least distance from point `k` to the path the predicted positions (`pred`)
    /// trace from the vehicle now, and the separation (path point − point, as the point
    /// counts it) where it is least.
    fn approach(&self, k: usize, h: f64) -> (f64, Vector3<f64>) {
        let pt = self.points[k];
        let mut from = Vector3::zeros();
        let mut best = (f64::INFINITY, Vector3::zeros());
        for (&j, &to) in self.steps.iter().zip(&self.pred) {
            #[allow(clippy::cast_precision_loss)]
            let o = pt.at + pt.vel * (j as f64 * h);
            let (a, b) = (pt.apart(from - o), pt.apart(to - o));
            from = to;
            let c = segment_closest(a, b);
            if c.norm() < best.0 {
                best = (c.norm(), c);
            }
        }
        best
    }

    /// True when the moves `x` (scaled) keep every clearance all along the predicted path.
    pub(crate) fn keeps_clear(&mut self, x: &[f64], h: f64, umax: &nalgebra::Vector6<f64>) -> bool {
        self.predict(Some(x), umax);
        (0..N_POINTS)
            .filter(|&k| self.active[k])
            .all(|k| !self.crosses(k, h))
    }

    /// Solves the controller's QP (`qp`, as filled by `assemble`) with the half-spaces,
    /// linearised about the moves `lin` (scaled; `None`: zero moves).
    /// Returns the scaled moves (the first `6M` entries of clarabel's solution are copied
    /// to `out`), the iterations and the status.
    pub(crate) fn solve(
        &mut self,
        qp: QpData<'_>,
        lin: Option<&[f64]>,
        h: f64,
        umax: &nalgebra::Vector6<f64>,
        out: &mut Vec<f64>,
    ) -> Result<(u32, MpcStatus), MpcError> {
        let (p, q, b) = (qp.p, qp.q, qp.b);
        let n_u = self.n_u;
        let nb = self.steps.len();
        let n_j = self.steps.len();
        self.predict(lin, umax);
        self.p_vals[..p.len()].copy_from_slice(p);
        self.q_vals[..n_u].copy_from_slice(q);
        self.b_vals[..2 * n_u].copy_from_slice(b);
        let col = self.col_len();
        let hs0 = 2 * n_u;
        // How each point is held off. A point the linearisation's path passes clear of:
        // from that path (the tangent at each predicted position). A point it comes within
        // the clearance of: away from the path's nearest approach (a wall beside the track
        // that the vehicle sags toward is kept beside it, and the vehicle goes on) —
        // unless the point is pinched, another such point within twice the clearance being
        // pushed the other way (the path runs between two returns of a wall across it):
        // then along the line of sight from the vehicle now, so that it stops short instead
        // of being pushed sideways both ways at once.
        let mut crossing = [false; N_POINTS];
        let mut away: [Option<Vector3<f64>>; N_POINTS] = [None; N_POINTS];
        for k in (0..N_POINTS).filter(|&k| self.active[k]) {
            let (d, sep) = self.approach(k, h);
            crossing[k] = d < self.points[k].clearance;
            if crossing[k] && d > 1e-6 {
                away[k] = Some(sep / d);
            }
        }
        let mut pinched = [false; N_POINTS];
        for k in 0..N_POINTS {
            for j in 0..N_POINTS {
                if let (Some(a), Some(b)) = (away[k], away[j]) {
                    let (pk, pj) = (self.points[k], self.points[j]);
                    let close = pk.apart(pk.at - pj.at).norm() < pk.clearance + pj.clearance;
                    if j != k && close && a.dot(&b) < 0.0 {
                        pinched[k] = true;
                    }
                }
            }
        }
        for k in 0..N_POINTS {
            let crossing = crossing[k];
            for jj in 0..n_j {
                let row = k * n_j + jj;
                let (coef, rhs) = if self.active[k] {
                    let pt = self.points[k];
                    #[allow(clippy::cast_precision_loss)]
                    let o = pt.at + pt.vel * (self.steps[jj] as f64 * h);
                    let d = pt.apart(self.pred[jj] - o);
                    let back = pt.apart(-o);
                    let n = if !crossing && d.norm() > 1e-6 {
                        d.normalize()
                    } else if let (Some(a), false) = (away[k], pinched[k]) {
                        a
                    } else if back.norm() > 1e-6 {
                        back.normalize()
                    } else {
                        -Vector3::x()
                    };
                    // n·(G v̂ + f − o) + s ≥ r  ⇔  −n·G v̂ − s ≤ n·(f − o) − r
                    (Some(n), n.dot(&(self.free_pos[jj] - o)) - pt.clearance)
                } else {
                    (None, 1.0)
                };
                for bk in 0..nb {
                    let g = &self.sens[jj * nb + bk];
                    for c in 0..NU {
                        let v = coef.map_or(0.0, |n| -(n.dot(&g.column(c).into_owned())) * umax[c]);
                        self.a_vals[(bk * NU + c) * col + 2 + row] = v;
                    }
                }
                self.b_vals[hs0 + row] = rhs;
            }
        }
        let setup = |e: clarabel::solver::DataUpdateError| MpcError::Setup(e.to_string());
        self.solver.update_P(&self.p_vals).map_err(setup)?;
        self.solver.update_q(&self.q_vals).map_err(setup)?;
        self.solver.update_A(&self.a_vals).map_err(setup)?;
        self.solver.update_b(&self.b_vals).map_err(setup)?;
        self.solver.solve();
        let sol = &self.solver.solution;
        let (iterations, status) = crate::outcome(sol, MpcStatus::Guarded)?;
        out.clear();
        out.extend_from_slice(&sol.x[..n_u]);
        Ok((iterations, status))
    }
}

/// Margin beyond a clearance at which a held reference stops, m.
const HOLD_MARGIN_M: f64 = 0.1;

/// The way to the target runs through a point when it passes within this share of the
/// point's clearance (through a wall of returns 1.5 m apart it passes within 0.75 m).
const THROUGH: f64 = 0.75;

/// The fraction of the segment from `a` to `b` at which it first comes within `r` of the
/// origin, or `None`. A segment that starts within `r` enters at 0 if it goes on toward
/// the origin, and not at all if it runs along or away (a vehicle already inside a
/// clearance is not held there: the constraints take it out).
fn entry(a: Vector3<f64>, b: Vector3<f64>, r: f64) -> Option<f64> {
    if a.norm() < r {
        return (a.dot(&(b - a)) < 0.0).then_some(0.0);
    }
    let d = b - a;
    let (qa, qb, qc) = (d.norm_squared(), 2.0 * a.dot(&d), a.norm_squared() - r * r);
    if qa <= 0.0 {
        return None;
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return None;
    }
    let f = (-qb - disc.sqrt()) / (2.0 * qa);
    (0.0..=1.0).contains(&f).then_some(f)
}

/// The point of the segment from `a` to `b` nearest the origin.
fn segment_closest(a: Vector3<f64>, b: Vector3<f64>) -> Vector3<f64> {
    let ab = b - a;
    let l2 = ab.norm_squared();
    let t = if l2 > 0.0 {
        (-a.dot(&ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    a + ab * t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entry_is_where_a_segment_first_meets_the_circle() {
        let e = |a: [f64; 3], b: [f64; 3]| entry(Vector3::from(a), Vector3::from(b), 1.0);
        // straight at it from 3 m: meets it at 2 m, two thirds of the way
        assert!((e([-3.0, 0.0, 0.0], [3.0, 0.0, 0.0]).unwrap() - 2.0 / 6.0).abs() < 1e-12);
        // past it at 1.5 m: never
        assert_eq!(e([-3.0, 1.5, 0.0], [3.0, 1.5, 0.0]), None);
        // inside already: going deeper enters at once, going along or out does not
        assert_eq!(e([0.5, 0.0, 0.0], [-3.0, 0.0, 0.0]), Some(0.0));
        assert_eq!(e([0.5, 0.0, 0.0], [3.0, 0.0, 0.0]), None);
        assert_eq!(e([0.0, 0.5, 0.0], [3.0, 0.5, 0.0]), None);
        // short of it
        assert_eq!(e([-3.0, 0.0, 0.0], [-2.0, 0.0, 0.0]), None);
    }

    #[test]
    fn segment_distance_is_to_the_nearest_point_of_the_segment() {
        let d =
            |a: [f64; 3], b: [f64; 3]| segment_closest(Vector3::from(a), Vector3::from(b)).norm();
        assert!((d([-1.0, 2.0, 0.0], [1.0, 2.0, 0.0]) - 2.0).abs() < 1e-12);
        assert!((d([1.0, 1.0, 0.0], [3.0, 1.0, 0.0]) - 2f64.sqrt()).abs() < 1e-12);
        assert!((d([0.5, 0.0, 0.0], [0.5, 0.0, 0.0]) - 0.5).abs() < 1e-12);
    }
}
