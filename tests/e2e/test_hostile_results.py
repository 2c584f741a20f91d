"""Hostile and broken result files: each is left by a real test run through the ctest RUNNER.

A test's result file is written by arbitrary code. Whatever it holds, the runner must
leave a canonical file that validates against our schema, says what was wrong, keeps
what could be recovered and keeps the original beside it as ``<name>.orig``; it must
never read local files or the network on the file's behalf, and a bomb or a
multi-gigabyte file must cost bounded time and memory.

Exit codes: 1 when the file is damaged (an error case "result file") or reports
failures; 0 when it was only repaired (the repair is listed in ``result_file_repairs``).
"""

from __future__ import annotations

import contextlib
import http.client
import os
import random
import subprocess
import sys
import urllib.request
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import capabilities, peak_rss
from helpers.commands import run_runner
from helpers.listener import Listener
from helpers.results import CaseResult, ResultSummary, load_result
from lxml import etree

from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.canonical import normalise_file
from ros_isolated_test.xunit.model import Case, Suite

MIB = 1024 * 1024
GIB = 1024 * MIB
#: Peak RSS allowed for the runner (and everything it waited for) on a hostile file.
MAX_RSS = 200 * 1000 * 1000
#: A canonical file never grows beyond this, whatever the test wrote.
MAX_CANONICAL = 5 * 1000 * 1000
DECLARATION = '<?xml version="1.0" encoding="UTF-8"?>\n'
DOCTYPE_REMOVED = "a DOCTYPE was removed: no DTD or external entity is ever loaded"
ENDS_INSIDE = "The result file ends inside this test case."
# Complete, passing test cases the files below are made of.
A = '<testcase classname="C" name="a" time="0.5"/>'
B = '<testcase classname="C" name="b"/>'
C = '<testcase classname="C" name="c"/>'


# --- running the RUNNER on a file the test writes ----------------------------------------


def result_path(tmp_path: Path) -> Path:
    return tmp_path / "pkg" / "t.xml"


def runner_args(result: Path, *command: str) -> list[str]:
    return [str(result), "--package-name", "pkg", "--command", *command]


def leave(
    runner_script: str, env: Mapping[str, str], tmp_path: Path, data: bytes
) -> subprocess.CompletedProcess[str]:
    """The test under the runner writes ``data`` as its result file, then exits 0."""
    source = tmp_path / "written-by-the-test"
    source.write_bytes(data)
    result = result_path(tmp_path)
    args = runner_args(result, "sh", "-c", 'cat "$2" > "$1"', "sh", str(result), str(source))
    return run_runner(runner_script, args, env, cwd=tmp_path)


def run_shell(
    runner_script: str, env: Mapping[str, str], tmp_path: Path, script: str
) -> subprocess.CompletedProcess[str]:
    """The test under the runner is ``sh -c SCRIPT sh RESULT_FILE``."""
    result = result_path(tmp_path)
    args = runner_args(result, "sh", "-c", script, "sh", str(result))
    return run_runner(runner_script, args, env, cwd=tmp_path)


@dataclass(frozen=True)
class Measured:
    """A runner process that was timed and whose peak RSS was taken with ``wait4``."""

    returncode: int | None
    stdout: str
    stderr: str
    wall: float
    max_rss: int  # bytes, the largest among the runner and the children it waited for
    timed_out: bool

    @property
    def output(self) -> str:
        return self.stdout + self.stderr


def measured_runner(
    runner_script: str, args: Sequence[str], env: Mapping[str, str], cwd: Path, timeout: float
) -> Measured:
    """The RUNNER as ctest calls it, with wall time and peak RSS (``helpers.peak_rss``).

    The peak is the largest RSS of the runner and of every descendant it waited for, so
    the test command's own memory counts too. Killed (its own session) at ``timeout``.
    """
    out, err = cwd / "runner.stdout", cwd / "runner.stderr"
    peak = peak_rss.measure(
        [sys.executable, "-u", runner_script, *args],
        env=env,
        cwd=cwd,
        stdout=out,
        stderr=err,
        timeout=timeout,
    )
    return Measured(
        returncode=None if peak.timed_out else peak.returncode,
        stdout=out.read_text(errors="replace"),
        stderr=err.read_text(errors="replace"),
        wall=peak.wall,
        max_rss=peak.max_rss,
        timed_out=peak.timed_out,
    )


