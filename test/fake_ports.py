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

"""What every port a test makes up offers the reader besides its reads and writes."""


class FakePort:
    """A port that hands over what it has: the wait size a reader sets changes nothing."""

    #: Bytes a read waits for (SerialPort.wake_for).
    wakes_for = 1

    def wake_for(self, nbytes: int) -> None:
        """Note the wait size, as SerialPort does; nothing here waits."""
        self.wakes_for = nbytes
