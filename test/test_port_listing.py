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
Listing the serial ports: which ones look like a sensor, and their stable paths.

pyserial lists only real serial hardware, so the ports here are pyserial's own
ListPortInfo objects filled in as its Linux backend fills them for USB
adapters, and /dev/serial/by-id is a temporary directory of symlinks to
temporary files standing in for /dev/ttyUSB*.
"""

import os

from i3dmgx2_driver.tools.port_listing import (
    by_id_path, describe_path, KIND_MICROSTRAIN, list_ports, port_kind, PortInfo,
)
import pytest
from serial.tools.list_ports_common import ListPortInfo


def usb_port(device: str, vid: int | None, pid: int | None, description: str = 'n/a',
             manufacturer: str | None = None) -> ListPortInfo:
    """Return a ListPortInfo as pyserial's Linux backend makes it for a USB adapter."""
    info = ListPortInfo(device, skip_link_detection=True)
    info.vid, info.pid = vid, pid
    info.description = description
    info.manufacturer = manufacturer
    return info


@pytest.fixture
def dev(tmp_path):
    """Make a /dev with three ttys and a by-id directory linking to two of them."""
    root = tmp_path / 'dev'
    by_id = root / 'serial' / 'by-id'
    by_id.mkdir(parents=True)
    for name in ('ttyUSB0', 'ttyUSB1', 'ttyACM0'):
        (root / name).write_bytes(b'')
    # udev makes relative links, as here.
    os.symlink('../../ttyUSB0', by_id / 'usb-FTDI_FT232R_USB_UART_A600XYZ-if00-port0')
    os.symlink('../../ttyUSB1', by_id / 'usb-MicroStrain_Base_Station_0001-if00-port0')
    return root


@pytest.mark.parametrize('vid, description, manufacturer, kind', [
    (0x199B, 'n/a', None, 'MicroStrain'),
    (0x0403, 'FT232R USB UART', 'FTDI', 'USB-serial (FTDI)'),
    (0x10C4, 'CP2102 USB to UART Bridge Controller', None, 'USB-serial (Silicon Labs)'),
    (0x067B, 'USB-Serial Controller', 'Prolific Technology Inc.', 'USB-serial (Prolific)'),
    (0x1A86, 'USB2.0-Serial', None, 'USB-serial (WCH CH340)'),
    (0x0403, 'MicroStrain Wireless Base Station', 'FTDI', 'MicroStrain'),
    (0x2341, 'Arduino Uno', 'Arduino', None),
    (None, '', '', None),
], ids=['microstrain', 'ftdi', 'cp210x', 'prolific', 'ch340', 'microstrain-on-ftdi',
        'arduino', 'built-in'])
def test_kind_of_port(vid, description, manufacturer, kind):
    assert port_kind(vid, description, manufacturer or '') == kind


def test_by_id_path_follows_relative_links(dev):
    by_id = str(dev / 'serial' / 'by-id')
    assert by_id_path(str(dev / 'ttyUSB0'), by_id) == \
        f'{by_id}/usb-FTDI_FT232R_USB_UART_A600XYZ-if00-port0'
    assert by_id_path(str(dev / 'ttyUSB1'), by_id) == \
        f'{by_id}/usb-MicroStrain_Base_Station_0001-if00-port0'
    assert by_id_path(str(dev / 'ttyACM0'), by_id) is None
    assert by_id_path(str(dev / 'ttyUSB0'), str(dev / 'no-such-dir')) is None


def test_listing_marks_and_orders_ports(dev):
    by_id = str(dev / 'serial' / 'by-id')
    entries = [
        usb_port(str(dev / 'ttyACM0'), 0x2341, 0x0043, 'Arduino Uno'),
        usb_port(str(dev / 'ttyUSB0'), 0x0403, 0x6001, 'FT232R USB UART'),
        usb_port(str(dev / 'ttyUSB1'), 0x199B, 0x0001, 'n/a', 'MicroStrain, Inc.'),
    ]
    ports = list_ports(by_id, comports=lambda: entries)
    assert ports == [
        PortInfo(str(dev / 'ttyUSB1'), f'{by_id}/usb-MicroStrain_Base_Station_0001-if00-port0',
                 0x199B, 0x0001, '', KIND_MICROSTRAIN),
        PortInfo(str(dev / 'ttyUSB0'), f'{by_id}/usb-FTDI_FT232R_USB_UART_A600XYZ-if00-port0',
                 0x0403, 0x6001, 'FT232R USB UART', 'USB-serial (FTDI)'),
        PortInfo(str(dev / 'ttyACM0'), None, 0x2341, 0x0043, 'Arduino Uno', None),
    ]
    assert [p.likely for p in ports] == [True, True, False]
    assert [p.usb_id for p in ports] == ['199b:0001', '0403:6001', '2341:0043']
    assert ports[1].stable_path.endswith('A600XYZ-if00-port0')
    assert ports[2].stable_path == str(dev / 'ttyACM0')


def test_a_port_given_by_path_finds_its_usb_details(dev):
    by_id = str(dev / 'serial' / 'by-id')
    entries = [usb_port(str(dev / 'ttyUSB0'), 0x0403, 0x6001, 'FT232R USB UART')]
    link = f'{by_id}/usb-FTDI_FT232R_USB_UART_A600XYZ-if00-port0'
    for given in (str(dev / 'ttyUSB0'), link):
        info = describe_path(given, by_id, comports=lambda: entries)
        assert info == PortInfo(str(dev / 'ttyUSB0'), link, 0x0403, 0x6001,
                                'FT232R USB UART', 'USB-serial (FTDI)')
    # Not listed (a pseudo-terminal): a bare entry under the path as given.
    assert describe_path(str(dev / 'ttyACM0'), by_id, comports=lambda: entries) == \
        PortInfo(str(dev / 'ttyACM0'), None, None, None, '', None)
