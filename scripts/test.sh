#!/usr/bin/env bash
# README command 2: build and pass every test in three trees: a Release tree,
# an ASan+UBSan tree, and a TSan tree for the threaded suites (ctest -L
# threaded). Each tree is reused if present (incremental builds).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
jobs="$(nproc)"
"$root/scripts/install-deps.sh"

run_tree() {  # name, ctest selection (e.g. "-L threaded" or ""), build target ("" = all), extra cmake args...
  local name="$1"; shift
  local select="$1"; shift
  local target="$1"; shift
  local dir="$root/build/$name"
  echo "=== $name: configure and build ($(date -u +%T)) ==="
  cmake -S "$root" -B "$dir" -G Ninja "$@" >/dev/null
  # shellcheck disable=SC2086  # $target is empty or one target
  cmake --build "$dir" -j "$jobs" ${target:+--target $target}
  echo "=== $name: test ($(date -u +%T)) ==="
  # shellcheck disable=SC2086  # $select is a list of ctest arguments
  (cd "$dir" && ctest --output-on-failure -j "$jobs" --timeout 600 $select)
}

run_tree release "" "" -DCMAKE_BUILD_TYPE=Release
# Sanitizers: -O1 (the sanitizers' own advice: fast enough to run, little
# inlining to hide a frame; 31-38 % less compile time than -O2 on the three
# heaviest files under ASan, which is most of this script's time) and line
# tables only (-g1: reports keep their file:line frames; 22 % less compile
# time than -g on the heaviest file, half the object size).
sanitizer_flags="-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
# float-cast-overflow is not part of GCC's `undefined`: a double converted to
# an integer it does not fit (a duration in nanoseconds, a step or sub-step
# count, a poll timeout in milliseconds) was the undefined behaviour five
# defects found on 2026-11-27 had in common, and only this check sees it.
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  LSAN_OPTIONS="suppressions=$root/tests/lsan.supp:print_suppressions=0" \
  run_tree asan "" "" -DCMAKE_BUILD_TYPE=RelWithDebInfo "$sanitizer_flags" \
  -DTISSUE_SANITIZE=address,undefined,float-cast-overflow -DTISSUE_BUILD_BENCH=OFF
# Threads: the suites labelled `threaded` (hand-offs, haptic and sim threads,
# control server, the service) once more under ThreadSanitizer; the tree
# builds only what they run (target threaded_tests).
TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$root/tests/tsan.supp" \
  run_tree tsan "-L threaded" threaded_tests -DCMAKE_BUILD_TYPE=RelWithDebInfo "$sanitizer_flags" -DTISSUE_SANITIZE=thread -DTISSUE_BUILD_BENCH=OFF
echo "=== all test trees passed ($(date -u +%T)) ==="
