# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``python -m mechdeconv_ros.demo`` (``make demo``): the whole product in half a minute.

1. Starts ``correct_node`` (``--params-file config/case2.yaml``) and ``demo_camera`` (the same
   file: it renders a grid chart through the same Case 2 lens) as two processes, each in its
   own process group, on a private ``ROS_DOMAIN_ID`` with discovery on localhost, the
   shared-memory Fast DDS profile ``config/fastdds_shm.xml`` and the glibc ``MALLOC_*``
   settings (:mod:`mechdeconv_ros.graph_env`; values the caller exported are kept).
2. A client node in this process (:mod:`mechdeconv_ros.demo_monitor`) subscribes
   ``image_rect``, ``camera_info`` and ``/diagnostics``; the demo prints the model and the
   node's diagnostics, then the live throughput and latency (receive time minus
   ``header.stamp``, which the camera sets when it publishes).
3. Writes ``raw.png`` and ``corrected.png``.
4. Changes the lens: ``lens.stop_offset_mm`` and ``lens.thickness_mm`` are set together, first
   on ``demo_camera`` (a physical change of the real lens), then on ``correct_node`` (the user
   telling the node), each through ``<node>/set_parameters_atomically``: one validation and
   one rebuild for the pair (two ``ros2 param set`` calls would apply them one at a time).
   Prints the replies, the time from the node's reply to the first frame corrected by the new
   model (seen as ``camera_info`` D changing) and the rebuild time the node reports.
5. Writes ``raw_after_change.png``, ``corrected_after_change.png`` and ``summary.png`` (the four
   side by side), prints throughput and latency again, stops both processes with SIGINT and
   checks that they exit with status 0.

Ctrl-C at any time stops the children and exits 130. Options: ``--seconds`` (each measuring
window, default 10; also ``MECHDECONV_DEMO_SECONDS``), ``--out`` (default ``demo_out``),
``--stop-offset``/``--thickness`` (the new lens), ``--rate``, ``--domain-id``.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import signal
import sys
import threading
import time
from typing import Any, Sequence

from mechdeconv_ros import graph_env
from mechdeconv_ros.demo_report import (
    DemoError, diagnostics_lines, say, stamp_ns, summary_image, to_bgr, wait_for, window_line,
    write_png)
from mechdeconv_ros.graph_env import Child

