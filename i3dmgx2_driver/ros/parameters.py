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
The node's parameters: one table with types, defaults, ranges and meaning.

Every parameter is declared with a descriptor (description, range, read-only
where changing it at run time makes no sense), so ``ros2 param describe``
documents the driver and rclpy rejects out-of-range values. Whatever rclpy
cannot check (choices, "0 or at least 1 Hz") is checked here; every failure
becomes one ``ParameterError`` whose message names the parameter and its
valid range, and the node stops. Nothing falls back to a default silently.

Values are taken as people type them (``-p data_rate:=300`` for a double,
``-p stream:=0xC2`` for a string) through rclpy's public API only: what was
given is read through a dynamically typed declaration, converted, and the
parameter then declared with its own type and descriptor (:func:`given_value`).
The QoS of the publishers is not here: rclpy declares its standard
``qos_overrides`` parameters itself (``publishers.py``); ``qos_reliability``
and ``qos_depth`` remain for one release, warned about when given.

Each parameter is typed once, in its ``Spec``, which also names the
configuration it feeds (``Spec.feeds``): a field of the device side's
``DeviceConfig`` (device/settings.py), of the messages' ``MessageSettings``
(conversions.py), the sensor set (sensor_set.py), or the ROS side's own
``DriverConfig``. :func:`driver_config` fills each from the table, so a new
parameter that reaches the dialogue is its entry here and its use there.

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
from dataclasses import dataclass, fields, replace
import difflib
import math
from typing import Any, NamedTuple

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterValueException, ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from .conversions import MessageSettings
from .sensor_set import check_shared_budget, sensor_settings, SensorSetting
from ..codec import streams
from ..codec.data_rate import MAX_RATE_HZ, MIN_RATE_HZ
from ..codec.framing import MAX_ADDRESS, MIN_ADDRESS
from ..codec.orientation import CONVENTIONS
from ..device.realtime import MAX_PRIORITY, ThreadPolicy
from ..device.settings import DeviceConfig

TIME_SOURCES = ('device', 'host')
#: Default standard deviations, per axis. No noise density of the 3DM-GX2 was
#: found in a source we can cite, so these are the per-sample figures the ROS 1
#: driver for this very sensor uses (ros-drivers/microstrain_3dmgx2_imu,
#: src/imu_node.cc: orientation_stdev 0.035, angular_velocity_stdev 0.012,
#: linear_acceleration_stdev 0.098); 0.035 rad is the datasheet's 2.0 degrees of
#: dynamic orientation accuracy. They do not depend on the data rate.
ORIENTATION_STDDEV = 0.035
ANGULAR_VELOCITY_STDDEV = 0.012
LINEAR_ACCELERATION_STDDEV = 0.098
#: Largest ``time_offset`` (s) either way: far beyond any radio's latency.
TIME_OFFSET_LIMIT = 10.0
RELIABILITIES = ('reliable', 'best_effort')
_REQUIRED = object()
#: How alike two names must be (difflib's ratio) for "did you mean".
CLOSE_ENOUGH = 0.6


#: The device side's own defaults, which a parameter that feeds ``DeviceConfig`` takes
#: rather than typing them a second time.
DEVICE_DEFAULTS = {field.name: field.default for field in fields(DeviceConfig)}


class ParameterError(ValueError):
    """A parameter is missing or invalid; the message says which and why."""


class Spec(NamedTuple):
    """One parameter: name, type, default (or _REQUIRED), meaning, limits."""

    name: str
    kind: Parameter.Type
    default: Any
    description: str
    limits: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = True
    #: A string that may be empty ('' switches a feature off).
    empty_ok: bool = False
    #: For a string: the text an integer override stands for (rcl reads 0xC2 as 194).
    from_integer: Callable[[int], str] | None = None
    #: Deprecated: the QoS policy of rclpy's standard parameter that replaces it.
    replaced_by: str = ''
    #: For a required one: not required when this other parameter is given.
    unless: str = ''
    #: Which configuration the value goes to: ``device.<field>`` (DeviceConfig),
    #: ``messages.<field>`` (MessageSettings), ``sensors`` (sensor_set.py, each
    #: sensor's address, name, frame, stream and rate), ``driver`` (the
    #: DriverConfig field of its name), or ``node`` (read from the node when used).
    feeds: str = 'driver'
    #: What the value becomes in the configuration it feeds (None: itself).
    convert: Callable[[Any], Any] | None = None


