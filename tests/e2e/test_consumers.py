"""Every canonical file is read alike by GitLab, Jenkins, junitparser, colcon, xunit-viewer
and our own ``report``.

The files are produced for real: each ``tests/data`` sample and each crafted producer file
below through ``ros-isolated-test normalise``, and real tests through the ctest RUNNER and
``run`` (a pass, a crash, a timeout, a refusal, output that is not UTF-8, a test writing a
colliding result of its own, one that fails once then passes with reruns allowed). Then
one ``colcon test-result`` and one xunit-viewer run read them all, and GitLab's and
Jenkins' reading rules (helpers/consumers.py) read each. Every consumer must count the
same tests, failures, errors and skips as ``report``, list every case once under its own
identity, and drop nothing (consumers.disagreements). colcon trusts only the count
attributes and xunit-viewer only the elements, so their agreement means the attributes and
the elements say the same thing. The controls show the comparison fails on raw files where
the consumers are known to differ.
"""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import consumers
from helpers.commands import REPO, normalise, run_cli, run_runner
from helpers.consumers import CONSUMERS, Counts, Reading
from helpers.xunit import SAMPLES
from lxml import etree

PACKAGE = "mypkg"


@dataclass(frozen=True)
class Crafted:
    """A producer's file with a shape some consumer reads differently."""

    xml: str
    counts: Counts | None = None
    """What every reader must count in its canonical form, when the issue says so."""


def _suite(name: str, body: str, counts: str = 'tests="1" failures="0" errors="0"') -> str:
    head = '<?xml version="1.0" encoding="UTF-8"?>\n'
    return f'{head}<testsuite name="{name}" {counts}>{body}</testsuite>\n'


CRAFTED: dict[str, Crafted] = {
    # GitLab's key "#{suite}_#{classname}_#{name}": a.b_c and a_b.c are one case to it.
    "gitlab_collision": Crafted(
        _suite(
            "gitlab_collision",
            '<testcase classname="pkg.a" name="b_c" time="0.1"/>'
            '<testcase classname="pkg.a_b" name="c" time="0.1"/>'
            '<testcase classname="pkg.a_b" name="c_d" time="0.1"><failure message="m">t</failure>'
            "</testcase>"
            '<testcase classname="pkg.a_b_c" name="d" time="0.1"><failure message="n">u</failure>'
            "</testcase>",
        ),
        (4, 2, 0, 0),
    ),
    # GitLab's type converter refuses yaml/symbol, a date that is no date and a file with no
    # text: the file is dropped.
    "type_attributes": Crafted(
        _suite(
            "type_attributes",
            '<testcase classname="C" name="yaml" time="0.1">'
            '<failure type="yaml" message="m">--- x</failure></testcase>'
            '<testcase classname="C" name="symbol" time="0.1">'
            '<error type="symbol" message="m">boom</error></testcase>'
            '<testcase classname="C" name="date" time="0.1">'
            '<skipped type="date" message="later">not a date</skipped></testcase>'
            '<testcase classname="C" name="datetime" time="0.1">'
            '<failure type="datetime" message="m">Traceback: oops</failure></testcase>'
            # ActiveSupport base64-decodes a type="file" element's text, and has none here.
            '<testcase classname="C" name="file" time="0.1"><skipped type="file"/></testcase>',
        ),
        (5, 2, 1, 2),
    ),
    # Small internal entities: one failure with its text, not three errors.
    "doctype_entities": Crafted(
        '<?xml version="1.0" encoding="UTF-8"?>\n<!DOCTYPE testsuite [\n'
        '<!ENTITY who "the talker">\n<!ENTITY msg "&who; never spoke">\n]>\n'
        '<testsuite name="doctype_entities" tests="2" failures="1" errors="0">'
        '<testcase classname="C" name="ok" time="0.1"/>'
        '<testcase classname="C" name="hears" time="0.1">'
        '<failure message="&msg;">AssertionError: &msg; (&who;)</failure></testcase>'
        "</testsuite>\n",
        (2, 1, 0, 0),
    ),
    # Counts claimed for cases that are not there.
    "claimed_counts": Crafted(
        _suite(
            "claimed_counts",
            '<testcase classname="C" name="only" time="0.1"/>',
            'tests="6" failures="1" errors="1" skipped="2"',
        )
    ),
    # pytest found no tests: Jenkins drops a suite without a testcase.
    "zero_cases": Crafted(
        '<?xml version="1.0" encoding="UTF-8"?>\n<testsuites><testsuite name="zero_cases" '
        'tests="0" failures="0" errors="0" skipped="0" time="0.0"/></testsuites>\n'
    ),
    # One case written twice in a suite (xunit-viewer merges), the same name in another.
    "duplicates": Crafted(
        '<?xml version="1.0" encoding="UTF-8"?>\n<testsuites>'
        '<testsuite name="duplicates_one" tests="3" failures="1" errors="1">'
        '<testcase classname="C" name="t" time="0.1"><failure message="f">f</failure></testcase>'
        '<testcase classname="C" name="t" time="0.1"><error message="teardown">e</error></testcase>'
        '<testcase classname="C" name="u" time="0.1"/></testsuite>'
        '<testsuite name="duplicates_two" tests="2" failures="0" errors="0">'
        '<testcase classname="C" name="t" time="0.1"/><testcase classname="C" name="u" time="0.1"/>'
        "</testsuite></testsuites>\n"
    ),
    # Surefire's own reruns: a flaky pass (no output), a flaky error pass, a rerun failure.
    "surefire_flaky": Crafted(
        _suite(
            "surefire_flaky",
            '<testcase classname="C" name="flaky_pass" time="0.1">'
            '<flakyFailure message="first" type="AssertionError">first try failed</flakyFailure>'
            "</testcase>"
            '<testcase classname="C" name="flaky_error_pass" time="0.1">'
            '<flakyError message="boom" type="RuntimeError">crashed once</flakyError>'
            "<system-out>second run ok</system-out></testcase>"
            '<testcase classname="C" name="always_fails" time="0.1">'
            '<failure message="third" type="AssertionError">third</failure>'
            '<rerunFailure message="first" type="AssertionError">first</rerunFailure>'
            '<rerunFailure message="second" type="AssertionError">second</rerunFailure>'
            "</testcase>",
            'tests="3" failures="1" errors="0"',
        ),
        (3, 1, 0, 0),
    ),
}

