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
The udev rule shipped with the package is one udev reads as meant.

udev skips a line it cannot parse with a note in the journal nobody reads,
and a match key it does not set for the device silently never matches: the
rule would then do nothing, and the user would be back to joining groups.
So every line (the commented-out option too, once uncommented) is parsed
here as udev parses it (``KEY[{attr}]OP"value"``, comma separated), the
match keys are checked against those udev sets for a USB-serial port (the
``tty`` device, and the ``usb-serial`` device that holds the FTDI latency
timer), and setup.py is checked to install the file.
"""

import os
import re
import runpy

from i3dmgx2_driver.device.port import UDEV_RULE_NAME
from i3dmgx2_driver.tools.port_listing import MICROSTRAIN_VID
import pytest
import setuptools

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RULE = os.path.join(REPO, 'udev', UDEV_RULE_NAME)

#: One key: NAME or NAME{attribute}, an operator, a double-quoted value.
_KEY = re.compile(r'(?P<key>[A-Z_]+)(?:\{(?P<attr>[^{}"]+)\})?(?P<op>==|!=|\+=|-=|:=|=)'
                  r'"(?P<value>[^"]*)"')
#: The operators that compare, and those that assign (udev(7)).
MATCH_OPS = ('==', '!=')
ASSIGN_OPS = ('=', '+=', '-=', ':=')
#: Keys that only match, keys that only assign, and those that do either (by operator).
MATCH_ONLY = {'ACTION', 'DEVPATH', 'KERNEL', 'KERNELS', 'SUBSYSTEM', 'SUBSYSTEMS', 'DRIVER',
              'DRIVERS', 'ATTRS', 'TAGS', 'TEST', 'PROGRAM', 'RESULT', 'CONST'}
ASSIGN_ONLY = {'OWNER', 'GROUP', 'MODE', 'RUN', 'LABEL', 'GOTO', 'IMPORT', 'OPTIONS',
               'SECLABEL'}
EITHER = {'NAME', 'SYMLINK', 'ATTR', 'SYSCTL', 'ENV', 'TAG'}
#: Keys that take an {attribute}.
WITH_ATTRIBUTE = {'ATTR', 'ATTRS', 'SYSCTL', 'ENV', 'TEST', 'RUN', 'IMPORT', 'SECLABEL',
                  'CONST'}

#: What udev sets, per SUBSYSTEM, for a port behind a USB-serial chip (ttyUSB<n>): the
#: device's own keys, and the parents' keys reached with ATTRS/DRIVERS (the USB device
#: holds idVendor, idProduct and serial; the interface is bound to ftdi_sio).
MATCH_KEYS = {
    'tty': {'ACTION', 'SUBSYSTEM', 'KERNEL', 'ATTRS{idVendor}', 'ATTRS{idProduct}',
            'ATTRS{serial}', 'DRIVERS', 'SUBSYSTEMS'},
    'usb-serial': {'ACTION', 'SUBSYSTEM', 'DRIVER', 'KERNEL', 'ATTRS{idVendor}',
                   'ATTRS{idProduct}', 'ATTRS{serial}', 'DRIVERS', 'SUBSYSTEMS'},
}
#: What may be assigned, per SUBSYSTEM: the tty is the device node (group, mode,
#: links); the latency timer is an attribute of the usb-serial device only.
ASSIGN_KEYS = {'tty': {'GROUP', 'MODE', 'SYMLINK'}, 'usb-serial': {'ATTR{latency_timer}'}}


def parse_rule(line: str) -> list[tuple[str, str, str]]:
    """Parse one rule line as udev does; return its (key, operator, value) triples."""
    keys = []
    rest = line.strip()
    while rest:
        found = _KEY.match(rest)
        assert found, f'not udev syntax at {rest!r} in: {line}'
        key, attr, op, value = found.group('key', 'attr', 'op', 'value')
        assert key in MATCH_ONLY | ASSIGN_ONLY | EITHER, f'no udev key {key} in: {line}'
        assert (attr is not None) == (key in WITH_ATTRIBUTE) or key == 'IMPORT', \
            f'{key} {"needs" if attr is None else "takes no"} {{attribute}} in: {line}'
        if key in MATCH_ONLY:
            assert op in MATCH_OPS, f'{key} only compares (== or !=), got {op}'
        if key in ASSIGN_ONLY:
            assert op in ASSIGN_OPS, f'{key} only assigns, got {op}'
        keys.append((f'{key}{{{attr}}}' if attr else key, op, value))
        rest = rest[found.end():]
        if rest:
            assert rest.startswith(','), f'keys are separated by commas: {rest!r}'
            rest = rest[1:].lstrip()
            assert rest, f'a comma ends the line: {line}'
    return keys


def rule_lines(text: str) -> tuple[list[str], list[str]]:
    """Return the active rule lines and the commented-out ones (the options)."""
    active, options = [], []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped:
            continue
        if not stripped.startswith('#'):
            active.append(stripped)
            continue
        body = stripped.lstrip('#').strip()
        if re.match(r'(ACTION|SUBSYSTEM|KERNEL)\b', body):
            options.append(body)
    return active, options


@pytest.fixture(scope='module')
def rules():
    with open(RULE) as handle:
        text = handle.read()
    assert not re.search(r'\\\n', text), 'no continued lines: udev joins them, people do not'
    return rule_lines(text)


def check_rule(line: str) -> dict[str, str]:
    keys = parse_rule(line)
    subsystem = [value for key, op, value in keys if key == 'SUBSYSTEM' and op == '==']
    assert len(subsystem) == 1, f'each rule names the one SUBSYSTEM it is for: {line}'
    kind = subsystem[0]
    assert kind in MATCH_KEYS, f'SUBSYSTEM=={kind!r} is not a USB-serial port: {line}'
    for key, op, value in keys:
        if op in MATCH_OPS:
            assert key in MATCH_KEYS[kind], f'udev sets no {key} on a {kind} device: {line}'
            assert value, f'{key} compares with an empty string: {line}'
        else:
            assert key in ASSIGN_KEYS[kind], f'{key} is not for a {kind} device: {line}'
    matches = {key: value for key, op, value in keys if op == '=='}
    vendor = matches.get('ATTRS{idVendor}')
    # sysfs spells the vendor id in four lower-case hex digits.
    assert vendor is not None and re.fullmatch(r'[0-9a-f]{4}', vendor), line
    if kind == 'usb-serial':
        # On plug-in, and on 'udevadm trigger' (whose default action is change).
        assert keys[0] == ('ACTION', '==', 'add|change'), line
        assert matches.get('DRIVER') == 'ftdi_sio', 'only ftdi_sio has latency_timer'
    return {key: value for key, op, value in keys} | {'SUBSYSTEM': kind}


def test_parser_refuses_what_udev_refuses():
    for bad in ('SUBSYSTEM="tty", GROUP="dialout"',          # = where == is meant
                'SUBSYSTEM=="tty" GROUP="dialout"',           # no comma
                "SUBSYSTEM=='tty'",                           # single quotes
                'SUBSYSTEMS=="usb", ATTRS="199b"',            # ATTRS without {attribute}
                'SUBSYSTEM=="tty", GROUP=="dialout"',         # GROUP compared
                'SUBSYSTEM=="tty", GRUOP="dialout"',          # no such key
                'SUBSYSTEM=="tty",'):
        with pytest.raises(AssertionError):
            parse_rule(bad)


def test_every_line_parses_as_udev_syntax(rules):
    active, options = rules
    assert len(active) == 2 and len(options) == 2
    for line in active + options:
        parse_rule(line)


def test_the_base_station_port_goes_to_dialout_with_a_link_and_a_short_latency_timer(rules):
    active, _ = rules
    tty, usb_serial = (check_rule(line) for line in active)
    vendor = f'{MICROSTRAIN_VID:04x}'
    assert tty['SUBSYSTEM'] == 'tty' and tty['ATTRS{idVendor}'] == vendor
    assert tty['GROUP'] == 'dialout' and tty['MODE'] == '0660'
    links = [value for key, op, value in parse_rule(active[0]) if key == 'SYMLINK']
    assert links == ['i3dmgx2', 'i3dmgx2-%s{serial}']
    assert all(op == '+=' for key, op, _ in parse_rule(active[0]) if key == 'SYMLINK'), \
        'SYMLINK+= adds to the by-id links udev makes; = would remove them'
    assert usb_serial['SUBSYSTEM'] == 'usb-serial'
    assert usb_serial['ATTRS{idVendor}'] == vendor and usb_serial['ATTR{latency_timer}'] == '1'


def test_the_ftdi_option_is_chosen_by_serial_number(rules):
    _, options = rules
    tty, usb_serial = (check_rule(line) for line in options)
    for rule in (tty, usb_serial):
        assert rule['ATTRS{idVendor}'] == '0403' and rule['ATTRS{serial}'], \
            'every FTDI adapter looks alike: only its serial number tells yours'
    assert tty['GROUP'] == 'dialout' and tty['MODE'] == '0660'
    assert usb_serial['ATTR{latency_timer}'] == '1'


def test_setup_installs_the_rule_under_share(monkeypatch):
    captured = {}
    monkeypatch.setattr(setuptools, 'setup', lambda **kwargs: captured.update(kwargs))
    monkeypatch.chdir(REPO)
    runpy.run_path(os.path.join(REPO, 'setup.py'))
    installed = {os.path.join(folder, os.path.basename(f))
                 for folder, files in captured['data_files'] for f in files}
    assert os.path.join('share', 'i3dmgx2_driver', 'udev', UDEV_RULE_NAME) in installed


def test_the_debian_package_installs_the_same_rule():
    # bloom's .deb installs debian/udev beside package.xml to /lib/udev/rules.d/
    # (dh_installudev), where udev reads it; share/ is for a copy by hand.
    with open(os.path.join(REPO, 'debian', 'udev'), 'rb') as deb, open(RULE, 'rb') as rule:
        assert deb.read() == rule.read(), \
            f'debian/udev differs from udev/{UDEV_RULE_NAME}: copy one onto the other'
