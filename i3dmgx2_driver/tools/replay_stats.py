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
What a replay did: for the log and for tests.

One set of counters, filled by the playing (replay.py) and the answering
(replay_answers.py): here so that neither has to import the other.
"""

import dataclasses


@dataclasses.dataclass(slots=True)
class ReplayStats:
    """What a replay did, for the log and for tests."""

    acks_sent: int = 0
    bytes_dropped: int = 0
    bytes_sent: int = 0
    chunks_sent: int = 0
    commands: int = 0
    host_bytes: int = 0
    nacks_sent: int = 0
    passes: int = 0
