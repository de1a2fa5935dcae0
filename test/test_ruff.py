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
Ruff, the project's Python linter besides ament_flake8, finds nothing (ruff.toml).

Ruff comes from requirements-dev.txt (scripts/setup.sh installs it into the
venv), not from package.xml: rosdep has no key for it. Built on a system
without it (colcon test in a ROS workspace), the test is skipped with a
message saying how to get it; in CI (``CI`` set, as every CI service and
``.ci/run`` do) a missing ruff is a failure, so that no skip hides a CI run.
"""

import os
import shutil
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def find_ruff() -> str | None:
    """Return the ruff next to this Python (the venv's), else the one on PATH, else None."""
    beside = os.path.join(os.path.dirname(sys.executable), 'ruff')
    return beside if os.path.exists(beside) else shutil.which('ruff')


@pytest.mark.linter
def test_ruff():
    ruff = find_ruff()
    if ruff is None:
        assert not os.environ.get('CI'), \
            'ruff is missing in CI: it is part of requirements-dev.txt'
        pytest.skip('ruff is not installed: pip install -r requirements-dev.txt '
                    '(or pip install ruff) to run this linter')
    result = subprocess.run([ruff, 'check', '--no-cache', '--output-format', 'concise', '.'],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def test_a_missing_ruff_skips_with_a_message_but_fails_in_ci(monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], 'find_ruff', lambda: None)
    monkeypatch.delenv('CI', raising=False)
    with pytest.raises(pytest.skip.Exception, match=r'pip install -r requirements-dev\.txt'):
        test_ruff()
    monkeypatch.setenv('CI', 'true')
    with pytest.raises(AssertionError, match='ruff is missing in CI'):
        test_ruff()
