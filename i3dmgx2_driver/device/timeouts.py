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
How long the driver and ``discover`` wait for the radio: the one place.

Every wait for an answer that crosses the radio (a ping, a command's reply,
the first record after continuous mode is asked for, the silence after it
is stopped, the next record of a stream) is named here, with the setting
that changes it, so that the node (``settings.DeviceConfig``, the dialogue),
``discover`` (``tools.discover_probe.ProbeConfig``) and ``bringup``, which
measures the real round trips and warns when one comes within a factor 2 of
a timeout (tools/bringup_round_trips.py), cannot disagree about them. The steps that wait
(``sensor_steps.py``) are the same for all three.
"""

#: The driver's ping of its sensor at start-up (s per try), and its tries.
PING_TIMEOUT = 0.3
PING_RETRIES = 2
#: A command's reply, per try (s), and the tries, in the driver's dialogue.
REQUEST_TIMEOUT = 0.5
REQUEST_RETRIES = 3
#: On a port several sensors share: how long (s) a command holds the port for the
#: base station's ACK (which names no sensor), before the others may send theirs.
ACK_TIMEOUT = 0.1
#: The serial-number read that resumes a known sensor after a reconnect (s per try).
RESUME_TIMEOUT = 0.1
RESUME_RETRIES = 5
#: How long a resume looks for records of a stream still running (s; two periods if shorter).
RESUME_LOOK_S = 0.1
#: How long a tool's reader waits in one read (s): a listening tool reacts within it.
TOOL_READ_TIMEOUT = 0.05
#: Continuous mode asked, in tries of one request each (the node's ``continuous_retries``).
CONTINUOUS_TRIES = 5
#: Continuous mode asked: its first record is looked for this long (s), or for
#: RECORD_PERIODS sample periods when they are longer.
FIRST_RECORD_S = 0.3
#: A stream told to stop counts as stopped after this much silence (s), plus
#: RECORD_PERIODS sample periods (a slow stream is silent between its records).
QUIET_S = 0.3
#: Sample periods a record may come late by (the radio's queue, jitter) before its
#: absence says something.
RECORD_PERIODS = 5
#: Told to stop (0xFA, which has no reply): how long (s) beyond the silence above to
#: wait for it, and how many times to say it before giving up.
STOP_PATIENCE_S = 0.7
STOP_TRIES = 3
#: After 0xFA: how long (s) the records already on their way are given to arrive
#: before they are dropped (the line quieted without waiting for silence).
STOP_SETTLE_S = 0.05
#: After a failed attempt the port is tried again this much later (s; sooner when it comes
#: back: watchdog.ReopenWait), the node's ``reconnect_interval``.
RECONNECT_INTERVAL = 1.0
#: No record for this long (s): the stream has stalled (the node's ``read_timeout``).
STALL_TIMEOUT = 1.0
#: The first polls before continuous mode (dialogue.py): tries of each, short of the
#: usual, since the sensor may still be waking and continuous mode is asked after anyway.
FIRST_POLL_RETRIES = 2
#: 0xFA has no reply: said this many times, this far apart (s), the radio may drop one.
STOP_REPEATS = 3
STOP_GAP_S = 0.02
#: The same when the driver stops and closes the port: its stop has a deadline.
STOP_REPEATS_AT_EXIT = 2
STOP_GAP_AT_EXIT_S = 0.01
#: The temperature poll while streaming (s per try, and tries): short, the next poll
#: tries again.
TEMPERATURE_TIMEOUT = 0.3
TEMPERATURE_RETRIES = 2
#: How often a wait for records, or for their silence, looks again (s).
RECORD_POLL_S = 0.01
#: How often a resume looks for a record of the stream still running (s; within RESUME_LOOK_S).
RESUME_POLL_S = 0.002
#: How often a request's wait looks for a NACK or a cancel beside its reply (s), and its wait
#: for the base station's ACK (a shared port's) for its sensor's NACK.
REPLY_LOOK_S = 0.02
ACK_LOOK_S = 0.01
#: The reader's select() timeout while the line is quiet: how soon it sees it is told to stop.
SELECT_TIMEOUT_S = 0.2
#: The reader's wait while the parser holds one byte (a lone 0xAA: an ACK, or a packet's
#: start), to tell the two apart soon (s).
LONE_BYTE_WAIT_S = 0.02
#: How long stopping waits for the supervisor thread to end (s).
SUPERVISOR_STOP_WAIT_S = 1.5
#: How long a port's reader is waited for to start (s), and to end once told to stop
#: (a read returns within its read timeout, far less).
READER_START_WAIT_S = 1.0
READER_STOP_WAIT_S = 2.0
#: discover: the first pings, until a base station has answered one (s per ping).
PROBE_PING_TIMEOUT = 0.5
#: discover: a ping once a base station is known to be there (s).
PROBE_ANSWER_TIMEOUT = 1.0
#: discover: a command's reply, per try (s), and the tries.
PROBE_REQUEST_TIMEOUT = 0.3
PROBE_REQUEST_RETRIES = 3
#: discover: how long it listens for sensors that stream already (s; one packet is enough).
PROBE_LISTEN_S = 0.5
#: discover: this many unanswered pings first mean no base station on the port.
PROBE_SILENT_PINGS = 2
