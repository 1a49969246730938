# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``python -m mechdeconv_ros.tools.demo`` (``make demo``): the whole product in half a minute.

1. Starts ``correct_node`` (``--params-file`` the ``--params`` file, default
   ``config/case2.yaml``) and ``demo_camera`` (the same file: it renders a grid chart through
   the same lens, at the file's ``sensor.width_px`` x ``sensor.height_px`` when both are set,
   else 640 x 480) as two processes, each in its own process group, on a private
   ``ROS_DOMAIN_ID`` with discovery on localhost, the shared-memory Fast DDS profile
   ``config/fastdds_shm.xml`` and the glibc ``MALLOC_*`` settings
   (:mod:`mechdeconv_ros.node.process_env`; values the caller exported are kept).
2. A client node in this process (:mod:`mechdeconv_ros.tools.demo_monitor`) subscribes
   ``image_rect``, ``camera_info`` and ``/diagnostics``; the demo prints the model and the
   node's diagnostics, then the live throughput and latency (receive time minus
   ``header.stamp``, which the camera sets when it publishes).
3. Writes ``raw.png`` and ``corrected.png``.
4. Changes the lens, first on ``demo_camera`` (a physical change of the real lens), then on
   ``correct_node`` (the user telling the node), each through
   ``<node>/set_parameters_atomically``: one validation and one rebuild for the whole change
   (two ``ros2 param set`` calls would apply two values one at a time). A thick lens gets new
   ``lens.stop_offset_mm`` and ``lens.thickness_mm``; a prescription (where those do nothing)
   gets its first air gap 5 % longer (the ``lens.surfaces.thickness_mm`` array), or, if the
   model refuses that, ``output.alpha`` = 1 on the node only (:func:`demo_report.lens_change`).
   Prints the replies, the time from the node's reply to the first frame corrected by the new
   model (seen as ``camera_info`` D changing) and the rebuild time the node reports.
5. Writes ``raw_after_change.png``, ``corrected_after_change.png`` and ``summary.png`` (the four
   side by side), prints throughput and latency again, stops both processes with SIGINT and
   checks that they exit with status 0.

Ctrl-C at any time stops the children and exits 130. Options: ``--params`` (the params
file), ``--seconds`` (each measuring window, default 10; also ``MECHDECONV_DEMO_SECONDS``),
``--out`` (default ``demo_out``), ``--stop-offset``/``--thickness`` (the new thick lens),
``--rate``, ``--domain-id``, and
``--transport compressed``: the camera then publishes JPEG frames on ``image_raw/compressed``
(``demo_camera`` ``transport:=compressed``) and the node decodes them
(``image_transport:=compressed``); the decode time shows in the node's diagnostics.
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

from mechdeconv_ros.node import process_env
from mechdeconv_ros.node.process_env import Child
from mechdeconv_ros.tools.demo_report import (
    DemoError, diagnostics_lines, in_background, lens_change, measure, newest_rect, say, stamp_ns,
    stop_children, summary_image, to_bgr, wait_for, write_png)
from mechdeconv_ros.tools.demo_sweep import sweep_scenario