#: Cases of the RUNNER's reruns file: the first attempt fails, the second passes.
ATTEMPT_FAILS = _suite(
    "attempt",
    '<testcase classname="T" name="talks" time="0.1"><failure message="late">no reply</failure>'
    "</testcase>",
    'tests="1" failures="1" errors="0"',
)
ATTEMPT_PASSES = _suite("attempt", '<testcase classname="T" name="talks" time="0.1"/>')
#: A second attempt without the failed case: "failed, then not run" (issue 30, item 5).
ATTEMPT_LACKS_IT = _suite("attempt", '<testcase classname="T" name="listens" time="0.1"/>')
#: sh -c: $0 fails.xml $1 passes.xml $2 state file $3 result file.
FAIL_ONCE = 'if [ -e "$2" ]; then cat "$1" > "$3"; exit 0; fi; touch "$2"; cat "$0" > "$3"; exit 1'

#: The test's own file of ``runner_own_file_exit_3``: three cases, one skipped.
OWN_RESULT = (
    '<?xml version="1.0" encoding="UTF-8"?>\n<testsuites><testsuite name="own" tests="3" '
    'failures="0" errors="0" skipped="1"><testcase classname="C" name="a" time="0.1"/>'
    '<testcase classname="C" name="b" time="0.2"/><testcase classname="C" name="c">'
    '<skipped message="later"/></testcase></testsuite></testsuites>\n'
)


@dataclass(frozen=True)
class Run:
    """One real run whose canonical result joins the folder."""

    args: tuple[str, ...]
    """After ``RUNNER RESULT --package-name mypkg`` (or ``run``'s options) for this run;
    ``OWN`` is replaced by a file holding ``OWN_RESULT``, ``RESULT`` by the result path."""
    counts: Counts
    code: int
    shell: bool = False
    """Through ``ros-isolated-test run --junit-xml`` instead of the RUNNER."""
    preset_domain: bool = False


