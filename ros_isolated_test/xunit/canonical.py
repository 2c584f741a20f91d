"""Any producer's result file made canonical: the test it belongs to, its cases, its bytes.

Apart from one test's file through its life (``result_file``): the runner adopts the
file its test wrote, and ``ros-isolated-test normalise`` rewrites a file nobody ran
here (:func:`normalise_to`); both read it the same way. The reader, and lxml behind it,
are imported only when a file is read: a test that wrote no file of its own never loads
them.
"""

from __future__ import annotations

from ros_isolated_test import atomic_file, names
from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.model import Suite

TYPE_CHECKING = False
if TYPE_CHECKING:
    from pathlib import Path

    from ros_isolated_test.xunit import raw
    from ros_isolated_test.xunit.model import Case


def test_name_of(result_file: Path) -> str:
    """The test a result file belongs to: its name without the producer's suffix."""
    name = result_file.name
    for suffix in (".gtest.xml", ".xunit.xml", ".xml"):
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


def read_cases(
    path: Path, package: str | None, test_name: str, named: Path | None = None
) -> tuple[list[Case], raw.ReadResult]:
    """The canonical cases of any result file, and what reading it found.

    ``named``: the path the cases speak of, when the file was read elsewhere (the test
    wrote it beside the result path, which it stands for).
    """
    from ros_isolated_test.xunit import normalise, reader

    read = reader.read(path)
    if named is not None:
        read.path = named
    return normalise.cases_from(read, package, test_name), read


def normalise_file(path: Path, package: str, test_name: str) -> tuple[bytes, bool]:
    """A producer's result file as canonical bytes, and whether anything in it failed."""
    cases, read = read_cases(path, package, test_name)
    properties = {"original_result_file": path.name}
    if read.repairs:
        properties[names.RESULT_FILE_REPAIRS] = "; ".join(read.repairs)
    suite = Suite(
        name=f"{package}.{test_name}",
        cases=cases,
        time=sum(case.time for case in cases),
        timestamp=validate.timestamp(),
        hostname=validate.hostname(),
        properties=properties,
    )
    rendered = validate.render(suite)
    return rendered.data, rendered.failed


class OutputError(Exception):
    """The canonical file cannot be written where asked: the one-line error, with the fix."""


def normalise_to(
    source: Path, output: Path | None, package: str, test_name: str | None = None
) -> tuple[bytes, bool]:
    """``normalise``: ``source`` canonical, written to ``output``; (its bytes, whether it failed).

    ``output`` None: written nowhere (the caller prints it); /dev/null keeps nothing; any
    other device node, FIFO or socket is never replaced (:class:`OutputError`, before
    ``source`` is read). ``test_name`` defaults to the one ``source``'s name gives.
    """
    discard = output is not None and atomic_file.discards(output)
    kind = None if output is None or discard else atomic_file.special_kind(output)
    if kind is not None:
        raise OutputError(f"cannot use -o {output}: it is {kind}; {atomic_file.SPECIAL_FIX}")
    data, failed = normalise_file(source, package, test_name or test_name_of(source))
    if output is not None and not discard:
        try:
            atomic_file.write_atomically(output, data)
        except OSError as error:  # one that became special meanwhile, a full disk
            fix = "choose a writable file path"
            if isinstance(error, atomic_file.NotReplaceableError):
                fix = atomic_file.SPECIAL_FIX
            raise OutputError(f"cannot write -o {output}: {error.strerror}; {fix}") from None
    return data, failed
