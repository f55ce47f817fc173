#!/usr/bin/env python3
"""Check a `shoal export --foxglove` MCAP against the OFFICIAL Foxglove schemas,
with no shoal code: PyPI `mcap` reads it, PyPI `foxglove-schemas-protobuf`
(Foxglove's own compiled message definitions) and `protobuf` judge it.

For every channel:
  * the schema is a Foxglove one (`foxglove.<Name>`), schema and message
    encoding `protobuf`;
  * the embedded FileDescriptorSet describes `foxglove.<Name>` exactly as the
    official definition does, recursively: the same fields with the same
    numbers, types, labels and nested message and enum types.
For every message:
  * it parses with the official class, leaves no unknown field anywhere, and
    re-encodes to the same bytes (nothing was written that protobuf drops);
  * quaternions are unit, colours in [0, 1], enums named values, publish time
    == log time, the message's own timestamps are sim times no later than
    its log time and at most 1 s earlier;
  * every frame an entity or pose refers to is connected to `world` by `/tf`.

With --self-test, broken copies of each channel's first message (an unknown
field, a bad wire type, a truncated field, a non-unit quaternion, a colour out
of range, a time from the future) must each be refused, so the check is known
to have teeth.

Prints a JSON report (per topic: schema, count, entity ids, primitives);
exits non-zero on the first failure, naming the topic, the message index and
the reason.
"""
import importlib
import json
import math
import sys

from google.protobuf import descriptor_pb2, descriptor_pool, unknown_fields
from google.protobuf.descriptor import FieldDescriptor
from google.protobuf.message import DecodeError
from mcap.reader import make_reader


class Bad(Exception):
    pass


def proto_class(schema_name):
    if not schema_name.startswith("foxglove."):
        raise Bad(f"schema {schema_name!r} is not a Foxglove schema")
    name = schema_name[len("foxglove."):]
    try:
        module = importlib.import_module(f"foxglove_schemas_protobuf.{name}_pb2")
    except ImportError as e:
        raise Bad(f"no official Foxglove message {schema_name!r}: {e}")
    return getattr(module, name)


def is_repeated(field):
    # protobuf >= 5 has is_repeated; older ones only label.
    rep = getattr(field, "is_repeated", None)
    if rep is not None:
        return rep() if callable(rep) else rep
    return field.label == FieldDescriptor.LABEL_REPEATED


