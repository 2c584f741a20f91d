"""A test command that runs until the pytest test lets it end: ``gate.py FOLDER NAME HOW``.

Each attempt says it is running (``FOLDER/NAME.ready.<k>``, ``k`` its attempt number)
and waits for ``FOLDER/NAME.go.<k>``, so the pytest test can look at the machine (``status``)
while the attempt surely runs, with no timing assumed. Then it ends as ``HOW`` says:
``pass``; ``fail`` (prints :data:`FAILURE` and exits 1); ``flaky`` (fails its first
attempt as ``fail`` does, passes the next).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

#: What a failing attempt prints: the message the report must show.
FAILURE = "AssertionError: the talker never heard its own token (expected 42, got 0)"
#: How often the gate is looked at; the pytest test's own deadline stops a hang.
POLL_SECONDS = 0.02


def attempt_number(folder: Path, name: str) -> int:
    """This attempt's number: one more than the attempts that said they were running."""
    return len(list(folder.glob(f"{name}.ready.*"))) + 1


def main(argv: list[str]) -> int:
    folder, name, how = Path(argv[0]), argv[1], argv[2]
    attempt = attempt_number(folder, name)
    print(f"{name}: attempt {attempt} running", flush=True)
    (folder / f"{name}.ready.{attempt}").touch()
    gate = folder / f"{name}.go.{attempt}"
    while not gate.exists():
        time.sleep(POLL_SECONDS)
    if how == "fail" or (how == "flaky" and attempt == 1):
        print(FAILURE, file=sys.stderr, flush=True)
        return 1
    print(f"{name}: passed", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
