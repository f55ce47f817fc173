#!/usr/bin/env python3
"""The paper's FOLLOWER planner in one readable file, to run in place of a follower's Rust
planner process (services/planner, `FollowerPlanner`) on scenarios/paper.toml.

Paper: Filaretov, Yukhimets, Seledets, Yuan, "Method of Visual Formation Control for Large
Group of AUV in Environment with Obstacles" (/work/shared/paper/visual-formation-control-auv.md).

What a follower does every planner step (at the time of its nav sample):

* Own odometry: dead reckoning from the DVL velocity rotated by the AHRS attitude
  (horizontal), depth from the pressure sensor (vertical). This "odometry frame" has
  NED-aligned axes and an arbitrary origin; the follower never knows its absolute position.
* Vision fix (eqs. 1-3, solved upstream by camera-pose): the parent's position and attitude in
  the follower's body frame at the image time. Placed in the odometry frame with the
  follower's own pose *at the image time* (kept in a short history), then fused by the
  observer of fig. 4: a constant-velocity Kalman filter of the parent's position/velocity
  and heading/turn rate (the Rust `ParentObserver` with `coordinated_turn = false`).
* Obstacle memory: every sonar return is placed in the odometry frame and remembered until
  it is `memory_behind_m` behind the follower (or `memory_max_age_s` old).
* Eq. (6): each remembered return in the parent's frame (parent position and heading from
  the observer); only its lateral coordinate y~_dj is used.
* Eq. (7): delta_j = S(y~_dj) (y~_dj - y~_F), S = +1 if y~_dj >= 0 else -1; X_dc = argmin.
* Eq. (8), corrected (the printed x~ line is identically zero; substituting y~* into eqs. 4
  and 5 gives the consistent form, as services/planner/src/shift.rs derives):
      y~*  = y~_dc - sign(y~_dc) D_min  if min delta_j < D_min, else y~_F,
             clamped between y~_F and 0 (never across the parent's track)
      lam  = (y~_F - y~*) / y~_F                       (0 at the slot, 1 on the track)
      x~*  = x~_F + s D_a/2 * lam    (eq. 4; s = +1 for a port slot, -1 starboard)
      z~*  = z~_F + D_b/2 * lam      (eq. 5; D_b signed, + = down)
* Eq. (9): X^*(k) = X^*(k-1) + beta (X~*(k) - X^*(k-1)), once per step.
* Target: parent position + R(psi_parent) X^*, its velocity (parent velocity + the arm
  turning with the parent's turn rate + the slot's own motion) as feed-forward, and the
  parent's heading.

Frames (ours vs the paper): body and parent frames are FRD (x forward, y starboard, z down);
the paper draws y~ to the left, so its "+" sign of D_a (follower left of x~) is our port
slot, y~_F < 0. Eq. (7) is unchanged by mirroring y~.

Setpoint contract (services/mpc/src/lib.rs "The setpoint contract", planner types.rs
`Target`): everything in the vehicle's LEVEL frame at the nav sample's instant: origin at the
vehicle, x along its current heading projected on the horizontal, y to starboard
(horizontal), z down. `position_m` = where to be (relative to the vehicle, m);
`velocity_mps` = how that target point moves over ground, expressed in level-frame axes
(the MPC reference is position_m + velocity_mps * t); `yaw_rel_rad` = desired heading minus
current heading, wrapped to (-pi, pi]. Roll and pitch play no part.

Lost parent (not in the paper; the Rust follower's defined behaviour, kept because it
decides what happens at start and when the parent leaves the image): the estimate is stale
`stale_after_s` after the last fused fix -> Coasting (the last target carried on while
slowing linearly to a stop over `coast_s`) -> ParentLost (hold that point and depth, facing
the parent's last estimated position). At start the follower is ParentLost (holding where it
is) until `reacquire_count` consecutive fixes were fused.

Left out versus the Rust follower (all of them off, or at their default 0, when the Rust
node runs the paper's method, `[method] generalised = false`; see follower_config in
services/planner/src/node.rs): keep-in-view heading (view_margin_deg), keep_clear, the
slot trail, the coordinated-turn observer, memory cells (memory_cell_m: here every return is
its own point, oldest dropped at 128), the post-loss search (search_s), the time headways
(headway_s, yaw_headway_s: default 0) and predict_s (default 0). Setting any of the last
three to non-zero in the scenario only draws a warning here.
"""

from __future__ import annotations

import math
import sys
from collections import deque
from dataclasses import dataclass, field
from typing import Iterable, Optional, Sequence

import numpy as np

# ---------------------------------------------------------------------------------------
# Constants (as in services/planner and ipc-types)
# ---------------------------------------------------------------------------------------

