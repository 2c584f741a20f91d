"""Why a host refuses a test its own namespaces, in the words of the setting behind it, and the fix.

``explain`` turns a failed step into the knob that caused it: the
``user.max_user_namespaces`` limit (0: turned off; else used up), a seccomp filter
(Docker's default profile), Debian's ``kernel.unprivileged_userns_clone``, Ubuntu's
AppArmor restriction, a kernel without them, threads in the process; else the step and
its error as they are. ``problem`` asks this host for real (``probe``, once per
process) and says None where namespaces work. Every setting is made for real, never
pretended: the limit set to 0 in a user namespace of the test's own, a real seccomp
filter, Debian's and Ubuntu's switches as files in a private mount namespace. Each
cause has its control: the same place without the setting gets another wording.
"""

from __future__ import annotations

import errno
import json
import os
from collections.abc import Sequence
from pathlib import Path

from helpers import capabilities
from helpers.namespaces import (
    kernel_switches_prefix,
    seccomp_prefix,
    user_namespace_prefix,
)
from helpers.process_tree import in_child

from ros_isolated_test.process.namespace import NamespaceError
from ros_isolated_test.process.namespace_diagnosis import MAX_USER_NAMESPACES, explain

pytestmark = [capabilities.UNSHARE.mark]

UNSHARE = "create user, network, mount and IPC namespaces (unshare)"
NOT_PERMITTED = "Operation not permitted"
GENERIC_FIX = "allow user namespaces for this user here"

#: ``explain`` where it runs: argv is a JSON list of ``[step, errno]``. Prints
#: ``[cause, fix]`` for each.
EXPLAIN = """
import json, sys
from ros_isolated_test.process.namespace import NamespaceError
from ros_isolated_test.process.namespace_diagnosis import explain
found = [explain(NamespaceError(step, number)) for step, number in json.loads(sys.argv[1])]
print(json.dumps([[problem.cause, problem.fix] for problem in found]))
"""


def explained(cases: Sequence[tuple[str, int]], prefix: Sequence[str]) -> list[list[str]]:
    """``[cause, fix]`` for each ``(step, errno)``, explained in a child run under ``prefix``."""
    found: list[list[str]] = in_child(EXPLAIN, json.dumps(cases), prefix=prefix)
    return found


# --- each cause in its words --------------------------------------------------------


def test_threads_and_xdist_workers_are_named_with_their_fix() -> None:
    threads = explain(NamespaceError("threads", errno.EINVAL))
    assert threads.cause == (
        "this process runs threads, and a process with threads cannot enter a user namespace"
    )
    assert threads.fix == "run pytest without -n (xdist), or use domain isolation"
    xdist = explain(NamespaceError("xdist", errno.EINVAL))
    assert xdist.cause.startswith("pytest-xdist's workers run threads, and a process")
    assert str(xdist) == f"{xdist.cause}; {xdist.fix}"


def test_a_limit_used_up_says_so_with_its_value_and_where() -> None:
    """ENOSPC (or EUSERS) under this host's limit, which is not 0: it was used up."""
    limit = Path(MAX_USER_NAMESPACES).read_text().strip()
    assert limit != "0", "namespaces work here, so the limit is not 0"
    for number in (errno.ENOSPC, errno.EUSERS):
        problem = explain(NamespaceError("unshare", number), here="the container")
        assert problem.cause == (
            f"no user namespace is left on the container: the limit user.max_user_namespaces "
            f"({limit}, here or in an enclosing namespace) is used up "
            f"(cannot {UNSHARE}: {os.strerror(number)})"
        )
        assert problem.fix == "raise it with sysctl -w user.max_user_namespaces=<more> (as root)"


def test_a_limit_of_zero_says_user_namespaces_are_turned_off() -> None:
    (turned_off,) = explained([("unshare", errno.ENOSPC)], user_namespace_prefix(forbid=True))
    assert turned_off == [
        "user namespaces are turned off on this host: user.max_user_namespaces is 0 "
        f"(cannot {UNSHARE}: No space left on device)",
        "allow them with sysctl -w user.max_user_namespaces=15000 (as root)",
    ]
    # The control: the same kind of user namespace, its limit left as it was.
    (control,) = explained([("unshare", errno.ENOSPC)], user_namespace_prefix(forbid=False))
    assert control[0].startswith("no user namespace is left on this host"), control


@capabilities.SECCOMP.mark
def test_a_seccomp_filter_is_named_as_docker_s_default_profile() -> None:
    """Under a real filter (here denying another call: any filter is one) EPERM is its doing."""
    (filtered,) = explained([("unshare", errno.EPERM)], seccomp_prefix("acct"))
    assert filtered == [
        "a seccomp filter forbids unshare(2) here, as Docker's default profile does "
        f"(cannot {UNSHARE}: {NOT_PERMITTED})",
        "run the container with --security-opt seccomp=unconfined (or a profile allowing "
        "unshare), or --cap-add SYS_ADMIN",
    ]
    # The control: this process, under no filter, gets no such blame.
    status = Path("/proc/self/status").read_text()
    assert "Seccomp:\t0" in status, "the control needs a process under no seccomp filter"
    (plain,) = explained([("unshare", errno.EPERM)], ())
    assert "seccomp" not in plain[0] and plain[1] == GENERIC_FIX, plain


