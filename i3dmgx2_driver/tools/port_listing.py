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
Which serial ports there are, and which of them may lead to a 3DM-GX2.

``/dev/ttyUSB0`` is a name the kernel hands out in plug-in order, so it
changes when a second adapter is plugged in or the machine reboots; the
links in ``/dev/serial/by-id/`` are named after the adapter's vendor,
product and serial number and stay put. A user should be given the by-id
path. The USB vendor id tells a MicroStrain base station and the common
USB-serial chips (what a wired sensor's cable uses) from the rest: a modem,
a GPS, a motor controller, which discovery must not send bytes to unasked.
"""

from collections.abc import Callable, Iterable
import grp
import os
from typing import Any, NamedTuple

import serial.tools.list_ports

#: Where udev puts the stable links to serial devices.
BY_ID_DIR = '/dev/serial/by-id'
#: MicroStrain's USB vendor id.
MICROSTRAIN_VID = 0x199B
#: USB vendor ids of the usual USB-serial bridge chips.
USB_SERIAL_VIDS = {0x0403: 'FTDI', 0x10C4: 'Silicon Labs', 0x067B: 'Prolific', 0x1A86: 'WCH CH340'}
#: What a port looks like, in the order of how likely it leads to a sensor.
KIND_MICROSTRAIN = 'MicroStrain'
KIND_USB_SERIAL = 'USB-serial'
#: Where the kernel shows each tty; an FTDI port's device there has latency_timer (ms).
SYS_CLASS_TTY = '/sys/class/tty'
#: The FTDI latency timer as the chip comes up (ms): bytes wait up to this long in the chip.
DEFAULT_LATENCY_TIMER_MS = 16


def port_group(path: str) -> tuple[str, bool] | None:
    """
    Return the group that owns ``path`` and whether this session is in it.

    None if the path cannot be examined. Root is counted as a member: it
    opens every port whatever the group.
    """
    try:
        gid = os.stat(path).st_gid
    except OSError:
        return None
    try:
        group = grp.getgrgid(gid).gr_name
    except KeyError:
        group = str(gid)
    return group, os.geteuid() == 0 or gid == os.getegid() or gid in os.getgroups()


class PortInfo(NamedTuple):
    """One serial port as discovery shows it."""

    device: str
    #: The stable /dev/serial/by-id/ link to it, or None (no such link).
    by_id: str | None
    vid: int | None
    pid: int | None
    description: str
    #: KIND_MICROSTRAIN, KIND_USB_SERIAL (with the chip maker) or None.
    kind: str | None

    @property
    def usb_id(self) -> str | None:
        """Return the USB vendor:product id as lsusb prints it, or None."""
        return None if self.vid is None else f'{self.vid:04x}:{self.pid or 0:04x}'

    @property
    def likely(self) -> bool:
        """Whether the port looks like a base station or a sensor's cable."""
        return self.kind is not None

    @property
    def stable_path(self) -> str:
        """Return the path to give the node: the by-id link if there is one."""
        return self.by_id or self.device


def port_kind(vid: int | None, description: str = '', manufacturer: str = '') -> str | None:
    """
    Say whether a port looks like a MicroStrain base station or a USB-serial cable.

    MicroStrain's vendor id, or its name in the USB strings (a base station
    built on a bridge chip that kept MicroStrain's product string), mark a
    base station; a known bridge chip marks a possible sensor cable.
    """
    text = f'{description} {manufacturer}'.lower()
    if vid == MICROSTRAIN_VID or 'microstrain' in text:
        return KIND_MICROSTRAIN
    return f'{KIND_USB_SERIAL} ({USB_SERIAL_VIDS[vid]})' if vid in USB_SERIAL_VIDS else None


def latency_timer_ms(device: str, sys_class_tty: str = SYS_CLASS_TTY) -> int | None:
    """
    Return the USB-serial adapter's latency timer for ``device`` in ms, or None.

    Only FTDI chips (ftdi_sio: MicroStrain's base station among them) have
    one; for any other port, a link that leads nowhere, or a sysfs that
    cannot be read, None. ``device`` may be a link (by-id, /dev/i3dmgx2).
    """
    name = os.path.basename(os.path.realpath(device))
    try:
        with open(os.path.join(sys_class_tty, name, 'device', 'latency_timer')) as handle:
            return int(handle.read().strip())
    except (OSError, ValueError):
        return None


def by_id_path(device: str, by_id_dir: str = BY_ID_DIR) -> str | None:
    """Return the link in ``by_id_dir`` that leads to ``device``, or None."""
    try:
        names = sorted(os.listdir(by_id_dir))
    except OSError:
        return None
    paths = (os.path.join(by_id_dir, name) for name in names)
    return next((p for p in paths if os.path.realpath(p) == os.path.realpath(device)), None)


def port_info(entry: Any, by_id_dir: str = BY_ID_DIR) -> PortInfo:
    """Turn one of pyserial's ListPortInfo (or alike) into a PortInfo."""
    description = entry.description if entry.description not in (None, 'n/a') else ''
    return PortInfo(entry.device, by_id_path(entry.device, by_id_dir), entry.vid, entry.pid,
                    description,
                    port_kind(entry.vid, description, getattr(entry, 'manufacturer', None) or ''))


def list_ports(by_id_dir: str = BY_ID_DIR,
               comports: Callable[[], Iterable[Any]] = serial.tools.list_ports.comports,
               ) -> list[PortInfo]:
    """
    List the serial ports, the likely ones first, each in device order.

    pyserial lists what the kernel shows as serial hardware; pseudo-terminals
    (a simulator) are not among them and are reached with an explicit path.
    """
    ports = [port_info(entry, by_id_dir) for entry in comports()]
    return sorted(ports, key=lambda p: (p.kind != KIND_MICROSTRAIN, not p.likely, p.device))


def describe_path(path: str, by_id_dir: str = BY_ID_DIR,
                  comports: Callable[[], Iterable[Any]] = serial.tools.list_ports.comports,
                  ) -> PortInfo:
    """
    Return what is known of a port given by path (``--port``).

    A path given as a by-id link, or as another link to a listed device,
    finds that device's USB details; anything else (a pseudo-terminal) gets
    a bare entry under the path as given.
    """
    target = os.path.realpath(path)
    for entry in comports():
        if os.path.realpath(entry.device) == target:
            info = port_info(entry, by_id_dir)
            if path.startswith(by_id_dir.rstrip('/') + '/'):
                info = info._replace(by_id=path)
            return info._replace(device=path) if info.by_id is None else info
    return PortInfo(path, by_id_path(path, by_id_dir), None, None, '', None)
