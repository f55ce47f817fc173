//! `shoal replay`: plays a recording back onto iceoryx2 in a new domain, or
//! re-runs one process of one vehicle alone on its recorded inputs, in
//! lockstep, and reports the first output that differs from the recording.
//!
//! A re-run is exact because lockstep makes a process a function of its
//! inputs: at tick `t` it reads every sample stamped before `t` and nothing
//! else. The replayer publishes, before each due tick, the recorded input
//! samples stamped before it (with their original headers), publishes the
//! clock, wakes the process, waits for `done`, and compares what it
//! published with the recording sample by sample (wall-clock fields, which
//! measure the machine, are masked).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use ipc_types::{Header, Sample};
use recordings::Recording;
use shoal_runtime::{ChannelLimits, Mode, Publisher, Subscriber};
use shoal_scenario::{ProcessKind, ProcessSpec, Scenario};

use crate::analysis::from_recording::{recorded_mode, recorded_scenario};
use crate::launch::os as sys;
use crate::launch::supervisor::Supervisor;
use crate::launch::{wait_done, wait_ready, Ports};

/// How `play` replays a recording.
#[derive(Debug, Clone)]
pub struct PlayOptions {
    /// Playback speed against simulated time; 0 = as fast as possible.
    pub speed: f64,
    /// Run id of the new domain (default: a fresh one, printed).
    pub run_id: Option<String>,
    /// Wait (up to 60 s) for this many subscribers before playing.
    pub wait_subscribers: usize,
    /// Show a progress bar (on a terminal): simulated seconds played.
    pub progress: bool,
}

/// Which process `rerun` re-runs, and how.
#[derive(Debug, Clone)]
pub struct RerunOptions {
    /// Process kind (sim-plant, world, camera-pose, sonar, planner, mpc).
    pub kind: String,
    /// Its vehicle (not needed for `world`).
    pub vehicle: Option<String>,
    /// `section.key=value` overrides of the recorded scenario.
    pub set: Vec<String>,
    /// Where the service binaries are (default: beside `shoal`).
    pub bin_dir: Option<PathBuf>,
}

/// A publisher of any recorded sample type, fed raw recorded bytes.
trait AnyPublisher {
    fn publish_raw(&mut self, data: &[u8]) -> anyhow::Result<()>;
    fn subscribers(&self) -> usize;
}

struct Typed<T: Sample> {
    publisher: Publisher<T>,
}

impl<T: Sample> AnyPublisher for Typed<T> {
    fn publish_raw(&mut self, data: &[u8]) -> anyhow::Result<()> {
        let sample: T = recordings::decode(data).context("a recorded sample of the wrong size")?;
        self.publisher.publish_stamped(sample)?;
        Ok(())
    }
    fn subscribers(&self) -> usize {
        self.publisher.subscribers()
    }
}

/// A follower's recorded camera frames (`sensor_msgs/msg/Image`), put back
/// into image samples in place.
struct ImagePublisher {
    publisher: Publisher<ipc_types::Image>,
    sent: u64,
}

impl AnyPublisher for ImagePublisher {
    fn publish_raw(&mut self, data: &[u8]) -> anyhow::Result<()> {
        let seq = self.sent;
        let mut ok = true;
        // Header included: the frame's recorded time, a gap-free sequence.
        self.publisher
            .publish_stamped_in_place(|img| ok = recordings::image::to_sample(data, seq, img))?;
        anyhow::ensure!(
            ok,
            "a recorded camera frame that is not a mono8 image that fits"
        );
        self.sent += 1;
        Ok(())
    }
    fn subscribers(&self) -> usize {
        self.publisher.subscribers()
    }
}

/// The service limits every opener of `topic` uses.
fn limits_of(topic: &str, vehicles: usize, processes: usize) -> ChannelLimits {
    match topic {
        "/world" => ChannelLimits::world(vehicles),
        "/stats" => shoal_runtime::stats::stats_limits(processes),
        "/events" => ChannelLimits::events(),
        t if t.ends_with("/image") => ChannelLimits::image(),
        _ => ChannelLimits::vehicle(),
    }
}

/// The iceoryx2 service of a recorded topic in domain `run_id`.
fn service_of(run_id: &str, topic: &str) -> String {
    format!("shoal/{run_id}{topic}")
}

