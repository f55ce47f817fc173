//! # sim-plant — the simulated vehicle
//!
//! A pure library: the Fossen 6-DOF AUV model of the paper's eqs. (10)-(13), a fixed-step
//! RK4 integrator with thrust saturation and a constant ocean current, and the vehicle's own
//! navigation sensors ([`nav`]). No I/O, no clock, no threads: state in, state out. The
//! `sim-plant` process (written by the lead) steps a [`Plant`] with the latest `thrust`
//! sample and publishes `truth` (the [`PlantState`]) and `nav` (a [`nav::NavMeasurement`]).
//!
//! ```
//! use nalgebra::{UnitQuaternion, Vector3, Vector6};
//! use sim_plant::{Plant, PlantConfig, PlantState};
//!
//! let config = PlantConfig::default();
//! let start = PlantState::at_rest(Vector3::new(0.0, 0.0, 5.0), UnitQuaternion::identity());
//! let mut plant = Plant::new(&config, start)?;
//! // 100 N of surge thrust for one 0.1 s tick (10 RK4 substeps of 0.01 s).
//! plant.advance(&Vector6::new(100.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0.1)?;
//! assert!(plant.state().nu[0] > 0.0);
//! # Ok::<(), sim_plant::PlantError>(())
//! ```
//!
//! ## Model (eq. 10)
//! `M ν̇ + (C(ν) + D(ν)) ν + g(η) = τ`, `η̇ = J(η) ν`, with `M = M_RB + M_A`; `C = C_RB + C_A`
//! built with the skew operator of eq. (11); `D = diag(d1ᵢ + d2ᵢ|νᵢ|)` (eq. 12); `g(η)` from
//! weight, buoyancy and the centres of gravity and buoyancy (eq. 13). The attitude is a unit
//! quaternion body→NED, so there is no singularity at ±90° pitch; Euler angles are produced
//! for output only ([`PlantState::euler_rpy`]). See [`model`] for the formulas.
//!
//! ## The paper's vehicle (the default [`VehicleParams`]) and our choices
//! The paper gives `m = 325 kg`, `Jxx = 225`, `Jyy = 175`, `Jzz = 215 kg·m²`, `Yc = 0.05 m`,
//! added masses `λ ∈ [40, 300] kg` (linear) and `[20, 225] kg·m²` (angular), `d1 ≤ 50 N·s/m`
//! (its `d1min` is missing from the text) and `d2 ∈ [75, 125] kg/m`. For a ~3 m torpedo:
//!
//! | quantity | surge/roll | sway, heave / pitch, yaw | why |
//! |---|---|---|---|
//! | added mass, kg | X: 40 (range min) | Y, Z: 300 (range max) | a slender body displaces little fluid moving along its axis, about its own mass moving across it |
//! | added inertia, kg·m² | K: 20 (min) | M, N: 200 | a body of revolution carries almost no fluid in roll; in pitch/yaw ≈ displaced mass · L²/12 ≈ 325·3²/12 ≈ 240, kept inside the range |
//! | d1 linear damping, N·s/m (N·m·s/rad) | 20 / 50 | 50 | we read the missing `d1min` as 10 N·s/m; surge is the streamlined axis, low; the rest at the max |
//! | d2 quadratic damping, kg/m (kg·m²) | 75 / 75 | 125 | surge drag is the smallest (min), cross-flow drag the largest (max); the paper gives one range, applied to the angular axes with the same numbers |
//!
//! **Axes and `Yc`.** The paper's `Yc = 0.05 m` is the only offset between the centres it
//! gives; we read it as the metacentric height `BG` — the CG 0.05 m *below* the CB — because
//! that is what makes the vehicle self-righting in roll and pitch. In our FRD body frame
//! (z down) that is `z_G > z_B`: the body origin is at the CG, `cg_body_m = [0, 0, 0]` and
//! `cb_body_m = [0, 0, −0.05]`. The inertia is taken about the CG (moved to the origin with
//! the parallel-axis theorem when `cg_body_m ≠ 0`). Neutral buoyancy by default:
//! `W = B = 325·9.81 N`.
//!
//! **Munk terms.** The off-diagonal blocks of `C_A` (with diagonal added mass) produce the
//! Munk moment, e.g. `(Y_v̇ − X_u̇)·u·v` in yaw — a destabilising moment that makes a bare
//! hull turn broadside. On a real torpedo its fins and hull lift cancel it, which is why
//! Fossen's own REMUS-100 simulator zeroes those entries of `C_A`. We drop the lower-left
//! block of `C_A` (the Munk moments) *together with* its skew-symmetric partner (the
//! upper-right block), so that `C` stays skew-symmetric: `νᵀC(ν)ν = 0` and the model stays
//! passive (energy only leaves through `D`), which zeroing entries one-sidedly would break.
//! [`VehicleParams::munk_moment`]` = true` keeps the full `C_A`.
//!
//! **Ocean current.** A constant NED current `v_c` enters through the relative velocity
//! `ν_r = ν − [Rᵀ v_c ; 0]`: `M ν̇_r + C(ν_r)ν_r + D(ν_r)ν_r + g = τ` (exact for a constant,
//! irrotational current, Fossen 2011 Property 8.1), `ν̇ = ν̇_r − [ω × Rᵀv_c ; 0]`, and the
//! position integrates the velocity over ground `ν`. [`PlantConfig::current_zones`] make
//! the current differ in places ([`current`]): then `v_c` is taken where the vehicle is, and
//! its rate along the vehicle's path adds `Rᵀ v̇_c` to `ν̇`.
//!
//! ## Integrator
//! Classic RK4 on `(p, q, ν)`, step `step_s` (default 0.01 s); [`Plant::advance`] runs
//! `⌈duration / step_s⌉` equal substeps covering exactly `duration`, renormalises the
//! quaternion after every substep, and rejects the whole call (state untouched) if anything
//! becomes non-finite. `τ` is saturated per axis to `±thrust_max` first.
#![forbid(unsafe_code)]

