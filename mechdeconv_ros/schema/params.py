# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The one parameter schema of mechdeconv_ros.

Every parameter the node declares, the CLI reads, the config YAML files hold and the README
table lists is one :class:`ParamSpec` in :data:`SCHEMA`. Nothing here imports ROS: the node
turns each spec into a ``ParameterDescriptor`` (``FloatingPointRange`` / ``IntegerRange``), and
the core builds models from plain ``dict[str, value]`` mappings checked by
:func:`check_values`.

Units are in the names (``_mm``, ``_um``, ``_px``). Lengths are millimetres. Radii follow the
optical sign convention: positive when the centre of curvature lies on the image side (+z),
0 for a flat surface. Defaults reproduce Case 2 of Lim & Furukawa (2008), Table 1: a
640x480 CMOS sensor behind a biconvex BK7 thick lens with the aperture stop 0.2 mm in front of
the front principal plane, looking at a scene 1 m away.

Ranges are the physical per-field bounds (rclpy enforces them, inclusive). Constraints between
fields (an afocal lens, a scene inside the focal length, mismatched surface arrays) are the
model's to check: see :func:`mechdeconv_ros.model.model.build_model`.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Mapping, Sequence, Union

import yaml

ParamValue = Union[bool, int, float, str, list]

#: Powers of r of the even asphere terms, ``lens.surfaces.asphere_a4`` ... ``asphere_a16``.
ASPHERE_POWERS = (4, 6, 8, 10, 12, 14, 16)
#: Allowed values of ``output.projection``: the corrected image's projection.
PROJECTIONS = ('pinhole', 'equidistant')
#: Allowed values of ``scene.medium`` and ``port.type`` (issue 27, underwater).
MEDIA = ('air', 'water', 'seawater')
PORT_TYPES = ('none', 'flat', 'dome')
#: Allowed values of ``image_transport``: what the node subscribes to.
IMAGE_TRANSPORTS = ('raw', 'compressed')

#: Allowed values of ``output.interpolation`` and the OpenCV flag names they stand for.
INTERPOLATIONS = ('nearest', 'linear', 'cubic', 'lanczos4')
#: Allowed values of ``debayer``: OpenCV's demosaicing methods (mechdeconv_ros.imaging.debayer).
DEBAYER_METHODS = ('bilinear', 'edge_aware', 'vng')
#: image_proc's default: its debayer node declares ``debayer`` = 3, VNG (ros-perception/
#: image_pipeline, image_proc/src/debayer.cpp and include/image_proc/debayer.hpp).
DEFAULT_DEBAYER = 'vng'
#: The Bayer tiles the node demosaics, named as the ROS bayer_* encodings (top-left pixel
#: first, row by row).
BAYER_PATTERNS = ('rggb', 'bggr', 'gbrg', 'grbg')


@dataclass(frozen=True)
class ParamSpec:
    """
    One parameter: name, type, default, unit, range and what it means.

    ``type`` is one of ``'double'``, ``'integer'``, ``'string'``, ``'bool'``,
    ``'double_array'``, ``'integer_array'`` and ``'string_array'``. ``minimum``/``maximum``
    are inclusive bounds (``None``: unbounded); for arrays they bound every element.
    """

    name: str
    type: str  # noqa: A003 - the ROS parameter type name
    default: ParamValue
    unit: str
    description: str
    minimum: float | None = None
    maximum: float | None = None
    read_only: bool = False
    choices: tuple[str, ...] = ()

    @property
    def group(self) -> str:
        """Return the first dotted component of the name (lens, sensor, scene, output, node)."""
        return self.name.split('.', 1)[0] if '.' in self.name else 'node'

    @property
    def is_model(self) -> bool:
        """Return True when a change of this parameter changes the lens model or its maps."""
        return self.group in ('lens', 'sensor', 'scene', 'output', 'port')


def _d(name: str, default: float, unit: str, description: str,
       minimum: float | None = None, maximum: float | None = None) -> ParamSpec:
    return ParamSpec(name, 'double', float(default), unit, description, minimum, maximum)


def _i(name: str, default: int, unit: str, description: str,
       minimum: int | None = None, maximum: int | None = None) -> ParamSpec:
    return ParamSpec(name, 'integer', int(default), unit, description, minimum, maximum)


def _sa(name: str, description: str) -> ParamSpec:
    return ParamSpec(name, 'string_array', [], '', description)


def _a(name: str, unit: str, description: str,
       minimum: float | None = None, maximum: float | None = None) -> ParamSpec:
    return ParamSpec(name, 'double_array', [], unit, description, minimum, maximum)


