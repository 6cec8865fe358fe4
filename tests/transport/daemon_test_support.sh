# Sourced by the daemon's live tests. They set $tissued and $tissue (the
# daemon and client binaries) and $work (a scratch directory); the daemon's
# control socket is $work/c.sock and its output $work/daemon.log.

# write_slab_scene CUBES CUBE_SIZE_M: $work/slab.yaml, a CUBES x CUBES x 2
# slab of cubes clamped along x = 0, at rest (no load, no gravity): the
# implicit solve converges at once, so a big surface costs the sim thread
# little and snapshots keep coming.
write_slab_scene() {
  python3 - "$1" "$2" >"$work/slab.yaml" <<'PY'
import sys
n, h = int(sys.argv[1]), float(sys.argv[2])
print(f"""name: slab
object:
  cubes: [{n}, {n}, 2]
  cube_size_m: {h}
material:
  youngs_modulus_Pa: 5.0e4
  density_kg_per_m3: 100
gravity_m_per_s2: [0, 0, 0]
fixed:
  - region: {{box: {{min_m: [0, 0, 0], max_m: [0, {n * h:g}, {2 * h:g}]}}}}
adaptivity:
  enabled: false
integrator:
  kind: implicit
  dt_s: 0.001""")
PY
}

# start_daemon [--set KEY=VALUE ...]: tissued on the slab for up to 60 s with
# the shipped config, its socket and state in $work, no SCHED_FIFO; its pid
# in $daemon.
start_daemon() {
  "$tissued" --config "$(dirname "$0")/../../config/tissued.yaml" --duration 60 \
    --set "scene=$work/slab.yaml" --set "control.unix_socket_path=$work/c.sock" --set "state_dir=$work" \
    --set realtime.sched_fifo=false "$@" >"$work/daemon.log" 2>&1 &
  daemon=$!
}

# status_field KEY.PATH prints one field of `tissue ctl status` (e.g.
# publishing.dds.meshes), or -1 when the daemon does not answer or has no
# such field.
status_field() {
  "$tissue" ctl --socket "$work/c.sock" status 2>/dev/null |
    python3 -c 'import json,sys
v=json.load(sys.stdin)
for k in sys.argv[1].split("."): v=v[k]
print(v)' "$1" 2>/dev/null || echo -1
}
