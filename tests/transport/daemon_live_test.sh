#!/bin/sh
# The daemon's live output end to end, between separate processes, inside a
# private network namespace and a private /dev/shm (the ctest entry wraps it):
# tissued publishes a 160 x 160 x 2 slab whose surface message is over 2 MB on
# LCM and Fast DDS; two subscriber processes per transport receive it (tissue
# x3d and tissue render, --lcm and --dds), a fifth subscriber is killed with
# SIGKILL mid-stream, and the daemon goes on publishing without a failure.
# Args: TISSUED_BINARY TISSUE_BINARY
set -eu
tissued="$1"; tissue="$2"
work="$(mktemp -d)"
daemon=""
cleanup() { [ -n "$daemon" ] && kill "$daemon" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
fail() { echo "daemon_live_test: $*" >&2; cat "$work"/*.log >&2 2>/dev/null || true; exit 1; }

. "$(dirname "$0")/daemon_test_support.sh"  # write_slab_scene, start_daemon, status_field
write_slab_scene 160 0.001
lcm_url='udpm://239.255.76.67:7667?ttl=0&recv_buf_size=16777216'
start_daemon --set publish.lcm.enabled=true --set "publish.lcm.url=$lcm_url" \
  --set publish.dds.enabled=true --set publish.dds.domain_id=23
i=0
until [ "$(status_field publishing.lcm.meshes)" -ge 1 ] 2>/dev/null; do
  i=$((i + 1)); [ "$i" -le 300 ] || fail "the daemon published no mesh within 30 s"
  kill -0 "$daemon" 2>/dev/null || fail "the daemon exited"
  sleep 0.1
done

# The victim: collects frames, killed with SIGKILL before it is done.
"$tissue" x3d --lcm "$lcm_url" --animate --seconds 30 -o "$work/victim.x3d" >"$work/victim.log" 2>&1 &
victim=$!
"$tissue" x3d --lcm "$lcm_url" --timeout 30 -o "$work/lcm.x3d" >"$work/lcm_x3d.log" 2>&1 &
a=$!
"$tissue" render --lcm "$lcm_url" --timeout 30 -o "$work/lcm.png" >"$work/lcm_render.log" 2>&1 &
b=$!
"$tissue" x3d --dds --dds-domain 23 --timeout 30 -o "$work/dds.x3d" >"$work/dds_x3d.log" 2>&1 &
c=$!
"$tissue" render --dds --dds-domain 23 --timeout 30 -o "$work/dds.png" >"$work/dds_render.log" 2>&1 &
d=$!
sleep 2
kill -9 "$victim"
wait "$victim" 2>/dev/null || true
for p in $a $b $c $d; do wait "$p" || fail "a subscriber failed (pid $p)"; done

# Every subscriber got the whole surface: over 100k triangles.
for log in lcm_x3d lcm_render dds_x3d dds_render; do
  tris="$(sed -n 's/.* \([0-9][0-9]*\) triangles.*/\1/p' "$work/$log.log" | head -1)"
  [ -n "$tris" ] && [ "$tris" -ge 100000 ] || fail "$log: expected a surface of >= 100000 triangles, got '${tris}'"
done
head -c 8 "$work/lcm.png" | grep -q PNG || fail "lcm.png is not a PNG"
head -c 8 "$work/dds.png" | grep -q PNG || fail "dds.png is not a PNG"

# The daemon is undisturbed: still serving, still publishing, no failure.
m1="$(status_field publishing.lcm.meshes)"; d1="$(status_field publishing.dds.meshes)"
sleep 2
m2="$(status_field publishing.lcm.meshes)"; d2="$(status_field publishing.dds.meshes)"
[ "$m2" -gt "$m1" ] || fail "LCM meshes stopped after the kill ($m1 -> $m2)"
[ "$d2" -gt "$d1" ] || fail "DDS meshes stopped after the kill ($d1 -> $d2)"
[ "$(status_field publishing.lcm.failures)" = 0 ] || fail "LCM publish failures"
[ "$(status_field publishing.dds.failures)" = 0 ] || fail "DDS publish failures"
[ "$(status_field publishing.dds.oversize_meshes)" = 0 ] || fail "DDS meshes held back under the default limit"
echo "daemon_live_test: 4 subscribers got the 2+ MB surface, one killed mid-stream; LCM meshes $m1 -> $m2, DDS $d1 -> $d2"
