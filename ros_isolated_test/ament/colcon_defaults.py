"""The CMake include added to a colcon defaults file that already has settings.

colcon reads one defaults file (``COLCON_DEFAULTS_FILE``, else ``$COLCON_HOME/defaults.yaml``)
and a workspace's may hold more than ours (``merge-install: true``, mixins, event
handlers, other CMake arguments). Adding the include must keep every one of them: the
file's text is edited where ``build``'s ``cmake-args`` are (found by PyYAML's marks, in
block or flow style alike), comments and layout stay, and the edit is checked by reading
the result back, every value as before plus the include, before anything is written.
PyYAML is what colcon reads the file with; it is imported here only, so without it (or
for a layout this cannot edit safely) the caller prints the lines to add instead.
"""

from __future__ import annotations

import copy
import importlib
import json
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ros_isolated_test.atomic_file import write_atomically

#: The CMake argument that names the include.
INCLUDE_ARG = "-DCMAKE_PROJECT_INCLUDE="


class DefaultsError(Exception):
    """The file cannot be changed safely; the message says why, in one line."""


@dataclass(frozen=True)
class Added:
    """What adding the include made of a defaults file."""

    #: The file's text with the include among build's cmake-args.
    text: str
    #: False when the file passed this very include already (text unchanged).
    changed: bool
    #: An include of another ros-isolated-test installation that this one replaced.
    replaced: str | None = None


def lines_to_add(include: Path) -> str:
    """The YAML to add by hand: build's cmake-args naming ``include``."""
    return f"build:\n  cmake-args:\n    - {_quoted(include)}\n"


def add_include(text: str, include: Path) -> Added:
    """``text`` (a colcon defaults file) with ``include`` among build's cmake-args.

    Raises :class:`DefaultsError` when PyYAML is missing, the text is not a YAML mapping
    colcon could read, it already names another project include (CMake takes one), or
    the edit would change anything else.
    """
    yaml = _yaml()
    try:
        before = yaml.safe_load(text)
        root = yaml.compose(text)
    except yaml.YAMLError as error:
        raise DefaultsError(f"it is not YAML that colcon can read ({_problem(error)})") from None
    if root is None:  # empty, or comments only
        joined = text if not text or text.endswith("\n") else text + "\n"
        return _checked(yaml, before, joined + lines_to_add(include), include, None)
    if not isinstance(root, yaml.MappingNode):
        raise DefaultsError("its top level is not a mapping of colcon verbs (build:, test:)")
    build = _value(root, "build")
    if build is None:
        flow = f'"build": {_flow_options(include)}'
        edited = _add_key(text, root, flow, _block_build(include), top=True)
        return _checked(yaml, before, edited, include, None)
    if _is_null(yaml, build):
        edited = _replace(text, build, _flow_options(include))
        return _checked(yaml, before, edited, include, None)
    if not isinstance(build, yaml.MappingNode):
        raise DefaultsError("its build: is not a mapping of colcon options")
    arguments = _value(build, "cmake-args")
    if arguments is None:
        flow = f'"cmake-args": [{_quoted(include)}]'
        block = f"cmake-args:\n  - {_quoted(include)}"
        edited = _add_key(text, build, flow, block, top=False)
        return _checked(yaml, before, edited, include, None)
    if _is_null(yaml, arguments):
        edited = _replace(text, arguments, f"[{_quoted(include)}]")
        return _checked(yaml, before, edited, include, None)
    if not isinstance(arguments, yaml.SequenceNode):
        raise DefaultsError("its build: cmake-args is not a list of arguments")
    return _into_list(yaml, text, before, arguments, include)


def add_to_file(path: Path, include: Path) -> Added:
    """Add ``include`` to the defaults file at ``path`` (made when missing), keeping the rest.

    A link is followed (the file it names is changed), and the file's mode is kept.
    """
    target = Path(os.path.realpath(path))
    try:
        text = target.read_text(encoding="utf-8")
        mode = stat.S_IMODE(target.stat().st_mode)
    except FileNotFoundError:
        text, mode = "", 0o644
    except (OSError, UnicodeError) as error:
        raise DefaultsError(f"it cannot be read ({error})") from None
    added = add_include(text, include)
    if added.changed:
        try:
            write_atomically(target, added.text.encode("utf-8"), mode)
        except OSError as error:
            raise DefaultsError(f"it cannot be written ({error})") from None
    return added


def said(path: Path, include: Path, added: Added) -> str:
    """One line for the person who asked: what happened to the file at ``path``."""
    argument = f"{INCLUDE_ARG}{include}"
    if not added.changed:
        return f"ros-isolated-test: {path} already passes {argument} to every build: unchanged"
    if added.replaced:
        return (
            f"ros-isolated-test: {path}: {added.replaced} replaced by {argument} in build's "
            "cmake-args; every other setting kept"
        )
    return (
        f"ros-isolated-test: {path}: {argument} added to build's cmake-args; every other "
        "setting kept"
    )


# --- the edits ----------------------------------------------------------------------------------