fn open_publisher(
    node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    schema: &str,
    service: &str,
    limits: &ChannelLimits,
) -> anyhow::Result<Box<dyn AnyPublisher>> {
    fn typed<T: Sample>(
        node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
        service: &str,
        limits: &ChannelLimits,
    ) -> anyhow::Result<Box<dyn AnyPublisher>> {
        Ok(Box::new(Typed::<T> {
            publisher: shoal_runtime::node_publisher::<T, _>(node, service, limits)?,
        }))
    }
    if schema == recordings::image::SCHEMA_NAME {
        return Ok(Box::new(ImagePublisher {
            publisher: shoal_runtime::node_publisher::<ipc_types::Image, _>(node, service, limits)?,
            sent: 0,
        }));
    }
    ipc_types::with_sample_type!(schema, T => typed::<T>(node, service, limits), else bail!("no sample type for schema {schema}"))
}

/// Plays every recorded message, in recorded order, onto a new domain.
pub fn play(rec: &Recording, opts: &PlayOptions) -> anyhow::Result<()> {
    if !(opts.speed >= 0.0 && opts.speed.is_finite()) {
        bail!("--speed must be ≥ 0, got {}", opts.speed);
    }
    let scenario = recorded_scenario(rec)?;
    let run_id = opts.run_id.clone().unwrap_or_else(sys::random_id);
    let vehicles = scenario.vehicles.len();
    let processes = scenario.processes().len();
    let node = shoal_runtime::domain_node(&run_id, "replay")?;
    let mut pubs: BTreeMap<u16, Box<dyn AnyPublisher>> = BTreeMap::new();
    for c in rec.channels() {
        let service = service_of(&run_id, &c.topic);
        let p = open_publisher(
            &node,
            &c.schema_name,
            &service,
            &limits_of(&c.topic, vehicles, processes),
        )
        .with_context(|| format!("cannot open {service}"))?;
        pubs.insert(c.id, p);
    }
    let span_s = match (rec.messages().first(), rec.messages().last()) {
        (Some(a), Some(b)) => (b.log_time - a.log_time) as f64 * 1e-9,
        _ => 0.0,
    };
    let pace = if opts.speed > 0.0 {
        format!(
            "{span_s:.1} s simulated at {}x: about {:.0} s",
            opts.speed,
            span_s / opts.speed
        )
    } else {
        format!("{span_s:.1} s simulated, as fast as possible")
    };
    println!(
        "replaying {} into run {run_id} ({pace})",
        rec.path().display()
    );
    let result = (|| -> anyhow::Result<u64> {
        if opts.wait_subscribers > 0 {
            let start = Instant::now();
            while pubs.values().map(|p| p.subscribers()).sum::<usize>() < opts.wait_subscribers {
                if start.elapsed() > Duration::from_secs(60) {
                    bail!("no {} subscriber(s) within 60 s", opts.wait_subscribers);
                }
                node.wait(Duration::from_millis(10))
                    .map_err(|_| anyhow::anyhow!("interrupted"))?;
            }
        }
        let start = Instant::now();
        let t0 = rec.messages().first().map_or(0, |m| m.log_time);
        let t_end = rec.messages().last().map_or(t0, |m| m.log_time);
        let bar = crate::progress::bar(
            opts.progress,
            (t_end - t0).div_ceil(1_000_000_000),
            "s simulated",
        );
        let mut sent = 0u64;
        for m in rec.messages() {
            bar.set_position((m.log_time - t0) / 1_000_000_000);
            if opts.speed > 0.0 {
                let due = Duration::from_secs_f64((m.log_time - t0) as f64 * 1e-9 / opts.speed);
                if let Some(wait) = due.checked_sub(start.elapsed()) {
                    node.wait(wait)
                        .map_err(|_| anyhow::anyhow!("interrupted after {sent} messages"))?;
                }
            }
            if let Some(p) = pubs.get_mut(&m.channel) {
                p.publish_raw(&m.data)?;
                sent += 1;
            }
        }
        bar.finish_and_clear();
        Ok(sent)
    })();
    drop(pubs);
    drop(node);
    shoal_runtime::cleanup_domain(&run_id);
    let sent = result?;
    println!("replayed {sent} messages");
    Ok(())
}

