//! # mpc — the vehicle's predictive controller (paper §4.2, eqs. 14-18)
//!
//! A pure library: each control period the `mpc` process hands [`Mpc::step`] the vehicle's
//! own navigation (attitude from the AHRS, body velocity and rates) and the planner's
//! setpoint, and publishes the returned thrust `τ`. If the solver fails the process applies
//! [`Mpc::fallback`] instead (the previous input, decaying) and counts the failure. No clock
//! is read here: the process measures solve time around `step`.
//!
//! ```
//! use nalgebra::{UnitQuaternion, Vector3, Vector6};
//! use mpc::{Keepout, Mpc, MpcConfig, MpcInput, MpcTarget};
//! use sim_plant::{model::Vehicle, VehicleParams};
//!
//! let vehicle = Vehicle::new(&VehicleParams::default())?;
//! let mut mpc = Mpc::new(&MpcConfig::default(), &vehicle)?;
//! let input = MpcInput {
//!     attitude: UnitQuaternion::identity(),
//!     nu: Vector6::zeros(),
//!     // Be 5 m ahead and 1 m deeper, on a target moving ahead at 1 m/s, same heading.
//!     target: MpcTarget {
//!         position_m: Vector3::new(5.0, 0.0, 1.0),
//!         velocity_mps: Vector3::new(1.0, 0.0, 0.0),
//!         yaw_rel_rad: 0.0,
//!     },
//!     // nothing sensed nearby: the safety layer stays out of the way
//!     keepout: Keepout::default(),
//! };
//! let out = match mpc.step(&input) {
//!     Ok(out) => out.tau,
//!     Err(_) => mpc.fallback(),
//! };
//! assert!(out[0] > 0.0 && out[2] > 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## The setpoint contract (agreed with the planner)
//! The target is given in the vehicle's **level frame**: origin at the vehicle now, x along
//! the current heading projected on the horizontal, y to starboard, z down.
//! `position_m` is where the vehicle should be, `velocity_mps` how that target point moves
//! (the reference over the horizon is `target(t) = position_m + velocity_mps·t`), and
//! `yaw_rel_rad` the desired heading minus the current one. Only roll and pitch of the input
//! attitude matter: heading is zero in the level frame by construction.
//!
//! ## The problem solved each step
//! - **Model (15)**: `x_{k+1} = f(x_k, u_k)` with the 12-state model of [`prediction`], built
//!   on `sim_plant::model::Vehicle::nu_dot` (the plant's own code, not a copy), linearised
//!   about the current state and the previously applied input, and discretised exactly
//!   (zero-order hold) with step `step_s`: `z_{k+1} = A_d z_k + B_d v_k + c_d` in deviations
//!   `z = x − x₀`, `v = u − u_prev`. The output is the whole state (`H = I`): the AHRS, DVL
//!   and the level frame give all twelve.
//! - **Cost (18)**: `J = Σ_{j=1..P} e_jᵀ diag(ρ₁) e_j + Σ_{j=0..P−1} Δu_jᵀ diag(ρ₂) Δu_j`,
//!   `e_j = x_j − r_j`. The reference `r_j` is the target position `position_m +
//!   velocity_mps·j·step_s`, zero roll and pitch, yaw `yaw_rel_rad`, the target's velocity
//!   expressed in a level body at the desired heading, and zero rates. The paper's
//!   `Σ_{j=1..P}(u_{i+j} − u_{i+j−1})²` indexes one step past the horizon; we take the
//!   standard form that starts with `Δu_0 = u_i − u_{i−1}` (the move from the input applied
//!   last), which is what makes `ρ₂` smooth the applied thrust. `ρ₁` and `ρ₂` are per
//!   component (the paper's scalars times a unit scaling of each channel).
//! - **Terminal weight** (our addition): the error at the last step `j = P` is weighted
//!   `terminal_weight·ρ₁` (default 30). With P = 20 steps of 0.1 s the horizon (2 s) is much
//!   shorter than the vehicle's slowest mode (yaw, `(I_z + N_ṙ)/N_r ≈ 8 s`); with plain (18)
//!   the closed loop went unstable once `ρ₂` was raised 10× above the default, with
//!   `terminal_weight = 30` it stays stable up to at least 30× (measured with the
//!   closed-loop harness of `tests/closed_loop.rs`). `terminal_weight = 1` is eq. (18) as
//!   printed.
//! - **Constraints (17)**: `|u_{i+j}| ≤ thrust_max` per axis, for every input on the horizon.
//! - **Receding horizon**: only the first input is applied.
//!
//! ## Condensing and move blocking
//! The states are eliminated (`Z = S V + F`), leaving a dense QP in the inputs only, with
//! box constraints. To keep it small the inputs are **move-blocked**: the horizon of `P`
//! steps is split into `control_moves` = M blocks during each of which the input is held;
//! the blocks grow quadratically (block `k` ends at step `round(P·(k/M)²)`; for P = 20,
//! M = 5: lengths 1, 2, 4, 6, 7), so the near future is finely resolved and the far future
//! coarse. `Δu` is then non-zero only at block starts. The QP has `6·M` variables and
//! `12·M` inequalities, whatever `P` is. The decision variables are scaled by
//! `thrust_max` so that all are O(1).
//!
//! ## Solver
//! Clarabel 0.11 (default features) with presolve off, built once in [`Mpc::new`] with the
//! full upper-triangular pattern of the dense Hessian and the data of a nominal problem (its
//! equilibration is computed then, once); each step changes `P`, `q` and `b` in place
//! (`update_P`, `update_q`, `update_b`): no allocation in the solver per step. Clarabel has
//! no warm start. Tolerances are 1e-6 and iterative refinement is off (see
//! `build_solver`). `Solved` and `AlmostSolved` are accepted; any other status is
//! [`MpcError::Solver`]. Clarabel keeps its own internal timers; this crate reads no clock
//! and sets no time limit (the process measures the solve time).
//!
//! ## Unconstrained first
//! The QP is strictly convex (`ρ₂ > 0` makes the Hessian positive definite) and its only
//! constraints are the bounds. So each step first factorises the dense `6M × 6M` Hessian
//! (Cholesky, in place, no allocation) and solves for the unconstrained minimiser; if that
//! lies within every bound it is the QP's exact solution ([`MpcStatus::Unconstrained`],
//! zero iterations) and clarabel is not called. Only steps with an active bound go to
//! clarabel. On the library's closed loop 96 % of the steps take the shortcut (`cargo bench
//! -p mpc --bench mpc` prints the table); `unconstrained_first = false` calls clarabel on
//! every step.
//!
//! ## Fallback
//! [`Mpc::fallback`] multiplies the previously applied input by `fallback_decay` (per call)
//! and returns it: finite and within bounds by construction, decaying to zero.
#![forbid(unsafe_code)]

