//! The vehicle model of paper eq. (10): `M ν̇ + (C(ν) + D(ν)) ν + g(η) = τ`, `η̇ = J(η) ν`.
//!
//! This is the code that both the plant integrates and the MPC linearises (`mpc` calls
//! [`Vehicle::nu_dot`]), so it is public and free of any integrator state.
//!
//! Conventions (Fossen): body frame x forward, y starboard, z down; NED world frame;
//! `ν = [u v w p q r]` in the body frame; attitude a unit quaternion body→NED. The body
//! origin is the point whose NED position the plant reports; with the default parameters it
//! is the centre of gravity (CG).

use nalgebra::{Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};

use crate::{PlantError, VehicleParams};

/// Standard gravity, m/s², used for the default weight.
pub const GRAVITY_MPS2: f64 = 9.81;

/// The skew operator `S(λ)` of eq. (11): `S(λ) x = λ × x`.
#[must_use]
pub fn skew(l: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -l.z, l.y, l.z, 0.0, -l.x, -l.y, l.x, 0.0)
}

/// A vehicle built from [`VehicleParams`]: `M = M_RB + M_A` and `M⁻¹` precomputed.
#[derive(Debug, Clone, PartialEq)]
pub struct Vehicle {
    m_rb: Matrix6<f64>,
    m_a: Matrix6<f64>,
    m: Matrix6<f64>,
    m_inv: Matrix6<f64>,
    d1: Vector6<f64>,
    d2: Vector6<f64>,
    weight_n: f64,
    buoyancy_n: f64,
    r_g: Vector3<f64>,
    r_b: Vector3<f64>,
    munk: bool,
}

