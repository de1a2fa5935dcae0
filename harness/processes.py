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
The processes a run starts, and the rclpy ends that talk to them.

The node runs as the real executable (:class:`NodeProcess`: ``main``, the
managed node, an instrumented node, an installed ``node``, or the node of
another checkout for an A/B run), the simulated device in a process of its
own (:class:`SimProcess`, ``harness/sim_process.py``: its ground truth read
back when it stops), and a subscriber either in another process
(:class:`SubscriberProcess`, ``harness/subscriber.py``) or in this one
(:class:`Listener`, with :class:`LifecycleClient` for a managed node).

Every run gets its own ROS domain and stays on localhost
(:func:`isolate_ros_domain`), so it never sees another run's messages.
Nothing here mocks ROS: the node process publishes through Fast DDS and the
subscriber receives through it.
"""

from collections.abc import Sequence
import json
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, ClassVar, NamedTuple

from ament_index_python.packages import get_package_prefix, PackageNotFoundError
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: How ``NodeProcess`` starts the node from the source tree, as ``ros2 run`` does.
NODE_COMMAND = (sys.executable, '-m', 'i3dmgx2_driver.ros.main')
#: How ``NodeProcess`` starts the managed node from the source tree.
LIFECYCLE_COMMAND = (sys.executable, '-m', 'i3dmgx2_driver.ros.lifecycle_node')
#: How long a hung child has to write its stacks after SIGABRT before it is killed (s).
ABORT_GRACE = 3.0
#: Node address the simulator and the node agree on.
ADDRESS = 95


def installed_executables() -> Path:
    """
    Return the folder of the installed executables: where ``ros2 run`` finds them.

    The environment says which install that is: ``colcon test``, a sourced
    workspace and scripts/env.sh each put the package's prefix on
    ``AMENT_PREFIX_PATH``. Without one (pytest by hand in a checkout), the
    checkout's own ``install/``, which scripts/setup.sh builds.
    """
    try:
        prefix = get_package_prefix('i3dmgx2_driver')
    except (PackageNotFoundError, OSError):  # OSError: no AMENT_PREFIX_PATH at all
        prefix = os.path.join(REPO, 'install', 'i3dmgx2_driver')
    return Path(prefix) / 'lib' / 'i3dmgx2_driver'


def run_by_colcon() -> bool:
    """Whether ``colcon`` started this process (it sets ``COLCON=1`` for what it runs)."""
    return os.environ.get('COLCON') == '1'


def ros_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """Environment for a child process: this repo first on PYTHONPATH, same domain."""
    env = dict(os.environ)
    env['PYTHONPATH'] = REPO + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH') else '')
    env['PYTHONUNBUFFERED'] = '1'
    env['RCUTILS_COLORIZED_OUTPUT'] = '0'
    # A child that hangs is sent SIGABRT before it is killed: its threads' stacks go to its log.
    env['PYTHONFAULTHANDLER'] = '1'
    if extra:
        env.update(extra)
    return env


#: Prefix of a command that must meet SIGHUP as a terminal's process does, with its default
#: disposition whatever this process inherited: under ``nohup`` SIGHUP is ignored, an ignored
#: signal stays ignored across exec, and the driver rightly honours that (it outlives a closed
#: terminal), so a test of the hang-up would otherwise test ``nohup`` instead.
DEFAULT_HANGUP = ('env', '--default-signal=HUP')


#: The ROS domains the tests draw from, and the benchmarks' (never the same: a
#: benchmark's node left publishing on a machine must not reach a test run).
TEST_DOMAINS = (1, 100)
BENCHMARK_DOMAINS = (101, 200)


def reserve_ros_domain(domains: tuple[int, int]) -> str:
    """
    Pick this process's ROS domain in ``domains``, unless one was picked already.

    Kept in ``$I3DMGX2_TEST_DOMAIN``, so every child and every later call
    shares it; :func:`isolate_ros_domain` puts it to use.
    """
    domain = os.environ.get('I3DMGX2_TEST_DOMAIN')
    if domain is None:
        domain = str(random.SystemRandom().randint(*domains))
        os.environ['I3DMGX2_TEST_DOMAIN'] = domain
    return domain


def isolate_ros_domain(domains: tuple[int, int] = TEST_DOMAINS) -> int:
    """Use the reserved ROS domain (one in ``domains`` if none is), localhost only."""
    domain = reserve_ros_domain(domains)
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


def wait_done(future: Any, timeout: float) -> bool:
    """Wait up to ``timeout`` s for a future its node's executor completes; say if it did."""
    deadline = time.monotonic() + timeout
    while not future.done() and time.monotonic() < deadline:
        time.sleep(0.01)
    return future.done()