# --- reading the canonical file ------------------------------------------------------------


def canonical(result: Path) -> ResultSummary:
    """The canonical file at ``result``: schema-valid, counts right, summarised."""
    assert result.is_file(), f"no canonical file at {result}"
    root = etree.parse(str(result), etree.XMLParser(resolve_entities=False)).getroot()
    assert validate.problems(root) == []
    return load_result(result)


def outcomes(summary: ResultSummary) -> list[tuple[str, str]]:
    return [(case.name, case.outcome) for case in summary.cases]


def damage(summary: ResultSummary) -> CaseResult:
    """The error case that says what was wrong with the file."""
    found = [case for case in summary.cases if case.name == "result file"]
    assert len(found) == 1, outcomes(summary)
    case = found[0]
    assert case.classname == "pkg.t"
    assert case.outcome == "error"
    assert case.message.startswith("Invalid result file t.xml, not fully readable: ")
    assert case.text == case.message
    return case


def repairs(summary: ResultSummary) -> str:
    return summary.properties.get("result_file_repairs", "")


def original(tmp_path: Path) -> Path:
    return result_path(tmp_path).with_name("t.xml.orig")


def suite(*cases: str, head: str = DECLARATION, attrs: str = 'name="s"') -> bytes:
    return (
        f"{head}<testsuites><testsuite {attrs}>{''.join(cases)}</testsuite></testsuites>".encode()
    )


# --- no local files, no network ------------------------------------------------------------


def _with_secret(secret: Path, variant: str) -> bytes:
    doctype = f'<!DOCTYPE x [<!ENTITY e SYSTEM "file://{secret}">]>'
    body = (
        f'<testsuites><testsuite name="s">{A}<testcase classname="C" name="b">'
        "<system-out>before &e; after</system-out></testcase>"
        f"{C}</testsuite></testsuites>"
    )
    if variant == "doctype":
        return (DECLARATION + doctype + body).encode()
    if variant == "doctype-smuggled-around-another":
        # Removing the inner DOCTYPE joins "<!DOC" and "TYPE x [...]>" into a live one.
        return (DECLARATION + doctype.replace("<!DOCTYPE", "<!DOC<!DOCTYPE z>TYPE") + body).encode()
    assert variant == "doctype-after-the-first-mebibyte"
    # "<a" in a comment ends the prolog check; the DOCTYPE comes in the next chunk.
    return f"<!-- <a -->{' ' * MIB}{doctype}{body}".encode()


@pytest.mark.parametrize(
    "variant",
    ["doctype", "doctype-smuggled-around-another", "doctype-after-the-first-mebibyte"],
)
def test_external_entity_is_never_read(
    runner_script: str, env: dict[str, str], tmp_path: Path, variant: str
) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET-4711\n")
    data = _with_secret(secret, variant)
    proc = leave(runner_script, env, tmp_path, data)
    result = result_path(tmp_path)
    assert "TOP-SECRET" not in result.read_text(), "the secret file was read into the result"
    assert "TOP-SECRET" not in proc.stdout + proc.stderr
    # An entity that is never defined leaves the file broken at the reference.
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = canonical(result)
    assert original(tmp_path).read_bytes() == data
    assert DOCTYPE_REMOVED in repairs(summary)
    problem = damage(summary)
    assert summary.cases[0].name == "a"
    assert summary.cases[0].outcome == "passed"
    if variant == "doctype":
        assert outcomes(summary) == [("a", "passed"), ("b", "error"), ("result file", "error")]
        assert summary.cases[1].message == ENDS_INSIDE
        assert "cut off or broken at line 2 (Entity 'e' not defined" in problem.message
        assert problem.message.endswith(" 2 test case(s) before the damage were kept.")


@pytest.fixture
def listener() -> Iterator[Listener]:
    found = Listener()
    yield found
    found.close()


#: One result file per way XML can name a URL to fetch, with the URL as ``{url}``.
URL_PROLOGS = {
    "external-dtd": '<!DOCTYPE testsuites SYSTEM "{url}junit.dtd">',
    "parameter-entity": '<!DOCTYPE x [<!ENTITY % p SYSTEM "{url}p.dtd"> %p;]>',
    "general-entity": '<!DOCTYPE x [<!ENTITY e SYSTEM "{url}e.txt">]>',
    "smuggled-parameter-entity": (
        '<!DOC<!DOCTYPE z>TYPE x [<!ENTITY % p SYSTEM "{url}p.dtd"> %p;]>'
    ),
}


