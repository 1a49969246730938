# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
correct_node: live lens-distortion correction from the lens's physical description.

Topics (relative names, so namespaces and remaps apply; ``/diagnostics`` is absolute):

* subscribes ``image_raw`` (sensor_msgs/Image) -- only while an output has a subscriber,
  unless ``lazy_subscription`` is false;
* publishes ``image_rect`` (same encoding, the input header), ``camera_info`` (the raw camera:
  K and the equivalent D of the traced lens, R = I, P = [K_new | 0]) and ``camera_info_rect``
  (the corrected image: K = K_new, D = 0, R = I, the same P), each with the input header.
  A big-endian 16-bit or float input is published in the host's byte order (``is_bigendian``
  says which), with the same values;
* publishes ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) at 1 Hz: the lens summary and
  the frame counters.

Parameters are the schema of :mod:`mechdeconv_ros.params`, declared at start-up with full
descriptors. A set is validated in the on-set callback by building the candidate model
(rejected sets leave everything untouched, with the model's reason). The two set services
are wrapped so that no request can stop the node and every refusal names its parameter
(``_guard_parameter_services``); a prescription has at most :data:`MAX_SURFACES` surfaces.
An accepted set of model parameters is answered at once and handed to a rebuild thread, which
builds the LensModel (reusing the on-set candidate) and the remap tables and then swaps one
reference; frames keep being corrected with the old model meanwhile, and a frame reads the
reference once, so it never mixes two models. Sets that arrive while a rebuild runs are
coalesced: the thread always builds the newest accepted values. The same thread computes the
model summary for /diagnostics after the swap, off the frame path.

A frame of a new size (the first frame, or a camera that changed resolution) is corrected by a
model built synchronously for it in the frame callback: that one frame is late by the build
time, none is dropped. When ``sensor.width_px``/``sensor.height_px`` fix the size and a frame
disagrees, the frame is dropped and counted, with a throttled error.

Threads: the node spins in rclpy's SingleThreadedExecutor and keeps the frame callback short
(1080p rgb8: ~12 ms, mostly ``cv2.remap`` into the preallocated message), so a parameter
service call waits at most one frame; the expensive part of a parameter change (the remap
tables) runs in the rebuild thread.
Measured on a 2-vCPU VM at 30 fps, rclpy's MultiThreadedExecutor (two threads, the frames in
their own callback group) was much worse: its wait loop kept a core busy, 640x480 output fell
from 30 to 5 fps and 1080p from 30 to 18 fps. The frame callback still has its own mutually
exclusive group, so the node stays correct when a user composes it into a multi-threaded
executor.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import math
import signal
import sys
import threading
import time
from typing import Any, Iterable, Mapping

import cv2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mechdeconv_ros.graph_env import keep_large_buffers
from mechdeconv_ros.image_msgs import (
    camera_info_from_model, image_to_array, MalformedImageError, OutputImagePool,
    UnsupportedEncodingError)
from mechdeconv_ros.model import build_model, LensModel
from mechdeconv_ros.params import coerce, MODEL_PARAMS, ParamSpec, ParamValue, SCHEMA, SPECS
from mechdeconv_ros.remap import Rectifier
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, Parameter as ParameterMsg, ParameterDescriptor,
    SetParametersResult)
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.exceptions import (
    InvalidParameterTypeException, InvalidParameterValueException,
    ParameterNotDeclaredException, ParameterUninitializedException)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from sensor_msgs.msg import CameraInfo, Image

#: Image size used to validate parameters before the first frame, when the sensor size is not
#: set (the paper's Case 2 sensor).
NOMINAL_SIZE = (640, 480)
#: Seconds between checks of the output subscriber counts (lazy subscription), as image_proc.
LAZY_POLL_S = 0.5
#: Seconds between diagnostics messages.
DIAGNOSTICS_PERIOD_S = 1.0
#: Minimum seconds between two log lines of the same per-frame problem.
LOG_THROTTLE_S = 5.0
#: Longest wait of the spin loop before it looks at the stop flag of SIGINT/SIGTERM, s.
STOP_POLL_S = 0.1
#: Most surfaces a prescription (``lens.surfaces.*``) may have: as many as ``lens.stop_surface``
#: can index. Validating a set traces every surface in the executor thread (about 0.2 ms per
#: surface), so an unbounded array would stall the frames for as long as the sender likes.
MAX_SURFACES = int(SPECS['lens.stop_surface'].maximum) + 1
#: The type codes of rcl_interfaces/msg/ParameterType that rclpy can parse.
PARAMETER_TYPES = frozenset(t.value for t in Parameter.Type)


