#!/usr/bin/env bash
# README command 2: build and pass every test, twice: a Release tree and an
# ASan+UBSan tree. Each tree is reused if present (incremental builds).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
jobs="$(nproc)"
"$root/scripts/install-deps.sh"

run_tree() {  # name, extra cmake args...
  local name="$1"; shift
  local dir="$root/build/$name"
  echo "=== $name: configure and build ==="
  cmake -S "$root" -B "$dir" -G Ninja "$@" >/dev/null
  cmake --build "$dir" -j "$jobs"
  echo "=== $name: test ==="
  (cd "$dir" && ctest --output-on-failure -j "$jobs" --timeout 600)
}

run_tree release -DCMAKE_BUILD_TYPE=Release
# Sanitizers: debug info, some optimisation so the suite stays fast.
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  run_tree asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTISSUE_SANITIZE=address,undefined -DTISSUE_BUILD_BENCH=OFF
echo "=== all test trees passed ==="
