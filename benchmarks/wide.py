# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Speed of aspheric and wide-angle lenses: rebuilds and the per-frame correction at 1920x1080.

Everything runs in one process, in interleaved rounds (:func:`benchmarks.common.interleave`),
two OpenCV threads (the node's default, ``remap_threads: 0``, on a 2-core machine). Lenses:

* **case2**: the paper's thick lens on 4.0625 x 4.4375 um pixels (as ``benchmarks.speed``),
  the reference of the ratios;
* **double Gauss, spherical**: optiland's ``DoubleGauss`` sample (10 refracting surfaces and
  the stop, d-line indices) on 20 um pixels (about 15 deg off axis at the corner);
* **double Gauss, aspheric**: the same with k = -0.1 and a4, a6, a8 on every curved surface,
  so every ray-surface intersection runs the asphere's Newton iteration;
* **fisheye**: Laikin's 170 deg f/1.8 lens (optiland ``WideAngle170FOV``, 17 surfaces) on
  6 um pixels, corners 96 deg off axis, ``output.projection: equidistant``, alpha 1.

Rebuild = ``build_model`` + ``Rectifier`` (what the node does after a parameter set), and
``build_model`` alone (model); the issue's target is a 20 ms median rebuild for the aspheric
10-surface lens. Per frame =
``Rectifier.correct`` into a preallocated output, mono8 and rgb8: a wide field must not slow
it (same maps, same remap).

::

    python -m benchmarks.wide [--quick] [--out results]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from benchmarks.common import bench_main, interleave, log, RESULTS
from benchmarks.report import machine_info, write_json
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import defaults, load_params_file
import numpy as np

REPO = Path(__file__).resolve().parents[1]
SIZE = (1920, 1080)
#: OpenCV threads: the node's default (``remap_threads: 0``, all cores; 2 on the bench machine).
THREADS = 2
#: The issue's rebuild target for a 10-surface aspheric prescription at 1920x1080.
REBUILD_TARGET_MS = 20.0
#: optiland DoubleGauss: (radius, thickness, index after), mm; surface 5 is the stop.
DOUBLE_GAUSS = [(56.20238, 8.75, 1.62229), (152.2858, 0.5, 1.0), (37.68262, 12.5, 1.60738),
                (0.0, 3.8, 1.60342), (24.2313, 16.369445, 1.0), (0.0, 13.747957, 1.0),
                (-28.37731, 3.8, 1.60342), (0.0, 11.0, 1.62041), (-37.92546, 0.5, 1.0),
                (177.41176, 7.0, 1.62041), (-79.41143, 0.0, 1.0)]
#: Laikin's 170 deg lens, inches: (radius, thickness, index after); surface 12 is the stop.
FISHEYE = [(6.0515, 0.1796, 1.5168), (1.2087, 0.9182, 1.0), (-9.4697, 0.1939, 1.5891),
           (1.0053, 0.6402, 1.0), (1.6634, 0.4518, 1.71736), (-1.6712, 0.1825, 1.691),
           (1.1206, 2.5272, 1.0), (1.3895, 0.25, 1.691), (0.5522, 0.6047, 1.55232),
           (-0.8844, 0.0196, 1.0), (-0.8804, 0.08, 1.71736), (-2.1545, 0.12, 1.0),
           (0.0, 0.12, 1.0), (1.0354, 0.483, 1.55232), (-0.8443, 0.0546, 1.0),
           (-0.7386, 0.1076, 1.71736), (-1.5285, 0.8308, 1.0)]


def _prescription(rows: list[tuple[float, float, float]], stop: int, scale: float,
                  pitch_um: float) -> dict[str, Any]:
    values = defaults()
    values.update({
        'lens.surfaces.radius_mm': [r * scale for r, _, _ in rows],
        'lens.surfaces.thickness_mm': [t * scale for _, t, _ in rows],
        'lens.surfaces.refractive_index': [n for _, _, n in rows],
        'lens.stop_surface': stop, 'scene.distance_mm': 0.0,
        'sensor.width_px': SIZE[0], 'sensor.height_px': SIZE[1],
        'sensor.pixel_size_x_um': pitch_um, 'sensor.pixel_size_y_um': pitch_um})
    return values


def lenses() -> dict[str, dict[str, Any]]:
    """Return the parameter sets of the benchmarked lenses by name."""
    case2 = load_params_file(REPO / 'config' / 'case2.yaml')
    case2.update({'sensor.width_px': SIZE[0], 'sensor.height_px': SIZE[1]})
    spherical = _prescription(DOUBLE_GAUSS, 5, 1.0, 20.0)
    curved = [r != 0.0 for r, _, _ in DOUBLE_GAUSS]
    aspheric = dict(spherical, **{
        'lens.surfaces.conic': [-0.1 if c else 0.0 for c in curved],
        'lens.surfaces.asphere_a4': [1e-7 if c else 0.0 for c in curved],
        'lens.surfaces.asphere_a6': [-2e-10 if c else 0.0 for c in curved],
        'lens.surfaces.asphere_a8': [1e-13 if c else 0.0 for c in curved]})
    fisheye = _prescription(FISHEYE, 12, 25.4, 6.0)
    fisheye.update({'output.projection': 'equidistant', 'output.alpha': 1.0})
    return {'case2': case2, 'double Gauss, spherical': spherical,
            'double Gauss, aspheric': aspheric, 'fisheye 170 deg, equidistant': fisheye}


