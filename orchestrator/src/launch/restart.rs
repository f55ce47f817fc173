//! What the orchestrator does when one of its processes dies during a run
//! (the scenario's `[supervision]` policy), and the run's events.
//!
//! Every fault, death, restart and the end of every gap is an event: a line
//! in summary.json's `events` and an [`Event`] sample on the run's `events`
//! channel, which the recorder writes as `/events`.
//!
//! With `policy = "restart"` a dead process is started again at once, with
//! `--restart n`, after iceoryx2's dead-node cleanup has removed what the
//! dead one held. The lockstep clock does not move on meanwhile: the tick in
//! progress waits for the new process to report ready (at most
//! `restart_timeout_s`), then wakes it to take the step it owes, so no
//! simulated time is lost. What a process cannot rebuild by itself is handed
//! over: sim-plant gets its vehicle's last `truth` (the orchestrator keeps
//! the latest of each vehicle while the policy is `restart`), a restarted
//! leader planner resumes its mission where the vehicle is, and a restarted
//! recorder writes `recording.rN.mcap`, joined to the first file when the run
//! ends.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use ipc_types::{Event, EventKind, Header, Sample, Truth};
use shoal_runtime::{ChannelLimits, Mode, Publisher, Subscriber};
use shoal_scenario::faults::Policy;
use shoal_scenario::{ProcessKind, ProcessSpec, Scenario};

use super::os::ExitInfo;
use super::supervisor::{Death, Supervisor};

/// How every process of a run is started (and started again).
#[derive(Debug, Clone)]
pub(crate) struct Launch {
    pub(crate) bin_dir: PathBuf,
    pub(crate) out: PathBuf,
    pub(crate) run_id: String,
    pub(crate) processes: usize,
    pub(crate) mode: Mode,
    pub(crate) epoch_mono_ns: u64,
    pub(crate) spin_us: u64,
    /// Vehicle processes are started with `--no-work`.
    pub(crate) no_work: bool,
    /// The recorder serves a live view on this address (`--live`).
    pub(crate) live: Option<String>,
    pub(crate) scenario_path: PathBuf,
    pub(crate) scenario: Scenario,
    /// The share of a run spread over hosts that this host runs; `None`:
    /// the whole run.
    pub(crate) scope: Option<HostScope>,
}

/// What one host of a run spread over hosts runs and records.
#[derive(Debug, Clone)]
pub(crate) struct HostScope {
    /// The host's name.
    pub(crate) host: String,
    /// By process index: true for the processes this host runs.
    pub(crate) local: Vec<bool>,
    /// The vehicles placed here (its recorder records their channels).
    pub(crate) vehicles: Vec<String>,
    /// True if the world runs here (its recorder records `/world`).
    pub(crate) world: bool,
}

impl Launch {
    /// True if this host runs `p`.
    pub(crate) fn is_local(&self, p: &ProcessSpec) -> bool {
        self.scope
            .as_ref()
            .is_none_or(|s| s.local.get(p.index).copied().unwrap_or(false))
    }
}

impl Launch {
    /// The program that runs `p`: its service binary, or the user's
    /// command that replaces it (`[[replace]]`).
    pub(crate) fn binary(&self, p: &ProcessSpec) -> PathBuf {
        match self.scenario.replacement(p.kind, &p.vehicle) {
            Some(command) => PathBuf::from(&command[0]),
            None => self.bin_dir.join(p.kind.binary()),
        }
    }

    /// The log file of `p` (every incarnation writes to the same one).
    pub(crate) fn log(&self, p: &ProcessSpec) -> PathBuf {
        let name = match &self.scope {
            // Every host runs a recorder: its log names the host.
            Some(scope) if p.kind == ProcessKind::Recorder => {
                format!("{}.{}.{}.log", p.vehicle, p.kind.name(), scope.host)
            }
            _ => format!("{}.{}.log", p.vehicle, p.kind.name()),
        };
        self.out.join("logs").join(name)
    }

    /// The scenario as every process runs it, defaults filled in
    /// ([`crate::preflight::effective_toml`]): the recorder keeps it in the
    /// recording.
    pub(crate) fn effective_scenario(&self) -> PathBuf {
        self.out.join("logs").join("effective-scenario.toml")
    }

    /// The recording the recorder's `restart`-th incarnation writes.
    pub(crate) fn recording(&self, restart: u32) -> PathBuf {
        if restart == 0 {
            self.out.join("recording.mcap")
        } else {
            self.out.join(format!("recording.r{restart}.mcap"))
        }
    }

