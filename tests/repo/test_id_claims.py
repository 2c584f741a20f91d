"""Two sessions of this suite never pick one domain ID for two tests at once.

helpers/domains.py picks IDs free now and claims each until the test that picked it ends,
so a second session (xdist's other worker, a second checkout's run) never takes an ID this
one checked and is about to reserve. The other session here is a real process holding its
claims; the control: once it let go, its IDs can be picked again.
"""

from __future__ import annotations

import subprocess
import sys

from helpers import domains
from helpers.commands import HUNG, REPO

#: Another session: picks argv[1] IDs, says them, holds them until told, then lets go.
OTHER_SESSION = """
import sys
from helpers import domains
picked = domains.free_ids(int(sys.argv[1]))
print(*picked, flush=True)
sys.stdin.readline()
domains.release_claims()
print("released", flush=True)
sys.stdin.readline()
"""


def test_ids_another_session_picked_are_not_picked_until_it_lets_go() -> None:
    other = subprocess.Popen(
        [sys.executable, "-c", OTHER_SESSION, "6"],
        cwd=REPO / "tests", stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert other.stdin is not None and other.stdout is not None
    try:
        theirs = [int(word) for word in other.stdout.readline().split()]
        assert len(theirs) == 6, theirs
        ours = domains.free_ids(40)
        assert not set(ours) & set(theirs), f"picked IDs another session holds: {ours}"
        domains.release_claims()
        # The control: the same IDs, asked for alone, once the other session let go.
        other.stdin.write("\n")
        other.stdin.flush()
        assert other.stdout.readline().strip() == "released"
        again = domains.free_ids(len(theirs), candidates=theirs)
        assert set(again) & set(theirs), f"its IDs stayed claimed after it let go: {again}"
    finally:
        other.stdin.close()
        other.wait(timeout=HUNG)
        domains.release_claims()


def test_ids_one_test_picks_twice_are_distinct() -> None:
    first = domains.free_ids(3)
    second = domains.free_ids(3)
    assert not set(first) & set(second), (first, second)
