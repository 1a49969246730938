# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``python -m mechdeconv_ros.demo`` (``make demo``): the whole product in half a minute.

1. Starts ``correct_node`` (``--params-file config/case2.yaml``) and ``demo_camera`` (the same
   file: it renders a grid chart through the same Case 2 lens) as two processes, each in its
   own process group, on a private ``ROS_DOMAIN_ID`` with ``ROS_AUTOMATIC_DISCOVERY_RANGE=
   LOCALHOST``, the shared-memory Fast DDS profile ``config/fastdds_shm.xml`` and the glibc
   ``MALLOC_*`` settings of the Makefile (README, "Transport").
2. A client node in this process subscribes ``image_rect``, ``camera_info`` and
   ``/diagnostics``, prints the model and the node's diagnostics, then the live throughput and
   latency (receive time minus ``header.stamp``, which the camera sets when it publishes).
3. Writes ``raw.png`` and ``corrected.png``.
4. Changes the lens: ``lens.stop_offset_mm`` and ``lens.thickness_mm`` are set together, first
   on ``demo_camera`` (a physical change of the real lens), then on ``correct_node`` (the user
   telling the node), each through ``<node>/set_parameters_atomically``: one validation and
   one rebuild for the pair (two ``ros2 param set`` calls, or ``ros2 param load``, would apply
   them one at a time; README, "Install as a ROS 2 package"). Prints the replies, the time
   from the node's reply to the first frame corrected by the new model (seen as
   ``camera_info`` D changing) and the rebuild time the node reports.
5. Writes ``raw_after_change.png``, ``corrected_after_change.png`` and ``summary.png`` (the four
   side by side), prints throughput and latency again, stops both processes with SIGINT and
   checks that they exit with status 0.

Ctrl-C at any time stops the children and exits 130. Options: ``--seconds`` (each measuring
window, default 10; also ``MECHDECONV_DEMO_SECONDS``), ``--out`` (default ``demo_out``),
``--stop-offset``/``--thickness`` (the new lens), ``--domain-id``.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Callable, Sequence

import cv2
from mechdeconv_ros.graph_env import MALLOC_ENV
import numpy as np

#: Seconds to wait for the first corrected frame after starting the processes.
STARTUP_TIMEOUT_S = 30.0
#: Seconds a child gets to exit after SIGINT before it is sent SIGTERM, then SIGKILL.
STOP_TIMEOUT_S = 10.0

_T0 = time.monotonic()


class DemoError(Exception):
    """Something went wrong that the demo reports in one line (exit status 1)."""


def say(text: str) -> None:
    """
    Print one progress line, prefixed with the seconds since the demo started.

    :param text: the line.
    """
    print(f'[demo {time.monotonic() - _T0:5.1f} s] {text}', flush=True)


def package_config_dir() -> Path:
    """
    Find the package's config folder: the source tree's, else the installed share folder.

    :return: the folder holding case2.yaml and fastdds_shm.xml.
    :raises DemoError: when neither exists.
    """
    candidates = [Path(__file__).resolve().parent.parent / 'config']
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory('mechdeconv_ros')) / 'config')
    except Exception:   # noqa: B902 - not installed through ament: only the source tree
        pass
    candidates.append(Path(sys.prefix) / 'share' / 'mechdeconv_ros' / 'config')
    for folder in candidates:
        if (folder / 'case2.yaml').is_file():
            return folder
    raise DemoError('cannot find config/case2.yaml (looked in '
                    + ', '.join(str(c) for c in candidates) + ')')