impl Vehicle {
    /// Builds the mass matrices from `p` (validated first).
    ///
    /// `M_RB = [[m·I, −m·S(r_G)], [m·S(r_G), I_O]]` where `I_O = I_G − m·S(r_G)²` moves the
    /// paper's inertia about the CG to the body origin (parallel-axis theorem); `M_A` is the
    /// diagonal added-mass matrix.
    ///
    /// # Errors
    /// [`PlantError::InvalidConfig`] for a bad parameter, [`PlantError::SingularMass`] if `M`
    /// cannot be inverted.
    pub fn new(p: &VehicleParams) -> Result<Self, PlantError> {
        p.validate()?;
        let m = p.mass_kg;
        let r_g = Vector3::from(p.cg_body_m);
        let s_g = skew(&r_g);
        let i_g = Matrix3::from_diagonal(&Vector3::from(p.inertia_kgm2));
        let i_o = i_g - m * s_g * s_g;
        let mut m_rb = Matrix6::zeros();
        m_rb.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * m));
        m_rb.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-m * s_g));
        m_rb.fixed_view_mut::<3, 3>(3, 0).copy_from(&(m * s_g));
        m_rb.fixed_view_mut::<3, 3>(3, 3).copy_from(&i_o);
        let m_a = Matrix6::from_diagonal(&Vector6::from(p.added_mass));
        let mass = m_rb + m_a;
        let m_inv = mass.try_inverse().ok_or(PlantError::SingularMass)?;
        if m_inv.iter().any(|x| !x.is_finite()) {
            return Err(PlantError::SingularMass);
        }
        Ok(Self {
            m_rb,
            m_a,
            m: mass,
            m_inv,
            d1: Vector6::from(p.damping_linear),
            d2: Vector6::from(p.damping_quadratic),
            weight_n: p.weight_n,
            buoyancy_n: p.buoyancy_n,
            r_g,
            r_b: Vector3::from(p.cb_body_m),
            munk: p.munk_moment,
        })
    }

    /// `M = M_RB + M_A` (eq. 10), symmetric positive definite.
    #[must_use]
    pub fn mass_matrix(&self) -> &Matrix6<f64> {
        &self.m
    }

    /// `M⁻¹`, precomputed.
    #[must_use]
    pub fn mass_matrix_inverse(&self) -> &Matrix6<f64> {
        &self.m_inv
    }

    /// Rigid-body inertia `M_RB`.
    #[must_use]
    pub fn rigid_body_mass(&self) -> &Matrix6<f64> {
        &self.m_rb
    }

    /// Added mass `M_A` (diagonal).
    #[must_use]
    pub fn added_mass(&self) -> &Matrix6<f64> {
        &self.m_a
    }

    /// The momenta `(a, b)` that build the skew blocks of eq. (11) for the rigid body and the
    /// added mass: `a = M11 ν1 + M12 ν2`, `b = M21 ν1 + M22 ν2`.
    #[inline]
    fn momenta(&self, nu: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let n1 = nu.fixed_rows::<3>(0);
        let n2 = nu.fixed_rows::<3>(3);
        let rb = &self.m_rb;
        let a_rb = rb.fixed_view::<3, 3>(0, 0) * n1 + rb.fixed_view::<3, 3>(0, 3) * n2;
        let b_rb = rb.fixed_view::<3, 3>(3, 0) * n1 + rb.fixed_view::<3, 3>(3, 3) * n2;
        let ma = &self.m_a;
        let a_a = ma.fixed_view::<3, 3>(0, 0) * n1 + ma.fixed_view::<3, 3>(0, 3) * n2;
        let b_a = ma.fixed_view::<3, 3>(3, 0) * n1 + ma.fixed_view::<3, 3>(3, 3) * n2;
        // Without Munk terms the off-diagonal blocks of C_A are dropped (see crate docs).
        let a = if self.munk { a_rb + a_a } else { a_rb };
        (a, b_rb + b_a)
    }

    /// `C(ν) = C_RB(ν) + C_A(ν)` of eq. (11):
    /// `[[0, −S(a)], [−S(a), −S(b)]]` with `a = M11 ν1 + M12 ν2`, `b = M21 ν1 + M22 ν2` summed
    /// over `M_RB` and `M_A`. The matrix is skew-symmetric, so `νᵀC(ν)ν = 0`.
    ///
    /// With [`VehicleParams::munk_moment`] off (the default) the off-diagonal blocks of `C_A`
    /// (the Munk moment and its energy conjugate) are left out; `C` stays skew-symmetric.
    #[must_use]
    pub fn coriolis(&self, nu: &Vector6<f64>) -> Matrix6<f64> {
        let (a, b) = self.momenta(nu);
        let sa = -skew(&a);
        let sb = -skew(&b);
        let mut c = Matrix6::zeros();
        c.fixed_view_mut::<3, 3>(0, 3).copy_from(&sa);
        c.fixed_view_mut::<3, 3>(3, 0).copy_from(&sa);
        c.fixed_view_mut::<3, 3>(3, 3).copy_from(&sb);
        c
    }

    /// `C(ν) ν` without building the matrix: `[ν2 × a ; ν1 × a + ν2 × b]`.
    #[must_use]
    #[inline]
    pub fn coriolis_force(&self, nu: &Vector6<f64>) -> Vector6<f64> {
        let (a, b) = self.momenta(nu);
        let n1: Vector3<f64> = nu.fixed_rows::<3>(0).into_owned();
        let n2: Vector3<f64> = nu.fixed_rows::<3>(3).into_owned();
        let top = n2.cross(&a);
        let bottom = n1.cross(&a) + n2.cross(&b);
        Vector6::new(top.x, top.y, top.z, bottom.x, bottom.y, bottom.z)
    }

    /// `D(ν) = diag(d1ᵢ + d2ᵢ |νᵢ|)`, eq. (12).
    #[must_use]
    pub fn damping(&self, nu: &Vector6<f64>) -> Matrix6<f64> {
        Matrix6::from_diagonal(&self.damping_diag(nu))
    }

    #[inline]
    fn damping_diag(&self, nu: &Vector6<f64>) -> Vector6<f64> {
        self.d1 + self.d2.component_mul(&nu.abs())
    }

    /// `D(ν) ν` (eq. 12) without building the matrix.
    #[must_use]
    #[inline]
    pub fn damping_force(&self, nu: &Vector6<f64>) -> Vector6<f64> {
        self.damping_diag(nu).component_mul(nu)
    }

    /// `g(η)` of eq. (13), from the attitude quaternion (no Euler angles):
    /// `g = −[f_G + f_B ; r_G × f_G + r_B × f_B]` with `f_G = Rᵀ[0 0 W]ᵀ`, `f_B = −Rᵀ[0 0 B]ᵀ`.
    ///
    /// This equals the paper's Euler-angle form except for a typo in its fourth row, which
    /// must read `−B_y cosθ cosφ + B_z cosθ sinφ` (Fossen 2011, eq. 4.6); the paper prints
    /// `B_z cosφ`. A unit test checks the quaternion form against the corrected Euler form.
    #[must_use]
    #[inline]
    pub fn restoring(&self, attitude: &UnitQuaternion<f64>) -> Vector6<f64> {
        // Down axis of NED expressed in the body frame.
        let k = attitude.inverse_transform_vector(&Vector3::z());
        let f_g = k * self.weight_n;
        let f_b = k * -self.buoyancy_n;
        let f = f_g + f_b;
        let m = self.r_g.cross(&f_g) + self.r_b.cross(&f_b);
        -Vector6::new(f.x, f.y, f.z, m.x, m.y, m.z)
    }

    /// `ν̇ = M⁻¹ (τ − C(ν_r) ν_r − D(ν_r) ν_r − g(η))`, eq. (10) solved for the acceleration.
    ///
    /// `nu_r` is the velocity relative to the water; without current it is `ν`. For a constant,
    /// irrotational current the rigid-body terms written in `ν_r` are exact (Fossen 2011,
    /// Property 8.1), so this returns `ν̇_r`; the plant adds `ν̇_c = [−ω × ν_c ; 0]`.
    #[must_use]
    #[inline]
    pub fn nu_dot(
        &self,
        nu_r: &Vector6<f64>,
        attitude: &UnitQuaternion<f64>,
        tau: &Vector6<f64>,
    ) -> Vector6<f64> {
        let rhs =
            tau - self.coriolis_force(nu_r) - self.damping_force(nu_r) - self.restoring(attitude);
        self.m_inv * rhs
    }

    /// Kinetic energy `½ νᵀ M ν` (rigid body plus added mass), J.
    #[must_use]
    pub fn kinetic_energy(&self, nu: &Vector6<f64>) -> f64 {
        0.5 * nu.dot(&(self.m * nu))
    }

    /// Hydrostatic potential energy, J, relative to the body origin at depth 0:
    /// `−W·z_G + B·z_B` with `z_G`, `z_B` the NED depths of the two centres. Its rate is
    /// `g(η)ᵀν`, so `kinetic + potential` never grows when `τ = 0` (only `D` acts).
    #[must_use]
    pub fn potential_energy(
        &self,
        position_ned_m: &Vector3<f64>,
        attitude: &UnitQuaternion<f64>,
    ) -> f64 {
        let z_g = position_ned_m.z + attitude.transform_vector(&self.r_g).z;
        let z_b = position_ned_m.z + attitude.transform_vector(&self.r_b).z;
        -self.weight_n * z_g + self.buoyancy_n * z_b
    }

    /// Weight `W`, N.
    #[must_use]
    pub fn weight_n(&self) -> f64 {
        self.weight_n
    }

    /// Buoyancy `B`, N.
    #[must_use]
    pub fn buoyancy_n(&self) -> f64 {
        self.buoyancy_n
    }
}

