//! The ocean current as a field: a constant current everywhere plus zones where it differs.
//!
//! A zone is a horizontal rectangle (centre, half length along its yaw, half width across)
//! through the whole water column, with a current of its own that adds to the constant one.
//! Its edge is a ramp `edge_m` wide centred on the rectangle's border (a smoothstep, so the
//! field and its gradient are continuous): a vehicle crossing into a cross-current zone feels
//! it build up over the ramp instead of a step.
//!
//! For a current that varies in space the relative-velocity form of the dynamics gains the
//! current's rate of change along the vehicle's path: `ν̇ = ν̇_r + Rᵀ (J ṗ) − ω × Rᵀ v_c`,
//! with `J` the field's spatial Jacobian (Fossen 2011 eq. 8.6 with `v̇_c = J ṗ`); the plant
//! takes `J ṗ` as a central difference along `ṗ`.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::PlantError;

/// A zone of current: a rectangle in the horizontal plane, all depths.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CurrentZone {
    /// Centre, north and east, m.
    pub center_ne_m: [f64; 2],
    /// Half length along `yaw_deg`, m (> 0).
    pub half_length_m: f64,
    /// Half width across it, m (> 0).
    pub half_width_m: f64,
    /// Direction of the zone's length, degrees from north (clockwise, NED yaw).
    #[serde(default)]
    pub yaw_deg: f64,
    /// The zone's current in NED, m/s, added to the constant current.
    pub current_ned_mps: [f64; 3],
    /// Width of the ramp at the zone's border, m (≥ 0; default 10).
    #[serde(default = "default_edge")]
    pub edge_m: f64,
}

fn default_edge() -> f64 {
    10.0
}

/// `0` below `-1/2`, `1` above `1/2`, a smoothstep between.
fn ramp(x: f64) -> f64 {
    let t = (x + 0.5).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl CurrentZone {
    /// The zone's share at `p` (NED): 1 inside, 0 outside, the ramp between.
    #[must_use]
    pub fn weight(&self, p: &Vector3<f64>) -> f64 {
        let (s, c) = self.yaw_deg.to_radians().sin_cos();
        let dn = p.x - self.center_ne_m[0];
        let de = p.y - self.center_ne_m[1];
        let along = dn * c + de * s;
        let across = -dn * s + de * c;
        let inside = |x: f64, half: f64| {
            let d = half - x.abs();
            if self.edge_m > 0.0 {
                ramp(d / self.edge_m)
            } else if d >= 0.0 {
                1.0
            } else {
                0.0
            }
        };
        inside(along, self.half_length_m) * inside(across, self.half_width_m)
    }

    /// # Errors
    /// [`PlantError::InvalidConfig`] naming the bad key of zone `i`.
    pub fn validate(&self, i: usize) -> Result<(), PlantError> {
        let key = |k: &str| format!("current_zones[{i}].{k}");
        let fin = self.center_ne_m.iter().all(|x| x.is_finite())
            && self.current_ned_mps.iter().all(|x| x.is_finite())
            && self.yaw_deg.is_finite();
        if !fin {
            return Err(PlantError::InvalidConfig(format!(
                "{} must be finite",
                key("center_ne_m / yaw_deg / current_ned_mps")
            )));
        }
        for (k, v) in [
            ("half_length_m", self.half_length_m),
            ("half_width_m", self.half_width_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlantError::InvalidConfig(format!(
                    "{} must be finite and > 0, got {v}",
                    key(k)
                )));
            }
        }
        if !(self.edge_m.is_finite() && self.edge_m >= 0.0) {
            return Err(PlantError::InvalidConfig(format!(
                "{} must be finite and >= 0, got {}",
                key("edge_m"),
                self.edge_m
            )));
        }
        Ok(())
    }
}

/// The current everywhere: a constant plus zones.
#[derive(Debug, Clone, PartialEq)]
pub struct CurrentField {
    base: Vector3<f64>,
    zones: Vec<CurrentZone>,
}

/// Step of the central difference along the path, s (at 1 m/s: 1 cm apart).
const DIFF_S: f64 = 0.01;

impl CurrentField {
    /// The field of a constant current and `zones`.
    #[must_use]
    pub fn new(base_ned_mps: [f64; 3], zones: Vec<CurrentZone>) -> Self {
        Self {
            base: Vector3::from(base_ned_mps),
            zones,
        }
    }

    /// True when the current is the same everywhere.
    #[must_use]
    pub fn is_uniform(&self) -> bool {
        self.zones.is_empty()
    }

    /// The current at `p` (NED), m/s.
    #[must_use]
    pub fn at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.zones.iter().fold(self.base, |acc, z| {
            acc + Vector3::from(z.current_ned_mps) * z.weight(p)
        })
    }

    /// How fast the current changes for a vehicle at `p` moving at `p_dot` (NED), m/s².
    #[must_use]
    pub fn rate_along(&self, p: &Vector3<f64>, p_dot: &Vector3<f64>) -> Vector3<f64> {
        if self.zones.is_empty() {
            return Vector3::zeros();
        }
        let d = p_dot * DIFF_S;
        (self.at(&(p + d)) - self.at(&(p - d))) / (2.0 * DIFF_S)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn zone() -> CurrentZone {
        CurrentZone {
            center_ne_m: [100.0, 0.0],
            half_length_m: 40.0,
            half_width_m: 200.0,
            yaw_deg: 0.0,
            current_ned_mps: [0.0, -0.3, 0.0],
            edge_m: 10.0,
        }
    }

    #[test]
    fn inside_the_zone_its_current_adds_to_the_constant_one_and_outside_only_the_constant() {
        let f = CurrentField::new([0.1, 0.0, 0.0], vec![zone()]);
        let inside = f.at(&Vector3::new(100.0, 5.0, 10.0));
        assert!((inside - Vector3::new(0.1, -0.3, 0.0)).norm() < 1e-12);
        let outside = f.at(&Vector3::new(0.0, 0.0, 10.0));
        assert!((outside - Vector3::new(0.1, 0.0, 0.0)).norm() < 1e-12);
        // on the border, half of it
        let border = f.at(&Vector3::new(140.0, 0.0, 10.0));
        assert!((border.y + 0.15).abs() < 1e-12, "{border}");
    }

    #[test]
    fn a_turned_zone_is_measured_along_its_own_axes() {
        let mut z = zone();
        z.center_ne_m = [0.0, 0.0];
        z.half_width_m = 5.0;
        z.yaw_deg = 90.0; // its length runs east
        z.edge_m = 0.0;
        assert!((z.weight(&Vector3::new(0.0, 35.0, 0.0)) - 1.0).abs() < 1e-12);
        assert!(z.weight(&Vector3::new(35.0, 0.0, 0.0)).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn the_rate_along_a_path_is_the_derivative_of_the_current_met(
            n in 40.0f64..160.0, e in -10.0f64..10.0, vn in -1.5f64..1.5, ve in -1.5f64..1.5,
        ) {
            let f = CurrentField::new([0.0; 3], vec![zone()]);
            let p = Vector3::new(n, e, 5.0);
            let v = Vector3::new(vn, ve, 0.0);
            let h = 1e-4;
            let numeric = (f.at(&(p + v * h)) - f.at(&(p - v * h))) / (2.0 * h);
            let rate = f.rate_along(&p, &v);
            // the ramp's curvature bounds the difference of the two steps
            prop_assert!((numeric - rate).norm() < 1e-4, "{numeric} vs {rate}");
            // a weight is always a share
            let w = zone().weight(&p);
            prop_assert!((0.0..=1.0).contains(&w));
        }
    }
}
