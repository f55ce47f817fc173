#!/usr/bin/env python3
"""Check a `shoal export --foxglove` MCAP against the OFFICIAL Foxglove schemas,
with no shoal code: PyPI `mcap` reads it, PyPI `foxglove-schemas-protobuf`
(Foxglove's own message definitions) and `jsonschema` judge it.

For every channel:
  * the schema is a Foxglove one (`foxglove.<Name>`), its encoding `jsonschema`,
    the message encoding `json`;
  * the embedded JSON schema has title `foxglove.<Name>` and describes exactly
    the fields of the official protobuf definition, recursively, with matching
    types (double -> number, bool -> boolean, enums -> their numbers, ...).
For every message:
  * it is strict JSON (no NaN/Infinity) and validates against the embedded schema
    (types, required fields, ranges);
  * it parses into the official protobuf message with
    `json_format.ParseDict(..., ignore_unknown_fields=False)` after the Foxglove
    JSON times `{sec, nsec}` are written in protobuf's JSON form; so an unknown
    field or a wrong type fails;
  * quaternions are unit, colours in [0, 1], publish time == log time, the
    message's own timestamps are sim times no later than its log time and at
    most 1 s earlier;
  * every frame an entity or pose refers to is connected to `world` by `/tf`.

With --self-test, broken copies of each channel's first message (unknown
fields, a number as a string, a float time, a missing field, a non-unit
quaternion, fractional nanoseconds) must each be refused, so the check is
known to have teeth.

Prints a JSON report (per topic: schema, count, entity ids, primitives);
exits non-zero on the first failure, naming the topic, the message index and
the reason.
"""
import copy
import importlib
import json
import math
import sys
import time

import jsonschema
from google.protobuf import json_format
from google.protobuf.descriptor import FieldDescriptor
from mcap.reader import make_reader

TIME_TYPES = {"google.protobuf.Timestamp": "time", "google.protobuf.Duration": "duration"}
SCALAR_JSON = {
    FieldDescriptor.TYPE_DOUBLE: "number",
    FieldDescriptor.TYPE_FLOAT: "number",
    FieldDescriptor.TYPE_BOOL: "boolean",
    FieldDescriptor.TYPE_STRING: "string",
    FieldDescriptor.TYPE_BYTES: "string",
    FieldDescriptor.TYPE_UINT32: "integer",
    FieldDescriptor.TYPE_INT32: "integer",
    FieldDescriptor.TYPE_UINT64: "integer",
    FieldDescriptor.TYPE_INT64: "integer",
    FieldDescriptor.TYPE_FIXED32: "integer",
    FieldDescriptor.TYPE_FIXED64: "integer",
}


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


def compare_schema(js, desc, path):
    """The JSON schema `js` describes exactly the protobuf message `desc`."""
    props = js.get("properties")
    if js.get("type") != "object" or not isinstance(props, dict):
        raise Bad(f"{path}: schema is not an object with properties")
    want = {f.name for f in desc.fields}
    have = set(props)
    if want != have:
        raise Bad(f"{path}: schema fields {sorted(have)} != official {sorted(want)}")
    for f in desc.fields:
        p = props[f.name]
        where = f"{path}.{f.name}"
        if is_repeated(f):
            if p.get("type") != "array":
                raise Bad(f"{where}: repeated field is not an array in the schema")
            p = p["items"]
        if f.type == FieldDescriptor.TYPE_MESSAGE:
            full = f.message_type.full_name
            if full in TIME_TYPES:
                if p.get("title") != TIME_TYPES[full] or set(p.get("properties", {})) != {"sec", "nsec"}:
                    raise Bad(f"{where}: {full} is not a {{sec, nsec}} {TIME_TYPES[full]} in the schema")
            else:
                if p.get("title") != full:
                    raise Bad(f"{where}: schema title {p.get('title')!r} != official {full!r}")
                compare_schema(p, f.message_type, where)
        elif f.type == FieldDescriptor.TYPE_ENUM:
            consts = {o.get("const") for o in p.get("oneOf", [])}
            numbers = {v.number for v in f.enum_type.values}
            if consts != numbers:
                raise Bad(f"{where}: enum values {sorted(consts)} != official {sorted(numbers)}")
        else:
            if p.get("type") != SCALAR_JSON[f.type]:
                raise Bad(f"{where}: schema type {p.get('type')!r} for protobuf type {f.type}")


