//! Eqs. (4)-(9), worked by hand.
#![allow(clippy::unwrap_used, clippy::panic)] // test fixtures

use approx::assert_relative_eq;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use planner::shift::{proximity, return_in_parent, Displacement, SlotFilter};
use proptest::prelude::*;

const D_MIN: f64 = 2.0;

fn stbd() -> Displacement {
    // 8 m behind, 4 m to starboard; D_a = 2.5 (paper sign: starboard moves back), D_b = 2
    Displacement {
        slot: Vector3::new(-8.0, 4.0, 0.0),
        d_a: 2.5,
        d_b: 2.0,
    }
}

fn port() -> Displacement {
    Displacement {
        slot: Vector3::new(-8.0, -4.0, 0.0),
        d_a: 2.5,
        d_b: -2.0,
    }
}

#[test]
fn no_obstacle_leaves_the_slot_unchanged() {
    for d in [stbd(), port()] {
        let s = d.shift(std::iter::empty(), D_MIN);
        assert_eq!(s.slot, d.slot);
        assert!(!s.active);
        assert_eq!(s.delta_min, f64::INFINITY);
        // a far point (δ = 3 ≥ D_min) and one across the parent's track change nothing
        let s = d.shift([7.0 * d.slot.y.signum(), -d.slot.y.signum()], D_MIN);
        assert_eq!(s.slot, d.slot);
        assert_relative_eq!(s.delta_min, 3.0);
    }
}

#[test]
fn proximity_is_eq_7() {
    // starboard follower at ỹ_F = 4
    assert_relative_eq!(proximity(5.0, 4.0), 1.0); // outward by 1
    assert_relative_eq!(proximity(3.0, 4.0), -1.0); // between follower and parent track
    assert_relative_eq!(proximity(-2.0, 4.0), 6.0); // across the parent's track
                                                    // port follower at ỹ_F = −4: mirror image
    assert_relative_eq!(proximity(-5.0, -4.0), 1.0);
    assert_relative_eq!(proximity(-3.0, -4.0), -1.0);
    assert_relative_eq!(proximity(2.0, -4.0), 6.0);
}

#[test]
fn obstacle_to_starboard_moves_the_starboard_slot_inward_back_and_down() {
    // point 1 m outside the follower's track: δ = 1 < 2
    // ỹ* = 5 − 2 = 3, λ = (4 − 3)/4 = 1/4
    // x̃* = −8 − (2.5/2)(1/4) = −8.3125 (starboard: "−" of eq. 4), z̃* = (2/2)(1/4) = 0.25
    let s = stbd().shift([5.0, 9.0], D_MIN);
    assert!(s.active);
    assert_relative_eq!(s.delta_min, 1.0);
    assert_relative_eq!(s.lambda, 0.25);
    assert_relative_eq!(s.slot, Vector3::new(-8.3125, 3.0, 0.25), epsilon = 1e-12);
}

#[test]
fn obstacle_to_port_moves_the_port_slot_inward_forward_and_up() {
    // ỹ_d = −5: δ = −(−5 + 4) = 1; ỹ* = −5 + 2 = −3; λ = (−4 + 3)/(−4) = 1/4
    // x̃* = −8 + (2.5/2)(1/4) = −7.6875 ("+" for the port/left follower), z̃* = (−2/2)/4
    let s = port().shift([-5.0], D_MIN);
    assert_relative_eq!(s.slot, Vector3::new(-7.6875, -3.0, -0.25), epsilon = 1e-12);
    // the nearest of several points wins: ỹ = −5.5 has δ = 1.5 > 1
    let s2 = port().shift([-5.5, -5.0, -12.0], D_MIN);
    assert_eq!(s2.slot, s.slot);
    assert_eq!(s2.y_dc, Some(-5.0));
}

#[test]
fn the_slot_never_crosses_the_parents_track() {
    // a point between the follower's track and the parent's: ỹ* = 1.5 − 2 < 0 → clamp to 0
    let s = stbd().shift([1.5], D_MIN);
    assert_relative_eq!(s.lambda, 1.0);
    assert_relative_eq!(s.slot, Vector3::new(-9.25, 0.0, 1.0), epsilon = 1e-12);
    assert_eq!(s.slot, stbd().end());
    // a slot on the parent's track has no segment
    let on = Displacement {
        slot: Vector3::new(-8.0, 0.0, 0.0),
        d_a: 2.5,
        d_b: 2.0,
    };
    assert_eq!(on.shift([0.5], D_MIN).slot, on.slot);
}

#[test]
fn the_slot_returns_when_the_obstacle_is_gone() {
    let d = stbd();
    assert_ne!(d.shift([5.0], D_MIN).slot, d.slot);
    assert_eq!(d.shift(std::iter::empty(), D_MIN).slot, d.slot);
}

