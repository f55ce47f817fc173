#!/usr/bin/env python3
"""Check a file written by `shoal recover` with the official MCAP reader
(PyPI `mcap` + `mcap-ros2-support`), no shoal code: it has a summary with
statistics, chunk indexes and message indexes; reading through the index
(log-time order) and linearly gives the same messages; every message decodes.

Usage: check_recovered.py RECOVERED.mcap
Prints a JSON report; exits non-zero on the first problem."""
import json
import sys

from mcap.reader import make_reader, NonSeekingReader
from mcap_ros2.decoder import DecoderFactory


def main(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            raise SystemExit("no summary section")
        if summary.statistics is None:
            raise SystemExit("no statistics record")
        n_stats = summary.statistics.message_count
        if summary.statistics.message_count > 0 and not summary.chunk_indexes:
            raise SystemExit("messages but no chunk index")
        indexed = 0
        last = -1
        # Through the chunk and message indexes, in log-time order.
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            if message.log_time < last:
                raise SystemExit(f"log time went back: {message.log_time} < {last}")
            last = message.log_time
            if decoded.header.sim_time_ns != message.log_time:
                raise SystemExit(f"{channel.topic}: decoded header disagrees with the record")
            indexed += 1
    # The same file read front to back without the summary.
    with open(path, "rb") as f:
        linear = sum(1 for _ in NonSeekingReader(f).iter_messages())
    if not (indexed == linear == n_stats):
        raise SystemExit(f"indexed {indexed}, linear {linear}, statistics {n_stats}")
    print(json.dumps({
        "messages": indexed,
        "channels": len(summary.channels),
        "schemas": len(summary.schemas),
        "chunks": len(summary.chunk_indexes),
        "metadata": len(summary.metadata_indexes),
    }))


if __name__ == "__main__":
    main(sys.argv[1])
