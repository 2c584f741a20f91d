"""Real headless Chromium for the report page: its DOM after the scripts ran, a screenshot,
and every request it makes counted.

Each run gets a fresh profile and as little background traffic as Chromium allows, host
names resolve to nothing, and every request is sent to :class:`RequestCounter`, a local
proxy that answers none and counts each. So "no request" is measured, not assumed: a
control page that asks for an image and a font shows the counter sees them. Chromium
still makes a few requests of its own for any page, an empty one too, whatever the
switches (its updater, its account check): those hosts are :data:`BROWSER_OWN`, told
apart by exact name (a page fetching a Google font is still counted).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import select
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from lxml import html

REPO = Path(__file__).resolve().parents[2]
#: Where tests leave what CI keeps (screenshots); gitignored. ROS_ISOLATED_TEST_ARTIFACTS moves it.
ARTIFACTS = Path(os.environ.get("ROS_ISOLATED_TEST_ARTIFACTS", REPO / "tests" / "artifacts"))
#: Only stops a hung browser; no verdict depends on it.
HUNG = 120
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--disable-extensions",
    "--disable-default-apps",
    "--no-pings",
    "--disable-domain-reliability",
    "--disable-client-side-phishing-detection",
    "--disable-features=NetworkTimeServiceQuerying,OptimizationHints,MediaRouter",
    # No name resolves (the counting proxy's address is no name): a request that did not
    # go to the proxy fails, it never leaves the machine.
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
)
#: Chromium's own service hosts, asked for an empty page too (see the module's note).
BROWSER_OWN = frozenset(
    {
        "update.googleapis.com",
        "accounts.google.com",
        "clients2.google.com",
        "redirector.gvt1.com",
        "optimizationguide-pa.googleapis.com",
    }
)


def executable() -> str | None:
    """Debian's ``chromium`` (or another Chromium build on PATH), if installed."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found is not None:
            return found
    return None


class RequestCounter:
    """A proxy on loopback that counts the connections (requests) made to it, answering 502."""

    def __init__(self) -> None:
        self.requests: list[str] = []
        self._server = socket.create_server(("127.0.0.1", 0))
        self.port: int = self._server.getsockname()[1]
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while True:
            try:
                client, _ = self._server.accept()
            except OSError:
                return
            with client:
                client.settimeout(5)
                try:
                    head = client.recv(4096).split(b"\r\n", 1)[0]
                    self.requests.append(head.decode("latin-1"))
                    client.sendall(b"HTTP/1.1 502 Bad Gateway\r\nContent-Length: 0\r\n\r\n")
                except OSError:
                    self.requests.append("(a connection that sent nothing)")

    def page_requests(self) -> list[str]:
        """The requests counted, less Chromium's own (:data:`BROWSER_OWN`) and connections
        that closed before naming a target (they reached nothing)."""
        return [line for line in self.requests if host_of(line) not in {"", *BROWSER_OWN}]

    def close(self) -> None:
        self._server.close()


def host_of(request_line: str) -> str:
    """The host a proxy request line asks for: ``CONNECT h:443`` or ``GET http://h/p``."""
    parts = request_line.split()
    if len(parts) < 2:
        return ""
    target = parts[1]
    if parts[0] != "CONNECT":
        target = target.split("://", 1)[-1].split("/", 1)[0]
    return target.rsplit(":", 1)[0] if ":" in target else target


@contextmanager
def browser_flags(counter: RequestCounter | None) -> Iterator[list[str]]:
    """The flags for one run: a fresh profile, requests through ``counter`` when given."""
    with tempfile.TemporaryDirectory(prefix="rit-chromium-") as profile:
        flags = [*FLAGS, f"--user-data-dir={profile}"]
        if counter is not None:
            flags += [
                f"--proxy-server=http://127.0.0.1:{counter.port}",
                "--proxy-bypass-list=<-loopback>",  # even loopback goes to the counter
            ]
        yield flags


