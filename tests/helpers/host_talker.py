#!/usr/bin/env python3
"""A test on one "host": publishes TOKEN until told to stop, having first heard itself.

Usage: host_talker.py TOKEN READY_FILE STOP_FILE [--max-seconds S]

Publishes TOKEN on token_listener.py's topic at 20 Hz and subscribes to it too. Once it
has heard its own token (so DDS works here with whatever discovery range it was given)
it creates READY_FILE, then keeps publishing until STOP_FILE exists or --max-seconds
pass. Prints one line ``RESULT {json}``; exits 0 if it heard itself.
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
    parser.add_argument("ready_file", type=Path)
    parser.add_argument("stop_file", type=Path)
    parser.add_argument("--max-seconds", type=float, default=40.0)
    args = parser.parse_args()

    started = time.monotonic()
    report = exchange(
        args.token,
        "host_talker",
        lambda _heard_for: (
            not args.stop_file.exists() and time.monotonic() < started + args.max_seconds
        ),
        on_heard=lambda: args.ready_file.write_text(str(os.getpid())),
    )
    print("RESULT " + json.dumps(report), flush=True)
    return 0 if report["own"] else 1


if __name__ == "__main__":
    sys.exit(main())
