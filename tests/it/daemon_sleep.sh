#!/usr/bin/env bash
# daemon_sleep.sh — an object that falls asleep still publishes the motion of its last step:
# a block dropped on the ground settles and sleeps; the surfaces rebuilt from a log of the run
# equal the daemon's own export within the stated bound (publish_epsilon + 2^-24·|x|), and
# after it sleeps no more deltas are sent. The sleep threshold is high (5 cm/s for 3 steps) so
# that the step in which it falls asleep still moves it by far more than publish_epsilon.
# Inside a private network namespace.
set -u
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"

cat >"$CS_TMP/drop.json" <<'JSON'
{ "dt": 0.0166667, "publish_hz": 60, "publish_epsilon": 1e-6, "ground": { "height": 0.0 },
  "sleep": { "speed": 0.05, "steps": 3 },
  "materials": { "m": { "young": 1e5, "poisson": 0.3, "density": 1000, "damping": [4, 0] } },
  "objects": [ { "name": "block", "model": "corotational", "material": "m", "cube_size": 0.025,
                 "box": { "min": [0, 0, 0.01], "size": [0.1, 0.1, 0.1] } } ] }
JSON
B=$CS_IT_BIN
steps=240
"$B/cubesim-log" "$CS_TMP/run.lcm" --passive >"$CS_TMP/log.out" 2>&1 &
lpid=$!
sleep 0.3
"$B/cubesimd" --scene "$CS_TMP/drop.json" --steps $steps --export "$CS_TMP/live.obj" \
    2>"$CS_TMP/daemon.err"
drc=$?
sleep 0.5
kill -INT $lpid; wait $lpid
cs_check sleep-daemon-exit [ "$drc" -eq 0 ]
deltas=$(awk '$1 == "CUBESIM_DELTA" {print $2}' "$CS_TMP/log.out")
lost=$(awk '/^lost/ {print $2}' "$CS_TMP/log.out")
if [ -n "$deltas" ] && [ "$deltas" -lt $((steps - 60)) ] && [ "$lost" = 0 ]; then
    cs_pass "sleep-stops-deltas ($deltas deltas in $steps steps, 0 lost)"
else
    cs_fail sleep-stops-deltas "expected well under $steps deltas and 0 lost, got '$deltas', lost '$lost'"
fi
if "$B/cubesim-replay" "$CS_TMP/run.lcm" --export "$CS_TMP/replayed.obj" >"$CS_TMP/replay.out" 2>&1; then
    worst=$(paste -d' ' <(grep '^v ' "$CS_TMP/live.obj") <(grep '^v ' "$CS_TMP/replayed.obj") |
        awk '{ for (i = 2; i <= 4; i++) { d = $i - $(i + 4); if (d < 0) d = -d;
                 a = $i < 0 ? -$i : $i; b = 1e-6 + a * 2^-24 + 1e-8 * a; if (d - b > w) w = d - b } }
             END { printf "%.3g", w + 0 }')
    nl=$(grep -c '^v ' "$CS_TMP/live.obj"); nr=$(grep -c '^v ' "$CS_TMP/replayed.obj")
    if [ "$nl" -gt 0 ] && [ "$nl" = "$nr" ] && awk -v w="$worst" 'BEGIN { exit !(w <= 0) }'; then
        cs_pass "sleep-replay-equals-live ($nl vertices within the bound)"
    else
        cs_fail sleep-replay-equals-live "$nl vs $nr vertices, worst excess over the bound $worst m"
    fi
else
    cs_fail sleep-replay-equals-live "replay failed: $(tail -1 "$CS_TMP/replay.out")"
fi
cs_finish