def _run(
    page: Path, extra: Sequence[str], counter: RequestCounter | None, fragment: str = ""
) -> str:
    chromium = executable()
    assert chromium is not None, "no chromium: mark the test with capabilities.CHROMIUM"
    with browser_flags(counter) as flags:
        done = subprocess.run(
            [chromium, *flags, *extra, page.resolve().as_uri() + fragment],
            capture_output=True,
            text=True,
            timeout=HUNG,
            check=False,
        )
    assert done.returncode == 0, done.stderr[-4000:]
    return done.stdout


def dump_dom(
    page: Path, counter: RequestCounter | None = None, fragment: str = ""
) -> html.HtmlElement:
    """The page's DOM once loaded and its scripts ran to their end.

    ``fragment`` (``#...``) is added to the page's URL. Driven over Chromium's DevTools
    pipe, by events rather than time: the DOM is taken once the document is complete
    and, for a page whose script marks the end of its drawing (``data-drawn-ms`` on the
    root, as the report page does), once that mark is there. (``--dump-dom`` with a
    virtual-time budget dumped before the script ended on a loaded machine.) Should the
    mark never come, the DOM is taken as it is when :data:`HUNG` runs out, so the test's
    own assertion says what is missing.
    """
    url = page.resolve().as_uri()
    script = page.read_bytes()
    waits_for_mark = any(name in script for name in (b"drawnMs", DRAWN_MARK.encode()))
    with browser_flags(counter) as flags, _DevTools([*flags, url + fragment]) as tools:
        text = tools.outer_html(url, DRAWN_MARK if waits_for_mark else None)
    assert text.strip(), "chromium dumped no DOM"
    return html.fromstring(text)


#: The attribute the report page's script sets on the root once it has drawn everything
#: (``root.dataset.drawnMs``).
DRAWN_MARK = "data-drawn-ms"
#: How often the page is looked at while it loads and draws (in the page's own timer).
_POLL_MS = 20


