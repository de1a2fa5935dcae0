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
Paths that can never be a serial port, told apart without opening them.

Real files, directories, pipes, /dev/null and pseudo-terminals; the serial
library is faked only where the point is what it raises (permission denied
as root cannot happen for real).
"""

import errno
import grp
import os
import stat
import tty

from i3dmgx2_driver.device import port as port_module
from i3dmgx2_driver.device.port import (
    check_port_path, describe_non_terminal, PortMissing, PortNotSerial, PortPermissionDenied,
    PortUnusable, SerialPort, terminal_majors,
)
import pytest
import serial


@pytest.fixture
def pty_path():
    master, slave = os.openpty()
    tty.setraw(slave)
    yield os.ttyname(slave)
    os.close(slave)
    os.close(master)


def refused(path):
    with pytest.raises(PortNotSerial) as info:
        check_port_path(path)
    assert isinstance(info.value, PortUnusable)
    text = str(info.value)
    assert "parameter 'port'" in text and path in text
    assert 'ls /dev/serial/by-id/' in text and '-p port:=' in text
    return text


def test_a_regular_file_is_refused(tmp_path):
    path = tmp_path / 'passwd'
    path.write_text('root:x:0:0\n')
    assert 'is a regular file, not a serial port' in refused(str(path))


def test_a_directory_is_refused(tmp_path):
    assert 'is a directory, not a serial port' in refused(str(tmp_path))


def test_dev_null_is_refused_without_being_opened():
    text = refused('/dev/null')
    assert 'is a character device (1:3) that is not a terminal' in text


def test_a_named_pipe_is_refused(tmp_path):
    path = tmp_path / 'fifo'
    os.mkfifo(path)
    assert 'is a named pipe (FIFO)' in refused(str(path))


def test_a_link_to_a_file_names_both(tmp_path):
    target = tmp_path / 'notes.txt'
    target.write_text('x')
    link = tmp_path / 'ttyUSB0'
    link.symlink_to(target)
    assert f'{link} (a link to {target}) is a regular file' in refused(str(link))


@pytest.mark.slow
def test_a_pseudo_terminal_passes(pty_path):
    check_port_path(pty_path)
    SerialPort(pty_path).close()


def test_a_missing_path_passes_it_may_be_plugged_in_later(tmp_path):
    check_port_path(str(tmp_path / 'ttyUSB0'))
    with pytest.raises(PortMissing) as info:
        SerialPort(str(tmp_path / 'ttyUSB0'))
    assert 'ls /dev/serial/by-id/' in str(info.value)
    assert not isinstance(info.value, PortUnusable)


def test_serial_port_refuses_before_opening(tmp_path):
    opened = []
    with pytest.raises(PortNotSerial):
        SerialPort(str(tmp_path), serial_factory=lambda **kw: opened.append(kw))
    assert opened == []


def test_terminal_drivers_are_read_from_the_kernel_list(tmp_path):
    drivers = tmp_path / 'drivers'
    drivers.write_text(
        '/dev/tty             /dev/tty        5       0 system:/dev/tty\n'
        'usbserial            /dev/ttyUSB   188 0-511 serial\n'
        'pty_slave            /dev/pts      136 0-1048575 pty:slave\n')
    ranges = terminal_majors(str(drivers))
    assert ranges == [(5, 0, 0), (188, 0, 511), (136, 0, 1048575)]
    char = stat.S_IFCHR | 0o660
    assert describe_non_terminal(char, os.makedev(188, 3), ranges) is None
    assert describe_non_terminal(char, os.makedev(188, 600), ranges) is not None
    assert describe_non_terminal(char, os.makedev(1, 3), ranges) == \
        'a character device (1:3) that is not a terminal'
    # No list (not Linux, /proc hidden): a character device gets the benefit of the doubt.
    assert terminal_majors(str(tmp_path / 'absent')) is None
    assert describe_non_terminal(char, os.makedev(1, 3), None) is None
    assert describe_non_terminal(stat.S_IFBLK | 0o660, os.makedev(8, 0), None) == \
        'a block device (8:0, a disk)'


def test_without_the_kernel_list_the_open_error_still_says_it(monkeypatch):
    # /dev/null then passes the check, so pyserial opens it and fails its
    # terminal ioctl (errno 25): that is classified as never working too.
    monkeypatch.setattr(port_module, 'TTY_DRIVERS', '/nonexistent/tty/drivers')
    check_port_path('/dev/null')
    with pytest.raises(PortNotSerial) as info:
        SerialPort('/dev/null')
    assert '/dev/null is a character device (1:3) that is not a terminal' in str(info.value)


def failing(code, text):
    def factory(**kwargs):
        raise serial.SerialException(code, text)
    return factory


@pytest.mark.slow
def test_permission_denied_names_the_group_that_owns_the_device(pty_path):
    group = 'dialout' if os.geteuid() == 0 and _has_group('dialout') else None
    if group is not None:
        os.chown(pty_path, -1, grp.getgrnam(group).gr_gid)
    os.chmod(pty_path, 0o660)
    owner = grp.getgrgid(os.stat(pty_path).st_gid).gr_name
    with pytest.raises(PortPermissionDenied) as info:
        SerialPort(pty_path, serial_factory=failing(errno.EACCES, 'Permission denied'))
    text = str(info.value)
    assert f'permission denied opening {pty_path}' in text
    assert f'the {owner} group' in text


@pytest.mark.slow
def test_permission_denied_on_an_owner_only_device_says_so(pty_path):
    os.chmod(pty_path, 0o600)
    with pytest.raises(PortPermissionDenied) as info:
        SerialPort(pty_path, serial_factory=failing(errno.EACCES, 'Permission denied'))
    assert 'only its owner may open it (mode 0600)' in str(info.value)


def _has_group(name):
    try:
        grp.getgrnam(name)
    except KeyError:
        return False
    return True
