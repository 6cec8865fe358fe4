#!/usr/bin/env bash
# DDS readers killed with SIGKILL must not starve the readers after them
# (the soak audit of 2026-11-26: with Fast DDS 2.9.1 shared memory, the next
# reader took the dead one's participant id and port names while the daemon
# kept writing into the unlinked old ports; every later reader on that id got
# nothing until the daemon restarted). Starts the daemon with DDS on, starts
# `tissue x3d --dds --animate` readers one after another and kills each
# 0.4-0.75 s after its start, then three plain readers must each get a mesh.
#
#   bench/analysis/dds_killed_readers.sh [BUILD_DIR] [KILLS]   (default build/dev, 40)
#
# Runs itself in a private network namespace with a private /dev/shm (no
# traffic leaves loopback, no segment is left on the host). About 25 s when
# it passes, 50 s when it fails. Prints RESULT ok=N fail=M; exits 1 on a fail,
# 2 (with the daemon's output, no RESULT line) when the daemon did not start.
# Measured 2026-11-27 with today's daemon: readers of the day before (shared
# memory) 4 of 4 runs failed (with 0 kills 3 of 3 checks passed); readers on
# UDP only, 1 of 1 passed (and 0 of 10 failed in the diagnosis's own runs).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
build="$(cd "${1:-$root/build/dev}" && pwd)"
kills="${2:-40}"
if [ "${TISSUE_IN_PRIVATE_NS:-}" != 1 ]; then
  exec unshare -rn -m env TISSUE_IN_PRIVATE_NS=1 bash -c \
    'mount -t tmpfs -o size=512m,mode=1777 dds_killed_readers /dev/shm && ip link set lo up &&
     ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && exec bash "$0" "$@"' "$0" "$build" "$kills"
fi
run="$(mktemp -d)"
trap 'rm -rf "$run"' EXIT
mkdir "$run/state"
tissue="$build/clients/tissue"
domain=61
"$build/daemon/tissued" --config "$root/config/tissued.yaml" --set "control.unix_socket_path=$run/ctl.sock" \
  --set "state_dir=$run/state" --set record.auto_start=false --set publish.dds.enabled=true \
  --set "publish.dds.domain_id=$domain" > "$run/daemon.out" 2>&1 &
daemon=$!
for _ in $(seq 100); do
  [ -S "$run/ctl.sock" ] && break
  kill -0 "$daemon" 2> /dev/null || break # exited: no socket is coming
  sleep 0.1
done
sleep 1
# Without a daemon every check below times out and the run ends in the
# regression's own signature, RESULT ok=0 fail=3, while the EXIT trap
# deletes the log that says why.
if [ ! -S "$run/ctl.sock" ] || ! kill -0 "$daemon" 2> /dev/null; then
  echo "daemon did not start:" >&2
  cat "$run/daemon.out" >&2
  exit 2
fi
delays=(0.4 0.5 0.6 0.7 0.45 0.55 0.65 0.75)
for n in $(seq "$kills"); do
  "$tissue" x3d --dds --dds-domain "$domain" --animate --seconds 5 --timeout 8 -o "$run/k$n.x3d" > /dev/null 2>&1 &
  reader=$!
  sleep "${delays[$(( (n - 1) % 8 ))]}"
  kill -KILL "$reader"
  wait "$reader" 2> /dev/null || true
done
ok=0 fail=0
for c in 1 2 3; do
  if timeout 20 "$tissue" x3d --dds --dds-domain "$domain" --timeout 8 -o "$run/c$c.x3d" > "$run/c$c.log" 2>&1; then
    ok=$((ok + 1))
  else
    fail=$((fail + 1))
    echo "check $c after $kills kills: $(tail -1 "$run/c$c.log")"
  fi
done
"$tissue" ctl --socket "$run/ctl.sock" shutdown > /dev/null 2>&1 || true
wait "$daemon" || true
echo "RESULT ok=$ok fail=$fail"
[ "$fail" -eq 0 ]
