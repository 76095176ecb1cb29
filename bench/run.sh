#!/usr/bin/env bash
# make bench: speed of the corotational implicit step against size, 1 and 2 threads, the
# cost of a fracture event against surface triangles (bench_fracture), localframe against
# corotational FEM, seed 004's mss studies (bench_mss) and the rigid drop demo (bench_rigid).
# Writes bench/results/blocks.csv, blocks.md (the README table) and blocks.svg (log-log plot), then
# the issue 7 figures: the 75×15×15 beam (beam.csv, beam.md), the targets table (targets.md),
# the machine's FMA peak and the element product's share of it (peak.md), the 32×8×8 static
# solve (static.md) and the two-thread speed-ups (blocks.speedup.txt).
# BENCH_SIZES / BENCH_RUNS override the defaults (8,16,32,48,64 and 5 runs; medians are
# reported; 64³ gets BENCH_BIG_RUNS runs, default 3, of 3 steps with Jacobi and 12 with
# multigrid; BENCH_BIG_STEPS sets both).
# BENCH_SKIP_64=1 leaves out 64³ (the longest part: ~2 min idle); BENCH_ONLY_BLOCKS=1 stops
# after the blocks part (skips fracture, localframe, mss, rigid and the work-precision sweep).
set -euo pipefail
cd "$(dirname "$0")/.."
out=bench/results
mkdir -p "$out"
if [ "${BENCH_SKIP_64:-0}" = 1 ]; then sizes=${BENCH_SIZES:-8,16,32,48}; else sizes=${BENCH_SIZES:-8,16,32,48,64}; fi
runs=${BENCH_RUNS:-5}
big="--big-runs ${BENCH_BIG_RUNS:-3}${BENCH_BIG_STEPS:+ --big-steps $BENCH_BIG_STEPS}"
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), load $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$out/machine.txt"
echo "bench_blocks: peak FMA rate and the element product on 32³, threads 1 and 2"
build/bin/bench_blocks --peak --kernel 32 --runs "$runs" --threads 1,2 \
  2> "$out/peak.speedup.txt" | tee "$out/peak.md"
echo "bench_blocks: sizes $sizes, $runs runs each, block Jacobi and multigrid, threads 1 and 2"
build/bin/bench_blocks --sizes "$sizes" --runs "$runs" $big --threads 1,2 --precond jacobi,multigrid \
  --csv "$out/blocks.csv" \
  2> "$out/blocks.growth.txt" | tee "$out/blocks.md"
cat "$out/blocks.growth.txt"
# The 75×15×15 cantilever (h = 0.04 m: a 3 m × 0.6 m × 0.6 m beam, end x = 0 held), preconditioner
# auto, at the scene default E = 1e5 Pa (a jelly: it folds down) and at E = 1e8 Pa (a stiff
# beam: its static tip sag is about 1 % of its length).
# beams NAME [ARGS]: both beams into $out/NAME.csv and NAME.md, ARGS passed to bench_blocks.
beams() {
  local name=$1
  shift
  build/bin/bench_blocks --box 75x15x15 --h 0.04 --young 1e5 --precond auto --runs "$runs" --threads 1,2 \
    "$@" --csv "$out/$name.csv" 2>/dev/null | tee "$out/$name.md"
  build/bin/bench_blocks --box 75x15x15 --h 0.04 --young 1e8 --precond auto --runs "$runs" --threads 1,2 \
    "$@" --csv "$out/$name.csv" --append 2>/dev/null | tee -a "$out/$name.md"
}
echo "bench_blocks: 75×15×15 cantilever, E = 1e5 and 1e8 Pa, auto, threads 1 and 2"
beams beam
# Sustained runs: the same beams over 120 steps (2 s of simulated time: the beam sags, swings
# and the warm start has its directions) and 64³ over 60 steps (1 s), after the first 12 steps
# from rest above, which are the hardest (6–8 CG iterations per step against 2–3 later).
# BENCH_SUSTAINED_STEPS / BENCH_SUSTAINED_BIG_STEPS override 120 / 60; BENCH_SKIP_64=1 leaves
# out 64³ here too.
ssteps=${BENCH_SUSTAINED_STEPS:-120}
sbig=${BENCH_SUSTAINED_BIG_STEPS:-60}
echo "bench_blocks: sustained: 75×15×15 cantilever over $ssteps steps, 64³ over $sbig steps"
beams beam_sustained --steps "$ssteps"
rm -f "$out/blocks_sustained.csv"
if [ "${BENCH_SKIP_64:-0}" != 1 ]; then
  build/bin/bench_blocks --sizes 64 --precond multigrid --big-runs "${BENCH_BIG_RUNS:-3}" \
    --big-steps "$sbig" --threads 1,2 --csv "$out/blocks_sustained.csv" 2>/dev/null |
    tee "$out/blocks_sustained.md"
