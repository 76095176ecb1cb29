#!/usr/bin/env bash
# clients_badlogs — cubesim-replay on logs it cannot use: random bytes, empty, truncated,
# corrupted in the middle, missing, a directory, and a valid LCM log with no cubesim
# messages. Each must end with one line on stderr naming the problem and exit status 2 —
# never a crash (status >= 128) or a sanitizer report — in every mode (export, verify,
# playback). Runs in a private network namespace because playback opens the bus.
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
R="$CS_IT_BIN/cubesim-replay"
L="$CS_IT_BIN/cubesim-log"
P="$CS_IT_BIN/cubesim-push"
for b in "$R" "$L" "$P"; do
    [ -x "$b" ] || { cs_fail clients_badlogs "missing $b (run make)"; cs_finish; }
done
cd "$CS_TMP" || exit 1

# A valid log with foreign-to-replay content: two commands recorded by our logger.
"$L" valid.lcm --passive --duration 1.5 --quiet --lcm "$CS_LCM_URL" & lp=$!
sleep 0.4
"$P" --lcm "$CS_LCM_URL" --no-wait pause >/dev/null
"$P" --lcm "$CS_LCM_URL" --no-wait step 3 >/dev/null
wait $lp
sz=$(stat -c %s valid.lcm)
[ "$sz" -gt 28 ] || cs_fail clients_badlogs_setup "our logger wrote $sz bytes"

head -c 4096 /dev/urandom > random.lcm
: > empty.lcm
head -c $((sz - 7)) valid.lcm > truncated.lcm
head -c 20 valid.lcm > header_cut.lcm
cp valid.lcm corrupt.lcm
# Overwrite the second event's sync word (the first event is 28 + channel + data bytes).
first_len=$(( 28 + $(od -An -tu1 -j20 -N4 valid.lcm | awk '{print $1*16777216+$2*65536+$3*256+$4}') \
              + $(od -An -tu1 -j24 -N4 valid.lcm | awk '{print $1*16777216+$2*65536+$3*256+$4}') ))
printf '\x00\x11\x22\x33' | dd of=corrupt.lcm bs=1 seek="$first_len" conv=notrunc status=none
# A huge data length in the first event.
cp valid.lcm hugelen.lcm
printf '\x7f\xff\xff\xff' | dd of=hugelen.lcm bs=1 seek=24 conv=notrunc status=none
mkdir adir.lcm

check_bad() { # name file mode-args... : exit 2, exactly one line on stderr, mentioning the problem
    local name=$1 file=$2; shift 2
    "$R" "$file" "$@" >out.txt 2>err.txt </dev/null
    local rc=$? lines
    lines=$(wc -l < err.txt)
    if [ "$rc" -eq 2 ] && [ "$lines" -eq 1 ] && grep -q "cubesim-replay: " err.txt; then
        cs_pass "$name"
    else
        cs_fail "$name" "exit $rc, $lines stderr lines: $(head -c 300 err.txt | tr '\n' '|')"
    fi
}

for f in random empty truncated header_cut corrupt hugelen missing adir; do
    check_bad "replay_export_$f" "$f.lcm" --export out.obj
    check_bad "replay_verify_$f" "$f.lcm" --verify
    check_bad "replay_play_$f" "$f.lcm" --speed 0 --lcm "$CS_LCM_URL"
done
grep -q 'not an LCM event log' <("$R" random.lcm --verify 2>&1) \
    && cs_pass replay_random_says_not_a_log || cs_fail replay_random_says_not_a_log "wrong message"
grep -q 'truncated' <("$R" truncated.lcm --verify 2>&1) \
    && cs_pass replay_truncated_says_truncated || cs_fail replay_truncated_says_truncated "wrong message"
# A readable log without cubesim surfaces: a clean "no snapshot" error for rebuilds.
check_bad replay_export_no_surfaces valid.lcm --export out.obj
grep -q 'no cubesim snapshot' <("$R" valid.lcm --export out.obj 2>&1) \
    && cs_pass replay_no_surfaces_message || cs_fail replay_no_surfaces_message "wrong message"
# ... while playing it is fine (2 messages on the bus).
out=$("$R" valid.lcm --speed 0 --lcm "$CS_LCM_URL" </dev/null 2>&1)
rc=$?
[ $rc -eq 0 ] && grep -q 'published 2 messages' <<<"$out" \
    && cs_pass replay_play_valid || cs_fail replay_play_valid "exit $rc: $out"
# Usage errors are status 2 too, and never touch the file.
check_bad replay_usage_bad_speed valid.lcm --speed -1
check_bad replay_usage_frame_without_export valid.lcm --frame 3
cs_finish