class _DevTools:
    """Chromium with ``--remote-debugging-pipe``: requests on fd 3, answers on fd 4, each a
    JSON message ended by a NUL byte."""

    def __init__(self, args: Sequence[str]) -> None:
        chromium = executable()
        assert chromium is not None, "no chromium: mark the test with capabilities.CHROMIUM"
        to_child, self._send = os.pipe()
        self._receive, from_child = os.pipe()

        def onto_3_and_4() -> None:  # in the child, before the exec
            os.dup2(to_child, 3)
            os.dup2(from_child, 4)

        self._process = subprocess.Popen(
            [chromium, "--remote-debugging-pipe", *args],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            preexec_fn=onto_3_and_4,  # noqa: PLW1509 (two dup2 calls, nothing else)
            pass_fds=(3, 4),  # kept open after preexec_fn put the pipes there
        )
        os.close(to_child)
        os.close(from_child)
        self._buffer = b""
        self._next_id = 0
        self._deadline = time.monotonic() + HUNG

    def __enter__(self) -> _DevTools:
        return self

    def __exit__(self, *exc: object) -> None:
        with contextlib.suppress(OSError, AssertionError):
            self._call("Browser.close")
        try:
            self._process.wait(timeout=HUNG)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()
        for fd in (self._send, self._receive):
            with contextlib.suppress(OSError):
                os.close(fd)
        if self._process.stderr is not None:
            self._process.stderr.close()

    def _call(self, method: str, session: str | None = None, **params: object) -> dict[str, Any]:
        """Send one command; its answer (events before it are skipped)."""
        self._next_id += 1
        message: dict[str, object] = {"id": self._next_id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        os.write(self._send, json.dumps(message).encode() + b"\0")
        while True:
            answer = self._message()
            if answer.get("id") == self._next_id:
                return answer

    def _message(self) -> dict[str, Any]:
        while b"\0" not in self._buffer:
            left = self._deadline - time.monotonic()
            assert left > 0, "chromium did not answer over its DevTools pipe"
            ready, _, _ = select.select([self._receive], [], [], left)
            if ready:
                chunk = os.read(self._receive, 65536)
                assert chunk, "chromium closed its DevTools pipe"
                self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        parsed: dict[str, Any] = json.loads(raw)
        return parsed

    def outer_html(self, url: str, mark: str | None) -> str:
        """The page's markup once it is ``url``, complete, and (if given) ``mark`` is set."""
        targets = self._call("Target.getTargets")["result"]["targetInfos"]
        (target,) = [info for info in targets if info["type"] == "page"][:1]
        session = self._call("Target.attachToTarget", targetId=target["targetId"], flatten=True)[
            "result"
        ]["sessionId"]
        expression = _WHEN_DRAWN % {
            "url": json.dumps(url),
            "mark": json.dumps(mark),
            "poll": _POLL_MS,
            "budget": int(HUNG * 1000),
        }
        while True:
            # A navigation while it waits (the start page, then ours) ends its context:
            # it is asked again in the page that is there now.
            answer = self._call(
                "Runtime.evaluate",
                session,
                expression=expression,
                awaitPromise=True,
                returnByValue=True,
            )
            result = answer.get("result", {})
            if "exceptionDetails" not in result and "result" in result:
                value = result["result"].get("value")
                if isinstance(value, str):
                    return value
            assert time.monotonic() < self._deadline, f"the page never answered: {answer}"


#: Resolves with the markup once the document is the page's, complete and drawn; after
#: the budget (only a hang stopper) with what is there.
_WHEN_DRAWN = """
new Promise((resolve) => {
  const url = %(url)s, mark = %(mark)s, until = Date.now() + %(budget)d;
  const look = () => {
    const here = location.href.split("#")[0] === url && document.readyState === "complete";
    const drawn = mark === null || document.documentElement.hasAttribute(mark);
    if ((here && drawn) || (here && Date.now() > until)) {
      resolve(document.documentElement.outerHTML);
    } else {
      setTimeout(look, %(poll)d);
    }
  };
  look();
})
"""


def screenshot(
    page: Path,
    png: Path,
    size: tuple[int, int] = (1400, 1500),
    counter: RequestCounter | None = None,
) -> None:
    """A PNG of the page as drawn in a window of ``size``."""
    png.parent.mkdir(parents=True, exist_ok=True)
    width, height = size
    _run(page, [f"--window-size={width},{height}", f"--screenshot={png}"], counter)
    assert png.is_file() and png.stat().st_size > 0, f"chromium drew no {png}"


def with_class(name: str) -> str:
    """An XPath predicate: the element has class ``name`` (lxml has no CSS selectors here)."""
    return f"contains(concat(' ', normalize-space(@class), ' '), ' {name} ')"


#: Attributes through which HTML fetches something, and CSS's ways to.
_FETCHING = ("src", "href", "srcset", "action", "formaction", "poster", "data", "background")
_CSS_FETCH = re.compile(r"""url\(\s*['"]?([^'")\s]+)|@import\s+['"]([^'"]+)""", re.IGNORECASE)


def external_references(page: str) -> list[str]:
    """Every URL in ``page`` that would be fetched from elsewhere: any but a ``#`` anchor.

    Attributes that fetch (``src``, ``href``, ...) and ``url(...)`` / ``@import`` in
    styles; a link to a part of the page itself (``#f1-1``) fetches nothing.
    """
    tree = html.fromstring(page)
    found: list[str] = []
    for element in tree.iter():
        for name in _FETCHING:
            value = element.get(name)
            if value is not None and not value.startswith("#"):
                found.append(value)
        styles = [element.get("style") or ""]
        if element.tag == "style":
            styles.append(element.text or "")
        for style in styles:
            for match in _CSS_FETCH.finditer(style):
                found.append(match.group(1) or match.group(2))
    return found
