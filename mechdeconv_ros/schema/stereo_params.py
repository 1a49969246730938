# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The parameters of a stereo pair (issue 38): two cameras, the rig between them, the pair's output.

:data:`STEREO_SCHEMA` is built from the single camera's :data:`~mechdeconv_ros.schema.params.
SCHEMA`, so a new camera parameter is a pair parameter twice without an edit here:

- every single-camera parameter except ``output.*`` and ``check.*``, prefixed ``left.`` and
  ``right.`` (``left.lens.surfaces.radius_mm``, ``right.sensor.axis_offset_x_mm``, ...);
- the rig: ``rig.baseline_mm`` (> 0), ``rig.offset_y_mm``, ``rig.offset_z_mm`` (mm) and
  ``rig.rotation_x_deg``, ``rig.rotation_y_deg``, ``rig.rotation_z_deg`` (deg), each with a
  1-sigma ``rig.tolerance.<same name>`` (0 holds it fixed);
- ``output.*`` of the pair (the rectified images) at the top level; the rectified size
  defaults to the left camera's;
- ``sync.slop_s`` (pairing two frames by stamp) and ``stereo_check.rate_hz``,
  ``stereo_check.window``, ``stereo_check.apply`` (the live estimate of the rig's rotation).

Convention of the rig (docs/design.md section 8, Stereo): in the left camera's optical frame
(X right, Y down, Z ahead, origin at its paraxial entrance pupil) the right camera's entrance
pupil is at ``t = (baseline_mm, offset_y_mm, offset_z_mm)`` mm and its axes are the columns of
``R = R_x(rotation_x_deg) R_y(rotation_y_deg) R_z(rotation_z_deg)`` (right-handed rotations
about the left camera's axes, applied z first); a scene point ``X_l`` is
``X_r = R^T (X_l - t)`` in the right camera's frame.

:func:`split_values` turns the pair's values into two single-camera value sets (the pair's
``output.*`` copied into both) that :func:`mechdeconv_ros.model.model.build_model` takes as
they are. Nothing here imports ROS.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping

from mechdeconv_ros.schema.params import (
    check_values, coerce, ParamSpec, ParamValue, read_params_file, SCHEMA)

#: The two cameras' prefixes, left first.
CAMERAS = ('left', 'right')
#: The single-camera groups the pair does not repeat per camera: the pair has one output,
#: and the straight-edge check is a single camera's (the pair has ``stereo_check.*``).
PAIR_GROUPS = ('output.', 'check.')
#: The rig's six parameters: name, unit, default, range, default 1-sigma tolerance, meaning.
_RIG = (
    ('baseline_mm', 'mm', 120.0, (0.0, 1.0e5), 0.0,
     "Distance along the left camera's X axis (its rows, to the right) from the left "
     "camera's paraxial entrance pupil to the right camera's; > 0 (the right camera is on "
     'the right). The scale of depth: images cannot measure it.'),
    ('offset_y_mm', 'mm', 0.0, (-1.0e4, 1.0e4), 0.5,
     "Right camera's entrance pupil along the left camera's Y axis (down)."),
    ('offset_z_mm', 'mm', 0.0, (-1.0e4, 1.0e4), 0.5,
     "Right camera's entrance pupil along the left camera's Z axis (ahead)."),
    ('rotation_x_deg', 'deg', 0.0, (-45.0, 45.0), 0.5,
     "Right camera turned about the left camera's X axis (pitch; right-handed, > 0 turns "
     'its view up, toward -Y), applied last of the three: R = R_x R_y R_z.'),
    ('rotation_y_deg', 'deg', 0.0, (-45.0, 45.0), 0.5,
     "Right camera turned about the left camera's Y axis (yaw; right-handed about Y down, "
     '> 0 turns its view toward +X), applied second.'),
    ('rotation_z_deg', 'deg', 0.0, (-45.0, 45.0), 0.5,
     "Right camera turned about the left camera's Z axis (roll; right-handed, > 0 turns its "
     'X axis toward +Y, down), applied first.'),
)
#: The rig's parameter names, in the order of :data:`_RIG`.
RIG_PARAMS = tuple(f'rig.{name}' for name, *_ in _RIG)
#: Largest 1-sigma rig tolerances (mm and deg): a mount's, not a free parameter.
_MAX_TOLERANCE = {'mm': 100.0, 'deg': 10.0}


def _camera_specs(camera: str) -> tuple[ParamSpec, ...]:
    return tuple(replace(spec, name=f'{camera}.{spec.name}',
                         description=f'{camera.capitalize()} camera: {spec.description}')
                 for spec in SCHEMA if not spec.name.startswith(PAIR_GROUPS))


def _rig_specs() -> tuple[ParamSpec, ...]:
    specs = []
    for name, unit, default, (low, high), _, description in _RIG:
        specs.append(ParamSpec(f'rig.{name}', 'double', default, unit, description, low, high))
    for name, unit, _, _, tolerance, _ in _RIG:
        held = " (the drawing's: scale is not observable)" if name == 'baseline_mm' else ''
        specs.append(ParamSpec(
            f'rig.tolerance.{name}', 'double', tolerance, unit,
            f'1-sigma tolerance of rig.{name}{held}: how far the live estimate '
            '(stereo_check.apply) may move it; 0 = held fixed.', 0.0, _MAX_TOLERANCE[unit]))
    return tuple(specs)


def _output_specs() -> tuple[ParamSpec, ...]:
    out = []
    for spec in SCHEMA:
        if not spec.name.startswith('output.'):
            continue
        if spec.name == 'output.width_px':
            spec = replace(spec, description='Width of both rectified images; 0 = the left '
                                             "camera's width.")
        elif spec.name == 'output.height_px':
            spec = replace(spec, description='Height of both rectified images; 0 = the left '
                                             "camera's height.")
        elif spec.name == 'output.alpha':
            spec = replace(spec, description=(
                "Scale of the rectified pair as stereoRectify's alpha: 0 shows only pixels "
                'valid in both cameras (no black border), 1 keeps every raw pixel of both in '
                'view; one focal length and principal point for both.'))
        elif spec.name == 'output.projection':
            spec = replace(spec, description='Projection of the rectified pair: pinhole only '
                                             '(rows are epipolar lines of pinhole images).',
                           choices=('pinhole',))
        out.append(spec)
    return tuple(out)


STEREO_SCHEMA: tuple[ParamSpec, ...] = (
    *_camera_specs('left'),
    *_camera_specs('right'),
    *_rig_specs(),
    *_output_specs(),
    ParamSpec('sync.slop_s', 'double', 0.01, 's',
              "Largest difference of the two frames' stamps that still makes a pair; "
              'unpaired frames are counted in /diagnostics, never published as a pair.',
              0.0, 1.0),
    ParamSpec('stereo_check.rate_hz', 'double', 0.2, 'Hz',
              "Largest rate of the live estimate of the rig's rotation from matched features "
              'between the raw pair (idle-time work, never on the frame path); 0 = off.',
              0.0, 10.0),
    ParamSpec('stereo_check.window', 'integer', 5, '1',
              'Pairs whose matches the estimate pools (the last N checked).', 1, 100),
    ParamSpec('stereo_check.apply', 'bool', False, '',
              'Set the estimated rig parameters (one atomic set) when the verdict is rig_off, '
              'never beyond their tolerances (rig.tolerance.*).'),
)

#: Specs by name.
STEREO_SPECS: dict[str, ParamSpec] = {spec.name: spec for spec in STEREO_SCHEMA}


def stereo_defaults() -> dict[str, ParamValue]:
    """
    Return the default value of every pair parameter.

    :return: a new dict; arrays are fresh lists.
    """
    return {spec.name: (list(spec.default) if isinstance(spec.default, list) else spec.default)
            for spec in STEREO_SCHEMA}


def check_stereo_values(values: Mapping[str, Any], partial: bool = False
                        ) -> dict[str, ParamValue]:
    """
    Check a pair's parameter mapping against :data:`STEREO_SCHEMA` and fill in defaults.

    :param values: full parameter name -> value. Unknown names are an error.
    :param partial: when True, return only the names given (no defaults filled in).
    :return: the canonical values, every name present unless ``partial``.
    :raises ValueError: naming the first bad parameter by its full name
        (``left.lens.r1_mm: ...``); ``rig.baseline_mm`` must be > 0.
    """
    unknown = sorted(set(values) - set(STEREO_SPECS))
    if unknown:
        raise ValueError(f'unknown parameter {unknown[0]!r} (known: left.*, right.*, rig.*, '
                         'output.*, sync.*, stereo_check.*)')
    out: dict[str, ParamValue] = {} if partial else stereo_defaults()
    for name, value in values.items():
        out[name] = coerce(STEREO_SPECS[name], value)
    if 'rig.baseline_mm' in out and not float(out['rig.baseline_mm']) > 0.0:
        raise ValueError('rig.baseline_mm: must be > 0 mm (the two entrance pupils cannot '
                         'coincide: a pair without a baseline measures no depth)')
    return out


def split_values(values: Mapping[str, Any]
                 ) -> tuple[dict[str, ParamValue], dict[str, ParamValue], dict[str, ParamValue]]:
    """
    Split a pair's values into the two cameras' and the pair's own.

    :param values: checked pair values (:func:`check_stereo_values`); missing names take
        their defaults.
    :return: ``(left, right, pair)``: ``left`` and ``right`` are full single-camera value sets
        (every :data:`~mechdeconv_ros.schema.params.SCHEMA` name, the pair's ``output.*``
        copied in, ``check.*`` at their defaults); ``pair`` holds ``rig.*``, ``output.*``,
        ``sync.*`` and ``stereo_check.*``.
    :raises ValueError: naming the first bad parameter by its full name.
    """
    full = check_stereo_values(values)
    output = {k: v for k, v in full.items() if k.startswith('output.')}
    cameras = []
    for camera in CAMERAS:
        prefix = f'{camera}.'
        own = {k[len(prefix):]: v for k, v in full.items() if k.startswith(prefix)}
        cameras.append(check_values({**own, **output}))
    pair = {k: v for k, v in full.items() if not k.startswith(('left.', 'right.'))}
    return cameras[0], cameras[1], pair


def load_stereo_params_file(path: str | Path, node_name: str = 'stereo_node'
                            ) -> dict[str, ParamValue]:
    """
    Read a stereo_node params file (``/**/stereo_node:``, ``stereo_node:`` or ``/**:``).

    :param path: the YAML file.
    :param node_name: the node whose section applies besides ``/**``.
    :return: the checked values of every pair parameter (defaults where the file is silent).
    :raises ValueError: when the file is not a params file or holds a bad value (naming it).
    :raises OSError: when the file cannot be read.
    """
    return check_stereo_values(read_params_file(path, node_name))
