# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The environment of a ROS graph we start, its child processes, and their memory settings.

No ROS import: the demo, the tests and the benchmarks use it before any node exists.

* :data:`MALLOC_ENV`: glibc's malloc settings that stop multi-MB buffers (frames, remap tables)
  from being mmap'ed and unmapped on every use. glibc reads them at process start only, so a
  child process gets them through its environment; a node applies the same numbers to itself
  at run time with :func:`keep_large_buffers`.
* :func:`pick_domain_id`: a private ``ROS_DOMAIN_ID`` per user of a graph, from disjoint
  ranges (:data:`DOMAIN_RANGES`), so a test run, a demo and a benchmark on one machine never
  see each other's nodes. Fast DDS maps domain d to UDP ports 7400 + 250 d + ...; ids up to
  232 keep every port below 65536.
* :func:`process_env`: the variables of every process of such a graph: the domain,
  ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (discovery on the loopback only), the package's
  Fast DDS profile ``config/fastdds_shm.xml`` (a shared-memory segment large enough for
  best-effort frames of 1280x720 and up: Fast DDS's builtin 512 KiB segment drops them),
  :data:`MALLOC_ENV`, unbuffered output, and this package first on ``PYTHONPATH`` so children
  import the same copy.
* :class:`Child`: a process in its own process group (a Ctrl-C in the terminal reaches only
  the parent, which then stops its children in order), logging to files, stopped by SIGINT
  to the group (as ``ros2 run`` is by Ctrl-C), then SIGTERM, then SIGKILL when it hangs.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from pathlib import Path
import signal
import subprocess
import sys
from typing import Any, Callable, Mapping, Sequence

#: Buffers below this many bytes come from the heap, not from mmap (64 MiB).
MMAP_THRESHOLD_BYTES = 64 * 1024 * 1024
#: glibc returns free heap memory to the kernel only above this many bytes (1 GiB).
TRIM_THRESHOLD_BYTES = 1024 * 1024 * 1024
#: The same settings as environment variables, for child processes.
MALLOC_ENV = {'MALLOC_MMAP_THRESHOLD_': str(MMAP_THRESHOLD_BYTES),
              'MALLOC_TRIM_THRESHOLD_': str(TRIM_THRESHOLD_BYTES)}

#: ``ROS_DOMAIN_ID`` ranges of the users of a graph, disjoint (first id, last id).
DOMAIN_RANGES = {'tests': (1, 100), 'demo': (101, 119), 'benchmarks': (120, 219),
                 'soak': (220, 232)}
#: The Fast DDS profile every process of our graphs reads (``config/`` of the package).
FASTDDS_PROFILE_NAME = 'fastdds_shm.xml'
PROFILE_VAR = 'FASTRTPS_DEFAULT_PROFILES_FILE'
#: Seconds a child gets after SIGINT, SIGTERM and SIGKILL to its group, by default.
STOP_TIMEOUTS_S = (10.0, 3.0, 3.0)

#: The folder holding this package (a source checkout's root, or site-packages).
PACKAGE_PARENT = Path(__file__).resolve().parents[2]


def keep_large_buffers() -> bool:
    """
    Stop glibc from returning multi-MB buffers to the kernel after every use.

    Each frame and each rebuild allocates buffers of megabytes (messages, maps). By default
    glibc serves those with mmap and unmaps them on free, so every reuse page-faults the
    memory in again: measured, a 1080p map rebuild takes 11.5 ms median that way and 8.3 ms
    with these settings. This is what :data:`MALLOC_ENV` does, applied at run time
    (``mallopt``) so that ``ros2 run`` gets it without an environment. No-op where glibc is
    not the C library.

    :return: True when both settings were applied.
    """
    try:
        libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6')
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3     # glibc's malloc.h
    return bool(mallopt(m_mmap_threshold, MMAP_THRESHOLD_BYTES)) and \
        bool(mallopt(m_trim_threshold, TRIM_THRESHOLD_BYTES))


# ---------------------------------------------------------------------------------------------
# Domain ids, config files, environment
# ---------------------------------------------------------------------------------------------

def pick_domain_id(user: str, salt: int = 0, lane: int = 0, lanes: int = 1) -> int:
    """
    Return a ``ROS_DOMAIN_ID`` in ``user``'s range, derived from the pid and ``salt``.

    Two processes (two test runs, say) get different ids unless their pids collide modulo the
    range; one process gets different ids for different salts. The caller's own exported
    ``ROS_DOMAIN_ID`` is skipped, so the graph never joins the user's everyday domain.
    With ``lanes`` > 1 the range is dealt out: lane k takes only the ids ``first + k``,
    ``first + k + lanes``, ..., so parallel callers with distinct lanes never share one.

    :param user: a key of :data:`DOMAIN_RANGES` (``tests``, ``demo``, ``benchmarks``,
        ``soak``).
    :param salt: a counter or offset of the caller.
    :param lane: this caller's lane, 0 to ``lanes`` - 1.
    :param lanes: how many callers share the range.
    :return: the domain id.
    :raises KeyError: for an unknown user.
    """
    first, last = DOMAIN_RANGES[user]
    slots = (last - first + 1) // lanes
    index = (os.getpid() * 7 + salt) % slots
    if str(first + lane + lanes * index) == os.environ.get('ROS_DOMAIN_ID'):
        index = (index + 1) % slots
    return first + lane + lanes * index


def config_file(name: str) -> Path:
    """
    Find a file of the package's ``config/``: the source checkout's, else the installed one.

    The installed copy is ``share/mechdeconv_ros/config`` of the ament index (colcon) or of
    ``sys.prefix`` (pip).

    :param name: the file name, e.g. ``case2.yaml``.
    :return: its path.
    :raises FileNotFoundError: when no candidate holds it.
    """
    candidates = [PACKAGE_PARENT / 'config']
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory('mechdeconv_ros')) / 'config')
    except Exception:   # noqa: B902 - not installed through ament: the other candidates
        pass
    candidates.append(Path(sys.prefix) / 'share' / 'mechdeconv_ros' / 'config')
    for folder in candidates:
        if (folder / name).is_file():
            return folder / name
    raise FileNotFoundError(f'cannot find config/{name} (looked in '
                            + ', '.join(str(c) for c in candidates) + ')')


