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
The threads that read ports, kept for the process's life and handed one port after another.

A node opens its port again at every reconnect, and a thread started for
each reading would cost memory that stays: every new thread rebuilds
``threading``'s table of running threads (a dict over CPython's small-object
limit, so from glibc), and glibc gives each new thread the next of its
arenas in turn, so the rebuild touches a fresh page in arena after arena
(the memory curve placed its last pages there: docs/soak.md, "The end of the
curve, mapping by mapping"). A thread that waits for its next port instead
touches nothing new.

A thread keeps the scheduling its first reading asked for (a realtime
priority is granted once, to the thread), so it is handed only readings
that ask for the same. Threads are never retired: there are as many as
readings ever ran at once (one per port), each asleep while idle.
"""

from collections.abc import Callable
import queue
import sys
import threading

from .realtime import apply_to_current_thread, PolicyOutcome, ThreadPolicy

__all__ = ['READERS', 'ReaderThreads', 'Reading']

#: One reading of a port, run in a reader thread with what the scheduler granted it.
Reading = Callable[[PolicyOutcome], None]
#: What a reader thread waits on: its next reading, and the event to set once it returned.
_Work = queue.SimpleQueue[tuple[Reading, threading.Event]]


class ReaderThreads:
    """Reader threads reused: a reading goes to an idle thread of its policy, else a new one."""

    def __init__(self, name: str = 'gx2-reader') -> None:
        self._name = name
        self._lock = threading.Lock()
        #: The idle threads by policy, each as the queue it waits on for its next reading.
        self._idle: dict[ThreadPolicy, list[_Work]] = {}
        #: Threads started so far (what the reuse saves is told by this staying small).
        self.started = 0

    def run(self, reading: Reading, policy: ThreadPolicy, done: threading.Event) -> None:
        """Run ``reading`` in a reader thread of ``policy``; ``done`` is set once it returned."""
        with self._lock:
            idle = self._idle.get(policy)
            work = idle.pop() if idle else None  # the most recently idle first
            self.started += work is None
        if work is None:
            work = queue.SimpleQueue()
            threading.Thread(target=self._serve, args=(policy, work), name=self._name,
                             daemon=True).start()
        work.put((reading, done))

    def _serve(self, policy: ThreadPolicy, work: _Work) -> None:
        """Apply ``policy`` once, then run each reading put on ``work``, forever."""
        outcome = apply_to_current_thread(policy)  # nothing asked: nothing granted
        while True:
            reading, done = work.get()
            try:
                reading(outcome)
            except Exception:  # noqa: BLE001 - reported as a thread of its own would be
                threading.excepthook(threading.ExceptHookArgs(
                    (*sys.exc_info(), threading.current_thread())))
            # Nothing of the reading may stay referenced here while idle (its
            # port, parser and links are freed by reference count when dropped),
            # and whoever waits for it finds this thread idle again.
            del reading
            with self._lock:
                self._idle.setdefault(policy, []).append(work)
            done.set()
            del done


#: The process's reader threads.
READERS = ReaderThreads()