fi
# Targets (issue 7): >= 100 steps/s for the beam, >= 11 steps/s for 64³ (auto = multigrid there),
# under both protocols: the first steps from rest (the tables above) and sustained.
{
  # "from CPU time" = 1000 / CPU ms per step × threads: the rate had the threads had their cores.
  echo "| scene | steps counted | threads | steps/s (wall) | steps/s from CPU time | target | ratio (wall) | ratio (CPU) |"
  echo "|---|---|---|---|---|---|---|---|"
  beam_rows() {
    awk -F, -v what="$2" 'NR>1 { split($14, d, "x"); c = 1000 / $7 * $3; printf "| %s×%s×%s beam, E = %s Pa | %s | %d | %.2f | %.2f | 100 | %.2f | %.2f |\n", d[1], d[2], d[3], $15, what, $3, $5, c, $5/100, c/100 }' "$1"
  }
  big_rows() {
    [ -f "$1" ] || return 0
    awk -F, -v what="$2" 'NR>1 && $1==262144 && $2=="multigrid" { c = 1000 / $7 * $3; printf "| 64³ block (auto = multigrid) | %s | %d | %.2f | %.2f | 11 | %.3f | %.3f |\n", what, $3, $5, c, $5/11, c/11 }' "$1"
  }
  beam_rows "$out/beam.csv" "12 from rest"
  beam_rows "$out/beam_sustained.csv" "$ssteps (sustained)"
  big_rows "$out/blocks.csv" "${BENCH_BIG_STEPS:-12} from rest"
  big_rows "$out/blocks_sustained.csv" "$sbig (sustained)"
} | tee "$out/targets.md"
# The same scenes at the solver's default tolerance (1e-4 of the step's residual, what a scene
# without "solver" gets) instead of issue 7's 1e-6 of ‖b‖: the speed a user sees by default.
# Two threads; the beams' and 64³'s rows of both protocols into targets_default_tol.md.
echo "bench_blocks: the beams and 64³ at the solver's default tolerance, two threads"
rm -f "$out/default_tol.csv"
for e in 1e5 1e8; do
  for st in 12 "$ssteps"; do
    build/bin/bench_blocks --box 75x15x15 --h 0.04 --young "$e" --precond auto --runs "$runs" \
      --threads 2 --steps "$st" --default-tolerance --csv "$out/default_tol.csv" --append \
      >/dev/null 2>&1
  done
done
if [ "${BENCH_SKIP_64:-0}" != 1 ]; then
  for st in 12 "$sbig"; do
    build/bin/bench_blocks --sizes 64 --precond multigrid --big-runs "${BENCH_BIG_RUNS:-3}" \
      --big-steps "$st" --threads 2 --default-tolerance --csv "$out/default_tol.csv" --append \
      >/dev/null 2>&1
  done
fi
{
  echo "| scene (default tolerance) | steps counted | threads | steps/s (wall) | CG it/step | target | ratio (wall) |"
  echo "|---|---|---|---|---|---|---|"
  # rows in the order run: per beam 12 then $ssteps steps; 64³ 12 then $sbig
  awk -F, -v s="$ssteps" -v b="$sbig" '
    $1 == 16875 { split($14, d, "x"); printf "| %s×%s×%s beam, E = %s Pa | %s | %d | %.2f | %.1f | 100 | %.2f |\n", d[1], d[2], d[3], $15, (++k[$15] == 1 ? "12 from rest" : s " (sustained)"), $3, $5, $8, $5/100 }
    $1 == 262144 { printf "| 64³ block (multigrid) | %s | %d | %.2f | %.1f | 11 | %.3f |\n", (++k["64"] == 1 ? "12 from rest" : b " (sustained)"), $3, $5, $8, $5/11 }' "$out/default_tol.csv"
} | tee "$out/targets_default_tol.md"
echo "bench_blocks: static solve of a 32×8×8 cantilever (h = 0.04 m, E = 1e7 Pa)"
build/bin/bench_blocks --static 32x8x8 --h 0.04 --young 1e7 --runs 3 --threads 1,2 \
  2> "$out/static.speedup.txt" | tee "$out/static.md"
# Two-thread speed-up per size, preconditioner and material (columns: cubes,precond,threads,runs,
# steps_per_s,ms_per_step,...,shape,young); the product's and the static solve's below.
{
  cat "$out/blocks.csv" "$out/beam.csv" | awk -F, '$1 != "cubes" { k=$14" ("$2", E = "$15")"; ms[k","$3]=$6; c[k]=$1 }
    END { for (k in c) if (ms[k",2"] > 0) printf "  speed-up with 2 threads at %d cubes, %s: %.2fx\n", c[k], k, ms[k",1"]/ms[k",2"] }' | sort -t' ' -k6 -n
  cat "$out/peak.speedup.txt"
  cat "$out/static.speedup.txt"
} | tee "$out/blocks.speedup.txt"
if command -v gnuplot >/dev/null; then
  gnuplot <<GP
