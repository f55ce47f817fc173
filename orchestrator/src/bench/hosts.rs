//! `shoal bench hosts`: what spreading a run over hosts costs, measured on
//! hosts that share nothing (network namespaces with their own mounts, see
//! [`crate::hosts::netns`]). Needs root, `ip` and `unshare`.
//!
//! 1. **The cross-host hop.** Ping-pong between host h1 and host h2 through
//!    a Zenoh router in the coordinator's namespace (the star every run
//!    uses): raw Zenoh (a put, a callback into the main thread, a put back)
//!    against shoal's hop (an iceoryx2 sample taken by the bridge, trimmed,
//!    put on Zenoh, received, written into iceoryx2 on the other host and
//!    read there, and back the same way), and raw Zenoh on a direct link
//!    between the two for reference. One-way latency is half the round
//!    trip; the modes alternate (A B C A B C ...) so a ratio holds on a busy
//!    machine. Sizes: a truth (232 B) and the world of `--vehicles`.
//! 2. **The lockstep tick**: the paper scenario (`--tick-duration` s) on one
//!    host as `shoal run` runs it, and over 1, 2 and 4 agents: real-time
//!    factor, wall time per busy tick, CPU per vehicle-second.
//! 3. **A large group**: a generated scenario of `--vehicles` run to its
//!    end on one host and over `--hosts` agents, side by side.
//! 4. **On paper**: 1,000 vehicles over 16 hosts, from the figures above.
//!
//! Every figure is printed and written to `OUT/hosts.json`; nothing fails
//! on a figure.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::{Duration, Instant};

use anyhow::Context;
use ipc_types::Sample;
use serde_json::{json, Value};
use zenoh::Wait;

use super::run::fmt_num;
use crate::hosts::bridge::{Bridge, Inbound};
use crate::hosts::netns::TestNet;
use crate::hosts::placement::{world_wire_bytes, Crossing};
use crate::hosts::tls::{Identity, Security};
use crate::hosts::wire;
use crate::launch;

/// `shoal bench hosts`.
#[derive(Debug, clap::Args)]
pub struct HostsBenchCmd {
    /// Round trips per mode and size (split over the alternations).
    #[arg(long, default_value_t = 4000)]
    rounds: usize,
    /// Times each mode of the hop runs, interleaved (A B C A B C ...).
    #[arg(long, default_value_t = 8)]
    alternations: usize,
    /// Let idle CPUs sleep during the hop (by default the bench holds
    /// `/dev/cpu_dma_latency` at 0, as cyclictest does, so that a wake-up
    /// from a halted virtual CPU does not swamp the hop).
    #[arg(long)]
    idle_sleep: bool,
    /// Simulated seconds of the paper scenario for the tick's cost.
    #[arg(long, default_value_t = 60.0, value_parser = crate::cli::parse_duration)]
    tick_duration: f64,
    /// Vehicles of the large group.
    #[arg(long, default_value_t = 200)]
    vehicles: usize,
    /// Hosts of the large group.
    #[arg(long, default_value_t = 4)]
    hosts: usize,
    /// Simulated seconds of the large group (default: the generated
    /// scenario's own, run to its end).
    #[arg(long, value_parser = crate::cli::parse_duration)]
    large_duration: Option<f64>,
    /// Skip the large group (the hop and the tick only).
    #[arg(long)]
    skip_large: bool,
    /// The hop only (no runs).
    #[arg(long)]
    hop_only: bool,
    /// Output directory (default: runs/bench-hosts-<unix time>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Directory holding the service binaries (default: next to `shoal`).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
}

/// One end of the hop benchmark, run inside a host (`shoal bench hop-peer`).
#[derive(Debug, clap::Args)]
pub struct HopPeerCmd {
    /// What this process is.
    #[arg(long, value_enum)]
    role: HopRole,
    /// Raw Zenoh, or shoal's bridge between iceoryx2 on both hosts.
    #[arg(long, value_enum, default_value = "raw")]
    mode: HopMode,
    /// Bytes of a sample on the wire.
    #[arg(long, default_value_t = 232)]
    size: usize,
    /// Zenoh endpoints to listen on.
    #[arg(long)]
    listen: Vec<String>,
    /// Zenoh endpoints to connect to.
    #[arg(long)]
    connect: Vec<String>,
    /// Round trips to time (ping), after 200 not timed.
    #[arg(long, default_value_t = 1000)]
    rounds: usize,
    /// TLS with these certificates (as `shoal certs` writes them) and the
    /// access control of a run; plain TCP without.
    #[arg(long, value_name = "DIR")]
    certs: Option<PathBuf>,
    /// This peer's certificate name (with --certs).
    #[arg(long, default_value = crate::hosts::tls::DEFAULT_COORDINATOR)]
    name: String,
}