pub mod closed_loop;
pub mod node;
pub mod prediction;
pub mod safety;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{DMatrix, DVector, Matrix6, SMatrix, UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};
use sim_plant::model::Vehicle;

use prediction::{InputMat, StateVec, NU};
pub use safety::{Keepout, MAX_KEEPOUT};

/// Why the solver did not return a usable solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolverFailure {
    /// Constraints infeasible (cannot happen with box bounds unless data is broken).
    PrimalInfeasible,
    /// Objective unbounded (cannot happen with a positive-definite Hessian).
    DualInfeasible,
    /// `max_iter` reached.
    MaxIterations,
    /// Clarabel's own time limit (not set by us) reached.
    MaxTime,
    /// Numerical trouble in the factorisation.
    NumericalError,
    /// No progress.
    InsufficientProgress,
    /// Anything else (unsolved, callback).
    Other,
}

impl SolverFailure {
    fn from_status(s: SolverStatus) -> Self {
        match s {
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                Self::PrimalInfeasible
            }
            SolverStatus::DualInfeasible | SolverStatus::AlmostDualInfeasible => {
                Self::DualInfeasible
            }
            SolverStatus::MaxIterations => Self::MaxIterations,
            SolverStatus::MaxTime => Self::MaxTime,
            SolverStatus::NumericalError => Self::NumericalError,
            SolverStatus::InsufficientProgress => Self::InsufficientProgress,
            _ => Self::Other,
        }
    }

    /// Stable numeric code for `mpc_stats` (continues [`MpcStatus::code`]): 10 + variant.
    #[must_use]
    pub fn code(self) -> u8 {
        match self {
            Self::PrimalInfeasible => 10,
            Self::DualInfeasible => 11,
            Self::MaxIterations => 12,
            Self::MaxTime => 13,
            Self::NumericalError => 14,
            Self::InsufficientProgress => 15,
            Self::Other => 19,
        }
    }
}

/// Errors of the controller. On any of them the caller applies [`Mpc::fallback`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MpcError {
    /// A configuration value is out of range; the message names the key.
    #[error("invalid config: {0}")]
    InvalidConfig(String),
    /// An input (attitude, ν, target) is NaN or infinite; names which.
    #[error("non-finite input: {0}")]
    NonFiniteInput(&'static str),
    /// Pitch so close to ±90° that the Euler kinematics of the model are singular.
    #[error("pitch {pitch_rad} rad too close to ±90° for the Euler prediction model")]
    AttitudeSingular {
        /// Measured pitch, rad.
        pitch_rad: f64,
    },
    /// The QP solver failed.
    #[error("QP solver failed: {status:?} after {iterations} iterations")]
    Solver {
        /// What went wrong.
        status: SolverFailure,
        /// Iterations spent.
        iterations: u32,
    },
    /// Clarabel refused the problem data (should not happen; a bug).
    #[error("QP setup failed: {0}")]
    Setup(String),
    /// The solution was not finite (should not happen; a bug or broken data).
    #[error("QP solution not finite")]
    NonFiniteSolution,
}

/// Controller configuration (serde, every key optional).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MpcConfig {
    /// Prediction horizon `P`, steps. Default 20 (2 s). In [1, 200].
    pub horizon: usize,
    /// Prediction step = control period, s. Default 0.1. In (0, 10].
    pub step_s: f64,
    /// Number of input moves (blocks) over the horizon, `M`. Default 5. In [1, horizon].
    /// `control_moves = horizon` disables move blocking.
    pub control_moves: usize,
    /// Output-error weights `ρ₁` for `[x y z φ θ ψ u v w p q r]` (1/m², 1/rad², s²/m²,
    /// s²/rad²). Default [100, 100, 100, 300, 300, 300, 30, 30, 30, 10, 10, 10].
    pub rho1: [f64; 12],
    /// Input-move weights `ρ₂` for `Δ[X Y Z K M N]`, 1/N² and 1/(N·m)².
    /// Default [1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1].
    pub rho2: [f64; 6],
    /// Per-axis thrust bound, N ×3 and N·m ×3 (constraint 17). Default
    /// [500, 300, 300, 100, 200, 200] (the plant's default saturation).
    pub thrust_max: [f64; 6],
    /// Multiplier of `ρ₁` on the last step of the horizon (a terminal cost standing in for
    /// the tail beyond the horizon), ≥ 1 (1 = eq. 18 exactly). Default 30, see the crate docs.
    pub terminal_weight: f64,
    /// Factor applied to the held input at each [`Mpc::fallback`] call, in [0, 1).
    /// Default 0.8 (at 10 Hz: a tenth after ~1 s).
    pub fallback_decay: f64,
    /// Clarabel iteration limit. Default 50.
    pub max_iter: u32,
    /// Solve the unconstrained problem first (one Cholesky factorisation of the 6M × 6M
    /// Hessian) and take its minimiser when it lies within every bound: the QP is strictly
    /// convex, so a feasible unconstrained minimiser is its exact solution. Clarabel solves
    /// the steps where some bound is active. Default true; false always calls clarabel.
    pub unconstrained_first: bool,
    /// The safety layer ([`safety`]): keep every predicted position `d_min_m/2 +
    /// safety_margin_m` from the returns the planner hands over and `d_min_m +
    /// safety_margin_m` from the parent's estimate (default true).
    pub safety: bool,
    /// The safe distance `D_min`, m (default 2; `shoal run` sets it from `[safety]`).
    pub d_min_m: f64,
    /// Clearance kept beyond `D_min/2` from a return and `D_min` from the parent, m
    /// (default 0.25).
    pub safety_margin_m: f64,
    /// Cost of a clearance given up, per m and step (and 10× that per m²; default 1e5):
    /// far above the tracking errors planners make, so a clearance yields only when no
    /// input can keep it.
    pub slack_weight: f64,
}

impl Default for MpcConfig {
    fn default() -> Self {
        Self {
            horizon: 20,
            step_s: 0.1,
            control_moves: 5,
            rho1: [
                100.0, 100.0, 100.0, 300.0, 300.0, 300.0, 30.0, 30.0, 30.0, 10.0, 10.0, 10.0,
            ],
            rho2: [1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1],
            thrust_max: [500.0, 300.0, 300.0, 100.0, 200.0, 200.0],
            terminal_weight: 30.0,
            fallback_decay: 0.8,
            max_iter: 50,
            unconstrained_first: true,
            safety: true,
            d_min_m: 2.0,
            safety_margin_m: 0.25,
            slack_weight: 1e5,
        }
    }
}

