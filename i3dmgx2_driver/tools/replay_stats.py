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


class ReplayStats:
    """What a replay did, for the log and for tests."""

    __slots__ = (
        'acks_sent',
        'bytes_dropped',
        'bytes_sent',
        'chunks_sent',
        'commands',
        'host_bytes',
        'nacks_sent',
        'passes',
    )

    def __init__(self) -> None:
        for name in self.__slots__:
            setattr(self, name, 0)

    def as_dict(self) -> dict:
        """Return the counters by name."""
        return {name: getattr(self, name) for name in self.__slots__}

    def __repr__(self) -> str:
        return 'ReplayStats(' + ', '.join(f'{k}={v}' for k, v in self.as_dict().items()) + ')'
