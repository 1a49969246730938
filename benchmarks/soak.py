# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The long run: correct_node at full rate for minutes, its memory sampled every second.

``python -m benchmarks.soak --minutes 10`` (``--minutes 1`` for a short run while developing).

Three processes, with the environment of :func:`benchmarks.node_latency.ros_env` (the package's
Fast DDS profile, the Makefile's ``MALLOC_*`` settings, discovery on localhost) and a private
``ROS_DOMAIN_ID`` (the soak's range of :data:`mechdeconv_ros.node.process_env.DOMAIN_RANGES`):

* the publisher of :mod:`benchmarks.node_latency` (``--role publisher``): one 1280x720 rgb8
  frame, paced at 30 Hz, stamped with the wall clock;
* the node under test, as ``ros2 run`` starts it with ``config/case2.yaml`` (sensor size from
  the frames);
* this process: subscribes to ``image_rect`` (raw CDR, stamps only), ``camera_info`` and
  ``/diagnostics``, and every ``--set-every`` seconds sets ``lens.stop_offset_mm`` to the other
  of 0.2 and 0.3 mm through ``/correct_node/set_parameters`` (so the run also rebuilds the
  model and its maps, and checks that the next frames carry the new model).

Every second it samples the node process with psutil: resident memory (RSS), CPU, threads and
open file descriptors; and the frames received in that second with their latency (receive
time - header stamp, publisher -> node -> here).

Memory growth is judged after warm-up, as the brief of issue #6 asks: a least-squares line is
fitted to the RSS samples of the second half of the run; its slope (MiB/min), the slope's
standard error and the residual noise are reported. The run is *flat* when the growth the slope
predicts over that half, ``|slope| x minutes``, is within three residual standard deviations or
1 MiB, whichever is larger (RSS moves in pages and allocator arenas, not bytes).

Writes ``results/soak_<N>min.json`` (every sample) and ``results/soak_rss.png`` (RSS over time
with the fitted line; ``soak_rss_<N>min.png`` for runs shorter than 10 minutes, so a short
development run does not overwrite the figure of the full one). Exit code 0 when every process
exited with 0, every parameter set was accepted and reached the frames, and the memory is flat.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
import statistics
import sys
import tempfile
import time
from typing import Any, Sequence

from benchmarks.common import LoadMonitor, log, RESULTS
from benchmarks.node_latency import node_argv, Probe, publisher_argv, ros_env, start_child
from benchmarks.report import machine_info, soak_plot, soak_report, write_json
from mechdeconv_ros.node.process_env import Child, configure_this_process, pick_domain_id

WIDTH, HEIGHT, RATE_HZ = 1280, 720, 30.0
SET_EVERY_S = 30.0
SET_VALUES = (0.3, 0.2)
#: A figure for the full run; shorter runs get their own name.
FULL_RUN_MIN = 10.0
READY_TIMEOUT_S = 20.0
FLAT_MIN_MIB = 1.0
FLAT_NOISE_SIGMAS = 3.0


def fit_line(t_min: Sequence[float], y: Sequence[float]) -> dict[str, float]:
    """
    Fit ``y = a + b t`` by least squares.

    :param t_min: times, minutes.
    :param y: values.
    :return: ``slope`` (per minute), its standard error ``slope_se``, ``intercept`` and the
        residual standard deviation ``residual_std``; NaN where fewer than 3 points.
    """
    n = len(t_min)
    if n < 3:
        return {'slope': math.nan, 'slope_se': math.nan, 'intercept': math.nan,
                'residual_std': math.nan}
    mt, my = statistics.fmean(t_min), statistics.fmean(y)
    sxx = sum((t - mt) ** 2 for t in t_min)
    slope = sum((t - mt) * (v - my) for t, v in zip(t_min, y)) / sxx
    intercept = my - slope * mt
    residuals = [v - (intercept + slope * t) for t, v in zip(t_min, y)]
    rss = sum(r * r for r in residuals)
    residual_std = math.sqrt(rss / (n - 2))
    return {'slope': slope, 'slope_se': residual_std / math.sqrt(sxx), 'intercept': intercept,
            'residual_std': residual_std}


def memory_verdict(samples: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """
    Judge the RSS of the second half of the run.

    :param samples: the per-second samples (``t_s``, ``rss_mib``).
    :return: the fit, the growth it predicts over the half, the noise and ``flat``.
    """
    end = samples[-1]['t_s']
    half = [s for s in samples if s['t_s'] >= end / 2.0]
    fit = fit_line([s['t_s'] / 60.0 for s in half], [s['rss_mib'] for s in half])
    minutes = (half[-1]['t_s'] - half[0]['t_s']) / 60.0 if half else 0.0
    growth = fit['slope'] * minutes
    allowed = max(FLAT_MIN_MIB, FLAT_NOISE_SIGMAS * fit['residual_std'])
    return {
        'window_s': [half[0]['t_s'], half[-1]['t_s']] if half else None,
        'samples': len(half),
        'slope_mib_per_min': fit['slope'],
        'slope_se_mib_per_min': fit['slope_se'],
        'intercept_mib': fit['intercept'],
        'residual_std_mib': fit['residual_std'],
        'growth_over_window_mib': growth,
        'allowed_growth_mib': allowed,
        'rss_min_mib': min(s['rss_mib'] for s in half) if half else math.nan,
        'rss_max_mib': max(s['rss_mib'] for s in half) if half else math.nan,
        'flat': bool(abs(growth) <= allowed),
    }


class SoakProbe(Probe):
    """
    The node_latency probe, recording every frame for the whole run.

    It keeps only the newest camera_info D and diagnostics (a 10-minute run would otherwise
    hold every message), and waits against monotonic deadlines rather than timeouts.
    """

    def __init__(self, domain_id: int) -> None:
        """Create the probe (context, node, subscriptions, parameter client)."""
        super().__init__(domain_id, name='soak_probe')
        self.recording = True
        self.last_d: tuple[float, ...] | None = None
        self.infos = 0          # type: ignore[assignment] - a count here, not a list
        self.diagnostics = {}   # type: ignore[assignment] - the newest status here

    def _on_info(self, msg: Any) -> None:
        self.last_d = tuple(float(v) for v in msg.d)
        self.infos += 1

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if 'lens correction' in status.name:
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def spin_until_deadline(self, predicate: Any, deadline: float) -> bool:
        """Spin until ``predicate()`` or the monotonic ``deadline``; return the predicate."""
        while not predicate():
            if time.monotonic() >= deadline:
                return bool(predicate())
            self.executor.spin_once(timeout_sec=min(0.02, max(0.0, deadline -
                                                              time.monotonic())))
        return True

    def set_stop_offset(self, value: float, timeout: float = 5.0) -> dict[str, Any]:
        """
        Set ``lens.stop_offset_mm``; wait for the reply and the first frame of the new model.

        :return: the value, whether it was accepted, the reply time and the time from the reply
            to the first camera_info with a new D (the stream keeps being recorded meanwhile).
        """
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        old_d = self.last_d
        infos = self.infos
        request = SetParameters.Request(
            parameters=[Parameter('lens.stop_offset_mm', value=float(value)).to_parameter_msg()])
        start = time.monotonic()
        future = self.set_client.call_async(request)
        out: dict[str, Any] = {'value': value}
        if not self.spin_until_deadline(future.done, start + timeout):
            out['error'] = 'no reply'
            return out
        replied = time.monotonic()
        result = future.result().results[0]
        out.update({'accepted': bool(result.successful), 'reason': result.reason,
                    'reply_ms': (replied - start) * 1e3})
        if result.successful and self.spin_until_deadline(
                lambda: self.infos > infos and self.last_d != old_d, replied + timeout):
            out['reply_to_new_model_ms'] = (time.monotonic() - replied) * 1e3
        elif result.successful:
            out['error'] = 'no frame of the new model'
        return out


def _percentile(values: Sequence[float], q: float) -> float:
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100.0 * (len(ordered) - 1))))]


