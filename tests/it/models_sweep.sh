#!/usr/bin/env bash
# models_sweep.sh — models nobody here chose: every file of Debian's assimp-testmodels
# (/usr/share/assimp/models, ~580 files in 40 formats, broken ones included) through the
# daemon's scene path (tests/stress/models.c: load, place, check, subdivide, voxelize, 5 steps,
# a forced fracture, 2 steps), one child process per file. Passes when no file crashes, hangs,
# or is refused without a one-line message, and every simulated one stays finite, closed,
# oriented and within 2 % of its volume through the fracture. Sanitizer build only (ASan and
# UBSan see the engine on all of them; about a minute); the release build skips it.
set -u
source "$(dirname "$0")/lib.sh"
case "$CS_IT_BIN" in */san/bin) ;; *) exit 0 ;; esac
if [ ! -d /usr/share/assimp/models ]; then
    cs_fail models-sweep "/usr/share/assimp/models missing (make deps installs assimp-testmodels)"
    cs_finish
fi
T="$CS_TMP/sweep.out" # in lib.sh's scratch folder (an EXIT trap of our own would replace lib.sh's, which removes it)
timeout 500 "$CS_IT_BIN/cs_stress_models" --timeout 120 >"$T" 2>&1
rc=$?
last=$(tail -n 1 "$T")
# at least 150 files must get through to the simulation, or the sweep proves little
sim=$(echo "$last" | sed -n 's/.* \([0-9]*\) simulated.*/\1/p')
if [ "$rc" -eq 0 ] && [ "${sim:-0}" -ge 150 ]; then
    cs_pass "models-sweep ($last)"
else
    cs_fail models-sweep "exit $rc: $last; $(grep '^FAIL' "$T" | head -n 3 | tr '\n' ' ')"
fi
cs_finish
