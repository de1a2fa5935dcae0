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

from .realtime import apply_to_current_thread, NOTHING_GRANTED, PolicyOutcome, ThreadPolicy

__all__ = ['READERS', 'ReaderThreads', 'Reading']

#: One reading of a port, run in a reader thread with what the scheduler granted it.
Reading = Callable[[PolicyOutcome], None]


class _ReaderThread:
    """One thread: applies its policy once, then runs each reading handed to it."""

    def __init__(self, owner: 'ReaderThreads', policy: ThreadPolicy, name: str) -> None:
        self._owner = owner
        self.policy = policy
        self._work: queue.SimpleQueue[tuple[Reading, threading.Event]] = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._serve, name=name, daemon=True)
        self.thread.start()

    def hand(self, reading: Reading, done: threading.Event) -> None:
        self._work.put((reading, done))

    def _serve(self) -> None:
        outcome = (apply_to_current_thread(self.policy) if self.policy.requested
                   else NOTHING_GRANTED)
        while True:
            reading, done = self._work.get()
            try:
                reading(outcome)
            except Exception:  # noqa: BLE001 - reported as a thread of its own would be
                threading.excepthook(threading.ExceptHookArgs(
                    (*sys.exc_info(), self.thread)))
            # Nothing of the reading may stay referenced here while idle (its
            # port, parser and links are freed by reference count when dropped),
            # and whoever waits for it finds this thread idle again.
            del reading
            self._owner.idle(self)
            done.set()
            del done


class ReaderThreads:
    """Reader threads reused: a reading goes to an idle thread of its policy, else a new one."""

    def __init__(self, name: str = 'gx2-reader') -> None:
        self._name = name
        self._lock = threading.Lock()
        self._idle: dict[ThreadPolicy, list[_ReaderThread]] = {}
        #: Threads started so far (what the reuse saves is told by this staying small).
        self.started = 0

    def run(self, reading: Reading, policy: ThreadPolicy, done: threading.Event) -> None:
        """Run ``reading`` in a reader thread of ``policy``; ``done`` is set once it returned."""
        with self._lock:
            idle = self._idle.get(policy)
            worker = idle.pop() if idle else None
            if worker is None:
                self.started += 1
        if worker is None:
            worker = _ReaderThread(self, policy, self._name)
        worker.hand(reading, done)

    def idle(self, worker: _ReaderThread) -> None:
        """Take ``worker`` back for the next reading (the most recent is handed out first)."""
        with self._lock:
            self._idle.setdefault(worker.policy, []).append(worker)


#: The process's reader threads.
READERS = ReaderThreads()
