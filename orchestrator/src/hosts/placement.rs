//! Which host runs what: the hosts file, the automatic placement, and the
//! services that cross hosts with the bandwidth they need.
//!
//! A vehicle's processes always run together on one host (its own loop
//! stays in shared memory); the world runs on one host; every host runs a
//! recorder of its own. Vehicles see each other only through the world, so
//! the only samples that cross hosts are the truths of the vehicles placed
//! away from the world (to the world's host) and the world snapshot (to
//! every other host with a vehicle), besides the lockstep clock and fences.

use std::collections::BTreeMap;
use std::path::Path;

use ipc_types::{Channel, RunChannel};
use serde::{Deserialize, Serialize};
use shoal_scenario::{ProcessKind, ProcessSpec, Scenario, RUN_VEHICLE};

/// Errors of a hosts file or a placement.
#[derive(Debug, thiserror::Error)]
pub enum PlacementError {
    /// The file could not be read.
    #[error("cannot read the hosts file {path}")]
    Read {
        /// Its path.
        path: String,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a valid hosts file.
    #[error("the hosts file {path} is not valid: {message}")]
    Parse {
        /// Its path.
        path: String,
        /// What toml said.
        message: String,
    },
    /// No host at all.
    #[error("a hosts file needs at least one [[host]]")]
    NoHosts,
    /// Two hosts with one name.
    #[error("host `{0}` is named twice")]
    DuplicateHost(String),
    /// A host name that cannot be a key expression chunk or a file name.
    #[error("host name `{0}` must be 1-32 characters of a-z, A-Z, 0-9, '-' or '_'")]
    BadHostName(String),
    /// A vehicle placed that the scenario does not have.
    #[error("host `{host}` lists vehicle `{vehicle}`, which the scenario does not have")]
    UnknownVehicle {
        /// The host.
        host: String,
        /// The vehicle.
        vehicle: String,
    },
    /// A vehicle placed on two hosts.
    #[error("vehicle `{vehicle}` is placed on both `{first}` and `{second}`")]
    PlacedTwice {
        /// The vehicle.
        vehicle: String,
        /// One host.
        first: String,
        /// The other.
        second: String,
    },
    /// `world = ...` names a host that is not in the file.
    #[error("[placement] world = `{0}` is not a host of the file")]
    UnknownWorldHost(String),
    /// A plain TCP endpoint without `--insecure`.
    #[error("host `{host}` listens on {endpoint}, plain TCP: anyone who reaches it can start, read and abort runs. Use quic/ endpoints (TLS 1.3, mutual authentication) and a [tls] section (`shoal certs` makes the certificates), or say --insecure")]
    Insecure {
        /// The host.
        host: String,
        /// Its endpoint.
        endpoint: String,
    },
    /// TLS endpoints without certificates.
    #[error("host `{host}` listens on {endpoint} (QUIC: TLS 1.3), but the hosts file has no [tls] section naming the coordinator's certificates (`certs = \"DIR\"`, as `shoal certs --out DIR` writes them)")]
    NoCertificates {
        /// The host.
        host: String,
        /// Its endpoint.
        endpoint: String,
    },
    /// Endpoints of another kind, or a mix.
    #[error("host `{host}`'s endpoint {endpoint} is not {expected}/ADDR:PORT (every host of a run is reached the same way: quic/ (TLS 1.3, mutual authentication), or tcp/ with --insecure; Zenoh's tls/ link is not used: in Zenoh 1.10 it breaks under a run's traffic, zenoh issue 2557)")]
    MixedEndpoints {
        /// The host.
        host: String,
        /// Its endpoint.
        endpoint: String,
        /// The first host's scheme.
        expected: String,
    },
    /// `--insecure` with a [tls] section.
    #[error("--insecure asks for plain TCP, but the hosts file has a [tls] section and quic/ endpoints: drop one of them")]
    InsecureWithTls,
}

/// The coordinator's certificates (`[tls]` of a hosts file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsSection {
    /// The directory `shoal certs --out DIR` wrote, relative to the hosts
    /// file's directory: it holds `ca.pem`, `<name>.pem` and `<name>.key`.
    pub certs: std::path::PathBuf,
    /// The coordinator's certificate name (default `coordinator`): the
    /// name every agent is told to answer (`shoal host --coordinator`).
    #[serde(default = "default_coordinator")]
    pub name: String,
}