def embedded_descriptor(schema):
    """The message descriptor the channel's FileDescriptorSet gives its schema name."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for file in fds.file:
        pool.Add(file)
    try:
        return pool.FindMessageTypeByName(schema.name)
    except KeyError:
        raise Bad(f"schema {schema.name}: its FileDescriptorSet has no such message")


def compare_descriptors(have, want, path, seen):
    """The embedded descriptor `have` describes exactly the official `want`."""
    if have.full_name != want.full_name:
        raise Bad(f"{path}: message {have.full_name} != official {want.full_name}")
    if want.full_name in seen:
        return
    seen.add(want.full_name)
    h = {f.name: f for f in have.fields}
    w = {f.name: f for f in want.fields}
    if set(h) != set(w):
        raise Bad(f"{path}: fields {sorted(h)} != official {sorted(w)}")
    for name, wf in w.items():
        hf = h[name]
        where = f"{path}.{name}"
        if (hf.number, hf.type, is_repeated(hf)) != (wf.number, wf.type, is_repeated(wf)):
            raise Bad(f"{where}: number/type/label {(hf.number, hf.type, is_repeated(hf))} "
                      f"!= official {(wf.number, wf.type, is_repeated(wf))}")
        if wf.type == FieldDescriptor.TYPE_MESSAGE:
            compare_descriptors(hf.message_type, wf.message_type, where, seen)
        elif wf.type == FieldDescriptor.TYPE_ENUM:
            hv = {(v.name, v.number) for v in hf.enum_type.values}
            wv = {(v.name, v.number) for v in wf.enum_type.values}
            if hv != wv:
                raise Bad(f"{where}: enum {sorted(hv)} != official {sorted(wv)}")


def no_unknown_fields(msg, path):
    if len(unknown_fields.UnknownFieldSet(msg)):
        raise Bad(f"{path}: unknown fields (not in the official definition)")
    for field, value in msg.ListFields():
        if field.type != FieldDescriptor.TYPE_MESSAGE:
            continue
        items = value if is_repeated(field) else [value]
        for i, item in enumerate(items):
            no_unknown_fields(item, f"{path}.{field.name}[{i}]")


def walk_checks(msg, path, frames_used, stamps):
    """Unit quaternions, colours in [0, 1], named enum values, frames referred to, timestamps."""
    name = msg.DESCRIPTOR.full_name
    if name == "google.protobuf.Timestamp":
        stamps.append(msg.seconds * 1_000_000_000 + msg.nanos)
        return
    if name == "google.protobuf.Duration":
        if msg.seconds < 0 or msg.nanos < 0:
            raise Bad(f"{path}: negative duration")
        return
    if name == "foxglove.Quaternion":
        n = math.sqrt(msg.x ** 2 + msg.y ** 2 + msg.z ** 2 + msg.w ** 2)
        if abs(n - 1.0) > 1e-6:
            raise Bad(f"{path}: quaternion norm {n}")
    if name == "foxglove.Color":
        for k in "rgba":
            v = getattr(msg, k)
            if not 0.0 <= v <= 1.0:
                raise Bad(f"{path}.{k}: colour component {v} outside [0, 1]")
    for field, value in msg.ListFields():
        where = f"{path}.{field.name}"
        items = value if is_repeated(field) else [value]
        if field.type == FieldDescriptor.TYPE_MESSAGE:
            for i, item in enumerate(items):
                walk_checks(item, f"{where}[{i}]", frames_used, stamps)
        elif field.type == FieldDescriptor.TYPE_ENUM:
            for v in items:
                if field.enum_type.values_by_number.get(v) is None:
                    raise Bad(f"{where}: {v} is not a value of {field.enum_type.full_name}")
        elif field.type == FieldDescriptor.TYPE_DOUBLE:
            for v in items:
                if not math.isfinite(v):
                    raise Bad(f"{where}: {v} is not finite")
        elif field.name.endswith("frame_id"):
            frames_used.add(value)


class Channel:
    """What is needed to judge the messages of one channel."""

    def __init__(self, schema, channel):
        topic = channel.topic
        if channel.message_encoding != "protobuf":
            raise Bad(f"{topic}: message encoding {channel.message_encoding!r}, want 'protobuf'")
        if schema.encoding != "protobuf":
            raise Bad(f"{topic}: schema encoding {schema.encoding!r}, want 'protobuf'")
        self.name = schema.name
        self.cls = proto_class(schema.name)
        compare_descriptors(embedded_descriptor(schema), self.cls.DESCRIPTOR, schema.name, set())

    def parse(self, data):
        msg = self.cls()
        try:
            msg.ParseFromString(data)
        except DecodeError as e:
            raise Bad(f"the official protobuf definition refuses it: {e}")
        return msg

    def check(self, data, log_time, frames_used):
        """The parsed message, or Bad unless `data` is a valid message logged at `log_time`."""
        msg = self.parse(data)
        no_unknown_fields(msg, self.name)
        if msg.SerializeToString(deterministic=True) != data:
            raise Bad("it does not re-encode to the same bytes")
        stamps = []
        walk_checks(msg, self.name, frames_used, stamps)
        for s in stamps:
            if s > log_time or log_time - s > 1_000_000_000:
                raise Bad(f"timestamp {s} ns is not the sim time of log time {log_time}")
        return msg


def first_field(msg, pred):
    """The first sub-message (depth first, `msg` included) for which pred holds."""
    if pred(msg):
        return msg
    for field, value in msg.ListFields():
        if field.type != FieldDescriptor.TYPE_MESSAGE:
            continue
        for item in (value if is_repeated(field) else [value]):
            found = first_field(item, pred)
            if found is not None:
                return found
    return None


def mutations(ch, data):
    """Broken copies of a good message, each of which the check must refuse."""
    out = [
        # field 1000, varint 1: unknown to every Foxglove message
        ("unknown field", data + bytes([0xC0, 0x3E, 0x01])),
        # field 1 with wire type 7, which does not exist
        ("bad wire type", bytes([0x0F]) + data),
        # a length-delimited field 1 that claims more bytes than there are
        ("truncated field", bytes([0x0A, 0x7F, 0x00])),
    ]

    def mutate(label, pred, fn):
        msg = ch.parse(data)
        target = first_field(msg, pred)
        if target is None:
            return
        fn(target)
        out.append((label, msg.SerializeToString(deterministic=True)))

    mutate("non-unit quaternion", lambda m: m.DESCRIPTOR.full_name == "foxglove.Quaternion",
           lambda q: setattr(q, "w", q.w * 2.0 + 1.0))
    mutate("colour out of range", lambda m: m.DESCRIPTOR.full_name == "foxglove.Color",
           lambda c: setattr(c, "r", 1.5))
    mutate("time from the future", lambda m: m.DESCRIPTOR.full_name == "google.protobuf.Timestamp",
           lambda t: setattr(t, "seconds", t.seconds + 10))
    return out


def main(path, self_test):
    report = {}
    channels = {}
    firsts = {}
    frames_used = set()
    tf_edges = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            topic = channel.topic
            if channel.id not in channels:
                try:
                    channels[channel.id] = Channel(schema, channel)
                except Bad as e:
                    raise SystemExit(str(e))
                report[topic] = {"schema": schema.name, "count": 0, "entities": set(), "primitives": {}}
            ch = channels[channel.id]
            entry = report[topic]
            where = f"{topic} message {entry['count']} (log time {message.log_time})"
            try:
                value = ch.check(message.data, message.log_time, frames_used)
                if message.publish_time != message.log_time:
                    raise Bad(f"publish time {message.publish_time} != log time")
            except Bad as e:
                raise SystemExit(f"{where}: {e}")
            if ch.name == "foxglove.FrameTransforms":
                for t in value.transforms:
                    tf_edges[t.child_frame_id] = t.parent_frame_id
            if ch.name == "foxglove.FrameTransform":
                tf_edges[value.child_frame_id] = value.parent_frame_id
            if ch.name == "foxglove.SceneUpdate":
                for e in value.entities:
                    entry["entities"].add(e.id)
                    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
                        entry["primitives"][kind] = entry["primitives"].get(kind, 0) + len(getattr(e, kind))
            firsts.setdefault(channel.id, (message.data, message.log_time))
            entry["count"] += 1
    if not report:
        raise SystemExit(f"{path}: no messages")
    for frame in sorted(frames_used):
        seen, cur = set(), frame
        while cur != "world":
            if cur in seen or cur not in tf_edges:
                raise SystemExit(f"frame {frame!r} is not connected to 'world' by the transforms")
            seen.add(cur)
            cur = tf_edges[cur]
    refused = 0
    if self_test:
        # The check must have teeth: broken copies of each channel's first
        # message are refused, each for its own reason.
        for cid, (data, log_time) in firsts.items():
            ch = channels[cid]
            for label, bad in mutations(ch, data):
                try:
                    ch.check(bad, log_time, set())
                except Bad:
                    refused += 1
                    continue
                raise SystemExit(f"self-test: a message with a {label} passed the {ch.name} check")
    for entry in report.values():
        entry["entities"] = sorted(entry["entities"])
    print(json.dumps({
        "messages": sum(c["count"] for c in report.values()),
        "channels": report,
        "frames": sorted(set(tf_edges) | {"world"}),
        "self_test_refused": refused,
    }))


if __name__ == "__main__":
    args = sys.argv[1:]
    self_test = "--self-test" in args
    files = [a for a in args if a != "--self-test"]
    if len(files) != 1:
        raise SystemExit("usage: check_foxglove.py [--self-test] EXPORT.mcap")
    main(files[0], self_test)
