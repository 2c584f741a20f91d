"""``resources``: how requests of machine resources and their capacity are written.

One syntax, one message each: ``parse`` reads ``run --resources``,
ROS_ISOLATED_TEST_RESOURCES (the RUNNER's ``--env``, the CMake macros' RESOURCES, the
pytest plugin's option) and ROS_ISOLATED_TEST_CAPACITY alike; every error is one line
starting with the origin it was given. The default capacity is read from the machine
here as the kernel reports it, never from the code under test.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from ros_isolated_test.domain_coordinator.resources import (
    MAX_AMOUNT,
    MAX_NAME,
    ResourceSpecError,
    capacity_for,
    default_capacity,
    describe,
    parse,
    show_amount,
)

ORIGIN = "--resources"
K, M, G, T = 1 << 10, 1 << 20, 1 << 30, 1 << 40


@pytest.mark.parametrize(
    ("text", "amounts"),
    [
        ("", {}),
        (" , ,", {}),  # empty items are no request
        ("cpu=2,mem=4G,gpu=1", {"cpu": 2, "mem": 4 * G, "gpu": 1}),
        (" cpu = 2 , gpu=1 ,", {"cpu": 2, "gpu": 1}),  # spaces and a trailing comma
        ("gpu=007", {"gpu": 7}),
        ("gpu_a-1=1,x2=3", {"gpu_a-1": 1, "x2": 3}),
        ("a" * MAX_NAME + "=1", {"a" * MAX_NAME: 1}),  # the longest name
        (f"gpu={MAX_AMOUNT}", {"gpu": MAX_AMOUNT}),  # the largest amount
        ("mem=1048576T", {"mem": MAX_AMOUNT}),
    ],
)
def test_good_requests(text: str, amounts: dict[str, int]) -> None:
    assert parse(text, ORIGIN) == amounts


@pytest.mark.parametrize(
    ("mem", "size"),
    [
        ("512", 512),
        ("512B", 512),
        ("1K", K),
        ("1k", K),
        ("4KiB", 4 * K),
        ("4kib", 4 * K),
        ("2M", 2 * M),
        ("2MiB", 2 * M),
        ("3G", 3 * G),
        ("2GB", 2 * G),  # GB is 1024^3 here, as free(1) and most CI runners mean it
        ("2gb", 2 * G),
        ("1T", T),
        ("1TiB", T),
    ],
)
def test_memory_units_are_powers_of_1024(mem: str, size: int) -> None:
    assert parse(f"mem={mem}", ORIGIN) == {"mem": size}


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("gpu", "'gpu' is not name=amount; write e.g. cpu=2,mem=4G,gpu=1"),
        ("gpu=", "'gpu=' is not name=amount"),
        ("gpu= ", "'gpu=' is not name=amount"),
        ("=1", "'' is not a resource name; use lower-case letters, digits, '_' and '-'"),
        ("GPU=1", "'GPU' is not a resource name"),
        ("1gpu=1", "'1gpu' is not a resource name"),
        ("_gpu=1", "'_gpu' is not a resource name"),
        ("g.pu=1", "'g.pu' is not a resource name"),
        ("g pu=1", "'g pu' is not a resource name"),
        ("gpü=1", "'gpü' is not a resource name"),
        ("a" * (MAX_NAME + 1) + "=1", "is not a resource name"),
        ("gpu=1,gpu=2", "gpu is given twice; give it once"),
        # Records keep 16 names: a 17th would be held unseen by everyone else.
        (",".join(f"r{i}=1" for i in range(17)), "17 resources named; name at most 16"),
        ("gpu=0", "gpu='0' is zero; give a positive amount or leave gpu out"),
        ("mem=0K", "mem='0K' is zero"),
        ("gpu=-1", "gpu='-1' is not a whole amount; write e.g. gpu=2"),
        ("gpu=1.5", "gpu='1.5' is not a whole amount"),
        ("gpu=1K", "gpu='1K' is not a whole amount"),  # units are for mem only
        ("gpu=٣", "gpu='٣' is not a whole amount"),  # a digit to isdigit(), not to a user
        ("gpu=" + "9" * 5000, "is not a whole amount"),  # past int()'s digit limit: still ours
        ("mem=4X", "mem='4X' is not a whole amount; write e.g. mem=4G (K, M, G, T: powers"),
        ("mem=G", "mem='G' is not a whole amount"),
        ("mem=1.5G", "mem='1.5G' is not a whole amount"),
        ("mem=4GG", "mem='4GG' is not a whole amount"),
        (f"gpu={MAX_AMOUNT + 1}", f"gpu='{MAX_AMOUNT + 1}' is too large"),
        ("mem=1048577T", "mem='1048577T' is too large"),
    ],
)
def test_every_error_is_one_line_naming_its_origin(text: str, says: str) -> None:
    with pytest.raises(ResourceSpecError) as raised:
        parse(text, ORIGIN)
    message = str(raised.value)
    assert message.startswith(f"{ORIGIN}: ") and says in message, message
    assert "\n" not in message


def test_sixteen_names_are_fine() -> None:
    assert len(parse(",".join(f"r{i}=1" for i in range(16)), ORIGIN)) == 16


def test_the_origin_is_the_one_given() -> None:
    with pytest.raises(ResourceSpecError, match=r"^--env ROS_ISOLATED_TEST_RESOURCES: 'x'"):
        parse("x", "--env ROS_ISOLATED_TEST_RESOURCES")


@pytest.mark.parametrize(
    ("name", "amount", "shown"),
    [
        ("mem", 4 * G, "4G"),
        ("mem", 1536 * M, "1536M"),
        ("mem", 3 * T, "3T"),
        ("mem", 1536 * K, "1536K"),
        ("mem", 1023, "1023"),
        ("mem", 1025, "1025"),
        ("gpu", 1024, "1024"),  # not mem: a count, never a unit
        ("cpu", 2, "2"),
    ],
)
def test_show_amount_writes_the_largest_unit_that_divides(
    name: str, amount: int, shown: str
) -> None:
    assert show_amount(name, amount) == shown
    assert parse(f"{name}={shown}", ORIGIN) == {name: amount}  # read back as it was


def test_describe_is_canonical_and_reads_back() -> None:
    amounts = {"mem": 4 * G + 512 * M, "gpu": 1, "cpu": 2, "lidar": 3}
    text = describe(amounts)
    assert text == "cpu=2,gpu=1,lidar=3,mem=4608M"  # names sorted
    assert parse(text, ORIGIN) == amounts
    assert describe(parse(" mem=4096M , gpu=01,cpu=2", ORIGIN)) == "cpu=2,gpu=1,mem=4G"
    assert describe({}) == ""


def _mem_total_from_the_kernel() -> int:
    with open("/proc/meminfo") as meminfo:
        for line in meminfo:
            if line.startswith("MemTotal:"):
                kib = int(line.split()[1])
                return kib * 1024
    raise AssertionError("no MemTotal in /proc/meminfo")


def test_the_default_capacity_is_this_machines() -> None:
    assert default_capacity("cpu") == len(os.sched_getaffinity(0))
    assert default_capacity("mem") == _mem_total_from_the_kernel()
    assert default_capacity("gpu") == 1  # any other name: exclusive
    assert capacity_for(["cpu", "gpu", "lidar"], {"gpu": 4}) == {
        "cpu": len(os.sched_getaffinity(0)),
        "gpu": 4,
        "lidar": 1,
    }


#: Prints what the default cpu capacity is once this process may run on one CPU only.
_ON_ONE_CPU = """\
import os, sys
from ros_isolated_test.domain_coordinator.resources import default_capacity
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
print(default_capacity("cpu"), os.cpu_count())
"""


def test_the_cpu_capacity_follows_the_affinity() -> None:
    """taskset or a container's cpuset cuts what a runner may use: the capacity says so
    (on this suite's machines cpu_count is 2 or more, so the count alone would say more)."""
    done = subprocess.run(
        [sys.executable, "-c", _ON_ONE_CPU], capture_output=True, text=True, check=True
    )
    capacity, cpu_count = map(int, done.stdout.split())
    assert capacity == 1, f"capacity {capacity} on one CPU of {cpu_count}"
