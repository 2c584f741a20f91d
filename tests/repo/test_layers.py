"""The package's imports: no circles, and none from a lower layer to a higher one.

The layers, highest first (``LAYERS``): the ways in at the top (the ``cli`` package and
``__main__``; the ``pytest_plugin`` package with its launch cases; the ``colcon``
extension), then ``ament`` (the ctest RUNNER, its arguments and where it is installed: a
way in too, below the others because the command and colcon point users at its script
and include), then ``runner`` (a request turned into an exit code), then ``history``,
then ``report`` (a tree of result files counted, printed and drawn: it reads each file
through ``xunit``, and sits below ``runner`` so that a runner may read what a report
wrote, such as measured durations), then ``domain_coordinator``, then ``process`` and
``xunit``, then ``shard`` (splitting tests over machines: all the above read it), then
at the bottom ``schemas``, ``text``, ``switches``, ``atomic_file``, ``libc`` (the C
library's prctl and renameat2), ``names`` (the
registry of variables and properties), ``not_run`` (the base of the errors that stop a
test before it runs) and the package's own ``__init__`` (its version). A module imports
within its own unit (a package, or the modules named together below) or from any lower
layer, never from a higher one. Two units of one layer do not import each other:
``process`` and ``xunit`` share no code (nor do the CLI, the plugin and the colcon
extension), so either can change without the other; the bottom is one unit. Within a
unit, imports go sideways, without circles.

Every import counts (see ``helpers.imports``): at module level, inside a function, and
under ``TYPE_CHECKING``. A lazy import hides a circle from Python's start-up but leaves
the two modules unable to be read or moved apart; a type taken from a higher layer ties
the lower one to it just the same (``result_file`` naming ``RunRequest`` did).
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

from helpers.commands import REPO
from helpers.imports import circles, import_graph, unplaced, upward_imports

PACKAGE = REPO / "ros_isolated_test"

#: Highest first: a module's first name below the package ("" for the package itself)
#: -> its unit.
LAYERS = (
    {
        "cli": "cli",
        "__main__": "cli",
        "pytest_plugin": "pytest plugin",
        "colcon": "colcon extension",
    },
    {"ament": "ament"},
    {"runner": "runner"},
    {"history": "history"},
    {"report": "report"},
    {"domain_coordinator": "domain_coordinator"},
    {"process": "process", "xunit": "xunit"},
    {"shard": "shard"},
    {
        "": "bottom",
        "atomic_file": "bottom",
        "libc": "bottom",
        "names": "bottom",
        "not_run": "bottom",
        "schemas": "bottom",
        "switches": "bottom",
        "text": "bottom",
    },
)

#: A synthetic package: ``top`` over ``low`` and ``side`` (one layer) over the package.
#: The ``# planted`` imports make a circle (through a lazy relative import one way and a
#: ``TYPE_CHECKING`` import the other), an upward import and a sideways one.
_SYNTHETIC = {
    "__init__.py": "VERSION = '1'\n",
    "top.py": "from pkg.low import base\nTHING = base\n",
    "low/__init__.py": "",
    "low/base.py": textwrap.dedent(
        """
        from pkg import VERSION


        def helped() -> object:
            from . import helper
            return helper
        """
    ),
    "low/helper.py": textwrap.dedent(
        """
        TYPE_CHECKING = False
        if TYPE_CHECKING:
            import pkg.low.base  # planted
        """
    ),
    "low/leak.py": "from pkg import top  # planted\n",
    "side.py": "from pkg.low.base import helped  # planted\n",
}
_SYNTHETIC_LAYERS = ({"top": "top"}, {"low": "low", "side": "side"}, {"": "root"})


def _synthetic(root: Path, planted: bool) -> Path:
    package = root / "pkg"
    for name, text in _SYNTHETIC.items():
        path = package / name
        path.parent.mkdir(parents=True, exist_ok=True)
        # Unplanted, each planted import becomes a ``pass`` where it stood.
        path.write_text(text if planted else re.sub(r"(?m)^( *)\S.*# planted$", r"\1pass", text))
    return package


def test_control_the_walk_finds_a_planted_circle_and_imports_against_the_layers(
    tmp_path: Path,
) -> None:
    graph = import_graph(_synthetic(tmp_path, planted=True))
    assert circles(graph) == [["pkg.low.base", "pkg.low.helper"]]
    assert upward_imports(graph, _SYNTHETIC_LAYERS) == [
        "pkg.low.leak:1 imports pkg.top: top is above low",
        "pkg.side:1 imports pkg.low.base: low is beside side, in one layer",
    ]
    assert unplaced(graph, _SYNTHETIC_LAYERS) == []
    assert unplaced(graph, _SYNTHETIC_LAYERS[1:]) == ["pkg.top"]


def test_control_the_same_package_without_the_planted_imports_is_clean(tmp_path: Path) -> None:
    graph = import_graph(_synthetic(tmp_path, planted=False))
    # The downward and within-unit imports are still seen: the walk is not blind.
    assert graph["pkg.top"] == {"pkg.low.base": 1}
    assert graph["pkg.low.base"] == {"pkg": 2, "pkg.low.helper": 6}
    assert circles(graph) == []
    assert upward_imports(graph, _SYNTHETIC_LAYERS) == []


def test_every_module_of_the_package_has_a_layer() -> None:
    graph = import_graph(PACKAGE)
    assert "ros_isolated_test.runner.session" in graph, "the walk must see the package"
    assert unplaced(graph, LAYERS) == []


def test_no_import_circle() -> None:
    found = circles(import_graph(PACKAGE))
    assert found == [], "modules that import each other round: " + "; ".join(
        " <-> ".join(circle) for circle in found
    )


def test_no_import_from_a_higher_layer() -> None:
    found = upward_imports(import_graph(PACKAGE), LAYERS)
    assert found == [], "\n".join(found)
