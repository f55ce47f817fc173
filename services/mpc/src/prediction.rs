//! The predictive model (15), `x_{k+1} = f(x_k, u_k)`, linearised about the current state.
//!
//! State (12), in the vehicle's **level frame** at the time of the step (origin at the
//! vehicle, x along the current heading projected on the horizontal, y to starboard, z down):
//! `x = [x y z  φ θ ψ  u v w  p q r]` — position in the level frame, ZYX Euler angles of the
//! body relative to the level frame (so `ψ` starts at 0 each step and only `φ`, `θ` come from
//! the AHRS), and the body velocity `ν`. Input `u = τ` (6).
//!
//! Continuous dynamics: `ṗ = R(φ,θ,ψ) ν₁`, `Θ̇ = T(φ,θ) ν₂` (eq. 10's `J(η)`), and
//! `ν̇ = sim_plant::model::Vehicle::nu_dot(ν, q(Θ), τ)` — the very code the plant integrates.
//! The MPC does not know the current, so it predicts with `ν_r = ν`.

use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3, Vector6};
use sim_plant::model::Vehicle;

/// State dimension.
pub const NX: usize = 12;
/// Input dimension.
pub const NU: usize = 6;

/// State vector.
pub type StateVec = SVector<f64, NX>;
/// State matrix.
pub type StateMat = SMatrix<f64, NX, NX>;
/// Input matrix.
pub type InputMat = SMatrix<f64, NX, NU>;

/// Below this `|cos θ|` the Euler kinematics `T(φ,θ)` are treated as singular (|θ| > 87°).
pub const MIN_COS_PITCH: f64 = 0.05;

/// Continuous-time `ẋ = f(x, τ)`.
#[must_use]
pub fn f(vehicle: &Vehicle, x: &StateVec, tau: &Vector6<f64>) -> StateVec {
    let (phi, th, psi) = (x[3], x[4], x[5]);
    let q = UnitQuaternion::from_euler_angles(phi, th, psi);
    let nu: Vector6<f64> = x.fixed_rows::<6>(6).into_owned();
    let v = Vector3::new(nu[0], nu[1], nu[2]);
    let (p, qr, r) = (nu[3], nu[4], nu[5]);
    let p_dot = q.transform_vector(&v);
    let (sf, cf) = phi.sin_cos();
    let (st, ct) = th.sin_cos();
    let tt = st / ct;
    let nu_dot = vehicle.nu_dot(&nu, &q, tau);
    let mut out = StateVec::zeros();
    out[0] = p_dot.x;
    out[1] = p_dot.y;
    out[2] = p_dot.z;
    out[3] = p + sf * tt * qr + cf * tt * r;
    out[4] = cf * qr - sf * r;
    out[5] = (sf * qr + cf * r) / ct;
    out.fixed_rows_mut::<6>(6).copy_from(&nu_dot);
    out
}

/// Continuous Jacobians at `(x0, τ0)`: `A = ∂f/∂x` by central differences (the position
/// columns are exactly zero: nothing depends on where the vehicle is), `B = ∂f/∂τ = [0; M⁻¹]`
/// exactly (`ν̇` is affine in `τ`). Returns `(A, B, f(x0, τ0))`.
#[must_use]
pub fn jacobians(
    vehicle: &Vehicle,
    x0: &StateVec,
    tau0: &Vector6<f64>,
) -> (StateMat, InputMat, StateVec) {
    let f0 = f(vehicle, x0, tau0);
    let mut a = StateMat::zeros();
    for i in 3..NX {
        let h = 1e-6 * x0[i].abs().max(1.0);
        let mut xp = *x0;
        let mut xm = *x0;
        xp[i] += h;
        xm[i] -= h;
        let col = (f(vehicle, &xp, tau0) - f(vehicle, &xm, tau0)) / (2.0 * h);
        a.set_column(i, &col);
    }
    let mut b = InputMat::zeros();
    b.fixed_view_mut::<6, 6>(6, 0)
        .copy_from(vehicle.mass_matrix_inverse());
    (a, b, f0)
}

