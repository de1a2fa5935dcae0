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

import json
from pathlib import Path
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

REPO_ROOT = Path(__file__).resolve().parents[1]
# The repository root is also the colcon workspace: leave out what colcon makes there.
# (ament_flake8 already skips directories starting with '.' or '_', such as .venv.)
GENERATED_DIRS = ('build', 'install', 'log')


def _excludes():
    return ['--exclude'] + [str(REPO_ROOT / name) for name in GENERATED_DIRS]


def main_with_errors(argv: list[str]) -> tuple[int, list[str]]:
    """
    Run ament_flake8 in a fresh interpreter; return its exit code and errors.

    flake8 checks files in worker processes forked from the caller. Forked
    from the test process, they inherit whatever other tests left there (an
    in-process rclpy context, its threads, a frozen heap) and have crashed in
    their first garbage collection; a fresh interpreter has none of it.
    """
    code = ('import json, sys\n'
            'from ament_flake8.main import main_with_errors\n'
            'rc, errors = main_with_errors(argv=sys.argv[1:])\n'
            'print(json.dumps([rc, errors]))\n')
    result = subprocess.run([sys.executable, '-c', code, *argv], capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    rc, errors = json.loads(result.stdout.strip().splitlines()[-1])
    return rc, errors


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8(monkeypatch):
    monkeypatch.chdir(REPO_ROOT)
    rc, errors = main_with_errors(argv=_excludes())
    assert rc == 0, \
        f'Found {len(errors)} code style errors / warnings:\n' + \
        '\n'.join(errors)


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8_plugins_are_active(tmp_path, monkeypatch):
    """ament_flake8 reports what each plugin of its configuration checks."""
    (tmp_path / 'bad.py').write_text(
        '"""Break one rule of each flake8 plugin that ament_flake8 uses."""\n'
        '\n'
        'import sys\n'
        'import os\n'
        '\n'
        'list = list(x for x in os.sep)\n'
        'name = "double quotes"\n'
        '\n'
        '\n'
        'def f():\n'
        '    """no capital, no period"""\n'
        '    return sys.path\n')
    monkeypatch.chdir(tmp_path)
    rc, errors = main_with_errors(argv=[])
    codes = {error.split(' ')[1] for error in errors}
    assert rc == 1
    expected = {
        'I100': 'flake8-import-order',
        'A001': 'flake8-builtins',
        'C400': 'flake8-comprehensions',
        'Q000': 'flake8-quotes',
        'D403': 'flake8-docstrings',
    }
    missing = {code: plugin for code, plugin in expected.items() if code not in codes}
    assert not missing, f'flake8 plugins not active: {missing} (got {sorted(codes)})'