#: Several sensors behind one base station, served by one driver (ros/sensor_set.py).
SENSOR_SET_SPECS = (
    Spec('addresses', Parameter.Type.INTEGER_ARRAY, [],
         'Node addresses of several sensors behind the one base station, served by this '
         "driver (instead of 'address'); each gets its topics under its name (see Several "
         'sensors).', feeds='sensors'),
    Spec('sensor_names', Parameter.Type.STRING_ARRAY, [],
         "With addresses: each sensor's name, the prefix of its topics (<name>/raw_data); "
         "default imu_<address>. For one sensor: 'imu'.", feeds='sensors'),
    Spec('frame_ids', Parameter.Type.STRING_ARRAY, [],
         "With addresses: each sensor's frame; default <name>_link (frame_id is one "
         "sensor's).", feeds='sensors'),
    Spec('streams', Parameter.Type.STRING_ARRAY, [],
         "With addresses: each sensor's stream (or one for all); default: stream for all.",
         from_integer=lambda code: f'0x{code:02X}', feeds='sensors'),
    Spec('data_rates', Parameter.Type.DOUBLE_ARRAY, [],
         "With addresses: each sensor's data rate (Hz; or one for all; 0: as the device "
         'is); default: data_rate for all. Together they must fit the serial line.',
         feeds='sensors'),
)


