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
What every phase of the dialogue with a sensor is given, in one piece.

The phases (identification.py, rate_setting.py, continuous.py) each speak
to the same sensor with the same settings, say what they do to the same
log, warn through the same throttled channel and give up on the same
cancel event; :class:`DialogueParts` hands them that together.
"""

from collections.abc import Callable
import threading
from typing import Any, NamedTuple

from .settings import DeviceConfig

#: ``warn(key, message, period)``: say a problem (throttled per key), keep it as the last error.
Warn = Callable[[str, str, float | None], None]


class DialogueParts(NamedTuple):
    """
    The sensor's settings, the log, the warning channel and the cancel event.

    ``log`` has ``debug/info/warning/error``; ``warn`` says a problem once
    per key and period; ``cancel`` set makes the waits give up (the driver
    is stopping or pausing the stream).
    """

    config: DeviceConfig
    log: Any
    warn: Warn
    cancel: threading.Event
