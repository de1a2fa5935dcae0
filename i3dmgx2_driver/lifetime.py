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
How a process of the package ends: told by a signal, with its parent, and by a deadline.

Every executable (the node, the managed node, the simulator and the tools)
ends the same three ways, so the rules live here, below every room that
starts a process:

- **A signal** (SIGINT, SIGTERM, SIGHUP) sets a :class:`StopSignal`, which
  the main thread waits on. Not a ``threading.Event``: its ``set()`` takes
  the lock its ``wait()`` holds for a moment at each call and each wake-up.
  A Python signal handler runs in the main thread between two bytecodes, so
  a signal that lands in that moment made the handler wait for a lock its
  own thread held, for good: the node hung once in about a hundred stops
  (SIGINT right after the first record, the main thread in ``stop.wait``).
  :class:`StopSignal` takes no lock in the handler: a flag and one byte
  written to a pipe the waiter selects on. The pipe is the interpreter's
  wakeup fd as well: a process's signal may be delivered to any of its
  threads (a DDS thread, the reader), and then the main thread, asleep in
  ``select()``, was never woken to run the handler: the stop was lost and
  the node ran on (test_shutdown.py sends one to another thread). The C
  handler writes the wakeup fd from whichever thread the signal reached.
- **The parent's death**: :func:`die_with_parent` asks Linux to send SIGTERM
  when the process that started this one ends (``PR_SET_PDEATHSIG``), so
  that a script killed outright, or a terminal closed under a process in
  a session of its own (the demo's simulator), leaves nothing running. A
  process started under ``nohup`` (SIGHUP ignored) is meant to outlive its
  terminal, and is left alone.
- **A deadline**: :func:`arm_deadline`, armed when a stop begins. If the
  process has not exited :data:`SHUTDOWN_DEADLINE` seconds later, the
  interpreter's fault handler writes every thread's stack to standard error
  (the log) and the process exits 1 (the handler's own ``_exit(1)``). The
  handler runs in a C thread of its own, without the interpreter's lock, so
  a thread stuck in C code cannot hold it up either.
"""

import contextlib
import ctypes
import faulthandler
import os
import select
import signal
import sys
import threading
import time
from typing import Any

#: Seconds from the start of a stop to the end of the process, at most.
SHUTDOWN_DEADLINE = 3.0
#: The signals that stop a process of the package cleanly.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: prctl(2) option: the signal the process gets when its parent ends.
_PR_SET_PDEATHSIG = 1
#: Where the deadline writes when the process has no standard error.
_DEVNULL: list[Any] = []


def _stop_signals(signals: tuple[int, ...] = STOP_SIGNALS) -> list[int]:
    """Return ``signals`` but SIGHUP when ignored (``nohup``: outliving the terminal is asked)."""
    return [s for s in signals if s != signal.SIGHUP or signal.getsignal(s) is not signal.SIG_IGN]


class StopSignal:
    """
    A stop flag that a signal handler may set; any thread may set it and wait on it.

    ``install()`` (main thread) makes SIGINT, SIGTERM and SIGHUP set it (not
    SIGHUP when it is ignored: ``nohup``) and :meth:`restore` puts the
    previous handlers back. ``signum`` is the signal that set it, if one did.
    The pipe that wakes a waiter stays open as long as the object lives, so
    that a late ``set()`` from another thread never writes to a descriptor
    reused meanwhile.
    """

    def __init__(self) -> None:
        self._read, self._write = os.pipe()
        os.set_blocking(self._read, False)
        os.set_blocking(self._write, False)
        self._set = False
        #: The signal that set the flag (None: not a signal, or not yet).
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}
        self._wakeup: int | None = None

    def install(self, signals: tuple[int, ...] = STOP_SIGNALS) -> 'StopSignal':
        """Have ``signals`` set the flag (from the main thread; elsewhere nothing changes)."""
        if threading.current_thread() is not threading.main_thread():
            return self
        for signum in _stop_signals(signals):
            self._previous[signum] = signal.signal(signum, self._on_signal)
        self._wakeup = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        return self

    def restore(self) -> None:
        """Put back the handlers :meth:`install` replaced."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()
        if self._wakeup is not None:
            signal.set_wakeup_fd(self._wakeup)
            self._wakeup = None

    def _on_signal(self, signum: int, frame: object) -> None:
        # The main thread, between two bytecodes of whatever it was doing: no lock here.
        self.signum = signum
        self.set()

    def set(self) -> None:  # noqa: A003 - threading.Event's name, for the same use
        """Set the flag and wake whoever waits (any thread, or a signal handler)."""
        self._set = True
        with contextlib.suppress(OSError):  # the pipe is full: a wake-up is pending already
            os.write(self._write, b'\0')

    def is_set(self) -> bool:
        """Whether the flag is set."""
        return self._set

    def wait(self, timeout: float | None = None) -> bool:
        """Wait up to ``timeout`` s (None: for ever) for the flag; return whether it is set."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._set:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                break
            if select.select([self._read], [], [], left)[0]:
                with contextlib.suppress(BlockingIOError):
                    while os.read(self._read, 64):
                        pass
        return self._set

    def __del__(self) -> None:
        close_quietly(getattr(self, '_read', None), getattr(self, '_write', None))


def close_quietly(*fds: int | None) -> None:
    """Close each descriptor given (None: none); one already closed is no error at the end."""
    for fd in fds:
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)


def die_with_parent(signum: int = signal.SIGTERM) -> bool:
    """
    Have Linux send ``signum`` to this process when its parent ends; return whether it will.

    Nothing on other systems, and nothing under ``nohup`` (SIGHUP ignored:
    the process is meant to outlive whoever started it). SIGINT suits a
    tool that cleans up on KeyboardInterrupt; an ignored ``signum`` gets its
    default action back. The parent is, to
    the kernel, the *thread* that started this process: a program that starts
    one from a thread must keep that thread until the process ends.
    """
    if not sys.platform.startswith('linux') or signal.getsignal(signal.SIGHUP) is signal.SIG_IGN:
        return False
    if signal.getsignal(signum) is signal.SIG_IGN and \
            threading.current_thread() is threading.main_thread():
        # A background job of a script starts with SIGINT ignored: it must end it still.
        signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT
                      else signal.SIG_DFL)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signum), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def interrupt_on_stop_signals() -> None:
    """
    Make SIGINT, SIGTERM and SIGHUP raise KeyboardInterrupt, and the parent's end send SIGINT.

    For a tool that leaves things as found on Ctrl-C (discover, bringup): a
    closed terminal, a ``kill`` or its parent's end then take the same way
    out rather than ending it where it stands. Main thread only; SIGHUP is
    left ignored under ``nohup``.
    """
    if threading.current_thread() is not threading.main_thread():
        return
    for signum in _stop_signals():
        signal.signal(signum, signal.default_int_handler)
    die_with_parent(signal.SIGINT)


def arm_deadline(seconds: float = SHUTDOWN_DEADLINE) -> None:
    """
    Make sure the process ends within ``seconds``: past them, every thread's stack, then exit 1.

    Written to standard error (the log); armed again, the count starts afresh.
    Without a standard error to write to, the deadline still ends the process.
    """
    try:
        faulthandler.dump_traceback_later(seconds, exit=True, file=sys.__stderr__ or sys.stderr)
    except (AttributeError, RuntimeError, ValueError, OSError):
        if not _DEVNULL:
            _DEVNULL.append(open(os.devnull, 'w'))  # noqa: SIM115 - for the process's life
        faulthandler.dump_traceback_later(seconds, exit=True, file=_DEVNULL[0])


def cancel_deadline() -> None:
    """Disarm :func:`arm_deadline` (a caller that goes on after the stop: a test)."""
    faulthandler.cancel_dump_traceback_later()
