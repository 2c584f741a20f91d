"""``ament.colcon_defaults``: the include added to a defaults file, every setting kept.

Each layout a defaults file is written in (block and flow style, JSON as action-ros-ci
writes it, an empty or null ``build:``, comments, another installation's include) gets
the include, and reading the result back as colcon does (PyYAML) gives every value it
had plus the include; comments and the other lines stay as they were. What cannot be
edited safely (not YAML, not a mapping, another project include) leaves the file as it
is, with a one-line reason. Real files for the file-level cases (a link, its mode).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from difflib import SequenceMatcher
from pathlib import Path
from typing import Any

import pytest
import yaml  # type: ignore[import-untyped]

from ros_isolated_test.ament import colcon_defaults
from ros_isolated_test.ament.colcon_defaults import DefaultsError, add_include, add_to_file

INCLUDE = Path('/opt/a "quoted" dir: with # and/ros_isolated_test_project_include.cmake')
ARGUMENT = f"-DCMAKE_PROJECT_INCLUDE={INCLUDE}"

#: Defaults files as people write them; each gains the include and keeps the rest.
LAYOUTS = {
    "empty": "",
    "comments only": "# my defaults\n",
    "no build": "test:\n  merge-install: true\n",
    "build without cmake-args": "build:\n  merge-install: true  # merged layout\n",
    "no newline at the end": "build:\n  merge-install: true",
    "block list": (
        "build:\n  merge-install: true\n  cmake-args:\n    - -DFOO=1  # keep this\n"
        "    - -DBAR=2\n  symlink-install: true\ntest:\n  merge-install: true\n"
    ),
    "block list, dashes flush": "build:\n  cmake-args:\n  - -DFOO=1\n",
    "block list, last a literal": "build:\n  cmake-args:\n    - |\n      -DX=1\n",
    "flow list": "build:\n  cmake-args: [-DFOO=1, '-DBAR=two words']\n",
    "empty flow list": "build:\n  cmake-args: []\n",
    "null cmake-args": "build:\n  cmake-args:\n  merge-install: true\n",
    "flow build": "build: {merge-install: true, cmake-args: [-DFOO=1]}\n",
    "null build": "build:\ntest:\n  parallel-workers: 2\n",
    "tilde build": "build: ~\n",
    "JSON": '{"build": {"merge-install": true}, "test": {"parallel-workers": 4}}',
    "JSON without build": '{\n  "test": {"parallel-workers": 4}\n}\n',
    "empty JSON": "{}",
}


def _with_include(before: Any) -> dict[str, Any]:
    """What colcon must read after the edit: ``before``, and the include last in build's list."""
    expected: dict[str, Any] = dict(before or {})
    build = dict(expected.get("build") or {})
    build["cmake-args"] = [*(build.get("cmake-args") or []), ARGUMENT]
    expected["build"] = build
    return expected


@pytest.mark.parametrize("text", LAYOUTS.values(), ids=LAYOUTS.keys())
def test_every_layout_keeps_every_setting_and_gains_the_include(text: str) -> None:
    added = add_include(text, INCLUDE)
    assert added.changed and added.replaced is None
    assert yaml.safe_load(added.text) == _with_include(yaml.safe_load(text)), added.text
    # Nothing of the text is lost, comments included: the edit only inserts (and writes a
    # null value, "~" or nothing, as the list it becomes).
    edits = SequenceMatcher(None, text, added.text, autojunk=False).get_opcodes()
    removed = [text[i1:i2] for tag, i1, i2, _, _ in edits if tag in ("replace", "delete")]
    assert all(part.strip() in ("", "~") for part in removed), (removed, added.text)
    # Adding again changes nothing.
    again = add_include(added.text, INCLUDE)
    assert (again.changed, again.text) == (False, added.text)


def test_comments_and_order_stay_where_they_were() -> None:
    text = LAYOUTS["block list"]
    assert add_include(text, INCLUDE).text == text.replace(
        "    - -DBAR=2\n", f"    - -DBAR=2\n    - {json.dumps(ARGUMENT)}\n"
    )


