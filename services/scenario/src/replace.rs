//! `[[replace]]`: a process kind of some or all vehicles run by the user's
//! own command instead of shoal's service binary.
//!
//! ```toml
//! [[replace]]
//! process = "planner"
//! vehicles = "followers"          # or "all", "leader", or ["F1", "F2"]
//! command = ["python3", "examples/python/paper_follower.py"]
//! ```
//!
//! The command is started, supervised, restarted and stopped like the
//! binary it replaces, with the same run arguments appended (`--run-id`,
//! `--vehicle`, `--process`, `--index`, … `--scenario`); the `shoal_node`
//! Python package and `shoal_runtime::Runtime` both read them. Relative
//! paths in `command` are as the user typed them: relative to the
//! directory `shoal` runs in.

use serde::{Deserialize, Serialize};

use crate::{invalid, ProcessKind, Scenario, ScenarioError};

/// The process kinds a user's command may take the place of: the ones
/// that read what the vehicle senses and write what it does. sim-plant
/// (the truth), camera-sim (the rendered truth), the world and the
/// recorder stay shoal's.
pub const REPLACEABLE: [ProcessKind; 4] = [
    ProcessKind::CameraPose,
    ProcessKind::Sonar,
    ProcessKind::Planner,
    ProcessKind::Mpc,
];

/// Which vehicles a replacement applies to.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Vehicles {
    /// `"all"`, `"followers"` or `"leader"`.
    Named(String),
    /// Vehicle names.
    List(Vec<String>),
}

impl Default for Vehicles {
    fn default() -> Self {
        Vehicles::Named("all".into())
    }
}

/// One `[[replace]]` entry.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Replace {
    /// The process kind: camera-pose, sonar, planner or mpc.
    pub process: ProcessKind,
    /// The vehicles whose process it replaces (default every vehicle).
    #[serde(default)]
    pub vehicles: Vehicles,
    /// The program and its first arguments; the run arguments follow.
    pub command: Vec<String>,
}

impl Replace {
    /// True when this entry replaces `kind` of vehicle `name` (`parent`:
    /// whether the vehicle has one).
    pub fn applies(&self, kind: ProcessKind, name: &str, follower: bool) -> bool {
        self.process == kind
            && match &self.vehicles {
                Vehicles::Named(w) => match w.as_str() {
                    "all" => true,
                    "followers" => follower,
                    "leader" => !follower,
                    _ => false,
                },
                Vehicles::List(names) => names.iter().any(|n| n == name),
            }
    }

    /// Parses the command line's form, `PROCESS[@VEHICLES]=COMMAND`:
    /// VEHICLES is `all` (the default), `followers`, `leader` or names
    /// separated by commas; COMMAND is split as a shell would split it
    /// (quotes kept together, nothing expanded).
    pub fn parse_flag(flag: &str) -> Result<Self, String> {
        let (target, command) = flag
            .split_once('=')
            .ok_or_else(|| format!("`{flag}`: expected PROCESS[@VEHICLES]=COMMAND"))?;
        let (process, vehicles) = match target.split_once('@') {
            Some((p, v)) => (p, Some(v)),
            None => (target, None),
        };
        let process = ProcessKind::ALL
            .into_iter()
            .find(|k| k.name() == process.trim())
            .ok_or_else(|| format!("`{process}` is not a process kind"))?;
        let vehicles = match vehicles.map(str::trim) {
            None => Vehicles::default(),
            Some(v @ ("all" | "followers" | "leader")) => Vehicles::Named(v.into()),
            Some(list) => Vehicles::List(list.split(',').map(|s| s.trim().to_string()).collect()),
        };
        let command = shlex::split(command)
            .ok_or_else(|| format!("`{command}`: an unclosed quote or a trailing backslash"))?;
        Ok(Self {
            process,
            vehicles,
            command,
        })
    }
}

impl Scenario {
    /// The user's command that runs `kind` of vehicle `vehicle`, if a
    /// `[[replace]]` entry says so (the last entry that applies wins, so a
    /// flag given on the command line overrides the file's).
    pub fn replacement(&self, kind: ProcessKind, vehicle: &str) -> Option<&[String]> {
        let follower = self.vehicle(vehicle)?.parent.is_some();
        self.replace
            .iter()
            .rev()
            .find(|r| r.applies(kind, vehicle, follower))
            .map(|r| r.command.as_slice())
    }
}

/// Checks every `[[replace]]` entry: a replaceable kind, vehicles that
/// exist (and at least one), a command.
pub(crate) fn validate(s: &Scenario) -> Result<(), ScenarioError> {
    for (i, r) in s.replace.iter().enumerate() {
        let key = |k: &str| format!("replace[{i}].{k}");
        if !REPLACEABLE.contains(&r.process) {
            return Err(invalid(
                key("process"),
                format!(
                    "`{}` cannot be replaced; one of: {}",
                    r.process.name(),
                    REPLACEABLE.map(ProcessKind::name).join(", ")
                ),
            ));
        }
        if r.command.is_empty() || r.command[0].trim().is_empty() {
            return Err(invalid(key("command"), "must name a program"));
        }
        match &r.vehicles {
            Vehicles::Named(w) if !matches!(w.as_str(), "all" | "followers" | "leader") => {
                return Err(invalid(
                    key("vehicles"),
                    format!(
                        "`{w}`: expected \"all\", \"followers\", \"leader\" or a list of names"
                    ),
                ));
            }
            Vehicles::List(names) => {
                if names.is_empty() {
                    return Err(invalid(key("vehicles"), "names no vehicle"));
                }
                if let Some(n) = names.iter().find(|n| s.vehicle(n).is_none()) {
                    return Err(invalid(key("vehicles"), format!("no vehicle `{n}`")));
                }
            }
            Vehicles::Named(_) => {}
        }
        // A camera-pose exists only for a follower with a camera: one
        // named for a vehicle without it would replace nothing.
        let any = s.vehicles.iter().any(|v| {
            r.applies(r.process, &v.name, v.parent.is_some())
                && s.processes()
                    .iter()
                    .any(|p| p.kind == r.process && p.vehicle == v.name)
        });
        if !any {
            return Err(invalid(
                key("vehicles"),
                format!("no vehicle named here runs a {}", r.process.name()),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flag_names_a_kind_the_vehicles_and_a_command_split_as_a_shell_would() {
        let r = Replace::parse_flag("planner@followers=python3 'my planner.py' --gain 2").unwrap();
        assert_eq!(r.process, ProcessKind::Planner);
        assert_eq!(r.vehicles, Vehicles::Named("followers".into()));
        assert_eq!(r.command, ["python3", "my planner.py", "--gain", "2"]);
        let r = Replace::parse_flag("mpc@F1, F2=./ctl").unwrap();
        assert_eq!(r.vehicles, Vehicles::List(vec!["F1".into(), "F2".into()]));
        assert!(r.applies(ProcessKind::Mpc, "F2", true));
        assert!(!r.applies(ProcessKind::Mpc, "F3", true));
        assert!(!r.applies(ProcessKind::Planner, "F1", true));
        let all = Replace::parse_flag("sonar=x").unwrap();
        assert!(all.applies(ProcessKind::Sonar, "L", false));
        assert!(Replace::parse_flag("planner").is_err());
        assert!(Replace::parse_flag("pilot=x").is_err());
        assert!(Replace::parse_flag("planner=python3 'open").is_err());
    }
}