/// The hop under access control: the router answers only the two hosts
/// (`h1`, `h2`); a peer answers only the router, as an agent answers only
/// its coordinator.
fn hop_security(cmd: &HopPeerCmd) -> (Security, Option<Value>) {
    let Some(dir) = &cmd.certs else {
        return (Security::Insecure, None);
    };
    let id = Identity::in_dir(dir, &cmd.name);
    let names = if cmd.role == HopRole::Router {
        vec!["h1".to_string(), "h2".to_string()]
    } else {
        vec![crate::hosts::tls::DEFAULT_COORDINATOR.to_string()]
    };
    let acl = crate::hosts::tls::answer_only(&names);
    (Security::Tls(id), Some(acl))
}

/// A hop benchmark process's role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum HopRole {
    /// The router between the two hosts (the coordinator's place).
    Router,
    /// Sends, times the answer.
    Ping,
    /// Answers.
    Echo,
}

/// What carries the hop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum HopMode {
    /// Zenoh put and subscriber callback.
    Raw,
    /// iceoryx2 on each host, shoal's bridge in between.
    Shoal,
}

const WARMUP: usize = 200;
const PING: &str = "shoal/benchhop/ping/truth";
const PONG: &str = "shoal/benchhop/pong/truth";

/// Runs one end of the hop benchmark.
pub fn hop_peer(cmd: HopPeerCmd) -> anyhow::Result<()> {
    let _ = launch::termination_requested();
    let (security, acl) = hop_security(&cmd);
    let config = || wire::router_config(&cmd.listen, &cmd.connect, &security, acl.as_ref());
    if cmd.role == HopRole::Router {
        let _session = zenoh::open(config()?)
            .wait()
            .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
        while launch::termination_requested().is_none() {
            std::thread::sleep(Duration::from_millis(50));
        }
        return Ok(());
    }
    anyhow::ensure!(cmd.size >= 16, "--size must be at least 16 bytes");
    let session = zenoh::open(config()?)
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    if cmd.size <= std::mem::size_of::<ipc_types::Truth>() {
        hop::<ipc_types::Truth>(&cmd, &session, "truth")
    } else {
        hop::<ipc_types::World>(&cmd, &session, "world")
    }
}

/// The round number a sample carries in its first 8 bytes.
fn round_of(bytes: &[u8]) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?))
}

/// Writes round `r` and `size - 8` bytes of 0xA5 over `out`, zeros after.
fn fill(out: &mut [u8], r: u64, size: usize) {
    out.fill(0);
    out[..8].copy_from_slice(&r.to_le_bytes());
    let end = size.min(out.len());
    out[8..end].fill(0xA5);
}

/// The two ends of one side of the hop.
enum Ends<T: Sample> {
    /// A Zenoh publisher; the subscriber feeds the channel.
    Raw {
        publisher: zenoh::pubsub::Publisher<'static>,
        _subscriber: zenoh::pubsub::Subscriber<()>,
    },
    /// iceoryx2 on this host, the bridge between it and Zenoh.
    Shoal {
        bridge: Bridge,
        publisher: shoal_runtime::Publisher<T>,
        subscriber: shoal_runtime::Subscriber<T>,
        _node: iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    },
}

impl<T: Sample> Ends<T> {
    /// Sends round `r` of `size` bytes, or `echo` as it came.
    fn send(&mut self, r: u64, size: usize, echo: Option<&[u8]>) -> anyhow::Result<()> {
        match self {
            Ends::Raw { publisher, .. } => {
                let bytes = match echo {
                    Some(b) => b.to_vec(),
                    None => {
                        let mut b = vec![0u8; size];
                        fill(&mut b, r, size);
                        b
                    }
                };
                publisher
                    .put(bytes)
                    .wait()
                    .map_err(|e| anyhow::anyhow!("zenoh: {e}"))
            }
            Ends::Shoal {
                bridge, publisher, ..
            } => {
                publisher.publish_stamped_in_place(|t| match echo {
                    Some(b) => {
                        wire::untrim(b, bytemuck::bytes_of_mut(t));
                    }
                    None => fill(bytemuck::bytes_of_mut(t), r, size),
                })?;
                bridge.forward()
            }
        }
    }

