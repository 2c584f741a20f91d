"""``ROS_ISOLATED_TEST_COLCON``: the one switch of every colcon extension of ours.

The colcon side's own reader (the runner's settings read the runner's variables). An
off word (``off``, ``0``, ``false``, ``no``) turns every extension off: a package then
builds and tests as without us. Unset or blank means on; any other word is said and
counts as on, so a typo never silently turns isolation off. The stable include reads
the same words from the environment at configure time (``project_include``).
"""

from __future__ import annotations

from collections.abc import Mapping

from ros_isolated_test.switches import NotOnOff, on_off

VARIABLE = "ROS_ISOLATED_TEST_COLCON"
#: What ``colcon --help`` and the docs say of it.
DESCRIPTION = (
    "Set to off to turn ros-isolated-test's colcon extensions off: no include for "
    "ament_cmake packages, no summary after colcon test"
)


def state(environ: Mapping[str, str]) -> tuple[bool, str | None]:
    """Whether our colcon extensions are on, and what to say of a word that is no switch."""
    value = environ.get(VARIABLE)
    try:
        return bool(on_off(value, True)), None
    except NotOnOff:
        return True, (
            f"{VARIABLE}={value!r} is neither on nor off; kept on. Set it to off to turn "
            "ros-isolated-test's colcon extensions off"
        )
