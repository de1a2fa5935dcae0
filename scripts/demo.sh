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

# Set up everything (scripts/setup.sh), then run the driver and show its data.
#
#   bash scripts/demo.sh                                # against the simulated sensor
#   bash scripts/demo.sh --port /dev/ttyUSB0 --address 95   # against real hardware
#   bash scripts/demo.sh --duration 10                  # stop by itself after 10 s
#
# It runs the colcon-installed executables, the very files `ros2 run i3dmgx2_driver ...`
# runs: simulator (unless --port is given), node, and monitor, which prints one line per
# half second from /imu/raw_data. Ctrl-C stops everything cleanly.

set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PORT=''
ADDRESS=95
DURATION=0
while [ $# -gt 0 ]; do
  case "$1" in
    --port) PORT="$2"; shift 2 ;;
    --address) ADDRESS="$2"; shift 2 ;;
    --duration) DURATION="$2"; shift 2 ;;
    -h|--help) sed -n '16,24p' "$0"; exit 0 ;;
    *) echo "demo.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done

bash "$ROOT/scripts/setup.sh"
# shellcheck source=scripts/env.sh
source "$ROOT/scripts/env.sh"
# Keep the demo's DDS traffic on this machine.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"

WORK="$(mktemp -d "${TMPDIR:-/tmp}/i3dmgx2-demo-XXXXXX")"
SIM_PID=''
NODE_PID=''
MONITOR_PID=''
cleanup() {
  # To the end, whatever fails or arrives meanwhile: a failed kill or wait must not stop it
  # half-way (set -e), nor a second signal (a closed terminal sends SIGHUP after Ctrl-C).
  set +e
  trap '' INT TERM HUP
  # SIGTERM, which each stops on as on Ctrl-C: a background job starts with SIGINT ignored,
  # so a SIGINT that came before its handlers were installed would be lost, and wait hang.
  [ -n "$MONITOR_PID" ] && kill -TERM "$MONITOR_PID" 2>/dev/null
  [ -n "$NODE_PID" ] && kill -TERM "$NODE_PID" 2>/dev/null && wait "$NODE_PID" 2>/dev/null
  [ -n "$SIM_PID" ] && kill -TERM "$SIM_PID" 2>/dev/null && wait "$SIM_PID" 2>/dev/null
  rm -rf "$WORK"
}
trap cleanup EXIT
# Ctrl-C, SIGTERM and a closed terminal (SIGHUP) all end the demo through cleanup. Should
# this script die without it (SIGKILL), each executable ends with it all the same: it asks
# for a signal when its parent ends (i3dmgx2_driver/lifetime.py), the simulator too,
# although its session, which a closed terminal does not reach, is its own.
trap 'exit 130' INT
trap 'exit 143' TERM
trap 'exit 129' HUP

if [ -z "$PORT" ]; then
  echo '[demo] no --port given: starting the simulated 3DM-GX2 and base station'
  # In its own session, so that Ctrl-C reaches the node first and the sensor goes away
  # only after the node has stopped its stream and closed the port (see cleanup).
  $(command -v setsid || true) "$I3DMGX2_LIB/simulator" --address "$ADDRESS" --quiet \
    > "$WORK/simulator.out" 2>&1 &
  SIM_PID=$!
  for _ in $(seq 100); do
    PORT="$(sed -n 's/^port: //p' "$WORK/simulator.out" | head -n 1)"
    [ -n "$PORT" ] && break
    sleep 0.1
  done
  [ -n "$PORT" ] || { cat "$WORK/simulator.out"; echo '[demo] the simulator did not start' >&2; exit 1; }
  echo "[demo] simulated sensor on $PORT"
fi

echo "[demo] ros2 run i3dmgx2_driver node --ros-args -p port:=$PORT -p address:=$ADDRESS"
"$I3DMGX2_LIB/node" --ros-args -p "port:=$PORT" -p "address:=$ADDRESS" &
NODE_PID=$!
sleep 1
echo '[demo] ros2 run i3dmgx2_driver monitor   (Ctrl-C to stop)'
# Waited for rather than run in the foreground, so that a signal's trap runs at once.
"$I3DMGX2_LIB/monitor" --duration "$DURATION" &
MONITOR_PID=$!
wait "$MONITOR_PID"