def url_result(variant: str, url: str) -> bytes:
    inner = "<system-out>&e;</system-out>" if variant == "general-entity" else ""
    prolog = URL_PROLOGS[variant].format(url=url)
    return suite(f'<testcase classname="C" name="a">{inner}</testcase>', head=DECLARATION + prolog)


class _FetchingResolver(etree.Resolver):
    """What a parser that follows URLs does (this lxml's libxml2 has no HTTP client)."""

    def resolve(  # type: ignore[override]  # lxml passes a context; its stubs omit it
        self, system_url: str, public_id: str, context: object
    ) -> None:
        with contextlib.suppress(OSError, http.client.HTTPException):
            urllib.request.urlopen(system_url, timeout=30).close()


@pytest.mark.parametrize("variant", ["external-dtd", "parameter-entity", "general-entity"])
def test_control_the_listener_sees_a_parser_that_fetches_the_url(
    listener: Listener, variant: str
) -> None:
    """Without this, an empty list below could mean a deaf listener or a URL never named."""
    parser = etree.XMLParser(load_dtd=True, resolve_entities=True, no_network=False)
    parser.resolvers.add(_FetchingResolver())
    with contextlib.suppress(etree.XMLSyntaxError):
        etree.fromstring(url_result(variant, listener.url), parser)
    assert listener.connections(), f"{variant}: nothing connected to {listener.url}"


@pytest.mark.parametrize(
    ("variant", "code", "names"),
    [
        ("external-dtd", 0, [("a", "passed")]),
        ("parameter-entity", 0, [("a", "passed")]),
        ("general-entity", 1, [("a", "error"), ("result file", "error")]),
        # No DOCTYPE can reach the parser (see the smuggled secret above); whatever it
        # then says, the network must stay untouched.
        ("smuggled-parameter-entity", None, None),
    ],
)
def test_network_is_never_contacted(
    runner_script: str,
    env: dict[str, str],
    tmp_path: Path,
    listener: Listener,
    variant: str,
    code: int | None,
    names: list[tuple[str, str]] | None,
) -> None:
    data = url_result(variant, listener.url)
    proc = leave(runner_script, env, tmp_path, data)
    assert listener.connections() == [], "the runner connected to the URL in the result file"
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    assert DOCTYPE_REMOVED in repairs(summary)
    if code is not None:
        assert proc.returncode == code, proc.stdout + proc.stderr
        assert outcomes(summary) == names
    if variant == "general-entity":
        assert "(Entity 'e' not defined" in damage(summary).message


# --- entity bombs --------------------------------------------------------------------------


def billion_laughs() -> tuple[bytes, int]:
    """10 levels of 10 references: 10**9 copies of "lol" if anything expanded it."""
    entities = '<!ENTITY lol0 "lol">' + "".join(
        f'<!ENTITY lol{level} "{f"&lol{level - 1};" * 10}">' for level in range(1, 10)
    )
    data = suite(
        A,
        '<testcase classname="C" name="bomb"><system-out>&lol9;</system-out></testcase>',
        head=f"{DECLARATION}<!DOCTYPE lolz [{entities}]>",
    )
    return data, 3 * 10**9


def quadratic_blowup() -> tuple[bytes, int]:
    """One 100 kB entity referenced 50 000 times: 5 GB if expanded, 250 kB on disk."""
    size, references = 100_000, 50_000
    data = suite(
        A,
        '<testcase classname="C" name="bomb"><system-out>'
        + "&big;" * references
        + "</system-out></testcase>",
        head=f'{DECLARATION}<!DOCTYPE q [<!ENTITY big "{"B" * size}">]>',
    )
    return data, size * references