def sensor_qos() -> QoSProfile:
    """
    Return the default QoS of the image and camera-info topics.

    Best effort, keep last 1, volatile: a live stream wants the newest frame, never a queue of
    old ones, and a best-effort subscription matches reliable and best-effort publishers. Users
    can change history, depth and reliability per topic with the ``qos_overrides.*`` parameters.

    :return: a new profile.
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


def descriptor_for(spec: ParamSpec) -> ParameterDescriptor:
    """
    Turn a schema entry into the ParameterDescriptor that ``ros2 param describe`` shows.

    Scalar bounds become a FloatingPointRange / IntegerRange, which rclpy enforces (inclusive).
    Array bounds and string choices go to ``additional_constraints`` (rclpy does not enforce
    them; the on-set callback does).

    :param spec: the parameter's spec.
    :return: the descriptor (its ``type`` is set by the declaration).
    """
    if spec.unit == '1':
        unit = ' Unit: 1 (dimensionless).'
    elif spec.unit:
        unit = f' Unit: {spec.unit}.'
    else:
        unit = ''
    descriptor = ParameterDescriptor(description=spec.description + unit,
                                     read_only=spec.read_only)
    low, high = spec.minimum, spec.maximum
    if spec.type == 'double' and (low is not None or high is not None):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(low) if low is not None else -sys.float_info.max,
            to_value=float(high) if high is not None else sys.float_info.max, step=0.0)]
    elif spec.type == 'integer' and (low is not None or high is not None):
        descriptor.integer_range = [IntegerRange(
            from_value=int(low) if low is not None else -(2 ** 63),
            to_value=int(high) if high is not None else 2 ** 63 - 1, step=1)]
    constraints = []
    if spec.choices:
        constraints.append('One of: ' + ', '.join(spec.choices) + '.')
    if spec.type == 'double_array' and (low is not None or high is not None):
        constraints.append(f'Every element in [{low:g}, {high:g}] {spec.unit}.'.replace(
            ' 1.', '.'))
    descriptor.additional_constraints = ' '.join(constraints)
    return descriptor


def _model_key(values: Mapping[str, Any], size: tuple[int, int]) -> tuple[Any, ...]:
    """Return a hashable key of the model parameters and the image size."""
    return (size,) + tuple(
        (name, tuple(values[name]) if isinstance(values[name], list) else values[name])
        for name in MODEL_PARAMS)


@dataclass(frozen=True)
class ActiveModel:
    """
    What a frame is corrected with: swapped as ONE reference, read once per frame.

    ``values_generation`` counts accepted parameter sets, so an older build never replaces a
    newer one.
    """

    model: LensModel
    rectifier: Rectifier
    revision: int
    values_generation: int
    info_raw: CameraInfo
    info_rect: CameraInfo
    build_ms: float


class FrameStats:
    """Frame counters and timings, written by the frame callback, read by diagnostics."""

    def __init__(self) -> None:
        """Start all counters at zero."""
        self.frames_in = 0
        self.frames_out = 0
        self.frames_dropped = 0
        self.frames_failed = 0
        self.rejected_encodings = 0
        self.last_rejected_encoding = ''
        self.last_error = ''
        self.frame_ms_last = math.nan
        self.frame_ms_max = 0.0         # since the last diagnostics message
        self.frame_ms_sum = 0.0         # since the last diagnostics message
        self.frame_count = 0            # since the last diagnostics message

    def add_time(self, ms: float) -> None:
        """Record the processing time of one published frame."""
        self.frame_ms_last = ms
        self.frame_ms_max = max(self.frame_ms_max, ms)
        self.frame_ms_sum += ms
        self.frame_count += 1

    def take_period(self) -> tuple[float, float, int]:
        """Return ``(mean ms, max ms, frames)`` since the last call and restart the period."""
        count = self.frame_count
        mean = self.frame_ms_sum / count if count else math.nan
        peak = self.frame_ms_max if count else math.nan
        self.frame_ms_sum, self.frame_ms_max, self.frame_count = 0.0, 0.0, 0
        return mean, peak, count


class CorrectNode(Node):
    """The lens-correction node: parameters -> lens model -> remap of every frame."""

    def __init__(self, **kwargs: Any) -> None:
        """
        Declare the parameters, validate them, create the topics and start the rebuild thread.

        :param kwargs: forwarded to :class:`rclpy.node.Node` (``context``,
            ``parameter_overrides``, ``cli_args``, ...).
        :raises ValueError: when the start-up parameters are invalid (the message names them).
        """
        self._lock = threading.Condition()
        self._values: dict[str, ParamValue] = {}
        self._values_generation = 0
        self._rebuild_pending = False
        self._rebuild_requested = False
        self._stopping = False
        self._input_size: tuple[int, int] | None = None
        self._active: ActiveModel | None = None
        self._revision = 0
        self._rebuilds = 0
        self._rebuild_failures = 0
        self._rebuild_error = ''
        self._last_rebuild_ms = math.nan
        self._validated: tuple[tuple[Any, ...], LensModel] | None = None
        self._report_cache: tuple[int, dict[str, Any]] | None = None
        self._report_wanted = False
        self._warmed_size: tuple[int, int] | None = None
        self._failed_build: tuple[int, int, int] | None = None
        self._stats = FrameStats()
        self._pool = OutputImagePool()
        self._subscription: Subscription | None = None
        self._worker: threading.Thread | None = None
        self._allow_undeclared = bool(kwargs.get('allow_undeclared_parameters', False))
        super().__init__('correct_node', **kwargs)
        self._guard_parameter_services()

        self._values = self._declare_parameters()
        # Validate the assembled start-up set once (raises ModelError with the reason).
        size = self._validation_size(self._values)
        startup_model = build_model(self._values, *size)
        self._apply_threads(self._values)

        self._frame_group = MutuallyExclusiveCallbackGroup()
        qos = sensor_qos()
        overrides = QoSOverridingOptions.with_default_policies()
        self._pub_image: Publisher = self.create_publisher(
            Image, 'image_rect', qos, qos_overriding_options=overrides)
        self._pub_info: Publisher = self.create_publisher(
            CameraInfo, 'camera_info', sensor_qos(), qos_overriding_options=overrides)
        self._pub_info_rect: Publisher = self.create_publisher(
            CameraInfo, 'camera_info_rect', sensor_qos(), qos_overriding_options=overrides)
        self._pub_diag: Publisher = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._outputs = (self._pub_image, self._pub_info, self._pub_info_rect)

        if self._sensor_size_fixed(self._values):
            # The size is known: build the maps now, so the first frame is not late.
            with self._lock:
                self._input_size = (startup_model.width, startup_model.height)
                self._install_locked(
                    self._make_active(startup_model, self._values_generation, 0.0))

        self._rebuild_trigger = self.create_guard_condition(self._request_rebuild)
        self._worker = threading.Thread(target=self._rebuild_loop, name='mechdeconv-rebuild',
                                        daemon=True)
        self._worker.start()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._post_set_parameters)
        self._update_subscription()
        self.create_timer(LAZY_POLL_S, self._update_subscription)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        self.get_logger().info(
            f'ready: f = {startup_model.focal_length_mm:.4g} mm, '
            f'{"lazy subscription" if self._values["lazy_subscription"] else "subscribed"} to '
            f'{self.resolve_topic_name("image_raw")}')

    # -----------------------------------------------------------------------------------------
    # Parameters
    # -----------------------------------------------------------------------------------------

    def _declare_parameters(self) -> dict[str, ParamValue]:
        """
        Declare every schema parameter with its descriptor and return the checked values.

        Double arrays are declared statically typed with an empty default, which rclpy cannot
        infer from ``[]`` (it would make a BYTE_ARRAY): they are declared by type, and set to
        ``[]`` when no override gave them a value.

        :return: every schema parameter's value.
        :raises ValueError: listing every parameter whose start-up value is refused.
        """
        errors = []
        for spec in SCHEMA:
            descriptor = descriptor_for(spec)
            try:
                if spec.type == 'double_array':
                    self.declare_parameter(spec.name, Parameter.Type.DOUBLE_ARRAY, descriptor)
                else:
                    self.declare_parameter(spec.name, spec.default, descriptor)
            except InvalidParameterTypeException as err:
                errors.append(f'{spec.name}: {err}{_type_hint(spec)}')
            except InvalidParameterValueException as err:
                errors.append(f'{spec.name}: {err}')
        if errors:
            raise ValueError('invalid start-up parameters:\n  ' + '\n  '.join(errors))
        unset = [Parameter(spec.name, Parameter.Type.DOUBLE_ARRAY, [])
                 for spec in SCHEMA if spec.type == 'double_array'
                 and self.get_parameter_or(spec.name).type_ == Parameter.Type.NOT_SET]
        if unset:
            self.set_parameters(unset)
        values: dict[str, ParamValue] = {}
        for spec in SCHEMA:
            try:
                value = self.get_parameter(spec.name).value
                _check_length(spec, value)
                values[spec.name] = coerce(spec, _plain(value))
            except ParameterUninitializedException:
                values[spec.name] = coerce(spec, spec.default)
            except ValueError as err:
                errors.append(str(err))
        if errors:
            raise ValueError('invalid start-up parameters:\n  ' + '\n  '.join(errors))
        return values

    def _merge(self, parameters: Iterable[Parameter]) -> tuple[dict[str, ParamValue], set[str]]:
        """
        Return current values with the schema parameters of a set applied, and their names.

        :param parameters: the parameters being set (names outside the schema are ignored).
        :return: ``(values, changed names)``.
        :raises ValueError: when a value has the wrong type, is not finite or is out of bounds.
        """
        with self._lock:
            values = dict(self._values)
        changed = set()
        for param in parameters:
            spec = SPECS.get(param.name)
            if spec is None:
                continue
            _check_length(spec, param.value)
            values[param.name] = coerce(spec, _plain(param.value))
            changed.add(param.name)
        return values, changed

    def _guard_parameter_services(self) -> None:
        """
        Wrap rclpy's set_parameters and set_parameters_atomically services.

        rclpy's own handlers let a malformed request kill the node (a type code outside
        rcl_interfaces/msg/ParameterType raises in the executor, which ends ``spin``), lose the
        names of undeclared parameters (its generator is consumed by ``any()``, so the reason
        lists ``[]``; a parameter named ``''`` is even declared), and refuse a wrong type or an
        undeclare without saying which parameter. The wrappers refuse the first two with a
        reason naming the parameter, put the name in front of the others, and turn any other
        exception into a refusal: a request can fail, the node cannot.
        """
        for service in self.services:
            if service.srv_type is SetParameters:
                service.callback = self._guarded_set_parameters(service.callback)
            elif service.srv_type is SetParametersAtomically:
                service.callback = self._guarded_set_parameters_atomically(service.callback)

    def _guarded_set_parameters(self, handler: Any) -> Any:
        def callback(request: Any, response: Any) -> Any:
            for msg in request.parameters:
                reason = self._refusal_before_rclpy(msg)
                if reason is None:
                    single = SetParameters.Response()
                    try:
                        handler(SetParameters.Request(parameters=[msg]), single)
                        result = single.results[0]
                    except Exception as err:    # noqa: B902 - a request fails, not the node
                        result = SetParametersResult(successful=False,
                                                     reason=f'{msg.name}: {err}')
                    result = self._name_in_reason(result, [msg])
                else:
                    result = SetParametersResult(successful=False, reason=reason)
                response.results.append(result)
            self._start_rebuild_of_request()
            return response
        return callback

    def _guarded_set_parameters_atomically(self, handler: Any) -> Any:
        def callback(request: Any, response: Any) -> Any:
            reasons = [reason for reason in map(self._refusal_before_rclpy, request.parameters)
                       if reason is not None]
            if reasons:
                response.result = SetParametersResult(successful=False,
                                                      reason='; '.join(reasons))
                return response
            try:
                handler(request, response)
            except Exception as err:    # noqa: B902 - a request fails, not the node
                response.result = SetParametersResult(
                    successful=False, reason=f'{", ".join(p.name for p in request.parameters)}'
                                             f': {err}')
            response.result = self._name_in_reason(response.result, request.parameters)
            self._start_rebuild_of_request()
            return response
        return callback

    def _refusal_before_rclpy(self, msg: ParameterMsg) -> str | None:
        """Return why rclpy must not see this parameter message, or None."""
        if msg.value.type not in PARAMETER_TYPES:
            return (f'{msg.name}: unknown parameter type {msg.value.type} (rcl_interfaces/msg/'
                    f'ParameterType has {min(PARAMETER_TYPES)} to {max(PARAMETER_TYPES)})')
        if not self._allow_undeclared and not self.has_parameter(msg.name):
            return f'{msg.name!r}: correct_node has no such parameter (see ros2 param list)'
        return None

    def _name_in_reason(self, result: SetParametersResult,
                        messages: Iterable[ParameterMsg]) -> SetParametersResult:
        """Put the parameter at fault in front of a refusal that does not name it."""
        messages = list(messages)
        if result.successful or any(m.name and m.name in result.reason for m in messages):
            return result
        culprit = messages[0].name if messages else ''
        hint = ''
        for msg in messages:
            try:
                descriptor = self.describe_parameter(msg.name)
            except ParameterNotDeclaredException:
                continue
            if descriptor.read_only or (not descriptor.dynamic_typing and msg.value.type not in (
                    descriptor.type, Parameter.Type.NOT_SET.value)):
                culprit = msg.name
                spec = SPECS.get(msg.name)
                if spec is not None and msg.value.type == Parameter.Type.INTEGER.value:
                    hint = _type_hint(spec)
                break
            if msg.value.type == Parameter.Type.NOT_SET.value:
                culprit = msg.name
                break
        return SetParametersResult(successful=False, reason=f'{culprit}: {result.reason}{hint}')

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """
        Validate a parameter set by building the candidate model; never raises.

        :param parameters: the proposed parameters.
        :return: success, or failure with the reason (the parameter at fault and why).
        """
        try:
            values, changed = self._merge(parameters)
            if changed & set(MODEL_PARAMS):
                size = self._validation_size(values)
                model = build_model(values, *size)
                self._validated = (_model_key(values, size), model)
        except ValueError as err:       # ModelError is a ValueError
            return SetParametersResult(successful=False, reason=str(err))
        except Exception as err:        # noqa: B902 - a callback must never raise
            return SetParametersResult(successful=False,
                                       reason=f'internal error while validating: {err!r}')
        return SetParametersResult(successful=True)

    def _post_set_parameters(self, parameters: list[Parameter]) -> None:
        """
        Commit an accepted set: hand model changes to the rebuild thread, apply the others.

        :param parameters: the parameters that were set (already validated).
        """
        try:
            values, changed = self._merge(parameters)
        except ValueError as err:       # cannot happen after on-set; never raise from here
            self.get_logger().error(f'accepted parameters do not check: {err}')
            return
        if not changed:
            return
        with self._lock:
            model_changed = any(values[name] != self._values[name]
                                for name in changed & set(MODEL_PARAMS))
            self._values = values
            if model_changed:               # setting a parameter to its value rebuilds nothing
                self._values_generation += 1
        if model_changed:
            # Rebuild once per request, not per parameter: rclpy's parameter service applies a
            # multi-parameter set_parameters (what `ros2 param load` sends) one parameter at a
            # time inside one callback. The wrapped services wake the rebuild thread at the end
            # of the request; the guard condition (its callback runs after the request) is the
            # fallback for a set that does not come through them, e.g. a composed node's own
            # set_parameters() call.
            self._rebuild_requested = True
            self._rebuild_trigger.trigger()
        if 'remap_threads' in changed:
            self._apply_threads(values)
        if 'lazy_subscription' in changed:
            self._update_subscription()

    def _start_rebuild_of_request(self) -> None:
        """
        Hand an accepted request's model change to the rebuild thread before the reply.

        The reply goes out at once and the maps are built off the executor, so frames keep
        flowing with the old model meanwhile. Waking the thread here, rather than from the
        guard condition's callback, saves waiting for the executor to come round to it (up to
        a frame callback); the guard condition then finds the build under way or done.
        """
        if not self._rebuild_requested:
            return
        self._rebuild_requested = False
        with self._lock:
            self._rebuild_pending = True
            self._lock.notify_all()

    def _request_rebuild(self) -> None:
        """Wake the rebuild thread for the newest accepted values (guard-condition callback)."""
        with self._lock:
            self._rebuild_pending = True
            self._lock.notify_all()

    def _validation_size(self, values: Mapping[str, Any]) -> tuple[int, int]:
        """Return the image size to build a candidate model for (``build_model``'s inputs)."""
        with self._lock:
            size = self._input_size
        if size is not None:
            return size
        return NOMINAL_SIZE

    @staticmethod
    def _sensor_size_fixed(values: Mapping[str, Any]) -> bool:
        return bool(values['sensor.width_px']) and bool(values['sensor.height_px'])

    @staticmethod
    def _apply_threads(values: Mapping[str, Any]) -> None:
        threads = int(values['remap_threads'])
        cv2.setNumThreads(threads if threads > 0 else -1)

    # -----------------------------------------------------------------------------------------
    # Models
    # -----------------------------------------------------------------------------------------

    def _make_active(self, model: LensModel, generation: int, build_ms: float) -> ActiveModel:
        """Build the remap tables and the CameraInfo messages of a model (not installed)."""
        start = time.perf_counter()
        rectifier = Rectifier(model)
        total_ms = build_ms + (time.perf_counter() - start) * 1e3
        return ActiveModel(model=model, rectifier=rectifier, revision=0,
                           values_generation=generation,
                           info_raw=camera_info_from_model(model, rectified=False),
                           info_rect=camera_info_from_model(model, rectified=True),
                           build_ms=total_ms)

    def _install_locked(self, candidate: ActiveModel) -> ActiveModel:
        """
        Swap a freshly built model in, unless the same or a newer one of its size is active.

        (The same one: when two builds of the newest values race, say the rebuild thread's
        and a frame's of a new size, the second is not a new revision.)

        Call with ``self._lock`` held. When the model installed is older than the newest
        accepted parameters, the rebuild thread is asked to build those.

        :param candidate: the model to install.
        :return: the model frames of this size now use.
        """
        current = self._active
        if (current is not None
                and current.values_generation >= candidate.values_generation
                and (current.model.width, current.model.height)
                == (candidate.model.width, candidate.model.height)):
            return current
        self._revision += 1
        self._rebuilds += 1
        installed = ActiveModel(
            model=candidate.model, rectifier=candidate.rectifier, revision=self._revision,
            values_generation=candidate.values_generation, info_raw=candidate.info_raw,
            info_rect=candidate.info_rect, build_ms=candidate.build_ms)
        self._active = installed                # the one atomic swap frames see
        self._last_rebuild_ms = candidate.build_ms
        self._rebuild_error = ''
        self._report_wanted = True              # the rebuild thread summarises it
        self._lock.notify_all()
        if installed.values_generation < self._values_generation:
            self._rebuild_pending = True
            self._lock.notify_all()
        return installed

    def _build(self, values: Mapping[str, Any], generation: int,
               size: tuple[int, int]) -> ActiveModel:
        """Build a model and its tables, reusing the on-set callback's candidate if it fits."""
        start = time.perf_counter()
        validated = self._validated
        if validated is not None and validated[0] == _model_key(values, size):
            model = validated[1]
        else:
            model = build_model(values, *size)
        return self._make_active(model, generation, (time.perf_counter() - start) * 1e3)

    def _rebuild_loop(self) -> None:
        """Rebuild the model whenever an accepted set asks for it; coalesce bursts."""
        while True:
            with self._lock:
                while not (self._rebuild_pending or self._report_wanted or self._stopping):
                    self._lock.wait()
                if self._stopping:
                    return
                rebuild, self._rebuild_pending = self._rebuild_pending, False
                self._report_wanted = False
                values, generation = dict(self._values), self._values_generation
                size = self._input_size
                active = self._active
            if rebuild:
                self._rebuild(values, generation, size, active)
            # The model in use gets its summary (cached per revision: free when it has one).
            self._summarize(self._active)
            self._warm_allocator(self._active)

    def _warm_allocator(self, active: ActiveModel | None) -> None:
        """
        Build and drop one set of remap tables once per frame size (rebuild thread).

        The first rebuild after a new size is installed otherwise takes its buffers (tens of
        MB at 1080p: maps and their intermediates) from fresh pages while the active tables
        hold the others: measured 40-65 ms instead of 8-10 ms at 1920x1080, which made the
        first parameter sets after start-up miss two frame periods. With the malloc settings
        of :func:`keep_large_buffers`, the dropped buffers stay in the heap for that rebuild.
        """
        if active is None:
            return
        size = (active.model.width, active.model.height)
        if self._warmed_size == size:
            return
        self._warmed_size = size
        try:
            Rectifier(active.model)
        except Exception as err:    # noqa: B902 - an optimisation must never stop the thread
            self.get_logger().warning(f'allocator warm-up failed: {err!r}')

    def _rebuild(self, values: dict[str, ParamValue], generation: int,
                 size: tuple[int, int] | None, active: ActiveModel | None) -> None:
        """Build and install the model of the newest accepted values (rebuild thread)."""
        if (active is not None and active.values_generation == generation
                and (active.model.width, active.model.height) == size):
            return          # a burst was coalesced into a build that is already in use
        if size is None and not self._sensor_size_fixed(values):
            return          # no frame yet: the first frame builds with the newest values
        size = size or NOMINAL_SIZE
        try:
            candidate = self._build(values, generation, size)
        except Exception as err:    # noqa: B902 - keep the thread and the old model alive
            with self._lock:
                self._rebuild_failures += 1
                self._rebuild_error = str(err)
            self.get_logger().error(f'rebuild failed, the previous model stays in use: {err}')
            return
        with self._lock:
            if self._input_size is not None and self._input_size != size:
                # A frame of another size arrived meanwhile and built its own model; make sure
                # the newest values get built for that size too.
                if generation >= self._values_generation:
                    self._rebuild_pending = True
                return
            self._install_locked(candidate)

    def _summarize(self, active: ActiveModel | None) -> None:
        """Compute the summary of a model for diagnostics (rebuild thread; never raises)."""
        if active is None:
            return
        try:
            self._report_of(active)
        except Exception as err:    # noqa: B902 - a summary must not stop the rebuilds
            self.get_logger().warning(f'model summary failed: {err!r}')

    def _model_for_frame(self, width: int, height: int) -> ActiveModel | None:
        """
        Return the model to correct a frame of this size with, building it if needed.

        :param width: the frame's width.
        :param height: the frame's height.
        :return: the model, or None when the frame must be dropped (reason logged, counted).
        """
        active = self._active                       # read the reference once
        if active is not None and (active.model.width, active.model.height) == (width, height):
            return active
        with self._lock:
            values, generation = dict(self._values), self._values_generation
        fixed_w, fixed_h = int(values['sensor.width_px']), int(values['sensor.height_px'])
        if (fixed_w and fixed_w != width) or (fixed_h and fixed_h != height):
            self._stats.frames_dropped += 1
            self._stats.last_error = (
                f'frame is {width}x{height} px but sensor.width_px x sensor.height_px is '
                f'{fixed_w or width}x{fixed_h or height}')
            self.get_logger().error(
                f'dropping frames: {self._stats.last_error}; set both to 0 to follow the '
                'images, or fix the camera resolution', throttle_duration_sec=LOG_THROTTLE_S)
            return None
        if self._failed_build == (generation, width, height):
            self._stats.frames_dropped += 1     # known to fail: do not rebuild every frame
            return None
        with self._lock:
            previous_size, self._input_size = self._input_size, (width, height)
        try:
            candidate = self._build(values, generation, (width, height))
        except Exception as err:        # noqa: B902 - drop the frame, never the node
            with self._lock:
                # No model of this size exists: parameter sets and rebuilds keep following
                # the frames the node does correct, not the one it could not.
                if self._input_size == (width, height):
                    self._input_size = previous_size
            self._failed_build = (generation, width, height)
            self._stats.frames_dropped += 1
            self._stats.last_error = f'no model for {width}x{height} px: {err}'
            self.get_logger().error(f'dropping frames: {self._stats.last_error}',
                                    throttle_duration_sec=LOG_THROTTLE_S)
            return None
        self.get_logger().info(
            f'input is {width}x{height} px: model built in {candidate.build_ms:.1f} ms')
        with self._lock:
            if self._input_size != (width, height):
                return candidate        # yet another size came in meanwhile: use, not install
            return self._install_locked(candidate)

    # -----------------------------------------------------------------------------------------
    # Frames
    # -----------------------------------------------------------------------------------------

    def _on_image(self, msg: Image) -> None:
        """Correct one frame and publish it with both CameraInfos; never raises."""
        start = time.perf_counter()
        stats = self._stats
        stats.frames_in += 1
        try:
            pixels, encoding = image_to_array(msg)
        except UnsupportedEncodingError as err:
            stats.rejected_encodings += 1
            stats.last_rejected_encoding = err.encoding
            stats.last_error = str(err)
            self.get_logger().error(f'{err} ({stats.rejected_encodings} frames so far)',
                                    throttle_duration_sec=LOG_THROTTLE_S)
            return
        except MalformedImageError as err:
            stats.frames_failed += 1
            stats.last_error = f'malformed frame: {err}'
            self.get_logger().error(f'{stats.last_error} ({stats.frames_failed} so far)',
                                    throttle_duration_sec=LOG_THROTTLE_S)
            return
        except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
            stats.frames_failed += 1
            stats.last_error = f'unreadable frame: {err!r}'
            self.get_logger().error(stats.last_error, throttle_duration_sec=LOG_THROTTLE_S)
            return
        active = self._model_for_frame(int(msg.width), int(msg.height))
        if active is None:
            return
        try:
            model = active.model
            out = self._pool.get(model.out_width, model.out_height, msg.encoding)
            active.rectifier.correct(pixels, out.pixels, nearest=encoding.depth)
            out.msg.header = msg.header
            active.info_raw.header = msg.header
            active.info_rect.header = msg.header
            self._pub_image.publish(out.msg)
            self._pub_info.publish(active.info_raw)
            self._pub_info_rect.publish(active.info_rect)
        except Exception as err:        # noqa: B902 - one bad frame must not stop the stream
            stats.frames_failed += 1
            stats.last_error = f'correction failed: {err}'
            self.get_logger().error(stats.last_error, throttle_duration_sec=LOG_THROTTLE_S)
            return
        stats.frames_out += 1
        stats.add_time((time.perf_counter() - start) * 1e3)

    def _update_subscription(self) -> None:
        """Subscribe to image_raw while it is needed (lazy), unsubscribe when it is not."""
        with self._lock:
            lazy = bool(self._values['lazy_subscription'])
        wanted = not lazy or any(pub.get_subscription_count() > 0 for pub in self._outputs)
        if wanted and self._subscription is None:
            try:
                self._subscription = self.create_subscription(
                    Image, 'image_raw', self._on_image, sensor_qos(),
                    callback_group=self._frame_group,
                    qos_overriding_options=QoSOverridingOptions.with_default_policies())
            except Exception as err:    # noqa: B902 - e.g. a bad qos_overrides value
                self._stats.last_error = f'cannot subscribe to image_raw: {err}'
                self.get_logger().error(self._stats.last_error,
                                        throttle_duration_sec=LOG_THROTTLE_S)
                return
            self.get_logger().debug('subscribed to image_raw')
        elif not wanted and self._subscription is not None:
            self.destroy_subscription(self._subscription)
            self._subscription = None
            self.get_logger().debug('no subscriber on the outputs: unsubscribed from image_raw')

    # -----------------------------------------------------------------------------------------
    # Diagnostics
    # -----------------------------------------------------------------------------------------

    def _publish_diagnostics(self) -> None:
        """Publish the model summary and the counters on /diagnostics."""
        try:
            self._pub_diag.publish(self.diagnostics())
        except Exception as err:        # noqa: B902 - diagnostics must not stop the node
            self.get_logger().error(f'diagnostics failed: {err!r}',
                                    throttle_duration_sec=LOG_THROTTLE_S)

    def _report_of(self, active: ActiveModel) -> dict[str, Any]:
        """
        Return the model summary of an active model, computed once per revision.

        The summary (tolerance propagation, depth of field, ...) costs a few ms for the thick
        lens but grows with the surfaces of a prescription (about 2.4 s for 256), so it is
        computed only in the rebuild thread, after the swap: never on the path from a parameter
        set to the first corrected frame, and never in the executor, where it would hold up the
        frames. Until it is ready, diagnostics say so (``summary_pending``).
        """
        cached = self._report_cache
        if cached is not None and cached[0] == active.revision:
            return cached[1]
        report = active.model.report()
        self._report_cache = (active.revision, report)
        return report

    def diagnostics(self) -> DiagnosticArray:
        """
        Return the current diagnostics: one status with the lens summary and the counters.

        :return: the message, stamped now.
        """
        stats = self._stats
        mean_ms, max_ms, period_frames = stats.take_period()
        with self._lock:
            active = self._active
            pending = self._rebuild_pending
            entries: dict[str, Any] = {
                'model_revision': self._revision,
                'rebuilds': self._rebuilds,
                'rebuild_failures': self._rebuild_failures,
                'last_rebuild_ms': self._last_rebuild_ms,
                'rebuild_pending': pending,
                'input_size_px': ('none yet' if self._input_size is None
                                  else '{}x{}'.format(*self._input_size)),
            }
            rebuild_error = self._rebuild_error
        entries.update({
            'subscribed': self._subscription is not None,
            'frames_in': stats.frames_in,
            'frames_out': stats.frames_out,
            'frames_dropped': stats.frames_dropped,
            'frames_failed': stats.frames_failed,
            'rejected_encodings': stats.rejected_encodings,
            'last_rejected_encoding': stats.last_rejected_encoding,
            'frames_in_last_period': period_frames,
            'frame_time_ms_mean': mean_ms,
            'frame_time_ms_max': max_ms,
            'frame_time_ms_last': stats.frame_ms_last,
            'last_error': stats.last_error,
        })
        status = DiagnosticStatus(name=f'{self.get_name()}: lens correction', hardware_id='')
        warnings: list[str] = []
        summary_pending = False
        if active is not None:
            entries['model_values_generation'] = active.values_generation
            cached = self._report_cache
            if cached is not None and cached[0] == active.revision:
                for key, value in _flatten_report(cached[1]):
                    entries[key] = value
                warnings = list(cached[1].get('warnings', []))
            else:
                summary_pending = True
                with self._lock:
                    self._report_wanted = True
                    self._lock.notify_all()
            entries['summary_pending'] = summary_pending
        if rebuild_error:
            status.level = DiagnosticStatus.ERROR
            status.message = f'rebuild failed, previous model in use: {rebuild_error}'
        elif active is None:
            status.level = DiagnosticStatus.OK
            status.message = 'waiting for the first frame'
        elif warnings:
            status.level = DiagnosticStatus.WARN
            status.message = '; '.join(warnings)
        elif stats.last_error and period_frames == 0 and stats.frames_in > stats.frames_out:
            status.level = DiagnosticStatus.WARN
            status.message = stats.last_error
        else:
            status.level = DiagnosticStatus.OK
            status.message = f'correcting, model revision {entries["model_revision"]}'
            if summary_pending:
                status.message += ' (lens summary being computed)'
        status.values = [KeyValue(key=key, value=_text(value)) for key, value in entries.items()]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        return array

    # -----------------------------------------------------------------------------------------
    # Shutdown
    # -----------------------------------------------------------------------------------------

    def destroy_node(self) -> None:
        """Stop the rebuild thread, then destroy the node."""
        with self._lock:
            self._stopping = True
            self._lock.notify_all()
        if self._worker is not None:
            self._worker.join(timeout=10.0)
        super().destroy_node()


def _plain(value: Any) -> Any:
    """Return a parameter value with arrays as lists (rclpy gives array.array for doubles)."""
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return value.tolist()
    return value


def _check_length(spec: ParamSpec, value: Any) -> None:
    """Refuse a ``lens.surfaces.*`` array longer than :data:`MAX_SURFACES` (before reading it)."""
    if spec.type == 'double_array' and hasattr(value, '__len__') and len(value) > MAX_SURFACES:
        raise ValueError(f'{spec.name}: {len(value)} values, more than the {MAX_SURFACES} '
                         'surfaces a prescription may have')


def _type_hint(spec: ParamSpec) -> str:
    if spec.type == 'double':
        return ' (write doubles with a decimal point, e.g. 4.0 not 4)'
    if spec.type == 'double_array':
        return ' (write every element with a decimal point, e.g. [4.0, -4.0])'
    return ''


def _flatten_report(report: Mapping[str, Any], prefix: str = '') -> Iterable[tuple[str, Any]]:
    """Yield ``(dotted key, value)`` of a model report, skipping the bulky curve."""
    for key, value in report.items():
        if key in ('distortion_curve', 'warnings'):
            continue
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            yield from _flatten_report(value, name + '.')
        else:
            yield name, value


def _text(value: Any) -> str:
    """Format a diagnostics value: compact floats, JSON for lists."""
    if isinstance(value, bool) or value is None:
        return str(value).lower() if isinstance(value, bool) else 'none'
    if isinstance(value, float):
        return f'{value:.6g}'
    if isinstance(value, (list, tuple)):
        return json.dumps(value, default=float)
    return str(value)


def main(args: list[str] | None = None) -> None:
    """
    Run the node until SIGINT/SIGTERM (exit code 0), or exit 1 on invalid parameters.

    SIGINT and SIGTERM only set a flag that the spin loop checks between callbacks. rclpy's own
    handler would raise KeyboardInterrupt wherever the interpreter happens to be; while a
    received image is being converted to Python, rclpy turns that into a RuntimeError, and a
    plain Ctrl-C (or ``ros2 launch`` stopping the node) ends with a traceback and exit code 1.
    A second signal stops the process the default way, should the shutdown ever hang.

    :param args: command-line arguments for rclpy (``--ros-args ...``); default ``sys.argv``.
    """
    keep_large_buffers()
    stop = threading.Event()

    def request_stop(signum: int, frame: Any) -> None:
        stop.set()
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {sig: signal.signal(sig, request_stop)
                    for sig in (signal.SIGINT, signal.SIGTERM)}
    node: CorrectNode | None = None
    failed = False
    try:
        node = CorrectNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not stop.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=STOP_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as err:           # invalid start-up parameters (incl. ModelError)
        rclpy.logging.get_logger('correct_node').fatal(str(err))
        failed = True
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if failed:
        sys.exit(1)


if __name__ == '__main__':
    main()