    /// Takes what arrived as a reader on this host does (shoal: through
    /// iceoryx2) and returns its round; with `echo`, sends it back as it
    /// came (shoal: from the taken sample into a loaned one, as a process
    /// that answers would).
    fn arrive(&mut self, index: usize, bytes: Vec<u8>, echo: bool) -> anyhow::Result<Option<u64>> {
        match self {
            Ends::Raw { .. } => {
                let round = round_of(&bytes);
                if echo {
                    self.send(0, 0, Some(&bytes))?;
                }
                Ok(round)
            }
            Ends::Shoal {
                bridge,
                subscriber,
                publisher,
                ..
            } => {
                bridge.receive(index, &bytes)?;
                let mut round = None;
                let mut sent = Ok(());
                subscriber.take_ready_in_place(&shoal_runtime::StepContext::any_time(), |v| {
                    let got = bytemuck::bytes_of(v);
                    round = round_of(got);
                    if echo {
                        sent = publisher.publish_stamped_in_place(|t| {
                            bytemuck::bytes_of_mut(t).copy_from_slice(got);
                        });
                    }
                })?;
                sent?;
                if echo {
                    bridge.forward()?;
                }
                Ok(round)
            }
        }
    }
}

fn hop<T: Sample>(
    cmd: &HopPeerCmd,
    session: &zenoh::Session,
    what: &'static str,
) -> anyhow::Result<()> {
    let (tx, rx) = mpsc::channel::<Inbound>();
    let ping_side = cmd.role == HopRole::Ping;
    let zerr = |e: zenoh::Error| anyhow::anyhow!("zenoh: {e}");
    let mut ends: Ends<T> = match cmd.mode {
        HopMode::Raw => {
            // The subscriber hands samples to the main thread, as the bridge does.
            let (listen_to, say_on) = if ping_side {
                (PONG, PING)
            } else {
                (PING, PONG)
            };
            let tx = tx.clone();
            let subscriber = session
                .declare_subscriber(listen_to)
                .callback(move |s| {
                    let _ = tx.send(Inbound::Sample {
                        index: 0,
                        bytes: s.payload().to_bytes().into_owned(),
                    });
                })
                .wait()
                .map_err(zerr)?;
            let publisher = session
                .declare_publisher(say_on)
                .congestion_control(zenoh::qos::CongestionControl::Block)
                .wait()
                .map_err(zerr)?;
            Ends::Raw {
                publisher,
                _subscriber: subscriber,
            }
        }
        HopMode::Shoal => {
            let node =
                shoal_runtime::domain_node("benchhop", if ping_side { "ping" } else { "echo" })?;
            let crossing = |service: &str, from: usize| Crossing {
                service: service.to_string(),
                vehicle: "bench".into(),
                what,
                from,
                to: vec![1 - from],
                sample_bytes: cmd.size,
                rate_hz: 0.0,
            };
            let crossings = [crossing(PING, 0), crossing(PONG, 1)];
            // The services are sized for the readers they have (the
            // bridge and the reader here), as a run sizes its own: a world
            // sized for 200 vehicles has 400 reader slots, which iceoryx2
            // scans on every publish, on one host as on several.
            let readers = 1;
            let bridge = Bridge::open(
                session,
                &node,
                &crossings,
                usize::from(!ping_side),
                readers,
                &[],
                &tx,
            )?;
            let limits = if what == "world" {
                shoal_runtime::ChannelLimits::world(readers)
            } else {
                shoal_runtime::ChannelLimits::vehicle()
            };
            let (out_service, in_service) = if ping_side {
                (PING, PONG)
            } else {
                (PONG, PING)
            };
            Ends::Shoal {
                bridge,
                publisher: shoal_runtime::node_publisher::<T, _>(&node, out_service, &limits)?,
                subscriber: shoal_runtime::node_subscriber::<T, _>(&node, in_service, &limits, 4)?,
                _node: node,
            }
        }
    };
    if !ping_side {
        loop {
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(Inbound::Sample { index, bytes }) => {
                    ends.arrive(index, bytes, true)?;
                }
                Ok(_) => {}
                Err(RecvTimeoutError::Timeout) => {
                    if launch::termination_requested().is_some() {
                        return Ok(());
                    }
                }
                Err(RecvTimeoutError::Disconnected) => return Ok(()),
            }
        }
    }
    let mut one_way_ns = Vec::with_capacity(cmd.rounds);
    for r in 0..(WARMUP + cmd.rounds) as u64 {
        let t0 = Instant::now();
        ends.send(r, cmd.size, None)?;
        let mut tries = 0;
        loop {
            match rx.recv_timeout(Duration::from_millis(200)) {
                Ok(Inbound::Sample { index, bytes }) => {
                    if ends.arrive(index, bytes, false)? == Some(r) {
                        break;
                    }
                }
                Ok(_) => {}
                // Before the route exists a ping is lost: send it again.
                Err(RecvTimeoutError::Timeout) if (r as usize) < WARMUP && tries < 150 => {
                    tries += 1;
                    ends.send(r, cmd.size, None)?;
                }
                Err(e) => anyhow::bail!("round {r}: no answer ({e})"),
            }
        }
        if r as usize >= WARMUP {
            one_way_ns.push(t0.elapsed().as_nanos() as f64 / 2.0);
        }
    }
    drop(ends);
    println!("{}", json!({ "one_way_ns": one_way_ns }));
    Ok(())
}

