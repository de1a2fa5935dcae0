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
Opening the port: each failure becomes an error a user can act on.

pyserial is replaced by a factory that raises what pyserial raises (this
fakes the serial library, not ROS), except for the busy-port case, which
uses a real pseudo-terminal opened twice.
"""

import errno
import os
import threading
import time
import tty

from i3dmgx2_driver.device import port as port_module
from i3dmgx2_driver.device.port import (
    PortBusy, PortDisconnected, PortError, PortMissing, PortPermissionDenied, SerialPort,
)
import pytest
import serial


def failing(exc: Exception):
    """Return a serial factory that raises ``exc`` as pyserial would."""
    def factory(**kwargs):
        raise exc
    return factory


@pytest.mark.parametrize('exc, kind, words', [
    (serial.SerialException(errno.EACCES, 'could not open port /dev/ttyUSB0: [Errno 13] '
                            "Permission denied: '/dev/ttyUSB0'"), PortPermissionDenied,
     'add your user to the dialout group'),
    (serial.SerialException(errno.ENOENT, 'could not open port /dev/ttyUSB0: [Errno 2] '
                            "No such file or directory: '/dev/ttyUSB0'"), PortMissing,
     'is the base station plugged in'),
    (serial.SerialException(errno.EAGAIN, 'Could not exclusively lock port /dev/ttyUSB0: '
                            '[Errno 11] Resource temporarily unavailable'), PortBusy,
     'in use by another process'),
    (OSError(errno.EIO, 'Input/output error'), PortError, 'cannot open serial port'),
], ids=['permission', 'missing', 'busy', 'other'])
def test_open_errors_say_what_to_do(exc, kind, words):
    with pytest.raises(kind) as info:
        SerialPort('/dev/ttyUSB0', serial_factory=failing(exc))
    assert words in str(info.value)
    assert '/dev/ttyUSB0' in str(info.value)


def test_a_missing_path_is_reported_as_missing(tmp_path):
    with pytest.raises(PortMissing):
        SerialPort(str(tmp_path / 'ttyUSB9'))


@pytest.fixture
def open_pty():
    """Return (master, port): a SerialPort on a pty's slave end, closed after the test."""
    master, slave = os.openpty()
    tty.setraw(slave)
    port = SerialPort(os.ttyname(slave))
    os.close(slave)
    ends = [master]
    yield ends, port
    port.close()
    for fd in ends:
        try:
            os.close(fd)
        except OSError:
            pass  # the test closed the master itself (an unplug)


@pytest.mark.slow
def test_exclusive_open_refuses_a_second_user():
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    first = SerialPort(path)
    try:
        with pytest.raises(PortBusy):
            SerialPort(path)
    finally:
        first.close()
        os.close(slave)
        os.close(master)


@pytest.mark.slow
def test_a_queue_flushed_between_select_and_read_is_no_unplug(monkeypatch, open_pty):
    """The race a CI machine found: readable by select, emptied by a flush, read empty."""
    (master,), port = open_pty
    real_select = port_module.select.select
    os.write(master, b'\xaa\x07')

    def select_then_flush(*args):
        ready = real_select(*args)
        port.flush_input()  # what the other thread did in between
        return ready

    monkeypatch.setattr(port_module.select, 'select', select_then_flush)
    assert port.read_some(1.0) == b''
    monkeypatch.setattr(port_module.select, 'select', real_select)
    os.write(master, b'\xaa\x07')
    assert port.read_some(1.0) == b'\xaa\x07'
    os.close(master)
    with pytest.raises(PortDisconnected):
        port.read_some(1.0)


@pytest.mark.slow
def test_a_queue_flushed_while_waiting_for_a_whole_packet_is_no_unplug(monkeypatch, open_pty):
    """The same race while a packet is waited for whole: the read says EAGAIN, not EOF."""
    (master,), port = open_pty
    real_select = port_module.select.select
    port.wake_for(88)
    os.write(master, bytes(88))

    def select_then_flush(*args):
        ready = real_select(*args)
        port.flush_input()
        return ready

    monkeypatch.setattr(port_module.select, 'select', select_then_flush)
    assert port.read_some(1.0) == b''  # raised PortDisconnected (EAGAIN) before the fix
    monkeypatch.setattr(port_module.select, 'select', real_select)
    os.write(master, bytes(88))
    assert port.read_some(1.0) == bytes(88)
    os.close(master)
    with pytest.raises(PortDisconnected):
        port.read_some(1.0)


@pytest.mark.slow
def test_flushes_from_another_thread_never_read_as_an_unplug(open_pty):
    (master,), port = open_pty
    stop = threading.Event()

    def write_and_flush():
        while not stop.is_set():
            os.write(master, bytes(50))
            port.flush_input()
            time.sleep(0.0003)

    helper = threading.Thread(target=write_and_flush)
    helper.start()
    try:
        got = sum(len(port.read_some(0.002)) for _ in range(1000))  # raised before the fix
    finally:
        stop.set()
        helper.join()
    assert got > 0


@pytest.mark.slow
def test_reads_after_the_other_end_closed_raise_disconnected(open_pty):
    (master,), port = open_pty
    os.write(master, b'\xaa\x07')
    assert port.read_some(1.0) == b'\xaa\x07'
    os.close(master)
    with pytest.raises(PortDisconnected):
        for _ in range(3):
            port.read_some(1.0)


@pytest.mark.parametrize('group', ['root', 'wheel', 'sudo', 'adm', 'disk', 'video'])
def test_permission_denied_never_advises_joining_a_powerful_group(monkeypatch, group):
    monkeypatch.setattr(port_module, '_owning_group', lambda path: (group, 0o20660))
    monkeypatch.setattr(port_module, '_in_group_database', lambda name: False)
    text = str(port_module._classify('/dev/ttyUSB0', PermissionError(errno.EACCES, 'denied')))
    assert f'usermod -aG {group}' not in text and f'newgrp {group}' not in text
    assert f'joining {group} would give your user far more than this port' in text
    assert '/etc/udev/rules.d/' in text and 'udevadm control --reload-rules' in text
    assert 'udevadm trigger' in text and port_module.UDEV_RULE_NAME in text
    assert 'usermod -aG dialout $USER' in text, 'the rule gives the port to dialout'


@pytest.mark.parametrize('group, path', [
    ('dialout', '/dev/ttyUSB0'), ('uucp', '/dev/ttyUSB0'), ('tty', '/dev/ttyUSB0'),
    ('serial', '/dev/ttyUSB0'), ('i3dmgx2', '/dev/i3dmgx2'), ('ttyusb1', '/dev/ttyUSB1')])
def test_permission_denied_advises_joining_a_group_made_for_serial_ports(monkeypatch, group,
                                                                         path):
    monkeypatch.setattr(port_module, '_owning_group', lambda p: (group, 0o20660))
    monkeypatch.setattr(port_module, '_in_group_database', lambda name: False)
    text = str(port_module._classify(path, PermissionError(errno.EACCES, 'denied')))
    assert f'add your user to the {group} group that owns it' in text
    assert f'sudo usermod -aG {group} $USER' in text
    assert 'udev' not in text


def test_an_owner_only_port_is_pointed_at_the_rule(monkeypatch):
    monkeypatch.setattr(port_module, '_owning_group', lambda p: ('root', 0o20600))
    text = str(port_module._classify('/dev/ttyUSB0', PermissionError(errno.EACCES, 'denied')))
    assert 'only its owner may open it (mode 0600)' in text
    assert 'udevadm control --reload-rules' in text