set terminal svg size 640,420
set output "$out/blocks.svg"
set datafile separator ","
set logscale xy
set xlabel "cubes"
set ylabel "ms per step (median)"
set title "corotational implicit Euler step, dt = 1/60 s"
set key left top
plot "< awk -F, 'NR>1 && \$2==\"jacobi\" && \$3==1' $out/blocks.csv" using 1:6 with linespoints title "Jacobi, 1 thread", \
     "< awk -F, 'NR>1 && \$2==\"jacobi\" && \$3==2' $out/blocks.csv" using 1:6 with linespoints title "Jacobi, 2 threads", \
     "< awk -F, 'NR>1 && \$2==\"multigrid\" && \$3==1' $out/blocks.csv" using 1:6 with linespoints title "multigrid, 1 thread", \
     "< awk -F, 'NR>1 && \$2==\"multigrid\" && \$3==2' $out/blocks.csv" using 1:6 with linespoints title "multigrid, 2 threads", \
     "< awk -F, 'NR>1 && \$2==\"jacobi\" && \$3==1' $out/blocks.csv" using 1:(\$1*0.004) with lines dt 2 title "linear in cubes"
GP
  echo "plot: $out/blocks.svg"
fi

[ "${BENCH_ONLY_BLOCKS:-0}" = 1 ] && exit 0

# Fracture: the cost of one fracture event against surface triangles at a fixed cube count.
# Writes bench/results/fracture.csv, fracture.md, fracture.growth.txt and fracture.svg.
# BENCH_FRACTURE_LEVELS / BENCH_FRACTURE_RUNS override the defaults (4..8: 1k..256k triangles).
flevels=${BENCH_FRACTURE_LEVELS:-4,5,6,7,8}
fruns=${BENCH_FRACTURE_RUNS:-$runs}
echo "bench_fracture: sphere levels $flevels (4·4^L triangles), $fruns runs each"
build/bin/bench_fracture --levels "$flevels" --runs "$fruns" --csv "$out/fracture.csv" \
  2> "$out/fracture.growth.txt" | tee "$out/fracture.md"
cat "$out/fracture.growth.txt"
if command -v gnuplot >/dev/null; then
  if awk -F, 'NR>1 && ($5+0 > 0 || $6+0 > 0) { found=1 } END { exit !found }' "$out/fracture.csv"; then
    gnuplot <<GP
set terminal svg size 640,420
set output "$out/fracture.svg"
set datafile separator ","
set datafile missing "nan"
set logscale xy
set xlabel "surface triangles"
set ylabel "ms (median)"
set title "one fracture event at a fixed cube count"
set key left top
plot "$out/fracture.csv" every ::1 using 2:5 with linespoints title "cs_world_fracture", \
     "$out/fracture.csv" every ::1 using 2:6 with linespoints title "loaded step that breaks", \
     "$out/fracture.csv" every ::1 using 2:7 with linespoints title "loaded step, intact"
GP
    echo "plot: $out/fracture.svg"
  else
    echo "no fracture plot: no size fractured (is the engine's fracture built?)"
  fi
fi

# localframe (seed 001) against corotational FEM: tip error of a ν = 0 cantilever in pure
# bending (exact answer known), static solve time, and wall seconds per simulated second of
# central differences (at 0.9 × each model's stability limit) and implicit Euler (1/60 s).
# Writes bench/results/localframe.csv, localframe.md and localframe.svg.
# BENCH_LF_SIZES overrides the cubes through the thickness (default 2,3,4,6).
lfsizes=${BENCH_LF_SIZES:-2,3,4,6}
echo "bench_localframe: nz $lfsizes, $runs runs of the static solve"
build/bin/bench_localframe --sizes "$lfsizes" --runs "$runs" --csv "$out/localframe.csv" \
  2> "$out/localframe.iterations.txt" | tee "$out/localframe.md"
cat "$out/localframe.iterations.txt"
if command -v gnuplot >/dev/null; then
  gnuplot <<GP
set terminal svg size 640,420
set output "$out/localframe.svg"
set datafile separator ","
set logscale xy
set xlabel "wall seconds per simulated second (central differences)"
set ylabel "|tip error| under pure bending (%)"
set title "localframe vs corotational FEM, cantilever nz = $lfsizes"
set key right top
plot "< awk -F, 'NR>1 && \$1==\"localframe\"' $out/localframe.csv" using 7:(abs(\$4)) with linespoints title "localframe (central differences)", \
     "< awk -F, 'NR>1 && \$1==\"corotational\"' $out/localframe.csv" using 7:(abs(\$4)) with linespoints title "corotational (central differences)", \
     "< awk -F, 'NR>1 && \$1==\"corotational\"' $out/localframe.csv" using 8:(abs(\$4)) with linespoints title "corotational (implicit Euler, 1/60 s)"
