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
What the suite's own run relies on: a ROS domain per worker, and SIGHUP's default for children.

Workers that shared a domain would receive each other's ``/imu/raw_data``;
a hang-up test run under ``nohup`` would test ``nohup`` instead of the
driver (test/conftest.py, harness/processes.py, docs/testing.md).
"""

import os
import subprocess
import sys

from conftest import DOMAIN_BASE_ENV
from harness.processes import DEFAULT_HANGUP, TEST_DOMAINS
import pytest


def test_this_worker_has_the_runs_base_plus_its_index_as_its_domain(worker_id):
    index = 0 if worker_id == 'master' else int(worker_id.removeprefix('gw'))
    domain = int(os.environ['ROS_DOMAIN_ID'])
    assert domain == int(os.environ[DOMAIN_BASE_ENV]) + index
    assert str(domain) == os.environ['I3DMGX2_TEST_DOMAIN']
    assert TEST_DOMAINS[0] <= domain <= TEST_DOMAINS[1]
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'


#: Run by a parent that ignores SIGHUP (as ``nohup`` leaves it): exits with the code of
#: a child started with the arguments as its prefix that reports whether SIGHUP has its default.
UNDER_NOHUP = """
import signal, subprocess, sys
signal.signal(signal.SIGHUP, signal.SIG_IGN)
child = ('import signal, sys; '
         'sys.exit(0 if signal.getsignal(signal.SIGHUP) == signal.SIG_DFL else 7)')
sys.exit(subprocess.run([*sys.argv[1:], sys.executable, '-c', child]).returncode)
"""


@pytest.mark.slow
def test_a_hangup_tests_child_meets_sighups_default_even_under_nohup():
    with_prefix = subprocess.run([sys.executable, '-c', UNDER_NOHUP, *DEFAULT_HANGUP])
    without = subprocess.run([sys.executable, '-c', UNDER_NOHUP])
    assert with_prefix.returncode == 0
    assert without.returncode == 7  # what the prefix is for: an ignored signal is inherited
