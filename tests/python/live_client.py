#!/usr/bin/env python3
"""A client of the Foxglove WebSocket protocol (ws-protocol's v1 spec, which
the Foxglove SDK serves under the subprotocol name `foxglove.sdk.v1`),
written from the protocol's published specification with PyPI `websockets`,
no shoal code and no Foxglove SDK: it connects to `shoal run --live`, reads
`serverInfo` and the `advertise`ments, subscribes, and decodes the binary
`messageData` frames from the schema the server advertised: `cdr` with
mcap-ros2-support's decoder (the recorded channels), `protobuf` with the
`protobuf` package from the advertised FileDescriptorSet (the scene).

usage: live_client.py URL [--subscribe TOPIC]... [--count N] [--stall S]

  --subscribe TOPIC  subscribe to TOPIC (repeatable; default: none)
  --count N          stop after N messages on every subscribed topic (default 20)
  --stall S          a slow client: subscribe to EVERY channel, then read
                     nothing for S seconds (the server must not stall the
                     run for it), then drain what is left until closed

Prints a JSON report: the server's name, every advertised topic with its
schema, and per subscribed topic the messages received, their log times,
the header's sim times and seqs as decoded (CDR), the scene entities' ids
(protobuf SceneUpdate), and each payload in hex (so a test can compare them
with the recording's bytes).
"""
import base64
import json
import struct
import sys
import time

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


def connect_retrying(url, timeout_s=30.0):
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return connect(url, subprotocols=[SUBPROTOCOL], open_timeout=5, max_size=None)
        except (OSError, TimeoutError) as e:
            if time.monotonic() > deadline:
                raise SystemExit(f"cannot connect to {url}: {e}")
            time.sleep(0.1)


def decoder_for(ch, factory):
    """A decoder of the channel's messages, from what the server advertised."""
    encoding, schema_encoding = ch["encoding"], ch.get("schemaEncoding")
    if (encoding, schema_encoding) == ("cdr", "ros2msg"):
        schema = Schema(id=ch["id"], name=ch["schemaName"], encoding="ros2msg",
                        data=ch["schema"].encode())
        return factory.decoder_for("cdr", schema)
    if (encoding, schema_encoding) == ("protobuf", "protobuf"):
        # a binary schema travels base64-encoded in the advertisement
        fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
        pool = descriptor_pool.DescriptorPool()
        for f in fds.file:
            pool.Add(f)
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))
        return cls.FromString
    raise SystemExit(f"{ch['topic']}: encoding {encoding}/{schema_encoding}")


def main():
    args = sys.argv[1:]
    if not args:
        raise SystemExit(__doc__)
    url, args = args[0], args[1:]
    subscribe, count, stall = [], 20, None
    while args:
        flag, value, args = args[0], args[1], args[2:]
        if flag == "--subscribe":
            subscribe.append(value)
        elif flag == "--count":
            count = int(value)
        elif flag == "--stall":
            stall = float(value)
        else:
            raise SystemExit(f"unknown flag {flag}")

    with connect_retrying(url) as ws:
        session(ws, subscribe, count, stall)


def session(ws, subscribe, count, stall):
    if ws.subprotocol != SUBPROTOCOL:
        raise SystemExit(f"server chose subprotocol {ws.subprotocol!r}")
    server_info = None
    channels = {}  # id -> advertised channel
    subscriptions = {}  # subscription id -> channel id
    decoders = {}
    factory = DecoderFactory()
    received = {}
    report = {"subscribed": {}}

    def subscribe_to(topics):
        subs = []
        for cid, ch in channels.items():
            if ch["topic"] in topics and cid not in subscriptions.values():
                sid = len(subscriptions) + 1
                subscriptions[sid] = cid
                subs.append({"id": sid, "channelId": cid})
        if subs:
            ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def handle(msg):
        nonlocal server_info
        if isinstance(msg, str):
            d = json.loads(msg)
            op = d.get("op")
            if op == "serverInfo":
                server_info = d
            elif op == "advertise":
                for ch in d["channels"]:
                    channels[ch["id"]] = ch
            elif op == "unadvertise":
                for cid in d["channelIds"]:
                    channels.pop(cid, None)
            return
        if msg[0] != MESSAGE_DATA:
            return
        sid, log_time = struct.unpack_from("<IQ", msg, 1)
        payload = msg[13:]
        ch = channels[subscriptions[sid]]
        topic = ch["topic"]
        if topic not in decoders:
            decoders[topic] = decoder_for(ch, factory)
        decoded = decoders[topic](payload)
        entry = received.setdefault(topic, {"count": 0, "log_times": [], "sim_times": [],
                                            "seqs": [], "entities": [], "payload_hex": []})
        for e in getattr(decoded, "entities", []):
            if e.id not in entry["entities"]:
                entry["entities"].append(e.id)
        entry["count"] += 1
        entry["log_times"].append(log_time)
        header = getattr(decoded, "header", None)
        # shoal's own header (a camera frame's is std_msgs/Header: a stamp)
        if hasattr(header, "sim_time_ns"):
            entry["sim_times"].append(header.sim_time_ns)
            entry["seqs"].append(header.seq)
        entry["payload_hex"].append(bytes(payload).hex())

    # serverInfo, then the advertisements (the recorder advertises every channel at start)
    deadline = time.monotonic() + 30
    while server_info is None or not channels:
        if time.monotonic() > deadline:
            raise SystemExit("no serverInfo and advertise within 30 s")
        handle(ws.recv(timeout=30))
    # let a burst of advertisements arrive
    try:
        while True:
            handle(ws.recv(timeout=0.5))
    except TimeoutError:
        pass

    if stall is not None:
        subscribe_to({ch["topic"] for ch in channels.values()})
        time.sleep(stall)
    else:
        missing = set(subscribe) - {ch["topic"] for ch in channels.values()}
        if missing:
            raise SystemExit(f"not advertised: {sorted(missing)}")
        subscribe_to(set(subscribe))
    try:
        while True:
            if stall is None and subscribe and all(
                received.get(t, {}).get("count", 0) >= count for t in subscribe
            ):
                break
            handle(ws.recv(timeout=60))
    except Exception as e:  # closed by the server at the run's end, or a time-out
        report["closed"] = type(e).__name__
    report["server"] = server_info.get("name")
    report["capabilities"] = server_info.get("capabilities")
    report["advertised"] = {ch["topic"]: ch["schemaName"] for ch in channels.values()}
    report["subscribed"] = received
    print(json.dumps(report))


if __name__ == "__main__":
    main()
