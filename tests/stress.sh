#!/usr/bin/env bash
# tests/stress.sh — `make stress`: soak and stress checks of cubesimd and its clients, all
# inside a private network namespace (tests/it/lib.sh; if it cannot be made: FAIL, exit 1).
# Every check prints one PASS or FAIL line with its criterion; the last line is
# "N passed, N failed"; the exit status is 1 if any failed.
#
#   1. soak      cubesimd --realtime on scenes/default.json for STRESS_SECONDS (default 60):
#                4 workers send random valid and invalid forces, drags, commands and malformed
#                messages (each worker at most ~10 a second), 2 loggers record everything.
#   2. valgrind  the same for STRESS_SECONDS/2 (at least 10 s) under memcheck, plus a short
#                unpaced force burst: no memcheck error, no definite leak.
#   3. flood     one client sends forces at 5000/s for 10 s (at most 50 000), then 50 000
#                unpaced: only load-shedding refusals, never a crash, bounded VmRSS.
#   4. physics   tests/stress/long.json (a fully fixed, a base-fixed and a free block) for
#                STRESS_STEPS (default 10 000) steps as fast as possible: finite energies
#                that never rise, a settled end, a finite and plausible --dump-nodes.
#   5. fracture  cs_stress_fracture_storm (tests/stress/fracture_storm.c) at each seed of
#                STORM_SEEDS (default "1 5"): STORM_FRACTURES
#                (default 2000) forced fractures at random points and normals on a box, the
#                icosphere, the torus and the star, and a brittle cantilever broken again and
#                again by a load over a ground: every surface closed and consistently oriented
#                after every fracture and step, volumes kept within 1 %, no crash; then a small
#                run (40 fractures, 40 steps) under valgrind memcheck: no error, no definite
#                leak, and the peak RSS of each big run below 1 GiB.
#
# Timing is never asserted tightly: every bound is stated next to its check. Default total run
# time: about 5 minutes (STRESS_SECONDS=60; each storm seed about 45-60 s of it). Set CS_IT_KEEP=1 to keep the scratch folder.
set -u
source "$(dirname "$0")/it/lib.sh"
CS_TEST_NAME=stress
cs_netns_reexec "$@"

S=${STRESS_SECONDS:-60}
STEPS=${STRESS_STEPS:-10000}
VG_S=$(( S / 2 > 10 ? S / 2 : 10 ))
BIN=$CS_IT_BIN
SCENE=$CS_ROOT/scenes/default.json
LONG=$CS_ROOT/tests/stress/long.json
# Loggers and the flood probe get a bigger receive buffer (best effort: capped by rmem_max).
BIG_URL="$CS_LCM_URL&recv_buf_size=8388608"
N_PASS=0
N_FAIL=0
T_START=$(date +%s)

pass() { echo "PASS $1${2:+ ($2)}"; N_PASS=$((N_PASS + 1)); }
fail() { echo "FAIL $1: $2"; N_FAIL=$((N_FAIL + 1)); }
info() { echo "     $*"; }

# Background processes of ours (workers, loggers, samplers), stopped by pid at exit.
BG_PIDS=()
st_cleanup() {
    local p
    for p in "${BG_PIDS[@]}"; do kill -TERM "$p" 2>/dev/null; done
    for p in "${BG_PIDS[@]}"; do wait "$p" 2>/dev/null; done
    cs_cleanup
}
trap st_cleanup EXIT

# The binaries are copied first: others rebuilding build/bin during the run (a shared
# checkout) made a push exit 126 once, a binary half written.
mkdir -p "$CS_TMP/bin"
for b in cubesimd cubesim-push cubesim-log cubesim-replay cs_it_bus cs_stress_probe cs_stress_fracture_storm; do
    if [ ! -x "$BIN/$b" ] || ! cp "$BIN/$b" "$CS_TMP/bin/$b"; then
        echo "FAIL stress: $BIN/$b missing (run make)"
        echo "0 passed, 1 failed"
        exit 1
    fi
done
BIN=$CS_TMP/bin
CS_IT_BIN=$BIN

