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

"""Fixtures shared by the test modules."""

from fixture_files import real_records_path
import pytest


@pytest.fixture(scope='session')
def fixture_path():
    """Return the path of the real-records fixture."""
    return real_records_path()


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