def to_proto_json(value, desc, path, stamps):
    """Foxglove JSON -> protobuf JSON, guided by the official descriptor.
    Only real time/duration fields are rewritten; anything else is passed on
    as it is, so ParseDict judges it (unknown keys stay and fail)."""
    if not isinstance(value, dict):
        raise Bad(f"{path}: expected an object, got {type(value).__name__}")
    out = {}
    fields = {f.name: f for f in desc.fields}
    for key, v in value.items():
        f = fields.get(key)
        if f is None or f.type != FieldDescriptor.TYPE_MESSAGE:
            out[key] = v
            continue
        conv = lambda item, i=None: convert_field(item, f, f"{path}.{key}" + ("" if i is None else f"[{i}]"), stamps)
        if is_repeated(f):
            if not isinstance(v, list):
                raise Bad(f"{path}.{key}: expected an array")
            out[key] = [conv(item, i) for i, item in enumerate(v)]
        else:
            out[key] = conv(v)
    return out


def sec_nsec(v, path, signed):
    if not isinstance(v, dict) or set(v) != {"sec", "nsec"}:
        raise Bad(f"{path}: a time must be exactly {{sec, nsec}}, got {v!r}")
    sec, nsec = v["sec"], v["nsec"]
    if type(sec) is not int or type(nsec) is not int:
        raise Bad(f"{path}: sec and nsec must be integers, got {v!r}")
    if not (0 <= nsec < 1_000_000_000) or (sec < 0 and not signed):
        raise Bad(f"{path}: out of range {v!r}")
    return sec, nsec


def convert_field(v, f, path, stamps):
    full = f.message_type.full_name
    if full == "google.protobuf.Timestamp":
        sec, nsec = sec_nsec(v, path, signed=False)
        stamps.append(sec * 1_000_000_000 + nsec)
        return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(sec)) + f".{nsec:09d}Z"
    if full == "google.protobuf.Duration":
        sec, nsec = sec_nsec(v, path, signed=True)
        if sec < 0 and nsec:
            raise Bad(f"{path}: negative durations with nanoseconds are ambiguous")
        return f"{sec}.{nsec:09d}s"
    return to_proto_json(v, f.message_type, path, stamps)


def walk_checks(value, path, frames_used):
    """Unit quaternions, colours in [0, 1], frames referred to."""
    if isinstance(value, dict):
        keys = set(value)
        if keys == {"x", "y", "z", "w"}:
            n = math.sqrt(sum(value[k] ** 2 for k in "xyzw"))
            if abs(n - 1.0) > 1e-6:
                raise Bad(f"{path}: quaternion norm {n}")
        if keys == {"r", "g", "b", "a"}:
            for k in "rgba":
                if not 0.0 <= value[k] <= 1.0:
                    raise Bad(f"{path}.{k}: colour component {value[k]} outside [0, 1]")
        if "frame_id" in value and isinstance(value["frame_id"], str):
            frames_used.add(value["frame_id"])
        for k, v in value.items():
            walk_checks(v, f"{path}.{k}", frames_used)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            walk_checks(v, f"{path}[{i}]", frames_used)


def reject_constant(name):
    raise Bad(f"non-JSON number {name}")


