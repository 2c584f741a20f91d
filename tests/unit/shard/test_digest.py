"""``shard.digest``: SHA-256 as the standard defines it, from the cheapest module at hand."""

from __future__ import annotations

import hashlib
import subprocess
import sys

from helpers.commands import REPO

from ros_isolated_test.shard.digest import sha256


def test_it_is_sha256() -> None:
    # The standard's own test vector (FIPS 180-2, "abc"), and hashlib's word on others.
    assert sha256(b"abc").hex() == (
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    )
    for data in (b"", b"pkg/test", "é/\udcff".encode("utf-8", "surrogatepass"), bytes(range(256))):
        assert sha256(data) == hashlib.sha256(data).digest()


def test_it_loads_no_openssl() -> None:
    """What it is for: a runner that hashes an identity does not pay for hashlib."""
    code = (
        "import sys\n"
        "from ros_isolated_test.shard.digest import sha256\n"
        "sha256(b'x')\n"
        "print(sorted(name for name in ('hashlib', '_hashlib') if name in sys.modules))\n"
    )
    found = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
    )
    assert found.stdout.strip() == "[]"
    # Control: hashlib itself loads OpenSSL's module here, which the test would have seen.
    control = code.replace("from ros_isolated_test.shard.digest import sha256", "import hashlib")
    control = control.replace("sha256(b'x')", "hashlib.sha256(b'x')")
    seen = subprocess.run(
        [sys.executable, "-c", control], capture_output=True, text=True, check=True, cwd=REPO
    )
    assert "'_hashlib'" in seen.stdout