def graph_env(domain_id: int, config: Path) -> dict[str, str]:
    """
    Return the environment variables every process of the demo's ROS graph gets.

    The Fast DDS profile and the MALLOC settings keep values the caller already exported (the
    Makefile exports the same ones); the domain and the discovery range are always private.

    :param domain_id: the ROS domain of the demo.
    :param config: the config folder (for fastdds_shm.xml).
    :return: the variables to set.
    """
    env = {
        'ROS_DOMAIN_ID': str(domain_id),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'FASTRTPS_DEFAULT_PROFILES_FILE': os.environ.get(
            'FASTRTPS_DEFAULT_PROFILES_FILE', str(config / 'fastdds_shm.xml')),
        'PYTHONUNBUFFERED': '1',
        'RCUTILS_COLORIZED_OUTPUT': '0',
    }
    for name, value in MALLOC_ENV.items():
        env[name] = os.environ.get(name, value)
    return env


def _pythonpath() -> str:
    """Return PYTHONPATH with this package's parent first: children import this very copy."""
    root = str(Path(__file__).resolve().parent.parent)
    rest = [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p and p != root]
    return os.pathsep.join([root] + rest)


def _set_parent_death_signal() -> None:
    """Ask Linux to send SIGTERM to the child if the demo dies without cleaning up."""
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)       # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class Child:
    """One process of the demo graph, in its own process group, logging to a file."""

    def __init__(self, name: str, argv: list[str], env: dict[str, str], log: Path) -> None:
        """
        Start the process.

        :param name: a short name for messages.
        :param argv: the command.
        :param env: its full environment.
        :param log: where its stdout and stderr go.
        """
        self.name = name
        self.log = log
        self.returncode: int | None = None
        with open(log, 'wb') as stream:
            self.proc = subprocess.Popen(
                argv, env=env, stdin=subprocess.DEVNULL, stdout=stream,
                stderr=subprocess.STDOUT, start_new_session=True,
                preexec_fn=_set_parent_death_signal)

    def alive(self) -> bool:
        """Return True while the process runs."""
        return self.proc.poll() is None

    def tail(self, lines: int = 15) -> str:
        """
        Return the end of the process's log, indented.

        :param lines: how many lines.
        :return: the text.
        """
        try:
            text = self.log.read_text(errors='replace').splitlines()[-lines:]
        except OSError:
            text = []
        return '\n'.join('    ' + line for line in text) or '    (empty log)'

    def stop(self) -> int:
        """
        Stop the process group with SIGINT (as Ctrl-C would); escalate if it hangs.

        :return: the exit status (negative: killed by that signal).
        """
        if self.returncode is not None:
            return self.returncode
        for sig, wait_s in ((signal.SIGINT, STOP_TIMEOUT_S), (signal.SIGTERM, 3.0),
                            (signal.SIGKILL, 3.0)):
            if self.proc.poll() is not None:
                break
            try:
                os.killpg(self.proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.proc.wait(timeout=wait_s)
                break
            except subprocess.TimeoutExpired:
                say(f'{self.name} did not exit within {wait_s:g} s of {sig.name}')
        self.returncode = self.proc.wait()
        return self.returncode


# ---------------------------------------------------------------------------------------------
# The client node
# ---------------------------------------------------------------------------------------------


def stamp_ns(stamp: Any) -> int:
    """
    Return a builtin_interfaces/Time in nanoseconds.

    :param stamp: the message field.
    :return: nanoseconds since the epoch.
    """
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def to_bgr(msg: Any) -> np.ndarray:
    """
    Copy a sensor_msgs/Image into a BGR (or grey) array that cv2.imwrite takes.

    :param msg: the Image.
    :return: ``(H, W, 3)`` or ``(H, W)`` uint8/uint16.
    """
    from mechdeconv_ros.image_msgs import image_to_array
    pixels, encoding = image_to_array(msg)
    conversions = {'rgb8': cv2.COLOR_RGB2BGR, 'rgba8': cv2.COLOR_RGBA2BGR,
                   'bgra8': cv2.COLOR_BGRA2BGR}
    if encoding.name in conversions:
        return cv2.cvtColor(pixels, conversions[encoding.name])
    return np.ascontiguousarray(pixels)


def make_monitor(rclpy_node_cls: Any) -> Any:
    """Define the client node class (rclpy is imported late, after the environment is set)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.srv import SetParametersAtomically
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    class Monitor(rclpy_node_cls):
        """Subscribes to the node's outputs and keeps what the demo prints and saves."""

        def __init__(self) -> None:
            super().__init__('mechdeconv_demo')
            self.lock = threading.Lock()
            self.frames: list[tuple[float, float]] = []     # (receive monotonic s, latency ms)
            self.last_rect: Image | None = None
            self.rect_by_stamp: dict[int, Image] = {}
            self.info_d: tuple[float, ...] | None = None
            self.d_changed_from: tuple[float, ...] | None = None
            self.d_changed_at: float | None = None          # monotonic s
            self.d_changed_stamp: int | None = None
            self.diag: dict[str, str] = {}
            self.frames_in: list[tuple[float, int]] = []    # (receive monotonic s, node input)
            self.diag_message = ''
            self.raw_wanted: list[Image] = []
            self._raw_sub: Any = None
            self.create_subscription(Image, 'image_rect', self._on_rect, qos_profile_sensor_data)
            self.create_subscription(CameraInfo, 'camera_info', self._on_info,
                                     qos_profile_sensor_data)
            self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag,
                                     qos_profile_sensor_data)
            self.param_clients = {
                name: self.create_client(SetParametersAtomically,
                                         f'/{name}/set_parameters_atomically')
                for name in ('correct_node', 'demo_camera')}
            self._parameter = Parameter

        def _on_rect(self, msg: Image) -> None:
            now = self.get_clock().now().nanoseconds
            latency_ms = (now - stamp_ns(msg.header.stamp)) / 1e6
            with self.lock:
                self.frames.append((time.monotonic(), latency_ms))
                self.last_rect = msg
                self.rect_by_stamp[stamp_ns(msg.header.stamp)] = msg
                if len(self.rect_by_stamp) > 30:
                    self.rect_by_stamp.pop(next(iter(self.rect_by_stamp)))

        def _on_info(self, msg: CameraInfo) -> None:
            d = tuple(float(v) for v in msg.d)
            with self.lock:
                if (self.d_changed_from is not None and self.d_changed_at is None
                        and d != self.d_changed_from):
                    self.d_changed_at = time.monotonic()
                    self.d_changed_stamp = stamp_ns(msg.header.stamp)
                self.info_d = d

        def _on_diag(self, msg: DiagnosticArray) -> None:
            for status in msg.status:
                if status.name.startswith('correct_node'):
                    with self.lock:
                        self.diag = {kv.key: kv.value for kv in status.values}
                        self.diag_message = status.message
                        if self.diag.get('frames_in', '').isdigit():
                            self.frames_in.append((time.monotonic(), int(self.diag['frames_in'])))

        def _on_raw(self, msg: Image) -> None:
            with self.lock:
                self.raw_wanted.append(msg)

        def grab_raw(self, timeout_s: float) -> Image:
            """Subscribe to image_raw until one frame arrives; return it."""
            with self.lock:
                self.raw_wanted = []
            sub = self.create_subscription(Image, 'image_raw', self._on_raw,
                                           qos_profile_sensor_data)
            try:
                wait_for(lambda: bool(self.raw_wanted), timeout_s, 'a frame on image_raw')
                with self.lock:
                    return self.raw_wanted[-1]
            finally:
                self.destroy_subscription(sub)

        def window(self, start: float, end: float) -> tuple[float, list[float], float]:
            """
            Return the image_rect fps and latencies (ms) received in a window.

            Also the node's input fps over the same window, from the frames_in counter of its
            diagnostics (1 Hz, so over the whole seconds inside the window; NaN if unknown).
            """
            with self.lock:
                lat = [ms for t, ms in self.frames if start <= t < end]
                counts = [(t, n) for t, n in self.frames_in if start <= t <= end]
            node_fps = float('nan')
            if len(counts) >= 2 and counts[-1][0] > counts[0][0]:
                node_fps = (counts[-1][1] - counts[0][1]) / (counts[-1][0] - counts[0][0])
            return len(lat) / max(end - start, 1e-9), lat, node_fps

        def set_lens(self, node: str, values: dict[str, float],
                     timeout_s: float) -> tuple[Any, float, float]:
            """
            Call ``/<node>/set_parameters_atomically``.

            :return: (SetParametersResult, request monotonic s, reply monotonic s).
            """
            client = self.param_clients[node]
            if not client.wait_for_service(timeout_sec=timeout_s):
                raise DemoError(f'/{node}/set_parameters_atomically is not available')
            request = SetParametersAtomically.Request()
            request.parameters = [self._parameter(name, value=float(value)).to_parameter_msg()
                                  for name, value in values.items()]
            replied: list[float] = []
            sent = time.monotonic()
            future = client.call_async(request)
            future.add_done_callback(lambda _: replied.append(time.monotonic()))
            wait_for(lambda: bool(replied), timeout_s, f'the reply of /{node}')
            return future.result().result, sent, replied[0]

    return Monitor


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str,
             children: Sequence[Child] = ()) -> None:
    """
    Poll ``condition`` until it holds.

    :param condition: the predicate.
    :param timeout_s: how long to wait.
    :param what: what is awaited, for the error message.
    :param children: processes that must stay alive meanwhile.
    :raises DemoError: on timeout or when a child exits.
    """
    deadline = time.monotonic() + timeout_s
    while not condition():
        for child in children:
            if not child.alive():
                raise DemoError(f'{child.name} exited with status {child.proc.returncode} '
                                f'while waiting for {what}; its log:\n{child.tail()}')
        if time.monotonic() > deadline:
            raise DemoError(f'no {what} within {timeout_s:g} s')
        time.sleep(0.02)


