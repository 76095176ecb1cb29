#!/usr/bin/env bash
# daemon_paused — what clients hold while cubesimd is paused, inside a private network
# namespace. A paused daemon must leave every client holding its surfaces as they are: the
# status' per-object state_hash (FNV-1a of the positions rounded to float32) equals the hash
# of the surfaces a logger's log rebuilds (cubesim-replay --export), object by object. With
# "publish_epsilon": 0 that is bit for bit. Passive loggers started before the daemon and
# stopped at each checkpoint are the clients (no snapshot requests that could hide a lag);
# key frames are off (keyframe_s 600). publish_hz 5 with dt 0.01: a publish frame every 20.
#   paused_step_published      `step N` ending off the publish grid: the log rebuilds the
#                              paused frame (not the last publish frame) with the daemon's
#                              hashes. Fails on main (the log stops at the last publish frame)
#   paused_fracture_consistent after a `fracture` of a deformable beam and of a spinning
#                              rigid stone while paused (after a snapshot at the same frame):
#                              the same hashes for every piece, and no stale warning (a delta
#                              ahead of its topology change would be refused and mark the
#                              rebuild stale). This one passes on main too: a fracture moves no
#                              vertex it had, sends the new ones where they are, and the rigid
#                              refit moves vertices by double round-off only (below float32)
#   paused_fracture_deltas     a logger of just that window got the topology changes and then
#                              the deltas of the paused frame (with publish_epsilon 0 they
#                              resend every vertex's rounding); main sent no delta while paused
#   paused_bad_fracture        bad `fracture` arguments while paused: one error ack and one
#                              stderr line each, nothing published, hashes and pieces kept
#   paused_on_publish_frame    `step` to a publish frame: the pause's exact flush follows the
#                              frame's regular deltas (rigid poses at publish_epsilon 0 send no
#                              vertex), same hashes (session 32: it was skipped, one pause in 20)
#   paused_pause_published     resume, then pause: the log ends at the paused frame, same
#                              hashes (fails on main unless the pause lands on a publish frame)
#   paused_replay_verify       the whole log passes cubesim-replay --verify, nothing lost
#   paused_eps_hashes          the first check again with publish_epsilon 2e-2: the paused
#                              flush is exact, so the hashes agree (before: both differed)
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
B=$CS_IT_BIN
U=$CS_LCM_URL
cs_need_bins daemon_paused cubesimd cubesim-push cubesim-log cubesim-replay cs_it_bus
cd "$CS_TMP" || exit 1
GRID=20 # steps per publish frame: dt 0.01, publish_hz 5

cat > scene.json <<'JSON'
{ "dt": 0.01, "gravity": [0, 0, -9.81], "publish_hz": 5, "keyframe_s": 600, "status_hz": 10,
  "publish_epsilon": 0,
  "materials": { "soft": { "young": 100000.0, "poisson": 0.3, "density": 500.0,
                           "damping": [1.0, 0.005] },
                 "stone": { "young": 1e7, "poisson": 0.3, "density": 2000.0 } },
  "objects": [
    { "name": "beam", "model": "corotational", "material": "soft", "cube_size": 0.05,
      "fracture_radius": 0.08,
      "box": { "min": [0, 0, 0], "size": [0.4, 0.1, 0.1] },
      "fixed": [ { "min": [-0.001, -1, -1], "max": [0.001, 1, 1] } ] },
    { "name": "stone", "model": "rigid", "material": "stone", "cube_size": 0.05,
      "box": { "min": [1.0, 0, 0], "size": [0.2, 0.1, 0.1] } } ] }
JSON

# "ID HASH" per object, sorted: from a status (cs_it_bus) and from a rebuilt log.
status_hashes() { sed -n 's/^object id=\([0-9]*\) name=[^ ]* hash=\([0-9a-f]*\).*/\1 \2/p' <<<"$1" | sort; }
status_field() { sed -n "s/^status .*$1=\([0-9]*\).*/\1/p" <<<"$2" | tail -1; }
replay_hashes() { sed -n "s/^  object \([0-9]*\) '.*': .* hash \([0-9a-f]*\)$/\1 \2/p" "$1" | sort; }
replay_frame() { sed -n 's/^exported frame \([0-9]*\) .*/\1/p' "$1"; }
# channel_count LOGGER_OUTPUT CHANNEL: messages the logger recorded on CHANNEL (0 if none).
channel_count() { awk -v c="$2" '$1 == c { n = $2 } END { print n + 0 }' "$1"; }
start_logger() { "$B/cubesim-log" "$1.lcm" --lcm "$U" --passive >"$1.txt" 2>&1 & }
stop_logger() { kill -INT "$1"; wait "$1"; }
# wait_paused FRAME: the status once the daemon is paused at FRAME (any frame if empty).
wait_paused() {
    local st i
    for i in $(seq 1 40); do
        st=$(cs_bus --timeout 3 status --count 2)
        if grep -q 'paused=1' <<<"$st" && { [ -z "$1" ] || [ "$(status_field frame "$st")" = "$1" ]; }; then
            echo "$st"; return 0
        fi
    done
    echo "$st"; return 1
}
# compare NAME LOG STATUS [FRAME]: rebuild LOG, compare its hashes (and frame) with STATUS.
compare() {
    local name=$1 log=$2 st=$3 frame=${4:-} want got f
    "$B/cubesim-replay" "$log.lcm" --export "$log.obj" >"$log.rep" 2>&1
    want=$(status_hashes "$st"); got=$(replay_hashes "$log.rep"); f=$(replay_frame "$log.rep")
    if [ -n "$want" ] && [ "$want" = "$got" ] && { [ -z "$frame" ] || [ "$f" = "$frame" ]; } \
        && ! grep -q 'went stale' "$log.rep"; then
        cs_pass "$name ($(wc -l <<<"$want") objects at frame $f)"
    else
        cs_fail "$name" "daemon at frame ${frame:-?}: $(tr '\n' ' ' <<<"$want")| log rebuilt frame $f: $(tr '\n' ' ' <<<"$got")| $(grep -v '^  object' "$log.rep" | head -3 | tr '\n' ' ')"
    fi
}

