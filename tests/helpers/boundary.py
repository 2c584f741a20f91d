"""What crosses the namespace boundary: the host's side of each channel, and a probe to run.

:class:`HostSide` opens, in the test's own process (the host), one end of every channel a
test might use to reach outside itself: a TCP listener and a UDP socket on 127.0.0.1, a
multicast group joined on loopback, an abstract Unix socket and one bound to a path, a
file in /dev/shm and one elsewhere, a System V shared-memory segment and a POSIX
message queue. :data:`PROBE` is the test: given the host side's ``spec`` it tries each
(and looks at /proc) and prints one ``BOUNDARY {json}`` line; :meth:`HostSide.heard`
says afterwards which of its datagrams reached the host, in order: a sentinel the host
sends itself after the run comes after anything the test sent.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import json
import os
import random
import shutil
import socket
import tempfile
import uuid
from pathlib import Path
from types import TracebackType
from typing import Any

#: The System V calls' flags (sys/ipc.h) and POSIX message queues' (fcntl.h).
IPC_CREAT, IPC_EXCL, IPC_RMID = 0o1000, 0o2000, 0
O_RDONLY, O_CREAT = 0, 0o100
SENTINEL = b"sentinel"

#: The test: ``SPEC_JSON``. Tries every channel of the host side, prints ``BOUNDARY {...}``.
PROBE = r"""
import ctypes, ctypes.util, json, os, socket, sys
spec = json.loads(sys.argv[1])
libc = ctypes.CDLL(None, use_errno=True)
mq = libc if hasattr(libc, "mq_open") else ctypes.CDLL(ctypes.util.find_library("rt"))
parent = os.getppid()
found = {}

def connects(family, address):
    with socket.socket(family, socket.SOCK_STREAM) as client:
        try:
            client.connect(address)
        except OSError:
            return False
        return True

def reads(path):
    try:
        with open(path) as handle:
            return handle.read()
    except OSError as error:
        return type(error).__name__

found["tcp"] = connects(socket.AF_INET, ("127.0.0.1", spec["tcp_port"]))
with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
    sender.sendto(spec["token"].encode(), ("127.0.0.1", spec["udp_port"]))
    sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    sender.sendto(spec["token"].encode(), (spec["group"], spec["group_port"]))
with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as own:  # a group of its own
    own.bind(("", 0))
    joined = socket.inet_aton(spec["group"]) + socket.inet_aton("127.0.0.1")
    own.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, joined)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
        sender.sendto(b"own", (spec["group"], own.getsockname()[1]))
    own.settimeout(60)  # only stops a hang
    found["own_multicast"] = own.recv(16) == b"own"
found["abstract_unix"] = connects(socket.AF_UNIX, "\0" + spec["abstract"])
found["path_unix"] = connects(socket.AF_UNIX, spec["unix_path"])
found["file"] = reads(spec["file"])
found["shm_file"] = reads(os.path.join("/dev/shm", spec["shm_name"]))
with open(os.path.join("/dev/shm", spec["shm_name"] + "-test"), "w") as handle:
    handle.write("from the test")
found["sysv_shm"] = libc.shmget(spec["sysv_key"], 0, 0) >= 0
found["posix_mq"] = mq.mq_open(spec["mq_name"].encode(), 0) >= 0
port = ":%04X " % spec["tcp_port"]
found["own_net_tcp"] = port in reads("/proc/self/net/tcp")
found["parent_net_tcp"] = port in reads(f"/proc/{parent}/net/tcp")
found["host_process"] = os.path.isdir(f"/proc/{spec['host_pid']}")
try:
    os.kill(spec["host_pid"], 0)
    found["signal_host"] = True
except OSError:
    found["signal_host"] = False
try:
    found["parent_root_shm"] = spec["shm_name"] in os.listdir(f"/proc/{parent}/root/dev/shm")
except OSError:
    found["parent_root_shm"] = False
