#!/usr/bin/env python3
"""Import a shoal recording with Rerun's own MCAP importer (PyPI `rerun-sdk`:
`rerun mcap convert`, then `rerun rrd print -vv`) and check that every channel's
messages (every channel that has any) were decoded by reflection into a struct holding every top-level field
of its ros2msg schema, rather than kept as raw bytes. No shoal code is used.
Prints a JSON report; exits non-zero on the first channel that is not decoded."""
import json
import os
import re
import subprocess
import sys
import tempfile

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


def main(path):
    # what the recording holds: topic -> (schema name, its top-level fields)
    topics = {}
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            # a channel without messages has nothing for Rerun to import
            if schema.encoding == "ros2msg" and counts.get(channel.id, 0) > 0:
                topics[channel.topic] = (schema.name, schema_fields(schema.data.decode()))
    if not topics:
        raise SystemExit("no ros2msg channel in the recording")

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

    # entity -> the struct type of its decoded `<schema>:message` column
    decoded = {}
    entity = None
    for line in printed.stdout.splitlines():
        m = re.match(r"Chunk\(\S+\) with \d+ rows \([^)]*\) - (\S+) -", line)
        if m:
            entity = m.group(1)
            continue
        if entity is not None and entity not in decoded:
            m = re.search(r"type: List\(Struct\((.*)", line)
            if m:
                decoded[entity] = m.group(1)

    report = {}
    for topic, (schema, fields) in sorted(topics.items()):
        ty = decoded.get(topic)
        if ty is None:
            raise SystemExit(f"{topic} ({schema}): no decoded message column in Rerun's import")
        missing = [f for f in fields if f'"{f}":' not in ty]
        if missing:
            raise SystemExit(f"{topic} ({schema}): Rerun's struct lacks {missing}")
        report[topic] = {"schema": schema, "fields": len(fields)}
    print(json.dumps({"channels": len(report), "decoded": report}))


if __name__ == "__main__":
    main(sys.argv[1])
