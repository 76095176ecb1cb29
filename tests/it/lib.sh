#!/usr/bin/env bash
# tests/it/lib.sh — shared helpers of the integration tests (sourced), and, when run on its own
# (tests/run_all.sh runs every tests/it/*.sh), a check that a private network namespace with
# multicast on loopback can be made here: "PASS netns" or "FAIL netns: why".
#
#   cs_netns_reexec "$@"   re-run the calling script inside a private network namespace
#                          (as root `unshare -n`, else `unshare -rn`), bring lo up, route
#                          224.0.0.0/4 via lo. If any of it fails: a FAIL line, exit 1 — never
#                          a silent skip. No packet of a test can leave the machine.
#   cs_pass NAME / cs_fail NAME WHY / cs_check NAME CMD...   report; cs_finish exits 0/1
#   cs_start_daemon ARGS...  cubesimd in the background (stderr -> $CS_TMP/daemon.err),
#                          waits for its first status; cs_stop_daemon [SIG] stops it, sets
#                          CS_DAEMON_RC.
#   cs_bus ARGS...         the test-side LCM tool (tests/it/tools/bus.c) on $CS_LCM_URL.
# Binaries come from $CS_IT_BIN (default build/bin); the LCM URL is LCM's default with ttl=0.

CS_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
CS_IT_BIN=${CS_IT_BIN:-$CS_ROOT/build/bin}
CS_LCM_URL=${CS_LCM_URL:-"udpm://239.255.76.67:7667?ttl=0"}
CS_TEST_NAME=$(basename "$0" .sh)
CS_FAILED=0
CS_DAEMON_PID=
CS_DAEMON_RC=

cs_pass() { echo "PASS $1"; }
cs_fail() { echo "FAIL $1: $2"; CS_FAILED=1; }
cs_finish() { [ "$CS_FAILED" -eq 0 ] && exit 0; exit 1; }
# cs_need_bins NAME BIN...: fail test NAME and finish unless every BIN is built in $CS_IT_BIN
cs_need_bins() {
    local name=$1 b
    shift
    for b in "$@"; do
        [ -x "$CS_IT_BIN/$b" ] || { cs_fail "$name" "missing $CS_IT_BIN/$b (run make)"; cs_finish; }
    done
}

# cs_check NAME CMD...: PASS if CMD succeeds, else FAIL naming the command.
cs_check() {
    local name=$1; shift
    if "$@"; then cs_pass "$name"; else cs_fail "$name" "failed: $*"; fi
}

cs_netns_reexec() {
    if [ "${CS_NETNS_INSIDE:-}" = 1 ]; then
        local why=""
        ip link set lo up 2>&1 >/dev/null || why="cannot bring lo up"
        if [ -z "$why" ] && ! ip route add 224.0.0.0/4 dev lo 2>/dev/null; then
            ip route show 224.0.0.0/4 | grep -q lo || why="cannot add the multicast route 224.0.0.0/4 dev lo"
        fi
        if [ -z "$why" ] && ! ip link show lo | grep -q 'UP'; then why="lo is not up"; fi
        if [ -n "$why" ]; then
            echo "FAIL $CS_TEST_NAME: network namespace: $why"
            exit 1
        fi
        return 0
    fi
    local -a un
    if [ "$(id -u)" = 0 ]; then un=(unshare -n); else un=(unshare -rn); fi
    if ! command -v unshare >/dev/null || ! command -v ip >/dev/null; then
        echo "FAIL $CS_TEST_NAME: network namespace: unshare or ip missing (make deps installs util-linux, iproute2)"
        exit 1
    fi
    local probe
    if ! probe=$("${un[@]}" true 2>&1); then
        echo "FAIL $CS_TEST_NAME: network namespace: '${un[*]}' failed: ${probe//$'\n'/ }"
        exit 1
    fi
    rm -rf "$CS_TMP" # exec skips the EXIT trap; the inner run makes its own
    CS_NETNS_INSIDE=1 exec "${un[@]}" -- bash "$0" "$@"
    echo "FAIL $CS_TEST_NAME: network namespace: exec ${un[*]} failed"
    exit 1
}

cs_bus() { "$CS_IT_BIN/cs_it_bus" --lcm "$CS_LCM_URL" "$@"; }