def process_cpu_seconds(pid: int) -> float:
    """User plus system CPU time (s) of a process and all its threads so far."""
    with open(f'/proc/{pid}/stat') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    # After the command name: state is field 3, utime 14 and stime 15 (1-based).
    utime, stime = int(fields[11]), int(fields[12])
    return (utime + stime) / os.sysconf('SC_CLK_TCK')


#: The lines of /proc/PID/task/TID/status that count a thread's context switches.
_SWITCHES = ('voluntary_ctxt_switches:', 'nonvoluntary_ctxt_switches:')


def thread_switches(pid: int) -> dict[int, tuple[str, int]]:
    """
    Each thread of a process: its id → (name, context switches so far).

    Voluntary plus involuntary switches (``/proc/PID/task/TID/status``): a
    thread that blocks until it has work switches once per wake, so their rate
    is how often it wakes. Threads that end while being read are left out.
    """
    threads = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm') as handle:
                name = handle.read().strip()
            with open(f'/proc/{pid}/task/{tid}/status') as handle:
                switches = sum(int(line.split()[1]) for line in handle
                               if line.startswith(_SWITCHES))
        except (FileNotFoundError, ProcessLookupError):
            continue
        threads[int(tid)] = (name, switches)
    return threads


def wakes_per_second(before: dict[int, tuple[str, int]], after: dict[int, tuple[str, int]],
                     seconds: float) -> dict[str, float]:
    """Each thread's wakes per second between two :func:`thread_switches` (name#tid)."""
    return {f'{name}#{tid}': (switches - before[tid][1]) / seconds
            for tid, (name, switches) in after.items() if tid in before}


# -- the node --------------------------------------------------------------------------------

