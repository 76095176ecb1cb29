#!/usr/bin/env bash
# daemon_sculpt — the sculpting inputs (seed 001 §4.1) through the daemon and cubesim-push, in
# a private network namespace:
#   sculpt_ok            paint, pressure (inflate and deflate) and curve get "ok", exit 0
#   sculpt_refused       bad values get a one-line error ack naming the problem, exit 1:
#                        zero radius, negative factor, unknown object, too large a pressure,
#                        a zero-length curve, no factor given (refused by cubesim-push, exit 2)
#   sculpt_moves         pressure moved the surface: the daemon's export differs from rest
#   sculpt_logged        cubesim-log recorded the messages on CUBESIM_PAINT/PRESSURE/CURVE
#   sculpt_replayed      replaying those channels of the log onto a fresh daemon gets one ack
#                        per message (ok or refused as live)
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
B=$CS_IT_BIN
U=$CS_LCM_URL
cs_need_bins daemon_sculpt cubesimd cubesim-push cubesim-log cubesim-replay
cd "$CS_TMP" || exit 1

cat > blob.json <<'JSON'
{ "dt": 0.0166667, "gravity": [0, 0, 0], "publish_hz": 60,
  "materials": { "soft": { "young": 20000.0, "poisson": 0.3, "density": 500.0,
                           "damping": [2.0, 0.005] } },
  "objects": [
    { "name": "blob", "model": "corotational", "material": "soft", "cube_size": 0.05,
      "box": { "min": [0, 0, 0], "size": [0.2, 0.2, 0.2] },
      "fields": [ { "shape": "radial", "centre": [0.1, 0.1, 0.1], "radius": 0.1,
                    "young": 2 } ] } ] }
JSON

P() { "$B/cubesim-push" --lcm "$U" --timeout 3 "$@"; }

"$B/cubesim-log" run.lcm --lcm "$U" --channels 'CUBESIM_(PAINT|PRESSURE|CURVE|ACK)' --passive \
    >log.txt 2>&1 & pl=$!
sleep 0.3
if ! cs_start_daemon --scene blob.json --realtime --export live.obj; then
    cs_fail daemon_sculpt "daemon did not start: $(head -c 400 "$CS_TMP/daemon.err" | tr '\n' '|')"
    kill -TERM $pl 2>/dev/null; wait; cs_finish
fi

bad=""
expect_ok() {
    local out rc
    out=$(P "$@"); rc=$?
    [ "$rc" -eq 0 ] && [ "$out" = ok ] || bad="$bad [$* -> $rc '$out']"
}
expect_refused() { # WORD ARGS...: exit 1, the ack's message holds WORD
    local word=$1 out rc; shift
    out=$(P "$@"); rc=$?
    { [ "$rc" -eq 1 ] && grep -q -- "$word" <<<"$out" && [ "$(wc -l <<<"$out")" -eq 1 ]; } ||
        bad="$bad [$* -> $rc '$out', want '$word']"
}
expect_ok paint blob --at 0.1 0.1 0.2 --radius 0.06 --young 5 --density 2
expect_ok paint '#1' --at 0 0 0 --radius 0.05 --damping 0
expect_ok pressure blob --pressure 400 --for 0.5
expect_ok curve blob --point 0.2 0.2 0.2 --point 0.3 0.2 0.2 --point 0.3 0.3 0.2 --for 0.5 --stiffness 50
[ -z "$bad" ] && cs_pass sculpt_ok || cs_fail sculpt_ok "$bad"

bad=""
expect_refused "radius" paint blob --at 0.1 0.1 0.1 --radius 0 --young 2
expect_refused "young factor" paint blob --at 0.1 0.1 0.1 --radius 0.1 --young -1
expect_refused "no object named 'nosuch'" paint nosuch --at 0.1 0.1 0.1 --radius 0.1 --young 2
expect_refused "max_force" pressure blob --pressure 1e15
expect_refused "no object named" pressure nosuch --pressure 10
expect_refused "zero length" curve blob --point 0 0 0 --point 0 0 0 --for 1
expect_refused "duration" curve blob --point 0 0 0 --point 1 0 0 --for 0
P paint blob --at 0 0 0 --radius 0.1 >/dev/null 2>&1; rc=$?
[ "$rc" -eq 2 ] || bad="$bad [paint without a factor -> $rc, want 2]"
[ -z "$bad" ] && cs_pass sculpt_refused || cs_fail sculpt_refused "$bad"

P pressure blob --pressure -300 --for 0.2 >/dev/null
sleep 0.5
cs_stop_daemon INT
sleep 0.3
kill -INT $pl; wait $pl

# rest surface of the same scene, for comparison
"$B/cubesimd" --scene blob.json --steps 1 --export rest.obj 2>/dev/null
moved=$(paste -d' ' <(obj_faces rest.obj) <(obj_faces live.obj) | awk '
    { for (i = 1; i <= 9; i++) { d = $i - $(i + 9); if (d < 0) d = -d; if (d > m) m = d } }
    END { printf "%.6g", m + 0 }')
if awk -v m="$moved" 'BEGIN { exit !(m > 1e-3) }'; then
    cs_pass "sculpt_moves (largest vertex motion $moved m)"
else
    cs_fail sculpt_moves "largest vertex motion $moved m"
fi

n_paint=$(awk '$1 == "CUBESIM_PAINT" {print $2}' log.txt)
n_press=$(awk '$1 == "CUBESIM_PRESSURE" {print $2}' log.txt)
n_curve=$(awk '$1 == "CUBESIM_CURVE" {print $2}' log.txt)
if [ "${n_paint:-0}" = 5 ] && [ "${n_press:-0}" = 4 ] && [ "${n_curve:-0}" = 3 ]; then
    cs_pass "sculpt_logged (paint $n_paint, pressure $n_press, curve $n_curve)"
else
    cs_fail sculpt_logged "paint '$n_paint' (want 5), pressure '$n_press' (4), curve '$n_curve' (3): $(tr '\n' '|' <log.txt)"
fi

"$B/cubesim-log" acks.lcm --lcm "$U" --channels 'CUBESIM_ACK' --passive >acks.txt 2>&1 & pa=$!
sleep 0.3
if cs_start_daemon --scene blob.json --realtime; then
    "$B/cubesim-replay" run.lcm --lcm "$U" --speed 4 --channels 'CUBESIM_(PAINT|PRESSURE|CURVE)' \
        --quiet >replay.txt 2>&1
    sleep 0.5
    cs_stop_daemon INT
fi
kill -INT $pa; wait $pa
n_ack=$(awk '$1 == "CUBESIM_ACK" {print $2}' acks.txt)
if [ "${n_ack:-0}" = 12 ]; then
    cs_pass "sculpt_replayed ($n_ack acks for 12 replayed inputs)"
else
    cs_fail sculpt_replayed "acks '$n_ack', want 12: $(tr '\n' '|' <acks.txt) $(tr '\n' '|' <replay.txt)"
fi
cs_finish