    /// Offset of `p`'s activations within its period, s: its stage of the
    /// lockstep frame; in a dataflow run the recorder's timer sits half a
    /// period after the plants', away from the chain their samples start.
    fn phase_s(&self, p: &ProcessSpec) -> f64 {
        let s = &self.scenario;
        if self.mode == Mode::Dataflow && p.kind == ProcessKind::Recorder {
            return 0.5 / s.rate_hz(p.kind);
        }
        p.phase as f64 * s.rates.tick_s
    }

    /// The command line of `p`'s `restart`-th incarnation.
    pub(crate) fn args(&self, p: &ProcessSpec, restart: u32, resume: Option<&Path>) -> Vec<String> {
        let s = &self.scenario;
        // A replacing command's own arguments go first, the run's after.
        let mut args: Vec<String> = s
            .replacement(p.kind, &p.vehicle)
            .map(|c| c[1..].to_vec())
            .unwrap_or_default();
        args.extend([
            "--run-id".to_string(),
            self.run_id.clone(),
            "--vehicle".into(),
            p.vehicle.clone(),
            "--process".into(),
            p.kind.name().into(),
            "--index".into(),
            p.index.to_string(),
            "--processes".into(),
            self.processes.to_string(),
            "--mode".into(),
            self.mode.as_str().into(),
            "--period-s".into(),
            format!("{}", 1.0 / s.rate_hz(p.kind)),
            "--epoch-mono-ns".into(),
            self.epoch_mono_ns.to_string(),
            "--phase-s".into(),
            format!("{}", self.phase_s(p)),
            "--spin-us".into(),
            self.spin_us.to_string(),
            "--scenario".into(),
            self.scenario_path.display().to_string(),
        ]);
        if restart > 0 {
            args.push("--restart".into());
            args.push(restart.to_string());
        }
        if let Some(r) = resume {
            args.push("--resume".into());
            args.push(r.display().to_string());
        }
        if self.no_work && !matches!(p.kind, ProcessKind::World | ProcessKind::Recorder) {
            args.push("--no-work".into());
        }
        if p.kind == ProcessKind::Recorder {
            args.push("--out".into());
            args.push(self.recording(restart).display().to_string());
            args.push("--effective".into());
            args.push(self.effective_scenario().display().to_string());
            if let Some(addr) = &self.live {
                args.push("--live".into());
                args.push(addr.clone());
            }
            if let Some(scope) = &self.scope {
                args.push("--host".into());
                args.push(scope.host.clone());
                args.push(format!("--vehicles={}", scope.vehicles.join(",")));
                if !scope.world {
                    args.push("--no-world".into());
                }
            }
        }
        args
    }
}

/// The run's events: summary.json's list and the `events` channel.
pub(crate) struct Journal {
    publisher: Publisher<Event>,
    /// Every event so far, as summary.json lists them.
    pub(crate) list: Vec<serde_json::Value>,
}

/// One event, before it is recorded.
pub(crate) struct Happening<'a> {
    pub(crate) kind: EventKind,
    pub(crate) t_s: f64,
    pub(crate) process: Option<&'a ProcessSpec>,
    pub(crate) restarts: u32,
    pub(crate) exit: Option<ExitInfo>,
    pub(crate) duration_s: f64,
    pub(crate) detail: String,
}

impl<'a> Happening<'a> {
    /// An event of `kind` at `t_s` about `process`.
    pub(crate) fn new(kind: EventKind, t_s: f64, process: Option<&'a ProcessSpec>) -> Self {
        Self {
            kind,
            t_s,
            process,
            restarts: 0,
            exit: None,
            duration_s: 0.0,
            detail: String::new(),
        }
    }
}

impl Journal {
    /// Opens the run's `events` publisher.
    pub(crate) fn open(
        node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
        run_id: &str,
    ) -> anyhow::Result<Self> {
        let publisher = shoal_runtime::node_publisher::<Event, _>(
            node,
            &ipc_types::run_service_name(run_id, ipc_types::RunChannel::Events),
            &ChannelLimits::events(),
        )?;
        Ok(Self {
            publisher,
            list: Vec::new(),
        })
    }

