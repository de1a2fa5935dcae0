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
How the reader thread is scheduled, and what the collector is told at start-up.

A sample waits on its way to ``publish()`` for three things besides its own
work: the kernel scheduling the reader thread (other processes may hold the
CPU), the interpreter lock (another thread of the node may hold it), and the
garbage collector (a full collection walks every object the process has).
docs/latency.md measures each of these levers.

- :class:`ThreadPolicy` asks for SCHED_FIFO for the reader thread. The
  kernel may refuse (an unprivileged user without an ``rtprio`` limit,
  another platform): the reader then runs as it would have, and
  :func:`apply_to_current_thread` says why in one sentence for the log.
  (Pinning the reader thread to a CPU was measured too, and left out: it
  did not help, with or without SCHED_FIFO.)
- :func:`freeze_startup_heap` freezes what start-up allocated, so that a
  collection never walks rclpy's and the driver's long-lived objects again.
  (A shorter interpreter lock switch interval was measured too, and left
  out: under a parameter flood it made the driver's share worse without
  SCHED_FIFO, and no better with it.)
- :func:`name_os_threads` gives every thread its ``threading`` name in the
  OS too, so that ``top -H`` and the benchmarks' wakes per thread (from
  ``/proc``) tell the reader from the others.
"""

import contextlib
import ctypes
import gc
import os
import sys
import threading
from typing import Any, NamedTuple

#: Highest SCHED_FIFO priority Linux accepts.
MAX_PRIORITY = 99
#: prctl(2) option: the calling thread's name (15 bytes and a NUL).
_PR_SET_NAME = 15


class ThreadPolicy(NamedTuple):
    """What the reader thread asks of the scheduler; the default asks for nothing."""

    #: SCHED_FIFO priority 1..99; 0 leaves the thread under the normal policy.
    realtime_priority: int = 0


#: Ask nothing of the scheduler.
NORMAL_SCHEDULING = ThreadPolicy()


class PolicyOutcome(NamedTuple):
    """What the scheduler granted (short phrases) and refused (a sentence each, for the log)."""

    applied: tuple[str, ...] = ()
    refused: tuple[str, ...] = ()


#: What a thread that asked nothing was granted.
NOTHING_GRANTED = PolicyOutcome()


def apply_to_current_thread(policy: ThreadPolicy) -> PolicyOutcome:
    """
    Apply ``policy`` to the calling thread; return what was applied and what refused.

    Never raises: a refusal leaves that part of the thread's scheduling as it
    was, and its sentence says what was refused, why, and how to allow it.
    """
    priority = policy.realtime_priority
    if priority <= 0:
        return NOTHING_GRANTED
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as exc:
        reason = getattr(exc, 'strerror', None) or 'not available on this platform'
        return PolicyOutcome(refused=(
            f'realtime_priority {priority} refused ({reason}): the reader thread keeps '
            f'normal scheduling; allow SCHED_FIFO with an rtprio limit of at least '
            f'{priority} (ulimit -r, /etc/security/limits.conf)',))
    return PolicyOutcome(applied=(f'SCHED_FIFO priority {priority}',))


def freeze_startup_heap() -> int:
    """
    Collect once, then move every object alive now out of the collector's sight.

    Start-up allocates the long-lived objects (modules, rclpy, message
    classes, the node); the hot path allocates nothing that survives a
    sample, so after this a collection has almost nothing to walk. Returns
    how many objects were frozen.
    """
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


def name_os_threads() -> None:
    """
    Give every thread started from now on its ``threading`` name in the OS too.

    Python (before 3.14) leaves each thread the process's name in
    ``/proc/PID/task/TID/comm``. The profile hook :mod:`threading` installs
    in each new thread names it and takes itself off at its first call, so
    nothing stays on the thread's path (every thread, rclpy's executor
    workers too). Linux only; elsewhere nothing is done.
    """
    if sys.platform.startswith('linux'):
        threading.setprofile(_name_and_forget)


def _name_and_forget(frame: Any, event: str, arg: Any) -> None:
    sys.setprofile(None)
    name = threading.current_thread().name.encode(errors='replace')[:15]
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).prctl(_PR_SET_NAME, ctypes.c_char_p(name), 0, 0, 0)
