#!/usr/bin/env bash
# daemon_localframe.sh — the localframe model (seed 001) in the daemon: scenes/localframe.json
# runs (central differences, a cantilever and two blocks on the ground) and its cantilever sags;
# a stiff localframe object at a dt above the central-difference stability limit is refused
# with one line naming the limit. Inside a private network namespace (the run opens the bus).
set -u
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
D="$CS_IT_BIN/cubesimd"

timeout 300 "$D" --scene "$CS_ROOT/scenes/localframe.json" --quiet --steps 250 \
    --dump-nodes "$CS_TMP/n.csv" 2>"$CS_TMP/err"
rc=$?
if [ $rc -eq 0 ] && [ "$(head -1 "$CS_TMP/n.csv")" = "x,y,z,ux,uy,uz" ] && [ ! -s "$CS_TMP/err" ]; then
    cs_pass localframe-scene-runs
else
    cs_fail localframe-scene-runs "exit $rc, stderr: $(head -2 "$CS_TMP/err" | tr '\n' ' ')"
fi
# the beam's free end (x = 0.6, rest z in [0.5, 0.8]) sagged; no node went below the ground
if awk -F, 'NR > 1 && $1 > 0.599 && $1 < 0.601 && $3 >= 0.5 && $6 < -1e-3 { sag = 1 }
            NR > 1 && $3 + $6 < -1e-9 { under = 1 } END { exit !(sag && !under) }' "$CS_TMP/n.csv"; then
    cs_pass localframe-scene-physics
else
    cs_fail localframe-scene-physics "beam did not sag, or a node went below the ground"
fi

sed 's/"young": 1.0e5/"young": 1.0e8/' "$CS_ROOT/scenes/localframe.json" >"$CS_TMP/stiff.json"
err=$(timeout 20 "$D" --scene "$CS_TMP/stiff.json" --steps 1 2>&1 >/dev/null); rc=$?
if [ $rc -eq 2 ] && [ "$(grep -c . <<<"$err")" -eq 1 ] && grep -q "stability limit" <<<"$err"; then
    cs_pass localframe-unstable-dt-refused
else
    cs_fail localframe-unstable-dt-refused "exit $rc: ${err//$'\n'/ | }"
fi
cs_finish