    /// Records `h` (with `extra` fields added to its summary.json entry).
    pub(crate) fn emit(&mut self, h: Happening<'_>, extra: serde_json::Value) {
        let now = shoal_runtime::mono_ns();
        let sim_ns = (h.t_s.max(0.0) * 1e9).round() as u64;
        let mut e = Event::zeroed();
        *e.header_mut() = Header {
            seq: self.list.len() as u64,
            sim_time_ns: sim_ns,
            publish_mono_ns: now,
            origin_mono_ns: now,
            origin_sim_time_ns: sim_ns,
        };
        e.kind = h.kind as u32;
        e.process_index = h.process.map_or(u32::MAX, |p| p.index as u32);
        e.restarts = h.restarts;
        e.exit_code = h.exit.and_then(|x| x.code).unwrap_or(-1);
        e.signal = h.exit.and_then(|x| x.signal).unwrap_or(0);
        e.duration_s = h.duration_s;
        e.event_mono_ns = now;
        let label = h.process.map(ProcessSpec::label).unwrap_or_default();
        e.process = ipc_types::fixed_str(&label);
        e.detail = ipc_types::fixed_str(&h.detail);
        if let Err(err) = self.publisher.publish_stamped(e) {
            tracing::warn!(%err, "cannot publish an event");
        }
        let mut map = serde_json::Map::new();
        map.insert("t_s".into(), h.t_s.into());
        map.insert("event".into(), h.kind.name().into());
        if h.process.is_some() {
            map.insert("process".into(), label.into());
        }
        if let Some(x) = h.exit {
            map.insert("exit".into(), x.describe().into());
        }
        if !h.detail.is_empty() {
            map.insert("detail".into(), h.detail.into());
        }
        if let serde_json::Value::Object(more) = extra {
            map.extend(more);
        }
        self.list.push(serde_json::Value::Object(map));
    }
}

/// The `[supervision]` policy at work.
pub(crate) struct Recovery {
    policy: Policy,
    max_restarts: u32,
    restart_timeout: Duration,
    /// Restarts so far, per process index.
    restarts: Vec<u32>,
    /// Processes whose "ready" is awaited: since when, and how long it may take.
    awaiting: Vec<Option<(Instant, Duration)>>,
    /// How many entries of `awaiting` are set (the wait loop asks on every
    /// pass; this keeps the answer O(1) with hundreds of processes).
    awaiting_count: usize,
    /// The latest truth of each vehicle, by its sim-plant's process index
    /// (policy `restart` only).
    truths: Vec<(usize, Subscriber<Truth>, Option<Truth>)>,
    launch: Option<Launch>,
    /// Recordings written by restarted recorders, in order.
    pub(crate) recording_parts: Vec<PathBuf>,
}

impl Recovery {
    /// The default: a death aborts the run; nothing is kept for a restart.
    pub(crate) fn abort(processes: usize) -> Self {
        Self {
            policy: Policy::Abort,
            max_restarts: 0,
            restart_timeout: Duration::from_secs(10),
            restarts: vec![0; processes],
            awaiting: vec![None; processes],
            awaiting_count: 0,
            truths: Vec::new(),
            launch: None,
            recording_parts: Vec::new(),
        }
    }

    /// The scenario's policy for a run started by `launch`; with `restart`
    /// it subscribes to every vehicle's truth (to hand it over to a
    /// restarted plant).
    pub(crate) fn for_run(
        node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
        procs: &[ProcessSpec],
        launch: Launch,
    ) -> anyhow::Result<Self> {
        let sup = &launch.scenario.supervision;
        let mut r = Self::abort(procs.len());
        r.policy = sup.policy;
        r.max_restarts = sup.max_restarts;
        r.restart_timeout = Duration::from_secs_f64(sup.restart_timeout_s);
        if r.policy == Policy::Restart {
            for p in procs
                .iter()
                .filter(|p| p.kind == ProcessKind::SimPlant && launch.is_local(p))
            {
                let sub = shoal_runtime::node_subscriber::<Truth, _>(
                    node,
                    &ipc_types::service_name(&launch.run_id, &p.vehicle, ipc_types::Channel::Truth),
                    &ChannelLimits::vehicle(),
                    2,
                )?;
                r.truths.push((p.index, sub, None));
            }
        }
        r.launch = Some(launch);
        Ok(r)
    }

    /// Keeps the latest truth of every vehicle (policy `restart`).
    pub(crate) fn track_truths(&mut self) {
        for (_, sub, last) in &mut self.truths {
            match sub.drain_latest() {
                Ok(Some(t)) => *last = Some(t),
                Ok(None) => {}
                Err(e) => tracing::warn!(%e, "cannot read a truth"),
            }
        }
    }

    /// Awaits the "ready" of `index` for at most `timeout`.
    pub(crate) fn await_ready(&mut self, index: usize, timeout: Duration) {
        if let Some(a) = self.awaiting.get_mut(index) {
            if a.is_none() {
                self.awaiting_count += 1;
            }
            *a = Some((Instant::now(), timeout));
        }
    }

    /// True while some process has not reported ready.
    pub(crate) fn any_awaiting(&self) -> bool {
        self.awaiting_count > 0
    }

