#!/usr/bin/env bash
# README command 2: build and pass every test, twice: a Release tree and an
# ASan+UBSan tree. Each tree is reused if present (incremental builds).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
jobs="$(nproc)"
"$root/scripts/install-deps.sh"

run_tree() {  # name, ctest selection (e.g. "-L threaded" or ""), extra cmake args...
  local name="$1"; shift
  local select="$1"; shift
  local dir="$root/build/$name"
  echo "=== $name: configure and build ==="
  cmake -S "$root" -B "$dir" -G Ninja "$@" >/dev/null
  cmake --build "$dir" -j "$jobs"
  echo "=== $name: test ==="
  # shellcheck disable=SC2086  # $select is a list of ctest arguments
  (cd "$dir" && ctest --output-on-failure -j "$jobs" --timeout 600 $select)
}

run_tree release "" -DCMAKE_BUILD_TYPE=Release
# Sanitizers: debug info, some optimisation so the suite stays fast.
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  LSAN_OPTIONS="suppressions=$root/tests/lsan.supp:print_suppressions=0" \
  run_tree asan "" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTISSUE_SANITIZE=address,undefined -DTISSUE_BUILD_BENCH=OFF
# Threads: the suites labelled `threaded` (hand-offs, haptic and sim threads,
# control server, the service) once more under ThreadSanitizer.
TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$root/tests/tsan.supp" \
  run_tree tsan "-L threaded" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTISSUE_SANITIZE=thread -DTISSUE_BUILD_BENCH=OFF
echo "=== all test trees passed ==="
