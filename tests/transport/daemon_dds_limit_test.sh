#!/bin/sh
# publish.dds.max_mesh_bytes in the daemon, inside a private network
# namespace and /dev/shm (the ctest entry wraps it): a surface whose DDS
# message is over the limit is not sent, `status` counts it in
# publishing.dds.oversize_meshes (and failures), stderr says so once naming
# the key, its size and the limit, and the small topics go on.
# Args: TISSUED_BINARY TISSUE_BINARY
set -eu
tissued="$1"; tissue="$2"
work="$(mktemp -d)"
daemon=""
cleanup() { [ -n "$daemon" ] && kill "$daemon" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
fail() { echo "daemon_dds_limit_test: $*" >&2; cat "$work/daemon.log" >&2 2>/dev/null || true; exit 1; }

. "$(dirname "$0")/daemon_test_support.sh"  # write_slab_scene, start_daemon, status_field
# 40 x 40 x 2 cubes: 7,040 surface triangles, a DDS message of 158,516 bytes.
write_slab_scene 40 0.004
start_daemon --set publish.dds.enabled=true --set publish.dds.domain_id=29 --set publish.dds.max_mesh_bytes=65536
i=0
until [ "$(status_field publishing.dds.oversize_meshes)" -ge 3 ] 2>/dev/null; do
  i=$((i + 1)); [ "$i" -le 300 ] || fail "no oversize mesh counted within 30 s"
  kill -0 "$daemon" 2>/dev/null || fail "the daemon exited"
  sleep 0.1
done
stats="$(status_field publishing.dds.stats)"
[ "$(status_field publishing.dds.meshes)" = 0 ] || fail "a mesh over the limit was sent"
oversize="$(status_field publishing.dds.oversize_meshes)"
failures="$(status_field publishing.dds.failures)"
[ "$failures" -ge "$oversize" ] || fail "failures $failures < oversize_meshes $oversize"
said="$(grep -c 'is over publish.dds.max_mesh_bytes (65536) and was not sent' "$work/daemon.log" || true)"
[ "$said" = 1 ] || fail "the oversize mesh was said $said times for $oversize meshes, expected once"
grep -q 'DDS: a surface mesh of [0-9]* bytes serialized is over publish.dds.max_mesh_bytes (65536)' "$work/daemon.log" ||
  fail "the message does not give the size"
# The small topics still go out.
i=0
until [ "$(status_field publishing.dds.stats)" -gt "$stats" ] 2>/dev/null; do
  i=$((i + 1)); [ "$i" -le 100 ] || fail "sim_stats stopped"
  sleep 0.1
done
echo "daemon_dds_limit_test: $oversize meshes held back, said once; stats went on"
