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
Copyright and license notices, as ament_copyright checks them.

ament_copyright is not on PyPI: where it cannot be imported, an equivalent check of our own
runs instead (never a skip). It requires of every .py file outside the generated directories,
after an optional shebang or coding line and blank lines, a comment block whose first line is
'# Copyright <year> <holder>' and whose next lines are the Apache-2.0 header of
scripts/license_header.txt; an empty file passes, as it does for ament_copyright. LICENSE must
hold the Apache License 2.0 and CONTRIBUTING.md the Apache-2.0 contribution clause.
"""

import os
from pathlib import Path
import re

import pytest

try:
    from ament_copyright.main import main as ament_copyright_main
except ImportError:
    ament_copyright_main = None

REPO_ROOT = Path(__file__).resolve().parents[1]
# The repository root is also the colcon workspace: leave out what colcon makes there.
GENERATED_DIRS = ('build', 'install', 'log')

APACHE2_FILE_HEADER = """\
Licensed under the Apache License, Version 2.0 (the "License");
you may not use this file except in compliance with the License.
You may obtain a copy of the License at

    http://www.apache.org/licenses/LICENSE-2.0

Unless required by applicable law or agreed to in writing, software
distributed under the License is distributed on an "AS IS" BASIS,
WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
See the License for the specific language governing permissions and
limitations under the License.
"""

APACHE2_CONTRIBUTING = """\
Any contribution that you make to this repository will
be under the Apache 2 License, as dictated by that
[license](http://www.apache.org/licenses/LICENSE-2.0.html):

~~~
5. Submission of Contributions. Unless You explicitly state otherwise,
   any Contribution intentionally submitted for inclusion in the Work
   by You to the Licensor shall be under the terms and conditions of
   this License, without any additional terms or conditions.
   Notwithstanding the above, nothing herein shall supersede or modify
   the terms of any separate license agreement you may have executed
   with Licensor regarding such Contributions.
~~~
"""

# Parts of the Apache License 2.0 text, in order, as LICENSE must hold them.
APACHE2_LICENSE_PARTS = (
    'Apache License Version 2.0, January 2004 http://www.apache.org/licenses/',
    'TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION',
    '5. Submission of Contributions.',
    '9. Accepting Warranty or Additional Liability.',
    'END OF TERMS AND CONDITIONS',
)

# The same as ament_copyright's: 'copyright', optional '(c)', years or year ranges, holder.
_YEARS = r'\d{4}(?:-\d{4})?(?:,\s*\d{4}(?:-\d{4})?)*'
COPYRIGHT_LINE = re.compile(rf'^Copyright(?:\s+\(c\))?\s+({_YEARS}),?\s+(\S.*)$',
                            re.IGNORECASE)


def _normalize(text):
    return ' '.join(text.split())


def source_files(root):
    """Yield the .py files under root, as ament_copyright finds them, less generated dirs."""
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(
            d for d in dirnames
            if d[0] not in '._' and
            not (Path(dirpath) == Path(root) and d in GENERATED_DIRS))
        for filename in sorted(filenames):
            if filename.endswith('.py'):
                yield Path(dirpath, filename)


def check_source_header(content):
    """Return what is wrong with the copyright and license header of a .py file, or None."""
    if not content:
        return None
    lines = content.splitlines()
    index = 0
    while index < len(lines) and (
            lines[index].startswith('#!') or
            (lines[index].startswith('#') and re.search(r'coding[:=]', lines[index]))):
        index += 1
    while index < len(lines) and not lines[index].strip():
        index += 1
    block = []
    while index < len(lines) and lines[index].startswith('#'):
        block.append(lines[index][2:] if lines[index].startswith('# ') else lines[index][1:])
        index += 1
    if not block or not COPYRIGHT_LINE.match(block[0].strip()):
        return 'could not find copyright notice: the first comment must be ' \
            "'# Copyright <year> <holder>' (see scripts/license_header.txt)"
    if not _normalize('\n'.join(block[1:])).startswith(_normalize(APACHE2_FILE_HEADER)):
        return 'the copyright line is not followed by the Apache-2.0 license header ' \
            '(see scripts/license_header.txt)'
    return None


def check_repository(root):
    """Return a list of 'path: problem' for the sources, LICENSE and CONTRIBUTING.md."""
    errors = []
    for path in source_files(root):
        problem = check_source_header(path.read_text(encoding='utf-8'))
        if problem:
            errors.append(f'{path.relative_to(root)}: {problem}')
    license_path = Path(root, 'LICENSE')
    if not license_path.is_file():
        errors.append('LICENSE: file not found')
    else:
        text = _normalize(license_path.read_text(encoding='utf-8'))
        position = 0
        for part in APACHE2_LICENSE_PARTS:
            position = text.find(part, position)
            if position == -1:
                errors.append(f'LICENSE: not the Apache License 2.0 (no {part!r})')
                break
    contributing_path = Path(root, 'CONTRIBUTING.md')
    if not contributing_path.is_file():
        errors.append('CONTRIBUTING.md: file not found')
    elif _normalize(APACHE2_CONTRIBUTING) not in _normalize(
            contributing_path.read_text(encoding='utf-8')):
        errors.append('CONTRIBUTING.md: does not hold the Apache-2.0 contribution clause')
    return errors


@pytest.mark.copyright
@pytest.mark.linter
def test_copyright(monkeypatch):
    monkeypatch.chdir(REPO_ROOT)
    if ament_copyright_main is not None:
        # ament_copyright cannot exclude directories: name what it should check instead.
        paths = sorted(
            {'LICENSE', 'CONTRIBUTING.md'} |
            {name for name in os.listdir('.')
             if name[0] not in '._' and name not in GENERATED_DIRS})
        rc = ament_copyright_main(argv=paths)
        assert rc == 0, 'Found errors'
    else:
        errors = check_repository(REPO_ROOT)
        assert not errors, 'Found errors:\n' + '\n'.join(errors)


def test_license_header_template_passes():
    template = (REPO_ROOT / 'scripts' / 'license_header.txt').read_text(encoding='utf-8')
    assert check_source_header(template + '\n"""A module."""\n') is None
    assert check_source_header('#!/usr/bin/env python3\n\n' + template) is None


@pytest.mark.parametrize('content', [
    '"""No header."""\n',
    '# A comment.\n"""No header."""\n',
    '# Copyright The i3dmgx2_driver Authors\n#\n# Licensed under the MIT License.\n',
    '# Copyright 2026 The i3dmgx2_driver Authors\n\n"""License header missing."""\n',
    '# Copyright 2026 The i3dmgx2_driver Authors\n#\n# Licensed under the MIT License.\n',
])
def test_copyright_check_finds_bad_headers(content):
    assert check_source_header(content) is not None


def test_copyright_check_of_a_repository(tmp_path):
    template = (REPO_ROOT / 'scripts' / 'license_header.txt').read_text(encoding='utf-8')
    for name in ('LICENSE', 'CONTRIBUTING.md'):
        (tmp_path / name).write_text((REPO_ROOT / name).read_text(encoding='utf-8'))
    (tmp_path / 'pkg').mkdir()
    (tmp_path / 'pkg' / '__init__.py').write_text('')
    (tmp_path / 'pkg' / 'good.py').write_text(template)
    (tmp_path / 'build').mkdir()
    (tmp_path / 'build' / 'generated.py').write_text('x = 1\n')
    assert check_repository(tmp_path) == []

    (tmp_path / 'pkg' / 'bad.py').write_text('x = 1\n')
    (tmp_path / 'CONTRIBUTING.md').write_text('Contributions welcome.\n')
    (tmp_path / 'LICENSE').unlink()
    errors = check_repository(tmp_path)
    assert len(errors) == 3, errors
    assert errors[0].startswith(os.path.join('pkg', 'bad.py') + ':')
