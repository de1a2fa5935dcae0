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
Test harness for the node: run it as a real process, subscribe with rclpy.

Every test session gets its own ROS domain and stays on localhost, so tests
never see another run's messages. Nothing here mocks ROS: the node process
publishes through Fast DDS and the test process subscribes through it.
"""

from collections.abc import Callable, Sequence
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import ClassVar

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: How ``NodeProcess`` starts the managed node from the source tree.
LIFECYCLE_COMMAND = (sys.executable, '-m', 'i3dmgx2_driver.ros.lifecycle_node')


def ros_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """Environment for a node process: this repo on PYTHONPATH, same domain."""
    env = dict(os.environ)
    env['PYTHONPATH'] = REPO + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH') else '')
    env['PYTHONUNBUFFERED'] = '1'
    env['RCUTILS_COLORIZED_OUTPUT'] = '0'
    if extra:
        env.update(extra)
    return env


def isolate_ros_domain() -> int:
    """Pick a random ROS domain for this process and its children, localhost only."""
    domain = os.environ.get('I3DMGX2_TEST_DOMAIN')
    if domain is None:
        domain = str(random.SystemRandom().randint(1, 100))
        os.environ['I3DMGX2_TEST_DOMAIN'] = domain
    os.environ['ROS_DOMAIN_ID'] = domain
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return int(domain)


def param_args(params: dict[str, object]) -> list[str]:
    """Turn a dict into ``--ros-args -p name:=value`` arguments."""
    args = ['--ros-args']
    for name, value in params.items():
        if isinstance(value, bool):
            text = 'true' if value else 'false'
        else:
            text = str(value)
        args += ['-p', f'{name}:={text}']
    return args


def wait_for_text(output: Callable[[], str], proc: subprocess.Popen, text: str,
                  timeout: float) -> bool:
    """Wait until ``text`` is in ``output()``, or ``proc`` ended; return whether it is."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in output():
            return True
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    return text in output()


class NodeProcess:
    """The driver node in its own process, with its output in a file."""

    def __init__(self, params: dict[str, object], extra_args: Sequence[str] = (),
                 command: Sequence[str] | None = None,
                 env: dict[str, str] | None = None) -> None:
        self.log_file = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed in close()
            prefix='i3dmgx2-node-', suffix='.log', delete=False)
        base = list(command) if command else [sys.executable, '-m', 'i3dmgx2_driver.ros.main']
        self.argv = base + param_args(params) + list(extra_args)
        self.proc = subprocess.Popen(
            self.argv, stdout=self.log_file, stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL, env=env or ros_env(), cwd=REPO)

    def output(self) -> str:
        """Everything the node printed so far."""
        with open(self.log_file.name, errors='replace') as handle:
            return handle.read()

    def wait_for_output(self, text: str, timeout: float = 20.0) -> bool:
        """Wait until ``text`` appears in the node's output."""
        return wait_for_text(self.output, self.proc, text, timeout)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> tuple[int, float]:
        """Send ``sig``; return the exit code and how long the exit took."""
        start = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode, time.monotonic() - start

    def wait(self, timeout: float = 20.0) -> int:
        """Wait for the process to end by itself; return its exit code."""
        return self.proc.wait(timeout)

    def __enter__(self) -> 'NodeProcess':
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Kill the process if it still runs and remove its log."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.log_file.close()
        try:
            os.unlink(self.log_file.name)
        except OSError:
            pass


class Listener:
    """An rclpy node in the test process that records what it receives."""

    def __init__(self, topics: dict[str, type], reliable: bool = True, depth: int = 1000,
                 namespace: str = '') -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('i3dmgx2_test_listener', namespace=namespace,
                                      context=self.context)
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=depth,
            reliability=ReliabilityPolicy.RELIABLE if reliable
            else ReliabilityPolicy.BEST_EFFORT)
        self.messages: dict[str, list[tuple[float, object]]] = {t: [] for t in topics}
        self._lock = threading.Lock()
        for topic, msg_type in topics.items():
            self.node.create_subscription(
                msg_type, topic, lambda msg, t=topic: self._store(t, msg), qos)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # noqa: B902 - the context is shut down under us at close()
            pass

    def _store(self, topic: str, msg: object) -> None:
        with self._lock:
            self.messages[topic].append((time.time(), msg))

    def received(self, topic: str) -> list[object]:
        """Return the messages of ``topic`` received so far."""
        with self._lock:
            return [m for _, m in self.messages[topic]]

    def wait_for(self, topic: str, count: int, timeout: float = 20.0) -> list[object]:
        """Wait until ``count`` messages of ``topic`` arrived; return them all."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            got = self.received(topic)
            if len(got) >= count:
                return got
            time.sleep(0.02)
        return self.received(topic)

    def clear(self) -> None:
        """Forget what was received."""
        with self._lock:
            for topic in self.messages:
                self.messages[topic].clear()

    def __enter__(self) -> 'Listener':
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop spinning and shut the context down."""
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=2.0)


