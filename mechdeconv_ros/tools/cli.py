# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``mechdeconv``: the offline command line, on the same core and the same params files as the node.

Commands::

    mechdeconv info --params FILE [--width W --height H] [--json]
    mechdeconv correct --params FILE [--bayer PATTERN] IN OUT   (an image, or a folder)
    mechdeconv plot --params FILE OUT.png
    mechdeconv camera-info --params FILE [--width W --height H]
    mechdeconv project --params FILE [--width W --height H] IN.csv   (tx,ty -> tx,ty,u,v)
    mechdeconv vignetting --params FILE [--png OUT.png] [--lensfun]
    mechdeconv check --params P [--json] IMAGE...
    mechdeconv stereo --params STEREO.yaml LEFT.png RIGHT.png -o DIR   (a rectified pair)
    mechdeconv stereo-check --params STEREO.yaml [--json] LEFT1 RIGHT1 [LEFT2 RIGHT2 ...]
    mechdeconv import LENS.zmx -o lens.yaml [--wavelength-nm NM]
    mechdeconv import TABLE.csv --focal-length-mm F -o lens.yaml

``--params`` takes a ROS 2 params file (``/**: ros__parameters:``) such as config/case2.yaml;
``-p name=value`` overrides one parameter; ``--lens-state zoom=X[,focus=Y]`` evaluates a lens
whose groups move (``lens.zoom.joint`` / ``lens.focus.joint``) at those joint positions, with
the node's interpolation (linear between table rows, clamped outside with a warning; default
the first rows). Bad input prints one line naming the parameter or file and exits with status
2. ``correct --bayer rggb`` (or bggr, gbrg, grbg) reads each input as a raw one-channel 8- or
16-bit Bayer mosaic, demosaics it with the ``debayer`` parameter
(:mod:`mechdeconv_ros.imaging.debayer`) and writes the corrected colour image.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
from typing import Any, Sequence

from mechdeconv_ros.lenses.lens_source import LensSource
from mechdeconv_ros.lenses.lens_table import mechanisms, parse_lens_state
from mechdeconv_ros.lenses.sources import source_for
from mechdeconv_ros.model.camera_yaml import camera_info_yaml
from mechdeconv_ros.model.model import build_model, LensModel, ModelError
from mechdeconv_ros.schema.params import BAYER_PATTERNS, check_values, load_params_file, SPECS
import numpy as np
import yaml

#: The colour (0 R, 1 G, 2 B) of each channel of an image cv2.imread returns, by channel count.
BGR_COLOURS = {3: (2, 1, 0), 4: (2, 1, 0, 1)}
#: The pixel types cv2.remap takes (a file may hold others, e.g. int8 or int32 TIFFs).
REMAP_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)
IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.pgm', '.ppm')


class UsageError(Exception):
    """Bad input from the user: printed as one line, exit status 2."""


def _values(args: argparse.Namespace) -> dict[str, Any]:
    try:
        values: dict[str, Any] = (load_params_file(args.params) if args.params
                                  else check_values({}))
    except OSError as err:
        raise UsageError(f'--params: cannot read {args.params}: {err.strerror}') from None
    except ValueError as err:
        raise UsageError(f'--params {args.params}: {err}') from None
    for item in args.param or []:
        name, sep, text = item.partition('=')
        if not sep or name not in SPECS:
            raise UsageError(f'-p {item}: expected NAME=VALUE with a known parameter name')
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise UsageError(f'-p {item}: the value is not YAML ({_one_line(err)})') from None
        try:
            values.update(check_values({name: value}, partial=True))
        except ValueError as err:
            raise UsageError(str(err)) from None
    return values


def _model(args: argparse.Namespace, width: int = 0, height: int = 0) -> LensModel:
    values = _values(args)
    width = getattr(args, 'width', None) or width
    height = getattr(args, 'height', None) or height
    if width:
        values['sensor.width_px'] = width
    if height:
        values['sensor.height_px'] = height
    if not (values['sensor.width_px'] or width) or not (values['sensor.height_px'] or height):
        raise UsageError('sensor.width_px: the image size is unknown; give --width and '
                         '--height or set sensor.width_px and sensor.height_px')
    model = build_model(values, width, height, source=_moving_source(args, values))
    if getattr(args, 'func', None) is not cmd_info:     # info lists them in its report
        _warn_once(args, model.warnings)
    return model


def _moving_source(args: argparse.Namespace, values: dict[str, Any]) -> LensSource | None:
    """Return the lens at ``--lens-state`` (None without the option: the default source)."""
    text = getattr(args, 'lens_state', None)
    if not text:
        return None
    try:
        state = parse_lens_state(text)
    except ValueError as err:
        raise UsageError(str(err)) from None
    try:
        # A malformed table is refused here as it is without --lens-state (build_model).
        moving = {m.name: m for m in mechanisms(values)}
    except ValueError as err:
        raise UsageError(str(err)) from None
    for name, position in state.items():
        if name not in moving:
            raise UsageError(f'--lens-state: {name} does not move (lens.{name}.joint is not set)')
        mech = moving[name]
        if mech.clamped(position):
            _warn_once(args, [f'lens.{name}: joint position {position:g} is outside '
                              f'lens.{name}.positions ({mech.positions[0]:g} to '
                              f'{mech.positions[-1]:g}): the nearest row is used'])
    return source_for(values, state)


def _warn_once(args: argparse.Namespace, warnings: Sequence[str]) -> None:
    """Print each model warning once per run to stderr (a folder may build several models)."""
    seen = args.__dict__.setdefault('warned', set())
    for warning in warnings:
        if warning not in seen:
            seen.add(warning)
            print(f'mechdeconv: warning: {warning}', file=sys.stderr)


def cmd_info(args: argparse.Namespace) -> int:
    """Print every derived quantity of the model."""
    model = _model(args)
    report = model.report()
    state = getattr(model.source, 'state', None)
    if state:
        report['lens_state'] = state
    if args.json:
        json.dump(report, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write('\n')
        return 0
    if state:
        print('lens state: ' + ', '.join(f'{k} = {v:g}' for k, v in state.items()))
    print(format_report(report))
    return 0


def format_report(report: dict[str, Any]) -> str:
    """
    Format a model report for people.

    :param report: :meth:`LensModel.report`.
    :return: a few aligned lines.
    """
    def mm(value: float | None) -> str:
        return 'inf' if value is None else f'{value:.4g} mm'

    def num(value: float | None, spec: str) -> str:
        return 'n/a' if value is None else format(value, spec)

    fov = report['fov_deg']
    dof = report['depth_of_field_mm']
    lines = [
        f"lens ({report['mode']}): f = {report['focal_length_mm']:.5g} "
        f"± {num(report['focal_length_sigma_mm'], '.2g')} mm, "
        f"f-number {report['f_number']:.3g}, "
        f"image distance {report['image_distance_mm']:.5g} mm",
        f"image: {report['width_px']}x{report['height_px']} px -> "
        f"{report['out_width_px']}x{report['out_height_px']} px",
        f"FOV: {fov['horizontal']:.2f} x {fov['vertical']:.2f} deg "
        f"(diagonal {fov['diagonal']:.2f} deg) paraxial; {_traced_fov(report)}",
        f"scene at {mm(report['scene_distance_mm'])}: footprint "
        f"{mm(report['footprint_mm']['x'])} x {mm(report['footprint_mm']['y'])}, "
        f"feature resolution {mm(report['feature_resolution_mm']['x'])} x "
        f"{mm(report['feature_resolution_mm']['y'])}",
        f"hyperfocal {num(report['hyperfocal_mm'], '.4g')} ± "
        f"{num(report['hyperfocal_sigma_mm'], '.2g')} mm, "
        f"depth of field {mm(dof['near'])} to {mm(dof['far'])}",
        f"distortion: max displacement {num(report['max_displacement_px'], '.3f')} px, "
        f"corner sigma {num(report['corner_sigma_px'], '.3g')} px",
        f"equivalent calibration: {report['distortion_model']} D = "
        f"[{', '.join(f'{d:.6g}' for d in report['D'])}] (max error "
        f"{_px(report['equivalent_max_error_px'])} over the raw image to "
        f"{report['equivalent_reach_deg']:.1f} deg, RMS {_px(report['fit_rms_px'])})"
        + _beyond_90(report['equivalent_beyond_90deg_fraction']),
        _field_line(report),
    ]
    lines += _glass_and_sensor_lines(report)
    pose = report.get('sensor_pose')
    if pose:
        sigma = pose['corner_sigma_px']
        lines.append(
            f"sensor as assembled: lens axis at pixel ({pose['axis_px'][0]:.2f}, "
            f"{pose['axis_px'][1]:.2f}), tilt {pose['tilt_x_deg']:g} / {pose['tilt_y_deg']:g} "
            f"deg; corner sigma from the sensor tolerances {_num(sigma['total'])} px (offset "
            f"x {_num(sigma['axis_offset_x_mm'])}, y {_num(sigma['axis_offset_y_mm'])}, tilt x "
            f"{_num(sigma['tilt_x_deg'])}, y {_num(sigma['tilt_y_deg'])})")
    ri = report.get('relative_illumination')
    if ri:
        line = f"relative illumination: {ri['corner_ri']:.3f} at the raw corner"
        if 'corner_pupil_pass_fraction' in ri:
            line += (f" ({100.0 * ri['corner_pupil_pass_fraction']:.1f} % of the stop's beam "
                     'passes the other apertures)')
        if ri['lit_height_mm'] < ri['corner_height_mm']:
            line += (f"; light reaches {ri['lit_height_mm']:.4g} mm of the "
                     f"{ri['corner_height_mm']:.4g} mm to the corner")
        lines.append(line)
    colour = report.get('lateral_color')
    if colour:
        waves = ', '.join(f"{c['name']} {c['wavelength_nm']:g}" for c in colour['channels'])
        lines.append(f"lateral colour: R-B up to {colour['max_rb_separation_px']:.3g} px on the "
                     f'raw image ({waves} nm, focused at {colour["focus_wavelength_nm"]:g} nm)')
    lines += [f'warning: {w}' for w in report['warnings']]
    return '\n'.join(lines)


def _glass_and_sensor_lines(report: dict[str, Any]) -> list[str]:
    """Return the glass line (when a glass is named) and the sensor line (when defocused)."""
    lines = []
    surfaces = report.get('surfaces') or []
    named = [(i, s) for i, s in enumerate(surfaces) if s['glass']]
    if named:
        lines.append(f"glass at {report['wavelength_nm']:g} nm: " + ', '.join(
            f"surface {i} {s['glass']} n = {s['refractive_index']:.6f}" for i, s in named))
    sensor = report.get('sensor_plane')
    if sensor and sensor['image_distance_mm'] is not None:
        lines.append(f"sensor: {sensor['image_distance_mm']:.5g} mm behind the last vertex, "
                     f"{sensor['defocus_mm']:+.4g} mm from the image of the scene: blur circle "
                     f"{sensor['blur_diameter_um']:.3g} um ({sensor['blur_diameter_px']:.3g} px)")
    return lines


def _num(value: float | None) -> str:
    return 'n/a' if value is None else f'{value:.3g}'


def _px(value: float | None) -> str:
    return 'n/a' if value is None else f'{value:.2g} px'


def _traced_fov(report: dict[str, Any]) -> str:
    """Return the raw image's field of view as the trace sees it (None past the circle)."""
    field = report['covered_field']
    parts = [field['horizontal_deg'], field['vertical_deg'], field['diagonal_deg']]
    text = ['n/a' if p is None else f'{p:.2f}' for p in parts]
    note = '; n/a: beyond the image circle' if None in parts else ''
    return f'traced {text[0]} x {text[1]} deg (diagonal {text[2]} deg{note})'


def _field_line(report: dict[str, Any]) -> str:
    """Return the field line: lens limit, raw corner, image circle and the output projection."""
    field = report['covered_field']

    def deg(value: float | None) -> str:
        return 'outside the image circle' if value is None else f'{value:.1f} deg'

    least = 'at least ' if field['max_field_is_trace_limit'] else ''
    return (f"field: the lens passes {least}{report['max_field_angle_deg']:.1f} deg off axis "
            f"(image circle r = {field['image_circle_radius_mm']:.4g} mm); raw corner "
            f"{deg(field['corner_field_angle_deg'])}; {report['projection']} output corner "
            f"{deg(field['output_corner_field_angle_deg'])}")


def _beyond_90(fraction: float) -> str:
    """Say how much of the raw image no camera_info consumer can undistort (past 90 deg)."""
    if not fraction > 0.0:
        return ''
    return (f'; {100.0 * fraction:.1f} % of the raw image lies past 90 deg, where no '
            'camera_info consumer has a direction (image_rect with output.projection '
            'equidistant shows it)')


def cmd_camera_info(args: argparse.Namespace) -> int:
    """Print the camera_calibration_parsers YAML of the raw camera."""
    model = _model(args)
    report = model.report()
    # A YAML comment: camera_calibration_parsers ignores it, a person reads it.
    sys.stdout.write(f'# equivalent calibration {model.distortion_model}: largest displacement '
                     f'{model.equivalent_max_error_px:.3g} px over the raw image to '
                     f"{report['equivalent_reach_deg']:.1f} deg (what a consumer rectifying "
                     f"with it is off by){_beyond_90(report['equivalent_beyond_90deg_fraction'])}"
                     '\n')
    sys.stdout.write(camera_info_yaml(model))
    return 0


def read_directions(path: str) -> np.ndarray:
    """
    Read ``tx,ty`` lines (blank lines and ``#`` comments skipped) into an ``(N, 2)`` array.

    :param path: the CSV file, ``-`` for standard input.
    :return: the directions.
    :raises UsageError: naming the file and line of anything else.
    """
    try:
        stream = sys.stdin if path == '-' else open(path, encoding='utf-8')
    except OSError as err:
        raise UsageError(f'{path}: cannot read it: {err.strerror}') from None
    rows = []
    with stream:
        for number, line in enumerate(stream, 1):
            text = line.split('#', 1)[0].strip()
            if not text:
                continue
            parts = [p.strip() for p in text.split(',')]
            try:
                if len(parts) != 2:
                    raise ValueError
                row = [float(parts[0]), float(parts[1])]
            except ValueError:
                raise UsageError(f'{path}:{number}: expected "tx,ty" (two numbers), got '
                                 f'{text[:60]!r}') from None
            if not all(np.isfinite(row)):
                raise UsageError(f'{path}:{number}: tx and ty must be finite, got {text!r}')
            rows.append(row)
    return np.array(rows, dtype=np.float64).reshape(-1, 2)


def cmd_project(args: argparse.Namespace) -> int:
    """Project scene directions (tx, ty) to raw pixels (u, v): the traced camera."""
    # Exact per point: through a tilted or decentred port in 3-D (docs/underwater.md).
    from mechdeconv_ros.model.projection import project_points as project

    model = _model(args)
    directions = read_directions(args.input)
    u, v = project(model, directions[:, 0], directions[:, 1])
    out = sys.stdout
    for (tx, ty), col, row in zip(directions, u, v):
        out.write(f'{float(tx)!r},{float(ty)!r},{float(col)!r},{float(row)!r}\n')
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    """Check raw images against the description (:mod:`mechdeconv_ros.tools.check_cli`)."""
    from mechdeconv_ros.tools.check_cli import run_check
    images = [_read(Path(p)) for p in args.images]
    h, w = images[0].shape[:2]
    if any(img.shape[:2] != (h, w) for img in images):
        raise UsageError('check: the images differ in size')
    return run_check(_model(args, w, h), images, _values(args), args.json, sys.stdout)


def cmd_stereo(args: argparse.Namespace) -> int:
    """Rectify a raw pair, write its camera_info files (:mod:`mechdeconv_ros.tools.stereo_cli`)."""
    from mechdeconv_ros.tools.stereo_cli import pair_values, run_stereo
    try:
        values = pair_values(args.params, args.param or [])
    except ValueError as err:
        raise UsageError(str(err)) from None
    left, right = _read(Path(args.left)), _read(Path(args.right))
    try:
        run_stereo(values, left, right, Path(args.output))
    except ModelError:
        raise
    except ValueError as err:
        raise UsageError(str(err)) from None
    print(f'mechdeconv: wrote {args.output}', file=sys.stderr)
    return 0


def cmd_stereo_check(args: argparse.Namespace) -> int:
    """Measure the rig's rotation from raw pairs (:mod:`mechdeconv_ros.tools.stereo_check_cli`)."""
    from mechdeconv_ros.tools.stereo_check_cli import print_result, run_stereo_check
    from mechdeconv_ros.tools.stereo_cli import pair_values
    try:
        values = pair_values(args.params, args.param or [])
    except ValueError as err:
        raise UsageError(str(err)) from None
    images = [_read(Path(name)) for name in args.images]
    try:
        result = run_stereo_check(values, images, args.images)
    except ModelError:
        raise
    except ValueError as err:
        raise UsageError(str(err)) from None
    print_result(result, args.json, sys.stdout)
    return 0


def _one_line(err: BaseException) -> str:
    """Return an exception's message on one line (YAML and OpenCV messages span several)."""
    return ' '.join(part.strip() for part in str(err).splitlines() if part.strip())


def _check_writable_image(option: str, path: Path) -> None:
    """Refuse, before any work, an output file whose format OpenCV cannot write."""
    import cv2
    if not cv2.haveImageWriter(str(path)):
        raise UsageError(f'{option}{path}: OpenCV writes no image format with the suffix '
                         f'{path.suffix!r} (e.g. .png, .tif)')


def _write_image(option: str, path: Path, image: np.ndarray) -> None:
    """Write an image; a path that cannot be written is bad input (one line, status 2)."""
    import cv2
    try:
        written = cv2.imwrite(str(path), image)
    except cv2.error as err:
        raise UsageError(f'{option}{path}: cannot write the image there ({_one_line(err)})'
                         ) from None
    if not written:
        raise UsageError(f'{option}{path}: cannot write the image there')


def _read(path: Path) -> np.ndarray:
    import cv2
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise UsageError(f'{path}: not a readable image')
    if image.dtype not in REMAP_DTYPES:
        raise UsageError(f'{path}: {image.dtype} pixels: cv2.remap corrects '
                         + ', '.join(str(np.dtype(d)) for d in REMAP_DTYPES) + ' images')
    return image


def _demosaic(args: argparse.Namespace, path: Path, image: np.ndarray, method: str
              ) -> np.ndarray:
    """Demosaic a ``--bayer`` input into BGR (what cv2.imwrite writes); refuse a non-mosaic."""
    import cv2

    from mechdeconv_ros.imaging.debayer import demosaic, method_for

    if image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise UsageError(f'{path}: --bayer {args.bayer} needs a one-channel 8- or 16-bit raw '
                         f'mosaic, got {image.shape[2] if image.ndim == 3 else 1} channels of '
                         f'{image.dtype}')
    if image.shape[0] % 2 or image.shape[1] % 2:
        raise UsageError(f'{path}: a Bayer mosaic needs an even width and height (whole 2x2 '
                         f'tiles), got {image.shape[1]}x{image.shape[0]}')
    if method_for(method, image.dtype) != method:
        _warn_once(args, ["debayer: OpenCV's VNG demosaics 8-bit mosaics only; 16-bit "
                          'mosaics are demosaiced edge_aware instead'])
    rgb = demosaic(image, args.bayer, method)
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)


def cmd_correct(args: argparse.Namespace) -> int:
    """Correct an image file, or every image of a folder into a folder."""
    from tqdm import tqdm

    from mechdeconv_ros.imaging.remap import Rectifier

    src, dst = Path(args.input), Path(args.output)
    if src.is_dir():
        files = sorted(p for p in src.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise UsageError(f'{src}: no images ({", ".join(IMAGE_SUFFIXES)})')
        try:
            dst.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise UsageError(f'{dst}: cannot make the output folder there: '
                             f'{err.strerror}') from None
        pairs = [(p, dst / p.name) for p in files]
    elif src.is_file():
        _check_writable_image('', dst)
        pairs = [(src, dst)]
    else:
        raise UsageError(f'{src}: no such file or folder')
    rectifiers: dict[tuple[int, int], Rectifier] = {}
    method = str(_values(args)['debayer']) if args.bayer else ''
    for path, out in tqdm(pairs, desc='correcting', unit='image', disable=len(pairs) < 2):
        image = _read(path)
        if args.bayer:
            image = _demosaic(args, path, image, method)
        size = (image.shape[1], image.shape[0])
        if size not in rectifiers:
            rectifiers[size] = Rectifier(_model(args, *size))
        # OpenCV reads colour files as BGR(A): each channel gets its colour's map (lateral
        # colour correction; without it the colours change nothing).
        colours = BGR_COLOURS.get(image.shape[2] if image.ndim == 3 else 1)
        corrected = rectifiers[size].correct(image, colours=colours)
        _write_image('', out, corrected)
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    """Plot the distortion curve, the displacement field and a grid before/after."""
    from matplotlib.figure import Figure

    from mechdeconv_ros.tools.plots import plot_model
    output = Path(args.output)
    suffix = output.suffix.lower().lstrip('.')
    formats = Figure().canvas.get_supported_filetypes()
    if suffix not in formats:
        raise UsageError(f'{output}: matplotlib writes no figure format with the suffix '
                         f'{output.suffix!r} (e.g. .png, .svg, .pdf)')
    model = _model(args)
    try:
        plot_model(model, output)
    except OSError as err:
        raise UsageError(f'{output}: cannot write the figure there: {err.strerror}') from None
    print(f'wrote {args.output}')
    return 0


def cmd_vignetting(args: argparse.Namespace) -> int:
    """Export the traced vignetting: a 16-bit attenuation PNG and/or a lensfun entry."""
    from mechdeconv_ros.optics.illumination import lensfun_fit, raw_attenuation

    if not args.png and not args.lensfun:
        raise UsageError('vignetting: give --png OUT.png, --lensfun or both')
    if args.png:
        _check_writable_image('--png ', Path(args.png))
    model = _model(args)
    try:
        curve = model.illumination(with_fraction=False)
    except ValueError as err:
        raise UsageError(f'lens.aperture_diameter_mm: {err}') from None
    if args.png:
        attenuation = raw_attenuation(model, curve)
        image = np.round(attenuation * (65535.0 / float(np.max(attenuation))))
        _write_image('--png ', Path(args.png), image.astype(np.uint16))
        print(f'wrote {args.png} ({model.width}x{model.height} px, 16-bit, corner RI '
              f'{curve.corner_ri:.4f})')
    if args.lensfun:
        fit = lensfun_fit(model, curve)
        print(fit.xml())
        print(fit.comment())
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    """Import a .zmx lens file or a datasheet CSV table into a params file."""
    from mechdeconv_ros.lenses.lens_import import import_zmx
    from mechdeconv_ros.lenses.params_file import params_text, write_atomically
    from mechdeconv_ros.lenses.zmx import LensImportError

    source = Path(args.lens)
    try:
        if source.suffix.lower() == '.csv':
            from mechdeconv_ros.lenses.datasheet_csv import table_values
            if args.focal_length_mm is None:
                raise UsageError(f'{source}: a datasheet table needs --focal-length-mm F')
            imported = table_values(source, args.focal_length_mm)
        else:
            if args.focal_length_mm is not None:
                raise UsageError('--focal-length-mm is for a datasheet table (.csv): a .zmx '
                                 'file has its own focal length')
            print(f'mechdeconv: importing {source}', file=sys.stderr)
            imported = import_zmx(source, args.wavelength_nm)
        unknown = sorted(set(imported.values) - set(SPECS))
        if unknown:
            raise UsageError(f'{source}: this build has no parameter {unknown[0]}')
        check_values(imported.values)
        text = params_text(imported)
        write_atomically(args.output, text)
    except LensImportError as err:
        raise UsageError(str(err)) from None
    except ValueError as err:
        raise UsageError(f'{source}: {err}') from None
    _warn_once(args, imported.warnings)
    print(f'mechdeconv: wrote {args.output}', file=sys.stderr)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """
    Build the argument parser.

    :return: the parser with its sub-commands.
    """
    parser = argparse.ArgumentParser(
        prog='mechdeconv',
        description='Calibration-free lens distortion model: inspect, export, correct, plot.')
    sub = parser.add_subparsers(dest='command', required=True)

    def add(name: str, help_text: str, sized: bool) -> argparse.ArgumentParser:
        cmd = sub.add_parser(name, help=help_text, description=help_text)
        cmd.add_argument('--params', metavar='FILE',
                         help='ROS 2 params file (e.g. config/case2.yaml); default: Case 2')
        cmd.add_argument('-p', '--param', action='append', metavar='NAME=VALUE',
                         help='override one parameter, e.g. -p lens.stop_offset_mm=0.5')
        cmd.add_argument('--lens-state', metavar='zoom=X[,focus=Y]',
                         help='joint positions of a lens whose groups move (lens.zoom.joint, '
                              "lens.focus.joint); default: the tables' first rows")
        if sized:
            cmd.add_argument('--width', type=int, help='image width in px')
            cmd.add_argument('--height', type=int, help='image height in px')
        return cmd

    info = add('info', 'print every derived quantity of the model', True)
    info.add_argument('--json', action='store_true', help='print one JSON object')
    info.set_defaults(func=cmd_info)
    add('camera-info', 'print camera_calibration_parsers YAML of the raw camera',
        True).set_defaults(func=cmd_camera_info)
    project = add('project', 'project scene directions (lines tx,ty) to raw pixels: prints '
                             'tx,ty,u,v (nan where no chief ray passes the lens)', True)
    project.add_argument('input', help='CSV of tx,ty (tangents X/Z, Y/Z in the optical '
                                       'frame); - for standard input')
    project.set_defaults(func=cmd_project)
    correct = add('correct', 'correct an image, or every image of a folder', False)
    correct.add_argument('--bayer', choices=BAYER_PATTERNS, metavar='PATTERN',
                         help='the inputs are raw Bayer mosaics with this 2x2 tile (rggb, bggr, '
                              'gbrg or grbg, top-left pixel first as the ROS bayer_* '
                              'encodings): demosaic them (parameter debayer) and write colour')
    correct.add_argument('input', help='image file or folder')
    correct.add_argument('output', help='output image file or folder')
    correct.set_defaults(func=cmd_correct)
    plot = add('plot', 'plot distortion curve, displacement field, grid before/after', True)
    plot.add_argument('output', help='PNG file to write')
    plot.set_defaults(func=cmd_plot)
    vignetting = add('vignetting', 'export the traced vignetting (DSO/TUM PNG, lensfun entry)',
                     True)
    vignetting.add_argument('--png', metavar='OUT.png',
                            help='write the attenuation at each raw pixel as a 16-bit PNG '
                                 '(brightest pixel 65535)')
    vignetting.add_argument('--lensfun', action='store_true',
                            help='print a lensfun <vignetting model="pa"/> entry')
    vignetting.set_defaults(func=cmd_vignetting)
    check = add('check', 'measure how straight the straight edges of raw images come out, '
                         'and estimate the assembly (axis offset, tilt, image distance) that '
                         'straightens them', False)
    check.add_argument('--json', action='store_true', help='print one JSON object')
    check.add_argument('images', nargs='+', help='raw image files of one camera')
    check.set_defaults(func=cmd_check)
    from mechdeconv_ros.tools.stereo_cli import add_stereo_parser
    add_stereo_parser(sub).set_defaults(func=cmd_stereo)
    from mechdeconv_ros.tools.stereo_check_cli import add_stereo_check_parser
    add_stereo_check_parser(sub).set_defaults(func=cmd_stereo_check)
    lens_import = sub.add_parser(
        'import', help='write a params file from a .zmx lens file or a datasheet CSV table',
        description='Write a ROS 2 params file (prescription mode) from a Zemax .zmx lens '
                    'file, or (datasheet mode) from a CSV table of field angle (deg) and '
                    'real image height (mm). Add the sensor to the written file.')
    lens_import.add_argument('lens', help='LENS.zmx or TABLE.csv')
    lens_import.add_argument('-o', '--output', required=True, metavar='lens.yaml',
                             help='params file to write (written whole or not at all)')
    lens_import.add_argument('--wavelength-nm', type=float, metavar='NM',
                             help="wavelength of the indices (default: the file's primary)")
    lens_import.add_argument('--focal-length-mm', type=float, metavar='F',
                             help='effective focal length of a datasheet table')
    lens_import.set_defaults(func=cmd_import)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the command line.

    :param argv: arguments (default ``sys.argv[1:]``).
    :return: exit status: 0 success, 2 bad input.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in ('width', 'height'):
        value = getattr(args, name, None)
        if value is not None and value <= 0:
            print(f'mechdeconv: error: --{name} must be a positive number of pixels',
                  file=sys.stderr)
            return 2
    try:
        return int(args.func(args))
    except (UsageError, ModelError) as err:
        print(f'mechdeconv: error: {_one_line(err)}', file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0


if __name__ == '__main__':
    sys.exit(main())