/// Exact zero-order-hold discretisation of `ż = A z + B v + c` over `h` by the Taylor series
/// of the matrix exponential (`‖A h‖` is ≪ 1 for this vehicle at 0.1 s; the series runs until
/// its terms are below 1e-15 relative, at most 40 terms):
/// `A_d = e^{Ah}`, `Γ = ∫₀ʰ e^{As} ds`, `B_d = Γ B`, `c_d = Γ c`.
///
/// When the position columns of `A` are zero, as [`jacobians`] makes them, every power of
/// `A h` has them zero too, so the series runs on the other nine columns alone. That skips
/// only products with exact zeros, whose sums are unchanged, so both paths give the same
/// numbers (a test checks it) and the structured one costs about a third less.
#[must_use]
#[inline(always)]
pub fn discretise(
    a: &StateMat,
    b: &InputMat,
    c: &StateVec,
    h: f64,
) -> (StateMat, InputMat, StateVec) {
    let (ad, gamma) = if a.fixed_columns::<3>(0).iter().all(|&v| v == 0.0) {
        gamma_position_free(a, h)
    } else {
        gamma_dense(a, h)
    };
    // `B = [0; M⁻¹]` from [`jacobians`]: only its lower six rows take part, as above.
    let bd = if b.fixed_rows::<NU>(0).iter().all(|&v| v == 0.0) {
        gamma.fixed_columns::<NU>(NU) * b.fixed_rows::<NU>(NU)
    } else {
        gamma * b
    };
    (ad, bd, gamma * c)
}

/// `(e^{Ah}, ∫₀ʰ e^{As} ds)` by the Taylor series on full 12 × 12 terms.
fn gamma_dense(a: &StateMat, h: f64) -> (StateMat, StateMat) {
    let ah = a * h;
    let mut term = StateMat::identity();
    let mut ad = StateMat::identity();
    let mut gsum = StateMat::identity();
    for k in 1..=TAYLOR_TERMS {
        term = term * ah / f64::from(k);
        ad += term;
        gsum += term / f64::from(k + 1);
        if term.amax() <= TAYLOR_TOL * ad.amax() {
            break;
        }
    }
    (ad, gsum * h)
}

/// [`gamma_dense`] for an `A` whose first three columns are zero: the terms `(Ah)^k / k!`
/// (k ≥ 1) then have zero first columns as well, so only their last nine columns are kept
/// and multiplied by the lower-right 9 × 9 block of `A h`. The first three columns of both
/// sums stay those of the identity.
#[inline(always)]
fn gamma_position_free(a: &StateMat, h: f64) -> (StateMat, StateMat) {
    const NP: usize = 3;
    const NR: usize = NX - NP;
    let ah: SMatrix<f64, NR, NR> = a.fixed_view::<NR, NR>(NP, NP) * h;
    // The first term, `A h`, is the one that needs `A`'s top rows; the later ones follow
    // from it through the 9 × 9 block.
    let mut term: SMatrix<f64, NX, NR> = a.fixed_columns::<NR>(NP) * h;
    let identity: SMatrix<f64, NX, NR> = StateMat::identity().fixed_columns::<NR>(NP).into_owned();
    let mut ad = identity + term;
    let mut gsum = identity + term / 2.0;
    // The full `ad` also holds the identity's ones in its first columns.
    let mut k = 1;
    while k < TAYLOR_TERMS && term.amax() > TAYLOR_TOL * ad.amax().max(1.0) {
        k += 1;
        term = term * ah / f64::from(k);
        ad += term;
        gsum += term / f64::from(k + 1);
    }
    let mut ad_full = StateMat::identity();
    ad_full.fixed_columns_mut::<NR>(NP).copy_from(&ad);
    let mut gamma = StateMat::identity() * h;
    gamma.fixed_columns_mut::<NR>(NP).copy_from(&(gsum * h));
    (ad_full, gamma)
}

/// `A_d M`. When the first three columns of `A_d` are the identity's, as [`discretise`] makes
/// them from [`jacobians`], the products with their exact zeros and ones are skipped; each
/// entry is still summed in the full product's order, so the result is the same.
#[must_use]
#[inline(always)]
pub fn advance(ad: &StateMat, m: &InputMat) -> InputMat {
    let identity = StateMat::identity();
    if ad.fixed_columns::<3>(0) != identity.fixed_columns::<3>(0) {
        return ad * m;
    }
    let mut out = InputMat::zeros();
    for c in 0..NU {
        let mut col = StateVec::zeros();
        col.fixed_rows_mut::<3>(0)
            .copy_from(&m.fixed_view::<3, 1>(0, c));
        for l in 3..NX {
            col += ad.column(l) * m[(l, c)];
        }
        out.set_column(c, &col);
    }
    out
}