@pytest.mark.parametrize(
    ("bomb", "said"),
    [
        (billion_laughs, "(an entity bomb?)"),
        # Its DOCTYPE is longer than sanitiser.DOCTYPE_LIMIT: dropped, "big" is not defined.
        (quadratic_blowup, "(Entity 'big' not defined"),
    ],
    ids=["billion-laughs", "quadratic-blowup"],
)
def test_entity_bomb_is_rejected_fast_with_bounded_memory(
    runner_script: str,
    env: dict[str, str],
    tmp_path: Path,
    bomb: Callable[[], tuple[bytes, int]],
    said: str,
) -> None:
    data, expanded = bomb()
    source = tmp_path / "bomb.xml"
    source.write_bytes(data)
    result = result_path(tmp_path)
    args = runner_args(result, "sh", "-c", 'cat "$2" > "$1"', "sh", str(result), str(source))
    run = measured_runner(runner_script, args, env, tmp_path, timeout=60)
    print(f"{bomb.__name__}: {run.wall:.2f} s, peak RSS {run.max_rss / 1e6:.1f} MB")
    assert not run.timed_out
    assert run.wall < 20
    assert run.max_rss < MAX_RSS
    # Far from what expanding it would take, in memory and in output.
    assert run.max_rss * 10 < expanded
    assert result.stat().st_size < 100_000
    assert run.returncode == 1, run.output
    summary = canonical(result)
    assert original(tmp_path).read_bytes() == data
    assert outcomes(summary) == [("a", "passed"), ("bomb", "error"), ("result file", "error")]
    assert said in damage(summary).message
    assert DOCTYPE_REMOVED in repairs(summary)