start_logger all; p_all=$!
start_logger l1; p1=$!
start_logger l2; p2=$!
start_logger l3; p3=$!
sleep 0.5
if ! cs_start_daemon --scene scene.json --realtime; then
    cs_fail daemon_paused "daemon did not start: $(head -c 400 daemon.err | tr '\n' '|')"
    cs_finish
fi
# Set the stone spinning (a rotated rigid body: its refit after a fracture rounds differently).
"$B/cubesim-push" --lcm "$U" --timeout 5 force stone --at 1.2 0.1 0.1 --force 0 300 300 >/dev/null \
    || cs_fail paused_force_ack "no ok ack"
sleep 0.5
"$B/cubesim-push" --lcm "$U" --timeout 5 pause >/dev/null || cs_fail paused_pause_ack "no ok ack"
st=$(wait_paused "")
P=$(status_field frame "$st")
# step N so that the daemon pauses off the grid of publish frames (multiples of GRID)
N=1; [ $(((P + 1) % GRID)) -eq 0 ] && N=2
"$B/cubesim-push" --lcm "$U" --timeout 5 step $N >/dev/null || cs_fail paused_step_ack "no ok ack"
F1=$((P + N))
st1=$(wait_paused $F1) || cs_fail paused_step_published "never paused at frame $F1: $(head -1 <<<"$st1")"
sleep 0.3 # the FIFO's last deltas leave (paced, well under 0.1 s here)
stop_logger $p1
compare paused_step_published l1 "$st1" $F1

# A snapshot at the same frame makes every client current whatever the step left, so what
# follows isolates the fracture. Then break both objects while paused.
cs_bus --timeout 5 command snapshot >/dev/null
sleep 0.3
start_logger win; pw=$!
sleep 0.3
o1=$("$B/cubesim-push" --lcm "$U" --timeout 5 fracture beam --at 0.2 0.05 0.05 --normal 1 0 0 --radius 0.5)
o2=$("$B/cubesim-push" --lcm "$U" --timeout 5 fracture stone --at 1.1 0.05 0.05 --normal 1 0 0 --radius 0.5)
[ "$o1" = ok ] && [ "$o2" = ok ] || cs_fail paused_fracture_ack "beam '$o1', stone '$o2'"
sleep 0.5
st2=$(wait_paused $F1) || cs_fail paused_fracture_consistent "not paused at frame $F1 any more: $(head -1 <<<"$st2")"
stop_logger $p2
stop_logger $pw
nobj=$(status_field objects "$st2")
if [ "${nobj:-0}" -ge 4 ]; then
    compare paused_fracture_consistent l2 "$st2" $F1
else
    cs_fail paused_fracture_consistent "expected both objects broken (>= 4 objects), status: $(head -1 <<<"$st2")"
fi
nt=$(channel_count win.txt CUBESIM_TOPOLOGY); nd=$(channel_count win.txt CUBESIM_DELTA)
[ "$nt" -ge 2 ] && [ "$nd" -ge 1 ] && cs_pass "paused_fracture_deltas ($nt topology, $nd delta messages while paused)" \
    || cs_fail paused_fracture_deltas "while paused: $nt topology, $nd delta messages: $(tr '\n' '|' <win.txt)"

# Bad arguments while paused: refused with one line each, nothing published, nothing lost.
start_logger bad; pb=$!
sleep 0.3
e0=$(wc -l <daemon.err)
why=""
for arg in "beam 0.2 0.05 0.05 0 0 0" "beam 0.2 nan 0.05 1 0 0" "beam 1 2" "nosuch 0 0 0 1 0 0"; do
    ack=$(cs_bus --timeout 5 command fracture --arg "$arg")
    grep -q '^ack ok=0 request=fracture message=fracture: ' <<<"$ack" && [ "$(wc -l <<<"$ack")" -eq 1 ] \
        || why="$why '$arg' -> '$ack';"