# start_daemon LABEL PREFIX-WORDS... -- DAEMON-ARGS...: cubesimd (optionally under a wrapper
# such as valgrind) in the background, stderr to $CS_TMP/LABEL.err; waits up to WAIT_S (default
# 10) seconds for its first status.
start_daemon() {
    local label=$1 wait_s=${WAIT_S:-10}; shift
    local -a pre=()
    while [ "$1" != -- ]; do pre+=("$1"); shift; done
    shift
    DERR=$CS_TMP/$label.err
    "${pre[@]}" "$BIN/cubesimd" --lcm "$CS_LCM_URL" "$@" 2>"$DERR" &
    CS_DAEMON_PID=$!
    local t0=$SECONDS
    while [ $((SECONDS - t0)) -lt "$wait_s" ]; do
        if cs_bus --timeout 1 status >/dev/null 2>&1; then return 0; fi
        kill -0 "$CS_DAEMON_PID" 2>/dev/null || return 1
    done
    return 1
}

# stop_daemon [WAIT_S]: SIGTERM, wait (default 20 s), DAEMON_RC = exit status or "timeout".
stop_daemon() {
    local wait_s=${1:-20} t0=$SECONDS
    DAEMON_RC=
    kill -TERM "$CS_DAEMON_PID" 2>/dev/null
    while kill -0 "$CS_DAEMON_PID" 2>/dev/null && [ $((SECONDS - t0)) -lt "$wait_s" ]; do
        sleep 0.2
    done
    if kill -0 "$CS_DAEMON_PID" 2>/dev/null; then
        kill -KILL "$CS_DAEMON_PID" 2>/dev/null
        wait "$CS_DAEMON_PID" 2>/dev/null
        DAEMON_RC=timeout
    else
        wait "$CS_DAEMON_PID"
        DAEMON_RC=$?
    fi
    CS_DAEMON_PID=
}

rss_kb() { awk '/^VmRSS:/ { print $2 }' "/proc/$1/status" 2>/dev/null; }

# ---------------------------------------------------------------------------------------------
# A worker: until DEADLINE (epoch seconds), one random operation every 50–150 ms. Each line of
# OUT is "OP EXPECTED GOT": for cubesim-push EXPECTED/GOT are exit statuses (0 ok, 1 refused
# by the daemon, 2 refused by the client itself, 3 no ack); for cs_it_bus requests "ok1",
# "ok0" or "noack"; for malformed messages (which cannot be acknowledged) "sent".
# Forces are at most 5 N for at most 0.2 s, drags 50 N/m: bounded, so no step may diverge.
worker() {
    local k=$1 deadline=$2 out=$3 to=$4 op exp got r a
    RANDOM=$((k * 7919 + 17))
    local -a objs=(beam beam '#1' ball '#2')
    local -a at_beam=("0.4 0 0.55" "0.3 0.05 0.6" "0.2 -0.05 0.5" "0.39 0 0.6")
    local -a at_ball=("0.8 0 0.5" "0.7 0 0.4" "0.8 0.1 0.4")
    local -a junk=(truncated badlength unterminated foreign)
    local -a jch=(CUBESIM_FORCE CUBESIM_COMMAND)
    push() { "$BIN/cubesim-push" --lcm "$CS_LCM_URL" --timeout "$to" "$@" >/dev/null 2>&1; }
    busreq() {
        a=$(cs_bus --timeout "$to" "$@" 2>/dev/null)
        case "$a" in "ack ok=1"*) got=ok1 ;; "ack ok=0"*) got=ok0 ;; *) got=noack ;; esac
    }
    f() { echo "$(( RANDOM % 11 - 5 )).$(( RANDOM % 10 ))"; }
    while [ "$(date +%s)" -lt "$deadline" ]; do
        r=$((RANDOM % 20))
        local o=${objs[RANDOM % 5]} at
        case "$o" in beam | '#1') at=${at_beam[RANDOM % 4]} ;; *) at=${at_ball[RANDOM % 3]} ;; esac
        case $r in
        0 | 1 | 2 | 3 | 4) op=force exp=0
            push force "$o" --at $at --force "$(f)" "$(f)" "$(f)" --for 0.$((RANDOM % 3)); got=$? ;;
        5 | 6) op=drag exp=0
            push drag "$o" --at $at --to 0.5 0 0.7 --stiffness 50 --for 0.2; got=$? ;;
        7) op=force-huge exp=1
            push force "$o" --at $at --force 0 0 1e300; got=$? ;;
        8) op=force-unknown exp=1
            if [ $((RANDOM % 2)) = 0 ]; then push force nosuch --at 0 0 0 --force 0 0 1
            else push drag '#99' --at 0 0 0 --to 0 0 1; fi; got=$? ;;
        9) op=force-nan-client exp=2
            push force "$o" --at $at --force nan 0 0; got=$? ;;
        10) op=force-nan-bus exp=ok0
            busreq force --name beam --point 0.4,0,0.55 --force 0,nan,0 ;;
        11) op=malformed exp=sent
            # A failed publish is the test tool's trouble, not the daemon's: logged, retried once.
            local jk=${junk[RANDOM % 4]} jc=${jch[RANDOM % 2]}
            if cs_bus "$jk" "$jc" >/dev/null 2>"$out.tmp"; then got=sent
            else
                echo "$jk $jc exit $?: $(tr '\n' ' ' <"$out.tmp")" >>"$out.senderr"
                sleep 0.1
                if cs_bus "$jk" "$jc" >/dev/null 2>>"$out.senderr"; then got=sent; else got=error; fi
            fi ;;
        12) op=pause exp=0; push pause; got=$? ;;
        13 | 14) op=resume exp=0; push resume; got=$? ;;
        15) op=step exp=0; push step $((RANDOM % 20 + 1)); got=$? ;;
        16) op=snapshot exp=0; push snapshot; got=$? ;;
        17) op=reset exp=0; push reset; got=$? ;;
        18) op=unknown-command exp=ok0; busreq command explode ;;
        19) op=step-zero exp=ok0; busreq command step --count 0 ;;
        esac
        echo "$op $exp $got" >>"$out"
        sleep "$(printf '0.%03d' $((RANDOM % 100 + 50)))"
    done
}