#: The mechanisms that move lens groups (issue 19): ``lens.<m>.joint`` names the joint whose
#: ``sensor_msgs/JointState`` position drives them. Tables:
#: :mod:`mechdeconv_ros.lenses.lens_table`.
MECHANISMS = ('zoom', 'focus')
#: Most rows (joint positions) a moving-group table may have: every row, and every pair of
#: rows of the two mechanisms, is checked for a lens that can exist when the table is set.
MAX_TABLE_ROWS = 64


def _moving_specs(mechanism: str) -> tuple[ParamSpec, ...]:
    prefix = f'lens.{mechanism}'
    return (
        ParamSpec(f'{prefix}.joint', 'string', '', '',
                  f'{mechanism.capitalize()} joint in lens_state; the sensor_msgs/JointState '
                  f'joint whose position drives the {mechanism} groups (prescription mode); '
                  f'empty = the {mechanism} does not move.'),
        _a(f'{prefix}.positions', '1',
           f'{mechanism.capitalize()} joint positions of the rows; those at which the moving gaps '
           "are tabled (at least 2, strictly increasing, the joint's unit); linear in between, "
           'clamped outside.', -1.0e9, 1.0e9),
        ParamSpec(f'{prefix}.surfaces', 'integer_array', [], '1',
                  f'Gap indices the {mechanism} moves; 0-based indices into '
                  'lens.surfaces.thickness_mm of air gaps (not a glass thickness, not the last '
                  'entry, not a gap the other mechanism moves).', 0, 255),
        _a(f'{prefix}.thickness_mm', 'mm',
           f'Moving gaps of each {mechanism} row; the gaps at each position, row-major '
           '(len(positions) x len(surfaces)): row j holds them at positions[j].',
           0.0, 1.0e4),
    )


#: The water and the port in front of the lens (issue 27, docs/underwater.md): their own block.
UNDERWATER_SPECS: tuple[ParamSpec, ...] = (
    ParamSpec('scene.medium', 'string', 'air', '',
              'Medium of the scene: air, water (fresh, salinity 0) or seawater '
              '(scene.salinity_psu); its index relative to air from Quan & Fry (1995), '
              '400-700 nm, 0-30 degC, 0-35 PSU, refused outside. scene.distance_mm stays '
              'measured from the front principal plane of the lens alone.', choices=MEDIA),
    _d('scene.salinity_psu', 35.0, 'PSU',
       'Salinity of seawater (scene.medium seawater); 0-35 PSU (the range of the formula).',
       0.0, 1.0e3),
    _d('scene.temperature_c', 20.0, 'degC',
       'Temperature of the water; 0-30 degC (the range of the formula).', -1.0e3, 1.0e3),
    _d('scene.medium_index', 0.0, '1',
       'Index of the medium of the scene relative to air at every wavelength (overrides '
       'the formula of scene.medium: no dispersion); 0 = from scene.medium; 1 = air, as '
       'scene.medium air. Below 1 is refused.',
       0.0, 4.0),
    ParamSpec('port.type', 'string', 'none', '',
              'Window in front of the lens: none, flat (a plane-parallel plate) or dome (a '
              'concentric spherical shell); traced as two more surfaces, the scene in '
              'scene.medium. Not with a datasheet lens (no surfaces to trace).',
              choices=PORT_TYPES),
    _d('port.thickness_mm', 5.0, 'mm', 'Thickness of the port (flat or dome); > 0.',
       0.0, 1.0e3),
    ParamSpec('port.glass', 'string', '', '',
              'Material of the port by name: a catalog glass (N-BK7), PMMA (acrylic) or '
              "POLYCARBONATE (Sultanova et al. 2009), its index at each wavelength; '' = "
              'port.refractive_index.'),
    _d('port.refractive_index', 1.4906, '1',
       'Index of the port when port.glass is empty (PMMA at the d line).', 1.0, 4.0),
    _d('port.distance_mm', 10.0, 'mm',
       'Flat port: from the first lens vertex along the axis toward the scene to the inner face '
       'of the port; > 0.', 0.0, 1.0e4),
    _d('port.tilt_x_deg', 0.0, 'deg',
       'Flat port: its plane turned about the row (x) line through the point where the axis '
       'meets its inner face; > 0 brings the part seen at larger v (image rows further down) '
       'closer to the lens. Applied first.', -45.0, 45.0),
    _d('port.tilt_y_deg', 0.0, 'deg',
       'Flat port: then turned about its own (tilted) column line, as sensor.tilt_y_deg; > 0 '
       'brings the part seen at larger u (further right) closer to the lens (before issue 37 '
       'it turned about the fixed y axis: docs/design.md section 1.1).', -45.0, 45.0),
    _d('port.radius_mm', 50.0, 'mm', 'Dome port: radius of its inner surface; > 0.',
       0.0, 1.0e4),
    _d('port.center_offset_mm', 0.0, 'mm',
       'Dome port: its centre along the axis from the paraxial entrance pupil of the lens (in '
       'air), > 0 toward the scene; 0 = centred on the pupil (nearly central).',
       -1.0e4, 1.0e4),
    _d('port.decenter_x_mm', 0.0, 'mm',
       'Dome port: its centre off the axis along the image rows (toward larger u).',
       -1.0e3, 1.0e3),
    _d('port.decenter_y_mm', 0.0, 'mm',
       'Dome port: its centre off the axis along the image columns (toward larger v).',
       -1.0e3, 1.0e3),
)


