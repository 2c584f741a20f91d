"""Whether the colcon on this PATH loads ros-isolated-test's colcon extension.

colcon loads extensions only from its own Python's entry points, so an install that
colcon does not see (another venv, the user site of another Python) leaves ``colcon
build`` and ``colcon test`` unisolated with nothing said. ``status`` asks: it finds
``colcon`` on PATH, reads the Python its script starts (the shebang, or the ``exec``
line pip writes when that path is too long for one), and asks that Python, with this
environment (its PYTHONPATH too, as colcon would have it), whether our event handler is
among its ``colcon_core.event_handler`` entry points. Not imported on the runner's path.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
from collections.abc import Mapping
from pathlib import Path

GROUP = "colcon_core.event_handler"
NAME = "ros_isolated_test"
#: Only stops a Python that hangs starting; the answer never depends on it.
_HUNG = 60
#: Run by colcon's Python: prints "yes" when our entry point is in the group.
_ASK = f"""\
import importlib.metadata as m
found = m.entry_points()
group = found.select(group={GROUP!r}) if hasattr(found, "select") else found.get({GROUP!r}, [])
print("yes" if any(entry.name == {NAME!r} for entry in group) else "no")
"""


def script_python(script: Path, path: str | None) -> str | None:
    """The Python a console script starts, or None when it says none.

    ``#!/path/python``, ``#!/usr/bin/env python3`` (found on ``path``), or pip's
    ``#!/bin/sh`` whose next line is ``'''exec' "/path/python" "$0" "$@"``.
    """
    try:
        with script.open("rb") as file:
            head = file.read(4096).decode("utf-8", "replace").splitlines()
    except OSError:
        return None
    if not head or not head[0].startswith("#!"):
        return None
    words = head[0][2:].split()
    if words and words[0] == "/bin/sh" and len(head) > 1 and head[1].startswith("'''exec' "):
        words = shlex.split(head[1][len("'''exec' ") :])[:1]
    elif words and Path(words[0]).name == "env":
        found = [word for word in words[1:] if not word.startswith("-")][:1]
        located = shutil.which(found[0], path=path) if found else None
        words = [located] if located else []
    return words[0] if words else None


def loads_us(python: str, environ: Mapping[str, str], where: Path) -> bool | None:
    """Whether ``python`` has our colcon entry point; None if it cannot say.

    Asked in ``environ`` from ``where`` (the script's folder, first on its path as on colcon's).
    """
    try:
        done = subprocess.run(
            [python, "-c", _ASK], env=dict(environ), capture_output=True, text=True,
            timeout=_HUNG, check=False, cwd=where,
        )  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return None
    answer = done.stdout.strip()
    return {"yes": True, "no": False}.get(answer) if done.returncode == 0 else None


def said(environ: Mapping[str, str] | None = None) -> str:
    """The one line ``status`` prints of colcon on this PATH and our extension."""
    environ = os.environ if environ is None else environ
    path = environ.get("PATH", os.defpath)
    colcon = shutil.which("colcon", path=path)
    if colcon is None:
        return "colcon: no colcon on PATH"
    python = script_python(Path(colcon), path)
    if python is None:
        return (
            f"colcon: cannot tell which Python colcon on PATH ({colcon}) runs; "
            f"`colcon extensions | grep {NAME}` shows whether it loads ros-isolated-test"
        )
    answer = loads_us(python, environ, Path(colcon).parent)
    if answer is None:
        return (
            f"colcon: colcon on PATH ({colcon}) runs {python}, which did not answer; "
            f"`colcon extensions | grep {NAME}` shows whether it loads ros-isolated-test"
        )
    if answer:
        return f"colcon: colcon on PATH ({colcon}) loads ros-isolated-test's extension"
    return (
        f"colcon: colcon on PATH ({colcon}) does not load ros-isolated-test's extension: "
        f"install ros-isolated-test into colcon's Python ({python}), see docs/install.md"
    )
