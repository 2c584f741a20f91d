"""``shard.plan``: every test in exactly one share, balanced, and the same wherever computed.

Each machine, and each RUNNER on it, decides alone: the tests here plan with a fresh
:class:`Plan` per decision, seeing only the durations file, as the machines do.
"""

from __future__ import annotations

import random

import pytest

from ros_isolated_test.shard.durations import Durations, measured
from ros_isolated_test.shard.identity import spread
from ros_isolated_test.shard.plan import QUICK, Plan
from ros_isolated_test.shard.spec import MAX_TOTAL
from ros_isolated_test.shard.view import summary

#: A workspace's tests as a durations file once measured them.
MEASURED = {
    **{f"nav/test_long_{number}": 300.0 - number * 17 for number in range(4)},
    **{f"nav/test_mid_{number}": 20.0 + number for number in range(12)},
    **{f"msgs/test_short_{number}": 0.2 + number / 50 for number in range(30)},
    "py_pkg/test/test_node.py::TestNode::test_talks[1]": 4.2,
    "py_pkg/test/test_node.py::TestNode::test_talks[2]": 4.2,  # a tie: broken by identity
}


def _skewed(rng: random.Random, count: int) -> dict[str, float]:
    """A few long tests, more middling ones, many short ones (as ROS suites are)."""
    tests = {}
    for number in range(count):
        draw = rng.random()
        if draw < 0.1:
            seconds = rng.uniform(60, 300)
        elif draw < 0.3:
            seconds = rng.uniform(5, 30)
        else:
            seconds = rng.uniform(0.1, 3)
        tests[f"pkg_{number % 4}/test_{number}"] = seconds
    return tests


def _owners(identity: str, durations: Durations | None, total: int) -> list[int]:
    """The shares that would run ``identity``: each machine asks a plan of its own."""
    return [
        index for index in range(1, total + 1) if Plan(total, durations).share_of(identity) == index
    ]


@pytest.mark.parametrize("total", range(1, 9))
def test_every_test_known_or_new_runs_in_exactly_one_share(total: int) -> None:
    durations = measured(MEASURED)
    new = ["new_pkg/test_new", "nav/test_added", "py_pkg/test/test_x.py::test_y"]
    for identity in [*MEASURED, *new]:
        assert len(_owners(identity, durations, total)) == 1, identity
    # Without a file too (by count).
    for identity in [*MEASURED, *new]:
        assert len(_owners(identity, None, total)) == 1, identity


@pytest.mark.parametrize("total", range(1, 9))
def test_a_new_and_a_removed_test_leave_every_test_run_once(total: int) -> None:
    """The file was written before one test was added and another removed."""
    durations = measured(MEASURED)
    now = [identity for identity in MEASURED if identity != "nav/test_mid_3"] + ["nav/test_new"]
    runs = {identity: _owners(identity, durations, total) for identity in now}
    assert all(len(shares) == 1 for shares in runs.values()), runs
    # The new test goes where its hash says; the others where the whole file put them.
    assert runs["nav/test_new"] == [spread("nav/test_new", total)]
    planned = Plan(total, durations)
    assert all(runs[identity] == [planned.share_of(identity)] for identity in now)


def test_no_share_is_idle_while_tests_remain() -> None:
    plan = Plan(4, measured(MEASURED))
    assert all(plan.shares())
    # With more shares than tests some must be idle: 3 tests over 5 shares.
    few = Plan(5, measured({"p/a": 1, "p/b": 2, "p/c": 3}))
    assert sorted(len(tests) for tests in few.shares()) == [0, 0, 1, 1, 1]


def test_longest_first_onto_the_least_loaded_share() -> None:
    """LPT by hand: 8, 7, 6, 5 and 4 seconds over 2 shares."""
    plan = Plan(2, measured({"p/a": 8, "p/b": 7, "p/c": 6, "p/d": 5, "p/e": 4}))
    # a(8)->1; b(7)->2; c(6)->2 (7 < 8); d(5)->1 (8 < 13); e(4)->1 (13 = 13: the lower share).
    assert [plan.share_of(f"p/{name}") for name in "abcde"] == [1, 2, 2, 1, 1]


