"""A busy host: 3000 idle processes alive, each with a realistic environment.

A developer's machine or a CI host runs browsers, language servers, shells, containers:
thousands of processes that do nothing while tests run. A coordinator that reads every
process's environment (to find squatters on a domain ID) pays for each of them, on
every reservation. This scene puts them there so the benchmarks can measure that.

One helper process spawns the idle processes: ``cat`` with its stdin on a pipe whose
only write end the helper holds, each exec'd with ~40 variables (a few KB) as a login
shell with a sourced ROS setup has, and no ``ROS_DOMAIN_ID`` (they squat on nothing).
The helper waits on its own stdin, a pipe from the benchmark. However the benchmark
ends (return, exception, Ctrl-C, even SIGKILL), that pipe closes, the helper closes the
write end, and every ``cat`` reads EOF and exits: the scene cannot outlive the run.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from common import progress

IDLE_PROCESSES = 3000
QUIET = "quiet"
BUSY = "busy"
#: Marks the scene's processes, so the benchmark can count them in /proc.
MARK = "ROS_ISOLATED_TEST_BENCH_IDLE"

_HELPER = r"""
import os, sys
count, cat, env_file = int(sys.argv[1]), sys.argv[2], sys.argv[3]
with open(env_file, "rb") as handle:
    env = dict(item.split(b"=", 1) for item in handle.read().split(b"\0") if item)
read_end, write_end = os.pipe()  # both close-on-exec; the dup2 onto stdin is not
pids = [
    os.posix_spawn(cat, [cat], env, file_actions=[(os.POSIX_SPAWN_DUP2, read_end, 0)])
    for _ in range(count)
]
os.close(read_end)
print("ready", flush=True)
sys.stdin.buffer.read()  # until the benchmark closes the pipe, or dies
os.close(write_end)  # every cat reads EOF and exits
for pid in pids:
    os.waitpid(pid, 0)
"""


def idle_environment() -> dict[str, str]:
    """~40 variables, a few KB: a login shell on a ROS developer's machine, no domain ID."""
    extensions = (
        "tar tgz arc arj taz lha lz4 lzh lzma tlz txz tzo t7z zip z dz gz lrz lz lzo xz "
        "zst tzst bz2 bz tbz tbz2 tz deb rpm jar war ear sar rar alz ace zoo cpio 7z rz "
        "cab wim swm dwm esd jpg jpeg mjpg mjpeg gif bmp pbm pgm ppm tga xbm xpm tif "
        "tiff png svg svgz mng pcx mov mpg mpeg m2v mkv webm webp ogm mp4 m4v mp4v vob "
        "qt nuv wmv asf rm rmvb flc avi fli flv gl dl xcf xwd yuv cgm emf ogv ogx aac "
        "au flac m4a mid midi mka mp3 mpc ogg ra wav oga opus spx xspf"
    )
    colors = ":".join(f"*.{ext}=01;{31 + n % 7}" for n, ext in enumerate(extensions.split(" ")))
    ros = "/opt/ros/jazzy"
    env = {
        "HOME": "/home/developer",
        "USER": "developer",
        "LOGNAME": "developer",
        "SHELL": "/bin/bash",
        "SHLVL": "2",
        "PWD": "/home/developer/ros2_ws",
        "OLDPWD": "/home/developer",
        "LANG": "en_US.UTF-8",
        "LANGUAGE": "en_US:en",
        "LC_TIME": "en_GB.UTF-8",
        "TERM": "xterm-256color",
        "COLORTERM": "truecolor",
        "EDITOR": "vim",
        "PAGER": "less",
        "LESS": "-R -F -X",
        "HISTSIZE": "100000",
        "HISTCONTROL": "ignoreboth:erasedups",
        "MAIL": "/var/mail/developer",
        "XDG_RUNTIME_DIR": "/run/user/1000",
        "XDG_SESSION_ID": "42",
        "XDG_SESSION_TYPE": "tty",
        "XDG_DATA_DIRS": "/usr/local/share:/usr/share:/var/lib/snapd/desktop",
        "XDG_CONFIG_DIRS": "/etc/xdg",
        "DBUS_SESSION_BUS_ADDRESS": "unix:path=/run/user/1000/bus",
        "SSH_CLIENT": "10.0.0.23 51514 22",
        "SSH_CONNECTION": "10.0.0.23 51514 10.0.0.5 22",
        "SSH_TTY": "/dev/pts/3",
        "SSH_AUTH_SOCK": "/tmp/ssh-XXXXkq2Jm1/agent.4242",
        "LS_COLORS": "rs=0:di=01;34:ln=01;36:mh=00:pi=40;33:so=01;35:do=01;35:" + colors,
        "PATH": f"{ros}/bin:/home/developer/.local/bin:/usr/local/sbin:/usr/local/bin:"
        "/usr/sbin:/usr/bin:/sbin:/bin",
        "PYTHONPATH": f"{ros}/lib/python3.12/site-packages:"
        f"{ros}/local/lib/python3.12/dist-packages",
        "LD_LIBRARY_PATH": f"{ros}/opt/rviz_ogre_vendor/lib:{ros}/lib/x86_64-linux-gnu:{ros}/lib",
        "AMENT_PREFIX_PATH": f"/home/developer/ros2_ws/install/demo:{ros}",
        "CMAKE_PREFIX_PATH": "/home/developer/ros2_ws/install/demo",
        "COLCON_PREFIX_PATH": "/home/developer/ros2_ws/install",
        "ROS_VERSION": "2",
        "ROS_PYTHON_VERSION": "3",
        "ROS_DISTRO": "jazzy",
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        MARK: "1",
    }
    return env


