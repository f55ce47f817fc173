//! The observer of paper fig. 4: a Kalman filter on the parent's position, velocity, heading
//! and turn rate, fed by noisy, low-rate, slightly late vision fixes.
//!
//! The filter runs in the follower's **odometry frame**: NED-aligned axes (from the AHRS),
//! origin wherever the follower started, horizontal position dead-reckoned from the DVL and
//! the AHRS, vertical position = measured depth. The parent's motion in this frame is its own
//! motion, independent of the follower's manoeuvres, so a constant-velocity model fits; the
//! follower's dead-reckoning drift is common to its own position and to every fix, so it
//! cancels in the relative position the controller uses. A constant bias of the AHRS heading
//! likewise cancels: the absolute heading is never needed.
//!
//! Model, per axis: `p' = v`, `v'` = white acceleration of density `σ_a²`; heading
//! `ψ' = r`, `r'` = white of density `σ_ψ̈²`; with `coordinated_turn` the horizontal velocity
//! also turns at `r` (the parent's course follows its heading). A fix taken at `t_m ≤ t` updates the state at
//! `t` through `H = [I, −(t − t_m) I]` (the state extrapolated back), so camera latency does not
//! bias the estimate. Fixes whose Mahalanobis distance exceeds the gate are rejected; after
//! `max_rejections` rejections in a row the filter restarts from the latest fix (the parent
//! really is elsewhere, e.g. after a long occlusion).

use nalgebra::{Matrix2, Matrix3, Matrix3x6, Matrix6, Vector2, Vector3, Vector6};

use crate::frames::wrap;

/// Tuning of [`ParentObserver`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverParams {
    /// White-acceleration density of the parent, m/s² (1σ over 1 s).
    pub accel_noise_mps2: f64,
    /// White angular-acceleration density of the parent's heading, rad/s².
    pub yaw_accel_noise_radps2: f64,
    /// Chi-square gate on the position innovation (3 dof).
    pub gate_chi2: f64,
    /// Rejections in a row after which the filter restarts from the latest fix.
    pub max_rejections: u32,
    /// Initial velocity standard deviation after a (re)start, m/s.
    pub initial_speed_std_mps: f64,
    /// The horizontal velocity turns with the estimated turn rate (a coordinated turn)
    /// instead of keeping its direction (our addition; the paper's observer is
    /// constant-velocity): a parent predicted through a loss in a turn then goes on
    /// turning, where its follower looks for it, instead of straight out of its view.
    pub coordinated_turn: bool,
}

/// What happened to a fix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FixOutcome {
    /// Fused.
    Accepted,
    /// The filter was (re)started from this fix.
    Restarted,
    /// Outside the gate; not fused.
    Rejected,
}

/// Kalman filter on the parent's state in the odometry frame.
#[derive(Debug, Clone)]
pub struct ParentObserver {
    params: ObserverParams,
    initialized: bool,
    t: f64,
    /// [position; velocity], odometry frame.
    x: Vector6<f64>,
    p: Matrix6<f64>,
    /// [heading, turn rate].
    y: Vector2<f64>,
    py: Matrix2<f64>,
    rejections: u32,
}

impl ParentObserver {
    /// An uninitialised observer.
    pub fn new(params: ObserverParams) -> Self {
        Self {
            params,
            initialized: false,
            t: 0.0,
            x: Vector6::zeros(),
            p: Matrix6::identity(),
            y: Vector2::zeros(),
            py: Matrix2::identity(),
            rejections: 0,
        }
    }

    /// True once a fix has been fused.
    pub fn initialized(&self) -> bool {
        self.initialized
    }

    /// Forgets everything.
    pub fn clear(&mut self) {
        self.initialized = false;
        self.rejections = 0;
    }

    /// Parent position, odometry frame, m.
    pub fn position(&self) -> Vector3<f64> {
        self.x.fixed_rows::<3>(0).into_owned()
    }

