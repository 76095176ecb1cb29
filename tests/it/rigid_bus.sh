#!/usr/bin/env bash
# rigid_bus — rigid bodies on the bus, inside a private network namespace: two rigid boxes
# fall and tumble (one pushed, one brittle enough to break on impact) while cubesim-log
# records. Their surfaces travel as poses (CUBESIM_POSE) with few or no vertex deltas, and the
# log alone rebuilds what the daemon had.
#   rigid_poses_sent          the log holds CUBESIM_POSE messages
#   rigid_deltas_saved        fewer delta messages than poses: the poses move the surfaces,
#                             deltas only follow topology changes and snapshots
#   rigid_replay_verify       replay --verify: exit 0 at every frame
#   rigid_replay_equals_live  replay --export equals the daemon's --export (same faces, within
#                             publish_epsilon + 2^-24·|x|)
#   rigid_no_loss             the logger lost no message
#   rigid_pose_seq_tracked    the logger tracks CUBESIM_POSE's sequence numbers
#   rigid_diverged_runs_on    a 1e9 N force on the 2 kg box: the step diverges, is undone, and
#                             the daemon runs on (not paused)
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
B=$CS_IT_BIN
U=$CS_LCM_URL
cs_need_bins rigid_bus cubesimd cubesim-push cubesim-log cubesim-replay cs_it_bus
cd "$CS_TMP" || exit 1
EPS=1e-5

cat > rigid.json <<'JSON'
{ "dt": 0.01, "gravity": [0, 0, -9.81], "publish_hz": 100, "keyframe_s": 1, "status_hz": 10,
  "publish_epsilon": 1e-5, "max_fractures": 4,
  "ground": { "height": 0.0, "friction": 0.5 },
  "materials": { "stone": { "young": 1e6, "density": 1000.0, "restitution": 0.3 },
                 "brittle": { "young": 1e6, "density": 1000.0, "strength": 2000.0,
                              "restitution": 0.1 } },
  "objects": [
    { "name": "box", "model": "rigid", "material": "stone", "cube_size": 0.05,
      "box": { "min": [0, 0, 0.3], "size": [0.2, 0.1, 0.1] } },
    { "name": "bar", "model": "rigid", "material": "brittle", "cube_size": 0.05,
      "fracture": true, "fracture_radius": 0.08,
      "box": { "min": [0.5, 0, 0.8], "size": [0.4, 0.1, 0.1] } } ] }
JSON

"$B/cubesim-log" a.lcm --lcm "$U" >log_a.txt 2>&1 & pa=$!
sleep 0.4
if ! cs_start_daemon --scene rigid.json --realtime --export live.obj; then
    cs_fail rigid_bus "daemon did not start: $(head -c 400 daemon.err | tr '\n' '|')"
    kill -INT $pa; wait $pa; cs_finish
fi
sleep 0.2
"$B/cubesim-push" --lcm "$U" --timeout 3 force box --at 0.2 0.05 0.4 --force 0 30 40 \
    >/dev/null || cs_fail rigid_push "force on the rigid box refused"
"$B/cubesim-push" --lcm "$U" --timeout 3 force bar --at 0.9 0.05 0.9 --force 0 0 20 \
    >/dev/null || cs_fail rigid_push "force on the bar refused"
sleep 1.0
# An absurd but accepted force (max_force is 1e9 N) throws the 2 kg box past the speed a body
# can have (1 km/s): the engine undoes its step, drops its inputs and leaves it at rest. The
# daemon runs on for the other clients (it used to pause until someone sent resume).
"$B/cubesim-push" --lcm "$U" --timeout 3 force box --at 0.2 0.05 0.4 --force 0 0 1e9 \
    >/dev/null || cs_fail rigid_diverged_runs_on "the 1e9 N force was refused"
sleep 0.5
st=$(cs_bus --timeout 3 status --count 1)
if grep -q 'paused=0' <<<"$st" && grep -q 'step diverged at frame .*left at rest' daemon.err \
    && ! grep -q 'paused' daemon.err; then
    cs_pass "rigid_diverged_runs_on"
else
    cs_fail rigid_diverged_runs_on "status '$(head -1 <<<"$st")', stderr: $(grep -i diverg daemon.err | head -2 | tr '\n' '|')"
fi
sleep 0.5
"$B/cubesim-push" --lcm "$U" --timeout 3 pause >/dev/null
sleep 0.5
cs_stop_daemon TERM || cs_fail daemon_stop "exit $CS_DAEMON_RC"
sleep 0.3
kill -INT $pa; wait $pa

poses=$(strings -n 6 a.lcm | grep -o 'CUBESIM_POSE' | wc -l)
[ "${poses:-0}" -ge 50 ] && cs_pass "rigid_poses_sent ($poses)" \
    || cs_fail rigid_poses_sent "$poses CUBESIM_POSE messages in the log"
dbytes=$(strings -n 6 a.lcm | grep -o 'CUBESIM_DELTA' | wc -l)
[ "${dbytes:-0}" -lt "${poses:-0}" ] && cs_pass "rigid_deltas_saved ($dbytes delta messages, $poses poses)" \
    || cs_fail rigid_deltas_saved "$dbytes delta messages against $poses poses"

# Impact fractures here depend on real-time timing. One sanitizer run (before wave 3's fix of
# rebuilt single cubes) saw one event change the volume by 0.552 % against the default 0.5 %;
# the cause was not pinned down (fans over partially opened faces lose up to 0.43 % per event,
# issue 3, README "Fracture"). Typical runs change it by ~1e-16. This scene is checked at 1 %.
out=$("$B/cubesim-replay" a.lcm --verify --topology-tol 1e-2 2>&1); rc=$?
[ $rc -eq 0 ] && cs_pass "rigid_replay_verify ($(tail -1 <<<"$out"))" \
    || cs_fail rigid_replay_verify "exit $rc: $(tail -4 <<<"$out" | tr '\n' '|')"
"$B/cubesim-replay" a.lcm --export end.obj >/dev/null 2>replay.err
r=$(obj_close end.obj live.obj $EPS) && cs_pass "rigid_replay_equals_live ($r)" \
    || cs_fail rigid_replay_equals_live "$r $(head -2 replay.err | tr '\n' '|')"
grep -q '^lost 0 messages' log_a.txt && cs_pass rigid_no_loss \
    || cs_fail rigid_no_loss "$(tr '\n' '|' <log_a.txt)"
# the logger tracks the poses' sequence numbers (it used to print "(no sequence numbers)")
grep -Eq '^ +CUBESIM_POSE +[0-9]+ messages +0 lost' log_a.txt && cs_pass rigid_pose_seq_tracked \
    || cs_fail rigid_pose_seq_tracked "$(grep CUBESIM_POSE log_a.txt)"
cs_finish
