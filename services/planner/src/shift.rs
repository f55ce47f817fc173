//! The paper's formation shift, eqs. (4)-(9), as pure functions.
//!
//! Everything here is in the **parent's frame** `(x̃, ỹ, z̃)`: origin at the parent, x̃ along
//! its heading, ỹ to starboard, z̃ down (the paper draws ỹ to the left; see the sign rule
//! below). The nominal slot is `X̃_F = (x̃_F, ỹ_F, z̃_F)`.
//!
//! # The displacement segment, eqs. (4) and (5)
//! The follower's slot may slide along a straight segment from `X̃_F` to a point on the
//! parent's track `ỹ = 0`. Eq. (4) is the line through `(x̃_F, ỹ_F)` and
//! `(x̃_F ± D_a/2, 0)`:
//! ```text
//!   ±(D_a/2)(ỹ − ỹ_F) + ỹ_F (x̃ − x̃_F) = 0
//!   ⇒ x̃ = x̃_F ± (D_a/2) · (ỹ_F − ỹ)/ỹ_F               (ỹ_F ≠ 0)
//! ```
//! (check: `ỹ = ỹ_F` gives `x̃_F`, `ỹ = 0` gives `x̃_F ± D_a/2`). Eq. (5) is the same
//! construction in the vertical plane:
//! ```text
//!   ±(D_b/2)(ỹ − ỹ_F) + ỹ_F z̃ = 0   ⇒   z̃ = ±(D_b/2) · (ỹ_F − ỹ)/ỹ_F
//! ```
//! Both are linear in the **progress** `λ = (ỹ_F − ỹ)/ỹ_F ∈ [0, 1]` (0 at the slot, 1 on the
//! parent's track), which is how this module evaluates them.
//!
//! **End point of the vertical shift: `±D_b/2`, not the text's `±D_b`.** The paper's text
//! puts the end point at `(±D_b, 0)` while eq. (5) and eq. (8) both give `±D_b/2`. We follow
//! the two equations: it also gives `D_b` the same meaning as `D_a` — the separation between
//! two followers that shift in opposite directions (`±D_a/2` each) — which is the quantity
//! the formation check reasons about. We also allow a nominal depth offset `z̃_F ≠ 0`
//! (eq. (5) assumes 0): `z̃ = z̃_F + (d_b/2)·λ`.
//!
//! **Signs.** The paper's "±" in eq. (4) is "+" for a follower left of x̃ (port) and "−" for
//! one on the right. Here `d_a` is given as a length with the paper's sign applied
//! automatically ([`Displacement::d_a_signed`]): the end point is `x̃_F + s·d_a/2` with
//! `s = +1` for a port slot (`ỹ_F < 0` in our starboard-positive frame) and `−1` for a
//! starboard slot; a negative `d_a` reverses it. `d_b` is signed directly: `+` = down.
//!
//! # The shift, eqs. (7) and (8)
//! Eq. (7): proximity of an obstacle point `ỹ_dj` to the follower's predicted track
//! `ỹ = ỹ_F`: `δ_j = S(ỹ_dj)(ỹ_dj − ỹ_F)`, `S = +1` if `ỹ_dj ≥ 0` else `−1`. It is positive
//! when the point lies farther out than the follower on its own side of the parent's track,
//! and negative when it lies between the follower's track and the parent's. (The formula is
//! unchanged by mirroring ỹ, so our starboard-positive ỹ needs no conversion.) The point with
//! the smallest `δ_j` is `X_dc`.
//!
//! Eq. (8) as printed has typos: its x̃ line reads `D_a(ỹ_F − ỹ_F)/(2ỹ_F)`, which is
//! identically zero. Substituting the new lateral position `ỹ* ` into eq. (4) and (5) gives
//! the consistent form implemented here:
//! ```text
//!   ỹ*  = ỹ_dc − sign(ỹ_dc)·D_min   if min δ_j < D_min,   else ỹ_F
//!         then clamped to the segment: between 0 and ỹ_F (never across the parent's track)
//!   λ   = (ỹ_F − ỹ*)/ỹ_F
//!   x̃* = x̃_F ± (D_a/2)·λ          = x̃_F ± D_a(ỹ_F − ỹ*)/(2ỹ_F)
//!   z̃* = z̃_F ± (D_b/2)·λ          = z̃_F ± D_b(ỹ_F − ỹ*)/(2ỹ_F)
//! ```
//! (eq. (8)'s z̃ line is `±D_b(ỹ* − ỹ_F)/(2ỹ_F)`: the same up to the sign absorbed in "±").
//! So the slot keeps `D_min` laterally from the nearest obstacle point, on the side of the
//! parent's track (which the parent has already found safe). A follower whose slot is on the
//! parent's track (`ỹ_F = 0`) has no segment and never shifts.
//!
//! # The filter, eq. (9)
//! `X̂*(k) = X̂*(k−1) + β (X̃*(k) − X̂*(k−1))`, once per planner step: see [`SlotFilter`].
//!
//! # Eq. (6)
//! [`return_in_parent`] puts one rangefinder return into the parent's frame with the
//! parent's pose from vision: `X_d = X_F^L + R_L R_Fᵀ d_j (cos α_j, sin α_j)` is
//! `T_FL⁻¹ · p_body` with `T_FL` the parent's pose in the follower's body frame (eq. (1):
//! `X_F^L = −(R_L^F)ᵀ X_L^F`).

