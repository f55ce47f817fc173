#!/usr/bin/env python3
"""Import an MCAP with Rerun's own MCAP importer (PyPI `rerun-sdk`:
`rerun mcap convert`, then `rerun rrd print -vv`) and check that every channel's
messages (every channel that has any) were understood rather than kept as raw
bytes. No shoal code is used.

* A ros2msg channel (a shoal recording) or a protobuf channel (a
  `shoal export --foxglove` file) must be decoded by reflection into a struct
  holding every top-level field of its schema (ros2msg text, or the message
  in the channel's protobuf FileDescriptorSet),
* unless Rerun converts it into one of its own archetypes: then the report
  names the archetype (`Transform3D` for `foxglove.FrameTransforms`,
  `InstancePoses3D` for `foxglove.PoseInFrame`, ...), and `--expect
  TOPIC=ARCHETYPE` requires it.

Prints a JSON report; exits non-zero on the first channel that is not decoded."""
import json
import os
import re
import subprocess
import sys
import tempfile

from google.protobuf import descriptor_pb2
from mcap.reader import make_reader


def schema_fields(text):
    """Top-level field names of a ros2msg schema (the part before the first MSG section)."""
    fields = []
    for line in text.split("\n"):
        if line.startswith("====="):
            break
        line = line.split("#", 1)[0].strip()
        if line:
            fields.append(line.split()[1])
    return fields


def protobuf_fields(name, data):
    """Top-level field names of message `name` in a serialized FileDescriptorSet."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(data)
    for file in fds.file:
        for message in file.message_type:
            full = f"{file.package}.{message.name}" if file.package else message.name
            if full == name:
                return [f.name for f in message.field]
    raise SystemExit(f"schema {name}: no such message in its FileDescriptorSet")


def main(path, expect):
    # what the file holds: topic -> (schema name, its top-level fields)
    topics = {}
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            # a channel without messages has nothing for Rerun to import
            if counts.get(channel.id, 0) == 0:
                continue
            if schema.encoding == "ros2msg":
                topics[channel.topic] = (schema.name, schema_fields(schema.data.decode()))
            elif schema.encoding == "protobuf":
                topics[channel.topic] = (schema.name, protobuf_fields(schema.name, schema.data))
            else:
                raise SystemExit(f"{channel.topic}: schema encoding {schema.encoding!r} is neither ros2msg nor protobuf")
    if not topics:
        raise SystemExit("no channel with messages in the file")

    # no usage data leaves a test machine (Rerun's documented opt-out; idempotent)
    subprocess.run(["rerun", "analytics", "disable"], capture_output=True, check=False)
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        rrd = os.path.join(tmp, "recording.rrd")
        conv = subprocess.run(
            ["rerun", "mcap", "convert", path, "-o", rrd],
            capture_output=True, text=True, env=env, check=False,
        )
        if conv.returncode != 0:
            raise SystemExit(f"rerun mcap convert failed ({conv.returncode}): {conv.stderr[-2000:]}")
        unresolved = [l for l in conv.stderr.splitlines() if "cannot be resolved" in l]
        if unresolved:
            raise SystemExit("Rerun kept channels as raw data:\n" + "\n".join(unresolved[:5]))
        printed = subprocess.run(
            ["rerun", "rrd", "print", "-vv", rrd],
            capture_output=True, text=True, env=env, check=False,
        )
        if printed.returncode != 0:
            raise SystemExit(f"rerun rrd print failed: {printed.stderr[-2000:]}")

    # entity -> the struct type of its decoded `<schema>:message` column,
    # and the archetypes of its data columns
    decoded = {}
    archetypes = {}
    entity = None
    for line in printed.stdout.splitlines():
        m = re.match(r"Chunk\(\S+\) with \d+ rows \([^)]*\) - (\S+) -", line)
        if m:
            entity = m.group(1)
            continue
        if entity is None:
            continue
        if entity not in decoded:
            m = re.search(r"type: List\(Struct\((.*)", line)
            if m:
                decoded[entity] = m.group(1)
        for a in re.findall(r"archetype: ([A-Za-z0-9_.]+)", line):
            if not a.startswith("Mcap"):
                archetypes.setdefault(entity, set()).add(a)

    report = {}
    for topic, (schema, fields) in sorted(topics.items()):
        # the archetype named after the schema is the reflected message itself
        found = sorted(archetypes.get(topic, set()) - {schema, schema.replace("/", ".")})
        ty = decoded.get(topic)
        if ty is not None:
            missing = [f for f in fields if f'"{f}":' not in ty]
            if missing:
                raise SystemExit(f"{topic} ({schema}): Rerun's struct lacks {missing}")
            report[topic] = {"schema": schema, "fields": len(fields), "archetypes": found}
        elif found:
            report[topic] = {"schema": schema, "archetypes": found}
        else:
            raise SystemExit(f"{topic} ({schema}): neither decoded nor converted by Rerun's import")
    for topic, archetype in expect:
        got = report.get(topic, {}).get("archetypes", [])
        if archetype not in got:
            raise SystemExit(f"{topic}: Rerun made {got or 'no archetype'} of it, not {archetype}")
    print(json.dumps({"channels": len(report), "decoded": report}))


if __name__ == "__main__":
    args = sys.argv[1:]
    expect = []
    while len(args) >= 2 and args[0] == "--expect":
        topic, _, archetype = args[1].partition("=")
        expect.append((topic, archetype))
        args = args[2:]
    if len(args) != 1:
        raise SystemExit("usage: check_rerun.py [--expect TOPIC=ARCHETYPE]... FILE.mcap")
    main(args[0], expect)