#: Largest output (and input) frame the node accepts, in pixels: 8192 x 8192. The maps cost
#: 8 bytes per output pixel (two CV_32FC1) plus about 12 bytes of intermediates while they
#: are built, so this bounds a model at about 1.3 GiB transiently and 540 MiB held.
MAX_FRAME_PIXELS = 8192 * 8192
#: Largest width or height, in pixels, of an output or input frame.
MAX_SIDE_PX = 16384
#: Largest |sensor.axis_offset_*_mm|: beyond any sensor a model accepts (the axis must meet
#: the sensor: the model refuses an offset past its edge).
MAX_AXIS_OFFSET_MM = 100.0
#: Largest |sensor.tilt_*_deg|: an assembly error, not a tilt-shift or Scheimpflug mount.
MAX_TILT_DEG = 10.0

SCHEMA: tuple[ParamSpec, ...] = (
    # --- lens: the paper's thick lens (two spherical surfaces) ---
    _d('lens.refractive_index', 1.5168, '1',
       'Refractive index n of the lens glass (d-line); the paper uses BK7, 1.5168.', 1.0, 4.0),
    ParamSpec('lens.glass', 'string', '', '',
              "Thick-lens mode: lens glass by name ('' = off); its index at "
              'lens.wavelength_nm replaces lens.refractive_index. A catalog glass (N-BK7, '
              'SCHOTT:N-BK7, S-LAH66, H-ZF52, TAFD25) or MODEL:nd:vd. With '
              'lens.focal_length_mm the radii are designed at the d line (587.56 nm), so f '
              'changes with the wavelength.'),
    _d('lens.wavelength_nm', 587.56, 'nm',
       'Wavelength the lens is traced at: the index of every named glass (lens.glass, '
       'lens.surfaces.glass) is its catalog formula there.', 350.0, 2500.0),
    _d('lens.image_distance_mm', 0.0, 'mm',
       'Distance from the last lens vertex to the sensor; 0 = the paraxial image plane of '
       'scene.distance_mm (in focus). Another value defocuses: rays land where they meet '
       'that plane.', 0.0, 1.0e4),
    _d('lens.r1_mm', 4.0, 'mm',
       'Radius of the front surface; > 0 when its centre of curvature is on the image side, '
       '0 = flat.', -1.0e4, 1.0e4),
    _d('lens.r2_mm', -4.0, 'mm',
       'Radius of the rear surface; a biconvex lens has r2 < 0, 0 = flat.', -1.0e4, 1.0e4),
    _d('lens.thickness_mm', 3.0, 'mm', 'Centre thickness t of the lens.', 0.0, 1.0e3),
    _d('lens.aperture_diameter_mm', 1.0, 'mm',
       'Physical diameter d_a of the aperture stop (at lens.stop_surface in prescription '
       'mode; sets the f-number, eq. 16-18); at most what the surfaces let through.',
       1.0e-3, 1.0e3),
    _d('lens.stop_offset_mm', 0.2, 'mm',
       'Offset m_a of the aperture stop from the front principal plane; > 0 towards the '
       'object (eq. 26-34). May put the stop inside the glass. Thick-lens mode only.',
       -1.0e3, 1.0e3),
    _d('lens.focal_length_mm', 0.0, 'mm',
       'Nominal focal length (datasheet); > 0 replaces r1/r2 by a symmetric biconvex lens of '
       'this focal length, index n and thickness t. 0 = derive f from r1, r2, t, n. Datasheet '
       'mode: the effective focal length (required).',
       0.0, 1.0e4),
    _d('lens.exposure_constant_q', 2.0, '1',
       'Exposure constant q of the f-number n_f = sqrt(2/q) f / d_a (eq. 16-18).', 1.0e-3, 1.0e3),
    # --- lens tolerances: 1-sigma, Gaussian (eq. 9, 25) ---
    _d('lens.tolerance.r1_mm', 0.01, 'mm', '1-sigma manufacturing tolerance of r1.', 0.0, 1.0e3),
    _d('lens.tolerance.r2_mm', 0.01, 'mm', '1-sigma manufacturing tolerance of r2.', 0.0, 1.0e3),
    _d('lens.tolerance.thickness_mm', 0.02, 'mm', '1-sigma tolerance of the thickness t.',
       0.0, 1.0e3),
    _d('lens.tolerance.refractive_index', 0.0005, '1', '1-sigma tolerance of the index n.',
       0.0, 1.0),
    _d('lens.tolerance.aperture_diameter_mm', 0.01, 'mm',
       '1-sigma tolerance of the aperture diameter d_a (hyperfocal sigma, eq. 25).', 0.0, 1.0e3),
    # --- lens: general prescription (non-empty arrays select prescription mode) ---
    _a('lens.surfaces.radius_mm', 'mm',
       'Prescription mode: radius of each surface in order (0 = flat). Non-empty arrays '
       'replace the thick lens.', -1.0e4, 1.0e4),
    _a('lens.surfaces.thickness_mm', 'mm',
       'Prescription mode: axial distance from each surface to the next (the last is ignored: '
       'the sensor sits at the paraxial image plane).', 0.0, 1.0e4),
    _a('lens.surfaces.refractive_index', '1',
       'Prescription mode: refractive index after each surface (1.0 = air).', 1.0, 4.0),
    _sa('lens.surfaces.glass',
        'Prescription mode: glass after each surface by name; its index at '
        "lens.wavelength_nm (N-BK7, OHARA:S-LAH66, MODEL:nd:vd); '' or AIR = that surface's "
        'lens.surfaces.refractive_index (1.0 when that array is empty); empty = none.'),
    _a('lens.surfaces.semi_diameter_mm', 'mm',
       'Prescription mode: clear semi-diameter of each surface (0 = unlimited); empty = all '
       'unlimited.', 0.0, 1.0e4),
    _a('lens.surfaces.conic', '1',
       'Prescription mode: conic constant k of each surface (0 sphere, -1 paraboloid, < -1 '
       'hyperboloid); empty = all spheres.', -1.0e3, 1.0e3),
    *(_a(f'lens.surfaces.asphere_a{p}', f'mm^{1 - p}',
         f'Prescription mode: asphere term a{p} r^{p} of each surface; empty = all 0.',
         -1.0e6, 1.0e6) for p in ASPHERE_POWERS),
    ParamSpec('lens.channel_wavelengths_nm', 'double_array', [610.0, 550.0, 465.0], 'nm',
              'Wavelengths [R, G, B] of the colour channels. output.lateral_color_correction '
              "traces each channel at its own (defaults: the centroids of a typical sensor's "
              'colour filters).', 200.0, 2500.0),
    # --- lens: datasheet table (non-empty arrays select datasheet mode) ---
    _a('lens.datasheet.field_angle_deg', 'deg',
       'Datasheet mode: field angles of the image height table; strictly increasing from the '
       'axis (scene at infinity), with lens.focal_length_mm as the effective focal length. '
       'Non-empty replaces the thick lens.', 0.0, 179.0),
    _a('lens.datasheet.image_height_mm', 'mm',
       'Datasheet mode: real image height at each field angle; increasing (0 at 0 deg).',
       0.0, 1.0e3),
    _a('lens.datasheet.relative_illumination', '1',
       'Datasheet mode: relative illumination at each field angle; 1 on the axis, empty = '
       'unknown (no vignetting correction).', 0.0, 1.5),
    _i('lens.stop_surface', 0, '1',
       'Prescription mode: 0-based index of the surface whose axial point the chief ray '
       'crosses (the aperture stop).', 0, 255),
    # --- lens: moving groups (zoom, focus) driven from lens_state (issue 19) ---
    *(spec for mechanism in MECHANISMS for spec in _moving_specs(mechanism)),
    # --- sensor ---
    _d('sensor.pixel_size_x_um', 4.0625, 'um', 'Pixel pitch p_x along the image rows.',
       0.01, 1.0e3),
    _d('sensor.pixel_size_y_um', 4.4375, 'um', 'Pixel pitch p_y along the image columns.',
       0.01, 1.0e3),
    _i('sensor.width_px', 0, 'px', 'Sensor width p_r,x; 0 = take it from the incoming images.',
       0, MAX_SIDE_PX),
    _i('sensor.height_px', 0, 'px',
       'Sensor height p_r,y; 0 = take it from the incoming images.', 0, MAX_SIDE_PX),
    # --- sensor: the camera as assembled (issue 25) ---
    _d('sensor.axis_offset_x_mm', 0.0, 'mm',
       'Where the optical axis meets the sensor, along the rows from the sensor centre: the '
       'axis is at pixel u = (W - 1) / 2 + this / p_x (datasheet "optical centre offset").',
       -MAX_AXIS_OFFSET_MM, MAX_AXIS_OFFSET_MM),
    _d('sensor.axis_offset_y_mm', 0.0, 'mm',
       'Where the optical axis meets the sensor, down the columns from the sensor centre: '
       'the axis is at pixel v = (H - 1) / 2 + this / p_y.',
       -MAX_AXIS_OFFSET_MM, MAX_AXIS_OFFSET_MM),
    _d('sensor.tilt_x_deg', 0.0, 'deg',
       'Sensor tilt about its row line through the axis point; > 0 brings the rows of larger '
       'v closer to the lens (on-axis image distance unchanged).',
       -MAX_TILT_DEG, MAX_TILT_DEG),
    _d('sensor.tilt_y_deg', 0.0, 'deg',
       'Sensor tilt about its (tilted) column line through the axis point, after tilt_x (a '
       ".zmx break's tilts a, b import as -a, -b); > 0 brings the columns of larger u "
       'closer (docs/design.md section 1.1).',
       -MAX_TILT_DEG, MAX_TILT_DEG),
    _d('sensor.tolerance.axis_offset_x_mm', 0.02, 'mm',
       '1-sigma assembly tolerance of sensor.axis_offset_x_mm (info: the pixel sigma it '
       'causes at the corner).', 0.0, 10.0),
    _d('sensor.tolerance.axis_offset_y_mm', 0.02, 'mm',
       '1-sigma assembly tolerance of sensor.axis_offset_y_mm.', 0.0, 10.0),
    _d('sensor.tolerance.tilt_x_deg', 0.2, 'deg',
       '1-sigma assembly tolerance of sensor.tilt_x_deg.', 0.0, 10.0),
    _d('sensor.tolerance.tilt_y_deg', 0.2, 'deg',
       '1-sigma tolerance of sensor.tilt_y_deg.', 0.0, 10.0),
    # --- scene ---
    _d('scene.distance_mm', 1000.0, 'mm',
       'Distance l from the front principal plane to the scene; 0 = infinity.', 0.0, 1.0e9),
    _d('scene.focus_distance_mm', 0.0, 'mm',
       'Distance the lens is focused at, for the depth of field (eq. 19-21); 0 = the scene '
       'distance.', 0.0, 1.0e9),
    _d('scene.circle_of_confusion_mm', 0.0, 'mm',
       'Acceptable circle of confusion c (eq. 22); 0 = the paper default, 0.1 % of f.',
       0.0, 10.0),
    # --- underwater: the scene's medium and the port (issue 27; docs/underwater.md) ---
    *UNDERWATER_SPECS,
    # --- output ---
    _d('output.alpha', 0.0, '1',
       'Scale of the corrected image as in getOptimalNewCameraMatrix: 0 keeps only valid pixels '
       '(no black border), 1 keeps every source pixel in view.', 0.0, 1.0),
    ParamSpec('output.projection', 'string', 'pinhole', '',
              'Projection of the corrected image: pinhole (rectilinear, r = f tan(theta), at '
              'most 85 deg off axis) or equidistant (ideal fisheye, r = f theta, any field; '
              'camera_info_rect then says distortion_model equidistant with D = 0).',
              choices=PROJECTIONS),
    ParamSpec('output.interpolation', 'string', 'linear', '',
              'Interpolation of the remap: nearest, linear, cubic or lanczos4. Depth images '
              '(16UC1, 32FC1) always use nearest.', choices=INTERPOLATIONS),
    _i('output.width_px', 0, 'px', 'Width of the corrected image; 0 = the input width.',
       0, MAX_SIDE_PX),
    _i('output.height_px', 0, 'px', 'Height of the corrected image; 0 = the input height.',
       0, MAX_SIDE_PX),
    ParamSpec('output.vignetting_correction', 'bool', False, '',
              'Divide image_rect by the relative illumination traced through the lens '
              '(brighter corners, a flat white wall stays flat); false = a purely geometric '
              'rectification. Depth images (16UC1, 32FC1) are never gain-corrected.'),
    ParamSpec('output.lateral_color_correction', 'bool', False, '',
              'Correct lateral colour: remap R, G and B each by the chief rays traced at its '
              'own wavelength (lens.channel_wavelengths_nm) to the one sensor plane, so the '
              'three channels register on the corrected image (same K_new and camera_info). '
              'Needs the glass names (lens.surfaces.glass, or lens.glass for the thick lens). '
              'rgb8/bgr8/rgb16/bgr16/rgba8/bgra8 and demosaiced Bayer frames only: mono, '
              '8UC3/8UC4 and depth images ignore it (logged once).'),
    _d('output.max_vignetting_gain', 4.0, '1',
       'Largest gain of the vignetting correction; where the relative illumination is below '
       '1 / this the corrected field ends (black).', 1.0, 1.0e3),
    # --- the live self-check from straight edges (issue 26) ---
    _d('lens.tolerance.image_distance_mm', 0.01, 'mm',
       '1-sigma assembly tolerance of the sensor distance behind the lens (the check '
       'estimates lens.image_distance_mm within it; 0 = held fixed).', 0.0, 10.0),
    _d('check.rate_hz', 0.2, 'Hz',
       'Largest rate of the straight-edge self-check, a low-priority child process on a copy '
       'of a corrected frame (never on the frame path); 0 = off (the process stops).', 0.0,
       10.0),
    _d('check.max_load', 0.75, '1',
       'Busiest the CPUs may be (fraction of all cores over the last second; niced work, '
       'the check process included, counts as idle) for a check to start; above it a check '
       'waits, and one in progress is paused (SIGSTOP) until the load is below 0.8 of it: '
       'the frames come first. 1 = never held back.', 0.05, 1.0),
    _d('check.stable_period_s', 60.0, 's',
       'Seconds between checks once two checks in a row of the model in use gave the same '
       'verdict (if longer than 1 / check.rate_hz); a new model (a parameter set, a new '
       'frame size) is checked at check.rate_hz again. 0 = always at check.rate_hz.', 0.0,
       86400.0),
    ParamSpec('check.pause_during_frames', 'bool', True, '',
              'Stop the check process (SIGSTOP) while a frame is being corrected and '
              'published, and let it run (SIGCONT) between frames: the frame path never '
              'shares the CPUs, caches and memory bus with a check (issue 36).'),
    _i('check.window', 5, '1',
       'Frames whose straight edges the check and its estimate pool (the last N checked).',
       1, 100),
    _d('check.max_rms_px', 0.3, 'px',
       'RMS distance of straight-edge points from their lines (px of the corrected image) '
       'above which the verdict is description_off (WARN in /diagnostics).', 0.0, 100.0),
    ParamSpec('check.apply', 'bool', False, '',
              'Set the estimated assembly parameters on this node (one atomic set) when the '
              'verdict is description_off and their 1-sigma is within their tolerances; '
              'made as a user set is, never farther than 3 tolerances from the values set '
              'last by the user (at start-up or by a parameter set), and dropped when a set '
              'came after the model it judged.'),
    # --- node behaviour (no effect on the model) ---
    ParamSpec('lazy_subscription', 'bool', True, '',
              'Subscribe to image_raw only while an output topic has a subscriber, like '
              'image_proc; false = always subscribe.'),
    _i('remap_threads', 0, '1',
       'Threads OpenCV may use for the remap (cv2.setNumThreads); 0 = OpenCV default, all '
       'cores, as image_proc. 1 leaves the other cores to the camera driver and the DDS '
       'transport; on 2 cores it sustains about 2/3 of the frame rate. Bayer input with '
       'debayer vng is demosaiced in as many stripes, one per thread.', 0, 64),
    ParamSpec('image_transport', 'string', 'raw', '',
              'Input transport, read at start-up as image_proc does: raw subscribes image_raw '
              '(sensor_msgs/Image); compressed subscribes the resolved image_raw + '
              '/compressed (sensor_msgs/CompressedImage, JPEG or PNG as image_transport '
              'writes it) and decodes every frame.', choices=IMAGE_TRANSPORTS, read_only=True),
    ParamSpec('debayer', 'string', DEFAULT_DEBAYER, '',
              'Demosaicing of Bayer input, published as rgb8 / rgb16. The node reads '
              'bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8 and their 16-bit forms and '
              "demosaics them with OpenCV's bilinear, edge_aware (EA) or vng. Default vng, as "
              "image_proc's debayer node (ros-perception/image_pipeline image_proc/src/"
              'debayer.cpp declares debayer = 3, VNG). OpenCV has no 16-bit VNG: 16-bit '
              'mosaics then use edge_aware (logged once).', choices=DEBAYER_METHODS),
    # --- image_rect/compressed output (image_transport's parameter names) ---
    ParamSpec('image_rect.compressed.format', 'string', 'jpeg', '',
              'Codec of image_rect/compressed (sensor_msgs/CompressedImage, published only '
              "while it has a subscriber, as image_transport's compressed plugin writes it): "
              'jpeg or png.', choices=('jpeg', 'png')),
    _i('image_rect.compressed.jpeg_quality', 95, '1',
       'JPEG quality of image_rect/compressed.', 1, 100),
    _i('image_rect.compressed.png_level', 3, '1',
       'PNG compression level (zlib) of image_rect/compressed.', 0, 9),
)