#[test]
fn filter_step_response_is_geometric() {
    // eq. (9): X̂(k) = u + (1 − β)^k (X̂(0) − u)
    let beta = 0.1;
    let mut f = SlotFilter::new(beta);
    let x0 = Vector3::new(-8.0, 4.0, 0.0);
    let u = Vector3::new(-8.3125, 3.0, 0.25);
    f.reset(x0);
    for k in 1..=50 {
        let y = f.update(&u);
        let expect = u + (x0 - u) * (1.0 - beta).powi(k);
        assert_relative_eq!(y, expect, epsilon = 1e-12);
    }
    // after 1 step exactly β of the way; after 22 steps ≥ 90 %
    let mut f = SlotFilter::new(beta);
    f.reset(Vector3::zeros());
    let one = Vector3::new(1.0, 0.0, 0.0);
    assert_relative_eq!(f.update(&one).x, 0.1);
    for _ in 1..22 {
        f.update(&one);
    }
    assert!(f.value().unwrap().x > 0.9);
    // the first input initialises an empty filter (no transient from zero)
    let mut f = SlotFilter::new(beta);
    assert_eq!(f.update(&u), u);
}

#[test]
fn eq6_puts_a_return_in_the_parents_frame() {
    // parent 8 m ahead, 4 m to starboard, turned 90° to starboard relative to the follower
    let parent = Isometry3::from_parts(
        Translation3::new(8.0, 4.0, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
    );
    // a return 5 m dead ahead of a transducer at the follower's origin: body (5, 0, 0)
    // relative to the parent: (−3, −4, 0) in follower axes → rotate by −90°: (−4, 3, 0)
    let p = return_in_parent(&parent, &Vector3::zeros(), 5.0, 0.0, 0.0);
    assert_relative_eq!(p.coords, Vector3::new(-4.0, 3.0, 0.0), epsilon = 1e-12);
    // with the paper's eq. (1): the follower itself is at −Rᵀ X_L^F in the parent frame
    let me = return_in_parent(&parent, &Vector3::zeros(), 0.0, 0.0, 0.0);
    let eq1 = -(parent.rotation.inverse() * parent.translation.vector);
    assert_relative_eq!(me.coords, eq1, epsilon = 1e-12);
}

proptest! {
    /// Every point of the segment satisfies eq. (4) and eq. (5) (with the paper's "±" as the
    /// sign of the applied D_a / D_b), and the end point lies on the parent's track.
    #[test]
    fn segment_satisfies_eqs_4_and_5(
        x in -20.0..-2.0f64, y in prop_oneof![-10.0..-0.5f64, 0.5..10.0f64], z in -2.0..2.0f64,
        d_a in -6.0..6.0f64, d_b in -6.0..6.0f64, lambda in 0.0..1.0f64,
    ) {
        let d = Displacement { slot: Vector3::new(x, y, z), d_a, d_b };
        let p = d.at(lambda);
        let da = d.d_a_signed();
        let eq4 = (da / 2.0) * (p.y - y) + y * (p.x - x);
        let eq5 = (d_b / 2.0) * (p.y - y) + y * (p.z - z);
        prop_assert!(eq4.abs() < 1e-9, "eq4 residual {}", eq4);
        prop_assert!(eq5.abs() < 1e-9, "eq5 residual {}", eq5);
        prop_assert!(d.end().y.abs() < 1e-12);
        // the paper's sign: port (ỹ < 0, its "left") moves forward for d_a > 0
        prop_assert_eq!(da.signum() * d_a.signum(), if y < 0.0 { 1.0 } else { -1.0 });
    }

    /// Eq. (8): the shifted slot keeps D_min laterally from the nearest point, on the parent's
    /// side, unless clamped to the segment.
    #[test]
    fn shift_keeps_d_min_from_the_nearest_point(
        y in prop_oneof![-10.0..-2.5f64, 2.5..10.0f64],
        off in -4.0..2.0f64,
    ) {
        let d = Displacement { slot: Vector3::new(-8.0, y, 0.0), d_a: 2.5, d_b: 1.0 };
        let y_d = y + y.signum() * off; // off > 0: outward
        let s = d.shift([y_d], D_MIN);
        prop_assert!(s.lambda >= 0.0 && s.lambda <= 1.0);
        if off >= D_MIN {
            prop_assert_eq!(s.slot, d.slot);
        } else if (s.lambda - 1.0).abs() > 1e-12 && s.lambda > 1e-12 {
            prop_assert!(((s.slot.y - y_d).abs() - D_MIN).abs() < 1e-9);
        }
        // and it only ever moves toward the parent's track
        prop_assert!(s.slot.y.abs() <= y.abs() + 1e-12);
    }
}
