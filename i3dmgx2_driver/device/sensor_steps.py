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
The steps a conversation with a sensor is made of, each with its waits.

Quiet the line, stop a stream and see it stop, start one and see its
records, read the rate divider, write it, store a bias in EEPROM: the node
(whose dialogue.py puts these steps in its order and remembers what they
found), ``discover`` and ``bringup`` take the same steps, with the waits of
timeouts.py, so that they cannot disagree about when a stream has stopped or
started. What is learned is the caller's; what is kept here is the patience
of a request (its timeout and tries), the cancel event that cuts a wait
short, and the EEPROM writes sent.

Two facts of the radio shape every step. A command may be lost, and so may
its reply: a stream counts as started only once a record of it has arrived
(a lost reply may hide a stream that runs, a reply may come with no stream
after it), and as stopped only once the sensor has been silent for a while
(0xFA has no reply at all). And an EEPROM cell wears with every write: a
write is never resent blindly, and every one sent is counted.
"""

import contextlib
import threading
import time

from . import timeouts
from .link import DeviceError, DeviceLink, DeviceTimeout, EchoMismatch
from ..codec import commands, layouts
from ..codec.data_rate import RATE_DIVIDER_ADDRESS


def ping(link: DeviceLink, timeout: float = timeouts.PING_TIMEOUT,
         retries: int = timeouts.PING_RETRIES) -> bool:
    """Ask the base station whether the sensor answers over the radio (``retries`` pings)."""
    for _ in range(retries):
        answer = link.ping_once(link.address, timeout)
        if answer is not None:
            return answer
    return False


def say_stop(link: DeviceLink, repeats: int = timeouts.STOP_REPEATS,
             gap: float = timeouts.STOP_GAP_S) -> None:
    """Send 0xFA ``repeats`` times, ``gap`` s apart: it has no reply and the radio may drop it."""
    for _ in range(repeats):
        link.send(commands.stop_continuous())
        time.sleep(gap)


class SensorSteps:
    """
    Speak to a sensor over whichever link each step is given.

    ``timeout`` and ``retries`` are a request's patience (per try, and the
    tries); ``cancel`` set makes the waits for records give up at once.
    """

    def __init__(self, timeout: float = timeouts.REQUEST_TIMEOUT,
                 retries: int = timeouts.REQUEST_RETRIES,
                 cancel: threading.Event | None = None) -> None:
        self.timeout, self.retries = timeout, retries
        self._cancel = cancel if cancel is not None else threading.Event()
        #: EEPROM write commands sent (the divider's cell, a bias stored; each may wear it).
        self.eeprom_writes = 0

    # -- the line -------------------------------------------------------------------------

    def quiet(self, link: DeviceLink) -> None:
        """
        Stop any stream and drop what is in flight, without waiting for silence.

        For a link whose reader may not run yet, so that nothing would tell
        the silence (raises PortError).
        """
        if not link.running.is_set():
            link.flush_input()
        self.stop(link)
        link.flush_input()

    def stop(self, link: DeviceLink) -> None:
        """Send 0xFA (repeated: it has no reply); from now on a polled record is a reply only."""
        say_stop(link)
        link.set_streamed(None)
        time.sleep(timeouts.STOP_SETTLE_S)

    def stop_until_quiet(self, link: DeviceLink, period: float) -> bool:
        """
        Send 0xFA until the sensor is silent; True once it is.

        ``period`` is the time between its records: a slow stream is silent
        between two of them. The link's reader must run.
        """
        # Any record of this sensor says from now on that it still streams.
        link.set_streamed(None)
        for _ in range(timeouts.STOP_TRIES):
            since = time.monotonic()
            say_stop(link)
            if self.wait_quiet(link, since, period) is not None:
                return True
        return False

    def wait_quiet(self, link: DeviceLink, since: float, period: float,
                   within: float | None = None) -> float | None:
        """
        Wait until no record came since ``since`` (monotonic) for the quiet time; say when.

        The quiet time is ``QUIET_S`` plus ``RECORD_PERIODS`` periods. Returns
        the time of the last record (monotonic; 0.0 if none ever came), or
        None if records still came after ``within`` s (by default the quiet
        time and ``STOP_PATIENCE_S``).
        """
        quiet = timeouts.QUIET_S + timeouts.RECORD_PERIODS * period
        deadline = time.monotonic() + (quiet + timeouts.STOP_PATIENCE_S
                                       if within is None else within)
        while time.monotonic() < deadline:
            last = link.last_data_mono
            if time.monotonic() - max(last, since) >= quiet:
                return last
            time.sleep(timeouts.RECORD_POLL_S)
        return None

    def start_stream(self, link: DeviceLink, code: int, period: float,
                     tries: int = timeouts.CONTINUOUS_TRIES) -> bool:
        """
        Ask for continuous mode of record ``code`` until its records actually arrive.

        ``period`` is the time between records at the sensor's rate. Returns
        True once a record has arrived, False if cancelled first; raises
        DeviceTimeout when none comes after ``tries`` requests,
        PortDisconnected if the port goes. The link's reader must run.
        """
        # From now on a record of this code is a record of the stream, even one that
        # also answers a polled request.
        link.set_streamed(code)
        for _ in range(tries):
            before = link.records
            # The reply may be lost while the stream started: the records tell.
            with contextlib.suppress(DeviceError):
                link.request(commands.set_continuous(code), layouts.SET_CONTINUOUS,
                             self.timeout, 1)
            deadline = time.monotonic() + max(timeouts.FIRST_RECORD_S,
                                              timeouts.RECORD_PERIODS * period)
            while time.monotonic() < deadline and not self._cancel.is_set():
                if link.records > before:
                    return True
                link.check_port()
                time.sleep(timeouts.RECORD_POLL_S)
            if self._cancel.is_set():
                return False
        raise DeviceTimeout(f'continuous mode: no records after {tries} requests')

    # -- EEPROM ---------------------------------------------------------------------------

    def read_divider(self, link: DeviceLink) -> int:
        """Return the data-rate divider (EEPROM 0xFCA2); DeviceTimeout if unanswered."""
        return link.request(commands.read_eeprom(RATE_DIVIDER_ADDRESS), layouts.READ_EEPROM,
                            self.timeout, self.retries).value

    def write_divider(self, link: DeviceLink, current: int, wanted: int) -> int:
        """
        Write the divider ``wanted`` over ``current`` once; return it as read back.

        When the write's reply does not come, the write may have reached the
        sensor and only the reply been lost. The divider is read back
        instead, and written again only if the sensor still has the old one
        (the command itself was lost). So one change of setting writes the
        cell once, however rough the radio. Raises DeviceTimeout when the
        read-back is not ``wanted`` after every try, or is not answered.
        """
        readback = current
        for _ in range(self.retries):
            self.eeprom_writes += 1
            with contextlib.suppress(DeviceError):  # written or not: the read below tells
                link.request(commands.write_eeprom(RATE_DIVIDER_ADDRESS, wanted),
                             layouts.WRITE_EEPROM, self.timeout, 1)
            readback = self.read_divider(link)
            if readback != current:
                break
        if readback != wanted:
            raise EchoMismatch(f'data rate: wrote divider {wanted}, read back {readback}')
        return readback

    def transfer_to_non_volatile(self, link: DeviceLink, quantity: int) -> int:
        """
        Store a bias in the sensor's EEPROM (0xD0: 1 accel, 2 gyro); return the reply.

        Asked for once and counted as an EEPROM write: never resent blindly
        (it wears the memory); :data:`codec.records.INVALID_QUANTITY` back: refused.
        Raises DeviceTimeout when no reply comes (stored or not: unknown).
        """
        self.eeprom_writes += 1
        return link.request(commands.transfer_to_non_volatile(quantity),
                            layouts.TRANSFER_TO_NON_VOLATILE, self.timeout, 1).quantity
