"""The ``ros_isolated_test.domain_coordinator`` package: its names, loaded lazily, and its name.

Each public name comes from the module that defines it, loaded on first use only: a
runner that reserves an ID never loads ``status`` and its helpers. An unknown name is an
AttributeError, as for any module. The package is named ``ros_isolated_test.
domain_coordinator`` on purpose: ROS ships a top-level ``domain_coordinator`` that a
sourced setup puts first on PYTHONPATH, and the runner must never load it (a scan of the
sources, with its control, and real runs with an exploding one first on the path).
"""

from __future__ import annotations

import ast
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import REPO, run_cli, run_runner
from lxml import etree

import ros_isolated_test.domain_coordinator as package

#: Each public name and the module (below the package) that defines it. Written out, not
#: read from the package's own ``_MODULE_OF``: that table is what these tests check.
DEFINED_IN = {
    "LOCK_DIR_ENV": "lock_dir",
    "LockDirError": "lock_dir",
    "ensure_lock_dir": "lock_dir",
    "lock_dir_from_env": "lock_dir",
    "POOL_ENV": "pool",
    "PoolSpecError": "pool",
    "parse_pool": "pool",
    "DomainCoordinator": "reservation",
    "Reservation": "reservation",
    "PoolExhaustedError": "waiting",
    "Squatter": "squatters",
    "DomainUse": "status",
    "domain_uses": "status",
}

#: In a fresh interpreter: which of the package's modules are loaded after each step.
LOADED_AFTER_EACH_NAME = """
import json, sys
import ros_isolated_test.domain_coordinator as package
prefix = package.__name__ + "."
def loaded():
    return sorted(name[len(prefix):] for name in sys.modules if name.startswith(prefix))
steps = [["import", loaded()]]
for name in sys.argv[1:]:
    getattr(package, name)
    steps.append([name, loaded()])
print(json.dumps(steps))
"""


def test_every_public_name_is_the_object_its_module_defines() -> None:
    assert sorted(package.__all__) == sorted(DEFINED_IN)
    for name, module in DEFINED_IN.items():
        defining = importlib.import_module(f"{package.__name__}.{module}")
        assert getattr(package, name) is getattr(defining, name), name


def test_an_unknown_name_is_an_attribute_error_naming_it() -> None:
    with pytest.raises(AttributeError, match=r"has no attribute 'no_such_name'"):
        package.no_such_name  # noqa: B018
    assert not hasattr(package, "parse")  # a name of a module's, not the package's
    assert hasattr(package, "parse_pool")  # the control: a public name is there


def test_a_name_loads_its_own_module_only_when_first_used() -> None:
    """Importing the package loads no module; ``POOL_ENV`` loads ``pool`` alone.

    The control: ``domain_uses`` does load ``status`` (and what it needs), so the
    check would see it.
    """
    done = subprocess.run(
        [sys.executable, "-c", LOADED_AFTER_EACH_NAME, "POOL_ENV", "domain_uses"],
        capture_output=True,
        text=True,
        check=True,
    )
    steps = dict(json.loads(done.stdout))
    assert steps["import"] == []
    assert steps["POOL_ENV"] == ["pool"]
    assert "status" in steps["domain_uses"]
    assert "reservation" not in steps["domain_uses"]


# -- the runner never loads upstream's top-level domain_coordinator ------------------------


def _upstream_imports(text: str, label: str) -> list[str]:
    """Where ``text`` imports upstream's top-level ``domain_coordinator``, as label:line."""
    found = []
    for node in ast.walk(ast.parse(text, filename=label)):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            names = [str(node.args[0].value)]
        found += [
            f"{label}:{getattr(node, 'lineno', '?')}: {name}"
            for name in names
            if name == "domain_coordinator" or name.startswith("domain_coordinator.")
        ]
    return found


def test_control_the_import_scan_finds_every_way_to_import_upstream() -> None:
    text = (
        "import domain_coordinator\n"
        "from domain_coordinator import domain_id\n"
        "import importlib; importlib.import_module('domain_coordinator.impl')\n"
        "from ros_isolated_test.domain_coordinator import POOL_ENV\n"
        "from .domain_coordinator import pool\n"
        "from . import domain_coordinator\n"
    )
    assert _upstream_imports(text, "x.py") == [
        "x.py:1: domain_coordinator",
        "x.py:2: domain_coordinator",
        "x.py:3: domain_coordinator.impl",
    ]


def test_no_source_file_imports_the_top_level_domain_coordinator() -> None:
    package_dir = REPO / "ros_isolated_test"
    sources = sorted(package_dir.rglob("*.py"))
    assert len(sources) > 10
    offenders = []
    for source in sources:
        label = str(source.relative_to(REPO))
        offenders += _upstream_imports(source.read_text(encoding="utf-8"), label)
    assert offenders == []


@pytest.fixture
def poisoned_env(env: dict[str, str], tmp_path: Path) -> dict[str, str]:
    """A sourced ROS setup puts upstream's domain_coordinator first; this one explodes."""
    fake = tmp_path / "fake_ros" / "domain_coordinator"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(
        "raise RuntimeError('upstream domain_coordinator must not be imported')\n"
    )
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(fake.parent), env.get("PYTHONPATH")]))
    probe = subprocess.run(
        [sys.executable, "-c", "import domain_coordinator"],
        check=False,
        env=env,
        capture_output=True,
        text=True,
    )
    assert probe.returncode != 0
    assert "must not be imported" in probe.stderr
    return env


def test_run_works_with_a_poisoned_domain_coordinator_first_on_pythonpath(
    poisoned_env: dict[str, str], tmp_path: Path
) -> None:
    result_file = tmp_path / "result.xml"
    result = run_cli(["run", "--junit-xml", str(result_file), "--", "true"], poisoned_env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Running with ROS_DOMAIN_ID" in result.stdout
    assert "must not be imported" not in result.stdout + result.stderr
    assert not etree.parse(str(result_file)).getroot().findall(".//error")
    status = run_cli(["status", "--json"], poisoned_env)
    assert status.returncode == 0, status.stderr


def test_ctest_runner_works_with_a_poisoned_domain_coordinator_first_on_pythonpath(
    poisoned_env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    result_file = tmp_path / "pkg" / "t.xml"
    args = [str(result_file), "--package-name", "pkg", "--generate-result-on-success"]
    result = run_runner(runner_script, [*args, "--command", "true"], poisoned_env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Running with ROS_DOMAIN_ID" in result.stdout
    assert "must not be imported" not in result.stdout + result.stderr
