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

from pathlib import Path

from ament_pep257.main import main
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
# The repository root is also the colcon workspace: leave out what colcon makes there.
# (pydocstyle already skips directories starting with '.' or '_', such as .venv.)
GENERATED_DIRS = ('build', 'install', 'log')


@pytest.mark.slow  # seconds over the whole tree: the full suite's, as flake8 is
@pytest.mark.linter
@pytest.mark.pep257
def test_pep257(monkeypatch):
    monkeypatch.chdir(REPO_ROOT)
    rc = main(argv=['.', 'test', '--exclude', *GENERATED_DIRS])
    assert rc == 0, 'Found code style errors / warnings'


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257_reports_errors(tmp_path, monkeypatch):
    (tmp_path / 'bad.py').write_text('def f():\n    """no capital, no period"""\n')
    monkeypatch.chdir(tmp_path)
    assert main(argv=['.']) == 1
