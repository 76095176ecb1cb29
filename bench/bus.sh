#!/usr/bin/env bash
# bench/bus.sh — does the bus keep up? (issue 7 part 3) cubesimd publishes the deltas of a
# falling sphere of BUS_VERTICES surface vertices (default 100 002; every vertex moves every
# frame, so every frame is a full delta) at 60 Hz in real time, while BUS_CLIENTS (default 2)
# bench_bus subscribers on the same host keep its surface from snapshot + deltas for
# BUS_SECONDS (default 30) wall seconds. Reports per client the frames received and complete,
# lost messages (header.seq gaps), bytes per frame, rate, latency (LCM receive time minus
# the frame's header.utime), CPU, and how many status hashes the client's copy matched; and the
# daemon's CPU. Runs inside a private network namespace (tests/it/lib.sh): no packet leaves.
#
#   bash bench/bus.sh                      # -> bench/results/bus.md
#   BUS_VERTICES=20000 BUS_SECONDS=5 bash bench/bus.sh
#   BUS_RECV_BUF=N: the clients' recv_buf_size (default: the clients' own, 4194304 — see
#   cs_client_url; the kernel caps it at net.core.rmem_max)
# Exit status 0 when every client received every frame of its window complete, with no loss
# and every hash checked equal; 1 otherwise (the table is written either way).
set -u
source "$(dirname "$0")/../tests/it/lib.sh"
CS_TEST_NAME=bench_bus
cs_netns_reexec "$@"

N=${BUS_VERTICES:-100000}
SECS=${BUS_SECONDS:-30}
NCLI=${BUS_CLIENTS:-2}
OUT=${BUS_OUT:-$CS_ROOT/bench/results/bus.md}
BIN=$CS_IT_BIN

"$BIN/bench_bus" mesh "$CS_TMP/sphere.obj" --vertices "$N" >"$CS_TMP/mesh.out" || exit 1
NV=$(sed -n 's/.*vertices=\([0-9]*\).*/\1/p' "$CS_TMP/mesh.out")
NT=$(sed -n 's/.*triangles=\([0-9]*\).*/\1/p' "$CS_TMP/mesh.out")
# Free fall (no ground, sleep off): every vertex moves by more than publish_epsilon = 0 each
# frame. Cubes of 0.25 m: a handful of cubes, so the physics is cheap and the bus is measured.
cat >"$CS_TMP/bus.json" <<JSON
{ "dt": 0.016666666666666666, "publish_hz": 60, "publish_epsilon": 0, "status_hz": 4,
  "keyframe_s": ${BUS_KEYFRAME:-2}, "sleep": { "steps": 0 },
  "objects": [ { "name": "sphere", "model": "corotational", "cube_size": 0.25,
                 "mesh": { "file": "sphere.obj" } } ] }
JSON

SUB_URL="$CS_LCM_URL${BUS_RECV_BUF:+&recv_buf_size=$BUS_RECV_BUF}"
pids=()
for c in $(seq 1 "$NCLI"); do
    "$BIN/bench_bus" sub --lcm "$SUB_URL" --duration "$SECS" --wait 60 >"$CS_TMP/sub$c.out" \
        2>"$CS_TMP/sub$c.err" &
    pids+=($!)
done
sleep 0.3
if ! cs_start_daemon --scene "$CS_TMP/bus.json" --realtime --quiet; then
    echo "bench_bus: the daemon did not start: $(tail -2 "$CS_TMP/daemon.err")" >&2
    exit 1
fi
tck=$(getconf CLK_TCK)
dcpu() { awk '{ print $14 + $15 }' "/proc/$CS_DAEMON_PID/stat"; }
d0=$(dcpu); t0=$(date +%s.%N)
for p in "${pids[@]}"; do wait "$p"; done
d1=$(dcpu); t1=$(date +%s.%N)
cs_stop_daemon TERM
daemon_cpu=$(awk -v a="$d0" -v b="$d1" -v t="$tck" -v w0="$t0" -v w1="$t1" \
    'BEGIN { printf "%.1f", 100 * (b - a) / t / (w1 - w0) }')