def stamp_seconds(msg: object) -> float:
    """Return a message header's stamp in seconds."""
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


class LifecycleClient:
    """
    Drive a managed node through the standard lifecycle_msgs services.

    What a bringup manager or ``ros2 lifecycle set`` does: ``ChangeState``
    and ``GetState`` on ``<node>/change_state`` and ``<node>/get_state``,
    from the (spinning) node of a :class:`Listener`.
    """

    TRANSITIONS: ClassVar[dict[str, int]] = {
        'configure': Transition.TRANSITION_CONFIGURE,
        'cleanup': Transition.TRANSITION_CLEANUP,
        'activate': Transition.TRANSITION_ACTIVATE,
        'deactivate': Transition.TRANSITION_DEACTIVATE,
    }

    #: How long one get_state of :meth:`wait_ready` may take before another is sent.
    PROBE_S = 2.0

    def __init__(self, listener: Listener, node: str = '/i3dmgx2_driver') -> None:
        # change_state's client first: see wait_ready.
        self._change = listener.node.create_client(ChangeState, f'{node}/change_state')
        self._get = listener.node.create_client(GetState, f'{node}/get_state')

    def wait_ready(self, timeout: float = 30.0) -> bool:
        """
        Wait until both services are there and the node has answered a get_state.

        wait_for_service says only that this side has discovered the node's
        service. The node may not yet have discovered this client: a request
        it receives before is dropped for good (volatile), and an answer it
        cannot match in 100 ms is too (ros2/rmw_cyclonedds#74, ros2/rmw_fastrtps#390).
        That is how a loaded full run lost a configure: the node printed
        nothing in 30 s. A get_state answer shows that the node has matched
        this client's endpoints, change_state's included, which were
        announced before get_state's on the same ordered, reliable discovery
        channels. get_state changes nothing, so a probe the race swallowed
        is simply asked again; the transitions under test are asked once.
        """
        deadline = time.monotonic() + timeout
        if not (self._change.wait_for_service(timeout_sec=timeout)
                and self._get.wait_for_service(timeout_sec=timeout)):
            return False
        while time.monotonic() < deadline:
            future = self._get.call_async(GetState.Request())
            probe_end = min(deadline, time.monotonic() + self.PROBE_S)
            while not future.done() and time.monotonic() < probe_end:
                time.sleep(0.01)
            if future.done():
                return True
            self._get.remove_pending_request(future)
            print(f'get_state unanswered in {self.PROBE_S} s: asking again')
        return False

    @staticmethod
    def _result(future: object, timeout: float) -> object:
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert future.done(), f'no answer within {timeout} s'
        return future.result()

    def change_async(self, transition: str) -> object:
        """
        Request a transition by name; return the future of the response.

        'shutdown' goes by label: its id depends on the state it leaves.
        """
        request = ChangeState.Request()
        if transition in self.TRANSITIONS:
            request.transition.id = self.TRANSITIONS[transition]
        else:
            request.transition.label = transition
        return self._change.call_async(request)

    def change(self, transition: str, timeout: float = 30.0) -> bool:
        """
        Request a transition by name; return whether it succeeded.

        No answer is False too (and said on stdout), so that the caller's
        assertion shows the node's output: why it did not answer.
        """
        future = self.change_async(transition)
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        if not future.done():
            print(f'no answer to {transition!r} within {timeout} s')
            return False
        return future.result().success

    def state(self, timeout: float = 10.0) -> str:
        """Return the label of the node's current state."""
        return self._result(self._get.call_async(GetState.Request()),
                            timeout).current_state.label
