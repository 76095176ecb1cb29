#!/usr/bin/env bash
# daemon_bus.sh — cubesimd on the bus, fed bad input, inside a private network namespace.
# For every refused input: an error ack naming the problem, one stderr line, and the daemon
# keeps running with its (paused) state untouched: same session, epoch and state hash.
# Foreign types and truncated bytes on CUBESIM_FORCE / CUBESIM_COMMAND: a warning naming the
# channel (rate-limited). Then a good force still moves the block, and SIGTERM exits 0 with
# --dump-nodes and --export written.
set -u
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"

# A 2x2x2 block of 5 cm cubes held at its base: 27 nodes.
cat >"$CS_TMP/block.json" <<'JSON'
{ "dt": 0.01, "gravity": [0, 0, -9.81], "publish_hz": 50, "status_hz": 20, "keyframe_s": 1,
  "materials": { "m": { "young": 1e4, "poisson": 0.3, "density": 100.0 } },
  "objects": [ { "name": "block", "model": "corotational", "material": "m", "cube_size": 0.05,
                 "box": { "min": [0, 0, 0], "size": [0.1, 0.1, 0.1] },
                 "fixed": [ { "min": [-1, -1, -0.001], "max": [1, 1, 0.001] } ] } ] }
JSON
echo '{ "objects": [ ' >"$CS_TMP/broken.json"

if ! cs_start_daemon --scene "$CS_TMP/block.json" --dump-nodes "$CS_TMP/nodes.csv" \
    --export "$CS_TMP/out.obj"; then
    cs_fail daemon-starts "no status from cubesimd within 10 s: $(tail -3 "$CS_TMP/daemon.err" | tr '\n' ' ')"
    cs_finish
fi
cs_pass daemon-starts

snap=$(cs_bus --timeout 5 command snapshot >/dev/null; cs_bus --timeout 5 snapshot)
case "$snap" in
*"objects=1 vertices="*) v=$(sed -n 's/.*vertices=\([0-9]*\).*/\1/p' <<<"$snap")
    if [ "${v:-0}" -gt 0 ]; then cs_pass daemon-snapshot; else cs_fail daemon-snapshot "$snap"; fi ;;
*) cs_fail daemon-snapshot "no complete snapshot: '$snap'" ;;
esac

ack=$(cs_bus command pause)
case "$ack" in *"ok=1 request=pause"*) cs_pass daemon-pause-ack ;; *) cs_fail daemon-pause-ack "$ack" ;; esac

# Hash of the paused block, taken once it stopped changing (two statuses agree).
status_line() { cs_bus --timeout 3 status --count "${1:-2}"; }
s0=$(status_line 2)
h0=$(sed -n 's/^object id=1 name=block hash=\([0-9a-f]*\).*/\1/p' <<<"$s0")
sess0=$(sed -n 's/^status session=\([0-9]*\) .*/\1/p' <<<"$s0")
ep0=$(sed -n 's/^status .* epoch=\([0-9]*\) .*/\1/p' <<<"$s0")
if [ -n "$h0" ] && grep -q 'paused=1' <<<"$s0"; then cs_pass daemon-paused-status
else cs_fail daemon-paused-status "unexpected status: $(tr '\n' ' ' <<<"$s0")"; fi

# expect_refused NAME PATTERN CS_IT_BUS-ARGS...: an error ack whose message matches PATTERN,
# the same message on the daemon's stderr, and the state untouched.
expect_refused() {
    local name=$1 pat=$2; shift 2
    local before ack st h sess ep
    before=$(wc -l <"$CS_TMP/daemon.err")
    ack=$(cs_bus "$@" 2>&1)
    if ! grep -q '^ack ok=0 ' <<<"$ack"; then cs_fail "$name" "no error ack: '$ack'"; return; fi
    if ! grep -Eq "$pat" <<<"$ack"; then cs_fail "$name" "ack does not say /$pat/: '$ack'"; return; fi
    if ! tail -n +"$((before + 1))" "$CS_TMP/daemon.err" | grep -Eq "refused.*($pat)"; then
        cs_fail "$name" "no stderr line matching /$pat/"; return
    fi
    st=$(status_line 1)
    h=$(sed -n 's/^object id=1 name=block hash=\([0-9a-f]*\).*/\1/p' <<<"$st")
    sess=$(sed -n 's/^status session=\([0-9]*\) .*/\1/p' <<<"$st")
    ep=$(sed -n 's/^status .* epoch=\([0-9]*\) .*/\1/p' <<<"$st")
    if [ "$h" != "$h0" ] || [ "$sess" != "$sess0" ] || [ "$ep" != "$ep0" ] || ! grep -q 'paused=1' <<<"$st"; then
        cs_fail "$name" "state changed: hash $h0 -> $h, session $sess0 -> $sess, epoch $ep0 -> $ep"
        return
    fi
    cs_pass "$name"
}

