//! What the planner hands the controller's safety layer: the remembered returns nearest
//! the vehicle, spread over the obstacles around it, and the parent's estimate.
//!
//! The controller keeps every predicted position `D_min/2 + margin` from each of these
//! points (`mpc`'s crate docs). Eight points cannot hold a whole wall, so they are chosen
//! greedily: the nearest return first, then the nearest one at least [`SPACING_M`] from
//! every point already taken. Two walls of a gap, a pillar beside a wall, both get points
//! instead of eight cells of the nearest wall's face.

use nalgebra::Vector3;

pub use ipc_types::{Keepout, MAX_KEEPOUT};

/// Returns farther than this from the vehicle are not handed over, m: at 1 m/s the
/// controller's 2 s horizon cannot bring it nearer than `RANGE_M − 2` m to them.
pub const RANGE_M: f64 = 8.0;

/// Least distance between two points handed over, m.
pub const SPACING_M: f64 = 1.5;

/// Picks up to [`MAX_KEEPOUT`] of `points` (level frame, relative to the vehicle) within
/// [`RANGE_M`], nearest first and at least [`SPACING_M`] apart. `points` is called once per
/// point chosen (it is a cheap iterator over the planner's memory); ties go to the earlier
/// point, so the choice is deterministic.
pub fn select<I>(points: impl Fn() -> I) -> Keepout
where
    I: Iterator<Item = Vector3<f64>>,
{
    let mut k = Keepout::default();
    let mut taken: [Vector3<f64>; MAX_KEEPOUT] = [Vector3::zeros(); MAX_KEEPOUT];
    for slot in 0..MAX_KEEPOUT {
        let mut best: Option<(f64, Vector3<f64>)> = None;
        for p in points() {
            let d = p.norm();
            if d.is_nan() || d > RANGE_M {
                continue;
            }
            if taken[..slot].iter().any(|q| (p - q).norm() < SPACING_M) {
                continue;
            }
            if best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, p));
            }
        }
        let Some((_, p)) = best else { break };
        taken[slot] = p;
        k.push([p.x, p.y, p.z]);
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_first_spread_out_and_in_range() {
        // a wall to starboard, one cell every 0.5 m, and a pillar to port
        let mut pts: Vec<Vector3<f64>> = (-20..=20)
            .map(|i| Vector3::new(f64::from(i) * 0.5, 2.0, 0.0))
            .collect();
        pts.push(Vector3::new(1.0, -3.0, 0.0));
        pts.push(Vector3::new(30.0, 0.0, 0.0)); // out of range
        let k = select(|| pts.iter().copied());
        assert_eq!(k.count, MAX_KEEPOUT);
        assert_eq!(k.points()[0], [0.0, 2.0, 0.0]);
        assert!(k.points().contains(&[1.0, -3.0, 0.0]), "{:?}", k.points());
        for (i, a) in k.points().iter().enumerate() {
            let a = Vector3::from(*a);
            assert!(a.norm() <= RANGE_M);
            for b in &k.points()[i + 1..] {
                assert!((a - Vector3::from(*b)).norm() >= SPACING_M);
            }
        }
        // nothing in range: nothing handed over
        let far = [Vector3::new(9.0, 0.0, 0.0)];
        assert_eq!(select(|| far.iter().copied()).count, 0);
    }
}
