#!/usr/bin/env bash
# README command 1: install what is missing, build, run the main job: the
# daemon serving the paper's cantilever to the simulated hand for 20 s with
# live figures (a status line every second), recording the session to HDF5,
# then an X3D file and a PNG picture of the surface made from that session.
# Everything goes to build/run/. Arguments, when given, go to tissued as they
# are instead, e.g.
#   scripts/run.sh --config config/tissued.yaml          (serve until Ctrl-C)
#   scripts/run.sh --batch --scene config/scenes/beam.yaml --duration 5
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install-deps.sh"
cmake -S "$root" -B "$root/build/release" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$root/build/release" --target tissued tissue -j "$(nproc)"
bin="$root/build/release"
if [ $# -gt 0 ]; then
  exec "$bin/daemon/tissued" "$@"
fi

run_dir="$root/build/run"
mkdir -p "$run_dir"
stamp="$(date -u +%Y%m%d-%H%M%S)"
session="session-$stamp.h5"
# A source checkout keeps its socket and state in build/run (the installed
# service uses /run/tissued and /var/lib/tissued).
echo "tissued: serving for 20 s; meanwhile: $bin/clients/tissue ctl --socket $run_dir/control.sock status"
"$bin/daemon/tissued" --config "$root/config/tissued.yaml" --duration 20 \
  --set "control.unix_socket_path=$run_dir/control.sock" --set "state_dir=$run_dir" --record "$session"
"$bin/clients/tissue" session info "$run_dir/$session"
"$bin/clients/tissue" x3d --session "$run_dir/$session" --time 0.9 -o "$run_dir/surface-$stamp.x3d"
"$bin/clients/tissue" render --session "$run_dir/$session" --time 0.9 -o "$run_dir/surface-$stamp.png"
"$bin/clients/tissue" render --session "$run_dir/$session" --time 0.9 --colour strain \
  -o "$run_dir/strain-$stamp.png"
echo "run.sh: session, X3D and PNGs (levels, strain) are in $run_dir;" \
  "replay it live with: $bin/clients/tissue session replay $run_dir/$session --lcm"
