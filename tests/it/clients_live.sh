#!/usr/bin/env bash
# clients_live — the clients against a live cubesimd, in a private network namespace.
#
# One daemon run on a cantilever without gravity (it only moves when pushed), recorded from
# before the daemon starts by two of our loggers at once and by lcm-logger:
#   push_ack              cubesim-push force gets "ok", exit 0; an unknown object gets an
#                         error ack, exit 1
#   push_moves            the surface at the first snapshot (rest) and at the end differ by
#                         more than 1 mm: the pushed force moved the beam
#   two_clients           both loggers saw the same number of daemon messages, none lost,
#                         and rebuild bit-identical surfaces
#   late_logger           a logger started after the push (asks for a snapshot) and a passive
#                         one (waits for a key frame) each rebuild the surface from their log alone
#   replay_equals_live    replay --export of the log equals the daemon's own --export within
#                         publish_epsilon + 2^-24·|x| per coordinate (lcmtypes/delta_t.lcm)
#   read_lcm_logger_log   cubesim-replay rebuilds from lcm-logger's log the same surfaces
#   logplayer_plays_ours  lcm-logplayer plays our log; re-recorded, it rebuilds the same surfaces
#   replay_republishes    cubesim-replay plays our log; re-recorded by lcm-logger, same surfaces
#   replay_verify         every frame of the log is a watertight surface
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
B=$CS_IT_BIN
U=$CS_LCM_URL
cs_need_bins clients_live cubesimd cubesim-push cubesim-log cubesim-replay
command -v lcm-logger >/dev/null && command -v lcm-logplayer >/dev/null \
    || { cs_fail clients_live "lcm-logger/lcm-logplayer missing (make deps installs liblcm-bin)"; cs_finish; }
cd "$CS_TMP" || exit 1
EPS=1e-5

cat > beam.json <<'JSON'
{ "dt": 0.0166667, "gravity": [0, 0, 0], "publish_hz": 60, "keyframe_s": 1.5,
  "publish_epsilon": 1e-5,
  "materials": { "soft": { "young": 20000.0, "poisson": 0.3, "density": 500.0,
                           "damping": [1.0, 0.005] } },
  "objects": [
    { "name": "beam", "model": "corotational", "material": "soft", "cube_size": 0.05,
      "box": { "min": [0, 0, 0], "size": [0.4, 0.1, 0.1] },
      "fixed": [ { "min": [-0.001, -1, -1], "max": [0.001, 1, 1] } ] } ] }
JSON

# obj_maxdiff A B: the largest coordinate difference between two exports of the same faces.
obj_maxdiff() {
    paste -d' ' <(obj_faces "$1") <(obj_faces "$2") | awk '
        { for (i = 1; i <= 9; i++) { d = $i - $(i + 9); if (d < 0) d = -d; if (d > m) m = d } }
        END { printf "%.6g\n", m + 0 }'
}
hashes() { "$B/cubesim-replay" "$1" --export "$2" 2>>replay.err | grep 'hash' | awk '{print $2, $3, $NF}'; }

# Recorders first, so that the logs hold the daemon's first snapshot.
"$B/cubesim-log" a.lcm --lcm "$U" >log_a.txt 2>&1 & pa=$!
"$B/cubesim-log" b.lcm --lcm "$U" --passive >log_b.txt 2>&1 & pb=$!
lcm-logger --lcm-url="$U" -q -f lcmlogger.lcm >/dev/null 2>&1 & pl=$!
sleep 0.5
if ! cs_start_daemon --scene beam.json --realtime --export live.obj; then
    cs_fail clients_live "daemon did not start: $(head -c 400 "$CS_TMP/daemon.err" | tr '\n' '|')"
    kill -TERM $pa $pb $pl 2>/dev/null; wait; cs_finish
fi
sleep 0.5

out=$("$B/cubesim-push" --lcm "$U" --timeout 3 force beam --at 0.4 0.05 0.05 --force 0 0 -2 --for 0.5)
rc=$?
[ $rc -eq 0 ] && [ "$out" = ok ] && cs_pass push_ack || cs_fail push_ack "exit $rc: $out"
out=$("$B/cubesim-push" --lcm "$U" --timeout 3 force nosuchobject --at 0 0 0 --force 0 0 1)
rc=$?
[ $rc -eq 1 ] && [ -n "$out" ] && [ "$out" != ok ] && cs_pass push_unknown_object_error_ack \
    || cs_fail push_unknown_object_error_ack "exit $rc: $out"
"$B/cubesim-push" --lcm "$U" --timeout 3 drag '#1' --at 0.4 0.05 0.1 --to 0.4 0.05 0.2 --for 0.3 >/dev/null

sleep 1.0
# Late joiners: one asks for a snapshot, one waits for a key frame (keyframe_s 1.5).
"$B/cubesim-log" late.lcm --lcm "$U" --duration 3 >log_late.txt 2>&1 & plate=$!
"$B/cubesim-log" late_passive.lcm --lcm "$U" --passive --duration 3.5 >log_latep.txt 2>&1 & plp=$!
wait $plate $plp
"$B/cubesim-push" --lcm "$U" --timeout 3 pause >/dev/null || cs_fail push_pause "no ok ack"
sleep 0.7
cs_stop_daemon TERM || cs_fail daemon_stop "exit $CS_DAEMON_RC"
sleep 0.3
kill -INT $pa $pb $pl 2>/dev/null
wait $pa $pb $pl 2>/dev/null