RUNS: dict[str, Run] = {
    "runner_pass": Run(("--generate-result-on-success", "--command", "true"), (1, 0, 0, 0), 0),
    "runner_no_result": Run(
        ("--generate-result-on-success", "--command", "sh", "-c", "echo out-tail; exit 5"),
        (1, 1, 0, 0),
        5,
    ),
    "runner_sigsegv": Run(
        ("--command", "sh", "-c", "echo dying; ulimit -c 0; kill -SEGV $$"), (1, 1, 0, 0), 139
    ),
    "runner_skip_code": Run(
        ("--skip-return-code", "77", "--command", "sh", "-c", "exit 77"), (1, 0, 0, 1), 77
    ),
    "runner_refused": Run(("--command", "true"), (1, 1, 0, 0), 2, preset_domain=True),
    "runner_own_file_exit_3": Run(
        ("--command", "sh", "-c", 'cat "$0" > "$1"; exit 3', "OWN", "RESULT"), (4, 1, 0, 1), 3
    ),
    "runner_undecodable_output": Run(
        ("--command", "sh", "-c", r"printf 'bad \377\376 bytes\n'; exit 2"), (1, 1, 0, 0), 2
    ),
    "run_timeout": Run(("--timeout", "1", "--", "sleep", "30"), (1, 1, 0, 0), 124, shell=True),
}
SAMPLE_NAMES = sorted(path.stem for path in SAMPLES.glob("*.xml"))
RERUNS = ("runner_gitlab_collision", "runner_rerun_flaky", "runner_rerun_not_run_again")
NAMES = SAMPLE_NAMES + [f"crafted_{name}" for name in CRAFTED] + sorted(RUNS) + list(RERUNS)
#: What colcon says when it cannot read a file as it should.
COLCON_NOISE = re.compile(r"^(\[[0-9.]+s\] )?(WARNING|ERROR)\b|^Traceback ")


@dataclass(frozen=True)
class Folder:
    """The canonical files and every consumer's reading of each (by name)."""

    path: Path
    readings: dict[str, dict[str, Reading]]
    codes: dict[str, int]
    """The exit code of each RUNNER run."""
    report: dict[str, Counts]
    """What ``ros-isolated-test report --json`` counts in each file."""
    scratch: Path

    def file(self, name: str) -> Path:
        return self.path / f"{name}.xml"


def runner(
    name: str, command: list[str], staging: Path, script: str, env: Mapping[str, str]
) -> tuple[Path, int]:
    """A real test through the ctest RUNNER; the canonical file it left, its exit code."""
    result = staging / f"{name}.xml"
    args = [str(result), "--package-name", PACKAGE, "--command", *command]
    args = [str(result) if arg == "RESULT" else arg for arg in args]
    proc = run_runner(script, args, env, cwd=staging)
    assert result.is_file(), proc.stdout + proc.stderr
    return result, proc.returncode


def real_run(name: str, run: Run, staging: Path, script: str, env: Mapping[str, str]) -> Path:
    """``run`` for real, through the RUNNER or the shell's ``run``; the canonical file it left."""
    result = staging / f"{name}.xml"
    own = staging / f"{name}.own"
    own.write_text(OWN_RESULT)
    args = [{"OWN": str(own), "RESULT": str(result)}.get(arg, arg) for arg in run.args]
    run_env = dict(env)
    if run.preset_domain:
        run_env["ROS_DOMAIN_ID"] = "5"
    if run.shell:
        options, command = args[: args.index("--")], args[args.index("--") :]
        proc = run_cli(
            ["run", "--package-name", PACKAGE, "--junit-xml", str(result), *options, *command],
            run_env,
            cwd=staging,
        )
    else:
        proc = run_runner(
            script,
            [str(result), "--package-name", PACKAGE, *args],
            run_env,
            cwd=staging,
            errors="replace",
        )
    assert proc.returncode == run.code, proc.stdout + proc.stderr
    assert result.is_file(), proc.stdout + proc.stderr
    return result