    /// Parent velocity, odometry frame, m/s.
    pub fn velocity(&self) -> Vector3<f64> {
        self.x.fixed_rows::<3>(3).into_owned()
    }

    /// Parent heading in the odometry (AHRS) frame, rad.
    pub fn yaw(&self) -> f64 {
        self.y[0]
    }

    /// Parent turn rate, rad/s.
    pub fn yaw_rate(&self) -> f64 {
        self.y[1]
    }

    /// 1σ of the position estimate (square root of the largest diagonal term), m.
    pub fn position_std(&self) -> f64 {
        (0..3).map(|i| self.p[(i, i)]).fold(0.0, f64::max).sqrt()
    }

    /// Propagates the state to time `t` (no-op if `t` is not later).
    pub fn predict(&mut self, t: f64) {
        if !self.initialized {
            self.t = t;
            return;
        }
        let dt = t - self.t;
        if dt <= 0.0 {
            return;
        }
        let mut f = Matrix6::identity();
        for i in 0..3 {
            f[(i, i + 3)] = dt;
        }
        let r = self.y[1];
        if self.params.coordinated_turn && (r * dt).abs() > 1e-9 {
            // the horizontal velocity turns by r·dt, the position moves along the arc
            let (s, c) = (r * dt).sin_cos();
            f[(0, 3)] = s / r;
            f[(0, 4)] = -(1.0 - c) / r;
            f[(1, 3)] = (1.0 - c) / r;
            f[(1, 4)] = s / r;
            f[(3, 3)] = c;
            f[(3, 4)] = -s;
            f[(4, 3)] = s;
            f[(4, 4)] = c;
        }
        let qa = self.params.accel_noise_mps2.powi(2);
        let mut q = Matrix6::zeros();
        for i in 0..3 {
            q[(i, i)] = qa * dt.powi(3) / 3.0;
            q[(i, i + 3)] = qa * dt.powi(2) / 2.0;
            q[(i + 3, i)] = qa * dt.powi(2) / 2.0;
            q[(i + 3, i + 3)] = qa * dt;
        }
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + q;
        let fy = Matrix2::new(1.0, dt, 0.0, 1.0);
        let qy = self.params.yaw_accel_noise_radps2.powi(2);
        let qym = Matrix2::new(
            qy * dt.powi(3) / 3.0,
            qy * dt.powi(2) / 2.0,
            qy * dt.powi(2) / 2.0,
            qy * dt,
        );
        self.y = fy * self.y;
        self.y[0] = wrap(self.y[0]);
        self.py = fy * self.py * fy.transpose() + qym;
        self.t = t;
    }

    /// (Re)starts the filter at time `t` from a fix, with a velocity guess `v_guess` (the
    /// follower's own velocity: formation members move together).
    pub fn restart(
        &mut self,
        t: f64,
        pos: &Vector3<f64>,
        r_pos: &Matrix3<f64>,
        yaw: f64,
        yaw_var: f64,
        v_guess: &Vector3<f64>,
    ) {
        self.x.fixed_rows_mut::<3>(0).copy_from(pos);
        self.x.fixed_rows_mut::<3>(3).copy_from(v_guess);
        self.p = Matrix6::zeros();
        self.p.fixed_view_mut::<3, 3>(0, 0).copy_from(r_pos);
        let sv = self.params.initial_speed_std_mps.powi(2);
        for i in 3..6 {
            self.p[(i, i)] = sv;
        }
        self.y = Vector2::new(wrap(yaw), 0.0);
        self.py = Matrix2::new(yaw_var, 0.0, 0.0, 0.05f64.powi(2));
        self.t = t;
        self.initialized = true;
        self.rejections = 0;
    }