fn default_coordinator() -> String {
    super::tls::DEFAULT_COORDINATOR.to_string()
}

/// One host of a hosts file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HostEntry {
    /// The host's name (logs, key expressions, its recording part).
    pub name: String,
    /// Where its agent listens (`shoal host --listen`), a Zenoh locator
    /// such as `tcp/169.254.10.1:7447`.
    pub endpoint: String,
    /// Vehicles placed here by hand; the rest are placed automatically.
    #[serde(default)]
    pub vehicles: Vec<String>,
}

/// Placement options of a hosts file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlacementSection {
    /// The host of the world process (default: the first host).
    #[serde(default)]
    pub world: Option<String>,
}

/// A hosts file (`shoal run --hosts FILE`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HostsFile {
    /// The hosts, in order.
    #[serde(rename = "host", default)]
    pub hosts: Vec<HostEntry>,
    /// Where the run-level processes go.
    #[serde(default)]
    pub placement: PlacementSection,
    /// The coordinator's certificates, for quic/ endpoints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tls: Option<TlsSection>,
    /// `--insecure`: plain TCP allowed. Set by the command line, never
    /// read from or written to the file.
    #[serde(skip)]
    pub insecure: bool,
}

impl HostsFile {
    /// Reads and checks a hosts file.
    pub fn load(path: &Path) -> Result<Self, PlacementError> {
        let text = std::fs::read_to_string(path).map_err(|source| PlacementError::Read {
            path: path.display().to_string(),
            source,
        })?;
        let mut file = Self::parse(&text).map_err(|e| match e {
            PlacementError::Parse { message, .. } => PlacementError::Parse {
                path: path.display().to_string(),
                message,
            },
            other => other,
        })?;
        if let (Some(tls), Some(dir)) = (&mut file.tls, path.parent()) {
            if tls.certs.is_relative() {
                tls.certs = dir.join(&tls.certs);
            }
        }
        Ok(file)
    }

    /// How the coordinator reaches the hosts: TLS as the [tls] section's
    /// certificates say, or plain TCP if `--insecure` allowed it.
    pub fn security(&self) -> Result<super::tls::Security, PlacementError> {
        let first = &self.hosts.first().ok_or(PlacementError::NoHosts)?.endpoint;
        let scheme = first.split('/').next().unwrap_or("").to_string();
        for h in &self.hosts {
            if !h.endpoint.starts_with(&format!("{scheme}/"))
                || !matches!(scheme.as_str(), "quic" | "tcp")
            {
                return Err(PlacementError::MixedEndpoints {
                    host: h.name.clone(),
                    endpoint: h.endpoint.clone(),
                    expected: if scheme == "tcp" {
                        "tcp".into()
                    } else {
                        "quic".into()
                    },
                });
            }
        }
        let secure = scheme != "tcp";
        match (secure, &self.tls, self.insecure) {
            (true, Some(_), true) => Err(PlacementError::InsecureWithTls),
            (true, Some(t), false) => Ok(super::tls::Security::Tls(super::tls::Identity::in_dir(
                &t.certs, &t.name,
            ))),
            (true, None, _) => Err(PlacementError::NoCertificates {
                host: self.hosts[0].name.clone(),
                endpoint: first.clone(),
            }),
            (_, _, true) => Ok(super::tls::Security::Insecure),
            _ => Err(PlacementError::Insecure {
                host: self.hosts[0].name.clone(),
                endpoint: first.clone(),
            }),
        }
    }

    /// Parses and checks a hosts file's text.
    pub fn parse(text: &str) -> Result<Self, PlacementError> {
        let f: Self = toml::from_str(text).map_err(|e| PlacementError::Parse {
            path: "(text)".into(),
            message: e.to_string(),
        })?;
        f.check_names()?;
        Ok(f)
    }

