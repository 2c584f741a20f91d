"""The one request every entry point builds: shell ``run``, ctest RUNNER, Docker entrypoint."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from pathlib import Path


class Mode(Enum):
    """Which caller's conventions the exit code follows."""

    #: ``ros-isolated-test run``: exit with the command's own code (128+N for a signal).
    SHELL = "shell"
    #: ctest RUNNER (run_test.py's contract): a command that cannot start counts as code 1.
    AMENT = "ament"


WAIT_TIMEOUT_ENV = "ROS_ISOLATED_TEST_WAIT_TIMEOUT"
DEFAULT_WAIT_TIMEOUT = 600.0


def wait_timeout_from_env(environ: Mapping[str, str] | None = None) -> float:
    """``ROS_ISOLATED_TEST_WAIT_TIMEOUT`` in seconds (default 10 minutes); ValueError if bad."""
    environ = os.environ if environ is None else environ
    text = environ.get(WAIT_TIMEOUT_ENV, "").strip()
    if not text:
        return DEFAULT_WAIT_TIMEOUT
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (value >= 0 and math.isfinite(value)):
        raise ValueError(
            f"{WAIT_TIMEOUT_ENV}={text!r} is not a number of seconds; set e.g. 600, or unset it"
        )
    return value


def test_name_of(result_file: Path) -> str:
    """The test a result file belongs to: its name without the producer's suffix."""
    name = result_file.name
    for suffix in (".gtest.xml", ".xunit.xml", ".xml"):
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


@dataclass(frozen=True)
class EnvAssignment:
    """One ``--env`` (``append=False``) or ``--append-env`` (``append=True``) argument."""

    name: str
    value: str
    append: bool = False


@dataclass(frozen=True)
class RunRequest:
    """Everything needed to reserve a domain, run one test and write its result."""

    command: tuple[str, ...]
    mode: Mode
    result_file: Path | None = None
    package_name: str | None = None
    output_file: Path | None = None
    env: tuple[EnvAssignment, ...] = ()
    skip_test: bool = False
    skip_return_code: int | None = None
    generate_result_on_success: bool = False
    timeout: float | None = None
    kill_grace: float = 5.0
    #: --discovery-range (or its variable); None: the runner's default policy.
    discovery_range: str | None = None
    #: How long to wait for a free ID when the pool is full, in seconds.
    wait_timeout: float = DEFAULT_WAIT_TIMEOUT
    #: Where the assignments in ``env`` came from, for messages (``--env`` or ``ENV``).
    env_origin: str = "--env"

    @property
    def test_name(self) -> str:
        """The result file's stem, the name ament gives the test; else the command's name."""
        if self.result_file is not None:
            return test_name_of(self.result_file)
        return Path(self.command[0]).name if self.command else "test"

    @property
    def package(self) -> str:
        """``--package-name``, else the result file's folder name, as run_test.py does."""
        if self.package_name:
            return self.package_name
        if self.result_file is not None and self.result_file.parent.name:
            return self.result_file.parent.name
        return "ros_isolated_test"
