"""A third-party client of a live shoal run.

Subscribes to one vehicle's `truth` channel with the official `iceoryx2`
Python package (0.10, the crate's version) while `shoal run` is running, and
prints what it received as JSON. Nothing here comes from shoal's Rust code:
the sample layout is declared from DESIGN.md's channel table and the domain
(prefix, root) from the run's `run.json`.

usage: live_truth.py OUT_DIR VEHICLE [--samples N] [--timeout S] [--hold]

With --hold it keeps its subscriber until the run's orchestrator (run.json's
pid) has exited, as a viewer left open would, and only then lets go.
"""

import argparse
import ctypes
import json
import math
import pathlib
import sys
import time

import iceoryx2 as iox2


class Header(ctypes.Structure):
    _fields_ = [
        ("seq", ctypes.c_uint64),
        ("sim_time_ns", ctypes.c_uint64),
        ("publish_mono_ns", ctypes.c_uint64),
        ("origin_mono_ns", ctypes.c_uint64),
        ("origin_sim_time_ns", ctypes.c_uint64),
    ]


class Truth(ctypes.Structure):
    """shoal.Truth.v1: ground truth of one vehicle (232 bytes)."""

    _fields_ = [
        ("header", Header),
        ("position_ned_m", ctypes.c_double * 3),
        ("q_body_to_ned_wxyz", ctypes.c_double * 4),
        ("euler_rpy_rad", ctypes.c_double * 3),
        ("velocity_body_mps", ctypes.c_double * 3),
        ("rates_body_radps", ctypes.c_double * 3),
        ("tau_applied", ctypes.c_double * 6),
        ("thrust_origin_mono_ns", ctypes.c_uint64),
        ("thrust_applied_mono_ns", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "shoal.Truth.v1"


def running(pid: int) -> bool:
    """True while the process exists and has not exited (a zombie waiting
    for its parent to reap it has)."""
    try:
        stat = pathlib.Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=pathlib.Path)
    ap.add_argument("vehicle")
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument("--hold", action="store_true")
    args = ap.parse_args()
    assert ctypes.sizeof(Truth) == 232, ctypes.sizeof(Truth)

    deadline = time.monotonic() + args.timeout
    run_json = args.out / "run.json"
    while not run_json.exists():
        if time.monotonic() > deadline:
            print(f"no {run_json}", file=sys.stderr)
            return 2
        time.sleep(0.05)
    run = json.loads(run_json.read_text())

    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    config = iox2.config.default()
    config.global_cfg.prefix = iox2.FileName.new(run["domain_prefix"])
    config.global_cfg.root_path = iox2.Path.new(run["domain_root"])
    node = (
        iox2.NodeBuilder.new()
        .name(iox2.NodeName.new("python-live-truth"))
        .config(config)
        .create(iox2.ServiceType.Ipc)
    )
    name = iox2.ServiceName.new(f"shoal/{run['run_id']}/{args.vehicle}/truth")

    # The service appears once the vehicle's sim-plant has started.
    service = None
    last_error = None
    while service is None:
        try:
            service = node.service_builder(name).publish_subscribe(Truth).open()
        except Exception as e:  # noqa: BLE001 - any open failure means "not yet"
            last_error = e
            if time.monotonic() > deadline:
                print(f"cannot open {name}: {last_error!r}", file=sys.stderr)
                return 2
            time.sleep(0.05)
    subscriber = service.subscriber_builder().create()

    got = []
    while len(got) < args.samples and time.monotonic() < deadline:
        sample = subscriber.receive()
        if sample is None:
            time.sleep(0.01)
            continue
        t = sample.payload().contents
        got.append(
            {
                "seq": int(t.header.seq),
                "sim_time_ns": int(t.header.sim_time_ns),
                "publish_mono_ns": int(t.header.publish_mono_ns),
                "position_ned_m": [float(x) for x in t.position_ned_m],
                "q_norm": math.sqrt(sum(float(x) ** 2 for x in t.q_body_to_ned_wxyz)),
            }
        )
        del sample
    if args.hold:
        pid = int(run["pid"])
        while running(pid) and time.monotonic() < deadline + 30:
            time.sleep(0.05)
        # still attached after the run ended: its samples are still readable
        while subscriber.receive() is not None:
            pass
    del subscriber
    del service
    del node
    print(json.dumps({"service": f"shoal/{run['run_id']}/{args.vehicle}/truth", "samples": got}))
    return 0 if len(got) >= args.samples else 1


if __name__ == "__main__":
    sys.exit(main())