expect_refused daemon-nan-force 'not finite' force --name block --point 0.05,0.05,0.1 --force nan,0,0
expect_refused daemon-inf-point 'not finite' force --name block --point inf,0,0 --force 0,0,1
expect_refused daemon-absurd-force 'max_force' force --name block --point 0.05,0.05,0.1 --force 0,0,1e300
expect_refused daemon-unknown-object-name "no object named 'nosuch'" force --name nosuch --point 0,0,0 --force 0,0,1
expect_refused daemon-unknown-object-id 'unknown object id 99' force --id 99 --point 0,0,0 --force 0,0,1
# a name with a newline and a terminal escape: echoed with '?' for each control character, so
# the ack and the stderr entry stay one line and clear no screen
expect_refused daemon-control-chars-echoed "no object named 'a\?b\?\[2J'" force --name "$(printf 'a\nb\033[2J')" --point 0,0,0 --force 0,0,1
# a negative id names the object by its name (force_t: by object_id when > 0, else by name)
expect_refused daemon-negative-id-by-name "no object named 'nosuch'" force --id -3 --name nosuch --point 0,0,0 --force 0,0,1
expect_refused daemon-negative-duration 'negative duration' force --name block --point 0,0,0 --force 0,0,1 --duration -1
expect_refused daemon-bad-drag 'stiffness' force --name block --kind 1 --point 0,0,0 --target 0,0,1 --stiffness -5
expect_refused daemon-absurd-drag 'max_force' force --name block --kind 1 --point 0.05,0.05,0.1 --target 0.05,0.05,1 --stiffness 1e300
expect_refused daemon-bad-kind 'unknown kind 7' force --name block --kind 7 --point 0,0,0
expect_refused daemon-step-zero 'count 0 is less than 1' command step --count 0
expect_refused daemon-unknown-command "unknown command 'explode'" command explode
expect_refused daemon-load-broken-scene 'load: .*broken.json' command load --arg "$CS_TMP/broken.json"
expect_refused daemon-load-missing-scene 'load: .*nothere.json' command load --arg "$CS_TMP/nothere.json"
expect_refused daemon-fracture-arg-count 'fracture: argument must be .OBJECT X Y Z NX NY NZ' command fracture --arg "block 1 2"
expect_refused daemon-fracture-nan "fracture: 'nan' is not a finite number" command fracture --arg "block nan 0 0 1 0 0"
expect_refused daemon-fracture-hex "fracture: '0x10' is not a finite number .a decimal" command fracture --arg "block 0x10 0 0 1 0 0"
expect_refused daemon-fracture-zero-normal 'fracture: the normal is zero' command fracture --arg "block 0 0 0 0 0 0"
expect_refused daemon-fracture-negative-radius 'fracture: radius -1 m is negative' command fracture --arg "block 0 0 0 1 0 0 -1"
expect_refused daemon-fracture-unknown-object "fracture: no object named 'nosuch'" command fracture --arg "nosuch 0 0 0 1 0 0"
expect_refused daemon-fracture-unknown-id 'fracture: unknown object id 99' command fracture --arg "#99 0 0 0 1 0 0"