use nalgebra::{Isometry3, Point3, Vector3};

/// Eq. (7): proximity `δ = S(ỹ_d)(ỹ_d − ỹ_F)` of an obstacle point at lateral position
/// `y_d` (parent frame) to the follower's predicted track `ỹ = y_f`.
pub fn proximity(y_d: f64, y_f: f64) -> f64 {
    let s = if y_d >= 0.0 { 1.0 } else { -1.0 };
    s * (y_d - y_f)
}

/// Eq. (6): one return (range `d`, azimuth `az` to starboard, elevation `el` down, from a
/// transducer at `mount_body` on the follower) in the parent's frame, given the parent's
/// pose in the follower's body frame.
pub fn return_in_parent(
    parent_in_body: &Isometry3<f64>,
    mount_body: &Vector3<f64>,
    d: f64,
    az: f64,
    el: f64,
) -> Point3<f64> {
    let p_body = Point3::from(mount_body + beam_vector(d, az, el));
    parent_in_body.inverse_transform_point(&p_body)
}

/// The return point `d·(cos el cos az, cos el sin az, sin el)` relative to the transducer,
/// body axes.
pub fn beam_vector(d: f64, az: f64, el: f64) -> Vector3<f64> {
    Vector3::new(
        d * el.cos() * az.cos(),
        d * el.cos() * az.sin(),
        d * el.sin(),
    )
}

/// A follower's displacement segment (eqs. (4), (5)) in the parent's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Displacement {
    /// Nominal slot `X̃_F`, m.
    pub slot: Vector3<f64>,
    /// `D_a`, m: the length whose half moves the slot along x̃; the paper's side sign is
    /// applied by [`Displacement::d_a_signed`].
    pub d_a: f64,
    /// `D_b`, m, signed (+ = down): the slot moves `d_b/2` in z̃ at the end of the segment.
    pub d_b: f64,
}

/// The result of eqs. (7)-(8) for one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shift {
    /// The shifted slot `X̃*` (eq. (8)), parent frame, m.
    pub slot: Vector3<f64>,
    /// Progress along the segment, 0 (nominal) to 1 (on the parent's track).
    pub lambda: f64,
    /// `min δ_j` (eq. (7)), m; `f64::INFINITY` with no point.
    pub delta_min: f64,
    /// Lateral position `ỹ_dc` of the point that set `delta_min`, m.
    pub y_dc: Option<f64>,
    /// `true` if `min δ_j < D_min` (the slot is being shifted).
    pub active: bool,
}

