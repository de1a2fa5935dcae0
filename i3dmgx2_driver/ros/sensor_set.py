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
Which sensors one driver serves, and what each is called: the parameters, per sensor.

``address:=95`` is one sensor, its topics ``imu/raw_data``, ``imu/mag`` and
``imu/temperature`` as always. ``addresses:=[17, 95]`` is several sensors
behind one base station, each with topics under a name of its own:
``<name>/raw_data``, ``<name>/mag``, ``<name>/temperature`` (relative, so
namespaces and remaps apply as to the single sensor's), ``<name>`` being the
sensor's entry in ``sensor_names`` or ``imu_<address>``. The single sensor's
name is ``imu``: one rule for both. Each sensor's frame is its entry in
``frame_ids``, else ``<name>_link`` (``frame_id`` alone for one sensor).
``stream`` and ``data_rate`` apply to every sensor unless ``streams`` or
``data_rates`` give one value each.

Pure functions of plain values, so that every rule and its message are
tested without a node; a bad combination raises ValueError with a message
that names the parameter, what was given and what is valid.
"""

from collections.abc import Mapping, Sequence
import re
from typing import Any, NamedTuple

from ..codec import streams
from ..codec.data_rate import MAX_RATE_HZ, MIN_RATE_HZ
from ..codec.framing import MAX_ADDRESS, MIN_ADDRESS

#: The topic prefix of a driver with one sensor (``imu/raw_data``).
SINGLE_NAME = 'imu'
#: A sensor name: one ROS name token (it prefixes topics and service names).
_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*')
#: What a data rate may be: 0 leaves the device's own, any other is one its divider can give.
RATE_VALID = f'0 (leave the device as it is) or {MIN_RATE_HZ:g}..{MAX_RATE_HZ:.1f} Hz'


def settable_rate(rate: float) -> bool:
    """Whether ``rate`` is 0 (leave the device as it is) or a rate its divider can give."""
    return not rate or MIN_RATE_HZ <= rate <= MAX_RATE_HZ


class SensorSetting(NamedTuple):
    """One sensor the driver serves: its address, name (topic prefix), frame and stream."""

    address: int
    name: str
    frame_id: str
    stream: str
    data_rate: float

    @property
    def stream_choice(self) -> streams.Stream:
        """Return the stream the ``stream`` text names."""
        return streams.parse(self.stream)

    @property
    def data_rate_hz(self) -> float | None:
        """Return the rate to set, or None to leave the device as it is."""
        return self.data_rate or None


def default_name(address: int) -> str:
    """Return the name of a sensor that was given none: ``imu_<address>``."""
    return f'{SINGLE_NAME}_{address}'


def sensor_settings(given: Mapping[str, Any]) -> list[SensorSetting]:
    """
    Return the sensors the parameters ``given`` ask for, each with its name, frame and stream.

    ``given``: the parameters' values by name; per sensor, the arrays (empty:
    not given); for all of them, the single values the arrays leave to them.

    Raises ValueError naming the parameter for: ``address`` and
    ``addresses`` both given, an address out of range or given twice, an
    array of the wrong length, a name that is no ROS name token or used
    twice, a stream or rate out of range, several sensors on a wired line.
    """
    address, addresses, wireless = given['address'], given['addresses'], given['wireless']
    names, frame_ids = given['sensor_names'], given['frame_ids']
    stream_texts, data_rates = given['streams'], given['data_rates']
    if addresses and address:
        raise ValueError(f"parameters 'address' ({address}) and 'addresses' "
                         f'({list(addresses)}) both given: give one (address for one '
                         f'sensor, addresses for several on one base station)')
    listed = list(addresses) or [address]
    if len(set(listed)) != len(listed):
        raise ValueError(f"parameter 'addresses' must not list a sensor twice, got {listed}")
    count = len(listed)
    if count > 1 and not wireless:
        raise ValueError(f"parameter 'addresses' lists {count} sensors, but 'wireless' is "
                         f'false: several sensors share a port only behind a base station')
    for name, what, one_for_all in (('sensor_names', 'name', False), ('frame_ids', 'frame', False),
                                    ('streams', 'stream', True), ('data_rates', 'rate', True)):
        values = given[name]
        if values and len(values) != count and not (one_for_all and len(values) == 1):
            one = ' (or one for all)' if one_for_all else ''
            raise ValueError(f'parameter {name!r} must give one {what} per sensor{one}: '
                             f'{count} addresses, got {len(values)} ({list(values)})')
    for name, values, holds, must in (
            ('addresses', listed, lambda a: MIN_ADDRESS <= a <= MAX_ADDRESS,
             f'node addresses {MIN_ADDRESS}..{MAX_ADDRESS}'),
            ('sensor_names', names, _NAME.fullmatch,
             'names of letters, digits and _, starting with a letter'),
            ('streams', stream_texts, streams.names_a_stream, streams.valid_text()),
            ('data_rates', data_rates, settable_rate, RATE_VALID)):
        for value in values:
            if not holds(value):
                raise ValueError(f'parameter {name!r} must hold {must}, got {value!r}')
    if len(set(names)) != len(names):
        raise ValueError(f"parameter 'sensor_names' must not name two sensors alike, got "
                         f'{list(names)}')
    if len(set(frame_ids)) != len(frame_ids) or not all(frame_ids):
        raise ValueError(f"parameter 'frame_ids' must name each sensor's frame, each "
                         f'another, got {list(frame_ids)}')
    several = count > 1 or bool(names)
    out = []
    for i, value in enumerate(listed):
        name = names[i] if names else (default_name(value) if several else SINGLE_NAME)
        frame = frame_ids[i] if frame_ids else (f'{name}_link' if several else given['frame_id'])
        # One value each, or one for all (checked above): the i-th, or the one.
        text = stream_texts[i % len(stream_texts)] if stream_texts else given['stream']
        rate = data_rates[i % len(data_rates)] if data_rates else given['data_rate']
        out.append(SensorSetting(value, name, frame, text, float(rate)))
    return out


def shared_budget_refusal(sensors: Sequence[SensorSetting], baud: int, wireless: bool
                          ) -> str | None:
    """
    Refuse streams that do not fit the line together: say what fits per sensor, else None.

    The sensors behind one base station share its serial line, so the sum
    of their packets a second must fit it, with the same margin as one
    sensor's. Sensors whose rate is left as the device has it (0) are known
    only once connected: they are left out here.
    """
    known = [(s.address, s.stream_choice, s.data_rate) for s in sensors if s.data_rate]
    if len(known) < 2 or streams.shared_line_fits([(st, r) for _, st, r in known], baud, wireless):
        return None
    return ("parameters 'data_rate'/'data_rates' and 'stream'/'streams' do not fit the line: "
            + streams.shared_advice(known, baud, wireless))
