//! What the orchestrator does when a process dies (`[supervision]`), and
//! faults injected on purpose (`[[faults]]`).
//!
//! ```toml
//! [supervision]
//! policy = "restart"          # or "abort" (the default): stop cleanly with the cause
//! restart_timeout_s = 10.0    # a restarted process must be ready within this
//! max_restarts = 3            # per process; one more death aborts the run
//!
//! [[faults]]                  # kill F3's sonar at t = 40 s
//! action = "kill"
//! vehicle = "F3"
//! process = "sonar"
//! at_s = 40.0
//!
//! [[faults]]                  # stall F1's mpc for 2 s (SIGSTOP … SIGCONT)
//! action = "stall"
//! vehicle = "F1"
//! process = "mpc"
//! at_s = 30.0
//! duration_s = 2.0
//!
//! [[faults]]                  # drop 30 % of F2's camera frames from 50 to 60 s
//! action = "drop"
//! vehicle = "F2"
//! from_s = 50.0
//! to_s = 60.0
//! fraction = 0.3
//!
//! [[faults]]                  # blind F4's camera from 60 to 70 s
//! action = "blind"
//! vehicle = "F4"
//! from_s = 60.0
//! to_s = 70.0
//! ```

use serde::{Deserialize, Serialize};

use crate::{invalid, ProcessKind, Scenario, ScenarioError};

/// What to do when a process dies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Policy {
    /// Stop the run cleanly and report the cause.
    #[default]
    Abort,
    /// Start the process again; the lockstep clock waits for it.
    Restart,
}

/// `[supervision]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Supervision {
    /// Abort (default) or restart.
    pub policy: Policy,
    /// Longest a restarted process may take to be ready, s (default 10).
    pub restart_timeout_s: f64,
    /// Restarts allowed per process (default 3).
    pub max_restarts: u32,
}

impl Default for Supervision {
    fn default() -> Self {
        Self {
            policy: Policy::Abort,
            restart_timeout_s: 10.0,
            max_restarts: 3,
        }
    }
}

/// The kinds of injected fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultAction {
    /// SIGKILL the process at `at_s`.
    Kill,
    /// SIGSTOP the process at `at_s`, SIGCONT it `duration_s` later.
    Stall,
    /// The vehicle's camera loses `fraction` of its frames in `[from_s, to_s)`.
    Drop,
    /// The vehicle's camera sees nothing in `[from_s, to_s)`.
    Blind,
}

/// One `[[faults]]` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// What happens.
    pub action: FaultAction,
    /// To which vehicle (`run` for the world and recorder processes).
    pub vehicle: String,
    /// Which process (kill, stall): sim-plant, world, camera-pose, sonar,
    /// planner, mpc, recorder.
    #[serde(default)]
    pub process: Option<String>,
    /// When (kill, stall), s of simulated time.
    #[serde(default)]
    pub at_s: Option<f64>,
    /// How long (stall), s of wall time.
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// From (drop, blind), s.
    #[serde(default)]
    pub from_s: Option<f64>,
    /// To (drop, blind), s.
    #[serde(default)]
    pub to_s: Option<f64>,
    /// Share of frames lost (drop), in [0, 1].
    #[serde(default)]
    pub fraction: Option<f64>,
}

impl Fault {
    /// The process kind a kill or stall targets.
    pub fn process_kind(&self) -> Option<ProcessKind> {
        let p = self.process.as_deref()?;
        ProcessKind::ALL.into_iter().find(|k| k.name() == p)
    }

    /// True when a camera fault of this vehicle is active at `t_s`.
    pub fn camera_active(&self, vehicle: &str, t_s: f64) -> bool {
        matches!(self.action, FaultAction::Drop | FaultAction::Blind)
            && self.vehicle == vehicle
            && self.from_s.is_some_and(|a| t_s >= a)
            && self.to_s.is_some_and(|b| t_s < b)
    }
}

fn need(v: Option<f64>, key: String, what: &str) -> Result<f64, ScenarioError> {
    match v {
        Some(x) if x.is_finite() && x >= 0.0 => Ok(x),
        Some(x) => Err(invalid(
            key,
            format!("must be a finite number ≥ 0, got {x}"),
        )),
        None => Err(invalid(key, format!("is required for {what}"))),
    }
}