def run(minutes: float, out_dir: Path, set_every_s: float = SET_EVERY_S,
        width: int = WIDTH, height: int = HEIGHT, rate_hz: float = RATE_HZ) -> dict[str, Any]:
    """
    Run the soak and write its JSON and figure.

    :param minutes: how long to stream.
    :param out_dir: the results folder.
    :param set_every_s: seconds between two parameter sets (0: none).
    :param width: frame width.
    :param height: frame height.
    :param rate_hz: publisher rate.
    :return: the results document.
    """
    import psutil

    domain = pick_domain_id('soak')
    env = ros_env(domain, 'shm')
    # This process's own participant must use the same transport profile (read once, at the
    # first participant of the process).
    configure_this_process(env)
    tag = f'{minutes:g}min'
    log_dir = Path(tempfile.mkdtemp(prefix='mechdeconv_soak_'))
    doc: dict[str, Any] = {
        'benchmark': 'soak', 'minutes': minutes, 'width': width, 'height': height,
        'encoding': 'rgb8', 'rate_hz': rate_hz, 'set_every_s': set_every_s,
        'domain_id': domain, 'log_dir': str(log_dir), 'machine': machine_info(),
        'env': {k: env.get(k) for k in ('FASTRTPS_DEFAULT_PROFILES_FILE',
                                        'MALLOC_MMAP_THRESHOLD_', 'MALLOC_TRIM_THRESHOLD_')},
        'samples': [], 'sets': [], 'exit_codes': {}, 'errors': []}
    node = start_child(node_argv('node'), env, log_dir, 'correct_node')
    probe = SoakProbe(domain)
    pub: Child | None = None
    try:
        ready_by = time.monotonic() + READY_TIMEOUT_S
        if not probe.spin_until_deadline(
                lambda: probe.node.count_subscribers('/image_raw') > 0, ready_by):
            raise RuntimeError(f'correct_node not ready: {node.tail()}')
        pub = start_child(publisher_argv(width, height, rate_hz), env, log_dir, 'publisher')
        if not probe.spin_until_deadline(lambda: bool(probe.frames),
                                         time.monotonic() + READY_TIMEOUT_S):
            raise RuntimeError(f'no frame: {node.tail()}')
        proc = psutil.Process(node.pid)
        monitor = LoadMonitor(lambda: time.process_time() + node.cpu_s() + pub.cpu_s())
        start = time.monotonic()
        cpu_before = node.cpu_s()
        seen = len(probe.frames)
        next_set = start + set_every_s if set_every_s > 0 else math.inf
        set_index = 0
        tick = 1
        log(f'soak: {minutes:g} min of {width}x{height} rgb8 at {rate_hz:g} Hz; logs in '
            f'{log_dir}')
        while time.monotonic() - start < minutes * 60.0:
            now = time.monotonic()
            if now >= next_set:
                result = probe.set_stop_offset(SET_VALUES[set_index % len(SET_VALUES)])
                result['t_s'] = now - start
                doc['sets'].append(result)
                set_index += 1
                next_set = max(next_set + set_every_s, time.monotonic())
            probe.spin_until_deadline(lambda: False, min(next_set, start + tick))
            if time.monotonic() < start + tick:
                continue
            if not node.running():
                doc['errors'].append(f'correct_node exited: {node.tail()}')
                break
            frames = probe.frames[seen:]
            seen = len(probe.frames)
            latency = [(r - s) * 1e-6 for r, s in frames]
            cpu = node.cpu_s()
            memory = proc.memory_info()
            sample = {
                't_s': time.monotonic() - start,
                'rss_mib': memory.rss / 2 ** 20,
                'node_cores': cpu - cpu_before,
                'threads': proc.num_threads(),
                'fds': proc.num_fds(),
                'fps_out': len(frames),
                'latency_p50_ms': _percentile(latency, 50),
                'latency_p99_ms': _percentile(latency, 99),
            }
            cpu_before = cpu
            doc['samples'].append(sample)
            if tick % 60 == 0:
                log(f'soak: {tick // 60} min, RSS {sample["rss_mib"]:.1f} MiB, '
                    f'{sample["fps_out"]} fps, p50 {sample["latency_p50_ms"]:.1f} ms, '
                    f'{len(doc["sets"])} parameter sets')
            tick += 1
        doc['others_cores'] = monitor.others_cores()
        doc['diagnostics_at_end'] = dict(probe.diagnostics)
        all_latency = [(r - s) * 1e-6 for r, s in probe.frames]
        doc['frames_received'] = len(probe.frames)
        doc['latency_ms'] = {'p50': _percentile(all_latency, 50),
                             'p99': _percentile(all_latency, 99),
                             'max': max(all_latency) if all_latency else math.nan}
    except Exception as err:        # noqa: B902 - recorded; the processes are still stopped
        doc['errors'].append(f'{type(err).__name__}: {err}')
    finally:
        probe.close()
        for name, proc_ in (('publisher', pub), ('correct_node', node)):
            if proc_ is not None:
                code = proc_.stop()
                doc['exit_codes'][name] = code
                if code != 0 or proc_.killed:
                    doc['errors'].append(f'{name} exited with {code}: {proc_.tail()}')
        doc['node_stderr_tail'] = node.tail(5)
        if 'Traceback' in node.stderr():
            doc['errors'].append('Traceback in the node log')
    summarize(doc)
    write_json(out_dir / f'soak_{tag}.json', doc)
    if doc['samples']:
        name = 'soak_rss.png' if minutes >= FULL_RUN_MIN else f'soak_rss_{tag}.png'
        doc['figure'] = str(soak_plot(doc, out_dir / name))
    return doc


