"""A process of a shoal run, written in Python.

`Node.from_args()` reads the run arguments the orchestrator appends to a
replacing command (the ones every service binary takes), opens an iceoryx2
node in the run's domain, and gives the vehicle's ports; `Node.steps()` is
the step loop with the Rust runtime's contract:

- it reports ready once every port the program opened before the loop
  exists (the `done` event's ready id), so the first tick's samples reach it;
- lockstep: it sleeps on its doorbell slot, yields one `Step` per wake-up,
  and tells the orchestrator the step is over when the loop's body returns;
- realtime: on phased activations of the wall clock, counting the ones it
  missed;
- dataflow: it steps once a new sample has arrived on every trigger input
  (`node.subscriber(..., trigger=True)`; iceoryx2 arrival events, as the
  Rust runtime's `wake_on`), its phased timer a deadline at which it steps
  with what it has and counts a miss; every publisher announces its sends,
  so the stages after it wake on them; with no trigger it keeps its timer;
- SIGINT or SIGTERM ends the loop after the step in progress; statistics
  are published on the run's `stats` channel every simulated second and
  written to the stats file at exit, which `summary.json` merges.

What it does not do, and what stands in: `--spin-us` is taken and ignored
(a Python process always blocks in its wait); `--no-work` and `--resume` are
taken and left to the program (`node.args`); a replaced camera-pose reads
point observations (the image channel's frame type is not in the contract).

Samples are the generated `ctypes` structures of `contract.py`. A publisher
stamps the header and refuses a sample with a non-finite value; a subscriber
rejects (and counts) one, and counts gaps in a publisher's sequence as lost.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
import tomllib
from pathlib import Path
from typing import Iterator, NamedTuple, Optional

import iceoryx2 as iox2

from . import contract as c
from .doorbell import Doorbell

_STOP = False


def _on_signal(_signum, _frame) -> None:
    global _STOP
    _STOP = True


class Step(NamedTuple):
    """One step: the tick, its simulated time, whether it is the run's last."""

    tick: int
    sim_time_ns: int
    last: bool
    wake_mono_ns: int

    @property
    def sim_time_s(self) -> float:
        return self.sim_time_ns * 1e-9


class Origin(NamedTuple):
    """When the chain that led to a sample began (latency tracing): its first
    sensor event's monotonic and simulated times."""

    mono_ns: int = 0
    sim_time_ns: int = 0

    @staticmethod
    def of(header) -> "Origin":
        return Origin(int(header.origin_mono_ns), int(header.origin_sim_time_ns))

    def earliest(self, other: "Origin") -> "Origin":
        if self.mono_ns == 0:
            return other
        if other.mono_ns == 0 or self.mono_ns <= other.mono_ns:
            return self
        return other


