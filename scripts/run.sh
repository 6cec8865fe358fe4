#!/usr/bin/env bash
# README command 1: install what is missing, build, run the main job: the
# daemon serving the paper's cantilever with the simulated hand pressing it,
# printing live figures (status line every second) for 20 s and recording
# the session to build/run/session-*.h5 (HDF5), then stopping cleanly. Arguments replace the defaults and go to tissued as they are, e.g.
#   scripts/run.sh --config config/tissued.yaml          (until Ctrl-C)
#   scripts/run.sh --batch --scene config/scenes/beam.yaml --duration 5
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install-deps.sh"
cmake -S "$root" -B "$root/build/release" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$root/build/release" --target tissued tissue -j "$(nproc)"
run_dir="$root/build/run"
mkdir -p "$run_dir"
if [ $# -eq 0 ]; then
  # A source checkout keeps its socket and state in build/run (the installed
  # service uses /run/tissued and /var/lib/tissued).
  set -- --config "$root/config/tissued.yaml" --duration 20 \
    --set "control.unix_socket_path=$run_dir/control.sock" --set "state_dir=$run_dir" \
    --record "session-$(date -u +%Y%m%d-%H%M%S).h5"
  echo "tissued: serving for 20 s; meanwhile: build/release/clients/tissue ctl --socket $run_dir/control.sock status"
fi
exec "$root/build/release/daemon/tissued" "$@"
