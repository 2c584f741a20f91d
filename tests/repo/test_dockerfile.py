"""The Dockerfile, checked statically, for machines without a Docker engine.

What it installs and runs is read from the file itself with a small parser (Dockerfile
instructions, JSON exec forms, the shell commands of RUN), and the build context with
the same .dockerignore rules Docker applies, so a COPY of an ignored file is caught.
Where an engine can run, tests/e2e/test_docker_engine.py builds the image and runs it.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import re
import shlex
from collections.abc import Iterator
from dataclasses import dataclass
from fnmatch import fnmatchcase
from pathlib import PurePosixPath

import pytest
from helpers import capabilities, docs
from helpers.commands import REPO, run_cli
from helpers.docker_engine import HOST_NAMESPACES, STANDIN_DOCKERFILE

from ros_isolated_test.domain_coordinator import LOCK_DIR_ENV, lock_dir_from_env

DOCKERFILE = REPO / "Dockerfile"
DOCKERIGNORE = REPO / ".dockerignore"
BASE_IMAGE = "ros:jazzy-ros-base"
#: Where the ROS images define PATH; a console script must land in one of them.
STANDARD_PATH = ("/usr/local/sbin", "/usr/local/bin", "/usr/sbin", "/usr/bin", "/sbin", "/bin")
SHELL_OPERATORS = {"&&", "||", ";", "|", "&"}


@dataclass(frozen=True)
class Instruction:
    keyword: str
    arguments: str
    line: int

    def exec_form(self) -> list[str] | None:
        """The JSON array of an exec-form ENTRYPOINT/CMD/RUN/COPY, None for shell form."""
        if not self.arguments.startswith("["):
            return None
        parsed = json.loads(self.arguments)
        assert isinstance(parsed, list), self
        assert all(isinstance(item, str) for item in parsed), self
        return parsed


def parse_dockerfile(text: str) -> list[Instruction]:
    """Instructions with line continuations joined; comments and blank lines dropped.

    Like Docker, a comment line inside a continued instruction is skipped, not an end.
    """
    instructions: list[Instruction] = []
    pending: list[str] = []
    start = 0
    for number, raw in enumerate(text.splitlines(), 1):
        stripped = raw.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if not pending:
            start = number
        if stripped.endswith("\\"):
            pending.append(stripped[:-1].strip())
            continue
        pending.append(stripped)
        keyword, _, arguments = " ".join(pending).partition(" ")
        instructions.append(Instruction(keyword.upper(), arguments.strip(), start))
        pending = []
    assert not pending, f"the Dockerfile ends inside a continued instruction (line {start})"
    return instructions


def shell_commands(script: str) -> list[list[str]]:
    """A RUN's shell script as simple commands, split at &&, ||, ;, | and &."""
    lexer = shlex.shlex(script, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    commands: list[list[str]] = [[]]
    for token in lexer:
        if token in SHELL_OPERATORS:
            commands.append([])
        else:
            commands[-1].append(token)
    return [command for command in commands if command]


@dataclass(frozen=True)
class Copy:
    sources: list[str]
    destination: str
    flags: list[str]


def copy_of(instruction: Instruction) -> Copy:
    words = instruction.exec_form() or shlex.split(instruction.arguments)
    flags = [word for word in words if word.startswith("--")]
    paths = [word for word in words if not word.startswith("--")]
    assert len(paths) >= 2, instruction
    return Copy(paths[:-1], paths[-1], flags)


def copied_to(copy: Copy, source: str) -> str:
    """Where a source lands: into the destination folder when it ends with '/'."""
    if copy.destination.endswith("/") or len(copy.sources) > 1:
        return str(PurePosixPath(copy.destination) / PurePosixPath(source).name)
    return copy.destination.rstrip("/")


# -- .dockerignore, as Docker reads it ------------------------------------------------------


def ignore_patterns(text: str) -> list[tuple[bool, list[str]]]:
    """(is an exception, pattern segments) per line, in order; Docker cleans leading '/'."""
    patterns: list[tuple[bool, list[str]]] = []
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        negated = line.startswith("!")
        pattern = line[1:].strip() if negated else line
        parts = [part for part in pattern.strip("/").split("/") if part not in ("", ".")]
        patterns.append((negated, parts))
    return patterns


def _segments_match(pattern: list[str], path: list[str]) -> bool:
    """Go filepath.Match per segment ('*' never crosses '/'), plus Docker's '**'."""
    if not pattern:
        return not path
    if pattern[0] == "**":
        return any(_segments_match(pattern[1:], path[index:]) for index in range(len(path) + 1))
    return (
        bool(path) and fnmatchcase(path[0], pattern[0]) and _segments_match(pattern[1:], path[1:])
    )


def is_ignored(path: str, patterns: list[tuple[bool, list[str]]]) -> bool:
    """Whether Docker leaves ``path`` out of the build context.

    A pattern applies to a path when it matches the path or one of its parent folders;
    the last pattern that applies decides.
    """
    parts = path.split("/")
    ignored = False
    for negated, pattern in patterns:
        if any(_segments_match(pattern, parts[:end]) for end in range(1, len(parts) + 1)):
            ignored = not negated
    return ignored


def test_the_dockerignore_matcher_follows_dockers_rules() -> None:
    patterns = ignore_patterns("*\n!keep\nkeep/**/cache\n# comment\n/abs\n")
    assert is_ignored("other.txt", patterns)
    assert is_ignored("sub/deep/file", patterns)
    assert not is_ignored("keep", patterns)
    assert not is_ignored("keep/a/b.py", patterns)
    assert is_ignored("keep/cache/x", patterns)
    assert is_ignored("keep/a/b/cache/x.pyc", patterns)
    assert not is_ignored("keep/cachet", patterns)
    only_star_py = ignore_patterns("*.py\n")
    assert is_ignored("top.py", only_star_py)
    assert not is_ignored("sub/nested.py", only_star_py), "'*' must not cross '/'"


# -- fixtures -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def instructions() -> list[Instruction]:
    return parse_dockerfile(DOCKERFILE.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def patterns() -> list[tuple[bool, list[str]]]:
    return ignore_patterns(DOCKERIGNORE.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def pyproject() -> dict[str, object]:
    capabilities.require(capabilities.TOMLLIB)
    tomllib = importlib.import_module("tomllib")  # 3.11+; the suite also runs on 3.10
    data: dict[str, object] = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    return data


def project(pyproject: dict[str, object]) -> dict[str, object]:
    table = pyproject["project"]
    assert isinstance(table, dict)
    return table


def console_script(pyproject: dict[str, object]) -> str:
    scripts = project(pyproject)["scripts"]
    assert isinstance(scripts, dict)
    (name,) = scripts
    return str(name)


def only(instructions: list[Instruction], keyword: str) -> Instruction:
    found = [item for item in instructions if item.keyword == keyword]
    assert len(found) == 1, f"expected one {keyword}, found {found}"
    return found[0]


def copies(instructions: list[Instruction]) -> list[Copy]:
    return [copy_of(item) for item in instructions if item.keyword in ("COPY", "ADD")]


def run_commands(instructions: list[Instruction]) -> Iterator[list[str]]:
    for item in instructions:
        if item.keyword == "RUN":
            form = item.exec_form()
            yield from [form] if form is not None else shell_commands(item.arguments)


def pip_installs(instructions: list[Instruction]) -> list[list[str]]:
    """The words of every ``pip install`` / ``python -m pip install``, pip's path first."""
    found = []
    for command in run_commands(instructions):
        words = command
        if len(words) > 2 and words[1:3] == ["-m", "pip"]:
            words = [words[0], *words[3:]]
        elif not PurePosixPath(words[0]).name.startswith("pip"):
            continue
        if len(words) > 1 and words[1] == "install":
            found.append(words)
    return found


def requirement_name(requirement: str) -> str:
    """The PEP 503 normalised project name of a requirement string."""
    match = re.match(r"[A-Za-z0-9][A-Za-z0-9._-]*", requirement.strip())
    assert match is not None, requirement
    return re.sub(r"[-_.]+", "-", match.group(0)).lower()


def package_dir(instructions: list[Instruction]) -> str:
    """Where the COPY puts pyproject.toml: the directory pip must install from."""
    for copy in copies(instructions):
        if "pyproject.toml" in copy.sources:
            return str(PurePosixPath(copied_to(copy, "pyproject.toml")).parent)
    pytest.fail("no COPY of pyproject.toml")


# -- the image ------------------------------------------------------------------------------


def base_arguments(instructions: list[Instruction]) -> dict[str, str | None]:
    """The ARGs declared before FROM (the only ones FROM may use), with their defaults."""
    declared: dict[str, str | None] = {}
    for item in instructions:
        if item.keyword == "FROM":
            break
        assert item.keyword == "ARG", f"only ARG may come before FROM, not {item}"
        name, equals, default = item.arguments.partition("=")
        declared[name.strip()] = default.strip().strip("\"'") if equals else None
    return declared


def test_the_base_is_an_argument_that_defaults_to_ros_jazzy_ros_base(
    instructions: list[Instruction],
) -> None:
    """One file for Jazzy, Kilted, Humble or a stand-in: ``--build-arg BASE=...``."""
    base = only(instructions, "FROM").arguments
    match = re.fullmatch(r"\$\{(\w+)\}|\$(\w+)", base)
    assert match, f"FROM {base}: the base must come from an ARG declared before FROM"
    name = match.group(1) or match.group(2)
    assert base_arguments(instructions).get(name) == BASE_IMAGE


#: What only a test machine needs (its CA bundle, its proxy, its package index): never in
#: the image users build.
TEST_ONLY = re.compile(
    r"proxy|PIP_CERT|CA_BUNDLE|SSL_CERT|\.crt\b|\.pem\b|--cert\b|index-url|"
    r"trusted-host|find-links|PIP_NO_INDEX|PIP_INDEX",
    re.IGNORECASE,
)


def settings_for_tests(instructions: list[Instruction]) -> list[Instruction]:
    return [item for item in instructions if TEST_ONLY.search(item.arguments)]


def test_nothing_in_the_dockerfile_is_for_tests(instructions: list[Instruction]) -> None:
    assert settings_for_tests(instructions) == [], "these belong to the tests' stand-in base"


def test_control_the_stand_in_base_has_test_only_settings_that_the_check_finds() -> None:
    """Without this, the check above could match nothing at all."""
    stand_in = parse_dockerfile(STANDIN_DOCKERFILE.read_text(encoding="utf-8"))
    assert settings_for_tests(stand_in), "the stand-in installs from its wheelhouse only"


def test_the_package_is_copied_from_the_repo(instructions: list[Instruction]) -> None:
    for copy in copies(instructions):
        assert not any(flag.startswith("--from") for flag in copy.flags), copy
    target = package_dir(instructions)
    landed = {
        source: copied_to(copy, source) for copy in copies(instructions) for source in copy.sources
    }
    assert landed["ros_isolated_test"] == f"{target}/ros_isolated_test"


def test_every_file_pyproject_needs_to_build_is_copied_beside_it(
    instructions: list[Instruction], pyproject: dict[str, object]
) -> None:
    """setuptools reads the readme at build time: without it ``pip install`` fails."""
    target = package_dir(instructions)
    readme = project(pyproject).get("readme")
    needed = ["pyproject.toml", "ros_isolated_test"]
    if isinstance(readme, str):
        needed.append(readme)
    landed = {
        source: copied_to(copy, source) for copy in copies(instructions) for source in copy.sources
    }
    for source in needed:
        assert landed.get(source) == f"{target}/{source}", (source, landed)


def test_pip_installs_the_copied_package_and_nothing_else(
    instructions: list[Instruction],
) -> None:
    (install,) = pip_installs(instructions)
    arguments = install[2:]
    targets = [word for word in arguments if not word.startswith("-")]
    options = [word for word in arguments if word.startswith("-")]
    assert targets == [package_dir(instructions)], install
    assert not {"-r", "--requirement", "-e", "--editable", "-c", "--constraint"} & set(options)


def test_nothing_from_the_ros_or_dev_extras_is_installed(
    instructions: list[Instruction], pyproject: dict[str, object]
) -> None:
    """ROS comes from the base image; the extras are for this repo's tests and demo only."""
    extras = project(pyproject)["optional-dependencies"]
    assert isinstance(extras, dict)
    assert {"ros", "dev"} <= set(extras)
    forbidden = {requirement_name(item) for group in extras.values() for item in group}
    installed: list[str] = []
    for command in run_commands(instructions):
        if PurePosixPath(command[0]).name in ("apt-get", "apt") and "install" in command:
            after = command[command.index("install") + 1 :]
            installed += [word for word in after if not word.startswith("-")]
    for install in pip_installs(instructions):
        targets = [word for word in install[2:] if not word.startswith("-")]
        assert not any("[" in target for target in targets), install
        installed += targets
    assert installed
    names = [name for name in installed if not name.startswith(("/", "."))]  # not local paths
    assert not [name for name in names if requirement_name(name) in forbidden], installed
    assert not [name for name in names if name.startswith("ros-")], installed


def test_the_entrypoint_sources_ros_then_execs_the_console_script(
    instructions: list[Instruction], pyproject: dict[str, object]
) -> None:
    entrypoint = only(instructions, "ENTRYPOINT").exec_form()
    assert entrypoint == ["/ros_entrypoint.sh", console_script(pyproject)]


def test_the_console_script_is_on_the_images_path(
    instructions: list[Instruction], pyproject: dict[str, object]
) -> None:
    """pip of a venv puts the script in the venv's bin: it must be linked onto PATH."""
    script = console_script(pyproject)
    (install,) = pip_installs(instructions)
    pip = PurePosixPath(install[0])
    if not pip.is_absolute() or pip.parent.name != "bin":
        return  # the system pip installs scripts into /usr/local/bin
    expected_source = str(pip.parent / script)
    linked = [
        command
        for command in run_commands(instructions)
        if command[0] == "ln" and "-s" in "".join(command[1:3]) and expected_source in command
    ]
    assert linked, f"no 'ln -s {expected_source} ...' in a RUN"
    destination = PurePosixPath(linked[0][-1])
    assert destination.name == script
    assert str(destination.parent) in STANDARD_PATH


def test_the_default_command_is_a_valid_cli_invocation(
    instructions: list[Instruction], env: dict[str, str]
) -> None:
    command = only(instructions, "CMD").exec_form()
    assert command, "CMD must be a non-empty JSON array (exec form)"
    result = run_cli(command, env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.strip()


# -- the build context ----------------------------------------------------------------------


def test_every_copy_source_exists_and_is_in_the_build_context(
    instructions: list[Instruction], patterns: list[tuple[bool, list[str]]]
) -> None:
    for copy in copies(instructions):
        for source in copy.sources:
            path = REPO / source
            assert path.exists(), f"COPY source {source} is not in the repo"
            files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
            files = [p for p in files if "__pycache__" not in p.parts]
            assert files, source
            left_out = [
                str(p.relative_to(REPO))
                for p in files
                if is_ignored(p.relative_to(REPO).as_posix(), patterns)
            ]
            assert left_out == [], f".dockerignore leaves out files of COPY {source}"


def test_the_package_data_is_in_the_build_context(patterns: list[tuple[bool, list[str]]]) -> None:
    for path in (
        "ros_isolated_test/py.typed",
        "ros_isolated_test/schemas/junit.xsd",
        "ros_isolated_test/ament/run_test_isolated.py",
        "ros_isolated_test/runner/ament/run_test_isolated.py",
    ):
        assert (REPO / path).is_file(), path
        assert not is_ignored(path, patterns), path


@pytest.mark.parametrize(
    "path",
    [
        ".venv/bin/python",
        ".venv",
        "node_modules/some-package/index.js",
        "tests/unit/cli/test_run.py",
        "tests/conftest.py",
        "build/lib/ros_isolated_test/__init__.py",
        "dist/ros_isolated_test-0.1.0-py3-none-any.whl",
        "ros_isolated_test.egg-info/PKG-INFO",
        "ros_isolated_test/__pycache__/__init__.cpython-311.pyc",
        "ros_isolated_test/runner/__pycache__/cli.cpython-311.pyc",
        ".git/HEAD",
        ".mypy_cache/3.11/cache.db",
        "install/setup.bash",
        "log/latest",
    ],
)
def test_the_dockerignore_keeps_local_and_build_output_out(
    path: str, patterns: list[tuple[bool, list[str]]]
) -> None:
    assert is_ignored(path, patterns)


# -- the docs show how to run the image -----------------------------------------------------


def docker_commands(text: str, verb: str) -> list[list[str]]:
    """Every ``docker VERB ...`` command in the text, continuation lines joined."""
    joined = re.sub(r"\\\n\s*", " ", text)
    found = []
    for line in joined.splitlines():
        start = line.find(f"docker {verb} ")
        if start >= 0:
            with contextlib.suppress(ValueError):  # prose with a stray quote
                found.append(shlex.split(line[start:].split(" #", 1)[0]))
    return found


def image_name() -> str:
    """The tag the Dockerfile says to build with (``docker build -t NAME .``)."""
    for command in docker_commands(DOCKERFILE.read_text(encoding="utf-8"), "build"):
        if "-t" in command:
            return command[command.index("-t") + 1]
    pytest.fail("the Dockerfile's header does not say how to build it (docker build -t NAME .)")


def option_values(command: list[str], *names: str) -> list[str]:
    """Values of ``-x VALUE`` / ``--xx VALUE`` / ``--xx=VALUE`` options of a command."""
    found = []
    for index, word in enumerate(command):
        if word in names and index + 1 < len(command):
            found.append(command[index + 1])
        elif word.startswith(tuple(f"{name}=" for name in names if name.startswith("--"))):
            found.append(word.split("=", 1)[1])
    return found


def volumes(command: list[str]) -> list[tuple[str, str]]:
    """(host path, container path) of every bind mount."""
    mounts = []
    for spec in option_values(command, "-v", "--volume"):
        host, _, rest = spec.partition(":")
        mounts.append((host, rest.split(":", 1)[0]))
    return mounts


@pytest.mark.parametrize("page", ["README", "isolation"])
def test_the_docs_show_docker_run_with_the_shared_lock_dir_and_host_namespaces(page: str) -> None:
    """The line tests/e2e/test_docker_engine.py runs: host network, IPC and PID, one lock dir; on
    the front page's Docker block and in the isolation model's Docker section."""
    text = docs.readme() if page == "README" else docs.page(page)
    image = image_name()
    runs = [command for command in docker_commands(text, "run") if image in command]
    assert runs, f"{page} has no 'docker run ... {image}' line"
    default = str(lock_dir_from_env({}))
    shared = []
    namespaces = dict(zip(HOST_NAMESPACES[::2], HOST_NAMESPACES[1::2], strict=True))
    for command in runs:
        host_network = all(
            option_values(command, name) == [value] for name, value in namespaces.items()
        )
        configured = [
            value.split("=", 1)[1]
            for value in option_values(command, "-e", "--env")
            if value.startswith(f"{LOCK_DIR_ENV}=")
        ]
        lock_dir = configured[-1] if configured else default
        if host_network and any(inside == lock_dir for _, inside in volumes(command)):
            shared.append(command)
    flags = " ".join(HOST_NAMESPACES)
    assert shared, f"{page} has no 'docker run {flags} -v {default}:{default} ... {image}'"
