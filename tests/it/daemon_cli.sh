#!/usr/bin/env bash
# daemon_cli.sh — cubesimd's command line and scene errors: each bad invocation exits 2 with
# one stderr line naming the problem; good runs exit 0 and write their outputs (--steps,
# --duration, --static + --dump-nodes on scenes/cantilever.json). Inside a private network
# namespace, since a run that gets past its scene opens the bus.
set -u
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
D="$CS_IT_BIN/cubesimd"

cat >"$CS_TMP/ok.json" <<'JSON'
{ "dt": 0.01, "gravity": [0, 0, -9.81],
  "materials": { "m": { "young": 1e4, "poisson": 0.3, "density": 100.0 } },
  "objects": [ { "name": "cube", "model": "linear", "material": "m", "cube_size": 0.05,
                 "box": { "min": [0, 0, 0], "size": [0.1, 0.05, 0.05] },
                 "fixed": [ { "min": [-0.001, -1, -1], "max": [0.001, 1, 1] } ] } ] }
JSON
mesh_scene() { # mesh_scene FILE: a scene whose one object is the mesh FILE
    cat <<JSON
{ "materials": { "m": { "young": 1e4, "poisson": 0.3, "density": 100.0 } },
  "objects": [ { "name": "thing", "material": "m", "cube_size": 0.05,
                 "mesh": { "file": "$1" } } ] }
JSON
}
printf '{ "dt": 0.01, "objects": [ { "name": "a", }\n' >"$CS_TMP/malformed.json"
mesh_scene missing_mesh.obj >"$CS_TMP/missing.json"
printf 'ply\nformat ascii 1.0\nelement vertex banana\nend_header\n1 2\n' >"$CS_TMP/rejected.ply"
mesh_scene rejected.ply >"$CS_TMP/rejected.json"
head -c 300 /dev/urandom >"$CS_TMP/noise.stl"; printf 'solid x\nfacet normal nonsense\n' >>"$CS_TMP/noise.stl"
mesh_scene noise.stl >"$CS_TMP/noise.json"
sed 's/"young": 1e4/"young": "hard"/' "$CS_TMP/ok.json" >"$CS_TMP/illtyped.json"
sed -E 's/"dt": *[0-9.e-]+/"dt": 1e-9/' "$CS_TMP/ok.json" >"$CS_TMP/tinydt.json"
sed -E 's/"dt": *[0-9.e-]+/"dt": 5/' "$CS_TMP/ok.json" >"$CS_TMP/hugedt.json"

# expect_exit2 NAME PATTERN ARGS...: exit status 2, exactly one stderr line, matching PATTERN.
expect_exit2() {
    local name=$1 pat=$2; shift 2
    local err rc
    err=$(timeout 20 "$D" "$@" 2>&1 >/dev/null)
    rc=$?
    if [ "$rc" -ne 2 ]; then cs_fail "$name" "exit status $rc, expected 2 (stderr: ${err//$'\n'/ | })"; return; fi
    if [ "$(grep -c . <<<"$err")" -ne 1 ]; then cs_fail "$name" "not one stderr line: ${err//$'\n'/ | }"; return; fi
    if ! grep -Eq "^cubesimd: .*($pat)" <<<"$err"; then cs_fail "$name" "stderr '$err' does not match /$pat/"; return; fi
    cs_pass "$name"
}

