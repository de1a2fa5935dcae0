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
No thread started per reconnect or per fault capture: the memory curve's last pages.

Every new thread rebuilds ``threading``'s table of running threads in the
next of glibc's arenas, touching a page there that stays (docs/soak.md, "The
end of the curve, mapping by mapping"). So a port read after a port, as at
each reconnect, is read by the same thread (``ReaderThreads``), and a fault
capture, written whole at once, starts no flusher. Each test here fails on
the code that started a thread each time.
"""

import gc
import logging
import threading
import weakref

from fake_ports import FakePort
from i3dmgx2_driver.capture.fault_capture import FaultCapture
from i3dmgx2_driver.capture.file_format import read_capture
from i3dmgx2_driver.device.link import PortReader
from i3dmgx2_driver.device.port import PortDisconnected
from i3dmgx2_driver.device.reader_threads import ReaderThreads
from i3dmgx2_driver.device.realtime import NORMAL_SCHEDULING, PolicyOutcome, ThreadPolicy
import pytest


class _Unplugged(FakePort):
    """A port gone at the first read; notes which thread read it."""

    def __init__(self, readers: list[threading.Thread]) -> None:
        self._readers = readers

    def write(self, data: bytes) -> None:
        pass

    def read_some(self, timeout: float) -> bytes:
        self._readers.append(threading.current_thread())
        raise PortDisconnected('unplugged')


def test_ports_read_one_after_another_are_read_by_one_thread() -> None:
    readers: list[threading.Thread] = []
    for _ in range(6):  # six reconnects
        reader = PortReader(_Unplugged(readers), 95)
        reader.start()
        assert reader.disconnected.wait(5.0)
        reader.stop()
    assert len(readers) == 6
    assert readers[0] is not threading.current_thread()
    assert all(thread is readers[0] for thread in readers), \
        f'{len(set(readers))} threads for 6 readings one after another'
    assert readers[0].name == 'gx2-reader' and readers[0].is_alive()


def _run(threads: ReaderThreads, reading, policy: ThreadPolicy = NORMAL_SCHEDULING) -> None:
    done = threading.Event()
    threads.run(reading, policy, done)
    assert done.wait(5.0)


def test_a_thread_is_started_only_for_readings_at_once_or_of_another_policy() -> None:
    threads = ReaderThreads('test-reader')
    ran: list[threading.Thread] = []

    def note(outcome: PolicyOutcome) -> None:
        ran.append(threading.current_thread())

    for _ in range(10):
        _run(threads, note)
    assert threads.started == 1 and len(set(ran)) == 1

    # Two at once (two ports): a second thread, kept for later.
    release = threading.Event()
    done = threading.Event()
    threads.run(lambda outcome: release.wait(5.0), NORMAL_SCHEDULING, done)
    _run(threads, note)
    release.set()
    assert done.wait(5.0)
    assert threads.started == 2
    for _ in range(10):
        _run(threads, note)
    assert threads.started == 2 and len(set(ran)) == 2

    # A thread keeps the scheduling it was given: another policy, another thread.
    outcomes: list[PolicyOutcome] = []
    for _ in range(3):
        _run(threads, outcomes.append, ThreadPolicy(realtime_priority=1))
    assert threads.started == 3
    assert len(set(outcomes)) == 1 and (outcomes[0].applied or outcomes[0].refused)


def test_a_reading_that_raises_is_reported_and_the_thread_reads_on() -> None:
    threads = ReaderThreads('test-reader')
    reported: list[threading.ExceptHookArgs] = []
    hook = threading.excepthook
    threading.excepthook = reported.append
    try:
        def fail(outcome: PolicyOutcome) -> None:
            raise RuntimeError('a bug in a reading')

        _run(threads, fail)
    finally:
        threading.excepthook = hook
    assert len(reported) == 1
    assert reported[0].exc_type is RuntimeError and reported[0].thread.name == 'test-reader'
    ran: list[bool] = []
    _run(threads, lambda outcome: ran.append(True))
    assert ran == [True] and threads.started == 1


def test_an_idle_thread_keeps_nothing_of_its_last_reading() -> None:
    """A reconnect's port, parser and links are freed when dropped, not by the next one."""
    threads = ReaderThreads('test-reader')

    class Reading:
        def __call__(self, outcome: PolicyOutcome) -> None:
            pass

    reading = Reading()
    gone = weakref.ref(reading)
    gc.disable()
    try:
        _run(threads, reading)
        del reading
        assert gone() is None
    finally:
        gc.enable()


def test_a_fault_capture_starts_no_thread(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    faults = FaultCapture(str(tmp_path), seconds=5.0, kept=3,
                          log=logging.getLogger('test_reader_threads'))
    for i in range(20):
        faults.on_bytes(b'\x75\x65' * 10, 1000.0 + i * 0.01)
    started: list[str] = []
    start = threading.Thread.start

    def counted(thread: threading.Thread) -> None:
        started.append(thread.name)
        start(thread)

    monkeypatch.setattr(threading.Thread, 'start', counted)
    path = faults.save('stall')
    assert started == []
    header, chunks = read_capture(path)
    assert header['cause'] == 'stall'
    assert b''.join(data for _, data in chunks) == b'\x75\x65' * 200