    /// `k` hosts named `h1..hk` on the given endpoints (for generated runs).
    pub fn numbered(endpoints: &[String]) -> Self {
        Self {
            hosts: endpoints
                .iter()
                .enumerate()
                .map(|(i, e)| HostEntry {
                    name: format!("h{}", i + 1),
                    endpoint: e.clone(),
                    vehicles: Vec::new(),
                })
                .collect(),
            placement: PlacementSection::default(),
            tls: None,
            insecure: false,
        }
    }

    fn check_names(&self) -> Result<(), PlacementError> {
        if self.hosts.is_empty() {
            return Err(PlacementError::NoHosts);
        }
        let mut seen = std::collections::BTreeSet::new();
        for h in &self.hosts {
            if !super::tls::valid_name(&h.name) {
                return Err(PlacementError::BadHostName(h.name.clone()));
            }
            if !seen.insert(h.name.as_str()) {
                return Err(PlacementError::DuplicateHost(h.name.clone()));
            }
        }
        Ok(())
    }
}

/// Which host runs each process of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Host names, in the file's order.
    pub hosts: Vec<String>,
    /// Their agents' endpoints.
    pub endpoints: Vec<String>,
    /// Host index of every vehicle, in scenario order.
    pub vehicle_host: Vec<usize>,
    /// Host index of the world process.
    pub world_host: usize,
}

/// Relative cost of a vehicle's processes, for balancing: its process count.
fn vehicle_weight(scenario: &Scenario, v: usize) -> usize {
    let follower = scenario.vehicles[v].parent.is_some();
    let camera = if follower {
        scenario.camera_model().stages() as usize - 3
    } else {
        0
    };
    // sim-plant, sonar, planner, mpc, and the camera stages of a follower.
    4 + camera
}

impl Placement {
    /// Places `scenario` on the hosts of `file`: vehicles listed by a host
    /// go there; the others fill the hosts in scenario order, contiguously,
    /// so that every host ends with about the same number of processes (the
    /// world counts on its host).
    pub fn new(file: &HostsFile, scenario: &Scenario) -> Result<Self, PlacementError> {
        file.check_names()?;
        let k = file.hosts.len();
        let index_of: BTreeMap<&str, usize> = scenario
            .vehicles
            .iter()
            .enumerate()
            .map(|(i, v)| (v.name.as_str(), i))
            .collect();
        let world_host = match &file.placement.world {
            None => 0,
            Some(w) => file
                .hosts
                .iter()
                .position(|h| &h.name == w)
                .ok_or_else(|| PlacementError::UnknownWorldHost(w.clone()))?,
        };
        let mut vehicle_host: Vec<Option<usize>> = vec![None; scenario.vehicles.len()];
        let mut load = vec![0usize; k];
        load[world_host] += 1;
        for (h, host) in file.hosts.iter().enumerate() {
            for name in &host.vehicles {
                let &v =
                    index_of
                        .get(name.as_str())
                        .ok_or_else(|| PlacementError::UnknownVehicle {
                            host: host.name.clone(),
                            vehicle: name.clone(),
                        })?;
                if let Some(first) = vehicle_host[v] {
                    return Err(PlacementError::PlacedTwice {
                        vehicle: name.clone(),
                        first: file.hosts[first].name.clone(),
                        second: host.name.clone(),
                    });
                }
                vehicle_host[v] = Some(h);
                load[h] += vehicle_weight(scenario, v);
            }
        }
        // The rest, in scenario order, contiguously: each host has room for
        // its share of the total less what it holds already, and a vehicle
        // goes to the host whose room holds the middle of its weight.
        let free: Vec<usize> = (0..scenario.vehicles.len())
            .filter(|&v| vehicle_host[v].is_none())
            .collect();
        let free_weight: usize = free.iter().map(|&v| vehicle_weight(scenario, v)).sum();
        let total = (load.iter().sum::<usize>() + free_weight) as f64;
        let room: Vec<f64> = load
            .iter()
            .map(|&l| (total / k as f64 - l as f64).max(0.0))
            .collect();
        let room_sum: f64 = room.iter().sum();
        let mut before = 0.0;
        for v in free {
            let w = vehicle_weight(scenario, v) as f64;
            // Where the middle of this vehicle falls on the hosts' rooms laid end to end.
            let mid = (before + w / 2.0) / free_weight.max(1) as f64 * room_sum;
            let mut edge = 0.0;
            let mut h = k - 1;
            for (i, r) in room.iter().enumerate() {
                edge += r;
                if mid < edge {
                    h = i;
                    break;
                }
            }
            vehicle_host[v] = Some(h);
            load[h] += w as usize;
            before += w;
        }
        Ok(Self {
            hosts: file.hosts.iter().map(|h| h.name.clone()).collect(),
            endpoints: file.hosts.iter().map(|h| h.endpoint.clone()).collect(),
            // The last host took whatever was left.
            vehicle_host: vehicle_host
                .into_iter()
                .map(|h| h.unwrap_or(k - 1))
                .collect(),
            world_host,
        })
    }