S="$CS_TMP/ok.json"
expect_exit2 cli-unknown-flag "unknown option '--bogus'" --scene "$S" --bogus
expect_exit2 cli-stray-argument "unknown argument 'extra'" --scene "$S" extra
expect_exit2 cli-no-scene '--scene FILE is required' --steps 3
expect_exit2 cli-missing-value '--scene needs a value' --scene
expect_exit2 cli-steps-zero "--steps '0'" --scene "$S" --steps 0
expect_exit2 cli-steps-text "--steps 'ten'" --scene "$S" --steps ten
expect_exit2 cli-duration-negative "--duration '-1'" --scene "$S" --duration -1
expect_exit2 cli-duration-nan "--duration 'nan'" --scene "$S" --duration nan
expect_exit2 cli-steps-and-duration 'exclude each other' --scene "$S" --steps 2 --duration 1
# outputs that cannot be written are refused before the run, not after it
expect_exit2 cli-export-unknown-format "no assimp exporter for the extension '.off'" --scene "$S" --steps 1 --export "$CS_TMP/x.off"
expect_exit2 cli-export-missing-dir "--export: cannot write in '$CS_TMP/nodir'" --scene "$S" --steps 1 --export "$CS_TMP/nodir/x.obj"
expect_exit2 cli-dump-missing-dir "--dump-nodes: cannot write in '$CS_TMP/nodir'" --scene "$S" --steps 1 --dump-nodes "$CS_TMP/nodir/x.csv"
# a scene path longer than messages show whole: named once, by its end (it was printed whole and
# then again cut)
LONGD="$CS_TMP/$(printf 'd%.0s' {1..70})/$(printf 'e%.0s' {1..70})"
mkdir -p "$LONGD" && sed 's/"young": 1e4/"young": "hard"/' "$S" >"$LONGD/long_scene.json"
expect_exit2 cli-long-scene-path '…/e+/long_scene.json: materials.m.young' --scene "$LONGD/long_scene.json"
n=$(timeout 20 "$D" --scene "$LONGD/long_scene.json" 2>&1 >/dev/null | grep -o 'long_scene.json' | wc -l)
[ "$n" -eq 1 ] && cs_pass cli-long-scene-path-once || cs_fail cli-long-scene-path-once "named $n times"
# a duration whose step count would not fit (it wrapped and ran one step, exit 0)
expect_exit2 cli-duration-huge 'at most 1e15' --scene "$S" --duration 1e20
expect_exit2 cli-static-and-steps '--static cannot be combined' --scene "$S" --static --steps 2
# LCM itself prints a line about an unknown provider: only our last line is checked here.
err=$(timeout 20 "$D" --quiet --scene "$S" --lcm nosuch://x --steps 1 2>&1 >/dev/null); rc=$?
if [ $rc -eq 2 ] && tail -1 <<<"$err" | grep -q "^cubesimd: cannot open the LCM bus at 'nosuch://x'"; then
    cs_pass cli-bad-lcm-url
else
    cs_fail cli-bad-lcm-url "exit $rc, stderr: ${err//$'\n'/ | }"
fi
expect_exit2 scene-missing-file 'nothere.json' --scene "$CS_TMP/nothere.json" --steps 1
expect_exit2 scene-malformed-json 'malformed.json' --scene "$CS_TMP/malformed.json" --steps 1
expect_exit2 scene-ill-typed-field 'young' --scene "$CS_TMP/illtyped.json" --steps 1
expect_exit2 scene-tiny-dt 'dt must be in \[1e-06, 1\] s, got 1e-09' --scene "$CS_TMP/tinydt.json" --steps 1
expect_exit2 scene-huge-dt 'dt: must be in \(0, 1\], got 5' --scene "$CS_TMP/hugedt.json" --steps 1
expect_exit2 scene-missing-mesh 'missing_mesh.obj' --scene "$CS_TMP/missing.json" --steps 1
expect_exit2 scene-mesh-assimp-rejects 'rejected.ply' --scene "$CS_TMP/rejected.json" --steps 1
expect_exit2 scene-mesh-noise 'noise.stl' --scene "$CS_TMP/noise.json" --steps 1

out=$("$D" --help 2>&1); rc=$?
if [ $rc -eq 0 ] && grep -q -- '--dump-nodes' <<<"$out"; then cs_pass cli-help; else cs_fail cli-help "exit $rc"; fi

# --steps: exit 0, outputs written; 2x1x1 cubes -> 3*2*2 = 12 nodes, 10 steps of sagging.
"$D" --scene "$S" --quiet --steps 10 --dump-nodes "$CS_TMP/n.csv" --export "$CS_TMP/o.obj" 2>"$CS_TMP/err"
rc=$?
if [ $rc -eq 0 ] && [ "$(head -1 "$CS_TMP/n.csv")" = "x,y,z,ux,uy,uz" ] && [ "$(wc -l <"$CS_TMP/n.csv")" -eq 13 ] \
    && grep -Eq '^(g|o) cube' "$CS_TMP/o.obj"; then
    cs_pass cli-steps-outputs
else
    cs_fail cli-steps-outputs "exit $rc, $(wc -l <"$CS_TMP/n.csv" 2>/dev/null) csv lines, stderr: $(head -2 "$CS_TMP/err" | tr '\n' ' ')"
fi
# the free end sagged (uz < 0) and the fixed end did not move
if awk -F, 'NR > 1 && $1 > 0.099 && $6 < 0 { sag = 1 } NR > 1 && $1 < 0.001 && ($4 != 0 || $5 != 0 || $6 != 0) { moved = 1 }
            END { exit !(sag && !moved) }' "$CS_TMP/n.csv"; then
    cs_pass cli-steps-physics
else
    cs_fail cli-steps-physics "free end did not sag or fixed end moved"
fi
if [ ! -s "$CS_TMP/err" ]; then cs_pass cli-quiet; else cs_fail cli-quiet "stderr not empty: $(head -1 "$CS_TMP/err")"; fi

# --duration S is simulated time: 0.05 s at dt 0.01 is 5 steps.
err=$("$D" --scene "$S" --duration 0.05 2>&1 >/dev/null); rc=$?
if [ $rc -eq 0 ] && grep -q 'done after 5 steps' <<<"$err"; then cs_pass cli-duration
else cs_fail cli-duration "exit $rc: $(tail -1 <<<"$err")"; fi

# A scene load that makes every step diverge (1e5 N on a 1 kg rigid cube: past 1 km/s in a
# step): a --steps run ends with exit 1 after the second diverged step (it used to pause and
# wait for a resume no client would send).
cat >"$CS_TMP/diverge.json" <<'JSON'
{ "objects": [ { "name": "b", "model": "rigid", "box": { "min": [0, 0, 0], "size": [0.1, 0.1, 0.1] },
  "loads": [ { "min": [-1, -1, -1], "max": [1, 1, 1], "force": [1e5, 0, 0] } ] } ] }
JSON
err=$(timeout 20 "$D" --scene "$CS_TMP/diverge.json" --steps 5 2>&1 >/dev/null); rc=$?
if [ $rc -eq 1 ] && grep -q 'diverged again at frame 2 (undone): run stopped' <<<"$err" \
    && grep -q 'diverged after 2 steps' <<<"$err"; then
    cs_pass cli-diverged-run-ends
else
    cs_fail cli-diverged-run-ends "exit $rc: $(tr '\n' '|' <<<"$err" | tail -c 300)"
fi

# The same when the divergence alternates: 36 000 N on a 1 kg rigid cube gives it 600 m/s per
# step, so each step from rest succeeds and the next, past 1 km/s, diverges (frames 2, 4, 6,
# ...). Divergences count since the last input, not in a row: the run ends at frame 4 (before
# session 31 it diverged every other step and a --steps 6 run ended with exit 0).
sed 's/1e5, 0, 0/36000, 0, 0/' "$CS_TMP/diverge.json" >"$CS_TMP/alternate.json"
err=$(timeout 20 "$D" --scene "$CS_TMP/alternate.json" --steps 6 2>&1 >/dev/null); rc=$?
if [ $rc -eq 1 ] && grep -q 'step diverged at frame 2 (undone' <<<"$err" \
    && grep -q 'diverged again at frame 4 (undone): run stopped' <<<"$err"; then
    cs_pass cli-alternating-divergence-ends
else
    cs_fail cli-alternating-divergence-ends "exit $rc: $(tr '\n' '|' <<<"$err" | tail -c 300)"
fi

# Values inside each field's range that cannot work together are refused at load, exit 2,
# one line naming the fields (the outside review's scenes ran to NaN or did nothing, exit 0).
absurd() { # absurd NAME OBJECT-FIELDS: a 2x1x1 box of 0.1 m cubes with those fields
    printf '{ "ground": {}, "objects": [ { "name": "b", %s, "box": { "min": [0, 0, 0.5], "size": [%s] } } ] }\n' \
        "$2" "${3:-0.2, 0.1, 0.1}" >"$CS_TMP/$1.json"
}
absurd density '"material": { "density": 1e-300 }'
absurd cube_huge '"cube_size": 1e300' '1e300, 1e300, 1e300'
absurd cube_tiny '"cube_size": 1e-300' '1e-300, 1e-300, 1e-300'
absurd too_light '"material": { "density": 1e-13 }'
absurd mss_nu '"model": "mss", "material": { "poisson": 0.49999 }'
absurd load '"loads": [ { "min": [-1, -1, -1], "max": [1, 1, 1], "force": [1e100, 0, 0] } ]'
expect_exit2 scene-density-tiny "density 1e-300 kg/m\^3 and cube_size 0.1 m give nodes of 1.25e-304 kg" --scene "$CS_TMP/density.json" --steps 1
expect_exit2 scene-cube-size-huge "cube_size 1e\+300 m give nodes of inf kg" --scene "$CS_TMP/cube_huge.json" --steps 1
expect_exit2 scene-cube-size-tiny "cube_size 1e-300 m give nodes of 0 kg" --scene "$CS_TMP/cube_tiny.json" --steps 1
expect_exit2 scene-too-stiff-for-its-mass "'b' is too stiff for its mass at dt" --scene "$CS_TMP/too_light.json" --steps 1
expect_exit2 scene-mss-near-incompressible "model 'mss' takes poisson up to 0.45, got 0.49999" --scene "$CS_TMP/mss_nu.json" --steps 1
expect_exit2 scene-load-past-light-speed "loads\[0\]: the force \(1e\+100, 0, 0\) N .* beyond the speed of light" --scene "$CS_TMP/load.json" --steps 1

# --realtime paces steps to the wall clock: 30 steps of 0.01 s take about 0.3 s (not much less).
t0=$(date +%s.%N)
"$D" --scene "$S" --quiet --realtime --steps 30 2>/dev/null; rc=$?
t1=$(date +%s.%N)
if [ $rc -eq 0 ] && awk -v a="$t0" -v b="$t1" 'BEGIN { d = b - a; exit !(d >= 0.28 && d < 5) }'; then
    cs_pass cli-realtime-pacing
else
    cs_fail cli-realtime-pacing "exit $rc, took $(awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }') s for 0.3 s of simulated time"
fi

# --static + --dump-nodes on the project's cantilever: header and one row per node.
C="$CS_ROOT/scenes/cantilever.json"
read -r h sx sy sz < <(tr -d '\n' <"$C" | sed -n 's/.*"cube_size": *\([0-9.eE+-]*\).*"size": *\[ *\([^],]*\), *\([^],]*\), *\([^]]*\)\].*/\1 \2 \3 \4/p')
expect=$(awk -v h="$h" -v x="$sx" -v y="$sy" -v z="$sz" 'BEGIN { printf "%d", (int(x/h+0.5)+1)*(int(y/h+0.5)+1)*(int(z/h+0.5)+1) }')
timeout 400 "$D" --scene "$C" --static --quiet --dump-nodes "$CS_TMP/c.csv" 2>"$CS_TMP/err"
rc=$?
rows=$(($(wc -l <"$CS_TMP/c.csv" 2>/dev/null || echo 1) - 1))
if [ $rc -eq 0 ] && [ "$(head -1 "$CS_TMP/c.csv")" = "x,y,z,ux,uy,uz" ] && [ "$rows" -eq "$expect" ] \
    && ! grep -Eqv '^-?[0-9]' <(tail -n +2 "$CS_TMP/c.csv"); then
    cs_pass static-cantilever-dump-nodes
else
    cs_fail static-cantilever-dump-nodes "exit $rc, $rows rows (expected $expect), stderr: $(head -1 "$CS_TMP/err")"
fi

# Linear statics near incompressibility (the outside review's 40x4x4 beam at poisson 0.4999):
# converges with the default preconditioner (block Jacobi stops, multigrid goes on; it spent
# 434 000 CG iterations, 20 s, and failed); with "jacobi" asked for it fails at once, exit 1,
# naming the object near incompressibility.
nearly() { # nearly PRECONDITIONER
    printf '{ "solver": { "threads": 1, "preconditioner": "%s" }, "objects": [ { "name": "b", "model": "linear", "cube_size": 0.025, "material": { "poisson": 0.4999 }, "box": { "min": [0, 0, 0], "size": [1, 0.1, 0.1] }, "fixed": [ { "min": [-0.001, -1, -1], "max": [0.001, 1, 1] } ] } ] }\n' "$1"
}
nearly auto >"$CS_TMP/nearly_auto.json"
nearly jacobi >"$CS_TMP/nearly_jacobi.json"
err=$(timeout 20 "$D" --scene "$CS_TMP/nearly_auto.json" --static 2>&1 >/dev/null); rc=$?
if [ $rc -eq 0 ] && grep -q 'static solve converged' <<<"$err"; then
    cs_pass static-near-incompressible-converges
else
    cs_fail static-near-incompressible-converges "exit $rc: $(tr '\n' '|' <<<"$err" | tail -c 300)"
fi
err=$(timeout 10 "$D" --scene "$CS_TMP/nearly_jacobi.json" --static 2>&1 >/dev/null); rc=$?
if [ $rc -eq 1 ] && grep -q "static solve: not converged (residual 1 of the loads after .*object 'b' has poisson 0.4999: near incompressibility" <<<"$err"; then
    cs_pass static-near-incompressible-jacobi-fails-fast
else
    cs_fail static-near-incompressible-jacobi-fails-fast "exit $rc: $(tr '\n' '|' <<<"$err" | tail -c 300)"
fi
# static_warns NAME LOADS-BOX FORCE PATTERN: a corotational 8x8x8 block of 2.5 cm cubes held
# at its base, a dead load on the faces in LOADS-BOX ("min": [...], "max": [...]), solved with
# --static: exit 0 and exactly one stderr line, matching PATTERN.
static_warns() {
    printf '{ "gravity": [0, 0, 0], "solver": { "threads": 1 }, "objects": [ { "name": "blk", "model": "corotational", "cube_size": 0.025, "material": { "young": 1e6, "poisson": 0.3 }, "box": { "min": [-0.1, -0.1, 0], "size": [0.2, 0.2, 0.2] }, "fixed": [ { "min": [-1, -1, -2.5e-5], "max": [1, 1, 2.5e-5] } ], "loads": [ { %s, "force": [0, 0, %s] } ] } ] }\n' "$2" "$3" >"$CS_TMP/$1.json"
    local err rc
    err=$(timeout 60 "$D" --scene "$CS_TMP/$1.json" --static --quiet 2>&1 >/dev/null); rc=$?
    if [ $rc -eq 0 ] && [ "$(grep -c . <<<"$err")" -eq 1 ] && grep -q "$4" <<<"$err"; then
        cs_pass "$1"
    else
        cs_fail "$1" "exit $rc, stderr: ${err//$'\n'/ | }"
    fi
}
# A static solve that converges with cubes turned inside out (a load of 20 % of E on the
# central 2x2 top faces) says so in one line.
static_warns static-inverted-cubes-warned \
    '"min": [-0.012525, -0.012525, 0.199975], "max": [0.012525, 0.012525, 0.200025]' -2000 \
    "^cubesimd: static solve: object 'blk': 4 of 512 cubes turned inside out (smallest corner volume ratio -1.1[0-9]): its loads are beyond what the model represents there$"
# A static solve that converges to an unstable equilibrium (the clamped-free block under a
# dead top load of 0.25 E*A, past its buckling load near 0.16, held straight by symmetry) says
# so in one line.
static_warns static-unstable-equilibrium-warned \
    '"min": [-1, -1, 0.199975], "max": [1, 1, 0.200025]' -10000 \
    "^cubesimd: static solve: object 'blk': the equilibrium found is unstable (its tangent stiffness has a direction of negative curvature: a column past its buckling load, held straight by symmetry); a small disturbance leaves it$"
# SIGTERM stops a long static solve (a localframe 40x4x4 cantilever bent far, under block
# Jacobi: about 14 s on one core; session 46's multigrid, the default, solves it in 0.7 s) within
# moments, not when the solve ends: exit 1, one line saying so, and the nodes written at the
# last load level reached (before, only SIGKILL stopped it).
printf '{ "gravity": [0, 0, 0], "solver": { "threads": 1, "preconditioner": "jacobi" }, "objects": [ { "name": "beam", "model": "localframe", "cube_size": 0.025, "material": { "young": 1e6, "poisson": 0.45 }, "box": { "min": [0, -0.05, -0.05], "size": [1, 0.1, 0.1] }, "fixed": [ { "min": [-1e-4, -1, -1], "max": [1e-4, 1, 1] } ], "loads": [ { "min": [0.9999, -1, -1], "max": [1.0001, 1, 1], "force": [0, 0, -12.5] } ] } ] }\n' >"$CS_TMP/long_static.json"
rm -f "$CS_TMP/long.csv"
timeout 120 "$D" --scene "$CS_TMP/long_static.json" --static --quiet --dump-nodes "$CS_TMP/long.csv" 2>"$CS_TMP/err" &
lp=$!
sleep 1.5
t0=$(date +%s.%N)
kill -TERM $lp
wait $lp; rc=$?
t1=$(date +%s.%N)
took=$(awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }')
rows=$(($(wc -l <"$CS_TMP/long.csv" 2>/dev/null || echo 1) - 1))
if [ $rc -eq 1 ] && awk -v t="$took" 'BEGIN { exit !(t < 2) }' && [ "$rows" -eq 1025 ] &&
   [ "$(grep -c . "$CS_TMP/err")" -eq 1 ] &&
   grep -q '^cubesimd: static solve stopped by signal after .* iterations; objects left at their last load level reached$' "$CS_TMP/err" &&
   ! grep -Eqv '^-?[0-9]' <(tail -n +2 "$CS_TMP/long.csv"); then
    cs_pass static-stops-on-sigterm
else
    cs_fail static-stops-on-sigterm "exit $rc $took s after SIGTERM, $rows rows, stderr: $(tr '\n' '|' <"$CS_TMP/err" | tail -c 300)"
fi
# a mesh under cubes far larger than it runs, and says so in one line: one 1 m cube holds 250
# times the icosphere's 0.004 m^3 (its mass and stiffness are the cube's); cubes that fit it
# say nothing, and neither do the shipped scenes
sed 's/"cube_size": 0.05/"cube_size": 1.0/' <(mesh_scene "$CS_ROOT/scenes/meshes/icosphere.obj") >"$CS_TMP/coarse.json"
err=$(timeout 30 "$D" --quiet --scene "$CS_TMP/coarse.json" --steps 2 2>&1 >/dev/null); rc=$?
if [ $rc -eq 0 ] && [ "$(grep -c . <<<"$err")" -eq 1 ] &&
   grep -q "^cubesimd: objects\[0\] 'thing': its 1 cube of 1 m holds 1 m^3, .* times the 0.00405 m^3 its mesh encloses (0.2 x 0.2 x 0.2 m): cube_size is coarse" <<<"$err"; then
    cs_pass scene-coarse-mesh-warned
else
    cs_fail scene-coarse-mesh-warned "exit $rc, stderr: ${err//$'\n'/ | }"
fi
# an object that starts below the ground runs, and says so in one line (a deformable one is
# pushed up in its first step, a rigid one by its contacts); one resting on the plane, and the
# shipped scenes, say nothing (session 34)
below_scene() { # below_scene MODEL ZMIN
    cat <<JSON
{ "ground": { "height": 0.0 },
  "materials": { "m": { "young": 1e5, "poisson": 0.3, "density": 1000.0 } },
  "objects": [ { "name": "sunk", "material": "m", "model": "$1", "cube_size": 0.05,
                 "box": { "min": [0, 0, $2], "size": [0.2, 0.2, 0.2] } } ] }
JSON
}
below_scene corotational -0.03 >"$CS_TMP/below.json"
below_scene rigid -0.03 >"$CS_TMP/below_rigid.json"
below_scene corotational 0.0 >"$CS_TMP/onground.json"
err=$(timeout 30 "$D" --quiet --scene "$CS_TMP/below.json" --steps 2 2>&1 >/dev/null); rc=$?
err_r=$(timeout 30 "$D" --quiet --scene "$CS_TMP/below_rigid.json" --steps 2 2>&1 >/dev/null); rc_r=$?
if [ $rc -eq 0 ] && [ "$(grep -c . <<<"$err")" -eq 1 ] &&
   grep -q "^cubesimd: objects\[0\] 'sunk': starts 0.03 m below the ground (z = 0): it is pushed up onto the plane (in its first step, compressed and thrown up by the depth), place it on or above the ground$" <<<"$err" &&
   [ $rc_r -eq 0 ] && [ "$(grep -c . <<<"$err_r")" -eq 1 ] &&
   grep -q "'sunk': starts 0.03 m below the ground (z = 0): it is pushed up onto the plane (by its contacts, a little each step)" <<<"$err_r"; then
    cs_pass scene-below-ground-warned
else
    cs_fail scene-below-ground-warned "exit $rc/$rc_r, stderr: ${err//$'\n'/ | } / ${err_r//$'\n'/ | }"
fi
# neither warning from a fitting mesh, a box on the plane or the shipped scenes
mesh_scene "$CS_ROOT/scenes/meshes/icosphere.obj" >"$CS_TMP/fine.json"
coarse_warned="" below_warned=""
for sc in "$CS_TMP/fine.json" "$CS_TMP/onground.json" "$CS_ROOT"/scenes/*.json; do
    err=$(timeout 60 "$D" --quiet --scene "$sc" --steps 1 2>&1 >/dev/null)
    grep -q "is coarse" <<<"$err" && coarse_warned+=" $(basename "$sc")"
    grep -q "below the ground" <<<"$err" && below_warned+=" $(basename "$sc")"
done
[ -z "$coarse_warned" ] && cs_pass scene-fitting-meshes-not-warned || cs_fail scene-fitting-meshes-not-warned "warned:$coarse_warned"
[ -z "$below_warned" ] && cs_pass scene-on-ground-not-warned || cs_fail scene-on-ground-not-warned "warned:$below_warned"
cs_finish
