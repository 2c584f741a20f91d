"""What a test sees of its namespaces, and hosts that refuse them, made for real.

``LOOK`` is a test command that reports its network, /dev/shm, user and domain as one
``SEEN`` line (:func:`seen`); :func:`private_shm_name` names the file it writes into
/dev/shm, removed from the host's if it got there. Refusals are made, never pretended:
:func:`user_namespace_prefix` runs a command in a user namespace of its own where
``user.max_user_namespaces`` can be 0 (the host untouched), :func:`seccomp_prefix` under
a real seccomp filter failing one system call with EPERM (as Docker's default profile
fails unshare), :func:`kernel_switches_prefix` with Debian's or Ubuntu's sysctl switches
set in a private mount namespace.
"""

from __future__ import annotations

import contextlib
import json
import shlex
import sys
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

ISOLATION = "ROS_ISOLATED_TEST_ISOLATION"
#: What the runner's first line says in namespace mode.
NAMESPACES = "in namespaces of its own"

#: What the test sees of its namespaces: ``SHM_FILE``. Prints a JSON line ``SEEN {...}``.
LOOK = r"""
import json, os, pathlib, sys
shm = pathlib.Path("/dev/shm") / sys.argv[1]
shm.write_text("from the test")
interfaces = [line.split(":")[0].strip() for line in open("/proc/net/dev").readlines()[2:]]
print("SEEN " + json.dumps({
    "uid": os.getuid(), "gid": os.getgid(), "home": os.environ.get("HOME"),
    "interfaces": interfaces, "shm": sorted(os.listdir("/dev/shm")),
    "net": os.readlink("/proc/self/ns/net"), "domain": os.environ.get("ROS_DOMAIN_ID"),
}), flush=True)
"""


def seen(output: str) -> dict[str, Any]:
    """The one ``SEEN`` line the LOOK command printed."""
    lines = [line for line in output.splitlines() if line.startswith("SEEN ")]
    assert len(lines) == 1, output
    found: dict[str, Any] = json.loads(lines[0][len("SEEN ") :])
    return found


@contextlib.contextmanager
def private_shm_name() -> Iterator[str]:
    """A file name the test writes into its /dev/shm; removed from the host's if it got there."""
    name = f"rit-ns-{uuid.uuid4().hex}"
    try:
        yield name
    finally:
        (Path("/dev/shm") / name).unlink(missing_ok=True)


def user_namespace_prefix(forbid: bool) -> list[str]:
    """Run what follows inside a user namespace of its own (the host untouched).

    With ``forbid``, ``user.max_user_namespaces`` is 0 there first: every user namespace
    the command asks for fails with ENOSPC, as on a host where they are turned off.
    """
    limit = "echo 0 > /proc/sys/user/max_user_namespaces && " if forbid else ""
    script = f'{limit}exec "$@"'
    return ["unshare", "--user", "--map-root-user", "sh", "-c", script, "sh"]


#: Runs ``COMMAND...`` under a real seccomp filter (libseccomp, as Docker's default profile
#: is one) that fails SYSCALL with EPERM: ``SYSCALL COMMAND...``.
SECCOMP_EXEC = r"""
import ctypes, errno, os, sys
lib = ctypes.CDLL("libseccomp.so.2")
lib.seccomp_init.restype = ctypes.c_void_p
lib.seccomp_init.argtypes = [ctypes.c_uint32]
lib.seccomp_syscall_resolve_name.argtypes = [ctypes.c_char_p]
lib.seccomp_rule_add.argtypes = [ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int, ctypes.c_uint]
lib.seccomp_load.argtypes = [ctypes.c_void_p]
allow, fail = 0x7FFF0000, 0x00050000 | errno.EPERM  # SCMP_ACT_ALLOW, SCMP_ACT_ERRNO(EPERM)
context = lib.seccomp_init(allow)
number = lib.seccomp_syscall_resolve_name(sys.argv[1].encode())
if number < 0 or lib.seccomp_rule_add(context, fail, number, 0) or lib.seccomp_load(context):
    sys.exit(f"cannot install the seccomp filter for {sys.argv[1]}")
os.execv(sys.argv[2], sys.argv[2:])
"""


def seccomp_prefix(denied: str) -> list[str]:
    """Run what follows (a program's full path first) with system call ``denied`` failing."""
    return [sys.executable, "-c", SECCOMP_EXEC, denied]


#: Where the kernel keeps the sysctls that Debian's and Ubuntu's kernels add.
KERNEL_SYSCTLS = "/proc/sys/kernel"


def kernel_switches_prefix(switches: Mapping[str, str]) -> list[str]:
    """Run what follows where ``/proc/sys/kernel/<name>`` reads each value of ``switches``.

    A tmpfs over /proc/sys/kernel in a private mount namespace (root, a mount namespace),
    holding only those files: how a Debian kernel (``unprivileged_userns_clone``) or an
    Ubuntu one (``apparmor_restrict_unprivileged_userns``) shows its setting, on any host.
    """
    writes = "".join(
        f"echo {shlex.quote(value)} > {KERNEL_SYSCTLS}/{name} && "
        for name, value in switches.items()
    )
    script = f'mount -t tmpfs tmpfs {KERNEL_SYSCTLS} && {writes}exec "$@"'
    return ["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh"]
