# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Cost and accuracy of the vignetting correction (relative illumination traced through the lens).

Everything runs in one process, in interleaved rounds (:func:`benchmarks.common.interleave`).

* **Rebuild** at 1920x1080, ``build_model`` + ``Rectifier`` with ``output.vignetting_correction``
  false (today's rebuild) and true (plus the traced RI curve and the gain map), for the Case 2
  thick lens (``config/case2.yaml``, sensor size from the frame, as :mod:`benchmarks.speed`) and
  a 10-surface prescription (Smith's F/1.25 double Gauss, "Modern Lens Design" p. 304, with an
  11th flat dummy surface carrying the stop). Target: with / without <= 2.
* **Per frame**, 1280x720 and 1920x1080, rgb8 and mono8: ``Rectifier.correct`` without the
  gain (the remap alone), the gain alone (``cv2.multiply`` of the remapped frame by the float32
  gain map, in place, saturating) and both. Target: gain <= remap.
* **Accuracy**: the traced RI against the independent flux counts of
  :mod:`mechdeconv_ros.optics.illumination` (``forward_flux``: rays uniform over the scene and an
  entrance disk; ``stop_flux``: uniform over the stop and its direction cosines), as annulus
  means, in percentage points of the on-axis irradiance. Target: 0.5.
"""

from __future__ import annotations

from pathlib import Path
import sys
import time
from typing import Any, Mapping

from benchmarks.common import bench_main, interleave, log, RESULTS, Variant
from benchmarks.report import machine_info, markdown_table, write_json
from benchmarks.speed import case2_values
import cv2
from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.optics import illumination as il
from mechdeconv_ros.optics.raytrace import image_plane
from mechdeconv_ros.schema.params import load_params_file, scene_distance
import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: Smith, Modern Lens Design (1992) p. 304: F/1.25 double Gauss, EFL 100 mm, half field
#: 12.4 deg (US 2,771,006); indices at d, semi-apertures as published. Surface 5 is the stop;
#: ``lens.aperture_diameter_mm`` is its physical diameter: 44 mm, just inside the 44.34 mm
#: that the published clear apertures pass on axis (f/1.43 here).
DOUBLE_GAUSS = {
    'lens.surfaces.radius_mm': [93.32, 358.29, 46.32, 0.0, 28.68, 0.0, -41.32, 60.8, -55.0,
                                90.2, -212.58],
    'lens.surfaces.thickness_mm': [11.32, 0.4, 20.0, 2.0, 14.0, 10.0, 6.0, 22.0, 13.0, 16.0,
                                   0.0],
    'lens.surfaces.refractive_index': [1.717, 1.0, 1.643, 1.589, 1.0, 1.0, 1.762, 1.744, 1.0,
                                       1.717, 1.0],
    'lens.surfaces.semi_diameter_mm': [40.0, 40.0, 36.0, 36.0, 24.5, 24.3, 24.0, 30.0, 30.0,
                                       28.0, 28.0],
    'lens.stop_surface': 5, 'lens.aperture_diameter_mm': 44.0, 'scene.distance_mm': 0.0,
    'sensor.pixel_size_x_um': 18.0, 'sensor.pixel_size_y_um': 18.0,
    'sensor.width_px': 0, 'sensor.height_px': 0,
}
#: A retrofocus wide-angle lens (f = 10.9 mm, 85 deg diagonal on 16 x 12 mm) whose front
#: element's rim clips the corner beams: a negative meniscus, a positive doublet-like pair,
#: the stop on a flat dummy surface, a positive rear element. test/test_illumination.py
#: traces it too.
WIDE = {
    'lens.surfaces.radius_mm': [40.0, 11.0, 30.0, -60.0, 0.0, 40.0, -14.0],
    'lens.surfaces.thickness_mm': [2.0, 14.0, 5.0, 4.0, 4.0, 5.0, 0.0],
    'lens.surfaces.refractive_index': [1.6, 1.0, 1.7, 1.0, 1.0, 1.6, 1.0],
    'lens.surfaces.semi_diameter_mm': [18.0, 9.5, 7.0, 6.0, 0.0, 6.0, 7.0],
    'lens.stop_surface': 4, 'lens.aperture_diameter_mm': 6.0, 'scene.distance_mm': 0.0,
    'sensor.width_px': 1600, 'sensor.height_px': 1200,
    'sensor.pixel_size_x_um': 10.0, 'sensor.pixel_size_y_um': 10.0,
}
REBUILD_SIZE = (1920, 1080)
FRAME_SIZES = ((1280, 720), (1920, 1080))
ENCODINGS = {'rgb8': 3, 'mono8': 1}
#: with / without correction, rebuild; gain / remap, per frame.
REBUILD_RATIO_TARGET = 2.0
FRAME_RATIO_TARGET = 1.0
AGREEMENT_TARGET_PTS = 0.5


def _lenses() -> dict[str, dict[str, Any]]:
    double_gauss = load_params_file(REPO / 'config' / 'case2.yaml')
    double_gauss.update(DOUBLE_GAUSS)
    return {'case2 (thick lens)': case2_values(), 'double Gauss (11 surfaces)': double_gauss}


def rebuilds(rounds: int, reps: int, quiet: float) -> dict[str, Any]:
    """Time the rebuild with and without the correction, per lens, interleaved."""
    width, height = REBUILD_SIZE
    variants = []
    for lens, values in _lenses().items():
        for on in (False, True):
            vals = dict(values, **{'output.vignetting_correction': on})
            variants.append(Variant(f'{lens} {"with" if on else "without"}',
                                    lambda v=vals: Rectifier(build_model(v, width, height)),
                                    1, {'lens': lens, 'correction': on}, group=lens))
        vals = dict(values, **{'output.vignetting_correction': True})
        variants.append(Variant(f'{lens} RI curve only',
                                lambda v=vals: build_model(v, width, height).illumination(
                                    with_fraction=False),
                                1, {'lens': lens, 'correction': 'ri_only'}, group=lens))
    timings, others = interleave(variants, rounds, reps, quiet)
    out: dict[str, Any] = {'size': f'{width}x{height}', 'others_cores': others, 'lenses': {}}
    for lens, values in _lenses().items():
        off = timings[f'{lens} without'].summary()
        on = timings[f'{lens} with'].summary()
        ri = timings[f'{lens} RI curve only'].summary()
        model = build_model(dict(values, **{'output.vignetting_correction': True}), width,
                            height)
        curve = model.illumination()
        out['lenses'][lens] = {
            'without_ms': off, 'with_ms': on, 'ri_and_model_ms': ri,
            'ratio_median': on['median_ms'] / off['median_ms'],
            'ratio_min': on['min_ms'] / off['min_ms'],
            'surfaces': len(model.prescription.surfaces),
            'corner_ri': curve.corner_ri,
            'target_met': bool(on['median_ms'] / off['median_ms'] <= REBUILD_RATIO_TARGET)}
        log(f'vignetting: rebuild {lens}: {off["median_ms"]:.3g} -> {on["median_ms"]:.3g} ms '
            f'(x{on["median_ms"] / off["median_ms"]:.2f})')
    return out


def frames(rounds: int, reps: int, quiet: float, sizes=FRAME_SIZES) -> dict[str, Any]:
    """Time the remap, the gain and both per frame, interleaved."""
    values = dict(case2_values(), **{'output.vignetting_correction': True})
    out: dict[str, Any] = {}
    rng = np.random.default_rng(0)
    for width, height in sizes:
        rect = Rectifier(build_model(values, width, height))
        for encoding, channels in ENCODINGS.items():
            shape = (height, width, channels) if channels > 1 else (height, width)
            src = rng.integers(0, 256, shape, dtype=np.uint8)
            dst = np.empty(rect.out_shape + shape[2:], np.uint8)
            gain = rect.gain_for(channels)
            variants = [
                Variant('remap', lambda s=src, d=dst: rect.correct(s, d, gain=False), 1),
                Variant('gain', lambda d=dst, g=gain: cv2.multiply(d, g, dst=d,
                                                                   dtype=cv2.CV_8U), 1),
                Variant('remap+gain', lambda s=src, d=dst: rect.correct(s, d), 1),
            ]
            timings, others = interleave(variants, rounds, reps, quiet)
            result = {name: t.summary() for name, t in timings.items()}
            ratio = result['gain']['median_ms'] / result['remap']['median_ms']
            result.update({'gain_over_remap_median': ratio,
                           'gain_over_remap_min': result['gain']['min_ms']
                           / result['remap']['min_ms'],
                           'others_cores': others,
                           'target_met': bool(ratio <= FRAME_RATIO_TARGET)})
            out[f'{width}x{height} {encoding}'] = result
            log(f'vignetting: frame {width}x{height} {encoding}: remap '
                f'{result["remap"]["median_ms"]:.3g} ms, gain {result["gain"]["median_ms"]:.3g}'
                f' ms (x{ratio:.2f})')
    return out


def agreement(rays: int, configs: tuple[str, ...] = ('wide_angle', 'fisheye')
              ) -> dict[str, Any]:
    """
    Compare the traced RI with the flux counts, per lens, in percentage points.

    :param rays: rays of each flux count.
    :param configs: the wide ``config/*.yaml`` lenses counted too (their traced RI costs
        seconds each; test/test_illumination.py checks them with 1.5 million rays).
    :return: the figures by lens.
    """
    config = REPO / 'config'
    clipped = load_params_file(config / 'cooke_triplet.yaml')
    clipped.update({'sensor.width_px': 3600, 'sensor.height_px': 2400})
    clipped['lens.surfaces.semi_diameter_mm'][0] = 8.0
    clipped['lens.surfaces.semi_diameter_mm'][5] = 6.8
    wide = load_params_file(config / 'case2.yaml')
    wide.update(WIDE)
    cases = {
        'case2': (load_params_file(config / 'case2.yaml'), 'forward', (1.0, 0.42)),
        'cooke_triplet': (load_params_file(config / 'cooke_triplet.yaml'), 'forward',
                          (9.8, 0.2)),
        'cooke_triplet clipped (3600x2400, rims 8.0 / 6.8 mm)': (clipped, 'forward',
                                                                 (9.0, 0.36)),
        'wide angle clipped (85 deg)': (wide, 'stop', 0.75),
        'case2 (stop count)': (load_params_file(config / 'case2.yaml'), 'stop', 0.5),
    }
    for name in configs:
        if (config / f'{name}.yaml').exists():
            cases[name] = (load_params_file(config / f'{name}.yaml'), 'stop', None)
    out = {}
    for name, (values, method, extent) in cases.items():
        start = time.monotonic()
        model = build_model(values)
        curve = model.illumination()
        radius, surface = il.stop_of(model.values)
        distance = scene_distance(values)
        sensor_z, _ = image_plane(model.prescription, distance)
        on_axis = il.beam_area(il.backward_system(model.prescription, radius, surface,
                                                  sensor_z), np.zeros(1))[0]
        if method == 'forward':
            edges, flux = il.forward_flux(model.prescription, radius, surface, distance,
                                          curve.corner_height_mm, bins=8, rays=rays,
                                          entrance_radius_mm=extent[0],
                                          field_cosine=extent[1])
        else:
            edges, flux = il.stop_flux(model.prescription, radius, surface, distance,
                                       curve.corner_height_mm, bins=8, rays=rays,
                                       stop_cosine=extent)
        traced = il.annulus_means(curve.height_mm, curve.ri, edges)
        error = float(np.max(np.abs(flux / on_axis - traced))) * 100.0
        fraction = float(np.interp(curve.corner_height_mm, curve.height_mm,
                                   curve.pupil_pass_fraction))
        fit = il.lensfun_fit(model, curve)
        out[name] = {'method': method, 'rays': rays, 'max_error_pts': error,
                     'corner_ri': curve.corner_ri, 'corner_pupil_pass_fraction': fraction,
                     'lensfun_max_fit_error_pts': fit.max_error_pts,
                     'target_met': bool(error <= AGREEMENT_TARGET_PTS)}
        log(f'vignetting: agreement {name}: {error:.3f} pts, corner RI {curve.corner_ri:.4f}'
            f' (pass {fraction:.3f}) [{time.monotonic() - start:.1f} s]')
    return out


def run(out_dir: Path = RESULTS, quick: bool = False) -> dict[str, Any]:
    """
    Run the vignetting benchmark; write ``vignetting.json`` into ``out_dir``.

    :param out_dir: results folder.
    :param quick: one round, one call, few rays, and the agreement without the wide_angle
        and fisheye configs (smoke test).
    :return: the results document.
    """
    quiet = 0.0 if quick else 2.0
    doc = {
        'benchmark': 'vignetting',
        'machine': machine_info(),
        'method': __doc__,
        'rebuild': rebuilds(1 if quick else 5, 1 if quick else 5, quiet),
        'per_frame': frames(1 if quick else 5, 1 if quick else 10, quiet,
                            ((320, 240),) if quick else FRAME_SIZES),
        'agreement': agreement(20_000 if quick else 2_000_000, () if quick else
                               ('wide_angle', 'fisheye')),
    }
    write_json(Path(out_dir) / 'vignetting.json', doc)
    return doc


def tables(doc: Mapping[str, Any]) -> list[str]:
    """Return the markdown tables of a results document."""
    rebuild = doc['rebuild']
    lines = [f"Rebuild at {rebuild['size']} (median ms, 1 thread):", '']
    lines += markdown_table(
        ('lens', 'without', 'with', 'with / without', 'RI curve + model', 'corner RI'),
        [(lens, f"{r['without_ms']['median_ms']:.3g}", f"{r['with_ms']['median_ms']:.3g}",
          f"{r['ratio_median']:.2f}", f"{r['ri_and_model_ms']['median_ms']:.3g}",
          f"{r['corner_ri']:.3f}") for lens, r in rebuild['lenses'].items()])
    lines += ['', 'Per frame (median ms, 1 thread, Case 2):', '']
    lines += markdown_table(
        ('frame', 'remap', 'gain', 'remap + gain', 'gain / remap'),
        [(key, f"{r['remap']['median_ms']:.3g}", f"{r['gain']['median_ms']:.3g}",
          f"{r['remap+gain']['median_ms']:.3g}", f"{r['gain_over_remap_median']:.2f}")
         for key, r in doc['per_frame'].items()])
    lines += ['', 'Traced RI against the flux counts (8 annuli of equal area):', '']
    lines += markdown_table(
        ('lens', 'count', 'max error [pts]', 'corner RI', 'pupil pass at corner',
         'lensfun fit max error [pts]'),
        [(name, r['method'], f"{r['max_error_pts']:.3f}", f"{r['corner_ri']:.4f}",
          f"{r['corner_pupil_pass_fraction']:.3f}", f"{r['lensfun_max_fit_error_pts']:.3f}")
         for name, r in doc['agreement'].items()])
    return lines


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark alone and print its tables."""
    return bench_main(__doc__ or '', run, tables, 'one round, tiny frames, few rays', argv)


if __name__ == '__main__':
    sys.exit(main())