impl Displacement {
    /// `D_a` with the paper's sign: `+|d_a|` for a port slot (`ỹ_F < 0`, the paper's "left"),
    /// `−|d_a|` for starboard; a negative configured `d_a` flips it. 0 on the track.
    pub fn d_a_signed(&self) -> f64 {
        let y = self.slot.y;
        if y < 0.0 {
            self.d_a
        } else if y > 0.0 {
            -self.d_a
        } else {
            0.0
        }
    }

    /// The point of the segment at progress `lambda` ∈ [0, 1] (eqs. (4), (5)).
    pub fn at(&self, lambda: f64) -> Vector3<f64> {
        let l = lambda.clamp(0.0, 1.0);
        if self.slot.y == 0.0 {
            return self.slot;
        }
        Vector3::new(
            self.slot.x + 0.5 * self.d_a_signed() * l,
            self.slot.y * (1.0 - l),
            self.slot.z + 0.5 * self.d_b * l,
        )
    }

    /// The segment's end point on the parent's track.
    pub fn end(&self) -> Vector3<f64> {
        self.at(1.0)
    }

    /// The slot at lateral position `y_star` (eq. (8) with ỹ* given), clamped to the segment.
    pub fn at_lateral(&self, y_star: f64) -> (Vector3<f64>, f64) {
        let y_f = self.slot.y;
        if y_f == 0.0 {
            return (self.slot, 0.0);
        }
        let lambda = ((y_f - y_star) / y_f).clamp(0.0, 1.0);
        (self.at(lambda), lambda)
    }

    /// Eqs. (7)-(8): the shifted slot given the lateral positions `ỹ_dj` (parent frame) of
    /// the obstacle points seen this step.
    pub fn shift(&self, y_d: impl IntoIterator<Item = f64>, d_min: f64) -> Shift {
        let y_f = self.slot.y;
        let mut delta_min = f64::INFINITY;
        let mut y_dc = None;
        for y in y_d {
            let delta = proximity(y, y_f);
            if delta < delta_min {
                delta_min = delta;
                y_dc = Some(y);
            }
        }
        match y_dc {
            Some(y) if delta_min < d_min && y_f != 0.0 => {
                let sign = if y >= 0.0 { 1.0 } else { -1.0 };
                let (slot, lambda) = self.at_lateral(y - sign * d_min);
                Shift {
                    slot,
                    lambda,
                    delta_min,
                    y_dc,
                    active: true,
                }
            }
            _ => Shift {
                slot: self.slot,
                lambda: 0.0,
                delta_min,
                y_dc,
                active: y_dc.is_some() && delta_min < d_min,
            },
        }
    }
}

/// Eq. (9): first-order low-pass of the moving slot, one update per planner step.
///
/// `X̂(k) = X̂(k−1) + β (X̃(k) − X̂(k−1))`. The first input initialises the state (no
/// transient from zero). After `k` steps of a constant input `u` from `X̂(0)`:
/// `X̂(k) = u + (1 − β)^k (X̂(0) − u)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlotFilter {
    beta: f64,
    state: Option<Vector3<f64>>,
}

impl SlotFilter {
    /// A filter with smoothing coefficient `beta` ∈ [0, 1] (1 = no smoothing).
    pub fn new(beta: f64) -> Self {
        Self {
            beta: beta.clamp(0.0, 1.0),
            state: None,
        }
    }

    /// One step of eq. (9); returns the filtered slot.
    pub fn update(&mut self, input: &Vector3<f64>) -> Vector3<f64> {
        let next = match self.state {
            None => *input,
            Some(prev) => prev + self.beta * (input - prev),
        };
        self.state = Some(next);
        next
    }

    /// The current output, if any input was seen.
    pub fn value(&self) -> Option<Vector3<f64>> {
        self.state
    }

    /// Sets the state (e.g. to the nominal slot at start).
    pub fn reset(&mut self, value: Vector3<f64>) {
        self.state = Some(value);
    }
}
