# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``demo_camera``: a simulated camera that looks at a flat target through the modelled lens.

It publishes ``image_raw`` (sensor_msgs/Image) at ``rate_hz``, rendered through the SAME lens
model that ``correct_node`` corrects with (:func:`mechdeconv_ros.model.model.build_model` and
:func:`mechdeconv_ros.imaging.remap.distort_image`), so the node's output should show the target
undistorted. The target is the paper's 20 x 18 box grid
(:func:`mechdeconv_ros.tools.plots.grid_image`) on coloured checker cells, a flat chart at
``scene.distance_mm`` in front of the lens.

The camera declares the schema's ``lens.*``, ``sensor.*`` and ``scene.*`` parameters, and reads
the same params files (``/**`` sections apply to every node), so::

    demo_camera --ros-args --params-file config/case2.yaml

renders through the Case 2 lens. With ``transport:=compressed`` it publishes
``image_raw/compressed`` (sensor_msgs/CompressedImage) instead, named and formatted as
image_transport's ``compressed`` plugin does: the resolved ``image_raw`` plus ``/compressed``,
format ``"<encoding>; jpeg compressed bgr8"`` (or ``png``), with the plugin's parameter names
``image_raw.compressed.format``, ``.jpeg_quality`` and ``.png_level``.

A lens parameter set on the camera (``ros2 param set /demo_camera lens.stop_offset_mm 0.6``)
simulates a physical change of the real lens; the user then tells ``correct_node`` the same
values. The demo (:mod:`mechdeconv_ros.tools.demo`) does both.

Geometry: the chart is fixed in the world. Its texture is drawn at the resolution of the first
model's corrected image and mapped with that model's ``K_new`` (normalised coordinates
``x_n = X / l`` to texture pixels), scaled by ``l / l_0`` when the scene distance changes. A
later lens (another focal length, stop offset) therefore sees the same chart at another scale
and distortion, as a real camera would.

A lens whose groups move (``lens.zoom.joint`` / ``lens.focus.joint``, issue 19) is swept:
every moving mechanism runs through its table and back, one way in ``lens_sweep_s``
seconds; each tick publishes ``lens_state`` (sensor_msgs/JointState: the joints and their
positions) and then the frame, both with the same stamp, the frame rendered at that state
(the chart through the model of that state, interpolated over a grid of states as the node
does, :func:`mechdeconv_ros.imaging.moving_maps.render_grid`; built at start-up, seconds).

Publishing follows docs/design.md section 4.4 (pixels in and out of rclpy): one ``Image`` per
size and encoding, ``data`` set once to ``array.array('B', bytes(n))`` and written through a
numpy view (:func:`mechdeconv_ros.node.image_msgs.new_output_image`). The chart is static, so the
pixels are rendered (and compressed) once per model and each tick only sets ``header.stamp``
(the publish time) and publishes.
"""

from __future__ import annotations

import array
from typing import Any, Sequence

import cv2
from mechdeconv_ros.imaging.moving_maps import is_moving, MovingMaps, render_grid
from mechdeconv_ros.imaging.remap import distortion_maps
from mechdeconv_ros.model.model import build_model, LensModel, ModelError
from mechdeconv_ros.node.compressed import CODECS, DEFAULT_JPEG_QUALITY, DEFAULT_PNG_LEVEL, encode
from mechdeconv_ros.node.image_msgs import ImageFormatError, new_output_image, OutputImage
from mechdeconv_ros.node.node_main import run_node
from mechdeconv_ros.node.ros_params import declare_schema
from mechdeconv_ros.schema.params import check_values, load_params_file, ParamSpec, SCHEMA
from mechdeconv_ros.tools.plots import grid_image
import numpy as np
import numpy.typing as npt
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult)
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import CompressedImage, JointState

#: Schema groups the camera declares: what defines the lens, the sensor and the scene.
CAMERA_GROUPS = ('lens', 'sensor', 'scene')
#: Grey level of the wall around the chart (and of anything outside the lens's valid field).
WALL = 40
#: Encodings the camera renders (8 bits per channel, and mono16 scaled from mono8).
CAMERA_ENCODINGS = ('rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8', 'mono16')
#: What the camera publishes: ``image_raw`` (raw) or ``image_raw/compressed`` (compressed).
TRANSPORTS = ('raw', 'compressed')
#: Parameter prefix of the compressed output, as image_transport names it for image_raw.
COMPRESSED_PREFIX = 'image_raw.compressed.'


def camera_specs() -> tuple[ParamSpec, ...]:
    """
    Return the schema parameters the camera declares (``lens.*``, ``sensor.*``, ``scene.*``).

    :return: the specs, in schema order.
    """
    return tuple(spec for spec in SCHEMA if spec.group in CAMERA_GROUPS)


def chart_texture(width: int, height: int) -> npt.NDArray[np.uint8]:
    """
    Draw the target: white box-grid lines on coloured checker cells, dark outside the grid.

    Hue runs left to right, brightness alternates between neighbouring cells, so both the
    straightness of the lines and the position of each cell are easy to see.

    :param width: texture width in px.
    :param height: texture height in px.
    :return: ``(height, width, 3)`` uint8, RGB.
    """
    cells_x, cells_y = 20, 18
    lines = grid_image(width, height, cells_x, cells_y)
    edges_x = np.linspace(0.04 * width, width - 1 - 0.04 * width, cells_x + 1)
    edges_y = np.linspace(0.04 * height, height - 1 - 0.04 * height, cells_y + 1)
    cell_x = np.searchsorted(edges_x, np.arange(width)) - 1
    cell_y = np.searchsorted(edges_y, np.arange(height)) - 1
    inside = ((cell_x[None, :] >= 0) & (cell_x[None, :] < cells_x)
              & (cell_y[:, None] >= 0) & (cell_y[:, None] < cells_y))
    hsv = np.empty((height, width, 3), np.uint8)
    hsv[..., 0] = (np.clip(cell_x, 0, cells_x - 1) * 170 // cells_x).astype(np.uint8)[None, :]
    hsv[..., 1] = 190
    checker = (cell_x[None, :] + cell_y[:, None]) % 2
    hsv[..., 2] = np.where(checker == 0, 215, 120).astype(np.uint8)
    rgb = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    rgb[~inside] = WALL
    rgb[lines > 0] = 255
    return rgb


def convert_rgb(rgb: npt.NDArray[np.uint8], encoding: str) -> npt.NDArray[Any]:
    """
    Convert an RGB rendering to the pixels of an Image encoding.

    :param rgb: ``(H, W, 3)`` uint8.
    :param encoding: one of :data:`CAMERA_ENCODINGS`.
    :return: the pixels, shaped like :func:`mechdeconv_ros.node.image_msgs.image_to_array` returns.
    :raises ValueError: for another encoding.
    """
    if encoding == 'rgb8':
        return rgb
    if encoding == 'bgr8':
        return cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    if encoding == 'rgba8':
        return cv2.cvtColor(rgb, cv2.COLOR_RGB2RGBA)
    if encoding == 'bgra8':
        return cv2.cvtColor(rgb, cv2.COLOR_RGB2BGRA)
    if encoding == 'mono8':
        return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    if encoding == 'mono16':
        return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.uint16) * np.uint16(257)
    raise ValueError(f"encoding '{encoding}' is not one the demo camera renders: "
                     f"{', '.join(CAMERA_ENCODINGS)}")


class Chart:
    """
    The flat target, fixed in the world: a texture and its camera matrix at distance ``l_0``.

    Built from the first lens model so that this model's corrected image shows the texture
    pixel for pixel.
    """

    def __init__(self, model: LensModel) -> None:
        """
        Draw the texture for ``model``'s corrected image size and remember its geometry.

        :param model: the camera's first lens model.
        """
        self.texture = chart_texture(model.out_width, model.out_height)
        self.K = np.array(model.K_new, dtype=np.float64)
        self.distance_mm = float(model.values['scene.distance_mm'])

    def camera_matrix(self, distance_mm: float) -> npt.NDArray[np.float64]:
        """
        Return the texture's camera matrix for the scene at another distance.

        A chart point at lateral position ``X`` is at ``x_n = X / l``; the texture is drawn at
        ``l_0``, so its focal terms scale by ``l / l_0`` (a chart at infinity, ``l = 0``, is
        given in angles and does not scale).

        :param distance_mm: the scene distance (0 = infinity).
        :return: 3x3 matrix from normalised coordinates to texture pixels.
        """
        K = self.K.copy()
        if distance_mm > 0.0 and self.distance_mm > 0.0:
            K[0, 0] *= distance_mm / self.distance_mm
            K[1, 1] *= distance_mm / self.distance_mm
        return K

    def render(self, model: LensModel) -> npt.NDArray[np.uint8]:
        """
        Render what the camera with ``model``'s lens sees of the chart.

        This is :func:`mechdeconv_ros.imaging.remap.distort_image` with the wall colour instead of
        black around the chart.

        :param model: the lens model.
        :return: ``(model.height, model.width, 3)`` uint8 RGB.
        """
        K = self.camera_matrix(float(model.values['scene.distance_mm']))
        map_x, map_y = distortion_maps(model, K)
        return cv2.remap(self.texture, map_x, map_y, cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=(WALL, WALL, WALL))


class DemoCamera(Node):
    """
    Publish ``image_raw`` rendered through a lens model; rebuild on a lens parameter set.

    Parameters: ``width``, ``height``, ``encoding``, ``rate_hz``, ``frame_id``,
    ``transport`` (read once at start-up), ``image_raw.compressed.{format, jpeg_quality,
    png_level}``, ``params_file`` (read once at start-up; its values become the defaults of the
    lens parameters) and the schema's ``lens.*``, ``sensor.*`` and ``scene.*``.
    """

    def __init__(self, **kwargs: Any) -> None:
        """
        Declare the parameters, build the first model and start the timer.

        :param kwargs: forwarded to :class:`rclpy.node.Node` (``context=``,
            ``parameter_overrides=``, ...).
        :raises ModelError: when the start-up parameters describe no camera.
        :raises ValueError: when ``params_file`` cannot be read or another parameter is bad.
        """
        self._pending: tuple[dict[str, Any], LensModel | None, OutputImage | None,
                             CompressedImage | None] | None = None
        super().__init__('demo_camera', **kwargs)
        self._declare(
            'params_file', '', 'ROS 2 params file whose lens.*, sensor.* and scene.* values are '
            'the defaults of those parameters (read once at start-up); empty = the schema '
            "defaults (the paper's Case 2). --params-file overrides win over it.",
            ParameterType.PARAMETER_STRING, read_only=True)
        self._declare('width', 640, 'Image width [px].', ParameterType.PARAMETER_INTEGER,
                      int_range=(1, 16384))
        self._declare('height', 480, 'Image height [px].', ParameterType.PARAMETER_INTEGER,
                      int_range=(1, 16384))
        self._declare('encoding', 'rgb8', 'Image encoding: ' + ', '.join(CAMERA_ENCODINGS) + '.',
                      ParameterType.PARAMETER_STRING)
        self._declare('rate_hz', 30.0, 'Publishing rate [Hz].', ParameterType.PARAMETER_DOUBLE,
                      float_range=(0.1, 1000.0))
        self._declare('lens_sweep_s', 4.0, 'A lens whose groups move (lens.zoom.joint, '
                      'lens.focus.joint) runs through its tables and back, one way in this '
                      'many seconds; 0 = it stays at the first rows. Read once at start-up.',
                      ParameterType.PARAMETER_DOUBLE, float_range=(0.0, 3600.0),
                      read_only=True)
        self._declare('frame_id', 'camera_optical_frame',
                      'header.frame_id of the images (REP-103 optical frame).',
                      ParameterType.PARAMETER_STRING)
        self._declare('transport', 'raw', 'raw: publish image_raw (sensor_msgs/Image); '
                      'compressed: publish image_raw/compressed (sensor_msgs/CompressedImage) '
                      'as image_transport does. Read once at start-up.',
                      ParameterType.PARAMETER_STRING, read_only=True)
        self._declare(COMPRESSED_PREFIX + 'format', 'jpeg', 'Codec of the compressed output: '
                      'jpeg or png.', ParameterType.PARAMETER_STRING)
        self._declare(COMPRESSED_PREFIX + 'jpeg_quality', DEFAULT_JPEG_QUALITY,
                      'JPEG quality of the compressed output (1-100).',
                      ParameterType.PARAMETER_INTEGER, int_range=(1, 100))
        self._declare(COMPRESSED_PREFIX + 'png_level', DEFAULT_PNG_LEVEL,
                      'PNG compression level of the compressed output (0-9).',
                      ParameterType.PARAMETER_INTEGER, int_range=(0, 9))
        self._transport = str(self.get_parameter('transport').value)
        if self._transport not in TRANSPORTS:
            raise ValueError(f"transport: '{self._transport}' is not one of "
                             f"{', '.join(TRANSPORTS)}")
        base = self._file_values(str(self.get_parameter('params_file').value))
        self._values = self._current_values(declare_schema(self, camera_specs(), base))
        self._model = self._build(self._values)
        self._chart = Chart(self._model)
        self._out = self._render(self._model, self._values)
        self._compressed = self._compress(self._out, self._values)
        # image_transport's name: the RESOLVED base topic plus /compressed, so a remapping of
        # image_raw moves the compressed topic with it.
        topic = ('image_raw' if self._compressed is None
                 else self.resolve_topic_name('image_raw') + '/compressed')
        self._publisher = self.create_publisher(
            type(self._out.msg) if self._compressed is None else CompressedImage, topic,
            qos_profile_sensor_data,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._sweep: MovingMaps | None = None
        self._sweep_s = float(self.get_parameter('lens_sweep_s').value)
        if is_moving(self._model) and self._sweep_s > 0.0:
            if self._compressed is not None:
                raise ValueError('transport: a moving lens is rendered per frame, raw only')
            self._sweep = render_grid(self._model, build_model, self._chart.camera_matrix(
                float(self._values['scene.distance_mm'])))
            self._lens_pub = self.create_publisher(JointState, 'lens_state', 10)
            self._sweep_start = self.get_clock().now().nanoseconds
        self._timer = self.create_timer(1.0 / float(self._values['rate_hz']), self._tick)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)
        self._log_model('publishing')

    # ----------------------------------------------------------------------------------------
    # Parameters
    # ----------------------------------------------------------------------------------------

    def _declare(self, name: str, default: Any, description: str, type_: int, *,
                 read_only: bool = False, int_range: tuple[int, int] | None = None,
                 float_range: tuple[float, float] | None = None) -> None:
        desc = ParameterDescriptor(name=name, type=type_, description=description,
                                   read_only=read_only)
        if int_range is not None:
            desc.integer_range = [IntegerRange(from_value=int_range[0], to_value=int_range[1],
                                               step=0)]
        if float_range is not None:
            desc.floating_point_range = [FloatingPointRange(
                from_value=float_range[0], to_value=float_range[1], step=0.0)]
        self.declare_parameter(name, default, desc)

    def _file_values(self, path: str) -> dict[str, Any]:
        if not path:
            return check_values({})
        try:
            return load_params_file(path, node_name=self.get_name())
        except OSError as err:
            raise ValueError(f'params_file: cannot read {path}: {err.strerror}') from None

    def _current_values(self, lens_values: dict[str, Any]) -> dict[str, Any]:
        names = ['width', 'height', 'encoding', 'rate_hz', 'frame_id']
        names += [COMPRESSED_PREFIX + name for name in ('format', 'jpeg_quality', 'png_level')]
        values = {name: self.get_parameter(name).value for name in names}
        values.update(lens_values)
        return values

    @staticmethod
    def _model_values(values: dict[str, Any]) -> dict[str, Any]:
        return {spec.name: (list(values[spec.name])
                            if spec.type in ('double_array', 'integer_array')
                            else values[spec.name]) for spec in camera_specs()}

    def _build(self, values: dict[str, Any]) -> LensModel:
        """Build the camera's lens model; the image size is the camera's ``width x height``."""
        width, height = int(values['width']), int(values['height'])
        for axis, size in (('width', width), ('height', height)):
            sensor = int(values[f'sensor.{axis}_px'])
            if sensor and sensor != size:
                raise ModelError(f'sensor.{axis}_px',
                                 f'{sensor} px differs from the camera {axis} {size} px: set '
                                 f'both (or sensor.{axis}_px to 0)')
        if values[COMPRESSED_PREFIX + 'format'] not in CODECS:
            raise ModelError(COMPRESSED_PREFIX + 'format',
                             f"'{values[COMPRESSED_PREFIX + 'format']}' is not one of "
                             f"{', '.join(CODECS)}")
        if values['encoding'] not in CAMERA_ENCODINGS:
            raise ModelError('encoding', f"'{values['encoding']}' is not one of "
                                         f"{', '.join(CAMERA_ENCODINGS)}")
        return build_model(self._model_values(values), width, height)

    def _render(self, model: LensModel, values: dict[str, Any]) -> OutputImage:
        """Render the chart through ``model`` into a new preallocated Image."""
        out = new_output_image(model.width, model.height, str(values['encoding']))
        np.copyto(out.pixels, convert_rgb(self._chart.render(model), str(values['encoding'])))
        out.msg.header.frame_id = str(values['frame_id'])
        return out

    def _compress(self, out: OutputImage, values: dict[str, Any]) -> CompressedImage | None:
        """Return ``out`` compressed as image_transport would (None: transport raw)."""
        if self._transport != 'compressed':
            return None
        codec = str(values[COMPRESSED_PREFIX + 'format'])
        fmt, data = encode(out.pixels, out.msg.encoding, codec,
                           jpeg_quality=int(values[COMPRESSED_PREFIX + 'jpeg_quality']),
                           png_level=int(values[COMPRESSED_PREFIX + 'png_level']))
        msg = CompressedImage()
        msg.header.frame_id = out.msg.header.frame_id
        msg.format = fmt
        msg.data = array.array('B', data)
        return msg

    def _on_set(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate a set by building (and rendering) the candidate; never raises."""
        mine = {p.name: p.value for p in parameters if p.name in self._values}
        if not mine:
            return SetParametersResult(successful=True)
        candidate = dict(self._values)
        candidate.update({k: ([] if v is None else v) for k, v in mine.items()})
        rebuild = any(name not in ('rate_hz', 'frame_id') for name in mine)
        try:
            check_values(self._model_values(candidate))
            model = self._build(candidate) if rebuild else None
            out = self._render(model, candidate) if model is not None else None
            compressed = self._compress(out, candidate) if out is not None else None
        except (ValueError, ImageFormatError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        self._pending = (candidate, model, out, compressed)
        return SetParametersResult(successful=True)

    def _post_set(self, parameters: list[Parameter]) -> None:
        """Swap in the candidate validated by :meth:`_on_set`."""
        if self._pending is None:
            return
        candidate, model, out, compressed = self._pending
        self._pending = None
        rate_changed = candidate['rate_hz'] != self._values['rate_hz']
        self._values = candidate
        if model is not None and out is not None:
            self._model, self._out, self._compressed = model, out, compressed
            self._log_model('lens changed')
        self._out.msg.header.frame_id = str(candidate['frame_id'])
        if self._compressed is not None:
            self._compressed.header.frame_id = str(candidate['frame_id'])
        if rate_changed:
            self._timer.cancel()
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(1.0 / float(candidate['rate_hz']), self._tick)

    def _log_model(self, what: str) -> None:
        model = self._model
        transport = ('' if self._compressed is None
                     else f' ({self._compressed.format}, {len(self._compressed.data)} bytes)')
        self.get_logger().info(
            f"{what}: image_raw {model.width}x{model.height} {self._values['encoding']}"
            f'{transport} at '
            f"{float(self._values['rate_hz']):g} Hz through f = {model.focal_length_mm:.4g} mm, "
            f"t = {float(self._values['lens.thickness_mm']):g} mm, stop offset "
            f"{float(self._values['lens.stop_offset_mm']):g} mm (max displacement "
            f'{model.max_displacement_px:.2f} px)')

    # ----------------------------------------------------------------------------------------
    # Publishing
    # ----------------------------------------------------------------------------------------

    def _tick(self) -> None:
        msg = self._out.msg if self._compressed is None else self._compressed
        now = self.get_clock().now()
        msg.header.stamp = now.to_msg()
        if self._sweep is not None:
            self._render_state(now.nanoseconds, msg.header.stamp)
        self._publisher.publish(msg)

    def _render_state(self, now_ns: int, stamp: Any) -> None:
        """Publish the lens state of this tick and render the frame at it."""
        grid = self._sweep
        phase = ((now_ns - self._sweep_start) * 1e-9 / self._sweep_s) % 2.0
        phase = phase if phase <= 1.0 else 2.0 - phase
        state = {m.name: float(a[0] + (a[-1] - a[0]) * phase)
                 for m, a in zip(grid.mechanisms, grid.axes)}
        joints = JointState(name=[m.joint for m in grid.mechanisms],
                            position=[state[m.name] for m in grid.mechanisms])
        joints.header.stamp = stamp
        self._lens_pub.publish(joints)
        _, full = grid.at(state)
        rgb = cv2.remap(self._chart.texture, full, None, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=(WALL, WALL, WALL))
        np.copyto(self._out.pixels, convert_rgb(rgb, str(self._values['encoding'])))


def main(args: Sequence[str] | None = None) -> None:
    """
    Run the demo camera until SIGINT/SIGTERM (exit 0), or exit 1 when it describes no camera.

    Stopped as correct_node is (:func:`mechdeconv_ros.node.node_main.run_node`): a signal only sets
    a flag the spin loop checks, so Ctrl-C or ``ros2 launch`` never ends it with a traceback.

    :param args: command-line arguments, ``--ros-args`` included (default ``sys.argv``).
    """
    run_node(DemoCamera, 'demo_camera', list(args) if args is not None else None)


if __name__ == '__main__':
    main()