def _into_list(yaml: Any, text: str, before: Any, arguments: Any, include: Path) -> Added:
    """Append the include to build's cmake-args, or replace another installation's."""
    wanted = f"{INCLUDE_ARG}{include}"
    for item in arguments.value:
        value = item.value if isinstance(item, yaml.ScalarNode) else None
        if not isinstance(value, str) or not value.startswith(INCLUDE_ARG):
            continue
        if value == wanted:
            return Added(text, changed=False)
        if Path(value[len(INCLUDE_ARG) :]).name != include.name:
            raise DefaultsError(
                f"its build: cmake-args already pass {value}, and CMake takes one "
                f"CMAKE_PROJECT_INCLUDE: make a file that include()s both and name that one"
            )
        edited = _replace(text, item, _quoted(include))
        return _checked(yaml, before, edited, include, value)
    if arguments.flow_style:
        if arguments.value:
            edited = _insert(text, arguments.value[-1].end_mark.index, f", {_quoted(include)}")
        else:
            edited = _insert(text, text.index("[", arguments.start_mark.index) + 1,
                             _quoted(include))  # fmt: skip
        return _checked(yaml, before, edited, include, None)
    first, last = arguments.value[0], arguments.value[-1]
    dash = " " * _dash_column(text, first.start_mark.index)
    item = f"{dash}- {_quoted(include)}"
    if last.end_mark.column == 0:  # ended at the start of a line (a block scalar)
        edited = _insert(text, last.end_mark.index, item + "\n")
    else:
        end = text.find("\n", last.end_mark.index)
        edited = text + "\n" + item if end == -1 else _insert(text, end, "\n" + item)
    return _checked(yaml, before, edited, include, None)


def _add_key(text: str, mapping: Any, flow: str, block: str, top: bool) -> str:
    """``text`` with a key added to ``mapping``: ``flow`` or ``block``, as it is written.

    ``top``: the file's top level, where a new verb goes at the end.
    """
    if mapping.flow_style or not mapping.value:
        if mapping.value:
            return _insert(text, mapping.value[-1][1].end_mark.index, f", {flow}")
        return _insert(text, text.index("{", mapping.start_mark.index) + 1, flow)
    first_key = mapping.value[0][0]
    indent = " " * first_key.start_mark.column
    if top:
        lines = "".join(f"{indent}{line}\n" for line in block.splitlines())
        return (text if text.endswith("\n") else text + "\n") + lines
    # A nested mapping: the key goes first, where its first key starts.
    lines = block.replace("\n", "\n" + indent)
    return _insert(text, first_key.start_mark.index, f"{lines}\n{indent}")


def _checked(yaml: Any, before: Any, edited: str, include: Path, replaced: str | None) -> Added:
    """``edited``, once reading it back gives every setting of ``before`` plus the include."""
    wanted = f"{INCLUDE_ARG}{include}"
    expected = copy.deepcopy(before) if isinstance(before, dict) else {}
    build = expected.get("build")
    build = build if isinstance(build, dict) else {}
    expected["build"] = build
    arguments = build.get("cmake-args")
    arguments = list(arguments) if isinstance(arguments, list) else []
    if replaced is None:
        arguments.append(wanted)
    else:
        arguments = [wanted if argument == replaced else argument for argument in arguments]
    build["cmake-args"] = arguments
    try:
        after = yaml.safe_load(edited)
    except yaml.YAMLError:
        after = None
    if after != expected:
        raise DefaultsError("its layout is one this cannot edit without risk to its other settings")
    return Added(edited, changed=True, replaced=replaced)


# --- small helpers -------------------------------------------------------------------------------


def _yaml() -> Any:
    """PyYAML, as colcon has it; :class:`DefaultsError` when this Python lacks it."""
    try:
        return importlib.import_module("yaml")
    except ImportError:
        raise DefaultsError(
            "PyYAML (python3-yaml), which reads it as colcon does, is not installed for "
            "ros-isolated-test's Python"
        ) from None


def _problem(error: Any) -> str:
    """PyYAML's words for what is wrong, and where (lines and columns from 1)."""
    problem = getattr(error, "problem", None) or type(error).__name__
    mark = getattr(error, "problem_mark", None)
    return f"{problem}, line {mark.line + 1} column {mark.column + 1}" if mark else str(problem)


def _value(mapping: Any, key: str) -> Any:
    """The node of ``key`` in ``mapping``, or None."""
    for key_node, value_node in mapping.value:
        if getattr(key_node, "value", None) == key:
            return value_node
    return None


def _is_null(yaml: Any, node: Any) -> bool:
    return isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null"


def _replace(text: str, node: Any, new: str) -> str:
    """``text`` with ``node`` written as ``new``.

    An empty value (``build:`` and nothing after it) gets the blank YAML needs after the colon.
    """
    start = node.start_mark.index
    if start == node.end_mark.index and text[start - 1 : start] == ":":
        new = " " + new
    return text[:start] + new + text[node.end_mark.index :]


def _insert(text: str, index: int, new: str) -> str:
    return text[:index] + new + text[index:]


def _dash_column(text: str, index: int) -> int:
    """The column of the ``-`` that starts the block sequence item at ``index``."""
    line_start = text.rfind("\n", 0, index) + 1
    dash = text.rfind("-", line_start, index)
    return (dash if dash != -1 else index) - line_start


def _quoted(include: Path) -> str:
    """The include's argument as a YAML (and JSON) double-quoted string."""
    return json.dumps(f"{INCLUDE_ARG}{include}")


def _flow_options(include: Path) -> str:
    return f'{{"cmake-args": [{_quoted(include)}]}}'


def _block_build(include: Path) -> str:
    return f"build:\n  cmake-args:\n    - {_quoted(include)}"
