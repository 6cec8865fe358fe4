# Sourced by the daemon's live tests: status_field KEY.PATH prints one field
# of `tissue ctl status` (e.g. publishing.dds.meshes), or -1 when the daemon
# does not answer or has no such field. Needs $tissue (the client binary) and
# $work (the directory holding the control socket c.sock).
status_field() {
  "$tissue" ctl --socket "$work/c.sock" status 2>/dev/null |
    python3 -c 'import json,sys
v=json.load(sys.stdin)
for k in sys.argv[1].split("."): v=v[k]
print(v)' "$1" 2>/dev/null || echo -1
}