class NodeProcess:
    """
    The driver node in its own process, with its output in a file.

    ``command`` starts it (default :data:`NODE_COMMAND`); ``params`` become
    its ``--ros-args -p``, then ``extra_args`` follow. ``tree`` runs the
    node of another checkout (an A/B run): that tree first on PYTHONPATH,
    and its working directory.
    """

    def __init__(self, params: dict[str, object], extra_args: Sequence[str] = (),
                 command: Sequence[str] | None = None,
                 env: dict[str, str] | None = None, tree: Path | None = None) -> None:
        self.log_file = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed in close()
            prefix='i3dmgx2-node-', suffix='.log', delete=False)
        base = list(command) if command else list(NODE_COMMAND)
        self.argv = base + param_args(params) + list(extra_args)
        env = dict(env) if env else ros_env()
        if tree is not None:
            env['PYTHONPATH'] = os.pathsep.join((str(tree), env.get('PYTHONPATH', '')))
        self.proc = subprocess.Popen(
            self.argv, stdout=self.log_file, stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL, env=env, cwd=str(tree or REPO))

    def output(self) -> str:
        """Everything the node printed so far."""
        with open(self.log_file.name, errors='replace') as handle:
            return handle.read()

    def wait_for_output(self, text: str, timeout: float = 20.0) -> bool:
        """Wait until ``text`` appears in the node's output, or it ended; return whether it did."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.output():
                return True
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        return text in self.output()

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> tuple[int, float]:
        """Send ``sig`` (SIGINT: as Ctrl-C); return the exit code and how long the exit took."""
        start = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self._abort_with_stacks()
        return self.proc.returncode, time.monotonic() - start

    def _abort_with_stacks(self) -> None:
        """End a hung process so that its log says where each thread waited (faulthandler)."""
        self.proc.send_signal(signal.SIGABRT)
        try:
            self.proc.wait(ABORT_GRACE)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()

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


# -- helper processes that save JSON: the simulator, a subscriber ----------------------------

class ChildProcess:
    """A helper process that prints a line when ready and saves JSON when stopped."""

    #: The command-line option that names the JSON file the child writes.
    out_flag = '--out'

    def __init__(self, argv: list[str], ready_prefix: str, timeout: float = 20.0) -> None:
        handle, self.out_path = tempfile.mkstemp(prefix='i3dmgx2-bench-', suffix='.json')
        os.close(handle)
        self.name = argv[2] if argv[1] == '-m' else Path(argv[1]).name
        # Standard error goes to a file: a pipe nobody reads could fill and block the child.
        handle, self._stderr_path = tempfile.mkstemp(prefix='i3dmgx2-bench-', suffix='.err')
        try:
            self.proc = subprocess.Popen(
                [*argv, self.out_flag, self.out_path],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=handle,
                text=True, env=ros_env(), cwd=REPO)
        finally:
            os.close(handle)
        self.ready_line = self._wait_line(ready_prefix, timeout)
        self._lines: list[str] = []
        self._reader = threading.Thread(target=self._read_rest, daemon=True)
        self._reader.start()

    def _wait_line(self, prefix: str, timeout: float) -> str:
        timer = threading.Timer(timeout, self.proc.kill)
        timer.start()
        try:
            for line in self.proc.stdout:
                if line.startswith(prefix):
                    return line.strip()
        finally:
            timer.cancel()
        raise RuntimeError(f'{self.name} did not start: {self.errors()}')

    def errors(self) -> str:
        """Return what the process wrote to standard error so far."""
        with open(self._stderr_path, errors='replace') as handle:
            return handle.read()

    def _read_rest(self) -> None:
        for line in self.proc.stdout:
            self._lines.append(line.strip())

    def signal(self, signum: int) -> None:
        """Send a signal if the process still runs."""
        if self.proc.poll() is None:
            self.proc.send_signal(signum)

    def stop(self, timeout: float = 15.0) -> Any:
        """Stop the process; return the JSON it saved."""
        self.signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        try:
            with open(self.out_path) as handle:
                return json.load(handle)
        except (OSError, ValueError) as exc:
            raise RuntimeError(f'{self.name} saved nothing: {self.errors()}') from exc
        finally:
            os.unlink(self.out_path)
            os.unlink(self._stderr_path)


class TruthEntry(NamedTuple):
    """One data packet the simulator produced."""

    timer: int | None
    sample_time: float
    write_time: float | None
    valid: bool
    source: str


class SimProcess(ChildProcess):
    """The simulated device in its own process; ``truth`` after :meth:`stop`."""

    out_flag = '--truth'

    def __init__(self, **config: Any) -> None:
        config.setdefault('address', ADDRESS)
        config.setdefault('seed', 1)
        super().__init__([sys.executable, '-m', 'harness.sim_process',
                          '--config', json.dumps(config)], 'port: ')
        self.port = self.ready_line.split(': ', 1)[1]
        self.truth: list[TruthEntry] = []
        self.stats: dict[str, int] = {}

    def silence(self, timeout: float = 5.0) -> None:
        """Stop the sensor's packets for good (the radio goes silent)."""
        self.signal(signal.SIGUSR1)
        deadline = time.monotonic() + timeout
        while 'silent' not in self._lines and time.monotonic() < deadline:
            time.sleep(0.01)

    def stop(self, timeout: float = 15.0) -> dict:
        """Stop the simulator; fill ``truth`` and ``stats``."""
        document = super().stop(timeout)
        self.truth = [TruthEntry(*row) for row in document['truth']]
        self.stats = document['stats']
        return document

    def written_stream(self) -> list[TruthEntry]:
        """Return the valid streamed packets that were written whole."""
        return [e for e in self.truth
                if e.source == 'stream' and e.valid and e.write_time is not None]


