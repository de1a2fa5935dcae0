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
The documentation cannot drift from the code, nor point where nothing is.

The README's parameter table is what ``scripts/parameter_table.py`` prints
from the parameter table, and the shipped params file names every
parameter, with values that are valid defaults. The README opens with the
two commands a newcomer runs, says how to run the tests, and each row of its
headline table ("How fast, how true") links to the docs/ page that holds the
measurement, since the figures themselves live there. In README.md
and docs/*.md every relative link leads to a file that exists, every
``#anchor`` to a heading (GitHub's slugs), every repository path named in
code (``benchmarks/latency.py``, ``device/link.py``) to a file, and every
page of docs/ is linked from the README, so that moving a file or renaming
a heading fails here rather than in a reader's browser. The names that
docs/architecture.md's "Making a change" tells a maintainer to read and edit
(``DeviceLink.on_data``, ``ReopenWait``, a test's name) exist in the code, so
that the map is walked again whenever a name it gives is renamed.
"""

import glob
import os
import re
import runpy

from i3dmgx2_driver.ros.parameter_table import REQUIRED, SPECS
import pytest
import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(REPO, 'README.md')
#: The pages checked: the README and every Markdown file in docs/.
PAGES = [README, *sorted(glob.glob(os.path.join(REPO, 'docs', '*.md')))]

#: The README's first lines, exactly: the two commands a newcomer runs.
OPENING = '\n'.join((
    '# i3dmgx2_driver',
    '',
    '```bash',
    'bash scripts/demo.sh     # set up, then run the driver against the simulated sensor and '
    'show its data',
    'bash scripts/test.sh     # set up, then run every test (what CI runs)',
    '```',
    ''))


def test_readme_parameter_table_is_generated_from_the_code():
    generator = runpy.run_path(os.path.join(REPO, 'scripts', 'parameter_table.py'))
    with open(os.path.join(REPO, 'README.md')) as handle:
        readme = handle.read()
    assert generator['table']() in readme, \
        'README is stale: paste the output of scripts/parameter_table.py'


@pytest.fixture(scope='module')
def params_file():
    with open(os.path.join(REPO, 'config', 'i3dmgx2.yaml')) as handle:
        text = handle.read()
    return text, yaml.safe_load(text)['/**']['ros__parameters']


def test_params_file_names_every_parameter(params_file):
    text, values = params_file
    for spec in SPECS:
        if spec.default is REQUIRED or spec.replaced_by or spec.default == []:
            # Documented, deliberately left unset: there is no silent default, a
            # deprecated name set here would warn at every start, and an empty array
            # has no type a params file could give it.
            assert f'# {spec.name}:' in text
            assert spec.name not in values
        else:
            assert values[spec.name] == spec.default, spec.name
    assert set(values) <= {spec.name for spec in SPECS}


# -- links, anchors and paths ------------------------------------------------

_FENCE = re.compile(r'^\s*(```|~~~)')
_HEADING = re.compile(r'^(#{1,6})\s+(.*?)\s*#*\s*$')
_HTML_ANCHOR = re.compile(r'<a\s+(?:id|name)="([^"]+)"')
_CODE_SPAN = re.compile(r'`+[^`]*`+')
#: An inline link or image, ``[text](target)`` or ``![alt](target "title")``.
_LINK = re.compile(r'!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+"[^"]*")?\s*\)')
#: A path inside the repository, as the pages name files in code and commands.
_TOP = ('i3dmgx2_driver', 'benchmarks', 'harness', 'scripts', 'test', 'config', 'launch',
        'docs')
#: Module paths relative to the package, as the pages name them (``device/link.py``).
_PACKAGE = ('capture', 'codec', 'device', 'ros', 'simulator', 'tools')
_REPO_PATH = re.compile(
    r'(?<![\w./-])((?:' + '|'.join(_TOP + _PACKAGE) + r')/[\w./-]*\w'
    r'\.(?:py|sh|yaml|md|txt|png|xml|json|bin))\b')


def split_page(text: str) -> tuple[list[str], list[str]]:
    """Return the page's prose lines and the lines inside its fenced code blocks."""
    prose, code = [], []
    fence = None
    for line in text.splitlines():
        match = _FENCE.match(line)
        if fence is None and match:
            fence = match.group(1)
        elif fence is not None and line.strip().startswith(fence):
            fence = None
        elif fence is None:
            prose.append(line)
        else:
            code.append(line)
    return prose, code


def slug(heading: str) -> str:
    """Return the anchor GitHub gives a heading: lower case, punctuation gone, '-' for ' '."""
    text = re.sub(r'!?\[([^\]]*)\]\([^)]*\)', r'\1', heading)  # a link: its text
    text = text.replace('`', '').replace('*', '').strip().lower()
    return re.sub(r'[^\w\- ]', '', text).replace(' ', '-')


def anchors(text: str) -> set[str]:
    """Return every anchor of a page: its headings' slugs (-1, -2 for repeats), HTML ids."""
    found: set[str] = set()
    seen: dict[str, int] = {}
    prose, _ = split_page(text)
    for line in prose:
        match = _HEADING.match(line)
        if match:
            base = slug(match.group(2))
            count = seen.get(base, 0)
            seen[base] = count + 1
            found.add(base if count == 0 else f'{base}-{count}')
        found.update(_HTML_ANCHOR.findall(line))
    return found


def links(text: str) -> list[str]:
    """Return the targets of the page's links, outside code."""
    prose, _ = split_page(text)
    return [target for line in prose for target in _LINK.findall(_CODE_SPAN.sub('', line))]


def broken_links(page: str) -> list[str]:
    """Return 'target: why' for each relative link of ``page`` that leads nowhere."""
    with open(page) as handle:
        text = handle.read()
    problems = []
    for target in links(text):
        if re.match(r'[a-z][a-z0-9+.-]*:', target, re.IGNORECASE):
            continue  # http:, https:, mailto: ... not ours to check here
        path, _, anchor = target.partition('#')
        resolved = os.path.normpath(os.path.join(os.path.dirname(page), path)) if path \
            else page
        if not os.path.exists(resolved):
            problems.append(f'{target}: no file {os.path.relpath(resolved, REPO)}')
            continue
        if anchor and resolved.endswith('.md'):
            with open(resolved) as handle:
                if anchor not in anchors(handle.read()):
                    problems.append(f'{target}: no heading with the anchor #{anchor} in '
                                    f'{os.path.relpath(resolved, REPO)}')
    return problems


def missing_paths(text: str, root: str = REPO) -> list[str]:
    """Return the repository paths the page names (in prose or code) that do not exist."""
    missing = []
    for path in sorted(set(_REPO_PATH.findall(text))):
        candidates = [os.path.join(root, path)]
        if path.split('/', 1)[0] in _PACKAGE:
            candidates.append(os.path.join(root, 'i3dmgx2_driver', path))
        if not any(os.path.exists(candidate) for candidate in candidates):
            missing.append(path)
    return missing


def _name(page: str) -> str:
    return os.path.relpath(page, REPO)


@pytest.mark.parametrize('page', PAGES, ids=_name)
def test_relative_links_lead_to_files_and_headings_that_exist(page):
    problems = broken_links(page)
    assert not problems, f'{_name(page)}: ' + '; '.join(problems)


@pytest.mark.parametrize('page', PAGES, ids=_name)
def test_repository_paths_named_exist(page):
    with open(page) as handle:
        missing = missing_paths(handle.read())
    assert not missing, f'{_name(page)} names files that do not exist: {missing}'


#: Where the names a page cites live: the code, the tests, the harness and benchmarks.
_CODE_FOLDERS = ('i3dmgx2_driver', 'test', 'harness', 'benchmarks', 'scripts', 'launch')
_CITED_NAME = re.compile(r'`([A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*)(?:\(\))?`')


def section(text: str, heading: str) -> str:
    """Return the part of ``text`` from ``heading`` to the next heading of its level."""
    level = heading.partition(' ')[0]
    start = text.index(heading + '\n')
    end = text.find('\n' + level + ' ', start + len(heading))
    return text[start:] if end < 0 else text[start:end]


def uncited_names(text: str, root: str = REPO) -> list[str]:
    """Return the names in code spans of ``text`` that some part of is in no source file."""
    words: set[str] = set()
    for folder in _CODE_FOLDERS:
        for path in glob.glob(os.path.join(root, folder, '**', '*.py'), recursive=True):
            with open(path) as handle:
                words.update(re.findall(r'\w+', handle.read()))
    names = {m.group(1) for m in _CITED_NAME.finditer(text)
             if not re.search(r'\.(py|md|yaml|sh)$', m.group(1))}
    return sorted(n for n in names if not words.issuperset(n.split('.')))


def test_the_names_making_a_change_cites_exist():
    with open(os.path.join(REPO, 'docs', 'architecture.md')) as handle:
        text = section(handle.read(), '## Making a change')
    assert not uncited_names(text), \
        f'docs/architecture.md "Making a change" cites names the code lacks: {uncited_names(text)}'


def test_every_page_of_docs_is_linked_from_the_readme():
    with open(README) as handle:
        targets = {os.path.normpath(os.path.join(REPO, target.partition('#')[0]))
                   for target in links(handle.read())}
    unlinked = [_name(page) for page in PAGES[1:] if page not in targets]
    assert not unlinked, f'README.md does not link to {unlinked}'


def test_readme_opens_with_the_two_commands():
    with open(README) as handle:
        assert handle.read().startswith(OPENING)


def test_readme_says_how_to_run_the_tests_and_the_quick_loop():
    with open(README) as handle:
        text = handle.read()
    assert 'bash scripts/test.sh' in text
    assert "-m 'not slow'" in text


def test_each_headline_figure_links_to_where_it_was_measured():
    with open(README) as handle:
        text = handle.read()
    section = text[text.index('\n## How fast, how true\n'):]
    section = section[:section.index('\n## ', 1)]
    rows = [line for line in section.splitlines()
            if line.startswith('| ') and not line.startswith('| what |')]
    assert len(rows) >= 5, 'the headline table is gone'
    for row in rows:
        assert any(target.startswith('docs/') for target in links(row)), row


def test_slugs_are_githubs():
    # Headings of these pages, and the anchors GitHub renders for them.
    assert slug('Frames: ENU and NED') == 'frames-enu-and-ned'
    assert slug('Running the reader thread under `SCHED_FIFO`') == \
        'running-the-reader-thread-under-sched_fifo'
    assert slug("Where a sample's time goes") == 'where-a-samples-time-goes'
    assert slug('Tools: simulator, capture, replay') == 'tools-simulator-capture-replay'
    assert slug('See [the map](docs/architecture.md) (draft)') == 'see-the-map-draft'
    text = '# Title\n\n## Same\n\n```bash\n# not a heading\n```\n\n## Same\n'
    assert anchors(text) == {'title', 'same', 'same-1'}


def test_the_checks_find_what_is_broken(tmp_path):
    (tmp_path / 'other.md').write_text('# Other\n\n## A part\n')
    page = tmp_path / 'page.md'
    page.write_text(
        '# Page\n\n'
        '[fine](other.md#a-part) [fine too](#page) [web](https://example.com/x#y)\n'
        '[no file](missing.md) [no heading](other.md#nowhere) [no anchor](#gone)\n'
        '`[in code](missing-too.md)`\n\n'
        '```bash\n[in a block](missing-three.md)\n```\n')
    assert [problem.split(':')[0] for problem in broken_links(str(page))] == \
        ['missing.md', 'other.md#nowhere', '#gone']
    (tmp_path / 'scripts').mkdir()
    (tmp_path / 'scripts' / 'there.sh').write_text('')
    text = ('`scripts/there.sh`, `scripts/gone.sh`, `device/link.py`, '
            '/opt/ros/jazzy/setup.bash, `benchmarks/output/`\n')
    assert missing_paths(text, str(tmp_path)) == ['device/link.py', 'scripts/gone.sh']
    (tmp_path / 'i3dmgx2_driver').mkdir()
    (tmp_path / 'i3dmgx2_driver' / 'link.py').write_text('class DeviceLink:\n    on_data = 1\n')
    cited = '# Page\n\n## Making a change\n`DeviceLink.on_data`, `DeviceLink.gone()`, `x.py`\n'
    assert uncited_names(section(cited, '## Making a change'), str(tmp_path)) == \
        ['DeviceLink.gone']