#: Specs by name.
SPECS: dict[str, ParamSpec] = {spec.name: spec for spec in SCHEMA}

#: Names of the parameters that define the lens model and its maps.
MODEL_PARAMS: tuple[str, ...] = tuple(spec.name for spec in SCHEMA if spec.is_model)


def defaults() -> dict[str, ParamValue]:
    """
    Return the default value of every parameter (the paper's Case 2).

    :return: a new dict; arrays are fresh lists.
    """
    return {spec.name: (list(spec.default) if isinstance(spec.default, list) else spec.default)
            for spec in SCHEMA}


def scene_distance(values: Mapping[str, Any]) -> float:
    """
    Return the scene distance l from H in mm: ``math.inf`` for ``scene.distance_mm`` = 0.

    The one reading of the parameter's sentinel (0 = infinity): every module that needs l
    calls this (or :func:`distance_from_setting`) instead of comparing with 0 itself.

    :param values: parameter values (``scene.distance_mm`` missing: infinity).
    :return: l, > 0 (``math.inf`` for a scene at infinity).
    """
    return distance_from_setting(float(values.get('scene.distance_mm', 0.0)))


def distance_from_setting(distance_mm: float) -> float:
    """
    Return l (mm) of a ``scene.distance_mm`` setting: 0 (or below, never valid) is infinity.

    :param distance_mm: the parameter's value.
    :return: l, ``math.inf`` for the sentinel.
    """
    return math.inf if not distance_mm > 0.0 else float(distance_mm)