    /// Number of hosts.
    pub fn len(&self) -> usize {
        self.hosts.len()
    }

    /// True with no host (never, for a placement that was made).
    pub fn is_empty(&self) -> bool {
        self.hosts.is_empty()
    }

    /// The host of process `p`; `None` for the recorder, which every host
    /// runs (each records what its own processes publish).
    pub fn host_of(&self, scenario: &Scenario, p: &ProcessSpec) -> Option<usize> {
        match p.kind {
            ProcessKind::Recorder => None,
            ProcessKind::World => Some(self.world_host),
            _ => scenario
                .vehicles
                .iter()
                .position(|v| v.name == p.vehicle)
                .map(|v| self.vehicle_host[v]),
        }
    }

    /// True if host `h` runs process `p`.
    pub fn runs(&self, scenario: &Scenario, h: usize, p: &ProcessSpec) -> bool {
        self.host_of(scenario, p).is_none_or(|x| x == h)
    }

    /// The vehicles placed on host `h`, in scenario order.
    pub fn vehicles_on<'a>(&self, scenario: &'a Scenario, h: usize) -> Vec<&'a str> {
        scenario
            .vehicles
            .iter()
            .zip(&self.vehicle_host)
            .filter(|(_, &x)| x == h)
            .map(|(v, _)| v.name.as_str())
            .collect()
    }

    /// Every service that crosses hosts, in a fixed order (world first,
    /// then truths in scenario order).
    pub fn crossings(&self, scenario: &Scenario, run_id: &str) -> Vec<Crossing> {
        let mut out = Vec::new();
        let world_rate = scenario.rate_hz(ProcessKind::World);
        let to: Vec<usize> = (0..self.len())
            .filter(|&h| h != self.world_host && self.vehicle_host.contains(&h))
            .collect();
        if !to.is_empty() {
            out.push(Crossing {
                service: ipc_types::run_service_name(run_id, RunChannel::World),
                vehicle: RUN_VEHICLE.to_string(),
                what: "world",
                from: self.world_host,
                to,
                sample_bytes: world_wire_bytes(scenario.vehicles.len()),
                rate_hz: world_rate,
            });
        }
        for (v, &h) in scenario.vehicles.iter().zip(&self.vehicle_host) {
            if h != self.world_host {
                out.push(Crossing {
                    service: ipc_types::service_name(run_id, &v.name, Channel::Truth),
                    vehicle: v.name.clone(),
                    what: "truth",
                    from: h,
                    to: vec![self.world_host],
                    sample_bytes: Channel::Truth.sample_size(),
                    rate_hz: scenario.rate_hz(ProcessKind::SimPlant),
                });
            }
        }
        out
    }

    /// What each host's link to the coordinator carries per simulated
    /// second, `(up, down)` by host: every message between hosts passes the
    /// coordinator's router (the star of [`super::wire`]), so a crossing
    /// sample goes up once from its publisher and down once to each
    /// subscribing host; every busy tick sends one clock down and one fence
    /// up each link. `overhead` is the framing per message, bytes.
    pub fn link_load(
        &self,
        scenario: &Scenario,
        run_id: &str,
        overhead: usize,
    ) -> Vec<(LinkLoad, LinkLoad)> {
        let mut links = vec![(LinkLoad::default(), LinkLoad::default()); self.len()];
        let add = |l: &mut LinkLoad, rate: f64, bytes: usize| {
            l.messages_per_s += rate;
            l.bytes_per_s += rate * (bytes + overhead) as f64;
        };
        for c in self.crossings(scenario, run_id) {
            add(&mut links[c.from].0, c.rate_hz, c.sample_bytes);
            for &t in &c.to {
                add(&mut links[t].1, c.rate_hz, c.sample_bytes);
            }
        }
        let ticks_per_s = lockstep_ticks_per_sim_s(scenario);
        for (up, down) in &mut links {
            add(up, ticks_per_s, FENCE_BYTES);
            add(down, ticks_per_s, FENCE_BYTES);
        }
        links
    }
}

