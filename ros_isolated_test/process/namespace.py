"""Linux namespaces for one test: a network, a /dev/shm and IPC of its own, as the same user.

A domain ID keeps DDS discovery apart and nothing else: two tests serving on one fixed
port (rosbridge's 9090, a Zenoh router's 7447, a test's own server) still collide, and
shared-memory transports meet in the common /dev/shm even across network namespaces
(measured). So in namespace mode the test runs in new user, network, mount and IPC
namespaces: loopback up with multicast (DDS, Zenoh and plain sockets work inside,
reach no network outside), a private tmpfs on /dev/shm, and a user namespace that maps
the caller's own uid and gid (``getuid()``, file owners and ``$HOME`` unchanged; every
ID the caller may map, each to itself: root's all, its groups with CAP_SETGID). Not a
sandbox: the other mounts and the processes (no PID namespace) stay the host's, so a
file, a Unix socket bound to a path and a signal still reach it.

Done with ``unshare(2)``, ``mount(2)`` and one ``ioctl(SIOCSIFFLAGS)`` through ctypes,
which the reaper has loaded already: no helper program, no second interpreter. The
supervisor forks (``fork_exec``: it is single-threaded), the child unshares and waits
while the runner, still outside, writes its ID maps (only a process in the parent
namespace may map more than its own ID); the child then mounts, brings loopback up and
execs the test, tethered to the runner as in domain mode.

No PID namespace: its first process would be init there, which ignores SIGTERM unless
it handles it, so a timeout's SIGTERM would no longer end a plain test; and the
runner, a child subreaper in its own PID namespace, already finds and ends every
process of the test, however it forked.

This module is the mechanics; why a host refuses them, in the words of the setting
behind the refusal and with its fix, is ``namespace_diagnosis``.
"""

from __future__ import annotations

import errno
import os
import signal
import sys

from ros_isolated_test.process.fork_exec import (
    HELD_BACK,
    Exec,
    fork,
    plan_for,
    read_all,
    reap,
    report,
    threads,
)

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence
    from typing import NoReturn

    from ros_isolated_test.process.fork_exec import Mask, Spawner

CLONE_NEWNS = 0x00020000
CLONE_NEWIPC = 0x08000000
CLONE_NEWUSER = 0x10000000
CLONE_NEWNET = 0x40000000
#: Everything the test gets of its own, in one unshare(2).
FLAGS = CLONE_NEWUSER | CLONE_NEWNET | CLONE_NEWNS | CLONE_NEWIPC
_MS_NOSUID = 0x2
_MS_NODEV = 0x4
_MS_REC = 0x4000
_MS_PRIVATE = 1 << 18
_AF_INET = 2
_SOCK_DGRAM = 2
_SOCK_CLOEXEC = 0o2000000
_SIOCSIFFLAGS = 0x8914
#: What a new network namespace's loopback needs for DDS: up, and multicast (measured).
LOOPBACK_FLAGS = 0x1 | 0x8 | 0x1000  # IFF_UP | IFF_LOOPBACK | IFF_MULTICAST
SHM = "/dev/shm"
#: ``capset(2)``'s header version for 64-bit capability sets.
_CAPABILITY_VERSION_3 = 0x20080522

#: What each step does, for messages: "cannot <this>: <strerror>".
STEPS = {
    "threads": "enter a user namespace from a process that runs threads",
    "xdist": "enter a user namespace from a pytest-xdist worker, which runs threads",
    "unshare": "create user, network, mount and IPC namespaces (unshare)",
    "map": "map the user's uid and gid into the new user namespace",
    "mount": "make the test's mounts private",
    "shm": f"mount a private tmpfs on {SHM}",
    "loopback": "bring the loopback interface up",
    "capabilities": "drop the capabilities the new user namespace gave",
}


class NamespaceError(OSError):
    """A step of entering the namespaces failed; ``step`` names it (see :data:`STEPS`)."""

    def __init__(self, step: str, number: int) -> None:
        super().__init__(number, f"cannot {STEPS.get(step, step)}: {os.strerror(number)}")
        self.step = step