@capabilities.MOUNT_NAMESPACE.mark
def test_debians_switch_turned_off_is_named() -> None:
    debian = "unprivileged_userns_clone"
    (off,) = explained([("unshare", errno.EPERM)], kernel_switches_prefix({debian: "0"}))
    assert off == [
        "unprivileged user namespaces are turned off: kernel.unprivileged_userns_clone is 0 "
        f"(cannot {UNSHARE}: {NOT_PERMITTED})",
        "allow them with sysctl -w kernel.unprivileged_userns_clone=1 (as root)",
    ]
    (on,) = explained([("unshare", errno.EPERM)], kernel_switches_prefix({debian: "1"}))
    assert "unprivileged_userns_clone" not in on[0] and on[1] == GENERIC_FIX, on


@capabilities.MOUNT_NAMESPACE.mark
def test_ubuntus_apparmor_restriction_is_named_for_the_steps_it_refuses() -> None:
    """It lets the namespace be made but gives no capabilities there: the mount then fails."""
    apparmor = "apparmor_restrict_unprivileged_userns"
    steps = [("unshare", errno.EPERM), ("mount", errno.EPERM), ("shm", errno.EPERM)]
    steps += [("loopback", errno.EPERM), ("map", errno.EPERM)]
    *refused, mapping = explained(steps, kernel_switches_prefix({apparmor: "1"}))
    for cause, fix in refused:
        assert cause.startswith(
            "AppArmor restricts unprivileged user namespaces "
            "(kernel.apparmor_restrict_unprivileged_userns=1) and gives this program no "
            "capabilities in one (cannot "
        ), cause
        assert fix == (
            "allow this Python in an AppArmor profile with the userns rule, or "
            "sysctl -w kernel.apparmor_restrict_unprivileged_userns=0 (as root)"
        )
    assert "cannot make the test's mounts private: " in refused[1][0]
    assert "AppArmor" not in mapping[0], "writing the ID maps is not a step AppArmor refuses"
    # The control: the restriction lifted, the same steps are not blamed on it.
    lifted = explained(steps, kernel_switches_prefix({apparmor: "0"}))
    assert not any("AppArmor" in cause for cause, _fix in lifted), lifted


def test_a_kernel_without_namespaces_and_any_other_failure() -> None:
    kernel = explain(NamespaceError("unshare", errno.EINVAL))
    assert kernel.cause == (
        f"this kernel has no user or network namespaces (cannot {UNSHARE}: Invalid argument)"
    )
    assert kernel.fix == "use a kernel built with CONFIG_USER_NS and CONFIG_NET_NS"
    other = explain(NamespaceError("map", errno.EPERM))
    assert other.cause == (
        f"cannot map the user's uid and gid into the new user namespace: {NOT_PERMITTED}"
    )
    assert other.fix == GENERIC_FIX
    # No errno at all reads as "not permitted", never as "Success".
    assert explain(NamespaceError("loopback", 0)).cause == (
        f"cannot bring the loopback interface up: {NOT_PERMITTED}"
    )


# --- problem() and probe() against the host -------------------------------------------

#: ``problem`` as a child sees it: argv: whether it runs threads. Prints both answers.
PROBLEM = """
import json, sys, threading
from ros_isolated_test.process.namespace_diagnosis import problem
release = threading.Event()
if sys.argv[1] == "1":
    threading.Thread(target=release.wait).start()
found = [problem(), problem(in_process=True)]
release.set()
print(json.dumps([None if answer is None else str(answer) for answer in found]))
"""


def test_problem_is_none_on_this_host_and_the_cause_where_namespaces_are_turned_off() -> None:
    assert in_child(PROBLEM, 0) == [None, None], "namespaces work here"
    for answer in in_child(PROBLEM, 0, prefix=user_namespace_prefix(forbid=True)):
        assert "user.max_user_namespaces is 0" in answer, answer


def test_a_process_running_threads_is_refused_only_for_work_in_itself() -> None:
    """The pytest plugin enters them in its own process; a runner's child has no threads."""
    for_a_child, in_itself = in_child(PROBLEM, 1)
    assert for_a_child is None
    assert in_itself.startswith("this process runs threads"), in_itself


#: ``probe`` twice in a user namespace of its own, the limit set to 0 in between (as
#: its root). Prints both probes and a fresh try.
PROBED_ONCE = """
import json
from ros_isolated_test.process.namespace import try_in_child
from ros_isolated_test.process.namespace_diagnosis import MAX_USER_NAMESPACES, probe
first = probe()
with open(MAX_USER_NAMESPACES, "w") as limit:
    limit.write("0")
again, fresh = probe(), try_in_child()
print(json.dumps([None if answer is None else answer.step for answer in (first, again, fresh)]))
"""


def test_probe_asks_the_host_once_per_process() -> None:
    first, again, fresh = in_child(PROBED_ONCE, prefix=user_namespace_prefix(forbid=False))
    assert (first, again) == (None, None), "the first answer is kept"
    assert fresh == "unshare", "the host did change: a fresh try is refused"