fn bad(key: &str, rule: &str, got: impl std::fmt::Debug) -> MpcError {
    MpcError::InvalidConfig(format!("{key} must be {rule}, got {got:?}"))
}

impl MpcConfig {
    /// # Errors
    /// [`MpcError::InvalidConfig`] naming the first bad key.
    pub fn validate(&self) -> Result<(), MpcError> {
        if !(1..=200).contains(&self.horizon) {
            return Err(bad("horizon", "in [1, 200]", self.horizon));
        }
        if !(self.step_s.is_finite() && self.step_s > 0.0 && self.step_s <= 10.0) {
            return Err(bad("step_s", "in (0, 10]", self.step_s));
        }
        if !(1..=self.horizon).contains(&self.control_moves) {
            return Err(bad("control_moves", "in [1, horizon]", self.control_moves));
        }
        if !self.rho1.iter().all(|x| x.is_finite() && *x >= 0.0) {
            return Err(bad("rho1", "finite and >= 0", self.rho1));
        }
        if !self.rho2.iter().all(|x| x.is_finite() && *x > 0.0) {
            return Err(bad("rho2", "finite and > 0", self.rho2));
        }
        if !self.thrust_max.iter().all(|x| x.is_finite() && *x > 0.0) {
            return Err(bad("thrust_max", "finite and > 0", self.thrust_max));
        }
        if !(self.terminal_weight.is_finite() && self.terminal_weight >= 1.0) {
            return Err(bad(
                "terminal_weight",
                "finite and >= 1",
                self.terminal_weight,
            ));
        }
        if !(self.fallback_decay.is_finite() && (0.0..1.0).contains(&self.fallback_decay)) {
            return Err(bad("fallback_decay", "in [0, 1)", self.fallback_decay));
        }
        if self.max_iter == 0 {
            return Err(bad("max_iter", ">= 1", self.max_iter));
        }
        if !(self.d_min_m.is_finite() && self.d_min_m > 0.0) {
            return Err(bad("d_min_m", "finite and > 0", self.d_min_m));
        }
        if !(self.safety_margin_m.is_finite() && self.safety_margin_m >= 0.0) {
            return Err(bad(
                "safety_margin_m",
                "finite and >= 0",
                self.safety_margin_m,
            ));
        }
        if !(self.slack_weight.is_finite() && self.slack_weight > 0.0) {
            return Err(bad("slack_weight", "finite and > 0", self.slack_weight));
        }
        Ok(())
    }

    /// Lengths of the input blocks over the horizon (sum = `horizon`).
    #[must_use]
    pub fn block_lengths(&self) -> Vec<usize> {
        block_lengths(self.horizon, self.control_moves)
    }
}

/// Quadratically growing blocks: block `k` (1-based) ends at `round(P·(k/M)²)`, each at least
/// one step long.
fn block_lengths(p: usize, m: usize) -> Vec<usize> {
    let mut out = Vec::with_capacity(m);
    let mut prev = 0usize;
    for k in 1..=m {
        #[allow(clippy::cast_precision_loss)]
        let frac = (k as f64 / m as f64).powi(2);
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss
        )]
        let mut end = (p as f64 * frac).round() as usize;
        end = end.max(prev + 1).min(p - (m - k));
        out.push(end - prev);
        prev = end;
    }
    out
}

/// The setpoint, in the vehicle's level frame (see the crate docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MpcTarget {
    /// Where the vehicle should be now, level frame, m.
    pub position_m: Vector3<f64>,
    /// Velocity of the target point, level frame, m/s (feed-forward).
    pub velocity_mps: Vector3<f64>,
    /// Desired heading minus current heading, rad (wrapped to (−π, π] here).
    pub yaw_rel_rad: f64,
}

/// One control step's input: the vehicle's own navigation and the setpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcInput {
    /// AHRS attitude body→NED (only roll and pitch are used).
    pub attitude: UnitQuaternion<f64>,
    /// Body velocity `[u v w p q r]` (DVL + AHRS rates).
    pub nu: Vector6<f64>,
    /// The setpoint.
    pub target: MpcTarget,
    /// What the safety layer keeps clear of (level frame; empty: nothing).
    pub keepout: Keepout,
}

/// How the QP ended when it gave a usable answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MpcStatus {
    /// Solved to full accuracy.
    Solved,
    /// Solved to reduced accuracy (still applied).
    AlmostSolved,
    /// The unconstrained minimiser already satisfies every bound, so it is the QP's exact
    /// solution (see [`MpcConfig::unconstrained_first`]); clarabel was not called.
    Unconstrained,
    /// Solved with the safety layer's clearances in the QP (some clearance would otherwise
    /// have been entered, or a bound was active near something to keep clear of).
    Guarded,
}

impl MpcStatus {
    /// Stable numeric code for `mpc_stats`: 0 solved, 1 almost solved, 2 unconstrained,
    /// 3 guarded (failures: see [`SolverFailure::code`]).
    #[must_use]
    pub fn code(self) -> u8 {
        match self {
            Self::Solved => 0,
            Self::AlmostSolved => 1,
            Self::Unconstrained => 2,
            Self::Guarded => 3,
        }
    }
}

/// One control step's result.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MpcOutput {
    /// Thrust to apply `[X Y Z K M N]`, within `±thrust_max`, finite.
    pub tau: Vector6<f64>,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Solver status.
    pub status: MpcStatus,
    /// Value of the cost (18) at the solution, under the linearised model.
    pub cost: f64,
}

/// The predictive controller. Build once; call [`Mpc::step`] every control period.
pub struct Mpc {
    cfg: MpcConfig,
    vehicle: Vehicle,
    n_blocks: usize,
    umax: Vector6<f64>,
    u_prev: Vector6<f64>,
    rho1: StateVec,
    solver: DefaultSolver<f64>,
    /// First and one-past-last step of every block.
    block_start: Vec<usize>,
    block_end: Vec<usize>,
    // scratch, allocated once
    /// `Ψ_k = Σ_{l≤k} A_d^l B_d`, k = 0..P−1.
    psi: Vec<InputMat>,
    /// `S_jᵀ` blocks and `diag(ρ₁) S_j` blocks of the current prediction step.
    s_blk: Vec<InputRowMat>,
    ws_blk: Vec<InputMat>,
    /// Hessian blocks `H_bc` (row-major nb × nb; only b ≤ c used) and gradient blocks.
    hess: Vec<Matrix6<f64>>,
    grad: Vec<Vector6<f64>>,
    p_vals: Vec<f64>,
    q_vals: Vec<f64>,
    b_vals: Vec<f64>,
    /// The dense Hessian `P` for the unconstrained solve (factorised in place, kept across
    /// steps so that no step allocates) and its right-hand side / solution.
    dense: DMatrix<f64>,
    x_free: DVector<f64>,
    /// Whether `x_free` holds this step's unconstrained minimiser (the factorisation held).
    x_free_ok: bool,
    /// The safety layer (none when `safety` is off).
    safety: Option<safety::Safety>,
    /// For each step `j` of the horizon, its index among the safety layer's constrained
    /// steps.
    constrained: Vec<Option<usize>>,
    /// Scratch for the safety layer's solution.
    guarded_x: Vec<f64>,
}

