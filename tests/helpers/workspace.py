"""The example package (examples/crosstalk_demo) built once per session, tested many times.

The demo's own helpers (examples/crosstalk_workspace.py) build and run it, so the demo and
the tests check exactly the same thing. A build per runner is configured once per session
(the runner is baked into CTestTestfile.cmake); every test then runs ``colcon test`` on
that build, after clearing what an earlier run left in it. A build is per distro too: Jazzy's
(the suite's own venv, as ever) and Kilted's (.venv-kilted's colcon, CMake prefix, Python
and installed runner, with the environment its sourced setup would give: helpers/distros.py).
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from helpers.commands import REPO
from helpers.distros import JAZZY, Distro

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Run, Toolchain


def crosstalk_workspace() -> ModuleType:
    """``examples/crosstalk_workspace.py`` (examples/ is no package), loaded once by path."""
    loaded = sys.modules.get("crosstalk_workspace")
    if loaded is not None:
        return loaded
    path = REPO / "examples" / "crosstalk_workspace.py"
    spec = importlib.util.spec_from_file_location("crosstalk_workspace", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being created
    spec.loader.exec_module(module)
    return module


class CrosstalkBuilds:
    """The session's builds of the example package, one per runner and distro, made on first use."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.ws = crosstalk_workspace()
        self._bases: dict[tuple[str, str], Path] = {}
        self.builds = 0  # colcon builds made, so a test can prove there was only one each

    def toolchain(self, distro: Distro = JAZZY) -> Toolchain:
        """The venv that builds and tests for ``distro``, with this process's environment now.

        Jazzy's is the suite's own interpreter and environment, unchanged; another distro's
        starts from this environment made over as that distro's sourced setup would.
        """
        if distro == JAZZY:
            default: Toolchain = self.ws.THIS_PYTHON
            return default
        made: Toolchain = self.ws.Toolchain(
            python=str(distro.python), prefix=str(distro.prefix), base_env=distro.env(os.environ)
        )
        return made

    def workspace(self, distro: Distro = JAZZY) -> Path:
        """Jazzy's builds where they always were; another distro's in a folder of its own."""
        return self.root if distro == JAZZY else self.root / distro.name

    def base(self, runner: str, distro: Distro = JAZZY) -> Path:
        """The build of the package for ``runner`` (built now if this is the first ask)."""
        key = (distro.name, runner)
        if key not in self._bases:
            toolchain = self.toolchain(distro)
            if runner == "isolated" and (problem := self.ws.isolated_runner_problem(toolchain)):
                raise AssertionError(f"ros-isolated-test's runner is not available: {problem}")
            self._bases[key] = self.ws.build(self.workspace(distro), runner, toolchain)
            self.builds += 1
        return self._bases[key]

    def fresh(self, runner: str, distro: Distro = JAZZY) -> Path:
        """The build for ``runner``, with no result file or record of an earlier test run."""
        base = self.base(runner, distro)
        package: str = self.ws.PACKAGE
        for stale in (base / "build" / package / "test_results").glob("**/*.xml"):
            stale.unlink()
        for stale in (base / "records").glob("*.json"):
            stale.unlink()
        return base

    def test(self, runner: str, jobs: int = 6, distro: Distro = JAZZY) -> Run:
        """``colcon test --ctest-args -jJOBS`` on the session's build, as ``ws.run`` does it.

        Reads the environment of this process at call time (pool, lock dir), like
        ``ws.run``; only the build step is skipped, since the session made it already.
        """
        ws = self.ws
        base = self.fresh(runner, distro)
        toolchain = self.toolchain(distro)
        record_dir = base / "records"
        record_dir.mkdir(exist_ok=True)
        _, test_output = ws._colcon(
            ["--log-base", str(base / "log"), "test", *ws._common(base), "--ctest-args",
             f"-j{jobs}"],
            cwd=self.workspace(distro),
            extra_env={"CROSSTALK_RECORD_DIR": str(record_dir)},
            toolchain=toolchain,
        )  # fmt: skip
        runner_path, tokens = ws.registered_tests(base)
        records = ws.read_records(record_dir)
        cases = tuple(
            ws.Case(name, token, records.get(token)) for name, token in sorted(tokens.items())
        )
        run: Run = ws.Run(
            runner=runner,
            runner_path=runner_path,
            base=base,
            build_seconds=0.0,
            test_seconds=0.0,
            test_output=test_output,
            cases=cases,
            result=ws.result_summary(base, toolchain),
        )
        return run


#: The zero-edit example's packages and the talker every crosstalk test runs.
ZERO_EDIT = REPO / "examples" / "zero_edit"
TOKEN_TALKER = REPO / "examples" / "crosstalk_demo" / "test" / "token_talker.py"


def two_talker_packages(root: Path, second: str, tokens: tuple[str, ...]) -> None:
    """``root/src``: zero_edit_talkers, zero_edit_py and a copy of the talkers as ``second``.

    The copy's three tests publish ``tokens``, so the two packages' six tests all differ;
    the token talker sits where the packages' tests look for it.
    """
    import shutil

    src = root / "src" / "zero_edit"
    for name in ("zero_edit_talkers", "zero_edit_py"):
        shutil.copytree(ZERO_EDIT / name, src / name)
    copy = src / second
    shutil.copytree(ZERO_EDIT / "zero_edit_talkers", copy)
    for name in ("CMakeLists.txt", "package.xml"):
        text = (copy / name).read_text().replace("zero_edit_talkers", second)
        (copy / name).write_text(text.replace("ivy juniper kale", " ".join(tokens)))
    talker = root / "src" / "crosstalk_demo" / "test"
    talker.mkdir(parents=True)
    shutil.copy(TOKEN_TALKER, talker)
