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
The port's and the threads' life: ``Lifecycle`` starts and stops a simulation.

Start creates the pty and its symlink, powers the sensors up (through the
``power_up`` it is given, under the simulator's lock) and starts the
threads: the reader and one transmitter per sensor. Stop ends them and
removes the port, also at interpreter exit if nobody called it, so that no
symlink is left behind. The order of these steps is what keeps a host from
seeing a port before its sensor is up, or a sensor after its port is gone.
"""

import atexit
import collections.abc
import threading
import time

from .host_reader import HostReader
from .pty_port import PtyPort
from .transmitter import Transmitter


class Lifecycle:
    """
    Starts and stops the port and the threads; start and stop from one thread.

    ``wake`` is the condition on the simulator's lock the transmitters wait
    on, ``stop`` the event every thread stops at (the cable's too);
    ``transmitters`` the thread name and transmitter of every sensor;
    ``power_up(now)`` powers everything up at start, the lock held.
    """

    def __init__(self, pty: PtyPort, reader: HostReader, wake: threading.Condition,
                 stop: threading.Event,
                 transmitters: collections.abc.Sequence[tuple[str, Transmitter]],
                 power_up: collections.abc.Callable[[float], None]) -> None:
        self._pty = pty
        self._reader = reader
        self._wake = wake
        self._stop = stop
        self._transmitters = transmitters
        self._power_up = power_up
        self._threads: list[threading.Thread] = []
        self.started = False
        #: Wall-clock time of start() (the sensor's power-up).
        self.start_time: float | None = None

    def start(self) -> None:
        """Create the port, power the sensor up and start the threads."""
        if self.started:
            raise RuntimeError('the simulator is already started')
        self._stop.clear()
        self._pty.create()
        self._reader.open_pipe()
        self._reader.plug_in()
        now = time.time()
        with self._wake:
            self.start_time = now
            self._power_up(now)
        self.started = True
        # An interpreter that exits without stop() still removes the port.
        atexit.register(self.stop)
        self._threads = [
            threading.Thread(target=self._reader.run, args=(self._stop,), name='gx2sim-rx',
                             daemon=True),
            *(threading.Thread(target=tx.run, args=(self._stop,), name=name, daemon=True)
              for name, tx in self._transmitters),
        ]
        for thread in self._threads:
            thread.start()

    def stop(self) -> None:
        """Stop the threads, close the pty and remove the port symlink."""
        if not self.started:
            return
        self._stop.set()
        self._reader.wake()
        with self._wake:
            self._wake.notify_all()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._pty.pull_out()
        self._reader.close_pipe()
        self._pty.remove()
        self.started = False
        atexit.unregister(self.stop)