def percentile(values: Sequence[float], q: float) -> float:
    """
    Return the q-th percentile, NaN for no values.

    :param values: the samples.
    :param q: percent, 0-100.
    :return: the percentile.
    """
    return float(np.percentile(values, q)) if len(values) else float('nan')


def measure(monitor: Any, seconds: float, label: str, rate_hz: float,
            children: Sequence[Child]) -> None:
    """
    Print the throughput and latency of image_rect over the next ``seconds``.

    :param monitor: the client node.
    :param seconds: the window.
    :param label: what the window is (before/after the change).
    :param rate_hz: the camera rate.
    :param children: processes that must stay alive meanwhile.
    """
    say(f'measuring image_rect for {seconds:g} s ({label}) ...')
    start = time.monotonic()
    wait_for(lambda: time.monotonic() - start >= seconds, seconds + 5.0, 'end of window',
             children)
    fps, lat, node_fps = monitor.window(start, time.monotonic())
    say(f'  throughput {fps:.1f} fps of image_rect (camera {rate_hz:g} Hz, node input '
        f'{node_fps:.1f} fps); latency camera -> image_rect p50 {percentile(lat, 50):.1f} ms, '
        f'p95 {percentile(lat, 95):.1f} ms ({len(lat)} frames)')


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """
    Put a caption strip above an image.

    :param image: BGR uint8.
    :param text: the caption.
    :return: the captioned image.
    """
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    strip = np.full((30, image.shape[1], 3), 255, np.uint8)
    cv2.putText(strip, text, (8, 21), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1,
                cv2.LINE_AA)
    return np.vstack([strip, image])