# A scratch folder removed at exit; any daemon still running is stopped first.
CS_TMP=$(mktemp -d "${TMPDIR:-/tmp}/cs_it.XXXXXX")
cs_cleanup() {
    if [ -n "$CS_DAEMON_PID" ] && kill -0 "$CS_DAEMON_PID" 2>/dev/null; then
        kill -KILL "$CS_DAEMON_PID" 2>/dev/null
        wait "$CS_DAEMON_PID" 2>/dev/null
    fi
    if [ -n "${CS_IT_KEEP:-}" ]; then echo "kept $CS_TMP" >&2; else rm -rf "$CS_TMP"; fi
}
trap cs_cleanup EXIT

# cs_start_daemon ARGS...: start cubesimd on $CS_LCM_URL; returns 1 if no status within 10 s.
cs_start_daemon() {
    "$CS_IT_BIN/cubesimd" --lcm "$CS_LCM_URL" "$@" 2>"$CS_TMP/daemon.err" &
    CS_DAEMON_PID=$!
    local i
    for i in $(seq 1 20); do
        if cs_bus --timeout 0.5 status >/dev/null 2>&1; then return 0; fi
        kill -0 "$CS_DAEMON_PID" 2>/dev/null || break
    done
    return 1
}

# cs_stop_daemon [SIGNAL]: signal it (default TERM), wait up to 10 s, CS_DAEMON_RC = exit status.
cs_stop_daemon() {
    local sig=${1:-TERM} i
    CS_DAEMON_RC=
    [ -n "$CS_DAEMON_PID" ] || return 1
    kill -"$sig" "$CS_DAEMON_PID" 2>/dev/null
    for i in $(seq 1 100); do
        kill -0 "$CS_DAEMON_PID" 2>/dev/null || break
        sleep 0.1
    done
    if kill -0 "$CS_DAEMON_PID" 2>/dev/null; then
        kill -KILL "$CS_DAEMON_PID" 2>/dev/null
        wait "$CS_DAEMON_PID" 2>/dev/null
        CS_DAEMON_RC=timeout
    else
        wait "$CS_DAEMON_PID"
        CS_DAEMON_RC=$?
    fi
    CS_DAEMON_PID=
    [ "$CS_DAEMON_RC" = 0 ]
}

# Comparing two OBJ exports (cubesimd --export, cubesim-replay --export) face by face.
# The faces of an OBJ file as lines of 9 coordinates (independent of vertex welding/order).
obj_faces() {
    awk '/^v /{n++; x[n]=$2; y[n]=$3; z[n]=$4}
         /^f /{s=""; for(i=2;i<=NF;i++){split($i,p,"/"); k=p[1]+0; if(k<0)k=n+1+k;
               s=s" "x[k]" "y[k]" "z[k]} print substr(s,2)}' "$1"
}
# obj_close A B EPS: same faces, every coordinate within EPS + 2^-24|x| (+ text rounding).
obj_close() {
    local fa fb
    fa=$(obj_faces "$1" | wc -l); fb=$(obj_faces "$2" | wc -l)
    if [ "$fa" -ne "$fb" ] || [ "$fa" -eq 0 ]; then echo "faces $fa vs $fb"; return 1; fi
    paste -d' ' <(obj_faces "$1") <(obj_faces "$2") | awk -v eps="$3" '
        { if (NF != 18) { bad++; next }
          for (i = 1; i <= 9; i++) { a = $i; b = $(i + 9); d = a - b; if (d < 0) d = -d;
            m = a < 0 ? -a : a; tol = eps + m * (2 ^ -24) + m * 1e-8 + 1e-12;
            if (d - tol > worst) worst = d - tol; if (d > maxd) maxd = d } }
        END { printf "max |diff| %.3g", maxd; if (bad || worst > 0) { printf ", over bound by %.3g", worst; exit 1 } }'
}

# Run on its own: check that the namespace can be made (and that lib.sh itself works).
if [ "${BASH_SOURCE[0]}" = "$0" ]; then
    CS_TEST_NAME=netns
    cs_netns_reexec "$@"
    if ip route show 224.0.0.0/4 | grep -q 'dev lo' && [ "$(ip -o link show | wc -l)" -ge 1 ]; then
        # Only lo exists in the namespace: no way out.
        others=$(ip -o link show | awk -F': ' '{print $2}' | grep -v '^lo$' | tr '\n' ' ')
        if [ -z "$others" ]; then cs_pass netns; else cs_fail netns "links besides lo: $others"; fi
    else
        cs_fail netns "multicast route missing"
    fi
    cs_finish
fi
