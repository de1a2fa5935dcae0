#!/usr/bin/env bash
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

# The test command: set up (scripts/setup.sh), then run the whole test suite with the venv's
# python, two workers per core (pytest-xdist; each worker its own ROS domain: test/conftest.py):
# most tests wait on a node or a simulator, so two per core keep the cores busy. The quick loop
# (-m 'not slow': no process, all CPU) takes one worker per core.
# Extra arguments go to pytest and win over these, e.g. `scripts/test.sh -m 'not slow' -x`,
# `scripts/test.sh -n 0` (one process), `scripts/test.sh --cov --cov-report=term` (coverage).
# Exits with pytest's exit code.

set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

bash "$ROOT/scripts/setup.sh"

cd "$ROOT"
# Tests import the package from the source tree (setup.cfg: pythonpath = .); env.sh gives the
# ones that start the installed executables what those need ($I3DMGX2_LIB, PYTHONPATH, ...).
# shellcheck source=scripts/env.sh
source "$ROOT/scripts/env.sh"

set +e
# loadfile: a file's tests run on one worker, one after another (a module's node is started
# once, and the checks of one file that measure time never run beside each other). The quick
# loop starts nothing: its tests go wherever a worker is free.
per_core=2
dist=loadfile
case " $* " in *'not slow'*) per_core=1 dist=load ;; esac
workers="${I3DMGX2_TEST_WORKERS:-$((per_core * $(nproc) < 16 ? per_core * $(nproc) : 16))}"
"$I3DMGX2_PY" -m pytest -n "$workers" --dist "$dist" "$@"
rc=$?
set -e
exit "$rc"
