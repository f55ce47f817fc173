//! The formation of a generated scenario: which lattice cells the shape
//! fills, who follows whom, and the slots in the parent's frame.
//!
//! The group is made of **files**: file `c` (0 = the leader's, negative =
//! port) runs straight back `c · col_m` to starboard of the leader's track.
//! Its first vehicle, the file's *head*, follows the head of the next file
//! inward diagonally (a lateral link, slot `[−diag_m, ±col_m, 0]`, which
//! shifts toward its parent's track near obstacles, eqs. 4-8); every other
//! vehicle follows the one straight ahead in its file (a rigid link, slot
//! `[−row_m, 0, 0]`, which never shifts). The leader heads file 0. Vehicle
//! `(c, j)` (the `j`-th behind its file's head) is `|c|` lateral and `j`
//! rigid links from the leader: its tree depth is `|c| + j`, and a shape is
//! filled level by level, so the tree's depth grows with N as the group
//! extends past one camera's visibility range.
//!
//! `diag_m = 1.5 · row_m`, so neighbouring files are staggered by half a
//! row: side by side, neighbours are `√((row/2)² + col²)` apart (5 m for the
//! default 6 m × 4 m), not `col_m`, and a head that shifts onto the next
//! file's track lands between two of its vehicles. The lateral link is as
//! short as the camera allows (the parent one file across within the field
//! of view, with a margin); the rigid link is shorter still.
//!
//! Measured on 25 vehicles (why this shape): each level of a vision-only
//! chain adds its own tracking error — heading noise on the slot's arm, and
//! pose noise that grows as range² — so vehicles four levels down wander
//! about a metre. With unstaggered 8 m × 4 m files, neighbours at depth 4
//! came within 0.7-1.2 m of each other; a "herringbone" (every vehicle
//! diagonally off the row in front) was worse (0.6 m, parents in view 93 %
//! of the frames) and its displacements could not be assigned at 256.

use camera_pose::{BeaconLayout, BeaconStatus, Camera, CameraConfig};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::{GenError, Shape};

/// One vehicle of the generated formation.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    /// Name (`L` for the leader, `F1`, `F2`, … level by level).
    pub name: String,
    /// Index of the parent in the member list (`None` for the leader).
    pub parent: Option<usize>,
    /// Tree depth (0 = the leader).
    pub depth: i64,
    /// File (0 = the leader's, negative = port).
    pub col: i64,
    /// Position in the leader's frame at the start, FRD, m.
    pub pos_m: [f64; 3],
    /// Slot in the parent's frame, FRD, m (`None` for the leader).
    pub slot_m: Option<[f64; 3]>,
}

/// The lattice spacings, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lattice {
    /// Along the track, from a file's head to the head of the next file
    /// inward (the lateral link).
    pub diag_m: f64,
    /// Along the track, between neighbours in a file (the rigid link):
    /// `2/3 · diag_m`.
    pub row_m: f64,
    /// Across, between files.
    pub col_m: f64,
}

/// Field-of-view margin kept at the start: beacons must lie this far inside
/// the image edge (degrees of the half-angle), as the paper scenario's ~5°.
pub const FOV_MARGIN_DEG: f64 = 5.0;
/// Range margin kept at the start below the visibility range, m.
pub const RANGE_MARGIN_M: f64 = 1.0;
/// Smallest column spacing: neighbouring files at least `D_min + 1 m` apart.
pub const MIN_SPACING_M: f64 = 3.0;
/// Room left in the visibility range for the displacement (`D_a/2` along,
/// `D_b/2` down), m: rows farther apart than `visibility − this` are refused.
pub const SHIFT_ROOM_M: f64 = 2.5;

/// Farthest rows may be apart (the visibility range less [`SHIFT_ROOM_M`]), m.
pub fn max_row_m() -> f64 {
    CameraConfig::default().visibility_range_m - SHIFT_ROOM_M
}

