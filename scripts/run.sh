#!/usr/bin/env bash
# README command 1: install what is missing, build, run the main job.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install-deps.sh"
cmake -S "$root" -B "$root/build/release" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$root/build/release" --target tissued -j "$(nproc)"
# Without arguments: the paper's cantilever, loaded then released, with live figures.
if [ $# -eq 0 ]; then
  set -- --batch --scene "$root/config/scenes/cantilever.yaml" --duration 2 --progress 0.1 \
    --report "$root/build/cantilever-report.json"
fi
exec "$root/build/release/daemon/tissued" "$@"
