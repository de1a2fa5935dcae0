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

Each parameter is one row (a :class:`Spec`), and the row says all there is
to know about it; ``parameters.py`` applies the rows to a node and has no
case for any name. A row says:

- its **kind**: the type it is declared with, and how a person may write a
  value of it. rcl reads ``-p data_rate:=300`` (and ``300`` in a YAML or a
  launch file) as an integer, and users type rates and deviations that way,
  so an integer stands for a :data:`DOUBLE`; rcl reads ``-p stream:=0xC2``
  as the integer 194, so a :data:`CODE` gets its text back. An integer
  parameter given a double stays an error.
- its **range** (``limits``, the descriptor's: rclpy enforces it and
  ``ros2 param describe`` shows it) or its **choices**, and what else a
  value must be (``accepts``: "0 or at least 1 Hz", a stream's name) where
  rclpy cannot check it.
- the **"valid" part** of its refusal, where choices, range and kind do not
  say it: every refusal names the parameter, what was given and what is
  valid (:meth:`Spec.valid_range`).
- the **configuration it feeds** (``feeds``): a field of the device side's
  ``DeviceConfig`` (device/settings.py), of the messages' ``MessageSettings``
  (conversions.py), the sensor set (sensor_set.py), or the ROS side's own
  ``DriverConfig`` (parameters.py). So a new parameter that reaches the
  dialogue is its row here and its use there.

The QoS of the publishers is not here: rclpy declares its standard
``qos_overrides`` parameters itself (``publishers.py``); ``qos_reliability``
and ``qos_depth`` remain for one release, warned about when given.
"""

from collections.abc import Callable
from dataclasses import fields
import math
from typing import Any, NamedTuple

from rclpy.parameter import Parameter

from .mag_calibration import HARD_IRON, IDENTITY, is_matrix_list, is_offset_list, SOFT_IRON, ZERO
from .sensor_set import RATE_VALID, settable_rate
from ..codec import streams
from ..codec.data_rate import MAX_RATE_HZ, MIN_RATE_HZ
from ..codec.framing import MAX_ADDRESS, MIN_ADDRESS
from ..codec.orientation import CONVENTIONS
from ..device.realtime import MAX_PRIORITY, ThreadPolicy
from ..device.settings import DeviceConfig

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
#: The default of a parameter that has none: it must be given.
REQUIRED = object()
#: The names of the parameters read where they are used (``feeds='node'``, and the
#: bias the services look at), so that a rename is one edit and a typo an ImportError.
GYRO_BIAS_SAMPLING_MS = 'gyro_bias_sampling_ms'
CALIBRATION_FILE = 'calibration_file'
GYRO_BIAS = 'gyro_bias'
ACCEL_BIAS = 'accel_bias'

#: The device side's own defaults, which a parameter that feeds ``DeviceConfig`` takes
#: rather than typing them a second time.
DEVICE_DEFAULTS = {field.name: field.default for field in fields(DeviceConfig)}


class Kind(NamedTuple):
    """A parameter's type, and how a person may write a value of it."""

    #: The type it is declared with (``ros2 param get`` shows it).
    type_: Parameter.Type
    #: How to write a value, in the refusal of one written as another type.
    written_as: str
    #: What is valid when the row says no more (no choices, no range).
    valid: str = 'a valid value'
    #: Another type rcl reads from a way people write it, and what that value stands for.
    also: tuple[Parameter.Type, Callable[[Any], Any]] | None = None


#: A command byte as people write it: 194 -> '0xC2'.
_code_text = '0x{:02X}'.format


BOOL = Kind(Parameter.Type.BOOL, 'true or false', 'true or false')
INTEGER = Kind(Parameter.Type.INTEGER, 'an integer')
#: ``-p data_rate:=300``: rcl reads an integer, a person means 300.0.
DOUBLE = Kind(Parameter.Type.DOUBLE, 'a floating-point number, e.g. 1.0',
              also=(Parameter.Type.INTEGER, float))
TEXT = Kind(Parameter.Type.STRING, 'a string', 'a non-empty string')
#: A name or a command byte: ``-p stream:=0xC2`` is read as the integer 194, meant as '0xC2'.
CODE = TEXT._replace(also=(Parameter.Type.INTEGER, _code_text))
INTEGERS = Kind(Parameter.Type.INTEGER_ARRAY, 'a list of integers, e.g. [17, 95]')
#: ``-p data_rates:=[100, 50]`` is a list of integers, meant as doubles.
DOUBLES = Kind(Parameter.Type.DOUBLE_ARRAY, 'a list of numbers, e.g. [100.0, 50.0]',
               also=(Parameter.Type.INTEGER_ARRAY, lambda values: list(map(float, values))))
NAMES = Kind(Parameter.Type.STRING_ARRAY, 'a list of names, e.g. [left, right]')
#: Names or command bytes, as :data:`CODE`.
CODES = NAMES._replace(also=(Parameter.Type.INTEGER_ARRAY, lambda c: list(map(_code_text, c))))


class Spec(NamedTuple):
    """One parameter: name, kind, default (or REQUIRED), meaning, what is valid."""

    name: str
    kind: Kind
    default: Any
    description: str
    #: The range rclpy enforces on an integer or a double (the descriptor's).
    limits: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = True
    #: A string that may be empty ('' switches a feature off).
    empty_ok: bool = False
    #: The "valid" part of its refusal, where choices, limits and kind do not say it.
    valid: str = ''
    #: What a value must be beyond its kind, limits and choices (rclpy cannot check it).
    accepts: Callable[[Any], bool] | None = None
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

    def valid_range(self) -> str:
        """Return what is valid, as its refusals and ``ros2 param describe`` say it."""
        if self.choices:
            return 'one of ' + ', '.join(map(repr, self.choices))
        if self.valid or self.empty_ok or self.limits is None:
            return self.valid or ("a string, or '' (off)" if self.empty_ok else self.kind.valid)
        return f'{self.limits[0]:g}..{self.limits[1]:g}'


def _device_setting(name: str, kind: Kind, description: str,
                    limits: tuple[float, float] | None = None, field: str = '') -> Spec:
    """Return the row of a parameter that sets a ``DeviceConfig`` field (of its name)."""
    field = field or name
    return Spec(name, kind, DEVICE_DEFAULTS[field], description, limits, feeds=f'device.{field}')


def _bias(name: str, what: str, unit: str, command: str) -> Spec:
    """Return the row of a bias written to the sensor at every start ([]: the sensor's own)."""
    return Spec(name, DOUBLES, [], f"{what} bias [x, y, z] ({unit}, the sensor's axes and units) "
                f'written to the sensor at every start ({command}) and checked against its echo; '
                "[]: leave the sensor's own. One sensor only (not with addresses).",
                valid=f'[] (as the sensor is), or three finite numbers [x, y, z] in {unit}',
                accepts=lambda v: not v or (len(v) == 3 and all(map(math.isfinite, v))),
                feeds=f'device.{name}', convert=lambda v: tuple(map(float, v)) or None)


def _one_for_all(single: str) -> str:
    return f"[] (then '{single}' for all), one for all, or one per address"


#: What sensor_names and frame_ids take: one each, none twice (sensor_set.py checks them).
_ONE_NAME_EACH = '[] (the default), or one distinct name per address'


SPECS: list[Spec] = [
    Spec('port', TEXT, '/dev/ttyUSB0', 'Serial port of the base station (or wired sensor).',
         feeds='device.port'),
    Spec('address', INTEGER, REQUIRED, 'Node address of the sensor (factory: last two digits of '
         'its serial number).', (MIN_ADDRESS, MAX_ADDRESS), unless='addresses', feeds='sensors'),
    # Several sensors behind one base station, served by one driver (ros/sensor_set.py):
    # the defaults, empty, leave the one sensor of 'address' as it always was.
    Spec('addresses', INTEGERS, [], 'Node addresses of several sensors behind the one base '
         "station, served by this driver (instead of 'address'); each gets its topics under its "
         'name (see Several sensors).', feeds='sensors',
         valid=f"[] (then 'address'), or distinct addresses {MIN_ADDRESS}..{MAX_ADDRESS}"),
    Spec('sensor_names', NAMES, [], "With addresses: each sensor's name, the prefix of its "
         "topics (<name>/raw_data); default imu_<address>. For one sensor: 'imu'.",
         valid=_ONE_NAME_EACH, feeds='sensors'),
    Spec('frame_ids', NAMES, [], "With addresses: each sensor's frame; default <name>_link "
         "(frame_id is one sensor's).", valid=_ONE_NAME_EACH, feeds='sensors'),
    Spec('streams', CODES, [], "With addresses: each sensor's stream (or one for all); default: "
         'stream for all.', valid=_one_for_all('stream'), feeds='sensors'),
    Spec('data_rates', DOUBLES, [], "With addresses: each sensor's data rate (Hz; or one for "
         'all; 0: as the device is); default: data_rate for all. Together they must fit the '
         'serial line.', valid=_one_for_all('data_rate'), feeds='sensors'),
    _device_setting('baud', INTEGER, 'Serial baud rate.', (9600, 921600)),
    _device_setting('wireless', BOOL, 'True: through a wireless base station (packets, '
                    'ACK/NACK); false: wired sensor.'),
    Spec('stream', CODE, streams.DEFAULT.name, 'What the sensor streams: a stream name, or the '
         "command byte of its record as text (e.g. '0xC2'); see Choosing a stream. With "
         'data_rate it must fit the serial line, or the node refuses to start.',
         valid=streams.valid_text(), accepts=streams.names_a_stream, feeds='sensors'),
    Spec('frame_id', TEXT, 'imu_link', 'Frame of the published messages (_ned is appended in the '
         'ned convention).', feeds='sensors'),
    Spec('frame_convention', TEXT, 'enu', 'enu: REP-103 (ENU world, x-forward/y-left/z-up body); '
         'ned: device axes (NED world, x-forward/y-right/z-down body).', choices=CONVENTIONS,
         feeds='messages.frame_convention'),
    Spec('orientation_stddev', DOUBLE, ORIENTATION_STDDEV,
         'Orientation standard deviation (rad); 0: unknown. Default: 2.0 degrees, the '
         "3DM-GX2 datasheet's dynamic orientation accuracy (0.5 degrees static), as the ROS 1 "
         'microstrain_3dmgx2_imu driver.', (0.0, 10.0), feeds='messages.orientation_stddev'),
    Spec('angular_velocity_stddev', DOUBLE, ANGULAR_VELOCITY_STDDEV, 'Angular velocity standard '
         "deviation (rad/s); 0: unknown. Default: the ROS 1 microstrain_3dmgx2_imu driver's "
         'figure for this sensor.', (0.0, 10.0), feeds='messages.angular_velocity_stddev'),
    Spec('linear_acceleration_stddev', DOUBLE, LINEAR_ACCELERATION_STDDEV,
         'Linear acceleration standard deviation (m/s^2); 0: unknown. Default: the ROS 1 '
         "microstrain_3dmgx2_imu driver's figure for this sensor (10 mg).", (0.0, 100.0),
         feeds='messages.linear_acceleration_stddev'),
    Spec('magnetic_field_stddev', DOUBLE, 0.0, 'Magnetic field standard deviation (T); 0: '
         'unknown (no published figure).', (0.0, 1.0), feeds='messages.magnetic_field_stddev'),
    # The field's calibration (ros/mag_calibration.py), measured by magcal (docs/magcal.md).
    Spec(HARD_IRON, DOUBLES, list(ZERO), "Hard-iron offset [x, y, z] (T, the sensor's own axes: "
         'x forward, y right, z down) taken off the field before it is published (imu/mag); with '
         'addresses, 3 for all or 3 per sensor. Measured by magcal.',
         valid='3 finite numbers (T), or 3 per sensor', accepts=is_offset_list),
    Spec(SOFT_IRON, DOUBLES, list(IDENTITY),
         'Soft-iron matrix (row-major, 9 values) the field is multiplied by once the hard '
         'iron is off, in the same axes; with addresses, 9 for all or 9 per sensor. '
         'Measured by magcal.', valid='a symmetric (within 1e-6 relative), positive-definite '
         '3x3 matrix, row-major (9 numbers), or 9 per sensor', accepts=is_matrix_list),
    Spec('time_source', TEXT, 'device', 'device: sample time from the sensor timer aligned to '
         'the host clock; host: time the packet was read.', choices=('device', 'host')),
    Spec('time_offset', DOUBLE, 0.0, 'Seconds added to every stamp (imu/raw_data, imu/mag, '
         "imu/temperature), for the radio's latency the host cannot see; shown on /diagnostics "
         '(status time).', (-TIME_OFFSET_LIMIT, TIME_OFFSET_LIMIT)),
    Spec('qos_reliability', TEXT, 'reliable', 'Deprecated (removed in the next release): use '
         'qos_overrides./imu/raw_data.publisher.reliability. QoS reliability of the data '
         'publishers (best_effort does not match reliable subscribers).',
         choices=('reliable', 'best_effort'), replaced_by='reliability'),
    Spec('qos_depth', INTEGER, 10, 'Deprecated (removed in the next release): use '
         'qos_overrides./imu/raw_data.publisher.depth. QoS history depth of the data publishers.',
         (1, 1000), replaced_by='depth'),
    _device_setting('read_timeout', DOUBLE, 'Seconds without data before the stream counts '
                    'as stalled.', (0.1, 60.0), field='stall_timeout'),
    _device_setting('reconnect_interval', DOUBLE,
                    'Seconds between attempts to reopen a lost port.', (0.1, 60.0)),
    # How patient the dialogue is (device/timeouts.py has each default and why).
    _device_setting('request_timeout', DOUBLE,
                    "Seconds to wait for a command's reply, per try (a slow radio link may "
                    'need more; bringup measures the round trips).', (0.05, 10.0)),
    _device_setting('request_retries', INTEGER,
                    'Tries of a command before the sensor counts as not answering.', (1, 20)),
    _device_setting('continuous_retries', INTEGER, 'Tries of the continuous-mode request before '
                    'the stream counts as not started.', (1, 20)),
    _device_setting('fast_reconnect', BOOL,
                    'After a reconnect, confirm the sensor already identified with one '
                    'serial-number read; false: the full start-up dialogue every time.'),
    _device_setting('resume_timeout', DOUBLE,
                    "Seconds per try of a fast reconnect's serial-number read (short: a reply "
                    'lost in a stall is asked again soon after the radio is back).', (0.02, 5.0)),
    _device_setting('resume_retries', INTEGER, "Tries of a fast reconnect's serial-number read "
                    'before the full dialogue.', (1, 20)),
    Spec('publish_mag', BOOL, True,
         'Publish sensor_msgs/MagneticField on imu/mag (NaN readings are skipped).'),
    Spec('data_rate', DOUBLE, 0.0, 'Data rate (Hz) to write to the device (EEPROM 0xFCA2, '
         f'persists); 0: leave the device as it is; otherwise {MIN_RATE_HZ:g}..{MAX_RATE_HZ:.1f}, '
         'and the stream must fit the serial line at that rate (see Choosing a stream).',
         (0.0, round(MAX_RATE_HZ, 1)), feeds='sensors', valid=RATE_VALID, accepts=settable_rate),
    _device_setting('low_latency', BOOL, 'Put the serial port in Linux low-latency mode (USB '
                    'adapters) when it supports it.'),
    Spec(GYRO_BIAS_SAMPLING_MS, INTEGER, 10000, 'Sampling time (ms) of ~/capture_gyro_bias '
         '(0xCD); the sensor must stay still that long. The protocol advises 10000..30000; down '
         'to 100 is accepted for tests and the simulator, at the cost of a noisier bias.',
         (100, 30000), read_only=False, feeds='node'),
    Spec('capture_gyro_bias_on_start', BOOL, False, 'Capture the gyro bias once, right after '
         'streaming first starts (the sensor must be still then).'),
    # A calibration that lasts (README, Calibration): known biases written at every
    # start, and where a capture writes its result for the next start.
    _bias(GYRO_BIAS, 'Gyro', 'rad/s', '0xCA'),
    _bias(ACCEL_BIAS, 'Accelerometer', 'g', '0xC9'),
    Spec(CALIBRATION_FILE, TEXT, '', 'An accepted ~/capture_gyro_bias writes its bias to this '
         "YAML parameter file (gyro_bias under the node's name, overwritten), to load at the "
         "next start; '': off.", empty_ok=True, feeds='node'),
    Spec('temperature_period', DOUBLE, 0.0, 'Seconds between polls of the temperatures (0xD1), '
         'published on imu/temperature; 0: off.', (0.0, 3600.0)),
    Spec('realtime_priority', INTEGER, 0, 'SCHED_FIFO priority of the thread that reads the port '
         'and publishes; 0: normal scheduling. Where the system refuses it (no rtprio limit) one '
         'warning is logged and the thread runs as usual.', (0, MAX_PRIORITY),
         feeds='device.thread_policy', convert=ThreadPolicy),
    Spec('capture_file', TEXT, '', 'Write every byte read from the port, with its receive time, '
         'to this capture file (GX2CAP format, overwritten; replay with '
         "i3dmgx2_driver.tools.replay); '': off.", empty_ok=True),
    # The fault capture (capture/fault_capture.py FaultCapture): the last seconds, kept always.
    Spec('fault_capture_dir', TEXT, '~/.ros/i3dmgx2_captures',
         'Keep the last fault_capture_seconds of bytes read from the port in memory, and '
         'write them to a capture file in this directory (named by UTC time and cause) on a '
         'stall, a disconnect, a device reset, a burst of corrupted packets, a refused '
         "command, or a ~/save_capture call; '': off.", empty_ok=True),
    Spec('fault_capture_seconds', DOUBLE, 30.0,
         'Seconds of the port kept in memory for a fault capture (also the least time '
         'between two of its files: faults closer together share one).', (1.0, 600.0)),
    Spec('fault_captures_kept', INTEGER, 20,
         'Fault capture files kept in fault_capture_dir; the oldest are deleted.', (1, 10000)),
]