def write_png(path: Path, image: np.ndarray) -> None:
    """
    Write a PNG and say so.

    :param path: the file.
    :param image: what cv2.imwrite takes.
    :raises DemoError: when it cannot be written.
    """
    if not cv2.imwrite(str(path), image):
        raise DemoError(f'cannot write {path}')
    say(f'wrote {path}')


# ---------------------------------------------------------------------------------------------
# The demo
# ---------------------------------------------------------------------------------------------


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """
    Parse the command line.

    :param argv: arguments (default ``sys.argv[1:]``).
    :return: the options.
    """
    parser = argparse.ArgumentParser(
        prog='python -m mechdeconv_ros.demo',
        description='Run correct_node and a simulated camera, change the lens live, measure.')
    parser.add_argument('--seconds', type=float,
                        default=float(os.environ.get('MECHDECONV_DEMO_SECONDS', '10')),
                        help='length of each measuring window (default 10 s; '
                             'env MECHDECONV_DEMO_SECONDS)')
    parser.add_argument('--out', type=Path, default=Path('demo_out'),
                        help='folder for the PNGs and the process logs (default demo_out)')
    parser.add_argument('--stop-offset', type=float, default=0.6,
                        help='new lens.stop_offset_mm (default 0.6; Case 2 has 0.2)')
    parser.add_argument('--thickness', type=float, default=4.0,
                        help='new lens.thickness_mm (default 4.0; Case 2 has 3.0)')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate in Hz (30)')
    parser.add_argument('--domain-id', type=int, default=None,
                        help='ROS_DOMAIN_ID of the demo graph (default: a random one, 1-101)')
    args = parser.parse_args(argv)
    if not args.seconds > 0:
        parser.error('--seconds must be positive')
    return args