SPECS: list[Spec] = [
    Spec('port', Parameter.Type.STRING, '/dev/ttyUSB0',
         'Serial port of the base station (or wired sensor).', feeds='device.port'),
    Spec('address', Parameter.Type.INTEGER, _REQUIRED,
         'Node address of the sensor (factory: last two digits of its serial number).',
         (MIN_ADDRESS, MAX_ADDRESS), unless='addresses', feeds='sensors'),
    # Several sensors behind one base station (ros/sensor_set.py): the defaults,
    # empty, leave the one sensor of 'address' as it always was.
    *SENSOR_SET_SPECS,
    Spec('baud', Parameter.Type.INTEGER, DEVICE_DEFAULTS['baud'], 'Serial baud rate.',
         (9600, 921600),
         feeds='device.baud'),
    Spec('wireless', Parameter.Type.BOOL, DEVICE_DEFAULTS['wireless'],
         'True: through a wireless base station (packets, ACK/NACK); false: wired sensor.',
         feeds='device.wireless'),
    Spec('stream', Parameter.Type.STRING, streams.DEFAULT.name,
         'What the sensor streams: a stream name, or the command byte of its record as '
         "text (e.g. '0xC2'); see Choosing a stream. With data_rate it must fit the "
         'serial line, or the node refuses to start.',
         from_integer=lambda code: f'0x{code:02X}', feeds='sensors'),
    Spec('frame_id', Parameter.Type.STRING, 'imu_link',
         'Frame of the published messages (_ned is appended in the ned convention).',
         feeds='sensors'),
    Spec('frame_convention', Parameter.Type.STRING, 'enu',
         'enu: REP-103 (ENU world, x-forward/y-left/z-up body); ned: device axes '
         '(NED world, x-forward/y-right/z-down body).', choices=CONVENTIONS,
         feeds='messages.frame_convention'),
    Spec('orientation_stddev', Parameter.Type.DOUBLE, ORIENTATION_STDDEV,
         'Orientation standard deviation (rad); 0: unknown. Default: 2.0 degrees, the '
         "3DM-GX2 datasheet's dynamic orientation accuracy (0.5 degrees static), as the ROS 1 "
         'microstrain_3dmgx2_imu driver.', (0.0, 10.0), feeds='messages.orientation_stddev'),
    Spec('angular_velocity_stddev', Parameter.Type.DOUBLE, ANGULAR_VELOCITY_STDDEV,
         'Angular velocity standard deviation (rad/s); 0: unknown. Default: the ROS 1 '
         "microstrain_3dmgx2_imu driver's figure for this sensor.", (0.0, 10.0),
         feeds='messages.angular_velocity_stddev'),
    Spec('linear_acceleration_stddev', Parameter.Type.DOUBLE, LINEAR_ACCELERATION_STDDEV,
         'Linear acceleration standard deviation (m/s^2); 0: unknown. Default: the ROS 1 '
         "microstrain_3dmgx2_imu driver's figure for this sensor (10 mg).", (0.0, 100.0),
         feeds='messages.linear_acceleration_stddev'),
    Spec('magnetic_field_stddev', Parameter.Type.DOUBLE, 0.0,
         'Magnetic field standard deviation (T); 0: unknown (no published figure).',
         (0.0, 1.0), feeds='messages.magnetic_field_stddev'),
    Spec('time_source', Parameter.Type.STRING, 'device',
         'device: sample time from the sensor timer aligned to the host clock; '
         'host: time the packet was read.', choices=TIME_SOURCES),
    Spec('time_offset', Parameter.Type.DOUBLE, 0.0,
         'Seconds added to every stamp (imu/raw_data, imu/mag, imu/temperature), for the '
         "radio's latency the host cannot see; shown on /diagnostics (status time).",
         (-TIME_OFFSET_LIMIT, TIME_OFFSET_LIMIT)),
    Spec('qos_reliability', Parameter.Type.STRING, 'reliable',
         'Deprecated (removed in the next release): use '
         'qos_overrides./imu/raw_data.publisher.reliability. QoS reliability of the data '
         'publishers (best_effort does not match reliable subscribers).',
         choices=RELIABILITIES, replaced_by='reliability'),
    Spec('qos_depth', Parameter.Type.INTEGER, 10,
         'Deprecated (removed in the next release): use '
         'qos_overrides./imu/raw_data.publisher.depth. QoS history depth of the data '
         'publishers.', (1, 1000), replaced_by='depth'),
    Spec('read_timeout', Parameter.Type.DOUBLE, DEVICE_DEFAULTS['stall_timeout'],
         'Seconds without data before the stream counts as stalled.', (0.1, 60.0),
         feeds='device.stall_timeout'),
    Spec('reconnect_interval', Parameter.Type.DOUBLE, DEVICE_DEFAULTS['reconnect_interval'],
         'Seconds between attempts to reopen a lost port.', (0.1, 60.0),
         feeds='device.reconnect_interval'),
    Spec('publish_mag', Parameter.Type.BOOL, True,
         'Publish sensor_msgs/MagneticField on imu/mag (NaN readings are skipped).'),
    Spec('data_rate', Parameter.Type.DOUBLE, 0.0,
         f'Data rate (Hz) to write to the device (EEPROM 0xFCA2, persists); 0: leave the '
         f'device as it is; otherwise {MIN_RATE_HZ:g}..{MAX_RATE_HZ:.1f}, and the stream '
         f'must fit the serial line at that rate (see Choosing a stream).',
         (0.0, round(MAX_RATE_HZ, 1)), feeds='sensors'),
    Spec('low_latency', Parameter.Type.BOOL, DEVICE_DEFAULTS['low_latency'],
         'Put the serial port in Linux low-latency mode (USB adapters) when it supports it.',
         feeds='device.low_latency'),
    Spec('gyro_bias_sampling_ms', Parameter.Type.INTEGER, 10000,
         'Sampling time (ms) of ~/capture_gyro_bias (0xCD); the sensor must stay still that '
         'long. The protocol advises 10000..30000; down to 100 is accepted for tests and the '
         'simulator, at the cost of a noisier bias.',
         (100, 30000), read_only=False, feeds='node'),
    Spec('capture_gyro_bias_on_start', Parameter.Type.BOOL, False,
         'Capture the gyro bias once, right after streaming first starts (the sensor must '
         'be still then).'),
    # A calibration that lasts (README, Calibration): known biases written at every
    # start, and where a capture writes its result for the next start.
    Spec('gyro_bias', Parameter.Type.DOUBLE_ARRAY, [],
         "Gyro bias [x, y, z] (rad/s, the sensor's axes and units) written to the sensor "
         "at every start (0xCA) and checked against its echo; []: leave the sensor's own. "
         'One sensor only (not with addresses).', feeds='device.gyro_bias',
         convert=lambda value: _bias('gyro_bias', value)),
    Spec('accel_bias', Parameter.Type.DOUBLE_ARRAY, [],
         "Accelerometer bias [x, y, z] (g, the sensor's axes and units) written to the "
         "sensor at every start (0xC9) and checked against its echo; []: leave the sensor's "
         'own. One sensor only (not with addresses).', feeds='device.accel_bias',
         convert=lambda value: _bias('accel_bias', value)),
    Spec('calibration_file', Parameter.Type.STRING, '',
         'An accepted ~/capture_gyro_bias writes its bias to this YAML parameter file '
         "(gyro_bias under the node's name, overwritten), to load at the next start; "
         "'': off.", empty_ok=True, feeds='node'),
    Spec('temperature_period', Parameter.Type.DOUBLE, 0.0,
         'Seconds between polls of the temperatures (0xD1), published on imu/temperature; '
         '0: off.', (0.0, 3600.0)),
    Spec('realtime_priority', Parameter.Type.INTEGER, 0,
         'SCHED_FIFO priority of the thread that reads the port and publishes; 0: normal '
         'scheduling. Where the system refuses it (no rtprio limit) one warning is logged and '
         'the thread runs as usual.', (0, MAX_PRIORITY),
         feeds='device.thread_policy', convert=ThreadPolicy),
    Spec('capture_file', Parameter.Type.STRING, '',
         'Write every byte read from the port, with its receive time, to this capture file '
         '(GX2CAP format, overwritten; replay with i3dmgx2_driver.tools.replay); '
         "'': off.",
         empty_ok=True),
    # The fault capture (capture/fault_capture.py FaultCapture): the last seconds, kept always.
    Spec('fault_capture_dir', Parameter.Type.STRING, '~/.ros/i3dmgx2_captures',
         'Keep the last fault_capture_seconds of bytes read from the port in memory, and '
         'write them to a capture file in this directory (named by UTC time and cause) on a '
         'stall, a disconnect, a device reset, a burst of corrupted packets, a refused '
         "command, or a ~/save_capture call; '': off.",
         empty_ok=True),
    Spec('fault_capture_seconds', Parameter.Type.DOUBLE, 30.0,
         'Seconds of the port kept in memory for a fault capture (also the least time '
         'between two of its files: faults closer together share one).', (1.0, 600.0)),
    Spec('fault_captures_kept', Parameter.Type.INTEGER, 20,
         'Fault capture files kept in fault_capture_dir; the oldest are deleted.',
         (1, 10000)),
]


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

    def device_for(self, sensor: SensorSetting) -> DeviceConfig:
        """Return how the device side reaches and treats ``sensor``."""
        return _sensor_device(self.device, sensor)

    def messages_for(self, sensor: SensorSetting) -> MessageSettings:
        """Return how ``sensor``'s records become messages (its frame and stream)."""
        return replace(self.messages, frame_id=sensor.frame_id, stream=sensor.stream_choice)


