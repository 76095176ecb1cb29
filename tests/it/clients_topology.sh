#!/usr/bin/env bash
# clients_topology — the clients on CUBESIM_TOPOLOGY, from hand-made logs (cs_it_mklog: a bar
# of two cubes breaks into two cubes at frame 2; see tests/it/tools/mklog.c), so this runs
# before the engine makes real fractures:
#   topo_verify_good        replay --verify passes every frame (closed pieces, volume kept at
#                           unchanged positions to 1e-9)
#   topo_verify_sources     the piece's crack vertices sent 0.5 mm off the client's copy of
#                           the left cube's (positions the client lags behind): naming their
#                           sources (topology_t.vnew_src), the volume still checks to 1e-9;
#                           without sources the same log fails at frame 2
#   topo_export_frame       --export --frame 2 writes both pieces (8 vertices, 12 triangles,
#                           one OBJ group each, named bar and bar.1)
#   topo_chunked            the same changes in 40-byte chunks rebuild bit-identical surfaces
#   topo_verify_volume      a piece 20 % too long fails --verify at frame 2 (volume), exit 1
#   topo_verify_open        a piece without its closing face fails (boundary edges), exit 1
#   topo_gap_noticed        a lost topology chunk: --verify fails at the fracture frame, the
#                           rebuild warns it went stale, and the next snapshot repairs it
#   topo_logger_asks        cubesim-log, hearing the gap on the bus, asks for a snapshot
# Inside a private network namespace (the last check publishes).
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
B=$CS_IT_BIN
cs_need_bins clients_topology cs_it_mklog cubesim-replay cubesim-log
cd "$CS_TMP" || exit 1
for m in good badvolume open gap lagged nosrc; do "$B/cs_it_mklog" $m.lcm $m || cs_fail "mklog_$m" "cs_it_mklog failed"; done
"$B/cs_it_mklog" chunked.lcm good --chunk-bytes 40

out=$("$B/cubesim-replay" good.lcm --verify --topology-tol 1e-9 2>&1); rc=$?
[ $rc -eq 0 ] && grep -q '^verify: 5 frames checked, 0 failed (2 topology changes' <<<"$out" \
    && cs_pass "topo_verify_good ($(tail -1 <<<"$out"))" || cs_fail topo_verify_good "exit $rc: $out"

out=$("$B/cubesim-replay" lagged.lcm --verify --topology-tol 1e-9 2>&1); rc=$?
out2=$("$B/cubesim-replay" nosrc.lcm --verify --topology-tol 1e-9 2>&1); rc2=$?
[ $rc -eq 0 ] && [ $rc2 -eq 1 ] && grep -q '^frame 2: .*unchanged positions.*expected' <<<"$out2" \
    && cs_pass "topo_verify_sources ($(sed -n 's/.*\(largest relative change [^,]*\).*/\1/p' <<<"$out"))" \
    || cs_fail topo_verify_sources "exit $rc/$rc2: $(tr '\n' '|' <<<"$out$out2")"

out=$("$B/cubesim-replay" good.lcm --export f2.obj --frame 2 2>&1); rc=$?
if [ $rc -eq 0 ] && grep -q "object 1 'bar': 8 vertices, 12 triangles" <<<"$out" \
    && grep -q "object 2 'bar.1': 8 vertices, 12 triangles" <<<"$out" \
    && grep -qx 'g bar' f2.obj && grep -qx 'g bar.1' f2.obj; then cs_pass topo_export_frame
else cs_fail topo_export_frame "exit $rc: $(tr '\n' '|' <<<"$out")"; fi

hashes() { "$B/cubesim-replay" "$1" --export "$2" --frame "$3" 2>/dev/null | grep hash; }
a=$(hashes good.lcm a.obj 3); b=$(hashes chunked.lcm b.obj 3)
ntopo=$(grep -ao CUBESIM_TOPOLOGY chunked.lcm | wc -l)
[ -n "$a" ] && [ "$a" = "$b" ] && [ "$ntopo" -gt 4 ] && cs_pass "topo_chunked ($ntopo chunks)" \
    || cs_fail topo_chunked "'$a' vs '$b' ($ntopo chunks)"

out=$("$B/cubesim-replay" badvolume.lcm --verify 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q '^frame 2: .*expected .* m^3' <<<"$out" && grep -q '1 failed' <<<"$out" \
    && cs_pass topo_verify_volume || cs_fail topo_verify_volume "exit $rc: $(tr '\n' '|' <<<"$out")"

out=$("$B/cubesim-replay" open.lcm --verify 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "^frame 2: .*bar.1.*boundary edges" <<<"$out" \
    && cs_pass topo_verify_open || cs_fail topo_verify_open "exit $rc: $(tr '\n' '|' <<<"$out")"

ok=1; why=""
out=$("$B/cubesim-replay" gap.lcm --verify 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q '^frame 2: ' <<<"$out" || { ok=0; why="verify: exit $rc $(tr '\n' '|' <<<"$out")"; }
out=$("$B/cubesim-replay" gap.lcm --export g3.obj --frame 3 2>&1)
grep -q 'went stale' <<<"$out" && grep -q '1 topology messages' <<<"$out" || { ok=0; why="$why; no stale warning: $out"; }
g=$(hashes gap.lcm g.obj 4); e=$(hashes good.lcm e.obj 4)
[ -n "$g" ] && [ "$g" = "$e" ] || { ok=0; why="$why; the snapshot did not repair: '$g' vs '$e'"; }
[ $ok = 1 ] && cs_pass topo_gap_noticed || cs_fail topo_gap_noticed "$why"

# The logger asks for a snapshot at start, then (at most once a second) after a loss: the gap
# log played on the bus must make it ask again. Its own requests are on CUBESIM_COMMAND, which
# it records too.
"$B/cubesim-log" heard.lcm --lcm "$CS_LCM_URL" >heard.txt 2>&1 & lp=$!
sleep 1.3
"$B/cubesim-replay" gap.lcm --lcm "$CS_LCM_URL" --speed 0 --quiet </dev/null
sleep 1.5
kill -INT $lp; wait $lp
lost=$(awk '$1 == "CUBESIM_TOPOLOGY" { print $4 }' heard.txt)
cmds=$(awk '$1 == "CUBESIM_COMMAND" { print $2 }' heard.txt)
[ "${lost:-0}" -ge 1 ] && [ "${cmds:-0}" -ge 2 ] && cs_pass "topo_logger_asks (lost $lost, $cmds requests)" \
    || cs_fail topo_logger_asks "lost '$lost', requests '$cmds': $(tr '\n' '|' <heard.txt)"
cs_finish