impl std::fmt::Debug for Mpc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mpc")
            .field("cfg", &self.cfg)
            .field("n_blocks", &self.n_blocks)
            .field("u_prev", &self.u_prev)
            .finish_non_exhaustive()
    }
}

fn wrap_pi(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
    }
}

/// [`Mpc::assemble`], in copies compiled for the CPU's vector extensions, the best the CPU
/// has picked at run time.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn assemble_dispatched(mpc: &mut Mpc, input: &MpcInput) -> Result<f64, MpcError> {
    mpc.assemble_generic(input)
}

/// `S_jᵀ` of one block: 6 × 12.
type InputRowMat = SMatrix<f64, NU, { prediction::NX }>;

/// `h += sᵀ ws` given `st = sᵀ`: each entry summed exactly as nalgebra's `tr_mul` sums its
/// dot product of length 12 (eight partial products added in pairs, then the last four in
/// turn), but a whole column of `h` at once, so the six sums run side by side in vector
/// lanes instead of one horizontal reduction per entry.
#[inline(always)]
fn add_tr_mul(h: &mut Matrix6<f64>, st: &InputRowMat, ws: &InputMat) {
    for ci in 0..NU {
        let w = ws.column(ci);
        let p = |k: usize| st.column(k) * w[k];
        let mut r = (p(0) + p(4)) + (p(1) + p(5));
        r += p(2) + p(6);
        r += p(3) + p(7);
        for k in 8..prediction::NX {
            r += p(k);
        }
        let mut col = h.column_mut(ci);
        col += r;
    }
}

/// Iterations and status of a clarabel solve (`solved`: what a full-accuracy solution is
/// called), or the failure.
fn outcome(
    sol: &clarabel::solver::DefaultSolution<f64>,
    solved: MpcStatus,
) -> Result<(u32, MpcStatus), MpcError> {
    let status = match sol.status {
        SolverStatus::Solved => solved,
        SolverStatus::AlmostSolved => MpcStatus::AlmostSolved,
        other => {
            return Err(MpcError::Solver {
                status: SolverFailure::from_status(other),
                iterations: sol.iterations,
            })
        }
    };
    Ok((sol.iterations, status))
}

fn all_finite<'a>(it: impl IntoIterator<Item = &'a f64>) -> bool {
    it.into_iter().all(|x| x.is_finite())
}

impl Mpc {
    /// Builds the controller and its QP solver (once) for `vehicle`.
    ///
    /// # Errors
    /// [`MpcError::InvalidConfig`], or [`MpcError::Setup`] if clarabel refuses the problem.
    pub fn new(config: &MpcConfig, vehicle: &Vehicle) -> Result<Self, MpcError> {
        config.validate()?;
        let lengths = config.block_lengths();
        let n_blocks = lengths.len();
        let n = NU * n_blocks;
        let mut block_start = Vec::with_capacity(n_blocks);
        let mut block_end = Vec::with_capacity(n_blocks);
        let mut acc = 0;
        for &l in &lengths {
            block_start.push(acc);
            acc += l;
            block_end.push(acc);
        }

        // P: full upper triangle, column-major; A = [I; −I]; cone: 2n non-negatives.
        let mut colptr = Vec::with_capacity(n + 1);
        let mut rowval = Vec::with_capacity(n * (n + 1) / 2);
        colptr.push(0);
        for c in 0..n {
            rowval.extend(0..=c);
            colptr.push(rowval.len());
        }
        let nnz = rowval.len();
        let a_colptr: Vec<usize> = (0..=n).map(|c| 2 * c).collect();
        let a_rowval: Vec<usize> = (0..n).flat_map(|c| [c, n + c]).collect();
        let a_nzval: Vec<f64> = (0..n).flat_map(|_| [1.0, -1.0]).collect();
        let a_mat = CscMatrix::new(2 * n, n, a_colptr, a_rowval, a_nzval);

        let mut mpc = Self {
            cfg: config.clone(),
            vehicle: vehicle.clone(),
            n_blocks,
            umax: Vector6::from(config.thrust_max),
            u_prev: Vector6::zeros(),
            rho1: StateVec::from(config.rho1),
            // Placeholder replaced below once the nominal data exist.
            solver: Self::build_solver(
                config,
                &CscMatrix::new(n, n, colptr.clone(), rowval.clone(), vec![0.0; nnz]),
                &vec![0.0; n],
                &a_mat,
                &vec![1.0; 2 * n],
            )?,
            block_start,
            block_end,
            psi: vec![InputMat::zeros(); config.horizon],
            s_blk: vec![InputRowMat::zeros(); n_blocks],
            ws_blk: vec![InputMat::zeros(); n_blocks],
            hess: vec![Matrix6::zeros(); n_blocks * n_blocks],
            grad: vec![Vector6::zeros(); n_blocks],
            p_vals: vec![0.0; nnz],
            q_vals: vec![0.0; n],
            b_vals: vec![0.0; 2 * n],
            dense: DMatrix::zeros(n, n),
            x_free: DVector::zeros(n),
            x_free_ok: false,
            safety: None,
            constrained: vec![None; config.horizon + 1],
            guarded_x: Vec::with_capacity(n),
        };
        // Equilibration is computed once, at construction: build the solver on the data of
        // a representative problem (at rest, level, target 1 m ahead) so its scaling fits.
        let nominal = MpcInput {
            attitude: UnitQuaternion::identity(),
            nu: Vector6::zeros(),
            target: MpcTarget {
                position_m: Vector3::new(1.0, 0.0, 0.0),
                velocity_mps: Vector3::zeros(),
                yaw_rel_rad: 0.0,
            },
            keepout: Keepout::default(),
        };
        mpc.assemble(&nominal)?;
        if config.safety {
            let ends = mpc.block_end.clone();
            for (jj, &j) in ends.iter().enumerate() {
                mpc.constrained[j] = Some(jj);
            }
            mpc.safety = Some(safety::Safety::new(
                config,
                &ends,
                (&colptr, &rowval),
                safety::QpData {
                    p: &mpc.p_vals,
                    q: &mpc.q_vals,
                    b: &mpc.b_vals,
                },
                |p, q, a, b| Self::build_solver(config, p, q, a, b),
            )?);
        }
        let p_mat = CscMatrix::new(n, n, colptr, rowval, mpc.p_vals.clone());
        mpc.solver = Self::build_solver(config, &p_mat, &mpc.q_vals, &a_mat, &mpc.b_vals)?;
        Ok(mpc)
    }

