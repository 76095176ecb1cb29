#!/usr/bin/env bash
# bench_blocks.sh — the speed benchmark's modes run (tiny sizes, about 1 s; no timings are
# judged): the n³ table with its growth lines, a cantilever box, the FMA peak with the element
# product's fraction of it (must lie in (0, 100 %]), the default tolerance (fewer iterations), and the static solve of a 16×4×4
# cantilever (h = 0.04 m, E = 1e7 Pa), whose tip sag must be within 10 % of Euler–Bernoulli's
# q L⁴ / (8 E I) = 9.64 mm (the corotational FEM gives 9.6 mm; shear adds ~0.5 % at L/t = 4).
# Release build only: the sanitizer build's timings are meaningless. No bus.
set -u
source "$(dirname "$0")/lib.sh"
case "$CS_IT_BIN" in */san/bin) exit 0 ;; esac
B="$CS_IT_BIN/bench_blocks"
T="$CS_TMP" # lib.sh's scratch folder (an EXIT trap of our own would replace lib.sh's, which removes it)
if timeout 120 "$B" --sizes 4,6 --runs 1 --threads 1,2 --precond jacobi,multigrid --csv "$T/b.csv" \
       >"$T/b.md" 2>"$T/b.err" &&
   [ "$(grep -c '^| [46]³' "$T/b.md")" -eq 8 ] && [ "$(wc -l <"$T/b.csv")" -eq 9 ] &&
   [ "$(grep -c 'cost grows as cubes^' "$T/b.err")" -eq 4 ]; then
    cs_pass bench-blocks-sizes
else
    cs_fail bench-blocks-sizes "$(head -c 300 "$T/b.err")"
fi
if timeout 120 "$B" --box 10x3x3 --steps 3 --runs 1 --precond auto --csv "$T/box.csv" >"$T/box.md" 2>&1 &&
   timeout 120 "$B" --box 10x3x3 --young 1e8 --steps 3 --runs 1 --precond auto --csv "$T/box.csv" --append \
       >>"$T/box.md" 2>&1 &&
   awk -F, 'NR > 1 && $14 == "10x3x3" && $5 > 0 && $8 > 0 { n++ } END { exit n != 4 }' "$T/box.csv"; then
    cs_pass bench-blocks-box
else
    cs_fail bench-blocks-box "$(head -c 300 "$T/box.md")"
fi
# --default-tolerance: the solver's default (1e-4 of the step's residual) instead of 1e-6 of ‖b‖,
# so fewer CG iterations per step on the same 8³ block (1.2 against 1.8; deterministic)
if timeout 120 "$B" --sizes 8 --runs 1 --threads 1 --precond multigrid --csv "$T/t.csv" >/dev/null 2>&1 &&
   timeout 120 "$B" --sizes 8 --runs 1 --threads 1 --precond multigrid --default-tolerance \
       --csv "$T/t.csv" --append >/dev/null 2>&1 &&
   awk -F, 'NR == 2 { a = $8 } NR == 3 { b = $8 } END { exit !(NR == 3 && b > 0 && b < a) }' "$T/t.csv"; then
    cs_pass bench-blocks-default-tolerance
else
    cs_fail bench-blocks-default-tolerance "$(tr '\n' ' ' <"$T/t.csv" | head -c 300)"
fi
if timeout 120 "$B" --peak --kernel 8 --calls 5 --runs 1 --threads 1,2 >"$T/p.md" 2>"$T/p.err" &&
   awk -F'|' '/GFLOP/ { next } /^\| AVX/ && $5 + 0 > 0 { pk++ }
              /^\| cs_fem_apply_K/ { f = $8 + 0; if (f > 0 && f <= 100) k++; if (/lattice off/) off++ }
              END { exit !(pk >= 2 && k == 4 && off == 2) }' "$T/p.md"; then
    cs_pass bench-blocks-peak-kernel
else
    cs_fail bench-blocks-peak-kernel "$(cat "$T/p.md" | tr '\n' ' ' | head -c 400)"
fi
if timeout 120 "$B" --static 16x4x4 --h 0.04 --young 1e7 --runs 1 --threads 1 >"$T/s.md" 2>&1 &&
   awk -F'|' '/^\| 16×4×4/ { s = $8 + 0; ok = ($9 ~ /yes/) && s > 0.9 * 0.00964 && s < 1.1 * 0.00964 }
              END { exit !ok }' "$T/s.md"; then
    cs_pass bench-blocks-static
else
    cs_fail bench-blocks-static "$(tr '\n' ' ' <"$T/s.md" | head -c 400)"
fi
cs_finish