def summarize(doc: dict[str, Any]) -> None:
    """Add the summary (memory verdict, rates, thread and descriptor counts) to ``doc``."""
    samples = doc['samples']
    if len(samples) < 6:
        doc['errors'].append(f'only {len(samples)} samples')
        doc['ok'] = False
        return
    memory = memory_verdict(samples)
    half = [s for s in samples if s['t_s'] >= samples[-1]['t_s'] / 2.0]
    doc['summary'] = {
        'seconds': samples[-1]['t_s'],
        'rss_mib': {'first': samples[0]['rss_mib'],
                    'after_1_min': next((s['rss_mib'] for s in samples if s['t_s'] >= 60.0),
                                        math.nan),
                    'at_half': half[0]['rss_mib'], 'end': samples[-1]['rss_mib'],
                    'max': max(s['rss_mib'] for s in samples)},
        'memory_second_half': memory,
        'threads': {'min': min(s['threads'] for s in samples),
                    'max': max(s['threads'] for s in samples),
                    'second_half': sorted({s['threads'] for s in half})},
        'fds': {'min': min(s['fds'] for s in samples), 'max': max(s['fds'] for s in samples),
                'second_half': sorted({s['fds'] for s in half})},
        'fps_out_mean': statistics.fmean(s['fps_out'] for s in samples),
        'fps_out_min': min(s['fps_out'] for s in samples),
        'node_cores_mean': statistics.fmean(s['node_cores'] for s in samples),
        'sets': len(doc['sets']),
        'sets_reaching_frames': sum('reply_to_new_model_ms' in s for s in doc['sets']),
    }
    bad_sets = [s for s in doc['sets'] if not s.get('accepted') or 'error' in s]
    if bad_sets:
        doc['errors'].append(f'{len(bad_sets)} parameter sets failed: {bad_sets[:3]}')
    if len(doc['summary']['fds']['second_half']) > 3:
        doc['errors'].append(f"open descriptors drift: {doc['summary']['fds']}")
    doc['ok'] = bool(memory['flat'] and not doc['errors'])