def run(args: argparse.Namespace, children: list[Child]) -> int:
    """
    Run the demo (children are appended to ``children`` so the caller can stop them).

    :param args: the options.
    :param children: filled with the started processes.
    :return: exit status.
    """
    from mechdeconv_ros.cli import format_report
    from mechdeconv_ros.model import build_model, ModelError
    from mechdeconv_ros.params import load_params_file

    config = package_config_dir()
    params_file = config / 'case2.yaml'
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    domain = args.domain_id
    if domain is None:
        current = os.environ.get('ROS_DOMAIN_ID', '0')
        domain = random.choice([d for d in range(1, 102) if str(d) != current])
    env_vars = graph_env(domain, config)
    env = dict(os.environ, **env_vars, PYTHONPATH=_pythonpath())

    # The lens before and after, built here too: the summary, and a check of the new values.
    values = load_params_file(params_file)
    change = {'lens.stop_offset_mm': args.stop_offset, 'lens.thickness_mm': args.thickness}
    before = build_model(values, 640, 480)
    try:
        after = build_model({**values, **change}, 640, 480)
    except ModelError as err:
        raise DemoError(f'the new lens describes no usable camera: {err}') from None

    say(f'ROS_DOMAIN_ID={domain}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, '
        f"FASTRTPS_DEFAULT_PROFILES_FILE={env_vars['FASTRTPS_DEFAULT_PROFILES_FILE']}")
    python = sys.executable
    children.append(Child(
        'correct_node', [python, '-m', 'mechdeconv_ros.correct_node', '--ros-args',
                         '--params-file', str(params_file)], env, out / 'correct_node.log'))
    say(f'started correct_node (pid {children[-1].proc.pid}, log {out}/correct_node.log)')
    children.append(Child(
        'demo_camera', [python, '-m', 'mechdeconv_ros.demo_camera', '--ros-args',
                        '--params-file', str(params_file), '-p', f'rate_hz:={args.rate!r}'],
        env, out / 'demo_camera.log'))
    say(f'started demo_camera (pid {children[-1].proc.pid}, log {out}/demo_camera.log): '
        f'640x480 rgb8 at {args.rate:g} Hz through the Case 2 lens')

    os.environ.update(env_vars)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=[], domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    monitor = make_monitor(Node)()
    executor = SingleThreadedExecutor()
    executor.add_node(monitor)
    spinner = threading.Thread(target=_spin, args=(executor,), name='demo-spin', daemon=True)
    spinner.start()
    try:
        return _scenario(args, children, monitor, before, after, change, format_report, out)
    finally:
        executor.shutdown(timeout_sec=2.0)
        monitor.destroy_node()
        rclpy.try_shutdown()
        spinner.join(timeout=2.0)