# Mode values, sent as u32 on setpoint and planner_state (services/planner/src/types.rs).
TRACKING, AVOIDING, COASTING, PARENT_LOST = 0, 1, 2, 3
MODE_NAMES = {TRACKING: "Tracking", AVOIDING: "Avoiding", COASTING: "Coasting", PARENT_LOST: "ParentLost"}

MEMORY_CAPACITY = 128  # remembered obstacle points (follower.rs)
HISTORY_CAPACITY = 64  # own poses kept to place late vision fixes (follower.rs)
LOOK_MIN_RANGE_M = 1.0  # ParentLost: face the parent only if farther than this (follower.rs)
INITIAL_SPEED_STD_MPS = 1.0  # observer velocity 1-sigma after a (re)start (follower.rs)
RETURNING_TOL_M = 0.05  # filtered slot this far from nominal still counts as Avoiding
MAX_BEAMS = 16  # ipc_types::MAX_BEAMS
MAX_KEEPOUT = 8  # ipc_types::MAX_KEEPOUT
KEEPOUT_RANGE_M = 8.0  # planner keepout.rs RANGE_M
KEEPOUT_SPACING_M = 1.5  # planner keepout.rs SPACING_M

# PlannerState.waypoint_distance_m for a follower. NOTE: the Rust node publishes 0.0 for
# followers (PlannerState::waypoint_distance_m = 0 there); -1 marks "not applicable".
FOLLOWER_WAYPOINT_DISTANCE_M = -1.0

# The [follower] keys this file uses, with the Rust defaults (FollowerConfig::default()).
DEFAULTS = {
    "beta": 0.1,
    "sonar_mount_body_m": [0.8, 0.0, 0.0],
    "parent_echo_radius_m": 1.5,
    "memory_behind_m": 3.0,
    "memory_max_age_s": 60.0,
    "stale_after_s": 0.5,
    "coast_s": 4.0,
    "reacquire_count": 3,
    "accel_noise_mps2": 0.1,
    "yaw_accel_noise_radps2": 0.02,
    "pose_noise_min_m": 0.05,
    "yaw_noise_min_rad": 0.02,
    "pose_noise_default_m": 0.3,
    "gate_chi2": 16.27,
    "max_rejections": 3,
}
# Keys that only drive shoal's extras: ignored here, with a warning when they would change
# what the Rust follower does in the paper's method.
IGNORED_UNLESS_ZERO = ("headway_s", "yaw_headway_s", "predict_s")


# ---------------------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------------------

TAU = 2.0 * math.pi
EZ = np.array([0.0, 0.0, 1.0])