done
sleep 0.3
st3=$(wait_paused $F1) || why="$why not paused at $F1;"
stop_logger $pb
nref=$(tail -n +"$((e0 + 1))" daemon.err | grep -c 'refused fracture .*: fracture: ')
nnew=$(tail -n +"$((e0 + 1))" daemon.err | wc -l)
[ "$nref" -eq 4 ] && [ "$nnew" -eq 4 ] || why="$why $nnew new stderr lines, $nref refusals (want 4 and 4);"
[ "$(status_hashes "$st3")" = "$(status_hashes "$st2")" ] || why="$why hashes changed;"
[ "$(status_field objects "$st3")" = "$nobj" ] || why="$why objects $nobj -> $(status_field objects "$st3");"
sent=$(( $(channel_count bad.txt CUBESIM_TOPOLOGY) + $(channel_count bad.txt CUBESIM_DELTA) + $(channel_count bad.txt CUBESIM_SNAPSHOT) ))
[ "$sent" -eq 0 ] || why="$why $sent surface messages published;"
[ -z "$why" ] && cs_pass "paused_bad_fracture (4 refusals)" || cs_fail paused_bad_fracture "$why"

# Step on to the next publish frame and pause there (the spinning stone's pose was published at
# that frame with publish_epsilon 0, which sends no vertex of a rigid object: the pause's exact
# flush must follow all the same; it did not, so a pause landing on the grid, one in 20 above,
# left the log's rigid surfaces a rounding off the daemon's).
M=$((GRID - F1 % GRID))
"$B/cubesim-push" --lcm "$U" --timeout 5 step $M >/dev/null || cs_fail paused_on_grid_ack "no ok ack"
F5=$((F1 + M))
st5=$(wait_paused $F5) || cs_fail paused_on_publish_frame "never paused at frame $F5: $(head -1 <<<"$st5")"
sleep 0.3
stop_logger $p3
compare paused_on_publish_frame l3 "$st5" $F5

# Resume, run on (the pieces fall), pause again: the pause itself publishes the paused frame.
"$B/cubesim-push" --lcm "$U" --timeout 5 resume >/dev/null
sleep 0.4
"$B/cubesim-push" --lcm "$U" --timeout 5 pause >/dev/null
st4=$(wait_paused "")
F4=$(status_field frame "$st4")
sleep 0.3
stop_logger $p_all
if [ $((F4 % GRID)) -eq 0 ]; then
    echo "note: paused on a publish frame ($F4): paused_pause_published checks only the rebuild"
fi
compare paused_pause_published all "$st4" "$F4"
cs_stop_daemon TERM || cs_fail daemon_stop "exit $CS_DAEMON_RC"

out=$("$B/cubesim-replay" all.lcm --verify 2>&1); rc=$?
lost=$(sed -n 's/^lost \([0-9]*\) messages.*/\1/p' all.txt)
[ $rc -eq 0 ] && [ "${lost:-x}" = 0 ] && cs_pass "paused_replay_verify ($(tail -1 <<<"$out" | cut -c1-60))" \
    || cs_fail paused_replay_verify "exit $rc, lost '$lost': $(tail -3 <<<"$out" | tr '\n' '|')"

# The same with a coarse publish_epsilon (2 cm): the pause's flush is exact (every vertex whose
# float32 changed, every vertex of a rigid object), so the hashes still agree. Before it sent
# only what moved by more than publish_epsilon, and clients lagged by up to it.
sed 's/"publish_epsilon": 0,/"publish_epsilon": 2e-2,/' scene.json >scene_eps.json
start_logger eps; pe=$!
sleep 0.5
if cs_start_daemon --scene scene_eps.json --realtime; then
    "$B/cubesim-push" --lcm "$U" --timeout 5 force stone --at 1.2 0.1 0.1 --force 0 300 300 >/dev/null
    sleep 0.6
    "$B/cubesim-push" --lcm "$U" --timeout 5 pause >/dev/null
    st5=$(wait_paused "")
    P=$(status_field frame "$st5")
    N=1; [ $(((P + 1) % GRID)) -eq 0 ] && N=2
    "$B/cubesim-push" --lcm "$U" --timeout 5 step $N >/dev/null
    st5=$(wait_paused $((P + N))) || cs_fail paused_eps_hashes "never paused at frame $((P + N))"
    sleep 0.3
    stop_logger $pe
    compare paused_eps_hashes eps "$st5" $((P + N))
    cs_stop_daemon TERM || cs_fail daemon_stop "exit $CS_DAEMON_RC"
else
    cs_fail paused_eps_hashes "daemon did not start: $(head -c 400 daemon.err | tr '\n' '|')"
    stop_logger $pe
fi
cs_finish
