//! The parent's trail: where the parent's estimate has been, for slots that follow the
//! parent's path instead of turning rigidly with its heading (`[follower] trail`).
//!
//! The paper's slot is rigid: the target is `p + R(ψ)·s`, the slot `s` turned with the
//! parent's heading `ψ` now. In a turn a slot `|s_x|` behind swings across the parent's
//! track by `|s_x|·Δψ`; a follower of a follower adds its own swing, so deep files cut a
//! corner by more than a shallow one beside them and neighbouring files cross (measured on
//! composed courses: columns of 11-50 through 50-150° turns came within 0.2-1.96 m, where
//! passages kept 2.5 m). With a trail the slot bends along the parent's path: its
//! along-track arm lies on the chord from where the parent was the arm's length back along
//! its path (heading `ψ_q` there) to where it is now, its lateral and vertical parts square
//! to the path there:
//!
//! ```text
//!   target = p + R(ψ_c)·(s_x, 0, 0) + R(ψ_q)·(0, s_y, s_z),   ψ_c = ψ − (ψ − ψ_q)/2,
//! ```
//!
//! with `ψ_q` the parent's heading at arc length `L = −s_x` back along its trail. In a
//! steady turn of radius `R` the chord's end is the point of the path `L` back (to
//! `L·(L/R)²/24`), so each file swims its parent's path offset sideways and a turn does not
//! fold files onto each other; on a straight leg `ψ_q = ψ` and the target is the rigid
//! slot's, also while the parent moves sideways (a trail of positions would replay that
//! move `L` later: measured on the paper scenario, its followers' clearance fell from 1.85
//! to 1.72 m and the after-passage slot RMS rose from 0.22 to 0.28 m). The follower heads
//! so that it sees its parent where the rigid slot shows it. The target's velocity is the
//! parent's speed along its path at the trail point (heading `ψ_q`), without the sideways
//! part of the parent's velocity: a file then passes a parent's swerve on without
//! amplifying it even without the headway (`tests/string.rs`). Where the trail is shorter
//! than `L` (the start) it is carried straight back along its oldest heading. A slot ahead
//! of its parent (`s_x ≥ 0`) stays rigid.
//!
//! Only estimates are stored (the planner's observer of its parent, in the follower's
//! odometry frame): no truth. Points closer than [`STEP_M`] to the last are not stored,
//! so that the estimate's noise does not lengthen the path.

use nalgebra::Vector3;

use crate::frames::wrap;

/// Least distance between stored points, m.
pub const STEP_M: f64 = 0.5;
/// Points kept: 80 m of path at [`STEP_M`].
pub const CAPACITY: usize = 160;

/// Where the parent has been (odometry frame) and its heading there.
#[derive(Debug, Clone, Default)]
pub struct Trail {
    /// Oldest first.
    points: std::collections::VecDeque<(Vector3<f64>, f64)>,
}

impl Trail {
    /// An empty trail.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the trail (the parent's estimate restarted).
    pub fn clear(&mut self) {
        self.points.clear();
    }

    /// Points stored.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Adds the parent's estimate if it moved [`STEP_M`] from the last point.
    pub fn push(&mut self, pos: Vector3<f64>, yaw: f64) {
        if !(pos.iter().all(|x| x.is_finite()) && yaw.is_finite()) {
            return;
        }
        if let Some((last, _)) = self.points.back() {
            if (pos - last).xy().norm() < STEP_M {
                return;
            }
        }
        if self.points.len() == CAPACITY {
            self.points.pop_front();
        }
        self.points.push_back((pos, yaw));
    }

    /// The point `behind_m` back along the path from the parent at `now` (heading
    /// `yaw_now`), and the parent's heading there; horizontal arc length, the depth
    /// interpolated.
    pub fn behind(&self, now: Vector3<f64>, yaw_now: f64, behind_m: f64) -> (Vector3<f64>, f64) {
        let mut left = behind_m.max(0.0);
        let (mut a, mut yaw_a) = (now, yaw_now);
        for &(b, yaw_b) in self.points.iter().rev() {
            let seg = (a - b).xy().norm();
            if seg >= left && seg > 0.0 {
                let f = left / seg;
                let yaw = wrap(yaw_a + f * wrap(yaw_b - yaw_a));
                return (a + (b - a) * f, yaw);
            }
            left -= seg;
            (a, yaw_a) = (b, yaw_b);
        }
        // past the oldest point: straight back along its heading
        let back = Vector3::new(yaw_a.cos(), yaw_a.sin(), 0.0);
        (a - back * left, yaw_a)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use proptest::prelude::*;

    #[test]
    fn straight_leg_is_the_rigid_slot() {
        let mut t = Trail::new();
        for i in 0..100 {
            t.push(Vector3::new(0.1 * f64::from(i), 0.0, 10.0), 0.0);
        }
        let now = Vector3::new(10.0, 0.0, 10.0);
        let (q, yaw) = t.behind(now, 0.0, 6.0);
        assert!((q - Vector3::new(4.0, 0.0, 10.0)).norm() < 1e-9, "{q}");
        assert_eq!(yaw, 0.0);
        // past the start: carried straight back
        let (q, _) = t.behind(now, 0.0, 25.0);
        assert!((q - Vector3::new(-15.0, 0.0, 10.0)).norm() < 1e-9, "{q}");
        // an empty trail is the rigid slot
        let (q, _) = Trail::new().behind(now, 0.5, 6.0);
        assert!((q - (now - 6.0 * Vector3::new(0.5f64.cos(), 0.5f64.sin(), 0.0))).norm() < 1e-9);
    }

    #[test]
    fn noise_smaller_than_a_step_is_not_stored() {
        let mut t = Trail::new();
        for i in 0..50 {
            let wobble = if i % 2 == 0 { 0.05 } else { -0.05 };
            t.push(Vector3::new(0.0, wobble, 10.0), 0.0);
        }
        assert_eq!(t.len(), 1);
        t.push(Vector3::new(f64::NAN, 0.0, 0.0), 0.0);
        assert_eq!(t.len(), 1);
    }

    proptest! {
        /// On a circle the point is on the circle, the arc length back, with the heading
        /// the parent had there (to the resolution of the stored chords).
        #[test]
        fn on_a_circle_the_point_is_the_arc_back(
            radius in 15.0f64..80.0,
            behind in 2.0f64..20.0,
            turn in prop_oneof![Just(1.0f64), Just(-1.0f64)],
        ) {
            let mut t = Trail::new();
            let (mut now, mut yaw_now) = (Vector3::zeros(), 0.0);
            // a quarter turn and more, in 5 cm steps
            let n = (radius * 2.5 / 0.05) as usize;
            for i in 0..=n {
                let s = i as f64 * 0.05;
                let th = s / radius;
                let p = Vector3::new(radius * th.sin(), turn * radius * (1.0 - th.cos()), 5.0);
                now = p;
                yaw_now = turn * th;
                t.push(p, yaw_now);
            }
            let (q, yaw) = t.behind(now, yaw_now, behind);
            let th_now = yaw_now * turn;
            let th = th_now - behind / radius;
            let want = Vector3::new(radius * th.sin(), turn * radius * (1.0 - th.cos()), 5.0);
            // chords of 0.5 m on a radius ≥ 15 m: the arc is longer by < 0.1 %
            prop_assert!((q - want).norm() < 0.05 + behind * 2e-3, "{} vs {}", q, want);
            prop_assert!((yaw - turn * th).abs() < 0.04, "{} vs {}", yaw, turn * th);
        }
    }
}