def test_catastrophic_doctype_pattern_is_read_fast(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """A prolog the DOCTYPE remover backtracks on must not hang the runner."""
    data = b'<?xml version="1.0"?><!DOCTYPE x ' + b"[]" * 40
    source = tmp_path / "prolog.xml"
    source.write_bytes(data)
    result = result_path(tmp_path)
    args = runner_args(result, "sh", "-c", 'cat "$2" > "$1"', "sh", str(result), str(source))
    # Backtracking on it would take for ever; reading it takes well under a second.
    run = measured_runner(runner_script, args, env, tmp_path, timeout=30)
    assert not run.timed_out, f"the runner was still reading an {len(data)}-byte file after 30 s"
    assert run.returncode == 1, run.output
    summary = canonical(result)
    assert outcomes(summary) == [("result file", "error")]


# --- bytes and characters ------------------------------------------------------------------


def test_invalid_utf8_is_replaced_and_the_cases_kept(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    data = suite(
        '<testcase classname="C\xff" name="a"><system-out>x\xfe\xc3y</system-out></testcase>',
        B,
    )
    # suite() encodes as UTF-8: put the invalid bytes back as raw single bytes.
    data = data.replace("\xff".encode(), b"\xff").replace("\xfe\xc3".encode(), b"\xfe\xc3")
    with pytest.raises(UnicodeDecodeError):
        data.decode("utf-8")
    proc = leave(runner_script, env, tmp_path, data)
    # Repaired without loss of meaning: nothing failed.
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    assert [(case.classname, case.name, case.outcome) for case in summary.cases] == [
        ("pkg.C\\xff", "a", "passed"),
        ("pkg.C", "b", "passed"),
    ]
    out = etree.parse(str(result_path(tmp_path))).findtext(".//testcase/system-out")
    # Shown as \xNN, never U+FFFD: xunit-viewer aborts its whole run on a U+FFFD.
    assert out == "x\\xfe\\xc3y"
    assert repairs(summary) == "3 byte(s) that were not valid text were written as \\xNN"
    assert "not valid text" in proc.stdout


def test_illegal_characters_raw_and_as_references_are_shown(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    data = suite(
        '<testcase classname="C" name="a\x01b">'
        '<failure message="m\x1fn\x1b!">t\x01 &#1;|&#x1B;|&#xFFFF;|&#55296;|&#233;|&amp;</failure>'
        "</testcase>"
    )
    with pytest.raises(etree.XMLSyntaxError):
        etree.fromstring(data)
    proc = leave(runner_script, env, tmp_path, data)
    # The file reports a failure; the characters themselves were only repaired.
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    case = summary.only
    assert (case.name, case.outcome) == ("a\\x01b", "failure")
    assert case.message == "m\\x1fn\\x1b!"
    assert case.text == "t\\x01 \\x01|\\x1b|\\uffff|\\ud800|\u00e9|&"
    assert repairs(summary) == "8 character(s) that XML 1.0 forbids were written as \\xNN"


# --- damaged files -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("cut", "last"),
    [
        ('<testcase classname="C" name="d"><system-out>partial out', ("d", "error", ENDS_INSIDE)),
        (
            '<testcase classname="C" name="d"><failure message="m">partial trace',
            ("d", "failure", "m"),
        ),
        ('<testcase classname="C" name="d"><failure message="ha', ("d", "error", ENDS_INSIDE)),
    ],
    ids=["inside-system-out", "inside-failure-text", "inside-an-attribute"],
)
def test_truncated_file_keeps_complete_cases_and_the_cut_one(
    runner_script: str, env: dict[str, str], tmp_path: Path, cut: str, last: tuple[str, str, str]
) -> None:
    data = f'{DECLARATION}<testsuites><testsuite name="s">{A}{B}{C}{cut}'.encode()
    proc = leave(runner_script, env, tmp_path, data)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    assert outcomes(summary) == [
        ("a", "passed"),
        ("b", "passed"),
        ("c", "passed"),
        last[:2],
        ("result file", "error"),
    ]
    assert summary.cases[3].message == last[2]
    problem = damage(summary).message
    assert "the file is cut off or broken at line 2 (" in problem
    assert problem.endswith(
        "; what came before is kept. 4 test case(s) before the damage were kept."
    )
    assert "cut off or broken" in proc.stdout


def test_empty_file_is_an_error(runner_script: str, env: dict[str, str], tmp_path: Path) -> None:
    proc = run_shell(runner_script, env, tmp_path, ': > "$1"')
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert outcomes(summary) == [("result file", "error")]
    assert damage(summary).message == (
        "Invalid result file t.xml, not fully readable: the result file is empty."
    )
    assert original(tmp_path).read_bytes() == b""


def test_second_root_is_ignored_and_the_first_kept(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    data = (
        f'{DECLARATION}<testsuite name="s">{A}</testsuite>\n<testsuite name="t">{B}</testsuite>\n'
    ).encode()
    proc = leave(runner_script, env, tmp_path, data)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    assert outcomes(summary) == [("a", "passed"), ("result file", "error")]
    assert damage(summary).message == (
        "Invalid result file t.xml, not fully readable: content after the root element "
        "(a second root?) was ignored. 1 test case(s) before the damage were kept."
    )


def test_directory_where_the_file_should_be(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    proc = run_shell(runner_script, env, tmp_path, 'rm -f "$1"; mkdir "$1"; echo x > "$1/inside"')
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert outcomes(summary) == [("result file", "error")]
    assert damage(summary).message == (
        "Invalid result file t.xml, not fully readable: "
        "a directory is where the result file should be."
    )
    assert (original(tmp_path) / "inside").read_text() == "x\n"


def test_fifo_where_the_file_should_be_does_not_hang(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """A named pipe nobody writes to: opening it to read blocks for ever."""
    result = result_path(tmp_path)
    args = runner_args(result, "sh", "-c", 'rm -f "$1"; mkfifo "$1"', "sh", str(result))
    run = measured_runner(runner_script, args, env, tmp_path, timeout=30)
    assert not run.timed_out, "the runner was still waiting on the FIFO after 30 s"
    assert run.returncode == 1, run.output
    summary = canonical(result)
    assert outcomes(summary) == [("result file", "error")]
    assert os.path.lexists(original(tmp_path))


@pytest.mark.parametrize(
    ("data", "problem"),
    [
        (b"this is not xml at all\n", "not XML (no element found in it)"),
        (
            b'<?xml version="1.0"?>\n<Site BuildName="b"><Testing><Test/></Testing></Site>\n',
            "the root element is <Site>, not <testsuites> or <testsuite>.",
        ),
        (bytes(range(256)) * 4, "not XML ("),
    ],
    ids=["text", "other-root", "binary"],
)
def test_not_a_result_file_is_named(
    runner_script: str, env: dict[str, str], tmp_path: Path, data: bytes, problem: str
) -> None:
    proc = leave(runner_script, env, tmp_path, data)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    assert outcomes(summary) == [("result file", "error")]
    assert problem in damage(summary).message


# --- encodings -----------------------------------------------------------------------------


def _declared(encoding: str, name: str) -> str:
    return (
        f'<?xml version="1.0" encoding="{encoding}"?>\n<testsuite name="s">'
        f'<testcase classname="C" name="{name}"><system-out>{name} out</system-out>'
        "</testcase></testsuite>\n"
    )


@pytest.mark.parametrize(
    "data",
    [
        _declared("ISO-8859-1", "caf\u00e9").encode("latin-1"),
        _declared("UTF-16", "caf\u00e9").encode("utf-16"),
        b"\xfe\xff" + _declared("UTF-16", "caf\u00e9").encode("utf-16-be"),
    ],
    ids=["iso-8859-1", "utf-16-bom", "utf-16-big-endian-bom"],
)
def test_declared_encoding_and_bom_are_honoured(
    runner_script: str, env: dict[str, str], tmp_path: Path, data: bytes
) -> None:
    assert "\u00e9".encode() not in data
    proc = leave(runner_script, env, tmp_path, data)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    assert outcomes(summary) == [("caf\u00e9", "passed")]
    assert "result_file_repairs" not in summary.properties
    out = etree.parse(str(result_path(tmp_path))).findtext(".//testcase/system-out")
    assert out == "caf\u00e9 out"


@pytest.mark.parametrize(
    "encoding", ["mbcs", "hex", "base64", "rot13", "idna", "utf-32", "undefined"]
)
def test_declared_encoding_that_cannot_decode_text_is_read_as_utf8(
    runner_script: str, env: dict[str, str], tmp_path: Path, encoding: str
) -> None:
    """Only text encodings can be honoured; the rest are read as UTF-8, like unknown ones.

    ``mbcs`` is unknown on Linux; ``hex`` ... ``undefined`` are Python codecs that are not
    text encodings (or, for UTF-32 without a BOM, not what the bytes are).
    """
    data = _declared(encoding, "a").encode()
    proc = leave(runner_script, env, tmp_path, data)
    assert "Traceback" not in proc.stdout + proc.stderr
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = canonical(result_path(tmp_path))
    assert original(tmp_path).read_bytes() == data
    assert outcomes(summary) == [("a", "passed")]
    assert repairs(summary).startswith(
        (
            f"unknown encoding '{encoding}' declared; read as UTF-8",
            "the declared encoding failed; read as UTF-8",
        )
    )


# --- size ----------------------------------------------------------------------------------

_HUGE_HEAD = f'{DECLARATION}<testsuites><testsuite name="s">{A}{B}<system-out>'.encode()


@capabilities.FREE_DISK
@pytest.mark.parametrize("content", ["written", "sparse"])
def test_multi_gigabyte_file_is_read_to_a_cap(
    runner_script: str, env: dict[str, str], tmp_path: Path, content: str
) -> None:
    """A 2.5 GiB result file: read to 256 MiB, in bounded time and memory.

    ``written``: the read window (260 MiB of "x" in a suite's system-out) is real data,
    so the reader does its full work on it, and only the tail beyond is a hole, which
    makes the file 2.5 GiB on disk with 260 MiB written. ``sparse``: everything after the
    head is a hole, read back as NUL bytes, which XML forbids, so each one must be shown.
    """
    size = 2 * GIB + 512 * MIB
    written = 260 if content == "written" else 0
    make = (
        "import sys\n"
        "with open(sys.argv[1], 'wb') as f:\n"
        f"    f.write({_HUGE_HEAD!r})\n"
        "    chunk = b'x' * (1 << 20)\n"
        f"    for _ in range({written}):\n"
        "        f.write(chunk)\n"
        f"    f.truncate({size})\n"
    )
    result = result_path(tmp_path)
    args = runner_args(result, sys.executable, "-c", make, str(result))
    try:
        # Some 10 s on a loaded machine; this only stops a reader that never stops reading.
        run = measured_runner(runner_script, args, env, tmp_path, timeout=120)
        print(f"{content}: {run.wall:.2f} s, peak RSS {run.max_rss / 1e6:.1f} MB")
        assert not run.timed_out, "the runner was still reading after 120 s"
        assert original(tmp_path).stat().st_size == size
        assert run.max_rss < MAX_RSS
        assert result.stat().st_size < MAX_CANONICAL
        assert run.returncode == 1, run.output
        summary = canonical(result)
        assert outcomes(summary) == [("a", "passed"), ("b", "passed"), ("result file", "error")]
        assert damage(summary).message == (
            "Invalid result file t.xml, not fully readable: only the first 256 MiB of "
            f"{size} bytes were read: the file is too large to be a useful result. "
            "2 test case(s) before the damage were kept."
        )
    finally:
        with contextlib.suppress(FileNotFoundError):
            original(tmp_path).unlink()
        with contextlib.suppress(FileNotFoundError):
            result.unlink()


def test_huge_texts_and_100000_cases_make_a_small_file(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    count, every = 100_000, 1000
    failing = {index for index in range(count) if index % every == every - 1}
    source = tmp_path / "huge.xml"
    with open(source, "w", encoding="utf-8") as handle:
        handle.write(
            f'{DECLARATION}<testsuites tests="{count + 2}" failures="{len(failing) + 1}">'
            f'<testsuite name="s" tests="{count + 2}" failures="{len(failing) + 1}">'
            '<testcase classname="C" name="big-out"><system-out>HEAD-MARK'
        )
        for _ in range(50):
            handle.write("o" * 1_000_000)
        handle.write(
            'TAIL-MARK</system-out></testcase><testcase classname="C" name="big-message">'
            '<failure message="MSG-HEAD' + "m" * 20_000_000 + 'MSG-TAIL">trace</failure>'
            "</testcase>"
        )
        for index in range(count):
            body = '<failure message="no">trace</failure>' if index in failing else ""
            handle.write(f'<testcase classname="C" name="case{index}">{body}</testcase>')
        handle.write("</testsuite></testsuites>\n")
    result = result_path(tmp_path)
    args = runner_args(result, "sh", "-c", 'cat "$2" > "$1"', "sh", str(result), str(source))
    try:
        run = measured_runner(runner_script, args, env, tmp_path, timeout=90)
        assert original(tmp_path).stat().st_size == source.stat().st_size
    finally:
        for big in (source, original(tmp_path)):
            with contextlib.suppress(FileNotFoundError):
                big.unlink()
    print(f"huge texts: {run.wall:.2f} s, peak RSS {run.max_rss / 1e6:.1f} MB")
    assert not run.timed_out
    assert run.returncode == 1, run.output  # the file reports failures
    # About 65 bytes per case: 100,000 cases make a file of a few MB, not more.
    assert result.stat().st_size < 8 * 1000 * 1000
    summary = canonical(result)
    tree = etree.parse(str(result))
    kept = 100_000  # MAX_CASES: beyond it, failing cases are kept, passed ones counted
    names = [case.name for case in summary.cases]
    assert names == [
        "big-out",
        "big-message",
        *(f"case{index}" for index in range(kept - 2)),
        f"case{count - 1}",
        "further test cases",
    ]
    out = tree.findtext(".//testcase[@name='big-out']/system-out")
    assert out is not None
    assert out.startswith("HEAD-MARK")
    assert out.endswith("TAIL-MARK")
    assert " characters cut ...]" in out
    big_message = summary.cases[1]
    assert big_message.outcome == "failure"
    assert big_message.message.startswith("MSG-HEAD")
    assert big_message.message.endswith("MSG-TAIL")
    assert " characters cut ...]" in big_message.message
    assert len(big_message.message) < 100_000
    assert count - 1 in failing and count - 2 not in failing
    further = summary.cases[-1]
    assert further.outcome == "passed"
    element = tree.find("testsuite")
    assert element is not None
    assert element.get("tests") == str(kept + 2)
    assert element.get("failures") == str(len(failing) + 1)
    assert "unreported test cases" not in names


@pytest.mark.parametrize(
    "name",
    ["n" * 300, "first line&#10;second line"],
    ids=["longer-than-the-name-cap", "multi-line"],
)
def test_overlong_or_multiline_case_name_keeps_every_case(
    runner_script: str, env: dict[str, str], tmp_path: Path, name: str
) -> None:
    """A name is capped like any text, but the capped name must still be a valid name."""
    data = suite(A, f'<testcase classname="C" name="{name}"/>')
    proc = leave(runner_script, env, tmp_path, data)
    summary = canonical(result_path(tmp_path))
    assert len(summary.cases) == 2, outcomes(summary)
    assert summary.cases[0].name == "a"
    assert summary.cases[1].name.startswith(name[:5])
    assert summary.cases[1].outcome == "passed"
    assert proc.returncode == 0, proc.stdout + proc.stderr


# --- our own bugs, and fuzzing -------------------------------------------------------------


@pytest.mark.parametrize("name", ["", "  ", "t ", "a\nb"])
def test_unusable_suite_names_are_made_usable_not_fatal(name: str) -> None:
    rendered = validate.render(
        Suite(
            name=name,
            cases=[Case("pkg.C", "a")],
            time=1.0,
            timestamp=validate.timestamp(),
            hostname="host",
        )
    )
    root = etree.fromstring(rendered.data)
    assert validate.problems(root) == []
    assert not rendered.failed
    assert [case.get("name") for case in root.iter("testcase")] == ["a"]


def _suite(name: str, cases: list[Case]) -> Suite:
    return Suite(name=name, cases=cases, time=1.0, timestamp=validate.timestamp(), hostname="host")


@pytest.mark.parametrize(
    ("broken", "named"),
    [
        (
            _suite("pkg.t", [Case("pkg.C", "a"), Case("pkg.C", "a")]),
            "Duplicate key-sequence ['pkg.C', 'a'] in unique identity-constraint 'unique-case'",
        ),
    ],
    ids=["duplicate-case"],
)
def test_schema_violation_becomes_a_valid_file_with_an_error_case(
    broken: Suite, named: str
) -> None:
    rendered = validate.render(broken)
    assert rendered.failed, "a result replaced by the internal error must fail the run"
    root = etree.fromstring(rendered.data)
    assert validate.problems(root) == []
    cases = root.findall(".//testcase")
    assert [case.get("name") for case in cases] == ["result file"]
    error = cases[0].find("error")
    assert error is not None
    message = error.get("message", "")
    assert "does not match its own schema (a bug: please report it)" in message
    assert named in message
    assert error.get("type") == "InternalError"


_VALID = suite(
    '<testcase classname="C" name="a" time="1.5"><system-out>out &amp; about</system-out>'
    "</testcase>",
    '<testcase classname="C" name="b"><failure message="m&#10;n" type="T">trace]]&gt;'
    "</failure><system-err>err</system-err></testcase>",
    '<testcase classname="D" name="c"><skipped message="later"/></testcase>',
    '<testcase classname="D" name="d"><error message="e"><![CDATA[x < y]]></error></testcase>',
    attrs='name="s" tests="4" failures="1" errors="1" skipped="1"',
)
_FRAGMENTS = [
    b"<",
    b">",
    b"&",
    b"&#1;",
    b"&#xD800;",
    b"\xff",
    b"\xc3",
    b"\x00",
    b"\x1b[31m",
    b"]]>",
    b"<!DOCTYPE x [<!ENTITY e 'v'>]>",
    b"<testcase name='x'>",
    b"</testsuite>",
    b"<testsuite>",
    b'"',
    b"<?xml version='1.0' encoding='latin-1'?>",
    b"\xef\xbb\xbf",
]


def _mutated(rng: random.Random) -> bytes:
    data = bytearray(_VALID)
    for _ in range(rng.randint(1, 6)):
        where = rng.randrange(len(data) + 1)
        operation = rng.randrange(4)
        if operation == 0:
            data[where:where] = rng.choice(_FRAGMENTS)
        elif operation == 1 and data:
            data[min(where, len(data) - 1)] = rng.randrange(256)
        elif operation == 2:
            del data[where : where + rng.randint(1, 40)]
        else:
            del data[where:]
    return bytes(data[:5000])


def test_random_bytes_never_raise_and_always_give_a_valid_file(tmp_path: Path) -> None:
    rng = random.Random(0)
    inputs: list[bytes] = []
    for index in range(50):
        if index % 2:
            inputs.append(_mutated(rng))
        else:
            inputs.append(bytes(rng.randrange(256) for _ in range(rng.randint(0, 5000))))
    inputs[0] = b""
    bad: list[str] = []
    for index, data in enumerate(inputs):
        path = tmp_path / f"fuzz{index}.xml"
        path.write_bytes(data)
        try:
            rendered, _failed = normalise_file(path, "pkg", "t")
            found = validate.problems(etree.fromstring(rendered))
        except Exception as error:
            bad.append(f"{path}: raised {error!r}")
            continue
        if found:
            bad.append(f"{path}: {found[:2]}")
    assert bad == []