def test_asking_in_any_order_gives_the_whole_plans_answers() -> None:
    """A RUNNER stops placing at its test; later questions go on from there, alike."""
    durations = measured(MEASURED)
    whole = {
        test.identity: index
        for index, tests in enumerate(Plan(3, durations).shares(), 1)
        for test in tests
    }
    asked = Plan(3, durations)
    assert asked.share_of("nav/test_long_0") == whole["nav/test_long_0"]
    assert len(asked._placed) == 1  # the longest test: placed first, and alone
    names = sorted(MEASURED)
    random.Random(5).shuffle(names)
    assert {name: asked.share_of(name) for name in names} == whole
    assert len(asked._placed) == len(MEASURED)


def test_ties_are_broken_by_identity_never_by_the_files_order() -> None:
    same = {f"p/t{number}": 1.0 for number in range(20)}
    forward = Durations({key: 1_000_000 for key in same})
    backward = Durations({key: 1_000_000 for key in reversed(list(same))})
    assert list(forward.micros) != list(backward.micros)  # control: the orders differ
    plans = [Plan(3, durations) for durations in (forward, backward)]
    assert [plans[0].share_of(key) for key in same] == [plans[1].share_of(key) for key in same]
    # Equal durations go round the shares in the identities' order.
    ordered = sorted(same)
    assert [plans[0].share_of(key) for key in ordered[:6]] == [1, 2, 3, 1, 2, 3]


def test_the_plan_is_pinned() -> None:
    """The same file gives the same plan from one version of ours to the next."""
    plan = Plan(3, measured(MEASURED))
    shares = {
        index: [test.identity for test in tests] for index, tests in enumerate(plan.shares(), 1)
    }
    assert shares[1][:3] == ["nav/test_long_0", "nav/test_mid_10", "nav/test_mid_8"]
    assert shares[2][:3] == ["nav/test_long_1", "nav/test_mid_11", "nav/test_mid_9"]
    # The 3rd and 4th longest share a share: two of the 4 longest must (the pair bound).
    assert shares[3] == ["nav/test_long_2", "nav/test_long_3"]
    assert [plan.share_of(key) for key in sorted(MEASURED)[:8]] == [2, 1, 1, 2, 2, 1, 2, 1]


