#!/usr/bin/env bash
# scenes/demo.sh — the demonstration behind `make run` (README.md, "The demo", says what it shows).
#
# Owns the end-to-end walk through daemon and clients, with no terminal and no arguments:
#   1. a private network namespace (as root `unshare -n`, else `unshare -rn`; lo up; multicast
#      224.0.0.0/4 via lo; no other link), so no LCM packet can leave the machine — or a loud
#      failure, never a silent skip (the same logic as tests/it/lib.sh);
#   2. cubesim-log recording build/demo/demo.lcmlog, then cubesimd --realtime on the scene;
#   3. cubesim-push: a force and a drag on the beam's free end, pause, resume, each with its ack;
#   4. SIGINT: the daemon stops cleanly and writes build/demo/live.obj;
#   5. cubesim-replay rebuilds build/demo/replayed.obj from the log alone and --verifies every
#      frame; the summary compares the two exports vertex by vertex against the stated bound
#      publish_epsilon + 2^-24·|x| (README.md, lcmtypes/delta_t.lcm).
# Exit 0 only if every stage worked; otherwise the stage that failed says why (exit 1).
#
# Environment: DEMO_SECONDS (wall seconds the daemon runs, default 6, at least 3),
# DEMO_SCENE (default scenes/default.json; it must have an object named "beam"; the clients'
# push and drag are the defaults below unless NAME.demo beside NAME.json sets them),
# DEMO_BIN (default build/bin), DEMO_OUT (default build/demo), DEMO_VOLUME_TOL (passed to
# cubesim-replay --verify as --volume-tol: adds its frame-to-frame volume check; default none).

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
SELF="$ROOT/scenes/$(basename "${BASH_SOURCE[0]}")"

die() { echo "demo: FAILED: $*"; exit 1; }

# ---- 1. the private network namespace --------------------------------------------------------
if [ "${CS_DEMO_NETNS:-}" != 1 ]; then
    command -v unshare >/dev/null && command -v ip >/dev/null \
        || die "unshare or ip is missing (make deps installs util-linux and iproute2)"
    if [ "$(id -u)" = 0 ]; then un=(unshare -n); else un=(unshare -rn); fi
    if ! probe=$("${un[@]}" true 2>&1); then
        die "cannot make a private network namespace: '${un[*]}' failed: ${probe//$'\n'/ }
      (the demo never sends LCM traffic on a shared network; run it as root or where
       unprivileged user namespaces are allowed)"
    fi
    CS_DEMO_NETNS=1 exec "${un[@]}" -- bash "$SELF" "$@"
    die "exec ${un[*]} failed"
fi
ip link set lo up >/dev/null 2>&1 || die "network namespace: cannot bring lo up"
if ! ip route add 224.0.0.0/4 dev lo 2>/dev/null; then
    ip route show 224.0.0.0/4 | grep -q 'dev lo' \
        || die "network namespace: cannot add the multicast route 224.0.0.0/4 dev lo"
fi
others=$(ip -o link show | awk -F': ' '{print $2}' | grep -v '^lo$' | tr '\n' ' ')
[ -z "$others" ] || die "network namespace: links besides lo: $others"
ip link show lo | grep -q 'UP' || die "network namespace: lo is not up"

# ---- settings --------------------------------------------------------------------------------
cd "$ROOT" || die "cannot enter $ROOT"
BIN=${DEMO_BIN:-build/bin}
OUT=${DEMO_OUT:-build/demo}
SCENE=${DEMO_SCENE:-scenes/default.json}
T=${DEMO_SECONDS:-6}
URL="udpm://239.255.76.67:7667?ttl=0"
awk -v t="$T" 'BEGIN { exit !(t + 0 == t && t >= 3 && t <= 3600) }' \
    || die "DEMO_SECONDS='$T' is not a number of seconds in [3, 3600]"
for b in cubesimd cubesim-push cubesim-log cubesim-replay; do
    [ -x "$BIN/$b" ] || die "missing $BIN/$b (run 'make' first, or 'make run')"
done
[ -r "$SCENE" ] || die "cannot read the scene $SCENE"