class Channel:
    """What is needed to judge the messages of one channel."""

    def __init__(self, schema, channel):
        topic = channel.topic
        if channel.message_encoding != "json":
            raise Bad(f"{topic}: message encoding {channel.message_encoding!r}, want 'json'")
        if schema.encoding != "jsonschema":
            raise Bad(f"{topic}: schema encoding {schema.encoding!r}, want 'jsonschema'")
        self.name = schema.name
        self.cls = proto_class(schema.name)
        js = json.loads(schema.data)
        if js.get("title") != schema.name:
            raise Bad(f"{topic}: schema title {js.get('title')!r} != schema name {schema.name!r}")
        compare_schema(js, self.cls.DESCRIPTOR, schema.name)
        vcls = jsonschema.validators.validator_for(js)
        vcls.check_schema(js)
        self.validator = vcls(js)

    def check(self, value, log_time, frames_used):
        """Raises Bad unless `value` is a valid message logged at `log_time`."""
        errors = sorted(self.validator.iter_errors(value), key=lambda e: list(e.path))
        if errors:
            e = errors[0]
            raise Bad(f"schema: {e.message} at {'/'.join(map(str, e.path))}")
        stamps = []
        converted = to_proto_json(value, self.cls.DESCRIPTOR, self.name, stamps)
        try:
            json_format.ParseDict(converted, self.cls(), ignore_unknown_fields=False)
        except json_format.ParseError as e:
            raise Bad(f"official protobuf definition refuses it: {e}")
        walk_checks(value, self.name, frames_used)
        for s in stamps:
            if s > log_time or log_time - s > 1_000_000_000:
                raise Bad(f"timestamp {s} ns is not the sim time of log time {log_time}")


def first_object(value, pred):
    """The first dict inside `value` (depth first) for which pred holds."""
    if isinstance(value, dict):
        if pred(value):
            return value
        for v in value.values():
            found = first_object(v, pred)
            if found is not None:
                return found
    elif isinstance(value, list):
        for v in value:
            found = first_object(v, pred)
            if found is not None:
                return found
    return None


def mutations(value):
    """Broken copies of a good message, each of which the check must refuse."""
    out = []

    def mutate(label, fn):
        v = copy.deepcopy(value)
        if fn(v) is not False:
            out.append((label, v))

    def top_unknown(v):
        v["bogus"] = 1

    def nested_unknown(v):
        o = first_object(v, lambda d: {"x", "y", "z"} <= set(d))
        if o is None:
            return False
        o["extra"] = 0.0

    def number_as_string(v):
        o = first_object(v, lambda d: isinstance(d.get("x"), float))
        if o is None:
            return False
        o["x"] = str(o["x"])

    def time_as_float(v):
        o = first_object(v, lambda d: "timestamp" in d)
        if o is None:
            return False
        o["timestamp"] = 1.5

    def missing_required(v):
        del v[next(iter(v))]

    def non_unit_quaternion(v):
        o = first_object(v, lambda d: set(d) == {"x", "y", "z", "w"})
        if o is None:
            return False
        o["w"] = o["w"] * 2.0 + 1.0

    def integer_as_float(v):
        o = first_object(v, lambda d: isinstance(d.get("nsec"), int))
        if o is None:
            return False
        o["nsec"] = o["nsec"] + 0.5

    for label, fn in [
        ("unknown top-level field", top_unknown),
        ("unknown nested field", nested_unknown),
        ("number written as a string", number_as_string),
        ("time written as a float", time_as_float),
        ("required field missing", missing_required),
        ("non-unit quaternion", non_unit_quaternion),
        ("fractional nanoseconds", integer_as_float),
    ]:
        mutate(label, fn)
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
                value = json.loads(message.data, parse_constant=reject_constant)
                ch.check(value, message.log_time, frames_used)
                if message.publish_time != message.log_time:
                    raise Bad(f"publish time {message.publish_time} != log time")
            except Bad as e:
                raise SystemExit(f"{where}: {e}")
            if ch.name == "foxglove.FrameTransforms":
                for t in value["transforms"]:
                    tf_edges[t["child_frame_id"]] = t["parent_frame_id"]
            if ch.name == "foxglove.FrameTransform":
                tf_edges[value["child_frame_id"]] = value["parent_frame_id"]
            if ch.name == "foxglove.SceneUpdate":
                for e in value["entities"]:
                    entry["entities"].add(e["id"])
                    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
                        entry["primitives"][kind] = entry["primitives"].get(kind, 0) + len(e[kind])
            firsts.setdefault(channel.id, (value, message.log_time))
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
        for cid, (value, log_time) in firsts.items():
            ch = channels[cid]
            for label, bad in mutations(value):
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