# expect_warned NAME CHANNEL VERB: a foreign or truncated message gets a warning naming the
# channel, no ack, and the daemon goes on with its state intact.
expect_warned() {
    local name=$1 ch=$2 verb=$3 before st h
    before=$(wc -l <"$CS_TMP/daemon.err")
    cs_bus "$verb" "$ch" >/dev/null
    st=$(status_line 2)
    if ! tail -n +"$((before + 1))" "$CS_TMP/daemon.err" | grep -q "ignored a message on $ch "; then
        cs_fail "$name" "no warning naming $ch on stderr"; return
    fi
    h=$(sed -n 's/^object id=1 name=block hash=\([0-9a-f]*\).*/\1/p' <<<"$st")
    if [ "$h" != "$h0" ] || ! kill -0 "$CS_DAEMON_PID" 2>/dev/null; then
        cs_fail "$name" "daemon died or state changed ($h0 -> $h)"; return
    fi
    cs_pass "$name"
}
expect_warned daemon-foreign-force CUBESIM_FORCE foreign
expect_warned daemon-foreign-command CUBESIM_COMMAND foreign
expect_warned daemon-truncated-force CUBESIM_FORCE truncated
expect_warned daemon-truncated-command CUBESIM_COMMAND truncated
expect_warned daemon-badlength-force CUBESIM_FORCE badlength
expect_warned daemon-badlength-command CUBESIM_COMMAND badlength
expect_warned daemon-unterminated-force CUBESIM_FORCE unterminated
expect_warned daemon-unterminated-command CUBESIM_COMMAND unterminated

# A flood of junk is rate-limited: at most 5 lines a second per kind, plus a summary.
before=$(wc -l <"$CS_TMP/daemon.err")
cs_bus truncated CUBESIM_FORCE --repeat 30 >/dev/null
sleep 1.3
status_line 1 >/dev/null   # the summary is printed on the daemon's next second
lines=$(tail -n +"$((before + 1))" "$CS_TMP/daemon.err" | grep -c 'ignored a message on CUBESIM_FORCE')
if [ "$lines" -le 10 ] && tail -n +"$((before + 1))" "$CS_TMP/daemon.err" | grep -q 'more .* warnings suppressed'; then
    cs_pass daemon-warning-rate-limit
else
    cs_fail daemon-warning-rate-limit "$lines warning lines for 30 junk messages, or no summary"
fi

# A burst of 5000 inputs at once: every one gets its ack (here refused: no such object, so
# the state stays as it is). An outside client lost up to a quarter of such a burst without a
# word: LCM's subscription queue held 1000 and dropped the rest silently.
# (the tool's socket gets the daemon's 4 MiB receive buffer: it takes 5000 acks at once)
b=$("$CS_IT_BIN/cs_it_bus" --lcm "$CS_LCM_URL&recv_buf_size=4194304" --timeout 30 force \
    --name no-such-object --point 0.1,0.1,0.1 --force 0,0,0 --duration 0 --cid 100000 \
    --burst 5000)
case "$b" in
"burst sent=5000 acked=5000 "*) cs_pass "daemon-burst-all-acked ($b)" ;;
*) cs_fail daemon-burst-all-acked "'$b'" ;;
esac

# The hash check above is not vacuous: a real force and a few steps change it.
ack=$(cs_bus force --name block --point 0.1,0.1,0.1 --force 0,5,0 --duration 0.05)
ack2=$(cs_bus command step --count 10)
for i in $(seq 1 40); do   # until the 10 steps are done (slow under sanitizers)
    st=$(status_line 1)
    grep -q 'paused=1' <<<"$st" && break
done
h=$(sed -n 's/^object id=1 name=block hash=\([0-9a-f]*\).*/\1/p' <<<"$st")
if grep -q '^ack ok=1' <<<"$ack" && grep -q '^ack ok=1' <<<"$ack2" && [ -n "$h" ] && [ "$h" != "$h0" ] \
    && grep -q 'paused=1' <<<"$st"; then
    cs_pass daemon-good-force-moves
else
    cs_fail daemon-good-force-moves "acks '$ack' '$ack2', hash $h0 -> $h, status $(head -1 <<<"$st")"
fi