# The clients' inputs: a push on the beam's free end, then a drag of it. NAME.demo beside the
# scene may set any of them, one "key value..." per line (# starts a comment): a scene whose
# beam breaks needs a shorter push and a softer drag than one whose beam holds (README, "The
# demo").
PUSH_AT="0.4 0 0.55" PUSH_FORCE="0 40 0" PUSH_FOR=0.3
DRAG_AT="0.4 0 0.6" DRAG_TO="0.4 0 0.8" DRAG_STIFFNESS=400 DRAG_FOR=0.5
INPUTS=${SCENE%.json}.demo
if [ -f "$INPUTS" ]; then
    num='[-+]?([0-9]+[.]?[0-9]*|[.][0-9]+)([eE][-+]?[0-9]+)?'
    n=0
    while IFS= read -r line || [ -n "$line" ]; do
        n=$((n + 1))
        line=${line%%#*}
        read -r key rest <<<"$line"
        [ -z "$key" ] && continue
        case $key in
            push_at | push_force | drag_at | drag_to) want=3 ;;
            push_for | drag_stiffness | drag_for) want=1 ;;
            *) die "$INPUTS:$n: unknown key '$key' (push_at, push_force, push_for, drag_at, drag_to, drag_stiffness, drag_for)" ;;
        esac
        read -r -a vals <<<"$rest"
        [ "${#vals[@]}" = "$want" ] || die "$INPUTS:$n: $key takes $want number(s), got '${rest}'"
        for v in "${vals[@]}"; do
            [[ $v =~ ^$num$ ]] || die "$INPUTS:$n: $key: '$v' is not a number"
        done
        case $key in
            push_at) PUSH_AT=$rest ;; push_force) PUSH_FORCE=$rest ;; push_for) PUSH_FOR=$rest ;;
            drag_at) DRAG_AT=$rest ;; drag_to) DRAG_TO=$rest ;;
            drag_stiffness) DRAG_STIFFNESS=$rest ;; drag_for) DRAG_FOR=$rest ;;
        esac
    done <"$INPUTS"
fi
# (word splitting of the 3-vectors below is intended)
mkdir -p "$OUT" || die "cannot create $OUT"
LOG=$OUT/demo.lcmlog LIVE=$OUT/live.obj REPLAYED=$OUT/replayed.obj REST=$OUT/rest.obj
DLOG=$OUT/daemon.log LOGGER=$OUT/logger.txt
rm -f "$LOG" "$LIVE" "$REPLAYED" "$REST" "$DLOG" "$LOGGER" "$OUT/replay.txt" "$OUT/verify.txt"

# Processes this script started; stopped (by pid) whatever happens.
PD= PL=
cleanup() {
    local p
    for p in $PD $PL; do
        kill -0 "$p" 2>/dev/null && kill -KILL "$p" 2>/dev/null && wait "$p" 2>/dev/null
    done
}
trap cleanup EXIT
trap 'echo "demo: interrupted"; exit 130' INT TERM

