"""The plan: which share runs each test, the same on every machine from the same file.

No machine sees the others, and a ctest RUNNER decides for its one test without even
seeing its neighbours: so the share of a test is a function of the durations file's
content, the number of shares and the test's identity, and of nothing else (not the
tests found here, not the order of a dict, not ``hash()``). That function is total: a
test the file does not know still gets exactly one share. Hence every test runs exactly
once over the N machines, whichever tests exist, as long as they all read the same file
(results record its fingerprint, so a merge can tell when they did not).

- **Tests the file knows**: longest first, each onto the share with the least load so far
  (LPT); equal durations go in identity order, and equal loads to the share with the
  fewest tests, then the lowest; loads are whole microseconds, so the arithmetic is exact
  everywhere. Tests quicker than :data:`QUICK` (a millisecond, 0 included) are placed by
  count after the others: each onto the share with the fewest tests so far, then the
  lowest. Their measured time is then no better a guide than their number (the work
  around each test that no measurement holds, its report and its line in the result
  file, is of the same order), and as weights they would pile onto whichever share is
  least loaded; by count, 16 of them over 3 shares are 6/5/5 whatever they measured, and
  among tests of seconds they add about the same to every share. LPT's longest share is at most
  4/3 of the best possible, and it is far closer when there are many more tests than
  shares (its excess is at most the one test placed last on the longest share). A search
  for the exact optimum would chase the noise of the measurements themselves (a test's
  time moves by several percent between runs) at a cost every runner would pay.
- **Tests it does not know** (new since it was written): the share their identity's
  SHA-256 draws (:func:`identity.spread`), weighed as the median of the file's durations
  in what the plan shows. A runner cannot know the other new tests, so it cannot place
  them onto the least loaded share (every new test would land on the same one); a hash
  spreads them evenly and stays put as tests come and go.
- **Tests it knows that are gone**: still placed, so the others do not move; their share
  just ends sooner.
- **No file** (or an empty one): by count, which for a runner deciding alone can only mean
  the hash: each share gets N-th of the tests on average but not exactly (40 tests over
  4 shares: 10 each give or take 3), and with few tests a share may get none.
"""

from __future__ import annotations

from ros_isolated_test.shard.identity import spread

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator

    from ros_isolated_test.shard.durations import Durations

__all__ = ["QUICK", "Placed", "Plan"]

#: Tests measured below this many microseconds (a millisecond) are placed by count.
QUICK = 1000

#: Bits of a share's index in the loads heap: room for 1023 shares (MAX_TOTAL is 1000).
_INDEX_BITS = 10
_INDEX_MASK = (1 << _INDEX_BITS) - 1
#: Bits of a share's count of tests in the heap, above its index: far more tests than a
#: durations file can hold (MAX_FILE_BYTES).
_COUNT_BITS = 40
_LOAD_SHIFT = _INDEX_BITS + _COUNT_BITS
_ONE_TEST = 1 << _INDEX_BITS
_COUNT_AND_INDEX = (1 << _LOAD_SHIFT) - 1


class Placed:
    """One test in the plan as shown: its identity, weight and whether the file knew it."""

    __slots__ = ("identity", "known", "micros")

    def __init__(self, identity: str, micros: int, known: bool) -> None:
        self.identity = identity
        #: Its duration in the file (microseconds), or the file's median for a test it
        #: does not know (0 when the split is by count).
        self.micros = micros
        self.known = known

    def __repr__(self) -> str:
        return f"Placed({self.identity!r}, {self.micros}, known={self.known})"


class Plan:
    """Which of ``total`` shares runs each test, planned from ``durations`` (None: by count)."""

    __slots__ = ("_placed", "_steps", "durations", "total")

    def __init__(self, total: int, durations: Durations | None) -> None:
        if not 1 <= total <= _INDEX_MASK:
            raise ValueError(f"a plan has from 1 to {_INDEX_MASK} shares, not {total}")
        self.total = total
        #: None, or an empty file: the split is by count (the identity's hash alone).
        self.durations = durations if durations else None
        #: The file's tests placed so far, and the placing still to come.
        self._placed: dict[str, int] = {}
        self._steps: Iterator[tuple[str, int]] | None = None

    @property
    def by_count(self) -> bool:
        """Whether there are no durations to balance by."""
        return self.durations is None

    @property
    def median(self) -> int:
        """The file's median duration (the lower middle): the weight of a test it lacks."""
        if self.durations is None:
            return 0
        values = sorted(self.durations.micros.values())
        return values[(len(values) - 1) // 2]

    def _placing(self, durations: Durations) -> Iterator[tuple[str, int]]:
        """Each test of the file with its share, longest first (LPT)."""
        import heapq

        micros = durations.micros
        # Longest first; equal durations by identity (a stable sort of the sorted
        # identities): no dict order, no hash.
        order = sorted(durations.ordered(), key=micros.__getitem__, reverse=True)
        # Each share's load, count of tests and index in one integer (load, then count,
        # then index, from the top bits): the least is the least loaded share, ties going
        # to the one with fewest tests, then to the lowest index.
        loads = list(range(1, self.total + 1))  # a heap already
        placed = 0
        for key in order:
            weight = micros[key]
            if weight < QUICK:
                break  # the rest are quicker still (longest first): placed by count below
            least = loads[0]
            yield key, least & _INDEX_MASK
            heapq.heapreplace(loads, least + (weight << _LOAD_SHIFT) + _ONE_TEST)
            placed += 1
        # Quick tests by count: onto the share with the fewest tests so far (their time
        # is left out of the heap: it decides nothing here).
        counts = [entry & _COUNT_AND_INDEX for entry in loads]
        heapq.heapify(counts)
        for key in order[placed:]:
            least = counts[0]
            yield key, least & _INDEX_MASK
            heapq.heapreplace(counts, least + _ONE_TEST)

    def _place(self, until: str | None = None) -> dict[str, int]:
        """The file's tests placed so far, placing them up to ``until`` (None: all).

        A RUNNER asking about one test stops there, half way on average; the plugin asking
        about each goes on from where it stopped. Each test is placed once per process.
        """
        if self.durations is not None and (until is None or until not in self._placed):
            if self._steps is None:
                self._steps = self._placing(self.durations)
            placed = self._placed
            for key, index in self._steps:
                placed[key] = index
                if key == until:
                    break
        return self._placed

    def knows(self, identity: str) -> bool:
        """Whether the durations file has this test."""
        return self.durations is not None and identity in self.durations

    def share_of(self, identity: str) -> int:
        """The share, from 1 to ``total``, that runs the test ``identity``."""
        if self.knows(identity):
            return self._place(identity)[identity]
        return spread(identity, self.total)

    def shares(self, found: Iterable[str] = ()) -> list[list[Placed]]:
        """Each share's tests, longest first: the file's, and those of ``found`` it lacks.

        ``found`` are tests seen elsewhere (result trees): those the file knows are in
        already, the others go where a runner would put them, weighed as the median.
        """
        listing: list[list[Placed]] = [[] for _ in range(self.total)]
        if self.durations is not None:
            for key, index in self._place().items():
                listing[index - 1].append(Placed(key, self.durations.micros[key], True))
        median = self.median
        for key in sorted(set(found)):
            if not self.knows(key):
                listing[spread(key, self.total) - 1].append(Placed(key, median, False))
        for tests in listing:
            tests.sort(key=lambda test: (-test.micros, test.identity))
        return listing
