# Copyright 2026 The i3dmgx2_driver Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The parameter table (parameter_table.py) applied to a node: declared, checked, assembled.

Every parameter is declared with a descriptor (description, range, read-only
where changing it at run time makes no sense), so ``ros2 param describe``
documents the driver and rclpy rejects out-of-range values. Whatever rclpy
cannot check (choices, what a row ``accepts``) is checked here from the
row, and the rules between parameters (:data:`RULES`) on the assembled
configuration; every failure becomes one ``ParameterError`` whose message
names the parameter and its valid range, and the node stops. Nothing falls
back to a default silently.

Values are taken as people type them (each row's ``Kind``) through rclpy's
public API only: what was given is read through a dynamically typed
declaration, converted, and the parameter then declared with its own type
and descriptor (:func:`given_value`). :func:`driver_config` puts each value
in the configuration its row ``feeds``.

rclpy silently ignores ``-p data_rat:=200.0`` (a typo of ``data_rate``): the
user believes the rate is set. :func:`warn_unknown_parameters` names every
override given on the command line or in a params file (under ``/**`` or the
node's name) that the node does not declare and that is not one of the
driver's own names (they may not be declared yet when a required one is
missing), in one warning each, with the closest real name when one is close.
rclpy's own parameters (``use_sim_time``, ``start_type_description_service``)
are declared by rclpy itself, so they are never reported. Only a missing
required parameter stops the node; an unknown one does not.
"""

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
import difflib
import math
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterValueException, ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from .conversions import MessageSettings
from .mag_calibration import one_sensors, per_sensor_problem
from .parameter_table import ACCEL_BIAS, GYRO_BIAS, REQUIRED, Spec, SPECS
from .sensor_set import sensor_settings, SensorSetting, shared_budget_refusal
from ..codec import streams
from ..device.settings import DeviceConfig

#: How alike two names must be (difflib's ratio) for "did you mean".
CLOSE_ENOUGH = 0.6
_ARRAYS = (Parameter.Type.INTEGER_ARRAY, Parameter.Type.DOUBLE_ARRAY, Parameter.Type.STRING_ARRAY)
#: The descriptor's range of a number parameter: its field, its type, its bounds' type, its step.
_RANGES = {Parameter.Type.INTEGER: ('integer_range', IntegerRange, int, 1),
           Parameter.Type.DOUBLE: ('floating_point_range', FloatingPointRange, float, 0.0)}


class ParameterError(ValueError):
    """A parameter is missing or invalid; the message says which and why."""


@dataclass(frozen=True)
class DriverConfig:
    """
    The validated parameters, each in the configuration it feeds (``Spec.feeds``).

    The fields below ``sensors`` are the ROS side's own: what no other
    configuration holds.
    """

    #: How the device side reaches and treats the first sensor (the port, the line,
    #: the patience); :meth:`device_for` gives any sensor's.
    device: DeviceConfig
    #: How the first sensor's records become messages; :meth:`messages_for`: any sensor's.
    messages: MessageSettings
    #: Every sensor to serve: address, name (topic prefix), frame, stream, rate.
    sensors: tuple[SensorSetting, ...]
    time_source: str
    time_offset: float
    qos_reliability: str
    qos_depth: int
    publish_mag: bool
    capture_gyro_bias_on_start: bool
    temperature_period: float
    capture_file: str
    fault_capture_dir: str
    fault_capture_seconds: float
    fault_captures_kept: int
    #: The field's calibration as given: one for all sensors, or one each (mag_calibration.py).
    mag_hard_iron: tuple[float, ...]
    mag_soft_iron: tuple[float, ...]

    def device_for(self, sensor: SensorSetting) -> DeviceConfig:
        """Return how the device side reaches and treats ``sensor``."""
        return replace(self.device, address=sensor.address, data_rate_hz=sensor.data_rate_hz,
                       stream=sensor.stream_choice.code)

    def messages_for(self, sensor: SensorSetting) -> MessageSettings:
        """Return how ``sensor``'s records become messages (its frame, stream, calibration)."""
        index = self.sensors.index(sensor)
        return replace(self.messages, frame_id=sensor.frame_id, stream=sensor.stream_choice,
                       mag_hard_iron=one_sensors(self.mag_hard_iron, 3, index),
                       mag_soft_iron=one_sensors(self.mag_soft_iron, 9, index))


def _descriptor(spec: Spec) -> ParameterDescriptor:
    ranges = {}
    if spec.limits is not None and spec.kind.type_ in _RANGES:
        field, range_, number, step = _RANGES[spec.kind.type_]
        low, high = map(number, spec.limits)
        ranges[field] = [range_(from_value=low, to_value=high, step=step)]
    return ParameterDescriptor(description=spec.description, read_only=spec.read_only,
                               additional_constraints=f'valid: {spec.valid_range()}', **ranges)


def given_value(node: Node, name: str) -> Any:
    """
    Return the override given for ``name`` (-p, a params file, a launch file), or None.

    Through public API only: a parameter declared with dynamic typing takes
    an override of any type, so declaring one and undeclaring it again shows
    what was given, typed as rcl read it (``-p data_rate:=300`` is an
    integer, ``-p stream:=0xC2`` the integer 194), without the type error a
    statically typed declaration would raise.
    """
    value = node.declare_parameter(name, None, ParameterDescriptor(dynamic_typing=True)).value
    node.undeclare_parameter(name)
    return value


def _as_typed(spec: Spec, value: Any) -> Any:
    """Return ``value`` as the parameter's type, the way its kind says a person means it."""
    given = Parameter.Type.from_parameter_value(value)
    if given == spec.kind.type_:
        return value
    if spec.kind.also is not None and given == spec.kind.also[0]:
        return spec.kind.also[1](value)
    raise ParameterError(f'parameter {spec.name!r} must be {spec.valid_range()}, written as '
                         f'{spec.kind.written_as}: got {value!r} ({given.name.lower()})')


def _warn_deprecated(node: Node, spec: Spec) -> None:
    """Name the standard parameter that replaces a deprecated one the user gave."""
    topic = node.resolve_topic_name('imu/raw_data')
    node.get_logger().warning(
        f"parameter '{spec.name}' is deprecated and will be removed in the next release: use "
        f"'qos_overrides.{topic}.publisher.{spec.replaced_by}' instead (rclpy's standard QoS "
        'parameters; likewise for imu/mag, imu/temperature and the other topics). Until then '
        'it still sets the data topics (imu/raw_data, imu/mag, imu/temperature).')


def _declare(node: Node, spec: Spec) -> Any:
    given = None
    try:
        if not node.has_parameter(spec.name):  # else a managed node configured again: read it
            given = given_value(node, spec.name)
            if given is not None and spec.replaced_by:
                _warn_deprecated(node, spec)
            value = spec.default if given is None else _as_typed(spec, given)
            if value is REQUIRED or value == []:
                # An empty array has no type of its own: declared by its type, unset.
                node.declare_parameter(spec.name, spec.kind.type_, _descriptor(spec))
            else:
                # The override was read above and is given here, converted.
                node.declare_parameter(spec.name, value, _descriptor(spec), ignore_override=True)
        return node.get_parameter(spec.name).value
    except ParameterUninitializedException:
        if spec.default is not REQUIRED:
            return list(spec.default)
        if spec.unless and _is_set(node, spec.unless):
            return 0
        raise ParameterError(f'parameter {spec.name!r} is required: set it with '
                             f'-p {spec.name}:=<value> ({spec.valid_range()})') from None
    except InvalidParameterValueException:
        # Out of the descriptor's range: rclpy refused what was given.
        raise ParameterError(f'parameter {spec.name!r} must be {spec.valid_range()}, '
                             f'got {given!r}') from None


def declared_value(node: Node, name: str) -> Any:
    """Return parameter ``name``'s value; None when ``node`` does not declare it or it is unset."""
    if not node.has_parameter(name):
        return None
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None  # an empty array (a bias left to the sensor) is declared unset


def _is_set(node: Node, name: str) -> bool:
    """Whether parameter ``name`` was given something (declared already, or not yet)."""
    return bool(declared_value(node, name) if node.has_parameter(name)
                else given_value(node, name))


def _fits(spec: Spec, value: Any) -> bool:
    """Whether ``value`` is what the row allows: its choices, range, kind and ``accepts``."""
    declared = spec.kind.type_
    refused = ((spec.choices and value not in spec.choices)
               or (declared == Parameter.Type.STRING and not value and not spec.empty_ok)
               or (declared == Parameter.Type.DOUBLE and not math.isfinite(value))
               or (spec.limits is not None and declared in _RANGES
                   and not spec.limits[0] <= value <= spec.limits[1]))
    return not refused and (spec.accepts is None or spec.accepts(value))


def _check(spec: Spec, value: Any) -> Any:
    if spec.unless and value == 0:
        return value  # left to the parameter it gives way to
    if spec.kind.type_ in _ARRAYS:
        # Kept as a tuple; the sensor set's arrays are checked with each other (sensor_set.py).
        value = tuple(value)
    if not _fits(spec, value):
        shown = list(value) if isinstance(value, tuple) else value
        raise ParameterError(f'parameter {spec.name!r} must be {spec.valid_range()}, '
                             f'got {shown!r}')
    return value


def declare_parameters(node: Node) -> dict[str, Any]:
    """
    Declare every parameter on ``node``; return the validated values by name.

    Parameters declared already (by an earlier call that failed, or by the
    last configure of a managed node) are read, not declared again, and
    checked all the same: the same bad value gives the same message.
    """
    return {spec.name: _check(spec, _declare(node, spec)) for spec in SPECS}


def driver_config(values: Mapping[str, Any]) -> DriverConfig:
    """
    Build the driver's configuration from validated values; apply the :data:`RULES`.

    Each value goes where its ``Spec.feeds`` says, converted if it says how.
    """
    try:
        sensors = tuple(sensor_settings(values))
    except ValueError as exc:
        raise ParameterError(str(exc)) from None
    fed: dict[str, dict[str, Any]] = {'device': {}, 'messages': {}, 'driver': {}}
    for spec in SPECS:
        config, _, field = spec.feeds.partition('.')
        if config in fed:
            convert = spec.convert or (lambda value: value)
            fed[config][field or spec.name] = convert(values[spec.name])
    first = sensors[0]
    config = DriverConfig(
        device=DeviceConfig(address=first.address, data_rate_hz=first.data_rate_hz,
                            stream=first.stream_choice.code, **fed['device']),
        messages=MessageSettings(frame_id=first.frame_id, stream=first.stream_choice,
                                 **fed['messages']),
        sensors=sensors, **fed['driver'])
    for refusal in filter(None, (rule(config) for rule in RULES)):
        raise ParameterError(refusal)
    return config


def _one_sensors_bias(config: DriverConfig) -> str | None:
    """Refuse a bias given with several sensors: it is one sensor's, and whose is a guess."""
    for name, bias in ((GYRO_BIAS, config.device.gyro_bias),
                       (ACCEL_BIAS, config.device.accel_bias)):
        if bias is not None and len(config.sensors) > 1:
            return (f"parameter {name!r} is one sensor's bias: it cannot be given with "
                    f'addresses (several sensors)')
    return None


def _line_budget(config: DriverConfig) -> str | None:
    """
    Refuse a stream and data rate the serial line cannot carry: say why, else None.

    The sensor would skip records to keep up, and the rate seen would be far
    below the one asked for with no error anywhere. With ``data_rate`` 0 the
    rate is the device's and is known only once connected: the supervisor
    warns then.
    """
    sensors = config.sensors
    if len(sensors) > 1 or sensors[0].data_rate_hz is None:
        return None  # several sensors: their budget together (the first rule)
    stream, rate = sensors[0].stream_choice, sensors[0].data_rate
    budget = streams.line_budget(stream, rate, config.device.baud, config.device.wireless)
    return None if budget.fits else (
        f"parameter 'data_rate' ({rate:g} Hz) does not fit the line with stream "
        f'{stream.name!r}: ' + streams.advice(stream, budget))


#: The rules between parameters, each a refusal or None, applied in this order: streams of
#: several sensors that do not fit the base station's line together, a bias given with several
#: sensors, one stream that does not fit, a field calibration neither one for all nor one each.
RULES: tuple[Callable[[DriverConfig], str | None], ...] = (
    lambda c: shared_budget_refusal(c.sensors, c.device.baud, c.device.wireless),
    _one_sensors_bias, _line_budget,
    lambda c: per_sensor_problem(c.mag_hard_iron, c.mag_soft_iron, len(c.sensors)))


def unknown_names(given: Iterable[str], known: Iterable[str]) -> list[tuple[str, str | None]]:
    """
    Return (unknown name, closest known name or None) for each given name not known.

    Pure, sorted by name, so that messages come in a stable order.
    """
    known = sorted(set(known))
    return [(name, (difflib.get_close_matches(name, known, 1, CLOSE_ENOUGH) or [None])[0])
            for name in sorted(set(given) - set(known))]


def unknown_message(name: str, closest: str | None) -> str:
    """One line about one unknown parameter: what it is, and what was probably meant."""
    meant = f" (did you mean '{closest}'?)" if closest else ''
    return (f"unknown parameter '{name}'{meant}: ignored, the driver has no such parameter "
            f'(ros2 param list shows those it has)')


def warn_unknown_parameters(node: Node, expected: Iterable[str]) -> list[str]:
    """
    Warn once about each override ``node`` does not declare; return the messages.

    ``expected`` are the names the entry point declares (or is about to):
    the rest of the known names are those ``node`` has declared so far,
    rclpy's own among them.
    """
    # rclpy offers no public view of the overrides it was given (-p, params files):
    # this one read of its private field is the only one in the driver (the
    # parameters themselves go through public API, above), and
    # test/test_parameter_typing.py fails loudly if rclpy renames or reshapes it.
    given = getattr(node, '_parameter_overrides', None) or {}
    declared = node.list_parameters([], 0).names
    lines = [unknown_message(name, closest)
             for name, closest in unknown_names(given, [*expected, *declared])]
    for line in lines:
        node.get_logger().warning(line)
    return lines