T0=$(date +%s.%N)
now() { awk -v a="$T0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }'; }
# at FRACTION: sleep until FRACTION·T seconds after the daemon started.
at() {
    local d
    d=$(awk -v a="$T0" -v b="$(date +%s.%N)" -v f="$1" -v t="$T" \
        'BEGIN { d = a + f * t - b; printf "%.3f", (d > 0 ? d : 0) }')
    sleep "$d"
}
# wait_exit PID SECONDS: wait for PID to end (rc in WAIT_RC) or give up (WAIT_RC=timeout).
wait_exit() {
    local i n
    n=$(awk -v s="$2" 'BEGIN { printf "%d", s * 10 }')
    for ((i = 0; i < n; i++)); do kill -0 "$1" 2>/dev/null || break; sleep 0.1; done
    if kill -0 "$1" 2>/dev/null; then WAIT_RC=timeout; return 1; fi
    wait "$1"; WAIT_RC=$?
    [ "$WAIT_RC" = 0 ]
}

echo "cubesim demo: $SCENE for ${T} s, files in $OUT/"
echo "[1/5] private network namespace: lo up, multicast 224.0.0.0/4 via lo, no other link"
echo "      (no LCM packet can leave this machine)"

# ---- 2. logger, then daemon ------------------------------------------------------------------
"$BIN/cubesim-log" "$LOG" --lcm "$URL" </dev/null >"$LOGGER" 2>&1 & PL=$!
sleep 0.3
kill -0 "$PL" 2>/dev/null || die "cubesim-log did not start: $(head -3 "$LOGGER")"
T0=$(date +%s.%N)
"$BIN/cubesimd" --scene "$SCENE" --lcm "$URL" --realtime --export "$LIVE" </dev/null 2>"$DLOG" & PD=$!
for ((i = 0; i < 100; i++)); do
    grep -q '^cubesimd: session ' "$DLOG" 2>/dev/null && break
    kill -0 "$PD" 2>/dev/null || break
    sleep 0.1
done
grep -q '^cubesimd: session ' "$DLOG" \
    || die "cubesimd did not start: $(grep -v '^$' "$DLOG" | head -3 | tr '\n' '|')"
echo "[2/5] cubesim-log records the bus to $LOG; cubesimd (pid $PD) runs in real time:"
sed -n 's/^cubesimd: /      /p' "$DLOG" | head -2

# ---- 3. drive the beam -----------------------------------------------------------------------
echo "[3/5] cubesim-push drives the daemon (each line: wall time, request, the daemon's ack)"
PUSH_FAILED=0
push() {
    local out rc
    out=$("$BIN/cubesim-push" --lcm "$URL" --timeout 15 "$@" </dev/null 2>&1)
    rc=$?
    printf '      t=%4ss  %-58s -> %s\n' "$(now)" "$*" "${out//$'\n'/ }"
    if [ $rc -ne 0 ]; then PUSH_FAILED=1; fi
}
# shellcheck disable=SC2086
at 0.10; push force beam --at $PUSH_AT --force $PUSH_FORCE --for "$PUSH_FOR"
# shellcheck disable=SC2086
at 0.25; push drag beam --at $DRAG_AT --to $DRAG_TO --stiffness "$DRAG_STIFFNESS" --for "$DRAG_FOR"
at 0.50; push pause
at 0.70; push resume
[ $PUSH_FAILED = 0 ] || die "a push was refused or not acknowledged (see above; daemon log: $DLOG)"

# ---- 4. stop -----------------------------------------------------------------------------------
at 1.00
kill -INT "$PD" 2>/dev/null
wait_exit "$PD" 30 || die "cubesimd did not stop cleanly on SIGINT (exit $WAIT_RC; see $DLOG)"
PD=
sleep 0.5
kill -INT "$PL" 2>/dev/null
wait_exit "$PL" 10 || die "cubesim-log did not stop cleanly (exit $WAIT_RC): $(tail -2 "$LOGGER")"
PL=
[ -s "$LIVE" ] || die "cubesimd wrote no $LIVE"
echo "[4/5] SIGINT: cubesimd exited 0 and wrote $LIVE; its log:"
grep -v 'behind real time' "$DLOG" | sed -n '3,$s/^cubesimd: /      /p'
behind=$(grep -c 'behind real time' "$DLOG")
if [ "$behind" -gt 0 ]; then
    echo "      (+ $behind 'behind real time' warnings: steps took longer than dt, so the daemon"
    echo "       skipped ahead; simulated time ran slower than the wall clock)"
fi
dframe=$(sed -n 's/.*stopped by signal after .*(frame \([0-9]*\),.*/\1/p' "$DLOG" | tail -1)
[ -n "$dframe" ] || die "no 'stopped by signal' line in $DLOG"
paused=$(sed -n 's/^cubesimd: paused at frame \([0-9]*\).*/\1/p' "$DLOG" | tail -1)
resumed=$(sed -n 's/^cubesimd: resumed at frame \([0-9]*\).*/\1/p' "$DLOG" | tail -1)
[ -n "$paused" ] && [ "$paused" = "$resumed" ] \
    || die "pause did not hold the world: paused at frame '$paused', resumed at '$resumed'"

# ---- 5. rebuild from the log alone -----------------------------------------------------------
grep -q '^lost ' "$LOGGER" || die "cubesim-log printed no summary: $(tail -2 "$LOGGER")"
"$BIN/cubesim-replay" "$LOG" --export "$REPLAYED" </dev/null >"$OUT/replay.txt" 2>&1 \
    || die "cubesim-replay --export failed: $(tail -3 "$OUT/replay.txt" | tr '\n' '|')"
"$BIN/cubesim-replay" "$LOG" --export "$REST" --frame 0 </dev/null >/dev/null 2>&1 \
    || die "cubesim-replay could not rebuild frame 0 (the first snapshot) from $LOG"
"$BIN/cubesim-replay" "$LOG" --verify ${DEMO_VOLUME_TOL:+--volume-tol "$DEMO_VOLUME_TOL"} \
    </dev/null >"$OUT/verify.txt" 2>&1
vrc=$?
echo "[5/5] cubesim-replay rebuilt the surfaces from $LOG alone:"
sed 's/^/      /' "$OUT/replay.txt"
echo "      $(tail -1 "$OUT/verify.txt")"
[ $vrc -eq 0 ] || die "cubesim-replay --verify found failures: $(head -3 "$OUT/verify.txt" | tr '\n' '|')"
rframe=$(awk '/^exported frame/ { print $3 }' "$OUT/replay.txt")

# ---- summary -----------------------------------------------------------------------------------
# publish_epsilon from the scene (default 1e-6 m, README.md "Scene files").
eps=$(tr -d '\n' <"$SCENE" | sed -n 's/.*"publish_epsilon"[[:space:]]*:[[:space:]]*\([-+0-9.eE]*\).*/\1/p')
eps=${eps:-1e-6}
# Same faces (topology: vertex indices; the exporter's normal and texture indices are left
# out, since it shares a normal between faces whose normals come out equal, which the live
# doubles and the replayed float32 positions need not do), then every vertex within
# eps + 2^-24·|x| (+ the OBJ text's ~1e-9 relative).
faces() { sed -n 's|/[0-9]*||g; s|/||g; /^f /p' "$1"; }
same_faces=0
cmp -s <(faces "$LIVE") <(faces "$REPLAYED") && same_faces=1
cmpres=$(paste -d' ' <(grep '^v ' "$LIVE") <(grep '^v ' "$REPLAYED") | awk -v eps="$eps" '
    { if (NF != 8) { bad++; next }
      for (i = 2; i <= 4; i++) { a = $i; b = $(i + 4); d = a - b; if (d < 0) d = -d;
        m = a < 0 ? -a : a; tol = eps + m * 2 ^ -24 + m * 1e-8 + 1e-12;
        if (d > maxd) maxd = d; if (d > tol) over++ } n++ }
    END { printf "%d %.3g %d %d", n, maxd, over + 0, bad + 0 }')
read -r nv maxd over bad <<<"$cmpres"
# The beam's free end: the beam's vertices at its largest rest x, averaged (rest = frame 0).
tip() {
    awk -v which="$2" '
        FNR == 1 { file++ }
        file == 1 && /^v / { n++; rx[n] = $2; ry[n] = $3; rz[n] = $4 }
        file == 1 && /^g / { ing = ($2 == "beam") }
        file == 1 && ing && /^f / { for (i = 2; i <= NF; i++) { split($i, p, "/"); use[p[1] + 0] = 1 } }
        file == 2 && /^v / { m++; x[m] = $2; y[m] = $3; z[m] = $4 }
        END { mx = -1e300; for (k in use) if (rx[k] > mx) mx = rx[k]
              for (k in use) if (rx[k] >= mx - 1e-6) { c++; sx += x[k]; sy += y[k]; sz += z[k] }
              if (c) printf "(%.3f, %.3f, %.3f)", sx / c, sy / c, sz / c }' "$REST" "$1"
}
tip_rest=$(tip "$REST"); tip_end=$(tip "$LIVE")
moved=$(awk -v a="$tip_rest" -v b="$tip_end" 'BEGIN { gsub(/[(),]/, " ", a); gsub(/[(),]/, " ", b);
    split(a, p, " "); split(b, q, " "); print sqrt((p[1]-q[1])^2 + (p[2]-q[2])^2 + (p[3]-q[3])^2) }')

channels=$(awk '$1 ~ /^CUBESIM_/ { n[$1] = $2 }
    END { split("SNAPSHOT DELTA TOPOLOGY STATUS ACK FORCE COMMAND", c, " ")
          for (i = 1; i <= 7; i++) { printf "%s%s %d", sep, c[i], n["CUBESIM_" c[i]]; sep = ", " } }' "$LOGGER")
lost=$(awk '/^lost / { print $2 }' "$LOGGER")
echo "summary"
echo "  frames          $dframe stepped by the daemon, $rframe rebuilt from the log" \
     "(paused at frame $paused, resumed at $resumed)"
echo "  messages        $channels"
echo "  lost            ${lost:-?} messages (gaps in the daemon's per-channel sequence numbers)"
echo "  live vs replay  $nv vertices, same triangles: $([ $same_faces = 1 ] && echo yes || echo NO);" \
     "largest difference $maxd m (bound $eps m + 2^-24·|x|)"
echo "  beam free end   $tip_rest at rest -> $tip_end at the end (moved $(printf '%.3f' "$moved") m)"
echo "  files           $LOG (the bus), $LIVE (the daemon's export),"
echo "                  $REPLAYED (rebuilt from the log), $REST (frame 0),"
echo "                  $DLOG (daemon stderr), $LOGGER (logger summary)"

[ "$lost" = 0 ] || die "cubesim-log lost ${lost:-?} messages"
[ "$rframe" = "$dframe" ] || die "the log rebuilds frame $rframe, the daemon stopped at frame $dframe"
[ "$same_faces" = 1 ] || die "live.obj and replayed.obj have different triangles"
[ "$nv" -gt 0 ] && [ "$bad" = 0 ] && [ "$over" = 0 ] \
    || die "$over of $nv vertices of replayed.obj are farther from live.obj than the bound ($bad malformed)"
[ -n "$tip_end" ] && awk -v d="$moved" 'BEGIN { exit !(d > 1e-3) }' \
    || die "the beam's free end did not move (by $moved m)"
echo "demo OK"
