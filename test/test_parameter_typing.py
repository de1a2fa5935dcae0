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
Parameters typed as a person types them, through rclpy's public API only.

Each test makes a real rclpy node in this process with a command line of
its own (``cli_args``), so rcl parses ``-p`` exactly as for the executable;
the node processes of test_node_params.py and test_node_every_stream.py
check the same end to end.
"""

from dataclasses import fields
import os
import re

from i3dmgx2_driver.device.realtime import ThreadPolicy
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.ros.conversions import MessageSettings
from i3dmgx2_driver.ros.parameter_table import (
    ANGULAR_VELOCITY_STDDEV, DEVICE_DEFAULTS, LINEAR_ACCELERATION_STDDEV, ORIENTATION_STDDEV,
    SPECS,
)
from i3dmgx2_driver.ros.parameters import (
    declare_parameters, driver_config, DriverConfig, ParameterError, unknown_message,
    unknown_names, warn_unknown_parameters,
)
from i3dmgx2_driver.ros.publishers import (
    ALONE_TOPICS, create_publisher, override_names, SensorTopics,
)
import pytest
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy
from std_msgs.msg import Bool

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def make_node():
    """Make rclpy nodes with a command line each; destroy them and their context after."""
    context = rclpy.Context()
    rclpy.init(context=context)
    nodes = []

    def make(*arguments: str) -> Node:
        node = Node('i3dmgx2_driver', context=context, cli_args=['--ros-args', *arguments])
        nodes.append(node)
        return node

    yield make
    for node in nodes:
        node.destroy_node()
    rclpy.shutdown(context=context)


def test_integers_stand_for_doubles_and_command_bytes_for_their_text(make_node):
    node = make_node('-p', 'address:=95', '-p', 'data_rate:=300', '-p', 'stream:=0xC2',
                     '-p', 'read_timeout:=2')
    values = declare_parameters(node)
    assert values['address'] == 95
    assert values['data_rate'] == 300.0 and isinstance(values['data_rate'], float)
    assert values['stream'] == '0xC2'
    assert values['read_timeout'] == 2.0
    # Declared with their own types: ros2 param get shows a double, a string.
    assert node.get_parameter('data_rate').type_ == Parameter.Type.DOUBLE
    assert node.get_parameter('stream').type_ == Parameter.Type.STRING
    assert node.describe_parameter('data_rate').read_only
    # rclpy still checks the range at run time (and read-only refuses every change).
    assert not node.set_parameters([Parameter('data_rate', value=1000.0)])[0].successful


def test_a_double_where_an_integer_is_wanted_is_refused(make_node):
    node = make_node('-p', 'address:=95.0')
    with pytest.raises(ParameterError, match=r"parameter 'address' must be 1\.\.65534, "
                                             r'written as an integer: got 95\.0 \(double\)'):
        declare_parameters(node)


@pytest.mark.parametrize('argument, expected', [
    ('address:=0', "parameter 'address' must be 1..65534, got 0"),
    ('data_rate:=400', "parameter 'data_rate' must be 0 (leave the device as it is) or "
                       '1..301.2 Hz, got 400'),
    ('time_offset:=11.5', "parameter 'time_offset' must be -10..10, got 11.5"),
    ('orientation_stddev:=-1', "parameter 'orientation_stddev' must be 0..10, got -1"),
])
def test_a_value_out_of_range_is_refused_with_what_was_given(make_node, argument, expected):
    # rclpy checks the descriptor's range; the message still says what was given, as typed.
    node = make_node('-p', 'address:=95', '-p', argument)
    with pytest.raises(ParameterError) as raised:
        declare_parameters(node)
    assert str(raised.value) == expected


@pytest.mark.parametrize('argument, expected', [
    ('reliability:=sometimes', "reliability' must be one of 'system_default', 'reliable', "
                               "'best_effort', 'best_available', got 'sometimes'"),
    ('reliability:=5', "reliability' must be one of 'system_default', 'reliable', "
                       "'best_effort', 'best_available', got 5"),
    ('durability:=latched', "durability' must be one of 'system_default', "
                            "'transient_local', 'volatile', 'best_available', got 'latched'"),
    ('history:=all', "history' must be one of 'system_default', 'keep_last', 'keep_all', "
                     "got 'all'"),
    # rclpy would raise a type error, and rcl fail after rmw printed its own.
    ('depth:=abc', "depth' must be 0..2147483647 (0: the system default), got 'abc'"),
    ('depth:=-3', "depth' must be 0..2147483647 (0: the system default), got -3"),
])
def test_a_bad_qos_override_is_refused_naming_parameter_value_and_choices(
        make_node, argument, expected):
    node = make_node('-r', '__ns:=/robot1', '-p', f'qos_overrides./robot1/imu/raw_data.'
                                                  f'publisher.{argument}')
    with pytest.raises(ParameterError) as raised:
        create_publisher(node, Bool, 'imu/raw_data', 10)
    assert str(raised.value) == \
        "parameter 'qos_overrides./robot1/imu/raw_data.publisher." + expected
    # Another topic's publisher is not concerned.
    create_publisher(node, Bool, 'imu/mag', 10)


def test_good_qos_overrides_are_applied_as_rclpy_takes_them(make_node):
    node = make_node('-p', 'qos_overrides./imu/raw_data.publisher.reliability:=Best_Effort',
                     '-p', 'qos_overrides./imu/raw_data.publisher.depth:=0')
    with pytest.warns(UserWarning, match='zero depth'):  # rclpy: the system default
        publisher = create_publisher(node, Bool, 'imu/raw_data', 10)
    assert publisher.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert node.get_parameter('qos_overrides./imu/raw_data.publisher.depth').value == 0


def test_a_run_time_parameter_keeps_its_range(make_node):
    node = make_node('-p', 'address:=95', '-p', 'gyro_bias_sampling_ms:=400')
    declare_parameters(node)
    assert node.get_parameter('gyro_bias_sampling_ms').value == 400
    assert not node.set_parameters([Parameter('gyro_bias_sampling_ms', value=50)])[0].successful
    assert node.set_parameters([Parameter('gyro_bias_sampling_ms', value=500)])[0].successful


def test_covariance_defaults_come_from_the_sensor_and_zero_still_means_unknown(make_node):
    values = declare_parameters(make_node('-p', 'address:=95'))
    assert (values['orientation_stddev'], values['angular_velocity_stddev'],
            values['linear_acceleration_stddev'], values['magnetic_field_stddev']) == \
        (ORIENTATION_STDDEV, ANGULAR_VELOCITY_STDDEV, LINEAR_ACCELERATION_STDDEV, 0.0)
    # The ROS 1 microstrain_3dmgx2_imu driver's figures; 0.035 rad is 2.0 degrees.
    assert (ORIENTATION_STDDEV, ANGULAR_VELOCITY_STDDEV, LINEAR_ACCELERATION_STDDEV) == \
        (0.035, 0.012, 0.098)
    values = declare_parameters(make_node(
        '-p', 'address:=95', '-p', 'orientation_stddev:=0', '-p', 'angular_velocity_stddev:=0',
        '-p', 'linear_acceleration_stddev:=0'))
    assert (values['orientation_stddev'], values['angular_velocity_stddev'],
            values['linear_acceleration_stddev']) == (0.0, 0.0, 0.0)


def test_the_parameters_never_write_rclpys_private_overrides():
    """The unknown-parameter warning reads them (getattr); nothing assigns or indexes them."""
    with open(os.path.join(REPO, 'i3dmgx2_driver', 'ros', 'parameters.py')) as handle:
        text = handle.read()
    assert "getattr(node, '_parameter_overrides', None)" in text
    assert not re.search(r'\._parameter_overrides\b', text)
    assert 'setattr(' not in text


def test_rclpy_still_keeps_the_overrides_where_the_unknown_parameter_warning_reads_them(
        make_node):
    # rclpy has no public view of the overrides; parameters.py reads this
    # private field. If rclpy renames or reshapes it, this fails rather than the
    # warning going silent.
    node = make_node('-p', 'data_rat:=200.0')
    overrides = getattr(node, '_parameter_overrides', None)
    assert isinstance(overrides, dict), (
        'rclpy no longer has Node._parameter_overrides: warn_unknown_parameters must find '
        'the overrides another way')
    assert overrides['data_rat'].value == 200.0
    lines = warn_unknown_parameters(node, ['data_rate'])
    assert lines == ["unknown parameter 'data_rat' (did you mean 'data_rate'?): ignored, the "
                     'driver has no such parameter (ros2 param list shows those it has)']


def test_qos_overrides_of_the_drivers_topics_are_known_names_and_a_misspelt_one_is_not(
        make_node):
    node = make_node('-r', '__ns:=/robot1')
    known = override_names(node, ALONE_TOPICS)
    # Resolved names, as rclpy declares them: the namespace and the node's name in.
    assert 'qos_overrides./robot1/imu/raw_data.publisher.reliability' in known
    assert 'qos_overrides./robot1/i3dmgx2_driver/is_calibrated.publisher.durability' in known
    assert 'qos_overrides./diagnostics.publisher.depth' in known
    assert 'qos_overrides./robot1/imu/raw_dat.publisher.depth' not in known
    assert 'qos_overrides./robot1/imu/raw_data.publisher.lifespan' not in known


def test_qos_overrides_of_each_of_several_sensors_are_known_names(make_node):
    """With several sensors the topics are under each one's name (sensor_set.py)."""
    node = make_node()
    known = override_names(node, [*SensorTopics.of('left_arm', several=True), '/diagnostics'])
    assert 'qos_overrides./left_arm/raw_data.publisher.depth' in known
    assert 'qos_overrides./left_arm/mag.publisher.reliability' in known
    assert 'qos_overrides./i3dmgx2_driver/left_arm/is_calibrated.publisher.durability' in known
    assert 'qos_overrides./imu/raw_data.publisher.depth' not in known