# push_moves: rest (first snapshot, frame 0) against the end.
"$B/cubesim-replay" a.lcm --export rest.obj --frame 0 >/dev/null 2>>replay.err
"$B/cubesim-replay" a.lcm --export end.obj >/dev/null 2>>replay.err
if [ -s rest.obj ] && [ -s end.obj ]; then
    d=$(obj_maxdiff rest.obj end.obj)
    awk -v d="$d" 'BEGIN { exit !(d > 1e-3) }' && cs_pass push_moves \
        || cs_fail push_moves "the surface moved only $d m"
else
    cs_fail push_moves "no rebuild: $(tail -2 replay.err | tr '\n' '|')"
fi

# two_clients: same daemon message counts, no loss, identical surfaces.
cnt() { awk -v c="$2" '$1 == c { print $2 }' "$1"; }
ok=1
for ch in CUBESIM_SNAPSHOT CUBESIM_DELTA CUBESIM_STATUS; do
    na=$(cnt log_a.txt $ch); nb=$(cnt log_b.txt $ch)
    [ -n "$na" ] && [ "$na" = "$nb" ] || { ok=0; why="$ch: $na vs $nb messages"; }
done
grep -q '^lost 0 messages' log_a.txt && grep -q '^lost 0 messages' log_b.txt || { ok=0; why="loss: $(grep '^lost' log_a.txt log_b.txt | tr '\n' ' ')"; }
ha=$(hashes a.lcm ha.obj); hb=$(hashes b.lcm hb.obj)
[ -n "$ha" ] && [ "$ha" = "$hb" ] || { ok=0; why="surfaces differ: '$ha' vs '$hb'"; }
[ $ok = 1 ] && cs_pass two_clients || cs_fail two_clients "$why"

# late_logger: the late log's last frame F, rebuilt from it alone, equals frame F rebuilt from
# the full log (one came from a snapshot, the other from deltas: both within the bound).
for f in late late_passive; do
    if out=$("$B/cubesim-replay" $f.lcm --export $f.obj 2>$f.err); then
        fr=$(awk '/^exported frame/ { print $3 }' <<<"$out")
        "$B/cubesim-replay" a.lcm --export ref_$f.obj --frame "$fr" >/dev/null 2>>replay.err
        r=$(obj_close $f.obj ref_$f.obj $EPS) && cs_pass "late_logger_$f (frame $fr, $r)" \
            || cs_fail "late_logger_$f" "frame $fr differs from the full log's: $r"
    else
        cs_fail "late_logger_$f" "$(cat $f.err)"
    fi
done

# replay_equals_live
if [ -s live.obj ] && [ -s end.obj ]; then
    r=$(obj_close end.obj live.obj $EPS) && cs_pass "replay_equals_live ($r)" \
        || cs_fail replay_equals_live "$r"
else
    cs_fail replay_equals_live "missing live.obj (daemon --export) or end.obj"
fi

# read_lcm_logger_log
hl=$(hashes lcmlogger.lcm hl.obj)
[ -n "$hl" ] && [ "$hl" = "$ha" ] && cs_pass read_lcm_logger_log \
    || cs_fail read_lcm_logger_log "'$hl' vs '$ha'"

# logplayer_plays_ours / replay_republishes: re-record a playback, rebuild the same surfaces.
"$B/cubesim-log" replayed1.lcm --lcm "$U" --passive --quiet & p1=$!
sleep 0.4
lcm-logplayer --lcm-url="$U" --speed=2 a.lcm >/dev/null 2>&1
sleep 0.5; kill -INT $p1; wait $p1
h1=$(hashes replayed1.lcm h1.obj)
[ -n "$h1" ] && [ "$h1" = "$ha" ] && cs_pass logplayer_plays_ours || cs_fail logplayer_plays_ours "'$h1' vs '$ha'"

lcm-logger --lcm-url="$U" -q -f replayed2.lcm >/dev/null 2>&1 & p2=$!
sleep 0.4
"$B/cubesim-replay" a.lcm --lcm "$U" --speed 2 --channels 'CUBESIM_(SNAPSHOT|DELTA|STATUS)' </dev/null >/dev/null
rc=$?
sleep 0.5; kill -INT $p2; wait $p2
h2=$(hashes replayed2.lcm h2.obj)
[ $rc -eq 0 ] && [ -n "$h2" ] && [ "$h2" = "$ha" ] && cs_pass replay_republishes \
    || cs_fail replay_republishes "exit $rc, '$h2' vs '$ha'"

# replay_verify
out=$("$B/cubesim-replay" a.lcm --verify 2>&1)
rc=$?
[ $rc -eq 0 ] && cs_pass "replay_verify ($(tail -1 <<<"$out"))" || cs_fail replay_verify "exit $rc: $(tail -3 <<<"$out" | tr '\n' '|')"
cs_finish