/// Checks `[supervision]` and every `[[faults]]` entry against the scenario.
pub fn validate(s: &Scenario) -> Result<(), ScenarioError> {
    let sup = &s.supervision;
    if !(sup.restart_timeout_s.is_finite() && sup.restart_timeout_s > 0.0) {
        return Err(invalid(
            "supervision.restart_timeout_s",
            format!("must be > 0, got {}", sup.restart_timeout_s),
        ));
    }
    for (i, f) in s.faults.iter().enumerate() {
        let key = |k: &str| format!("faults[{i}].{k}");
        // A key the action does not use would be silently ignored.
        let unused: &[(&str, bool)] = match f.action {
            FaultAction::Kill => &[
                ("duration_s", f.duration_s.is_some()),
                ("from_s", f.from_s.is_some()),
                ("to_s", f.to_s.is_some()),
                ("fraction", f.fraction.is_some()),
            ],
            FaultAction::Stall => &[
                ("from_s", f.from_s.is_some()),
                ("to_s", f.to_s.is_some()),
                ("fraction", f.fraction.is_some()),
            ],
            FaultAction::Drop => &[
                ("process", f.process.is_some()),
                ("at_s", f.at_s.is_some()),
                ("duration_s", f.duration_s.is_some()),
            ],
            FaultAction::Blind => &[
                ("process", f.process.is_some()),
                ("at_s", f.at_s.is_some()),
                ("duration_s", f.duration_s.is_some()),
                ("fraction", f.fraction.is_some()),
            ],
        };
        if let Some((k, _)) = unused.iter().find(|(_, set)| *set) {
            return Err(invalid(
                key(k),
                format!(
                    "is not used by a `{}` fault",
                    format!("{:?}", f.action).to_lowercase()
                ),
            ));
        }
        let is_vehicle = s.vehicles.iter().any(|v| v.name == f.vehicle);
        match f.action {
            FaultAction::Kill | FaultAction::Stall => {
                let kind = f.process_kind().ok_or_else(|| {
                    invalid(
                        key("process"),
                        format!(
                            "must name a process kind (sim-plant, world, camera-pose, sonar, planner, mpc, recorder), got {:?}",
                            f.process
                        ),
                    )
                })?;
                let run_level = matches!(kind, ProcessKind::World | ProcessKind::Recorder);
                if run_level && f.vehicle != "run" {
                    return Err(invalid(
                        key("vehicle"),
                        format!("the {} process belongs to vehicle \"run\"", kind.name()),
                    ));
                }
                if !run_level && !is_vehicle {
                    return Err(invalid(
                        key("vehicle"),
                        format!("\"{}\" is not a vehicle of the scenario", f.vehicle),
                    ));
                }
                if !s
                    .processes()
                    .iter()
                    .any(|p| p.kind == kind && p.vehicle == f.vehicle)
                {
                    return Err(invalid(
                        key("process"),
                        format!("{} has no {} process", f.vehicle, kind.name()),
                    ));
                }
                let at = need(f.at_s, key("at_s"), "a kill or stall")?;
                if at >= s.duration_s {
                    return Err(invalid(
                        key("at_s"),
                        format!("{at} s is after the run's end ({} s)", s.duration_s),
                    ));
                }
                if f.action == FaultAction::Stall {
                    let d = need(f.duration_s, key("duration_s"), "a stall")?;
                    if d <= 0.0 {
                        return Err(invalid(key("duration_s"), "must be > 0"));
                    }
                }
            }
            FaultAction::Drop | FaultAction::Blind => {
                if !s
                    .vehicles
                    .iter()
                    .any(|v| v.name == f.vehicle && v.parent.is_some())
                {
                    return Err(invalid(
                        key("vehicle"),
                        format!(
                            "\"{}\" is not a follower (only followers have a camera)",
                            f.vehicle
                        ),
                    ));
                }
                let a = need(f.from_s, key("from_s"), "a camera fault")?;
                let b = need(f.to_s, key("to_s"), "a camera fault")?;
                if b <= a {
                    return Err(invalid(
                        key("to_s"),
                        format!("must be after from_s ({a}), got {b}"),
                    ));
                }
                if a >= s.duration_s {
                    return Err(invalid(
                        key("from_s"),
                        format!("{a} s is after the run's end ({} s)", s.duration_s),
                    ));
                }
                if f.action == FaultAction::Drop {
                    let p = need(f.fraction, key("fraction"), "a drop")?;
                    if !(0.0..=1.0).contains(&p) {
                        return Err(invalid(
                            key("fraction"),
                            format!("must be in [0, 1], got {p}"),
                        ));
                    }
                }
            }
        }
    }
    Ok(())
}