def run(out_dir: Path = RESULTS, quick: bool = False) -> dict[str, Any]:
    """
    Time rebuilds and frames of every lens; write ``wide.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: one round of one call, and no model reports for the log (proves it runs;
        the numbers mean little).
    :return: the results document.
    """
    rounds, reps = (1, 1) if quick else (5, 6)
    sets = lenses()
    models = {}
    for name, values in sets.items():
        model = build_model(values)
        models[name] = model
        # The field angles come from the model's report (its tolerance sigmas and relative
        # illumination: seconds per wide lens), which nothing here times: not when quick.
        field = '' if quick else _field_text(model.report())
        log(f'{name}: {len(model.prescription.surfaces)} surfaces, {field}'
            f'{model.distortion_model} (max error {model.equivalent_max_error_px:.3g} px)')

    def rebuild(values: dict[str, Any]) -> Any:
        return lambda: Rectifier(build_model(values))

    def model_only(values: dict[str, Any]) -> Any:
        return lambda: build_model(values)

    variants = [_variant(f'rebuild {name}', rebuild(values), 'rebuild')
                for name, values in sets.items()]
    variants += [_variant(f'model {name}', model_only(values), 'model')
                 for name, values in sets.items()]
    rng = np.random.default_rng(3)
    for name in ('case2', 'fisheye 170 deg, equidistant'):
        rectifier = Rectifier(models[name])
        for encoding, channels in (('mono8', 1), ('rgb8', 3)):
            shape = (SIZE[1], SIZE[0]) + ((channels,) if channels > 1 else ())
            src = rng.integers(0, 256, shape, dtype=np.uint8)
            dst = np.empty((rectifier.out_shape + shape[2:]), np.uint8)
            variants.append(_variant(f'frame {encoding} {name}',
                                     _frame(rectifier, src, dst), f'frame {encoding}'))
    log(f'timing {len(variants)} variants, {rounds} rounds of {reps} calls')
    timings, others = interleave(variants, rounds, reps, quiet_wait_s=0.0 if quick else 2.0)
    results = {name: t.summary() for name, t in timings.items()}
    reference = results['rebuild case2']['median_ms']
    for name, summary in results.items():
        kind = name.split()[0]
        base = (f'{kind} case2' if kind in ('rebuild', 'model')
                else ' '.join(name.split()[:2]) + ' case2')
        summary['ratio_to_case2'] = summary['median_ms'] / results[base]['median_ms']
    doc = {'machine': machine_info(), 'size': list(SIZE), 'threads': THREADS, 'rounds': rounds,
           'reps': reps,
           'others_cores': others,
           'reference_rebuild_ms': reference, 'target_ms': REBUILD_TARGET_MS,
           'results': results}
    write_json(out_dir / 'wide.json', doc)
    return doc


def _field_text(report: dict[str, Any]) -> str:
    return (f"max field {report['max_field_angle_deg']:.1f} deg, corner "
            f"{report['covered_field']['corner_field_angle_deg']} deg, ")


def _variant(name: str, call: Any, group: str) -> Any:
    from benchmarks.common import Variant
    return Variant(name, call, THREADS, {}, group)


def _frame(rectifier: Rectifier, src: np.ndarray, dst: np.ndarray) -> Any:
    return lambda: rectifier.correct(src, dst)


def tables(doc: dict[str, Any]) -> list[str]:
    """Return the markdown table of a results document."""
    lines = ['Rebuild (build_model + Rectifier) and per-frame correction at '
             f"{doc['size'][0]}x{doc['size'][1]}, {doc['threads']} OpenCV threads, median of "
             f"{doc['rounds']} rounds (target for the aspheric rebuild: "
             f"{doc['target_ms']:g} ms).", '',
             '| what | median ms | min ms | vs case2 |', '|---|---:|---:|---:|']
    for name, s in doc['results'].items():
        lines.append(f"| {name} | {s['median_ms']:.2f} | {s['min_ms']:.2f} | "
                     f"{s['ratio_to_case2']:.2f}x |")
    return lines


def main(argv: list[str] | None = None) -> int:
    """Run from the command line."""
    return bench_main(__doc__ or '', run, tables, 'one round of two calls', argv)


if __name__ == '__main__':
    raise SystemExit(main())