# -- unknown names: which are unknown, and the closest real name ------------------

KNOWN = [spec.name for spec in SPECS] + ['use_sim_time', 'start_type_description_service']


def test_typos_get_the_closest_real_name():
    given = ['adress', 'data_rat', 'prot', 'wirless', 'frame', 'port', 'use_sim_time']
    assert unknown_names(given, KNOWN) == [
        ('adress', 'address'), ('data_rat', 'data_rate'), ('frame', 'frame_id'),
        ('prot', 'port'), ('wirless', 'wireless')]


def test_a_name_like_none_gets_no_suggestion():
    assert unknown_names(['qos_overrides./imu.publisher.depth', 'xyz'], KNOWN) == [
        ('qos_overrides./imu.publisher.depth', None), ('xyz', None)]


def test_declared_names_are_never_reported():
    assert unknown_names(KNOWN, KNOWN) == []


def test_the_message_names_both():
    assert unknown_message('data_rat', 'data_rate') == (
        "unknown parameter 'data_rat' (did you mean 'data_rate'?): ignored, the driver has "
        'no such parameter (ros2 param list shows those it has)')
    assert unknown_message('xyz', None).startswith("unknown parameter 'xyz': ignored")


# -- each parameter typed once, in the configuration it feeds ---------------------

def test_each_parameter_feeds_a_field_that_exists_and_the_drivers_own_are_all_fed():
    device = {field.name for field in fields(DeviceConfig)}
    messages = {field.name for field in fields(MessageSettings)}
    own = {field.name for field in fields(DriverConfig)} - {'device', 'messages', 'sensors'}
    fed: dict[str, set[str]] = {'device': set(), 'messages': set(), 'driver': set()}
    for spec in SPECS:
        config, _, field = spec.feeds.partition('.')
        assert config in {'device', 'messages', 'driver', 'sensors', 'node'}, spec.name
        if config in fed:
            fed[config].add(field or spec.name)
    # Every device setting is a user's: the address, stream and rate each sensor's.
    assert fed['device'] == device - {'address', 'stream', 'data_rate_hz'}
    # The frame and the stream are each sensor's (sensor_set.py), and the field's
    # calibration (DriverConfig.messages_for picks it from one for all or one each).
    assert fed['messages'] == messages - {'frame_id', 'stream', 'mag_hard_iron', 'mag_soft_iron'}
    assert fed['driver'] == own