#: The bias parameters: what each of their three values is in.
BIAS_UNITS = {'gyro_bias': 'rad/s', 'accel_bias': 'g'}


def _bias_range(name: str) -> str:
    return f'[] (as the sensor is), or three finite numbers [x, y, z] in {BIAS_UNITS[name]}'


def _bias(name: str, value: Any) -> tuple[float, float, float] | None:
    """Return a bias parameter's three values, or None when it is [] (left to the sensor)."""
    if not value:
        return None
    if len(value) != 3 or not all(math.isfinite(v) for v in value):
        raise ParameterError(f'parameter {name!r} must be {_bias_range(name)}, '
                             f'got {list(value)!r}')
    return tuple(float(v) for v in value)


def _sensor_device(device: DeviceConfig, sensor: SensorSetting) -> DeviceConfig:
    return replace(device, address=sensor.address, data_rate_hz=sensor.data_rate_hz,
                   stream=sensor.stream_choice.code)


def _valid_range(spec: Spec) -> str:
    if spec.choices:
        return 'one of ' + ', '.join(repr(c) for c in spec.choices)
    if spec.empty_ok:
        return "a string, or '' (off)"
    if spec.name == 'stream':
        return streams.valid_text()
    if spec.name == 'data_rate':
        return f'0 (leave the device as it is) or {MIN_RATE_HZ:g}..{MAX_RATE_HZ:.1f} Hz'
    if spec.name == 'addresses':
        return f"[] (then 'address'), or distinct addresses {MIN_ADDRESS}..{MAX_ADDRESS}"
    if spec.name in ('streams', 'data_rates'):
        return f"[] (then '{spec.name[:-1]}' for all), one for all, or one per address"
    if spec.name in BIAS_UNITS:
        return _bias_range(spec.name)
    if isinstance(spec.default, list):
        return '[] (the default), or one distinct name per address'
    if spec.limits is not None:
        low, high = spec.limits
        return f'{low:g}..{high:g}'
    return {Parameter.Type.STRING: 'a non-empty string',
            Parameter.Type.BOOL: 'true or false'}.get(spec.kind, 'a valid value')


