#!/usr/bin/env bash
# bench_wp.sh — the work-precision harness works: `bench_wp --quick --check` (about 15 s CPU)
# runs every model and integrator on the coarse meshes and checks itself: the Richardson-
# extrapolated fine mesh agrees with Timoshenko's static deflection within 0.5 % and with
# Euler–Bernoulli's ω₁ within 3 %, the corotational error falls from 1 to 2 cubes through the
# thickness, the large-rotation case drops its tip by about L/3, and a corotational run is
# within 8 % of ω₁. Here we also require every model in the CSVs and a finite error for the
# implicit Euler runs. Release build only: under the sanitizers the sweep takes minutes and
# its timings mean nothing (the same code runs there in the unit tests' worlds anyway). No bus.
set -u
source "$(dirname "$0")/lib.sh"
case "$CS_IT_BIN" in */san/bin) exit 0 ;; esac
B="$CS_IT_BIN/bench_wp"
T="$CS_TMP" # lib.sh's scratch folder (an EXIT trap of our own would replace lib.sh's, which removes it)
timeout 300 "$B" --quick --check --out "$T" >"$T/out" 2>"$T/err"; rc=$?
if [ $rc -eq 0 ] && grep -q "^check: ok" "$T/err"; then
    cs_pass bench-wp-quick-check
else
    cs_fail bench-wp-quick-check "exit $rc: $(grep '^check' "$T/err" | tr '\n' ' ')"
fi
if awk -F, 'NR > 1 && $2 == "implicit_euler" && $11 != "nan" { seen[$1] = 1 }
            END { exit !(seen["linear"] && seen["corotational"] && seen["mss"] && seen["localframe"]) }' \
       "$T/wp_dynamic.csv" &&
   [ "$(grep -c '^static_small' "$T/wp_static.csv")" -ge 16 ] && grep -q '^| localframe' "$T/out"; then
    cs_pass bench-wp-quick-outputs
else
    cs_fail bench-wp-quick-outputs "a model is missing from wp_dynamic.csv / wp_static.csv / the tables"
fi
cs_finish