/// Bytes of a fence message (the tick it closes).
pub const FENCE_BYTES: usize = 8;

/// Bytes a world snapshot of `vehicles` vehicles takes on the wire: the
/// bridge sends a sample without its zero tail, and the poses past `count`
/// are zero.
pub fn world_wire_bytes(vehicles: usize) -> usize {
    let pose = std::mem::size_of::<ipc_types::VehiclePose>();
    let full = std::mem::size_of::<ipc_types::World>();
    (full - pose * ipc_types::MAX_VEHICLES + pose * vehicles).min(full)
}

/// Lockstep ticks with at least one due process, per simulated second.
pub fn lockstep_ticks_per_sim_s(scenario: &Scenario) -> f64 {
    let procs = scenario.processes();
    let ticks = scenario.ticks().max(1);
    let sample = ticks.min(10_000);
    let busy = (0..sample)
        .filter(|&t| procs.iter().any(|p| p.due(t)))
        .count();
    busy as f64 / sample as f64 / scenario.rates.tick_s
}

/// A service whose publisher and some subscriber run on different hosts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Crossing {
    /// The iceoryx2 service name (also the Zenoh key expression).
    pub service: String,
    /// The vehicle it belongs to (`run` for the world).
    pub vehicle: String,
    /// `world` or `truth`.
    pub what: &'static str,
    /// Publishing host.
    pub from: usize,
    /// Subscribing hosts.
    pub to: Vec<usize>,
    /// Bytes of one sample on the wire.
    pub sample_bytes: usize,
    /// Samples per simulated second.
    pub rate_hz: f64,
}

