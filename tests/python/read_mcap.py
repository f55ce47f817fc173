#!/usr/bin/env python3
"""Decode every message of a shoal recording with the official MCAP readers
(PyPI `mcap` + `mcap-ros2-support`) and no shoal code. Prints a JSON report;
exits non-zero on the first message that does not decode or whose decoded
header disagrees with the MCAP record."""
import json
import math
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main(path):
    counts = {}
    schemas = {}
    first = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            h = decoded.header
            if h.sim_time_ns != message.log_time:
                raise SystemExit(f"{channel.topic}: header.sim_time_ns {h.sim_time_ns} != log_time {message.log_time}")
            if (h.seq & 0xFFFFFFFF) != message.sequence:
                raise SystemExit(f"{channel.topic}: header.seq {h.seq} != sequence {message.sequence}")
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            schemas[channel.topic] = schema.name
            if channel.topic not in first and h.seq == 5:
                sample = {}
                for field in ("position_ned_m", "q_body_to_ned_wxyz", "tau", "ranges_m", "depth_m", "valid"):
                    if hasattr(decoded, field):
                        v = getattr(decoded, field)
                        sample[field] = list(v) if not isinstance(v, (int, float)) else v
                first[channel.topic] = sample
            if schema.name == "shoal_msgs/msg/Truth":
                q = decoded.q_body_to_ned_wxyz
                n = math.sqrt(sum(x * x for x in q))
                if abs(n - 1.0) > 1e-6:
                    raise SystemExit(f"{channel.topic}: quaternion norm {n}")
        summary = reader.get_summary()
    print(json.dumps({
        "messages": sum(counts.values()),
        "counts": counts,
        "schemas": schemas,
        "samples": first,
        "statistics_messages": summary.statistics.message_count if summary and summary.statistics else None,
    }))


if __name__ == "__main__":
    main(sys.argv[1])
