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

# The smoke test on another ROS 2 distribution: `bash scripts/smoke.sh kilted`.
#
# Makes .venv-DISTRO with requirements-DISTRO.txt (that distribution's runtime wheels from PyPI,
# pyserial, numpy, pytest; nothing of Jazzy's), then runs the tests marked `smoke`
# (test/test_smoke.py: the plain and the managed node against the simulator, a subscriber, a
# service call, /diagnostics, a clean stop) with it, from the source tree. Extra arguments go to
# pytest. Environment: I3DMGX2_PYTHON, the interpreter to make the venv with (as setup.sh).

set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DISTRO="${1:-kilted}"
shift || true
REQUIREMENTS="$ROOT/requirements-$DISTRO.txt"
VENV="$ROOT/.venv-$DISTRO"
STAMP="$VENV/.i3dmgx2_requirements.sha256"

log() { printf '[smoke] %s\n' "$*"; }
[ -f "$REQUIREMENTS" ] || { log "ERROR: no $REQUIREMENTS: which distributions have one: \
$(cd "$ROOT" && ls requirements-*.txt | sed -n 's/^requirements-\(.*\)\.txt$/\1/p' \
  | grep -v '^dev$' | tr '\n' ' ')" >&2; exit 2; }

if [ ! -x "$VENV/bin/python" ]; then
  PYTHON="${I3DMGX2_PYTHON:-python3}"
  log "creating $VENV with $PYTHON"
  "$PYTHON" -m venv "$VENV"
fi
req_hash="$(sha256sum < "$REQUIREMENTS" | cut -d' ' -f1)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$req_hash" ]; then
  log "installing $(basename "$REQUIREMENTS")"
  "$VENV/bin/python" -m pip install --disable-pip-version-check --no-input \
    --progress-bar off -q -r "$REQUIREMENTS"
  echo "$req_hash" > "$STAMP"
fi
touch "$VENV/AMENT_IGNORE"

cd "$ROOT"
"$VENV/bin/python" - "$DISTRO" <<'PY'
import importlib.metadata as md
import sys

print('[smoke] python', sys.version.split()[0], ' '.join(
    f'{name}=={md.version(name)}' for name in (
        f'ros-{sys.argv[1]}-rclpy', f'ros-{sys.argv[1]}-common-interfaces',
        f'ros-{sys.argv[1]}-rmw-fastrtps-cpp')))
PY
# From the source tree, none of Jazzy's environment: the ROS libraries come from the venv.
exec env -u PYTHONPATH -u AMENT_PREFIX_PATH -u COLCON_PREFIX_PATH -u LD_LIBRARY_PATH \
  "$VENV/bin/python" -m pytest -p no:cacheprovider -m smoke -q "$@" test/test_smoke.py
