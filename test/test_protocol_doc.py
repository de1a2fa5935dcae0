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
docs/protocol.md against the code that cites it and the codec that implements it.

Every citation in the sources names a section the document has (``docs/
protocol.md §N``, never a bare ``protocol.md`` the repository does not
hold), and the document's command table agrees with the codec's layout table
(every command, and each one's wired reply size), its timer with the
codec's ticks per second: a document that drifts from the code fails here.
"""

from pathlib import Path
import re

from i3dmgx2_driver.codec import command_firmware as firmware, layouts
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND

REPO = Path(__file__).resolve().parents[1]
DOC = (REPO / 'docs' / 'protocol.md').read_text(encoding='utf-8')
#: The document's prose with its line breaks folded, to find a sentence in it.
PROSE = ' '.join(DOC.split())
SECTIONS = set(re.findall(r'^## (§\d+) ', DOC, re.M))
SOURCES = [p for folder in ('i3dmgx2_driver', 'test', 'benchmarks', 'harness', 'launch',
                            'scripts')
           for p in sorted((REPO / folder).rglob('*.py'))]


def test_every_citation_names_a_section_that_exists():
    bad = []
    cited = 0
    for path in SOURCES:
        text = path.read_text(encoding='utf-8')
        for number, line in enumerate(text.splitlines(), 1):
            if 'protocol.md' not in line or path.name == 'test_protocol_doc.py':
                continue
            for match in re.finditer(r'(\S*)protocol\.md(?: (§\d+)(?:-(§\d+))?)?', line):
                cited += 1
                prefix, first, last = match.groups()
                if not prefix.endswith('docs/') or first is None:
                    bad.append(f'{path.relative_to(REPO)}:{number}: {line.strip()}')
                    continue
                for section in (first, last):
                    if section is not None and section not in SECTIONS:
                        bad.append(f'{path.relative_to(REPO)}:{number}: no {section}')
    assert cited > 30
    assert not bad, '\n'.join(bad)


def _command_table() -> dict[int, tuple[int, str]]:
    """Command byte -> (wired reply bytes, least firmware), from the document's §6 table."""
    section = DOC.split('## §6 ', 1)[1].split('\n## ', 1)[0]
    table = {}
    for row in section.splitlines():
        cells = [cell.strip() for cell in row.strip('|').split('|')]
        if len(cells) == 6 and re.fullmatch(r'0x[0-9A-F]{2}', cells[0]):
            table[int(cells[0], 16)] = (int(re.match(r'\d+', cells[4]).group()), cells[5])
    return table


def test_the_command_table_is_the_codecs():
    table = _command_table()
    assert set(table) == set(layouts.LAYOUTS)
    for code, (_, least) in table.items():
        assert least == firmware.text(layouts.LAYOUTS[code].firmware), f'0x{code:02X}'
    # The ping's answer is one bare byte, which the parser takes apart from records.
    assert table.pop(layouts.PING)[0] == 1
    for code, (size, _) in table.items():
        assert layouts.LAYOUTS[code].wired_size == size, f'0x{code:02X}'


def test_the_timer_and_the_worked_packet_size_are_the_codecs():
    assert f'**{TICKS_PER_SECOND:,} ticks a second**' in PROSE
    record = layouts.LAYOUTS[layouts.ACCEL_ANG_RATE_MAG_ORIENTATION].record_size
    assert f'the 0xCC record is {record + 2} bytes wired, {record} in a packet' in PROSE