def _spin(executor: Any) -> None:
    from rclpy.executors import ExternalShutdownException
    try:
        executor.spin()
    except (ExternalShutdownException, KeyboardInterrupt):
        pass
    except Exception as err:    # noqa: B902 - a context shut down under the executor
        if 'shutdown' not in str(err).lower():
            raise


def _scenario(args: argparse.Namespace, children: list[Child], monitor: Any, before: Any,
              after: Any, change: dict[str, float], format_report: Any, out: Path) -> int:
    say('waiting for the first corrected frame on image_rect ...')
    wait_for(lambda: monitor.last_rect is not None, STARTUP_TIMEOUT_S,
             'corrected frame on image_rect', children)
    say('first corrected frame received')
    print('\nmodel (config/case2.yaml, as the node builds it):', flush=True)
    print('  ' + format_report(before.report()).replace('\n', '\n  '), flush=True)
    wait_for(lambda: bool(monitor.diag.get('model_revision')), 5.0, 'diagnostics from the node',
             children)
    print_diagnostics(monitor)

    time.sleep(1.0)     # warm-up: caches, DDS buffers, the first diagnostics period
    measure(monitor, args.seconds, 'Case 2 lens', args.rate, children)

    raw = monitor.grab_raw(5.0)
    write_png(out / 'raw.png', to_bgr(raw))
    with monitor.lock:
        rect = monitor.last_rect
    corrected = to_bgr(rect)
    write_png(out / 'corrected.png', corrected)

    # --- the lens change ---
    text = ', '.join(f'{k} = {v:g}' for k, v in change.items())
    say(f'changing the lens: {text} (Case 2: stop offset '
        f"{before.values['lens.stop_offset_mm']:g} mm, thickness "
        f"{before.values['lens.thickness_mm']:g} mm)")
    result, sent, replied = monitor.set_lens('demo_camera', change, 10.0)
    say(f'  /demo_camera/set_parameters_atomically -> successful={result.successful} '
        f'reason={result.reason!r} ({(replied - sent) * 1e3:.0f} ms: the camera now renders '
        'through the new lens)')
    if not result.successful:
        raise DemoError('demo_camera refused the new lens')
    with monitor.lock:
        revision_before = int(monitor.diag.get('model_revision', '0'))
        monitor.d_changed_from = monitor.info_d
        monitor.d_changed_at = None
    result, sent, replied = monitor.set_lens('correct_node', change, 10.0)
    say(f'  /correct_node/set_parameters_atomically -> successful={result.successful} '
        f'reason={result.reason!r} (reply after {(replied - sent) * 1e3:.1f} ms)')
    if not result.successful:
        raise DemoError('correct_node refused the new lens')
    wait_for(lambda: monitor.d_changed_at is not None, 5.0,
             'camera_info with the new D', children)
    first_ms = (monitor.d_changed_at - replied) * 1e3
    period_ms = 1e3 / args.rate
    say(f'  first frame from the new model {first_ms:.1f} ms after the reply '
        f'({first_ms / period_ms:.2f} frame periods at {args.rate:g} Hz); camera_info D = '
        f"[{', '.join(f'{d:.5g}' for d in after.D)}]")
    wait_for(lambda: int(monitor.diag.get('model_revision', '0')) > revision_before, 5.0,
             'diagnostics of the new model', children)
    say(f"  node rebuild time (diagnostics last_rebuild_ms): {monitor.diag['last_rebuild_ms']} "
        f"ms, model revision {monitor.diag['model_revision']}")

    time.sleep(0.3)
    raw_after = to_bgr(monitor.grab_raw(5.0))
    write_png(out / 'raw_after_change.png', raw_after)
    with monitor.lock:
        rect = monitor.last_rect
    if stamp_ns(rect.header.stamp) < (monitor.d_changed_stamp or 0):
        raise DemoError('the newest corrected frame predates the new model')
    corrected_after = to_bgr(rect)
    write_png(out / 'corrected_after_change.png', corrected_after)
    lens_text = 'stop offset {:g} mm, t = {:g} mm, f = {:.3f} mm'
    before_text = lens_text.format(before.values['lens.stop_offset_mm'],
                                   before.values['lens.thickness_mm'], before.focal_length_mm)
    after_text = lens_text.format(after.values['lens.stop_offset_mm'],
                                  after.values['lens.thickness_mm'], after.focal_length_mm)
    summary = np.vstack([
        np.hstack([caption(to_bgr(raw), f'image_raw: {before_text}'),
                   caption(corrected, 'image_rect (corrected)')]),
        np.hstack([caption(raw_after, f'image_raw: {after_text}'),
                   caption(corrected_after, 'image_rect after the parameter set')])])
    write_png(out / 'summary.png', summary)

    measure(monitor, args.seconds, 'new lens', args.rate, children)
    print_diagnostics(monitor)

    say('stopping correct_node and demo_camera with SIGINT ...')
    failed = []
    for child in reversed(children):
        status = child.stop()
        say(f'  {child.name} exited with status {status}')
        if status != 0:
            failed.append(f'{child.name} exited with status {status}; its log:\n{child.tail()}')
    if failed:
        raise DemoError('\n'.join(failed))
    say(f'done: see {out}/summary.png')
    return 0


