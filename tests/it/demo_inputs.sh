#!/usr/bin/env bash
# demo_inputs — the demo's per-scene client inputs (scenes/demo.sh reads NAME.demo beside
# NAME.json), inside a private network namespace:
#   demo_inputs_unknown_key    a key the demo does not know stops it before the daemon starts,
#                              naming the file, the line and the keys it knows
#   demo_inputs_not_a_number   a value that is not a number: file, line, key and value
#   demo_inputs_count          a 3-vector given 2 numbers: file, line, what it takes
#   demo_inputs_used           a valid file: the demo pushes with its force (0 25 0, shown in
#                              the push line) and passes (demo OK), 3 s on the default scene
source "$(dirname "$0")/lib.sh"
cs_netns_reexec "$@"
B=$CS_IT_BIN
cs_need_bins demo_inputs cubesimd cubesim-push cubesim-log cubesim-replay
cp "$CS_ROOT/scenes/default.json" "$CS_TMP/x.json"
cp -r "$CS_ROOT/scenes/meshes" "$CS_TMP/meshes"

demo() { # run the demo on $CS_TMP/x.json (already in our namespace), output in $CS_TMP/out.txt
    CS_DEMO_NETNS=1 DEMO_BIN=$B DEMO_SCENE=$CS_TMP/x.json DEMO_OUT=$CS_TMP/demo \
        DEMO_SECONDS=${1:-3} timeout 120 bash "$CS_ROOT/scenes/demo.sh" </dev/null \
        >"$CS_TMP/out.txt" 2>&1
}
expect_refusal() { # NAME PATTERN: the demo exits 1, says PATTERN, and started no daemon
    local rc
    demo; rc=$?
    if [ $rc = 1 ] && grep -q -- "$2" "$CS_TMP/out.txt" && ! grep -q '^\[2/5\]' "$CS_TMP/out.txt"; then
        cs_pass "$1"
    else
        cs_fail "$1" "exit $rc, want 1 and '$2': $(tr '\n' '|' <"$CS_TMP/out.txt" | cut -c1-300)"
    fi
}

printf 'push_force 0 40 0\npushfor 0.2\n' >"$CS_TMP/x.demo"
expect_refusal demo_inputs_unknown_key "x.demo:2: unknown key 'pushfor' (push_at, push_force"
printf 'push_force 0 abc 0 # comment\n' >"$CS_TMP/x.demo"
expect_refusal demo_inputs_not_a_number "x.demo:1: push_force: 'abc' is not a number"
printf '# a comment line\n\ndrag_to 0.4 0.8\n' >"$CS_TMP/x.demo"
expect_refusal demo_inputs_count "x.demo:3: drag_to takes 3 number(s), got '0.4 0.8'"

printf 'push_force 0 25 0   # softer than the default 40 N\npush_for 0.2\n' >"$CS_TMP/x.demo"
demo 3
rc=$?
if [ $rc = 0 ] && grep -q -- '--force 0 25 0 --for 0.2' "$CS_TMP/out.txt" && grep -q '^demo OK' "$CS_TMP/out.txt"; then
    cs_pass demo_inputs_used
else
    cs_fail demo_inputs_used "exit $rc: $(tail -3 "$CS_TMP/out.txt" | tr '\n' '|')"
fi
cs_finish
