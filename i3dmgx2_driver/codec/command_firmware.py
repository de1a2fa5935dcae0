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
Which firmware answers what: the layout table's least firmware, said in words.

The table (layouts.py) holds each command's least firmware as 0xE9 reports
it (2105 for 2.1.05); this is how everyone who sends a command reads it: the
node before it streams, polls the temperatures or stores a bias, the tools
before they list or try a stream, the simulator before it answers. A
firmware not known (0xE9 unanswered) is ``None``: nothing can be checked, so
everything is allowed, as before the firmware was read at all.

What the driver offers that not every firmware has is named as users know it
(:data:`FEATURES`): each stream by its name, the temperatures, the bias store.
"""

import re

from . import layouts as lay
from . import streams
from .records import FirmwareVersion

#: The newest least firmware of any command: a sensor with it answers them all.
NEWEST = max(layout.firmware for layout in lay.LAYOUTS.values())

#: What the driver uses, by the name users know it by, and the command it sends.
FEATURES: tuple[tuple[str, int], ...] = (
    *((stream.name, stream.code) for stream in streams.STREAMS),
    ('temperatures', lay.TEMPERATURES),
    ('bias store', lay.TRANSFER_TO_NON_VOLATILE),
)

_TEXT = re.compile(r'(\d+)\.(\d)\.(\d\d)')


def text(version: int) -> str:
    """Return ``version`` (2103) as the manual writes it (``2.1.03``)."""
    return FirmwareVersion(version).text


def parse(written: str) -> int:
    """Return the version 0xE9 reports for ``written`` as the manual writes it (2.1.03)."""
    match = _TEXT.fullmatch(written.strip())
    if match is None:
        raise ValueError(f'firmware {written!r}: write it as the manual does, major.minor.patch '
                         f'with two patch digits (2.1.03, 2.1.13)')
    major, minor, patch = (int(group) for group in match.groups())
    return major * 1000 + minor * 100 + patch


def version_of(written: str) -> int | None:
    """Return the version of an identity's firmware text ('' when 0xE9 went unanswered: None)."""
    return parse(written) if written else None


def needs(code: int) -> int:
    """Return the least firmware that answers command ``code``."""
    return lay.LAYOUTS[code].firmware


def has(version: int | None, code: int) -> bool:
    """Whether firmware ``version`` answers ``code`` (None, not known: assumed so)."""
    return version is None or version >= needs(code)


def refusal(what: str, code: int, version: int | None) -> str:
    """Say why ``what`` (command ``code``) cannot be asked of ``version``; '' when it can."""
    return '' if has(version, code) else (
        f'{what} (0x{code:02X}) needs firmware {text(needs(code))}; this sensor has '
        f'{text(version)}')


def offered(version: int | None) -> list[streams.Stream]:
    """Return the streams firmware ``version`` can stream."""
    return [stream for stream in streams.STREAMS if has(version, stream.code)]


def stream_refusal(stream: streams.Stream, version: int | None) -> str:
    """Say why ``stream`` cannot be streamed, and what can; '' when it can."""
    why = refusal(stream.name, stream.code, version)
    return f'{why}; it offers {", ".join(s.name for s in offered(version))}' if why else ''


def lacks(version: int | None) -> list[str]:
    """Return what of :data:`FEATURES` firmware ``version`` does not answer."""
    return [name for name, code in FEATURES if not has(version, code)]


def summary(version: int | None) -> str:
    """Say the firmware and what it lacks (``firmware 2.1.03: no euler, ...``)."""
    if version is None:
        return 'firmware unknown (0xE9 not answered): what it lacks was not checked'
    missing = lacks(version)
    return f'firmware {text(version)}' + (': no ' + ', '.join(missing) if missing else '')