@pytest.fixture(scope="module")
def folder(
    module_env: dict[str, str], runner_script: str, tmp_path_factory: pytest.TempPathFactory
) -> Folder:
    out = tmp_path_factory.mktemp("canonical")
    raw = tmp_path_factory.mktemp("crafted")
    staging = tmp_path_factory.mktemp("staging")
    for name in SAMPLE_NAMES:
        normalise(SAMPLES / f"{name}.xml", out / f"{name}.xml", module_env, PACKAGE)
    for name, crafted in CRAFTED.items():
        (raw / f"{name}.xml").write_text(crafted.xml)
        normalise(raw / f"{name}.xml", out / f"crafted_{name}.xml", module_env, PACKAGE)
    own = staging / "collision.own"
    own.write_text(CRAFTED["gitlab_collision"].xml)
    collided, collided_code = runner(
        "runner_gitlab_collision",
        ["sh", "-c", 'cat "$0" > "$1"; exit 1', str(own), "RESULT"],
        staging,
        runner_script,
        module_env,
    )
    (out / collided.name).write_bytes(collided.read_bytes())
    fails, passes = staging / "fails.own", staging / "passes.own"
    fails.write_text(ATTEMPT_FAILS)
    passes.write_text(ATTEMPT_PASSES)
    rerun_env = {**module_env, "ROS_ISOLATED_TEST_RERUNS": "2"}
    state = staging / "attempted"
    flaky, flaky_code = runner(
        "runner_rerun_flaky",
        ["sh", "-c", FAIL_ONCE, str(fails), str(passes), str(state), "RESULT"],
        staging,
        runner_script,
        rerun_env,
    )
    (out / flaky.name).write_bytes(flaky.read_bytes())
    lacks = staging / "lacks.own"
    lacks.write_text(ATTEMPT_LACKS_IT)
    gone, gone_code = runner(
        "runner_rerun_not_run_again",
        ["sh", "-c", FAIL_ONCE, str(fails), str(lacks), str(staging / "tried"), "RESULT"],
        staging,
        runner_script,
        rerun_env,
    )
    (out / gone.name).write_bytes(gone.read_bytes())
    for name, run in RUNS.items():
        # Only the canonical file: the test's own, kept as .orig, stays in staging.
        shutil.copy(real_run(name, run, staging, runner_script, module_env), out / f"{name}.xml")
    assert sorted(path.stem for path in out.glob("*.xml")) == sorted(NAMES)
    paths = [out / f"{name}.xml" for name in NAMES]
    readings = consumers.read_all(paths, tmp_path_factory.mktemp("readers"))
    codes = {collided.stem: collided_code, flaky.stem: flaky_code, gone.stem: gone_code}
    proc = run_cli(["report", "--json", str(out)], module_env)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    report = {
        Path(row["path"]).stem: (row["tests"], row["failures"], row["errors"], row["skipped"])
        for row in json.loads(proc.stdout)["files"]
    }
    return Folder(
        out,
        {path.stem: readings[path] for path in paths},
        codes,
        report,
        tmp_path_factory.mktemp("scratch"),
    )


# --- agreement ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_every_reader_reads_the_canonical_file_alike(folder: Folder, name: str) -> None:
    if name == "runner_gitlab_collision":
        assert folder.codes[name] == 1
    readings = folder.readings[name]
    assert sorted(readings) == sorted(CONSUMERS)
    assert list(consumers.disagreements(folder.file(name), readings)) == []


@pytest.mark.parametrize("name", NAMES)
def test_every_reader_counts_what_report_counts(folder: Folder, name: str) -> None:
    """Our own ``report`` and every consumer count each file alike (and each run as meant)."""
    expected = folder.report[name]
    if name in RUNS:
        assert expected == RUNS[name].counts
    counts = {reader: reading.counts for reader, reading in folder.readings[name].items()}
    assert counts == dict.fromkeys(CONSUMERS, expected)