def _descriptor(spec: Spec) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(
        description=spec.description, read_only=spec.read_only,
        additional_constraints=f'valid: {_valid_range(spec)}')
    if spec.limits is not None and spec.kind == Parameter.Type.INTEGER:
        descriptor.integer_range = [IntegerRange(
            from_value=int(spec.limits[0]), to_value=int(spec.limits[1]), step=1)]
    elif spec.limits is not None and spec.kind == Parameter.Type.DOUBLE:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.limits[0]), to_value=float(spec.limits[1]), step=0.0)]
    return descriptor


def given_value(node: Node, name: str) -> Any:
    """
    Return the override given for ``name`` (-p, a params file, a launch file), or None.

    Through public API only: a parameter declared with dynamic typing takes
    an override of any type, so declaring one and undeclaring it again shows
    what was given, typed as rcl read it (``-p data_rate:=300`` is an
    integer, ``-p stream:=0xC2`` the integer 194), without the type error a
    statically typed declaration would raise.
    """
    value = node.declare_parameter(
        name, None, ParameterDescriptor(dynamic_typing=True)).value
    node.undeclare_parameter(name)
    return value


def _as_typed(spec: Spec, value: Any) -> Any:
    """
    Return ``value`` as the parameter's type, the way a person means it, or raise.

    rcl types ``-p data_rate:=300`` (and ``300`` in a YAML file or a launch
    file) as an integer; users type rates and deviations as integers, so an
    integer stands for a double. Likewise rcl reads ``stream:=0xC2`` as the
    integer 194: a string parameter that takes command bytes gets its text
    back. An integer parameter given a double stays an error.
    """
    given = Parameter.Type.from_parameter_value(value)
    if given == spec.kind:
        return value
    if given == Parameter.Type.INTEGER and spec.kind == Parameter.Type.DOUBLE:
        return float(value)
    if given == Parameter.Type.INTEGER and spec.from_integer is not None:
        return spec.from_integer(value)
    # The same for arrays: -p data_rates:=[100, 50] is an array of integers.
    if given == Parameter.Type.INTEGER_ARRAY and spec.kind == Parameter.Type.DOUBLE_ARRAY:
        return [float(v) for v in value]
    if given == Parameter.Type.INTEGER_ARRAY and spec.kind == Parameter.Type.STRING_ARRAY \
            and spec.from_integer is not None:
        return [spec.from_integer(v) for v in value]
    kind = {Parameter.Type.DOUBLE: 'a floating-point number, e.g. 1.0',
            Parameter.Type.INTEGER: 'an integer', Parameter.Type.BOOL: 'true or false',
            Parameter.Type.STRING: 'a string',
            Parameter.Type.INTEGER_ARRAY: 'a list of integers, e.g. [17, 95]',
            Parameter.Type.DOUBLE_ARRAY: 'a list of numbers, e.g. [100.0, 50.0]',
            Parameter.Type.STRING_ARRAY: 'a list of names, e.g. [left, right]'}[spec.kind]
    raise ParameterError(f'parameter {spec.name!r} must be {_valid_range(spec)}, written as '
                         f'{kind}: got {value!r} ({given.name.lower()})')