/// Most terms of the Taylor series.
const TAYLOR_TERMS: u32 = 40;
/// The series stops when a term's largest entry is below this fraction of the sum's.
const TAYLOR_TOL: f64 = 1e-15;

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use sim_plant::VehicleParams;

    fn vehicle() -> Vehicle {
        Vehicle::new(&VehicleParams::default()).unwrap()
    }

    #[test]
    fn jacobian_matches_a_second_difference_scheme() {
        let v = vehicle();
        let mut x0 = StateVec::zeros();
        x0[3] = 0.1;
        x0[4] = -0.2;
        x0.fixed_rows_mut::<6>(6)
            .copy_from(&Vector6::new(1.2, 0.1, -0.1, 0.05, 0.02, 0.1));
        let tau = Vector6::new(100.0, 10.0, 0.0, 1.0, 2.0, 3.0);
        let (a, b, f0) = jacobians(&v, &x0, &tau);
        // Linear prediction of a small perturbation agrees with the nonlinear f.
        let dx = StateVec::from_fn(|i, _| if i >= 3 { 1e-4 * (i as f64 - 6.5) } else { 0.0 });
        let du = Vector6::new(5.0, -3.0, 2.0, 0.5, -0.5, 0.2);
        let lin = f0 + a * dx + b * du;
        let non = f(&v, &(x0 + dx), &(tau + du));
        assert_relative_eq!(lin, non, epsilon = 1e-6);
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(128))]
        /// The structured series (position columns of `A` zero) gives bit for bit what the
        /// dense one gives, on the Jacobians of any state and input a run can meet, and on
        /// a stiffer `A` that needs many terms.
        #[test]
        fn the_position_free_series_equals_the_dense_one(
            roll in -0.6f64..0.6, pitch in -0.6f64..0.6,
            nu in proptest::array::uniform6(-2.0f64..2.0),
            tau in proptest::array::uniform6(-500.0f64..500.0),
            stiff in 1.0f64..30.0, h in 0.01f64..0.5,
        ) {
            let v = vehicle();
            let mut x0 = StateVec::zeros();
            x0[3] = roll;
            x0[4] = pitch;
            x0.fixed_rows_mut::<6>(6).copy_from(&Vector6::from(nu));
            let (a, b, c) = jacobians(&v, &x0, &Vector6::from(tau));
            for a in [a, a * stiff] {
                proptest::prop_assert!(a.fixed_columns::<3>(0).iter().all(|&e| e == 0.0));
                let (ad, bd, cd) = discretise(&a, &b, &c, h);
                let (ad0, gamma0) = gamma_dense(&a, h);
                proptest::prop_assert_eq!(ad, ad0);
                proptest::prop_assert_eq!(bd, gamma0 * b);
                proptest::prop_assert_eq!(cd, gamma0 * c);
                proptest::prop_assert_eq!(advance(&ad, &bd), ad * bd);
            }
        }
    }

    #[test]
    fn discretisation_matches_fine_euler_integration_of_the_linear_model() {
        let v = vehicle();
        let mut x0 = StateVec::zeros();
        x0[6] = 1.5;
        x0[11] = 0.1;
        let tau = Vector6::new(200.0, 0.0, 0.0, 0.0, 0.0, 10.0);
        let (a, b, c) = jacobians(&v, &x0, &tau);
        let h = 0.1;
        let (ad, bd, cd) = discretise(&a, &b, &c, h);
        let dv = Vector6::new(10.0, 5.0, -5.0, 1.0, 1.0, -1.0);
        let z0 = StateVec::from_fn(|i, _| 0.01 * i as f64);
        let n = 100_000;
        let dt = h / f64::from(n);
        let mut z = z0;
        for _ in 0..n {
            // Midpoint rule on the linear ODE.
            let k1 = a * z + b * dv + c;
            let zm = z + k1 * (dt / 2.0);
            z += (a * zm + b * dv + c) * dt;
        }
        assert_relative_eq!(ad * z0 + bd * dv + cd, z, epsilon = 1e-9);
    }
}
