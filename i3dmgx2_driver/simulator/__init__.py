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
A simulated 3DM-GX2 (wireless with its base station, or wired), for tests and demos.

``SimulatedSensor`` is the device model (no I/O); ``PtySimulator`` puts it
behind a pseudo-terminal that a driver opens like a real serial port, with
faults from ``FaultConfig`` and the ground truth of every packet in
``SentRecord`` entries. One module per part: ``config`` (how it is set up),
``sensor``, ``cycle_clock``, ``data_records`` and ``motion`` (the device),
``base_station`` (wireless: ACK/NACK, ping) or ``wired_line`` (a wired
sensor's own line), ``transmitter`` (the records on their way: timing,
faults, chunked writes), ``host_reader`` (the reader thread),
``sensor_unit`` (one sensor's parts: its inbox with the firmware's quirks,
its power), ``pty_port`` (the pseudo-terminal, its symlink), ``ground_truth``
(the record of it all, and its read side), and
``pty_link`` (``PtySimulator``, which builds every part, starts and stops
them, unplugs the cable and changes their faults, timed ones included).
``python -m i3dmgx2_driver.simulator`` runs it from a shell. Pure Python on
top of the codec: the simulator and the driver share one implementation of
every byte.
"""

from .config import SimulatorConfig
from .faults import FaultConfig
from .ground_truth import HostCommand, SentRecord, SimulatorStats
from .motion import Motion, MotionConfig
from .pty_link import PtySimulator
from .sensor import Reply, SimulatedSensor

__all__ = [
    'FaultConfig', 'HostCommand', 'Motion', 'MotionConfig', 'PtySimulator', 'Reply',
    'SentRecord', 'SimulatedSensor', 'SimulatorConfig', 'SimulatorStats',
]