def scene_in_air(values: Mapping[str, Any]) -> bool:
    """
    Return True when the scene's medium is air: ``scene.medium_index`` 1, or 0 and air.

    ``scene.medium_index`` > 0 overrides ``scene.medium``; 1.0 is air written out (no port
    path, no refraction at a medium), anything else a medium (below 1 is then refused).

    :param values: parameter values.
    :return: whether the scene is in air.
    """
    given = float(values.get('scene.medium_index', 0.0))
    if given > 0.0:
        return given == 1.0
    return str(values.get('scene.medium', 'air')) == 'air'


def _is_real(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def coerce(spec: ParamSpec, value: Any) -> ParamValue:
    """
    Check one value against its spec and return it in its canonical Python type.

    Integers are accepted for doubles (a YAML ``4`` for ``4.0``); everything else must match.

    :param spec: the parameter's spec.
    :param value: the proposed value.
    :return: the value as ``float``, ``int``, ``str``, ``bool``, ``list[float]`` or
        ``list[str]``.
    :raises ValueError: with a message naming the parameter, when the type, a bound or a choice
        is violated or a number is not finite.
    """
    name = spec.name
    if spec.type == 'bool':
        if not isinstance(value, bool):
            raise ValueError(f'{name}: expected true or false, got {value!r}')
        return value
    if spec.type == 'string':
        if not isinstance(value, str):
            raise ValueError(f'{name}: expected a string, got {value!r}')
        if spec.choices and value not in spec.choices:
            raise ValueError(f'{name}: expected one of {", ".join(spec.choices)}, got {value!r}')
        return value
    if spec.type == 'string_array':
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ValueError(f'{name}: expected a list of strings, got {value!r}')
        return [str(v) for v in value]
    if spec.type in ('double_array', 'integer_array'):
        if not isinstance(value, (list, tuple)) and not hasattr(value, 'tolist'):
            raise ValueError(f'{name}: expected a list of numbers, got {value!r}')
        items = list(value.tolist() if hasattr(value, 'tolist') else value)
        out = []
        for i, item in enumerate(items):
            number = _check_number(spec, item, f'{name}[{i}]')
            if spec.type == 'integer_array':
                if isinstance(number, float) and not number.is_integer():
                    raise ValueError(f'{name}[{i}]: expected an integer, got {item!r}')
                number = int(number)
            out.append(number)
        return out
    number = _check_number(spec, value, name)
    if spec.type == 'integer':
        if not float(number).is_integer():
            raise ValueError(f'{name}: expected an integer, got {value!r}')
        return int(number)
    return float(number)


def _check_number(spec: ParamSpec, value: Any, label: str) -> float:
    if not _is_real(value):
        raise ValueError(f'{label}: expected a number, got {value!r}')
    if spec.type in ('integer', 'integer_array') and isinstance(value, float) and \
            not value.is_integer():
        raise ValueError(f'{label}: expected an integer, got {value!r}')
    if not math.isfinite(value):
        raise ValueError(f'{label}: must be finite, got {value!r}')
    unit = f' {spec.unit}' if spec.unit not in ('', '1') else ''
    if spec.minimum is not None and value < spec.minimum:
        raise ValueError(f'{label}: {value:g}{unit} is below the minimum {spec.minimum:g}{unit}')
    if spec.maximum is not None and value > spec.maximum:
        raise ValueError(f'{label}: {value:g}{unit} is above the maximum {spec.maximum:g}{unit}')
    return value


def check_values(values: Mapping[str, Any], *, partial: bool = False) -> dict[str, ParamValue]:
    """
    Check a parameter mapping against the schema and fill in defaults.

    :param values: parameter name -> value. Unknown names are an error.
    :param partial: when True, return only the names given (no defaults filled in).
    :return: the canonical values, every schema name present unless ``partial``.
    :raises ValueError: naming the first bad parameter.
    """
    unknown = sorted(set(values) - set(SPECS))
    if unknown:
        raise ValueError(f'unknown parameter {unknown[0]!r} (known: lens.*, sensor.*, scene.*, '
                         'output.*, lazy_subscription, remap_threads)')
    out: dict[str, ParamValue] = {} if partial else defaults()
    for name, value in values.items():
        out[name] = coerce(SPECS[name], value)
    return out


def load_params_file(path: str | Path, node_name: str = 'correct_node') -> dict[str, ParamValue]:
    """
    Read a ROS 2 params file (``/**: ros__parameters:`` or ``<node>: ros__parameters:``).

    Nested keys are flattened with dots (``lens: {r1_mm: 4.0}`` -> ``lens.r1_mm``), as
    rclpy does. Sections for ``/**``, ``/**/node_name``, ``node_name`` and ``/node_name`` are
    merged in that order; others are ignored.

    :param path: the YAML file.
    :param node_name: the node whose section applies besides ``/**``.
    :return: the checked values of every schema parameter (defaults where the file is silent).
    :raises ValueError: when the file is not a params file or holds a bad value.
    :raises OSError: when the file cannot be read.
    """
    return check_values(read_params_file(path, node_name))


def read_params_file(path: str | Path, node_name: str) -> dict[str, Any]:
    """
    Read a ROS 2 params file's values for one node, flattened but not checked.

    The sections ``/**``, ``/**/node_name`` (rcl's key for the node in any namespace, what a
    file for ``ros2 launch ... namespace:=x`` needs: a bare ``node_name`` key only matches the
    node in the root namespace), ``node_name`` and ``/node_name`` are merged in that order;
    ``use_sim_time`` and ``qos_overrides.*`` (rclpy's own) are dropped.

    :param path: the YAML file.
    :param node_name: the node whose section applies besides ``/**``.
    :return: dotted name -> value as written.
    :raises ValueError: when the file is not a params file.
    :raises OSError: when the file cannot be read.
    """
    with open(path, encoding='utf-8') as stream:
        try:
            document = yaml.safe_load(stream)
        except yaml.YAMLError as err:
            raise ValueError(f'{path}: not valid YAML ({err})') from None
    if not isinstance(document, dict):
        raise ValueError(f'{path}: expected a ROS 2 params file ("/**: ros__parameters: ...")')
    merged: dict[str, Any] = {}
    found = False
    for key in ('/**', '/**/' + node_name, node_name, '/' + node_name):
        section = document.get(key)
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict):
            merged.update(flatten(section['ros__parameters']))
            found = True
    if not found:
        raise ValueError(f'{path}: no "/**" or "{node_name}" section with ros__parameters')
    return {k: v for k, v in merged.items() if k != 'use_sim_time' and
            not k.startswith('qos_overrides.')}