/// The recorded channels a process reads and writes.
fn channels_of(
    kind: ProcessKind,
    vehicle: &str,
    scenario: &Scenario,
) -> (Vec<String>, Vec<String>) {
    let v = |c: &str| format!("/{vehicle}/{c}");
    match kind {
        ProcessKind::SimPlant => (vec![v("thrust")], vec![v("truth"), v("nav")]),
        ProcessKind::World => (
            scenario
                .vehicles
                .iter()
                .map(|x| format!("/{}/truth", x.name))
                .collect(),
            vec!["/world".into()],
        ),
        ProcessKind::CameraPose => {
            let input = match scenario.camera_model() {
                shoal_scenario::CameraModel::Point => "/world".to_string(),
                shoal_scenario::CameraModel::Image => v("image"),
            };
            (vec![input], vec![v("beacons"), v("leader_pose")])
        }
        ProcessKind::CameraSim => (vec!["/world".into()], vec![v("image")]),
        ProcessKind::Sonar => (vec!["/world".into()], vec![v("sonar")]),
        ProcessKind::Planner => {
            let follower = scenario
                .vehicles
                .iter()
                .any(|x| x.name == vehicle && x.parent.is_some());
            let mut inputs = vec![v("nav"), v("sonar")];
            if follower {
                inputs.push(v("leader_pose"));
            }
            (inputs, vec![v("setpoint"), v("planner_state")])
        }
        ProcessKind::Mpc => (
            vec![v("nav"), v("setpoint")],
            vec![v("thrust"), v("mpc_stats")],
        ),
        ProcessKind::Recorder => (vec![], vec![]),
    }
}

/// The first sample where a re-run's output differs from the recording.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Difference {
    /// Topic.
    pub topic: String,
    /// Sequence number of the sample.
    pub seq: u64,
    /// Simulation time of the sample, s.
    pub sim_time_s: f64,
    /// Field path (`position_ned_m[1]`), or what is missing.
    pub field: String,
    /// Value in the recording.
    pub recorded: String,
    /// Value the re-run published.
    pub rerun: String,
}

/// What a re-run found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RerunReport {
    /// `<vehicle>/<process>`.
    pub process: String,
    /// Overrides applied.
    pub overrides: Vec<String>,
    /// Steps driven.
    pub steps: u64,
    /// Output samples compared, per topic.
    pub compared: BTreeMap<String, u64>,
    /// The first difference, if any.
    pub difference: Option<Difference>,
}

impl RerunReport {
    /// A human-readable verdict.
    pub fn describe(&self) -> String {
        let counts: Vec<String> = self
            .compared
            .iter()
            .map(|(t, n)| format!("{t}: {n}"))
            .collect();
        match &self.difference {
            None => format!(
                "{}: no differences over {} steps ({})",
                self.process,
                self.steps,
                counts.join(", ")
            ),
            Some(d) => format!(
                "{}: first difference at t = {:.3} s on {} (seq {}): {}: recorded {} vs re-run {} ({} samples matched before it: {})",
                self.process,
                d.sim_time_s,
                d.topic,
                d.seq,
                d.field,
                d.recorded,
                d.rerun,
                self.compared.values().sum::<u64>(),
                counts.join(", ")
            ),
        }
    }
}

/// Applies `section.key=value` overrides (the value in TOML syntax).
fn apply_overrides(scenario: &Scenario, sets: &[String]) -> anyhow::Result<Scenario> {
    if sets.is_empty() {
        return Ok(scenario.clone());
    }
    let mut doc: toml::Table = toml::from_str(&scenario.to_toml()?)?;
    for s in sets {
        let (path, value) = s
            .split_once('=')
            .with_context(|| format!("--set {s}: expected section.key=value"))?;
        let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut keys: Vec<&str> = path.trim().split('.').collect();
        let last = keys.pop().context("empty --set key")?;
        let mut table = &mut doc;
        for k in keys {
            table = table
                .entry(k)
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .with_context(|| format!("--set {s}: {k} is not a table"))?;
        }
        table.insert(last.to_string(), value);
    }
    Scenario::from_toml(&toml::to_string(&doc)?).context("the overridden scenario is invalid")
}