    /// A "ready" from `index` arrived: ends its gap (an event if it was a
    /// restart). Returns false if none was awaited.
    pub(crate) fn ready(
        &mut self,
        index: usize,
        procs: &[ProcessSpec],
        journal: &mut Journal,
        t_s: f64,
    ) -> bool {
        let Some((since, _)) = self.awaiting.get_mut(index).and_then(Option::take) else {
            return false;
        };
        self.awaiting_count -= 1;
        let restarts = self.restarts.get(index).copied().unwrap_or(0);
        if restarts > 0 {
            let gap = since.elapsed().as_secs_f64();
            let mut h = Happening::new(EventKind::ProcessReady, t_s, procs.get(index));
            h.restarts = restarts;
            h.duration_s = gap;
            h.detail = format!("ready again after {:.3} s", gap);
            tracing::info!(process = %procs.get(index).map(ProcessSpec::label).unwrap_or_default(), gap_s = gap, "restarted process ready");
            journal.emit(h, serde_json::json!({ "gap_s": gap, "restarts": restarts }));
        }
        true
    }

    /// The processes whose "ready" is overdue.
    pub(crate) fn overdue(&self, procs: &[ProcessSpec]) -> Vec<String> {
        if self.awaiting_count == 0 {
            return Vec::new();
        }
        self.awaiting
            .iter()
            .enumerate()
            .filter(|(_, a)| a.is_some_and(|(since, limit)| since.elapsed() > limit))
            .filter_map(|(i, _)| procs.get(i).map(ProcessSpec::label))
            .collect()
    }

    /// A process died at simulated time `t_s`: records it and applies the
    /// policy. `Ok` means it was started again (its ready is now awaited);
    /// `Err` gives the death back when the run must stop.
    pub(crate) fn on_death(
        &mut self,
        d: Death,
        procs: &[ProcessSpec],
        sup: &mut Supervisor,
        node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
        journal: &mut Journal,
        t_s: f64,
    ) -> Result<(), Death> {
        // What the dead node held (its ports in every service, its files).
        let cleaned = node.try_cleanup_dead_nodes();
        let spec = procs.get(d.index);
        let done = self.restarts.get(d.index).copied().unwrap_or(0);
        let restart = self.policy == Policy::Restart && done < self.max_restarts;
        let mut h = Happening::new(EventKind::ProcessDied, t_s, spec);
        h.restarts = done;
        h.exit = Some(d.exit);
        h.detail = d.exit.describe();
        journal.emit(
            h,
            serde_json::json!({
                "policy": if self.policy == Policy::Restart { "restart" } else { "abort" },
                "dead_nodes_cleaned": cleaned.cleanups,
            }),
        );
        let (Some(spec), Some(launch), true) = (spec, self.launch.as_ref(), restart) else {
            let mut h = Happening::new(EventKind::RunAborted, t_s, spec);
            h.restarts = done;
            h.detail = if self.policy == Policy::Restart {
                format!("{} died after {done} restarts (max_restarts)", d.label)
            } else {
                format!("{} died (policy abort)", d.label)
            };
            journal.emit(h, serde_json::json!({}));
            return Err(d);
        };
        let n = done + 1;
        let resume = (spec.kind == ProcessKind::SimPlant)
            .then(|| self.handover_truth(spec, launch, n))
            .flatten();
        let args = launch.args(spec, n, resume.as_deref());
        if let Err(e) = sup.spawn(spec, &launch.binary(spec), &args, &launch.log(spec), n) {
            tracing::error!(process = %d.label, %e, "cannot restart");
            let mut h = Happening::new(EventKind::RunAborted, t_s, Some(spec));
            h.detail = format!("cannot restart {}: {e}", d.label);
            journal.emit(h, serde_json::json!({}));
            return Err(d);
        }
        if spec.kind == ProcessKind::Recorder {
            self.recording_parts.push(launch.recording(n));
        }
        self.restarts[d.index] = n;
        self.await_ready(d.index, self.restart_timeout);
        tracing::warn!(process = %d.label, exit = %d.exit.describe(), restart = n, "process died; restarted");
        let mut h = Happening::new(EventKind::ProcessRestarted, t_s, Some(spec));
        h.restarts = n;
        h.detail = match &resume {
            Some(_) => "started again from its vehicle's last truth".into(),
            None => "started again".into(),
        };
        journal.emit(h, serde_json::json!({ "restarts": n }));
        Ok(())
    }

    /// Writes the latest truth of `spec`'s vehicle for its restarted plant.
    fn handover_truth(&self, spec: &ProcessSpec, launch: &Launch, n: u32) -> Option<PathBuf> {
        let truth = self
            .truths
            .iter()
            .find(|(i, _, _)| *i == spec.index)
            .and_then(|(_, _, t)| *t)?;
        let path = launch
            .out
            .join("logs")
            .join(format!("{}.sim-plant.resume{n}.truth", spec.vehicle));
        match std::fs::write(&path, bytemuck::bytes_of(&truth)) {
            Ok(()) => Some(path),
            Err(e) => {
                tracing::warn!(%e, path = %path.display(), "cannot hand the truth over; the plant starts afresh");
                None
            }
        }
    }
}