/// What one directed link carries per simulated second.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LinkLoad {
    /// Messages.
    pub messages_per_s: f64,
    /// Bytes, framing included.
    pub bytes_per_s: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn scenario(vehicles: usize) -> Scenario {
        let o = crate::gen::GenOptions {
            vehicles,
            ..crate::gen::GenOptions::default()
        };
        Scenario::from_toml(&crate::gen::generate(&o).unwrap()).unwrap()
    }

    fn hosts(k: usize) -> HostsFile {
        HostsFile::numbered(
            &(0..k)
                .map(|i| format!("tcp/169.254.10.{}:7447", i + 1))
                .collect::<Vec<_>>(),
        )
    }

    #[test]
    fn a_hosts_file_parses_and_its_mistakes_are_named() {
        let f = HostsFile::parse(
            "[[host]]\nname = \"a\"\nendpoint = \"tcp/169.254.0.1:7447\"\nvehicles = [\"L\"]\n\
             [[host]]\nname = \"b\"\nendpoint = \"tcp/169.254.0.2:7447\"\n\
             [placement]\nworld = \"b\"\n",
        )
        .unwrap();
        assert_eq!(f.hosts.len(), 2);
        assert_eq!(f.placement.world.as_deref(), Some("b"));
        let err = |t: &str| HostsFile::parse(t).unwrap_err().to_string();
        assert!(err("").contains("at least one"), "{}", err(""));
        assert!(err("[[host]]\nname = \"a b\"\nendpoint = \"x\"\n").contains("a-z"));
        assert!(err(
            "[[host]]\nname = \"a\"\nendpoint = \"x\"\n[[host]]\nname = \"a\"\nendpoint = \"y\"\n"
        )
        .contains("twice"));
        assert!(err("[[host]]\nname = \"a\"\nendpoint = \"x\"\nport = 1\n").contains("port"));
    }

    #[test]
    fn hand_placed_vehicles_and_the_world_go_where_the_file_says() {
        let s = scenario(6);
        let mut f = hosts(3);
        f.hosts[2].vehicles = vec![s.vehicles[0].name.clone()];
        f.placement.world = Some("h2".into());
        let p = Placement::new(&f, &s).unwrap();
        assert_eq!(p.vehicle_host[0], 2);
        assert_eq!(p.world_host, 1);
        f.hosts[1].vehicles = vec![s.vehicles[0].name.clone()];
        assert!(matches!(
            Placement::new(&f, &s),
            Err(PlacementError::PlacedTwice { .. })
        ));
        f.hosts[1].vehicles = vec!["nobody".into()];
        assert!(matches!(
            Placement::new(&f, &s),
            Err(PlacementError::UnknownVehicle { .. })
        ));
        f.hosts[1].vehicles.clear();
        f.placement.world = Some("h9".into());
        assert!(matches!(
            Placement::new(&f, &s),
            Err(PlacementError::UnknownWorldHost(_))
        ));
    }

    #[test]
    fn only_truths_away_from_the_world_and_the_world_itself_cross() {
        let s = scenario(4);
        let p = Placement::new(&hosts(2), &s).unwrap();
        let c = p.crossings(&s, "r");
        let away = p.vehicle_host.iter().filter(|&&h| h != 0).count();
        assert!(away > 0 && away < 4, "{:?}", p.vehicle_host);
        assert_eq!(c.len(), 1 + away);
        assert_eq!(c[0].what, "world");
        assert_eq!(c[0].to, vec![1]);
        assert!(c[1..].iter().all(|c| c.what == "truth" && c.to == vec![0]));
        // One host: nothing crosses.
        assert!(Placement::new(&hosts(1), &s)
            .unwrap()
            .crossings(&s, "r")
            .is_empty());
    }

    #[test]
    fn the_world_on_the_wire_is_its_header_and_the_run_s_poses() {
        let pose = std::mem::size_of::<ipc_types::VehiclePose>();
        assert_eq!(world_wire_bytes(2) + pose, world_wire_bytes(3));
        assert_eq!(
            world_wire_bytes(ipc_types::MAX_VEHICLES),
            std::mem::size_of::<ipc_types::World>()
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// Automatic placement puts every vehicle on exactly one host,
        /// keeps the hosts' process counts within one vehicle's weight (plus
        /// the world) of each other, and keeps scenario order contiguous.
        #[test]
        fn automatic_placement_balances_the_hosts(n in 2usize..60, k in 1usize..9) {
            let s = scenario(n);
            let p = Placement::new(&hosts(k), &s).unwrap();
            prop_assert_eq!(p.vehicle_host.len(), n);
            prop_assert!(p.vehicle_host.windows(2).all(|w| w[0] <= w[1]));
            let mut load = vec![0usize; k];
            load[p.world_host] += 1;
            for (v, &h) in p.vehicle_host.iter().enumerate() {
                prop_assert!(h < k);
                load[h] += vehicle_weight(&s, v);
            }
            let (lo, hi) = (load.iter().min().unwrap(), load.iter().max().unwrap());
            prop_assert!(hi - lo <= 6 + 1 + 5, "loads {:?}", load);
            // Every process has one host, recorders excepted.
            for proc in s.processes() {
                let hosts_running = (0..k).filter(|&h| p.runs(&s, h, &proc)).count();
                if proc.kind == ProcessKind::Recorder {
                    prop_assert_eq!(hosts_running, k);
                } else {
                    prop_assert_eq!(hosts_running, 1);
                }
            }
        }
    }
}