GP
  echo "plot: $out/localframe.svg"
fi
# Seed 004 §4: the mss cantilever and L-shaped shear studies against a fine corotational FEM
# reference. Writes bench/results/mss_cantilever.csv, mss_lshape.csv and mss.md (the README
# tables). BENCH_MSS_REF / BENCH_MSS_LREF override the references (cubes across the cantilever's 100 mm,
# default 24; per 2 m of the L, default 24).
mref=${BENCH_MSS_REF:-24}
echo "bench_mss: seed 004 studies, reference FEM at $mref cubes across"
build/bin/bench_mss --ref "$mref" --lref "${BENCH_MSS_LREF:-24}" --csv-cantilever "$out/mss_cantilever.csv" \
  --csv-lshape "$out/mss_lshape.csv" | tee "$out/mss.md"

# Rigid bodies: the drop demo headless (real-time factor, pieces checked closed).
echo "bench_rigid: scenes/drop.json, 2 s"
build/bin/bench_rigid scenes/drop.json 2 | tee "$out/rigid_drop.txt"
echo "bench_rigid: boxes falling and sleeping, N = 4, 8, 16 (2·N² boxes)"
for n in 4 8 16; do build/bin/bench_rigid --boxes $n; done | tee "$out/rigid_boxes.txt"
echo "bench_rigid: boxes on a held deformable slab, grid broad phase against the plain loop, N = 2, 4, 8"
for n in 2 4 8; do build/bin/bench_rigid --slab $n; done | tee "$out/rigid_slab.txt"

# Work-precision (issue 6): run time against error for every model and integrator, sweeping
# the cube size, dt and the CG tolerance, on a ν = 0 cantilever against Timoshenko beam theory
# and Richardson-extrapolated fine-mesh references. Writes bench/results/wp_static.csv,
# wp_dynamic.csv, wp_pareto.csv, wp_refs.txt, wp.md (the README tables) and wp_<case>.svg.
# BENCH_WP_RUNS (default 3) and BENCH_WP_ARGS (e.g. --quick, --wide, --cap 15) adjust it; ~15-20 min
# on a shared machine, < 1 min with --quick.
wpruns=${BENCH_WP_RUNS:-3}
echo "bench_wp: work-precision sweep ($wpruns runs of each setting shorter than 1 s; CPU time)"
build/bin/bench_wp --runs "$wpruns" --out "$out" --check ${BENCH_WP_ARGS:-} \
  2> "$out/wp_runs.txt" | tee "$out/wp.md"
build/bin/bench_tol --runs "$wpruns" --csv "$out/tol.csv" 2> "$out/tol_runs.txt" | tee "$out/tol.md" # the CG tolerance beyond bending: contact, momentum, drags, fracture, drops (README "Defaults (issue 6 part 3)")
if command -v gnuplot >/dev/null; then
  ci=0
  for c in static_small dyn freq amp static_large; do
    case $c in
      static_small) title="static tip deflection, small (vs Timoshenko)";;
      dyn) title="released cantilever: max(frequency, amplitude) error";;
      freq) title="released cantilever: first-mode frequency error";;
      amp) title="released cantilever: amplitude lost over 2 periods";;
      static_large) title="large rotation (tip drop L/3) vs converged corotational";;
    esac
    gnuplot <<GP
set terminal svg size 640,420
set output "$out/wp_$c.svg"
set datafile separator ","
set logscale xy
set xlabel "CPU seconds (median, 1 thread)"
set ylabel "relative error"
set title "$title"
set key right top
plot "$out/wp_pareto.csv" index $((ci*4+0)) using 3:5 with linespoints title "linear", \
     "$out/wp_pareto.csv" index $((ci*4+1)) using 3:5 with linespoints title "corotational", \
     "$out/wp_pareto.csv" index $((ci*4+2)) using 3:5 with linespoints title "mss", \
     "$out/wp_pareto.csv" index $((ci*4+3)) using 3:5 with linespoints title "localframe"
GP
    ci=$((ci+1))
  done
  echo "plots: $out/wp_*.svg"
fi

# The bus keeps up (issue 7 part 3): a 100 000-vertex surface's deltas at 60 Hz to two clients
# for 30 s (BUS_SECONDS, BUS_VERTICES, BUS_CLIENTS, BUS_RECV_BUF scale it), in a private network
# namespace (needs root or unprivileged user namespaces) -> bench/results/bus.md.
echo "== bus: 100k-vertex surface deltas at 60 Hz to 2 clients"
bash bench/bus.sh || echo "bench/bus.sh: frames lost or incomplete (see bench/results/bus.md)"