/// A camera like the default one but with the margins above: a follower
/// whose parent's beacons all fall in this camera's image, within its range,
/// sees them in the real one with room to spare.
fn margin_camera() -> Result<Camera, GenError> {
    let real = CameraConfig::default();
    let cfg = CameraConfig {
        fov_deg: real.fov_deg - 2.0 * FOV_MARGIN_DEG,
        visibility_range_m: real.visibility_range_m - RANGE_MARGIN_M,
        ..real
    };
    Camera::new(&cfg).map_err(|e| GenError::Internal(format!("margin camera: {e}")))
}

/// Whether a follower at `slot` (parent frame, both on the same heading)
/// sees every beacon of its parent with `camera`, nothing in between.
pub fn sees_parent(camera: &Camera, layout: &BeaconLayout, slot: [f64; 3]) -> bool {
    let parent = Isometry3::identity();
    let follower = Isometry3::from_parts(
        Translation3::new(slot[0], slot[1], slot[2]),
        UnitQuaternion::identity(),
    );
    let cam = camera.camera_in_world(&follower);
    (0..layout.positions_body_m.len())
        .all(|i| camera.beacon_status(&cam, &parent, layout, i, &[]).0 == BeaconStatus::Visible)
}

/// The lattice for a file spacing: the shortest lateral link (in 1.5 m
/// steps, at least `2 · col_m`, the paper's 8 m × 4 m) that keeps a parent one
/// file across in the camera's view with [`FOV_MARGIN_DEG`] to spare; rigid
/// links two thirds of that.
pub fn lattice(col_m: f64) -> Result<Lattice, GenError> {
    let visibility = CameraConfig::default().visibility_range_m;
    if !(col_m.is_finite() && col_m >= MIN_SPACING_M) {
        return Err(GenError::Spacing {
            spacing_m: col_m,
            reason: format!(
                "must be at least {MIN_SPACING_M} m (neighbouring files keep the 2 m safe \
                 distance plus 1 m)"
            ),
        });
    }
    let camera = margin_camera()?;
    let layout = BeaconLayout::default();
    let max_row = max_row_m();
    let mut diag = (2.0 * col_m / 1.5).ceil() * 1.5;
    while diag <= max_row + 1e-9 {
        let row = diag * 2.0 / 3.0;
        if sees_parent(&camera, &layout, [-diag, col_m, 0.0])
            && sees_parent(&camera, &layout, [-diag, -col_m, 0.0])
            && sees_parent(&camera, &layout, [-row, 0.0, 0.0])
        {
            return Ok(Lattice {
                diag_m: diag,
                row_m: row,
                col_m,
            });
        }
        diag += 1.5;
    }
    Err(GenError::Spacing {
        spacing_m: col_m,
        reason: format!(
            "a parent one file ({col_m} m) across is out of the camera's view ({}° field of \
             view less {FOV_MARGIN_DEG}° each side) unless it is more than {max_row} m ahead, \
             beyond the {visibility} m visibility range less {SHIFT_ROOM_M} m for the \
             displacement; use a smaller spacing",
            CameraConfig::default().fov_deg
        ),
    })
}

/// Half-width, in columns, of a grid of `n` vehicles (its files: `2k + 1`).
pub fn grid_half_width(n: usize) -> i64 {
    ((n as f64).sqrt() / 2.5).round().max(1.0) as i64
}

/// Vehicles per file (head included) in each arm of a V of `n` vehicles.
pub fn v_thickness(n: usize) -> i64 {
    ((n as f64 / 8.0).sqrt()).round().max(1.0) as i64
}

/// Whether the shape has vehicle `j` of file `c` (for `n` vehicles).
fn has_cell(shape: Shape, n: usize, c: i64, j: i64) -> bool {
    let a = c.abs();
    j >= 0
        && match shape {
            Shape::Triangle => true,
            Shape::Grid => a <= grid_half_width(n),
            Shape::Column => a <= 1,
            Shape::V | Shape::Paper => j < v_thickness(n),
        }
}

/// The shape's `(file, index in file)` cells, level by level (tree depth
/// `|c| + j`), each level from the centre out (port before starboard), the
/// first `n`.
pub fn cells(shape: Shape, n: usize) -> Vec<(i64, i64)> {
    let mut out = Vec::with_capacity(n);
    let mut depth = 0i64;
    while out.len() < n {
        for a in 0..=depth {
            let files: &[i64] = if a == 0 { &[0] } else { &[-a, a] };
            for &c in files {
                if out.len() < n && has_cell(shape, n, c, depth - a) {
                    out.push((c, depth - a));
                }
            }
        }
        depth += 1;
    }
    out
}