/// Re-runs one process on its recorded inputs.
pub fn rerun(rec: &Recording, opts: &RerunOptions) -> anyhow::Result<RerunReport> {
    let kind_name = opts.kind.as_str();
    let kind = ProcessKind::ALL
        .into_iter()
        .find(|k| k.name() == kind_name && *k != ProcessKind::Recorder)
        .with_context(|| {
            format!("--rerun {kind_name}: expected one of sim-plant, world, camera-pose, sonar, planner, mpc")
        })?;
    let base = recorded_scenario(rec)?;
    let mode = recorded_mode(rec);
    if mode != "lockstep" {
        bail!("only a lockstep recording can be re-run exactly (this one is {mode})");
    }
    let vehicle = if kind == ProcessKind::World {
        "run".to_string()
    } else {
        opts.vehicle
            .clone()
            .context("--vehicle is required to re-run a vehicle's process")?
    };
    let mut scenario = apply_overrides(&base, &opts.set)?;
    crate::preflight::resolve(&mut scenario).context("the re-run's scenario is refused")?;
    let mut spec: ProcessSpec = scenario
        .processes()
        .into_iter()
        .find(|p| p.kind == kind && p.vehicle == vehicle)
        .with_context(|| format!("no process {kind_name} of vehicle {vehicle} in the scenario"))?;
    spec.index = 0;
    let bin_dir = crate::launch::bin_dir_or_default(opts.bin_dir.clone())?;

    let run_id = sys::random_id();
    let dir = std::env::temp_dir().join(format!("shoal-rerun-{run_id}"));
    std::fs::create_dir_all(&dir)?;
    let scenario_path = dir.join("scenario.toml");
    std::fs::write(&scenario_path, scenario.to_toml()?)?;
    let procs = vec![spec.clone()];
    let mut ports = Ports::open(&run_id, &procs)?;
    let mut sup = Supervisor::default();
    // The process is started as `shoal run` starts it, alone in its run.
    let launch = crate::launch::restart::Launch {
        bin_dir: bin_dir.clone(),
        out: dir.clone(),
        run_id: run_id.clone(),
        processes: 1,
        mode: Mode::Lockstep,
        epoch_mono_ns: 0,
        spin_us: 0,
        no_work: false,
        live: None,
        scenario_path: scenario_path.clone(),
        scenario: scenario.clone(),
        scope: None,
    };
    // shoal's binary, or the user's command the recorded run replaced it by.
    let binary = launch.binary(&spec);
    if sys::find_program(&binary.to_string_lossy()).is_none() {
        bail!("{} not found", binary.display());
    }
    let result = drive(rec, &scenario, &spec, &run_id, &mut ports, &mut sup, || {
        (
            binary.clone(),
            launch.args(&spec, 0, None),
            dir.join(format!("{}.{}.log", spec.vehicle, kind.name())),
        )
    });
    sup.stop_all(|_| false, Duration::from_secs(2));
    drop(ports);
    shoal_runtime::cleanup_domain(&run_id);
    let mut report = result?;
    report.overrides = opts.set.clone();
    let _ = std::fs::remove_dir_all(&dir);
    Ok(report)
}

/// One recorded output stream and what the re-run produced of it.
struct OutputTap {
    topic: String,
    expected: Vec<Vec<u8>>,
    next: usize,
    sub: Box<dyn AnyTap>,
    schema: String,
}

/// A subscriber of any type that returns raw sample bytes.
trait AnyTap {
    fn take(&mut self, out: &mut Vec<Vec<u8>>) -> anyhow::Result<()>;
}

struct TypedTap<T: Sample> {
    sub: Subscriber<T>,
}

impl<T: Sample> AnyTap for TypedTap<T> {
    fn take(&mut self, out: &mut Vec<Vec<u8>>) -> anyhow::Result<()> {
        self.sub
            .take_all(|v| out.push(bytemuck::bytes_of(&v).to_vec()))?;
        Ok(())
    }
}

