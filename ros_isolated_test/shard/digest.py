"""SHA-256 without loading OpenSSL: the one stable hash of the shard package.

Every machine of a split must draw the same share for a test and the same fingerprint
for a durations file, whatever its Python: so never ``hash()`` (salted per process), and
a function whose output a standard fixes. ``hashlib`` gives the same digest, but
importing it loads OpenSSL (about 8 ms here), which every ctest test's runner would pay;
the interpreter's own SHA-256 module (``_sha2`` from Python 3.12, ``_sha256`` before)
loads in a tenth of a millisecond. A build without it (some FIPS builds) falls back to
``hashlib``: the digest is the same, only slower to reach.
"""

from __future__ import annotations

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Callable
    from hashlib import _Hash

_constructor: Callable[[bytes], _Hash] | None = None


def _cheapest() -> Callable[[bytes], _Hash]:
    """The cheapest SHA-256 constructor this interpreter has (``_sha2``: Python 3.12+)."""
    for name in ("_sha2", "_sha256"):
        try:
            module = __import__(name)
        except ImportError:
            continue
        found: Callable[[bytes], _Hash] = module.sha256
        return found
    from hashlib import sha256

    return sha256


def sha256(data: bytes) -> bytes:
    """The SHA-256 digest of ``data`` (32 bytes), as ``hashlib.sha256(data).digest()``."""
    global _constructor
    if _constructor is None:
        _constructor = _cheapest()
    return _constructor(data).digest()
