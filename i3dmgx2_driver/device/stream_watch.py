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
What the reader hands one sensor's data packets to: the stream's bookkeeping.

Each packet of the sensor's address is a reply to the request waiting for
it, a record of the stream, or both; this decides which, keeps the time the
stream was last heard (what the stall watch and the wait for the stream
read), counts records and replies, and passes the records on. It runs in
the reader thread for every sample: it allocates nothing and takes no lock.
"""

from .exchange import Exchange
from .port_reader import RecordCallback
from .radio import RadioQuality
from ..codec import layouts
from ..codec.framing import DataPacket

_CODE_OF_TYPE = {layout.record_type: code for code, layout in layouts.LAYOUTS.items()
                 if layout.record_type is not None}


class StreamWatch:
    """
    One sensor's data packets: replies to ``exchange``, records to ``on_record``.

    ``streamed`` is the command byte of the record being streamed, None
    while the device is not streaming (the dialogue sets it): a polled
    reply of that code is then both the reply and a record of the stream.
    """

    def __init__(self, on_record: RecordCallback, exchange: Exchange,
                 radio: RadioQuality) -> None:
        self._on_record = on_record
        self._exchange = exchange
        self._radio = radio
        self.streamed: int | None = None
        self.last_data_time = 0.0
        #: The same instant on the monotonic clock, for stall detection.
        self.last_data_mono = 0.0
        #: Records of the stream (of any code while none is streamed) received so far.
        self.records = 0
        #: Replies to this link's requests (data packets it asked for).
        self.replies = 0
        #: Command byte of the last record handed to ``on_record`` (None before one).
        self.last_code: int | None = None

    def on_data(self, event: DataPacket, now: float, mono: float) -> None:
        """Take one data packet of this sensor (reader thread)."""
        code = _CODE_OF_TYPE.get(type(event.record))
        # While a stream runs, only its records keep it alive: a sensor power-cycled
        # into its EEPROM auto-start streams another record, and the stall watch
        # and the wait for the stream must not take that one for it (found by the
        # long soak).
        ours = self.streamed is None or code == self.streamed
        if ours:
            self.last_data_time = now
            self.last_data_mono = mono
        if event.lqi is not None:
            self._radio.note(event.lqi, event.rssi)
        pending = self._exchange.pending
        if pending is not None and pending.code == code:
            pending.fulfil(event.record)
            self.replies += 1
            if code != self.streamed:
                return
        if ours:
            self.records += 1
        self.last_code = code
        self._on_record(event, now, mono)

    def wake(self) -> None:
        """Make the request waiting for this sensor's packets look again (the port is gone)."""
        self._exchange.wake()