pub mod current;
pub mod model;
pub mod nav;

use nalgebra::{Quaternion, UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use current::{CurrentField, CurrentZone};
use model::Vehicle;

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlantError {
    /// A configuration value is out of range; the message names the key.
    #[error("invalid config: {0}")]
    InvalidConfig(String),
    /// An input (thrust, duration, initial state) is NaN or infinite; names which.
    #[error("non-finite input: {0}")]
    NonFiniteInput(&'static str),
    /// An input is finite but out of range (negative duration, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// Integration produced a NaN or infinity; the state was left as it was before the call.
    #[error("state became non-finite during integration; state left unchanged")]
    NonFiniteState,
    /// `M = M_RB + M_A` is not invertible.
    #[error("mass matrix M = M_RB + M_A is singular")]
    SingularMass,
}

/// Physical parameters of one vehicle (paper §5; see the crate docs for the choices).
/// Body frame x forward, y starboard, z down; the body origin is the reported position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleParams {
    /// Rigid-body mass `m`, kg. Default 325.
    pub mass_kg: f64,
    /// Principal moments of inertia about the CG `[Jxx Jyy Jzz]`, kg·m². Default [225, 175, 215].
    pub inertia_kgm2: [f64; 3],
    /// Diagonal added mass `[X_u̇ Y_v̇ Z_ẇ K_ṗ M_q̇ N_ṙ]` as positive numbers, kg (first
    /// three) and kg·m² (last three). Default [40, 300, 300, 20, 200, 200].
    pub added_mass: [f64; 6],
    /// Linear damping `d1` per axis (eq. 12), N·s/m and N·m·s/rad. Default [20, 50, 50, 50, 50, 50].
    pub damping_linear: [f64; 6],
    /// Quadratic damping `d2` per axis (eq. 12), kg/m and kg·m². Default [75, 125, 125, 75, 125, 125].
    pub damping_quadratic: [f64; 6],
    /// Weight `W = m g`, N. Default 325·9.81 = 3188.25.
    pub weight_n: f64,
    /// Buoyancy `B`, N. Default = weight (neutral).
    pub buoyancy_n: f64,
    /// Centre of gravity in the body frame, m. Default [0, 0, 0] (origin at the CG).
    pub cg_body_m: [f64; 3],
    /// Centre of buoyancy in the body frame, m. Default [0, 0, −0.05]: the paper's
    /// `Yc = 0.05 m`, CB above CG, self-righting.
    pub cb_body_m: [f64; 3],
    /// Keep the Munk-moment blocks of `C_A` (see crate docs). Default false.
    pub munk_moment: bool,
}

impl Default for VehicleParams {
    fn default() -> Self {
        let weight = 325.0 * model::GRAVITY_MPS2;
        Self {
            mass_kg: 325.0,
            inertia_kgm2: [225.0, 175.0, 215.0],
            added_mass: [40.0, 300.0, 300.0, 20.0, 200.0, 200.0],
            damping_linear: [20.0, 50.0, 50.0, 50.0, 50.0, 50.0],
            damping_quadratic: [75.0, 125.0, 125.0, 75.0, 125.0, 125.0],
            weight_n: weight,
            buoyancy_n: weight,
            cg_body_m: [0.0, 0.0, 0.0],
            cb_body_m: [0.0, 0.0, -0.05],
            munk_moment: false,
        }
    }
}

fn bad(key: &str, rule: &str, got: impl std::fmt::Debug) -> PlantError {
    PlantError::InvalidConfig(format!("{key} must be {rule}, got {got:?}"))
}

fn check_all(key: &str, v: &[f64], ok: impl Fn(f64) -> bool, rule: &str) -> Result<(), PlantError> {
    if v.iter().all(|&x| x.is_finite() && ok(x)) {
        Ok(())
    } else {
        Err(bad(key, rule, v))
    }
}

impl VehicleParams {
    /// Checks every parameter; the error names the key (`vehicle.<field>`).
    ///
    /// # Errors
    /// [`PlantError::InvalidConfig`].
    pub fn validate(&self) -> Result<(), PlantError> {
        check_all(
            "vehicle.mass_kg",
            &[self.mass_kg],
            |x| x > 0.0,
            "finite and > 0",
        )?;
        check_all(
            "vehicle.inertia_kgm2",
            &self.inertia_kgm2,
            |x| x > 0.0,
            "finite and > 0",
        )?;
        check_all(
            "vehicle.added_mass",
            &self.added_mass,
            |x| x >= 0.0,
            "finite and >= 0",
        )?;
        check_all(
            "vehicle.damping_linear",
            &self.damping_linear,
            |x| x >= 0.0,
            "finite and >= 0",
        )?;
        check_all(
            "vehicle.damping_quadratic",
            &self.damping_quadratic,
            |x| x >= 0.0,
            "finite and >= 0",
        )?;
        check_all(
            "vehicle.weight_n",
            &[self.weight_n],
            |x| x > 0.0,
            "finite and > 0",
        )?;
        check_all(
            "vehicle.buoyancy_n",
            &[self.buoyancy_n],
            |x| x >= 0.0,
            "finite and >= 0",
        )?;
        check_all("vehicle.cg_body_m", &self.cg_body_m, |_| true, "finite")?;
        check_all("vehicle.cb_body_m", &self.cb_body_m, |_| true, "finite")?;
        Ok(())
    }
}

/// Plant configuration: the vehicle, the integrator step, saturation, current.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantConfig {
    /// The vehicle. Default: the paper's.
    pub vehicle: VehicleParams,
    /// RK4 step, s. Default 0.01. Must be in (0, 1].
    pub step_s: f64,
    /// Per-axis limit on `|τ|`: N for `[X Y Z]`, N·m for `[K M N]`.
    /// Default [500, 300, 300, 100, 200, 200].
    pub thrust_max: [f64; 6],
    /// Constant ocean current in NED, m/s. Default [0, 0, 0].
    pub current_ned_mps: [f64; 3],
    /// Zones where the current differs (each adds its own to the constant one). Default
    /// none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub current_zones: Vec<CurrentZone>,
}