def test_colcon_reads_the_canonical_files_without_a_warning(folder: Folder) -> None:
    """colcon says nothing but counts: no WARNING, ERROR or traceback about any file."""
    proc = consumers.colcon_test_result(folder.path, folder.scratch, "--verbose")
    noise = [line for line in proc.stdout.splitlines() if COLCON_NOISE.search(line)]
    assert noise == [], proc.stdout
    assert not re.search("WARNING|ERROR|Traceback", proc.stderr), proc.stderr
    assert sorted(consumers.colcon_counts(proc.stdout)) == sorted(f"{n}.xml" for n in NAMES)


def test_xunit_viewer_reads_a_run_whose_output_was_not_utf8(folder: Folder) -> None:
    """Its encoding guesser takes any U+FFFD for "not UTF-8" and the whole run dies.

    A test printing bytes that are not UTF-8 is ordinary (binary data, a Latin-1 log).
    """
    name = "runner_undecodable_output"
    alone = folder.scratch / "undecodable"
    alone.mkdir()
    shutil.copy(folder.file(name), alone / f"{name}.xml")
    proc = consumers.run_xunit_viewer(alone, folder.scratch / "viewer-undecodable")
    assert "Failed to parse" not in proc.stdout + proc.stderr
    assert consumers.viewer_totals(proc.stdout) == folder.report[name]
    assert not (REPO / "index.html").exists()


@pytest.mark.parametrize("name", [name for name, crafted in CRAFTED.items() if crafted.counts])
def test_every_reader_counts_what_the_producer_meant(folder: Folder, name: str) -> None:
    """Alike is not enough: the counts are the producer's (one failure stays one failure)."""
    readings = folder.readings[f"crafted_{name}"]
    assert {reader: r.counts for reader, r in readings.items()} == dict.fromkeys(
        CONSUMERS, CRAFTED[name].counts
    )


def test_internal_entities_keep_the_failure_text(folder: Folder) -> None:
    root = etree.parse(str(folder.file("crafted_doctype_entities"))).getroot()
    texts = [node.text or "" for node in root.iter("failure")]
    assert texts and all("the talker never spoke (the talker)" in text for text in texts), texts


@pytest.mark.parametrize("name", ["crafted_surefire_flaky", "runner_rerun_flaky"])
def test_a_flaky_pass_is_a_pass_to_every_reader(folder: Folder, name: str) -> None:
    """The canonical file keeps the failed attempt as flakyFailure/flakyError; no reader fails it.

    GitLab, Jenkins and colcon do not look at the attempt elements; junitparser marks the
    case flaky; xunit-viewer shows the status of the first child element, so a flaky pass
    must not start with its flaky element or it is shown as ``?``.
    """
    path = folder.file(name)
    root = etree.parse(str(path)).getroot()
    flaky = [
        consumers.CaseKey(str(suite.get("name")), str(case.get("classname")), str(case.get("name")))
        for suite in root.iter("testsuite")
        for case in suite.iterchildren("testcase")
        if any(case.find(tag) is not None for tag in consumers.FLAKY)
        and case.find("failure") is None
        and case.find("error") is None
    ]
    assert flaky, f"no case of {name} keeps its failed attempt as flakyFailure/flakyError"
    assert folder.codes.get(name, 0) == 0, "a flaky pass exits 0"
    readings = folder.readings[name]
    for reader, reading in readings.items():
        shown_failing = [key for key in flaky if consumers.IDENTITY[reader](key) in reading.failing]
        assert shown_failing == [], f"{reader} fails a flaky pass"
        assert not reading.unclassified, f"{reader}: {reading.unclassified}"
    assert readings["junitparser"].flaky == consumers.expected("junitparser", flaky)
    assert list(consumers.disagreements(path, readings)) == []


def test_a_case_failing_every_attempt_is_one_failure_to_every_reader(folder: Folder) -> None:
    path = folder.file("crafted_surefire_flaky")
    root = etree.parse(str(path)).getroot()
    case = next(node for node in root.iter("testcase") if node.get("name") == "always_fails")
    assert len(case.findall("failure")) == 1
    key = consumers.CaseKey(
        str(root.find("testsuite").get("name")),  # type: ignore[union-attr]
        str(case.get("classname")),
        "always_fails",
    )
    for reader, reading in folder.readings["crafted_surefire_flaky"].items():
        assert reading.failing[consumers.IDENTITY[reader](key)] == 1, reader