class SubscriberProcess(ChildProcess):
    """
    A subscriber to ``imu/raw_data`` (or ``topics``) in its own process.

    ``values``: each row also holds the topic, frame_id and angular velocity.
    """

    def __init__(self, values: bool = False, topics: Sequence[str] = ()) -> None:
        argv = [sys.executable, '-m', 'harness.subscriber']
        for name in topics:
            argv += ['--topic', name]
        super().__init__(argv + (['--values'] if values else []), 'ready')
        self.rows: list[tuple[int, int, float]] = []

    def stop(self, timeout: float = 15.0) -> list:
        """Stop; return and keep the rows (stamp sec, stamp nanosec, receive time)."""
        self.rows = [tuple(row) for row in super().stop(timeout)]
        return self.rows


# -- subscribers and clients in this process -------------------------------------------------

class Listener:
    """
    An rclpy node in the test process that records what it receives.

    ``domain``: the ROS domain, if not this process's (several nodes side by side).
    """

    def __init__(self, topics: dict[str, type], reliable: bool = True, depth: int = 1000,
                 domain: int | None = None) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('i3dmgx2_test_listener', context=self.context)
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

    def call(self, kind: type, name: str, timeout: float = 30.0) -> object:
        """Call service ``name`` (of type ``kind``, an empty request); return the response."""
        client = self.node.create_client(kind, name)
        try:
            assert client.wait_for_service(timeout_sec=timeout), f'no service {name}'
            future = client.call_async(kind.Request())
            assert wait_done(future, timeout), f'{name} did not answer in {timeout} s'
            return future.result()
        finally:
            self.node.destroy_client(client)

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

    def __init__(self, listener: Listener, node: str = '/i3dmgx2_driver') -> None:
        self._change = listener.node.create_client(ChangeState, f'{node}/change_state')
        self._get = listener.node.create_client(GetState, f'{node}/get_state')

    def wait_ready(self, timeout: float = 30.0) -> bool:
        """
        Wait until both services are there and have answered once.

        A service found is not yet a service that can answer: the server
        drops a response when it has not matched this client's response
        reader within 100 ms (rmw_fastrtps, ros2/rmw_fastrtps#390, #467),
        which a loaded machine makes likely for the first request. So each
        service is asked something harmless (the state; a transition that
        does not exist, which rcl_lifecycle answers with a failure and one
        warning in the node's log) until it answers, before any real request.
        """
        deadline = time.monotonic() + timeout
        if not (self._change.wait_for_service(timeout_sec=timeout)
                and self._get.wait_for_service(timeout_sec=timeout)):
            return False
        probes = ((self._get, GetState.Request()),
                  (self._change, ChangeState.Request(
                      transition=Transition(label='no_such_transition'))))
        for client, request in probes:
            while True:
                future = client.call_async(request)
                if wait_done(future, min(deadline - time.monotonic(), 2.0)):
                    break
                client.remove_pending_request(future)
                if time.monotonic() >= deadline:
                    return False
        return True

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
        if not wait_done(future, timeout):
            print(f'no answer to {transition!r} within {timeout} s')
            return False
        return future.result().success

    def state(self, timeout: float = 10.0) -> str:
        """Return the label of the node's current state."""
        future = self._get.call_async(GetState.Request())
        assert wait_done(future, timeout), f'no answer within {timeout} s'
        return future.result().current_state.label
