#!/usr/bin/env bash
# README command 1: install what is missing, build, run the main job.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install-deps.sh"
cmake -S "$root" -B "$root/build/release" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$root/build/release" --target tissued -j "$(nproc)"
exec "$root/build/release/daemon/tissued" "$@"