    fn build_solver(
        config: &MpcConfig,
        p: &CscMatrix<f64>,
        q: &[f64],
        a: &CscMatrix<f64>,
        b: &[f64],
    ) -> Result<DefaultSolver<f64>, MpcError> {
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(config.max_iter)
            // The QP is small and scaled (variables in units of thrust_max): iterative
            // refinement of the KKT solves and 1e-8 tolerances cost ~30 % of the solve
            // time and change τ by < 1e-3 N.
            .iterative_refinement_enable(false)
            .tol_gap_abs(1e-6)
            .tol_gap_rel(1e-6)
            .tol_feas(1e-6)
            .tol_ktratio(1e-5)
            .build()
            .map_err(|e| MpcError::Setup(e.to_string()))?;
        let cones = [SupportedConeT::NonnegativeConeT(b.len())];
        DefaultSolver::new(p, q, a, b, &cones, settings).map_err(|e| MpcError::Setup(e.to_string()))
    }

    /// The configuration in use.
    #[must_use]
    pub fn config(&self) -> &MpcConfig {
        &self.cfg
    }

    /// The input applied last (by `step` or `fallback`).
    #[must_use]
    pub fn last_tau(&self) -> &Vector6<f64> {
        &self.u_prev
    }

    /// Forgets the previous input (e.g. after a reset of the vehicle).
    pub fn reset(&mut self) {
        self.u_prev = Vector6::zeros();
    }

    /// Linearises, condenses and fills `p_vals`, `q_vals`, `b_vals`. Returns the constant
    /// term of the cost.
    ///
    /// On a CPU with AVX2 the same code runs compiled for it: the Hessian's column sums and
    /// the series' products then take four lanes a step instead of two. The compiler does
    /// not reorder or fuse floating-point operations for it, so the numbers are the same
    /// bit for bit (a test compares both paths).
    fn assemble(&mut self, input: &MpcInput) -> Result<f64, MpcError> {
        assemble_dispatched(self, input)
    }

    #[inline(always)]
    fn assemble_generic(&mut self, input: &MpcInput) -> Result<f64, MpcError> {
        let (roll, pitch, _) = input.attitude.euler_angles();
        if pitch.cos().abs() < prediction::MIN_COS_PITCH {
            return Err(MpcError::AttitudeSingular { pitch_rad: pitch });
        }
        let mut x0 = StateVec::zeros();
        x0[3] = roll;
        x0[4] = pitch;
        x0.fixed_rows_mut::<6>(6).copy_from(&input.nu);
        let (ac, bc, f0) = prediction::jacobians(&self.vehicle, &x0, &self.u_prev);
        let h = self.cfg.step_s;
        let (ad, bd, cd) = prediction::discretise(&ac, &bc, &f0, h);

        let tgt = &input.target;
        let yaw_ref = wrap_pi(tgt.yaw_rel_rad);
        let (sy, cy) = yaw_ref.sin_cos();
        // Target velocity in a level body at the desired heading.
        let v = tgt.velocity_mps;
        let v_body = Vector3::new(cy * v.x + sy * v.y, -sy * v.x + cy * v.y, v.z);

        // Ψ_k = Σ_{l=0..k} A_d^l B_d.
        let horizon = self.cfg.horizon;
        let mut phi = bd;
        let mut sum = InputMat::zeros();
        for k in 0..horizon {
            sum += phi;
            self.psi[k] = sum;
            if k + 1 < horizon {
                phi = prediction::advance(&ad, &phi);
            }
        }
        for blk in &mut self.hess {
            blk.fill(0.0);
        }
        for g in &mut self.grad {
            g.fill(0.0);
        }
        let nb = self.n_blocks;
        let mut free = StateVec::zeros(); // F_j: response to the affine term alone
        let mut constant = 0.0;
        for j in 1..=horizon {
            free = ad * free + cd;
            // the safety layer's constrained steps keep their position rows (copies only:
            // nothing below changes)
            // (`constrained` is empty without the layer)
            let guard_step = self.constrained[j];
            if let (Some(jj), Some(s)) = (guard_step, self.safety.as_mut()) {
                s.free_pos[jj] = free.fixed_rows::<3>(0).into_owned();
                for g in &mut s.sens[jj * nb..(jj + 1) * nb] {
                    g.fill(0.0);
                }
            }
            #[allow(clippy::cast_precision_loss)]
            let t = j as f64 * h;
            let p_ref = tgt.position_m + tgt.velocity_mps * t;
            let mut r = StateVec::zeros();
            r[0] = p_ref.x;
            r[1] = p_ref.y;
            r[2] = p_ref.z;
            r[5] = yaw_ref;
            r[6] = v_body.x;
            r[7] = v_body.y;
            r[8] = v_body.z;
            let e0 = x0 + free - r;
            let w = if j == horizon {
                self.rho1 * self.cfg.terminal_weight
            } else {
                self.rho1
            };
            let we0 = w.component_mul(&e0);
            constant += e0.dot(&we0);
            // z_j = Σ_b S_j^b v_b + F_j, with S_j^b = Σ_{i in block b, i<j} A_d^{j−1−i} B_d
            //     = Ψ_{j−1−start_b} − Ψ_{j−1−end_b} (the latter only if the block ended).
            // Blocks that start at or after step j do not act yet.
            let active = self.block_start.iter().take_while(|&&s0| s0 < j).count();
            for b in 0..active {
                let mut sb = self.psi[j - 1 - self.block_start[b]];
                if self.block_end[b] < j {
                    sb -= self.psi[j - 1 - self.block_end[b]];
                }
                let mut wsb = sb;
                for (row, wr) in w.iter().enumerate() {
                    for c in 0..NU {
                        wsb[(row, c)] *= *wr;
                    }
                }
                self.grad[b] += sb.tr_mul(&we0);
                self.s_blk[b] = sb.transpose();
                self.ws_blk[b] = wsb;
                if let (Some(jj), Some(s)) = (guard_step, self.safety.as_mut()) {
                    s.sens[jj * nb + b] = sb.fixed_rows::<3>(0).into_owned();
                }
            }
            for b in 0..active {
                for c in b..active {
                    add_tr_mul(&mut self.hess[b * nb + c], &self.s_blk[b], &self.ws_blk[c]);
                }
            }
        }
        // Δu penalty: Σ_b (v_b − v_{b−1})ᵀ diag(ρ₂) (v_b − v_{b−1}), v_{−1} = 0.
        let rho2 = Matrix6::from_diagonal(&Vector6::from(self.cfg.rho2));
        for b in 0..nb {
            // Term b: (v_b − v_{b−1})ᵀ ρ₂ (v_b − v_{b−1}).
            self.hess[b * nb + b] += rho2;
            if b > 0 {
                self.hess[(b - 1) * nb + b - 1] += rho2;
                self.hess[(b - 1) * nb + b] -= rho2;
            }
        }
        // Scale to v̂ = v / thrust_max and write clarabel's data: P = 2 Ĥ, q = 2 ĝ.
        let n = NU * self.n_blocks;
        let mut k = 0;
        for c in 0..n {
            let (cb, ci) = (c / NU, c % NU);
            let sc = self.umax[ci];
            for r in 0..=c {
                let (rb, ri) = (r / NU, r % NU);
                // Upper triangle: rb ≤ cb; within a diagonal block use the (ri ≤ ci) entry.
                let hv = self.hess[rb * nb + cb][(ri, ci)];
                self.p_vals[k] = 2.0 * self.umax[ri] * sc * hv;
                k += 1;
            }
            self.q_vals[c] = 2.0 * sc * self.grad[cb][ci];
        }
        for c in 0..n {
            let up = self.u_prev[c % NU] / self.umax[c % NU];
            self.b_vals[c] = 1.0 - up;
            self.b_vals[n + c] = 1.0 + up;
        }
        if !(all_finite(&self.p_vals) && all_finite(&self.q_vals) && constant.is_finite()) {
            return Err(MpcError::NonFiniteSolution);
        }
        Ok(constant)
    }