/// A re-run's camera frames, written as the recorder writes them (every
/// `every`-th frame, `sensor_msgs/msg/Image`) so that they compare byte for
/// byte with the recorded ones.
struct ImageTap {
    sub: Subscriber<ipc_types::Image>,
    frame_id: String,
    every: u32,
}

impl AnyTap for ImageTap {
    fn take(&mut self, out: &mut Vec<Vec<u8>>) -> anyhow::Result<()> {
        let (frame_id, every) = (&self.frame_id, self.every);
        self.sub
            .take_ready_in_place(&shoal_runtime::StepContext::any_time(), |img| {
                if img.frame % every == 0 {
                    let mut body = Vec::with_capacity(img.pixels().len() + 64);
                    recordings::image::encode(img, frame_id, &mut body);
                    out.push(body);
                }
            })?;
        Ok(())
    }
}

/// Every how many frames the recorder of `scenario` kept one.
fn frames_recorded_every(scenario: &Scenario) -> anyhow::Result<u32> {
    let camera: camera_pose::CameraConfig = scenario.section("camera")?;
    Ok((scenario.rates.camera_hz / camera.record_hz)
        .round()
        .max(1.0) as u32)
}

fn open_tap(
    node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    schema: &str,
    service: &str,
    limits: &ChannelLimits,
    scenario: &Scenario,
) -> anyhow::Result<Box<dyn AnyTap>> {
    if schema == recordings::image::SCHEMA_NAME {
        // shoal/<run>/<vehicle>/image
        let vehicle = service.rsplit('/').nth(1).unwrap_or_default();
        return Ok(Box::new(ImageTap {
            sub: shoal_runtime::node_subscriber::<ipc_types::Image, _>(
                node,
                service,
                limits,
                limits.max_buffer,
            )?,
            frame_id: recordings::image::frame_id(vehicle),
            every: frames_recorded_every(scenario)?,
        }));
    }
    fn typed<T: Sample>(
        node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
        service: &str,
        limits: &ChannelLimits,
    ) -> anyhow::Result<Box<dyn AnyTap>> {
        Ok(Box::new(TypedTap::<T> {
            sub: shoal_runtime::node_subscriber::<T, _>(node, service, limits, limits.max_buffer)?,
        }))
    }
    ipc_types::with_sample_type!(schema, T => typed::<T>(node, service, limits), else bail!("no sample type for schema {schema}"))
}

/// The sequence number and simulated time (s) of the `k`-th sample of a
/// stream, from its bytes: shoal's header, or a camera frame's stamp.
fn position_of(schema: &str, bytes: &[u8], k: usize) -> (u64, f64) {
    if schema == recordings::image::SCHEMA_NAME {
        let mut data = recordings::CDR_HEADER.to_vec();
        data.extend_from_slice(bytes);
        let t = recordings::image::read(&data).map_or(0, |f| f.stamp_ns);
        return (k as u64, t as f64 * 1e-9);
    }
    match bytes.get(..std::mem::size_of::<Header>()) {
        Some(h) => {
            let header: Header = bytemuck::pod_read_unaligned(h);
            (header.seq, header.sim_time_ns as f64 * 1e-9)
        }
        None => (k as u64, 0.0),
    }
}