def _scene_pids(helper: int) -> list[int]:
    """The live children of ``helper`` that carry the scene's mark, from /proc."""
    found = []
    mark = f"{MARK}=1".encode()
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as handle:
                stat = handle.read()
            ppid = int(stat[stat.rindex(b")") + 2 :].split()[1])
            if ppid != helper:
                continue
            with open(f"/proc/{name}/environ", "rb") as handle:
                if mark in handle.read().split(b"\0"):
                    found.append(int(name))
        except (OSError, ValueError):
            continue
    return found


@contextlib.contextmanager
def idle_processes(python: str, work: Path, count: int = IDLE_PROCESSES) -> Iterator[str]:
    """``count`` idle processes alive for the ``with`` block; yields what /proc showed."""
    cat = shutil.which("cat")
    if cat is None:
        raise RuntimeError("idle scene: no cat command")
    env_file = work / "idle-environment"
    env = idle_environment()
    env_file.write_bytes(b"".join(f"{k}={v}\0".encode() for k, v in env.items()))
    environ_bytes = env_file.stat().st_size
    progress(f"idle scene: starting {count} idle processes")
    started = time.monotonic()
    helper = subprocess.Popen(
        [python, "-c", _HELPER, str(count), cat, str(env_file)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
    )
    try:
        assert helper.stdout is not None
        line = helper.stdout.readline().strip()
        if line != b"ready":
            raise RuntimeError(f"idle scene: the helper did not start ({line!r})")
        visible: list[int] = []
        deadline = time.monotonic() + 120.0
        while len(visible) < count and time.monotonic() < deadline:
            visible = _scene_pids(helper.pid)  # exec may lag the spawn a little
            if len(visible) < count:
                time.sleep(0.2)
        if len(visible) < count:
            raise RuntimeError(f"idle scene: only {len(visible)} of {count} visible in /proc")
        took = time.monotonic() - started
        progress(f"idle scene: {len(visible)} idle processes in /proc after {took:.1f} s")
        yield (
            f"{len(visible)} idle processes (`cat` on a pipe, {len(env)} variables, "
            f"{environ_bytes} bytes of environment each) checked visible in /proc"
        )
    finally:
        if helper.stdin is not None:
            helper.stdin.close()  # the helper closes the pipe: every cat exits
        try:
            helper.wait(120)
        except subprocess.TimeoutExpired:
            helper.kill()  # its write end closes with it: the cats exit all the same
            helper.wait()
        if helper.stdout is not None:
            helper.stdout.close()
        progress("idle scene: ended")


def phases(reps: int) -> list[tuple[str, int]]:
    """Quiet, busy, quiet (ABA): drift in the machine's load hits both scenes alike.

    The busy phase runs all ``reps`` in one scene (starting 3000 processes takes
    seconds); the quiet repetitions are split around it.
    """
    first = (reps + 1) // 2
    plan = [(QUIET, first), (BUSY, reps), (QUIET, reps - first)]
    return [(scene, n) for scene, n in plan if n > 0]


def in_scenes(python: str, work: Path, reps: int, body: Callable[[str, int], None]) -> str:
    """Call ``body(scene, reps)`` for each phase, the busy one with the scene alive.

    Returns the scene's description for the table's note.
    """
    described = ""
    for scene, n in phases(reps):
        if scene == BUSY:
            with idle_processes(python, work) as described:
                body(scene, n)
        else:
            body(scene, n)
    return described
