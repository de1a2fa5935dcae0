#!/usr/bin/env python3
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
Fuzz the codec: stream parsers, one-shot decoders, orientation on decoded garbage.

Coverage-guided with atheris when it is installed (``pip install atheris``),
seeded with valid packets of every record type and the real 0xCC records of
test/fixtures/gx2_real_0xcc_records.txt; otherwise hypothesis, with a large
example budget. Every input is checked by ``harness.fuzz_checks.check_input``
(harness/fuzz_checks.py says which parsers and decoders it goes through and
which properties must hold), which the regression test shares.

Violations are saved (deduplicated by what broke) in a temporary folder the
run names, each after the property, for test/fixtures/fuzz/ and
test/test_fuzz_regressions.py.

    python benchmarks/fuzz_parser.py --minutes 10
"""

import argparse
import os
from pathlib import Path
import re
import sys
import tempfile
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.fuzz_checks import (  # noqa: E402 - the repository is on the path from here on
    ADDRESS, bind, check_input, command_frame, load_codec, PropertyViolation, wired_frame,
    wireless_frame,
)

try:  # atheris is optional
    import atheris
except ImportError:
    atheris = None

FIXTURE = Path(__file__).resolve().parents[1] / 'test' / 'fixtures' / 'gx2_real_0xcc_records.txt'
#: The longest input (bytes).
MAX_LEN = 2048

# -- seeds ------------------------------------------------------------------------------------


def seed_inputs() -> list[bytes]:
    """Return valid packets of every kind, real records, and some run together."""
    from i3dmgx2_driver.codec import layouts
    from i3dmgx2_driver.simulator.sensor import SensorSpec, SimulatedSensor, STREAMABLE
    sensor = SimulatedSensor(SensorSpec(ADDRESS), seed=1)
    seeds = []
    for code in sorted(STREAMABLE):
        record = sensor.record_at(code, 1.0).data
        seeds.append(wireless_frame(ADDRESS, record, 200, 150))
        seeds.append(wired_frame(record))
    for code, layout in layouts.LAYOUTS.items():
        if layout.record_size and code not in STREAMABLE:
            record = bytes((code,)) + bytes(layout.record_size - 1)
            seeds.append(wireless_frame(ADDRESS, record, 1, 2))
        seeds.append(command_frame(ADDRESS, bytes((code,)) + layout.confirm
                                   + bytes(layout.request_size - 1 - len(layout.confirm))))
    lines = (line.strip() for line in FIXTURE.read_text().splitlines())
    real = [bytes.fromhex(line) for line in lines if line and not line.startswith('#')]
    for record in real[::100]:
        seeds.append(wireless_frame(ADDRESS, record, 230, 170))
        seeds.append(wired_frame(record))
    mixed = (b'\xaa' + wireless_frame(ADDRESS, real[0], 1, 2) + b'\x21\x02'
             + wireless_frame(ADDRESS + 1, real[1], 3, 4) + b'\x00\xaa\x07'
             + wireless_frame(ADDRESS, real[2], 5, 6)[:50] + wireless_frame(ADDRESS, real[3], 7, 8)
             + b'\xaa')
    seeds.append(mixed)
    seeds.append(b'\xaa' * 64)
    seeds.append(bytes(range(256)))
    return seeds


# -- engines ----------------------------------------------------------------------------------


class Findings:
    """Save each kind of violation once."""

    def __init__(self, directory: str, engine: str, seconds: float) -> None:
        self.directory = directory
        os.makedirs(directory, exist_ok=True)
        self.engine = engine
        self.seen: dict[str, int] = {}
        self.inputs = 0
        self.start = time.monotonic()
        # libFuzzer ends the process itself at -max_total_time, without returning:
        # the summary is printed just before.
        self._summary_at = self.start + max(seconds - 1.0, 0.0)
        self._summarised = False

    def summary(self) -> str:
        """One line: inputs, rate, violations."""
        elapsed = time.monotonic() - self.start
        return (f'{self.engine}: {self.inputs} inputs in {elapsed:.0f} s '
                f'({self.inputs / max(elapsed, 1e-9):.0f}/s); '
                'violations: ' + (', '.join(f'{k} x{n}' for k, n in sorted(self.seen.items()))
                                  or 'none'))

    def test(self, data: bytes) -> None:
        """Check one input; save it if it breaks a property never broken before."""
        self.inputs += 1
        if self.engine == 'atheris' and time.monotonic() >= self._summary_at \
                and not self._summarised:
            self._summarised = True
            print(f'SUMMARY {self.summary()}', flush=True)
        try:
            check_input(data)
        except PropertyViolation as exc:
            key = re.sub(r'[^a-z0-9_]+', '_', exc.name.lower())
            self.seen[key] = self.seen.get(key, 0) + 1
            if self.seen[key] == 1:
                path = os.path.join(self.directory, f'{key}.bin')
                with open(path, 'wb') as handle:
                    handle.write(data)
                print(f'\nFINDING {key}: {exc} -> {path}', flush=True)


def run_atheris(findings: Findings, seconds: float) -> None:
    """Coverage-guided fuzzing with libFuzzer through atheris."""
    with atheris.instrument_imports(include=['i3dmgx2_driver']):
        modules = load_codec()
    bind(modules)
    corpus = tempfile.mkdtemp(prefix='i3dmgx2-fuzz-corpus-')
    for index, data in enumerate(seed_inputs()):
        with open(os.path.join(corpus, f'seed{index:04d}'), 'wb') as handle:
            handle.write(data)
    print(f'atheris: {len(os.listdir(corpus))} seeds in {corpus}', flush=True)
    argv = [sys.argv[0], corpus, f'-max_total_time={int(seconds)}', f'-max_len={MAX_LEN}',
            '-print_final_stats=1', '-print_pcs=0', '-reload=0', '-timeout=10',
            '-rss_limit_mb=4096']
    atheris.Setup(argv, findings.test)
    atheris.Fuzz()


def run_hypothesis(findings: Findings, seconds: float) -> None:
    """Property-based fuzzing with hypothesis until the time is up."""
    from hypothesis import given, HealthCheck, settings, strategies as st
    bind(load_codec())
    seeds = seed_inputs()
    for data in seeds:
        findings.test(data)
    pieces = st.one_of(st.binary(max_size=64), st.sampled_from(seeds),
                       st.sampled_from([b'\xaa', b'\x21', b'\x02', b'\x07', b'\xaa\x07\x00']))
    inputs = st.one_of(st.binary(max_size=MAX_LEN),
                       st.lists(pieces, max_size=12).map(b''.join))
    deadline = time.monotonic() + seconds

    @settings(max_examples=2000, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(inputs)
    def fuzz(data: bytes) -> None:
        findings.test(data)

    # Rounds of 2000 fresh examples each (no database), until the time is up.
    while time.monotonic() < deadline:
        fuzz()


def main(argv: list[str] | None = None) -> int:
    """Fuzz for the given time; print statistics; return 1 if anything broke."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--minutes', type=float, default=10.0)
    args = parser.parse_args(argv)
    engine = 'atheris' if atheris is not None else 'hypothesis'
    seconds = args.minutes * 60.0
    directory = os.path.join(tempfile.gettempdir(), 'i3dmgx2-fuzz-findings')
    findings = Findings(directory, engine, seconds)
    print(f'fuzzing with {engine} for {args.minutes:g} min; findings go to {directory}',
          flush=True)
    if engine == 'atheris':
        run_atheris(findings, seconds)  # does not return: libFuzzer exits
    run_hypothesis(findings, seconds)
    print(f'SUMMARY {findings.summary()}', flush=True)
    return 1 if findings.seen else 0


if __name__ == '__main__':
    sys.exit(main())