# reset: a new epoch, the rest shape back (same hash as a fresh daemon's first status? the
# rest hash differs from the sagged one), still paused.
ack=$(cs_bus command reset)
st=$(status_line 2)
ep=$(sed -n 's/^status .* epoch=\([0-9]*\) .*/\1/p' <<<"$st")
if grep -q '^ack ok=1' <<<"$ack" && [ "$ep" = "$((ep0 + 1))" ]; then cs_pass daemon-reset-epoch
else cs_fail daemon-reset-epoch "ack '$ack', epoch $ep0 -> $ep"; fi

# load: a good scene replaces the world (new epoch, the new object's name in the status).
sed 's/"name": "block"/"name": "block2"/' "$CS_TMP/block.json" >"$CS_TMP/block2.json"
ack=$(cs_bus command load --arg "$CS_TMP/block2.json")
st=$(status_line 2)
if grep -q '^ack ok=1 request=load' <<<"$ack" && grep -q 'name=block2 ' <<<"$st" \
    && grep -q "epoch=$((ep0 + 2)) " <<<"$st"; then
    cs_pass daemon-load-scene
else
    cs_fail daemon-load-scene "ack '$ack', status $(tr '\n' ' ' <<<"$st")"
fi

# A burst of 5000 forces on the (paused) object: every one acked, exactly 1024 taken (an
# object's active inputs; the rest refused, by that limit or the full input queue).
before=$(wc -l <"$CS_TMP/daemon.err")
b=$("$CS_IT_BIN/cs_it_bus" --lcm "$CS_LCM_URL&recv_buf_size=4194304" --timeout 30 force \
    --name block2 --point 0.1,0.1,0.1 --force 0,0,0 --duration 0 --cid 200000 --burst 5000)
case "$b" in
"burst sent=5000 acked=5000 ok=1024") cs_pass "daemon-burst-to-an-object ($b)" ;;
*) cs_fail daemon-burst-to-an-object "'$b'" ;;
esac
# ... and the log holds a few lines of each kind a second and a summary, not 5000 lines (the
# 1024 applied forces were 1024 lines until session 42).
sleep 1.3
status_line 1 >/dev/null   # the summaries are printed on the daemon's next second
burst_log=$(tail -n +"$((before + 1))" "$CS_TMP/daemon.err")
applied=$(grep -c 'force from client [0-9]* (command [0-9]*) applied' <<<"$burst_log")
refused=$(grep -c 'refused force from client' <<<"$burst_log")
if [ "$applied" -ge 1 ] && [ "$applied" -le 15 ] && [ "$refused" -le 15 ] \
    && grep -q "more 'applied input, client [0-9]*' lines suppressed" <<<"$burst_log" \
    && grep -q "more 'refused input, client [0-9]*' warnings suppressed" <<<"$burst_log"; then
    cs_pass "daemon-burst-log-rate-limited ($applied applied, $refused refused lines)"
else
    cs_fail daemon-burst-log-rate-limited "$applied applied and $refused refused lines, $(wc -l <<<"$burst_log") in all: $(tail -3 <<<"$burst_log" | tr '\n' '|')"
fi

if cs_stop_daemon TERM; then cs_pass daemon-sigterm-exit0; else cs_fail daemon-sigterm-exit0 "exit status $CS_DAEMON_RC"; fi
if [ "$(head -1 "$CS_TMP/nodes.csv" 2>/dev/null)" = "x,y,z,ux,uy,uz" ] && [ "$(wc -l <"$CS_TMP/nodes.csv")" -eq 28 ]; then
    cs_pass daemon-sigterm-dump-nodes
else
    cs_fail daemon-sigterm-dump-nodes "nodes.csv missing or not header + 27 rows"
fi
if grep -Eq '^(g|o) block2' "$CS_TMP/out.obj" 2>/dev/null && grep -q '^v ' "$CS_TMP/out.obj"; then
    cs_pass daemon-sigterm-export
else
    cs_fail daemon-sigterm-export "out.obj missing or without a 'block2' group"
fi
if grep -q 'stopped by signal' "$CS_TMP/daemon.err"; then cs_pass daemon-sigterm-log
else cs_fail daemon-sigterm-log "no 'stopped by signal' line"; fi
cs_finish