/// Builds the formation: members with their parents, start positions in the
/// leader's frame and slots.
pub fn members(shape: Shape, n: usize, lattice: Lattice) -> Result<Vec<Member>, GenError> {
    let cells = cells(shape, n);
    let index = |c: i64, j: i64| cells.iter().position(|&x| x == (c, j));
    let mut out: Vec<Member> = Vec::with_capacity(n);
    for (i, &(c, j)) in cells.iter().enumerate() {
        let along = c.abs() as f64 * lattice.diag_m + j as f64 * lattice.row_m;
        let pos = [-along, c as f64 * lattice.col_m, 0.0];
        let parent = if i == 0 {
            None
        } else {
            let p = if j > 0 {
                index(c, j - 1)
            } else {
                index(c - c.signum(), 0)
            };
            Some(p.ok_or_else(|| {
                GenError::Internal(format!("vehicle {j} of file {c} has no parent cell"))
            })?)
        };
        let slot_m = parent.map(|p| {
            let pp = out[p].pos_m;
            [pos[0] - pp[0], pos[1] - pp[1], pos[2] - pp[2]]
        });
        out.push(Member {
            name: if i == 0 {
                "L".to_string()
            } else {
                format!("F{i}")
            },
            parent,
            depth: c.abs() + j,
            col: c,
            pos_m: pos,
            slot_m,
        });
    }
    Ok(out)
}

/// For each member, how far behind it its farthest descendant is, m (0 for
/// a vehicle nobody follows).
pub fn reach_behind(members: &[Member]) -> Vec<f64> {
    let mut out = vec![0.0f64; members.len()];
    for m in members {
        // walk up the (acyclic, `members` built it) chain of parents
        let mut cur = m.parent;
        for _ in 0..members.len() {
            let Some(p) = cur else { break };
            out[p] = out[p].max(members[p].pos_m[0] - m.pos_m[0]);
            cur = members[p].parent;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_lattice_is_nine_six_four() {
        let l = lattice(4.0).unwrap();
        assert_eq!((l.diag_m, l.row_m, l.col_m), (9.0, 6.0, 4.0));
        assert!(lattice(2.0).is_err());
        assert!(lattice(8.0).is_err());
    }

    #[test]
    fn v_of_five_is_the_papers_triangle() {
        let l = lattice(4.0).unwrap();
        let m = members(Shape::V, 5, l).unwrap();
        let slots: Vec<_> = m.iter().skip(1).map(|m| m.slot_m.unwrap()).collect();
        let d = l.diag_m;
        assert_eq!(
            slots,
            vec![
                [-d, -4.0, 0.0],
                [-d, 4.0, 0.0],
                [-d, -4.0, 0.0],
                [-d, 4.0, 0.0]
            ]
        );
        assert_eq!(m[3].parent, Some(1));
        assert_eq!(m[4].parent, Some(2));
    }

    #[test]
    fn neighbouring_files_are_staggered() {
        let l = lattice(4.0).unwrap();
        let m = members(Shape::Grid, 40, l).unwrap();
        for a in &m {
            for b in &m {
                if b.col == a.col + 1 {
                    let dx = (a.pos_m[0] - b.pos_m[0]).abs() % l.row_m;
                    assert!((dx - l.row_m / 2.0).abs() < 1e-9, "{} {}", a.name, b.name);
                }
            }
        }
    }

    #[test]
    fn every_shape_fills_exactly_n_cells() {
        for shape in [Shape::Triangle, Shape::V, Shape::Column, Shape::Grid] {
            for n in [1, 2, 7, 33, 256] {
                let c = cells(shape, n);
                assert_eq!(c.len(), n, "{shape:?} {n}");
                let mut d = c.clone();
                d.sort();
                d.dedup();
                assert_eq!(d.len(), n, "{shape:?} {n}: duplicate cells");
                members(shape, n, lattice(4.0).unwrap()).unwrap();
            }
        }
    }
}
