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

# Source this file (bash or zsh) after scripts/setup.sh to run the colcon-installed executables:
#
#   source scripts/env.sh
#   "$I3DMGX2_LIB/simulator" --help
#   "$I3DMGX2_LIB/node"
#
# The executables' shebang already names the venv's python, which loads the ROS libraries of
# the wheels by itself. What they need from the environment is PYTHONPATH (to find the
# installed package and its entry points) and AMENT_PREFIX_PATH (for ament_index lookups of
# the package's share directory). PATH is left alone on purpose: .venv/bin holds tools with
# generic names, and this package's own executables are reached through $I3DMGX2_LIB.
#
# Sets: I3DMGX2_ROOT, I3DMGX2_PY (the venv's python), I3DMGX2_LIB (the installed executables),
# and prepends to PYTHONPATH and AMENT_PREFIX_PATH (without duplicates when sourced again).

if [ -n "${BASH_VERSION:-}" ]; then
  I3DMGX2_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
elif [ -n "${ZSH_VERSION:-}" ]; then
  # shellcheck disable=SC2296
  I3DMGX2_ROOT="$(cd "$(dirname "${(%):-%x}")/.." && pwd)"
elif [ -z "${I3DMGX2_ROOT:-}" ]; then
  echo 'scripts/env.sh: not bash or zsh: set I3DMGX2_ROOT to the repository root first' >&2
  return 1
fi
export I3DMGX2_ROOT
export I3DMGX2_PY="$I3DMGX2_ROOT/.venv/bin/python"
export I3DMGX2_LIB="$I3DMGX2_ROOT/install/i3dmgx2_driver/lib/i3dmgx2_driver"

_i3dmgx2_prepend() {
  # _i3dmgx2_prepend VAR DIR: put DIR first in the colon-separated list VAR, once.
  eval "_i3dmgx2_old=\"\${$1:-}\""
  case ":${_i3dmgx2_old}:" in
    *":$2:"*) ;;
    *) eval "export $1=\"$2\${_i3dmgx2_old:+:\$_i3dmgx2_old}\"" ;;
  esac
  unset _i3dmgx2_old
}

if [ ! -x "$I3DMGX2_PY" ] || [ ! -d "$I3DMGX2_LIB" ]; then
  echo "scripts/env.sh: $I3DMGX2_ROOT is not set up yet: run scripts/setup.sh" >&2
else
  for _i3dmgx2_site in "$I3DMGX2_ROOT"/install/i3dmgx2_driver/lib/python3*/site-packages; do
    [ -d "$_i3dmgx2_site" ] && _i3dmgx2_prepend PYTHONPATH "$_i3dmgx2_site"
  done
  unset _i3dmgx2_site
  _i3dmgx2_prepend AMENT_PREFIX_PATH "$I3DMGX2_ROOT/.venv"
  _i3dmgx2_prepend AMENT_PREFIX_PATH "$I3DMGX2_ROOT/install/i3dmgx2_driver"
fi
unset -f _i3dmgx2_prepend