def wrap(a: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    x = a % TAU
    return x - TAU if x > math.pi else x


def quat_to_rot(q_wxyz: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a (normalised) quaternion [w, x, y, z]."""
    w, x, y, z = np.asarray(q_wxyz, dtype=float) / np.linalg.norm(q_wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def yaw_of(r: np.ndarray) -> float:
    """Heading of a body->NED rotation, ZYX Euler (Fossen)."""
    return math.atan2(r[1, 0], r[0, 0])


def rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def to_level(yaw: float, v: np.ndarray) -> np.ndarray:
    """A NED-aligned vector in the level frame of heading `yaw`."""
    return rot_z(yaw).T @ v


def from_level(yaw: float, v: np.ndarray) -> np.ndarray:
    """A level-frame vector of heading `yaw` in NED-aligned axes."""
    return rot_z(yaw) @ v


def beam_vector(d: float, az: float, el: float) -> np.ndarray:
    """A return at range d, azimuth az (starboard +), elevation el (down +), body axes."""
    return np.array([d * math.cos(el) * math.cos(az), d * math.cos(el) * math.sin(az), d * math.sin(el)])


# ---------------------------------------------------------------------------------------
# Eqs. (4)-(9)
# ---------------------------------------------------------------------------------------


def proximity(y_d: float, y_f: float) -> float:
    """Eq. (7): delta = S(y_d) (y_d - y_f)."""
    return (1.0 if y_d >= 0.0 else -1.0) * (y_d - y_f)


@dataclass
class Shift:
    slot: np.ndarray  # shifted slot X~* (eq. 8), parent frame, m
    lam: float  # progress along the segment, 0..1
    delta_min: float  # min delta_j (eq. 7), inf with no point
    active: bool  # min delta_j < D_min


@dataclass
class Displacement:
    """A follower's displacement segment, eqs. (4)-(5), in the parent's frame."""

    slot: np.ndarray  # nominal slot X~_F
    d_a: float
    d_b: float

    def d_a_signed(self) -> float:
        # the paper's "+" for a follower left (port) of x~, "-" for one on the right
        y = self.slot[1]
        return self.d_a if y < 0.0 else (-self.d_a if y > 0.0 else 0.0)

    def at(self, lam: float) -> np.ndarray:
        """Eqs. (4), (5): the segment's point at progress lam in [0, 1]."""
        lam = min(max(lam, 0.0), 1.0)
        if self.slot[1] == 0.0:
            return self.slot.copy()
        x, y, z = self.slot
        return np.array([x + 0.5 * self.d_a_signed() * lam, y * (1.0 - lam), z + 0.5 * self.d_b * lam])

    def shift(self, y_d: Iterable[float], d_min: float) -> Shift:
        """Eqs. (7)-(8) over the lateral positions y~_dj of the obstacle points."""
        y_f = self.slot[1]
        delta_min, y_dc = math.inf, None
        for y in y_d:
            delta = proximity(y, y_f)
            if delta < delta_min:
                delta_min, y_dc = delta, y
        active = y_dc is not None and delta_min < d_min
        if active and y_f != 0.0:
            y_star = y_dc - (1.0 if y_dc >= 0.0 else -1.0) * d_min
            lam = min(max((y_f - y_star) / y_f, 0.0), 1.0)  # clamped to the segment
            return Shift(self.at(lam), lam, delta_min, True)
        return Shift(self.slot.copy(), 0.0, delta_min, active)


class SlotFilter:
    """Eq. (9): first-order low-pass of the moving slot, one update per planner step."""

    def __init__(self, beta: float, initial: np.ndarray):
        self.beta = min(max(beta, 0.0), 1.0)
        self.value = initial.copy()

    def update(self, target: np.ndarray) -> np.ndarray:
        self.value = self.value + self.beta * (target - self.value)
        return self.value

    def reset(self, value: np.ndarray) -> None:
        self.value = value.copy()


# ---------------------------------------------------------------------------------------
# The observer of fig. 4 (services/planner/src/observer.rs without the coordinated turn)
# ---------------------------------------------------------------------------------------

ACCEPTED, RESTARTED, REJECTED = "accepted", "restarted", "rejected"


class ParentObserver:
    """Kalman filter of the parent in the follower's odometry frame.

    Position/velocity: constant velocity, white acceleration of density accel_noise.
    Heading/turn rate: constant turn rate, white angular acceleration. A fix taken at t_m <=
    t updates the state at t through H = [I, -(t - t_m) I] (the state extrapolated back), so
    camera latency does not bias the estimate. Fixes outside a chi-square gate are rejected;
    after max_rejections in a row the filter restarts from the latest fix.

    The odometry frame is the right place for a constant-velocity model: the parent's motion
    there is its own, independent of the follower's manoeuvres; the follower's dead-reckoning
    drift is common to its own position and to every fix and cancels in the slot.
    """

    def __init__(self, accel_noise: float, yaw_accel_noise: float, gate_chi2: float, max_rejections: int):
        self.qa = accel_noise**2
        self.qy = yaw_accel_noise**2
        self.gate_chi2 = gate_chi2
        self.max_rejections = max_rejections
        self.initialized = False
        self.t = 0.0
        self.x = np.zeros(6)  # [position; velocity], odometry frame
        self.p = np.eye(6)
        self.y = np.zeros(2)  # [heading, turn rate]
        self.py = np.eye(2)
        self.rejections = 0

    position = property(lambda self: self.x[:3].copy())
    velocity = property(lambda self: self.x[3:].copy())
    yaw = property(lambda self: float(self.y[0]))
    yaw_rate = property(lambda self: float(self.y[1]))

    def predict(self, t: float) -> None:
        if not self.initialized:
            self.t = t
            return
        dt = t - self.t
        if dt <= 0.0:
            return
        i3 = np.eye(3)
        f = np.block([[i3, dt * i3], [np.zeros((3, 3)), i3]])
        q = np.block(
            [[self.qa * dt**3 / 3 * i3, self.qa * dt**2 / 2 * i3], [self.qa * dt**2 / 2 * i3, self.qa * dt * i3]]
        )
        self.x = f @ self.x
        self.p = f @ self.p @ f.T + q
        fy = np.array([[1.0, dt], [0.0, 1.0]])
        qy = self.qy * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        self.y = fy @ self.y
        self.y[0] = wrap(self.y[0])
        self.py = fy @ self.py @ fy.T + qy
        self.t = t

    def restart(self, t, pos, r_pos, yaw, yaw_var, v_guess) -> None:
        """(Re)start from a fix; the velocity guess is the follower's own (formation members
        move together)."""
        self.x = np.concatenate([pos, v_guess]).astype(float)
        self.p = np.zeros((6, 6))
        self.p[:3, :3] = r_pos
        self.p[3:, 3:] = np.eye(3) * INITIAL_SPEED_STD_MPS**2
        self.y = np.array([wrap(yaw), 0.0])
        self.py = np.diag([yaw_var, 0.05**2])
        self.t = t
        self.initialized = True
        self.rejections = 0

    def fuse(self, t_meas, pos, r_pos, yaw, yaw_var, v_guess) -> str:
        """Fuses a fix taken at t_meas into the state at self.t (predict first)."""
        if not self.initialized:
            self.restart(self.t, pos, r_pos, yaw, yaw_var, v_guess)
            return RESTARTED
        lag = max(self.t - t_meas, 0.0)
        h = np.hstack([np.eye(3), -lag * np.eye(3)])
        innov = pos - h @ self.x
        s = h @ self.p @ h.T + r_pos
        try:
            s_inv = np.linalg.inv(s)
        except np.linalg.LinAlgError:
            return REJECTED
        d2 = float(innov @ s_inv @ innov)
        if not (math.isfinite(d2) and d2 <= self.gate_chi2):
            self.rejections += 1
            if self.rejections >= self.max_rejections:
                # the parent really is elsewhere: restart, the fix moved to now
                self.restart(self.t, pos + v_guess * lag, r_pos, yaw, yaw_var, v_guess)
                return RESTARTED
            return REJECTED
        self.rejections = 0
        k = self.p @ h.T @ s_inv
        self.x = self.x + k @ innov
        ikh = np.eye(6) - k @ h
        self.p = ikh @ self.p @ ikh.T + k @ r_pos @ k.T  # Joseph form
        # heading
        hy = np.array([1.0, -lag])
        iy = wrap(yaw - (self.y[0] - lag * self.y[1]))
        sy = float(hy @ self.py @ hy) + yaw_var
        if sy > 0.0:
            ky = self.py @ hy / sy
            self.y = self.y + ky * iy
            self.y[0] = wrap(self.y[0])
            iky = np.eye(2) - np.outer(ky, hy)
            self.py = iky @ self.py @ iky.T + np.outer(ky, ky) * yaw_var
        return ACCEPTED


# ---------------------------------------------------------------------------------------
# The follower
# ---------------------------------------------------------------------------------------


@dataclass
class Fix:
    """One vision fix of the parent (a valid or invalid LeaderPose sample)."""

    t_s: float  # image time, s (header.origin_sim_time_ns)
    position_body_m: np.ndarray  # parent position in the follower's body frame (eq. 3)
    q_parent_to_body_wxyz: np.ndarray  # parent attitude in the follower's body frame
    covariance: np.ndarray  # 6x6, [position, rotation vector], body frame
    valid: bool


@dataclass
class Target:
    """The setpoint for mpc, in the vehicle's level frame (see the module docstring)."""

    position_m: np.ndarray
    velocity_mps: np.ndarray
    yaw_rel_rad: float


@dataclass
class State:
    mode: int
    slot_nominal_m: np.ndarray
    slot_shifted_m: np.ndarray
    slot_filtered_m: np.ndarray
    delta_min_m: float  # inf with no remembered point
    parent_age_s: float
    parent_valid: bool  # the estimate is fresh
    avoiding: bool


@dataclass
class Output:
    target: Target
    state: State
    # what the controller's safety layer keeps clear of (level frame; mpc ignores it when
    # [method] generalised = false, its safety layer being off then)
    keepout_points_m: list = field(default_factory=list)
    parent_keepout: Optional[tuple] = None  # (position, velocity) while the estimate is fresh


@dataclass
class _Anchor:
    t0: float
    pos: np.ndarray
    vel: np.ndarray
    yaw: float
    look: Optional[np.ndarray]


def config_from_scenario(scenario: dict, name: str) -> dict:
    """The PaperFollower configuration of vehicle `name`: the scenario's [follower] section
    (defaults as the Rust planner's), its slot and resolved D_a, D_b, D_min = the safe
    distance (as follower_config in services/planner/src/node.rs)."""
    spec = next(v for v in scenario["vehicles"] if v["name"] == name)
    section = dict(scenario.get("follower") or {})
    cfg = {k: section.get(k, d) for k, d in DEFAULTS.items()}
    for k in IGNORED_UNLESS_ZERO:
        if float(section.get(k, 0.0)) != 0.0:
            print(f"paper_follower: [follower] {k} = {section[k]} ignored (not the paper's method)", file=sys.stderr)
    for key in ("slot_m", "d_a_m", "d_b_m"):
        if spec.get(key) is None:
            raise ValueError(f"{name}: {key} not resolved (start the run through `shoal run`)")
    cfg["slot_in_parent_m"] = spec["slot_m"]
    cfg["d_a_m"] = spec["d_a_m"]
    cfg["d_b_m"] = spec["d_b_m"]
    cfg["d_min_m"] = scenario.get("safety", {}).get("safe_distance_m", 2.0)
    return cfg


class PaperFollower:
    """The paper's follower planner (sec. 3, fig. 4). Pure: no I/O, time in the inputs."""

    def __init__(self, config: dict):
        c = {**DEFAULTS, **config}
        self.slot = np.asarray(c["slot_in_parent_m"], dtype=float)
        self.d_min = float(c["d_min_m"])
        self.beta = float(c["beta"])
        if not 0.0 < self.beta <= 1.0:
            raise ValueError(f"follower.beta must be in (0, 1], got {self.beta}")
        if np.linalg.norm(self.slot) < self.d_min:
            raise ValueError(f"slot {self.slot} is closer to the parent than d_min_m {self.d_min}")
        self.mount = np.asarray(c["sonar_mount_body_m"], dtype=float)
        self.parent_echo_radius = float(c["parent_echo_radius_m"])
        self.memory_behind = float(c["memory_behind_m"])
        self.memory_max_age = float(c["memory_max_age_s"])
        self.stale_after = float(c["stale_after_s"])
        self.coast_s = float(c["coast_s"])
        self.reacquire_count = int(c["reacquire_count"])
        self.pose_noise_min = float(c["pose_noise_min_m"])
        self.yaw_noise_min = float(c["yaw_noise_min_rad"])
        self.pose_noise_default = float(c["pose_noise_default_m"])
        self.lost_after = self.stale_after + self.coast_s  # (+ predict_s, 0 here)

        self.disp = Displacement(self.slot.copy(), float(c["d_a_m"]), float(c["d_b_m"]))
        self.filter = SlotFilter(self.beta, self.slot)
        self.last_shift = Shift(self.slot.copy(), 0.0, math.inf, False)
        self.observer = ParentObserver(
            float(c["accel_noise_mps2"]), float(c["yaw_accel_noise_radps2"]), float(c["gate_chi2"]), int(c["max_rejections"])
        )
        self.t_start: Optional[float] = None
        self.t_prev = 0.0
        self.odo = np.zeros(3)  # own position, odometry frame
        self.history: deque = deque(maxlen=HISTORY_CAPACITY)  # (t, pos, R_body_to_ned)
        self.memory: deque = deque(maxlen=MEMORY_CAPACITY)  # (t, pos) odometry frame
        self.t_last_fix: Optional[float] = None  # image time of the last fused fix
        self.t_last_seen_fix: Optional[float] = None
        self.consecutive_fixes = 0
        self.mode = PARENT_LOST
        self.anchor: Optional[_Anchor] = None
        self.last_target = None  # (pos, vel, yaw), odometry frame

    # -- helpers --------------------------------------------------------------------------

    def _own_at(self, t: float):
        """Own pose at (or just before) t, from the history."""
        for h in reversed(self.history):
            if h[0] <= t + 1e-9:
                return h
        return self.history[0]

    def _fix_noise(self, r_own: np.ndarray, cov: np.ndarray):
        """Fix position covariance (odometry axes) and heading variance, with floors."""
        usable = np.all(np.isfinite(cov)) and np.all(np.diag(cov) >= 0.0)
        if usable:
            pos = r_own @ cov[:3, :3] @ r_own.T
            yaw_var = (r_own @ cov[3:, 3:] @ r_own.T)[2, 2]
        else:
            pos = np.eye(3) * self.pose_noise_default**2
            yaw_var = math.radians(5.0) ** 2
        return pos + np.eye(3) * self.pose_noise_min**2, max(yaw_var, 0.0) + self.yaw_noise_min**2

    # -- one step -------------------------------------------------------------------------

    def step(
        self,
        t_s: float,
        q_body_to_ned_wxyz: Sequence[float],
        nu: Sequence[float],
        depth_m: float,
        fix: Optional[Fix] = None,
        sonar_returns: Iterable[tuple] = (),
    ) -> Output:
        """One planner step at t_s (the nav sample's time). nu = [u, v, w, p, q, r] (DVL +
        gyros, body axes); sonar_returns = (range m, azimuth rad, elevation rad) of this
        step's new scan, valid returns only. Raises ValueError on bad input."""
        q = np.asarray(q_body_to_ned_wxyz, dtype=float)
        nu = np.asarray(nu, dtype=float)
        if not (math.isfinite(t_s) and np.all(np.isfinite(q)) and np.all(np.isfinite(nu)) and math.isfinite(depth_m)):
            raise ValueError("non-finite nav input")
        if fix is not None and fix.valid:
            if not (math.isfinite(fix.t_s) and np.all(np.isfinite(fix.position_body_m)) and np.all(np.isfinite(fix.q_parent_to_body_wxyz))):
                raise ValueError("non-finite pose input")
        t = float(t_s)
        first = self.t_start is None
        if not first and t < self.t_prev:
            raise ValueError(f"time went backwards: {self.t_prev} s then {t} s")
        dt = 0.0 if first else min(t - self.t_prev, 1.0)
        if first:
            self.t_start = t
        self.t_prev = t

        # 1. own odometry
        r_own = quat_to_rot(q)
        yaw_own = yaw_of(r_own)
        v_own = r_own @ nu[:3]
        self.odo[0] += v_own[0] * dt
        self.odo[1] += v_own[1] * dt
        self.odo[2] = depth_m
        self.history.append((t, self.odo.copy(), r_own))

        # 2. observer: predict to now, then the new fix (eqs. 1-3 placed in odometry frame)
        self.observer.predict(t)
        age_before = math.inf if self.t_last_fix is None else t - self.t_last_fix
        repeat = fix is not None and self.t_last_seen_fix is not None and fix.t_s <= self.t_last_seen_fix
        if fix is not None and not repeat:
            self.t_last_seen_fix = fix.t_s
            if fix.valid:
                t_meas = min(fix.t_s, t)
                _, own_pos, own_r = self._own_at(t_meas)  # own pose at the image time
                p_fix = own_pos + own_r @ np.asarray(fix.position_body_m, dtype=float)
                yaw_fix = yaw_of(own_r @ quat_to_rot(fix.q_parent_to_body_wxyz))
                r_pos, yaw_var = self._fix_noise(own_r, np.asarray(fix.covariance, dtype=float).reshape(6, 6))
                if not self.observer.initialized or age_before > self.lost_after:
                    here = p_fix + v_own * (t - t_meas)
                    self.observer.restart(t, here, r_pos, yaw_fix, yaw_var, v_own)
                    outcome = RESTARTED
                else:
                    outcome = self.observer.fuse(t_meas, p_fix, r_pos, yaw_fix, yaw_var, v_own)
                if outcome == ACCEPTED:
                    self.t_last_fix = t_meas
                    self.consecutive_fixes += 1
                elif outcome == RESTARTED:
                    self.t_last_fix = t_meas
                    self.consecutive_fixes = 1
                else:
                    self.consecutive_fixes = 0
            else:
                self.consecutive_fixes = 0
        age = (t - self.t_start) if self.t_last_fix is None else (t - self.t_last_fix)
        fresh = self.observer.initialized and self.t_last_fix is not None and age <= self.stale_after

        # 3. sonar returns into the odometry frame (the parent's own echo ignored), then
        #    forget what is memory_behind_m behind or too old
        parent_pos = self.observer.position if fresh else None
        for d, az, el in sonar_returns:
            p = self.odo + r_own @ (self.mount + beam_vector(d, az, el))
            if parent_pos is not None and np.linalg.norm(p - parent_pos) < self.parent_echo_radius:
                continue
            self.memory.append((t, p))  # full: the oldest is dropped
        kept = [
            (tm, p)
            for tm, p in self.memory
            if to_level(yaw_own, p - self.odo)[0] >= -self.memory_behind and t - tm <= self.memory_max_age
        ]
        self.memory = deque(kept, maxlen=MEMORY_CAPACITY)

        # 4. mode
        if fresh:
            reacquiring = self.mode == PARENT_LOST and self.consecutive_fixes < self.reacquire_count
            nxt = PARENT_LOST if reacquiring else TRACKING
        elif self.observer.initialized and self.mode in (TRACKING, AVOIDING, COASTING) and age <= self.lost_after:
            nxt = COASTING
        else:
            nxt = PARENT_LOST

        if nxt == TRACKING:
            if self.mode == PARENT_LOST:
                self.filter.reset(self.last_shift.slot)  # re-entering
            self.anchor = None
            pos, vel, yaw, mode = self._track(dt)
        elif nxt == COASTING:
            pos, vel, yaw, mode = self._coast(t, yaw_own)
        else:
            pos, vel, yaw, mode = self._lost(t, yaw_own)
        self.mode = mode

        # the target in the level frame at the nav instant
        target = Target(
            position_m=to_level(yaw_own, pos - self.odo),
            velocity_mps=to_level(yaw_own, vel),
            yaw_rel_rad=wrap(yaw - yaw_own),
        )
        keep = self._keepout([to_level(yaw_own, p - self.odo) for _, p in self.memory])
        parent = None
        if fresh:
            parent = (to_level(yaw_own, self.observer.position - self.odo), to_level(yaw_own, self.observer.velocity))
        state = State(
            mode=mode,
            slot_nominal_m=self.disp.slot.copy(),
            slot_shifted_m=self.last_shift.slot.copy(),
            slot_filtered_m=self.filter.value.copy(),
            delta_min_m=self.last_shift.delta_min,
            parent_age_s=age,
            parent_valid=fresh,
            avoiding=self.last_shift.active,
        )
        return Output(target, state, keep, parent)

    def _track(self, dt: float):
        """Tracking: eqs. (6)-(9) in the parent's frame; target in the odometry frame."""
        p_parent = self.observer.position
        v_parent = self.observer.velocity
        yaw_parent = self.observer.yaw
        r_parent = self.observer.yaw_rate
        # eq. (6): remembered returns in the parent's frame; eq. (7)-(8): the shift
        y_d = (to_level(yaw_parent, p - p_parent)[1] for _, p in self.memory)
        shift = self.disp.shift(y_d, self.d_min)
        prev = self.filter.value
        filtered = self.filter.update(shift.slot)  # eq. (9)
        slot_rate = (filtered - prev) / dt if dt > 0.0 else np.zeros(3)
        self.last_shift = shift
        # the rigid slot: it turns with the parent's heading
        arm = from_level(yaw_parent, filtered)
        vel = v_parent + np.cross(EZ, arm) * r_parent + from_level(yaw_parent, slot_rate)
        pos = p_parent + arm
        yaw = yaw_parent
        self.last_target = (pos, vel, yaw)
        returning = np.linalg.norm(filtered - self.disp.slot) > RETURNING_TOL_M
        return pos, vel, yaw, (AVOIDING if shift.active or returning else TRACKING)

    def _coast(self, t: float, yaw_own: float):
        """Coasting: the last target carried on, slowing linearly to a stop over coast_s."""
        if self.anchor is None or self.mode != COASTING:
            if self.last_target is not None:
                p, v, y = self.last_target
            else:
                p, v, y = self.odo.copy(), np.zeros(3), yaw_own
            self.anchor = _Anchor(t, p.copy(), np.array([v[0], v[1], 0.0]), y, None)
        a = self.anchor
        big_t = self.coast_s
        tau = min(max(t - a.t0, 0.0), big_t)
        s, f = (tau - tau * tau / (2.0 * big_t), 1.0 - tau / big_t) if big_t > 0.0 else (0.0, 0.0)
        return a.pos + a.vel * s, a.vel * f, a.yaw, COASTING

    def _lost(self, t: float, yaw_own: float):
        """ParentLost: hold a point and depth, facing the parent's last estimated position
        (so that a parent lost at the image edge comes back into view)."""
        look = self.observer.position if self.observer.initialized else None
        a = self.anchor
        if a is not None and self.mode == PARENT_LOST:
            pass
        elif a is not None and self.mode == COASTING:
            # where the coast ends
            a = _Anchor(t, a.pos + a.vel * (0.5 * self.coast_s), np.zeros(3), a.yaw, look)
        elif self.last_target is not None:
            p, _, y = self.last_target
            a = _Anchor(t, p.copy(), np.zeros(3), y, look)
        else:
            a = _Anchor(t, self.odo.copy(), np.zeros(3), yaw_own, look)
        self.anchor = a
        yaw = a.yaw
        if a.look is not None:
            d = a.look - self.odo
            if math.hypot(d[0], d[1]) > LOOK_MIN_RANGE_M:
                yaw = math.atan2(d[1], d[0])
        return a.pos.copy(), np.zeros(3), yaw, PARENT_LOST

    @staticmethod
    def _keepout(points: list) -> list:
        """Up to MAX_KEEPOUT remembered returns (level frame) within KEEPOUT_RANGE_M, nearest
        first, at least KEEPOUT_SPACING_M apart (planner keepout.rs)."""
        pts = np.array(points, dtype=float).reshape(-1, 3)
        dist = np.linalg.norm(pts, axis=1)
        in_range = dist <= KEEPOUT_RANGE_M  # (NaN compares False)
        taken: list = []
        for _ in range(MAX_KEEPOUT):
            ok = in_range.copy()
            for q in taken:
                ok &= np.linalg.norm(pts - q, axis=1) >= KEEPOUT_SPACING_M
            if not ok.any():
                break
            idx = np.flatnonzero(ok)
            taken.append(pts[idx[np.argmin(dist[idx])]])  # ties: the earlier point
        return taken


# ---------------------------------------------------------------------------------------
# The process: wiring to shoal's channels (as services/planner/src/node.rs)
# ---------------------------------------------------------------------------------------


def _vec(a) -> np.ndarray:
    return np.array(a[:], dtype=float)


def _put(dst, values) -> None:
    for i, x in enumerate(values):
        dst[i] = float(x)


def main() -> int:
    import shoal_node as sn
    from shoal_node import msgs

    node = sn.Node.from_args()
    if not node.vehicle_spec.get("parent"):
        print(f"paper_follower: {node.vehicle} has no parent; this replaces a follower's planner", file=sys.stderr)
        return 2
    planner = PaperFollower(config_from_scenario(node.scenario, node.vehicle))

    # In a dataflow run the planner steps once its frame's sonar scan and (with the camera)
    # parent fix are in, as shoal's planner does; nav is read as it stands.
    camera = node.scenario.get("method", {}).get("perception", "camera") == "camera"
    nav_in = node.subscriber("nav")
    sonar_in = node.subscriber("sonar", trigger=node.rate_hz("sonar") == node.rate_hz("planner"))
    pose_in = node.subscriber(
        "leader_pose", trigger=camera and node.rate_hz("camera-pose") == node.rate_hz("planner")
    )
    sp_out = node.publisher("setpoint")
    st_out = node.publisher("planner_state")

    nav = None
    for step in node.steps():
        n = nav_in.latest(step)
        if n is not None:
            nav = n
        if nav is None:
            continue  # nothing known about ourselves yet: publish nothing
        scan = sonar_in.latest(step)
        origin = sn.Origin.of(nav.header)
        if scan is not None:
            origin = origin.earliest(sn.Origin.of(scan.header))
        pose = pose_in.latest(step)
        fix = None
        if pose is not None:
            origin = origin.earliest(sn.Origin.of(pose.header))
            fix = Fix(
                t_s=pose.header.origin_sim_time_ns * 1e-9,  # image time
                position_body_m=_vec(pose.parent_position_body_m),
                q_parent_to_body_wxyz=_vec(pose.q_parent_to_body_wxyz),
                covariance=_vec(pose.covariance).reshape(6, 6),  # row-major
                valid=pose.valid != 0,
            )
        returns = []
        if scan is not None:
            for i in range(min(int(scan.count), MAX_BEAMS)):
                r, az, el = scan.ranges_m[i], scan.azimuth_rad[i], scan.elevation_rad[i]
                if scan.valid[i] and math.isfinite(r) and math.isfinite(az) and math.isfinite(el) and r >= 0.0:
                    returns.append((r, az, el))

        # the planner's time base is the nav sample's time (node.rs): dead reckoning, the
        # placing of the (image-time stamped) fixes and the target refer to that instant
        v, w = _vec(nav.velocity_body_mps), _vec(nav.rates_body_radps)
        out = planner.step(
            t_s=nav.header.sim_time_ns * 1e-9,
            q_body_to_ned_wxyz=_vec(nav.q_body_to_ned_wxyz),
            nu=np.concatenate([v, w]),
            depth_m=float(nav.depth_m),
            fix=fix,
            sonar_returns=returns,
        )

        sp = msgs.Setpoint()
        _put(sp.position_m, out.target.position_m)
        _put(sp.velocity_mps, out.target.velocity_mps)
        sp.yaw_rel_rad = out.target.yaw_rel_rad
        sp.mode = out.state.mode
        sp.keepout_count = len(out.keepout_points_m)
        for k, p in enumerate(out.keepout_points_m):  # x0, y0, z0, x1, ...
            for j in range(3):
                sp.keepout_m[3 * k + j] = float(p[j])
        if out.parent_keepout is not None:
            _put(sp.parent_position_m, out.parent_keepout[0])
            _put(sp.parent_velocity_mps, out.parent_keepout[1])
            sp.parent_valid = 1
        sp_out.publish(sp, step, origin)

        s = out.state
        st = msgs.PlannerState()
        _put(st.slot_nominal_m, s.slot_nominal_m)
        _put(st.slot_shifted_m, s.slot_shifted_m)
        _put(st.slot_filtered_m, s.slot_filtered_m)
        st.delta_min_m = s.delta_min_m if math.isfinite(s.delta_min_m) else -1.0
        st.parent_age_s = s.parent_age_s if math.isfinite(s.parent_age_s) else -1.0
        st.waypoint_distance_m = FOLLOWER_WAYPOINT_DISTANCE_M
        st.mode = s.mode
        st.parent_valid = int(s.parent_valid)
        st.avoiding = int(s.avoiding)
        st_out.publish(st, step, origin)
    return 0


if __name__ == "__main__":
    sys.exit(main())