def print_diagnostics(monitor: Any) -> None:
    """
    Print the node's own summary from /diagnostics.

    :param monitor: the client node.
    """
    with monitor.lock:
        diag, message = dict(monitor.diag), monitor.diag_message
    keys = ('model_revision', 'last_rebuild_ms', 'focal_length_mm', 'distortion_model', 'D',
            'fit_rms_px', 'max_displacement_px', 'frames_in', 'frames_out', 'frames_dropped',
            'frame_time_ms_mean', 'frame_time_ms_max')
    if 'D' in diag:
        try:
            diag['D'] = '[' + ', '.join(f'{d:.5g}' for d in json.loads(diag['D'])) + ']'
        except (ValueError, TypeError):
            pass
    print(f'node diagnostics ({message}):', flush=True)
    print('  ' + ', '.join(f'{k} {diag[k]}' for k in keys if k in diag), flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the demo.

    :param argv: arguments (default ``sys.argv[1:]``).
    :return: 0 on success, 1 on failure, 130 when interrupted.
    """
    args = parse_args(argv)
    missing = {k: v for k, v in MALLOC_ENV.items() if k not in os.environ}
    if missing:
        # glibc reads MALLOC_* at start-up only: restart with them so this process (the
        # subscriber whose latency is measured) runs like the other two.
        os.execve(sys.executable, [sys.executable, '-m', 'mechdeconv_ros.demo',
                                   *(sys.argv[1:] if argv is None else argv)],
                  dict(os.environ, **missing, PYTHONPATH=_pythonpath()))
    interrupted = threading.Event()

    def on_signal(signum: int, frame: Any) -> None:
        if interrupted.is_set():
            return      # already stopping: let the cleanup finish
        interrupted.set()
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    children: list[Child] = []
    status = 1
    try:
        status = run(args, children)
    except KeyboardInterrupt:
        status = 130
    except DemoError as err:
        say(f'error: {err}')
        status = 1
    finally:
        interrupted.set()       # from here on a signal no longer interrupts the cleanup
        if status == 130:
            say('interrupted: stopping the processes ...')
        for child in reversed(children):
            if child.returncode is None:
                child.stop()
    if status == 130:
        say('stopped')
    return status


if __name__ == '__main__':
    sys.exit(main())
