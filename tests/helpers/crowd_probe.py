#!/usr/bin/env python3
"""One of N crosstalk probes run at once: talks on the shared topic until all N are up.

Usage: crowd_probe.py TOKEN RENDEZVOUS COUNT [--listen SECONDS] [--deadline SECONDS]

Publishes TOKEN on token_exchange.TOPIC and subscribes to it. Once it has heard its own
token (DDS works here), it writes RENDEZVOUS/TOKEN.ready holding its ROS_DOMAIN_ID; it
keeps talking until COUNT such files exist, so every probe is up and talking at the
same moment, then listens --listen seconds more. --deadline only stops a probe whose
peers never came. Prints one line ``RESULT {json}``; exits 0 only if it heard itself,
met all its peers, and heard nothing foreign.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

# Run as a program: its folder is on sys.path, the folder holding `helpers` is not.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from helpers.token_exchange import exchange


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("token")
    parser.add_argument("rendezvous", type=Path)
    parser.add_argument("count", type=int)
    parser.add_argument("--listen", type=float, default=5.0)
    parser.add_argument("--deadline", type=float, default=90.0)
    args = parser.parse_args()

    started = time.monotonic()
    listen: float = args.listen
    deadline: float = args.deadline
    met_at: float | None = None

    def arrive() -> None:
        partial = args.rendezvous / f"{args.token}.partial"
        partial.write_text(os.environ.get("ROS_DOMAIN_ID", ""))
        partial.rename(args.rendezvous / f"{args.token}.ready")

    def keep_going(_heard_for: float) -> bool:
        nonlocal met_at
        if met_at is None:
            if len(list(args.rendezvous.glob("*.ready"))) >= args.count:
                met_at = time.monotonic()
            else:
                return time.monotonic() < started + deadline
        return time.monotonic() < met_at + listen

    report = exchange(args.token, "crowd_probe", keep_going, on_heard=arrive)
    report["met_all"] = met_at is not None
    print("RESULT " + json.dumps(report), flush=True)
    return 0 if report["own"] and report["met_all"] and not report["foreign"] else 1


if __name__ == "__main__":
    sys.exit(main())
