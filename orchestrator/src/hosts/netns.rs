//! Hosts that share nothing, on one machine: K Linux network namespaces,
//! each agent in a mount namespace of its own (private `/dev/shm` and
//! `/tmp`, so iceoryx2 cannot cross and only Zenoh can), joined by veth
//! links to a bridge in a switch namespace, addresses only on those links
//! (169.254.77.0/24, link-local). A coordinator namespace reaches them the
//! same way. Everything is removed when the [`TestNet`] is dropped, also
//! after a panic; namespaces a killed harness left are removed by the next.
//!
//! The links are QUIC (TLS 1.3) with mutual authentication, as a
//! deployment's are:
//! the net makes its own CA and a certificate per host and for the
//! coordinator (in a directory it removes), and every agent sees them at
//! `/mnt/certs`. [`TestNet::set_insecure`] makes them plain TCP.
//!
//! Needs root (CAP_SYS_ADMIN, CAP_NET_ADMIN), `ip` (iproute2), `unshare`
//! and `mount` (util-linux). The tests and `shoal bench hosts` use it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;

use super::placement::{HostsFile, TlsSection};
use super::tls::{self, CertRequest};
use crate::launch::os as sys;

/// Namespaces of this module start with it.
const PREFIX: &str = "shoal-net";
/// The port agents listen on.
pub const AGENT_PORT: u16 = 7447;
/// Where a host sees the net's certificates.
pub const CERTS_MOUNT: &str = "/mnt/certs";

static NEXT: AtomicU32 = AtomicU32::new(0);

/// One host of a [`TestNet`].
#[derive(Debug)]
pub struct NetHost {
    /// Its name (`h1`, ...).
    pub name: String,
    /// Its network namespace.
    pub netns: String,
    /// Its address on the link.
    pub addr: String,
    /// Its switch-side link (cut it to cut the host off).
    pub port: String,
    /// Its agent, once started.
    pub agent: Option<Child>,
}

/// K hosts and a coordinator namespace joined by a bridge.
#[derive(Debug)]
pub struct TestNet {
    switch: String,
    /// The coordinator's namespace.
    pub ctl: String,
    /// The hosts.
    pub hosts: Vec<NetHost>,
    /// Plain TCP ([`TestNet::set_insecure`]) instead of QUIC with the
    /// certificates.
    insecure: bool,
    /// The directory of the certificates (`h1`.. and `coordinator`),
    /// removed with the net.
    certs_dir: PathBuf,
}

fn ip(args: &[&str]) -> anyhow::Result<()> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .context("cannot run `ip` (install iproute2)")?;
    anyhow::ensure!(
        out.status.success(),
        "ip {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr).trim()
    );
    Ok(())
}

/// Namespaces whose harness (the pid in their name) is gone.
fn stale_namespaces() -> Vec<String> {
    let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
        return Vec::new();
    };
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|n| n.starts_with(PREFIX))
        .filter(|n| {
            n.split('-')
                .nth(2)
                .and_then(|p| p.parse::<i32>().ok())
                .is_some_and(|pid| !Path::new(&format!("/proc/{pid}")).exists())
        })
        .map(String::from)
        .collect()
}

/// Kills every process in network namespace `ns` (but this one).
fn kill_all_in(ns: &str) {
    let me = std::process::id() as i32;
    for pid in pids_in(ns).into_iter().filter(|p| *p != me) {
        sys::send_signal(pid, libc::SIGKILL);
    }
}

/// The processes in network namespace `ns`.
pub fn pids_in(ns: &str) -> Vec<i32> {
    Command::new("ip")
        .args(["netns", "pids", ns])
        .output()
        .map(|o| {
            String::from_utf8_lossy(&o.stdout)
                .split_whitespace()
                .filter_map(|p| p.parse().ok())
                .collect()
        })
        .unwrap_or_default()
}