    /// One control step: linearise at the measured state, solve the QP, apply the first
    /// input. The returned `tau` is finite and within `±thrust_max`.
    ///
    /// # Errors
    /// [`MpcError::NonFiniteInput`], [`MpcError::AttitudeSingular`], [`MpcError::Solver`],
    /// [`MpcError::NonFiniteSolution`]. On error nothing changes; apply [`Mpc::fallback`].
    pub fn step(&mut self, input: &MpcInput) -> Result<MpcOutput, MpcError> {
        if !all_finite(input.attitude.coords.iter()) {
            return Err(MpcError::NonFiniteInput("attitude"));
        }
        if !all_finite(input.nu.iter()) {
            return Err(MpcError::NonFiniteInput("nu"));
        }
        let t = &input.target;
        if !(all_finite(t.position_m.iter())
            && all_finite(t.velocity_mps.iter())
            && t.yaw_rel_rad.is_finite())
        {
            return Err(MpcError::NonFiniteInput("target"));
        }
        // the safety layer takes part only when there is something to keep clear of; the
        // reference then stops short of what it would run into
        let guard = match self.safety.as_mut() {
            Some(s) => s.load(&input.keepout),
            None => false,
        };
        let held;
        let input = match self.safety.as_ref().filter(|_| guard) {
            Some(s) => {
                let horizon_s = self.cfg.step_s * self.cfg.horizon as f64;
                held = MpcInput {
                    target: s.hold_short(&input.target, horizon_s),
                    ..*input
                };
                &held
            }
            None => input,
        };
        let constant = self.assemble(input)?;
        self.x_free_ok = false;
        let (h, umax) = (self.cfg.step_s, self.umax);
        let within_bounds = self.cfg.unconstrained_first && self.solve_unconstrained();
        // whether the unconstrained path keeps every clearance (checked once)
        let free_clear = !guard
            || (self.x_free_ok
                && self
                    .safety
                    .as_mut()
                    .is_some_and(|s| s.keeps_clear(self.x_free.as_slice(), h, &umax)));
        if within_bounds && free_clear {
            let x = std::mem::replace(&mut self.x_free, DVector::zeros(0));
            let out = self.finish(x.as_slice(), constant, 0, MpcStatus::Unconstrained);
            self.x_free = x;
            return out;
        }
        // Bounds alone next (clarabel on the small QP) unless the unconstrained path
        // already runs into something; its answer stands when it keeps every clearance.
        if free_clear {
            let (iterations, status) = self.solve_bounds()?;
            let x = std::mem::take(&mut self.solver.solution.x);
            let clear = !guard
                || self
                    .safety
                    .as_mut()
                    .is_some_and(|s| s.keeps_clear(&x, h, &umax));
            let out = clear.then(|| self.finish(&x, constant, iterations, status));
            self.solver.solution.x = x;
            if let Some(out) = out {
                return out;
            }
        }
        // only a guarded step gets here (without points the bounds-only answer stood)
        let Some(s) = self.safety.as_mut() else {
            return Err(MpcError::Setup("no safety layer for a guarded step".into()));
        };
        let lin = self.x_free_ok.then_some(self.x_free.as_slice());
        let mut x = std::mem::take(&mut self.guarded_x);
        let qp = safety::QpData {
            p: &self.p_vals,
            q: &self.q_vals,
            b: &self.b_vals,
        };
        let solved = s.solve(qp, lin, h, &umax, &mut x);
        let out =
            solved.and_then(|(iterations, status)| self.finish(&x, constant, iterations, status));
        self.guarded_x = x;
        out
    }

    /// Clarabel on the QP with its bounds only; the solution stays in `solver.solution.x`.
    fn solve_bounds(&mut self) -> Result<(u32, MpcStatus), MpcError> {
        let setup = |e: clarabel::solver::DataUpdateError| MpcError::Setup(e.to_string());
        self.solver.update_P(&self.p_vals).map_err(setup)?;
        self.solver.update_q(&self.q_vals).map_err(setup)?;
        self.solver.update_b(&self.b_vals).map_err(setup)?;
        self.solver.solve();
        outcome(&self.solver.solution, MpcStatus::Solved)
    }

    /// The minimiser of `½v̂ᵀPv̂ + qᵀv̂` into `x_free` (Cholesky of `P`, in place); true when
    /// it satisfies every bound `A v̂ ≤ b`, i.e. when it is the QP's solution.
    fn solve_unconstrained(&mut self) -> bool {
        let n = self.q_vals.len();
        let mut dense = std::mem::replace(&mut self.dense, DMatrix::zeros(0, 0));
        let mut k = 0;
        for c in 0..n {
            for r in 0..=c {
                dense[(r, c)] = self.p_vals[k];
                dense[(c, r)] = self.p_vals[k];
                k += 1;
            }
        }
        for (x, q) in self.x_free.iter_mut().zip(&self.q_vals) {
            *x = -q;
        }
        let feasible = match nalgebra::linalg::Cholesky::new(dense) {
            Some(chol) => {
                chol.solve_mut(&mut self.x_free);
                self.dense = chol.unpack();
                self.x_free_ok = self.x_free.iter().all(|x| x.is_finite());
                self.x_free
                    .iter()
                    .enumerate()
                    .all(|(c, &x)| x.is_finite() && x <= self.b_vals[c] && -x <= self.b_vals[n + c])
            }
            None => {
                // Not positive definite to working precision: leave it to clarabel.
                self.dense = DMatrix::zeros(n, n);
                false
            }
        };
        feasible
    }