def main(argv: list[str] | None = None) -> int:
    """Run the soak from the command line; exit 0 when it held."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--minutes', type=float, default=FULL_RUN_MIN)
    parser.add_argument('--set-every', type=float, default=SET_EVERY_S,
                        help='seconds between two parameter sets (0: none)')
    parser.add_argument('--width', type=int, default=WIDTH)
    parser.add_argument('--height', type=int, default=HEIGHT)
    parser.add_argument('--rate', type=float, default=RATE_HZ)
    parser.add_argument('--out', type=Path, default=RESULTS, help='results folder')
    parser.add_argument('--replot', type=Path, metavar='JSON',
                        help='redraw the figure of a finished run from its JSON, run nothing')
    args = parser.parse_args(argv)
    if args.replot:
        import json
        doc = json.loads(args.replot.read_text())
        name = ('soak_rss.png' if doc['minutes'] >= FULL_RUN_MIN
                else f"soak_rss_{doc['minutes']:g}min.png")
        print(soak_plot(doc, args.replot.parent / name))
        print(soak_report(doc))
        return 0 if doc.get('ok') else 1
    doc = run(args.minutes, args.out, args.set_every, args.width, args.height, args.rate)
    print(soak_report(doc))
    return 0 if doc.get('ok') else 1


if __name__ == '__main__':
    sys.exit(main())
