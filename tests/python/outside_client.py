"""An outside client of a shoal host agent, with PyPI's `eclipse-zenoh`.

It connects to one agent's endpoint, optionally with a certificate, and
tries what an intruder would: open a session, read everything (`**`), and
publish on a run's abort and clock keys and a world sample. It prints one
JSON line: whether the session opened (and the error if not), how many
samples it read and on which keys, and what it published.

    python3 outside_client.py --connect tls/169.254.77.1:7447 \
        --ca ca.pem --cert h2.pem --key h2.key --run RUN --seconds 5

Without --cert the client still trusts --ca (it can check the agent) but
presents no certificate of its own; without --ca it connects over tcp/.
"""

import argparse
import json
import sys
import time

import zenoh


def config(args):
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps("client"))
    c.insert_json5("connect/endpoints", json.dumps([args.connect]))
    c.insert_json5("scouting/multicast/enabled", "false")
    # Fail fast: one attempt, no retry.
    c.insert_json5("connect/timeout_ms", "3000")
    c.insert_json5("connect/exit_on_failure", "true")
    if args.ca:
        c.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(args.ca))
        c.insert_json5("transport/link/tls/verify_name_on_connect", "false")
    if args.cert:
        c.insert_json5("transport/link/tls/connect_certificate", json.dumps(args.cert))
        c.insert_json5("transport/link/tls/connect_private_key", json.dumps(args.key))
        c.insert_json5("transport/link/tls/enable_mtls", "true")
    return c


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--ca")
    p.add_argument("--cert")
    p.add_argument("--key")
    p.add_argument("--run", default="*", help="the run id whose keys to publish on")
    p.add_argument("--seconds", type=float, default=3.0)
    args = p.parse_args()
    out = {"opened": False, "error": None, "received": 0, "keys": [], "published": []}
    try:
        session = zenoh.open(config(args))
    except Exception as e:  # zenoh.ZError: the session could not open
        out["error"] = str(e)
        print(json.dumps(out))
        return 0
    out["opened"] = True
    keys = set()
    count = [0]

    def heard(sample):
        count[0] += 1
        keys.add(str(sample.key_expr))

    # Only what comes from the agent (not this session's own puts).
    sub = session.declare_subscriber("**", heard, allowed_origin=zenoh.Locality.REMOTE)
    run = args.run
    deadline = time.monotonic() + args.seconds
    reason = json.dumps({"from": "outside", "reason": "rogue"})
    while time.monotonic() < deadline:
        for key, payload in (
            (f"shoal-ctl/{run}/abort", reason.encode()),
            (f"shoal-ctl/{run}/clock", (10**9).to_bytes(8, "little")),
            (f"shoal/{run}/run/world", b"\x01" * 64),
        ):
            if run != "*":
                session.put(key, payload)
                if key not in out["published"]:
                    out["published"].append(key)
        time.sleep(0.2)
    sub.undeclare()
    session.close()
    out["received"] = count[0]
    out["keys"] = sorted(keys)[:50]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