    /// Cost, applied input and the new previous input from the scaled solution `x`.
    fn finish(
        &mut self,
        x: &[f64],
        constant: f64,
        iterations: u32,
        status: MpcStatus,
    ) -> Result<MpcOutput, MpcError> {
        if !all_finite(x) {
            return Err(MpcError::NonFiniteSolution);
        }
        let sol_x = x;
        // Cost (18) at the solution: v̂ᵀĤv̂ + 2ĝᵀv̂ + const = ½v̂ᵀPv̂ + qᵀv̂ + const.
        let n = NU * self.n_blocks;
        let mut cost = constant;
        let mut k = 0;
        for c in 0..n {
            for r in 0..=c {
                let w = if r == c { 0.5 } else { 1.0 };
                cost += w * self.p_vals[k] * sol_x[r] * sol_x[c];
                k += 1;
            }
            cost += self.q_vals[c] * sol_x[c];
        }
        let mut tau = Vector6::zeros();
        for c in 0..NU {
            let u = self.u_prev[c] + self.umax[c] * sol_x[c];
            tau[c] = u.clamp(-self.umax[c], self.umax[c]);
        }
        if !all_finite(tau.iter()) {
            return Err(MpcError::NonFiniteSolution);
        }
        self.u_prev = tau;
        Ok(MpcOutput {
            tau,
            iterations,
            status,
            cost,
        })
    }