class _Libc:
    """The system calls Python 3.11's os lacks (unshare, mount, ioctl, capset), bound once.

    Bound before any fork: the child only calls them, it loads nothing.
    """

    def __init__(self) -> None:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        self.get_errno = ctypes.get_errno
        self.unshare = libc.unshare
        self.unshare.argtypes = [ctypes.c_int]
        self.mount = libc.mount
        self.mount.argtypes = [ctypes.c_char_p] * 3 + [ctypes.c_ulong, ctypes.c_char_p]
        self.socket = libc.socket
        self.socket.argtypes = [ctypes.c_int] * 3
        self.ioctl = libc.ioctl
        self.ioctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_char_p]
        self.close = libc.close
        self.close.argtypes = [ctypes.c_int]
        self.capset = libc.capset
        self.capset.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
        # struct ifreq: the name in 16 bytes, then the flags (a short) in a 24-byte union.
        flags = LOOPBACK_FLAGS.to_bytes(2, sys.byteorder)
        self.ifreq = ctypes.create_string_buffer(b"lo".ljust(16, b"\0") + flags.ljust(24, b"\0"))
        # capset(2): header {version, pid 0: this process}, then two empty sets of three.
        version = _CAPABILITY_VERSION_3.to_bytes(4, sys.byteorder)
        self.cap_header = ctypes.create_string_buffer(version + bytes(4))
        self.cap_data = ctypes.create_string_buffer(24)

    def failed(self, step: str) -> NamespaceError:
        return NamespaceError(step, self.get_errno() or errno.EPERM)


_LIBC: _Libc | None = None


def _libc() -> _Libc:
    global _LIBC
    if _LIBC is None:
        _LIBC = _Libc()
    return _LIBC


def _inside(lib: _Libc, shm: bool) -> None:
    """In the new namespaces (capabilities there, IDs mapped): private mounts, /dev/shm, lo.

    Propagation private first, so the tmpfs never shows outside (a mount namespace made
    in a new user namespace gets slave propagation anyway; "/" that is no mount point,
    as in a chroot, refuses with EINVAL and is left so).
    """
    if lib.mount(None, b"/", None, _MS_REC | _MS_PRIVATE, None) != 0:
        error = lib.failed("mount")
        if error.errno != errno.EINVAL:
            raise error
    if shm and lib.mount(b"tmpfs", SHM.encode(), b"tmpfs", _MS_NOSUID | _MS_NODEV, b"mode=1777"):
        raise lib.failed("shm")
    fd = lib.socket(_AF_INET, _SOCK_DGRAM | _SOCK_CLOEXEC, 0)
    if fd < 0:
        raise lib.failed("loopback")
    done = lib.ioctl(fd, _SIOCSIFFLAGS, lib.ifreq)
    error = lib.failed("loopback")
    lib.close(fd)
    if done != 0:
        raise error


def _identity(kind: str) -> str:
    """Every range of IDs this process has (``uid_map``/``gid_map``), each mapped to itself."""
    with open(f"/proc/self/{kind}", encoding="ascii") as handle:
        ranges = [line.split() for line in handle if line.strip()]
    return "".join(f"{first} {first} {count}\n" for first, _outside, count in ranges)


def _write(path: str, text: str) -> None:
    # os.open, never open(..., "w"): O_CREAT|O_TRUNC on these files can fail the write.
    fd = os.open(path, os.O_WRONLY | os.O_CLOEXEC)
    try:
        os.write(fd, text.encode("ascii"))
    finally:
        os.close(fd)


