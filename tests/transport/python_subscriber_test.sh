#!/bin/sh
# End to end in a private network namespace (run through in_netns.sh): the
# daemon publishes over LCM, the Python template subscriber prints stats
# and writes its SVG plot. Args: TISSUED_BINARY SOURCE_DIR PYTHON_TYPES_DIR
set -eu
tissued="$1"; src="$2"; types="$3"
if ! python3 -c 'import lcm' 2>/dev/null; then
  echo "python_subscriber_test: python3 has no 'lcm' module (scripts/install-deps.sh installs it); skipped" >&2
  exit 77
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$tissued" --config "$src/config/tissued.yaml" --duration 4 \
  --set "control.unix_socket_path=$work/c.sock" --set "state_dir=$work" \
  --set publish.lcm.enabled=true --set realtime.sched_fifo=false >"$work/daemon.log" 2>&1 &
daemon=$!
# A foreign publisher on the same channels (this private namespace): one
# datagram that is not a mesh, and statistics with a NaN real-time factor.
# The subscriber drops the first (saying so), prints the second and keeps it
# out of the plot.
python3 "$(dirname "$0")/foreign_lcm_publisher.py" "$types" &
foreign=$!
python3 "$src/clients/python/tissue_subscriber.py" --types "$types" --seconds 3 --plot "$work/stats.svg" \
  >"$work/sub.log" 2>"$work/sub.err"
wait "$foreign"
wait "$daemon"
grep -q 'dropped a 18-byte message on TISSUE_SURFACE_MESH that is not a surface_mesh' "$work/sub.err" ||
  { echo "the foreign message was not reported"; cat "$work/sub.err"; exit 1; }
grep -q '1 undecodable message(s) dropped on TISSUE_SURFACE_MESH' "$work/sub.err" || { cat "$work/sub.err"; exit 1; }
grep -q 'rtf   nan' "$work/sub.log" || { echo "the NaN statistics were not printed"; cat "$work/sub.log"; exit 1; }
if grep -qi 'nan' "$work/stats.svg"; then echo "NaN in the plot"; exit 1; fi
lines="$(grep -c '^t ' "$work/sub.log")"
echo "subscriber printed $lines stats lines"
[ "$lines" -ge 5 ] || { cat "$work/sub.log" "$work/daemon.log"; exit 1; }
grep -q '<polyline' "$work/stats.svg" || { echo "no plot"; exit 1; }
# Meshes and haptic states arrived and decoded.
grep '^t ' "$work/sub.log" | tail -1 | grep -q 'meshes [1-9][0-9]*, haptic states [1-9]' || { tail -3 "$work/sub.log"; exit 1; }
