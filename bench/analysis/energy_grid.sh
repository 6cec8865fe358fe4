#!/usr/bin/env bash
# The stability bar from the outside: the shipped cantilever in batch over
# load x E x dt x CG cap (implicit) and load x E x dt (projective, explicit),
# one line per run with the report's energy audit, energy guard and inverted
# tets. Pass = worst_excess 0 (never more energy than E0 + work), no error
# except the explicit rung's refusal above max_substeps.
#
#   bench/analysis/energy_grid.sh [path/to/tissued]   (default build/dev/daemon/tissued)
#
# About 3 minutes on 2 cores. No network: batch runs open no socket.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
tissued="${1:-$root/build/dev/daemon/tissued}"
scene="$root/config/scenes/cantilever.yaml"
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
line() {  # kind F E dt cg
  local report="$out/r.json"
  local args=(--batch --scene "$scene" --duration 2 --progress 0 --no-timing --report "$report"
    --set "integrator.kind=$1" --set "loads[0].total_force_N=[0,0,-$2]" --set "material.youngs_modulus_Pa=$3"
    --set "integrator.dt_s=$4")
  [ "$5" != "-" ] && args+=(--set "integrator.cg_max_iterations=$5")
  "$tissued" "${args[@]}" >/dev/null 2>&1 || true
  /usr/bin/python3 - "$report" "$@" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))["result"]
kind, F, E, dt, cg = sys.argv[2:7]
lim = r["solver"]["energy_limited"]
err = (r["error"] or "")[:60]
print(f"{kind:10} F {F:>4} N  E {E:>4}  dt {float(dt):.4g}  cg {cg:>3}  excess {r['energy_audit']['worst_excess']:.3g}"
      f"  guard {lim['steps']} steps {lim['removed_J']:.3g} J  inverted {r['inverted_tets']['peak']}  {err}")
PY
}
for F in 5 1000; do for E in 1e3 5e4 1e6 1e9; do for dt in 0.001 0.01 0.0333333333333; do
  for cg in 1 3 10 100; do line implicit $F $E $dt $cg; done
  line projective $F $E $dt -
  line explicit $F $E $dt -
done; done; done | tee "$out/all.txt"
echo
# Over budget: an excess above 1e-6 (the guard leaves 1e-9 of room for rounding).
echo "runs: $(wc -l < "$out/all.txt");" \
  "over budget: $(awk '{for (i = 1; i < NF; ++i) if ($i == "excess" && $(i + 1) + 0 > 1e-6) n++} END {print n + 0}' "$out/all.txt");" \
  "implicit runs the guard acted in: $(grep -c '^implicit .* guard [1-9]' "$out/all.txt" || true);" \
  "explicit refusals: $(grep -c 'explicit integrator:' "$out/all.txt" || true)"