def test_a_parameter_that_feeds_the_device_takes_the_device_sides_default():
    # The default is the device side's, not typed a second time here (the port's is the
    # one exception: DeviceConfig has none, a node without hardware needs one).
    for spec in SPECS:
        config, _, field = spec.feeds.partition('.')
        if config == 'device' and spec.convert is None and spec.name != 'port':
            assert spec.default == DEVICE_DEFAULTS[field], spec.name


def test_the_parameters_reach_the_device_and_message_settings_of_each_sensor(make_node):
    values = declare_parameters(make_node(
        '-p', 'addresses:=[17, 95]', '-p', 'streams:=[full, inertial]',
        '-p', 'data_rates:=[50, 0]', '-p', 'read_timeout:=2', '-p', 'realtime_priority:=5',
        '-p', 'port:=/dev/ttyUSB3', '-p', 'frame_convention:=ned'))
    config = driver_config(values)
    left, right = config.sensors
    device = config.device_for(right)
    assert (device.port, device.address, device.stream, device.data_rate_hz) == \
        ('/dev/ttyUSB3', 95, 0xC2, None)
    assert (device.stall_timeout, device.thread_policy) == (2.0, ThreadPolicy(5))
    assert config.device == config.device_for(left)
    assert (config.device.address, config.device.data_rate_hz) == (17, 50.0)
    messages = config.messages_for(right)
    assert (messages.frame_id, messages.frame_convention, messages.stream.name) == \
        ('imu_95_link', 'ned', 'inertial')
    assert messages.orientation_stddev == ORIENTATION_STDDEV
    assert config.messages == config.messages_for(left)


def test_how_patient_the_dialogue_is_is_the_users_to_set(make_node):
    device = driver_config(declare_parameters(make_node(
        '-p', 'address:=5', '-p', 'request_timeout:=1', '-p', 'request_retries:=4',
        '-p', 'continuous_retries:=2', '-p', 'fast_reconnect:=false',
        '-p', 'resume_timeout:=0.25', '-p', 'resume_retries:=7'))).device
    assert (device.request_timeout, device.request_retries, device.continuous_retries,
            device.fast_reconnect, device.resume_timeout, device.resume_retries) == \
        (1.0, 4, 2, False, 0.25, 7)
