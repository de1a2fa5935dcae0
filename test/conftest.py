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

"""Fixtures shared by the test modules, and each test worker's own ROS domain."""

import os
import random
import subprocess
import sys

from fixture_files import real_records_path
import pytest

#: Where the domains of one run start: drawn once by the first process (the controller of a
#: parallel run), inherited by its workers, so that workers never share a domain.
DOMAIN_BASE_ENV = 'I3DMGX2_TEST_DOMAIN_BASE'
#: Workers of one run at the most (pytest-xdist's ``-n``); each takes base + its index.
MOST_WORKERS = 16


def pytest_configure(config):
    """
    Give this process (a test worker, or the only one) a ROS domain no other worker has.

    The node tests subscribe to what the nodes they start publish; two workers
    in one domain would see each other's ``/imu/raw_data``. harness/processes.py
    uses ``$I3DMGX2_TEST_DOMAIN`` when a test isolates itself; it is set here
    to the run's base plus the worker's index (gw3 -> base + 3), and put to
    use at once: a test that starts a node without asking is isolated too.
    """
    from harness.processes import isolate_ros_domain, TEST_DOMAINS
    first, last = TEST_DOMAINS
    if DOMAIN_BASE_ENV not in os.environ:
        os.environ[DOMAIN_BASE_ENV] = str(random.SystemRandom().randint(
            first, last - MOST_WORKERS + 1))
    worker = getattr(config, 'workerinput', {}).get('workerid', 'gw0')
    index = int(worker.removeprefix('gw'))
    if index >= MOST_WORKERS:
        raise pytest.UsageError(f'at most {MOST_WORKERS} test workers (-n), not {index + 1}')
    os.environ['I3DMGX2_TEST_DOMAIN'] = str(int(os.environ[DOMAIN_BASE_ENV]) + index)
    isolate_ros_domain()


@pytest.fixture(scope='session')
def fixture_path():
    """Return the path of the real-records fixture."""
    return real_records_path()


#: scripts/test.sh runs the suite in two phases: ``parallel`` (all but the tests marked
#: ``alone``, on several workers), then ``alone`` (those, in one process); unset: everything.
PHASE_ENV = 'I3DMGX2_TEST_PHASE'
#: Set on a ``colcon test`` run given no ``-n``: its ``alone`` phase comes after the other.
_ALONE_AFTER = pytest.StashKey[bool]()


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """
    Under ``colcon test``, run the two phases of scripts/test.sh (docs/testing.md).

    colcon starts one pytest, in the source folder, with what it installed on
    the paths; in one process the suite takes 18 minutes. Unless the command
    line chose its workers (``--pytest-args -n 0``) or coverage, this process runs the
    ``parallel`` phase on pytest-xdist's workers as scripts/test.sh does (three
    per core, ``--dist loadfile``), and :func:`pytest_sessionfinish` the
    ``alone`` tests afterwards, in one process.
    """
    from harness.processes import run_by_colcon
    # pytest-cov chose its one-process set-up before this hook (--pytest-with-coverage).
    if (not run_by_colcon() or PHASE_ENV in os.environ
            or getattr(config.option, 'numprocesses', 0) is not None
            or getattr(config.option, 'cov_source', None)):
        return
    config.option.numprocesses = min(3 * len(os.sched_getaffinity(0)), MOST_WORKERS)
    config.option.dist = 'loadfile'
    os.environ[PHASE_ENV] = 'parallel'  # the workers inherit it
    config.stash[_ALONE_AFTER] = True


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_sessionfinish(session, exitstatus):
    """
    After a ``colcon test`` run's parallel phase (and its summary), run the ``alone`` tests.

    In a pytest of their own, with colcon's options (``PYTEST_ADDOPTS``) and
    their JUnit file beside colcon's, which ``colcon test-result`` reads too.
    The exit status is scripts/test.sh's: the first phase's failure, else the
    second's; 5 (nothing ran) only when neither ran a test.
    """
    result = yield
    if not session.config.stash.get(_ALONE_AFTER, False):
        return result
    command = [sys.executable, '-m', 'pytest', '-n', '0', *session.config.invocation_params.args]
    xml = session.config.option.xmlpath
    if xml:
        command.append(f'--junit-xml={os.path.splitext(xml)[0]}-alone.xml')
    print('\n== the tests that run alone (marked alone), after the others', flush=True)
    alone = subprocess.run(command,
                           env=dict(os.environ, **{PHASE_ENV: 'alone'}),
                           cwd=session.config.invocation_params.dir).returncode
    first = int(session.exitstatus)
    if first not in (0, 5):
        session.exitstatus = first
    elif alone not in (0, 5):
        session.exitstatus = alone
    else:
        session.exitstatus = 5 if first == alone == 5 else 0
    return result


def pytest_collection_modifyitems(config, items):
    """
    Keep this phase's tests; run the long files first, then those with slow tests.

    pytest-xdist (``--dist loadfile``, scripts/test.sh) hands the files to the
    workers in this order; a long file handed out last keeps one worker busy
    while the others have finished (test_stamps_through_faults, three minutes
    on one worker, handed out in its alphabetical place, ended the parallel
    phase 50 s after the rest).
    """
    phase = os.environ.get(PHASE_ENV)
    if phase in ('parallel', 'alone'):
        wanted = phase == 'alone'
        deselected = [item for item in items
                      if (item.get_closest_marker('alone') is not None) != wanted]
        if deselected:
            config.hook.pytest_deselected(items=deselected)
            gone = set(deselected)
            items[:] = [item for item in items if item not in gone]
    slow_files = {item.path for item in items if item.get_closest_marker('slow') is not None}
    long_files = {item.path for item in items if item.get_closest_marker('long') is not None}
    items.sort(key=lambda item: (item.path not in long_files, item.path not in slow_files))


class StartsSomething(AssertionError):
    """A test not marked slow tried to start a process or a pseudo-terminal."""


@pytest.fixture(autouse=True)
def _quick_tests_start_nothing(request, monkeypatch):
    """
    Keep ``-m 'not slow'`` a quick loop: a test not marked slow starts nothing.

    No process (a node, a linter, a tool's command line) and no
    pseudo-terminal (a simulated sensor): those are what make a test take
    seconds and depend on the machine's load. A test that needs one is
    marked slow.
    """
    if request.node.get_closest_marker('slow') is not None:
        return
    import os
    import subprocess

    def refuse(what):
        def refused(*args, **kwargs):
            raise StartsSomething(f'{request.node.nodeid} starts {what} but is not marked '
                                  f'slow: mark it @pytest.mark.slow')
        return refused

    monkeypatch.setattr(subprocess.Popen, '__init__', refuse('a process'))
    monkeypatch.setattr(os, 'openpty', refuse('a pseudo-terminal'))
    monkeypatch.setattr(os, 'fork', refuse('a process'))