def flatten(tree: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """
    Flatten nested YAML mappings into dotted parameter names.

    :param tree: the ``ros__parameters`` mapping.
    :param prefix: the dotted prefix of ``tree`` itself.
    :return: ``{'lens.r1_mm': 4.0, ...}``.
    """
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            flat.update(flatten(value, name + '.'))
        else:
            flat[name] = value
    return flat


def to_params_yaml(values: Mapping[str, Any], node_name: str = '/**',
                   names: Sequence[str] | None = None) -> str:
    """
    Write values as a ROS 2 params file, nested by the dotted names.

    :param values: parameter name -> value.
    :param node_name: the section key (``/**`` matches every node).
    :param names: the names to write, in order; default every name in ``values``.
    :return: YAML text; floats always carry a decimal point, as rclpy requires for doubles.
    """
    tree: dict[str, Any] = {}
    for name in names if names is not None else list(values):
        node = tree
        *parents, leaf = name.split('.')
        for part in parents:
            node = node.setdefault(part, {})
        value = values[name]
        if isinstance(value, list):
            spec = SPECS.get(name)
            if spec is not None and spec.type == 'integer_array':
                value = [int(v) for v in value]
            else:
                value = [v if isinstance(v, str) else float(v) for v in value]
        node[leaf] = value
    return yaml.safe_dump({node_name: {'ros__parameters': tree}}, sort_keys=False)
