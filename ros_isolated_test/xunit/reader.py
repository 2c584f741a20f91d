"""Reading a result file written by arbitrary code: bounded, offline, and never giving up.

A test's result file may be broken or hostile: invalid UTF-8, characters XML forbids
(raw or as references), an entity bomb, a DTD that points at the network, two roots,
a cut-off end, gigabytes of output, a directory instead of a file. Everything is read
as a stream, by stage: the ``sanitiser`` (with ``markup``) makes the bytes safe, the
parser of ``safe_parser`` loads nothing external, and the ``builder`` turns its events into
the small raw model of ``raw``; this module drives them over the file. What cannot be read
is described in ``problems`` and whatever came before it is kept. Memory is bounded by
caps kept beside the stage that applies them, not by the file: markup the parser would
hold whole (an attribute, a tag, a comment, a CDATA section) is bounded before it gets
there, and so is the depth of open elements; texts and names shrink as they add up; every
case is kept up to MAX_CASES, and beyond it every case that did not pass.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

from lxml import etree

from ros_isolated_test.xunit.builder import Builder, Stop
from ros_isolated_test.xunit.raw import ReadResult
from ros_isolated_test.xunit.safe_parser import describe, new_parser
from ros_isolated_test.xunit.sanitiser import Sanitiser

#: Read at most this much of a file; the rest is reported, not parsed.
MAX_READ_BYTES = 256 * 1024 * 1024
CHUNK_BYTES = 1024 * 1024


def _open_regular(path: Path, result: ReadResult) -> BinaryIO | None:
    """The file opened for reading, or None with the reason added to ``result``."""
    try:
        # Raises for a file in a folder this user may list but not enter.
        is_dir = path.is_dir()
    except OSError as error:
        result.problems.append(f"cannot open the result file: {error.strerror}")
        return None
    if is_dir:
        result.problems.append("a directory is where the result file should be")
        return None
    try:
        # Non-blocking: a FIFO planted at the path must not hang the runner.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as error:
        result.problems.append(f"cannot open the result file: {error.strerror}")
        return None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        result.problems.append("something other than a file is where the result file should be")
        return None
    os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


def read(path: Path) -> ReadResult:
    """Read ``path`` as far as it can be read; never raises for what the file contains."""
    result = ReadResult(path=path)
    handle = _open_regular(path, result)
    if handle is None:
        return result
    with handle:
        _parse(handle, result)
    if result.size == 0:
        result.problems[:] = ["the result file is empty"]
    elif result.root_tag is None and not result.problems:
        result.problems.append("no XML element was found in the result file")
    elif result.root_tag is not None and not result.is_xunit:
        result.problems.append(
            f"the root element is <{result.root_tag}>, not <testsuites> or <testsuite>"
        )
    return result


def _parse(handle: BinaryIO, result: ReadResult) -> None:
    """Stream the file through the sanitiser into the parser, stopping at the first damage."""
    builder = Builder(result)
    parser = new_parser(builder)
    sanitiser = Sanitiser(result)
    while True:
        chunk = handle.read(CHUNK_BYTES)
        result.size += len(chunk)
        final = not chunk
        if result.size > MAX_READ_BYTES and not final:
            total = result.size + _remaining(handle)
            result.problems.append(
                f"only the first {MAX_READ_BYTES // (1024 * 1024)} MiB of {total} bytes "
                "were read: the file is too large to be a useful result"
            )
            break
        try:
            data = sanitiser.feed(chunk, final)
            builder.fed += len(data)
            builder.count_expansion = sanitiser.doctype_kept
            parser.feed(data)
            if sanitiser.markup.damage is not None:
                result.problems.append(sanitiser.markup.damage)
                break
            if final:
                parser.close()
        except Stop as stop:
            result.problems.append(str(stop))
            break
        except etree.XMLSyntaxError as error:
            if sanitiser.in_prolog:
                result.problems.append("not XML (no element found in it)")
            elif not (builder.root_closed and "Extra content" in str(error)):
                result.problems.append(
                    describe(
                        error, root_seen=result.root_tag is not None, inside=bool(builder.stack)
                    )
                )
            else:
                result.problems.append(
                    "content after the root element (a second root?) was ignored"
                )
            break
        if final:
            break
    sanitiser.finish()
    builder.finish()


def _remaining(handle: BinaryIO) -> int:
    try:
        return max(os.fstat(handle.fileno()).st_size - handle.tell(), 0)
    except OSError:
        return 0
