"""Why a host refuses a test its own namespaces, in the words of the setting behind it.

Apart from the mechanics (``namespace``) because a reader who meets a refusal wants the
knobs that cause it (a sysctl, a seccomp filter, Debian's switch, Ubuntu's AppArmor
restriction) and their fixes, not the forks and pipes of entering; the runner's policy
needs only this part, to decide ``auto`` and to word a refusal.
"""

from __future__ import annotations

import errno
import os

from ros_isolated_test.process.namespace import STEPS, NamespaceError, threads, try_in_child

#: A sysctl read to explain a refusal, and the file holding it.
MAX_USER_NAMESPACES = "/proc/sys/user/max_user_namespaces"
_DEBIAN_SWITCH = "/proc/sys/kernel/unprivileged_userns_clone"
_APPARMOR_SWITCH = "/proc/sys/kernel/apparmor_restrict_unprivileged_userns"


class Problem:
    """Why namespaces cannot be had here: the cause and the fix, each a short clause."""

    __slots__ = ("cause", "fix")

    def __init__(self, cause: str, fix: str) -> None:
        self.cause = cause
        self.fix = fix

    def __str__(self) -> str:
        return f"{self.cause}; {self.fix}"


_PROBED: list[NamespaceError | None] = []


def probe() -> NamespaceError | None:
    """Whether a child may enter the namespaces here: None, or the step that failed.

    Done for real (a forked child makes them all, mounts, brings loopback up, exits),
    once per process: a sysctl, a seccomp filter or AppArmor each refuse a different step.
    """
    if not _PROBED:
        _PROBED.append(try_in_child())
    return _PROBED[0]


def _read_text(path: str) -> str | None:
    try:
        with open(path, encoding="ascii", errors="replace") as handle:
            return handle.read().strip()
    except OSError:
        return None


def _seccomp_filtered() -> bool:
    """Whether a seccomp filter is on this process (Docker's default profile is one)."""
    status = _read_text("/proc/self/status") or ""
    return any(line.split() == ["Seccomp:", "2"] for line in status.splitlines())


def explain(error: NamespaceError, here: str = "this host") -> Problem:
    """The cause of ``error`` in the words of the setting behind it, and how to allow it.

    Looks at the knobs that forbid user namespaces: ``user.max_user_namespaces`` (ENOSPC
    when 0 or used up), a seccomp filter (Docker's default profile), Debian's
    ``kernel.unprivileged_userns_clone`` and Ubuntu's AppArmor restriction, which lets
    the namespace be made but gives no capabilities in it (the mount then fails).
    """
    step, number = error.step, error.errno or errno.EPERM
    said = f"{STEPS.get(step, step)}: {os.strerror(number)}"
    if step in ("threads", "xdist"):
        who = "pytest-xdist's workers run" if step == "xdist" else "this process runs"
        return Problem(
            f"{who} threads, and a process with threads cannot enter a user namespace",
            "run pytest without -n (xdist), or use domain isolation",
        )
    if step == "unshare" and number in (errno.ENOSPC, errno.EUSERS):
        limit = _read_text(MAX_USER_NAMESPACES)
        if limit == "0":
            return Problem(
                f"user namespaces are turned off on {here}: user.max_user_namespaces is 0 "
                f"(cannot {said})",
                "allow them with sysctl -w user.max_user_namespaces=15000 (as root)",
            )
        return Problem(
            f"no user namespace is left on {here}: the limit user.max_user_namespaces "
            f"({limit or '?'}, here or in an enclosing namespace) is used up (cannot {said})",
            "raise it with sysctl -w user.max_user_namespaces=<more> (as root)",
        )
    if step == "unshare" and number in (errno.EPERM, errno.EACCES):
        if _seccomp_filtered():
            return Problem(
                f"a seccomp filter forbids unshare(2) here, as Docker's default profile does "
                f"(cannot {said})",
                "run the container with --security-opt seccomp=unconfined (or a profile "
                "allowing unshare), or --cap-add SYS_ADMIN",
            )
        if _read_text(_DEBIAN_SWITCH) == "0":
            return Problem(
                f"unprivileged user namespaces are turned off: "
                f"kernel.unprivileged_userns_clone is 0 (cannot {said})",
                "allow them with sysctl -w kernel.unprivileged_userns_clone=1 (as root)",
            )
    if step in ("unshare", "mount", "shm", "loopback") and _read_text(_APPARMOR_SWITCH) == "1":
        return Problem(
            f"AppArmor restricts unprivileged user namespaces "
            f"(kernel.apparmor_restrict_unprivileged_userns=1) and gives this program no "
            f"capabilities in one (cannot {said})",
            "allow this Python in an AppArmor profile with the userns rule, or "
            "sysctl -w kernel.apparmor_restrict_unprivileged_userns=0 (as root)",
        )
    if step == "unshare" and number == errno.EINVAL:
        return Problem(
            f"this kernel has no user or network namespaces (cannot {said})",
            "use a kernel built with CONFIG_USER_NS and CONFIG_NET_NS",
        )
    return Problem(f"cannot {said}", "allow user namespaces for this user here")


def problem(in_process: bool = False) -> Problem | None:
    """Why namespaces cannot be had for a test here, or None when they can.

    ``in_process``: the work runs in this very process (the pytest plugin), which must
    then have no threads too.
    """
    if in_process and threads() > 1:
        return explain(NamespaceError("threads", errno.EINVAL))
    found = probe()
    return None if found is None else explain(found)


__all__ = [
    "MAX_USER_NAMESPACES",
    "Problem",
    "explain",
    "probe",
    "problem",
]