    /// Safe fallback after a failed [`Mpc::step`]: the previously applied input times
    /// `fallback_decay`, which becomes the new "previous input". Always finite and in bounds.
    pub fn fallback(&mut self) -> Vector6<f64> {
        let d = self.cfg.fallback_decay;
        for c in 0..NU {
            let u = self.u_prev[c] * d;
            self.u_prev[c] = if u.is_finite() {
                u.clamp(-self.umax[c], self.umax[c])
            } else {
                0.0
            };
        }
        self.u_prev
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use sim_plant::VehicleParams;

    #[test]
    fn blocks_grow_quadratically_and_cover_the_horizon() {
        assert_eq!(block_lengths(20, 5), vec![1, 2, 4, 6, 7]);
        assert_eq!(block_lengths(7, 3), vec![1, 2, 4]);
        assert_eq!(block_lengths(5, 5), vec![1, 1, 1, 1, 1]);
        assert_eq!(block_lengths(10, 1), vec![10]);
        for p in 1..40 {
            for m in 1..=p {
                let l = block_lengths(p, m);
                assert_eq!(l.len(), m);
                assert_eq!(l.iter().sum::<usize>(), p);
                assert!(l.iter().all(|&x| x >= 1));
            }
        }
    }

    #[test]
    fn wrap_pi_maps_into_half_open_interval() {
        assert_relative_eq!(wrap_pi(3.0 * std::f64::consts::PI), std::f64::consts::PI);
        assert_relative_eq!(wrap_pi(-std::f64::consts::PI), std::f64::consts::PI);
        assert_relative_eq!(wrap_pi(0.5), 0.5);
        assert_relative_eq!(wrap_pi(-7.0), -7.0 + std::f64::consts::TAU);
    }

    /// The condensed QP (P, q, constant) evaluates to exactly the cost (18) of the blocked
    /// input sequence simulated through the discrete linear model step by step.
    #[test]
    fn condensed_cost_equals_cost_of_simulated_prediction() {
        let vehicle = Vehicle::new(&VehicleParams::default()).unwrap();
        let cfg = MpcConfig {
            horizon: 7,
            control_moves: 3,
            terminal_weight: 4.0,
            ..MpcConfig::default()
        };
        let mut mpc = Mpc::new(&cfg, &vehicle).unwrap();
        mpc.u_prev = Vector6::new(120.0, -20.0, 30.0, 2.0, -5.0, 8.0);
        let input = MpcInput {
            attitude: UnitQuaternion::from_euler_angles(0.1, -0.15, 0.7),
            nu: Vector6::new(1.1, 0.2, -0.1, 0.03, -0.02, 0.05),
            target: MpcTarget {
                position_m: Vector3::new(4.0, -1.5, 0.7),
                velocity_mps: Vector3::new(0.9, 0.3, -0.1),
                yaw_rel_rad: 0.4,
            },
            keepout: Keepout::default(),
        };
        let constant = mpc.assemble(&input).unwrap();
        let n = NU * mpc.n_blocks;
        let vhat: Vec<f64> = (0..n).map(|i| 0.3 * ((i as f64) * 1.7).sin()).collect();
        let mut quad = constant;
        let mut k = 0;
        for c in 0..n {
            for r in 0..=c {
                let w = if r == c { 0.5 } else { 1.0 };
                quad += w * mpc.p_vals[k] * vhat[r] * vhat[c];
                k += 1;
            }
            quad += mpc.q_vals[c] * vhat[c];
        }

        // Explicit simulation.
        let (roll, pitch, _) = input.attitude.euler_angles();
        let mut x0 = StateVec::zeros();
        x0[3] = roll;
        x0[4] = pitch;
        x0.fixed_rows_mut::<6>(6).copy_from(&input.nu);
        let (a, b, f0) = prediction::jacobians(&vehicle, &x0, &mpc.u_prev);
        let (ad, bd, cd) = prediction::discretise(&a, &b, &f0, cfg.step_s);
        let umax = Vector6::from(cfg.thrust_max);
        let v_of = |blk: usize| Vector6::from_fn(|i, _| umax[i] * vhat[NU * blk + i]);
        let rho1 = StateVec::from(cfg.rho1);
        let mut z = StateVec::zeros();
        let mut cost = 0.0;
        let lengths = cfg.block_lengths();
        let steps: Vec<usize> = lengths
            .iter()
            .enumerate()
            .flat_map(|(b, &l)| std::iter::repeat_n(b, l))
            .collect();
        for (j, &blk) in steps.iter().enumerate() {
            z = ad * z + bd * v_of(blk) + cd;
            let t = (j + 1) as f64 * cfg.step_s;
            let p = input.target.position_m + input.target.velocity_mps * t;
            let (s, c) = input.target.yaw_rel_rad.sin_cos();
            let v = input.target.velocity_mps;
            let r = StateVec::from_column_slice(&[
                p.x,
                p.y,
                p.z,
                0.0,
                0.0,
                input.target.yaw_rel_rad,
                c * v.x + s * v.y,
                -s * v.x + c * v.y,
                v.z,
                0.0,
                0.0,
                0.0,
            ]);
            let e = x0 + z - r;
            let wt = if j + 1 == cfg.horizon {
                cfg.terminal_weight
            } else {
                1.0
            };
            cost += wt * e.component_mul(&rho1).dot(&e);
        }
        let rho2 = Vector6::from(cfg.rho2);
        let mut prev = Vector6::zeros();
        for blk in 0..lengths.len() {
            let d = v_of(blk) - prev;
            cost += d.component_mul(&rho2).dot(&d);
            prev = v_of(blk);
        }
        assert_relative_eq!(quad, cost, max_relative = 1e-10);
    }

    #[test]
    fn validate_names_the_bad_key() {
        let bad_cfgs = [
            (
                MpcConfig {
                    horizon: 0,
                    ..MpcConfig::default()
                },
                "horizon",
            ),
            (
                MpcConfig {
                    control_moves: 21,
                    ..MpcConfig::default()
                },
                "control_moves",
            ),
            (
                MpcConfig {
                    step_s: -0.1,
                    ..MpcConfig::default()
                },
                "step_s",
            ),
            (
                MpcConfig {
                    rho2: [0.0; 6],
                    ..MpcConfig::default()
                },
                "rho2",
            ),
            (
                MpcConfig {
                    fallback_decay: 1.0,
                    ..MpcConfig::default()
                },
                "fallback_decay",
            ),
            (
                MpcConfig {
                    terminal_weight: 0.5,
                    ..MpcConfig::default()
                },
                "terminal_weight",
            ),
        ];
        for (c, key) in bad_cfgs {
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(key), "{e}");
        }
        assert!(MpcConfig::default().validate().is_ok());
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(64))]
        /// The QP data from the copy of `assemble` the CPU runs (on x86-64 with AVX2, the
        /// one compiled for it) equal, bit for bit, those of the portable code.
        #[test]
        fn every_copy_of_assemble_gives_the_same_qp(
            roll in -0.3f64..0.3, pitch in -0.3f64..0.3, yaw in -3.0f64..3.0,
            nu in proptest::array::uniform6(-1.5f64..1.5),
            x in -20.0f64..20.0, y in -10.0f64..10.0, z in -3.0f64..3.0,
            vx in -2.0f64..2.0, vy in -1.0f64..1.0, yaw_ref in -3.0f64..3.0,
            prev in -0.9f64..0.9,
        ) {
            let vehicle = Vehicle::new(&VehicleParams::default()).unwrap();
            let input = MpcInput {
                attitude: UnitQuaternion::from_euler_angles(roll, pitch, yaw),
                nu: Vector6::from(nu),
                target: MpcTarget {
                    position_m: Vector3::new(x, y, z),
                    velocity_mps: Vector3::new(vx, vy, 0.0),
                    yaw_rel_rad: yaw_ref,
                },
                keepout: Keepout::default(),
            };
            let cfg = MpcConfig::default();
            let mut run = Mpc::new(&cfg, &vehicle).unwrap();
            let mut portable = Mpc::new(&cfg, &vehicle).unwrap();
            let u_prev = Vector6::from(cfg.thrust_max) * prev;
            run.u_prev = u_prev;
            portable.u_prev = u_prev;
            let a = run.assemble(&input).unwrap();
            let b = portable.assemble_generic(&input).unwrap();
            proptest::prop_assert_eq!(a.to_bits(), b.to_bits());
            proptest::prop_assert_eq!(&run.p_vals, &portable.p_vals);
            proptest::prop_assert_eq!(&run.q_vals, &portable.q_vals);
            proptest::prop_assert_eq!(&run.b_vals, &portable.b_vals);
        }
    }

    proptest::proptest! {
        /// The column-at-a-time Hessian update gives bit for bit what nalgebra's `tr_mul`
        /// gives.
        #[test]
        fn add_tr_mul_equals_nalgebras_tr_mul(
            s in proptest::collection::vec(-1e3f64..1e3, 72),
            w in proptest::collection::vec(-1e3f64..1e3, 72),
            h0 in proptest::collection::vec(-1e3f64..1e3, 36),
        ) {
            let s = InputMat::from_column_slice(&s);
            let ws = InputMat::from_column_slice(&w);
            let mut h = Matrix6::from_column_slice(&h0);
            let want = h + s.tr_mul(&ws);
            add_tr_mul(&mut h, &s.transpose(), &ws);
            proptest::prop_assert_eq!(h, want);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(64))]
        /// Whatever the state and setpoint, the unconstrained-first path returns what
        /// clarabel alone returns (to the solver's tolerance), and it takes the shortcut
        /// only when its input is within every bound.
        #[test]
        fn unconstrained_first_returns_what_clarabel_returns(
            roll in -0.3f64..0.3, pitch in -0.3f64..0.3,
            u in -0.5f64..2.0, v in -0.5f64..0.5, r in -0.2f64..0.2,
            x in -20.0f64..20.0, y in -10.0f64..10.0, z in -3.0f64..3.0,
            yaw in -1.0f64..1.0, prev in -0.5f64..0.5,
        ) {
            let vehicle = Vehicle::new(&VehicleParams::default()).unwrap();
            let input = MpcInput {
                attitude: UnitQuaternion::from_euler_angles(roll, pitch, 0.0),
                nu: Vector6::new(u, v, 0.0, 0.0, 0.0, r),
                target: MpcTarget {
                    position_m: Vector3::new(x, y, z),
                    velocity_mps: Vector3::new(1.0, 0.0, 0.0),
                    yaw_rel_rad: yaw,
                },
                keepout: Keepout::default(),
            };
            let cfg = MpcConfig::default();
            let mut fast = Mpc::new(&cfg, &vehicle).unwrap();
            let mut slow = Mpc::new(&MpcConfig { unconstrained_first: false, ..cfg.clone() }, &vehicle).unwrap();
            let u_prev = Vector6::from(cfg.thrust_max) * prev;
            fast.u_prev = u_prev;
            slow.u_prev = u_prev;
            let a = fast.step(&input).unwrap();
            let b = slow.step(&input).unwrap();
            proptest::prop_assert_ne!(b.status, MpcStatus::Unconstrained);
            for c in 0..NU {
                let tol = 1e-4 * cfg.thrust_max[c];
                proptest::prop_assert!((a.tau[c] - b.tau[c]).abs() <= tol,
                    "axis {}: {} vs {} ({:?})", c, a.tau[c], b.tau[c], a.status);
                if a.status == MpcStatus::Unconstrained {
                    proptest::prop_assert!(a.tau[c].abs() <= cfg.thrust_max[c]);
                }
            }
        }
    }
}