/// An error once SIGINT or SIGTERM came.
fn stop_if_asked() -> anyhow::Result<()> {
    match launch::termination_requested() {
        Some(sig) => Err(launch::RunError::Interrupted(sig).into()),
        None => Ok(()),
    }
}

/// A percentile of `v` (sorted in place), µs.
fn pct_us(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let i = ((v.len() - 1) as f64 * p).round() as usize;
    v[i] / 1e3
}

/// Stops a helper process: SIGTERM, then SIGKILL after 5 s.
fn stop(mut child: Child) {
    launch::os::send_signal(child.id() as i32, libc::SIGTERM);
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// One ping-pong measurement of `mode` (`direct`: no router; `tls`: TLS
/// and access control, else plain TCP) with `size` bytes; returns the
/// one-way latencies, ns.
#[allow(clippy::too_many_arguments)]
fn measure_hop(
    net: &TestNet,
    bin: &Path,
    dir: &Path,
    mode: HopMode,
    direct: bool,
    tls: bool,
    size: usize,
    rounds: usize,
) -> anyhow::Result<Vec<f64>> {
    let scheme = if tls {
        crate::hosts::tls::SECURE_SCHEME
    } else {
        "tcp"
    };
    let (e1, e2) = (net.endpoint_with(0, scheme), net.endpoint_with(1, scheme));
    let ctl_certs = net.certs_dir().display().to_string();
    let certs = |args: &mut Vec<&str>, dir: &'static str, name: &'static str| {
        if tls {
            args.extend(["--certs", dir, "--name", name]);
        }
    };
    let mut router_args = vec![
        "bench",
        "hop-peer",
        "--role",
        "router",
        "--connect",
        e1.as_str(),
        "--connect",
        e2.as_str(),
    ];
    if tls {
        router_args.extend(["--certs", ctl_certs.as_str()]);
    }
    let router = if direct {
        None
    } else {
        Some(
            net.in_ctl(&bin.join("shoal"))
                .args(&router_args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .context("router")?,
        )
    };
    let mode_s = match mode {
        HopMode::Raw => "raw",
        HopMode::Shoal => "shoal",
    };
    let size_s = size.to_string();
    let rounds_s = rounds.to_string();
    let mut echo_args = vec![
        "bench", "hop-peer", "--role", "echo", "--mode", mode_s, "--size", &size_s, "--listen", &e2,
    ];
    certs(&mut echo_args, crate::hosts::netns::CERTS_MOUNT, "h2");
    let echo = net.spawn_in_host(1, bin, &echo_args, &dir.join("echo.log"))?;
    let ping_log = dir.join("ping.log");
    let mut args = vec![
        "bench", "hop-peer", "--role", "ping", "--mode", mode_s, "--size", &size_s, "--listen",
        &e1, "--rounds", &rounds_s,
    ];
    if direct {
        args.extend(["--connect", e2.as_str()]);
    }
    certs(&mut args, crate::hosts::netns::CERTS_MOUNT, "h1");
    let mut ping = net.spawn_in_host(0, bin, &args, &ping_log)?;
    let status = ping.wait()?;
    stop(echo);
    if let Some(r) = router {
        stop(r);
    }
    let text = std::fs::read_to_string(&ping_log)?;
    anyhow::ensure!(status.success(), "the ping failed:\n{text}");
    let line = text
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .context("no figures from the ping")?;
    let v: Value = serde_json::from_str(line)?;
    Ok(v["one_way_ns"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default())
}

/// The figures of one run's summary.json (and hosts.json if any).
fn run_figures(out: &Path, vehicles: usize) -> anyhow::Result<Value> {
    let s: Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("summary.json"))
            .with_context(|| format!("no summary in {}", out.display()))?,
    )?;
    let sim = s["sim_time_s"].as_f64().unwrap_or(f64::NAN);
    let wall = s["wall_time_s"].as_f64().unwrap_or(f64::NAN);
    let cpu: f64 = s["cpu_time_s"]
        .as_object()
        .map(|m| m.values().filter_map(Value::as_f64).sum())
        .unwrap_or(f64::NAN);
    let ticks = s["ticks"].as_f64().unwrap_or(f64::NAN);
    let hosts: Value = std::fs::read_to_string(out.join("hosts.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(Value::Null);
    Ok(json!({
        "real_time_factor": s["real_time_factor"],
        "wall_time_s": wall,
        "sim_time_s": sim,
        "cpu_s": cpu,
        "cpu_ms_per_vehicle_s": cpu * 1e3 / (vehicles as f64 * sim),
        "busy_ticks": ticks,
        "pass": s["verdict"]["pass"],
        "dropped": s["recording"]["dropped"],
        "hosts": hosts["hosts"],
    }))
}

/// Runs `scenario` on one host (`hosts = None`) or over the hosts file, into `out`.
fn run_one(
    net: &TestNet,
    bin: &Path,
    scenario: &Path,
    hosts: Option<&Path>,
    out: &Path,
) -> anyhow::Result<()> {
    let mut cmd = match hosts {
        None => Command::new(bin.join("shoal")),
        Some(_) => net.in_ctl(&bin.join("shoal")),
    };
    cmd.args(["run", "--quiet", "--force"])
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .arg("--bin-dir")
        .arg(bin);
    if let Some(h) = hosts {
        cmd.arg("--hosts").arg(h);
    }
    let o = cmd.stdout(Stdio::null()).output()?;
    anyhow::ensure!(
        o.status.success(),
        "run of {} failed: {}",
        scenario.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    Ok(())
}

/// A hosts file of the first `k` hosts of `net`, written into `dir`.
fn hosts_file(net: &TestNet, k: usize, dir: &Path) -> anyhow::Result<PathBuf> {
    let mut f = net.hosts_file();
    f.hosts.truncate(k);
    let p = dir.join(format!("hosts{k}.toml"));
    std::fs::write(&p, toml::to_string(&f)?)?;
    Ok(p)
}

/// Runs the benchmark.
pub fn run(cmd: HostsBenchCmd) -> anyhow::Result<()> {
    // Ctrl-C or SIGTERM ends the step under way, then the bench, so that
    // the namespaces and their agents are removed.
    let _ = launch::termination_requested();
    let bin = launch::bin_dir_or_default(cmd.bin_dir.clone())?;
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let out = cmd
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("runs/bench-hosts-{secs}")));
    std::fs::create_dir_all(&out)?;
    let out = out.canonicalize()?;
    let k_large = cmd.hosts.clamp(1, 16);
    let mut net = TestNet::create(4.max(k_large))?;
    let mut report = json!({ "load_average": launch::os::load_average() });

    // 1. The hop.
    println!(
        "cross-host hop, h1 <-> h2, one way (round trip / 2), {} round trips per mode:",
        cmd.rounds
    );
    println!(
        "  {:>8}  {:<22} {:>9} {:>9} {:>9}",
        "bytes", "mode", "p50 us", "p99 us", "mean us"
    );
    let world = world_wire_bytes(cmd.vehicles.min(ipc_types::MAX_VEHICLES));
    let mut hops = Vec::new();
    let qos = if cmd.idle_sleep {
        None
    } else {
        launch::os::hold_cpu_latency()
    };
    println!(
        "  (idle CPUs {} during the hop)",
        if qos.is_some() {
            "poll: /dev/cpu_dma_latency held at 0"
        } else {
            "may sleep"
        }
    );
    let hop_dir = out.join("hop");
    std::fs::create_dir_all(&hop_dir)?;
    // Plain TCP (--insecure) first, then what a run uses: QUIC (TLS 1.3)
    // with mutual authentication and access control.
    let modes = [
        ("zenoh, via router", HopMode::Raw, false, false),
        ("shoal, via router", HopMode::Shoal, false, false),
        ("zenoh, direct link", HopMode::Raw, true, false),
        ("shoal, via router, QUIC", HopMode::Shoal, false, true),
    ];
    let mut ratios_out = Vec::new();
    for size in [232usize, world] {
        let mut all: Vec<Vec<f64>> = vec![Vec::new(); modes.len()];
        // A B C A B C ...: each mode in turn, so that a drift of the
        // machine falls on all alike.
        let alternations = cmd.alternations.max(1);
        // Shoal's p50 over raw Zenoh's, per alternation (side by side).
        let mut ratios = Vec::with_capacity(alternations);
        // Shoal over TLS against shoal over TCP, per alternation.
        let mut tls_ratios = Vec::with_capacity(alternations);
        for _ in 0..alternations {
            let mut p50_here = [f64::NAN; 4];
            for (i, (_, mode, direct, tls)) in modes.iter().enumerate() {
                stop_if_asked()?;
                let mut v = measure_hop(
                    &net,
                    &bin,
                    &hop_dir,
                    *mode,
                    *direct,
                    *tls,
                    size,
                    (cmd.rounds / alternations).max(1),
                )?;
                all[i].extend_from_slice(&v);
                p50_here[i] = pct_us(&mut v, 0.5);
            }
            ratios.push(p50_here[1] / p50_here[0]);
            tls_ratios.push(p50_here[3] / p50_here[1]);
        }
        let mut p50 = Vec::new();
        for (i, (name, _, _, _)) in modes.iter().enumerate() {
            let v = &mut all[i];
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64 / 1e3;
            let (a, b) = (pct_us(v, 0.5), pct_us(v, 0.99));
            p50.push(a);
            println!(
                "  {size:>8}  {name:<22} {:>9} {:>9} {:>9}",
                fmt_num(a),
                fmt_num(b),
                fmt_num(mean)
            );
            hops.push(
                json!({ "bytes": size, "mode": name, "p50_us": a, "p99_us": b, "mean_us": mean }),
            );
        }
        let pooled = p50[1] / p50[0];
        let median = pct_us(&mut ratios, 0.5) * 1e3;
        println!(
            "  {size:>8}  shoal / zenoh via the same router: {} (p50 of all), median of the {alternations} side-by-side ratios {} (range {} - {})",
            fmt_num(pooled),
            fmt_num(median),
            fmt_num(ratios.first().copied().unwrap_or(f64::NAN)),
            fmt_num(ratios.last().copied().unwrap_or(f64::NAN)),
        );
        let tls_pooled = p50[3] / p50[1];
        let tls_median = pct_us(&mut tls_ratios, 0.5) * 1e3;
        println!(
            "  {size:>8}  shoal QUIC+TLS / shoal TCP (goal <= 1.15): {} (p50 of all), median of the {alternations} side-by-side ratios {} (range {} - {})",
            fmt_num(tls_pooled),
            fmt_num(tls_median),
            fmt_num(tls_ratios.first().copied().unwrap_or(f64::NAN)),
            fmt_num(tls_ratios.last().copied().unwrap_or(f64::NAN)),
        );
        ratios_out.push(json!({ "bytes": size, "pooled_p50_ratio": pooled, "median_ratio": median, "ratios": ratios,
            "tls_pooled_p50_ratio": tls_pooled, "tls_median_ratio": tls_median, "tls_ratios": tls_ratios }));
    }
    report["hop_ratio"] = json!(ratios_out);
    report["hop"] = json!(hops);
    report["hop_idle_poll"] = json!(qos.is_some());
    drop(qos);
    if cmd.hop_only {
        std::fs::write(
            out.join("hosts.json"),
            serde_json::to_string_pretty(&report)?,
        )?;
        println!("\n{}", out.join("hosts.json").display());
        return Ok(());
    }

    // 2. The lockstep tick.
    net.start_agents(&bin, &out)?;
    let paper = out.join("paper.toml");
    let mut sc = crate::preflight::load_scenario(&None)?;
    sc.duration_s = cmd.tick_duration;
    std::fs::write(&paper, sc.to_toml()?)?;
    let n_paper = sc.vehicles.len();
    println!(
        "\nlockstep tick, paper scenario ({} vehicles, {} s simulated):",
        n_paper, cmd.tick_duration
    );
    println!(
        "  {:<10} {:>8} {:>14} {:>16} {:>10}",
        "hosts", "RTF", "us/busy tick", "CPU ms/veh-s", "agents s"
    );
    let mut ticks = Vec::new();
    for k in [0usize, 1, 2, 4] {
        let dir = out.join(format!("tick-k{k}"));
        let hf = if k == 0 {
            None
        } else {
            Some(hosts_file(&net, k, &out)?)
        };
        stop_if_asked()?;
        run_one(&net, &bin, &paper, hf.as_deref(), &dir)?;
        let f = run_figures(&dir, n_paper)?;
        let busy = crate::hosts::placement::lockstep_ticks_per_sim_s(&sc) * cmd.tick_duration;
        let us_tick = f["wall_time_s"].as_f64().unwrap_or(f64::NAN) * 1e6 / busy;
        let agents: f64 = f["hosts"]
            .as_array()
            .map(|a| a.iter().filter_map(|h| h["agent_cpu_s"].as_f64()).sum())
            .unwrap_or(0.0);
        let label = if k == 0 {
            "one (run)".to_string()
        } else {
            k.to_string()
        };
        println!(
            "  {label:<10} {:>8} {:>14} {:>16} {:>10}",
            fmt_num(f["real_time_factor"].as_f64().unwrap_or(f64::NAN)),
            fmt_num(us_tick),
            fmt_num(f["cpu_ms_per_vehicle_s"].as_f64().unwrap_or(f64::NAN)),
            fmt_num(agents)
        );
        ticks.push(json!({ "hosts": k, "us_per_busy_tick": us_tick, "run": f }));
    }
    report["tick"] = json!(ticks);

    // 3. A large group.
    let mut large = Value::Null;
    if !cmd.skip_large {
        let text = crate::gen::generate(&crate::gen::GenOptions {
            vehicles: cmd.vehicles,
            seed: 1,
            ..crate::gen::GenOptions::default()
        })?;
        let mut s = shoal_scenario::Scenario::from_toml(&text)?;
        if let Some(d) = cmd.large_duration {
            s.duration_s = d;
        }
        let path = out.join("large.toml");
        std::fs::write(&path, s.to_toml()?)?;
        println!(
            "\n{} vehicles, {} s simulated, one host against {k_large} hosts:",
            cmd.vehicles, s.duration_s
        );
        println!(
            "  {:<10} {:>8} {:>16} {:>8} {:>10}",
            "hosts", "RTF", "CPU ms/veh-s", "pass", "dropped"
        );
        let mut rows = Vec::new();
        for k in [0usize, k_large] {
            let dir = out.join(format!("large-k{k}"));
            let hf = if k == 0 {
                None
            } else {
                Some(hosts_file(&net, k, &out)?)
            };
            stop_if_asked()?;
            run_one(&net, &bin, &path, hf.as_deref(), &dir)?;
            let f = run_figures(&dir, cmd.vehicles)?;
            println!(
                "  {:<10} {:>8} {:>16} {:>8} {:>10}",
                if k == 0 {
                    "one (run)".to_string()
                } else {
                    k.to_string()
                },
                fmt_num(f["real_time_factor"].as_f64().unwrap_or(f64::NAN)),
                fmt_num(f["cpu_ms_per_vehicle_s"].as_f64().unwrap_or(f64::NAN)),
                f["pass"],
                f["dropped"]
            );
            rows.push(json!({ "hosts": k, "run": f }));
        }
        large = json!(rows);
    }
    report["large"] = large;

    // 4. On paper: 1,000 vehicles over 16 hosts.
    report["projection"] = projection(&report);
    std::fs::write(
        out.join("hosts.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    println!("\n{}", out.join("hosts.json").display());
    Ok(())
}

/// 1,000 vehicles over 16 hosts of 2 cores, from the measured figures.
fn projection(report: &Value) -> Value {
    let (n, k) = (1000.0f64, 16.0f64);
    let rates = shoal_scenario::Scenario::from_toml(shoal_scenario::PAPER_TOML)
        .map(|s| s.rates)
        .ok();
    let (world_hz, plant_hz, tick_s) = rates
        .as_ref()
        .map_or((10.0, 10.0, 0.02), |r| (r.world_hz, r.plant_hz, r.tick_s));
    // The world as the bridge sends it: header + 80 B per vehicle.
    let world_bytes = 48.0 + 80.0 * n;
    let truth_bytes = std::mem::size_of::<ipc_types::Truth>() as f64;
    let overhead = 16.0;
    let busy_ticks_per_s = 1.0 / tick_s;
    // Every host but the world's gets the world; the world's host gets the
    // others' truths.
    let down_bytes = world_hz * (world_bytes + overhead) + busy_ticks_per_s * (8.0 + overhead);
    let up_bytes =
        plant_hz * (n / k) * (truth_bytes + overhead) + busy_ticks_per_s * (8.0 + overhead);
    let world_host_down = plant_hz * n * (k - 1.0) / k * (truth_bytes + overhead);
    let router_out = down_bytes * (k - 1.0) + world_host_down;
    // CPU: the largest measured run's per-vehicle cost on 2 cores per host.
    let cpu_ms = report["large"]
        .as_array()
        .and_then(|a| a.last())
        .and_then(|r| r["run"]["cpu_ms_per_vehicle_s"].as_f64())
        .or_else(|| {
            report["tick"]
                .as_array()
                .and_then(|a| a.last())
                .and_then(|r| r["run"]["cpu_ms_per_vehicle_s"].as_f64())
        })
        .unwrap_or(f64::NAN);
    let cpu_rtf = 2.0 * 1e3 / (cpu_ms * n / k);
    // The barrier: one round trip per busy tick, from the measured hop.
    let hop_us = report["hop"]
        .as_array()
        .and_then(|h| h.iter().find(|x| x["mode"] == "shoal, via router"))
        .and_then(|x| x["p50_us"].as_f64())
        .unwrap_or(f64::NAN);
    let barrier_rtf = 1.0 / (busy_ticks_per_s * 2.0 * hop_us * 1e-6);
    let rtf = cpu_rtf.min(barrier_rtf);
    println!("\n1,000 vehicles over 16 hosts of 2 cores, projected from the figures above:");
    println!(
        "  link of a host: down {} kB/s (the world at {world_hz} Hz, {world_bytes:.0} B), up {} kB/s (its truths)",
        fmt_num(down_bytes / 1e3),
        fmt_num(up_bytes / 1e3)
    );
    println!(
        "  the coordinator's router sends {} MB/s ({} Mbit/s) in all",
        fmt_num(router_out / 1e6),
        fmt_num(router_out * 8.0 / 1e6)
    );
    println!(
        "  CPU: {} ms per vehicle-second x {} vehicles per host on 2 cores: {}x real time",
        fmt_num(cpu_ms),
        n / k,
        fmt_num(cpu_rtf)
    );
    println!(
        "  lockstep barrier: {busy_ticks_per_s:.0} busy ticks per simulated s x a round trip of 2 x {} us: at most {}x real time",
        fmt_num(hop_us),
        fmt_num(barrier_rtf)
    );
    println!(
        "  so about {}x real time, {} ticks per second",
        fmt_num(rtf),
        fmt_num(rtf * busy_ticks_per_s)
    );
    let limit = format!(
        "a world sample holds at most {} vehicles (ipc_types::MAX_VEHICLES): 1,000 need it raised to 1,024 (a {} kB sample) or the world split by region",
        ipc_types::MAX_VEHICLES,
        fmt_num((48.0 + 80.0 * 1024.0) / 1e3)
    );
    println!("  but {limit}");
    json!({
        "limit": limit,
        "vehicles": n, "hosts": k,
        "host_down_bytes_per_s": down_bytes, "host_up_bytes_per_s": up_bytes,
        "router_out_bytes_per_s": router_out,
        "cpu_ms_per_vehicle_s": cpu_ms, "cpu_bound_rtf": cpu_rtf,
        "barrier_bound_rtf": barrier_rtf, "rtf": rtf, "ticks_per_s": rtf * busy_ticks_per_s,
    })
}
