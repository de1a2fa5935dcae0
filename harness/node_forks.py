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
Node processes by the thousand: a fork server that starts each in milliseconds.

A shutdown stress run starts the node thousands of times, and a fresh
interpreter spends most of a start importing rclpy and the driver.
:class:`ForkServer` runs ``python -m harness.node_forks``, which imports the
plain and the managed node's entry points once and then, for each request,
forks a child that runs the executable's own ``main()`` as its console script
does: its arguments in ``sys.argv``, its environment (its own ROS domain), its
output in a file, and the process's normal way out (the interpreter's exit
with its thread joins and atexit hooks). The server has no thread when it
forks. It reports each child's pid and, when the child ends (a pidfd), its
exit code and the monotonic time of its end.

What differs from the installed executable: the interpreter's start and the
imports, done once before the fork, and the process's parent (the server: its
end ends the children, ``lifetime.die_with_parent``). The end of its standard
input ends the server, which kills what it started.
"""

from collections.abc import Callable
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

#: The executables a child can run, by their console-script names.
KINDS = ('node', 'lifecycle_node')
#: How long a hung child has to write its stacks after SIGABRT before it is killed (s).
ABORT_GRACE = 3.0


# -- the server (its own process) -------------------------------------------------------------

def _send(message: dict) -> None:
    os.write(1, (json.dumps(message) + '\n').encode())


def _child(request: dict, entries: dict[str, Callable[[], int]], inherited: list[int]) -> None:
    """Become the requested executable: never returns (SystemExit, the process's own exit)."""
    for fd in inherited:  # the server's watches on its other children
        os.close(fd)
    log = os.open(request['log'], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    os.environ.update(request['env'])
    sys.argv = [request['kind'], *request['argv']]
    sys.exit(entries[request['kind']]())


def serve() -> int:
    """Fork a child for every request line on standard input, until it ends."""
    # As from a terminal, from the fork on: SIGINT not ignored (a script's background job, as
    # the run that started this server may be, starts with it ignored, and a child would
    # lose a SIGINT that comes before the node's handlers exist).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from i3dmgx2_driver.ros import lifecycle_node, main as node_main
    entries = {'node': node_main.main, 'lifecycle_node': lifecycle_node.main}
    # No Python thread may run when it forks. The C libraries' own (lttng-ust's two
    # listeners, blocked in a futex) are not copied into a child, and hold nothing it needs.
    if threading.active_count() != 1:
        print(f'node_forks: {threading.active_count()} Python threads after the imports: '
              f'cannot fork safely', file=sys.stderr)
        return 1
    children: dict[int, tuple[Any, int]] = {}  # pidfd -> (request id, pid)
    pending = b''
    _send({'ready': True})
    while True:
        ready, _, _ = select.select([0, *children], [], [])
        for fd in ready:
            if fd != 0:
                ident, pid = children.pop(fd)
                os.close(fd)
                _, status = os.waitpid(pid, 0)
                _send({'id': ident, 'code': os.waitstatus_to_exitcode(status),
                       'ended': time.monotonic()})
                continue
            chunk = os.read(0, 65536)
            if not chunk:
                for _, pid in children.values():
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
                return 0
            pending += chunk
            while b'\n' in pending:
                line, pending = pending.split(b'\n', 1)
                request = json.loads(line)
                pid = os.fork()
                if pid == 0:
                    _child(request, entries, list(children))
                children[os.pidfd_open(pid)] = (request['id'], pid)
                _send({'id': request['id'], 'pid': pid})


# -- the client (the benchmark's or the test's process) ---------------------------------------

class ForkedNode:
    """One node the server forked: its pid, its log, its end."""

    def __init__(self, ident: int, log: str) -> None:
        self.ident = ident
        self.log = log
        self.pid: int | None = None
        #: The exit code (negative: the signal that ended it) and when, once it ended.
        self.code: int | None = None
        self.ended: float | None = None
        self._have_pid = threading.Event()
        self._done = threading.Event()

    def output(self) -> str:
        """Everything the node wrote so far."""
        try:
            with open(self.log, errors='replace') as handle:
                return handle.read()
        except OSError:
            return ''

    def wait_for_output(self, text: str, timeout: float) -> bool:
        """Wait until ``text`` is in the log (False if the node ended first or time is up)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.output():
                return True
            if self._done.is_set():
                break
            time.sleep(0.01)
        return text in self.output()

    def signal(self, signum: int) -> None:
        """Send ``signum`` if the node still runs."""
        self._have_pid.wait(10.0)
        if not self._done.is_set() and self.pid is not None:
            try:
                os.kill(self.pid, signum)
            except ProcessLookupError:
                pass

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the node to end; return whether it has."""
        return self._done.wait(timeout)

    def end(self, timeout: float) -> tuple[bool, bool]:
        """
        Wait ``timeout`` s for the end; a node still running is hung: SIGABRT, then SIGKILL.

        Returns (hung, killed): SIGABRT has the fault handler write every
        thread's stack to the log; killed means even that did not end it.
        """
        if self.wait(timeout):
            return False, False
        self.signal(signal.SIGABRT)
        if self.wait(ABORT_GRACE):
            return True, False
        self.signal(signal.SIGKILL)
        self.wait(5.0)
        return True, True

    def close(self) -> None:
        """Remove the log."""
        try:
            os.unlink(self.log)
        except OSError:
            pass


class ForkServer:
    """The fork server in its own process, and the nodes it started."""

    def __init__(self) -> None:
        # Not at the top: the server itself imports only this module and the driver.
        from harness.processes import REPO, ros_env
        env = ros_env({'OPENBLAS_NUM_THREADS': '1'})
        self.proc = subprocess.Popen(
            [sys.executable, '-m', 'harness.node_forks'], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, env=env, cwd=REPO)
        line = self.proc.stdout.readline()
        if not line or not json.loads(line).get('ready'):
            raise RuntimeError('the fork server did not start')
        self._lock = threading.Lock()
        self._nodes: dict[int, ForkedNode] = {}
        self._next = 0
        self._reader = threading.Thread(target=self._read, name='fork-server-reader',
                                        daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            message = json.loads(line)
            with self._lock:
                node = self._nodes.get(message['id'])
            if node is None:
                continue
            if 'pid' in message:
                node.pid = message['pid']
                node._have_pid.set()
            else:
                node.code, node.ended = message['code'], message['ended']
                node._done.set()
                with self._lock:
                    self._nodes.pop(node.ident, None)

    def start(self, kind: str, argv: list[str], env: dict[str, str]) -> ForkedNode:
        """Fork ``kind`` (a name of :data:`KINDS`) with ``argv`` in ``env``; return it."""
        handle, log = tempfile.mkstemp(prefix='i3dmgx2-fork-', suffix='.log')
        os.close(handle)
        with self._lock:
            self._next += 1
            node = ForkedNode(self._next, log)
            self._nodes[node.ident] = node
            request = {'id': node.ident, 'kind': kind, 'argv': argv, 'env': env, 'log': log}
            self.proc.stdin.write((json.dumps(request) + '\n').encode())
            self.proc.stdin.flush()
        if not node._have_pid.wait(10.0):
            raise RuntimeError('the fork server did not fork')
        return node

    def close(self) -> None:
        """End the server (and whatever it still runs)."""
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(10.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


if __name__ == '__main__':
    sys.exit(serve())