impl Default for PlantConfig {
    fn default() -> Self {
        Self {
            vehicle: VehicleParams::default(),
            step_s: 0.01,
            thrust_max: [500.0, 300.0, 300.0, 100.0, 200.0, 200.0],
            current_ned_mps: [0.0; 3],
            current_zones: Vec::new(),
        }
    }
}

impl PlantConfig {
    /// # Errors
    /// [`PlantError::InvalidConfig`] naming the bad key.
    pub fn validate(&self) -> Result<(), PlantError> {
        self.vehicle.validate()?;
        if !(self.step_s.is_finite() && self.step_s > 0.0 && self.step_s <= 1.0) {
            return Err(bad("step_s", "in (0, 1]", self.step_s));
        }
        check_all(
            "thrust_max",
            &self.thrust_max,
            |x| x > 0.0,
            "finite and > 0",
        )?;
        check_all("current_ned_mps", &self.current_ned_mps, |_| true, "finite")?;
        for (i, z) in self.current_zones.iter().enumerate() {
            z.validate(i)?;
        }
        Ok(())
    }
}

/// The plant's true state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlantState {
    /// Position of the body origin in NED, m.
    pub position_ned_m: Vector3<f64>,
    /// Attitude, body→NED.
    pub attitude: UnitQuaternion<f64>,
    /// Body velocity over ground `[u v w p q r]`, m/s and rad/s.
    pub nu: Vector6<f64>,
}