def fastdds_profile() -> Path:
    """
    Return the package's Fast DDS profile, ``config/fastdds_shm.xml``.

    :return: its path.
    """
    return config_file(FASTDDS_PROFILE_NAME)


def python_path(first: str | os.PathLike[str] = PACKAGE_PARENT,
                rest: str | None = None) -> str:
    """
    Return a ``PYTHONPATH`` with ``first`` in front of the current one (without repeats).

    :param first: the folder children must import this package from.
    :param rest: the path to extend (default: this process's ``PYTHONPATH``).
    :return: the joined path.
    """
    rest = os.environ.get('PYTHONPATH', '') if rest is None else rest
    parts = [p for p in rest.split(os.pathsep) if p and p != str(first)]
    return os.pathsep.join([str(first)] + parts)


def graph_env(domain_id: int, *, shm_profile: bool = True, keep_exported: bool = False,
              base: Mapping[str, str] | None = None,
              extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """
    Return the full environment of a process of our ROS graph.

    :param domain_id: the graph's ``ROS_DOMAIN_ID``.
    :param shm_profile: give it the package's Fast DDS profile (False: Fast DDS's builtin
        transports, as a benchmark baseline; the profile variable is then removed).
    :param keep_exported: keep a Fast DDS profile and ``MALLOC_*`` values the caller already
        exported (the demo, run by the Makefile, which exports the same ones); False (tests,
        benchmarks): always the package's own, and ``FASTDDS_BUILTIN_TRANSPORTS`` removed.
    :param base: the environment to extend (default ``os.environ``).
    :param extra: variables that override everything else.
    :return: a new dict.
    """
    env = dict(os.environ if base is None else base)
    env.pop('ROS_LOCALHOST_ONLY', None)     # superseded by the discovery range, conflicts
    defaults = dict(MALLOC_ENV)
    if shm_profile:
        defaults[PROFILE_VAR] = str(fastdds_profile())
    else:
        env.pop(PROFILE_VAR, None)
    if keep_exported:
        for name, value in defaults.items():
            env.setdefault(name, value)
    else:
        env.pop('FASTDDS_BUILTIN_TRANSPORTS', None)
        env.update(defaults)
    env.update({
        'ROS_DOMAIN_ID': str(domain_id),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'PYTHONUNBUFFERED': '1',
        'RCUTILS_COLORIZED_OUTPUT': '0',
        'RCUTILS_LOGGING_BUFFERED_STREAM': '0',
        'PYTHONPATH': python_path(rest=env.get('PYTHONPATH', '')),
    })
    env.update(extra or {})
    return env


def announcing_profile(folder: Path, period_s: float = 0.5,
                       source: Path | None = None) -> Path:
    """
    Write a copy of a Fast DDS profile whose participants announce themselves every period_s.

    For a process that waits for others to appear (a test client, a benchmark probe): a
    participant that exists before another starts discovered the newcomer only at one of its
    own periodic announcements (Fast DDS default: every 3 s), so each node start-up waited
    0 to 3 s for discovery (1.4 s mean, 0.3 s with 0.5 s announcements; measured on this
    package's profile, LOCALHOST range, 2026-11-27). The processes of the graph keep the
    package's profile; only the waiting process loads this copy (before its first participant).

    :param folder: where the copy is written (``announcing_fastdds.xml``).
    :param period_s: seconds between announcements.
    :param source: the profile to copy (default: the package's).
    :return: the copy's path (the source itself if it already sets builtin discovery).
    """
    import xml.etree.ElementTree as ET

    source = fastdds_profile() if source is None else Path(source)
    namespace = 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'
    ET.register_namespace('', namespace)
    tree = ET.parse(source)
    rtps = tree.getroot().find(f'.//{{{namespace}}}participant/{{{namespace}}}rtps')
    if rtps is None or rtps.find(f'{{{namespace}}}builtin') is not None:
        return source
    config = ET.SubElement(ET.SubElement(rtps, f'{{{namespace}}}builtin'),
                           f'{{{namespace}}}discovery_config')
    lease = ET.SubElement(config, f'{{{namespace}}}leaseAnnouncement')
    seconds, nanoseconds = divmod(int(round(period_s * 1e9)), 1_000_000_000)
    ET.SubElement(lease, f'{{{namespace}}}sec').text = str(seconds)
    ET.SubElement(lease, f'{{{namespace}}}nanosec').text = str(nanoseconds)
    path = Path(folder) / 'announcing_fastdds.xml'
    tree.write(path, encoding='UTF-8', xml_declaration=True)
    return path


def configure_this_process(env: Mapping[str, str]) -> None:
    """
    Give this process the discovery range and Fast DDS profile of ``env``.

    Fast DDS reads its profile once per process, at the first participant, so this must run
    before the first ``rclpy.init`` of a process that joins the graph. The domain is not set:
    pass it to ``rclpy.init(domain_id=...)``.

    :param env: an environment from :func:`process_env`.
    """
    os.environ.pop('ROS_LOCALHOST_ONLY', None)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = env['ROS_AUTOMATIC_DISCOVERY_RANGE']
    if PROFILE_VAR in env:
        os.environ[PROFILE_VAR] = env[PROFILE_VAR]
    else:
        os.environ.pop(PROFILE_VAR, None)


# ---------------------------------------------------------------------------------------------
# Child processes
# ---------------------------------------------------------------------------------------------

def _die_with_parent() -> None:
    """Ask Linux to SIGTERM the child when its parent dies without cleaning up."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)     # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class Child:
    """A process in its own process group, stopped by signals to the group, logging to files."""

    def __init__(self, argv: Sequence[str], env: Mapping[str, str], stdout: Path,
                 stderr: Path | None = None, name: str = '',
                 die_with_parent: bool = False) -> None:
        """
        Start the process.

        :param argv: the command.
        :param env: its full environment.
        :param stdout: the file its stdout goes to.
        :param stderr: the file its stderr goes to (None: into ``stdout``).
        :param name: a short name for messages (default: the stdout file's stem).
        :param die_with_parent: SIGTERM it when this process dies (Linux; only for a parent
            whose main thread starts it: the kernel sends it when the starting *thread* ends).
        """
        self.argv = list(argv)
        self.name = name or stdout.stem
        self.out_path, self.err_path = stdout, stderr
        self._streams = [open(stdout, 'wb')]
        if stderr is not None:
            self._streams.append(open(stderr, 'wb'))
        self.proc = subprocess.Popen(
            self.argv, env=dict(env), stdin=subprocess.DEVNULL, stdout=self._streams[0],
            stderr=self._streams[1] if stderr is not None else subprocess.STDOUT,
            start_new_session=True, preexec_fn=_die_with_parent if die_with_parent else None)
        self.returncode: int | None = None
        #: The signals that did not stop it in time (escalation happened when not empty).
        self.ignored: list[str] = []

    @property
    def pid(self) -> int:
        """Return the process id (also its process group id)."""
        return self.proc.pid

    @property
    def killed(self) -> bool:
        """Return True when SIGINT did not stop it in time (it got SIGTERM or SIGKILL)."""
        return bool(self.ignored)

    def running(self) -> bool:
        """Return True while the process runs."""
        return self.proc.poll() is None

    def signal_group(self, sig: int) -> bool:
        """
        Send ``sig`` to the process group.

        :param sig: the signal.
        :return: False when the group is gone.
        """
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            return False
        return True

    def stop(self, sig: int = signal.SIGINT, timeout: float = STOP_TIMEOUTS_S[0],
             escalate_s: tuple[float, float] = STOP_TIMEOUTS_S[1:],
             log: Callable[[str], Any] | None = None) -> int:
        """
        Stop the group with ``sig``, wait; then SIGTERM, then SIGKILL if it still runs.

        :param sig: the first signal (SIGINT, as Ctrl-C in ``ros2 run``).
        :param timeout: seconds to wait after ``sig``.
        :param escalate_s: seconds to wait after SIGTERM and after SIGKILL.
        :param log: called with a line when a signal did not stop it in time.
        :return: the exit code (negative: ended by that signal).
        """
        if self.returncode is None:
            steps = ((sig, timeout), (signal.SIGTERM, escalate_s[0]),
                     (signal.SIGKILL, escalate_s[1]))
            for step, wait_s in steps:
                if self.proc.poll() is not None or not self.signal_group(step):
                    break
                try:
                    self.proc.wait(timeout=wait_s)
                    break
                except subprocess.TimeoutExpired:
                    name = signal.Signals(step).name
                    self.ignored.append(name)
                    if log is not None:
                        log(f'{self.name} did not exit within {wait_s:g} s of {name}')
            self.returncode = self.proc.wait()
        self._close()
        return self.returncode

    def kill(self) -> None:
        """Kill the whole process group (its children too), now."""
        self.signal_group(signal.SIGKILL)
        self.returncode = self.proc.wait()
        self._close()

    def _close(self) -> None:
        for stream in self._streams:
            if not stream.closed:
                stream.close()

    def cpu_s(self) -> float:
        """Return the CPU seconds (user + system, all threads) used so far; 0 when gone."""
        try:
            with open(f'/proc/{self.pid}/stat', encoding='ascii') as stream:
                fields = stream.read().rsplit(')', 1)[1].split()
            return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
        except (OSError, IndexError, ValueError):
            return 0.0

    def stdout(self) -> str:
        """Return what it wrote to its stdout file so far."""
        for stream in self._streams:
            if not stream.closed:
                stream.flush()
        return self.out_path.read_text(errors='replace')

    def stderr(self) -> str:
        """Return what it wrote to its stderr file so far ('' when merged into stdout)."""
        if self.err_path is None:
            return ''
        for stream in self._streams:
            if not stream.closed:
                stream.flush()
        return self.err_path.read_text(errors='replace')

    def output(self) -> str:
        """Return everything it wrote so far (stdout, then stderr)."""
        return self.stdout() + ('\n' + self.stderr() if self.err_path is not None else '')

    def tail(self, lines: int = 15, indent: str = '') -> str:
        """
        Return the last lines of its stderr (of its stdout when merged).

        :param lines: how many.
        :param indent: put in front of each.
        :return: the text (``(empty log)`` when empty).
        """
        try:
            text = (self.stderr() if self.err_path is not None else self.stdout())
        except OSError:
            text = ''
        return '\n'.join(indent + line for line in text.splitlines()[-lines:]) or \
            f'{indent}(empty log)'

    def __enter__(self) -> Child:
        """Return self."""
        return self

    def __exit__(self, *exc: Any) -> None:
        """Make sure nothing outlives the block."""
        if self.proc.poll() is None:
            self.kill()
        self._close()