/// Kinematics of eq. (10), `η̇ = J(η) ν`, in quaternion form: returns
/// `(ṗ_NED, q̇)` with `ṗ = R(q) ν1` and `q̇ = ½ q ⊗ (0, ν2)` (as a raw 4-vector `[i j k w]`).
#[must_use]
#[inline]
pub fn kinematics(
    attitude: &UnitQuaternion<f64>,
    nu: &Vector6<f64>,
) -> (Vector3<f64>, nalgebra::Quaternion<f64>) {
    let v: Vector3<f64> = nu.fixed_rows::<3>(0).into_owned();
    let w: Vector3<f64> = nu.fixed_rows::<3>(3).into_owned();
    let p_dot = attitude.transform_vector(&v);
    let omega = nalgebra::Quaternion::from_imag(w);
    let q_dot = attitude.quaternion() * omega * 0.5;
    (p_dot, q_dot)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn vehicle_with_offsets() -> Vehicle {
        let p = VehicleParams {
            cg_body_m: [0.02, -0.01, 0.03],
            cb_body_m: [-0.01, 0.02, -0.04],
            buoyancy_n: 3000.0,
            munk_moment: true,
            ..VehicleParams::default()
        };
        Vehicle::new(&p).unwrap()
    }

    /// The quaternion form of g(η) equals Fossen's Euler form of eq. (13), with the paper's
    /// fourth-row typo corrected.
    #[test]
    fn restoring_matches_euler_form_of_eq13() {
        let v = vehicle_with_offsets();
        let p = VehicleParams {
            cg_body_m: [0.02, -0.01, 0.03],
            cb_body_m: [-0.01, 0.02, -0.04],
            buoyancy_n: 3000.0,
            ..VehicleParams::default()
        };
        let (w, b) = (p.weight_n, p.buoyancy_n);
        let bx = w * p.cg_body_m[0] - b * p.cb_body_m[0];
        let by = w * p.cg_body_m[1] - b * p.cb_body_m[1];
        let bz = w * p.cg_body_m[2] - b * p.cb_body_m[2];
        for &(phi, th, psi) in &[
            (0.3, -0.4, 1.0),
            (-1.2, 0.7, -2.5),
            (0.0, 0.0, 0.0),
            (2.0, 1.4, 0.3),
        ] {
            let q = UnitQuaternion::from_euler_angles(phi, th, psi);
            let g = v.restoring(&q);
            let (sf, cf, st, ct) = (f64::sin(phi), f64::cos(phi), f64::sin(th), f64::cos(th));
            let expected = Vector6::new(
                (w - b) * st,
                -(w - b) * ct * sf,
                -(w - b) * ct * cf,
                -by * ct * cf + bz * ct * sf,
                bz * st + bx * ct * cf,
                -bx * ct * sf - by * st,
            );
            assert_relative_eq!(g, expected, epsilon = 1e-9);
        }
    }

    #[test]
    fn coriolis_force_equals_matrix_times_nu() {
        for v in [
            vehicle_with_offsets(),
            Vehicle::new(&VehicleParams::default()).unwrap(),
        ] {
            let nu = Vector6::new(1.2, -0.3, 0.4, 0.1, -0.2, 0.3);
            assert_relative_eq!(v.coriolis(&nu) * nu, v.coriolis_force(&nu), epsilon = 1e-12);
            let c = v.coriolis(&nu);
            assert_relative_eq!(c, -c.transpose(), epsilon = 1e-12);
        }
    }

    #[test]
    fn rigid_body_coriolis_is_newton_euler_for_cg_origin() {
        // With the origin at the CG and no added mass, C_RB ν = [m ω×v ; ω×Iω].
        let p = VehicleParams {
            added_mass: [0.0; 6],
            ..VehicleParams::default()
        };
        let v = Vehicle::new(&p).unwrap();
        let nu = Vector6::new(1.0, 0.5, -0.2, 0.3, -0.1, 0.2);
        let lin = Vector3::new(nu[0], nu[1], nu[2]);
        let w = Vector3::new(nu[3], nu[4], nu[5]);
        let i = Matrix3::from_diagonal(&Vector3::from(p.inertia_kgm2));
        let f = w.cross(&lin) * p.mass_kg;
        let m = w.cross(&(i * w));
        assert_relative_eq!(
            v.coriolis_force(&nu),
            Vector6::new(f.x, f.y, f.z, m.x, m.y, m.z),
            epsilon = 1e-12
        );
    }

    #[test]
    fn munk_moment_is_dropped_by_default_and_kept_on_request() {
        let nu = Vector6::new(1.5, 0.2, 0.0, 0.0, 0.0, 0.0);
        let off = Vehicle::new(&VehicleParams::default()).unwrap();
        assert_relative_eq!(off.coriolis_force(&nu)[5], 0.0, epsilon = 1e-12);
        let on = Vehicle::new(&VehicleParams {
            munk_moment: true,
            ..VehicleParams::default()
        })
        .unwrap();
        // Yaw Munk moment (Y_v̇ − X_u̇)·u·v = (300 − 40)·1.5·0.2 appears in C(ν)ν.
        assert_relative_eq!(on.coriolis_force(&nu)[5], 260.0 * 1.5 * 0.2, epsilon = 1e-9);
    }

    #[test]
    fn mass_matrix_is_symmetric_and_inverse_is_exact() {
        let v = vehicle_with_offsets();
        let m = v.mass_matrix();
        assert_relative_eq!(*m, m.transpose(), epsilon = 1e-12);
        assert_relative_eq!(
            m * v.mass_matrix_inverse(),
            Matrix6::identity(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn potential_energy_rate_is_g_dot_nu() {
        let v = vehicle_with_offsets();
        let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.5);
        let p = Vector3::new(1.0, 2.0, 3.0);
        let nu = Vector6::new(0.4, -0.2, 0.3, 0.2, 0.1, -0.3);
        let h = 1e-6;
        let (pd, qd) = kinematics(&q, &nu);
        let q2 = UnitQuaternion::new_normalize(q.quaternion() + qd * h);
        let q1 = UnitQuaternion::new_normalize(q.quaternion() - qd * h);
        let rate = (v.potential_energy(&(p + pd * h), &q2)
            - v.potential_energy(&(p - pd * h), &q1))
            / (2.0 * h);
        assert_relative_eq!(rate, v.restoring(&q).dot(&nu), epsilon = 1e-5);
    }
}
