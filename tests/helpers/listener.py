"""A TCP server on loopback that counts who connected: proof that nothing fetched a URL.

Every test that checks a parser or runner never touches the network points the URL at
one of these, and has a control that a real fetch of the same URL is seen.
"""

from __future__ import annotations

import contextlib
import socket
import threading


class Listener:
    """A real TCP server on loopback that records every connection made to it.

    It answers nothing and closes at once: a fetch fails, but only after it connected.
    """

    def __init__(self) -> None:
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.bind(("127.0.0.1", 0))
        self._server.listen(64)
        self._server.settimeout(0.05)
        self.port: int = self._server.getsockname()[1]
        self._accepted: list[tuple[str, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                connection, peer = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            self._accepted.append(peer)
            connection.close()

    def connections(self) -> list[tuple[str, int]]:
        """Every connection made so far, those still in the backlog included.

        A connect() has returned only once the kernel queued it here, so after the
        connecting process ended nothing it did can still be on its way: no wait needed.
        """
        self._stop.set()
        self._thread.join(30)
        self._server.setblocking(False)
        with contextlib.suppress(BlockingIOError):
            while True:
                connection, peer = self._server.accept()
                self._accepted.append(peer)
                connection.close()
        return list(self._accepted)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(30)
        self._server.close()
