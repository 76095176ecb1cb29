#!/usr/bin/env bash
# daemon_stream.sh — what cubesimd publishes is enough to follow it: a client that joins late
# takes the next key frame, applies every delta after it, and at each later key frame its
# copy equals the snapshot — exactly when publish_epsilon = 0, within publish_epsilon
# otherwise (README.md, CUBESIM_DELTA error bound). A large plate needs several snapshot chunks,
# all of which must arrive (pacing). Inside a private network namespace.
set -u
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"

beam() { # beam EPS: a soft undamped cantilever of 6 cubes that keeps swinging
    cat <<JSON
{ "dt": 0.01, "gravity": [0, 0, -9.81], "publish_hz": 100, "keyframe_s": 0.25,
  "status_hz": 10, "publish_epsilon": $1,
  "materials": { "m": { "young": 2000.0, "poisson": 0.3, "density": 100.0 } },
  "objects": [ { "name": "beam", "model": "corotational", "material": "m", "cube_size": 0.05,
                 "box": { "min": [0, 0, 0], "size": [0.3, 0.05, 0.05] },
                 "fixed": [ { "min": [-0.001, -1, -1], "max": [0.001, 1, 1] } ] } ] }
JSON
}
beam 0 >"$CS_TMP/beam0.json"
beam 2e-3 >"$CS_TMP/beam4.json"
cat >"$CS_TMP/plate.json" <<'JSON'
{ "dt": 0.01, "gravity": [0, 0, -9.81], "publish_hz": 100, "keyframe_s": 0.2,
  "publish_epsilon": 0,
  "materials": { "m": { "young": 5000.0, "poisson": 0.3, "density": 100.0 } },
  "objects": [ { "name": "plate", "model": "linear", "material": "m", "cube_size": 0.025,
                 "box": { "min": [0, 0, 0], "size": [1.0, 1.0, 0.025] },
                 "fixed": [ { "min": [-0.001, -1, -1], "max": [0.001, 2, 1] } ] } ] }
JSON

# run NAME SCENE MINERR MAXERR MINCHUNKS MINDELTAS DAEMON-ARGS...
run() {
    local name=$1 scene=$2 minerr=$3 maxerr=$4 minchunks=$5 mindeltas=$6; shift 6
    # The follower listens first, so it sees the sagging that follows the start.
    cs_bus --timeout 60 follow 3 >"$CS_TMP/follow.out" &
    local fpid=$! out
    sleep 0.2
    if ! cs_start_daemon --scene "$scene" "$@"; then
        cs_fail "$name" "daemon did not start: $(tail -2 "$CS_TMP/daemon.err" | tr '\n' ' ')"
        kill "$fpid"; wait "$fpid"; return
    fi
    wait "$fpid"
    out=$(cat "$CS_TMP/follow.out")
    [ -n "${CS_IT_VERBOSE:-}" ] && echo "# $name: $out"
    cs_stop_daemon TERM
    local cmp d e bad ch
    cmp=$(sed -n 's/.*compared=\([0-9]*\).*/\1/p' <<<"$out")
    d=$(sed -n 's/.*deltas=\([0-9]*\).*/\1/p' <<<"$out")
    e=$(sed -n 's/.*max_error=\([^ ]*\).*/\1/p' <<<"$out")
    bad=$(sed -n 's/.*bad=\([0-9]*\).*/\1/p' <<<"$out")
    ch=$(sed -n 's/.*max_chunks=\([0-9]*\).*/\1/p' <<<"$out")
    if [ "${cmp:-0}" -ge 3 ] && [ "${d:-0}" -ge "$mindeltas" ] && [ "${bad:-1}" -eq 0 ] && [ "${ch:-0}" -ge "$minchunks" ] \
        && awk -v e="$e" -v lo="$minerr" -v m="$maxerr" 'BEGIN { exit !(e >= lo && e <= m) }'; then
        cs_pass "$name"
    else
        cs_fail "$name" "$out (want $minerr <= max_error <= $maxerr, >= $minchunks chunks)"
    fi
}
# eps 0: every moved vertex resent, so the copy is the daemon's floats bit for bit.
run stream-follow-exact "$CS_TMP/beam0.json" 0 0 1 10 --realtime
# eps 2e-3: within 2e-3 (+ float rounding, < 1e-7 here); and not trivially 0 (some vertex
# moved less than eps since it was last sent), or the bound was not exercised.
run stream-follow-epsilon "$CS_TMP/beam4.json" 1e-12 2.001e-3 1 10 --realtime
# a 40x40 plate: ~3400 vertices and ~6700 triangles, several chunks per snapshot, as fast as possible.
run stream-follow-chunked "$CS_TMP/plate.json" 0 0 2 1
cs_finish