impl TestNet {
    /// Makes `k` hosts, the coordinator's namespace and the switch.
    pub fn create(k: usize) -> anyhow::Result<Self> {
        anyhow::ensure!((1..=64).contains(&k), "1 to 64 hosts, not {k}");
        for ns in stale_namespaces() {
            kill_all_in(&ns);
            let _ = ip(&["netns", "del", &ns]);
        }
        let tag = format!(
            "{PREFIX}-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        let certs_dir = std::env::temp_dir().join(format!("{tag}-certs"));
        let mut net = Self {
            switch: format!("{tag}-sw"),
            ctl: format!("{tag}-ctl"),
            hosts: Vec::new(),
            insecure: false,
            certs_dir,
        };
        // From here on, Drop removes whatever was made.
        ip(&["netns", "add", &net.switch])?;
        ip(&["-n", &net.switch, "link", "add", "br0", "type", "bridge"])?;
        ip(&["-n", &net.switch, "link", "set", "br0", "up"])?;
        let ctl = net.ctl.clone();
        net.join(&ctl, "p0", "169.254.77.100")?;
        for h in 0..k {
            let name = format!("h{}", h + 1);
            let netns = format!("{tag}-{name}");
            let port = format!("p{}", h + 1);
            let addr = format!("169.254.77.{}", h + 1);
            net.hosts.push(NetHost {
                name,
                netns: netns.clone(),
                addr: addr.clone(),
                port: port.clone(),
                agent: None,
            });
            net.join(&netns, &port, &addr)?;
        }
        let requests: Vec<CertRequest> = net
            .hosts
            .iter()
            .map(|h| CertRequest {
                name: h.name.clone(),
                addresses: vec![h.addr.clone()],
            })
            .chain([CertRequest {
                name: tls::DEFAULT_COORDINATOR.into(),
                addresses: Vec::new(),
            }])
            .collect();
        tls::make_certs(&net.certs_dir, &requests, 0, 2)?;
        Ok(net)
    }

    /// Plain TCP from here on: agents started after this listen on tcp/
    /// with `--insecure`, and the hosts file allows it.
    pub fn set_insecure(&mut self) {
        self.insecure = true;
    }

    /// The directory of the net's certificates (`ca.pem`, `h1.pem`, …,
    /// `coordinator.pem` and their keys), while the links are TLS.
    pub fn certs(&self) -> Option<&Path> {
        (!self.insecure).then_some(self.certs_dir.as_path())
    }

    /// The directory the net made its certificates in (also after
    /// [`TestNet::set_insecure`]).
    pub fn certs_dir(&self) -> &Path {
        &self.certs_dir
    }

    /// Makes namespace `ns` with `eth0` at `addr`, linked to the switch by `port`.
    fn join(&self, ns: &str, port: &str, addr: &str) -> anyhow::Result<()> {
        ip(&["netns", "add", ns])?;
        ip(&[
            "-n",
            &self.switch,
            "link",
            "add",
            port,
            "type",
            "veth",
            "peer",
            "name",
            "eth0",
            "netns",
            ns,
        ])?;
        ip(&["-n", &self.switch, "link", "set", port, "master", "br0"])?;
        ip(&["-n", &self.switch, "link", "set", port, "up"])?;
        ip(&[
            "-n",
            ns,
            "addr",
            "add",
            &format!("{addr}/24"),
            "dev",
            "eth0",
        ])?;
        ip(&["-n", ns, "link", "set", "eth0", "up"])?;
        ip(&["-n", ns, "link", "set", "lo", "up"])?;
        Ok(())
    }

    /// The endpoint of host `h`'s agent (quic/, or tcp/ once insecure).
    pub fn endpoint(&self, h: usize) -> String {
        let scheme = if !self.insecure {
            tls::SECURE_SCHEME
        } else {
            "tcp"
        };
        self.endpoint_with(h, scheme)
    }

    /// Host `h`'s endpoint with `scheme` (`quic` or `tcp`).
    pub fn endpoint_with(&self, h: usize, scheme: &str) -> String {
        format!("{scheme}/{}:{AGENT_PORT}", self.hosts[h].addr)
    }

    /// A hosts file naming every host: over TLS with the net's
    /// certificates, or plain TCP allowed.
    pub fn hosts_file(&self) -> HostsFile {
        let mut f = HostsFile::numbered(
            &(0..self.hosts.len())
                .map(|h| self.endpoint(h))
                .collect::<Vec<_>>(),
        );
        if self.insecure {
            f.insecure = true;
        } else {
            f.tls = Some(TlsSection {
                certs: self.certs_dir.clone(),
                name: tls::DEFAULT_COORDINATOR.into(),
            });
        }
        f
    }

    /// Starts `shoal host` on host `h` ([`TestNet::spawn_in_host`]); its
    /// output goes to `log`. Returns at once; the agent answers when its
    /// liveliness token is up (the coordinator waits for it).
    pub fn start_agent(&mut self, h: usize, bin_dir: &Path, log: &Path) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.hosts[h].agent.is_none(),
            "host {} runs an agent already",
            self.hosts[h].name
        );
        let endpoint = self.endpoint(h);
        let name = self.hosts[h].name.clone();
        let mut args = vec![
            "host",
            "--bin-dir",
            "/mnt/bin",
            "--listen",
            &endpoint,
            "--name",
            &name,
        ];
        if !self.insecure {
            args.extend(["--certs", CERTS_MOUNT]);
        } else {
            args.push("--insecure");
        }
        let child = self.spawn_in_host(h, bin_dir, &args, log)?;
        self.hosts[h].agent = Some(child);
        Ok(())
    }

    /// Starts `shoal ARGS` on host `h`, in a mount namespace of its own
    /// with fresh `/dev/shm` and `/tmp`; the binaries in `bin_dir` are
    /// bind-mounted at `/mnt/bin` first (they may lie below `/tmp`), and
    /// the net's certificates at `/mnt/certs`. Its output goes to `log`.
    pub fn spawn_in_host(
        &self,
        h: usize,
        bin_dir: &Path,
        args: &[&str],
        log: &Path,
    ) -> anyhow::Result<Child> {
        let out = std::fs::File::create(log)
            .with_context(|| format!("cannot create {}", log.display()))?;
        let err = out.try_clone()?;
        let script = "set -e; mount -t tmpfs shoal-mnt /mnt; mkdir /mnt/bin /mnt/certs; \
             mount --bind \"$0\" /mnt/bin; mount --bind \"$SHOAL_NET_CERTS\" /mnt/certs; \
             mount -t tmpfs shoal-shm /dev/shm; \
             mount -t tmpfs shoal-tmp /tmp; exec /mnt/bin/shoal \"$@\"";
        Command::new("ip")
            .env("SHOAL_NET_CERTS", &self.certs_dir)
            .args(["netns", "exec", &self.hosts[h].netns])
            .args(["unshare", "--mount", "--propagation", "private", "--"])
            .args(["sh", "-c", script])
            .arg(bin_dir)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::from(out))
            .stderr(Stdio::from(err))
            .spawn()
            .context("cannot start a process on a host")
    }

    /// Starts an agent on every host, logs in `dir/<host>.agent.log`.
    pub fn start_agents(&mut self, bin_dir: &Path, dir: &Path) -> anyhow::Result<()> {
        for h in 0..self.hosts.len() {
            let log = dir.join(format!("{}.agent.log", self.hosts[h].name));
            self.start_agent(h, bin_dir, &log)?;
        }
        Ok(())
    }

    /// The pid of host `h`'s agent.
    pub fn agent_pid(&self, h: usize) -> Option<i32> {
        self.hosts[h].agent.as_ref().map(|c| c.id() as i32)
    }

    /// Sends `sig` to host `h`'s agent and, unless it is SIGSTOP/SIGCONT,
    /// reaps it (SIGKILL after `grace`).
    pub fn stop_agent(
        &mut self,
        h: usize,
        sig: i32,
        grace: Duration,
    ) -> Option<std::process::ExitStatus> {
        let host = &mut self.hosts[h];
        let mut child = host.agent.take()?;
        sys::send_signal(child.id() as i32, sig);
        let start = Instant::now();
        loop {
            if let Ok(Some(status)) = child.try_wait() {
                return Some(status);
            }
            if start.elapsed() > grace {
                let _ = child.kill();
                return child.wait().ok();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Moves the calling thread into the coordinator's namespace: the
    /// threads and processes it starts from here on (a Zenoh session's)
    /// reach the hosts. The guard moves it back home.
    pub fn enter_ctl(&self) -> anyhow::Result<CtlGuard> {
        let home = std::fs::File::open("/proc/thread-self/ns/net")
            .context("cannot open this thread's network namespace")?;
        let ctl = std::fs::File::open(format!("/var/run/netns/{}", self.ctl))
            .with_context(|| format!("no namespace {}", self.ctl))?;
        sys::enter_netns(&ctl).context("cannot enter the coordinator's namespace")?;
        Ok(CtlGuard { home })
    }

    /// A command run in the coordinator's namespace (same mounts as the
    /// caller: it writes the run's output where the caller can read it).
    pub fn in_ctl(&self, program: &Path) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.ctl]).arg(program);
        c
    }

    /// A command run in host `h`'s network namespace.
    pub fn in_host(&self, h: usize, program: &str) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.hosts[h].netns, program]);
        c
    }

    /// Every process in host `h`'s namespace other than its agent (after a
    /// run: orphans).
    pub fn others_on(&self, h: usize) -> Vec<i32> {
        let agent = self.agent_pid(h);
        pids_in(&self.hosts[h].netns)
            .into_iter()
            .filter(|p| Some(*p) != agent)
            .collect()
    }

    /// Files in host `h`'s own `/dev/shm` (the iceoryx2 domains: shared
    /// memory, and below `/dev/shm/shoal` their roots), read through its
    /// agent's root.
    pub fn shm_files(&self, h: usize) -> anyhow::Result<Vec<PathBuf>> {
        let pid = self
            .agent_pid(h)
            .with_context(|| format!("host {} has no agent", self.hosts[h].name))?;
        let root = PathBuf::from(format!("/proc/{pid}/root"));
        Ok(super::files_under(&root.join("dev/shm")))
    }

    /// Takes host `h`'s link down (`up = false`) or back up.
    pub fn set_link(&self, h: usize, up: bool) -> anyhow::Result<()> {
        ip(&[
            "-n",
            &self.switch,
            "link",
            "set",
            &self.hosts[h].port,
            if up { "up" } else { "down" },
        ])
    }

    fn teardown(&mut self) {
        for h in 0..self.hosts.len() {
            self.stop_agent(h, libc::SIGTERM, Duration::from_secs(5));
        }
        let all: Vec<String> = self
            .hosts
            .iter()
            .map(|h| h.netns.clone())
            .chain([self.ctl.clone(), self.switch.clone()])
            .collect();
        for ns in &all {
            kill_all_in(ns);
        }
        for ns in &all {
            let _ = ip(&["netns", "del", ns]);
        }
        let _ = std::fs::remove_dir_all(&self.certs_dir);
    }
}