def _warn_deprecated(node: Node, spec: Spec) -> None:
    """Name the standard parameter that replaces a deprecated one the user gave."""
    topic = node.resolve_topic_name('imu/raw_data')
    node.get_logger().warning(
        f"parameter '{spec.name}' is deprecated and will be removed in the next release: "
        f"use 'qos_overrides.{topic}.publisher.{spec.replaced_by}' instead (rclpy's "
        f'standard QoS parameters; likewise for imu/mag, imu/temperature and the other '
        f'topics). Until then it still sets the data topics (imu/raw_data, imu/mag, '
        f'imu/temperature).')


def _declare(node: Node, spec: Spec) -> Any:
    problem = f'parameter {spec.name!r} must be {_valid_range(spec)}'
    given = None
    try:
        if node.has_parameter(spec.name):
            pass  # a managed node configured again: read what is there
        else:
            given = given_value(node, spec.name)
            if given is not None and spec.replaced_by:
                _warn_deprecated(node, spec)
            value = spec.default if given is None else _as_typed(spec, given)
            if value is _REQUIRED or value == []:
                # An empty array has no type of its own: declared by its type, unset.
                node.declare_parameter(spec.name, spec.kind, _descriptor(spec))
            else:
                # The override was read above and is given here, converted.
                node.declare_parameter(spec.name, value, _descriptor(spec),
                                       ignore_override=True)
        value = node.get_parameter(spec.name).value
    except ParameterUninitializedException:
        if spec.default is not _REQUIRED:
            return list(spec.default)
        if spec.unless and _is_set(node, spec.unless):
            return 0
        raise ParameterError(f'parameter {spec.name!r} is required: set it with '
                             f'-p {spec.name}:=<value> ({_valid_range(spec)})') from None
    except InvalidParameterValueException:
        # Out of the descriptor's range: rclpy refused what was given.
        raise ParameterError(f'{problem}, got {given!r}') from None
    return value


def _is_set(node: Node, name: str) -> bool:
    """Whether parameter ``name`` was given something (declared already, or not yet)."""
    if node.has_parameter(name):
        try:
            return bool(node.get_parameter(name).value)
        except ParameterUninitializedException:
            return False
    return bool(given_value(node, name))


