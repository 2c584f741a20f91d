"""The one request every entry point builds: shell ``run``, ctest RUNNER, Docker entrypoint.

Plain classes rather than dataclasses, as everywhere on a test's path: importing
``dataclasses`` would cost more than the runner's own work.
"""

from __future__ import annotations

import os
from enum import Enum
from pathlib import Path

from ros_isolated_test.process.supervisor import KILL_GRACE
from ros_isolated_test.xunit.canonical import test_name_of

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from ros_isolated_test.runner.settings import Settings
    from ros_isolated_test.shard.selection import Selection

__all__ = [
    "EnvAssignment",
    "Mode",
    "RunRequest",
]


class Mode(Enum):
    """Which caller's conventions the exit code follows."""

    #: ``ros-isolated-test run``: exit with the command's own code (128+N for a signal).
    SHELL = "shell"
    #: ctest RUNNER (run_test.py's contract): a command that cannot start counts as code 1.
    AMENT = "ament"


class EnvAssignment:
    """One ``--env`` (``append=False``) or ``--append-env`` (``append=True``) argument."""

    __slots__ = ("append", "name", "value")

    def __init__(self, name: str, value: str, append: bool = False) -> None:
        self.name = name
        self.value = value
        self.append = append

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, EnvAssignment):
            return NotImplemented
        return (self.name, self.value, self.append) == (other.name, other.value, other.append)

    def __hash__(self) -> int:
        return hash((self.name, self.value, self.append))

    def __repr__(self) -> str:
        return f"EnvAssignment({self.name!r}, {self.value!r}, append={self.append})"


class RunRequest:
    """Everything needed to reserve a domain, run one test and write its result.

    With a ``shard``, a package or test name no split can name raises
    :class:`~ros_isolated_test.shard.identity.PackageNameError`, a usage error.
    """

    __slots__ = (
        "command",
        "env",
        "env_origin",
        "generate_result_on_success",
        "kill_grace",
        "mode",
        "output_file",
        "package_name",
        "result_file",
        "settings",
        "shard",
        "skip_return_code",
        "skip_test",
        "timeout",
    )

    def __init__(
        self,
        command: tuple[str, ...],
        mode: Mode,
        settings: Settings,
        *,
        result_file: Path | None = None,
        package_name: str | None = None,
        output_file: Path | None = None,
        env: tuple[EnvAssignment, ...] = (),
        skip_test: bool = False,
        skip_return_code: int | None = None,
        generate_result_on_success: bool = False,
        timeout: float | None = None,
        kill_grace: float = KILL_GRACE,
        env_origin: str = "--env",
        shard: Selection | None = None,
    ) -> None:
        self.command = command
        self.mode = mode
        self.result_file = result_file
        self.package_name = package_name
        self.output_file = output_file
        self.env = env
        self.skip_test = skip_test
        self.skip_return_code = skip_return_code
        self.generate_result_on_success = generate_result_on_success
        self.timeout = timeout
        self.kill_grace = kill_grace
        #: The runner's settings (pool, lock dir, wait timeout, discovery range), read once
        #: by the entry point (settings.read): nothing deeper reads the environment.
        self.settings = settings
        #: Where the assignments in ``env`` came from, for messages (``--env`` or ``ENV``).
        self.env_origin = env_origin
        #: This machine's share of a split (``ROS_ISOLATED_TEST_SHARD``), read once by the
        #: entry point; None: no split, every test runs.
        self.shard = shard
        if shard is not None:
            # A split names the test <package>/<test>: a name that cannot form one is a
            # usage error here, where each entry point reports it, not a crash later.
            from ros_isolated_test.shard.identity import checked

            checked(self.package, self.test_name)

    def command_writing_to(self, own_result: Path) -> tuple[str, ...]:
        """The command with the result path it names pointed at ``own_result`` instead.

        An argument names it when it is that path, or ends in it after ``=`` or ``:``
        (``--junit-xml=PATH``, ``--gtest_output=xml:PATH``, as ament passes it); paths
        are compared made absolute, so ``./r.xml`` names ``r.xml``. The new path is given
        absolute: a test that changes directory still writes where the runner reads.
        """
        if self.result_file is None:
            return self.command
        wanted = os.path.abspath(self.result_file)
        own_result = Path(os.path.abspath(own_result))
        command = list(self.command)
        for index, word in enumerate(command):
            if not word.endswith(self.result_file.name):
                continue  # the cheap test first: a test's arguments can be long
            cuts = [0, *(at + 1 for at, char in enumerate(word) if char in "=:")]
            for cut in cuts:
                if word[cut:] and os.path.abspath(word[cut:]) == wanted:
                    command[index] = f"{word[:cut]}{own_result}"
                    break
        return tuple(command)

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