/// Holds the calling thread in the coordinator's namespace (see
/// [`TestNet::enter_ctl`]); dropped, it moves it back.
#[derive(Debug)]
pub struct CtlGuard {
    home: std::fs::File,
}

impl Drop for CtlGuard {
    fn drop(&mut self) {
        if let Err(e) = sys::enter_netns(&self.home) {
            tracing::warn!("cannot return to this process's network namespace: {e}");
        }
    }
}

/// `shoal run --hosts netns:K`: K hosts made here, their agents up, a hosts
/// file naming them written to `hosts_toml`, and the calling thread in the
/// coordinator's namespace. Drop the guard before the net.
pub fn local_hosts(
    k: usize,
    bin_dir: &Path,
    logs: &Path,
    hosts_toml: &Path,
    insecure: bool,
) -> anyhow::Result<(TestNet, CtlGuard)> {
    anyhow::ensure!(
        (1..=16).contains(&k),
        "netns:K takes 1 to 16 hosts, not {k}"
    );
    let mut net = TestNet::create(k)
        .context("netns:K makes network namespaces (run as root, with iproute2 and util-linux)")?;
    std::fs::create_dir_all(logs)?;
    if insecure {
        net.set_insecure();
    }
    net.start_agents(bin_dir, logs)?;
    std::fs::write(hosts_toml, toml::to_string(&net.hosts_file())?)?;
    let guard = net.enter_ctl()?;
    Ok((net, guard))
}

/// The K of a `netns:K` hosts argument; `None` for a file's path.
pub fn parse_local(spec: &str) -> Option<Result<usize, String>> {
    let k = spec.strip_prefix("netns:")?;
    Some(
        k.parse::<usize>()
            .ok()
            .filter(|k| (1..=16).contains(k))
            .ok_or_else(|| format!("netns:K takes a number of hosts from 1 to 16, not {k:?}")),
    )
}

impl Drop for TestNet {
    fn drop(&mut self) {
        self.teardown();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn netns_k_names_a_number_of_hosts_and_anything_else_is_a_file() {
        assert_eq!(parse_local("netns:3"), Some(Ok(3)));
        assert!(matches!(parse_local("netns:0"), Some(Err(_))));
        assert!(matches!(parse_local("netns:17"), Some(Err(_))));
        assert!(matches!(parse_local("netns:x"), Some(Err(_))));
        assert_eq!(parse_local("hosts.toml"), None);
        assert_eq!(parse_local("runs/netns.toml"), None);
    }
}
