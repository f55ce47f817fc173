//! The leader's own position estimate: dead reckoning (DVL velocity over ground rotated by
//! the AHRS) corrected by the noisy absolute fixes, depth from the pressure sensor.
//!
//! Why: the absolute fix (USBL/GNSS-at-surface stand-in) is noisy — 0.5 m 1σ per axis at
//! 10 Hz by default — while the DVL is precise (0.01 m/s). Steering on the raw fix made the
//! line-of-sight heading jump by `atan(0.5 m / los_lookahead_m)` ≈ 6° from step to step, and
//! ratcheted the virtual target forward (it is never behind the leader's projection, so the
//! noise's maxima pushed it: the leader ran at ~1.4 m/s instead of 1 m/s). Every follower's
//! slot hangs on the leader's heading with an 8 m arm, so that noise reached all of them.
//!
//! Model, horizontal axes independent and alike (one scalar variance): `p_{k+1} = p_k +
//! R(q) v_body dt + w`, `w ~ N(0, (σ_dr dt)²)`; fix `z = p + n`, `n ~ N(0, σ_fix²)`. This is
//! the Kalman filter of that model. At the defaults (σ_dr = 0.02 m/s, σ_fix = 0.5 m, 10 Hz)
//! its steady-state gain is ≈ 0.004 per fix (a ~25 s time constant) and its 1σ error ≈ 3 cm.
//! The vertical position is the depth sensor's (0.02 m), not the fix's.

use nalgebra::{UnitQuaternion, Vector3};

/// Kalman filter of the leader's horizontal position (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionFilter {
    fix_var: f64,
    dr_noise_mps: f64,
    initialized: bool,
    p: Vector3<f64>,
    var: f64,
    /// Dead-reckoned displacement since the first fix (horizontal), m.
    dr: Vector3<f64>,
}

impl PositionFilter {
    /// A filter for fixes of 1σ `fix_noise_m` per axis and a dead-reckoning velocity error of
    /// 1σ `dr_noise_mps` per step. Both must be > 0 (checked by the caller's config).
    pub fn new(fix_noise_m: f64, dr_noise_mps: f64) -> Self {
        Self {
            fix_var: fix_noise_m * fix_noise_m,
            dr_noise_mps,
            initialized: false,
            p: Vector3::zeros(),
            var: 0.0,
            dr: Vector3::zeros(),
        }
    }

    /// One step: propagate by `dt` with the body velocity `v_body` and the attitude, then fuse
    /// the fix `fix_ned`; the vertical component is `depth_m`. Returns the estimate.
    pub fn step(
        &mut self,
        dt: f64,
        attitude: &UnitQuaternion<f64>,
        v_body: &Vector3<f64>,
        fix_ned: &Vector3<f64>,
        depth_m: f64,
    ) -> Vector3<f64> {
        if !self.initialized {
            self.p = Vector3::new(fix_ned.x, fix_ned.y, depth_m);
            self.var = self.fix_var;
            self.initialized = true;
            return self.p;
        }
        let v = attitude * v_body;
        let d = Vector3::new(v.x * dt, v.y * dt, 0.0);
        self.p += d;
        self.dr += d;
        self.var += (self.dr_noise_mps * dt).powi(2);
        let k = self.var / (self.var + self.fix_var);
        self.p.x += k * (fix_ned.x - self.p.x);
        self.p.y += k * (fix_ned.y - self.p.y);
        self.var *= 1.0 - k;
        self.p.z = depth_m;
        self.p
    }

    /// The position estimate, NED, m.
    pub fn position(&self) -> Vector3<f64> {
        self.p
    }

    /// 1σ of the horizontal estimate, m.
    pub fn std_m(&self) -> f64 {
        self.var.sqrt()
    }

    /// Where the vehicle was at the first fix, as now best estimated: the estimate minus the
    /// dead-reckoned displacement since then (horizontal; depth as now).
    pub fn start_estimate(&self) -> Vector3<f64> {
        self.p - self.dr
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn converges_on_the_truth_from_noisy_fixes() {
        let mut f = PositionFilter::new(0.5, 0.02);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let fix = Normal::new(0.0, 0.5).unwrap();
        let dvl = Normal::new(0.0, 0.01).unwrap();
        let att = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3);
        let v_body = Vector3::new(1.0, 0.1, 0.0);
        let mut truth = Vector3::new(5.0, -3.0, 10.0);
        let mut worst_late: f64 = 0.0;
        let mut raw_late: f64 = 0.0;
        for k in 0..1500 {
            if k > 0 {
                truth += att * v_body * 0.1;
            }
            let z = truth + Vector3::new(fix.sample(&mut rng), fix.sample(&mut rng), 0.0);
            let meas_v = v_body + Vector3::new(dvl.sample(&mut rng), dvl.sample(&mut rng), 0.0);
            let est = f.step(0.1, &att, &meas_v, &z, truth.z);
            if k > 300 {
                worst_late = worst_late.max((est - truth).norm());
                raw_late = raw_late.max((z - truth).norm());
            }
        }
        // the fixes alone are off by up to ~2 m; the filter stays within ~0.2 m
        assert!(raw_late > 1.0, "{raw_late}");
        assert!(worst_late < 0.2, "{worst_late}");
        assert!(f.std_m() < 0.05);
        // the start is recovered from the estimate and the dead reckoning
        assert!((f.start_estimate().xy() - Vector3::new(5.0, -3.0, 0.0).xy()).norm() < 0.2);
    }

    #[test]
    fn first_fix_initialises_and_depth_comes_from_the_sensor() {
        let mut f = PositionFilter::new(0.5, 0.02);
        let p = f.step(
            0.0,
            &UnitQuaternion::identity(),
            &Vector3::zeros(),
            &Vector3::new(1.0, 2.0, 3.0),
            10.0,
        );
        assert_eq!(p, Vector3::new(1.0, 2.0, 10.0));
        assert!((f.std_m() - 0.5).abs() < 1e-12);
        let p = f.step(
            0.1,
            &UnitQuaternion::identity(),
            &Vector3::new(1.0, 0.0, 0.0),
            &Vector3::new(1.1, 2.0, 3.0),
            10.5,
        );
        assert!((p.x - 1.1).abs() < 1e-9 && (p.y - 2.0).abs() < 1e-9);
        assert_eq!(p.z, 10.5);
    }
}