print("BOUNDARY " + json.dumps(found), flush=True)
"""


def reported(output: str) -> dict[str, Any]:
    """The one ``BOUNDARY`` line the probe printed."""
    lines = [line for line in output.splitlines() if line.startswith("BOUNDARY ")]
    assert len(lines) == 1, output
    found: dict[str, Any] = json.loads(lines[0][len("BOUNDARY ") :])
    return found


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None, use_errno=True)


def _mq() -> ctypes.CDLL:
    libc = _libc()
    return libc if hasattr(libc, "mq_open") else ctypes.CDLL(ctypes.util.find_library("rt"))


class HostSide:
    """The host's end of every channel, open while in the ``with`` block; see :data:`PROBE`."""

    def __init__(self) -> None:
        tag = uuid.uuid4().hex[:12]
        self.token = f"rit-boundary-{tag}"
        self._folder = Path(tempfile.mkdtemp(prefix="rit-b-"))
        self._sockets: list[socket.socket] = []
        self.tcp = self._open(socket.AF_INET, socket.SOCK_STREAM, ("127.0.0.1", 0))
        self.udp = self._open(socket.AF_INET, socket.SOCK_DGRAM, ("127.0.0.1", 0))
        self.group = f"239.255.{random.randrange(1, 255)}.{random.randrange(1, 255)}"
        self.multicast = self._open(socket.AF_INET, socket.SOCK_DGRAM, ("", 0))
        membership = socket.inet_aton(self.group) + socket.inet_aton("127.0.0.1")
        self.multicast.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        self.abstract = self._open(socket.AF_UNIX, socket.SOCK_STREAM, "\0" + self.token)
        self.unix_path = str(self._folder / "sock")
        self._open(socket.AF_UNIX, socket.SOCK_STREAM, self.unix_path)
        self.file = self._folder / "file"
        self.file.write_text("the host's file")
        self.shm_file = Path("/dev/shm") / self.token
        self.shm_file.write_text("the host's")
        self.sysv_key = random.randrange(1 << 20, 1 << 30)
        self._sysv_id = _libc().shmget(self.sysv_key, 4096, IPC_CREAT | IPC_EXCL | 0o600)
        assert self._sysv_id >= 0, os.strerror(ctypes.get_errno())
        self.mq_name = f"/{self.token}"
        mq = _mq()
        self._mq = mq.mq_open(self.mq_name.encode(), O_RDONLY | O_CREAT, 0o600, None)
        assert self._mq >= 0, os.strerror(ctypes.get_errno())

    def _open(self, family: int, kind: int, address: tuple[str, int] | str) -> socket.socket:
        opened = socket.socket(family, kind)
        self._sockets.append(opened)
        opened.bind(address)
        if kind == socket.SOCK_STREAM:
            opened.listen(8)
        return opened

    @property
    def spec(self) -> str:
        """What the probe needs to find each channel, as its one argument."""
        return json.dumps(
            {
                "token": self.token,
                "tcp_port": self.tcp.getsockname()[1],
                "udp_port": self.udp.getsockname()[1],
                "group": self.group,
                "group_port": self.multicast.getsockname()[1],
                "abstract": self.token,
                "unix_path": self.unix_path,
                "file": str(self.file),
                "shm_name": self.token,
                "sysv_key": self.sysv_key,
                "mq_name": self.mq_name,
                "host_pid": os.getpid(),
            }
        )

    def heard(self) -> dict[str, bool]:
        """Whether the test's datagram reached the host's UDP socket and multicast group.

        The host sends each a sentinel now, after the run: a datagram the test sent
        would have been queued before it, so reading up to the sentinel is enough.
        """
        heard = {}
        for name, receiver, target in (
            ("udp", self.udp, self.udp.getsockname()),
            ("multicast", self.multicast, (self.group, self.multicast.getsockname()[1])),
        ):
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
                interface = socket.inet_aton("127.0.0.1")
                sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, interface)
                sender.sendto(SENTINEL, target)
            receiver.settimeout(60)  # only stops a hang: the sentinel is on its way
            data: list[bytes] = []
            while (datagram := receiver.recv(256)) != SENTINEL:
                data.append(datagram)
            heard[name] = self.token.encode() in data
        return heard

    def test_wrote_into_the_hosts_shm(self) -> bool:
        """Whether the file the test wrote into its /dev/shm is in the host's."""
        return (Path("/dev/shm") / f"{self.token}-test").exists()

    def __enter__(self) -> HostSide:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        for opened in self._sockets:
            opened.close()
        shutil.rmtree(self._folder, ignore_errors=True)
        for name in (self.token, f"{self.token}-test"):
            (Path("/dev/shm") / name).unlink(missing_ok=True)
        _libc().shmctl(self._sysv_id, IPC_RMID, None)
        mq = _mq()
        mq.mq_close(self._mq)
        mq.mq_unlink(self.mq_name.encode())