class Histogram:
    """Values in ns, kept to three significant digits (the exit file's
    `(ns, count)` buckets, which the orchestrator merges)."""

    def __init__(self) -> None:
        self.counts: dict[int, int] = {}
        self.n = 0
        self.max = 0

    def record(self, ns: int) -> None:
        ns = max(int(ns), 1)
        e = max(len(str(ns)) - 3, 0)
        key = (ns // 10**e) * 10**e
        self.counts[key] = self.counts.get(key, 0) + 1
        self.n += 1
        self.max = max(self.max, ns)

    def quantile(self, q: float) -> int:
        if self.n == 0:
            return 0
        rank = max(1, math.ceil(q * self.n))
        seen = 0
        for k in sorted(self.counts):
            seen += self.counts[k]
            if seen >= rank:
                return k
        return self.max

    def buckets(self) -> list[list[int]]:
        return [[k, n] for k, n in sorted(self.counts.items())]


def _float_slots(cls) -> tuple[list[int], list[int]]:
    """Indices of every float64 and float32 of a sample type, as 8- and
    4-byte words (repr(C): each sits at a multiple of its size)."""
    import ctypes

    f64: list[int] = []
    f32: list[int] = []

    def walk(t, base: int) -> None:
        if isinstance(t, type) and issubclass(t, ctypes.Structure):
            for name, ft in t._fields_:
                walk(ft, base + getattr(t, name).offset)
        elif isinstance(t, type) and issubclass(t, ctypes.Array):
            for k in range(t._length_):
                walk(t._type_, base + k * ctypes.sizeof(t._type_))
        elif t is ctypes.c_double:
            f64.append(base // 8)
        elif t is ctypes.c_float:
            f32.append(base // 4)

    walk(cls, 0)
    return f64, f32


_SLOTS: dict[type, tuple[list[int], list[int]]] = {}


def non_finite_field(sample) -> Optional[int]:
    """The byte offset of the first NaN or infinity in `sample`, if any."""
    cls = type(sample)
    if cls not in _SLOTS:
        _SLOTS[cls] = _float_slots(cls)
    f64, f32 = _SLOTS[cls]
    raw = memoryview(bytearray(sample))
    d = raw.cast("d") if f64 else None
    for i in f64:
        if not math.isfinite(d[i]):
            return 8 * i
    f = raw.cast("f") if f32 else None
    for i in f32:
        if not math.isfinite(f[i]):
            return 4 * i
    return None


class _Hops:
    """Per input channel kind: publish → take latency, lost and rejected."""

    def __init__(self) -> None:
        self.kinds: dict[str, dict] = {}

    def of(self, kind: str) -> dict:
        return self.kinds.setdefault(kind, {"latency": Histogram(), "lost": 0, "rejected": 0})


class Subscriber:
    """A subscriber of one channel, with the Rust runtime's semantics: in
    lockstep a sample is ready at a step when it was stamped before the
    step's tick; later ones are held for the next step."""

    def __init__(self, node: "Node", service: str, cls, limits: c.Limits, buffer: int, kind: str, trigger: bool = False):
        self.service = service
        self._cls = cls
        self._lockstep = node.mode == "lockstep"
        port = node._open(service, cls, limits)
        if trigger and node.mode == "dataflow":
            arrival = node._arrival(service, limits)
            node._triggers.append(arrival.listener_builder().create())
            node._trigger_names.append(kind)
        self._sub = port.subscriber_builder().buffer_size(max(1, min(buffer, limits.max_buffer))).create()
        self._held: list = []
        self._next_seq: dict[str, int] = {}
        self._hop = node._hops.of(kind)

    def _pull(self) -> None:
        while True:
            s = self._sub.receive()
            if s is None:
                return
            taken = time.monotonic_ns()
            value = self._cls.from_buffer_copy(s.payload().contents)
            publisher = str(s.header.publisher_id)
            del s
            h = value.header
            if h.publish_mono_ns and taken >= h.publish_mono_ns:
                self._hop["latency"].record(taken - h.publish_mono_ns)
            expected = self._next_seq.get(publisher)
            if expected is not None and h.seq > expected:
                self._hop["lost"] += h.seq - expected
            self._next_seq[publisher] = h.seq + 1
            if non_finite_field(value) is not None:
                self._hop["rejected"] += 1
                print(f"shoal_node: {self.service}: rejected a sample with a non-finite value (seq {h.seq})", file=sys.stderr)
                continue
            self._held.append(value)

    def take_ready(self, step: Step) -> list:
        """Every sample ready at this step, oldest first."""
        self._pull()
        n = 0
        for v in self._held:
            if self._lockstep and v.header.sim_time_ns >= step.sim_time_ns:
                break
            n += 1
        ready, self._held = self._held[:n], self._held[n:]
        return ready

    def latest(self, step: Step):
        """The newest sample ready at this step that arrived since the last
        call, or None."""
        ready = self.take_ready(step)
        return ready[-1] if ready else None


class Publisher:
    """A publisher of one channel: stamps the header and sends a copy."""

    def __init__(self, node: "Node", service: str, cls, limits: c.Limits):
        self.service = service
        self._cls = cls
        self._pub = node._open(service, cls, limits).publisher_builder().create()
        self._seq = 0
        # Dataflow: every send is announced, so the stages it triggers wake.
        self._arrival = None
        if node.mode == "dataflow":
            self._arrival = node._arrival(service, limits).notifier_builder().create()

    def publish(self, sample, step: Step, origin: Origin = Origin()) -> None:
        """Stamps `sample`'s header (sequence, the step's simulated time, the
        origin, the publish time) and sends it. A non-finite value is refused
        with ValueError and nothing is sent."""
        if not isinstance(sample, self._cls):
            raise TypeError(f"{self.service} carries {self._cls.__name__}, not {type(sample).__name__}")
        bad = non_finite_field(sample)
        if bad is not None:
            raise ValueError(f"{self.service}: a non-finite value at byte {bad} of {self._cls.__name__}; not sent")
        h = sample.header
        h.seq = self._seq
        h.sim_time_ns = step.sim_time_ns
        h.origin_mono_ns = origin.mono_ns
        h.origin_sim_time_ns = origin.sim_time_ns
        h.publish_mono_ns = time.monotonic_ns()
        self._pub.send_copy(sample)
        self._seq += 1
        if self._arrival is not None:
            self._arrival.notify()


def _arguments(argv: Optional[list[str]]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description="A shoal process written in Python; started by `shoal run` with the run's arguments."
    )
    ap.add_argument("--run-id", required=True)
    ap.add_argument("--vehicle", required=True)
    ap.add_argument("--process", required=True)
    ap.add_argument("--index", type=int, required=True)
    ap.add_argument("--processes", type=int, required=True)
    ap.add_argument("--mode", choices=["lockstep", "realtime", "dataflow"], default="lockstep")
    ap.add_argument("--period-s", type=float, default=0.1)
    ap.add_argument("--epoch-mono-ns", type=int, default=0)
    ap.add_argument("--phase-s", type=float, default=0.0)
    ap.add_argument("--spin-us", type=int, default=0)
    ap.add_argument("--restart", type=int, default=0)
    ap.add_argument("--resume", default=None)
    ap.add_argument("--no-work", action="store_true")
    ap.add_argument("--scenario", required=True)
    args, rest = ap.parse_known_args(argv)
    args.rest = rest
    return args


class Node:
    """This process's place in the run: its vehicle, the scenario, its ports."""

    @classmethod
    def from_args(cls, argv: Optional[list[str]] = None) -> "Node":
        """The node of the run arguments in `argv` (default `sys.argv[1:]`);
        the program's own arguments before them are left in `node.rest`."""
        return cls(_arguments(sys.argv[1:] if argv is None else argv))

    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.run_id: str = args.run_id
        self.vehicle: str = args.vehicle
        self.process: str = args.process
        self.index: int = args.index
        self.processes: int = args.processes
        self.mode: str = args.mode
        self.rest: list[str] = args.rest
        with open(args.scenario, "rb") as f:
            self.scenario: dict = tomllib.load(f)
        self.vehicle_spec: dict = next(v for v in self.scenario["vehicles"] if v["name"] == self.vehicle)
        signal.signal(signal.SIGINT, _on_signal)
        signal.signal(signal.SIGTERM, _on_signal)
        iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
        config = iox2.config.default()
        config.global_cfg.prefix = iox2.FileName.new(c.DOMAIN_PREFIX.format(run_id=self.run_id))
        config.global_cfg.root_path = iox2.Path.new(c.DOMAIN_ROOT.format(run_id=self.run_id))
        config.defaults.publish_subscribe.subscriber_expired_connection_buffer = c.EXPIRED_CONNECTIONS
        config.global_cfg.node.cleanup_dead_nodes_on_creation = False
        config.global_cfg.node.cleanup_dead_nodes_on_destruction = False
        config.global_cfg.service.cleanup_dead_nodes_on_open = False
        self._node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(f"{self.vehicle}/{self.process}"))
            .config(config)
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc)
        )
        self._ports: list = []
        self._triggers: list = []
        self._trigger_names: list[str] = []
        self._hops = _Hops()
        self.steps_taken = 0
        self.deadline_misses = 0
        self._step_ns = Histogram()
        self._recent_ns = Histogram()
        self._wake_late = Histogram()
        stats_cls, stats_service = c.RUN_CHANNELS["stats"]
        base, per = c.STATS_LIMITS
        stats_limits = c.Limits(*(b + self.processes * p for b, p in zip(base, per)))
        try:
            self._stats = Publisher(self, stats_service.format(run_id=self.run_id), stats_cls, stats_limits)
        except Exception as e:  # noqa: BLE001 - the statistics go to the exit file alone
            print(f"shoal_node: no stats channel ({e}); statistics go to the exit file only", file=sys.stderr)
            self._stats = None

    def _retrying(self, what: str, build):
        """`build()` (an `open_or_create`) until it succeeds: two processes
        opening a new service at once race inside it, as in the Rust
        runtime's `open_retrying`; the port factory is kept while the node
        lives."""
        last = None
        for _ in range(200):
            try:
                port = build()
                self._ports.append(port)
                return port
            except Exception as e:  # noqa: BLE001 - half-created by another process: retry
                last = e
                time.sleep(0.01)
        raise RuntimeError(f"cannot open {what}: {last!r}")

    def _open(self, service: str, cls, limits: c.Limits):
        name = iox2.ServiceName.new(service)
        return self._retrying(
            service,
            lambda: self._node.service_builder(name)
            .publish_subscribe(cls)
            .max_publishers(limits.max_publishers)
            .max_subscribers(limits.max_subscribers)
            .max_nodes(limits.max_nodes)
            .subscriber_max_buffer_size(limits.max_buffer)
            .history_size(limits.history)
            .subscriber_max_borrowed_samples(2)
            .enable_safe_overflow(True)
            .open_or_create(),
        )

    def _arrival(self, service: str, limits: c.Limits):
        """The arrival event of pub-sub `service` (dataflow), as the Rust
        runtime's `open_arrival` opens it."""
        name = iox2.ServiceName.new(c.ARRIVAL_SERVICE.format(service=service))
        return self._retrying(
            f"{service}'s arrival event",
            lambda: self._node.service_builder(name)
            .event()
            .max_notifiers(limits.max_publishers)
            .max_listeners(limits.max_subscribers)
            .max_nodes(limits.max_nodes)
            .event_id_max_value(0)
            .open_or_create(),
        )

    def _channel(self, channel: str, vehicle: Optional[str]):
        if channel not in c.CHANNELS:
            raise KeyError(f"no channel `{channel}`; one of {', '.join(c.CHANNELS)}")
        cls, fmt = c.CHANNELS[channel]
        return cls, fmt.format(run_id=self.run_id, vehicle=vehicle or self.vehicle)

    def subscriber(self, channel: str, buffer: int = 4, trigger: bool = False) -> Subscriber:
        """A subscriber of this vehicle's `channel` (`nav`, `sonar`, ...).
        With `trigger`, a dataflow run steps this process once a new sample
        has arrived on every trigger input (nothing in the other modes)."""
        cls, service = self._channel(channel, None)
        return Subscriber(self, service, cls, c.VEHICLE_LIMITS, buffer, channel, trigger)

    def rate_hz(self, process: str) -> float:
        """The scenario's rate of a process kind (`planner`, `sonar`, ...), Hz."""
        key = {"sim-plant": "plant", "camera-pose": "camera", "camera-sim": "camera"}.get(process, process)
        return float(self.scenario["rates"][f"{key}_hz"])

    def world(self, buffer: int = 4) -> Subscriber:
        """A subscriber of the run's world snapshot (what a sonar or camera reads)."""
        cls, fmt = c.RUN_CHANNELS["world"]
        base, per = c.WORLD_LIMITS
        n = len(self.scenario["vehicles"])
        limits = c.Limits(*(b + n * p for b, p in zip(base, per)))
        return Subscriber(self, fmt.format(run_id=self.run_id), cls, limits, buffer, "world")

    def publisher(self, channel: str) -> Publisher:
        """A publisher of this vehicle's `channel` (`setpoint`, ...)."""
        cls, service = self._channel(channel, None)
        return Publisher(self, service, cls, c.VEHICLE_LIMITS)

    def _notify_ready(self) -> None:
        name = iox2.ServiceName.new(c.DONE_SERVICE.format(run_id=self.run_id))
        done = self._node.service_builder(name).event().open()
        notifier = done.notifier_builder().create()
        a, b = c.READY_ID
        notifier.notify_with_custom_event_id(iox2.EventId.new(a * self.index + b * self.processes))
        self._done = (done, notifier)

    def stopping(self) -> bool:
        """True once SIGINT or SIGTERM asked the process to end."""
        return _STOP

    def steps(self) -> Iterator[Step]:
        """The step loop: one `Step` per wake-up until the run ends."""
        try:
            if self.mode == "lockstep":
                yield from self._lockstep()
            elif self.mode == "dataflow" and self._triggers:
                yield from self._dataflow()
            else:
                yield from self._realtime()
        finally:
            self._write_stats_file()

    def _after(self, step: Step) -> None:
        ns = time.monotonic_ns() - step.wake_mono_ns
        self.steps_taken += 1
        self._step_ns.record(ns)
        self._recent_ns.record(ns)
        if self._stats is not None and step.sim_time_ns >= self._next_stats_ns:
            self._next_stats_ns = (step.sim_time_ns // c.STATS_EVERY_NS + 1) * c.STATS_EVERY_NS
            try:
                self._stats.publish(self._stats_sample(), step)
            except Exception as e:  # noqa: BLE001 - statistics never stop a run
                print(f"shoal_node: stats not published: {e}", file=sys.stderr)
            self._recent_ns = Histogram()

    def _lockstep(self) -> Iterator[Step]:
        bell = Doorbell(self.run_id, self.processes)
        me = self.index
        seen = bell.seq(me)
        self._notify_ready()
        self._next_stats_ns = c.STATS_EVERY_NS
        try:
            while not _STOP:
                now = bell.wait(me, seen, 1.0)
                if now is None:
                    continue
                seen = now
                rung = bell.rung(me)
                step = Step(rung.tick, rung.sim_time_ns, rung.last, time.monotonic_ns())
                yield step
                self._after(step)
                if bell.finished(me, seen):
                    bell.notify_done()
        finally:
            bell.close()

    def _schedule(self) -> tuple[int, int, int, int]:
        """The phased timer, as the Rust runtime's `schedule`: activation k
        is due at epoch + phase + k·period (ns, monotonic); a restarted
        process joins at its next activation. Returns (period, phase,
        epoch, first k)."""
        period = max(int(round(self.args.period_s * 1e9)), 100_000)
        phase = max(int(round(self.args.phase_s * 1e9)), 0)
        epoch = self.args.epoch_mono_ns or time.monotonic_ns()
        k = 0
        if self.args.restart > 0:
            k = max(0, -(-(time.monotonic_ns() - epoch - phase) // period))
        return period, phase, epoch, k

    def _realtime(self) -> Iterator[Step]:
        period, phase, epoch, k = self._schedule()
        self._notify_ready()
        self._next_stats_ns = c.STATS_EVERY_NS
        while not _STOP:
            due = epoch + phase + k * period
            now = time.monotonic_ns()
            if now < due:
                time.sleep((due - now) * 1e-9)
                if _STOP:
                    break
                now = time.monotonic_ns()
            late = now - due
            if late >= period:
                missed = late // period
                self.deadline_misses += missed
                k += missed
                due += missed * period
                late = now - due
            self._wake_late.record(late)
            step = Step(k, phase + k * period, False, now)
            yield step
            self._after(step)
            k += 1

    def _dataflow(self) -> Iterator[Step]:
        period, phase, epoch, k = self._schedule()
        waitset = (
            iox2.WaitSetBuilder.new()
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc)
        )
        guards = [waitset.attach_notification(t) for t in self._triggers]
        print(
            f"shoal_node: {self.vehicle}/{self.process}: dataflow, stepping on the arrivals of "
            f"{', '.join(self._trigger_names)} (deadline every {period / 1e6:g} ms)",
            file=sys.stderr,
        )
        self._notify_ready()
        self._next_stats_ns = c.STATS_EVERY_NS
        pending = [False] * len(self._triggers)
        started = False  # no miss is counted before the first input arrived
        last_sim = 0
        while not _STOP:
            due = epoch + phase + k * period
            now = time.monotonic_ns()
            if now >= due:
                # The deadline: step with what there is, and count the miss.
                skipped = (now - due) // period
                k += skipped
                tick, k = k, k + 1
                if started:
                    self.deadline_misses += skipped + 1
                self._wake_late.record(now - (epoch + tick * period + phase))
                last_sim = max(last_sim, tick * period + phase)
                step = Step(tick, last_sim, False, now)
                yield step
                self._after(step)
                continue
            waitset.wait_and_process_with_timeout(iox2.Duration.from_nanos(due - now))
            for i, t in enumerate(self._triggers):
                if t.try_wait():
                    pending[i] = True
            if all(pending):
                pending = [False] * len(pending)
                started = True
                now = time.monotonic_ns()
                # This step stands for the frame whose activation is the
                # first due after now: the next one due is the frame after.
                first_after = -(-(now + 1 - epoch - phase) // period)
                k = max(k, first_after + 1)
                last_sim = max(last_sim, now - epoch)
                step = Step(k, last_sim, False, now)
                yield step
                self._after(step)
        del guards

    def _stats_sample(self):
        cls = c.RUN_CHANNELS["stats"][0]
        s = cls()
        s.vehicle[: len(self.vehicle[:15])] = self.vehicle[:15].encode()
        s.process[: len(self.process[:15])] = self.process[:15].encode()
        s.steps = self.steps_taken
        s.deadline_misses = self.deadline_misses
        s.step_p50_ns = self._step_ns.quantile(0.5)
        s.step_p99_ns = self._step_ns.quantile(0.99)
        s.step_max_ns = self._step_ns.max
        s.recent_step_p50_ns = self._recent_ns.quantile(0.5)
        s.recent_step_p99_ns = self._recent_ns.quantile(0.99)
        s.wake_late_p99_ns = self._wake_late.quantile(0.99)
        kinds = list(self._hops.kinds.items())[: len(s.hops)]
        for slot, (kind, h) in zip(s.hops, kinds):
            slot.channel[: len(kind[:15])] = kind[:15].encode()
            lat = h["latency"]
            slot.count = lat.n
            slot.p50_ns = lat.quantile(0.5)
            slot.p99_ns = lat.quantile(0.99)
            slot.p999_ns = lat.quantile(0.999)
            slot.max_ns = lat.max
        s.hop_count = len(kinds)
        s.lost = sum(h["lost"] for h in self._hops.kinds.values())
        s.rejected = sum(h["rejected"] for h in self._hops.kinds.values())
        return s

    def _write_stats_file(self) -> None:
        peak = None
        try:
            for line in Path("/proc/self/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    peak = int(line.split()[1])
        except OSError:
            pass
        doc = {
            "vehicle": self.vehicle,
            "process": self.process,
            "steps": self.steps_taken,
            "deadline_misses": self.deadline_misses,
            "step_ns": self._step_ns.buckets(),
            "wake_late_ns": self._wake_late.buckets(),
            "hops": [
                {"kind": k, "lost": h["lost"], "rejected": h["rejected"], "latency_ns": h["latency"].buckets()}
                for k, h in self._hops.kinds.items()
            ],
            "peak_rss_kib": peak,
        }
        d = Path(c.STATS_DIR.format(run_id=self.run_id))
        try:
            d.mkdir(parents=True, exist_ok=True)
            path = d / f"{self.vehicle}.{self.process}.json"
            tmp = path.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(doc))
            os.replace(tmp, path)
        except OSError as e:
            print(f"shoal_node: cannot write the stats file: {e}", file=sys.stderr)