get() { sed -n "s/.* $2=\([^ ]*\).*/\1/p" "$1"; }
ok=1
mkdir -p "$(dirname "$OUT")"
{
    echo "# Bus throughput (bench/bus.sh)"
    echo
    echo "$(date -u '+%Y-%m-%d %H:%M UTC'), $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg)."
    echo "A falling UV sphere of $NV surface vertices ($NT triangles), publish_epsilon 0 (every"
    echo "vertex in every frame's delta), dt = 1/60 s, publish_hz 60, key frames every ${BUS_KEYFRAME:-2} s,"
    echo "\`cubesimd --realtime\`; $NCLI \`bench_bus sub\` clients (recv_buf_size=${BUS_RECV_BUF:-4194304}, net.core.rmem_max $(cat /proc/sys/net/core/rmem_max)) for $SECS s"
    echo "each, all in one private network namespace. Daemon CPU: ${daemon_cpu} % of one core."
    echo
    echo "| client | frames | complete | lost msgs | rate [Hz] | delta msgs/frame | bytes/frame | MB/s | latency p50 / p99 / max [ms] | CPU [% of a core] | hashes equal |"
    echo "|---|---|---|---|---|---|---|---|---|---|---|"
    for c in $(seq 1 "$NCLI"); do
        f="$CS_TMP/sub$c.out"
        if ! grep -q '^sub ' "$f"; then
            echo "| $c | no result: $(tr '\n' ' ' <"$CS_TMP/sub$c.err") | | | | | | | | | |"
            ok=0; continue
        fi
        fr=$(get "$f" frames); co=$(get "$f" complete); lo=$(get "$f" lost)
        ms=$(get "$f" delta_msgs); by=$(get "$f" bytes); w=$(get "$f" wall_s)
        hc=$(get "$f" hash_checked); hb=$(get "$f" hash_bad)
        ff=$(get "$f" first_frame); lf=$(get "$f" last_frame)
        span=$((lf - ff + 1))
        awk -v c="$c" -v fr="$fr" -v co="$co" -v lo="$lo" -v r="$(get "$f" rate_hz)" -v ms="$ms" \
            -v by="$by" -v w="$w" -v l50="$(get "$f" lat_ms_p50)" -v l99="$(get "$f" lat_ms_p99)" \
            -v lmx="$(get "$f" lat_ms_max)" -v cpu="$(get "$f" cpu_pct)" -v hc="$hc" -v hb="$hb" \
            -v span="$span" 'BEGIN {
            printf "| %d | %d of %d | %d | %d | %.2f | %.1f | %.0f | %.1f | %s / %s / %s | %s | %d of %d |\n",
                c, fr, span, co, lo, r, ms / fr, by / fr, by / w / 1e6, l50, l99, lmx, cpu, hc - hb, hc }'
        if [ "$fr" -ne "$span" ] || [ "$co" -ne "$fr" ] || [ "$lo" -ne 0 ] || [ "$hb" -ne 0 ] \
            || [ "$hc" -lt 1 ]; then ok=0; fi
    done
    echo
    echo "frames: physics frames of the client's window of which a delta arrived, of all frames"
    echo "published in it (first to last frame seen); complete: all of the frame's chunks arrived;"
    echo "lost: gaps in CUBESIM_DELTA's header.seq; latency: LCM's receive time of a frame's last"
    echo "chunk minus the frame's header.utime; hashes equal: CUBESIM_STATUS state_hash against the"
    echo "client's copy at that frame (bit-identical floats). Daemon real-time factor (last status):"
    echo "$(get "$CS_TMP/sub1.out" daemon_rtf), step $(get "$CS_TMP/sub1.out" daemon_step_ms) ms."
} >"$OUT"
cat "$OUT"
for c in $(seq 1 "$NCLI"); do echo "# client $c: $(cat "$CS_TMP/sub$c.out")" >&2; done
[ "$ok" = 1 ]
