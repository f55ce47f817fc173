#!/usr/bin/env python3
"""Read a shoal recording as a ROS 2 bag with a reader nobody here wrote
(PyPI `rosbags`, pure Python, its own CDR decoder), and check what makes the
file a rosbag2 bag: `pkg/msg/Type` schema names, each channel's
`offered_qos_profiles`, and the `rosbag2` metadata record whose
`serialized_metadata` is the bag's metadata.yaml (read with the `mcap`
package, parsed with rosbags' own YAML library). Prints a JSON report; exits
non-zero on the first thing that does not hold."""
import json
import re
import sys
from pathlib import Path

from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

RESOURCE = re.compile(r"^[a-z][a-z0-9_]*/msg/[A-Z][A-Za-z0-9]*$")


def main(path):
    path = Path(path)
    counts = {}
    types = {}
    first, last = None, None
    qos_depths = set()
    with AnyReader([path]) as reader:
        for c in reader.connections:
            if not RESOURCE.match(c.msgtype):
                raise SystemExit(f"{c.topic}: type {c.msgtype!r} is not pkg/msg/Type")
            if not c.ext.offered_qos_profiles:
                raise SystemExit(f"{c.topic}: no offered_qos_profiles")
            qos_depths.update(q.depth for q in c.ext.offered_qos_profiles)
            types[c.topic] = c.msgtype
        for c, t, raw in reader.messages():
            msg = reader.deserialize(raw, c.msgtype)
            if msg.header.sim_time_ns != t:
                raise SystemExit(f"{c.topic}: header.sim_time_ns {msg.header.sim_time_ns} != timestamp {t}")
            counts[c.topic] = counts.get(c.topic, 0) + 1
            first = t if first is None else min(first, t)
            last = t if last is None else max(last, t)

    with open(path, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    if "rosbag2" not in meta:
        raise SystemExit("no `rosbag2` metadata record")
    info = YAML(typ="safe").load(meta["rosbag2"]["serialized_metadata"])["rosbag2_bagfile_information"]
    listed = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    for topic, n in counts.items():
        if topic not in listed:
            raise SystemExit(f"{topic} is not in serialized_metadata")
        if listed[topic]["message_count"] != n:
            raise SystemExit(f"{topic}: serialized_metadata says {listed[topic]['message_count']}, the file holds {n}")
        if listed[topic]["topic_metadata"]["type"] != types[topic]:
            raise SystemExit(f"{topic}: serialized_metadata type differs")
    if info["message_count"] != sum(counts.values()):
        raise SystemExit(f"message_count {info['message_count']} != {sum(counts.values())}")
    if info["relative_file_paths"] != [path.name] or [f["path"] for f in info["files"]] != [path.name]:
        raise SystemExit(f"the bag's files are {info['relative_file_paths']}, not [{path.name!r}]")
    if info["starting_time"]["nanoseconds_since_epoch"] != first or info["duration"]["nanoseconds"] != last - first:
        raise SystemExit("serialized_metadata's time span differs from the messages'")
    for name, t in listed.items():
        if name not in counts and t["message_count"] != 0:
            raise SystemExit(f"{name}: serialized_metadata counts {t['message_count']}, the file holds none")
    print(json.dumps({
        "messages": sum(counts.values()),
        "topics": len(counts),
        "types": sorted(set(types.values())),
        "qos_depths": sorted(qos_depths),
        "version": info["version"],
        "storage_identifier": info["storage_identifier"],
        "duration_ns": info["duration"]["nanoseconds"],
    }))


if __name__ == "__main__":
    main(sys.argv[1])
