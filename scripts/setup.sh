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

# Set up a development environment without a system ROS installation (idempotent):
#   1. create .venv at the repository root with python3 (3.10 to 3.13);
#   2. install requirements-dev.txt into it (ROS 2 Jazzy comes as wheels from PyPI);
#   3. build the package with colcon into build/ install/ log/ at the repository root.
# Afterwards `source scripts/env.sh` gives the environment the installed executables need.
#
# Environment: I3DMGX2_PYTHON  interpreter to create the venv with (default: the first of
#              python3, python3.12, python3.13, python3.11, python3.10 that is 3.10-3.13).

set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
STAMP="$VENV/.i3dmgx2_requirements.sha256"

log() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

# Prints "3.11" for a working interpreter, nothing otherwise.
py_version() {
  "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null || true
}

version_ok() {
  case "$1" in
    3.10 | 3.11 | 3.12 | 3.13) return 0 ;;
    *) return 1 ;;
  esac
}

cd "$ROOT"

# --- 1. the virtual environment ---------------------------------------------------------------
if [ -x "$VENV/bin/python" ] && version_ok "$(py_version "$VENV/bin/python")"; then
  log "using existing $VENV (Python $(py_version "$VENV/bin/python"))"
else
  # The interpreter: $I3DMGX2_PYTHON if set, else the first of python3, python3.12, ... that
  # is 3.10-3.13.
  if [ -n "${I3DMGX2_PYTHON:-}" ]; then
    candidates=("$I3DMGX2_PYTHON")
  else
    candidates=(python3.12 python3 python3.13 python3.11 python3.10)
  fi
  PYTHON=''
  tried=''
  for candidate in "${candidates[@]}"; do
    command -v "$candidate" >/dev/null 2>&1 || continue
    version="$(py_version "$candidate")"
    tried="$tried $candidate (${version:-does not run})"
    if [ -n "$version" ] && version_ok "$version"; then
      PYTHON="$candidate"
      break
    fi
  done
  [ -n "$PYTHON" ] || die "no Python 3.10-3.13 found (tried:${tried:- ${candidates[*]}, none found}); \
the ROS 2 Jazzy wheels need one of them. Install one, or set I3DMGX2_PYTHON=/path/to/python3.X"
  if [ -e "$VENV" ]; then
    log "removing unusable $VENV"
    rm -rf "$VENV"
  fi
  log "creating $VENV with $PYTHON (Python $version)"
  "$PYTHON" -m venv "$VENV" \
    || die "'$PYTHON -m venv' failed (on Debian/Ubuntu: apt-get install python3-venv)."
fi

# --- 2. the requirements (skipped when unchanged since the last successful install) -----------
req_hash="$(cat requirements.txt requirements-dev.txt | sha256sum | cut -d' ' -f1)"
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$req_hash" ]; then
  log 'requirements unchanged since the last install'
else
  log 'installing requirements-dev.txt'
  rm -f "$STAMP"
  "$VENV/bin/python" -m pip install --disable-pip-version-check --no-input \
    --progress-bar off -r requirements-dev.txt
  echo "$req_hash" > "$STAMP"
fi
# ament_flake8 walks the whole tree for AMENT_IGNORE markers: stop it at the venv.
touch "$VENV/AMENT_IGNORE"

# --- 3. the colcon build ---------------------------------------------------------------------
# A plain (not --symlink-install) build from scratch: the installed copy never keeps modules
# that were deleted from the sources, and the executables need only PYTHONPATH (scripts/env.sh).
# Variables of a sourced ROS installation would mix another Python's packages into the build.
log 'building with colcon'
rm -rf "$ROOT/build" "$ROOT/install"
env -u PYTHONPATH -u AMENT_PREFIX_PATH -u COLCON_PREFIX_PATH -u CMAKE_PREFIX_PATH \
  "$VENV/bin/colcon" --log-base "$ROOT/log" build \
  --paths "$ROOT" \
  --build-base "$ROOT/build" \
  --install-base "$ROOT/install" \
  --event-handlers desktop_notification- terminal_title-
for dir in build install log; do
  touch "$ROOT/$dir/AMENT_IGNORE"
done

LIB="$ROOT/install/i3dmgx2_driver/lib/i3dmgx2_driver"
for exe in node lifecycle_node simulator replay plot monitor discover bringup magcal; do
  [ -x "$LIB/$exe" ] || die "colcon did not install $LIB/$exe"
done
log "done: executables in $LIB; run 'source scripts/env.sh' to use them"