def _check(spec: Spec, value: Any) -> Any:
    if isinstance(spec.default, list):
        return tuple(value)  # each entry is checked with the others (sensor_set.py)
    if spec.unless and value == 0:
        return value  # left to the parameter it gives way to
    problem = f'parameter {spec.name!r} must be {_valid_range(spec)}, got {value!r}'
    if spec.choices and value not in spec.choices:
        raise ParameterError(problem)
    if spec.kind == Parameter.Type.STRING and not value and not spec.empty_ok:
        raise ParameterError(problem)
    if spec.kind == Parameter.Type.DOUBLE:
        if not math.isfinite(value):
            raise ParameterError(problem)
        if spec.limits is not None and not spec.limits[0] <= value <= spec.limits[1]:
            raise ParameterError(problem)
    if spec.kind == Parameter.Type.INTEGER and spec.limits is not None \
            and not spec.limits[0] <= value <= spec.limits[1]:
        raise ParameterError(problem)
    if spec.name == 'data_rate' and value and not MIN_RATE_HZ <= value <= MAX_RATE_HZ:
        raise ParameterError(problem)
    if spec.name == 'stream':
        try:
            streams.parse(value)
        except ValueError:
            raise ParameterError(problem) from None
    return value


def declare_parameters(node: Node) -> dict[str, Any]:
    """
    Declare every parameter on ``node``; return the validated values by name.

    Parameters declared already (by an earlier call that failed, or by the
    last configure of a managed node) are read, not declared again, and
    checked all the same: the same bad value gives the same message.
    """
    values = {}
    for spec in SPECS:
        values[spec.name] = _check(spec, _declare(node, spec))
    return values


def driver_config(values: Mapping[str, Any]) -> DriverConfig:
    """
    Build the driver's configuration from validated values; check the line budget.

    Each value goes where its ``Spec.feeds`` says, converted if it says how.
    """
    try:
        sensors = tuple(sensor_settings(values))
        if len(sensors) > 1:
            check_shared_budget(sensors, values['baud'], values['wireless'])
    except ValueError as exc:
        raise ParameterError(str(exc)) from None
    fed: dict[str, dict[str, Any]] = {'device': {}, 'messages': {}, 'driver': {}}
    for spec in SPECS:
        config, _, field = spec.feeds.partition('.')
        if config in fed:
            value = values[spec.name]
            fed[config][field or spec.name] = (value if spec.convert is None
                                               else spec.convert(value))
    first = sensors[0]
    biases = [name for name in BIAS_UNITS if fed['device'][name] is not None]
    if biases and len(sensors) > 1:
        raise ParameterError(f"parameter {biases[0]!r} is one sensor's bias: it cannot be "
                             f'given with addresses (several sensors)')
    config = DriverConfig(
        device=_sensor_device(DeviceConfig(address=first.address, **fed['device']), first),
        messages=MessageSettings(frame_id=first.frame_id, stream=first.stream_choice,
                                 **fed['messages']),
        sensors=sensors, **fed['driver'])
    check_line_budget(config)
    return config


def check_line_budget(config: DriverConfig) -> None:
    """
    Refuse a stream and data rate the serial line cannot carry.

    The sensor would skip records to keep up, and the rate seen would be far
    below the one asked for with no error anywhere. With ``data_rate`` 0 the
    rate is the device's and is known only once connected: the supervisor
    warns then.
    """
    sensors = config.sensors
    if len(sensors) > 1 or sensors[0].data_rate_hz is None:
        return  # several sensors: the budget of them all (sensor_set.py)
    stream, rate = sensors[0].stream_choice, sensors[0].data_rate
    budget = streams.line_budget(stream, rate, config.device.baud, config.device.wireless)
    if not budget.fits:
        raise ParameterError(f"parameter 'data_rate' ({rate:g} Hz) does not fit "
                             f'the line with stream {stream.name!r}: '
                             + streams.advice(stream, budget))


def unknown_names(given: Iterable[str], known: Iterable[str]) -> list[tuple[str, str | None]]:
    """
    Return (unknown name, closest known name or None) for each given name not known.

    Pure, sorted by name, so that messages come in a stable order.
    """
    known = sorted(set(known))
    out = []
    for name in sorted(set(given) - set(known)):
        close = difflib.get_close_matches(name, known, n=1, cutoff=CLOSE_ENOUGH)
        out.append((name, close[0] if close else None))
    return out


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
