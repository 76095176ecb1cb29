#!/usr/bin/env bash
# daemon_hollow — a hollow mesh end to end, inside a private network namespace: a 0.2 m cube
# with a 0.08 m cavity at its centre (an inner closed shell wound inward, [0.06, 0.14]³), h =
# 0.025 m, loaded by the daemon, stepped, broken through its cavity by a client while
# cubesim-log records. The cavity holds the 2×2×2 cubes [0.075, 0.125]³ wholly.
#   hollow_static_nodes        --static --dump-nodes: 9³ − 1 = 728 nodes (the node at the
#                              centre of the cavity's empty cubes is not there; 729 when it
#                              was filled)
#   hollow_export_both_shells  --export: the surface holds both shells and encloses
#                              0.2³ − 0.08³ = 0.007488 m³ (the cavity's wall counted inward)
#   hollow_fracture_ack        cubesim-push fracture through the cavity gets "ok"
#   hollow_replay_verify       replay --verify: every frame closed and oriented, with at least
#                              one topology change applied
#   hollow_replay_equals_live  replay --export equals the daemon's --export
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
B=$CS_IT_BIN
U=$CS_LCM_URL
cs_need_bins daemon_hollow cubesimd cubesim-push cubesim-log cubesim-replay cs_it_bus
cd "$CS_TMP" || exit 1

# outer cube [0, 0.2]³ outward, inner cube [0.06, 0.14]³ inward
awk 'BEGIN {
    split("0 2 3 0 3 1 4 5 7 4 7 6 0 1 5 0 5 4 2 6 7 2 7 3 0 4 6 0 6 2 1 3 7 1 7 5", t, " ")
    for (s = 0; s < 2; s++) {
        lo = s ? 0.06 : 0; sz = s ? 0.08 : 0.2
        for (i = 0; i < 8; i++)
            printf "v %g %g %g\n", lo + (i % 2) * sz, lo + (int(i / 2) % 2) * sz, lo + int(i / 4) * sz
    }
    for (s = 0; s < 2; s++)
        for (f = 0; f < 12; f++) {
            a = t[3 * f + 1]; b = t[3 * f + 2]; c = t[3 * f + 3]
            if (s) { x = b; b = c; c = x }
            printf "f %d %d %d\n", 8 * s + a + 1, 8 * s + b + 1, 8 * s + c + 1
        }
}' > hollow.obj
cat > hollow.json <<'JSON'
{ "dt": 0.01, "gravity": [0, 0, -9.81], "publish_hz": 100, "keyframe_s": 1, "status_hz": 10,
  "publish_epsilon": 1e-5, "ground": { "height": 0 },
  "materials": { "soft": { "young": 1e5, "poisson": 0.3, "density": 500.0,
                           "damping": [1.0, 0.005] } },
  "objects": [
    { "name": "hollow", "model": "corotational", "material": "soft", "cube_size": 0.025,
      "fracture": true, "mesh": { "file": "hollow.obj" } } ] }
JSON

# signed volume and shell count (connected components of faces through shared vertices)
obj_volume() {
    awk '/^v /{n++; x[n]=$2; y[n]=$3; z[n]=$4}
         /^f /{for(i=2;i<=4;i++){split($i,p,"/"); k[i]=p[1]+0}
               a=k[2]; b=k[3]; c=k[4]
               vol += x[a]*(y[b]*z[c]-z[b]*y[c]) - y[a]*(x[b]*z[c]-z[b]*x[c]) + z[a]*(x[b]*y[c]-y[b]*x[c])
               for(i=3;i<=4;i++){ r1=a; while(par[r1]) r1=par[r1]; r2=k[i]; while(par[r2]) r2=par[r2]
                                   if(r1!=r2) par[r2]=r1 }
               used[a]=used[b]=used[c]=1}
         END { for(v in used){ r=v+0; while(par[r]) r=par[r]; root[r]=1 }
               for(r in root) shells++
               printf "%.9f %d\n", vol/6, shells }' "$1"
}

"$B/cubesimd" --scene hollow.json --static --dump-nodes nodes.csv --export static.obj --quiet \
    2>static.err
rc=$?
nn=$(($(wc -l <nodes.csv 2>/dev/null || echo 1) - 1))
[ $rc -eq 0 ] && [ "$nn" -eq 728 ] && cs_pass "hollow_static_nodes ($nn nodes)" \
    || cs_fail hollow_static_nodes "exit $rc, $nn nodes (want 728): $(head -c 300 static.err)"
read -r vol shells < <(obj_volume static.obj)
awk -v v="$vol" 'BEGIN { exit !(v > 0.0074879 && v < 0.0074881) }' && [ "$shells" = 2 ] \
    && cs_pass "hollow_export_both_shells (volume $vol m^3, $shells shells)" \
    || cs_fail hollow_export_both_shells "volume $vol m^3, $shells shells (want 0.007488, 2)"

"$B/cubesim-log" a.lcm --lcm "$U" >log_a.txt 2>&1 & pa=$!
sleep 0.4
if ! cs_start_daemon --scene hollow.json --realtime --export live.obj; then
    cs_fail daemon_hollow "daemon did not start: $(head -c 400 daemon.err | tr '\n' '|')"
    kill -INT $pa; wait $pa; cs_finish
fi
sleep 0.5
out=$("$B/cubesim-push" --lcm "$U" --timeout 5 fracture hollow --at 0.1 0.1 0.1 --normal 1 0 0 \
    --radius 0.3)
rc=$?
[ $rc -eq 0 ] && [ "$out" = ok ] && cs_pass hollow_fracture_ack || cs_fail hollow_fracture_ack "exit $rc: $out"
sleep 1.0
"$B/cubesim-push" --lcm "$U" --timeout 3 pause >/dev/null
sleep 0.3
cs_stop_daemon TERM || cs_fail daemon_stop "exit $CS_DAEMON_RC"
sleep 0.3
kill -INT $pa; wait $pa

out=$("$B/cubesim-replay" a.lcm --verify 2>&1); rc=$?
applied=$(sed -n 's/.*failed (\([0-9]*\) topology changes.*/\1/p' <<<"$out")
[ $rc -eq 0 ] && [ "${applied:-0}" -ge 1 ] && cs_pass "hollow_replay_verify ($(tail -1 <<<"$out"))" \
    || cs_fail hollow_replay_verify "exit $rc: $(tail -4 <<<"$out" | tr '\n' '|')"
"$B/cubesim-replay" a.lcm --export end.obj >/dev/null 2>replay.err
r=$(obj_close end.obj live.obj 1e-5) && cs_pass "hollow_replay_equals_live ($r)" \
    || cs_fail hollow_replay_equals_live "$r $(head -2 replay.err | tr '\n' '|')"
cs_finish