def _perfect_split(seed: int) -> tuple[int, int, dict[str, int]]:
    """(shares, load, tests): skewed tests cut from that many shares of exactly that load.

    Drawn in milliseconds, given in microseconds (as a plan weighs them).
    """
    rng = random.Random(seed)
    total = rng.randint(2, 8)
    load = 600_000  # ms per share in the perfect split
    tests: dict[str, int] = {}
    for share in range(total):
        left = load
        long = rng.randint(load // 3, load * 2 // 3)  # one long test per share
        tests[f"pkg_{share}/long"] = long
        left -= long
        number = 0
        while left > 0:  # the rest in short ones of 0.1 s to 30 s
            piece = min(left, rng.randint(100, 30_000))
            tests[f"pkg_{share}/short_{number}"] = piece
            left -= piece
            number += 1
    return total, load * 1000, {key: ms * 1000 for key, ms in tests.items()}


@pytest.mark.parametrize("seed", range(40))
def test_balance_within_ten_percent_where_a_perfect_split_exists(seed: int) -> None:
    """Skewed sets cut from N equal loads: the lower bound is achievable, LPT comes close."""
    total, load, tests = _perfect_split(seed)
    figures = summary(Plan(total, Durations(tests)))
    assert figures.lower_bound == load  # the bound is the perfect split's
    assert max(figures.loads) <= 1.10 * figures.lower_bound, (total, max(figures.loads))


def test_control_the_same_sets_split_by_count_miss_the_ten_percent() -> None:
    """The bar is a real one: placed by their hash alone, most of those sets miss it."""
    missed = 0
    for seed in range(40):
        total, load, tests = _perfect_split(seed)
        loads = [0] * total
        for identity, us in tests.items():
            loads[spread(identity, total) - 1] += us
        missed += max(loads) > 1.10 * load
    assert missed > 30


@pytest.mark.parametrize("seed", range(100))
def test_balance_within_ten_percent_of_what_any_split_can_do(seed: int) -> None:
    """Random skewed sets: within 10% of the lower bound, or of the pair bound where larger."""
    rng = random.Random(seed)
    durations = measured(_skewed(rng, rng.choice([40, 60, 100, 200])))
    for total in range(2, 9):
        figures = summary(Plan(total, durations))
        assert max(figures.loads) <= 1.10 * figures.best_possible, (total, figures.loads)


def test_the_pair_bound_explains_where_the_lower_bound_cannot_be_reached() -> None:
    """Five tests of 100 s over 4 shares: 125 s is the lower bound, 200 s the best split."""
    plan = Plan(4, measured({f"p/t{number}": 100 for number in range(5)}))
    figures = summary(plan)
    assert figures.lower_bound == 125_000_000
    assert figures.best_possible == max(figures.loads) == 200_000_000


def test_a_test_the_file_lacks_goes_by_its_hash_and_weighs_the_median() -> None:
    durations = measured({"p/a": 1, "p/b": 2, "p/c": 30, "p/d": 40})
    plan = Plan(4, durations)
    assert plan.median == 2_000_000  # the lower middle: a duration the file has
    assert plan.knows("p/a") and not plan.knows("p/new")
    assert plan.share_of("p/new") == spread("p/new", 4)
    placed = [test for tests in plan.shares(["p/new", "p/a"]) for test in tests]
    assert sorted((test.identity, test.micros, test.known) for test in placed) == [
        ("p/a", 1_000_000, True),
        ("p/b", 2_000_000, True),
        ("p/c", 30_000_000, True),
        ("p/d", 40_000_000, True),
        ("p/new", 2_000_000, False),
    ]


@pytest.mark.parametrize("durations", [None, Durations({})])
def test_without_durations_the_split_is_by_the_hash_alone(durations: Durations | None) -> None:
    plan = Plan(5, durations)
    assert plan.by_count
    assert plan.median == 0
    tests = [f"pkg/test_{number}" for number in range(50)]
    assert [plan.share_of(test) for test in tests] == [spread(test, 5) for test in tests]
    counts = [len(share) for share in plan.shares(tests)]
    assert sum(counts) == 50
    assert all(counts)  # about even (10 each, give or take a few), not exactly


def test_a_thousand_shares_are_all_used_and_no_more_can_be_planned() -> None:
    tests = {f"p/t{number}": 1 + number % 7 for number in range(3000)}
    plan = Plan(MAX_TOTAL, measured(tests))
    assert {plan.share_of(identity) for identity in tests} == set(range(1, MAX_TOTAL + 1))
    with pytest.raises(ValueError, match="shares"):
        Plan(1024, None)
    with pytest.raises(ValueError, match="shares"):
        Plan(0, None)


def test_one_share_runs_everything() -> None:
    plan = Plan(1, measured(MEASURED))
    assert {plan.share_of(identity) for identity in [*MEASURED, "x/new"]} == {1}


def test_tests_of_no_measured_duration_spread_by_count() -> None:
    """Issue 41 item 8: 0 s tests went all to the least loaded share (13 of 16 on one)."""
    mixed = {
        **{f"p/slow_{number}": 1_000_000 for number in range(4)},
        **{f"p/instant_{number:02d}": 0 for number in range(12)},
    }
    for tests, counts in ((mixed, [6, 5, 5]), ({f"p/t{n:02d}": 0 for n in range(16)}, [6, 5, 5])):
        durations = Durations(tests)
        listing = Plan(3, durations).shares()
        assert [len(share) for share in listing] == counts
        # Still every test once, and the loads as LPT leaves them (zeros cost nothing).
        assert sorted(test.identity for share in listing for test in share) == sorted(tests)
        # The same answers asked one at a time, in any order, each from a plan of its own
        # (a RUNNER), or in turn from one plan (the plugin): one plan everywhere.
        whole = {test.identity: index for index, share in enumerate(listing, 1) for test in share}
        assert {key: Plan(3, durations).share_of(key) for key in tests} == whole
        names = sorted(tests)
        random.Random(3).shuffle(names)
        asked = Plan(3, durations)
        assert {key: asked.share_of(key) for key in names} == whole


def _one_plan_everywhere(durations: Durations, total: int) -> list[list[str]]:
    """Each share's tests, checked to be what a RUNNER (one test, a plan of its own) and the
    plugin (every test in turn, in any order, from one plan) are told."""
    listing = Plan(total, durations).shares()
    whole = {test.identity: index for index, share in enumerate(listing, 1) for test in share}
    assert sorted(whole) == sorted(durations)  # every test once
    assert {key: Plan(total, durations).share_of(key) for key in durations} == whole
    names = sorted(durations)
    random.Random(7).shuffle(names)
    asked = Plan(total, durations)
    assert {key: asked.share_of(key) for key in names} == whole
    return [[test.identity for test in share] for share in listing]


@pytest.mark.parametrize("seed", range(20))
def test_sub_millisecond_tests_spread_by_count_whatever_they_measured(seed: int) -> None:
    """Issue 41 item 8: 16 pytest items of 0.2 to 0.4 ms over 3 shares are 6/5/5."""
    rng = random.Random(seed)
    seconds = {f"py/test_q.py::test_{n:02d}": rng.uniform(0.0002, 0.0004) for n in range(16)}
    durations = measured(seconds)
    assert all(200 <= us <= 400 for us in durations.micros.values())  # kept, not 0
    counts = [len(share) for share in _one_plan_everywhere(durations, 3)]
    assert counts == [6, 5, 5]
    counts = [len(share) for share in _one_plan_everywhere(durations, 4)]
    assert counts == [4, 4, 4, 4]


def test_quick_tests_go_by_count_slower_ones_by_their_time() -> None:
    """Below QUICK (a millisecond) a test's time decides nothing; from it on, it decides.

    One test of 0.9 ms and eight of 0.1 ms over 2 shares: by count, 5 and 4. The control,
    the same times a thousand times longer (0.9 s and eight of 0.1 s): by time, the long
    one alone and the eight together, as LPT places them.
    """
    assert QUICK == 1000
    quick = {"p/a": 0.0009, **{f"p/b{n}": 0.0001 for n in range(8)}}
    assert sorted(map(len, _one_plan_everywhere(measured(quick), 2))) == [4, 5]
    slow = {key: value * 1000 for key, value in quick.items()}
    assert _one_plan_everywhere(measured(slow), 2) == [["p/a"], [f"p/b{n}" for n in range(8)]]
    # At the floor a test is weighed: 4 ms and four of 1 ms go by time (1 and 4), while
    # four of 0.99 ms below it go by count (with the 4 ms test, 3 and 2).
    edge = {"p/a": 0.004, **{f"p/b{n}": 0.001 for n in range(4)}}
    assert _one_plan_everywhere(measured(edge), 2) == [["p/a"], [f"p/b{n}" for n in range(4)]]
    below = {**edge, **{f"p/b{n}": 0.00099 for n in range(4)}}
    assert [len(share) for share in _one_plan_everywhere(measured(below), 2)] == [3, 2]


def test_real_tests_among_many_quick_ones_spread_sensibly() -> None:
    """Tests of seconds balanced by time as before; hundreds of sub-ms items by count."""
    rng = random.Random(41)
    slow = {f"nav/test_{n}": rng.uniform(5, 60) for n in range(9)}
    quick = {f"py/test_q.py::test_{n:03d}": rng.uniform(0.00005, 0.0009) for n in range(300)}
    durations = measured({**slow, **quick})
    listing = _one_plan_everywhere(durations, 4)
    # The slow tests land where LPT puts them without the quick ones.
    alone = _one_plan_everywhere(measured(slow), 4)
    assert [[key for key in share if key in slow] for share in listing] == alone
    # Every share ends within one test of the others by count, and the quick tests add
    # well under a second to any share.
    counts = [len(share) for share in listing]
    assert max(counts) - min(counts) <= 1, counts
    micros = durations.micros
    for share in listing:
        assert sum(micros[key] for key in share if key in quick) < 100_000