/// Spawns the process, feeds it tick by tick and compares its outputs.
#[allow(clippy::too_many_arguments)]
fn drive(
    rec: &Recording,
    scenario: &Scenario,
    spec: &ProcessSpec,
    run_id: &str,
    ports: &mut Ports,
    sup: &mut Supervisor,
    command: impl Fn() -> (PathBuf, Vec<String>, PathBuf),
) -> anyhow::Result<RerunReport> {
    let vehicles = scenario.vehicles.len();
    let (inputs, outputs) = channels_of(spec.kind, &spec.vehicle, scenario);
    let schema_of = |topic: &str| -> anyhow::Result<(u16, String)> {
        let c = rec
            .channel(topic)
            .with_context(|| format!("the recording has no {topic}"))?;
        Ok((c.id, c.schema_name.clone()))
    };
    // Inputs: recorded messages of the input topics, in recorded order.
    let mut pubs: BTreeMap<u16, Box<dyn AnyPublisher>> = BTreeMap::new();
    for t in &inputs {
        let (id, schema) = schema_of(t)?;
        pubs.insert(
            id,
            open_publisher(
                &ports.node,
                &schema,
                &service_of(run_id, t),
                &limits_of(t, vehicles, 1),
            )?,
        );
    }
    let feed: Vec<&recordings::StoredMessage> = rec
        .messages()
        .iter()
        .filter(|m| pubs.contains_key(&m.channel))
        .collect();
    let mut taps = Vec::new();
    for t in &outputs {
        let (_, schema) = schema_of(t)?;
        taps.push(OutputTap {
            topic: t.clone(),
            expected: rec
                .topic_messages(t)
                .filter_map(|m| {
                    m.data
                        .strip_prefix(&recordings::CDR_HEADER)
                        .map(<[u8]>::to_vec)
                })
                .collect(),
            next: 0,
            sub: open_tap(
                &ports.node,
                &schema,
                &service_of(run_id, t),
                &limits_of(t, vehicles, 1),
                scenario,
            )?,
            schema,
        });
    }

    let (binary, args, log) = command();
    sup.spawn(spec, &binary, &args, &log, 0)
        .with_context(|| format!("cannot start {}", spec.label()))?;
    wait_ready(
        ports,
        sup,
        std::slice::from_ref(spec),
        &[0],
        Duration::from_secs(30),
    )?;

    let ticks = scenario.ticks();
    let tick_ns = (scenario.rates.tick_s * 1e9).round() as u64;
    let mut fed = 0usize;
    let mut steps = 0u64;
    let mut got = Vec::new();
    let mut difference = None;
    'ticks: for tick in 0..ticks {
        if !spec.due(tick) {
            continue;
        }
        let sim = tick * tick_ns;
        while fed < feed.len() && feed[fed].log_time < sim {
            let m = feed[fed];
            if let Some(p) = pubs.get_mut(&m.channel) {
                p.publish_raw(&m.data)?;
            }
            fed += 1;
        }
        ports.start_tick(tick, ticks, tick_ns, &[0], std::slice::from_ref(spec))?;
        wait_done(
            ports,
            sup,
            std::slice::from_ref(spec),
            &[0],
            Duration::from_secs(30),
            sim as f64 * 1e-9,
            Duration::ZERO,
        )?;
        steps += 1;
        for tap in &mut taps {
            got.clear();
            tap.sub.take(&mut got)?;
            for bytes in &got {
                let k = tap.next;
                tap.next += 1;
                let d = match tap.expected.get(k) {
                    None => Some((
                        "(extra sample)".to_string(),
                        "none".to_string(),
                        "a sample".to_string(),
                    )),
                    Some(exp) => recordings::first_field_difference(&tap.schema, exp, bytes),
                };
                if let Some((field, recorded, rerun)) = d {
                    let (seq, sim_time_s) = position_of(&tap.schema, bytes, k);
                    difference = Some(Difference {
                        topic: tap.topic.clone(),
                        seq,
                        sim_time_s,
                        field,
                        recorded,
                        rerun,
                    });
                    tap.next -= 1;
                    break 'ticks;
                }
            }
        }
    }
    if difference.is_none() {
        for tap in &taps {
            if tap.next < tap.expected.len() {
                let exp = &tap.expected[tap.next];
                let (seq, sim_time_s) = position_of(&tap.schema, exp, tap.next);
                difference = Some(Difference {
                    topic: tap.topic.clone(),
                    seq,
                    sim_time_s,
                    field: "(missing sample)".into(),
                    recorded: "a sample".into(),
                    rerun: "none".into(),
                });
                break;
            }
        }
    }
    Ok(RerunReport {
        process: spec.label(),
        overrides: Vec::new(),
        steps,
        compared: taps
            .iter()
            .map(|t| (t.topic.clone(), t.next as u64))
            .collect(),
        difference,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_set_nested_keys_with_toml_values() {
        let s = Scenario::paper().unwrap();
        let o = apply_overrides(&s, &["follower.beta=0.25".into(), "seed=7".into()]).unwrap();
        assert_eq!(o.seed, 7);
        assert_eq!(
            o.follower.get("beta").and_then(|v| v.as_float()),
            Some(0.25)
        );
        assert!(apply_overrides(&s, &["nonsense".into()]).is_err());
    }
}