#: Seconds to wait for the first corrected frame after starting the processes.
STARTUP_TIMEOUT_S = 30.0


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
    first, last = graph_env.DOMAIN_RANGES['demo']
    parser.add_argument('--domain-id', type=int, default=None,
                        help=f'ROS_DOMAIN_ID of the demo graph (default: one of {first}-{last})')
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
    from mechdeconv_ros.model import build_model, ModelError
    from mechdeconv_ros.params import load_params_file

    try:
        params_file = graph_env.config_file('case2.yaml')
    except FileNotFoundError as err:
        raise DemoError(str(err)) from None
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    domain = graph_env.pick_domain_id('demo') if args.domain_id is None else args.domain_id
    env = graph_env.graph_env(domain, keep_exported=True)

    # The lens before and after, built here too: the summary, and a check of the new values.
    values = load_params_file(params_file)
    change = {'lens.stop_offset_mm': args.stop_offset, 'lens.thickness_mm': args.thickness}
    before = build_model(values, 640, 480)
    try:
        after = build_model({**values, **change}, 640, 480)
    except ModelError as err:
        raise DemoError(f'the new lens describes no usable camera: {err}') from None

    say(f'ROS_DOMAIN_ID={domain}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, '
        f'FASTRTPS_DEFAULT_PROFILES_FILE={env.get(graph_env.PROFILE_VAR)}')
    commands = {
        'correct_node': ['--params-file', str(params_file)],
        'demo_camera': ['--params-file', str(params_file), '-p', f'rate_hz:={args.rate!r}']}
    for name, ros_args in commands.items():
        argv = [sys.executable, '-m', f'mechdeconv_ros.{name}', '--ros-args', *ros_args]
        children.append(Child(argv, env, out / f'{name}.log', die_with_parent=True))
        say(f'started {name} (pid {children[-1].pid}, log {out}/{name}.log)')
    say(f'demo_camera publishes 640x480 rgb8 at {args.rate:g} Hz through the Case 2 lens')

    graph_env.configure_this_process(env)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from mechdeconv_ros.demo_monitor import Monitor

    rclpy.init(args=[], domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    monitor = Monitor()
    executor = SingleThreadedExecutor()
    executor.add_node(monitor)
    spinner = threading.Thread(target=_spin, args=(executor,), name='demo-spin', daemon=True)
    spinner.start()
    try:
        return scenario(args, children, monitor, before, after, change, out)
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


def measure(monitor: Any, seconds: float, label: str, rate_hz: float,
            children: Sequence[Child]) -> None:
    """Print the throughput and latency of image_rect over the next ``seconds``."""
    say(f'measuring image_rect for {seconds:g} s ({label}) ...')
    start = time.monotonic()
    wait_for(lambda: time.monotonic() - start >= seconds, seconds + 5.0, 'end of window',
             children)
    say(window_line(*monitor.window(start, time.monotonic()), rate_hz))


def newest_rect(monitor: Any) -> Any:
    """Return the newest image_rect the monitor received."""
    with monitor.lock:
        return monitor.last_rect


def scenario(args: argparse.Namespace, children: list[Child], monitor: Any, before: Any,
             after: Any, change: dict[str, float], out: Path) -> int:
    """Tell the story: the lens, the correction, the lens change, its reaction; 0 on success."""
    from mechdeconv_ros.cli import format_report

    say('waiting for the first corrected frame on image_rect ...')
    wait_for(lambda: monitor.last_rect is not None, STARTUP_TIMEOUT_S,
             'corrected frame on image_rect', children)
    say('first corrected frame received')
    print('\nmodel (config/case2.yaml, as the node builds it):\n  '
          + format_report(before.report()).replace('\n', '\n  '), flush=True)
    wait_for(lambda: bool(monitor.diag.get('model_revision')), 5.0, 'diagnostics from the node',
             children)
    print(diagnostics_lines(monitor.diag, monitor.diag_message), flush=True)
    time.sleep(1.0)     # warm-up: caches, DDS buffers, the first diagnostics period
    measure(monitor, args.seconds, 'Case 2 lens', args.rate, children)
    raw = to_bgr(monitor.grab_raw(5.0))
    write_png(out / 'raw.png', raw)
    corrected = to_bgr(newest_rect(monitor))
    write_png(out / 'corrected.png', corrected)

    # The lens change: first the real lens (the camera), then the user tells the node.
    say('changing the lens: ' + ', '.join(f'{k} = {v:g}' for k, v in change.items())
        + f" (Case 2: stop offset {before.values['lens.stop_offset_mm']:g} mm, thickness "
        f"{before.values['lens.thickness_mm']:g} mm)")
    result, sent, replied = monitor.set_lens('demo_camera', change, 10.0)
    say(f'  /demo_camera/set_parameters_atomically -> successful={result.successful} '
        f'reason={result.reason!r} ({(replied - sent) * 1e3:.0f} ms: the camera now renders '
        'through the new lens)')
    if not result.successful:
        raise DemoError('demo_camera refused the new lens')
    revision_before = int(monitor.diag.get('model_revision', '0'))
    monitor.watch_d()
    result, sent, replied = monitor.set_lens('correct_node', change, 10.0)
    say(f'  /correct_node/set_parameters_atomically -> successful={result.successful} '
        f'reason={result.reason!r} (reply after {(replied - sent) * 1e3:.1f} ms)')
    if not result.successful:
        raise DemoError('correct_node refused the new lens')
    wait_for(lambda: monitor.d_changed_at is not None, 5.0, 'camera_info with the new D',
             children)
    first_ms = (monitor.d_changed_at - replied) * 1e3
    say(f'  first frame from the new model {first_ms:.1f} ms after the reply '
        f'({first_ms * args.rate / 1e3:.2f} frame periods at {args.rate:g} Hz); camera_info D '
        f"= [{', '.join(f'{d:.5g}' for d in after.D)}]")
    wait_for(lambda: int(monitor.diag.get('model_revision', '0')) > revision_before, 5.0,
             'diagnostics of the new model', children)
    say(f"  node rebuild time (diagnostics last_rebuild_ms): {monitor.diag['last_rebuild_ms']} "
        f"ms, model revision {monitor.diag['model_revision']}")

    time.sleep(0.3)
    raw_after = to_bgr(monitor.grab_raw(5.0))
    write_png(out / 'raw_after_change.png', raw_after)
    rect = newest_rect(monitor)
    if stamp_ns(rect.header.stamp) < (monitor.d_changed_stamp or 0):
        raise DemoError('the newest corrected frame predates the new model')
    corrected_after = to_bgr(rect)
    write_png(out / 'corrected_after_change.png', corrected_after)
    write_png(out / 'summary.png',
              summary_image(raw, corrected, raw_after, corrected_after, before, after))
    measure(monitor, args.seconds, 'new lens', args.rate, children)
    print(diagnostics_lines(monitor.diag, monitor.diag_message), flush=True)

    say('stopping correct_node and demo_camera with SIGINT ...')
    failed = []
    for child in reversed(children):
        status = child.stop(log=say)
        say(f'  {child.name} exited with status {status}')
        if status != 0:
            failed.append(f'{child.name} exited with status {status}; its log:\n'
                          + child.tail(indent='    '))
    if failed:
        raise DemoError('\n'.join(failed))
    say(f'done: see {out}/summary.png')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the demo.

    :param argv: arguments (default ``sys.argv[1:]``).
    :return: 0 on success, 1 on failure, 130 when interrupted.
    """
    args = parse_args(argv)
    missing = {k: v for k, v in graph_env.MALLOC_ENV.items() if k not in os.environ}
    if missing:
        # glibc reads MALLOC_* at start-up only: restart with them so this process (the
        # subscriber whose latency is measured) runs like the other two.
        os.execve(sys.executable, [sys.executable, '-m', 'mechdeconv_ros.demo',
                                   *(sys.argv[1:] if argv is None else argv)],
                  dict(os.environ, **missing, PYTHONPATH=graph_env.python_path()))
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
    finally:
        interrupted.set()       # from here on a signal no longer interrupts the cleanup
        if status == 130:
            say('interrupted: stopping the processes ...')
        for child in reversed(children):
            child.stop(log=say)
    if status == 130:
        say('stopped')
    return status


if __name__ == '__main__':
    sys.exit(main())