#: Seconds to wait for the first corrected frame after starting the processes.
STARTUP_TIMEOUT_S = 30.0


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """
    Parse the command line.

    :param argv: arguments (default ``sys.argv[1:]``).
    :return: the options.
    """
    parser = argparse.ArgumentParser(
        prog='python -m mechdeconv_ros.tools.demo',
        description='Run correct_node and a simulated camera, change the lens live, measure.')
    parser.add_argument('--params', type=Path, default=None,
                        help='ROS 2 params file of the lens (default: config/case2.yaml)')
    parser.add_argument('--seconds', type=float,
                        default=float(os.environ.get('MECHDECONV_DEMO_SECONDS', '10')),
                        help='length of each measuring window (default 10 s; '
                             'env MECHDECONV_DEMO_SECONDS)')
    parser.add_argument('--out', type=Path, default=Path('demo_out'),
                        help='folder for the PNGs and the process logs (default demo_out)')
    parser.add_argument('--stop-offset', type=float, default=0.6,
                        help='new lens.stop_offset_mm of a thick lens (default 0.6; Case 2 '
                             'has 0.2)')
    parser.add_argument('--thickness', type=float, default=4.0,
                        help='new lens.thickness_mm of a thick lens (default 4.0; Case 2 '
                             'has 3.0)')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate in Hz (30)')
    parser.add_argument('--transport', choices=('raw', 'compressed'), default='raw',
                        help='raw: image_raw (default); compressed: the camera publishes JPEG '
                             'on image_raw/compressed and the node decodes it')
    first, last = process_env.DOMAIN_RANGES['demo']
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
    from mechdeconv_ros.model.model import build_model, ModelError
    from mechdeconv_ros.schema.params import load_params_file

    try:
        params_file = (process_env.config_file('case2.yaml') if args.params is None
                       else args.params.resolve(strict=True))
        values = load_params_file(params_file)
    except (OSError, ValueError) as err:
        raise DemoError(f'--params: {err}') from None
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    domain = process_env.pick_domain_id('demo') if args.domain_id is None else args.domain_id
    env = process_env.graph_env(domain, keep_exported=True)

    # The lens before and after, built here too: the summary, and a check of the new values.
    width, height = int(values['sensor.width_px']), int(values['sensor.height_px'])
    if not (width and height):
        width, height = 640, 480
    try:
        before = build_model(values, width, height)
    except ModelError as err:
        raise DemoError(f'{params_file} describes no usable camera: {err}') from None
    moving = getattr(before.source, 'moving', ())
    if moving:
        # Issue 19: the lens moves by itself; the story is the sweep, not a parameter set.
        change, after, change_text, report = {}, before, '', None
    else:
        report = in_background(before.report)   # seconds of tracing, beside the children's start
        change, after, change_text = lens_change(values, width, height, args.stop_offset,
                                                 args.thickness)

    say(f'ROS_DOMAIN_ID={domain}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, '
        f'FASTRTPS_DEFAULT_PROFILES_FILE={env.get(process_env.PROFILE_VAR)}')
    modules = {'correct_node': 'mechdeconv_ros.node.entry',
               'demo_camera': 'mechdeconv_ros.tools.demo_camera'}
    commands = {
        'correct_node': ['--params-file', str(params_file),
                         '-p', f'image_transport:={args.transport}'],
        'demo_camera': ['--params-file', str(params_file), '-p', f'rate_hz:={args.rate!r}',
                        '-p', f'transport:={args.transport}', '-p', f'width:={width}',
                        '-p', f'height:={height}']}
    for name, ros_args in commands.items():
        argv = [sys.executable, '-m', modules[name], '--ros-args', *ros_args]
        children.append(Child(argv, env, out / f'{name}.log', die_with_parent=True))
        say(f'started {name} (pid {children[-1].pid}, log {out}/{name}.log)')
    topic = 'image_raw' if args.transport == 'raw' else 'image_raw/compressed (JPEG)'
    say(f'demo_camera publishes {width}x{height} rgb8 on {topic} at {args.rate:g} Hz through '
        f'the lens of {params_file.name}')

    process_env.configure_this_process(env)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from mechdeconv_ros.tools.demo_monitor import Monitor, spin

    rclpy.init(args=[], domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    monitor = Monitor(args.transport)
    executor = SingleThreadedExecutor()
    executor.add_node(monitor)
    spinner = threading.Thread(target=spin, args=(executor,), name='demo-spin', daemon=True)
    spinner.start()
    try:
        if moving:
            return sweep_scenario(args, children, monitor, before, params_file, out)
        return scenario(args, children, monitor, (before, after, change, change_text),
                        params_file, out, report)
    finally:
        # The spin thread ends before the node it spins is destroyed.
        executor.shutdown(timeout_sec=2.0)
        spinner.join(timeout=2.0)
        monitor.destroy_node()
        rclpy.try_shutdown()


def scenario(args: argparse.Namespace, children: list[Child], monitor: Any,
             lens: tuple[Any, Any, dict[str, Any], str], params_file: Path, out: Path,
             report: Any) -> int:
    """Tell the story: the lens, the correction, the lens change, its reaction; 0 on success."""
    from mechdeconv_ros.tools.cli import format_report
    before, after, change, change_text = lens

    say('waiting for the first corrected frame on image_rect ...')
    wait_for(lambda: monitor.last_rect is not None, STARTUP_TIMEOUT_S,
             'corrected frame on image_rect', children)
    say('first corrected frame received')
    print(f'\nmodel ({params_file.name}, {before.width}x{before.height}, as the node builds '
          'it):\n  ' + format_report(report()).replace('\n', '\n  '), flush=True)
    wait_for(lambda: bool(monitor.diag.get('model_revision')), 5.0, 'diagnostics from the node',
             children)
    print(diagnostics_lines(monitor.diag, monitor.diag_message), flush=True)
    time.sleep(1.0)     # warm-up: caches, DDS buffers, the first diagnostics period
    measure(monitor, args.seconds, f'lens of {params_file.name}', args.rate, children)
    raw = to_bgr(monitor.grab_raw(5.0))
    write_png(out / 'raw.png', raw)
    corrected = to_bgr(newest_rect(monitor))
    write_png(out / 'corrected.png', corrected)

    # The lens change: first the real lens (the camera), then the user tells the node.
    say(f'changing the lens: {change_text}')
    if 'output.alpha' in change:
        say('  demo_camera keeps its lens (output.alpha is how the node corrects, not the lens)')
    else:
        result, sent, replied = monitor.set_lens('demo_camera', change, 20.0)
        say(f'  /demo_camera/set_parameters_atomically -> successful={result.successful} '
            f'reason={result.reason!r} ({(replied - sent) * 1e3:.0f} ms: the camera now renders '
            'through the new lens)')
        if not result.successful:
            raise DemoError('demo_camera refused the new lens')
    revision_before = int(monitor.diag.get('model_revision', '0'))
    monitor.watch_d()
    result, sent, replied = monitor.set_lens('correct_node', change, 20.0)
    say(f'  /correct_node/set_parameters_atomically -> successful={result.successful} '
        f'reason={result.reason!r} (reply after {(replied - sent) * 1e3:.1f} ms)')
    if not result.successful:
        raise DemoError('correct_node refused the new lens')
    if tuple(after.D) == tuple(before.D):   # output.alpha: K and P change, D does not
        say('  camera_info D unchanged: no first-frame time for this change')
    else:
        wait_for(lambda: monitor.d_changed_at is not None, 5.0, 'camera_info with the new D',
                 children)
        first_ms = (monitor.d_changed_at - replied) * 1e3
        say(f'  first frame from the new model {first_ms:.1f} ms after the reply '
            f'({first_ms * args.rate / 1e3:.2f} frame periods at {args.rate:g} Hz); '
            f"camera_info D = [{', '.join(f'{d:.5g}' for d in after.D)}]")
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

    stop_children(children)
    say(f'done: see {out}/summary.png')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the demo.

    :param argv: arguments (default ``sys.argv[1:]``).
    :return: 0 on success, 1 on failure, 130 when interrupted.
    """
    args = parse_args(argv)
    missing = {k: v for k, v in process_env.MALLOC_ENV.items() if k not in os.environ}
    if missing:
        # glibc reads MALLOC_* at start-up only: restart with them so this process (the
        # subscriber whose latency is measured) runs like the other two.
        os.execve(sys.executable, [sys.executable, '-m', 'mechdeconv_ros.tools.demo',
                                   *(sys.argv[1:] if argv is None else argv)],
                  dict(os.environ, **missing, PYTHONPATH=process_env.python_path()))
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