impl Default for PlantState {
    fn default() -> Self {
        Self::at_rest(Vector3::zeros(), UnitQuaternion::identity())
    }
}

impl PlantState {
    /// A state with zero velocity.
    #[must_use]
    pub fn at_rest(position_ned_m: Vector3<f64>, attitude: UnitQuaternion<f64>) -> Self {
        Self {
            position_ned_m,
            attitude,
            nu: Vector6::zeros(),
        }
    }

    /// ZYX Euler angles `(roll φ, pitch θ, yaw ψ)`, rad — for output only.
    #[must_use]
    pub fn euler_rpy(&self) -> (f64, f64, f64) {
        self.attitude.euler_angles()
    }

    /// True when every component is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.position_ned_m.iter().all(|x| x.is_finite())
            && self.attitude.coords.iter().all(|x| x.is_finite())
            && self.nu.iter().all(|x| x.is_finite())
    }
}

/// The integrated vehicle: owns its state; [`Plant::advance`] moves it forward in time.
#[derive(Debug, Clone)]
pub struct Plant {
    vehicle: Vehicle,
    step_s: f64,
    thrust_max: Vector6<f64>,
    current: CurrentField,
    state: PlantState,
    applied_tau: Vector6<f64>,
}

/// Time derivative of `(p, q_raw, ν)`.
struct Deriv {
    p: Vector3<f64>,
    q: Quaternion<f64>,
    nu: Vector6<f64>,
}

impl Plant {
    /// # Errors
    /// [`PlantError::InvalidConfig`] for a bad config, [`PlantError::NonFiniteInput`] for a
    /// non-finite initial state, [`PlantError::SingularMass`].
    pub fn new(config: &PlantConfig, initial: PlantState) -> Result<Self, PlantError> {
        config.validate()?;
        if !initial.is_finite() {
            return Err(PlantError::NonFiniteInput("initial state"));
        }
        Ok(Self {
            vehicle: Vehicle::new(&config.vehicle)?,
            step_s: config.step_s,
            thrust_max: Vector6::from(config.thrust_max),
            current: CurrentField::new(config.current_ned_mps, config.current_zones.clone()),
            state: PlantState {
                attitude: UnitQuaternion::new_normalize(*initial.attitude.quaternion()),
                ..initial
            },
            applied_tau: Vector6::zeros(),
        })
    }

    /// The model this plant integrates.
    #[must_use]
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// Current true state.
    #[must_use]
    pub fn state(&self) -> &PlantState {
        &self.state
    }

    /// The thrust applied by the last [`Plant::advance`], after saturation.
    #[must_use]
    pub fn applied_tau(&self) -> &Vector6<f64> {
        &self.applied_tau
    }

    /// Replaces the state (e.g. a scenario reset).
    ///
    /// # Errors
    /// [`PlantError::NonFiniteInput`] if `state` is not finite (the state is then unchanged).
    pub fn set_state(&mut self, state: PlantState) -> Result<(), PlantError> {
        if !state.is_finite() {
            return Err(PlantError::NonFiniteInput("state"));
        }
        self.state = state;
        Ok(())
    }

    /// Saturates `tau` per axis to `±thrust_max`.
    #[must_use]
    pub fn saturate(&self, tau: &Vector6<f64>) -> Vector6<f64> {
        tau.zip_map(&self.thrust_max, |t, m| t.clamp(-m, m))
    }

