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

"""Where the test data lives: one place, so every test finds it the same way."""

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REAL_RECORDS = 'gx2_real_0xcc_records.txt'


def real_records_path() -> Path:
    """
    Find the 1,900 real 0xCC records.

    The repository carries a copy; ``$I3DMGX2_FIXTURES`` or the project's
    shared folder beside the clone are looked at too. Missing data fails the
    test: a skipped test would pass for nothing.
    """
    candidates = []
    if os.environ.get('I3DMGX2_FIXTURES'):
        candidates.append(Path(os.environ['I3DMGX2_FIXTURES']) / REAL_RECORDS)
    candidates += [REPO / 'test' / 'fixtures' / REAL_RECORDS,
                   REPO.parent / 'shared' / 'fixtures' / REAL_RECORDS]
    for path in candidates:
        if path.is_file():
            return path
    pytest.fail(f'{REAL_RECORDS} not found; looked in: ' + ', '.join(map(str, candidates)))
