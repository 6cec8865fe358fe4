#!/bin/sh
# `cmake --install` of a build tree (the install rules of the top-level
# CMakeLists.txt) into a scratch prefix: what systemd/README.md and
# clients/python/README.md tell a lab to use is there, and the installed
# Python subscriber finds its generated types beside itself.
# Args: BUILD_DIR
set -eu
build="$1"
prefix="$(mktemp -d)"
trap 'rm -rf "$prefix"' EXIT
cmake --install "$build" --prefix "$prefix" >"$prefix.log" 2>&1 || { cat "$prefix.log"; rm -f "$prefix.log"; exit 1; }
rm -f "$prefix.log"
fail=0
for f in bin/tissued bin/tissue share/tissued/tissued.yaml share/tissued/scenes/cantilever.yaml \
  lib/systemd/system/tissued.service lib/sysusers.d/tissued.conf share/doc/tissued/control-protocol.md \
  share/tissued/python/tissue_subscriber.py share/tissued/python/README.md \
  share/tissued/python/tissue/sim_stats.py share/tissued/python/tissue/surface_mesh.py; do
  [ -e "$prefix/$f" ] || { echo "install_test: $f is not installed"; fail=1; }
done
[ -x "$prefix/share/tissued/python/tissue_subscriber.py" ] || { echo "install_test: the subscriber is not executable"; fail=1; }
# The installed script's own search finds the installed types (no --types).
found="$(cd / && python3 -c "import sys; sys.path.insert(0, '$prefix/share/tissued/python'); import tissue_subscriber as t; print(t.find_types(None))")"
[ "$found" = "$prefix/share/tissued/python" ] || { echo "install_test: the subscriber found types at '$found'"; fail=1; }
"$prefix/bin/tissued" --help >/dev/null || { echo "install_test: the installed tissued does not run"; fail=1; }
exit "$fail"