def test_a_case_that_failed_and_then_was_not_run_is_a_failure_to_every_reader(
    folder: Folder,
) -> None:
    """Never seen to pass: one failure to each reader, and the RUNNER exits 1."""
    name = "runner_rerun_not_run_again"
    assert folder.codes[name] == 1
    root = etree.parse(str(folder.file(name))).getroot()
    case = next(node for node in root.iter("testcase") if node.get("name") == "talks")
    assert [child.tag for child in case][:2] == ["failure", "rerunFailure"]
    key = consumers.CaseKey(
        str(root.find("testsuite").get("name")),  # type: ignore[union-attr]
        str(case.get("classname")),
        "talks",
    )
    for reader, reading in folder.readings[name].items():
        assert reading.failing[consumers.IDENTITY[reader](key)] == 1, reader
        assert reading.counts == (2, 1, 0, 0), reader


# --- controls: where the readers disagree on raw files ------------------------------------------


@pytest.fixture(scope="module")
def raw(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Reading]]:
    """The crafted producer files as they are, read by every consumer."""
    folder = tmp_path_factory.mktemp("raw")
    names = [name for name in CRAFTED if name != "doctype_entities"]
    for name in names:
        (folder / f"{name}.xml").write_text(CRAFTED[name].xml)
    paths = [folder / f"{name}.xml" for name in names]
    readings = consumers.read_all(paths, tmp_path_factory.mktemp("raw-readers"))
    return {path.stem: readings[path] for path in paths}


@pytest.mark.parametrize(
    ("name", "reader", "says"),
    [
        ("gitlab_collision", "gitlab", "counts 2 tests"),
        ("type_attributes", "gitlab", "dropped the file: Disallowed type attribute: 'yaml'"),
        ("zero_cases", "jenkins", "shows the suites [], not"),
        ("duplicates", "xunit-viewer", "counts 4 tests"),
        ("claimed_counts", "colcon", "counts 6 tests"),
        ("surefire_flaky", "xunit-viewer", "no known status"),
    ],
)
def test_control_raw_files_are_read_differently(
    raw: dict[str, dict[str, Reading]], tmp_path: Path, name: str, reader: str, says: str
) -> None:
    """The comparison above can fail: each raw shape trips the consumer the issue names."""
    path = tmp_path / f"{name}.xml"
    path.write_text(CRAFTED[name].xml)
    found = list(consumers.disagreements(path, raw[name]))
    assert any(line.startswith(reader) and says in line for line in found), found


@pytest.mark.parametrize(
    "sample",
    [
        # pytest writes the case twice; colcon counts both, xunit-viewer merges them.
        "pytest-9.2_fail_plus_teardown_error",
        # gtest's set-up failure is under failures="0": colcon sees a pass.
        "gtest-1.17.0_setupsuite_failure_after_run_test.gtest",
        # ctest's disabled test: colcon counts it skipped, xunit-viewer passed.
        "ctest-4.4.4_output-junit",
    ],
)
def test_control_raw_file_counts_differ_and_its_canonical_form_agrees(
    folder: Folder, sample: str
) -> None:
    """A real producer's raw file is counted differently by colcon and xunit-viewer; its
    canonical form, read in the same run, by both as ``report`` counts it."""
    work = folder.scratch / "control" / sample
    raw_base = work / "raw"
    raw_base.mkdir(parents=True)
    shutil.copy(SAMPLES / f"{sample}.xml", raw_base / f"{sample}.xml")
    both = work / "both"
    both.mkdir()
    shutil.copy(SAMPLES / f"{sample}.xml", both / "raw.xml")
    shutil.copy(folder.file(sample), both / "canonical.xml")
    # Without --verbose, which drops the ctest file altogether (see the next test).
    raw_colcon = consumers.colcon_counts(consumers.colcon_test_result(raw_base, work).stdout)
    readings = consumers.xunit_viewer([both / "raw.xml", both / "canonical.xml"], work)
    assert raw_colcon[f"{sample}.xml"] != readings[both / "raw.xml"].counts
    assert readings[both / "canonical.xml"].counts == folder.report[sample]