def test_another_installations_include_is_replaced_in_place() -> None:
    old = "-DCMAKE_PROJECT_INCLUDE=/old/prefix/ros_isolated_test_project_include.cmake"
    text = f"build:\n  cmake-args: [{old}, -DA=1]\n  merge-install: true\n"
    added = add_include(text, INCLUDE)
    assert added.replaced == old
    assert yaml.safe_load(added.text) == {
        "build": {"cmake-args": [ARGUMENT, "-DA=1"], "merge-install": True}
    }


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("build: [\n", "it is not YAML that colcon can read (expected the node content"),
        ("- build\n", "its top level is not a mapping of colcon verbs"),
        ("build: [merge-install]\n", "its build: is not a mapping of colcon options"),
        ("build:\n  cmake-args: -DX=1\n", "its build: cmake-args is not a list of arguments"),
        (
            "build:\n  cmake-args: [-DCMAKE_PROJECT_INCLUDE=/mine/setup.cmake]\n",
            "already pass -DCMAKE_PROJECT_INCLUDE=/mine/setup.cmake, and CMake takes one",
        ),
    ],
    ids=["not-yaml", "a-list", "build-a-list", "cmake-args-a-string", "another-include"],
)
def test_what_cannot_be_edited_safely_is_refused_with_the_reason(text: str, reason: str) -> None:
    with pytest.raises(DefaultsError) as raised:
        add_include(text, INCLUDE)
    assert str(raised.value).startswith(reason) or reason in str(raised.value), raised.value
    assert "\n" not in str(raised.value)


def test_the_file_is_changed_where_a_link_points_its_mode_kept(tmp_path: Path) -> None:
    real = tmp_path / "dotfiles" / "defaults.yaml"
    real.parent.mkdir()
    real.write_text("build:\n  merge-install: true\n")
    real.chmod(0o600)
    link = tmp_path / "defaults.yaml"
    link.symlink_to(real)
    added = add_to_file(link, INCLUDE)
    assert added.changed and link.is_symlink()
    assert real.read_text() == added.text
    assert real.stat().st_mode & 0o777 == 0o600
    assert yaml.safe_load(real.read_text())["build"]["merge-install"] is True


def test_a_missing_file_is_made_and_an_unchanged_one_not_written(tmp_path: Path) -> None:
    path = tmp_path / ".colcon" / "defaults.yaml"
    assert add_to_file(path, INCLUDE).changed
    assert yaml.safe_load(path.read_text()) == {"build": {"cmake-args": [ARGUMENT]}}
    before = path.stat()
    assert not add_to_file(path, INCLUDE).changed
    assert path.stat().st_ino == before.st_ino and path.stat().st_mtime_ns == before.st_mtime_ns


def test_a_refused_file_is_left_byte_for_byte(tmp_path: Path) -> None:
    path = tmp_path / "defaults.yaml"
    path.write_text("build: [\n")
    with pytest.raises(DefaultsError):
        add_to_file(path, INCLUDE)
    assert path.read_text() == "build: [\n"


def test_without_pyyaml_the_reason_names_it() -> None:
    """A Python without PyYAML (ros-isolated-test needs none elsewhere): no guess, a reason."""
    code = (
        "import sys; sys.modules['yaml'] = None\n"
        "from pathlib import Path\n"
        "from ros_isolated_test.ament.colcon_defaults import add_include, DefaultsError\n"
        "try:\n    add_include('build: {}', Path('/x.cmake'))\n"
        "except DefaultsError as error:\n    print(error)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ}, check=True)  # fmt: skip
    assert done.stdout.startswith("PyYAML (python3-yaml), which reads it as colcon does, is not ")


def test_the_lines_to_add_are_the_include_under_build() -> None:
    assert yaml.safe_load(colcon_defaults.lines_to_add(INCLUDE)) == {
        "build": {"cmake-args": [ARGUMENT]}
    }