    fn deriv(
        &self,
        p: &Vector3<f64>,
        q_raw: &Quaternion<f64>,
        nu: &Vector6<f64>,
        tau: &Vector6<f64>,
    ) -> Deriv {
        let q = UnitQuaternion::new_normalize(*q_raw);
        let v_c = q.inverse_transform_vector(&self.current.at(p));
        let omega: Vector3<f64> = nu.fixed_rows::<3>(3).into_owned();
        let nu_r = nu - Vector6::new(v_c.x, v_c.y, v_c.z, 0.0, 0.0, 0.0);
        let mut nu_dot = self.vehicle.nu_dot(&nu_r, &q, tau);
        let v: Vector3<f64> = nu.fixed_rows::<3>(0).into_owned();
        let p_dot = q.transform_vector(&v);
        // ν̇ = ν̇_r + ν̇_c, with ν̇_c = −ω × v_c for a current constant in NED, and
        // Rᵀ v̇_c more where it changes along the path.
        let mut c_dot = -omega.cross(&v_c);
        if !self.current.is_uniform() {
            c_dot += q.inverse_transform_vector(&self.current.rate_along(p, &p_dot));
        }
        nu_dot[0] += c_dot.x;
        nu_dot[1] += c_dot.y;
        nu_dot[2] += c_dot.z;
        Deriv {
            p: p_dot,
            q: q_raw * Quaternion::from_imag(omega) * 0.5,
            nu: nu_dot,
        }
    }

    /// One RK4 step of size `h` from `s`, with `tau` held constant. Renormalises the quaternion.
    fn rk4(&self, s: &PlantState, tau: &Vector6<f64>, h: f64) -> PlantState {
        let p0 = s.position_ned_m;
        let q0 = *s.attitude.quaternion();
        let n0 = s.nu;
        let k1 = self.deriv(&p0, &q0, &n0, tau);
        let k2 = self.deriv(
            &(p0 + k1.p * (h / 2.0)),
            &(q0 + k1.q * (h / 2.0)),
            &(n0 + k1.nu * (h / 2.0)),
            tau,
        );
        let k3 = self.deriv(
            &(p0 + k2.p * (h / 2.0)),
            &(q0 + k2.q * (h / 2.0)),
            &(n0 + k2.nu * (h / 2.0)),
            tau,
        );
        let k4 = self.deriv(&(p0 + k3.p * h), &(q0 + k3.q * h), &(n0 + k3.nu * h), tau);
        let w = h / 6.0;
        let p = p0 + (k1.p + (k2.p + k3.p) * 2.0 + k4.p) * w;
        let q = q0 + (k1.q + (k2.q + k3.q) * 2.0 + k4.q) * w;
        let nu = n0 + (k1.nu + (k2.nu + k3.nu) * 2.0 + k4.nu) * w;
        PlantState {
            position_ned_m: p,
            attitude: UnitQuaternion::new_normalize(q),
            nu,
        }
    }

    /// Advances the plant by `duration_s` with `tau` (saturated to `±thrust_max`) held
    /// constant, in `⌈duration_s / step_s⌉` equal RK4 substeps.
    ///
    /// # Errors
    /// [`PlantError::NonFiniteInput`] for a non-finite `tau` or `duration_s`,
    /// [`PlantError::InvalidInput`] for a negative or absurdly long `duration_s`,
    /// [`PlantError::NonFiniteState`] if integration blew up. On any error the state and
    /// [`Plant::applied_tau`] are left unchanged.
    pub fn advance(&mut self, tau: &Vector6<f64>, duration_s: f64) -> Result<(), PlantError> {
        if tau.iter().any(|x| !x.is_finite()) {
            return Err(PlantError::NonFiniteInput("tau"));
        }
        if !duration_s.is_finite() {
            return Err(PlantError::NonFiniteInput("duration_s"));
        }
        let ratio = duration_s / self.step_s;
        if !(0.0..=1.0e7).contains(&ratio) {
            return Err(PlantError::InvalidInput(format!(
                "duration_s must be in [0, 1e7·step_s], got {duration_s}"
            )));
        }
        let tau = self.saturate(tau);
        // Tolerate round-off such as 0.1 / 0.01 = 10.000000000000002.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (ratio - 1e-9).ceil().max(0.0) as usize;
        let mut s = self.state;
        if n > 0 {
            #[allow(clippy::cast_precision_loss)]
            let h = duration_s / n as f64;
            for _ in 0..n {
                s = self.rk4(&s, &tau, h);
                if !s.is_finite() {
                    return Err(PlantError::NonFiniteState);
                }
            }
        }
        self.state = s;
        self.applied_tau = tau;
        Ok(())
    }
}