def test_control_colcon_verbose_drops_a_raw_ctest_file_with_a_traceback(folder: Folder) -> None:
    """The no-WARNING/ERROR check above can fail: the raw ctest file trips it."""
    base = folder.scratch / "control" / "ctest-verbose"
    base.mkdir(parents=True)
    shutil.copy(SAMPLES / "ctest-3.25.1_output-junit.xml", base / "ctest.xml")
    proc = consumers.colcon_test_result(base, folder.scratch, "--verbose")
    assert re.search(r"ERROR.*Skipping", proc.stderr), proc.stderr
    assert "Traceback" in proc.stderr
    assert consumers.colcon_counts(proc.stdout) == {}
    assert proc.returncode == 0, "its failures vanished with the file"


# --- the reading rules themselves --------------------------------------------------------------


def _file(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "case.xml"
    path.write_text(_suite("s", body))
    return path


def test_gitlab_keeps_one_case_per_key_and_status(tmp_path: Path) -> None:
    path = _file(
        tmp_path,
        '<testcase classname="a" name="b_c"/><testcase classname="a_b" name="c"/>'
        '<testcase classname="x" name="y_z"/>'
        '<testcase classname="x_y" name="z"><failure message="m">t</failure></testcase>'
        '<testcase classname="p" name="q"/>',
    )
    reading = consumers.gitlab(path)
    # a.b_c and a_b.c: one kept; x.y_z passed and x_y.z failed: both kept; p.q apart.
    assert reading.counts == (4, 1, 0, 0)
    assert reading.cases == {"s_a_b_c": 1, "s_x_y_z": 2, "s_p_q": 1}
    assert consumers.jenkins(path).counts == (5, 1, 0, 0)


@pytest.mark.parametrize(
    ("element", "dropped"),
    [
        ('<failure type="yaml" message="m">t</failure>', True),
        ('<skipped type="symbol"/>', True),
        ('<error type="date" message="m">not a date</error>', True),
        ('<failure type="datetime" message="m">Traceback</failure>', True),
        ('<error type="date" message="m">2026-11-21</error>', False),
        ('<failure type="date" message="m"/>', False),
        ('<skipped type="file"/>', True),
        ('<skipped type="file">aGk=</skipped>', False),
        ('<failure type="AssertionError" message="m">t</failure>', False),
        ('<failure message="m">t</failure>', False),
    ],
)
def test_gitlab_type_converter_drops_the_whole_file(
    tmp_path: Path, element: str, dropped: bool
) -> None:
    path = _file(
        tmp_path,
        f'<testcase classname="C" name="t">{element}</testcase><testcase classname="C" name="u"/>',
    )
    reading = consumers.gitlab(path)
    assert bool(reading.dropped) == dropped, reading
    assert reading.tests == (0 if dropped else 2)


def test_jenkins_drops_suites_without_cases_and_reads_attempts_as_their_outcome(
    tmp_path: Path,
) -> None:
    path = tmp_path / "jenkins.xml"
    path.write_text(
        '<testsuites><testsuite name="empty" tests="0" failures="0" errors="0"/>'
        '<testsuite name="s" tests="3" failures="1" errors="0">'
        '<testcase classname="C" name="flaky"><flakyFailure type="E" message="m"/></testcase>'
        '<testcase classname="C" name="rerun"><failure message="m">t</failure>'
        '<rerunFailure type="E" message="m"/><rerunFailure type="E" message="m"/></testcase>'
        '<testcase name="skip_wins"><failure message="m">t</failure><skipped/></testcase>'
        "</testsuite></testsuites>"
    )
    reading = consumers.jenkins(path)
    assert reading.suites == frozenset({"s"})
    assert reading.counts == (3, 1, 0, 1)
    assert reading.failing == {"C/rerun": 1}
    assert reading.cases == {"C/flaky": 1, "C/rerun": 1, "s/skip_wins": 1}
    assert consumers.junitparser(path).flaky == {"s/C/flaky": 1}