# soak LABEL SECONDS PUSH_TIMEOUT MIN_RATE [PREFIX-WORDS...]: phase 1 (and, with a valgrind
# prefix, 2). MIN_RATE: the least operations per second the 4 workers must have managed (a
# push waits for its ack, so a slow daemon slows them down).
soak() {
    local label=$1 secs=$2 to=$3 min_rate=$4; shift 4
    local -a pre=("$@")
    local t0=$SECONDS
    if ! WAIT_S=$((${#pre[@]} ? 120 : 10)) start_daemon "$label" "${pre[@]}" -- \
        --scene "$SCENE" --realtime; then
        fail "$label-daemon-starts" "no status within the wait: $(tail -3 "$DERR" | tr '\n' ' ')"
        [ -n "$CS_DAEMON_PID" ] && stop_daemon 5
        return
    fi
    pass "$label-daemon-starts" "a status within $((SECONDS - t0)) s"
    local lg
    for lg in 1 2; do
        "$BIN/cubesim-log" "$CS_TMP/$label-$lg.lcm" --lcm "$BIG_URL" \
            >"$CS_TMP/$label-log$lg.out" 2>&1 &
        eval "LOGPID$lg=$!"
        BG_PIDS+=($!)
    done
    sleep 1   # the loggers subscribe before the traffic starts
    local deadline=$(( $(date +%s) + secs )) w
    local -a wp=()
    for w in 1 2 3 4; do
        : >"$CS_TMP/$label-w$w.txt"
        worker "$w" "$deadline" "$CS_TMP/$label-w$w.txt" "$to" &
        wp+=($!)
        BG_PIDS+=($!)
    done
    for w in "${wp[@]}"; do wait "$w"; done
    if [ ${#pre[@]} -gt 0 ]; then
        # Under valgrind the refusal paths of an unpaced burst, too (after the workers: a
        # burst overflows the daemon's socket, and their requests would be lost with it).
        "$BIN/cs_stress_probe" --lcm "$BIG_URL" flood --name beam --point 0.4,0,0.55 \
            --force 0,0,-1 --count 3000 --rate 0 --seconds 5 --linger 10 \
            >"$CS_TMP/$label-burst.txt" 2>&1
        info "$label burst: $(head -1 "$CS_TMP/$label-burst.txt")"
    fi

    # Results of the workers.
    cat "$CS_TMP/$label"-w?.txt >"$CS_TMP/$label-ops.txt"
    if cat "$CS_TMP/$label"-w?.txt.senderr >"$CS_TMP/$label-senderr.txt" 2>/dev/null; then
        info "$label: $(wc -l <"$CS_TMP/$label-senderr.txt") malformed publishes retried: $(head -1 "$CS_TMP/$label-senderr.txt")"
    fi
    local total noack wrong
    total=$(wc -l <"$CS_TMP/$label-ops.txt")
    noack=$(awk '$3 == 3 || $3 == "noack"' "$CS_TMP/$label-ops.txt" | wc -l)
    wrong=$(awk '$2 != $3' "$CS_TMP/$label-ops.txt" | wc -l)
    info "$label: $total operations: $(awk '{ n[$1]++ } END { for (o in n) printf "%s=%d ", o, n[o] }' \
        "$CS_TMP/$label-ops.txt")"
    if [ "$total" -ge $((secs * min_rate)) ]; then
        pass "$label-traffic" "$total operations >= $min_rate/s for $secs s"
    else
        fail "$label-traffic" "only $total operations in $secs s (want >= $min_rate/s)"
    fi
    if [ "$noack" -eq 0 ]; then pass "$label-every-push-acked" "no request without an ack within $to s"
    else fail "$label-every-push-acked" "$noack of $total requests got no ack within $to s"; fi
    if [ "$wrong" -eq 0 ]; then
        pass "$label-outcomes" "every valid request ok, every invalid one refused"
    else
        fail "$label-outcomes" "$wrong unexpected outcomes (op expected got): $(awk '$2 != $3' \
            "$CS_TMP/$label-ops.txt" | sort | uniq -c | head -5 | tr -s ' \n' ' ')"
    fi

    # The daemon is still there and answering.
    local ok=1
    kill -0 "$CS_DAEMON_PID" 2>/dev/null || ok=0
    local ack
    ack=$("$BIN/cubesim-push" --lcm "$CS_LCM_URL" --timeout "$to" snapshot 2>&1) || ok=0
    if [ "$ok" = 1 ] && [ "$ack" = ok ]; then pass "$label-daemon-answers" "a final snapshot request acked ok"
    else fail "$label-daemon-answers" "daemon gone or final snapshot not acked: '$ack'"; fi
    local bad_steps
    bad_steps=$(grep -cE 'step diverged|step failed' "$DERR")
    if [ "$bad_steps" -eq 0 ]; then pass "$label-no-divergence" "no step diverged or failed under forces <= 5 N"
    else fail "$label-no-divergence" "$bad_steps diverged/failed steps: $(grep -m1 -E 'diverged|failed' "$DERR")"; fi
    sleep 2   # the snapshot reaches the loggers

    stop_daemon $(( ${#pre[@]} ? 300 : 20 ))
    local vg_rc=${VG_RC:-97}
    if [ ${#pre[@]} -eq 0 ]; then
        if [ "$DAEMON_RC" = 0 ]; then pass "$label-sigterm-exit0"
        else fail "$label-sigterm-exit0" "exit status $DAEMON_RC"; fi
    else
        local supp
        supp=$(sed -n 's/.*suppressed: [0-9,]* bytes in \([0-9,]*\) blocks.*/\1/p' "$DERR" | tail -1)
        if [ "$DAEMON_RC" = 0 ] && [ "${supp:-0}" -le 1 ]; then
            pass "$label-memcheck-clean" "exit 0 after SIGTERM: no memcheck error, no definite leak (LCM's one-off mutex suppressed: ${supp:-0} block)"
        elif [ "$DAEMON_RC" = 0 ]; then
            fail "$label-memcheck-clean" "$supp leaked blocks matched the one-off LCM suppression (want <= 1)"
        elif [ "$DAEMON_RC" = "$vg_rc" ]; then
            fail "$label-memcheck-clean" "memcheck errors: $(grep -E 'ERROR SUMMARY|definitely lost' "$DERR" | tr '\n' ' ')"
        else
            fail "$label-memcheck-clean" "exit status $DAEMON_RC: $(tail -3 "$DERR" | tr '\n' ' ')"
        fi
        info "$label: $(grep -E 'ERROR SUMMARY' "$DERR" | sed 's/^==[0-9]*== //')"
    fi
    sleep 1
    local rc1 rc2 lost1 lost2
    kill -INT "$LOGPID1" "$LOGPID2" 2>/dev/null
    wait "$LOGPID1"; rc1=$?
    wait "$LOGPID2"; rc2=$?
    lost1=$(sed -n 's/^lost \([0-9]*\) messages.*/\1/p' "$CS_TMP/$label-log1.out")
    lost2=$(sed -n 's/^lost \([0-9]*\) messages.*/\1/p' "$CS_TMP/$label-log2.out")
    info "$label logger 1: $(head -1 "$CS_TMP/$label-log1.out")"
    if [ "$rc1" = 0 ] && [ "$rc2" = 0 ] && [ "${lost1:-x}" = 0 ] && [ "${lost2:-x}" = 0 ]; then
        pass "$label-loggers-no-loss" "both loggers exit 0 and report 0 lost messages"
    else
        fail "$label-loggers-no-loss" "exit $rc1/$rc2, lost '${lost1}'/'${lost2}' (they must report 0)"
    fi
    local v
    for lg in 1 2; do
        v=$("$BIN/cubesim-replay" "$CS_TMP/$label-$lg.lcm" --verify 2>&1)
        if [ $? = 0 ]; then pass "$label-replay-verify-$lg" "$(tail -1 <<<"$v")"
        else fail "$label-replay-verify-$lg" "$(tail -3 <<<"$v" | tr '\n' ' ')"; fi
    done
    # Two loggers that saw every message rebuild the same final surfaces (frame and hashes).
    local e1 e2
    e1=$("$BIN/cubesim-replay" "$CS_TMP/$label-1.lcm" --export "$CS_TMP/$label-1.obj" 2>&1 | grep -v 'wrote\|export')
    e2=$("$BIN/cubesim-replay" "$CS_TMP/$label-2.lcm" --export "$CS_TMP/$label-2.obj" 2>&1 | grep -v 'wrote\|export')
    if [ -n "$e1" ] && [ "$e1" = "$e2" ] && grep -q hash <<<"$e1"; then
        pass "$label-loggers-agree" "both logs rebuild the same final frame and state hashes"
    else
        fail "$label-loggers-agree" "log 1: $(tr '\n' ' ' <<<"$e1") / log 2: $(tr '\n' ' ' <<<"$e2")"
    fi
}

echo "stress: STRESS_SECONDS=$S (soak $S s, valgrind $VG_S s), STRESS_STEPS=$STEPS"

# 1. ------------------------------------------------------------------------------------------
soak soak "$S" 5 4

# 2. ------------------------------------------------------------------------------------------
if command -v valgrind >/dev/null; then
    VG_RC=97
    soak valgrind "$VG_S" 60 1 valgrind --error-exitcode=$VG_RC --leak-check=full \
        --errors-for-leak-kinds=definite --show-possibly-lost=no --show-reachable=no \
        --suppressions="$CS_ROOT/tests/stress/lcm.supp"
else
    fail valgrind "valgrind is not installed (make deps installs it)"
fi

# 3. ------------------------------------------------------------------------------------------
if start_daemon flood -- --scene "$SCENE" --realtime; then
    pass flood-daemon-starts
    sleep 2
    rss0=$(rss_kb "$CS_DAEMON_PID")
    frame_of() { cs_bus --timeout 5 status 2>/dev/null | sed -n 's/^status .* frame=\([0-9]*\) .*/\1/p'; }
    f0=$(frame_of) w0=$(date +%s.%N)
    ( while kill -0 "$CS_DAEMON_PID" 2>/dev/null; do rss_kb "$CS_DAEMON_PID"; sleep 0.25; done ) \
        >"$CS_TMP/flood-rss.txt" 2>/dev/null &
    BG_PIDS+=($!)
    "$BIN/cs_stress_probe" --lcm "$BIG_URL" flood --name beam --point 0.4,0,0.55 \
        --force 0,0,-1 --count 50000 --rate 5000 --seconds 10 --linger 5 >"$CS_TMP/flood1.txt" 2>&1
    rc_a=$?
    f1=$(frame_of) w1=$(date +%s.%N)
    alive_a=$([ -n "$f1" ] && echo yes || echo no)
    # Not a check (it depends on the machine): how far 5000 forces a second slow the physics.
    info "paced flood: real-time factor $(awk -v a="${f0:-0}" -v b="${f1:-0}" -v s="$w0" -v e="$w1" \
        'BEGIN { printf "%.2f", (b - a) * 0.0166667 / (e - s) }') (frames $f0 -> $f1)"
    rss1=$(rss_kb "$CS_DAEMON_PID")
    "$BIN/cs_stress_probe" --lcm "$BIG_URL" flood --name beam --point 0.4,0,0.55 \
        --force 0,0,-1 --count 50000 --rate 0 --seconds 10 --linger 5 >"$CS_TMP/flood2.txt" 2>&1
    rc_b=$?
    alive_b=$(cs_bus --timeout 5 status >/dev/null 2>&1 && echo yes || echo no)
    rss2=$(rss_kb "$CS_DAEMON_PID")
    info "paced:   $(head -1 "$CS_TMP/flood1.txt")"
    info "unpaced: $(head -1 "$CS_TMP/flood2.txt")"
    for n in 1 2; do
        line=$(head -1 "$CS_TMP/flood$n.txt")
        val() { sed -n "s/.* $1=\([0-9]*\).*/\1/p" <<<"$line"; }
        sent=$(val sent) acks=$(val acks) other=$(val other) dup=$(val dup) stray=$(val stray)
        if [ -n "$sent" ] && [ "$sent" -gt 0 ] && [ "$sent" -le 50000 ] && [ "${acks:-0}" -ge 1 ] \
            && [ "$acks" -le "$sent" ] && [ "$other" = 0 ] && [ "$dup" = 0 ] && [ "$stray" = 0 ]; then
            pass "flood-$n-acks" "1..sent acks, none twice or unknown, every refusal a load refusal (queue full / active inputs)"
        else
            fail "flood-$n-acks" "$line $(sed -n 2p "$CS_TMP/flood$n.txt")"
        fi
    done
    if [ "$alive_a" = yes ] && [ "$alive_b" = yes ] && kill -0 "$CS_DAEMON_PID" 2>/dev/null \
        && [ "$("$BIN/cubesim-push" --lcm "$CS_LCM_URL" --timeout 5 snapshot 2>&1)" = ok ]; then
        pass flood-daemon-survives "status after each flood, final snapshot acked ok"
    else
        fail flood-daemon-survives "status after floods: $alive_a/$alive_b; daemon $(kill -0 "$CS_DAEMON_PID" 2>/dev/null && echo running || echo gone)"
    fi
    stop_daemon 20
    if [ "$DAEMON_RC" = 0 ]; then pass flood-sigterm-exit0; else fail flood-sigterm-exit0 "exit status $DAEMON_RC"; fi
    peak=$(sort -n "$CS_TMP/flood-rss.txt" | tail -1)
    info "VmRSS kB: before $rss0, after paced $rss1, after unpaced $rss2, peak ${peak:-?}"
    # Bounds: the outbox is capped at 64 MiB and the input queue at 4096 entries, so the peak
    # may not exceed the idle size by more than 64 MiB; a second flood of 50 000 may not add
    # more than 4 MiB (a leak of one small allocation per force would).
    if [ -n "$rss0" ] && [ -n "$peak" ] && [ "$peak" -le $((rss0 + 65536)) ]; then
        pass flood-rss-bounded "peak $peak kB <= idle $rss0 kB + 64 MiB"
    else
        fail flood-rss-bounded "peak ${peak:-?} kB vs idle ${rss0:-?} kB + 64 MiB"
    fi
    if [ -n "$rss1" ] && [ -n "$rss2" ] && [ "$rss2" -le $((rss1 + 4096)) ]; then
        pass flood-rss-no-growth "after a second flood $rss2 kB <= after the first $rss1 kB + 4 MiB"
    else
        fail flood-rss-no-growth "after the first flood ${rss1:-?} kB, after the second ${rss2:-?} kB (bound +4 MiB)"
    fi
else
    fail flood-daemon-starts "no status within 10 s: $(tail -3 "$DERR" | tr '\n' ' ')"
    [ -n "$CS_DAEMON_PID" ] && stop_daemon 5
fi

# 4. ------------------------------------------------------------------------------------------
"$BIN/cs_stress_probe" --lcm "$BIG_URL" energy --frame "$STEPS" --seconds 600 >"$CS_TMP/energy.txt" 2>&1 &
EPID=$!
BG_PIDS+=($EPID)
sleep 0.5
t0=$SECONDS
"$BIN/cubesimd" --lcm "$CS_LCM_URL" --scene "$LONG" --steps "$STEPS" --quiet \
    --dump-nodes "$CS_TMP/long.csv" 2>"$CS_TMP/long.err"
lrc=$?
wait "$EPID"
erc=$?
info "physics: $STEPS steps in $((SECONDS - t0)) s; $(cat "$CS_TMP/energy.txt")"
if [ "$lrc" = 0 ]; then pass physics-exit0 "$STEPS steps, exit 0"
else fail physics-exit0 "exit $lrc: $(tail -2 "$CS_TMP/long.err" | tr '\n' ' ')"; fi
if grep -qE 'diverged|failed' "$CS_TMP/long.err"; then
    fail physics-no-divergence "$(grep -m1 -E 'diverged|failed' "$CS_TMP/long.err")"
else
    pass physics-no-divergence "no step diverged or failed"
fi
eline=$(head -1 "$CS_TMP/energy.txt")
ev() { sed -n "s/.* $1=\([^ ]*\).*/\1/p" <<<"$eline"; }
if [ "$erc" = 0 ] && [ "$(ev nonfinite)" = 0 ] && [ "$(ev statuses)" -ge 2 ] && [ "$(ev frame)" = "$STEPS" ]; then
    pass physics-energy-finite "$(ev statuses) statuses up to frame $STEPS, every energy finite"
else
    fail physics-energy-finite "probe exit $erc: $eline"
fi
# A damped passive system: the total energy (kinetic + elastic + gravity) never rises above
# its first sample by more than 1% of |first| + 1 mJ, and the end is at rest: kinetic energy
# below 1e-3 of its peak + 1e-9 J.
if awk -v f="$(ev first)" -v m="$(ev max)" -v kl="$(ev ke_last)" -v km="$(ev ke_max)" 'BEGIN {
        a = f < 0 ? -f : f; exit !(m <= f + 0.01 * a + 1e-3 && kl <= 1e-3 * km + 1e-9) }'; then
    pass physics-energy-decays "max $(ev max) J <= first $(ev first) J + 1%; final kinetic $(ev ke_last) J"
else
    fail physics-energy-decays "first $(ev first), max $(ev max), kinetic peak $(ev ke_max), last $(ev ke_last)"
fi
# The dump: header + one row per node (anchored 27, column 81, free 64), every value finite;
# the anchored block did not move at all; every node within 1 m of its rest position; the free
# block rests on the ground (z + uz >= -5 mm everywhere, its top below 0.2 m).
if awk -F, 'NR == 1 { if ($0 != "x,y,z,ux,uy,uz") bad = "header " $0; next }
    { n++; for (i = 1; i <= 6; i++) if ($i !~ /^-?[0-9.]+(e[-+]?[0-9]+)?$/) bad = "row " NR ": " $0
      if (n <= 27 && ($4 != 0 || $5 != 0 || $6 != 0)) bad = "anchored node moved: " $0
      if ($4 * $4 + $5 * $5 + $6 * $6 > 1) bad = "node moved > 1 m: " $0
      if ($3 + $6 < -0.005) bad = "node below the ground: " $0
      if (n > 108 && $3 + $6 > 0.2) bad = "free block not on the ground: " $0 }
    END { if (n != 172) bad = bad " rows " n " (want 172)"; if (bad != "") { print bad; exit 1 } }' \
    "$CS_TMP/long.csv" >"$CS_TMP/long-check.txt" 2>&1; then
    pass physics-dump-nodes "172 finite rows, anchored block exact, free block resting on the ground"
else
    fail physics-dump-nodes "$(head -1 "$CS_TMP/long-check.txt")"
fi

# Statuses are observations: how often the daemon reports energies must not change the
# physics. The same scene for 300 steps with statuses only at start and stop (status_hz 0.5)
# twice, and with a status every millisecond of wall time: all three --dump-nodes files equal
# bit for bit (the first pair shows the run is deterministic, so the comparison means something).
sed 's/"status_hz": 20/"status_hz": 0.5/' "$LONG" >"$CS_TMP/quiet.json"
sed 's/"status_hz": 20/"status_hz": 1000/' "$LONG" >"$CS_TMP/chatty.json"
for v in quiet:a quiet:b chatty:c; do
    "$BIN/cubesimd" --lcm "$CS_LCM_URL" --scene "$CS_TMP/${v%:*}.json" --steps 300 --quiet \
        --dump-nodes "$CS_TMP/det-${v#*:}.csv" 2>>"$CS_TMP/det.err"
done
if ! cmp -s "$CS_TMP/det-a.csv" "$CS_TMP/det-b.csv" || [ ! -s "$CS_TMP/det-a.csv" ]; then
    fail physics-deterministic "two identical 300-step runs give different nodes (or none): $(head -2 "$CS_TMP/det.err" | tr '\n' ' ')"
else
    pass physics-deterministic "two identical 300-step runs give the same nodes bit for bit"
    if cmp -s "$CS_TMP/det-a.csv" "$CS_TMP/det-c.csv"; then
        pass physics-status-is-observation "statuses at 1000 Hz leave the nodes bit for bit unchanged"
    else
        fail physics-status-is-observation "statuses at 1000 Hz change the nodes: max |du| $(paste -d, \
            "$CS_TMP/det-a.csv" "$CS_TMP/det-c.csv" | awk -F, 'NR > 1 { for (i = 4; i <= 6; i++) {
            d = $i - $(i + 6); if (d < 0) d = -d; if (d > m) m = d } } END { printf "%.3g m", m }')"
    fi
fi

# 5. ------------------------------------------------------------------------------------------
NF=${STORM_FRACTURES:-2000}
# Seed 1, and seed 5: its fracture 1497 cut through a crack that had opened before (copies of
# surface vertices started on the crack's other side until fracture.c's sv_append_copy
# skinned them on their own; test_fracture_open.c is the small case).
for SEED in ${STORM_SEEDS:-1 5}; do
    "$BIN/cs_stress_fracture_storm" --fractures "$NF" --seed "$SEED" \
        --meshes "$CS_ROOT/scenes/meshes" >"$CS_TMP/storm-$SEED.txt" 2>&1
    src=$?
    grep -E '^(PASS|FAIL|     )' "$CS_TMP/storm-$SEED.txt" | sed 's/^ *//' | while IFS= read -r l; do info "seed $SEED: $l"; done
    sline=$(tail -1 "$CS_TMP/storm-$SEED.txt")
    if [ "$src" = 0 ] && grep -q ': ok$' <<<"$sline"; then
        pass fracture-storm-seed-$SEED "$sline"
    else
        fail fracture-storm-seed-$SEED "exit $src: $(grep -m1 '^FAIL' "$CS_TMP/storm-$SEED.txt") $sline"
    fi
    rss=$(sed -n 's/.*peak RSS \([0-9]*\) kB.*/\1/p' <<<"$sline")
    if [ -n "$rss" ] && [ "$rss" -le 1048576 ]; then pass fracture-storm-memory-seed-$SEED "peak RSS $rss kB <= 1 GiB"
    else fail fracture-storm-memory-seed-$SEED "peak RSS '${rss}' kB (bound 1 GiB)"; fi
done
if command -v valgrind >/dev/null; then
    valgrind --error-exitcode=97 --leak-check=full --errors-for-leak-kinds=definite \
        --show-possibly-lost=no --show-reachable=no "$BIN/cs_stress_fracture_storm" \
        --fractures 40 --steps 40 --meshes "$CS_ROOT/scenes/meshes" >"$CS_TMP/storm-vg.txt" 2>&1
    vrc=$?
    if [ "$vrc" = 0 ]; then
        pass fracture-storm-memcheck "40 fractures + 40 load steps: $(grep -m1 'ERROR SUMMARY' "$CS_TMP/storm-vg.txt" | sed 's/^==[0-9]*== //')"
    else
        fail fracture-storm-memcheck "exit $vrc: $(grep -E 'ERROR SUMMARY|definitely lost|^FAIL' "$CS_TMP/storm-vg.txt" | tr '\n' ' ')"
    fi
else
    fail fracture-storm-memcheck "valgrind is not installed (make deps installs it)"
fi

echo "stress: $(( $(date +%s) - T_START )) s"
echo "$N_PASS passed, $N_FAIL failed"
[ "$N_FAIL" -eq 0 ]