    /// Fuses a fix taken at `t_meas` into the state at the filter's current time
    /// (call [`ParentObserver::predict`] first). Restarts the filter if it is uninitialised
    /// or after too many rejections.
    #[allow(clippy::too_many_arguments)]
    pub fn fuse(
        &mut self,
        t_meas: f64,
        pos: &Vector3<f64>,
        r_pos: &Matrix3<f64>,
        yaw: f64,
        yaw_var: f64,
        v_guess: &Vector3<f64>,
    ) -> FixOutcome {
        if !self.initialized {
            let t = self.t;
            self.restart(t, pos, r_pos, yaw, yaw_var, v_guess);
            return FixOutcome::Restarted;
        }
        let lag = (self.t - t_meas).max(0.0);
        let mut h = Matrix3x6::zeros();
        for i in 0..3 {
            h[(i, i)] = 1.0;
            h[(i, i + 3)] = -lag;
        }
        let innov = pos - h * self.x;
        let s = h * self.p * h.transpose() + r_pos;
        let Some(s_inv) = s.try_inverse() else {
            return FixOutcome::Rejected;
        };
        let d2 = (innov.transpose() * s_inv * innov)[(0, 0)];
        if !(d2.is_finite() && d2 <= self.params.gate_chi2) {
            self.rejections += 1;
            if self.rejections >= self.params.max_rejections {
                let t = self.t;
                // the fix is `lag` old: move it to now with the follower's velocity guess
                let here = pos + v_guess * lag;
                self.restart(t, &here, r_pos, yaw, yaw_var, v_guess);
                return FixOutcome::Restarted;
            }
            return FixOutcome::Rejected;
        }
        self.rejections = 0;
        let k = self.p * h.transpose() * s_inv;
        self.x += k * innov;
        // Joseph form keeps P symmetric positive definite
        let ikh = Matrix6::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * r_pos * k.transpose();

        // heading
        let hy = Vector2::new(1.0, -lag);
        let iy = wrap(yaw - (self.y[0] - lag * self.y[1]));
        let sy = (hy.transpose() * self.py * hy)[(0, 0)] + yaw_var;
        if sy > 0.0 {
            let ky = self.py * hy / sy;
            self.y += ky * iy;
            self.y[0] = wrap(self.y[0]);
            let iky = Matrix2::identity() - ky * hy.transpose();
            self.py = iky * self.py * iky.transpose() + ky * ky.transpose() * yaw_var;
        }
        FixOutcome::Accepted
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parent on a circle of radius 30 m at 1 m/s, fixed every 0.1 s for 20 s, then
    /// predicted 5 s without a fix: the coordinated turn keeps it near the circle.
    fn predicted_miss_m(coordinated_turn: bool) -> f64 {
        let (radius, speed) = (30.0, 1.0);
        let w = speed / radius;
        let at = |t: f64| {
            let a = w * t;
            (
                Vector3::new(radius * a.sin(), radius * (1.0 - a.cos()), 10.0),
                a,
            )
        };
        let mut o = ParentObserver::new(ObserverParams {
            accel_noise_mps2: 0.1,
            yaw_accel_noise_radps2: 0.02,
            gate_chi2: 16.27,
            max_rejections: 3,
            initial_speed_std_mps: 1.0,
            coordinated_turn,
        });
        let r = Matrix3::identity() * 0.05f64.powi(2);
        let v0 = Vector3::new(speed, 0.0, 0.0);
        for k in 0..=200 {
            let t = f64::from(k) * 0.1;
            let (p, yaw) = at(t);
            o.predict(t);
            o.fuse(t, &p, &r, yaw, 0.02f64.powi(2), &v0);
        }
        o.predict(25.0);
        (o.position() - at(25.0).0).norm()
    }

    #[test]
    fn a_parent_lost_in_a_turn_is_predicted_along_it() {
        let turning = predicted_miss_m(true);
        let straight = predicted_miss_m(false);
        assert!(turning < 0.1, "{turning}");
        // straight on: off by about v·w·t²/2 = 0.42 m after 5 s
        assert!(straight > 0.3, "{straight}");
    }
}
