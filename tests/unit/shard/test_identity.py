"""``shard.identity``: ``<package>/<test>`` both ways, and a share drawn by the hash alone."""

from __future__ import annotations

import subprocess
import sys

import pytest
from helpers.commands import REPO

from ros_isolated_test.shard.identity import IdentityError, identity, split, spread

NAMES = [
    ("nav2_util", "test_lifecycle_node"),
    ("my_pkg", "test/test_talker.py::TestTalker::test_rate[2]"),  # a node id: / and ::
    ("my_pkg", "test/a::b/c"),
    ("p", "x"),
    ("pkg", "name with spaces and \u00e9"),
    ("pkg", "not utf-8 \udcff"),  # a file name's undecodable byte
]


@pytest.mark.parametrize(("package", "name"), NAMES)
def test_an_identity_splits_back_into_its_package_and_name(package: str, name: str) -> None:
    text = identity(package, name)
    assert text == f"{package}/{name}"
    assert split(text) == (package, name)


def test_identities_of_different_tests_differ() -> None:
    texts = [identity(package, name) for package, name in NAMES]
    assert len(set(texts)) == len(texts)
    # A node id's "/" cannot be taken for the package's: the package ends at the first.
    assert split("a/b/c") == ("a", "b/c")


@pytest.mark.parametrize(("package", "name"), [("", "t"), ("a/b", "t"), ("pkg", "")])
def test_no_identity_from_an_empty_part_or_a_slash_in_the_package(package: str, name: str) -> None:
    with pytest.raises(IdentityError):
        identity(package, name)


@pytest.mark.parametrize("text", ["nopackage", "/test", "pkg/", "", "/"])
def test_no_split_of_what_is_no_identity(text: str) -> None:
    with pytest.raises(IdentityError, match="<package>/<test>"):
        split(text)


def test_spread_is_a_share_from_one_to_total() -> None:
    for total in (1, 2, 3, 7, 1000):
        shares = {spread(f"pkg/test_{number}", total) for number in range(3000)}
        assert shares <= set(range(1, total + 1))
    assert {spread(f"pkg/test_{number}", 4) for number in range(100)} == {1, 2, 3, 4}


def test_spread_is_even() -> None:
    """Similar names (the usual test_1, test_2, ...) fall evenly: no share gets a run of them."""
    counts = [0] * 8
    for number in range(8000):
        counts[spread(f"pkg/test_{number}", 8) - 1] += 1
    assert min(counts) > 900 and max(counts) < 1100, counts


def test_spread_is_fixed_forever() -> None:
    """The same identity draws the same share on every machine, Python and version of ours.

    Pinned values: a change here moves tests between machines of a split that planned with
    an older version, so it must be deliberate.
    """
    assert [spread(f"pkg/test_{number}", 4) for number in range(12)] == [
        3,
        3,
        2,
        1,
        2,
        2,
        1,
        3,
        1,
        2,
        3,
        2,
    ]
    assert spread("my_pkg/test/test_talker.py::test_rate[2]", 1000) == 126


def test_spread_does_not_depend_on_the_process() -> None:
    """Unlike ``hash()``, salted per process: three processes, three hash seeds, one answer."""
    code = (
        "from ros_isolated_test.shard.identity import spread\n"
        "print([spread(f'pkg/t{n}', 7) for n in range(50)], hash('pkg/t0'))\n"
    )
    outputs = [
        subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            check=True,
            cwd=REPO,
            env={"PYTHONHASHSEED": seed, "PATH": "/usr/bin:/bin"},
        ).stdout.split("] ")
        for seed in ("1", "2", "3")
    ]
    assert len({spreads for spreads, _ in outputs}) == 1
    assert len({salted for _, salted in outputs}) == 3  # control: hash() did differ


def test_checked_names_the_option_and_the_fix_for_a_slash_in_the_package() -> None:
    from ros_isolated_test.shard.identity import PackageNameError, checked

    assert checked("pkg", "t") == "pkg/t"  # the control
    with pytest.raises(PackageNameError, match=r"^--package-name 'a/b' cannot name .*package\.xml"):
        checked("a/b", "t")
    with pytest.raises(PackageNameError, match=r"need a name"):
        checked("pkg", "")