def write_maps(pid: int) -> None:
    """Map the caller's IDs into ``pid``'s new user namespace, from outside it.

    Each map holds every ID the caller has, each to itself, where the kernel allows it
    (uids: CAP_SETUID and CAP_SETFCAP over the caller's namespace; gids: CAP_SETGID;
    root holds all three), and setgroups is kept: other users' files stay theirs, root
    stays root to them, supplementary groups read as themselves. Else (any other user;
    a root in a user namespace without those IDs) the one line the kernel allows: the
    caller's own ID, and for gids setgroups denied first, so supplementary groups read
    as the overflow group there (still granting their access: the kernel checks them).
    """
    base = f"/proc/{pid}/"
    for kind, own in (("uid_map", os.geteuid()), ("gid_map", os.getegid())):
        try:
            _write(base + kind, _identity(kind))
        except PermissionError:
            if kind == "gid_map":
                _write(base + "setgroups", "deny")
            _write(base + kind, f"{own} {own} 1")


def _failure(report: bytes) -> NamespaceError:
    """What the child reported back, as the error it describes."""
    words = report.split()
    try:
        return NamespaceError(words[0].decode("ascii"), int(words[1]))
    except (IndexError, ValueError, UnicodeDecodeError):
        return NamespaceError("unshare", errno.EIO)


def _child(lib: _Libc, report_w: int, go_r: int, shm: bool, plan: Exec | None) -> NoReturn:
    """The forked child: unshare, wait for the maps, set up, exec (or, probing, exit 0)."""
    try:
        if lib.unshare(FLAGS) != 0:
            raise lib.failed("unshare")
        os.write(report_w, b"U")
        if os.read(go_r, 1) != b"G":
            os._exit(127)  # the runner could not map us, and says so itself
        _inside(lib, shm)
        if plan is None:
            os._exit(0)
        plan.run()
    except BaseException as error:  # never back into the runner's code
        report(report_w, error)
    os._exit(127)


def _fork(lib: _Libc, shm: bool, plan: Exec | None) -> tuple[int, int, int]:
    """Fork the child, :data:`HELD_BACK` blocked in it; (pid, report_r, go_w)."""
    report_r, report_w = os.pipe()
    go_r, go_w = os.pipe()

    def child(mask: Mask) -> NoReturn:  # pragma: no cover (reports through the pipe)
        if plan is not None:
            plan.mask = mask
        os.close(report_r)
        os.close(go_w)
        _child(lib, report_w, go_r, shm, plan)

    try:
        pid = fork(child)
    except BaseException:
        for fd in (report_r, report_w, go_r, go_w):
            os.close(fd)
        raise
    os.close(report_w)
    os.close(go_r)
    return pid, report_r, go_w


def _hand_over(pid: int, report_r: int, go_w: int) -> bytes:
    """Map the child's IDs once it has unshared; what it reported after (b"": no failure)."""
    try:
        first = os.read(report_r, 1)
        if first != b"U":
            os.close(go_w)
            go_w = -1
            return first + read_all(report_r) if first else b""
        try:
            write_maps(pid)
        except OSError as error:
            os.close(go_w)
            go_w = -1
            read_all(report_r)
            return f"map {error.errno or errno.EPERM}\n".encode("ascii")
        os.write(go_w, b"G")
        return read_all(report_r)
    finally:
        if go_w >= 0:
            os.close(go_w)
        os.close(report_r)


def spawn(
    name: str,
    candidates: Sequence[str],
    argv: Sequence[str],
    env: Mapping[str, str],
    output_fd: int,
    defaults: Iterable[int],
) -> int:
    """Start the test in namespaces of its own: the ``fork_exec.Spawner`` of namespace mode.

    Raises :class:`NamespaceError` when a step of the set-up fails.
    """
    lib = _libc()
    plan = plan_for(candidates, argv, env, output_fd, defaults)
    pid, report_r, go_w = _fork(lib, os.path.isdir(SHM), plan)
    said = _hand_over(pid, report_r, go_w)
    if not said:
        return pid
    reap(pid)
    error = _failure(said)
    if error.step == "exec":
        raise OSError(error.errno, os.strerror(error.errno or errno.EIO), name)
    raise error


def try_in_child() -> NamespaceError | None:
    """Enter the namespaces for real in a forked child that then exits: None, or the failed step.

    The child makes them all, mounts and brings loopback up, as :func:`spawn`'s does
    before its exec; ``namespace_diagnosis.probe`` calls this once per process.
    """
    try:
        lib = _libc()
        pid, report_r, go_w = _fork(lib, os.path.isdir(SHM), None)
    except OSError as error:
        return NamespaceError("unshare", error.errno or errno.EPERM)
    said = _hand_over(pid, report_r, go_w)
    status = reap(pid)
    if said:
        return _failure(said)
    if os.WIFEXITED(status) and os.WEXITSTATUS(status) != 0:
        return NamespaceError("unshare", errno.EPERM)
    return None


def _status(field: str) -> str | None:
    """A field of /proc/self/status (``CapEff``); None where /proc cannot say."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as handle:
            for line in handle:
                if line.startswith(f"{field}:"):
                    return line.split()[1]
    except (OSError, IndexError):
        pass
    return None


def enter_here() -> None:
    """Put this very process (the pytest plugin's session) into namespaces of its own.

    A helper forked first stays outside and writes our ID maps, as the runner does for
    its child. A user who is not root gives back the capabilities the new user
    namespace gave it, as an exec would: the tests run as they would have. Raises
    :class:`NamespaceError`; nothing is entered when the unshare itself fails.
    """
    if threads() > 1:
        raise NamespaceError("threads", errno.EINVAL)
    lib = _libc()
    me = os.getpid()
    ready_r, ready_w = os.pipe()
    done_r, done_w = os.pipe()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_BACK)
    try:
        helper = os.fork()
    finally:
        if os.getpid() == me:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    if helper == 0:  # pragma: no cover (a child: reports through the pipe)
        try:
            os.close(ready_w)
            os.close(done_r)
            if os.read(ready_r, 1) == b"U":
                try:
                    write_maps(me)
                    os.write(done_w, b"M")
                except OSError as error:
                    os.write(done_w, f"map {error.errno or errno.EPERM}\n".encode("ascii"))
        finally:
            os._exit(0)
    os.close(ready_r)
    os.close(done_w)
    try:
        if lib.unshare(FLAGS) != 0:
            raise lib.failed("unshare")
        os.write(ready_w, b"U")
        os.close(ready_w)
        ready_w = -1
        answer = read_all(done_r)
        if answer != b"M":
            raise _failure(answer)
        _inside(lib, os.path.isdir(SHM))
        if os.geteuid() != 0 and lib.capset(lib.cap_header, lib.cap_data) != 0:
            raise lib.failed("capabilities")
    finally:
        if ready_w >= 0:
            os.close(ready_w)
        os.close(done_r)
        reap(helper)


if TYPE_CHECKING:
    _SPAWN: Spawner = spawn  # checked against the one contract


#: CAP_SETGID's bit in a capability set: what maps supplementary groups (:func:`write_maps`).
_CAP_SETGID = 6


def describe_user() -> str:
    """Who the test is in its user namespace: the caller's uid and gid, and its groups.

    Supplementary groups read as the overflow group there unless this process may map
    them (CAP_SETGID, as root holds): said, as ``getgroups()`` inside differs.
    """
    said = f"uid {os.geteuid()}, gid {os.getegid()}"
    groups = sorted(set(os.getgroups()) - {os.getegid()})
    held = _status("CapEff")
    if not groups or (held is not None and int(held, 16) >> _CAP_SETGID & 1):
        return said
    try:
        with open("/proc/sys/kernel/overflowgid", encoding="ascii") as handle:
            overflow = handle.read().strip()
    except OSError:
        overflow = "65534"  # the kernel's default
    listed = ", ".join(map(str, groups))
    return f"{said} (supplementary groups {listed} read as {overflow} there, granting as before)"


__all__ = [
    "FLAGS",
    "LOOPBACK_FLAGS",
    "NamespaceError",
    "describe_user",
    "enter_here",
    "spawn",
    "threads",
    "try_in_child",
    "write_maps",
]
